//! # camspring
//!
//! Design nonlinear elastic transmissions whose force grows exponentially with deflection
//! (stiffness affine in force, like passive muscle), realised as a cam with spring-loaded
//! roller followers; after Sen, Chatterjee and Har, *Design and Impedance Estimation of a
//! Biologically Inspired Flexible Mechanical Transmission with Exponential Elastic
//! Characteristic*.
//!
//! The design layers ([`law`], [`cam`], [`mod@design`], [`part`], [`toolpath`]) are pure computation. [`spec`] reads the
//! TOML spec, [`export`] writes files (design data, STEP, STL, DXF, drawings, G-code), [`run`]
//! is what the command line calls. [`estimate`] reads calibration logs of a built spring,
//! simulates them with known truth, models sensor noise and identifies the parameters.
//!
//! ```
//! use camspring::{design::design, spec::{Spec, DEFAULT_SPEC_TOML}};
//! let spec = Spec::from_toml(DEFAULT_SPEC_TOML).unwrap();
//! let d = design(&spec).unwrap();
//! println!("lift {:.3} mm", d.pitch_curve.lift_mm());
//! ```
#![deny(clippy::all)]
#![warn(missing_docs, missing_debug_implementations, rust_2018_idioms)]

pub mod cam;
pub mod design;
pub mod error;
pub mod estimate;
pub mod export;
pub mod law;
pub mod part;
pub mod run;
pub mod spec;
pub mod sweep;
pub mod toolpath;
pub mod units;

pub use design::{design, Design, DesignError};
pub use error::Error;
pub use law::{ExpLaw, LawTargets};
pub use spec::Spec;
