//! Simulated calibration runs with known truth (docs/THEORY.md section 4).
//!
//! A motor drives the deflection x(t) along a smooth profile; the rod force follows eq. (9):
//! F = m*xdd + d1*xd + d2*xd^3 + d0*sgn(xd) + F_S(x), with the spec's designed law as F_S. The
//! wire only pulls, so a profile that would need F < 0 (or more than Fmax) is refused.
//! White noise at the given variances (the paper's by default) is added to force and
//! position. The truth (parameters, and sigma(t), D(t), M at every sample) is returned with
//! the log.

use rand::{rngs::StdRng, Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use serde::Serialize;

use super::log::CalibrationLog;
use crate::model::ForceLaw;

/// The motion profile.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Profile {
    /// Two superposed sines (0.15 Hz and 0.41 Hz) over 15 ... 85 % of the stroke.
    Sines,
    /// Slow ramps (4 s) between levels with 2 s holds: quasi-static.
    RampHold,
    /// Quick smoothed steps ([`STEP_RAMP_S`]) between random levels with 1.5 s holds.
    Steps,
    /// At rest at mid stroke (for noise models).
    Static,
}

/// Transmission parameters besides the spring law (N, mm, s).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Dynamics {
    /// Inertia m.
    pub m_n_s2_per_mm: f64,
    /// Coulomb friction d0.
    pub d0_n: f64,
    /// Linear damping d1.
    pub d1_n_s_per_mm: f64,
    /// Cubic damping d2 (negative: the damper saturates; keep |xd| < sqrt(d1/(3|d2|))).
    pub d2_n_s3_per_mm3: f64,
}

impl Default for Dynamics {
    /// A transmission of the order of the paper's Table II (m = 0.055, d2 = -0.11): m = 0.05
    /// N s^2/mm, d1 = 0.2 N s/mm, d2 = -1e-4 N s^3/mm^3 (the damper force keeps growing with
    /// speed up to 25.8 mm/s), no Coulomb friction.
    fn default() -> Self {
        Dynamics {
            m_n_s2_per_mm: 0.05,
            d0_n: 0.0,
            d1_n_s_per_mm: 0.2,
            d2_n_s3_per_mm3: -1e-4,
        }
    }
}

impl Dynamics {
    /// A light transmission (m = 2e-3, d1 = 0.02, d2 = -1e-5): its inertia and damping forces
    /// are below the paper's force noise, which tests identification at the edge.
    pub fn light() -> Self {
        Dynamics {
            m_n_s2_per_mm: 2e-3,
            d0_n: 0.0,
            d1_n_s_per_mm: 0.02,
            d2_n_s3_per_mm3: -1e-5,
        }
    }
}

/// White sensor noise (variances).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Noise {
    /// Force variance (N^2); the paper's 0.017.
    pub force_variance_n2: f64,
    /// Position variance (mm^2); the paper's 0.01.
    pub position_variance_mm2: f64,
}

impl Default for Noise {
    fn default() -> Self {
        Noise {
            force_variance_n2: 0.017,
            position_variance_mm2: 0.01,
        }
    }
}

/// Settings of one run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SimSettings {
    /// Profile.
    pub profile: Profile,
    /// Duration.
    pub duration_s: f64,
    /// Sampling rate.
    pub rate_hz: f64,
    /// Random seed.
    pub seed: u64,
    /// Speed of the profile relative to its nominal one: 0.5 runs every move half as fast
    /// (for heavy dampers, whose force must keep rising with speed, and for slow runs).
    pub speed: f64,
    /// Dynamics.
    pub dynamics: Dynamics,
    /// Noise.
    pub noise: Noise,
}

impl Default for SimSettings {
    /// What `camspring simulate` does by default: sines for 300 s at 100 Hz, seed 0, the
    /// default transmission and the paper's sensor noise.
    fn default() -> Self {
        SimSettings {
            profile: Profile::Sines,
            duration_s: 300.0,
            rate_hz: 100.0,
            seed: 0,
            speed: 1.0,
            dynamics: Dynamics::default(),
            noise: Noise::default(),
        }
    }
}

