//! Twin logs: simulated copies of a calibration log with known truth, on which the filter's
//! own bias in its constants is measured and then taken out of the log's estimates.
//!
//! The EKF takes the measured force rate as its input and treats that input's noise as
//! process noise. Where the force noise dominates the dynamics (a light transmission, a slow
//! run), the filter's constants come out biased: on a light transmission's ramp-hold log, k2
//! 0.3 to 1.2 % low, 3 to 5 of its own standard deviations, where identification of the same
//! log is within 0.1 %. The bias is a property of the filter on this motion at these noise
//! levels, so it is measured the way a simulation study would, on the log's own motion:
//!
//! - **Truth:** the transmission identification found (the filter's start), with the
//!   filter's held states at their held values.
//! - **Motion:** the logged position smoothed over identification's window (zero phase), then
//!   through a fast third-order Butterworth low-pass ([`MotionFilter`]). Its x, xd and xdd are
//!   the state of one linear system, so they are exact derivatives of one smooth motion, as
//!   the model requires; the smoothing before it keeps the motion's shape and removes the
//!   noise. A causal low-pass alone at the window's band did neither: on a heavy
//!   transmission's ramp-hold it weakened the accelerations and moved M's bias by 1.5 %.
//! - **Force:** m xdd + d1 xd + d2 xd^3 + d0 s + mu exp(k2 x) + F0 along that motion, with the
//!   friction's sign s as below.
//! - **Noise:** fresh white noise at the sensors' variances, a different seed per twin.
//! - **Friction:** d0 in the sliding direction until the motion's velocity reaches zero (the
//!   stop), none from there until the velocity leaves the band its smoothed noise keeps it in;
//!   the start is then placed where the velocity last left zero. A rod's friction turns on
//!   when it starts and off when it stops; a twin whose friction switched at the band (until
//!   2026-11-29) dropped it before each stop and picked it up late, and did not identify like
//!   the log (reduced chi-square 13.8 on a simulated Table I ramp-hold at the log's window).
//!
//! Each twin is identified as the log was (at its window), and its friction stage and filter
//! run as on the log, from the twin's own identification (the filter's start and the stage's
//! model alike): its identification's error is correlated with its noise as the log's is with
//! the log's. Each twin's error in k2 is known. Their mean is the bias; their scatter beyond the
//! filter's own standard deviation is what identification's error does to the filter's k2.
//! The pipeline subtracts the bias and adds its uncertainty and that excess scatter to the
//! variance ([`TwinBias::new`]).

use std::collections::VecDeque;

use nalgebra::{Matrix3, Matrix4, Vector3};
use rand::{rngs::StdRng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use serde::Serialize;

use super::log::Sample;
use super::sg;
use crate::model::ExpLaw;

/// The transmission a twin is simulated with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwinTruth {
    /// Inertia (N s^2/mm).
    pub m_n_s2_per_mm: f64,
    /// Coulomb friction (N).
    pub d0_n: f64,
    /// The friction that grows with the spring: mu_f exp(k2 x) in the sliding direction (N).
    pub mu_f_n: f64,
    /// Linear damping (N s/mm).
    pub d1_n_s_per_mm: f64,
    /// Cubic damping (N s^3/mm^3).
    pub d2_n_s3_per_mm3: f64,
    /// The spring law.
    pub law: ExpLaw,
}

/// A third-order Butterworth low-pass of the logged position, discretised exactly for an
/// input held over each sample. Its state [x, xd, xdd] is one smooth motion.
#[derive(Debug, Clone)]
pub struct MotionFilter {
    phi: Matrix3<f64>,
    gamma: Vector3<f64>,
    state: Option<Vector3<f64>>,
}

