//! Offline identification (paper section V): k2 by non-linear least squares, then
//! X = [m, d0, d1, d2, mu, F0] by weighted least squares (eqs. 16-18), then a joint refinement;
//! beyond the paper, a friction that grows with the spring's force, mu_f sgn(xd) exp(k2 x)
//! (a cam's contact friction), fitted and kept where the log shows it ([`LoadFriction`]).
//!
//! 1. Position, velocity and acceleration come from quintic Savitzky-Golay kernels with mutually
//!    uncorrelated noise ([`super::sg`]), over a window chosen from the data
//!    ([`super::window::choose_window`]).
//! 2. k2: Gauss-Newton with backtracking line search on F = mu*exp(k2 x) + F0 over the
//!    quasi-static samples (|xd| below 10 % of its maximum), started from the best of a
//!    log-spaced grid of k2 with (mu, F0) solved linearly for each.
//! 3. With k2 fixed, WLS on rows [xdd, sgn(xd), xd, xd^3, exp(k2 x), 1] (and
//!    sgn(xd) exp(k2 x) for mu_f) gives X and the
//!    paper's covariance (A^T R^-1 A)^-1. Each row's variance R is the force variance plus the
//!    filtered position noise carried through the model (stiffness, damping and inertia times
//!    the filtered noise of x, xd and xdd): effective-variance weights from the noise model.
//! 4. A joint weighted Gauss-Newton over all parameters (with line search) refines k2
//!    together with X.
//!
//! Where the log allows (a fine encoder: most moving samples have only moving samples within
//! the filter's reach), steps 3 and 4 regress through the parallel filter
//! ([`Regression::ParallelFilter`]): the force goes through the acceleration kernel's own
//! smoother, so the inertia force is filtered alike on both sides and m carries no filter
//! bias from the motion's corners. Elsewhere the regression is direct, and m is corrected for
//! the acceleration filter's loss of gain ([`correct_inertia`]).
//!
//! Samples whose filtered velocity is within three of its noise standard deviations of zero are
//! left out of steps 3 and 4: their friction sign is unknown (at rest, static friction is
//! anywhere in +-d0), and guessing it biases d0 and d1.
//!
//! Unresolved transients: a motion whose speed steps (a servo following a velocity command
//! with a lag of a few samples) puts the inertia force where the step is, while the filtered
//! acceleration spreads it over the window. Samples within half a window of a force residual
//! beyond [`TRANSIENT_SIGMAS`] standard deviations (at rest: beyond d0 by as much, since the
//! friction there is anywhere in +-d0) are left out and the fit repeated, when those residuals
//! raise the reduced chi-square by at least the window choice's tolerance
//! ([`super::window::CHI2_RISE_MIN`]) and half the moving samples remain.
//!
//! Reported standard deviations: the smoothed position noise makes neighbouring residuals
//! correlated over one filter window, so (A^T R^-1 A)^-1 is too optimistic (it assumes
//! independent rows). The reported covariance is the sandwich H^-1 S H^-1 with S summed from
//! the residual scores over lags up to one window (a truncated HAC estimate); it also carries
//! any model error. The paper's matrix is reported as well, for comparison.
//!
//! Poor excitation: the normal matrix is scaled to unit diagonal. While its smallest eigenvalue
//! is below [`IDENTIFIABILITY_LIMIT`] times the largest, the parameter dominating that
//! eigenvector is removed and reported as not identifiable, instead of printed as a number.
//!
//! Every fit is judged ([`super::adequacy`]): a reduced chi-square far from 1 or coloured
//! residuals make it "does not fit", never a clean-looking result.

use nalgebra::{DMatrix, DVector, SMatrix, SVector, SymmetricEigen};
use serde::Serialize;

pub use super::adequacy::{
    whiteness, Adequacy, FitStatus, Whiteness, MAX_REDUCED_CHI2, MIN_REDUCED_CHI2, WHITENESS_LAGS,
    WHITENESS_LEVEL,
};
use super::log::{CalibrationLog, MIN_LOG_SAMPLES};
use super::quantisation::{Quantisation, RowShares, SpeedShares, SHARE_KERNELS};
use super::sg::{self, Differentiator};
pub use super::window::{
    candidate_windows, choose_window, fit_with_noise_uncertainty, WindowCandidate, WindowChoice,
    WindowMethod, BALANCING_SIGMAS, CHI2_RISE_MIN, LONGEST_WINDOW_S, SHORTEST_WINDOW_S,
    SHORTEST_WINDOW_SAMPLES, WINDOW_RATIO,
};

/// Parameter names in model order (the JSON keys, with units).
pub const PARAMS: [&str; NP] = [
    "m_n_s2_per_mm",
    "d0_n",
    "d1_n_s_per_mm",
    "d2_n_s3_per_mm3",
    "mu_n",
    "f0_n",
    "k2_per_mm",
    "mu_f_n",
];

/// How many parameters the transmission model has.
pub const NP: usize = 8;

/// A parameter of the transmission model F = m xdd + (d0 + mu_f exp(k2 x)) sgn(xd) + d1 xd
/// + d2 xd^3 + mu exp(k2 x) + F0, in model order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub enum Param {
    /// Inertia m (N s^2/mm).
    M,
    /// Coulomb friction d0 (N).
    D0,
    /// Linear damping d1 (N s/mm).
    D1,
    /// Cubic damping d2 (N s^3/mm^3).
    D2,
    /// The law's coefficient mu (N).
    Mu,
    /// The law's offset F0 (N).
    F0,
    /// The law's exponent rate k2 (1/mm).
    K2,
    /// The friction that grows with the spring's force, mu_f exp(k2 x) sgn(xd) (N): a cam's
    /// contact friction, which is a share of the load the rollers carry (mu_f / mu of the
    /// spring's exponential part).
    MuF,
}

impl Param {
    /// Every parameter, in model order.
    pub const ALL: [Param; NP] = [
        Param::M,
        Param::D0,
        Param::D1,
        Param::D2,
        Param::Mu,
        Param::F0,
        Param::K2,
        Param::MuF,
    ];

    /// Position in the parameter vector.
    pub const fn index(self) -> usize {
        self as usize
    }

    /// The unit-bearing name (JSON key), e.g. `k2_per_mm`.
    pub fn key(self) -> &'static str {
        PARAMS[self.index()]
    }

    /// The parameter with this unit-bearing name.
    pub fn from_key(key: &str) -> Option<Param> {
        Param::ALL.into_iter().find(|p| p.key() == key)
    }
}

const M: usize = Param::M.index();
const D0: usize = Param::D0.index();
const D1: usize = Param::D1.index();
const D2: usize = Param::D2.index();
const MU: usize = Param::Mu.index();
const F0: usize = Param::F0.index();
const K2: usize = Param::K2.index();
const MUF: usize = Param::MuF.index();

/// The order in which [`prune`] gives up parameters that share a near-null direction:
/// mu_f, m, d0, d2, d1, then F0, mu, k2.
const DROP_ORDER: [usize; NP] = [MUF, M, D0, D2, D1, F0, MU, K2];

/// The dynamic parameters whose information can be mostly noise, in the order they are given
/// up: m, d2, d1.
const NOISY_ORDER: [usize; 3] = [M, D2, D1];

/// Smallest share of the information on m that must be signal rather than acceleration noise
/// for m to count as identifiable.
pub const MIN_INERTIA_SIGNAL_SHARE: f64 = 0.0;

/// A force residual this many standard deviations from the model marks a transient the window
/// does not resolve (over 30 000 rows of white noise, about 0.02 would pass it by chance).
pub const TRANSIENT_SIGMAS: f64 = 5.0;

/// How many times identification leaves out unresolved transients and fits again.
pub const TRANSIENT_ROUNDS: usize = 3;

/// Transients are left out only while at least this share of the moving samples remains: a
/// log that is mostly transients at a window is judged by its fit's adequacy instead.
pub const TRANSIENT_KEEP_SHARE: f64 = 0.5;

/// Share of the inertia's signal (the filtered acceleration's mean square beyond its noise,
/// over the moving samples) that must remain after transients are left out for m to be kept.
pub const INERTIA_KEEP_SHARE: f64 = 0.75;

/// Least share of the log's travel one way (summed over the moving samples) that its travel
/// the other way must reach for d0 to be fitted ([`identify`]). On the independent rig's random
/// sweep (256 logs), logs that reverse had 0.56 to 1; a force-controlled rod that slipped one
/// way only, in two slow slides, had 0.011: the filter's ringing at the slides' ends, whose
/// ten samples at rest put d0 at 1.97 +- 0.04 N against 3.45 (z -36).
pub const REVERSAL_TRAVEL_SHARE: f64 = 0.1;

/// A log's travel the way it moves less, as a share of its travel the way it moves more, from
/// the velocities (mm/s) of its moving samples: 1 for a log that goes and comes back as far,
/// 0 for one that moves one way only (and for no motion). Below [`REVERSAL_TRAVEL_SHARE`]
/// the outside friction is a constant on the one stroke logged.
pub fn reversal_travel_share(velocities: impl Iterator<Item = f64>) -> f64 {
    let (forward, back) =
        velocities.fold(
            (0.0, 0.0),
            |(f, b), v| {
                if v > 0.0 {
                    (f + v, b)
                } else {
                    (f, b - v)
                }
            },
        );
    let most = f64::max(forward, back);
    if most > 0.0 {
        f64::min(forward, back) / most
    } else {
        0.0
    }
}

/// Smallest eigenvalue, relative to the largest, of the unit-diagonal normal matrix for which
/// every parameter counts as identifiable (a condition number of 1e8).
pub const IDENTIFIABILITY_LIMIT: f64 = 1e-8;

/// Whether identification's model has the friction that grows with the spring's force,
/// mu_f sgn(xd) exp(k2 x) ([`Param::MuF`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum LoadFriction {
    /// Fitted, and kept where it is positive beyond [`LOAD_FRICTION_SIGMAS`] of its standard
    /// deviations; elsewhere the fit is made again without it
    /// ([`Identification::load_friction_left_out`]).
    #[default]
    Auto,
    /// Fitted whatever it comes to.
    Fitted,
    /// Not in the model: the paper's constant friction d0 alone.
    LeftOut,
}

/// How many of its standard deviations the friction that grows with the load must be above
/// zero for [`LoadFriction::Auto`] to keep it. Below, the log does not show it, and the
/// paper's model is fitted: a parameter that is zero within its noise only widens the
/// others', and one that comes out negative (the loading stroke below the unloading one,
/// which no friction does) is what a force read late looks like on a steady motion. Kept
/// there, it took up the delay: on the light transmission's sines read two samples late,
/// mu_f came out at -4.7 % of mu and the screen for a late force no longer found the delay.
pub const LOAD_FRICTION_SIGMAS: f64 = 3.0;

/// Sensor noise used for the weights.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SensorNoise {
    /// Force variance (N^2).
    pub force_variance_n2: f64,
    /// Position variance (mm^2).
    pub position_variance_mm2: f64,
    /// The position variance's relative standard deviation (0: known exactly). Beyond
    /// [`super::window::NOISE_UNCERTAINTY_MIN`] identification carries it into its estimates'
    /// standard deviations (`noise_std`).
    pub position_variance_relative_std: f64,
    /// The step of a position read in steps whose error is its noise, when the noise was read
    /// from the log: identification then weights its kernels' noise by what they pass of the
    /// step's sawtooth error at the log's speeds ([`super::quantisation`]), not by
    /// `position_variance_mm2`.
    #[serde(skip)]
    pub position_quantisation: Option<Quantisation>,
}

impl SensorNoise {
    /// Force and position variances known exactly.
    pub fn new(force_variance_n2: f64, position_variance_mm2: f64) -> SensorNoise {
        SensorNoise {
            force_variance_n2,
            position_variance_mm2,
            position_variance_relative_std: 0.0,
            position_quantisation: None,
        }
    }

    /// The same noise with the position's variance (and a quantised position's error power)
    /// multiplied by `factor`.
    pub fn position_scaled(&self, factor: f64) -> SensorNoise {
        SensorNoise {
            position_variance_mm2: self.position_variance_mm2 * factor,
            position_quantisation: self.position_quantisation.map(|q| Quantisation {
                variance_scale: q.variance_scale * factor,
                ..q
            }),
            ..*self
        }
    }
}

impl Default for SensorNoise {
    /// The paper's sensors: force 0.017 N^2, position 0.01 mm^2.
    fn default() -> Self {
        SensorNoise::new(0.017, 0.01)
    }
}

/// One identified parameter.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Estimate {
    /// Value (None when not identifiable from this log).
    pub value: Option<f64>,
    /// Standard deviation (sandwich covariance).
    pub std: Option<f64>,
}

impl Estimate {
    /// The estimate in words for a message: `0.11400 +- 0.00120 1/mm`, `0.11400 1/mm` without a
    /// standard deviation, or `not identified` where the log gave it up (never `NaN`).
    pub fn describe(&self, unit: &str) -> String {
        match (self.value, self.std) {
            (Some(v), Some(s)) => format!("{v:.5} +- {s:.5} {unit}"),
            (Some(v), None) => format!("{v:.5} {unit}"),
            (None, _) => "not identified".to_owned(),
        }
    }
}

/// The spring's curvature and exponential part as identification left them, for the messages
/// that say they are not resolved ([`spring_resolved`]): `k2 = ... 1/mm, mu = ... N`.
pub fn describe_spring(k2: &Estimate, mu: &Estimate) -> String {
    format!("k2 = {}, mu = {}", k2.describe("1/mm"), mu.describe("N"))
}

/// One estimate per parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimates([Estimate; NP]);

impl Estimates {
    /// Sets the standard deviation of `p` (the window choice adds the filter's bias).
    pub(super) fn set_std(&mut self, p: Param, std: f64) {
        self.0[p.index()].std = Some(std);
    }

    /// The estimate of `p`.
    pub fn get(&self, p: Param) -> Estimate {
        self.0[p.index()]
    }

    /// The value of `p`, when identifiable.
    pub fn value(&self, p: Param) -> Option<f64> {
        self.get(p).value
    }

    /// Each parameter with its estimate, in model order.
    pub fn iter(&self) -> impl Iterator<Item = (Param, Estimate)> + '_ {
        Param::ALL.into_iter().map(|p| (p, self.get(p)))
    }
}

impl Serialize for Estimates {
    /// A map from the unit-bearing key to `{value, std}`, in model order.
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut map = s.serialize_map(Some(NP))?;
        for (p, e) in self.iter() {
            map.serialize_entry(p.key(), &e)?;
        }
        map.end()
    }
}

/// The result of [`identify`].
#[derive(Debug, Clone, Serialize)]
pub struct Identification {
    /// Every parameter's estimate.
    pub parameters: Estimates,
    /// Where the rod stands at an end of the logged positions while the force moves on
    /// beyond the law and friction ([`PositionStop`]): the model does not fit such a log.
    pub position_stop: Option<PositionStop>,
    /// Parameters this log cannot identify.
    pub not_identifiable: Vec<String>,
    /// k2 from the quasi-static stage alone (1/mm).
    pub k2_quasi_static_per_mm: f64,
    /// Covariance of the identifiable parameters, in [`PARAMS`] order (sandwich estimate).
    pub covariance: Vec<Vec<f64>>,
    /// The paper's (A^T R^-1 A)^-1 with k2 fixed, for the identifiable ones of X = [m, d0, d1,
    /// d2, mu, F0] and mu_f where it is in the model (last).
    pub paper_covariance_k2_fixed: Vec<Vec<f64>>,
    /// Names of the rows and columns of [`Self::covariance`].
    pub covariance_parameters: Vec<String>,
    /// How [`Self::covariance`] was estimated.
    pub covariance_method: CovarianceMethod,
    /// Condition number of the unit-diagonal normal matrix of the final fit.
    pub condition_number: f64,
    /// Reduced chi-square of the final fit with the noise model's weights (about 1 when the
    /// noise model and the dynamic model are right).
    pub reduced_chi2: f64,
    /// RMS force residual (N).
    pub residual_rms_n: f64,
    /// The smallest share, over m, d1 and d2, of a parameter's information (its diagonal
    /// entry in the normal matrix) that is signal rather than the noise of its filtered
    /// regressor: near 1 when that noise is negligible, near 0 where the errors-in-variables
    /// correction removes almost all of it (and, being a first-order correction, is then not
    /// to be trusted).
    pub signal_share: f64,
    /// How the dynamic rows were regressed ([`Regression`]).
    pub regression: Regression,
    /// The acceleration filter's loss of gain over this log's motion, estimated from the data
    /// (`inertia_attenuation` in this module), with which m was corrected ([`correct_inertia`]); None where
    /// m is not fitted or the log does not determine it.
    pub inertia_attenuation: Option<f64>,
    /// Samples identified from: after block averaging to [`IDENTIFY_RATE_HZ`], and at most the
    /// first [`MAX_IDENTIFY_SAMPLES`].
    pub samples: usize,
    /// Samples in the log as read.
    pub log_samples: usize,
    /// Log samples averaged into each identified sample (1: none).
    pub block_samples: usize,
    /// Samples used in the dynamic fit.
    pub dynamic_samples: usize,
    /// Moving samples left out of the dynamic fit as unresolved transients: within half a
    /// window of a force residual beyond [`TRANSIENT_SIGMAS`] standard deviations (a motion
    /// that changes faster than the window resolves, or a glitch in the log).
    pub transient_samples: usize,
    /// The reduced chi-square before unresolved transients were left out (equal to
    /// [`Self::reduced_chi2`] when none were): how well this window's filter follows the
    /// whole motion, which the window choice compares.
    pub reduced_chi2_with_transients: f64,
    /// The log's top speed, from its smoothed motion velocity (mm/s).
    pub speed_max_mm_per_s: f64,
    /// Quasi-static samples used for the k2 stage.
    pub quasi_static_samples: usize,
    /// Savitzky-Golay window (samples).
    pub sg_window: usize,
    /// Savitzky-Golay window (s).
    pub sg_window_s: f64,
    /// How the window was chosen, with the windows tried.
    pub window_choice: WindowChoice,
    /// Whether the model explains this log: reduced chi-square and residual whiteness.
    pub adequacy: Adequacy,
    /// Parameters with signs no transmission has, and the sensor likely read reversed
    /// (`judge_signs` in this module); the fit then does not fit.
    pub sign_fault: Option<SignFault>,
    /// The filter's estimated bias in each parameter, in model order, already included in the
    /// standard deviations (zero when the window was given, or none was seen).
    pub filter_bias_std: [f64; NP],
    /// What the position noise's uncertainty does to each parameter, in model order, already
    /// included in the standard deviations (zero when the noise is known well enough,
    /// [`super::window::NOISE_UNCERTAINTY_MIN`]).
    pub noise_std: [f64; NP],
    /// How much the reduced chi-square rises with the position variance one standard
    /// deviation higher (0 when the noise is known well enough): the window choice allows
    /// for it when it compares windows' reduced chi-squares.
    pub reduced_chi2_noise_change: f64,
    /// The friction that grows with the load as the fit with it gave it, where
    /// [`LoadFriction::Auto`] then left it out (not positive beyond [`LOAD_FRICTION_SIGMAS`]
    /// of its standard deviations); None where it is in the model or was never fitted.
    pub load_friction_left_out: Option<Estimate>,
}

/// Share of its value beyond which a k2's standard deviation no longer bounds it.
pub const K2_RESOLVED_SHARE: f64 = 0.5;

