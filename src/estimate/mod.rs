//! Calibration logs of a built spring: reading ([`log`]), simulating with known truth
//! ([`sim`]), sensor noise by Allan variance ([`allan`]), smoothing differentiators ([`sg`]) and
//! offline identification of the transmission parameters ([`identify`], paper sections IV-V),
//! with its filter window chosen from the data ([`window`]) and its fit judged ([`adequacy`]).
//! The paper's EKF ([`ekf`]) estimates stiffness, damping and inertia on-line; [`pipeline`]
//! runs it as one call. [`noise`] models the sensors of a log at rest, and
//! [`quantisation`] what an encoder's steps pass through identification's kernels. This layer depends only
//! on the law's model; verdicts against a design are in [`crate::verdict`], and what the
//! commands print in [`crate::render::calibration`].

pub mod adequacy;
pub mod allan;
pub mod ekf;
pub mod identify;
pub mod log;
pub mod noise;
pub mod pipeline;
pub mod quantisation;
pub mod retime;
pub mod sg;
pub mod sim;
pub mod twin;
pub mod window;
