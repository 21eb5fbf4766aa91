//! `camspring validate`: a built spring's calibration log against its design.
//!
//! The log goes through identification (offline) and the EKF (on-line impedance). Three
//! things are compared with the designed law, each as a relative deviation against the one
//! `--tolerance`:
//!
//! - `k2`: the EKF's converged exponent rate against the designed k2;
//! - `stiffness_force_line`: over the converged second half of the run, the RMS deviation of
//!   the estimated stiffness sigma(t) from the designed line sigma = k2 (F - F0) at the
//!   estimated spring force F = sigma / k2_est + F0_est;
//! - `force_rms` and `force_max`: the identified characteristic mu exp(k2 x) + F0 against the
//!   designed one over the deflections the log covers, RMS and maximum relative deviation.
//!
//! The verdict passes when every criterion does. `validation.svg` shows the stiffness-force
//! scatter with the designed line, and the estimates converging over time
//! ([`crate::render::calibration::validation_svg`]).

use serde::Serialize;

use crate::estimate::ekf::{idx, EkfRun, State};
use crate::estimate::identify::{Identification, Param};
use crate::model::ExpLaw;

/// The spring force the EKF's state implies: sigma / k2 + F0 (the affine relation), with F0
/// from the parallel filter's `offsets`.
pub fn spring_force_n(z: &State, offsets: &[f64; 2]) -> f64 {
    z[idx::SIGMA] / z[idx::K2] + offsets[0]
}

/// One criterion of the verdict.
#[derive(Debug, Clone, Serialize)]
pub struct Criterion {
    /// Name (k2, stiffness_force_line, force_rms, force_max).
    pub name: &'static str,
    /// What it compares.
    pub what: &'static str,
    /// Measured relative deviation (percent).
    pub deviation_percent: f64,
    /// Allowed (percent).
    pub tolerance_percent: f64,
    /// Whether it passes.
    pub pass: bool,
}

/// The verdict and what it rests on.
#[derive(Debug, Clone, Serialize)]
pub struct Validation {
    /// All criteria pass.
    pub pass: bool,
    /// The criteria.
    pub criteria: Vec<Criterion>,
    /// The designed law.
    pub designed: ExpLaw,
    /// The identified law (offline).
    pub identified: ExpLaw,
    /// The EKF's final k2 (1/mm).
    pub ekf_k2_per_mm: f64,
    /// Its standard deviation (1/mm).
    pub ekf_k2_per_mm_std: f64,
    /// Smallest deflection in the log (mm).
    pub range_min_mm: f64,
    /// Largest deflection in the log (mm).
    pub range_max_mm: f64,
}

/// Compares a log's identification and EKF run with the designed law.
pub fn validate(
    designed: &ExpLaw,
    id: &Identification,
    run: &EkfRun,
    positions_mm: &[f64],
    tolerance: f64,
) -> Validation {
    let value = |p: Param| id.get(p).value;
    let identified = ExpLaw {
        mu_n: value(Param::Mu).unwrap_or(f64::NAN),
        k2_per_mm: value(Param::K2).unwrap_or(id.k2_quasi_static_per_mm),
        f0_n: value(Param::F0).unwrap_or(f64::NAN),
    };
    let tol = 100.0 * tolerance;
    let mut criteria = Vec::new();
    let mut add = |name, what, deviation: f64| {
        criteria.push(Criterion {
            name,
            what,
            deviation_percent: deviation,
            tolerance_percent: tol,
            pass: deviation.is_finite() && deviation <= tol,
        })
    };
    let last = run.last.z;
    let k2_std = run.last.std()[idx::K2];
    add(
        "k2",
        "EKF exponent rate k2 against the design",
        100.0 * (last[idx::K2] / designed.k2_per_mm - 1.0).abs(),
    );
    // Stiffness against force over the converged half.
    let n = run.states.len();
    let (mut num, mut den) = (0.0, 0.0);
    for (z, off) in run.states[n / 2..].iter().zip(&run.offsets[n / 2..]) {
        let force = spring_force_n(z, off);
        let line = designed.k2_per_mm * (force - designed.f0_n);
        num += (z[idx::SIGMA] - line).powi(2);
        den += line * line;
    }
    add(
        "stiffness_force_line",
        "RMS of estimated stiffness against the designed line sigma = k2 (F - F0)",
        100.0 * (num / den.max(1e-300)).sqrt(),
    );
    // Force-deflection over the measured range.
    let (lo, hi) = positions_mm
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    let samples = 200;
    let (mut sq, mut max, mut dsq) = (0.0_f64, 0.0_f64, 0.0_f64);
    for i in 0..=samples {
        let x = lo + (hi - lo) * i as f64 / samples as f64;
        let (fd, fi) = (designed.force_n(x), identified.force_n(x));
        sq += (fi - fd).powi(2);
        dsq += fd * fd;
        max = max.max(((fi - fd) / fd).abs());
    }
    add(
        "force_rms",
        "RMS of the identified force-deflection curve against the design over the measured range",
        100.0 * (sq / dsq.max(1e-300)).sqrt(),
    );
    add(
        "force_max",
        "largest relative deviation of the identified force from the design over the measured range",
        100.0 * max,
    );
    Validation {
        pass: criteria.iter().all(|c| c.pass),
        criteria,
        designed: *designed,
        identified,
        ekf_k2_per_mm: last[idx::K2],
        ekf_k2_per_mm_std: k2_std,
        range_min_mm: lo,
        range_max_mm: hi,
    }
}
