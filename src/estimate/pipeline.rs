//! The paper's on-line estimation as one call: initial state from identification (or a law),
//! Coulomb friction taken out of the force, the EKF with its parallel F0, d0 filter, and the
//! friction put back. The command layer only reads the log and shows progress.

use super::ekf::{self, EkfError, EkfInit, EkfInput, EkfRun, EkfSettings};
use super::identify::{identify_with_window, Identification, IdentifyError, SensorNoise};
use super::log::CalibrationLog;
use super::sg;
use crate::model::ExpLaw;

/// Where the filter's initial state comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum EstimateInit {
    /// Offline identification of the same log (the paper's procedure; default).
    Identify,
    /// A designed law (k2, mu, F0) over a stroke; the dynamics start wide.
    Law {
        /// The law.
        law: ExpLaw,
        /// The stroke it is designed for (mm).
        xmax_mm: f64,
    },
}

/// A state of the filter, for overrides of its tuning.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StateName {
    /// Position x.
    X,
    /// Velocity xd.
    Xd,
    /// Acceleration xdd.
    Xdd,
    /// Stiffness sigma.
    Sigma,
    /// Damping D.
    D,
    /// Inertia M.
    M,
    /// Exponent rate k2.
    K2,
    /// Cubic damping d2.
    D2,
}

impl StateName {
    /// Every state, in state-vector order.
    pub const ALL: [StateName; 8] = [
        StateName::X,
        StateName::Xd,
        StateName::Xdd,
        StateName::Sigma,
        StateName::D,
        StateName::M,
        StateName::K2,
        StateName::D2,
    ];

    /// Short name as typed on the command line (`xdd`, `sigma`, ...).
    pub fn short(self) -> &'static str {
        ["x", "xd", "xdd", "sigma", "d", "m", "k2", "d2"][self.index()]
    }

    /// Index in the state vector.
    pub fn index(self) -> usize {
        self as usize
    }

    /// The state for a short name (any case) or a unit-bearing one of [`ekf::STATE_NAMES`].
    pub fn parse(name: &str) -> Option<StateName> {
        let name = name.trim();
        StateName::ALL
            .into_iter()
            .find(|s| s.short().eq_ignore_ascii_case(name) || ekf::STATE_NAMES[s.index()] == name)
    }
}

/// Options of the estimation.
#[derive(Debug, Clone)]
pub struct EstimateOptions {
    /// Initial state.
    pub init: EstimateInit,
    /// Prediction method.
    pub discretization: ekf::Discretization,
    /// Force-rate input.
    pub force_rate: ekf::ForceRate,
    /// Sensor noise (R and the force-rate noise).
    pub noise: SensorNoise,
    /// Identification window (s), when identifying.
    pub window_s: Option<f64>,
    /// Innovations beyond this many standard deviations count as outliers; 50 in a row stop
    /// the filter (None: the default of [`ekf::default_settings`]).
    pub outlier_sigmas: Option<f64>,
    /// Overrides of the process noise density Q of states.
    pub q: Vec<(StateName, f64)>,
    /// Overrides of the initial standard deviation of states.
    pub p0_std: Vec<(StateName, f64)>,
    /// Override of the position measurement variance R (mm^2).
    pub r_position_mm2: Option<f64>,
}

impl EstimateOptions {
    /// Identification init, RK4, zero-phase force rate, the given sensors, no overrides.
    pub fn new(noise: SensorNoise) -> EstimateOptions {
        EstimateOptions {
            init: EstimateInit::Identify,
            discretization: ekf::Discretization::Rk4,
            force_rate: ekf::ForceRate::ZeroPhase,
            noise,
            window_s: None,
            outlier_sigmas: None,
            q: Vec::new(),
            p0_std: Vec::new(),
            r_position_mm2: None,
        }
    }
}

/// What the estimation computed.
#[derive(Debug, Clone)]
pub struct EstimateRun {
    /// The filter run.
    pub run: EkfRun,
    /// The settings used.
    pub settings: EkfSettings,
    /// The identification, when the init came from it.
    pub identification: Option<Identification>,
}