impl MotionFilter {
    /// Cut-off `cutoff_hz` (at most a fifth of the sampling rate) for samples every `dt_s`.
    pub fn new(cutoff_hz: f64, dt_s: f64) -> MotionFilter {
        let w = std::f64::consts::TAU * cutoff_hz.min(0.2 / dt_s);
        // x''' = w^3 (u - x) - 2 w^2 x' - 2 w x'': poles of s^3 + 2w s^2 + 2w^2 s + w^3.
        let mut m = Matrix4::zeros();
        m[(0, 1)] = 1.0;
        m[(1, 2)] = 1.0;
        m[(2, 0)] = -w * w * w;
        m[(2, 1)] = -2.0 * w * w;
        m[(2, 2)] = -2.0 * w;
        m[(2, 3)] = w * w * w;
        let e = (m * dt_s).exp();
        MotionFilter {
            phi: e.fixed_view::<3, 3>(0, 0).into_owned(),
            gamma: e.fixed_view::<3, 1>(0, 3).into_owned(),
            state: None,
        }
    }

    /// Takes the next logged position; returns [x, xd, xdd] of the smooth motion (mm, mm/s,
    /// mm/s^2). It starts at rest at the first position.
    pub fn push(&mut self, position_mm: f64) -> [f64; 3] {
        let s = match self.state {
            None => Vector3::new(position_mm, 0.0, 0.0),
            Some(s) => self.phi * s + self.gamma * position_mm,
        };
        self.state = Some(s);
        [s[0], s[1], s[2]]
    }
}

/// Makes one twin's samples from the log's as they arrive, lagging them by half a window.
///
/// The logged position is first smoothed over identification's window (the zero-phase
/// Savitzky-Golay position kernel, every s-th sample of long windows, as the friction stage
/// does), which keeps the motion's shape and lag-free timing but not exact derivatives. A fast
/// third-order Butterworth ([`MotionFilter`], cut-off [`TWIN_MOTION_CUTOFF_WINDOWS`] over the
/// window, far above the motion it passes) then makes x, xd and xdd one motion.
#[derive(Debug, Clone)]
pub struct TwinSource {
    truth: TwinTruth,
    weights: Vec<f64>,
    /// Where the weights may be nonzero ([`sg::Differentiator::taps`]).
    taps: (usize, usize),
    stride: usize,
    reach: usize,
    positions: sg::SlidingWindow,
    waiting: VecDeque<(usize, f64)>,
    /// The centre (sample index) of the last full window, and its smoothed position.
    last: Option<(usize, f64)>,
    motion: MotionFilter,
    band_mm_per_s: f64,
    /// The friction's sign now: that of the sliding direction, 0 at rest.
    sliding: f64,
    /// The motion at rest, held back (up to `rest_lookback` samples) until it is known whether
    /// a start has begun among them.
    rest: VecDeque<(usize, f64, [f64; 3])>,
    rest_lookback: usize,
    rng: StdRng,
    force_std_n: f64,
    position_std_mm: f64,
    /// Twin samples ready, in order, with their index in the log.
    pub out: VecDeque<(usize, Sample)>,
}

/// The most points of the twin's smoothing kernel (longer windows use every s-th sample).
pub const TWIN_KERNEL_POINTS: usize = 701;

/// The twin motion's Butterworth cut-off, in cycles per smoothing window. Up to one cycle per
/// window, where the smoothing kernel passes the motion, its gain is within 0.07 % of 1 and
/// its delay constant; above, it removes what the kernel's side lobes let through of the
/// position noise. At 1.5 (a filter that also shapes the motion) M's twin bias was 1.5 %
/// off on heavy ramp-hold runs; at 8 the side lobes' noise made a jerky motion whose M bias
/// was 3 % off on sines; k2's bias moved little over that range.
pub const TWIN_MOTION_CUTOFF_WINDOWS: f64 = 3.0;

/// How far back a twin's start may be placed, in smoothing windows: the smoothed velocity of
/// a move that starts gently (a quintic ramp's grows with the square of the time) leaves the
/// noise's band up to a window or more after the move began.
pub const REST_LOOKBACK_WINDOWS: usize = 4;

