//! The crate's top-level error: everything a command can fail with, sorted by exit code.

use std::path::PathBuf;

use crate::design::DesignError;
use crate::part::PartError;
use crate::spec::SpecError;
use crate::toolpath::ToolpathError;

/// Any failure of a camspring command.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Produced by [`crate::run::load_spec`] when the spec is invalid.
    #[error("spec {path}: {source}")]
    Spec {
        /// The spec file (or "built-in default").
        path: String,
        /// What is wrong.
        #[source]
        source: SpecError,
    },
    /// Produced by [`crate::design::design`] (through the commands) when the spec cannot be realised.
    #[error(transparent)]
    Design(#[from] DesignError),
    /// Produced by [`crate::export::write_design`] when the part cannot be built (a hole
    /// that does not fit, or a fit that cannot reach its tolerance).
    #[error("part: {0}")]
    Part(#[from] PartError),
    /// Produced by [`crate::export::write_design`] when the machining settings are unusable
    /// (a tolerance finer than the dialect writes).
    #[error("machining: {0}")]
    Toolpath(#[from] ToolpathError),
    /// Produced by [`crate::run::read_log_file`] for a malformed calibration log.
    #[error("log {path}: {source}")]
    Log {
        /// The log file.
        path: PathBuf,
        /// What is wrong, with the line.
        #[source]
        source: crate::estimate::log::LogError,
    },
    /// Produced by [`crate::run::run_simulate`] when the run cannot be simulated.
    #[error("simulate: {0}")]
    Simulate(#[from] crate::estimate::sim::SimError),
    /// Produced by [`crate::run::run_identify`] when the log cannot identify the spring.
    #[error("identify: {0}")]
    Identify(#[from] crate::estimate::identify::IdentifyError),
    /// Produced by [`crate::run::run_estimate`] and [`crate::run::run_validate`] when the
    /// filter diverges or the log is too short for it.
    #[error("estimate: {0}")]
    Estimate(#[from] crate::estimate::ekf::EkfError),
    /// Produced by the commands for an unusable option value.
    #[error("{0}")]
    Argument(String),
    /// Produced when an input file cannot be read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// Produced by the exporters when an output cannot be written.
    #[error("cannot write {path}: {source}")]
    Write {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// Produced by the exporters when an output cannot be encoded.
    #[error("cannot encode {what}: {message}")]
    Encode {
        /// Which output.
        what: &'static str,
        /// Why.
        message: String,
    },
}

impl Error {
    /// Whether the user's input is at fault (exit code 2) rather than the machine (exit code 3).
    pub fn is_bad_input(&self) -> bool {
        matches!(
            self,
            Error::Spec { .. }
                | Error::Design(_)
                | Error::Part(_)
                | Error::Toolpath(_)
                | Error::Read { .. }
                | Error::Log { .. }
                | Error::Simulate(_)
                | Error::Identify(_)
                | Error::Estimate(_)
                | Error::Argument(_)
        )
    }
}

/// Result with the crate's error.
pub type Result<T, E = Error> = std::result::Result<T, E>;
