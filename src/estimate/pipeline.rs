//! The paper's on-line estimation as one call: initial state from identification (or a law),
//! Coulomb friction taken out of the force, the EKF with its parallel F0, d0 filter, and the
//! friction put back. The command layer only reads the log and shows progress.

use super::ekf::{self, EkfError, EkfInit, EkfInput, EkfRun, EkfSettings};
use super::identify::{identify_with_window, Identification, IdentifyError, SensorNoise};
use super::log::CalibrationLog;
use super::sg;
use crate::model::{ExpLaw, ForceLaw};
use serde::Serialize;

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
    /// The log's encoder zero: taken out of the positions before anything else.
    pub position_offset: PositionOffset,
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
            position_offset: PositionOffset::None,
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
    /// How a diverged first run was recovered, if it was.
    pub recovery: Option<String>,
    /// Whether the run's estimates and standard deviations can be trusted.
    pub consistency: Consistency,
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
    /// Produced by [`estimate`] for [`PositionOffset::Auto`] without a law to fit against.
    #[error(
        "--position-offset auto fits the encoder zero against a designed law: use it with \
         validate SPEC, or with estimate --init SPEC; or give the offset, e.g. --position-offset 0.5mm"
    )]
    OffsetNeedsLaw,
}

/// Removes Coulomb friction `d0_n` from the force: it steps the force at every reversal, and
/// its derivative is not in the filter's model.
///
/// The sign is that of the motion velocity (Savitzky-Golay over `window` samples, zero phase).
/// Where the velocity stays within three of its noise standard deviations of zero for longer
/// than half a window, the spring is at rest and the model's friction is zero. A shorter stay
/// is a reversal, and the sign follows the velocity's through zero, so the friction's step
/// falls within a few samples of the true one. What is left near each reversal, a force error
/// of 2 d0 over those samples, reaches the filter through the force rate: with strong friction
/// (d0 many times the force noise) the filter's inertia and k2 suffer, and
/// [`Consistency`] says so.
fn without_coulomb(
    log: &CalibrationLog,
    d0_n: f64,
    noise: &SensorNoise,
    window: usize,
) -> Vec<f64> {
    let mut force = log.force_n.clone();
    if d0_n == 0.0 {
        return force;
    }
    let dt = log.dt_s();
    let diff = sg::Differentiator::new(window);
    let v = diff.apply(&log.position_mm, dt, sg::MOTION_VELOCITY);
    let band = 3.0
        * diff
            .noise_variance(sg::MOTION_VELOCITY, noise.position_variance_mm2, dt)
            .sqrt();
    let n = force.len();
    // The sign at every sample (edges: the nearest filtered velocity).
    let velocity = |i: usize| v[i.saturating_sub(diff.half).min(v.len().saturating_sub(1))];
    let mut sign = vec![0.0; n];
    if v.is_empty() {
        return force;
    }
    let mut i = 0;
    while i < n {
        let vi = velocity(i);
        if vi.abs() > band {
            sign[i] = vi.signum();
            i += 1;
            continue;
        }
        let start = i;
        while i < n && velocity(i).abs() <= band {
            i += 1;
        }
        let at_rest = i - start > diff.half;
        for (k, s) in sign.iter_mut().enumerate().take(i).skip(start) {
            *s = if at_rest { 0.0 } else { velocity(k).signum() };
        }
    }
    for (f, s) in force.iter_mut().zip(&sign) {
        *f -= d0_n * s;
    }
    force
}