/// Why the estimation failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EstimateError {
    /// Produced by [`estimate`] when identification (the init) fails.
    #[error("identify: {0}")]
    Identify(#[from] IdentifyError),
    /// Produced by [`estimate`] when the filter diverges or the log is too short for it.
    #[error("estimate: {0}")]
    Filter(#[from] EkfError),
}

/// Removes Coulomb friction `d0_n` from the force: it steps the force at every reversal, and
/// its derivative is not in the filter's model. The sign is that of the motion velocity,
/// held while the velocity is within three noise standard deviations of zero.
fn without_coulomb(log: &CalibrationLog, d0_n: f64, noise: &SensorNoise) -> Vec<f64> {
    let mut force = log.force_n.clone();
    if d0_n == 0.0 {
        return force;
    }
    let dt = log.dt_s();
    let diff = sg::Differentiator::for_rate(1.0 / dt);
    let v = diff.apply(&log.position_mm, dt, sg::MOTION_VELOCITY);
    let band = 3.0
        * diff
            .noise_variance(sg::MOTION_VELOCITY, noise.position_variance_mm2, dt)
            .sqrt();
    let mut sign = 0.0;
    for (i, f) in force.iter_mut().enumerate() {
        let vi = v.get(i.saturating_sub(diff.half).min(v.len().saturating_sub(1)));
        if let Some(&vi) = vi {
            if vi > band {
                sign = 1.0;
            } else if vi < -band {
                sign = -1.0;
            }
        }
        *f -= d0_n * sign;
    }
    force
}

/// Runs the EKF over a log; `progress(k, n)` is called as samples are processed.
pub fn estimate(
    log: &CalibrationLog,
    opts: &EstimateOptions,
    progress: impl FnMut(usize, usize),
) -> Result<EstimateRun, EstimateError> {
    let (init, identification, stroke) = match &opts.init {
        EstimateInit::Identify => {
            let id = identify_with_window(log, &opts.noise, opts.window_s)?;
            let stroke = log.position_mm.iter().fold(0.0_f64, |m, &x| m.max(x.abs()));
            (EkfInit::from_identification(&id), Some(id), stroke)
        }
        EstimateInit::Law { law, xmax_mm } => (EkfInit::from_law(law), None, *xmax_mm),
    };
    let dt = log.dt_s();
    let mut settings =
        ekf::default_settings(&init, &opts.noise, dt, opts.discretization, opts.force_rate);
    let force = without_coulomb(log, init.d0_n, &opts.noise);
    let first = ekf::force_rate_first_sample(dt, opts.force_rate);
    let x0 = log.position_mm.get(first).copied().unwrap_or(0.0);
    let (z0, sigma_std) = ekf::initial_state(&init, x0, stroke);
    settings.p0_std[ekf::idx::SIGMA] = sigma_std;
    if let Some(k) = opts.outlier_sigmas {
        settings.outlier_sigmas = k;
    }
    for &(s, v) in &opts.q {
        settings.q[s.index()] = v;
    }
    for &(s, v) in &opts.p0_std {
        settings.p0_std[s.index()] = v;
    }
    if let Some(r) = opts.r_position_mm2 {
        settings.r_position_mm2 = r.max(1e-12);
    }
    let mut run = ekf::run(
        EkfInput {
            t_s: &log.t_s,
            force_n: &force,
            position_mm: &log.position_mm,
            force_rate: opts.force_rate,
            z0,
            settings,
            offsets0: [init.f0_n, init.d0_n],
            offset_memory_s: ekf::OFFSET_MEMORY_S,
        },
        progress,
    )?;
    // The parallel filter saw the force with the initial d0 taken out: add it back.
    for o in run.offsets.iter_mut() {
        o[1] += init.d0_n;
    }
    run.offset_filter.theta[1] += init.d0_n;
    Ok(EstimateRun {
        run,
        settings,
        identification,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn state_names_follow_the_state_vector() {
        assert_eq!(StateName::parse("XDD"), Some(StateName::Xdd));
        assert_eq!(StateName::Xdd.index(), ekf::idx::XDD);
        assert_eq!(StateName::Sigma.index(), ekf::idx::SIGMA);
        assert_eq!(StateName::M.index(), ekf::idx::M);
        assert_eq!(StateName::K2.index(), ekf::idx::K2);
        assert_eq!(StateName::D2.index(), ekf::idx::D2);
        assert_eq!(StateName::parse(ekf::STATE_NAMES[6]), Some(StateName::K2));
        assert_eq!(StateName::parse("nope"), None);
    }
}