/// Whether a log resolves k2: positive, with a standard deviation at most
/// [`K2_RESOLVED_SHARE`] of it (a k2 without a standard deviation is judged as it is). Where the
/// log hardly fixes the spring's curvature, the fit's linearised deviation no longer bounds
/// the estimate: on the independent rig's multisine of a heavy transmission (m 0.46 N s^2/mm)
/// at four times the paper's noise, identification found k2 = -0.008 +- 0.028 /mm against
/// 0.163 (z -6.2), and validate failed the true law on it (k2 71 % beyond two of those
/// deviations) while the force curve passed. identify warns of an unresolved k2, and validate
/// does not judge it: it cannot fail, and the pass is not shown.
pub fn k2_resolved(k2: f64, k2_std: f64) -> bool {
    !k2_std.is_finite() || (k2 > 0.0 && k2_std <= K2_RESOLVED_SHARE * k2)
}

/// Whether an identification resolves the spring's curvature: its k2 is resolved
/// ([`k2_resolved`]), and so is the exponential part that k2 shapes, mu positive with a
/// standard deviation at most its value. A fit whose mu the log cannot tell from zero has no
/// exponential to take a curvature from: on the independent rig's sweep draw 103 (a
/// force-controlled rod that slides one way, 2.5 % of its samples moving, 31 % of the stroke)
/// the fit put mu at 0.00034 +- 0.0014 N against 1.28 and k2 at 0.61 +- 0.27 /mm against 0.114,
/// a sharp rise at the stroke's end.
pub fn spring_resolved(id: &Identification) -> bool {
    let (k2, mu) = (id.get(Param::K2), id.get(Param::Mu));
    let k2_ok = match (k2.value, k2.std) {
        (Some(v), Some(s)) => k2_resolved(v, s),
        (Some(_), None) => true,
        (None, _) => false,
    };
    let mu_ok = match (mu.value, mu.std) {
        (Some(v), Some(s)) => v > 0.0 && (!s.is_finite() || s <= v),
        (Some(v), None) => v > 0.0,
        (None, _) => false,
    };
    k2_ok && mu_ok
}

/// The precision the calibration of a spring law aims at: k2 within 0.5 % and mu within
/// 1.5 %, each at two standard deviations (95 %).
pub const TARGET_PRECISION: [(Param, f64); 2] = [(Param::K2, 0.005), (Param::Mu, 0.015)];

impl Identification {
    /// The model this identification settled on: [`LoadFriction::Fitted`] where the friction
    /// that grows with the load is in it, [`LoadFriction::LeftOut`] elsewhere. Fits of the same
    /// log re-timed or simulated again (a delay's profile, the twins) use the same model.
    pub fn load_friction(&self) -> LoadFriction {
        if self.get(Param::MuF).value.is_some() {
            LoadFriction::Fitted
        } else {
            LoadFriction::LeftOut
        }
    }

    /// The law parameters whose two standard deviations exceed [`TARGET_PRECISION`], each
    /// with its relative standard deviation and how many times longer a log of the same kind
    /// would have to be to reach the target (the variance falls as 1 / duration).
    pub fn imprecise(&self) -> Vec<(Param, f64, f64)> {
        TARGET_PRECISION
            .iter()
            .filter_map(|&(p, target)| {
                let e = self.get(p);
                let rel = e.std? / e.value?.abs().max(1e-300);
                (2.0 * rel > target).then(|| (p, rel, (2.0 * rel / target).powi(2)))
            })
            .collect()
    }

    /// The estimate of a parameter.
    pub fn get(&self, p: Param) -> Estimate {
        self.parameters.get(p)
    }
}

/// How identification regresses the force on the dynamic samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Regression {
    /// The force at each sample against the filtered acceleration, velocity and position
    /// there. The acceleration filter smooths the motion's corners (a jerk's steps, a long
    /// window on sines) while the force keeps them, so m comes out high by the filter's
    /// loss of gain, which is then corrected to first order (`inertia_attenuation`).
    Direct,
    /// The parallel filter (IDIM's "parallel filtering"). The filtered acceleration is the
    /// smoother Q ([`acceleration_smoother`]) applied to the second difference over two
    /// samples, which is exactly the acceleration's mean under a triangle two samples wide
    /// each side; on the samples the three-sample mean T has the same weight and spread (and
    /// is exact at a corner on a sample). So the force goes through Q after T, and every
    /// other column with it: the velocity's as Q applied to central differences (the
    /// velocity's mean over two samples), the spring's as Q applied to
    /// exp(k2 x) (1 + dt^2/3 (k2 xdd + k2^2 xd^2)), whose second factor is T's effect. The
    /// inertia force has then been through the same filter on both sides, and m carries no
    /// filter bias. A row's filter must reach only moving samples (a rest's or a turn's
    /// friction is unknown), so this is used where at least [`PARALLEL_MIN_SHARE`] of the
    /// moving samples qualify.
    ParallelFilter,
}

/// Why identification failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IdentifyError {
    /// Produced by [`super::retime::fit_force_delay`] when the fit keeps improving up to the
    /// edge of its search.
    #[error(
        "the fit keeps improving as the force is re-timed up to the search's limit of \
         {limit_s:.3} s either way: the force channel's delay lies beyond it, or the model does \
         not fit this log for another reason; give the delay with --force-delay, e.g. 0.3s"
    )]
    ForceDelayBeyondSearch {
        /// The search's limit (s).
        limit_s: f64,
    },
    /// Produced by [`super::retime::fit_force_delay`] on a log too short to fit the delay.
    #[error(
        "a log of {log_s:.1} s is too short to fit the force channel's delay (at least \
         {min_s:.1} s: ten filter windows, and forty times the delays searched either way); \
         give it with --force-delay, e.g. 5ms, or record a longer run"
    )]
    ForceDelayLogTooShort {
        /// The log's length (s).
        log_s: f64,
        /// The least length (s).
        min_s: f64,
    },
    /// Produced by [`super::retime::fit_force_delay`] when the fit's chi-square does not
    /// curve upward about its least value: the log does not determine the delay.
    #[error(
        "the fit hardly changes as the force is re-timed (with the filter window at \
         {window_s:.3} s): this log does not determine the force channel's delay; give it \
         with --force-delay, e.g. 5ms as the rig's data sheet states, or leave it out"
    )]
    ForceDelayUndetermined {
        /// The filter window the profile held (s).
        window_s: f64,
    },
    /// Produced by [`identify`] when the log does not move the spring enough.
    #[error(
        "the filtered position varies by only {range_mm:.4} mm (position noise {noise_mm:.4} mm): this log \
         does not excite the spring, so k2, mu and F0 cannot be identified; record a run over the stroke"
    )]
    NoExcitation {
        /// Range of the filtered position.
        range_mm: f64,
        /// Position noise standard deviation.
        noise_mm: f64,
    },
    /// Produced by [`identify`] when too few samples move clearly.
    #[error(
        "only {found} samples move faster than the velocity noise ({band_mm_s:.4} mm/s, through a \
         {window_s} s Savitzky-Golay window); at least {needed} are needed for the dynamic fit: \
         record a run with more motion, or (with --window) a longer window, whose velocity is less \
         noisy"
    )]
    TooLittleMotion {
        /// Moving samples.
        found: usize,
        /// Needed.
        needed: usize,
        /// The velocity band (mm/s).
        band_mm_s: f64,
        /// The smoothing window (s) whose velocity noise sets the band.
        window_s: f64,
    },
    /// Produced by [`identify_with_window`] for a window too short for the smoothing filter.
    #[error(
        "--window {window_s} s is {samples:.1} samples at this log's {rate_hz} Hz; the \
         Savitzky-Golay filter needs at least {min} samples, so give --window {min_s} s or more \
         (or leave it out for the default)"
    )]
    WindowTooShort {
        /// The window asked.
        window_s: f64,
        /// In samples.
        samples: f64,
        /// The log's rate.
        rate_hz: f64,
        /// Fewest samples.
        min: usize,
        /// Shortest window for this log (s).
        min_s: f64,
    },
    /// Produced by [`identify`] when the log is shorter than the filter window.
    #[error(
        "the log has {found} samples; the {window}-sample filter window (--window) needs at \
         least {needed}: record a longer run or give a shorter --window"
    )]
    TooShort {
        /// Samples.
        found: usize,
        /// Window.
        window: usize,
        /// Needed.
        needed: usize,
    },
    /// Produced by [`identify`] when Gauss-Newton cannot reduce the residual.
    #[error("the non-linear fit did not converge ({0})")]
    NoConvergence(String),
}

struct Rows {
    /// Sample index of each row (for residual correlation).
    index: Vec<usize>,
    x: Vec<f64>,
    xd: Vec<f64>,
    xdd: Vec<f64>,
    /// The force: at the sample, or through the parallel filter ([`Filtered`]).
    f: Vec<f64>,
    /// The friction sign: at the sample, or through the parallel filter.
    sgn: Vec<f64>,
    /// The position's, velocity's and acceleration's noise variances, of white noise where
    /// the position is read in steps (each row's own share in `shares`).
    var_x: f64,
    var_xd: f64,
    var_xdd: f64,
    var_f: f64,
    /// The parallel filter's columns, when the rows went through it.
    filtered: Option<Filtered>,
    /// A position read in steps: what each row's kernels pass of the steps' error, as shares
    /// of white noise's, in the order of [`share_kernels`].
    shares: Option<RowShares>,
}

/// The share column of the parallel filter's velocity in [`Rows::shares`] (after the four
/// kernels of [`sg::Differentiator`] identification uses).
const PARALLEL_SHARE: usize = 4;

/// Rows through the parallel filter ([`Parallel`]): the velocity columns filtered, and the
/// exponential's filtered column as moments about a k2.
struct Filtered {
    /// The filtered velocity regressor.
    xd: Vec<f64>,
    /// The filtered unbiased cube of the velocity ([`unbiased_cube`]).
    cube: Vec<f64>,
    /// sum_j q_j c_j d_j^k exp(k2_ref d_j), k = 0, 1, 2 ([`exp_moments`]).
    moments: [Vec<f64>; 3],
    /// The same with the friction's sign at each tap: sum_j q_j c_j s_j d_j^k exp(k2_ref d_j).
    signed_moments: [Vec<f64>; 3],
    /// The k2 the moments were summed at.
    k2_ref: f64,
    /// Noise variance of the filtered velocity column.
    var_xd: f64,
    /// The filtered cube's noise of second and third order ([`CubeNoise`]).
    cube_noise: CubeNoise,
}

/// The noise of the filtered unbiased cube C = sum_j q_j c_j, c_j = o_j^3 - 3 o_j s2, beyond
/// its part linear in the noise (which is 3 v^2 times the filtered velocity's). Each c_j is
/// v^3 + 3 v^2 H1 + 3 v H2 + H3 in the Hermite polynomials of the difference's noise d_j
/// (variance s2), and for jointly Gaussian d_j, d_k of covariance c_jk,
/// E[Ha(d_j) Hb(d_k)] = [a = b] a! c_jk^a. So var(C) = 9 v^4 var_o + 18 v^2 `second` + 6
/// `third`, with `second` = sum_jk q_j q_k c_jk^2 and `third` = sum_jk q_j q_k c_jk^3.
/// Neighbouring taps of the parallel filter's central differences share a sample, with
/// correlation -1/2, so neither is var_o times s2 or s2^2: through a smooth filter var_o
/// nearly cancels while these do not (2026-11-28: on a 1 kHz trapezoid log that scaling left
/// d2 shrunk to 1 % of the truth, at z +39).
#[derive(Debug, Clone, Copy, PartialEq)]
struct CubeNoise {
    second: f64,
    third: f64,
}

impl CubeNoise {
    /// The cube's higher-order noise through `taps` (consecutive samples, centred), whose
    /// inputs are central differences of noise variance `s2`: correlation -1/2 two samples
    /// apart, none otherwise.
    fn through_differences(taps: &[f64], s2: f64) -> CubeNoise {
        let (mut second, mut third) = (0.0, 0.0);
        for (j, &a) in taps.iter().enumerate() {
            second += a * a;
            third += a * a;
            if let Some(&b) = taps.get(j + 2) {
                // Both orders of the pair: 2 a b rho^2 and 2 a b rho^3, rho = -1/2.
                second += 0.5 * a * b;
                third -= 0.25 * a * b;
            }
        }
        CubeNoise {
            second: second * s2 * s2,
            third: third * s2 * s2 * s2,
        }
    }

    /// The variance of the cube's noise beyond its linear part, at velocity squared `v2`,
    /// where the differences' noise is `scale` times the variance it was summed for (its
    /// second and third orders scale as its square and cube).
    fn variance(&self, v2: f64, scale: f64) -> f64 {
        18.0 * v2 * self.second * scale * scale + 6.0 * self.third * scale * scale * scale
    }
}

impl Rows {
    /// Row `i`'s share of the steps' error through kernel column `k` (1 without steps).
    fn share(&self, i: usize, k: usize) -> f64 {
        self.shares.as_ref().map_or(1.0, |s| s.share(i, k))
    }

    /// Noise variance of row `i`'s position (through the parallel filter, where it went).
    fn var_x_at(&self, i: usize) -> f64 {
        let k = if self.filtered.is_some() {
            PARALLEL_SHARE
        } else {
            sg::POSITION
        };
        self.var_x * self.share(i, k)
    }

    /// Noise variance of row `i`'s velocity column (the filtered one, where the rows went
    /// through the parallel filter).
    fn var_xd_at(&self, i: usize) -> f64 {
        match &self.filtered {
            Some(q) => q.var_xd * self.share(i, PARALLEL_SHARE),
            None => self.var_xd * self.share(i, sg::VELOCITY),
        }
    }

    /// Noise variance of row `i`'s acceleration.
    fn var_xdd_at(&self, i: usize) -> f64 {
        self.var_xdd * self.share(i, sg::ACCELERATION)
    }

    /// The filtered cube's noise beyond its linear part at row `i` ([`CubeNoise`]).
    fn cube_noise_at(&self, i: usize, q: &Filtered, v2: f64) -> f64 {
        q.cube_noise.variance(v2, self.share(i, PARALLEL_SHARE))
    }

    fn subset(&self, keep: &[usize], dynamic: bool) -> Rows {
        let pick = |v: &Vec<f64>| keep.iter().map(|&i| v[i]).collect::<Vec<f64>>();
        let zero = vec![0.0; keep.len()];
        Rows {
            index: keep.iter().map(|&i| self.index[i]).collect(),
            x: pick(&self.x),
            xd: if dynamic {
                pick(&self.xd)
            } else {
                zero.clone()
            },
            xdd: if dynamic {
                pick(&self.xdd)
            } else {
                zero.clone()
            },
            f: pick(&self.f),
            sgn: if dynamic { pick(&self.sgn) } else { zero },
            var_x: self.var_x,
            var_xd: if dynamic { self.var_xd } else { 0.0 },
            var_xdd: if dynamic { self.var_xdd } else { 0.0 },
            var_f: self.var_f,
            filtered: None,
            shares: self.shares.as_ref().map(|s| s.pick(keep)),
        }
    }

    /// The rows at the samples `keep` of these (every sample's) rows through the parallel
    /// filter, the exponential's moments summed at `k2`.
    fn parallel(&self, keep: &[usize], par: &Parallel, k2: f64) -> Rows {
        let pick = |v: &Vec<f64>| keep.iter().map(|&i| v[i]).collect::<Vec<f64>>();
        let index: Vec<usize> = keep.iter().map(|&i| self.index[i]).collect();
        let [moments, signed_moments] = exp_moments(self, par, &index, k2);
        Rows {
            index,
            x: pick(&self.x),
            xd: pick(&self.xd),
            xdd: pick(&self.xdd),
            f: pick(&par.f),
            sgn: pick(&par.sgn),
            var_x: par.var_x,
            var_xd: self.var_xd,
            var_xdd: self.var_xdd,
            var_f: par.var_f,
            filtered: Some(Filtered {
                xd: pick(&par.xd),
                cube: pick(&par.cube),
                moments,
                signed_moments,
                k2_ref: k2,
                var_xd: par.var_xd,
                cube_noise: par.cube_noise,
            }),
            shares: self.shares.as_ref().map(|s| s.pick(keep)),
        }
    }

    /// Sums the exponential's moments again at `k2` (`all`: every sample's rows).
    fn refresh_moments(&mut self, all: &Rows, par: &Parallel, k2: f64) {
        if let Some(f) = self.filtered.as_mut() {
            [f.moments, f.signed_moments] = exp_moments(all, par, &self.index, k2);
            f.k2_ref = k2;
        }
    }
}

/// The parallel filter over every sample: the force, the friction sign and the velocity
/// columns through it, and their noise variances (see [`fit_model`]).
struct Parallel {
    /// Q's weights (every second sample, centred: [`acceleration_smoother`]).
    q: Vec<f64>,
    /// dt^2 / 3: the three-sample mean's curvature term.
    curvature: f64,
    f: Vec<f64>,
    sgn: Vec<f64>,
    xd: Vec<f64>,
    cube: Vec<f64>,
    /// Noise variance of the filtered position (through the exponential's column).
    var_x: f64,
    /// Noise variance of the filtered force.
    var_f: f64,
    /// Noise variance of the filtered velocity.
    var_xd: f64,
    /// The filtered cube's noise of second and third order.
    cube_noise: CubeNoise,
}

/// The filter `kernel` (consecutive samples, centred) applied to `y`: NaN within its half
/// width of either end.
fn parallel_filter(kernel: &[f64], y: &[f64]) -> Vec<f64> {
    let half = kernel.len() / 2;
    let n = y.len();
    (0..n)
        .map(|s| {
            if s < half || s + half >= n {
                return f64::NAN;
            }
            kernel
                .iter()
                .zip(&y[s - half..=s + half])
                .map(|(k, v)| k * v)
                .sum()
        })
        .collect()
}

/// The parallel filter's exponential column at each sample s of `index`: the moments
/// sum_j q_j c_j d_j^k exp(k2 d_j), k = 0, 1, 2, with d_j = x(t_j) - x(s) at Q's taps
/// t_j = s + 2 j - 2 (len(q) / 2) and c_j = 1 + dt^2/3 (k2 xdd(t_j) + k2^2 xd(t_j)^2), the
/// three-sample mean's curvature term of exp(k2 x) (NaN within Q's reach of either end).
/// Q applied to exp(k2' x) is then exp(k2' x(s)) times their Taylor sum in k2' - k2. The
/// second set is the friction's column sgn(xd) exp(k2 x) alike: each tap weighted by the
/// three-sample mean of the friction's sign around it.
fn exp_moments(all: &Rows, par: &Parallel, index: &[usize], k2: f64) -> [[Vec<f64>; 3]; 2] {
    let reach = 2 * (par.q.len() / 2);
    let x = &all.x;
    let column = || {
        [
            Vec::with_capacity(index.len()),
            Vec::with_capacity(index.len()),
            Vec::with_capacity(index.len()),
        ]
    };
    let (mut out, mut signed) = (column(), column());
    for &s in index {
        let (mut m0, mut m1, mut m2) = (f64::NAN, f64::NAN, f64::NAN);
        let (mut s0, mut s1, mut s2) = (f64::NAN, f64::NAN, f64::NAN);
        if s >= reach && s + reach < x.len() {
            (m0, m1, m2) = (0.0, 0.0, 0.0);
            (s0, s1, s2) = (0.0, 0.0, 0.0);
            for (j, qj) in par.q.iter().enumerate() {
                let t = s + 2 * j - reach;
                let d = x[t] - x[s];
                let c = 1.0 + par.curvature * k2 * (all.xdd[t] + k2 * all.xd[t] * all.xd[t]);
                let w = qj * c * (k2 * d).exp();
                m0 += w;
                m1 += w * d;
                m2 += w * d * d;
                let before = all.sgn[t.saturating_sub(1)];
                let after = all.sgn[(t + 1).min(x.len() - 1)];
                let ws = w * (before + all.sgn[t] + after) / 3.0;
                s0 += ws;
                s1 += ws * d;
                s2 += ws * d * d;
            }
        }
        for (column, v) in out.iter_mut().zip([m0, m1, m2]) {
            column.push(v);
        }
        for (column, v) in signed.iter_mut().zip([s0, s1, s2]) {
            column.push(v);
        }
    }
    [out, signed]
}