/// The truth behind a simulated log.
#[derive(Debug, Clone, Serialize)]
pub struct Truth {
    /// The spring law.
    pub law: ForceLaw,
    /// The other parameters.
    pub dynamics: Dynamics,
    /// Noise injected.
    pub noise: Noise,
    /// Settings.
    pub settings: SimSettings,
    /// Generalised stiffness sigma = dF/dx at each sample.
    pub sigma_n_per_mm: Vec<f64>,
    /// Generalised damping D = d1 + 3 d2 xd^2 at each sample.
    pub d_n_s_per_mm: Vec<f64>,
    /// Generalised inertia M (constant).
    pub m_n_s2_per_mm: f64,
    /// True (noise-free) deflection.
    pub position_mm: Vec<f64>,
    /// True force.
    pub force_n: Vec<f64>,
}

/// Why a run could not be simulated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    /// Produced by [`simulate`] when the profile cannot run with these dynamics: a rod force
    /// that would push (the wire only pulls) or exceed the limit, or a damper force that would
    /// fall with speed. The message says where, and what change runs it (a `--speed` found to
    /// run the whole profile, or the friction the spring can carry).
    #[error("{0}")]
    Unrunnable(String),
    /// Produced by [`simulate`] for unusable settings.
    #[error("{0}")]
    Settings(String),
}

/// The most samples one simulated run may have (duration times rate).
pub const MAX_SAMPLES: f64 = 2e7;

/// Slowest profile speed factor ([`SimSettings::speed`]).
pub const MIN_SPEED: f64 = 0.01;

/// Fastest profile speed factor ([`SimSettings::speed`]).
pub const MAX_SPEED: f64 = 10.0;

/// Duration of one move of the steps profile: a few filter windows, so that the smoothing
/// differentiator follows it.
pub const STEP_RAMP_S: f64 = 1.2;

/// Quintic smootherstep on [0, 1] with its first two derivatives.
fn smoother(u: f64) -> (f64, f64, f64) {
    let u = u.clamp(0.0, 1.0);
    (
        u * u * u * (u * (6.0 * u - 15.0) + 10.0),
        30.0 * u * u * (u - 1.0).powi(2),
        60.0 * u * (2.0 * u * u - 3.0 * u + 1.0),
    )
}

/// A sequence of smoothed moves between levels: (x, xd, xdd) at time t.
fn moves(levels: &[f64], ramp: f64, hold: f64, t: f64) -> (f64, f64, f64) {
    let period = ramp + hold;
    let k = (t / period).floor() as usize;
    let local = t - k as f64 * period;
    let a = levels[k % levels.len()];
    let b = levels[(k + 1) % levels.len()];
    if local < hold {
        return (a, 0.0, 0.0);
    }
    let (s, ds, dds) = smoother((local - hold) / ramp);
    (
        a + (b - a) * s,
        (b - a) * ds / ramp,
        (b - a) * dds / (ramp * ramp),
    )
}

/// One simulated sample: what the log holds (with noise) and the truth behind it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimSample {
    /// The logged sample: time, force and position with sensor noise.
    pub logged: super::log::Sample,
    /// True deflection (mm).
    pub position_mm: f64,
    /// True velocity (mm/s): its sign is the Coulomb friction's.
    pub velocity_mm_per_s: f64,
    /// True rod force (N).
    pub force_n: f64,
    /// Generalised stiffness sigma = dF/dx (N/mm).
    pub sigma_n_per_mm: f64,
    /// Generalised damping D = d1 + 3 d2 xd^2 (N s/mm).
    pub d_n_s_per_mm: f64,
}

/// The noise-free motion and rod force of one sample ([`Simulator`]).
#[derive(Debug, Clone, Copy)]
struct Motion {
    x: f64,
    xd: f64,
    f: f64,
}