impl TwinSource {
    /// A twin of a log sampled every `dt_s`, smoothed over `window` samples, with white
    /// noise of the given variances drawn from `seed`.
    pub fn new(
        truth: TwinTruth,
        window: usize,
        dt_s: f64,
        force_variance_n2: f64,
        position_variance_mm2: f64,
        seed: u64,
    ) -> TwinSource {
        let window = window.max(sg::MIN_WINDOW);
        let stride = window.div_ceil(TWIN_KERNEL_POINTS).max(1);
        let diff = sg::Differentiator::new((window / stride) | 1);
        let h = dt_s * stride as f64;
        let window_s = diff.window() as f64 * h;
        let motion = MotionFilter::new(TWIN_MOTION_CUTOFF_WINDOWS / window_s, dt_s);
        // Friction acts where the motion's velocity is beyond four standard deviations of the
        // smoothed noise's: at rest, the position noise left after smoothing does not flip it.
        let band_mm_per_s = 4.0
            * diff
                .noise_variance(sg::MOTION_VELOCITY, position_variance_mm2, h)
                .max(0.0)
                .sqrt();
        TwinSource {
            truth,
            weights: diff.weights[sg::POSITION].clone(),
            taps: diff.taps(sg::POSITION),
            stride,
            reach: diff.half * stride,
            positions: sg::SlidingWindow::new(2 * diff.half * stride + 1),
            waiting: VecDeque::new(),
            last: None,
            motion,
            band_mm_per_s,
            sliding: 0.0,
            rest: VecDeque::new(),
            rest_lookback: REST_LOOKBACK_WINDOWS * (2 * diff.half * stride + 1),
            rng: StdRng::seed_from_u64(seed),
            force_std_n: force_variance_n2.max(0.0).sqrt(),
            position_std_mm: position_variance_mm2.max(0.0).sqrt(),
            out: VecDeque::new(),
        }
    }

    /// Takes logged sample `i` (in order from 0).
    pub fn push(&mut self, i: usize, s: &Sample) {
        let span = 2 * self.reach + 1;
        self.positions.push(s.position_mm);
        self.waiting.push_back((i, s.t_s));
        if self.positions.len() < span {
            return;
        }
        let smoothed = sg::strided_sum(
            &self.weights,
            self.taps,
            self.positions.values(),
            self.stride,
        );
        let centre = i - self.reach;
        // The samples before the first window's centre take that window's fit at their own
        // times ([`sg::WindowFit`]).
        let first = match self.last {
            None => sg::WindowFit::new(self.positions.values(), self.stride),
            Some(_) => None,
        };
        while let Some(&(j, t)) = self.waiting.front() {
            if j > centre {
                break;
            }
            self.waiting.pop_front();
            let x = match &first {
                Some(fit) if j < centre => fit.value(j as f64 - centre as f64),
                _ => smoothed,
            };
            self.emit(j, t, x);
        }
        self.last = Some((centre, smoothed));
    }

    /// After the last sample: the last half window takes the last window's fit at its own
    /// times ([`sg::WindowFit`]; a log shorter than a window, the mean of its positions).
    pub fn finish(&mut self) {
        let fit = self.last.and_then(|(centre, _)| {
            Some((
                centre,
                sg::WindowFit::new(self.positions.values(), self.stride)?,
            ))
        });
        let held = self.last.map_or_else(
            || self.positions.values().iter().sum::<f64>() / self.positions.len().max(1) as f64,
            |(_, x)| x,
        );
        while let Some((j, t)) = self.waiting.pop_front() {
            let x = fit.map_or(held, |(centre, fit)| fit.value(j as f64 - centre as f64));
            self.emit(j, t, x);
        }
        while let Some((j, t, motion)) = self.rest.pop_front() {
            self.output(j, t, motion, 0.0);
        }
    }