type Vp = SVector<f64, NP>;
type Mp = SMatrix<f64, NP, NP>;
type Active = [bool; NP];

/// Model force and Jacobian row for parameters p = [m, d0, d1, d2, mu, F0, k2, mu_f].
fn model(p: &Vp, r: &Rows, i: usize) -> (f64, Vp) {
    model_at(p, r, i, (p[K2] * r.x[i]).exp())
}

/// [`model`] given the row's `at_row` = exp(k2 x).
fn model_at(p: &Vp, r: &Rows, i: usize, at_row: f64) -> (f64, Vp) {
    let (xd, xd3, e, e_signed, k2_column) = match &r.filtered {
        None => {
            let signed = r.sgn[i] * at_row;
            (
                r.xd[i],
                unbiased_cube(r.xd[i], r.var_xd_at(i)),
                at_row,
                signed,
                (p[MU] * at_row + p[MUF] * signed) * r.x[i],
            )
        }
        Some(q) => {
            // The filtered exp(k2 x) = exp(k2 x_row) sum_j q_j c_j exp(k2 d_j): a Taylor sum
            // in k2 - k2_ref, exact at k2_ref (the fit sums the moments again where it ends).
            // The friction's part, sgn(xd) exp(k2 x), alike with the sign at each tap.
            let d = p[K2] - q.k2_ref;
            let taylor = |m: &[Vec<f64>; 3]| {
                let [m0, m1, m2] = [m[0][i], m[1][i], m[2][i]];
                (m0 + d * (m1 + 0.5 * d * m2), m1 + d * m2)
            };
            let (sum, slope) = taylor(&q.moments);
            let (signed_sum, signed_slope) = taylor(&q.signed_moments);
            (
                q.xd[i],
                q.cube[i],
                at_row * sum,
                at_row * signed_sum,
                at_row
                    * (p[MU] * (r.x[i] * sum + slope)
                        + p[MUF] * (r.x[i] * signed_sum + signed_slope)),
            )
        }
    };
    let row = Vp::from([r.xdd[i], r.sgn[i], xd, xd3, e, 1.0, k2_column, e_signed]);
    let f = p[M] * r.xdd[i]
        + p[D0] * r.sgn[i]
        + p[D1] * xd
        + p[D2] * xd3
        + p[MU] * e
        + p[F0]
        + p[MUF] * e_signed;
    (f, row)
}

/// Effective variance of a row's force residual at parameters p.
fn row_variance(p: &Vp, r: &Rows, i: usize) -> f64 {
    row_variance_at(p, r, i, (p[K2] * r.x[i]).exp())
}

/// [`row_variance`] given the row's `at_row` = exp(k2 x).
fn row_variance_at(p: &Vp, r: &Rows, i: usize, at_row: f64) -> f64 {
    let stiffness = p[K2] * (p[MU] + p[MUF] * r.sgn[i]) * at_row;
    let damping = p[D1] + 3.0 * p[D2] * r.xd[i] * r.xd[i];
    let var_xd = r.var_xd_at(i);
    let linear = r.var_f
        + stiffness * stiffness * r.var_x_at(i)
        + damping * damping * var_xd
        + p[M] * p[M] * r.var_xdd_at(i);
    // Through the parallel filter the cube's noise of higher order does not cancel with the
    // filter, as its linear part does ([`CubeNoise`]).
    match &r.filtered {
        Some(q) => {
            let v2 = (q.xd[i] * q.xd[i] - var_xd).max(0.0);
            linear + p[D2] * p[D2] * r.cube_noise_at(i, q, v2)
        }
        None => linear,
    }
}

fn weights_at(p: &Vp, r: &Rows) -> Vec<f64> {
    (0..r.f.len())
        .map(|i| 1.0 / row_variance(p, r, i).max(1e-300))
        .collect()
}

fn masked(mut row: Vp, active: &Active) -> Vp {
    for k in 0..NP {
        if !active[k] {
            row[k] = 0.0;
        }
    }
    row
}

/// An unbiased estimate of v^3 from a noisy o = v + e with var(e) = s2: o^3 - 3 o s2.
pub(crate) fn unbiased_cube(o: f64, s2: f64) -> f64 {
    o * o * o - 3.0 * o * s2
}

/// The noise part of one row's normal-matrix contribution J^T J, over the regressors with
/// noise: xdd (for m; noise var_xdd, uncorrelated with the others, see [`super::sg`]) and the
/// velocity columns xd and xd^3 (the latter as [`unbiased_cube`]). For o = v + e with
/// Gaussian e of variance s2, E[o^2] = v^2 + s2, E[o c3] = v^4 + 3 v^2 s2 and
/// E[c3^2] = v^6 + 9 v^4 s2 + 18 v^2 s2^2 + 6 s2^3, where c3 = o^3 - 3 o s2; the
/// powers of v are replaced by their unbiased estimates from o.
fn row_correction(r: &Rows, i: usize, active: &Active) -> Mp {
    let mut c = Mp::zeros();
    if active[M] {
        c[(M, M)] = r.var_xdd_at(i);
    }
    // The velocity column o and its noise variance. Directly, o is the velocity kernel's
    // output and the cube is taken of it, so the single-sample moments above hold. Through
    // the parallel filter o is Q applied to central differences (to first order in the
    // noise, the velocity nearly constant over the filter, the linear terms are the filtered
    // variance's), and the cube's higher-order terms are summed over Q's correlated taps
    // ([`CubeNoise`]).
    let var_o = r.var_xd_at(i);
    let o = match &r.filtered {
        Some(q) => q.xd[i],
        None => r.xd[i],
    };
    if var_o > 0.0 {
        let o2 = o * o;
        let v2 = o2 - var_o;
        let v4 = o2 * o2 - 6.0 * o2 * var_o + 3.0 * var_o * var_o;
        if active[D1] {
            c[(D1, D1)] = var_o;
        }
        if active[D1] && active[D2] {
            c[(D1, D2)] = 3.0 * v2 * var_o;
            c[(D2, D1)] = c[(D1, D2)];
        }
        if active[D2] {
            c[(D2, D2)] = match &r.filtered {
                Some(q) => 9.0 * v4 * var_o + r.cube_noise_at(i, q, v2),
                // (In this order the direct rows' sum is the one it always was, to the last
                // bit.)
                None => {
                    let s2 = var_o;
                    9.0 * v4 * var_o + 18.0 * v2 * s2 * s2 + 6.0 * s2 * s2 * s2
                }
            };
        }
    }
    c
}

/// The entries of the normal matrix [`row_correction`] can fill (the one below the diagonal
/// is mirrored once the sums are done).
const CORRECTED_ENTRIES: [(usize, usize); 4] = [(M, M), (D1, D1), (D1, D2), (D2, D2)];

/// The noise part C = sum_i w_i C_i of the normal matrix.
fn correction(r: &Rows, active: &Active, weights: &[f64]) -> Mp {
    let mut c = Mp::zeros();
    for (i, &w) in weights.iter().enumerate() {
        let ci = row_correction(r, i, active);
        for (a, b) in CORRECTED_ENTRIES {
            c[(a, b)] += ci[(a, b)] * w;
        }
    }
    c[(D2, D1)] = c[(D1, D2)];
    c
}

/// Removes what this log cannot identify: parameters in near-null directions of the normal
/// matrix ([`prune`]) and, while the noise-corrected normal matrix is not positive definite,
/// the noise-corrected parameters in the order m, d2, d1 (their information is noise at this
/// filter window). A parameter whose corrected information is positive is kept, however
/// noisy: removing a force the log carries would bias the others.
fn prune_all(p: &mut Vp, r: &Rows, active: &mut Active, weights: &[f64]) -> Vec<String> {
    let c = correction(r, active, weights);
    let (jtj, _, _) = normal_with(p, r, active, weights, &c);
    let mut removed = prune(&(jtj + c), active);
    for k in NOISY_ORDER {
        let (jtj, _, _) = normal(p, r, active, weights);
        if scaled(&jtj, active).cholesky().is_some() {
            break;
        }
        if active[k] {
            active[k] = false;
            removed.push(PARAMS[k].to_string());
        }
    }
    drop_inactive(p, active);
    removed
}

/// Corrected normal equations over the active parameters: (J^T W J - C, J^T W r + C p) and
/// the corrected objective chi^2 - p^T C p, where C = sum_i w_i C_i ([`row_correction`]).
///
/// The filtered acceleration and velocity carry noise of known variance; plain least squares
/// would attenuate m by var(xdd) / (var(xdd) + noise) and bias d1 and d2 (errors in
/// variables). Subtracting the noise part of the normal matrix (corrected least squares,
/// Fuller 1987) removes that bias.
fn normal(p: &Vp, r: &Rows, active: &Active, weights: &[f64]) -> (Mp, Vp, f64) {
    normal_with(p, r, active, weights, &correction(r, active, weights))
}

/// [`normal`] with its noise part `c` (= `correction(r, active, weights)`) given: it depends
/// on the weights and the active set only, not on the parameters.
fn normal_with(p: &Vp, r: &Rows, active: &Active, weights: &[f64], c: &Mp) -> (Mp, Vp, f64) {
    let mut jtj = Mp::zeros();
    let mut jtr = Vp::zeros();
    let mut chi2 = 0.0;
    for (i, &w) in weights.iter().enumerate() {
        let (f, row) = model(p, r, i);
        let row = masked(row, active);
        let res = r.f[i] - f;
        // The upper triangle of row row^T w, mirrored below once the sums are done.
        for b in 0..NP {
            for a in 0..=b {
                jtj[(a, b)] += row[a] * row[b] * w;
            }
        }
        jtr += row * (w * res);
        chi2 += w * res * res;
    }
    jtj.fill_lower_triangle_with_upper_triangle();
    let cp = c * p;
    (jtj - c, jtr + cp, chi2 - p.dot(&cp))
}

/// The corrected objective of [`normal_with`] alone (the line search needs no matrix); the
/// same sums in the same order, so the same number.
fn objective(p: &Vp, r: &Rows, weights: &[f64], c: &Mp) -> f64 {
    let mut chi2 = 0.0;
    for (i, &w) in weights.iter().enumerate() {
        let (f, _) = model(p, r, i);
        let res = r.f[i] - f;
        chi2 += w * res * res;
    }
    chi2 - p.dot(&(c * p))
}

/// Gauss-Newton's sums at one point, from one pass over the rows ([`gauss_newton_pass`]).
struct GaussNewtonPass {
    /// [`weights_at`] the point.
    weights: Vec<f64>,
    /// [`correction`] at those weights.
    c: Mp,
    /// The corrected normal matrix of [`normal_with`] at those weights.
    jtj: Mp,
    /// Its right-hand side.
    jtr: Vp,
    /// Its corrected objective.
    chi2: f64,
}

/// [`weights_at`] `p`, then [`correction`] and [`normal_with`] at those weights: one pass
/// over the rows with exp(k2 x) taken once per row, where the functions apart take it twice.
/// Each sum runs over the rows in the same order with the same operations as the functions
/// apart, so the numbers are theirs to the last bit.
fn gauss_newton_pass(p: &Vp, r: &Rows, active: &Active) -> GaussNewtonPass {
    let n = r.f.len();
    let mut weights = Vec::with_capacity(n);
    let mut c = Mp::zeros();
    let mut jtj = Mp::zeros();
    let mut jtr = Vp::zeros();
    let mut chi2 = 0.0;
    for i in 0..n {
        let at_row = (p[K2] * r.x[i]).exp();
        let w = 1.0 / row_variance_at(p, r, i, at_row).max(1e-300);
        weights.push(w);
        let ci = row_correction(r, i, active);
        for (a, b) in CORRECTED_ENTRIES {
            c[(a, b)] += ci[(a, b)] * w;
        }
        let (f, row) = model_at(p, r, i, at_row);
        let res = r.f[i] - f;
        let row = masked(row, active);
        for b in 0..NP {
            for a in 0..=b {
                jtj[(a, b)] += row[a] * row[b] * w;
            }
        }
        jtr += row * (w * res);
        chi2 += w * res * res;
    }
    c[(D2, D1)] = c[(D1, D2)];
    jtj.fill_lower_triangle_with_upper_triangle();
    let cp = c * p;
    GaussNewtonPass {
        weights,
        jtj: jtj - c,
        jtr: jtr + cp,
        chi2: chi2 - p.dot(&cp),
        c,
    }
}

/// Indices of the active parameters and the square roots of their diagonal entries.
fn scaling(jtj: &Mp, active: &Active) -> (Vec<usize>, Vec<f64>) {
    let idx: Vec<usize> = (0..NP).filter(|&k| active[k]).collect();
    let d = idx
        .iter()
        .map(|&k| jtj[(k, k)].max(1e-300).sqrt())
        .collect();
    (idx, d)
}

/// The eigen-decomposition of a symmetric matrix, or None for an empty one or one with a
/// non-finite entry (nalgebra panics on the first and may not converge on the second).
fn eigen(m: DMatrix<f64>) -> Option<SymmetricEigen<f64, nalgebra::Dyn>> {
    (m.nrows() > 0 && m.iter().all(|v| v.is_finite()))
        .then(|| SymmetricEigen::new(m))
        .filter(|e| e.eigenvalues.iter().all(|v| v.is_finite()))
}

/// The eigenvalues of a symmetric matrix, as [`eigen`].
fn eigenvalues(m: DMatrix<f64>) -> Option<DVector<f64>> {
    eigen(m).map(|e| e.eigenvalues)
}

/// The normal matrix (or a covariance) over the active set, scaled to unit diagonal.
fn scaled(jtj: &Mp, active: &Active) -> DMatrix<f64> {
    let (idx, d) = scaling(jtj, active);
    DMatrix::from_fn(idx.len(), idx.len(), |a, b| {
        jtj[(idx[a], idx[b])] / (d[a] * d[b])
    })
}

/// Solves J^T W J dp = J^T W r over the active set.
fn solve(jtj: &Mp, jtr: &Vp, active: &Active) -> Option<Vp> {
    let (idx, d) = scaling(jtj, active);
    let b = DVector::from_iterator(idx.len(), idx.iter().zip(&d).map(|(&k, dk)| jtr[k] / dk));
    let sol = scaled(jtj, active).cholesky()?.solve(&b);
    let mut dp = Vp::zeros();
    for (a, &k) in idx.iter().enumerate() {
        dp[k] = sol[a] / d[a];
    }
    Some(dp)
}

/// (J^T W J)^-1 over the active set (zeros elsewhere).
fn inverse(jtj: &Mp, active: &Active) -> Option<Mp> {
    let (idx, d) = scaling(jtj, active);
    let inv = scaled(jtj, active).cholesky()?.inverse();
    let mut c = Mp::zeros();
    for a in 0..idx.len() {
        for b in 0..idx.len() {
            c[(idx[a], idx[b])] = inv[(a, b)] / (d[a] * d[b]);
        }
    }
    Some(c)
}

/// Removes, one at a time, the parameters that dominate near-null directions of the scaled
/// normal matrix. Returns the names removed.
fn prune(jtj: &Mp, active: &mut Active) -> Vec<String> {
    let mut removed = Vec::new();
    while active.iter().any(|a| *a) {
        let (idx, _) = scaling(jtj, active);
        let Some(eig) = eigen(scaled(jtj, active)) else {
            break;
        };
        let (imin, lmin) =
            eig.eigenvalues
                .iter()
                .enumerate()
                .fold(
                    (0, f64::INFINITY),
                    |m, (i, &l)| if l < m.1 { (i, l) } else { m },
                );
        let lmax = eig.eigenvalues.iter().cloned().fold(0.0, f64::max);
        if lmin > IDENTIFIABILITY_LIMIT * lmax && lmin > 0.0 {
            break;
        }
        // Of the parameters that make up the near-null direction (at least half the largest
        // component), drop the dynamic ones before the spring's: with a friction sign that never
        // changes, d0 and F0 are the same column, and F0 is the one worth keeping.
        let v = eig.eigenvectors.column(imin);
        let vmax = v.iter().fold(0.0_f64, |m, c| m.max(c.abs()));
        let k = DROP_ORDER
            .iter()
            .copied()
            .find(|&k| {
                idx.iter()
                    .position(|&i| i == k)
                    .is_some_and(|a| v[a].abs() >= 0.5 * vmax)
            })
            .unwrap_or(idx[0]);
        active[k] = false;
        removed.push(PARAMS[k].to_string());
    }
    removed
}

/// Zeroes the terms of X that were removed from the model (k2 keeps its last value).
fn drop_inactive(p: &mut Vp, active: &Active) {
    for k in 0..NP {
        if k != K2 && !active[k] {
            p[k] = 0.0;
        }
    }
}

/// Weighted Gauss-Newton with backtracking line search; weights follow the parameters.
/// A normal matrix that loses definiteness on the way (the corrected matrix of a barely
/// excited parameter) removes that parameter, reported in the returned list.
fn gauss_newton(
    mut p: Vp,
    r: &Rows,
    active: &mut Active,
    iterations: usize,
) -> Result<(Vp, Vec<String>), IdentifyError> {
    let mut at = gauss_newton_pass(&p, r, active);
    let mut removed = Vec::new();
    for _ in 0..iterations {
        let Some(dp) = solve(&at.jtj, &at.jtr, active) else {
            // A structural null direction first; otherwise the corrected matrix lost
            // definiteness through a noise-corrected column: m, then d2, then d1.
            let mut dropped = prune(&(at.jtj + at.c), active);
            if dropped.is_empty() {
                if let Some(k) = NOISY_ORDER.into_iter().find(|&k| active[k]) {
                    active[k] = false;
                    dropped.push(PARAMS[k].to_string());
                }
            }
            if dropped.is_empty() {
                return Err(IdentifyError::NoConvergence(
                    "singular normal matrix".into(),
                ));
            }
            removed.extend(dropped);
            drop_inactive(&mut p, active);
            // The weights are kept; the noise part and the sums follow the active set.
            at.c = correction(r, active, &at.weights);
            (at.jtj, at.jtr, at.chi2) = normal_with(&p, r, active, &at.weights, &at.c);
            continue;
        };
        // Converged when the full step would lower chi-square by less than 1e-8: far below
        // any change in the estimates that their standard deviations could show.
        if at.jtr.dot(&dp) < 1e-8 {
            break;
        }
        // Steps are judged by the objective alone (a pass's sums would be lost on a step not
        // taken: a sticking rod's fits halve the step often).
        let mut step = 1.0;
        let mut improved = None;
        for _ in 0..40 {
            let trial = p + dp * step;
            let c2 = objective(&trial, r, &at.weights, &at.c);
            if c2.is_finite() && c2 <= at.chi2 {
                improved = Some((trial, c2));
                break;
            }
            step *= 0.5;
        }
        // No descent along the Gauss-Newton direction: at the minimum within rounding.
        let Some((trial, c2)) = improved else {
            break;
        };
        let rel = (at.chi2 - c2) / at.chi2.max(1e-300);
        p = trial;
        at = gauss_newton_pass(&p, r, active);
        if rel < 1e-12 && step == 1.0 {
            break;
        }
    }
    if p.iter().all(|v| v.is_finite()) {
        Ok((p, removed))
    } else {
        Err(IdentifyError::NoConvergence("non-finite parameters".into()))
    }
}