/// Runs the EKF over a log; `progress(k, n)` is called as samples are processed.
pub fn estimate(
    log: &CalibrationLog,
    opts: &EstimateOptions,
    progress: impl FnMut(usize, usize),
) -> Result<EstimateRun, EstimateError> {
    let shifted;
    let log = match opts.position_offset {
        PositionOffset::None => log,
        PositionOffset::Mm(c) => {
            let mut l = log.clone();
            l.shift_position(c);
            shifted = l;
            &shifted
        }
        PositionOffset::Auto => {
            let EstimateInit::Law { law, .. } = &opts.init else {
                return Err(EstimateError::OffsetNeedsLaw);
            };
            let c = fit_offset_by_identification(log, &opts.noise, &ForceLaw::Exponential(*law))?;
            let mut l = log.clone();
            l.shift_position(c);
            shifted = l;
            &shifted
        }
    };
    let (mut init, identification, stroke) = match &opts.init {
        EstimateInit::Identify => {
            let id = identify_with_window(log, &opts.noise, opts.window_s)?;
            let stroke = log.position_mm.iter().fold(0.0_f64, |m, &x| m.max(x.abs()));
            (EkfInit::from_identification(&id), Some(id), stroke)
        }
        EstimateInit::Law { law, xmax_mm } => (EkfInit::from_law(law), None, *xmax_mm),
    };
    let dt = log.dt_s();
    // The inertia's floor keeps the prediction stable: RK4 needs D dt / M and
    // sqrt(sigma / M) dt of order 1 or less, and an inertia below that cannot be resolved at
    // this sampling rate anyway. A held inertia (not resolved by identification) starts there.
    let sigma_top =
        init.k2_per_mm.0.abs() * init.mu_n.abs() * (init.k2_per_mm.0.abs() * stroke).exp();
    let m_floor = (init.d1_n_s_per_mm.0.abs() * dt)
        .max(sigma_top * dt * dt)
        .max(1e-6);
    init.m_n_s2_per_mm.0 = init.m_n_s2_per_mm.0.max(m_floor);
    // Identification's window also gives the velocity whose sign is the friction's.
    let window = identification
        .as_ref()
        .map_or(sg::window_for_rate(1.0 / dt), |id| {
            // Identification may run on a block-averaged log: its window in this log's samples.
            ((id.sg_window_s / dt).round().max(sg::MIN_WINDOW as f64) as usize) | 1
        });
    let mut settings =
        ekf::default_settings(&init, &opts.noise, dt, opts.discretization, opts.force_rate);
    let force = without_coulomb(log, init.d0_n, &opts.noise, window);
    let first = ekf::force_rate_first_sample(dt, opts.force_rate);
    let x0 = log.position_mm.get(first).copied().unwrap_or(0.0);
    let (z0, sigma_std) = ekf::initial_state(&init, x0, stroke);
    settings.p0_std[ekf::idx::SIGMA] = sigma_std;
    settings.m_floor = settings.m_floor.max(m_floor);
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
    let input = |settings: EkfSettings| EkfInput {
        t_s: &log.t_s,
        force_n: &force,
        position_mm: &log.position_mm,
        force_rate: opts.force_rate,
        z0,
        settings,
        offsets0: [init.f0_n, init.d0_n],
        offset_memory_s: ekf::OFFSET_MEMORY_S,
    };
    let mut progress = progress;
    let mut recovery = None;
    let mut run = match ekf::run(input(settings), &mut progress) {
        Ok(run) => run,
        Err(EkfError::Diverged { sample, t_s, what }) => {
            // A poor start: widen what the filter may learn (ten times the initial standard
            // deviations of the impedance states and constants, ten times the process noise
            // of the acceleration) and run again from the start, once.
            let mut wide = settings;
            for i in [
                ekf::idx::SIGMA,
                ekf::idx::D,
                ekf::idx::M,
                ekf::idx::K2,
                ekf::idx::D2,
            ] {
                wide.p0_std[i] *= 10.0;
            }
            wide.q[ekf::idx::XDD] *= 10.0;
            let run = match ekf::run(input(wide), &mut progress) {
                Ok(run) => run,
                Err(second) => {
                    // Report the first divergence: the log's fault is most likely there.
                    return Err(EkfError::Diverged {
                        sample,
                        t_s,
                        what: format!(
                            "{what}; a second run with ten times the initial uncertainty failed \
                             too ({second})"
                        ),
                    }
                    .into());
                }
            };
            recovery = Some(format!(
                "the filter diverged at sample {sample} (t = {t_s:.3} s: {what}); it was run again \
                 from the start with ten times the initial standard deviations of sigma, D, M, k2 \
                 and d2 and ten times the process noise of the acceleration, and converged"
            ));
            settings = wide;
            run
        }
        Err(e) => return Err(e.into()),
    };
    // The parallel filter saw the force with the initial d0 taken out: add it back.
    for o in run.offsets.iter_mut() {
        o[1] += init.d0_n;
    }
    run.offset_filter.theta[1] += init.d0_n;
    let consistency = Consistency::new(&run, identification.as_ref());
    Ok(EstimateRun {
        run,
        settings,
        identification,
        recovery,
        consistency,
    })
}

