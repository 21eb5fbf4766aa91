//! The sensor noise that identification and the filter weight with: from a log recorded at
//! rest (Allan variance of force, position and the filtered force rate, [`noise_model`]), from
//! the calibration log itself (the scatter of its higher differences, [`DifferenceNoise`]), or
//! given; and which of them a run used ([`GivenNoise::resolve`]).

use serde::Serialize;

use super::allan::{allan_variance, white_noise_fit, AllanPoint, WhiteNoiseFit};
use super::identify::SensorNoise;
use super::log::CalibrationLog;
use super::quantisation::Quantisation;
use super::sg::Differentiator;

/// One channel's noise model.
#[derive(Debug, Clone)]
pub struct ChannelNoise {
    /// Channel name (force, position, force_rate).
    pub name: &'static str,
    /// Unit of the signal (N, mm, N/s).
    pub unit: &'static str,
    /// Unit suffix for JSON keys (n, mm, n_per_s).
    pub key_unit: &'static str,
    /// Allan curve.
    pub allan: Vec<AllanPoint>,
    /// White-noise fit over the first decade.
    pub fit: WhiteNoiseFit,
    /// Sample variance of the channel about its mean.
    pub sample_variance: f64,
}

/// Noise models of a log recorded at rest.
#[derive(Debug, Clone)]
pub struct NoiseModel {
    /// Force, position and force rate.
    pub channels: [ChannelNoise; 3],
    /// The force-rate variance the filter predicts from the force's white noise.
    pub force_rate_predicted_variance: f64,
    /// Sampling interval.
    pub dt_s: f64,
    /// The differentiator window (samples).
    pub window: usize,
}

impl NoiseModel {
    /// The sensor noise for identification: the white-noise variances of force and position.
    pub fn sensor_noise(&self) -> SensorNoise {
        SensorNoise {
            force_variance_n2: self.channels[0].fit.variance,
            position_variance_mm2: self.channels[1].fit.variance,
            position_variance_relative_std: 0.0,
            position_quantisation: None,
        }
    }
}

fn channel(
    name: &'static str,
    unit: &'static str,
    key_unit: &'static str,
    y: &[f64],
    dt: f64,
) -> ChannelNoise {
    let allan = allan_variance(y, dt);
    let fit = white_noise_fit(&allan, dt);
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    let sample_variance =
        y.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (y.len() as f64 - 1.0).max(1.0);
    ChannelNoise {
        name,
        unit,
        key_unit,
        allan,
        fit,
        sample_variance,
    }
}

/// Allan variance of force, position and the filtered force rate of a log at rest.
pub fn noise_model(log: &CalibrationLog) -> NoiseModel {
    let dt = log.dt_s();
    let diff = Differentiator::for_rate(1.0 / dt);
    let force_rate = diff.apply(&log.force_n, dt, super::sg::RATE);
    let force = channel("force", "N", "n", &log.force_n, dt);
    let predicted = diff.noise_variance(super::sg::RATE, force.fit.variance, dt);
    NoiseModel {
        channels: [
            force,
            channel("position", "mm", "mm", &log.position_mm, dt),
            channel("force_rate", "N/s", "n_per_s", &force_rate, dt),
        ],
        force_rate_predicted_variance: predicted,
        dt_s: dt,
        window: diff.window(),
    }
}

/// Most differences [`DifferenceNoise`] keeps per order: the first this many samples of a log
/// (about 11 minutes at 100 Hz) fix the noise to about 0.8 %, in 0.8 MB per channel on any
/// log.
pub const DIFFERENCE_NOISE_SAMPLES: usize = 1 << 16;

/// Fewest samples from which [`DifferenceNoise`] gives an estimate.
pub const DIFFERENCE_NOISE_MIN_SAMPLES: usize = 64;

/// The orders of difference [`DifferenceNoise`] tries.
pub const DIFFERENCE_ORDERS: [usize; 3] = [2, 3, 4];

/// Differences further than this many robust standard deviations from zero are taken as the
/// motion's (a step in acceleration or force) and left out.
pub const DIFFERENCE_CUT_SIGMAS: f64 = 4.0;

/// The least share of the differences the cut may keep: normal noise loses 6e-5 of them, a
/// motion's corners a few percent. A cut that takes more (differences mostly zero, as a
/// quantised encoder's are) is not made.
pub const DIFFERENCE_CUT_KEEPS: f64 = 0.9;

/// The share of a normal variable's variance that lies within +-4 standard deviations
/// (E[z^2; |z| <= 4] / P(|z| <= 4)), which corrects the cut.
pub const DIFFERENCE_CUT_VARIANCE: f64 = 0.998_929;

