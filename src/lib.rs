//! # camspring
//!
//! Design nonlinear elastic transmissions whose force grows exponentially with deflection
//! (stiffness affine in force, like passive muscle), realised as a cam with spring-loaded
//! roller followers; after Sen, Chatterjee and Har, *Design and Impedance Estimation of a
//! Biologically Inspired Flexible Mechanical Transmission with Exponential Elastic
//! Characteristic*. The derivations the code relies on are in `docs/THEORY.md`.
//!
//! ## Layers
//!
//! Data flows one way; each layer imports only those above it in this list (a test enforces
//! it, see `docs/ARCHITECTURE.md`):
//!
//! | layer | modules | pure? |
//! | --- | --- | --- |
//! | model | [`model`] (Spec and its sections, validation), [`units`], [`geom`] | yes |
//! | law | [`law`] (solving the law) | yes |
//! | synthesis, estimation | [`cam`], [`mod@estimate`] | yes |
//! | design | [`mod@design`] | yes |
//! | part, toolpath | [`part`], [`toolpath`] | yes |
//! | plan, sweep, verdict | [`outputs`], [`sweep`], [`verdict`] | yes |
//! | render, export | [`render`] (text, plots, HTML), [`export`] (files: STEP, STL, DXF, drawing) | export writes |
//! | formats, app | [`spec`] (TOML), [`app`] (commands, I/O, exit codes), [`Error`] | I/O |
//!
//! ## The public API
//!
//! The names a library user needs are re-exported here:
//! - spec: [`Spec`], [`SpecBuilder`], [`SpecError`], the sections ([`LawSpec`], [`LawTargets`],
//!   [`ExpLaw`], [`Follower`], [`PartSpec`], [`MachiningSpec`], [`ChecksSpec`], [`OutputSpec`]);
//! - design: [`design()`], [`Design`], [`DesignError`];
//! - outputs: [`plan`], [`Outputs`], [`DesignSummary`], and the writers [`write_design`] and
//!   [`write_atomic`];
//! - calibration: [`read_log`], [`ColumnMap`], [`CalibrationLog`], [`identify`],
//!   [`SensorNoise`], [`GivenNoise`], [`estimate()`], [`EstimateOptions`], [`validate`],
//!   [`Validation`].
//!
//! ```
//! use camspring::{design, plan, spec::DEFAULT_SPEC_TOML, Spec};
//! let spec = Spec::from_toml(DEFAULT_SPEC_TOML).unwrap();
//! let d = design(&spec).unwrap();
//! println!("lift {:.3} mm", d.pitch_curve.lift_mm());
//! let outputs = plan(&d).unwrap();
//! assert!(outputs.summary.outputs.contains(&"cam.ngc".to_string()));
//! ```
#![deny(clippy::all)]
#![warn(missing_docs, missing_debug_implementations, rust_2018_idioms)]

pub mod app;
pub mod cam;
pub mod design;
pub mod error;
pub mod estimate;
pub mod export;
pub mod geom;
pub mod law;
pub mod model;
pub mod outputs;
pub mod part;
pub mod render;
pub mod spec;
pub mod sweep;
pub mod toolpath;
pub mod units;
pub mod verdict;

pub use design::{design, Design, DesignError};
pub use error::Error;
pub use estimate::identify::{identify, Identification, SensorNoise};
pub use estimate::log::{read_log, CalibrationLog, ColumnMap};
pub use estimate::noise::GivenNoise;
pub use estimate::pipeline::{estimate, EstimateInit, EstimateOptions, EstimateRun};
pub use export::{write_atomic, write_design};
pub use model::{
    ChecksSpec, ExpLaw, Follower, LawSpec, LawTargets, MachiningSpec, OutputSpec, PartSpec, Spec,
    SpecBuilder, SpecError,
};
pub use outputs::{plan, DesignSummary, Outputs};
pub use verdict::validate::{validate, Validation};