/// How the reported covariance was estimated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum CovarianceMethod {
    /// Sandwich with residual correlations up to one filter window (the normal case).
    Truncated,
    /// Sandwich with Bartlett weights over two windows (when the truncated one is not
    /// positive definite).
    Bartlett,
    /// (J^T W J)^-1 times the reduced chi-square (too few samples for either sandwich):
    /// optimistic, because it ignores the correlation of neighbouring residuals.
    Model,
}

/// Whether a covariance is positive definite over the active set, judged on its correlation
/// matrix: the parameters' variances span many decades (mu's may be 1e-25 N^2 where m's is
/// 1e2), and the unscaled matrix's smallest eigenvalue is then below the rounding of its
/// largest, its sign noise. On an independent rig's stick-slip log a rounding change in the
/// kernels turned the Bartlett covariance (m -2.66 +- 8.7) into the model's (+- 0.52, which
/// ignores the residuals' correlation).
fn positive_definite(c: &Mp, active: &Active) -> bool {
    let (idx, _) = scaling(c, active);
    idx.iter().all(|&k| c[(k, k)] > 0.0)
        && eigenvalues(scaled(c, active)).is_some_and(|e| e.iter().all(|&l| l > 0.0))
}

/// Sandwich covariance H^-1 S H^-1, S summed from the residual scores g_i over all pairs of
/// samples at most `lag` apart (a truncated HAC estimate, computed in O(n) with a sliding sum
/// of the scores). If that is not positive definite, Bartlett weights over twice the lag
/// (O(n lag)); if that fails too, the model covariance.
fn sandwich(
    p: &Vp,
    r: &Rows,
    active: &Active,
    weights: &[f64],
    lag: usize,
) -> Option<(Mp, CovarianceMethod)> {
    let (jtj, _, _) = normal(p, r, active, weights);
    let hinv = inverse(&jtj, active)?;
    let scores: Vec<Vp> = (0..r.f.len())
        .map(|i| {
            let (f, row) = model(p, r, i);
            (masked(row, active) * (r.f[i] - f) + row_correction(r, i, active) * p) * weights[i]
        })
        .collect();
    // Truncated kernel: S = sum_i g_i (sum_{|t_j - t_i| <= lag} g_j)^T.
    let mut truncated = Mp::zeros();
    let (mut lo, mut hi) = (0usize, 0usize);
    let mut window = Vp::zeros();
    for i in 0..scores.len() {
        while hi < scores.len() && r.index[hi] <= r.index[i] + lag {
            window += scores[hi];
            hi += 1;
        }
        while r.index[lo] + lag < r.index[i] {
            window -= scores[lo];
            lo += 1;
        }
        truncated += scores[i] * window.transpose();
    }
    let truncated = (truncated + truncated.transpose()) * 0.5;
    let positive = |c: &Mp| positive_definite(c, active);
    let cov = hinv * truncated * hinv;
    if positive(&cov) {
        return Some((cov, CovarianceMethod::Truncated));
    }
    // Bartlett: S = sum_i g_i g_i^T + sum_i (g_i u_i^T + u_i g_i^T), where u_i is the
    // Bartlett-weighted sum of the later scores within the lag (one vector sum per pair
    // instead of one outer product).
    let mut bartlett = Mp::zeros();
    let wide = 2 * lag;
    for i in 0..scores.len() {
        let mut later = Vp::zeros();
        for (score, index) in scores[i + 1..].iter().zip(&r.index[i + 1..]) {
            let l = index - r.index[i];
            if l > wide {
                break;
            }
            later += score * (1.0 - l as f64 / (wide + 1) as f64);
        }
        let c = scores[i] * later.transpose();
        bartlett += scores[i] * scores[i].transpose() + c + c.transpose();
    }
    let cov = hinv * bartlett * hinv;
    if positive(&cov) {
        return Some((cov, CovarianceMethod::Bartlett));
    }
    // Too few samples for either: the model's covariance, scaled by the reduced chi-square.
    let (_, _, chi2) = normal(p, r, active, weights);
    let dof = (r.f.len() as f64 - active.iter().filter(|a| **a).count() as f64).max(1.0);
    let cov = hinv * (chi2 / dof).max(1.0);
    positive(&cov).then_some((cov, CovarianceMethod::Model))
}

/// The most samples identification uses, after block averaging to [`IDENTIFY_RATE_HZ`]: the
/// first ones of a longer log (about 5.8 hours at 100 Hz). Its work and memory are then bounded
/// whatever the log's length (about 0.4 GB at most); `samples` in the result says how many
/// were used.
pub const MAX_IDENTIFY_SAMPLES: usize = 1 << 21;

/// Logs sampled faster than twice this rate are block-averaged to between it and twice it
/// before identification (Hz).
pub const IDENTIFY_RATE_HZ: f64 = 100.0;

/// Identifies the transmission parameters from a calibration log, with the Savitzky-Golay
/// window chosen from the data ([`choose_window`]).
pub fn identify(
    log: &CalibrationLog,
    noise: &SensorNoise,
) -> Result<Identification, IdentifyError> {
    identify_with_window(log, noise, None)
}

/// [`identify`] with the Savitzky-Golay window given in seconds (odd number of samples, at
/// least [`sg::MIN_WINDOW`]), or chosen from the data when `None` ([`choose_window`]).
pub fn identify_with_window(
    log: &CalibrationLog,
    noise: &SensorNoise,
    window_s: Option<f64>,
) -> Result<Identification, IdentifyError> {
    if log.len() < MIN_LOG_SAMPLES {
        return identify_samples(log, noise, window_s, LoadFriction::Auto);
    }
    let block = block_for_interval(log.dt_s());
    if block == 1 && log.len() <= MAX_IDENTIFY_SAMPLES {
        let mut id = identify_samples(log, noise, window_s, LoadFriction::Auto)?;
        id.log_samples = log.len();
        id.block_samples = 1;
        return Ok(id);
    }
    let mut reduction = Reduction::with_block(block, MAX_IDENTIFY_SAMPLES);
    for i in 0..log.len() {
        reduction.push(super::log::Sample {
            t_s: log.t_s[i],
            force_n: log.force_n[i],
            position_mm: log.position_mm[i],
        });
    }
    identify_reduced(&reduction.finish(), noise, window_s)
}

/// The block of samples averaged into one for identification at a sampling interval `dt_s`:
/// logs sampled faster than [`IDENTIFY_RATE_HZ`] are brought down to between it and twice it.
pub fn block_for_interval(dt_s: f64) -> usize {
    ((1.0 / dt_s) / IDENTIFY_RATE_HZ).floor().clamp(1.0, 1e6) as usize
}

/// The samples identification uses, gathered as a log is read: block means of
/// [`block_for_interval`] samples (white noise averages to its variance over the block size,
/// and the motion lies far below [`IDENTIFY_RATE_HZ`]), and only the first `max_blocks` of
/// them. Its memory is bounded whatever the log's length.
#[derive(Debug, Clone)]
pub struct Reduction {
    block: usize,
    max_blocks: usize,
    first: Option<super::log::Sample>,
    sum: [f64; 3],
    in_block: usize,
    log: CalibrationLog,
    log_samples: usize,
}

/// A log reduced for identification ([`Reduction`]).
#[derive(Debug, Clone)]
pub struct ReducedLog {
    /// The block means.
    pub log: CalibrationLog,
    /// Samples per block.
    pub block: usize,
    /// Samples in the whole log.
    pub log_samples: usize,
}

impl Reduction {
    /// A reduction whose block is set by the log's first sampling interval.
    pub fn new(max_blocks: usize) -> Reduction {
        Reduction::with_block(0, max_blocks)
    }

    /// A log held in memory reduced as it would be read ([`Reduction::new`], at most
    /// [`MAX_IDENTIFY_SAMPLES`] blocks).
    pub fn of_log(log: &CalibrationLog) -> ReducedLog {
        let mut reduction = Reduction::new(MAX_IDENTIFY_SAMPLES);
        for i in 0..log.len() {
            reduction.push(super::log::Sample {
                t_s: log.t_s[i],
                force_n: log.force_n[i],
                position_mm: log.position_mm[i],
            });
        }
        reduction.finish()
    }

    /// A reduction over blocks of `block` samples (0: set by the first interval).
    pub fn with_block(block: usize, max_blocks: usize) -> Reduction {
        Reduction {
            block,
            max_blocks,
            first: None,
            sum: [0.0; 3],
            in_block: 0,
            log: CalibrationLog::default(),
            log_samples: 0,
        }
    }

    /// Adds the next sample of the log.
    pub fn push(&mut self, s: super::log::Sample) {
        self.log_samples += 1;
        if self.block == 0 {
            match self.first {
                None => {
                    self.first = Some(s);
                    return;
                }
                Some(f) => {
                    self.block = block_for_interval(s.t_s - f.t_s);
                    self.first = None;
                    self.add(f);
                }
            }
        }
        self.add(s);
    }

    fn add(&mut self, s: super::log::Sample) {
        if self.log.len() >= self.max_blocks {
            return;
        }
        self.sum[0] += s.t_s;
        self.sum[1] += s.force_n;
        self.sum[2] += s.position_mm;
        self.in_block += 1;
        if self.in_block == self.block {
            let b = self.block as f64;
            self.log.t_s.push(self.sum[0] / b);
            self.log.force_n.push(self.sum[1] / b);
            self.log.position_mm.push(self.sum[2] / b);
            self.sum = [0.0; 3];
            self.in_block = 0;
        }
    }

    /// The reduced log (a partial last block is left out).
    pub fn finish(mut self) -> ReducedLog {
        if let Some(f) = self.first.take() {
            self.block = 1;
            self.add(f);
        }
        ReducedLog {
            log: self.log,
            block: self.block.max(1),
            log_samples: self.log_samples,
        }
    }
}

/// Identification on a log reduced by [`Reduction`]: the sensor noise of the log's samples is
/// brought to that of the block means, and the result says how many samples the log had and
/// how many were averaged into each.
pub fn identify_reduced(
    reduced: &ReducedLog,
    noise: &SensorNoise,
    window_s: Option<f64>,
) -> Result<Identification, IdentifyError> {
    identify_reduced_with(reduced, noise, window_s, LoadFriction::Auto)
}

/// [`identify_reduced`] with the friction that grows with the load fitted, left out or
/// decided from the log ([`LoadFriction`]).
pub fn identify_reduced_with(
    reduced: &ReducedLog,
    noise: &SensorNoise,
    window_s: Option<f64>,
    load_friction: LoadFriction,
) -> Result<Identification, IdentifyError> {
    let b = reduced.block as f64;
    let block_noise = SensorNoise {
        force_variance_n2: noise.force_variance_n2 / b,
        position_variance_mm2: noise.position_variance_mm2 / b,
        position_quantisation: noise.position_quantisation.map(|q| Quantisation {
            block: q.block.max(1) * reduced.block,
            ..q
        }),
        ..*noise
    };
    let mut id = identify_samples(&reduced.log, &block_noise, window_s, load_friction)?;
    id.log_samples = reduced.log_samples;
    id.block_samples = reduced.block;
    Ok(id)
}

/// Identification on every sample of `log` as it is, then, where the log resolves no spring
/// and shows no sign fault, the same log with its position read the other way
/// ([`judge_mirrored`]).
fn identify_samples(
    log: &CalibrationLog,
    noise: &SensorNoise,
    window_s: Option<f64>,
    load_friction: LoadFriction,
) -> Result<Identification, IdentifyError> {
    let mut id = identify_samples_as_read(log, noise, window_s, load_friction)?;
    if id.sign_fault.is_none() && !spring_resolved(&id) {
        judge_mirrored(&mut id, log, noise, window_s, load_friction);
    }
    Ok(id)
}

/// Marks a fit that resolves no spring as not fitting where the log, its position read the
/// other way, fits one: a rising spring, mu and k2 each beyond [`IMPOSSIBLE_SIGMAS`] of their
/// standard deviations, and the model fitting. An encoder that counts the other way turns the
/// spring's force into one that falls as the position rises, which the exponential law with
/// a positive k2 cannot follow. The fit then drops mu and k2 as not identifiable and the
/// inertia and damping swell until their noise covers the spring's force, so the reduced
/// chi-square looks right: on a simulated default sines log read that way, a residual of
/// 83.5 N RMS on a force noise of 0.13 N was "fitted" at 1.02, with k2 and mu "not
/// identifiable (poor excitation)", and exit 0. The sign fault found by [`judge_signs`] needs
/// a resolved falling spring, which that fit never reaches.
fn judge_mirrored(
    id: &mut Identification,
    log: &CalibrationLog,
    noise: &SensorNoise,
    window_s: Option<f64>,
    load_friction: LoadFriction,
) {
    let mirrored = CalibrationLog {
        position_mm: log.position_mm.iter().map(|x| -x).collect(),
        ..log.clone()
    };
    let Ok(other) = identify_samples_as_read(&mirrored, noise, window_s, load_friction) else {
        return;
    };
    let beyond = |p: Param| {
        let e = other.get(p);
        matches!((e.value, e.std), (Some(v), Some(s)) if v > IMPOSSIBLE_SIGMAS * s.max(0.0))
    };
    if other.adequacy.status != FitStatus::Fits
        || !spring_resolved(&other)
        || !beyond(Param::Mu)
        || !beyond(Param::K2)
    {
        return;
    }
    let fault = SignFault {
        found: vec![format!(
            "a spring force that falls as it extends (no rising spring fits the log as read; \
             read with its position the other way, it fits one: k2 = {:.5} 1/mm, mu = {:.4} N, \
             reduced chi-square {:.2})",
            other.get(Param::K2).value.unwrap_or(f64::NAN),
            other.get(Param::Mu).value.unwrap_or(f64::NAN),
            other.reduced_chi2
        )],
        likely: ReversedSensor::Encoder,
    };
    id.adequacy.status = FitStatus::DoesNotFit;
    id.adequacy.reasons.push(fault.to_string());
    id.sign_fault = Some(fault);
}

/// Identification on every sample of `log` as it is.
fn identify_samples_as_read(
    log: &CalibrationLog,
    noise: &SensorNoise,
    window_s: Option<f64>,
    load_friction: LoadFriction,
) -> Result<Identification, IdentifyError> {
    if log.len() < MIN_LOG_SAMPLES {
        return Err(IdentifyError::TooShort {
            found: log.len(),
            window: sg::MIN_WINDOW,
            needed: 4 * sg::MIN_WINDOW,
        });
    }
    let dt = log.dt_s();
    let Some(w) = window_s else {
        let mut id = choose_window(log, noise, load_friction)?;
        correct_inertia(&mut id);
        judge_signs(&mut id, log);
        return Ok(id);
    };
    if w / dt < sg::MIN_WINDOW as f64 {
        return Err(IdentifyError::WindowTooShort {
            window_s: w,
            samples: w / dt,
            rate_hz: 1.0 / dt,
            min: sg::MIN_WINDOW,
            min_s: sg::MIN_WINDOW as f64 * dt,
        });
    }
    let samples = ((w / dt).round().clamp(0.0, 1e6) as usize) | 1;
    let mut id =
        fit_with_noise_uncertainty(log, noise, &Differentiator::new(samples), load_friction)?;
    id.window_choice = WindowChoice {
        method: WindowMethod::Given,
        candidates: Vec::new(),
    };
    correct_inertia(&mut id);
    judge_signs(&mut id, log);
    Ok(id)
}

/// How many standard deviations below zero an inertia or a viscous damping, or a stiffness of
/// the wrong sign, must be for identification to call it impossible ([`SignFault`]).
pub const IMPOSSIBLE_SIGMAS: f64 = 5.0;

/// The sensor that a fit with impossible signs likely read reversed, if either did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ReversedSensor {
    /// The force is negative on average: a load cell read with the opposite sign.
    LoadCell,
    /// The force rises as the position falls: an encoder that counts the other way.
    Encoder,
    /// Neither: the fitted spring force rises as it extends, which a reversed encoder would
    /// have turned, and the force is positive. The negative inertia or damping comes from
    /// motion the model does not describe.
    Neither,
}

/// A fit with parameters no transmission has: a negative inertia m or damping d1, or a spring
/// force that falls as it extends, each beyond [`IMPOSSIBLE_SIGMAS`], and its likely cause.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SignFault {
    /// What is impossible: `negative inertia m`, `negative damping d1`, `spring force that
    /// falls as it extends`.
    pub found: Vec<String>,
    /// The sensor likely read reversed.
    pub likely: ReversedSensor,
}

impl std::fmt::Display for SignFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let found = match self.found.split_last() {
            Some((last, [])) => last.clone(),
            Some((last, rest)) => format!("{} and {last}", rest.join(", ")),
            None => String::new(),
        };
        write!(f, "the fit has {found}, which no transmission has; ")?;
        match self.likely {
            ReversedSensor::LoadCell => write!(
                f,
                "the force is negative on average, so the likely cause is a load cell read with \
                 the opposite sign: give the force column a negative unit, --force NAME:-N"
            ),
            ReversedSensor::Encoder => write!(
                f,
                "the likely cause is an encoder that counts the other way (the force rises as \
                 the position falls): give the position column a negative unit, --position \
                 NAME:-mm (and --position-offset auto where its zero is then unknown)"
            ),
            ReversedSensor::Neither => write!(
                f,
                "the fitted spring force rises as it extends, so neither sensor reads reversed; \
                 the model does not describe this log's motion (likely causes: friction that \
                 holds the rod where the log never shows it sliding, or force and position \
                 sampled at different times); record a run that moves over the stroke, or \
                 check the channels' timing (--force-delay auto fits a load cell read after \
                 the encoder and re-times it)"
            ),
        }
    }
}