/// Why a sample cannot be simulated.
#[derive(Debug, Clone, Copy)]
enum Unrunnable {
    /// The damper force d1 xd + d2 xd^3 would fall with speed at velocity `xd`.
    DamperFalls { xd: f64 },
    /// The rod force leaves 0 ... the limit.
    Force { force_n: f64 },
}

/// A calibration run generated sample by sample, for runs too long to hold ([`simulate`]
/// collects one). The same settings and seed give the same samples.
#[derive(Debug, Clone)]
pub struct Simulator {
    law: ForceLaw,
    xmax_mm: f64,
    limit_n: f64,
    settings: SimSettings,
    step_levels: Vec<f64>,
    ramp_levels: [f64; 7],
    rng: StdRng,
    force_noise: Normal<f64>,
    position_noise: Normal<f64>,
    /// The unloading curve of a built cam with contact friction ([`BuiltSpring`]).
    unloading: Option<ForceLaw>,
    /// Added to every logged position: an encoder zero off by this much.
    position_offset_mm: f64,
    /// The last direction of motion (+1 loading, -1 unloading): at rest the contact friction
    /// holds the force of the stroke that came to rest.
    direction: f64,
}

/// A built cam spring: the rod force along the loading stroke and along the unloading stroke
/// (they differ by the contact friction's hysteresis), and the encoder zero of the rig.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BuiltSpring {
    /// Rod force while the deflection grows.
    pub loading: ForceLaw,
    /// Rod force while it shrinks.
    pub unloading: ForceLaw,
    /// The logged position is the true one plus this (mm).
    pub position_offset_mm: f64,
}