/// The white-noise variance of one channel from the scatter of its samples' k-th
/// differences, in bounded memory as the samples stream.
///
/// White noise of variance s^2 gives a k-th difference of variance s^2 C(2k, k), whatever the
/// motion, while a smooth motion sampled fast contributes almost nothing to it (at 100 Hz the
/// third difference of a 0.6 Hz, 5 mm sine is 2e-4 mm). The motion's corners (a step in
/// acceleration, or in a force) make a few large differences; a cut at
/// [`DIFFERENCE_CUT_SIGMAS`] robust standard deviations (from the median absolute
/// difference) leaves them out. The motion can only add to the scatter, so of orders 2, 3 and
/// 4 the smallest estimate is taken.
#[derive(Debug, Clone)]
pub struct DifferenceNoise {
    recent: [f64; 5],
    seen: usize,
    differences: [Vec<f32>; 3],
    /// First differences, for the quantisation step ([`lattice_step`]).
    steps: Vec<f32>,
    /// The largest and the smallest value so far, with the differences that are zero because
    /// every sample in them stood at it ([`HeldExtreme`]).
    held: [HeldExtreme; 2],
}

/// An extreme of a signal and the zero differences of samples that all stood at it: a load
/// cell clipped at the end of its range makes them, and they are no noise
/// ([`DifferenceNoise::estimate_without`]).
#[derive(Debug, Clone, Copy, PartialEq)]
struct HeldExtreme {
    value: f64,
    /// Zero differences of orders [`DIFFERENCE_ORDERS`], then first differences.
    zeros: [usize; 4],
}

impl Default for DifferenceNoise {
    fn default() -> Self {
        let held = HeldExtreme {
            value: f64::NAN,
            zeros: [0; 4],
        };
        DifferenceNoise {
            recent: [0.0; 5],
            seen: 0,
            differences: [Vec::new(), Vec::new(), Vec::new()],
            steps: Vec::new(),
            held: [held; 2],
        }
    }
}

/// A white-noise variance estimated from a log's differences ([`DifferenceNoise`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DifferenceEstimate {
    /// The white-noise variance (unit^2).
    pub variance: f64,
    /// Its relative standard deviation (from the differences' count and correlation).
    pub relative_std: f64,
    /// The order of difference that gave it.
    pub order: usize,
    /// How many differences it rests on (after the cut).
    pub differences: usize,
    /// The step of a quantised signal whose quantisation error dominates its noise (the
    /// variance then lies between the differences' estimate and step^2 / 12, see
    /// [`DifferenceNoise`]).
    pub quantum: Option<f64>,
    /// The standard deviation, in steps, of the analog noise a quantised signal carries
    /// before it is read in steps ([`dither_steps`]); 0 for a noiseless quantiser or a signal
    /// that is not quantised.
    pub dither_steps: f64,
}

impl DifferenceNoise {
    /// A new, empty estimator.
    pub fn new() -> DifferenceNoise {
        DifferenceNoise::default()
    }

    /// Adds the next sample.
    pub fn push(&mut self, y: f64) {
        if self.seen > DIFFERENCE_NOISE_SAMPLES {
            return;
        }
        self.recent.rotate_right(1);
        self.recent[0] = y;
        self.seen += 1;
        if self.seen > 1 {
            self.steps.push((self.recent[0] - self.recent[1]) as f32);
        }
        for (slot, &k) in DIFFERENCE_ORDERS.iter().enumerate() {
            if self.seen > k {
                // Single precision: a difference's own rounding, 6e-8 of it, is far below
                // the estimate's spread.
                self.differences[slot].push(difference(&self.recent, k) as f32);
            }
        }
        // The samples standing at an extreme with this one.
        let standing = self.recent[..self.seen.min(5)]
            .iter()
            .take_while(|&&v| v == y)
            .count();
        for (h, sign) in self.held.iter_mut().zip([1.0, -1.0]) {
            if self.seen == 1 || sign * (y - h.value) > 0.0 {
                *h = HeldExtreme {
                    value: y,
                    zeros: [0; 4],
                };
            }
            if h.value == y {
                for (slot, &k) in DIFFERENCE_ORDERS.iter().enumerate() {
                    h.zeros[slot] += usize::from(self.seen > k && standing > k);
                }
                h.zeros[3] += usize::from(self.seen > 1 && standing > 1);
            }
        }
    }