/// Marks a fit whose parameters no transmission can have as not fitting, with the likely
/// cause ([`SignFault`]): a negative inertia m, a negative viscous damping d1, or a spring
/// whose force falls as it extends (mu k2 < 0), each beyond [`IMPOSSIBLE_SIGMAS`]. The fit
/// itself may explain the log perfectly: a load cell or an encoder that counts the other way
/// turns every force term's sign, so the law is fitted with all of them reversed.
fn judge_signs(id: &mut Identification, log: &CalibrationLog) {
    let below = |p: Param| {
        let e = id.get(p);
        matches!((e.value, e.std), (Some(v), Some(s)) if v < -IMPOSSIBLE_SIGMAS * s)
    };
    let resolved = |p: Param| {
        let e = id.get(p);
        matches!((e.value, e.std), (Some(v), Some(s)) if v.abs() > IMPOSSIBLE_SIGMAS * s)
    };
    let (mu, k2) = (id.get(Param::Mu).value, id.get(Param::K2).value);
    let falling_spring = resolved(Param::Mu)
        && resolved(Param::K2)
        && mu.zip(k2).is_some_and(|(mu, k2)| mu * k2 < 0.0);
    let mut found = Vec::new();
    if below(Param::M) {
        found.push("a negative inertia m".to_string());
    }
    if below(Param::D1) {
        found.push("a negative damping d1".to_string());
    }
    if falling_spring {
        found.push("a spring force that falls as it extends (mu k2 < 0)".to_string());
    }
    if found.is_empty() {
        return;
    }
    let mean_force = log.force_n.iter().sum::<f64>() / log.force_n.len().max(1) as f64;
    // A reversed encoder turns the spring too: its fitted force falls as the position rises.
    // A fit whose spring rises (even one the log resolves poorly) read the encoder right.
    let spring_rises = mu.zip(k2).is_some_and(|(mu, k2)| mu * k2 > 0.0);
    let fault = SignFault {
        found,
        likely: if mean_force < 0.0 {
            ReversedSensor::LoadCell
        } else if spring_rises {
            ReversedSensor::Neither
        } else {
            ReversedSensor::Encoder
        },
    };
    id.adequacy.status = FitStatus::DoesNotFit;
    id.adequacy.reasons.push(fault.to_string());
    id.sign_fault = Some(fault);
}

/// The identification at one Savitzky-Golay window.
pub(super) fn fit(
    log: &CalibrationLog,
    noise: &SensorNoise,
    diff: &Differentiator,
    load_friction: LoadFriction,
) -> Result<Identification, IdentifyError> {
    fit_model(log, noise, diff, Inertia::Fitted, load_friction)
}

/// Whether a fit estimates the inertia m.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Inertia {
    /// m is estimated (unless the log cannot identify it).
    Fitted,
    /// m is left out, as not identifiable: the window choice's refit where m's information
    /// at this window is mostly the filtered acceleration's noise.
    LeftOut,
}

/// The identification at one Savitzky-Golay window, with or without the inertia.
///
/// Through the parallel filter where the log allows it ([`Regression::ParallelFilter`]), unless
/// the direct regression resolves more: its velocity columns come from central differences,
/// whose cube is far noisier than the velocity kernel's, so where the log's damper is cubic the
/// parallel fit can lose d2's information to noise. Where the parallel filter qualifies, the
/// direct regression is fitted too, and taken where it gives up fewer parameters, or as few
/// and its information is mostly signal ([`super::window::MIN_SIGNAL_SHARE`]) where the
/// parallel fit's is not. (2026-11-28: on a 1 kHz trapezoid log of a cubic damper, with the
/// cube's noise counted right ([`CubeNoise`]), the parallel fit's share was 0.21 at 0.61 s and
/// it kept neither m nor d2 at any window; the direct one identified all seven there, each
/// within 1.1 standard deviations.)
pub(super) fn fit_model(
    log: &CalibrationLog,
    noise: &SensorNoise,
    diff: &Differentiator,
    inertia: Inertia,
    load_friction: LoadFriction,
) -> Result<Identification, IdentifyError> {
    let fit = fit_regression(log, noise, diff, inertia, true, load_friction)?;
    if fit.regression != Regression::ParallelFilter {
        return Ok(fit);
    }
    let Ok(direct) = fit_regression(log, noise, diff, inertia, false, load_friction) else {
        return Ok(fit);
    };
    let resolves = |id: &Identification| {
        (
            std::cmp::Reverse(id.not_identifiable.len()),
            id.signal_share >= super::window::MIN_SIGNAL_SHARE,
        )
    };
    // The direct regression is taken for its signal share alone only where it explains the
    // log about as well: its velocity kernel rounds a servo's velocity steps, which the
    // parallel filter does not, and a direct fit whose reduced chi-square rises beyond the
    // window choice's tolerance is distorted. (On two servo logs read by 12.6 and 18.8 um
    // encoders, the parallel fit's share fell just below the threshold, and the direct fit,
    // its reduced chi-square 9 and 13 % higher, had d0, d1 and d2 8 to 10 deviations off.)
    let distorted = direct.reduced_chi2_with_transients
        > fit.reduced_chi2_with_transients
            * (1.0 + super::window::chi2_rise_tolerance(direct.dynamic_samples));
    let more_identified = direct.not_identifiable.len() < fit.not_identifiable.len();
    Ok(
        if resolves(&direct) > resolves(&fit) && (more_identified || !distorted) {
            direct
        } else {
            fit
        },
    )
}

/// [`fit_model`] through the parallel filter where the log allows it and `parallel_allowed`,
/// else directly. Where the fit finds the rod against a stop ([`position_stop`]), the samples
/// at that end ([`PositionStop::from_mm`] on) are left out and the law fitted again; where
/// that fails, the first fit is returned as not fitting the log.
fn fit_regression(
    log: &CalibrationLog,
    noise: &SensorNoise,
    diff: &Differentiator,
    inertia: Inertia,
    parallel_allowed: bool,
    load_friction: LoadFriction,
) -> Result<Identification, IdentifyError> {
    let first = fit_regression_beyond(
        log,
        noise,
        diff,
        inertia,
        parallel_allowed,
        None,
        load_friction,
    )?;
    let Some(stop) = first.position_stop else {
        return Ok(first);
    };
    match fit_regression_beyond(
        log,
        noise,
        diff,
        inertia,
        parallel_allowed,
        Some(&stop),
        load_friction,
    ) {
        Ok(mut refit) => {
            refit.position_stop = Some(stop);
            Ok(refit)
        }
        Err(e) => {
            let mut first = first;
            first.adequacy.status = FitStatus::DoesNotFit;
            first
                .adequacy
                .reasons
                .insert(0, format!("{}; fitted without them, {e}", stop.reason()));
            Ok(first)
        }
    }
}

/// [`fit_regression`], with the samples from a stop's [`PositionStop::from_mm`] on left out
/// (`stop`).
fn fit_regression_beyond(
    log: &CalibrationLog,
    noise: &SensorNoise,
    diff: &Differentiator,
    inertia: Inertia,
    parallel_allowed: bool,
    stop: Option<&PositionStop>,
    load_friction: LoadFriction,
) -> Result<Identification, IdentifyError> {
    let dt = log.dt_s();
    let h = diff.half;
    if log.len() < 4 * diff.window() {
        return Err(IdentifyError::TooShort {
            found: log.len(),
            window: diff.window(),
            needed: 4 * diff.window(),
        });
    }
    let [x, xd, xdd, motion]: [Vec<f64>; 4] = diff
        .apply_each(
            &log.position_mm,
            dt,
            &[
                sg::POSITION,
                sg::VELOCITY,
                sg::ACCELERATION,
                sg::MOTION_VELOCITY,
            ],
        )
        .try_into()
        .expect("one output per kernel");
    let n = x.len();
    let f = log.force_n[h..h + n].to_vec();
    // A position read in steps: each kernel's noise is what it passes of the steps' error at
    // each row's speed, not white noise's ([`RowShares`]); the rows' variances are white
    // noise's, times their shares. Which samples move is judged against the motion
    // velocity's mean share over the rows beyond its band ([`row_shares`]).
    let (variance_of, parallel_noise, shares) = match noise.position_quantisation {
        Some(q) => {
            let white_band = 3.0
                * diff
                    .noise_variance(sg::MOTION_VELOCITY, noise.position_variance_mm2, dt)
                    .sqrt();
            let (rows, motion_share) = row_shares(log, diff, q, &motion, white_band);
            let white = q.white_variance_mm2();
            let parallel = SensorNoise {
                position_variance_mm2: white,
                ..*noise
            };
            (
                [white, white, white, white * motion_share],
                parallel,
                Some(rows),
            )
        }
        None => ([noise.position_variance_mm2; 4], *noise, None),
    };
    let var_x = diff.noise_variance(sg::POSITION, variance_of[sg::POSITION], dt);
    let var_xd = diff.noise_variance(sg::VELOCITY, variance_of[sg::VELOCITY], dt);
    let var_xdd = diff.noise_variance(sg::ACCELERATION, variance_of[sg::ACCELERATION], dt);
    let var_motion = diff.noise_variance(sg::MOTION_VELOCITY, variance_of[sg::MOTION_VELOCITY], dt);
    let (lo, hi) = x
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let noise_mm = noise.position_variance_mm2.sqrt();
    let range_ok =
        (hi - lo).partial_cmp(&(10.0 * noise_mm.max(1e-9))) == Some(std::cmp::Ordering::Greater);
    if !range_ok {
        return Err(IdentifyError::NoExcitation {
            range_mm: hi - lo,
            noise_mm,
        });
    }
    // Which samples move, and their friction sign, come from the motion velocity: its noise
    // is independent of every regressor's, so the choice does not bias the fit.
    let vmax = motion.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let band = (3.0 * var_motion.sqrt()).max(1e-3 * vmax);
    let sgn = motion
        .iter()
        .map(|&v| if v > 0.0 { 1.0 } else { -1.0 })
        .collect();
    let all = Rows {
        index: (0..n).collect(),
        x,
        xd,
        xdd,
        f,
        sgn,
        var_x,
        var_xd,
        var_xdd,
        var_f: noise.force_variance_n2,
        filtered: None,
        shares,
    };
    // The samples the parallel filter reaches each side (see [`parallel_columns`]).
    let reach = 2 * (acceleration_smoother(diff).len() / 2) + 1;

    // A force the load cell clipped is not the spring's, and is left out of every stage
    // ([`CalibrationLog::unmeasured_force`]): on the paper spec's log clipped at 60 N, 4189
    // samples were left out as transients (a reduced chi-square of 5.41 with them), the window
    // fell from 1.21 s to 0.43 s, and k2 from the quasi-static samples alone was 0.224 /mm
    // against 0.274 unclipped.
    let mut unmeasured = log.unmeasured_force(h, n);
    // Against a stop, and within half a window of it: the smoothed motion there bends
    // round the stop's corner, where the rod stopped at once (the paper spec's log stopped at
    // 15 mm, fitted without the samples at the stop alone, had k2 9 of its standard
    // deviations high at a 0.43 s window).
    if let Some(stop) = stop {
        for (u, held) in unmeasured.iter_mut().zip(stop.held(&all.x, h)) {
            *u |= held;
        }
    }
    // Stage 1: k2 on quasi-static samples, model mu*exp(k2 x) + F0.
    let qs: Vec<usize> = (0..n)
        .filter(|&i| motion[i].abs() <= 0.1 * vmax && !unmeasured[i])
        .collect();
    let qs = if qs.len() >= 50 { qs } else { (0..n).collect() };
    let qs_rows = all.subset(&qs, false);
    let mut spring_only = [false, false, false, false, true, true, true, false];
    let mut best = (f64::INFINITY, Vp::zeros());
    for g in 0..120 {
        let k2 = 1e-4 * 10f64.powf(g as f64 * 5.0 / 119.0);
        let e: Vec<f64> = qs_rows.x.iter().map(|&x| (k2 * x).exp()).collect();
        let mut a = SMatrix::<f64, 2, 2>::zeros();
        let mut b = SVector::<f64, 2>::zeros();
        for (&ei, &fi) in e.iter().zip(&qs_rows.f) {
            let v = SVector::<f64, 2>::new(ei, 1.0);
            a += v * v.transpose();
            b += v * fi;
        }
        if let Some(sol) = a.cholesky().map(|c| c.solve(&b)) {
            let ssr: f64 = e
                .iter()
                .zip(&qs_rows.f)
                .map(|(&ei, &fi)| (fi - sol[0] * ei - sol[1]).powi(2))
                .sum();
            if ssr.is_finite() && ssr < best.0 {
                best = (ssr, Vp::from([0.0, 0.0, 0.0, 0.0, sol[0], sol[1], k2, 0.0]));
            }
        }
    }
    if !best.0.is_finite() {
        return Err(IdentifyError::NoConvergence(
            "no start for k2 on the quasi-static samples".into(),
        ));
    }
    let (p1, _) = gauss_newton(best.1, &qs_rows, &mut spring_only, 100)?;

    // The parallel filter's rows: the moving samples whose filter reaches only moving
    // samples (a rest's or a turn's friction is unknown). count[i]: samples before i that are
    // not moving or are left out.
    let spanning = |moving: &[usize], band: f64, excluded: &[bool]| -> Vec<usize> {
        let mut count = vec![0usize; n + 1];
        for i in 0..n {
            let unusable = motion[i].abs() <= band || excluded[i];
            count[i + 1] = count[i] + usize::from(unusable);
        }
        moving
            .iter()
            .copied()
            .filter(|&s| s >= reach && s + reach < n && count[s + reach + 1] == count[s - reach])
            .collect()
    };
    // The regression is chosen once, on the first band: through the parallel filter where its
    // rows are at least [`PARALLEL_MIN_SHARE`] of the moving samples. Its columns are made
    // only then.
    let par = {
        let moving: Vec<usize> = (0..n).filter(|&i| motion[i].abs() > band).collect();
        let share = spanning(&moving, band, &unmeasured).len() as f64;
        (parallel_allowed && share >= PARALLEL_MIN_SHARE * moving.len() as f64)
            .then(|| parallel_columns(&all, &log.position_mm, h, diff, &parallel_noise, dt))
    };

    // Gauss-Newton over the active parameters from `p`. The filtered exponential is a Taylor
    // sum about the k2 its moments were summed at: summed again where the fit ended, and the
    // fit repeated, until k2 stays. Returns the fit and the parameters it dropped.
    let joint_fit =
        |p: Vp, rows: &mut Rows, active: &mut Active| -> Result<(Vp, Vec<String>), IdentifyError> {
            let (mut p, mut dropped) = gauss_newton(p, rows, active, 100)?;
            for _ in 0..4 {
                let (Some(par), Some(k2_ref)) = (&par, rows.filtered.as_ref().map(|f| f.k2_ref))
                else {
                    break;
                };
                if (p[K2] - k2_ref).abs() <= 1e-9 * p[K2].abs() {
                    break;
                }
                rows.refresh_moments(&all, par, p[K2]);
                let (next, more) = gauss_newton(p, rows, active, 100)?;
                p = next;
                dropped.extend(more);
            }
            Ok((p, dropped))
        };

    // Stages 2 and 3 on the samples moving faster than `band`.
    let dynamic_fit =
        |band: f64, excluded: &[bool], fit_m: bool, fit_muf: bool| -> Result<_, IdentifyError> {
            // Stage 2: the paper's WLS with k2 fixed, on the samples whose friction sign is known.
            let moving: Vec<usize> = (0..n)
                .filter(|&i| motion[i].abs() > band && !excluded[i])
                .collect();
            let moving = if par.is_some() {
                spanning(&moving, band, excluded)
            } else {
                moving
            };
            let needed = 20 * 7;
            if moving.len() < needed {
                return Err(IdentifyError::TooLittleMotion {
                    found: moving.len(),
                    needed,
                    band_mm_s: band,
                    window_s: diff.window() as f64 * dt,
                });
            }
            let mut active = [fit_m, true, true, true, true, true, false, fit_muf];
            let mut p = p1;
            let mut not_identifiable = Vec::new();
            if !fit_m {
                not_identifiable.push(PARAMS[M].to_string());
            }
            // d0 sgn(xd) differs from a constant (F0) only through the rows that move the other
            // way. Where the log's travel that way is a small share of its travel the first way,
            // those rows are the filter's ringing at the ends of one-way moves and its noise, at
            // rest with any friction in +-d0, and d0 would be fitted to them.
            // The friction that grows with the load is d0's alike, times the exponential.
            if reversal_travel_share(moving.iter().map(|&i| motion[i])) < REVERSAL_TRAVEL_SHARE {
                for k in [D0, MUF] {
                    if !active[k] {
                        continue;
                    }
                    active[k] = false;
                    p[k] = 0.0;
                    not_identifiable.push(PARAMS[k].to_string());
                }
            }
            // A second start where the fit from the quasi-static start gave the spring's offset or
            // scale up (F0 or mu) and the profile over k2 on the moving samples has a point that
            // fits clearly better than that start: the fit from each, and the one that ends
            // clearly lower is kept. The quasi-static samples of a rod with friction carry +-d0 at
            // rest: on the independent rig's sweep draw 1083 (force control, d0 1.59 N, a spring
            // whose force spans 12.5 to 19 N) they put k2 at 0.006 against 0.134. There
            // mu e^(k2 x) is nearly mu (1 + k2 x), a column that F0 repeats, and the fit with k2
            // fixed gave F0 up as not identifiable; k2 then ended 72 % low, 59 of its standard
            // deviations, with nothing said. (Taken as the only start, the profile's point moved
            // fits that were right: a servo's transients, still in the samples, can make a wrong
            // k2 fit the direct rows better. Tried on every fit, the second start doubled the time
            // of many.)
            let profile_k2 = |direct: &Rows| {
                let w = weights_at(&p, direct);
                let c_fixed = correction(direct, &active, &w);
                let at_start =
                    linear_fit(&p, direct, &active, &w, &c_fixed).map_or(f64::INFINITY, |(c, _)| c);
                k2_profile(&p, direct, &active, &w, &c_fixed)
                    .filter(|(c, _)| *c < at_start - PROFILE_MARGIN)
                    .map(|(_, q)| q[K2])
            };
            // Stages 2 to 4 from `p`.
            let from = |mut p: Vp, mut active: Active, mut not_identifiable: Vec<String>| {
                let mut rows = match &par {
                    Some(par) => all.parallel(&moving, par, p[K2]),
                    None => all.subset(&moving, true),
                };
                for _ in 0..2 {
                    let weights = weights_at(&p, &rows);
                    not_identifiable.extend(prune_all(&mut p, &rows, &mut active, &weights));
                    // The WLS solution is one Gauss-Newton step from any start for linear parameters.
                    let (jtj, jtr, _) = normal(&p, &rows, &active, &weights);
                    let dp = solve(&jtj, &jtr, &active).ok_or_else(|| {
                        IdentifyError::NoConvergence("singular WLS normal matrix".into())
                    })?;
                    p += dp;
                }
                let weights = weights_at(&p, &rows);
                let (jtj2, _, _) = normal(&p, &rows, &active, &weights);
                let paper = inverse(&jtj2, &active).unwrap_or_else(Mp::zeros);
                let idx2: Vec<usize> = (0..NP).filter(|&k| k != K2 && active[k]).collect();
                let paper_covariance_k2_fixed = idx2
                    .iter()
                    .map(|&a| idx2.iter().map(|&b| paper[(a, b)]).collect())
                    .collect();

                // Stage 3: joint refinement with k2.
                active[K2] = true;
                not_identifiable.extend(prune_all(&mut p, &rows, &mut active, &weights));
                let (mut p, dropped) = joint_fit(p, &mut rows, &mut active)?;
                not_identifiable.extend(dropped);
                // Stage 4: the start from the quasi-static samples can mislead. On sines those are
                // the turning points, where a heavy rod's inertia force is largest and bends the
                // curve the other way: the fit then ends where k2 is near zero (mu and F0 large and
                // opposite, a straight spring), a minimum the profile over k2 shows is not the
                // lowest. The force is linear in every parameter but k2, so the profile is one
                // weighted least-squares fit per k2 (on the moving samples, unfiltered); where a k2
                // on the start grid fits clearly better, the fit is restarted there and kept if it
                // ends lower.
                if active[K2] {
                    let direct = all.subset(&rows.index, true);
                    // One set of weights and noise correction (the converged fit's) for every point:
                    // the linear parameters' weighted least squares is then one solve per k2, and the
                    // points and the fit are compared on the same objective.
                    let mut fixed = active;
                    fixed[K2] = false;
                    let w = weights_at(&p, &direct);
                    let c_fixed = correction(&direct, &fixed, &w);
                    let current = objective(&p, &direct, &w, &c_fixed);
                    let best = k2_profile(&p, &direct, &fixed, &w, &c_fixed);
                    if let Some((_, q)) = best.filter(|(c, _)| *c < current - PROFILE_MARGIN) {
                        let mut restart_rows = match (&par, rows.filtered.is_some()) {
                            (Some(par), true) => all.parallel(&rows.index, par, q[K2]),
                            _ => direct,
                        };
                        let mut act = active;
                        // Kept only with the same parameters (nothing dropped) and a lower objective,
                        // each at its own weights.
                        if let Ok((r, _)) = joint_fit(q, &mut restart_rows, &mut act) {
                            if act == active
                                && objective_at_own_weights(&r, &restart_rows, &active)
                                    < objective_at_own_weights(&p, &rows, &active)
                            {
                                p = r;
                                rows = restart_rows;
                            }
                        }
                    }
                }
                Ok((rows, p, active, not_identifiable, paper_covariance_k2_fixed))
            };
            let first = from(p, active, not_identifiable.clone());
            if first.as_ref().is_ok_and(|f| f.2[F0] && f.2[MU]) {
                return first;
            }
            let direct = all.subset(&moving, true);
            let Some(k2) = profile_k2(&direct) else {
                return first;
            };
            let mut q = p;
            q[K2] = k2;
            let second = from(q, active, not_identifiable);
            // Each fit's objective on the moving samples without the parallel filter, at its own
            // weights.
            let score = |f: &(Rows, Vp, Active, Vec<String>, Vec<Vec<f64>>)| {
                objective_at_own_weights(&f.1, &direct, &f.2)
            };
            match (first, second) {
                (Ok(a), Ok(b)) if score(&b) < score(&a) - PROFILE_MARGIN => Ok(b),
                (Err(_), Ok(b)) => Ok(b),
                (first, _) => first,
            }
        };
    let fit_m = inertia == Inertia::Fitted;
    // Stages 2 to 4 and what follows them, with the friction that grows with the load
    // fitted or not.
    let finish = |fit_muf: bool| -> Result<Identification, IdentifyError> {
        let mut excluded = unmeasured.clone();
        let mut band = band;
        let (mut rows, mut p, mut active, mut not_identifiable, mut paper_covariance_k2_fixed) =
            dynamic_fit(band, &excluded, fit_m, fit_muf)?;
        // A wrong friction sign costs a residual of 2 d0. Samples within a few velocity-noise
        // standard deviations of zero can have it; with strong Coulomb friction the band is widened
        // until the expected share of such rows, times (2 d0)^2, is below 1 % of the row variance.
        if active[D0] {
            // The friction at its largest, where the spring's force is (mu_f grows with it).
            let d0 = p[D0].abs() + p[MUF].abs() * (p[K2] * hi).exp();
            let weights = weights_at(&p, &rows);
            let mean_variance = weights.iter().map(|w| 1.0 / w).sum::<f64>() / weights.len() as f64;
            let sigma_motion = var_motion.sqrt();
            let mut z = 3.0;
            while z < 8.0 && 4.0 * d0 * d0 * normal_tail(z) > 0.01 * mean_variance {
                z += 0.25;
            }
            let wider = (z * sigma_motion).max(1e-3 * vmax);
            if wider > band {
                band = wider;
                (rows, p, active, not_identifiable, paper_covariance_k2_fixed) =
                    dynamic_fit(band, &excluded, fit_m, fit_muf)?;
            }
        }
        // Transients the window cannot resolve: where the motion changes within a window (a
        // servo's velocity step, a trapezoidal move's acceleration step), the filtered
        // acceleration spreads the inertia force over the window while the measured force has it
        // where it is. The residual there stands out far beyond its noise; every sample whose
        // filtered values it reaches (half a window each side) is left out and the fit repeated.
        let moving_samples = rows.f.len();
        let inertia_signal = |r: &Rows| {
            r.xdd
                .iter()
                .enumerate()
                .map(|(i, a)| (a * a - r.var_xdd_at(i)).max(0.0))
                .sum::<f64>()
        };
        let inertia_signal_before = inertia_signal(&rows);
        let reduced_chi2_with_transients =
            reduced_chi_square(&p, &rows, &active, &weights_at(&p, &rows));
        for _ in 0..TRANSIENT_ROUNDS {
            let weights = weights_at(&p, &rows);
            let mut next = excluded.clone();
            let mut excess = 0.0;
            for (i, w) in weights.iter().enumerate() {
                let z = (rows.f[i] - model(&p, &rows, i).0) * w.sqrt();
                if z.abs() > TRANSIENT_SIGMAS {
                    excess += z * z - 1.0;
                    let s = rows.index[i];
                    mark_window(&mut next, s, h);
                }
            }
            // At rest the friction is anywhere in +-d0, so a resting sample is a transient where
            // its residual without friction exceeds d0 by as much: a move's start or stop whose
            // inertia force the filtered acceleration spreads into the moving samples nearby.
            for i in (0..n).filter(|&i| motion[i].abs() <= band && !unmeasured[i]) {
                let (f, _) = model(&p, &all, i);
                let friction = p[D0] + p[MUF] * (p[K2] * all.x[i]).exp();
                let frictionless = all.f[i] - (f - friction * all.sgn[i]);
                let d0 = if active[D0] { friction.abs() } else { 0.0 };
                let sd = row_variance(&p, &all, i).sqrt();
                if frictionless.abs() > d0 + TRANSIENT_SIGMAS * sd {
                    let z = (frictionless.abs() - d0) / sd;
                    excess += z * z - 1.0;
                    mark_window(&mut next, i, h);
                }
            }
            // A few outliers that raise the reduced chi-square by less than the window choice
            // tolerates (a friction sign wrong on a sample or two at a reversal) are left in.
            let left = (0..n)
                .filter(|&i| motion[i].abs() > band && !next[i])
                .count();
            if excess < CHI2_RISE_MIN * rows.f.len() as f64
                || (left as f64) < TRANSIENT_KEEP_SHARE * moving_samples as f64
            {
                break;
            }
            let Ok(refit) = dynamic_fit(band, &next, fit_m, fit_muf) else {
                break;
            };
            excluded = next;
            (rows, p, active, not_identifiable, paper_covariance_k2_fixed) = refit;
        }
        let transient_samples = (0..n)
            .filter(|&i| motion[i].abs() > band && excluded[i] && !unmeasured[i])
            .count();
        // Where the transients left out held most of the inertia's signal (a servo's velocity
        // steps: the acceleration is there), the m fitted to what is left is chosen by its own
        // residuals: on the independent rig's servo log of a heavy transmission (m 0.36, d0 3.7 N,
        // 500 Hz), 46 % of the signal went with the transients and m came out 0.038 +- 0.057, z -5.7.
        // It is given up there, except through the parallel filter, which follows the corners,
        // where the fit without m explains what is left clearly worse (a fine encoder on a heavy
        // servo: m resolved, 0.230 against 0.243, and the reduced chi-square 60 to 234 without it
        // at every window). Regressed directly, a fit without m is worse by the smeared
        // transients' tails too, and m stays given up. Glitches take a window or two each (at
        // least 97 % stays).
        if transient_samples > 0
            && active[M]
            && inertia_signal(&rows) < INERTIA_KEEP_SHARE * inertia_signal_before
        {
            if let Ok(refit) = dynamic_fit(band, &excluded, false, fit_muf) {
                let with_m = reduced_chi_square(&p, &rows, &active, &weights_at(&p, &rows));
                let (r, q, a) = (&refit.0, &refit.1, &refit.2);
                let without_m = reduced_chi_square(q, r, a, &weights_at(q, r));
                let explains_worse =
                    without_m > with_m * (1.0 + super::window::chi2_rise_tolerance(r.f.len()));
                if !(rows.filtered.is_some() && explains_worse) {
                    (rows, p, active, not_identifiable, paper_covariance_k2_fixed) = refit;
                }
            }
        }
        let weights = weights_at(&p, &rows);
        let (jtj, _, _) = normal(&p, &rows, &active, &weights);
        let raw = jtj + correction(&rows, &active, &weights);
        let signal_share = NOISY_ORDER
            .iter()
            .filter(|&&k| active[k] && raw[(k, k)] > 0.0)
            .map(|&k| jtj[(k, k)] / raw[(k, k)])
            .fold(1.0_f64, f64::min);
        let m = rows.f.len();
        let reduced_chi2 = reduced_chi_square(&p, &rows, &active, &weights);
        // Residuals share noise over the position kernel's window, widened by the parallel
        // filter's reach each side where the rows went through it.
        let regression = if rows.filtered.is_some() {
            Regression::ParallelFilter
        } else {
            Regression::Direct
        };
        let correlation_span = match regression {
            Regression::ParallelFilter => diff.window() + 2 * reach,
            Regression::Direct => diff.window(),
        };
        let (cov, covariance_method) = sandwich(&p, &rows, &active, &weights, correlation_span)
            .ok_or_else(|| IdentifyError::NoConvergence("singular covariance".into()))?;
        let eig = eigenvalues(scaled(&jtj, &active)).ok_or_else(|| {
        IdentifyError::NoConvergence(
            "no parameter is left that this log determines (a normal matrix that is empty or not finite)".into(),
        )
    })?;
        let condition_number = eig.max() / eig.min().max(1e-300);
        let rms = ((0..m)
            .map(|i| (rows.f[i] - model(&p, &rows, i).0).powi(2))
            .sum::<f64>()
            / m as f64)
            .sqrt();
        let residuals: Vec<f64> = (0..m)
            .map(|i| (rows.f[i] - model(&p, &rows, i).0) * weights[i].sqrt())
            .collect();
        let adequacy = Adequacy::new(
            reduced_chi2,
            whiteness(&residuals, &rows.index, correlation_span),
        );
        let position_stop = position_stop(&p, &active, &all, &motion, band, &unmeasured);
        let parameters = Estimates(std::array::from_fn(|k| {
            if active[k] {
                Estimate {
                    value: Some(p[k]),
                    std: Some(cov[(k, k)].sqrt()),
                }
            } else {
                Estimate {
                    value: None,
                    std: None,
                }
            }
        }));
        let idx: Vec<usize> = (0..NP).filter(|&k| active[k]).collect();
        not_identifiable.sort();
        not_identifiable.dedup();
        let inertia_attenuation = if active[M] && regression == Regression::Direct {
            inertia_attenuation(diff, &all.xdd, &rows, &weights)
        } else {
            None
        };
        Ok(Identification {
            parameters,
            position_stop,
            not_identifiable,
            k2_quasi_static_per_mm: p1[K2],
            covariance: idx
                .iter()
                .map(|&a| idx.iter().map(|&b| cov[(a, b)]).collect())
                .collect(),
            paper_covariance_k2_fixed,
            covariance_parameters: idx.iter().map(|&k| PARAMS[k].to_string()).collect(),
            covariance_method,
            condition_number,
            reduced_chi2,
            residual_rms_n: rms,
            samples: log.len(),
            log_samples: log.len(),
            block_samples: 1,
            dynamic_samples: m,
            transient_samples,
            reduced_chi2_with_transients,
            speed_max_mm_per_s: vmax,
            quasi_static_samples: qs_rows.f.len(),
            sg_window: diff.window(),
            sg_window_s: diff.window() as f64 * dt,
            window_choice: WindowChoice {
                method: WindowMethod::Given,
                candidates: Vec::new(),
            },
            adequacy,
            sign_fault: None,
            filter_bias_std: [0.0; NP],
            noise_std: [0.0; NP],
            reduced_chi2_noise_change: 0.0,
            signal_share,
            inertia_attenuation,
            regression,
            load_friction_left_out: None,
        })
    };
    match load_friction {
        LoadFriction::LeftOut => finish(false),
        LoadFriction::Fitted => finish(true),
        LoadFriction::Auto => {
            let with = finish(true)?;
            let muf = with.get(Param::MuF);
            let Some((v, sd)) = muf.value.zip(muf.std) else {
                return Ok(with);
            };
            if v > LOAD_FRICTION_SIGMAS * sd {
                return Ok(with);
            }
            let mut without = finish(false)?;
            without.load_friction_left_out = Some(muf);
            Ok(without)
        }
    }
}