/// How far the filter's constants may lie from identification's, in standard deviations of
/// their difference, before the run counts as inconsistent.
pub const AGREEMENT_SIGMAS: f64 = 3.0;

/// The range of the mean normalised innovation squared inside which the filter counts as
/// consistent.
pub const NIS_RANGE: (f64, f64) = (0.7, 1.5);

/// One constant that the filter and identification both estimate.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Agreement {
    /// The state's unit-bearing name.
    pub state: &'static str,
    /// The filter's final value and standard deviation.
    pub filter: f64,
    /// Its standard deviation.
    pub filter_std: f64,
    /// Identification's value.
    pub identified: f64,
    /// Its standard deviation.
    pub identified_std: f64,
    /// |filter - identified| / sqrt(filter_std^2 + identified_std^2).
    pub sigmas: f64,
}

/// Whether the filter's estimates and standard deviations can be trusted on this log.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Consistency {
    /// Mean normalised innovation squared over the second half (about 1 when consistent).
    pub nis_mean: f64,
    /// The constants compared with identification's (empty without identification).
    pub agreement: Vec<Agreement>,
    /// True when the NIS is inside [`NIS_RANGE`] and every constant agrees within
    /// [`AGREEMENT_SIGMAS`].
    pub consistent: bool,
    /// What is wrong, with the likely cause (empty when consistent).
    pub reasons: Vec<String>,
}

impl Consistency {
    /// Checks a run: its innovations against their predicted variance, and its final M, k2
    /// and d2 against identification's estimates of the same log. The two see the same data,
    /// so their difference has less spread than the root sum of squares used here: a
    /// disagreement beyond it is a real one.
    pub fn new(run: &EkfRun, id: Option<&Identification>) -> Consistency {
        use super::identify::Param;
        let mut reasons = Vec::new();
        let nis = run.nis_mean;
        if !(NIS_RANGE.0..=NIS_RANGE.1).contains(&nis) {
            reasons.push(format!(
                "the position innovations are {nis:.2} times their predicted variance (expected {} to {}): \
                 the filter's model does not match this log, so its standard deviations are not to be \
                 trusted",
                NIS_RANGE.0, NIS_RANGE.1
            ));
        }
        let mut agreement = Vec::new();
        if let Some(id) = id {
            let z = run.last.z;
            let sd = run.last.std();
            for (state, p) in [
                (ekf::idx::M, Param::M),
                (ekf::idx::K2, Param::K2),
                (ekf::idx::D2, Param::D2),
            ] {
                let e = id.get(p);
                let (Some(v), Some(s)) = (e.value, e.std) else {
                    continue;
                };
                let spread = (s * s + sd[state] * sd[state]).sqrt();
                let sigmas = (z[state] - v).abs() / spread.max(1e-300);
                agreement.push(Agreement {
                    state: ekf::STATE_NAMES[state],
                    filter: z[state],
                    filter_std: sd[state],
                    identified: v,
                    identified_std: s,
                    sigmas,
                });
            }
            let off: Vec<String> = agreement
                .iter()
                .filter(|a| a.sigmas > AGREEMENT_SIGMAS)
                .map(|a| format!("{} ({:.1} sigma)", a.state, a.sigmas))
                .collect();
            if !off.is_empty() {
                let d0 = id.get(Param::D0).value.unwrap_or(0.0).abs();
                let noise = id.residual_rms_n;
                let cause = if d0 > 5.0 * noise {
                    format!(
                        "the likely cause is Coulomb friction: d0 = {d0:.2} N is {:.0} times the force \
                         residual, and its step at each reversal, known only to a few samples, enters the \
                         filter through the force rate",
                        d0 / noise.max(1e-12)
                    )
                } else {
                    "the likely cause is an inertia or damping force too small for the filter to \
                     resolve at this noise, or a model the log does not follow"
                        .to_string()
                };
                reasons.push(format!(
                    "the filter's {} disagree with identification of the same log beyond {AGREEMENT_SIGMAS} \
                     standard deviations; {cause}; use identify's estimates",
                    off.join(", ")
                ));
            }
        }
        Consistency {
            nis_mean: nis,
            agreement,
            consistent: reasons.is_empty(),
            reasons,
        }
    }
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

/// How a log's encoder zero is corrected before it is used.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum PositionOffset {
    /// Used as logged.
    None,
    /// Subtracted from every position (mm): x = x_logged - offset.
    Mm(f64),
    /// Fitted against a designed law ([`fit_position_offset`]).
    Auto,
}