    /// [`DifferenceNoise::estimate`] without the differences of samples that all stood at
    /// one of `values` where it is the signal's largest or smallest: a force clipped at the
    /// end of the load cell's range stands still while the rod moves, and its zero
    /// differences counted as noise made the force variance low (on the paper spec's log
    /// clipped at 60 N, 1.58e-2 against 1.71e-2 N^2).
    pub fn estimate_without(&self, values: &[f64]) -> Option<DifferenceEstimate> {
        let held: Vec<&HeldExtreme> = self
            .held
            .iter()
            .filter(|h| values.contains(&h.value))
            .collect();
        if held.is_empty() {
            return self.estimate();
        }
        let drop = |d: &[f32], slot: usize| -> Vec<f32> {
            let mut zeros: usize = held.iter().map(|h| h.zeros[slot]).sum();
            d.iter()
                .copied()
                .filter(|&v| {
                    let left_out = v == 0.0 && zeros > 0;
                    zeros -= usize::from(left_out);
                    !left_out
                })
                .collect()
        };
        let without = DifferenceNoise {
            recent: self.recent,
            seen: self.seen,
            differences: [0, 1, 2].map(|slot| drop(&self.differences[slot], slot)),
            steps: drop(&self.steps, 3),
            held: self.held,
        };
        without.estimate()
    }

    /// The estimate, or `None` on fewer than [`DIFFERENCE_NOISE_MIN_SAMPLES`] samples or
    /// non-finite ones.
    pub fn estimate(&self) -> Option<DifferenceEstimate> {
        if self.seen < DIFFERENCE_NOISE_MIN_SAMPLES {
            return None;
        }
        let white = DIFFERENCE_ORDERS
            .iter()
            .zip(&self.differences)
            .filter_map(|(&k, d)| order_estimate(d, k))
            .min_by(|a, b| a.variance.total_cmp(&b.variance))?;
        // A quantised signal whose steps outweigh its noise: the error is uniform over a step
        // (variance step^2 / 12) while the signal moves by steps each sample, zero at rest and
        // a slow sawtooth in between, which the differences count low. The midpoint of the two
        // is the variance the filter and the reports use, its half-range added to the
        // relative standard deviation; identification weights its kernels by the step itself
        // (`position_quantisation`, [`super::quantisation`]).
        // The differences of a quantised ramp count its error up to twice the uniform error's
        // variance (a rod moving half a step a sample steps every other sample, and its
        // second differences are +-q, twice white noise's of variance q^2 / 12): up to
        // [`QUANTISED_MAX_RATIO`] of it, the steps still make the noise, and the step is
        // reported with the differences' estimate.
        // A quantised signal with analog noise of its own before the steps (an ADC reading
        // an LVDT): its error is that noise plus the steps' error, of variance
        // step^2 / 12 + sigma^2, and the noise turns the steps' sawtooth into white noise
        // ([`super::quantisation`]). The differences' estimate then counts it low (at
        // sigma = 0.2 steps, 0.6 of it on the independent rig's 15.6 um encoder): the
        // variance is taken from sigma, read from how much more the readings move than the
        // motion ([`dither_steps`]).
        let lattice = lattice_step(&self.steps)
            .filter(|&step| white.variance <= QUANTISED_MAX_RATIO * step * step / 12.0);
        let dither = lattice.map_or(0.0, |step| dither_steps(&self.steps, step));
        match lattice {
            Some(step) if dither >= DITHER_MIN_STEPS => {
                let total = step * step * (1.0 / 12.0 + dither * dither);
                // The variance's share that sigma carries, known to DITHER_RELATIVE_STD.
                let spread = 2.0 * DITHER_RELATIVE_STD * dither * dither * step * step / total;
                Some(DifferenceEstimate {
                    variance: total,
                    relative_std: white.relative_std.hypot(spread),
                    quantum: Some(step),
                    dither_steps: dither,
                    ..white
                })
            }
            Some(step) if step * step / 12.0 > white.variance => {
                let uniform = step * step / 12.0;
                let spread = (uniform - white.variance) / (uniform + white.variance);
                Some(DifferenceEstimate {
                    variance: 0.5 * (uniform + white.variance),
                    relative_std: white.relative_std.hypot(spread),
                    quantum: Some(step),
                    ..white
                })
            }
            Some(step) if white.variance <= QUANTISED_MAX_RATIO * step * step / 12.0 => {
                Some(DifferenceEstimate {
                    quantum: Some(step),
                    ..white
                })
            }
            _ => Some(white),
        }
    }

    /// The estimate of a whole series.
    pub fn of(y: &[f64]) -> Option<DifferenceEstimate> {
        let mut d = DifferenceNoise::new();
        y.iter().for_each(|&v| d.push(v));
        d.estimate()
    }
}

/// The most the differences' white-noise estimate of a signal on a lattice may exceed the
/// uniform error's variance q^2 / 12 by, as a factor, for its steps to be taken as its noise
/// ([`DifferenceNoise::estimate`]). Beyond it the signal carries noise of its own of more
/// than about a third of a step, which dithers the steps into white noise.
pub const QUANTISED_MAX_RATIO: f64 = 2.0;