    /// The twin's sample `i` at time `t_s`, its motion driven by the smoothed position.
    ///
    /// Friction slides with the motion until its velocity reaches zero (the stop), and is
    /// held from there until the velocity leaves the band its noise keeps it in; the start is
    /// then placed where the velocity last left zero, up to `rest_lookback` samples back, as
    /// the rod's friction turns on when it starts to move, not when it is seen moving.
    fn emit(&mut self, i: usize, t_s: f64, smoothed_mm: f64) {
        let motion = self.motion.push(smoothed_mm);
        let v = motion[1];
        if self.sliding != 0.0 {
            if v * self.sliding > 0.0 {
                self.output(i, t_s, motion, self.sliding);
                return;
            }
            self.sliding = 0.0;
        }
        if v.abs() > self.band_mm_per_s {
            let s = v.signum();
            // After the last sample that did not move the new way, or (a rest whose velocity
            // never crossed zero) the one that moved that way least.
            let from = match self.rest.iter().rposition(|(_, _, m)| m[1] * s <= 0.0) {
                Some(k) => k + 1,
                None => self
                    .rest
                    .iter()
                    .enumerate()
                    .min_by(|a, b| (a.1 .2[1] * s).total_cmp(&(b.1 .2[1] * s)))
                    .map_or(0, |(k, _)| k + 1),
            };
            for k in 0..self.rest.len() {
                let (j, t, m) = self.rest[k];
                self.output(j, t, m, if k >= from { s } else { 0.0 });
            }
            self.rest.clear();
            self.sliding = s;
            self.output(i, t_s, motion, s);
        } else {
            self.rest.push_back((i, t_s, motion));
            if self.rest.len() > self.rest_lookback {
                if let Some((j, t, m)) = self.rest.pop_front() {
                    self.output(j, t, m, 0.0);
                }
            }
        }
    }

    /// The twin's sample `i`: the model's force along `motion` with friction of sign `sign`,
    /// and the sensors' noise.
    fn output(&mut self, i: usize, t_s: f64, [x, v, a]: [f64; 3], sign: f64) {
        let t = &self.truth;
        let force = t.m_n_s2_per_mm * a
            + t.d1_n_s_per_mm * v
            + t.d2_n_s3_per_mm3 * v * v * v
            + (t.d0_n + t.mu_f_n * (t.law.k2_per_mm * x).exp()) * sign
            + t.law.force_n(x);
        let force_noise: f64 = StandardNormal.sample(&mut self.rng);
        let position_noise: f64 = StandardNormal.sample(&mut self.rng);
        self.out.push_back((
            i,
            Sample {
                t_s,
                force_n: force + self.force_std_n * force_noise,
                position_mm: x + self.position_std_mm * position_noise,
            },
        ));
    }
}

/// What the twins said about one of the filter's constants.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TwinState {
    /// The state's name with its unit.
    pub state: &'static str,
    /// The filter's value on the log, before the correction.
    pub filter: f64,
    /// The filter's own standard deviation on the log.
    pub filter_std: f64,
    /// Each twin's error (estimate minus truth; None where the twin was left out: its
    /// identification did not fit it, or its filter diverged). Every twin has its own noise
    /// and starts from its own identification.
    pub errors: Vec<Option<f64>>,
    /// The mean of the twins' errors: the bias taken out.
    pub bias: f64,
    /// The standard deviation of the twins' errors about their mean: the filter's scatter on
    /// the twins, identification's error included.
    pub scatter: f64,
    /// The scatter beyond the filter's own standard deviation (scaled to the twins' span):
    /// what identification's error, through the filter's start and the friction stage's
    /// model, moves the filter's value by. A longer log does not shrink it.
    pub excess_scatter: f64,
    /// The reported value: filter minus bias.
    pub corrected: f64,
    /// Its standard deviation: the filter's own (or the scatter scaled to the log's length,
    /// if larger and nothing exceeds the filter's own), the excess scatter, and the bias's
    /// own uncertainty (scatter^2 / twins).
    pub corrected_std: f64,
}

/// The twins' verdict on the filter's constants.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TwinBias {
    /// Twins run.
    pub twins: usize,
    /// Twins whose filter diverged (left out).
    pub diverged: usize,
    /// Length of log each twin copies (s): the identification span, at most the log.
    pub span_s: f64,
    /// The window the logged motion was smoothed over (s).
    pub smoothing_window_s: f64,
    /// One entry per constant corrected ([`super::pipeline::TWIN_CORRECTED`]).
    pub states: Vec<TwinState>,
}