/// A rod that stands at an end of the logged positions while the force moves on beyond the
/// law and friction: a rod pushed against a stop, or an encoder at the end of its range
/// while the rod travels on. Found by identification after its fit, and left out.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PositionStop {
    /// Where the rod stands (mm): the smoothed position's mean over those samples.
    pub x_mm: f64,
    /// At the log's largest position (true) or its smallest.
    pub high: bool,
    /// Samples at rest there whose force lies off the fitted law by more than the fitted
    /// Coulomb friction and [`TRANSIENT_SIGMAS`] of the row's noise.
    pub samples: usize,
    /// The least force over those samples (N).
    pub force_from_n: f64,
    /// The largest (N).
    pub force_to_n: f64,
    /// How far the force there goes beyond the law and its friction, at most (N).
    pub excess_n: f64,
    /// Where the samples left out begin (mm): the end of the smoothed positions less the
    /// band the stop was looked for in. From here on (down, at the bottom) the fit has none.
    pub from_mm: f64,
}

impl PositionStop {
    /// Whether the smoothed position `x_mm` lies where the stop holds the rod.
    pub fn holds(&self, x_mm: f64) -> bool {
        if self.high {
            x_mm >= self.from_mm
        } else {
            x_mm <= self.from_mm
        }
    }

    /// Which of the smoothed positions `x` the stop holds, and every sample within `half` of
    /// one: there the smoothed motion bends round the stop's corner.
    pub fn held(&self, x: &[f64], half: usize) -> Vec<bool> {
        let n = x.len();
        let mut mask = vec![false; n];
        let mut filled_to = 0;
        for i in (0..n).filter(|&i| self.holds(x[i])) {
            let (from, to) = (i.saturating_sub(half).max(filled_to), (i + half + 1).min(n));
            if from < to {
                mask[from..to].fill(true);
            }
            filled_to = filled_to.max(to);
        }
        mask
    }

    /// What the stop is and what was done: "the rod stands at ...".
    pub fn reason(&self) -> String {
        format!(
            "the rod stands at x = {:.3} mm, the log's {} position, on {} samples while the \
             force moves over {:.2} ... {:.2} N, up to {:.2} N off the law beyond its friction: \
             a rod against a stop, or an encoder at the end of its range while the rod travels \
             on; the force there is not the spring's, so the samples {} x = {:.3} mm are left \
             out of the fit (record a run that stays off the stops)",
            self.x_mm,
            if self.high { "largest" } else { "smallest" },
            self.samples,
            self.force_from_n,
            self.force_to_n,
            self.excess_n,
            if self.high { "from" } else { "up to" },
            self.from_mm
        )
    }
}

/// The least excess of a stop's force over the law and its friction, as a share of the logged
/// force's range, for identification to call it a stop ([`PositionStop`]). A rod pushed
/// against a stop carries what the actuator adds (the paper spec's log stopped at 15 mm: up to
/// 31 N of an 87 N range); a rod that rests where the model fits less well strays by less.
pub const STOP_MIN_FORCE_SHARE: f64 = 0.1;

/// The rod against a stop ([`PositionStop`]): the samples at rest (`motion` within `band`,
/// the force measured: not `unmeasured`) whose force lies off the fitted law `p` by more than
/// its Coulomb friction and [`TRANSIENT_SIGMAS`] of the row's noise, at least
/// [`super::log::CLIP_MIN_SAMPLES`] and [`super::log::CLIP_MIN_SHARE`] of the samples, all
/// within [`super::log::CLIP_EDGE_SHARE`] of the range of smoothed positions from one end
/// (above the law at the top, below it at the bottom), and off the law beyond the friction
/// by at least [`STOP_MIN_FORCE_SHARE`] of the logged force's range somewhere. A rod held by
/// friction at a turn (the independent rig's digital-encoder draw 8, d0 3.25 N: 3407 samples
/// at its top position while the force moved 5.5 N) stays within the friction, and a rest at
/// a servo's hold within the noise. Without the rule on the sign, the sweep's draw 1003 (a
/// force-controlled rod at rest on all but 275 of its samples, whose fit does not explain it)
/// was named: 234 samples at its smallest position, up to 4.3 N above the law.
fn position_stop(
    p: &Vp,
    active: &Active,
    all: &Rows,
    motion: &[f64],
    band: f64,
    unmeasured: &[bool],
) -> Option<PositionStop> {
    let n = all.x.len();
    let (lo, hi) = all
        .x
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    let edge = super::log::CLIP_EDGE_SHARE * (hi - lo);
    let needed =
        super::log::CLIP_MIN_SAMPLES.max((super::log::CLIP_MIN_SHARE * n as f64).ceil() as usize);
    let (f_lo, f_hi) = all
        .f
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &f| {
            (a.min(f), b.max(f))
        });
    let mut found = [(0usize, 0.0_f64, f64::INFINITY, f64::NEG_INFINITY, 0.0_f64); 2];
    for i in (0..n).filter(|&i| motion[i].abs() <= band && !unmeasured[i]) {
        let (f, _) = model(p, all, i);
        let friction = p[D0] + p[MUF] * (p[K2] * all.x[i]).exp();
        let frictionless = all.f[i] - (f - friction * all.sgn[i]);
        let d0 = if active[D0] { friction.abs() } else { 0.0 };
        if frictionless.abs() <= d0 + TRANSIENT_SIGMAS * row_variance(p, all, i).sqrt() {
            continue;
        }
        let excess = frictionless.abs() - d0;
        let x = all.x[i];
        // Against a stop at the top the force stands above the law (the actuator pushes the
        // rod into it; an encoder at the top of its range reads short of the rod), at the
        // bottom below it.
        let side = if x >= hi - edge && frictionless > 0.0 {
            0
        } else if x <= lo + edge && frictionless < 0.0 {
            1
        } else {
            continue;
        };
        let s = &mut found[side];
        s.0 += 1;
        s.1 += x;
        s.2 = s.2.min(all.f[i]);
        s.3 = s.3.max(all.f[i]);
        s.4 = s.4.max(excess);
    }
    found
        .iter()
        .enumerate()
        .filter(|(_, s)| s.0 >= needed && s.4 >= STOP_MIN_FORCE_SHARE * (f_hi - f_lo))
        .max_by_key(|(_, s)| s.0)
        .map(|(side, s)| PositionStop {
            x_mm: s.1 / s.0 as f64,
            high: side == 0,
            samples: s.0,
            force_from_n: s.2,
            force_to_n: s.3,
            excess_n: s.4,
            from_mm: if side == 0 { hi - edge } else { lo + edge },
        })
}