/// The least analog noise before the steps (standard deviation, in steps) taken as such
/// ([`dither_steps`]): below it the steps' sawtooth keeps nine tenths of its first harmonic's
/// power, and every one of 97 noiseless encoder logs of the independent rig's sweep reads 0.
pub const DITHER_MIN_STEPS: f64 = 0.05;

/// How well [`dither_steps`] reads the analog noise before the steps, relative: on the
/// independent rig's encoder draws 1, 5, 7 and 30 with 0.2 steps of noise it read 0.18 to
/// 0.22.
pub const DITHER_RELATIVE_STD: f64 = 0.1;

/// The samples over which [`dither_steps`] smooths the readings into the motion (a quintic
/// Savitzky-Golay smoother).
pub const DITHER_SMOOTHING_SAMPLES: usize = 33;

/// The standard deviation, in steps, of the analog noise a signal read in steps of `step`
/// carries before it is read, from its first differences `steps`.
///
/// A reading y = Q(x + n) of a position x with noise n of standard deviation s steps moves,
/// from one sample to the next, by |Delta y| whose mean over the reading's phase in a step is
/// exactly E|a + d| (the mean of a folded normal), where a is the motion's own move in steps
/// and d ~ N(0, 2 s^2): a noiseless encoder moves by the motion's steps only, a noisy one
/// flickers across the step it rests near. With a from the readings smoothed over
/// [`DITHER_SMOOTHING_SAMPLES`], s is the noise for which the model's total move matches the
/// readings' (0 where the readings move no more than the motion).
pub fn dither_steps(steps: &[f32], step: f64) -> f64 {
    let half = DITHER_SMOOTHING_SAMPLES / 2;
    if steps.len() < DITHER_SMOOTHING_SAMPLES + 2 || step.is_nan() || step <= 0.0 {
        return 0.0;
    }
    // The readings in steps, from the first one.
    let mut y = Vec::with_capacity(steps.len() + 1);
    y.push(0.0);
    let mut at = 0.0;
    for d in steps {
        at += f64::from(*d) / step;
        y.push(at);
    }
    let weights = super::sg::quintic_smoother(half);
    let smooth: Vec<f64> = y
        .windows(weights.len())
        .map(|w| w.iter().zip(&weights).map(|(a, b)| a * b).sum())
        .collect();
    // The motion's move between smoothed samples j and j + 1 (readings half + j and
    // half + j + 1) and the readings' own move there.
    let moves: Vec<(f64, f64)> = smooth
        .windows(2)
        .enumerate()
        .map(|(j, w)| ((w[1] - w[0]).abs(), (y[half + j + 1] - y[half + j]).abs()))
        .collect();
    let observed: f64 = moves.iter().map(|m| m.1).sum();
    let expected = |s: f64| -> f64 {
        let sd = std::f64::consts::SQRT_2 * s;
        moves
            .iter()
            .map(|&(a, _)| {
                if sd <= 0.0 {
                    a
                } else {
                    a * statrs::function::erf::erf(a / (sd * std::f64::consts::SQRT_2))
                        + sd * (2.0 / std::f64::consts::PI).sqrt()
                            * (-a * a / (2.0 * sd * sd)).exp()
                }
            })
            .sum::<f64>()
            - observed
    };
    let top = 2.0;
    if expected(0.0) >= 0.0 {
        return 0.0;
    }
    if expected(top) <= 0.0 {
        return top;
    }
    let mut convergency = roots::SimpleConvergency {
        eps: 1e-4,
        max_iter: 60,
    };
    roots::find_root_brent(0.0, top, expected, &mut convergency).unwrap_or(0.0)
}

/// How well identification's model of a quantised position's error through its kernels
/// ([`super::quantisation`]) knows the error's power, relative: the model against the true
/// error of the independent rig's encoder draws (docs/CALIBRATION.md, "A quantised position
/// through the kernels"). Carried into the estimates as the position variance's uncertainty.
pub const QUANTISATION_MODEL_RELATIVE_STD: f64 = 0.2;

/// The step of a quantised signal: the least nonzero first difference, when at least 99 % of
/// them are whole multiples of it (within 5 % of a step). None for a signal that is not
/// quantised (a log written with a fixed number of decimals is, at a step far below its
/// noise).
fn lattice_step(steps: &[f32]) -> Option<f64> {
    let largest = steps.iter().fold(0.0_f32, |m, v| m.max(v.abs()));
    if largest == 0.0 || !largest.is_finite() {
        return None;
    }
    // Below a millionth of the largest, a difference is the single precision's rounding.
    let floor = 1e-6 * largest;
    let step = steps
        .iter()
        .map(|v| v.abs())
        .filter(|&v| v > floor)
        .fold(f32::INFINITY, f32::min);
    if !step.is_finite() {
        return None;
    }
    let on_lattice = steps
        .iter()
        .filter(|&&v| {
            let r = f64::from(v) / f64::from(step);
            (r - r.round()).abs() < 0.05
        })
        .count();
    (on_lattice as f64 >= 0.99 * steps.len() as f64).then_some(f64::from(step))
}