impl TwinBias {
    /// Combines the twins' errors on each constant with the filter's value on the log.
    /// `constants` holds (name, filter value, filter std, errors), one error per twin (None
    /// where it was left out); with fewer than two errors the constant is left out. The twins
    /// copy `span_s` of a log `log_s` long: where the log is longer, the twins' scatter is that
    /// of a shorter run, and the part of it the filter's own standard deviation explains is
    /// scaled by sqrt(span / log).
    pub fn new(
        twins: usize,
        span_s: f64,
        log_s: f64,
        smoothing_window_s: f64,
        constants: Vec<(&'static str, f64, f64, Vec<Option<f64>>)>,
    ) -> TwinBias {
        let mut left_out = 0;
        let share = if log_s > span_s && span_s > 0.0 {
            span_s / log_s
        } else {
            1.0
        };
        let states = constants
            .into_iter()
            .filter_map(|(state, filter, filter_std, errors)| {
                left_out = left_out.max(errors.iter().filter(|e| e.is_none()).count());
                let present: Vec<f64> = errors.iter().flatten().copied().collect();
                let n = present.len();
                if n < 2 {
                    return None;
                }
                let bias = present.iter().sum::<f64>() / n as f64;
                let scatter = (present.iter().map(|e| (e - bias).powi(2)).sum::<f64>()
                    / (n - 1) as f64)
                    .sqrt();
                // The twins' scatter beyond the filter's own standard deviation over their
                // span is what identification's error (and whatever else the filter does not
                // count) does to the filter. It does not shrink on a longer log: identification
                // sees only the span. The rest is the filter's own spread, which does.
                let own_span = filter_std / share.sqrt();
                let excess = (scatter * scatter - own_span * own_span).max(0.0).sqrt();
                let own = if excess > 0.0 {
                    filter_std
                } else {
                    (scatter * share.sqrt()).max(filter_std)
                };
                // The bias's own uncertainty: the twins' errors scatter at least as the
                // filter's would over their span.
                let twin_spread = scatter.max(own_span);
                let bias_variance = twin_spread * twin_spread / n as f64;
                Some(TwinState {
                    state,
                    filter,
                    filter_std,
                    bias,
                    scatter,
                    excess_scatter: excess,
                    corrected: filter - bias,
                    corrected_std: (own * own + excess * excess + bias_variance).sqrt(),
                    errors,
                })
            })
            .collect();
        TwinBias {
            twins,
            diverged: left_out,
            span_s,
            smoothing_window_s,
            states,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// N standard normal draws from `seed`.
    fn standard_normals<const N: usize>(seed: u64) -> [f64; N] {
        let mut rng = StdRng::seed_from_u64(seed);
        std::array::from_fn(|_| StandardNormal.sample(&mut rng))
    }

    #[test]
    fn the_motion_filter_passes_a_ramp_with_exact_derivatives_and_unit_gain() {
        // A ramp of 2 mm/s sampled at 100 Hz: after the transient the filter's velocity is
        // the ramp's, its acceleration zero, and its position lags by the Butterworth's
        // group delay at zero frequency, 2 / w.
        let dt = 0.01;
        let fc = 1.0;
        let mut f = MotionFilter::new(fc, dt);
        let mut last = [0.0; 3];
        for i in 0..2000 {
            last = f.push(2.0 * i as f64 * dt);
        }
        let t_end = 1999.0 * dt;
        let w = std::f64::consts::TAU * fc;
        assert!((last[1] - 2.0).abs() < 1e-6, "{last:?}");
        // The held input is a staircase: its steps leave a ripple of a few um/s^2 at the
        // sampling rate.
        assert!(last[2].abs() < 0.01, "{last:?}");
        // Each input is held over the interval that ends at its own sample, half a sample
        // ahead of its centre: the delay is half a sample less.
        let delay = 2.0 / w - 0.5 * dt;
        assert!((last[0] - 2.0 * (t_end - delay)).abs() < 2e-3, "{last:?}");
    }

    #[test]
    fn the_motion_velocity_is_the_derivative_of_its_position() {
        // Driven by a noisy input, the state is still one motion: the change of x over a
        // sample is the integral of xd, to second order.
        let dt = 0.01;
        let mut f = MotionFilter::new(2.0, dt);
        let noise = standard_normals::<500>(3);
        let states: Vec<[f64; 3]> = noise
            .iter()
            .enumerate()
            .map(|(i, n)| f.push(5.0 + (i as f64 * 0.02).sin() + 0.1 * n))
            .collect();
        for w in states.windows(2).skip(10) {
            let dx = w[1][0] - w[0][0];
            let trapezoid = 0.5 * (w[0][1] + w[1][1]) * dt;
            // The trapezoid's error is dt^3 / 12 times the third derivative.
            assert!((dx - trapezoid).abs() < 1e-4, "{dx} vs {trapezoid}");
            let dv = w[1][1] - w[0][1];
            let trapezoid_v = 0.5 * (w[0][2] + w[1][2]) * dt;
            assert!((dv - trapezoid_v).abs() < 5e-3, "{dv} vs {trapezoid_v}");
        }
    }

    /// A noise-free simulated ramp-hold of `duration_s` with the given dynamics.
    fn noise_free_ramp_hold(
        law: ExpLaw,
        dynamics: crate::estimate::sim::Dynamics,
        duration_s: f64,
    ) -> crate::estimate::log::CalibrationLog {
        use crate::estimate::sim::{simulate, Profile, SimSettings};
        let mut settings = SimSettings {
            profile: Profile::RampHold,
            duration_s,
            dynamics,
            ..SimSettings::default()
        };
        settings.noise.force_variance_n2 = 0.0;
        settings.noise.position_variance_mm2 = 0.0;
        simulate(law, 15.0, 500.0, &settings).unwrap().0
    }

    /// A twin's truth: the simulated log's law and dynamics.
    fn truth_of(law: ExpLaw, d: crate::estimate::sim::Dynamics) -> TwinTruth {
        TwinTruth {
            m_n_s2_per_mm: d.m_n_s2_per_mm,
            d0_n: d.d0_n,
            mu_f_n: 0.0,
            d1_n_s_per_mm: d.d1_n_s_per_mm,
            d2_n_s3_per_mm3: d.d2_n_s3_per_mm3,
            law,
        }
    }

    /// Every sample of `log` through `twin`, and the twin's samples out, in order.
    fn through(
        twin: &mut TwinSource,
        log: &crate::estimate::log::CalibrationLog,
    ) -> Vec<(usize, Sample)> {
        let mut out = Vec::new();
        for i in 0..log.len() {
            let s = Sample {
                t_s: log.t_s[i],
                force_n: log.force_n[i],
                position_mm: log.position_mm[i],
            };
            twin.push(i, &s);
            out.extend(twin.out.drain(..));
        }
        twin.finish();
        out.extend(twin.out.drain(..));
        out
    }

    #[test]
    fn a_twin_follows_the_logged_motion_with_the_law_s_force() {
        // A noise-free ramp-hold of the simulator: the twin (no noise of its own) must move
        // as the log did and carry the law's force plus the dynamics along its own motion.
        use crate::estimate::sim::Dynamics;
        let law = ExpLaw {
            mu_n: 1.1,
            k2_per_mm: 0.24,
            f0_n: 2.0,
        };
        let dynamics = Dynamics {
            m_n_s2_per_mm: 0.25,
            d0_n: 0.0,
            d1_n_s_per_mm: 1.5,
            d2_n_s3_per_mm3: 0.0,
        };
        let log = noise_free_ramp_hold(law, dynamics, 60.0);
        let truth = truth_of(law, dynamics);
        let out = through(&mut TwinSource::new(truth, 241, 0.01, 0.0, 0.0, 1), &log);
        assert_eq!(out.len(), log.len());
        let (mut worst_x, mut worst_f) = (0.0_f64, 0.0_f64);
        // Away from the ends (the first half window takes the first smoothed value), the
        // twin lags the log by the Butterworth's delay, 2 / w less half a sample.
        let lag = (2.0 / (std::f64::consts::TAU * TWIN_MOTION_CUTOFF_WINDOWS / 2.41) / 0.01 - 0.5)
            .round() as usize;
        for (k, (i, s)) in out.iter().enumerate().skip(300).take(log.len() - 600) {
            assert_eq!(*i, k);
            assert_eq!(s.t_s, log.t_s[k]);
            worst_x = worst_x.max((s.position_mm - log.position_mm[k - lag]).abs());
            worst_f = worst_f.max((s.force_n - log.force_n[k - lag]).abs());
        }
        // The ramps move up to 5 mm in 4 s: the twin is within 0.05 mm of the log's motion,
        // and its force within 0.2 N of the log's (of 3 to 40 N; the force noise of a rig is
        // about 0.13 N). The smoothing rounds the joints of ramp and hold a little.
        assert!(worst_x < 0.05, "{worst_x} mm");
        assert!(worst_f < 0.2, "{worst_f} N");
    }

    #[test]
    fn the_bias_is_the_mean_of_the_twins_and_the_std_grows_with_their_excess_scatter() {
        // Six twins: errors -0.003, -0.005, -0.005, -0.001, -0.003, -0.007 (mean -0.004, sum
        // of squared deviations 2.2e-5, scatter sqrt(2.2e-5 / 5) = 2.098e-3). A seventh twin
        // left out (None) is counted, not used.
        let six = [
            Some(-0.003),
            Some(-0.005),
            Some(-0.005),
            Some(-0.001),
            Some(-0.003),
            Some(-0.007),
        ];
        let mut errors = six.to_vec();
        errors.push(None);
        let b = TwinBias::new(
            7,
            300.0,
            300.0,
            1.0,
            vec![
                ("k2_per_mm", 0.30, 0.0005, errors),
                ("m_n_s2_per_mm", 0.1, 0.01, vec![Some(0.001), None]),
            ],
        );
        assert_eq!(b.states.len(), 1, "one twin is not enough for a bias");
        assert_eq!(b.diverged, 1);
        let k = &b.states[0];
        let scatter = (2.2e-5f64 / 5.0).sqrt();
        assert!((k.bias + 0.004).abs() < 1e-12);
        assert!((k.corrected - 0.304).abs() < 1e-12);
        assert!((k.scatter - scatter).abs() < 1e-12);
        // The scatter beyond the filter's own 5e-4 is identification's share.
        let excess = (scatter * scatter - 0.0005f64.powi(2)).sqrt();
        assert!((k.excess_scatter - excess).abs() < 1e-12);
        // The filter's own, the excess, and the bias's variance (the scatter squared over six
        // twins): the scatter squared in all, and a sixth of it.
        let expected = (scatter * scatter * (1.0 + 1.0 / 6.0)).sqrt();
        assert!(
            (k.corrected_std - expected).abs() < 1e-12,
            "{}",
            k.corrected_std
        );
        // Twins of the first hour of a day-long log with a filter whose own standard deviation
        // on the day is 1e-4: over an hour it is sqrt(24) times that, 4.9e-4. The excess over
        // it does not shrink on the day; the filter's own part does.
        let day = TwinBias::new(
            6,
            3600.0,
            86_400.0,
            1.0,
            vec![("k2_per_mm", 0.30, 1e-4, six.to_vec())],
        );
        let k = &day.states[0];
        let own_hour = 1e-4 * 24f64.sqrt();
        let excess = (scatter * scatter - own_hour * own_hour).sqrt();
        assert!((k.excess_scatter - excess).abs() < 1e-12);
        let expected = (1e-8 + excess * excess + scatter * scatter / 6.0).sqrt();
        assert!(
            (k.corrected_std - expected).abs() < 1e-15,
            "{}",
            k.corrected_std
        );
        // A filter whose own standard deviation exceeds the twins' scatter: no excess, and
        // the filter's own stands, with the bias's variance at least its own over the twins.
        let quiet = TwinBias::new(
            6,
            300.0,
            300.0,
            1.0,
            vec![("k2_per_mm", 0.30, 0.01, six.to_vec())],
        );
        let k = &quiet.states[0];
        assert_eq!(k.excess_scatter, 0.0);
        assert!((k.corrected_std - (1e-4f64 * (1.0 + 1.0 / 6.0)).sqrt()).abs() < 1e-15);
    }

    #[test]
    fn a_twin_s_friction_slides_to_the_stop_and_starts_where_the_motion_starts() {
        // A noise-free ramp-hold with Coulomb friction, through the twin: while the rod moves
        // the twin's force carries +-d0, and within its holds none, with the switches at the
        // moves' ends (not where the smoothed velocity enters the band its noise keeps it in).
        use crate::estimate::sim::Dynamics;
        let law = ExpLaw {
            mu_n: 1.1,
            k2_per_mm: 0.24,
            f0_n: 4.0,
        };
        let dynamics = Dynamics {
            m_n_s2_per_mm: 0.0,
            d0_n: 1.0,
            d1_n_s_per_mm: 0.0,
            d2_n_s3_per_mm3: 0.0,
        };
        let log = noise_free_ramp_hold(law, dynamics, 40.0);
        let truth = truth_of(law, dynamics);
        // A band as wide as a 0.1 mm encoder's would give: 0.01 mm^2 of position noise.
        let mut twin = TwinSource::new(truth, 61, 0.01, 0.0, 0.01, 1);
        twin.position_std_mm = 0.0;
        let out = through(&mut twin, &log);
        assert_eq!(out.len(), log.len());
        assert!(out.iter().enumerate().all(|(k, (i, _))| *i == k));
        // The twin's friction: its force less the law at its own position (noise free).
        let friction: Vec<f64> = out
            .iter()
            .map(|(_, s)| s.force_n - law.force_n(s.position_mm))
            .collect();
        // The log's: sliding (|F - law| = d0) or held (0).
        let sliding: Vec<bool> = (0..log.len())
            .map(|k| (log.force_n[k] - law.force_n(log.position_mm[k])).abs() > 0.5)
            .collect();
        let twin_sliding: Vec<bool> = friction.iter().map(|f| f.abs() > 0.5).collect();
        assert!(friction
            .iter()
            .all(|f| f.abs() < 1e-9 || (f.abs() - 1.0).abs() < 1e-9));
        // Each of the log's moves (a run of sliding samples) is one move of the twin's, as
        // long to within a tenth of a second at each end (the twin lags the log by its
        // motion filter's delay, about 0.07 s here). With the friction switched at the band
        // instead, the starts came 0.6 s late.
        let runs = |s: &[bool]| -> Vec<(usize, usize)> {
            let mut r = Vec::new();
            let mut k = 0;
            while k < s.len() {
                if s[k] {
                    let a = k;
                    while k < s.len() && s[k] {
                        k += 1;
                    }
                    r.push((a, k));
                } else {
                    k += 1;
                }
            }
            r
        };
        let (moves, twin_moves) = (runs(&sliding), runs(&twin_sliding));
        assert!(moves.len() >= 5, "{moves:?}");
        assert_eq!(moves.len(), twin_moves.len(), "{moves:?} {twin_moves:?}");
        // (A move the log ends in is left: the twin's last half window rests.)
        for ((a, b), (c, d)) in moves.iter().zip(&twin_moves).filter(|m| m.0 .1 < log.len()) {
            let lag = 7i64;
            assert!((*c as i64 - *a as i64 - lag).abs() <= 10, "{a} {c}");
            assert!((*d as i64 - *b as i64 - lag).abs() <= 10, "{b} {d}");
        }
    }
}