/// The profile over k2: at each of [`PROFILE_POINTS`] values of k2 (log-spaced over
/// [`PROFILE_K2_PER_MM`]) the linear parameters active in `fixed` (k2 not among them) by one
/// weighted least-squares solve from `p` on `rows`, with the weights `w` and the noise
/// correction `c`; the point with the lowest objective, and that objective. None where no
/// point solves.
fn k2_profile(p: &Vp, rows: &Rows, fixed: &Active, w: &[f64], c: &Mp) -> Option<(f64, Vp)> {
    // Unfiltered rows are linear in every parameter but k2, and only the exponential's column
    // exp(k2 x) moves with k2: the sums of the other columns are taken once
    // ([`LinearSums`]), and each point adds the exponential's.
    let fixed_sums = rows.filtered.is_none().then(|| LinearSums::new(rows, w));
    let mut best: Option<(f64, Vp)> = None;
    for g in 0..PROFILE_POINTS {
        let mut q = *p;
        q[K2] = PROFILE_K2_PER_MM.0
            * (PROFILE_K2_PER_MM.1 / PROFILE_K2_PER_MM.0)
                .powf(g as f64 / (PROFILE_POINTS - 1) as f64);
        let fit = match &fixed_sums {
            Some(sums) => sums.linear_fit(&q, rows, fixed, w, c),
            None => linear_fit(&q, rows, fixed, w, c),
        };
        let Some((objective, q)) = fit else {
            continue;
        };
        if best.is_none_or(|(b, _)| objective < b) {
            best = Some((objective, q));
        }
    }
    best
}

/// The linear parameters active in `fixed` by one weighted least-squares solve from `p` on
/// `rows` (k2 as in `p`), with the weights `w` and the noise correction `c`, and the
/// objective there; None where the solve fails or the objective is not finite.
fn linear_fit(p: &Vp, rows: &Rows, fixed: &Active, w: &[f64], c: &Mp) -> Option<(f64, Vp)> {
    let (jtj, jtr, _) = normal_with(p, rows, fixed, w, c);
    let q = p + solve(&jtj, &jtr, fixed)?;
    let objective = objective(&q, rows, w, c);
    objective.is_finite().then_some((objective, q))
}

/// The columns of unfiltered rows that do not depend on k2 (m, d0, d1, d2 and F0's: xdd,
/// the friction sign, xd, the unbiased cube and 1), with their weighted sums of products
/// taken once: each point of [`k2_profile`] then sums the exponential's columns alone
/// (mu's, and mu_f's signed one).
struct LinearSums {
    /// sum_i w_i r_a r_b over the columns but the exponential's (its row and column zero).
    jtj: Mp,
    /// sum_i w_i r_a f_i over the same columns.
    jtf: Vp,
    /// sum_i w_i f_i^2.
    ff: f64,
}

impl LinearSums {
    fn new(r: &Rows, weights: &[f64]) -> LinearSums {
        let mut jtj = Mp::zeros();
        let mut jtf = Vp::zeros();
        let mut ff = 0.0;
        for (i, &w) in weights.iter().enumerate() {
            let row = Self::fixed_row(r, i);
            for b in 0..NP {
                for a in 0..=b {
                    jtj[(a, b)] += row[a] * row[b] * w;
                }
            }
            jtf += row * (w * r.f[i]);
            ff += w * r.f[i] * r.f[i];
        }
        jtj.fill_lower_triangle_with_upper_triangle();
        LinearSums { jtj, jtf, ff }
    }

    /// Row i of the unfiltered model's columns ([`model`]) but the exponential's, k2's and
    /// the friction's that grows with it.
    fn fixed_row(r: &Rows, i: usize) -> Vp {
        let xd3 = unbiased_cube(r.xd[i], r.var_xd_at(i));
        Vp::from([r.xdd[i], r.sgn[i], r.xd[i], xd3, 0.0, 1.0, 0.0, 0.0])
    }

    /// [`linear_fit`] on the unfiltered `r` (k2 as in `p`), from these sums and the
    /// exponential's column at p's k2: the same normal equations (the sums regrouped, so
    /// equal to rounding), and the objective of the solution from them, chi^2(q) =
    /// sum w f^2 - 2 q . J^T W f + q^T J^T W J q less the noise part q^T C q.
    fn linear_fit(
        &self,
        p: &Vp,
        r: &Rows,
        fixed: &Active,
        weights: &[f64],
        c: &Mp,
    ) -> Option<(f64, Vp)> {
        let mut jtj = self.jtj;
        let mut jtf = self.jtf;
        for (i, &w) in weights.iter().enumerate() {
            let e = (p[K2] * r.x[i]).exp();
            let signed = r.sgn[i] * e;
            let row = Self::fixed_row(r, i);
            for a in 0..NP {
                jtj[(a, MU)] += row[a] * e * w;
                jtj[(a, MUF)] += row[a] * signed * w;
            }
            jtj[(MU, MU)] += e * e * w;
            jtj[(MU, MUF)] += e * signed * w;
            jtj[(MUF, MUF)] += signed * signed * w;
            jtf[MU] += e * (w * r.f[i]);
            jtf[MUF] += signed * (w * r.f[i]);
        }
        // The exponential's columns are zero in the fixed rows, so (MU, MU), (MU, MUF) and
        // (MUF, MUF) got their products alone; the columns' sums are mirrored into their rows.
        for a in 0..NP {
            if a != MU && a != MUF {
                jtj[(MU, a)] = jtj[(a, MU)];
                jtj[(MUF, a)] = jtj[(a, MUF)];
            }
        }
        jtj[(MUF, MU)] = jtj[(MU, MUF)];
        if !(jtj.iter().all(|v| v.is_finite()) && jtf.iter().all(|v| v.is_finite())) {
            return None;
        }
        // Over the active columns only, as the masked rows of [`normal_with`].
        let mut masked = jtj;
        let mut rhs = jtf - jtj * p;
        for k in 0..NP {
            if !fixed[k] {
                masked.row_mut(k).fill(0.0);
                masked.column_mut(k).fill(0.0);
                rhs[k] = 0.0;
            }
        }
        let cp = c * p;
        let q = p + solve(&(masked - c), &(rhs + cp), fixed)?;
        let chi2 = self.ff - 2.0 * q.dot(&jtf) + q.dot(&(jtj * q));
        let objective = chi2 - q.dot(&(c * q));
        objective.is_finite().then_some((objective, q))
    }
}

/// The corrected objective of `p` on `rows` at its own weights, with the noise correction of
/// the parameters in `active`: how two fits of the same rows are compared.
fn objective_at_own_weights(p: &Vp, rows: &Rows, active: &Active) -> f64 {
    let w = weights_at(p, rows);
    objective(p, rows, &w, &correction(rows, active, &w))
}

/// Points of the profile over k2 ([`PROFILE_K2_PER_MM`], log-spaced) on which identification
/// checks that its fit ended at the lowest minimum ([`fit_model`], stage 4).
const PROFILE_POINTS: usize = 17;

/// The profile's range of k2 (1/mm): from a spring nearly straight over 100 mm to one whose
/// force grows e-fold in a millimetre.
const PROFILE_K2_PER_MM: (f64, f64) = (0.01, 1.0);

/// How much lower (chi-square) a profile point must fit than the converged fit for the fit to
/// be restarted there: twice the 95 % quantile of one parameter's chi-square change (3.84),
/// so a rounding difference never restarts it.
const PROFILE_MARGIN: f64 = 8.0;

/// The least share of the moving samples whose parallel filter reaches only moving samples
/// at which identification regresses through the parallel filter ([`Regression`]).
pub const PARALLEL_MIN_SHARE: f64 = 0.75;

/// The smoother `q` at every second sample (consecutive samples, centred), and the force's
/// filter: that after the three-sample mean.
fn force_filter(q: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let reach = 2 * (q.len() / 2);
    let mut q_full = vec![0.0; 2 * reach + 1];
    for (j, w) in q.iter().enumerate() {
        q_full[2 * j] = *w;
    }
    let mut qt = vec![0.0; 2 * reach + 3];
    for (i, w) in q_full.iter().enumerate() {
        for k in 0..3 {
            qt[i + k] += w / 3.0;
        }
    }
    (q_full, qt)
}

/// Every sample's columns through the parallel filter (see [`Regression::ParallelFilter`]).
///
/// The velocity columns are Q applied to the central difference (x(t + dt) - x(t - dt)) /
/// (2 dt) at Q's taps, and to its unbiased cube: the difference is exactly the velocity's mean
/// over two samples, so unlike the velocity kernel it does not distort the motion as the
/// window grows; it reads the samples at odd offsets from the row, whose noise the
/// acceleration's (even offsets) does not share. `positions`: the logged positions, sample i
/// of `all` at `positions[i + offset]`.
fn parallel_columns(
    all: &Rows,
    positions: &[f64],
    offset: usize,
    diff: &Differentiator,
    noise: &SensorNoise,
    dt: f64,
) -> Parallel {
    let q = acceleration_smoother(diff);
    let (q_full, qt) = force_filter(&q);
    let var = noise.position_variance_mm2;
    let var_difference = var / (2.0 * dt * dt);
    let difference: Vec<f64> = (0..all.x.len())
        .map(|i| {
            let at = i + offset;
            match (
                at.checked_sub(1).and_then(|b| positions.get(b)),
                positions.get(at + 1),
            ) {
                (Some(before), Some(after)) => (after - before) / (2.0 * dt),
                _ => f64::NAN,
            }
        })
        .collect();
    let cube: Vec<f64> = difference
        .iter()
        .enumerate()
        .map(|(i, &v)| unbiased_cube(v, var_difference * all.share(i, PARALLEL_SHARE)))
        .collect();
    let through_q: Vec<f64> = parallel_velocity_weights(&q_full)
        .iter()
        .map(|w| w / dt)
        .collect();
    Parallel {
        f: parallel_filter(&qt, &all.f),
        sgn: parallel_filter(&qt, &all.sgn),
        xd: parallel_filter(&q_full, &difference),
        cube: parallel_filter(&q_full, &cube),
        var_x: diff.smoothed_noise_variance(sg::POSITION, &q_full, var, dt),
        var_f: noise.force_variance_n2 * qt.iter().map(|w| w * w).sum::<f64>(),
        var_xd: var * through_q.iter().map(|w| w * w).sum::<f64>(),
        cube_noise: CubeNoise::through_differences(&q_full, var_difference),
        curvature: dt * dt / 3.0,
        q,
    }
}

/// The trajectory a log's rod followed, as the quantisation error's shares are summed along
/// it ([`trajectory_shares`]): the position and speed smoothed over about a second, aligned
/// with the log's samples (NaN within the smoother's reach of either end). A step's error
/// averages out of it, and its phase along a window is the rod's. Over shorter smoothers the
/// steps' own error stayed in the trajectory and scrambled the harmonics' phases: on a servo
/// log read in 1.3 um steps at 100 Hz the velocity kernels' shares came out 0.75 over 0.2 s
/// where the true trajectory gives 1.06, and over a second 1.04.
struct Trajectory {
    position_mm: Vec<f64>,
    speed_mm_s: Vec<f64>,
}

impl Trajectory {
    fn of(log: &CalibrationLog) -> Trajectory {
        let dt = log.dt_s();
        let smooth =
            Differentiator::new(((1.0 / dt).round().min(1e6) as usize).max(sg::MIN_WINDOW) | 1);
        let along = |values: Vec<f64>| -> Vec<f64> {
            let mut out = vec![f64::NAN; log.len()];
            if let Some(span) = out.get_mut(smooth.half..smooth.half + values.len()) {
                span.copy_from_slice(&values);
            }
            out
        };
        Trajectory {
            position_mm: along(sg::smooth(
                &log.position_mm,
                &sg::quintic_smoother(smooth.half),
            )),
            speed_mm_s: along(smooth.apply(&log.position_mm, dt, sg::RATE)),
        }
    }
}

/// The kernels whose shares of a quantisation error identification weighs its rows by, in
/// the order of [`Rows::shares`]: the position, velocity, acceleration and motion-velocity
/// kernels, and the parallel filter's velocity ([`PARALLEL_SHARE`]).
fn share_kernels(diff: &Differentiator) -> [Vec<f64>; SHARE_KERNELS] {
    [
        diff.weights[sg::POSITION].clone(),
        diff.weights[sg::VELOCITY].clone(),
        diff.weights[sg::ACCELERATION].clone(),
        diff.weights[sg::MOTION_VELOCITY].clone(),
        parallel_velocity_weights(&force_filter(&acceleration_smoother(diff)).0),
    ]
}

/// What each of identification's kernels at `diff` passes of a position's quantisation error
/// `q` at each speed the log moves at ([`SpeedShares`]), as shares of white noise of the
/// uniform error's variance, summed along the log's [`Trajectory`] over every row.
pub(super) fn quantisation_shares(
    log: &CalibrationLog,
    diff: &Differentiator,
    q: Quantisation,
) -> SpeedShares {
    speed_shares(log, &Trajectory::of(log), diff, q)
}

fn speed_shares(
    log: &CalibrationLog,
    trajectory: &Trajectory,
    diff: &Differentiator,
    q: Quantisation,
) -> SpeedShares {
    let kernels = share_kernels(diff);
    let refs: [&[f64]; SHARE_KERNELS] = [
        &kernels[0],
        &kernels[1],
        &kernels[2],
        &kernels[3],
        &kernels[4],
    ];
    let row_speeds = class_speeds(log, diff);
    let rows: Vec<usize> = (0..row_speeds.len()).map(|i| i + diff.half).collect();
    SpeedShares::new(
        &refs,
        &trajectory.position_mm,
        &trajectory.speed_mm_s,
        &rows,
        &row_speeds,
        q,
        log.dt_s(),
    )
}

/// The speed (mm/s) each of identification's rows at `diff` is classed by in
/// [`SpeedShares`]: the mean over about a second about it (the positions half a second
/// either side, differenced; nearer the log's ends, the first or last second's). One
/// subtraction a row, where the [`Trajectory`]'s smoothed speed is a hundred.
fn class_speeds(log: &CalibrationLog, diff: &Differentiator) -> Vec<f64> {
    let dt = log.dt_s();
    let n = log.len();
    let rows = n.saturating_sub(2 * diff.half);
    let reach = (((0.5 / dt).round() as usize).max(1)).min(n.saturating_sub(1) / 2);
    if reach == 0 {
        return vec![0.0; rows];
    }
    let y = &log.position_mm;
    (0..rows)
        .map(|i| {
            let c = (i + diff.half).clamp(reach, n - 1 - reach);
            (y[c + reach] - y[c - reach]) / (2 * reach) as f64 / dt
        })
        .collect()
}

/// Each of identification's rows' shares of a position's quantisation error `q`
/// ([`RowShares`]), by the row's speed ([`class_speeds`]), with the motion velocity's mean
/// share over the rows the fit takes as moving: those beyond three of its standard
/// deviations at that share, first read over the rows beyond white noise's band
/// (`white_band`). The rows between the two bands creep a step in many samples and pass
/// several times white noise's share.
fn row_shares(
    log: &CalibrationLog,
    diff: &Differentiator,
    q: Quantisation,
    motion: &[f64],
    white_band: f64,
) -> (RowShares, f64) {
    let speeds = q
        .kernel_shares
        .unwrap_or_else(|| quantisation_shares(log, diff, q));
    let rows = RowShares::new(speeds, &class_speeds(log, diff));
    let vmax = motion.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let mean_beyond = |band: f64| {
        let (sum, count) = motion
            .iter()
            .enumerate()
            .filter(|(_, v)| v.abs() > band.max(1e-3 * vmax))
            .fold((0.0, 0usize), |(s, c), (i, _)| {
                (s + rows.share(i, sg::MOTION_VELOCITY), c + 1)
            });
        (count > 0).then(|| sum / count as f64)
    };
    let dt = log.dt_s();
    let first = mean_beyond(white_band).unwrap_or(1.0);
    let fit_band = 3.0
        * diff
            .noise_variance(sg::MOTION_VELOCITY, q.white_variance_mm2() * first, dt)
            .sqrt();
    let share = if fit_band > white_band {
        mean_beyond(fit_band).unwrap_or(first)
    } else {
        first
    };
    (rows, share)
}

/// The weights (unit sample spacing) of the parallel filter's velocity on the logged
/// positions: the central difference smoothed by `q_full`, Q's taps at even offsets, each the
/// difference of its two odd neighbours.
fn parallel_velocity_weights(q_full: &[f64]) -> Vec<f64> {
    let mut through_q = vec![0.0; q_full.len() + 2];
    for (i, w) in q_full.iter().enumerate() {
        through_q[i] -= w / 2.0;
        through_q[i + 2] += w / 2.0;
    }
    through_q
}

/// The least share of the acceleration regressor's weighted power that is signal (not the
/// kernel's noise) at which identification estimates the filter's loss of gain.
pub const ATTENUATION_MIN_SIGNAL: f64 = 0.5;

/// The largest loss of gain [`correct_inertia`] corrects. Beyond it the window smooths away
/// much of the motion's acceleration (its corners, or a servo's velocity steps), and the
/// first-order correction overshot: on the independent rig's Table II-d2 trapezoids and
/// S-curves at 1.71 s (a loss of 4.7 to 5.6 %) it moved m up to 0.9 of its standard deviation
/// below the truth, where uncorrected it was within 0.3 on most. Such fits are left as they
/// are (the window choice's filter-bias allowance is their guard).
pub const ATTENUATION_MAX: f64 = 0.03;

/// The share of the correction [`correct_inertia`] adds to m's standard deviation as the
/// correction's own uncertainty. On noiseless Table I sines the correction took m from +0.57
/// to +0.05 % at a 1.21 s window and from +1.98 to +0.09 % at 1.71 s: it left under a tenth
/// of the bias. On trapezoids, S-curves and ramp-holds it is less exact.
pub const ATTENUATION_UNCERTAINTY: f64 = 0.5;

/// The smoother Q, on the acceleration kernel's even offsets, with which the kernel is Q
/// applied to the second difference over two samples: K2 = Q * [1, 0, -2, 0, 1] / (2 dt)^2.
/// The kernel takes constants and slopes to zero, so the division is exact; Q sums to 1.
pub fn acceleration_smoother(diff: &Differentiator) -> Vec<f64> {
    let w = &diff.weights[sg::ACCELERATION];
    let h = diff.half as i64;
    let j_max = h / 2;
    // c_j: the kernel's weight at offset 2j, j = -j_max ..= j_max.
    let c: Vec<f64> = (-j_max..=j_max).map(|j| w[(h + 2 * j) as usize]).collect();
    // 4 c_j = q_{j-1} - 2 q_j + q_{j+1}, with q zero beyond |j| = j_max - 1: solved from the
    // left, q_{j+1} = 4 c_j + 2 q_j - q_{j-1}.
    let len = c.len().saturating_sub(2);
    let mut q = vec![0.0; len];
    let (mut before, mut at) = (0.0, 0.0);
    for (k, qk) in q.iter_mut().enumerate() {
        let next = 4.0 * c[k] + 2.0 * at - before;
        *qk = next;
        before = at;
        at = next;
    }
    q
}