/// The k-th difference of the newest k + 1 samples (`recent[0]` newest).
fn difference(recent: &[f64; 5], k: usize) -> f64 {
    (0..=k)
        .map(|j| {
            let sign = if j % 2 == 0 { 1.0 } else { -1.0 };
            sign * binomial(k, j) * recent[j]
        })
        .sum()
}

fn binomial(n: usize, k: usize) -> f64 {
    (0..k).fold(1.0, |c, i| c * (n - i) as f64 / (i + 1) as f64)
}

/// The white-noise variance from one order's differences (see [`DifferenceNoise`]).
fn order_estimate(d: &[f32], k: usize) -> Option<DifferenceEstimate> {
    if d.len() < DIFFERENCE_NOISE_MIN_SAMPLES / 2 || d.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let d: Vec<f64> = d.iter().map(|&v| f64::from(v)).collect();
    let mut abs: Vec<f64> = d.iter().map(|v| v.abs()).collect();
    let mid = abs.len() / 2;
    let (_, median, _) = abs.select_nth_unstable_by(mid, f64::total_cmp);
    // The median absolute value of a normal variable is 0.6745 of its standard deviation.
    let robust_std = *median / 0.674_489_750_196_081_7;
    let cut = DIFFERENCE_CUT_SIGMAS * robust_std;
    let (sum, kept) = d
        .iter()
        .filter(|v| v.abs() <= cut)
        .fold((0.0, 0usize), |(s, n), v| (s + v * v, n + 1));
    let (sum, kept, correction) = if kept as f64 >= DIFFERENCE_CUT_KEEPS * d.len() as f64 {
        (sum, kept, DIFFERENCE_CUT_VARIANCE)
    } else {
        // Not normal: most differences are zero or nearly (a quantised encoder: at rest, or
        // moving less than a step a sample), and the cut would take the steps for the
        // motion's. All are kept.
        (d.iter().map(|v| v * v).sum(), d.len(), 1.0)
    };
    if kept == 0 {
        return None;
    }
    let gain = binomial(2 * k, k);
    // The k-th differences of white noise are correlated over k lags:
    // rho_l = (-1)^l C(2k, k + l) / C(2k, k); the mean square's variance is
    // 2 sum_l rho_l^2 / n of its square.
    let rho2: f64 = (1..=k)
        .map(|l| (binomial(2 * k, k + l) / gain).powi(2))
        .sum::<f64>()
        * 2.0
        + 1.0;
    Some(DifferenceEstimate {
        variance: sum / kept as f64 / correction / gain,
        relative_std: (2.0 * rho2 / kept as f64).sqrt(),
        order: k,
        differences: kept,
        quantum: None,
        dither_steps: 0.0,
    })
}

/// The sensor noise of a calibration log from its own samples ([`DifferenceNoise`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LogNoise {
    /// The force's white noise (N^2).
    pub force: DifferenceEstimate,
    /// The position's white noise (mm^2).
    pub position: DifferenceEstimate,
}

/// [`LogNoise`] accumulated as a log's samples stream.
#[derive(Debug, Clone, Default)]
pub struct LogNoiseSurvey {
    force: DifferenceNoise,
    position: DifferenceNoise,
}

impl LogNoiseSurvey {
    /// Adds the next sample.
    pub fn push(&mut self, force_n: f64, position_mm: f64) {
        self.force.push(force_n);
        self.position.push(position_mm);
    }

    /// The estimate (`None` on too short a log).
    pub fn estimate(&self) -> Option<LogNoise> {
        self.estimate_without_force(&[])
    }

    /// The estimate, without the force's differences where it stood at one of `clips_n`
    /// (a load cell clipped at an end of its range, [`DifferenceNoise::estimate_without`]).
    pub fn estimate_without_force(&self, clips_n: &[f64]) -> Option<LogNoise> {
        Some(LogNoise {
            force: self.force.estimate_without(clips_n)?,
            position: self.position.estimate()?,
        })
    }
}

/// [`LogNoise`] of a log in memory, its clipped force readings left out
/// ([`LogNoiseSurvey::estimate_without_force`]).
pub fn log_noise(log: &CalibrationLog) -> Option<LogNoise> {
    let mut s = LogNoiseSurvey::default();
    for (&f, &x) in log.force_n.iter().zip(&log.position_mm) {
        s.push(f, x);
    }
    let clips: Vec<f64> = log
        .reading()
        .force_clips
        .iter()
        .flatten()
        .map(|c| c.force_n)
        .collect();
    s.estimate_without_force(&clips)
}