impl Simulator {
    /// Checks the settings (any number of samples; [`simulate`] bounds it) and draws the
    /// profile's random levels.
    pub fn new(
        law: impl Into<ForceLaw>,
        xmax_mm: f64,
        fmax_n: f64,
        s: &SimSettings,
    ) -> Result<Simulator, SimError> {
        if !(s.rate_hz > 0.0 && s.duration_s > 0.0 && s.duration_s * s.rate_hz >= 16.0) {
            return Err(SimError::Settings(format!(
                "--duration {} s at --rate {} Hz gives {:.0} samples; expected 16 or more",
                s.duration_s,
                s.rate_hz,
                s.duration_s * s.rate_hz
            )));
        }
        if !(s.speed.is_finite() && (MIN_SPEED..=MAX_SPEED).contains(&s.speed)) {
            return Err(SimError::Settings(format!(
                "--speed {}: expected a factor from {MIN_SPEED} to {MAX_SPEED} (1 is the profile's nominal speed)",
                s.speed
            )));
        }
        let d = &s.dynamics;
        for (value, flag, what) in [
            (d.m_n_s2_per_mm, "--m", "an inertia"),
            (d.d0_n, "--d0", "a Coulomb friction"),
            (d.d1_n_s_per_mm, "--d1", "a linear damping"),
            (s.noise.force_variance_n2, "--force-variance", "a variance"),
            (
                s.noise.position_variance_mm2,
                "--position-variance",
                "a variance",
            ),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(SimError::Settings(format!(
                    "{flag} {value}: expected {what} of 0 or more"
                )));
            }
        }
        if !d.d2_n_s3_per_mm3.is_finite() {
            return Err(SimError::Settings(format!(
                "--d2 {}: expected a finite cubic damping",
                d.d2_n_s3_per_mm3
            )));
        }
        let mut rng = StdRng::seed_from_u64(s.seed);
        let step_levels: Vec<f64> = (0..64)
            .map(|_| xmax_mm * rng.random_range(0.15..0.85))
            .collect();
        let force_noise = Normal::new(0.0, s.noise.force_variance_n2.sqrt())
            .map_err(|e| SimError::Settings(e.to_string()))?;
        let position_noise = Normal::new(0.0, s.noise.position_variance_mm2.sqrt())
            .map_err(|e| SimError::Settings(e.to_string()))?;
        Ok(Simulator {
            law: law.into(),
            xmax_mm,
            limit_n: fmax_n,
            settings: *s,
            step_levels,
            ramp_levels: [0.15, 0.5, 0.85, 0.3, 0.7, 0.2, 0.6].map(|f| f * xmax_mm),
            rng,
            force_noise,
            position_noise,
            unloading: None,
            position_offset_mm: 0.0,
            direction: 1.0,
        })
    }

    /// A run of a built spring: the loading curve while the deflection grows, the unloading
    /// curve while it shrinks (at rest, the last stroke's), and the rig's encoder zero.
    pub fn built(
        spring: &BuiltSpring,
        xmax_mm: f64,
        fmax_n: f64,
        s: &SimSettings,
    ) -> Result<Simulator, SimError> {
        if !spring.position_offset_mm.is_finite() {
            return Err(SimError::Settings(format!(
                "position offset {} mm: expected a finite length",
                spring.position_offset_mm
            )));
        }
        let mut sim = Simulator::new(spring.loading.clone(), xmax_mm, fmax_n, s)?;
        sim.unloading = Some(spring.unloading.clone());
        sim.position_offset_mm = spring.position_offset_mm;
        Ok(sim)
    }

    /// Samples in the run (duration times rate).
    pub fn samples(&self) -> usize {
        (self.settings.duration_s * self.settings.rate_hz).round() as usize
    }

    /// The profile's position (mm), velocity (mm/s) and acceleration (mm/s^2) at its own
    /// clock's `t` (s), at its nominal speed.
    fn kinematics(&self, t: f64) -> (f64, f64, f64) {
        let xmax_mm = self.xmax_mm;
        match self.settings.profile {
            Profile::Sines => {
                let (w1, w2) = (std::f64::consts::TAU * 0.15, std::f64::consts::TAU * 0.41);
                let (a1, a2) = (0.22 * xmax_mm, 0.13 * xmax_mm);
                (
                    0.5 * xmax_mm + a1 * (w1 * t).sin() + a2 * (w2 * t + 1.0).sin(),
                    a1 * w1 * (w1 * t).cos() + a2 * w2 * (w2 * t + 1.0).cos(),
                    -a1 * w1 * w1 * (w1 * t).sin() - a2 * w2 * w2 * (w2 * t + 1.0).sin(),
                )
            }
            Profile::RampHold => moves(&self.ramp_levels, 4.0, 2.0, t),
            Profile::Steps => moves(&self.step_levels, STEP_RAMP_S, 1.5, t),
            Profile::Static => (0.5 * xmax_mm, 0.0, 0.0),
        }
    }

    /// The run's motion and rod force at sample `i` when the profile runs at `speed`, free of
    /// noise: position (mm), velocity (mm/s), acceleration (mm/s^2), the friction's sign and the
    /// rod force (N). `direction` is the last direction of motion (the unloading curve's),
    /// carried from sample to sample. Fails where the damper force would fall with speed or
    /// the rod force leaves 0 ... the limit.
    fn motion(&self, i: usize, speed: f64, direction: &mut f64) -> Result<Motion, Unrunnable> {
        let dt = 1.0 / self.settings.rate_hz;
        // The profile runs on a scaled clock: its velocity scales with `speed`, its
        // acceleration with its square.
        let (x, xd, xdd) = self.kinematics(i as f64 * dt * speed);
        let (xd, xdd) = (xd * speed, xdd * speed * speed);
        let d = self.settings.dynamics;
        if d.d2_n_s3_per_mm3 < 0.0 && 3.0 * d.d2_n_s3_per_mm3.abs() * xd * xd > d.d1_n_s_per_mm {
            return Err(Unrunnable::DamperFalls { xd });
        }
        let sgn = if xd > 0.0 {
            1.0
        } else if xd < 0.0 {
            -1.0
        } else {
            0.0
        };
        if sgn != 0.0 {
            *direction = sgn;
        }
        let spring = match &self.unloading {
            Some(unloading) if *direction < 0.0 => unloading,
            _ => &self.law,
        };
        let f = d.m_n_s2_per_mm * xdd
            + d.d1_n_s_per_mm * xd
            + d.d2_n_s3_per_mm3 * xd.powi(3)
            + d.d0_n * sgn
            + spring.force_n(x);
        if !(0.0..=self.limit_n).contains(&f) {
            return Err(Unrunnable::Force { force_n: f });
        }
        Ok(Motion { x, xd, f })
    }

    /// The fastest of a few speeds below `speed` (9/10 of it down to [`MIN_SPEED`]) at which
    /// the whole run keeps its damper force rising with speed and its rod force in range;
    /// None when none does.
    fn speed_that_runs(&self, speed: f64) -> Option<f64> {
        let mut candidates: Vec<f64> = [
            0.9, 0.8, 0.7, 0.6, 0.5, 0.4, 0.3, 0.25, 0.2, 0.15, 0.1, 0.07, 0.05, 0.03, 0.02, 0.01,
            0.005, 0.002, 0.001,
        ]
        .iter()
        .map(|f| (f * speed * 100.0).floor() / 100.0)
        .filter(|&v| v >= MIN_SPEED)
        .collect();
        candidates.dedup();
        candidates.into_iter().find(|&v| {
            let mut direction = 1.0;
            (0..self.samples()).all(|i| self.motion(i, v, &mut direction).is_ok())
        })
    }

    /// What to change so that the run can be simulated, for the failure `why`.
    fn unrunnable(&self, why: Unrunnable, t_s: f64) -> SimError {
        let s = &self.settings;
        let d = s.dynamics;
        let slower = || match self.speed_that_runs(s.speed) {
            Some(v) => format!("run the profile slower (--speed {v:.2} runs the whole of it), or "),
            None => String::new(),
        };
        let message = match why {
            Unrunnable::DamperFalls { xd } => format!(
                "at t = {t_s:.3} s the {:?} profile moves at {:.2} mm/s, where the damper force \
                 d1 xd + d2 xd^3 would fall with speed (above sqrt(d1 / (3 |d2|)) = {:.2} \
                 mm/s); {}use a smaller |d2| or a larger d1",
                s.profile,
                xd.abs(),
                (d.d1_n_s_per_mm / (3.0 * d.d2_n_s3_per_mm3.abs())).sqrt(),
                slower()
            ),
            Unrunnable::Force { force_n, .. } => {
                // The friction a retracting rod needs the spring to overcome: where the
                // spring's force falls below d0 on the run's way down, no speed helps.
                let retracting = self.unloading.as_ref().unwrap_or(&self.law);
                let weakest = (0..self.samples())
                    .map(|i| {
                        let (x, _, _) = self.kinematics(i as f64 * s.speed / s.rate_hz);
                        retracting.force_n(x)
                    })
                    .fold(f64::INFINITY, f64::min);
                let change = if weakest < d.d0_n {
                    format!(
                        "the Coulomb friction d0 = {} N is more than the spring's least force \
                         over the run ({weakest:.2} N), which no speed changes: use a d0 below \
                         {weakest:.2} N, or a spec whose spring pulls harder at low deflection \
                         (a larger F0)",
                        d.d0_n
                    )
                } else {
                    "lower the damping or the inertia".to_string()
                };
                format!(
                    "the {:?} profile needs a rod force of {force_n:.3} N at t = {t_s:.3} s, \
                     outside 0 ... {:.1} N (the wire only pulls); {}{change}",
                    s.profile,
                    self.limit_n,
                    slower()
                )
            }
        };
        SimError::Unrunnable(message)
    }

    /// Sample `i`; samples must be taken in order from 0 (the noise is drawn as they come).
    pub fn sample(&mut self, i: usize) -> Result<SimSample, SimError> {
        let dt = 1.0 / self.settings.rate_hz;
        let t = i as f64 * dt;
        let mut direction = self.direction;
        let Motion { x, xd, f } = self
            .motion(i, self.settings.speed, &mut direction)
            .map_err(|why| self.unrunnable(why, t))?;
        self.direction = direction;
        let d = self.settings.dynamics;
        let spring = match &self.unloading {
            Some(unloading) if self.direction < 0.0 => unloading,
            _ => &self.law,
        };
        let force_noise = self.force_noise.sample(&mut self.rng);
        let position_noise = self.position_noise.sample(&mut self.rng);
        Ok(SimSample {
            logged: super::log::Sample {
                t_s: t,
                force_n: f + force_noise,
                position_mm: x + self.position_offset_mm + position_noise,
            },
            position_mm: x,
            velocity_mm_per_s: xd,
            force_n: f,
            sigma_n_per_mm: spring.stiffness_n_per_mm(x),
            d_n_s_per_mm: d.d1_n_s_per_mm + 3.0 * d.d2_n_s3_per_mm3 * xd * xd,
        })
    }
}

