//! Verdicts on a built spring: its calibration log judged against the design. Sits above the
//! design and the estimators and uses both; nothing below imports it.

pub mod diagnose;
pub mod revise;
pub mod validate;