/// The sensor noise a user gave (`--noise`, `--force-variance`, `--position-variance`); a
/// channel left out is taken from the log ([`GivenNoise::resolve`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct GivenNoise {
    /// Force variance (N^2), if given.
    pub force_variance_n2: Option<f64>,
    /// Position variance (mm^2), if given.
    pub position_variance_mm2: Option<f64>,
}

impl From<SensorNoise> for GivenNoise {
    fn from(n: SensorNoise) -> GivenNoise {
        GivenNoise {
            force_variance_n2: Some(n.force_variance_n2),
            position_variance_mm2: Some(n.position_variance_mm2),
        }
    }
}

/// Where a channel's noise came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum NoiseOrigin {
    /// Given by the user.
    Given,
    /// Estimated from the log's own differences ([`DifferenceNoise`]).
    Log,
    /// The paper's sensors (a log too short to estimate from).
    Paper,
}

/// How far a given variance may exceed the log's own estimate (relative, besides four of the
/// estimate's standard deviations) before [`GivenNoise::resolve`] warns. A position noise
/// stated too high makes identification's errors-in-variables correction take out signal:
/// at a window where noise is three quarters of the information, 10 % too much noise removes
/// 30 % of the signal's.
pub const GIVEN_NOISE_EXCESS: f64 = 0.1;

/// How far below the log's own estimate a given variance may be before
/// [`GivenNoise::resolve`] warns (the log's estimate also holds whatever of the motion its
/// differences keep, so only a large shortfall is reported).
pub const GIVEN_NOISE_SHORTFALL: f64 = 0.5;

/// The sensor noise a run used, with where each channel's came from.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ResolvedNoise {
    /// The variances used.
    pub noise: SensorNoise,
    /// Where the force's came from.
    pub force_origin: NoiseOrigin,
    /// Where the position's came from.
    pub position_origin: NoiseOrigin,
    /// The log's own estimate.
    pub log: Option<LogNoise>,
    /// Given variances that the log contradicts.
    pub warnings: Vec<String>,
}

impl GivenNoise {
    /// Resolves each channel: the given variance, else the log's own estimate, else the
    /// paper's sensors. A given variance well above the log's estimate (its samples scatter
    /// less than that: [`GIVEN_NOISE_EXCESS`]) or far below it ([`GIVEN_NOISE_SHORTFALL`])
    /// is kept and warned about.
    pub fn resolve(&self, log: Option<&LogNoise>) -> ResolvedNoise {
        let paper = SensorNoise::default();
        let mut warnings = Vec::new();
        let mut channel = |given: Option<f64>,
                           estimate: Option<&DifferenceEstimate>,
                           paper: f64,
                           what: &str,
                           unit: &str,
                           flag: &str| match (given, estimate) {
            (Some(g), e) => {
                if let Some(e) = e {
                    let excess = GIVEN_NOISE_EXCESS + 4.0 * e.relative_std;
                    let consequence = if g > e.variance * (1.0 + excess) {
                        Some(
                            "too high a noise makes identification over-correct (m and the \
                             damping come out too high)",
                        )
                    } else if g < e.variance * GIVEN_NOISE_SHORTFALL {
                        Some("the reported standard deviations may be too small")
                    } else {
                        None
                    };
                    if let Some(consequence) = consequence {
                        warnings.push(format!(
                            "the given {what} noise variance {g:.4e} {unit} is {:.2} times what \
                             the log's samples scatter by ({:.4e} {unit}, from their \
                             differences); {consequence}: drop {flag} to use the log's own",
                            g / e.variance,
                            e.variance
                        ));
                    }
                }
                (g, NoiseOrigin::Given)
            }
            (None, Some(e)) => (e.variance, NoiseOrigin::Log),
            (None, None) => (paper, NoiseOrigin::Paper),
        };
        let (force, force_origin) = channel(
            self.force_variance_n2,
            log.map(|l| &l.force),
            paper.force_variance_n2,
            "force",
            "N^2",
            "--force-variance/--noise",
        );
        let (position, position_origin) = channel(
            self.position_variance_mm2,
            log.map(|l| &l.position),
            paper.position_variance_mm2,
            "position",
            "mm^2",
            "--position-variance/--noise",
        );
        // How well the position's variance is known, for identification to carry into its
        // estimates: the log's estimate's spread (a given figure is taken as exact).
        // A position read in steps whose error is its noise: identification takes what its
        // kernels pass of the steps' error from the speeds the log moves at, to within
        // [`QUANTISATION_MODEL_RELATIVE_STD`].
        let position_quantisation = match (position_origin, log) {
            (NoiseOrigin::Log, Some(l)) => l
                .position
                .quantum
                .map(|step| Quantisation::new(step, l.position.dither_steps)),
            _ => None,
        };
        let position_variance_relative_std = match (position_origin, log) {
            (NoiseOrigin::Log, Some(l)) if position_quantisation.is_some() => l
                .position
                .relative_std
                .hypot(QUANTISATION_MODEL_RELATIVE_STD),
            (NoiseOrigin::Log, Some(l)) => l.position.relative_std,
            _ => 0.0,
        };
        ResolvedNoise {
            noise: SensorNoise {
                force_variance_n2: force.max(MIN_NOISE_VARIANCE),
                position_variance_mm2: position.max(MIN_NOISE_VARIANCE),
                position_variance_relative_std,
                position_quantisation,
            },
            force_origin,
            position_origin,
            log: log.copied(),
            warnings,
        }
    }
}