/// Simulates a calibration run of `law` over the stroke `xmax_mm` (force limit `fmax_n`).
pub fn simulate(
    law: impl Into<ForceLaw>,
    xmax_mm: f64,
    fmax_n: f64,
    s: &SimSettings,
) -> Result<(CalibrationLog, Truth), SimError> {
    check_samples(s)?;
    collect(Simulator::new(law, xmax_mm, fmax_n, s)?, s)
}

/// Simulates a calibration run of a built spring ([`BuiltSpring`]): loading and unloading
/// curves apart by the contact friction, and an encoder zero.
pub fn simulate_built(
    spring: &BuiltSpring,
    xmax_mm: f64,
    fmax_n: f64,
    s: &SimSettings,
) -> Result<(CalibrationLog, Truth), SimError> {
    check_samples(s)?;
    collect(Simulator::built(spring, xmax_mm, fmax_n, s)?, s)
}

/// Refuses a run of more than [`MAX_SAMPLES`] samples.
fn check_samples(s: &SimSettings) -> Result<(), SimError> {
    let samples = s.duration_s * s.rate_hz;
    if samples.is_nan() || samples > MAX_SAMPLES {
        return Err(SimError::Settings(format!(
            "--duration {} s at --rate {} Hz gives {:.0} samples; expected 16 to {MAX_SAMPLES:.0} \
             (a log and its truth take about 100 bytes per sample in memory)",
            s.duration_s,
            s.rate_hz,
            s.duration_s * s.rate_hz
        )));
    }
    Ok(())
}

