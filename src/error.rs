//! The commands' error: everything a command can fail with, sorted by exit code. Each layer
//! below has its own error type; this one wraps them for the application layer.

use std::path::PathBuf;

use crate::design::DesignError;
use crate::export::ExportError;
use crate::model::SpecError;
use crate::outputs::PlanError;

/// Any failure of a camspring command.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Produced by [`crate::app::load_spec`] when the spec is invalid.
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
    /// Produced by [`crate::outputs::plan`] (through the commands) when no part or program
    /// can be planned.
    #[error(transparent)]
    Plan(#[from] PlanError),
    /// Produced by [`crate::app::read_log_file`] for a malformed calibration log.
    #[error("log {path}: {source}")]
    Log {
        /// The log file.
        path: PathBuf,
        /// What is wrong, with the line.
        #[source]
        source: Box<crate::estimate::log::LogError>,
    },
    /// Produced by [`crate::app::run_simulate`] when the run cannot be simulated.
    #[error("simulate: {0}")]
    Simulate(#[from] crate::estimate::sim::SimError),
    /// Produced by [`crate::app::run_identify`] when the log cannot identify the spring.
    #[error("identify: {0}")]
    Identify(#[from] crate::estimate::identify::IdentifyError),
    /// Produced by [`crate::app::run_estimate`] and [`crate::app::run_validate`] when the
    /// filter diverges or the log is too short for it.
    #[error(transparent)]
    Estimate(#[from] crate::estimate::pipeline::EstimateError),
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
    /// Produced by the exporters when an output cannot be written or encoded.
    #[error(transparent)]
    Export(#[from] ExportError),
}

impl Error {
    /// What failed, as a word for scripts: spec, design, part, machining, log, simulate,
    /// identify, estimate, argument, read, write.
    pub fn kind(&self) -> &'static str {
        match self {
            Error::Spec { .. } => "spec",
            Error::Design(crate::design::DesignError::Spec(_)) => "spec",
            Error::Design(_) => "design",
            Error::Plan(PlanError::Part(_)) => "part",
            Error::Plan(PlanError::Toolpath(_)) => "machining",
            Error::Plan(PlanError::Mesh(_)) | Error::Export(_) => "write",
            Error::Log { .. } => "log",
            Error::Simulate(_) => "simulate",
            Error::Identify(_) => "identify",
            Error::Estimate(_) => "estimate",
            Error::Argument(_) => "argument",
            Error::Read { .. } => "read",
        }
    }

    /// The spec key the error names, if any.
    pub fn key(&self) -> Option<&str> {
        match self {
            Error::Spec { source, .. }
            | Error::Design(crate::design::DesignError::Spec(source)) => source.key(),
            _ => None,
        }
    }

    /// The line of the spec or log the error names, if any.
    pub fn line(&self) -> Option<u64> {
        match self {
            Error::Spec { source, .. } => source.line().map(|l| l as u64),
            Error::Log { source, .. } => source.line(),
            _ => None,
        }
    }

    /// Whether the user's input is at fault (exit code 2) rather than the machine (exit code 3).
    pub fn is_bad_input(&self) -> bool {
        matches!(
            self,
            Error::Spec { .. }
                | Error::Design(_)
                | Error::Plan(PlanError::Part(_) | PlanError::Toolpath(_))
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