/// The least variance (unit^2) a run weights with: a noise-free log (a simulation written
/// exactly) still gets finite weights.
pub const MIN_NOISE_VARIANCE: f64 = 1e-18;

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic normal generator (Box-Muller on a 64-bit LCG), for tests only.
    fn normals(seed: u64, n: usize) -> Vec<f64> {
        let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
        let mut uniform = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        (0..n)
            .map(|_| {
                let (u, v) = (uniform(), uniform());
                (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
            })
            .collect()
    }

    #[test]
    fn a_clipped_signals_standstill_is_not_counted_as_noise() {
        // A ramp with white noise of variance 0.09, read through a load cell that clips at 40:
        // the last fifth of the samples stand at 40 exactly.
        let n = 20_000;
        let noise = normals(7, n);
        let y: Vec<f64> = (0..n)
            .map(|i| (50.0 * i as f64 / n as f64 + 0.3 * noise[i]).min(40.0))
            .collect();
        let mut d = DifferenceNoise::new();
        for &v in &y {
            d.push(v);
        }
        let with = d.estimate().unwrap();
        let without = d.estimate_without(&[40.0]).unwrap();
        let z = |e: &DifferenceEstimate| (e.variance - 0.09) / (0.09 * e.relative_std);
        // Counted, the standstill's zero differences pull the variance down by about a fifth.
        assert!(z(&with) < -5.0, "{} (z {})", with.variance, z(&with));
        assert!(
            z(&without).abs() < 3.0,
            "{} (z {})",
            without.variance,
            z(&without)
        );
        // A value that is not an extreme leaves nothing out.
        assert_eq!(d.estimate_without(&[20.0]), Some(with));
    }

    #[test]
    fn the_differences_of_white_noise_give_its_variance_within_their_stated_spread() {
        let mut z = Vec::new();
        for seed in 0..20 {
            let e = DifferenceNoise::of(
                &normals(seed, 20_000)
                    .iter()
                    .map(|v| 0.3 * v)
                    .collect::<Vec<_>>(),
            )
            .unwrap();
            z.push((e.variance / 0.09 - 1.0) / e.relative_std);
        }
        let mean = z.iter().sum::<f64>() / z.len() as f64;
        let rms = (z.iter().map(|v| v * v).sum::<f64>() / z.len() as f64).sqrt();
        // The minimum over three strongly correlated orders sits a little low.
        assert!(mean.abs() < 1.0, "mean z {mean}");
        assert!(rms < 1.6 && rms > 0.4, "rms z {rms}");
    }

    #[test]
    fn a_motion_with_steps_in_acceleration_leaves_the_position_noise_estimate_within_two_percent() {
        // Point-to-point moves at 100 Hz: acceleration +-8 mm/s^2 in steps, noise 1 um rms.
        let dt = 0.01;
        let noise = normals(7, 30_000);
        let (mut x, mut v) = (0.0_f64, 0.0_f64);
        let y: Vec<f64> = (0..30_000)
            .map(|i| {
                let phase = (i as f64 * dt) % 4.0;
                let a = match phase {
                    p if p < 1.0 => 8.0,
                    p if p < 2.0 => -8.0,
                    p if p < 3.0 => -8.0,
                    _ => 8.0,
                };
                v += a * dt;
                x += v * dt;
                x + 1e-3 * noise[i]
            })
            .collect();
        let e = DifferenceNoise::of(&y).unwrap();
        assert!(
            (e.variance / 1e-6 - 1.0).abs() < 0.02,
            "variance {} against 1e-6",
            e.variance
        );
    }

    #[test]
    fn a_quantised_encoder_without_noise_gives_its_quantisation_variance() {
        // A slow ramp read by a 5 um encoder: the error is uniform over a step, variance
        // step^2 / 12 while it moves; most second differences are zero.
        let step = 0.005;
        let y: Vec<f64> = (0..20_000)
            .map(|i| {
                let x = 2.0 + 1.5 * (i as f64 * 0.01 * 0.3).sin();
                (x / step).round() * step
            })
            .collect();
        let e = DifferenceNoise::of(&y).unwrap();
        assert_eq!(e.quantum.map(|q| (q / step - 1.0).abs() < 1e-6), Some(true));
        let uniform = step * step / 12.0;
        assert!(
            e.variance > 0.5 * uniform && e.variance < 1.5 * uniform,
            "variance {} against {uniform}",
            e.variance
        );
    }

    #[test]
    fn the_noise_before_an_encoders_steps_is_read_from_how_much_more_the_readings_move() {
        // A 5 um encoder at 200 Hz on 4 mm sweeps of half a cosine, 5 s each, with rests of
        // 3 s between them, read with analog noise of 0, 0.1, 0.2 and 0.3 steps before the
        // steps: the noise is read within 15 % (none for the noiseless encoder), and the
        // variance is the steps' and the noise's within 15 %.
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let step = 0.005;
        for (seed, dither) in [(1, 0.0), (2, 0.1), (3, 0.2), (4, 0.3)] {
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            let noise = Normal::new(0.0, dither * step + 1e-300).unwrap();
            let y: Vec<f64> = (0..60_000)
                .map(|i| {
                    let t = i as f64 * 0.005;
                    // Out over 5 s, a rest of 3 s, back over 5 s, a rest of 3 s.
                    let cycle = t % 16.0;
                    let phase = (cycle.min(5.0) + (cycle - 8.0).clamp(0.0, 5.0)) / 5.0
                        * std::f64::consts::PI;
                    // Each sweep a little longer: the rests fall at every phase of a step.
                    let x = 3.0 + (2.0 + 0.0037 * (t / 16.0).floor()) * phase.cos();
                    let n = if dither > 0.0 {
                        noise.sample(&mut rng)
                    } else {
                        0.0
                    };
                    ((x + n) / step).round() * step
                })
                .collect();
            let e = DifferenceNoise::of(&y).unwrap();
            // At 0.3 steps the differences exceed twice the steps' variance: the noise is
            // then taken as white, from the differences alone.
            if dither < 0.3 {
                assert_eq!(
                    e.quantum.map(|q| (q / step - 1.0).abs() < 1e-6),
                    Some(true),
                    "dither {dither}: {e:?}"
                );
            }
            if dither == 0.0 {
                assert_eq!(e.dither_steps, 0.0);
            } else {
                if e.quantum.is_some() {
                    assert!(
                        (e.dither_steps / dither - 1.0).abs() < 0.15,
                        "dither {} against {dither}",
                        e.dither_steps
                    );
                }
                let total = step * step * (1.0 / 12.0 + dither * dither);
                assert!(
                    (e.variance / total - 1.0).abs() < 0.15,
                    "variance {} against {total}",
                    e.variance
                );
            }
        }
    }

    #[test]
    fn an_unchanging_quantised_signal_gives_zero_and_the_resolution_floors_it() {
        let e = DifferenceNoise::of(&[2.5; 200]).unwrap();
        assert_eq!(e.variance, 0.0);
        let log = LogNoise {
            force: e,
            position: e,
        };
        let r = GivenNoise::default().resolve(Some(&log));
        assert_eq!(r.noise.position_variance_mm2, MIN_NOISE_VARIANCE);
        assert_eq!(r.position_origin, NoiseOrigin::Log);
    }

    #[test]
    fn a_given_noise_far_above_the_logs_is_kept_and_warned_about() {
        let e = DifferenceEstimate {
            variance: 1e-4,
            relative_std: 0.01,
            order: 3,
            differences: 30_000,
            quantum: None,
            dither_steps: 0.0,
        };
        let log = LogNoise {
            force: DifferenceEstimate {
                variance: 0.017,
                ..e
            },
            position: e,
        };
        let given = GivenNoise {
            force_variance_n2: None,
            position_variance_mm2: Some(0.01),
        };
        let r = given.resolve(Some(&log));
        assert_eq!(r.noise.position_variance_mm2, 0.01);
        assert_eq!(r.noise.force_variance_n2, 0.017);
        assert_eq!(r.force_origin, NoiseOrigin::Log);
        assert_eq!(r.warnings.len(), 1);
        assert!(r.warnings[0].contains("100.00 times"), "{}", r.warnings[0]);
        // Within the allowance: no warning.
        let close = GivenNoise {
            position_variance_mm2: Some(1.1e-4),
            ..given
        };
        assert!(close.resolve(Some(&log)).warnings.is_empty());
        // No log estimate: the paper's sensors.
        let none = GivenNoise::default().resolve(None);
        assert_eq!(none.noise, SensorNoise::default());
        assert_eq!(none.position_origin, NoiseOrigin::Paper);
    }
}