/// Runs a simulator to its end, keeping the log and the truth.
fn collect(mut sim: Simulator, s: &SimSettings) -> Result<(CalibrationLog, Truth), SimError> {
    let n = sim.samples();
    let mut log = CalibrationLog {
        t_s: Vec::with_capacity(n),
        force_n: Vec::with_capacity(n),
        position_mm: Vec::with_capacity(n),
        ..CalibrationLog::default()
    };
    let mut truth = Truth {
        law: sim.law.clone(),
        dynamics: s.dynamics,
        noise: s.noise,
        settings: *s,
        sigma_n_per_mm: Vec::with_capacity(n),
        d_n_s_per_mm: Vec::with_capacity(n),
        m_n_s2_per_mm: s.dynamics.m_n_s2_per_mm,
        position_mm: Vec::with_capacity(n),
        force_n: Vec::with_capacity(n),
    };
    for i in 0..n {
        let sample = sim.sample(i)?;
        log.t_s.push(sample.logged.t_s);
        log.force_n.push(sample.logged.force_n);
        log.position_mm.push(sample.logged.position_mm);
        truth.sigma_n_per_mm.push(sample.sigma_n_per_mm);
        truth.d_n_s_per_mm.push(sample.d_n_s_per_mm);
        truth.position_mm.push(sample.position_mm);
        truth.force_n.push(sample.force_n);
    }
    Ok((log, truth))
}