/// The acceleration filter's loss of gain over the rows of a fit, estimated from the data.
///
/// The Savitzky-Golay acceleration is the true one through a low-pass response H: a motion
/// whose content reaches where H falls below 1 (a long window on sines, the corners of
/// S-curves) has its acceleration regressor shrunk while the measured force keeps the full
/// inertia force, so m comes out high by about 1/H - 1: +0.57 % on noiseless Table I sines at
/// a 1.21 s window, +2.0 % at 1.71 s. The smoother Q that makes the kernel Q applied to the
/// second difference ([`acceleration_smoother`]) has the response H too (to (2 w dt)^2 / 12), so
/// Q applied to the filtered acceleration a has H^2 a, and
/// r = 1 - <Q a, a> / <a, a> (weighted over the fit's rows, with the kernel's noise in both
/// taken out exactly) is the loss of gain 1 - H. None where the noise is more than half the
/// regressor's power, or the estimate is not finite.
fn inertia_attenuation(
    diff: &Differentiator,
    xdd: &[f64],
    rows: &Rows,
    weights: &[f64],
) -> Option<f64> {
    let q = acceleration_smoother(diff);
    let half = q.len() / 2;
    let n = xdd.len();
    // The kernel's noise: var_xdd on <a, a>; on <Q a, a> the sum over Q's taps of the kernel's
    // autocorrelation at their offsets.
    let w = &diff.weights[sg::ACCELERATION];
    let autocorrelation = |lag: usize| -> f64 {
        w.iter()
            .zip(w.iter().skip(lag))
            .map(|(a, b)| a * b)
            .sum::<f64>()
    };
    let r0 = autocorrelation(0);
    if r0 <= 0.0 {
        return None;
    }
    let cross_per_var = q
        .iter()
        .enumerate()
        .map(|(k, qk)| qk * autocorrelation(2 * k.abs_diff(half)))
        .sum::<f64>()
        / r0;
    // sum_k w_k var(a_k): each row's own noise.
    let (mut power, mut smoothed, mut noise) = (0.0, 0.0, 0.0);
    for (k, &i) in rows.index.iter().enumerate() {
        if i < 2 * half || i + 2 * half >= n {
            continue;
        }
        let a = xdd[i];
        let qa: f64 = q
            .iter()
            .enumerate()
            .map(|(j, qj)| qj * xdd[i + 2 * j - 2 * half])
            .sum();
        power += weights[k] * a * a;
        smoothed += weights[k] * qa * a;
        noise += weights[k] * rows.var_xdd_at(k);
    }
    let signal = power - noise;
    if signal.partial_cmp(&(ATTENUATION_MIN_SIGNAL * power)) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let r = 1.0 - (smoothed - noise * cross_per_var) / signal;
    r.is_finite().then_some(r)
}

/// Corrects m for the acceleration filter's loss of gain r (`inertia_attenuation` in this module):
/// m (1 - r), its standard deviation scaled alike, plus [`ATTENUATION_UNCERTAINTY`] of the
/// correction as a systematic error (in `filter_bias_std` and the covariance). A loss beyond
/// [`ATTENUATION_MAX`] (or a negative one beyond it) is left uncorrected and the estimate
/// cleared.
pub fn correct_inertia(id: &mut Identification) {
    let Some(r) = id.inertia_attenuation else {
        return;
    };
    let Estimate {
        value: Some(m),
        std: Some(std),
    } = id.get(Param::M)
    else {
        id.inertia_attenuation = None;
        return;
    };
    if r.abs() > ATTENUATION_MAX {
        id.inertia_attenuation = None;
        return;
    }
    let gain = 1.0 - r;
    let systematic = ATTENUATION_UNCERTAINTY * (m * r).abs();
    id.parameters.0[M] = Estimate {
        value: Some(m * gain),
        std: Some(((std * gain).powi(2) + systematic * systematic).sqrt()),
    };
    if let Some(k) = id.covariance_parameters.iter().position(|n| n == PARAMS[M]) {
        for (a, row) in id.covariance.iter_mut().enumerate() {
            for (b, v) in row.iter_mut().enumerate() {
                if a == k {
                    *v *= gain;
                }
                if b == k {
                    *v *= gain;
                }
            }
        }
        id.covariance[k][k] += systematic * systematic;
    }
    id.filter_bias_std[M] = id.filter_bias_std[M].hypot(systematic);
}

/// The weighted chi-square of the fit at `p` over `r` per degree of freedom.
fn reduced_chi_square(p: &Vp, r: &Rows, active: &Active, weights: &[f64]) -> f64 {
    let chi2: f64 = (0..r.f.len())
        .map(|i| weights[i] * (r.f[i] - model(p, r, i).0).powi(2))
        .sum();
    let dof =
        r.f.len()
            .saturating_sub(active.iter().filter(|a| **a).count());
    chi2 / dof.max(1) as f64
}

/// Marks the samples within `half` of `centre` in `mask` (the samples a transient at `centre`
/// reaches through a filter of that half width).
pub(crate) fn mark_window(mask: &mut [bool], centre: usize, half: usize) {
    let end = (centre + half).min(mask.len().saturating_sub(1));
    if let Some(window) = mask.get_mut(centre.saturating_sub(half)..=end) {
        window.fill(true);
    }
}

/// Two-sided tail probability P(|Z| > z) of a standard normal Z.
fn normal_tail(z: f64) -> f64 {
    use statrs::distribution::{ContinuousCDF, Normal};
    Normal::standard().sf(z) * 2.0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The profile's sums taken once ([`LinearSums`]) give the row-by-row [`linear_fit`]: the
    /// same solution and objective to rounding, at every k2 of the profile, with a parameter
    /// out of the active set and the noise correction in, on rows far from zero (a force
    /// of about 60 N against noise of 0.05 N).
    #[test]
    fn the_profiles_sums_taken_once_give_the_row_by_row_fit() {
        use rand::{rngs::StdRng, SeedableRng};
        use rand_distr::{Distribution, Normal};
        let mut rng = StdRng::seed_from_u64(5);
        let noise = Normal::new(0.0, 1.0).unwrap();
        let n = 5000;
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.01).collect();
        let x: Vec<f64> = t.iter().map(|t| 7.0 + 6.0 * (0.9 * t).sin()).collect();
        let xd: Vec<f64> = t.iter().map(|t| 5.4 * (0.9 * t).cos()).collect();
        let xdd: Vec<f64> = t.iter().map(|t| -4.86 * (0.9 * t).sin()).collect();
        let truth = Vp::from([0.3, 1.5, 0.8, -0.01, 1.2, 50.0, 0.2, 0.03]);
        let f: Vec<f64> = (0..n)
            .map(|i| {
                truth[M] * xdd[i]
                    + (truth[D0] + truth[MUF] * (truth[K2] * x[i]).exp()) * xd[i].signum()
                    + truth[D1] * xd[i]
                    + truth[D2] * xd[i].powi(3)
                    + truth[MU] * (truth[K2] * x[i]).exp()
                    + truth[F0]
                    + 0.05 * noise.sample(&mut rng)
            })
            .collect();
        let rows = Rows {
            index: (0..n).collect(),
            sgn: xd.iter().map(|v| v.signum()).collect(),
            x,
            xd,
            xdd,
            f,
            var_x: 1e-4,
            var_xd: 1e-3,
            var_xdd: 1e-2,
            var_f: 0.0025,
            filtered: None,
            shares: None,
        };
        let mut fixed = [true; NP];
        fixed[K2] = false;
        fixed[D2] = false;
        let mut start = truth * 0.9;
        start[D2] = 0.0;
        let w = weights_at(&start, &rows);
        let c = correction(&rows, &fixed, &w);
        let sums = LinearSums::new(&rows, &w);
        let mut compared = 0;
        for k2 in [0.01, 0.03, 0.1, 0.2, 0.5, 1.0] {
            let mut p = start;
            p[K2] = k2;
            let (row_by_row, once) = (
                linear_fit(&p, &rows, &fixed, &w, &c),
                sums.linear_fit(&p, &rows, &fixed, &w, &c),
            );
            let (Some((o1, q1)), Some((o2, q2))) = (row_by_row, once) else {
                assert_eq!(row_by_row.is_none(), once.is_none(), "k2 {k2}");
                continue;
            };
            compared += 1;
            assert!(
                (o1 - o2).abs() <= 1e-8 * o1.abs(),
                "k2 {k2}: {o1} against {o2}"
            );
            for k in 0..NP {
                assert!(
                    (q1[k] - q2[k]).abs() <= 1e-9 * q1[k].abs().max(1e-12),
                    "k2 {k2}, parameter {k}: {} against {}",
                    q1[k],
                    q2[k]
                );
            }
            assert_eq!(q2[D2], 0.0);
            assert_eq!(q2[K2], k2);
        }
        assert!(compared >= 4, "{compared} of the profile's points solved");
    }

    /// Position, velocity and acceleration at time `t` of a motion whose jerk is `jerks[k]`
    /// from `starts[k]` on (starts increasing, from rest at 0), integrated exactly.
    fn jerk_limited(starts: &[f64], jerks: &[f64], t: f64) -> (f64, f64, f64) {
        let (mut x, mut v, mut a) = (0.0, 0.0, 0.0);
        for (k, (&s, &j)) in starts.iter().zip(jerks).enumerate() {
            let end = starts.get(k + 1).copied().unwrap_or(f64::INFINITY);
            let d = (t.min(end) - s).max(0.0);
            x += v * d + a * d * d / 2.0 + j * d * d * d / 6.0;
            v += a * d + j * d * d / 2.0;
            a += j * d;
        }
        (x, v, a)
    }

    /// The filtered cube's noise ([`CubeNoise`]) against a simulation: white position noise,
    /// central differences at every sample, the parallel filter's smoother over them, and the
    /// sample variance of the filtered unbiased cube at a constant velocity. Neighbouring taps
    /// share a sample; scaling the single-sample moments by the filtered velocity's variance,
    /// as identification did until 2026-11-28, put it 70 times too low on these taps.
    #[test]
    fn the_filtered_cubes_noise_is_summed_over_correlated_differences() {
        use rand::{rngs::StdRng, SeedableRng};
        use rand_distr::{Distribution, Normal};
        let dt = 0.01;
        let sigma = 0.02;
        let s2 = sigma * sigma / (2.0 * dt * dt);
        let q = acceleration_smoother(&Differentiator::new(43));
        let (q_full, _) = force_filter(&q);
        let noise = CubeNoise::through_differences(&q_full, s2);
        let mut rng = StdRng::seed_from_u64(11);
        let normal = Normal::new(0.0, sigma).unwrap();
        let n = q_full.len() + 2;
        for v in [0.0, 1.5, 4.0] {
            let (mut sum_o, mut sum_o2, mut sum_c, mut sum_c2) = (0.0, 0.0, 0.0, 0.0);
            let trials = 40_000;
            let mut e = vec![0.0; n];
            for _ in 0..trials {
                e.iter_mut().for_each(|x| *x = normal.sample(&mut rng));
                let (mut o, mut c) = (0.0, 0.0);
                for (j, w) in q_full.iter().enumerate() {
                    let d = v + (e[j + 2] - e[j]) / (2.0 * dt);
                    o += w * d;
                    c += w * unbiased_cube(d, s2);
                }
                sum_o += o;
                sum_o2 += o * o;
                sum_c += c;
                sum_c2 += c * c;
            }
            let t = trials as f64;
            let var_o = sum_o2 / t - (sum_o / t).powi(2);
            let var_c = sum_c2 / t - (sum_c / t).powi(2);
            let predicted = 9.0 * v.powi(4) * var_o + noise.variance(v * v, 1.0);
            // The sample variance of 40 000 draws is known to about sqrt(2 / 40 000) = 0.7 %
            // for a Gaussian; the cube's tails are heavier, so 5 % is about four of its
            // standard deviations.
            assert!(
                (var_c / predicted - 1.0).abs() < 0.05,
                "v {v}: simulated {var_c}, predicted {predicted}"
            );
            assert!(
                (sum_c / t - v * v * v).abs() < 4.0 * (var_c / t).sqrt(),
                "v {v}"
            );
            // The old scaling, for the record of what it missed.
            let scaled = 9.0 * v.powi(4) * var_o + (18.0 * v * v * s2 + 6.0 * s2 * s2) * var_o;
            assert!(scaled < 0.2 * var_c, "v {v}: {scaled} against {var_c}");
        }
    }

    /// A fit with a negative inertia blames a sensor only where the sensor's reversal would
    /// show: a negative mean force (the load cell), or a spring that falls as it extends (a
    /// reversed encoder turns the spring with the rest). With the force positive and the
    /// spring rising, it names neither: on an independent rig's stick-slip log the fit's
    /// inertia was -2.66 +- 0.52 with a rising spring, and the message blamed the encoder.
    #[test]
    fn an_impossible_inertia_blames_a_sensor_only_where_its_reversal_would_show() {
        use crate::estimate::sim::{simulate, SimSettings};
        let law = crate::model::law::ExpLaw {
            mu_n: 1.1,
            k2_per_mm: 0.24,
            f0_n: 2.0,
        };
        let settings = SimSettings {
            duration_s: 60.0,
            ..SimSettings::default()
        };
        let (log, _) = simulate(law, 15.0, 500.0, &settings).unwrap();
        let fitted = identify(&log, &SensorNoise::default()).unwrap();
        assert!(fitted.sign_fault.is_none());
        let judged = |m: f64, k2: f64, log: &CalibrationLog| {
            let mut id = fitted.clone();
            id.parameters.0[Param::M.index()] = Estimate {
                value: Some(m),
                std: Some(0.01),
            };
            id.parameters.0[Param::K2.index()].value = Some(k2);
            judge_signs(&mut id, log);
            assert_eq!(id.adequacy.status, FitStatus::DoesNotFit);
            id.sign_fault.map(|f| f.likely)
        };
        assert_eq!(judged(-0.1, 0.24, &log), Some(ReversedSensor::Neither));
        assert_eq!(judged(-0.1, -0.24, &log), Some(ReversedSensor::Encoder));
        let mut pulled = log.clone();
        pulled.force_n.iter_mut().for_each(|f| *f = -*f);
        assert_eq!(judged(-0.1, 0.24, &pulled), Some(ReversedSensor::LoadCell));
        let message = SignFault {
            found: vec!["a negative inertia m".into()],
            likely: ReversedSensor::Neither,
        }
        .to_string();
        assert!(
            message.contains("neither sensor") && !message.contains("--position"),
            "{message}"
        );
    }

    /// A covariance whose variances span 26 decades is positive definite when its correlation
    /// matrix is: the check does not hang on the rounding of the largest variance.
    #[test]
    fn a_covariance_is_judged_positive_on_its_correlations_whatever_its_scales() {
        let active: Active = [true, true, true, false, false, false, false, false];
        let sd = [10.0, 1e-12, 0.3];
        let with = |rho: [f64; 3]| {
            let mut c = Mp::zeros();
            let r = [
                [1.0, rho[0], rho[1]],
                [rho[0], 1.0, rho[2]],
                [rho[1], rho[2], 1.0],
            ];
            for a in 0..3 {
                for b in 0..3 {
                    c[(a, b)] = r[a][b] * sd[a] * sd[b];
                }
            }
            c
        };
        // Strongly correlated but definite: the smallest eigenvalue of the correlations is
        // 1 - 0.999 (about 1e-3); of the unscaled matrix about 1e-27, far below the 1e-14
        // rounding of its largest (100).
        assert!(positive_definite(&with([0.999, 0.0, 0.0]), &active));
        // Correlations no covariance has (|rho| > 1, or three that contradict each other).
        assert!(!positive_definite(&with([1.001, 0.0, 0.0]), &active));
        assert!(!positive_definite(&with([0.9, 0.9, -0.9]), &active));
        // A variance that is not positive.
        let mut c = with([0.0, 0.0, 0.0]);
        c[(1, 1)] = -1e-30;
        assert!(!positive_definite(&c, &active));
    }

    #[test]
    fn through_the_parallel_filter_the_inertia_force_matches_the_filtered_acceleration() {
        // S-curve moves: jerk steps every 0.1 s, most between samples (dt 0.01 s), so the
        // acceleration has corners the quintic kernel rounds. With F = m xdd exactly, the
        // force at each sample differs from m times the filtered acceleration by the
        // rounding; through Q after the three-sample mean it matches to the three-sample
        // mean's fourth-order error.
        let dt = 0.01;
        let mut starts = Vec::new();
        let mut jerks = Vec::new();
        for k in 0..40 {
            let t0 = 0.2 + 0.9 * k as f64 + 0.0037 * k as f64;
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            for (i, j) in [800.0, 0.0, -800.0, 0.0, -800.0, 0.0, 800.0, 0.0]
                .iter()
                .enumerate()
            {
                starts.push(t0 + 0.1 * i as f64);
                jerks.push(sign * j);
            }
        }
        let n = 3800;
        let samples: Vec<(f64, f64, f64)> = (0..n)
            .map(|i| jerk_limited(&starts, &jerks, i as f64 * dt))
            .collect();
        let m = 0.25;
        let x: Vec<f64> = samples.iter().map(|s| s.0).collect();
        let force: Vec<f64> = samples.iter().map(|s| m * s.2).collect();
        let peak = force.iter().fold(0.0_f64, |p, f| p.max(f.abs()));
        for window in [21, 43, 85] {
            let diff = Differentiator::new(window);
            let xdd = diff.apply(&x, dt, sg::ACCELERATION);
            let h = diff.half;
            let (_, qt) = force_filter(&acceleration_smoother(&diff));
            let filtered = parallel_filter(&qt, &force[h..h + xdd.len()]);
            let (mut direct, mut parallel) = (0.0_f64, 0.0_f64);
            // m fitted to each (sum a F / sum a^2) over the rows both have.
            let (mut aa, mut af_direct, mut af_parallel) = (0.0, 0.0, 0.0);
            for (i, a) in xdd.iter().enumerate() {
                if filtered[i].is_finite() {
                    direct = direct.max((force[h + i] - m * a).abs());
                    parallel = parallel.max((filtered[i] - m * a).abs());
                    aa += a * a;
                    af_direct += a * force[h + i];
                    af_parallel += a * filtered[i];
                }
            }
            // Pointwise, a corner between samples leaves an error first order in dt (the
            // three-sample mean is not the triangle there); over the rows it averages out.
            assert!(
                direct > 0.05 * peak,
                "window {window}: direct {direct} of {peak}"
            );
            assert!(
                parallel < 0.05 * direct && parallel < 5e-3 * peak,
                "window {window}: parallel {parallel}, direct {direct}"
            );
            let bias_direct = af_direct / aa / m - 1.0;
            let bias_parallel = af_parallel / aa / m - 1.0;
            assert!(
                bias_direct > 2e-3,
                "window {window}: direct m {bias_direct}"
            );
            assert!(
                bias_parallel.abs() < 1e-4,
                "window {window}: parallel m {bias_parallel}"
            );
        }
    }

    #[test]
    fn the_acceleration_smoother_applied_to_the_second_difference_is_the_kernel() {
        for window in [9, 15, 21, 43, 121, 171] {
            let diff = Differentiator::new(window);
            let q = acceleration_smoother(&diff);
            let w = &diff.weights[sg::ACCELERATION];
            let h = diff.half as i64;
            // Q on offsets 2j (j = -(len-1)/2 ..), the second difference over two samples
            // [1, 0, -2, 0, 1] / 4 (at unit spacing the kernel's 1/(2 dt)^2 is 1/4).
            let half = (q.len() / 2) as i64;
            let mut rebuilt = vec![0.0; w.len()];
            for (k, qk) in q.iter().enumerate() {
                let j = k as i64 - half;
                for (d, c) in [(-1_i64, 0.25), (0, -0.5), (1, 0.25)] {
                    rebuilt[(h + 2 * (j + d)) as usize] += qk * c;
                }
            }
            let worst = rebuilt
                .iter()
                .zip(w)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            let scale = w.iter().map(|v| v.abs()).fold(0.0, f64::max);
            assert!(worst < 1e-9 * scale, "window {window}: {worst}");
            // A smoother: unit gain.
            assert!(
                (q.iter().sum::<f64>() - 1.0).abs() < 1e-9,
                "window {window}"
            );
        }
    }
}