/// The encoder zero of a log against a designed law: the log is identified as logged, and
/// the identified law is matched to the designed one ([`fit_position_offset`]).
pub fn fit_offset_by_identification(
    log: &CalibrationLog,
    noise: &SensorNoise,
    designed: &ForceLaw,
) -> Result<f64, IdentifyError> {
    use super::identify::{identify, Param};
    let id = identify(log, noise)?;
    let value = |p| id.get(p).value;
    let measured = ExpLaw {
        mu_n: value(Param::Mu).unwrap_or(f64::NAN),
        k2_per_mm: value(Param::K2).unwrap_or(id.k2_quasi_static_per_mm),
        f0_n: value(Param::F0).unwrap_or(0.0),
    };
    if !measured.mu_n.is_finite() {
        return Err(IdentifyError::NoConvergence(
            "this log does not identify the spring's mu, so the encoder zero cannot be fitted; \
             give --position-offset LENGTH"
                .into(),
        ));
    }
    let (lo, hi) = log.position_range_mm();
    Ok(fit_position_offset(&measured, designed, lo, hi))
}

/// The encoder zero that best explains a measured spring law by a designed one: the shift c
/// (mm) that minimises the squared difference between the measured force F_m(x) and the
/// designed F_d(x - c) over the logged deflections `lo ..= hi`. A spring built right but logged
/// with its zero off by c shows exactly such a shift; a spring built wrong leaves a residual,
/// which the verdict then judges. The search covers shifts up to half the logged range.
pub fn fit_position_offset(
    measured: &ExpLaw,
    designed: &crate::model::ForceLaw,
    lo: f64,
    hi: f64,
) -> f64 {
    let span = (hi - lo).max(1e-9);
    let points: Vec<f64> = (0..=100).map(|i| lo + span * i as f64 / 100.0).collect();
    let cost = |c: f64| -> f64 {
        points
            .iter()
            .map(|&x| (measured.force_n(x) - designed.force_n(x - c)).powi(2))
            .sum()
    };
    // A coarse grid, then golden-section refinement around its best point.
    let half = 0.5 * span;
    let steps = 400;
    let mut best = (f64::INFINITY, 0.0);
    for i in 0..=steps {
        let c = -half + 2.0 * half * i as f64 / steps as f64;
        let v = cost(c);
        if v < best.0 {
            best = (v, c);
        }
    }
    let h = 2.0 * half / steps as f64;
    let (mut a, mut b) = (best.1 - h, best.1 + h);
    let g = 0.5 * (5f64.sqrt() - 1.0);
    for _ in 0..60 {
        let (c1, c2) = (b - g * (b - a), a + g * (b - a));
        if cost(c1) < cost(c2) {
            b = c2;
        } else {
            a = c1;
        }
    }
    0.5 * (a + b)
}
