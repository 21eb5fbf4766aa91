//! Cam synthesis: followers, pitch curve, cam surface, forward force model and design checks.
//!
//! Data flow: [`crate::model::Follower`] + law -> [`pitch_curve::synthesize`] ->
//! [`surface::offset`] (roller radius) -> [`forces::predict`] -> [`checks::run_checks`].
//! Nothing here does I/O.

pub mod checks;
pub mod forces;
pub mod pitch_curve;
pub mod surface;
pub mod tolerance;
