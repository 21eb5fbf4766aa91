//! `camspring diagnose`: what the build got wrong, from its calibration log.
//!
//! The measured rod force is explained with the design's own forward model (docs/THEORY.md,
//! "Friction" and "The force band"): the made pitch curve, with the build's spring rate, preload,
//! contact friction and the rig's encoder zero free, plus the transmission's inertia, damping and
//! Coulomb friction outside the cam (eq. 9):
//!
//! ```text
//! F = (1 + rate) k_eff (Y(x - zero) + Yp + dYp) tan(theta(x - zero) +- atan(friction))
//!     + m xdd + d0 sgn(xd) + d1 xd + d2 xd^3
//! ```
//!
//! with + on loading and - on unloading (at rest, the stroke that came to rest). Position,
//! velocity and acceleration come from the Savitzky-Golay differentiator; samples where the
//! motion reverses inside the velocity's noise are left out, since their stroke is unknown, and
//! so are transients the window does not resolve (samples within half a window of a residual
//! far beyond the residuals' robust spread: a servo's velocity steps), as in identification.
//! The eight parameters are fitted by Levenberg-Marquardt, each sample weighted by its whole
//! force variance: the force noise, the smoothed position's noise times the local stiffness,
//! and the smoothed velocity's and acceleration's noise times the damping and the inertia. The
//! inertia and the damper carry identification's errors-in-variables correction (the
//! acceleration's noise would otherwise pull m towards zero, and the velocity's the damper's
//! slope), and the samples that move, with their Coulomb sign, are chosen by a velocity whose
//! noise the regressors do not share. The window is chosen from the data: from the one whose
//! fit explains the log best, lengthened until the fit's chi-square rises ([`diagnose`]). Their covariance is a
//! sandwich over blocks of samples, which stays honest when the residuals are coloured by the
//! smoothing or the weights are off. A build parameter whose standard deviation exceeds a
//! third of its [`RESOLUTION`] is named as not resolved by this log.

use nalgebra::{DMatrix, DVector};
use serde::Serialize;

use crate::cam::forces::stroke_force_ratio;
use crate::cam::tolerance::{build_curves, pitch_at, spring_load_n, Build};
use crate::design::Design;
use crate::estimate::adequacy::{whiteness, Adequacy, Whiteness, WHITENESS_LEVEL};
use crate::estimate::adequacy::{MAX_REDUCED_CHI2, MIN_REDUCED_CHI2};
use crate::estimate::identify::{
    mark_window, unbiased_cube, SensorNoise, CHI2_RISE_MIN, TRANSIENT_ROUNDS, TRANSIENT_SIGMAS,
};
use crate::estimate::log::CalibrationLog;
use crate::estimate::pipeline::PositionOffset;
use crate::estimate::sg;
use crate::estimate::sim::BuiltSpring;
use crate::estimate::window::{chi2_rise_tolerance, MIN_SIGNAL_SHARE};
use crate::model::{Follower, ForceLaw, TableLaw};
use rayon::prelude::*;

/// How a build departs from its design: what `simulate` can build and `diagnose` recovers.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AsBuilt {
    /// The springs' rate over the designed rate (1: as designed).
    pub spring_rate_scale: f64,
    /// Preload as assembled minus the designed preload, as follower travel (mm).
    pub preload_offset_mm: f64,
    /// The effective contact friction coefficient of the build.
    pub friction: f64,
    /// The rig's encoder reads the deflection plus this (mm).
    pub zero_offset_mm: f64,
}

impl AsBuilt {
    /// The build exactly as designed: the design's friction, no offsets.
    pub fn nominal(follower: &Follower) -> AsBuilt {
        AsBuilt {
            spring_rate_scale: 1.0,
            preload_offset_mm: 0.0,
            friction: follower.friction_coefficient(),
            zero_offset_mm: 0.0,
        }
    }

    /// The build as the spec assembles it: `[assembly]`'s spring and shim on the cam cut for
    /// `[follower]`.
    pub fn assembled(spec: &crate::model::Spec) -> AsBuilt {
        let f = &spec.follower;
        AsBuilt {
            spring_rate_scale: spec
                .assembly
                .spring_rate_n_per_mm
                .map_or(1.0, |k| k / f.spring_rate_n_per_mm),
            preload_offset_mm: spec.assembly.shim_mm,
            friction: spec
                .assembly
                .friction
                .unwrap_or_else(|| f.friction_coefficient()),
            ..AsBuilt::nominal(f)
        }
    }

    /// The build's deviations in the force model's terms.
    pub fn build(&self) -> Build {
        Build {
            rate: self.spring_rate_scale - 1.0,
            preload_mm: self.preload_offset_mm,
            roller_mm: 0.0,
            profile_mm: 0.0,
            friction: self.friction,
        }
    }

    /// Refuses values no build can have, naming the option.
    pub fn check(&self) -> Result<(), DiagnoseError> {
        let bad = |what: &str, value: f64, expected: &str| {
            Err(DiagnoseError::Build(format!(
                "{what} {value}: expected {expected}"
            )))
        };
        if !(self.spring_rate_scale.is_finite() && (0.05..=20.0).contains(&self.spring_rate_scale))
        {
            return bad(
                "--built-rate-scale",
                self.spring_rate_scale,
                "a factor from 0.05 to 20 on the designed spring rate",
            );
        }
        if !(self.preload_offset_mm.is_finite() && self.preload_offset_mm.abs() <= 100.0) {
            return bad(
                "--built-preload-offset",
                self.preload_offset_mm,
                "a length within +-100 mm",
            );
        }
        if !(self.friction.is_finite()
            && (0.0..crate::model::MAX_FRICTION).contains(&self.friction))
        {
            return bad(
                "--built-friction",
                self.friction,
                "a contact friction coefficient from 0 to below 1",
            );
        }
        if !(self.zero_offset_mm.is_finite() && self.zero_offset_mm.abs() <= 1000.0) {
            return bad(
                "--built-zero-offset",
                self.zero_offset_mm,
                "a length within +-1000 mm",
            );
        }
        Ok(())
    }
}

/// The spring a design becomes when built as `as_built`: its loading and unloading curves
/// through the forward model, for the simulator.
pub fn built_spring(design: &Design, as_built: &AsBuilt) -> Result<BuiltSpring, DiagnoseError> {
    as_built.check()?;
    let follower = &design.spec.follower;
    let (loading, unloading) = build_curves(&design.pitch_curve, follower, &as_built.build())
        .map_err(|x| {
            DiagnoseError::Build(format!(
                "built with contact friction {} the followers jam on loading at x = {x:.3} mm \
                 (pressure angle plus friction angle reach 90 deg)",
                as_built.friction
            ))
        })?;
    Ok(BuiltSpring {
        loading: ForceLaw::Table(TableLaw::new(&loading)),
        unloading: ForceLaw::Table(TableLaw::new(&unloading)),
        position_offset_mm: as_built.zero_offset_mm,
    })
}

/// Why a log could not be diagnosed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DiagnoseError {
    /// Produced by [`diagnose`] for a log too short or too still to fit.
    #[error("{0}")]
    Log(String),
    /// Produced by [`AsBuilt::check`] and [`built_spring`] for a build no part can have.
    #[error("build: {0}")]
    Build(String),
}

/// One build parameter, where a third of its standard deviation must fall for it to be resolved.
pub const RESOLUTION: [(BuildParam, f64); 4] = [
    (BuildParam::SpringRate, 0.01),
    (BuildParam::Preload, 0.05),
    (BuildParam::Friction, 0.005),
    (BuildParam::Zero, 0.05),
];

/// The build parameters `diagnose` fits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum BuildParam {
    /// Relative spring-rate error.
    SpringRate,
    /// Preload offset (mm).
    Preload,
    /// Contact friction coefficient.
    Friction,
    /// Encoder zero (mm).
    Zero,
}

impl BuildParam {
    /// The name with its unit, as in the JSON.
    pub fn key(self) -> &'static str {
        match self {
            BuildParam::SpringRate => "spring_rate_scale",
            BuildParam::Preload => "preload_offset_mm",
            BuildParam::Friction => "friction",
            BuildParam::Zero => "zero_offset_mm",
        }
    }
}

/// One fitted parameter. In JSON an unresolved parameter's `value` is null: the log does not
/// say it, and a number would be a guess.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fitted {
    /// The fitted value.
    pub value: f64,
    /// Its standard deviation.
    pub std: f64,
    /// The design's value.
    pub designed: f64,
    /// Whether the log resolves it ([`RESOLUTION`]); an unresolved value is not a finding.
    pub resolved: bool,
    /// Held at a given value, not fitted (the zero, unless fitted).
    pub fixed: bool,
    /// Its correlation with the fitted zero (0 when the zero is not fitted).
    pub zero_correlation: f64,
}

impl Serialize for Fitted {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        let mut s = serializer.serialize_struct("Fitted", 6)?;
        s.serialize_field(
            "value",
            &(self.resolved || self.fixed).then_some(self.value),
        )?;
        s.serialize_field("std", &self.std)?;
        s.serialize_field("designed", &self.designed)?;
        s.serialize_field("resolved", &self.resolved)?;
        s.serialize_field("fixed", &self.fixed)?;
        s.serialize_field("zero_correlation", &self.zero_correlation)?;
        s.end()
    }
}

/// One bin of the quasi-static force curve on one stroke.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DiagnosisBin {
    /// Mean logged deflection (mm).
    pub x_mm: f64,
    /// Loading (true) or unloading stroke.
    pub loading: bool,
    /// Measured force with the fitted inertia, damping and outside Coulomb friction taken out (N).
    pub measured_n: f64,
    /// Standard error of `measured_n` (N), from the scatter of the means of the bin's separate
    /// passes (runs of consecutive samples in it): within a pass the errors of the dynamic
    /// terms taken out are correlated over the smoothing window, between passes they are not.
    /// With fewer than three passes, counted by weight ([`MIN_WEIGHTED_PASSES`]), the
    /// samples' own scatter about the curve's local slope.
    /// Added to it, the fitted inertia's and damper's error, which every pass shares.
    pub measured_std_n: f64,
    /// The part of `measured_std_n` from the passes' scatter alone (N): independent from one
    /// bin to the next.
    pub pass_std_n: f64,
    /// The rest, the error of the fitted inertia, damping and outside friction taken out (N),
    /// as four independent components: it is shared between bins, two bins' errors covarying
    /// by the dot product of theirs (an outside friction fitted low raises every loading bin
    /// and lowers every unloading bin alike). Its squared length and `pass_std_n` squared
    /// add up to `measured_std_n` squared.
    #[serde(skip)]
    pub shared_error_n: [f64; 4],
    /// The design's forward model there, built as designed and logged with a true zero (N).
    pub designed_n: f64,
    /// The forward model with the fitted build (N).
    pub refitted_n: f64,
    /// Samples in the bin.
    pub samples: usize,
}

/// What `diagnose` found.
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    /// The springs' rate over the designed rate.
    pub spring_rate_scale: Fitted,
    /// Preload offset from the design (mm).
    pub preload_offset_mm: Fitted,
    /// Contact friction coefficient.
    pub friction: Fitted,
    /// Encoder zero (mm): the log reads the deflection plus this.
    pub zero_offset_mm: Fitted,
    /// Inertia taken out (N s^2/mm). The inertia and the damper are what the binned curve
    /// takes out, not measurements of the transmission (identify and estimate give those,
    /// with their deviations): at the long windows a smooth log allows, m takes up the
    /// smoothing's loss of acceleration (0.26 against 0.25, 10 to 17 of its own standard
    /// deviations, on the matrix's multisines), so none is given for them here.
    pub m_n_s2_per_mm: f64,
    /// Coulomb friction outside the cam (guides, seals), taken out (N), with its std.
    pub d0_n: [f64; 2],
    /// Linear damping taken out (N s/mm).
    pub d1_n_s_per_mm: f64,
    /// Cubic damping taken out (N s^3/mm^3).
    pub d2_n_s3_per_mm3: f64,
    /// Reduced chi-square of the fit with its noise weights.
    pub reduced_chi2: f64,
    /// Whether the design's forward model, with the build free, explains the log: its
    /// reduced chi-square from identification's [`MIN_REDUCED_CHI2`] up to
    /// [`BUILD_FIT_MAX_REDUCED_CHI2`] and residuals white beyond one window. Below the low end
    /// the weights, which take the position's noise through the designed stiffness, expect
    /// far more scatter than the log has: the log of a part far softer than this design (the
    /// paper spec's simulated log against the ankle spec: 0.04, with the springs "95 %
    /// softer").
    /// A diagnosis that does not fit is reported as such (exit 1), and `revise` does not
    /// build on it.
    pub fit: Adequacy,
    /// Samples fitted (reversals inside the velocity noise, and transients the window does not
    /// resolve, left out).
    pub samples: usize,
    /// RMS of the quasi-static force against the design's forward model, as a percent of
    /// the designed force's RMS: the miss.
    pub force_error_before_percent: f64,
    /// The same against the re-fitted model: what the found deviations leave unexplained.
    pub force_error_after_percent: f64,
    /// The findings, one sentence each.
    pub findings: Vec<String>,
    /// Parameters the log cannot resolve, each with why.
    pub unresolved: Vec<String>,
    /// The binned curves.
    pub bins: Vec<DiagnosisBin>,
    /// Savitzky-Golay window (s): of those tried, the one kept by the window rule of
    /// [`diagnose`] (from the smallest reduced chi-square, lengthened while the fit still
    /// explains the log and its chi-square does not rise).
    pub sg_window_s: f64,
    /// Every window tried (s) with its fit's reduced chi-square before transients were left
    /// out, which the choice compares (None: it failed).
    pub windows_tried: Vec<(f64, Option<f64>)>,
    /// The log's travel back, over the fitted moving samples, as a share of its travel
    /// forward (the smaller over the larger): below
    /// [`crate::estimate::identify::REVERSAL_TRAVEL_SHARE`] the log moves one way only, and
    /// the friction outside the cam cannot be told from the spring's force on that stroke.
    pub reversal_travel_share: f64,
    /// Samples left out because their position lies beyond the designed stroke by more than
    /// its margin ([`STROKE_MARGIN`]): the design's forward model does not reach them.
    pub outside_stroke_samples: usize,
    /// Samples left out because the force stands clipped there, at the top or bottom of the
    /// load cell's range ([`crate::estimate::log::measured_span`]): their readings are not the
    /// spring's force.
    pub clipped_samples: usize,
    /// Samples left out because a rod against a stop (found by identification) holds them,
    /// or lies within half a window of them ([`diagnose_beyond`]).
    pub stop_samples: usize,
    /// The force channel's delay the force was re-timed by before the diagnosis, if any (set
    /// by the caller that re-timed it).
    pub force_delay: Option<crate::estimate::retime::ForceDelayFit>,
    /// Where no delay was asked for, what identification's profile says of one (set by the
    /// caller that screened the log; None where it was not screened).
    pub force_delay_screen: Option<crate::estimate::retime::ForceDelayScreen>,
}

impl Diagnosis {
    /// Whether the log moves one way only ([`Diagnosis::reversal_travel_share`]): its
    /// outside friction is then a constant on the one stroke it logs, which the spring's
    /// force takes up, and neither the build's spring nor the force curve is resolved.
    pub fn moves_one_way(&self) -> bool {
        self.reversal_travel_share < crate::estimate::identify::REVERSAL_TRAVEL_SHARE
    }

    /// The fitted build (unresolved parameters at their fitted values).
    pub fn as_built(&self) -> AsBuilt {
        AsBuilt {
            spring_rate_scale: self.spring_rate_scale.value,
            preload_offset_mm: self.preload_offset_mm.value,
            friction: self.friction.value,
            zero_offset_mm: self.zero_offset_mm.value,
        }
    }

    /// The fitted parameter `p`.
    pub fn get(&self, p: BuildParam) -> &Fitted {
        match p {
            BuildParam::SpringRate => &self.spring_rate_scale,
            BuildParam::Preload => &self.preload_offset_mm,
            BuildParam::Friction => &self.friction,
            BuildParam::Zero => &self.zero_offset_mm,
        }
    }

    fn get_mut(&mut self, p: BuildParam) -> &mut Fitted {
        match p {
            BuildParam::SpringRate => &mut self.spring_rate_scale,
            BuildParam::Preload => &mut self.preload_offset_mm,
            BuildParam::Friction => &mut self.friction,
            BuildParam::Zero => &mut self.zero_offset_mm,
        }
    }

    /// Carries the standard deviation of a fitted force delay, which the log was re-timed by,
    /// into the build's fitted parameters and the outside friction d0: `plus` and `minus`
    /// diagnose the same log re-timed by the delay plus and minus its standard deviation, and
    /// half of each one's change is added to its standard deviation in quadrature (and noted
    /// in [`Diagnosis::force_delay`]'s `parameter_std`). A parameter the wider deviation no
    /// longer resolves is unresolved, and the findings are judged again. The delay moves the
    /// contact friction most: a load cell read late makes the loading and unloading strokes
    /// part like friction does (on the independent rig's default transmission read 15 ms
    /// late, the friction moved by 1.4 of its own standard deviations over +-1 of the delay's,
    /// the spring rate by 0.1).
    pub fn carry_delay_uncertainty(&mut self, plus: &Diagnosis, minus: &Diagnosis) {
        for (param, limit) in RESOLUTION {
            let change = 0.5 * (plus.get(param).value - minus.get(param).value);
            let f = self.get_mut(param);
            if f.fixed || !change.is_finite() {
                continue;
            }
            f.std = f.std.hypot(change);
            f.resolved = f.resolved && 3.0 * f.std <= limit;
            if let Some(d) = self.force_delay.as_mut() {
                d.parameter_std.insert(param.key(), change.abs());
            }
        }
        let change = 0.5 * (plus.d0_n[0] - minus.d0_n[0]);
        if change.is_finite() {
            self.d0_n[1] = self.d0_n[1].hypot(change);
            if let Some(d) = self.force_delay.as_mut() {
                d.parameter_std.insert("d0_n", change.abs());
            }
        }
        describe(self);
    }
}

#[cfg(test)]
impl Diagnosis {
    /// A diagnosis for unit tests: every build parameter `fitted`, no dynamics, a fit of 1000
    /// samples at a reduced chi-square of 1, and `bins` as its curves.
    pub(crate) fn fixture(fitted: Fitted, bins: Vec<DiagnosisBin>) -> Diagnosis {
        Diagnosis {
            force_delay: None,
            force_delay_screen: None,
            spring_rate_scale: fitted,
            preload_offset_mm: fitted,
            friction: fitted,
            zero_offset_mm: fitted,
            m_n_s2_per_mm: 0.0,
            d0_n: [0.0, 0.0],
            d1_n_s_per_mm: 0.0,
            d2_n_s3_per_mm3: 0.0,
            reduced_chi2: 1.0,
            fit: Adequacy::new(1.0, None),
            samples: 1000,
            force_error_before_percent: 0.0,
            force_error_after_percent: 0.0,
            findings: Vec::new(),
            unresolved: Vec::new(),
            bins,
            sg_window_s: 0.5,
            windows_tried: Vec::new(),
            reversal_travel_share: 1.0,
            outside_stroke_samples: 0,
            clipped_samples: 0,
            stop_samples: 0,
        }
    }
}

/// Parameters of the fit: the four build ones, then m, d0, d1, d2.
const P: usize = 8;

/// Finite-difference steps of the build parameters.
const STEPS: [f64; 4] = [1e-6, 1e-6, 1e-7, 1e-6];

/// Most samples fitted; a longer log is thinned evenly to this.
pub const MAX_SAMPLES: usize = 400_000;

/// A reversal of the stroke is confirmed when the smoothed position comes back this many of
/// its noise's standard deviations from its extreme; samples that close to a turning point are
/// left out.
pub const TURN_SIGMAS: f64 = 6.0;

/// The fit's systematic floor on the standard deviations of rate (relative), preload (mm),
/// friction and zero (mm): the forward model through a smoothed, noisy position leaves errors
/// of this order that the noise alone does not explain (on the simulated builds of
/// docs/CALIBRATION.md the largest were about twice these, against targets five times larger).
pub const FLOOR: [f64; 4] = [0.002, 0.01, 0.0005, 0.01];

/// Where the encoder zero is fitted, a build parameter more correlated with it than this is
/// not resolved apart from it.
pub const MAX_ZERO_CORRELATION: f64 = 0.95;

/// Bins of the curves over the logged deflections.
const BINS: usize = 30;

/// Fewest passes through a bin, counted by their weight (n^2 over the sum of the squared pass
/// lengths), whose means' scatter gives the bin's standard error; with fewer, the samples' own
/// scatter about the curve's slope is taken, not divided down ([`DiagnosisBin::measured_std_n`]).
pub const MIN_WEIGHTED_PASSES: f64 = 3.0;

/// Largest reduced chi-square at which the design's forward model, with the build free,
/// counts as explaining the log. Above identification's limit
/// ([`crate::estimate::adequacy::MAX_REDUCED_CHI2`]): the forward model carries the made
/// cam's path and the design's law with four build parameters, where identification fits
/// the law's own three, and its weights take the position's noise through the designed
/// stiffness. On the independent rig's 199 simulated logs that diagnose (draws 0-59, their digital-encoder
/// reading, and 1000-1099, each diagnosed against its own design) the fits that explained
/// the log reached 1.63 (an encoder read in 1.1 um steps, which identification fits at 1.34);
/// the one log above 2 (draw 1003, 275 moving samples of 30 000) reached 37.
pub const BUILD_FIT_MAX_REDUCED_CHI2: f64 = 2.0;

/// The fit's prepared samples.
struct Samples {
    /// Each sample's index in the smoothed motion.
    index: Vec<usize>,
    x: Vec<f64>,
    xd: Vec<f64>,
    xdd: Vec<f64>,
    sgn: Vec<f64>,
    loading: Vec<bool>,
    f: Vec<f64>,
    /// Each sample's force variance from the force noise and the smoothed position's noise
    /// through the designed stiffness (N^2).
    base_var: Vec<f64>,
    /// The weights 1 / (base_var + the velocity's and acceleration's noise through the
    /// current damping and inertia), see [`Samples::reweight`].
    w: Vec<f64>,
    /// Noise variance of the smoothed velocity ((mm/s)^2): in the weights, and in the
    /// unbiased cube.
    var_xd: f64,
    /// Noise variance of the smoothed acceleration ((mm/s^2)^2).
    var_xdd: f64,
    /// Whether [`Samples::noise_normal`] holds the velocity's noise too (the second stage of
    /// [`fit`]).
    correct_velocity: bool,
}

impl Samples {
    /// The unbiased cube of sample `i`'s velocity ([`unbiased_cube`]).
    fn cube(&self, i: usize) -> f64 {
        unbiased_cube(self.xd[i], self.var_xd)
    }

    /// Weights each sample by its whole force variance at `p`: the force noise, the position's
    /// through the stiffness, and the velocity's and acceleration's through the damping and
    /// the inertia. Without the last two, the acceleration's noise on a heavy transmission at
    /// a short window looked like a misfit (reduced chi-square 40 to 140 on a noisy multisine
    /// of m 0.49), and the window choice went to a long window that rounds the motion.
    fn reweight(&mut self, p: &[f64; P]) {
        self.w = (0..self.x.len())
            .map(|i| {
                let damping = p[6] + 3.0 * p[7] * self.xd[i] * self.xd[i];
                let var =
                    self.base_var[i] + p[4] * p[4] * self.var_xdd + damping * damping * self.var_xd;
                1.0 / var.max(1e-12)
            })
            .collect();
    }

    /// C, the noise part of J' W J that the smoothed acceleration and velocity carry, which
    /// would otherwise pull m, and the damper's slope, towards zero where that noise is a good
    /// part of their spread: sum_i w_i var_xdd on m's diagonal and, with `correct_velocity`,
    /// sum_i w_i var_xd g_i g_i' on d1's and d2's block, g_i = (1, 3 v_i^2) the velocity
    /// noise's first-order direction in their regressors (xd, and the unbiased cube), with v^2
    /// and v^4 taken unbiased from the noisy velocity.
    ///
    /// The velocity's part matters where d1 and d2 are nearly collinear over the log's speeds:
    /// small noise there moves them far along that line. On the independent rig's S-curve
    /// moves of the issue's transmission (paper noise, 1.13 s) the fit without it had d1 1.90
    /// and d2 -0.086 +- 0.006 against 1.5 and -0.008, the same at every seed and none on a
    /// noise-free log; with it, 1.40 +- 0.10 and 0.009 +- 0.015.
    fn noise_normal(&self) -> DMatrix<f64> {
        let mut c = DMatrix::<f64>::zeros(P, P);
        for (i, &w) in self.w.iter().enumerate() {
            let part = self.noise_part(i);
            c[(4, 4)] += w * part.m;
            c[(6, 6)] += w * part.d1_d1;
            c[(6, 7)] += w * part.d1_d2;
            c[(7, 7)] += w * part.d2_d2;
        }
        c[(7, 6)] = c[(6, 7)];
        c
    }

    /// Sample `i`'s unweighted part of C ([`Samples::noise_normal`]): what its smoothed
    /// acceleration's and velocity's noise adds, in expectation, to its part of J' W J. The
    /// sandwich's scores ([`fit`]) take the same part out of each sample, so that they have
    /// mean zero at the true parameters.
    fn noise_part(&self, i: usize) -> NoisePart {
        if !self.correct_velocity {
            return NoisePart {
                m: self.var_xdd,
                ..NoisePart::default()
            };
        }
        let s2 = self.var_xd;
        let v2 = self.xd[i] * self.xd[i];
        let v2u = v2 - s2;
        let v4u = v2 * v2 - 6.0 * v2 * s2 + 3.0 * s2 * s2;
        NoisePart {
            m: self.var_xdd,
            d1_d1: s2,
            d1_d2: s2 * 3.0 * v2u,
            d2_d2: s2 * 9.0 * v4u,
        }
    }
}

/// One sample's part of the noise matrix C ([`Samples::noise_part`]): on m's diagonal, and on
/// d1's and d2's block.
#[derive(Clone, Copy, Default)]
struct NoisePart {
    m: f64,
    d1_d1: f64,
    d1_d2: f64,
    d2_d2: f64,
}

/// One fit: the parameters, their covariance, the reduced chi-square.
struct Fit {
    p: [f64; P],
    /// d0 (N) of the first stage, without the velocity's correction ([`fit`]).
    d0_uncorrected_n: f64,
    cov: DMatrix<f64>,
    reduced_chi2: f64,
}

/// The build's rod force at logged deflection `x_mm` with build parameters `p` (rate, preload
/// offset, friction, zero), on the loading or the unloading stroke.
fn spring_force(design: &Design, p: &[f64; 4], x_mm: f64, loading: bool) -> f64 {
    let build = fitted_build(p);
    let lift = pitch_at(&design.pitch_curve, x_mm - p[3]);
    stroke_force(design, &build, build.friction.atan(), lift, loading)
}

/// The build that the fit's parameters `p` (rate, preload offset, friction) describe, with no
/// roller or profile error.
fn fitted_build(p: &[f64]) -> Build {
    Build {
        rate: p[0],
        preload_mm: p[1],
        roller_mm: 0.0,
        profile_mm: 0.0,
        friction: p[2].max(0.0),
    }
}

/// The `build`'s rod force on one stroke where the made cam has pitch lift and pressure angle
/// `(y, theta)`, with `phi` = atan(friction).
fn stroke_force(
    design: &Design,
    build: &Build,
    phi: f64,
    (y, theta): (f64, f64),
    loading: bool,
) -> f64 {
    let q = spring_load_n(&design.spec.follower, build, y, theta);
    stroke_force_ratio(theta, phi, loading).map_or(JAMMED_N, |ratio| q * ratio)
}

/// The model's force where a build jams (N): it has no loading force, and a steep penalty
/// keeps the fit away from it.
const JAMMED_N: f64 = 1e6;

/// The stroke of each sample (true: loading) from the turning points of `x`, or None within
/// `turn` of a turning point's position around it.
fn strokes(x: &[f64], turn: f64) -> Vec<Option<bool>> {
    let n = x.len();
    let mut turns: Vec<usize> = Vec::new();
    let mut up: Option<bool> = None;
    let (mut hi, mut lo) = (0usize, 0usize);
    for i in 1..n {
        if x[i] > x[hi] {
            hi = i;
        }
        if x[i] < x[lo] {
            lo = i;
        }
        let rising = x[i] - x[lo] > turn;
        let falling = x[hi] - x[i] > turn;
        match up {
            Some(true) | None if falling => {
                turns.push(hi);
                up = Some(false);
                lo = i;
            }
            Some(false) | None if rising => {
                turns.push(lo);
                up = Some(true);
                hi = i;
            }
            _ => {}
        }
    }
    let mut stroke = vec![None; n];
    let mut bounds = turns.clone();
    bounds.push(n.saturating_sub(1));
    for w in bounds.windows(2) {
        let (a, b) = (w[0], w[1]);
        let loading = x[b] > x[a];
        for s in &mut stroke[a..=b] {
            *s = Some(loading);
        }
    }
    for &t in &turns {
        let xt = x[t];
        let mut i = t;
        while i > 0 && (x[i] - xt).abs() <= turn {
            stroke[i] = None;
            i -= 1;
        }
        let mut i = t;
        while i < n && (x[i] - xt).abs() <= turn {
            stroke[i] = None;
            i += 1;
        }
    }
    stroke
}

/// What the differentiator makes of one log: smoothed position, velocity, acceleration, and
/// the velocity that decides which samples move and their Coulomb sign.
struct Smoothed {
    x: Vec<f64>,
    xd: Vec<f64>,
    xdd: Vec<f64>,
    /// From the kernel whose noise the regressors do not share ([`sg::MOTION_VELOCITY`]):
    /// choosing samples, and their friction sign, by the velocity regressor's own noise
    /// traded d0 against d1 on a Table I trapezoid log (d0 -0.74 N and d1 2.54 N s/mm against
    /// 3.82 and 1.84 at a 0.57 s window).
    motion: Vec<f64>,
}

fn smooth(diff: &sg::Differentiator, positions: &[f64], dt: f64) -> Smoothed {
    Smoothed {
        x: diff.apply(positions, dt, sg::POSITION),
        xd: diff.apply(positions, dt, sg::VELOCITY),
        xdd: diff.apply(positions, dt, sg::ACCELERATION),
        motion: diff.apply(positions, dt, sg::MOTION_VELOCITY),
    }
}

/// Noise levels of the smoothed signals, and the thresholds that follow from them.
#[derive(Clone, Copy)]
struct Levels {
    var_f: f64,
    var_x: f64,
    var_xd: f64,
    var_xdd: f64,
    band: f64,
    turn: f64,
}

impl Levels {
    fn new(diff: &sg::Differentiator, noise: &SensorNoise, dt: f64) -> Levels {
        let var_x = diff.noise_variance(sg::POSITION, noise.position_variance_mm2, dt);
        let var_xd = diff.noise_variance(sg::VELOCITY, noise.position_variance_mm2, dt);
        Levels {
            var_f: noise.force_variance_n2,
            var_x,
            var_xd,
            var_xdd: diff.noise_variance(sg::ACCELERATION, noise.position_variance_mm2, dt),
            band: 3.0
                * diff
                    .noise_variance(sg::MOTION_VELOCITY, noise.position_variance_mm2, dt)
                    .sqrt(),
            turn: TURN_SIGMAS * var_x.sqrt(),
        }
    }
}

/// The samples to fit: each with its stroke, the Coulomb sign, and its weight (the force
/// noise plus the smoothed position noise times the designed stiffness there). With
/// `rests` false, samples at rest are left out too (see [`fit_at_window`]).
fn prepare(
    design: &Design,
    m: &Smoothed,
    forces: &[f64],
    levels: &Levels,
    half: usize,
    rests: bool,
    excluded: &[bool],
) -> Samples {
    let n = m.x.len();
    let stroke = strokes(&m.x, levels.turn);
    // Within the velocity's noise band the Coulomb sign is unknown while the motion starts or
    // stops (the smoothed velocity lags by up to half a window): only the inside of a rest,
    // more than half a window from moving samples, counts as at rest.
    let still: Vec<bool> = m.motion.iter().map(|v| v.abs() <= levels.band).collect();
    let mut near_motion = vec![false; n];
    let mut last_moving: Option<usize> = None;
    for i in 0..n {
        if !still[i] {
            last_moving = Some(i);
        }
        near_motion[i] = still[i] && last_moving.is_some_and(|j| i - j <= half);
    }
    let mut next_moving: Option<usize> = None;
    for i in (0..n).rev() {
        if !still[i] {
            next_moving = Some(i);
        }
        near_motion[i] |= still[i] && next_moving.is_some_and(|j| j - i <= half);
    }
    let stride = n.div_ceil(MAX_SAMPLES).max(1);
    let law = &design.law.law;
    let xmax = design.xmax_mm();
    let mut s = Samples {
        index: Vec::new(),
        x: Vec::new(),
        xd: Vec::new(),
        xdd: Vec::new(),
        sgn: Vec::new(),
        loading: Vec::new(),
        f: Vec::new(),
        base_var: Vec::new(),
        w: Vec::new(),
        var_xd: levels.var_xd,
        var_xdd: levels.var_xdd,
        correct_velocity: false,
    };
    for i in (0..n).step_by(stride) {
        let Some(loading) = stroke[i] else { continue };
        if near_motion[i] || (!rests && still[i]) || excluded[i] {
            continue;
        }
        let v = m.xd[i];
        let sgn = match loading {
            true if m.motion[i] > levels.band => 1.0,
            false if m.motion[i] < -levels.band => -1.0,
            _ => 0.0,
        };
        let k = law.stiffness_n_per_mm(m.x[i].clamp(0.0, xmax));
        s.index.push(i);
        s.x.push(m.x[i]);
        s.xd.push(v);
        s.xdd.push(m.xdd[i]);
        s.sgn.push(sgn);
        s.loading.push(loading);
        s.f.push(forces[i]);
        let base = levels.var_f + k * k * levels.var_x;
        s.base_var.push(base);
        s.w.push(1.0 / base.max(1e-12));
    }
    s
}

/// J' W J.
fn weighted_normal(j: &DMatrix<f64>, w: &[f64]) -> DMatrix<f64> {
    let mut a = DMatrix::<f64>::zeros(P, P);
    for (i, &wi) in w.iter().enumerate() {
        let row = j.row(i);
        for u in 0..P {
            for v in u..P {
                a[(u, v)] += row[u] * wi * row[v];
            }
        }
    }
    for u in 0..P {
        for v in 0..u {
            a[(u, v)] = a[(v, u)];
        }
    }
    a
}

/// J' W r.
fn weighted_score(j: &DMatrix<f64>, w: &[f64], r: &[f64]) -> DVector<f64> {
    let mut g = DVector::<f64>::zeros(P);
    for (i, (&wi, &ri)) in w.iter().zip(r).enumerate() {
        for u in 0..P {
            g[u] += j[(i, u)] * wi * ri;
        }
    }
    g
}

/// Solves (A + lambda diag A) step = g, scaled to a unit diagonal; a parameter without
/// information does not move.
fn solve_scaled(
    a: &DMatrix<f64>,
    g: &DVector<f64>,
    lambda: f64,
    free: &[bool; P],
) -> Option<DVector<f64>> {
    let active = active(a, free);
    let q = active.len();
    let d: Vec<f64> = active.iter().map(|&k| a[(k, k)].sqrt()).collect();
    let mut scaled =
        DMatrix::<f64>::from_fn(q, q, |u, v| a[(active[u], active[v])] / (d[u] * d[v]));
    for k in 0..q {
        scaled[(k, k)] *= 1.0 + lambda;
    }
    let rhs = DVector::<f64>::from_fn(q, |u, _| g[active[u]] / d[u]);
    let x = scaled.cholesky()?.solve(&rhs);
    let mut step = DVector::<f64>::zeros(P);
    for (u, &k) in active.iter().enumerate() {
        step[k] = x[u] / d[u];
    }
    Some(step)
}

/// The contact friction's bounds in the fit (its lower one is physical; above 0.9 the cam
/// would lock), and the spring-rate scale's floor (a rate 5 % of the design's).
const FRICTION_BOUNDS: (f64, f64) = (0.0, 0.9);
const MIN_RATE_SCALE: f64 = -0.95;

/// A step of [`solve_scaled`] that holds a parameter at its bound where the free step would
/// push it beyond: the step is solved again without it (an active set). Clamping the step
/// instead (until 2026-11-26) left the other parameters moving as if the held one moved with
/// them: where the log shows no contact friction, each of the moving samples' minimisations
/// crept for all its 60 iterations (sweep draw 84 at 0.8 s: 4 there, and validate on the
/// draw from 36 s to 14 s).
fn step_within_bounds(
    a: &DMatrix<f64>,
    g: &DVector<f64>,
    lambda: f64,
    free: &[bool; P],
    p: &[f64; P],
) -> Option<DVector<f64>> {
    let mut held = *free;
    loop {
        let step = solve_scaled(a, g, lambda, &held)?;
        let mut hold = |k: usize, beyond: bool| {
            let newly = held[k] && beyond;
            if newly {
                held[k] = false;
            }
            newly
        };
        let friction = hold(
            2,
            (p[2] <= FRICTION_BOUNDS.0 && step[2] < 0.0)
                || (p[2] >= FRICTION_BOUNDS.1 && step[2] > 0.0),
        );
        let rate = hold(0, p[0] <= MIN_RATE_SCALE && step[0] < 0.0);
        if !friction && !rate {
            return Some(step);
        }
    }
}

/// The parameters that move: free, and with information in the log.
fn active(a: &DMatrix<f64>, free: &[bool; P]) -> Vec<usize> {
    (0..P).filter(|&k| free[k] && a[(k, k)] > 0.0).collect()
}

/// Residuals of the model at `p`.
fn residuals(design: &Design, s: &Samples, p: &[f64; P]) -> Vec<f64> {
    residuals_on(design, s, p, &lifts(design, s, p[3]))
}

/// The made cam's pitch lift (mm) and pressure angle (rad) at each sample's deflection less
/// the zero `zero_mm`: the part of the spring force that the build's rate, preload and
/// friction leave alone, so that the Jacobian's differences in those reuse it.
fn lifts(design: &Design, s: &Samples, zero_mm: f64) -> Vec<(f64, f64)> {
    s.x.iter()
        .map(|&x| pitch_at(&design.pitch_curve, x - zero_mm))
        .collect()
}

/// [`residuals`] on the samples' [`lifts`] at `p`'s zero: the same numbers as
/// [`spring_force`] at each sample.
fn residuals_on(design: &Design, s: &Samples, p: &[f64; P], lifts: &[(f64, f64)]) -> Vec<f64> {
    let ratios = force_ratios(s, lifts, fitted_build(p).friction.atan());
    residuals_with(design, s, p, lifts, &ratios)
}

/// Each sample's [`stroke_force_ratio`] at the friction angle `phi`: what the rate and preload
/// differences of the Jacobian share.
fn force_ratios(s: &Samples, lifts: &[(f64, f64)], phi: f64) -> Vec<Option<f64>> {
    lifts
        .iter()
        .zip(&s.loading)
        .map(|(&(_, theta), &loading)| stroke_force_ratio(theta, phi, loading))
        .collect()
}

/// [`residuals_on`] with the samples' force ratios at `p`'s friction given.
fn residuals_with(
    design: &Design,
    s: &Samples,
    p: &[f64; P],
    lifts: &[(f64, f64)],
    ratios: &[Option<f64>],
) -> Vec<f64> {
    let build = fitted_build(p);
    lifts
        .iter()
        .zip(ratios)
        .enumerate()
        .map(|(i, (&(y, theta), ratio))| {
            let q = spring_load_n(&design.spec.follower, &build, y, theta);
            s.f[i]
                - ratio.map_or(JAMMED_N, |ratio| q * ratio)
                - p[4] * s.xdd[i]
                - p[5] * s.sgn[i]
                - p[6] * s.xd[i]
                - p[7] * s.cube(i)
        })
        .collect()
}

/// d(model)/dp at `p`, with the samples' [`lifts`] at `p`'s zero given: central differences
/// for the free build parameters, the regressors for the linear ones. A fixed build
/// parameter's column is left zero: neither the steps nor the covariance read it ([`active`]),
/// and the zero's, taken as logged by default, costs the cam's lifts twice over.
fn jacobian_on(
    design: &Design,
    s: &Samples,
    p: &[f64; P],
    at_zero: &[(f64, f64)],
    free: &[bool; P],
) -> DMatrix<f64> {
    let m = s.x.len();
    let mut j = DMatrix::<f64>::zeros(m, P);
    let ratios = force_ratios(s, at_zero, fitted_build(p).friction.atan());
    for k in (0..4).filter(|&k| free[k]) {
        let (mut a, mut b) = (*p, *p);
        a[k] += STEPS[k];
        b[k] -= STEPS[k];
        let (ra, rb) = match k {
            0 | 1 => (
                residuals_with(design, s, &a, at_zero, &ratios),
                residuals_with(design, s, &b, at_zero, &ratios),
            ),
            2 => (
                residuals_on(design, s, &a, at_zero),
                residuals_on(design, s, &b, at_zero),
            ),
            _ => (residuals(design, s, &a), residuals(design, s, &b)),
        };
        for i in 0..m {
            j[(i, k)] = (rb[i] - ra[i]) / (2.0 * STEPS[k]);
        }
    }
    for i in 0..m {
        j[(i, 4)] = s.xdd[i];
        j[(i, 5)] = s.sgn[i];
        j[(i, 6)] = s.xd[i];
        j[(i, 7)] = s.cube(i);
    }
    j
}

/// The Levenberg-Marquardt iterations of [`fit`] at fixed weights; None where the corrected
/// normal matrix is not positive definite (the regressors' noise outweighs what is left of
/// their signal, and the corrected objective has no minimum).
fn minimise(design: &Design, s: &Samples, mut p: [f64; P], free: &[bool; P]) -> Option<[f64; P]> {
    let c = s.noise_normal();
    let as_vector = |p: &[f64; P]| DVector::<f64>::from_fn(P, |k, _| p[k]);
    let cost = |r: &[f64], p: &[f64; P]| -> f64 {
        let q = as_vector(p);
        r.iter().zip(&s.w).map(|(a, w)| a * a * w).sum::<f64>() - (q.transpose() * &c * &q)[(0, 0)]
    };
    // The lifts at the current zero, computed again only when a step moves the zero.
    let mut at_zero = lifts(design, s, p[3]);
    let mut r = residuals_on(design, s, &p, &at_zero);
    let mut cost_now = cost(&r, &p);
    let mut lambda = 1e-3;
    let mut j = jacobian_on(design, s, &p, &at_zero, free);
    let mut normal = weighted_normal(&j, &s.w) - &c;
    positive_definite(&normal, free)?;
    for _ in 0..60 {
        let g = weighted_score(&j, &s.w, &r) + &c * as_vector(&p);
        let mut improved = false;
        for _ in 0..12 {
            let Some(step) = step_within_bounds(&normal, &g, lambda, free, &p) else {
                lambda *= 10.0;
                continue;
            };
            let mut trial = p;
            for k in 0..P {
                trial[k] += step[k];
            }
            trial[2] = trial[2].clamp(FRICTION_BOUNDS.0, FRICTION_BOUNDS.1);
            trial[0] = trial[0].max(MIN_RATE_SCALE);
            let moved = (trial[3] != p[3]).then(|| lifts(design, s, trial[3]));
            let rt = residuals_on(design, s, &trial, moved.as_deref().unwrap_or(&at_zero));
            let ct = cost(&rt, &trial);
            if ct.is_finite() && ct <= cost_now {
                let rel = (cost_now - ct) / cost_now.abs().max(1e-300);
                p = trial;
                if let Some(moved) = moved {
                    at_zero = moved;
                }
                r = rt;
                cost_now = ct;
                lambda = (lambda / 10.0).max(1e-9);
                improved = rel > 1e-10;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
        j = jacobian_on(design, s, &p, &at_zero, free);
        normal = weighted_normal(&j, &s.w) - &c;
    }
    positive_definite(&normal, free)?;
    Some(p)
}

/// Some(()) where the active block of `a` is positive definite.
fn positive_definite(a: &DMatrix<f64>, free: &[bool; P]) -> Option<()> {
    solve_scaled(a, &DVector::<f64>::zeros(P), 0.0, free).map(|_| ())
}

/// Rounds of weights: the first weights know no damping or inertia; the second and third
/// take them from the fit before (as identification's WLS).
const WEIGHT_ROUNDS: usize = 3;

/// Rounds of the second stage, with the velocity's correction ([`fit`]): its weights are the
/// first stage's, and two rounds more changed the parameters only in their third digit (Table I
/// trapezoids, seed 1) for a third more time.
const CORRECTED_ROUNDS: usize = 1;

/// Levenberg-Marquardt from `p` (the design, and the zero if given) over the `free`
/// parameters, then the sandwich covariance over blocks of `block` samples (zero for a fixed
/// parameter).
///
/// The smoothed acceleration and velocity carry noise, so m and the damper are fitted with the
/// errors-in-variables correction of identification: the objective is the weighted sum of
/// squares less p' C p, C the noise part of J' W J ([`Samples::noise_normal`]), whose
/// expectation is the noise-free one's. Its normal matrix is J' W J - C and its gradient
/// J' W r + C p. The weights are the samples' whole force variances at the parameters of the
/// round before ([`Samples::reweight`]).
///
/// In two stages: the acceleration's correction alone, then the velocity's too from there.
/// The first stage's d0 decides whether rests are fitted ([`fit_at_window`]): on a motion
/// controller's moves at one cruise speed, sgn(xd), xd and xd^3 are nearly collinear, and the
/// velocity's correction lets d0 slide along that line into the cam's contact friction (Table I
/// trapezoids, seed 1, 0.57 s: d0 0.35 N and friction 0.06 against 3.82 N and none), so that
/// the rests were kept and the binned curve failed the true law by 16 %. Without the rests
/// the second stage keeps d0 (3.50 +- 0.22 N there; 4.53 +- 0.16 without the velocity's
/// correction).
fn fit(
    design: &Design,
    s: &mut Samples,
    block: usize,
    mut p: [f64; P],
    free: &[bool; P],
) -> Option<Fit> {
    s.correct_velocity = false;
    for _ in 0..WEIGHT_ROUNDS {
        s.reweight(&p);
        p = minimise(design, s, p, free)?;
    }
    let d0_uncorrected_n = p[5];
    s.correct_velocity = true;
    for _ in 0..CORRECTED_ROUNDS {
        s.reweight(&p);
        p = minimise(design, s, p, free)?;
    }
    s.reweight(&p);
    let s = &*s;
    let m = s.x.len();
    let at_zero = lifts(design, s, p[3]);
    let r = residuals_on(design, s, &p, &at_zero);
    let c = s.noise_normal();
    let j = jacobian_on(design, s, &p, &at_zero, free);
    let normal = weighted_normal(&j, &s.w) - &c;
    let chi2: f64 = r.iter().zip(&s.w).map(|(a, w)| a * a * w).sum();
    // Sandwich: (J'WJ - C)^-1 (sum over blocks of g_b g_b') (J'WJ - C)^-1, g_b the block's
    // corrected scores, honest when the residuals are coloured by the smoothing or the weights
    // are off.
    let act = active(&normal, free);
    let q = act.len();
    let d: Vec<f64> = act.iter().map(|&k| normal[(k, k)].sqrt()).collect();
    let scaled = DMatrix::<f64>::from_fn(q, q, |u, v| normal[(act[u], act[v])] / (d[u] * d[v]));
    let inv = scaled
        .try_inverse()
        .map(|inv| DMatrix::<f64>::from_fn(q, q, |u, v| inv[(u, v)] / (d[u] * d[v])))
        .unwrap_or_else(|| DMatrix::<f64>::from_element(q, q, f64::INFINITY));
    let mut meat = DMatrix::<f64>::zeros(q, q);
    let mut start = 0;
    while start < m {
        let end = (start + block.max(1)).min(m);
        let mut gb = DVector::<f64>::zeros(q);
        for i in start..end {
            let mut score = DVector::<f64>::from_fn(P, |k, _| j[(i, k)] * r[i]);
            let part = s.noise_part(i);
            score[4] += part.m * p[4];
            score[6] += part.d1_d1 * p[6] + part.d1_d2 * p[7];
            score[7] += part.d1_d2 * p[6] + part.d2_d2 * p[7];
            for (u, &k) in act.iter().enumerate() {
                gb[u] += s.w[i] * score[k];
            }
        }
        meat += &gb * gb.transpose();
        start = end;
    }
    let small = &inv * meat * &inv;
    let mut cov = DMatrix::<f64>::zeros(P, P);
    for (u, &a) in act.iter().enumerate() {
        for (v, &b) in act.iter().enumerate() {
            cov[(a, b)] = small[(u, v)];
        }
    }
    // A free parameter the log carries no information on is unbounded.
    for k in 0..P {
        if free[k] && !act.contains(&k) {
            cov[(k, k)] = f64::INFINITY;
        }
    }
    Some(Fit {
        p,
        d0_uncorrected_n,
        cov,
        reduced_chi2: chi2 / (m as f64 - P as f64).max(1.0),
    })
}

/// Windows tried when none is given: from [`SHORTEST_WINDOW_S`] up by sqrt(2).
const WINDOWS: usize = 9;

/// The shortest window tried (s).
pub const SHORTEST_WINDOW_S: f64 = 0.2;

/// One window's fit, with its samples.
struct WindowFit {
    fit: Fit,
    samples: Samples,
    window_s: f64,
    /// The spacing (samples) of the whiteness test's lags: the window, rounded up to whole
    /// strides where a long log was thinned ([`WindowFit::whiteness`]).
    lag_spacing: usize,
    /// The smaller share of the velocity's and the acceleration's mean square that is signal.
    signal_share: f64,
    /// The reduced chi-square before transients were left out: what the window choice
    /// compares (leaving samples out lowers it by itself, and a long window that distorts the
    /// motion's corners would look best).
    reduced_chi2_with_transients: f64,
    /// Samples beyond the designed stroke, left out ([`outside_stroke`]).
    outside_stroke: usize,
    /// Samples where the force stands clipped, left out ([`CalibrationLog::unmeasured_force`]).
    clipped: usize,
    /// Samples against a stop, and within half a window of it, left out.
    stopped: usize,
}

/// Smooths the log over `window` samples and fits.
fn fit_at_window(
    design: &Design,
    log: &CalibrationLog,
    noise: &SensorNoise,
    window: usize,
    start: [f64; P],
    free: &[bool; P],
    stop: Option<&crate::estimate::identify::PositionStop>,
) -> Result<WindowFit, DiagnoseError> {
    let dt = log.dt_s();
    let diff = sg::Differentiator::new(window);
    let levels = Levels::new(&diff, noise, dt);
    let motion = smooth(&diff, &log.position_mm, dt);
    let n = motion.x.len();
    if n < 200 {
        return Err(DiagnoseError::Log(format!(
            "{} samples: expected a log of at least {} samples ({} for the differentiator's window and 200 to fit)",
            log.len(),
            diff.window() + 199,
            diff.window() - 1
        )));
    }
    let forces = &log.force_n[diff.half..diff.half + n];
    // The design's forward model holds on the cam's stroke only: beyond it the made cam has no
    // profile (the pitch curve is carried on straight), and a real rod meets its stops. A log
    // whose rod travels far past the stroke (an independent rig's force-controlled heavy rod
    // without stops, draw 1073: 43 % of its samples from -74 to 0 and 15 to 27 mm of a 15 mm
    // stroke) was fitted there against that straight extension, m came out at a fifth of the
    // truth, and the true law failed force_rms at 69.5 %. Those samples are left out.
    let mut excluded = outside_stroke(design, &motion.x, start[3], free[3]);
    let outside = excluded.iter().filter(|&&e| e).count();
    // Nor is a force the load cell clipped the spring's: on the paper spec's log clipped at
    // 60 N, the bins at the clip's onset were judged (the loading bin at 15.50 mm read
    // 59.7 +- 1.4 N against 61.8 N designed) and the preload came out 0.112 +- 0.013 mm long
    // against 0.076 +- 0.010 mm from the same log unclipped. Left out, the bins end at
    // 14.97 mm, short of the clip's onset at 15.07 mm, and the preload is 0.094 +- 0.010 mm.
    let mut clipped = 0;
    for (e, c) in excluded.iter_mut().zip(log.unmeasured_force(diff.half, n)) {
        clipped += usize::from(c && !*e);
        *e |= c;
    }
    // A rod against a stop (found by identification): the samples it holds, and within half
    // a window of them, where the smoothed motion bends round the stop's corner. On the paper
    // spec's log stopped at 15 mm the diagnosis's transients took the stop's samples, and the
    // loading bin at 14.71 mm read 51.6 +- 0.16 N against 50.3 N designed.
    let mut stopped = 0;
    if let Some(stop) = stop {
        for (e, held) in excluded.iter_mut().zip(stop.held(&motion.x, diff.half)) {
            stopped += usize::from(held && !*e);
            *e |= held;
        }
    }
    let noise_hides = || {
        DiagnoseError::Log(format!(
            "at a window of {:.3} s the smoothed velocity's and acceleration's noise outweighs \
             their signal (the errors-in-variables correction leaves no minimum): expected a \
             longer window (--window) or a log with less position noise",
            diff.window() as f64 * dt
        ))
    };
    let stride = n.div_ceil(MAX_SAMPLES).max(1);
    let block_of = |m: usize| (4 * diff.window() / stride).max(1).max(m / 400);
    // At rest, Coulomb friction outside the cam holds whatever force the rod stopped with,
    // anywhere in +-d0 (a rod held still after loading keeps the friction it slid against;
    // one that sticks under a changing force takes up the change). A rest's force then says
    // nothing of the spring beyond +-d0, and taken as the spring's it moved the binned curve
    // of a built Table I transmission (d0 3.8 N) by 3 to 8 % on an independent rig's logs,
    // failing validate. So the moving samples are fitted first, and the rests are added only
    // where that fit finds no such friction: d0 within three of its standard deviations both
    // before the velocity's correction and after it. With the rests in the fit, the
    // correction can trade d0 for contact friction ([`fit`]); on the moving samples alone
    // either stage can miss it (the independent rig's heavy row, trapezoids, seed 1, 0.81 s:
    // 0.44 N before and 0.89 +- 0.22 N after, against 0.5).
    //
    // Fitted first with the rests (until 2026-11-26, sixth session), the contact friction
    // took up the outside friction, d0 came out near zero and the rests stayed: sweep draws 84
    // and 86 (d0 0.21 and 0.60 N) found friction 0.007 and 0.014 against none and failed the
    // true law (force_rms 3.3 and 3.8 %). Likely through slow moves that the velocity's noise
    // band counts as rests, where the model has no Coulomb force.
    let moving = prepare(
        design, &motion, forces, &levels, diff.half, false, &excluded,
    );
    let mut first = None;
    if moving.x.len() >= 200 {
        let mut moving = moving;
        let m = moving.x.len();
        if let Some(f) = fit(design, &mut moving, block_of(m), start, free) {
            first = Some((f, moving));
        }
    }
    let holds_friction =
        |f: &Fit| f.d0_uncorrected_n.max(f.p[5]) > 3.0 * f.cov[(5, 5)].max(0.0).sqrt();
    let (mut fitted, mut s, rests) = match first {
        Some((f, moving)) if holds_friction(&f) => (f, moving, false),
        first => {
            let mut all = prepare(design, &motion, forces, &levels, diff.half, true, &excluded);
            let m = all.x.len();
            if m < 200 {
                return Err(DiagnoseError::Log(format!(
                    "only {m} samples move in a known direction or rest after one: expected a \
                     log that loads and unloads the spring"
                )));
            }
            let from = first.as_ref().map_or(start, |(f, _)| f.p);
            match fit(design, &mut all, block_of(m), from, free) {
                Some(f) => (f, all, true),
                None => {
                    let (f, moving) = first.ok_or_else(noise_hides)?;
                    (f, moving, false)
                }
            }
        }
    };
    // Transients the window does not resolve (a servo's velocity steps) misplace the inertia
    // force, and the binned curve would carry it: as in identification, the samples within
    // half a window of a residual beyond TRANSIENT_SIGMAS of the residuals' robust spread are
    // left out and the fit repeated, when those residuals raise the chi-square by at least
    // the window choice's tolerance and half the samples remain.
    let before = s.x.len();
    let reduced_chi2_with_transients = fitted.reduced_chi2;
    for _ in 0..TRANSIENT_ROUNDS {
        let r = residuals(design, &s, &fitted.p);
        let z: Vec<f64> = r.iter().zip(&s.w).map(|(r, w)| r * w.sqrt()).collect();
        let spread = robust_spread(&z);
        let mut next = excluded.clone();
        let mut excess = 0.0;
        for (k, &zk) in z.iter().enumerate() {
            let zk = zk / spread;
            if zk.abs() > TRANSIENT_SIGMAS {
                excess += zk * zk - 1.0;
                let i = s.index[k];
                mark_window(&mut next, i, diff.half);
            }
        }
        if excess < CHI2_RISE_MIN * s.x.len() as f64 {
            break;
        }
        let mut kept = prepare(design, &motion, forces, &levels, diff.half, rests, &next);
        let m = kept.x.len();
        if 2 * m < before || m < 200 {
            break;
        }
        let Some(refit) = fit(design, &mut kept, block_of(m), fitted.p, free) else {
            break;
        };
        excluded = next;
        fitted = refit;
        s = kept;
    }
    // How much of the acceleration's and the velocity's spread over the fitted samples is
    // signal rather than their filtered noise: where the noise dominates, the corrections'
    // first order leaves m and the damper a bias it does not remove.
    let share = |values: &[f64], noise: f64| {
        let total = values.iter().map(|v| v * v).sum::<f64>() / values.len().max(1) as f64;
        if total > 0.0 {
            (1.0 - noise / total).max(0.0)
        } else {
            0.0
        }
    };
    let var_xd = diff.noise_variance(sg::VELOCITY, noise.position_variance_mm2, dt);
    let var_xdd = diff.noise_variance(sg::ACCELERATION, noise.position_variance_mm2, dt);
    let signal_share = share(&s.xd, var_xd).min(share(&s.xdd, var_xdd));
    Ok(WindowFit {
        fit: fitted,
        samples: s,
        window_s: diff.window() as f64 * dt,
        signal_share,
        reduced_chi2_with_transients,
        outside_stroke: outside,
        clipped,
        stopped,
        lag_spacing: diff.window().div_ceil(stride) * stride,
    })
}

impl WindowFit {
    /// The whiteness test of the fit's residuals beyond one window, at lags of whole windows
    /// (rounded up to whole strides where a long log was thinned, so that the lagged samples
    /// are fitted ones). None where there are too few samples, and where the position is read
    /// in steps (`quantised`): their error is a function of the position, the same on every
    /// pass, and this fit weighs it as white noise (identification models it), so its
    /// residuals are correlated over passes however right the build. On the independent rig's
    /// digital-encoder draws 0-59 the test failed on 9 of 52 fits that explained the log
    /// (reduced chi-squares 1.00 to 1.43, identification's whiteness p 0.001 to 0.86).
    /// Worked out only for the windows the choice looks at: its near lags cost up to a
    /// window's length of products per sample.
    fn whiteness(&self, design: &Design, quantised: bool) -> Option<Whiteness> {
        if quantised {
            return None;
        }
        let s = &self.samples;
        let standardized: Vec<f64> = residuals(design, s, &self.fit.p)
            .iter()
            .zip(&s.w)
            .map(|(r, w)| r * w.sqrt())
            .collect();
        whiteness(&standardized, &s.index, self.lag_spacing)
    }
}

/// How far past either end of the designed stroke a sample is still fitted, as a share of
/// the stroke: a zero a little off, or a rod that overshoots its end, stays in the fit.
pub const STROKE_MARGIN: f64 = 0.1;

/// Which of the smoothed positions `x` lie beyond the designed stroke by more than its
/// margin ([`STROKE_MARGIN`]), with the encoder zero at `zero_mm`. None where the zero is
/// fitted (`zero_free`): the samples are chosen before it is known, and an encoder read
/// reversed is zeroed at the stroke's other end, a whole stroke from where it is logged.
fn outside_stroke(design: &Design, x: &[f64], zero_mm: f64, zero_free: bool) -> Vec<bool> {
    let xmax = design.xmax_mm();
    x.iter()
        .map(|&x| !zero_free && beyond_stroke(x - zero_mm, xmax))
        .collect()
}

/// Whether a deflection `x_mm` lies beyond the stroke `0 ..= xmax_mm` by more than its
/// margin ([`STROKE_MARGIN`]): the one rule the diagnosis and validate's coverage share.
pub fn beyond_stroke(x_mm: f64, xmax_mm: f64) -> bool {
    let margin = xmax_mm * STROKE_MARGIN;
    !(-margin..=xmax_mm + margin).contains(&x_mm)
}

/// 1.4826 times the median absolute deviation from the median (the standard deviation of
/// Gaussian values, unmoved by a few outliers); 1 for fewer than two values.
fn robust_spread(z: &[f64]) -> f64 {
    if z.len() < 2 {
        return 1.0;
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let mut v = z.to_vec();
    let centre = median(&mut v);
    let mut dev: Vec<f64> = z.iter().map(|x| (x - centre).abs()).collect();
    let mad = median(&mut dev);
    if mad > 0.0 {
        1.4826 * mad
    } else {
        1.0
    }
}

/// Diagnoses a built spring from its calibration log with the design's forward model.
/// `window_s` overrides the differentiator's window (by default chosen from the data, from
/// [`SHORTEST_WINDOW_S`] up by sqrt(2): see the rule in the body); `zero`
/// says how the encoder zero is taken: as logged, given, or fitted with the rest.
///
/// On an exponential law a shift of the zero is nearly a change of scale, so where the zero
/// is fitted, the spring rate (and often the preload) trades against it over the logged
/// stroke: a parameter whose correlation with the zero exceeds [`MAX_ZERO_CORRELATION`] is
/// named as not resolved apart from it.
pub fn diagnose(
    design: &Design,
    log: &CalibrationLog,
    noise: &SensorNoise,
    window_s: Option<f64>,
    zero: PositionOffset,
) -> Result<Diagnosis, DiagnoseError> {
    diagnose_beyond(design, log, noise, window_s, zero, None)
}

/// [`diagnose`], with the samples a stop holds, which identification found
/// ([`crate::estimate::identify::PositionStop`]), left out with half a window round them.
pub fn diagnose_beyond(
    design: &Design,
    log: &CalibrationLog,
    noise: &SensorNoise,
    window_s: Option<f64>,
    zero: PositionOffset,
    stop: Option<&crate::estimate::identify::PositionStop>,
) -> Result<Diagnosis, DiagnoseError> {
    let dt = log.dt_s();
    let assembled = AsBuilt::assembled(&design.spec);
    let nominal_friction = assembled.friction;
    let (zero_start, zero_free) = match zero {
        PositionOffset::None => (0.0, false),
        PositionOffset::Mm(c) => (c, false),
        PositionOffset::Auto => (0.0, true),
    };
    let mut free = [true; P];
    free[3] = zero_free;
    let start = [
        assembled.spring_rate_scale - 1.0,
        assembled.preload_offset_mm,
        nominal_friction,
        zero_start,
        0.0,
        0.0,
        0.0,
        0.0,
    ];
    let at = |w: usize| fit_at_window(design, log, noise, w, start, &free, stop);
    let windows: Vec<usize> = match window_s {
        Some(w) => vec![((w / dt).round() as usize).max(sg::MIN_WINDOW) | 1],
        None => {
            let mut ws: Vec<usize> = (0..WINDOWS)
                .map(|k| {
                    ((SHORTEST_WINDOW_S * 2f64.sqrt().powi(k as i32) / dt).round() as usize)
                        .max(sg::MIN_WINDOW)
                        | 1
                })
                .filter(|&w| w <= log.len() / 8)
                .collect();
            ws.dedup();
            if ws.is_empty() {
                ws.push(sg::MIN_WINDOW);
            }
            ws
        }
    };
    let tried: Vec<Result<WindowFit, DiagnoseError>> = windows.par_iter().map(|&w| at(w)).collect();
    let candidates: Vec<(f64, Option<f64>)> = tried
        .iter()
        .zip(&windows)
        .map(|(t, &w)| (w as f64 * dt, t.as_ref().ok().map(|f| f.fit.reduced_chi2)))
        .collect();
    // Windows where the filtered noise makes up more than three quarters of the velocity's or
    // the acceleration's mean square are not compared (half the best share, where no window
    // reaches a quarter): there the fit's m and d1 sink towards zero, and leaving transients
    // out can then make it look best.
    let best_share = tried
        .iter()
        .filter_map(|t| t.as_ref().ok())
        .map(|f| f.signal_share)
        .fold(0.0_f64, f64::max);
    let min_share = MIN_SIGNAL_SHARE.min(0.5 * best_share);
    // The window kept: from the compared window with the smallest reduced chi-square,
    // lengthened while the next window's fit still explains the log by identification's
    // measure (a reduced chi-square from MIN_REDUCED_CHI2 to MAX_REDUCED_CHI2), keeps a
    // physical inertia, and does not raise the chi-square over any shorter window of the run
    // by more than identification's distortion threshold (CHI2_RISE_SIGMAS standard
    // deviations of a reduced chi-square, at least CHI2_RISE_MIN): as in identification's
    // balancing, a longer window takes less noise into the dynamics it takes out until it
    // distorts the motion, and a rise of the chi-square is the first sign. The run stops at the
    // first window that fails, so that a longer one that explains the log again, having bent
    // the motion another way, is not reached. Kept as "the longest within 0.5 to 1.5"
    // (until 2026-11-26), the issue row's noisy trapezoids (seed 5, four times the paper's
    // noise, 120 s; chi-squares 0.96, 1.03, 1.16 and 1.45 from 1.13 to 3.21 s) went to 3.21 s,
    // where d1 was 2.21 against 1.5, and failed the true law (force_max 3.3 %); 1.13 s passes
    // it (1.6 %). That rule had been needed while the velocity's noise biased the damper at
    // short windows ([`Samples::noise_normal`]).
    //
    // An inertia below zero by more than three of its standard deviations is a window that
    // distorts the motion, however small its chi-square's rise: on the build loop's light
    // sines (tests/build_loop.rs) 2.27 s explained the log at 1.30 with m -0.005 N s^2/mm, the
    // spring rate 0.4 % and the preload 0.017 mm off, and the revision's true build failed
    // force_max (2.06 % against 2 %).
    //
    // A window whose residuals are correlated beyond one window (the whiteness test at
    // identification's level) distorts the motion too, where its chi-square has not yet
    // risen: on the independent rig's multisine draw 25 (1 kHz, m 0.19, d1 0.14) 1.6 s
    // explained the log at 1.03, its residuals' whiteness p 7.5e-12, with "the springs are
    // 0.8 % stiffer than designed (+- 0.2 %)" and "the preload is 0.032 mm short" for springs
    // built as designed; at 1.13 s, p 0.75 and no finding.
    let explains = |c: f64| (MIN_REDUCED_CHI2..=MAX_REDUCED_CHI2).contains(&c);
    let physical = |f: &WindowFit| f.fit.p[4] >= -3.0 * f.fit.cov[(4, 4)].max(0.0).sqrt();
    let quantised = noise.position_quantisation.is_some();
    let coloured = |f: &WindowFit| {
        f.whiteness(design, quantised)
            .is_some_and(|w| w.p_value < WHITENESS_LEVEL)
    };
    let compared: Vec<Option<&WindowFit>> = tried
        .iter()
        .map(|t| t.as_ref().ok().filter(|f| f.signal_share >= min_share))
        .collect();
    // The start: the shortest window whose chi-square is within the distortion threshold of
    // the smallest, among physical fits, or among all where none is. Windows within it explain
    // the log alike, and a longer one only takes the chance of a distortion: on a
    // force-controlled rod that slips (the independent rig's digital-encoder sweep, draw 78,
    // 1.2 um, m 0.28, d0 0.63 N) the breakaways are transients at every window, the
    // chi-squares with them 5.1 to 5.6 from 0.2 to 3.2 s, and the smallest, at 2.27 s, had d0
    // at half the truth and d1 35 % high: the true law failed force_max (4.2 %).
    let smallest_where = |keep: &dyn Fn(&WindowFit) -> bool| {
        let eligible = || {
            compared
                .iter()
                .enumerate()
                .filter_map(|(i, f)| f.filter(|f| keep(f)).map(|f| (i, f)))
        };
        let least = eligible()
            .map(|(_, f)| f.reduced_chi2_with_transients)
            .min_by(f64::total_cmp)?;
        eligible()
            .find(|(_, f)| {
                f.reduced_chi2_with_transients
                    <= least * (1.0 + chi2_rise_tolerance(f.samples.x.len()))
            })
            .map(|(i, _)| i)
    };
    let smallest = smallest_where(&physical).or_else(|| smallest_where(&|_| true));
    let kept = smallest.map(|start| {
        let mut last = start;
        for (i, f) in compared.iter().enumerate().skip(start + 1) {
            let Some(f) = f else { break };
            if !explains(f.reduced_chi2_with_transients) || !physical(f) || coloured(f) {
                break;
            }
            let rise = chi2_rise_tolerance(f.samples.x.len());
            let distorted = compared[start..i].iter().flatten().any(|g| {
                f.reduced_chi2_with_transients > g.reduced_chi2_with_transients * (1.0 + rise)
            });
            if distorted {
                break;
            }
            last = i;
        }
        last
    });
    let mut best: Option<WindowFit> = None;
    let mut first_error = None;
    for (i, t) in tried.into_iter().enumerate() {
        match t {
            Ok(f) if Some(i) == kept => best = Some(f),
            Ok(_) => {}
            Err(e) => {
                first_error.get_or_insert(e);
            }
        }
    }
    let residual_whiteness = best.as_ref().and_then(|f| f.whiteness(design, quantised));
    let Some(WindowFit {
        fit,
        samples: s,
        window_s,
        outside_stroke,
        clipped,
        stopped,
        ..
    }) = best
    else {
        return Err(
            first_error.unwrap_or_else(|| DiagnoseError::Log("no window fits this log".into()))
        );
    };
    let m = s.x.len();
    let p = fit.p;
    let mut adequacy = Adequacy::within(
        fit.reduced_chi2,
        residual_whiteness,
        MIN_REDUCED_CHI2..=BUILD_FIT_MAX_REDUCED_CHI2,
    );
    if adequacy.problem().is_some() {
        adequacy.reasons.push(
            "or a build that the rate, preload, contact friction and zero cannot describe: a cam \
             cut to another profile, springs of another law, or a log of another design's part"
                .into(),
        );
    }
    let std: [f64; P] = std::array::from_fn(|q| {
        let own = fit.cov[(q, q)].max(0.0).sqrt();
        match FLOOR.get(q) {
            Some(&floor) if free[q] => own.hypot(floor),
            _ => own,
        }
    });
    let correlation_with_zero = |q: usize| {
        if !zero_free || q == 3 {
            return 0.0;
        }
        fit.cov[(q, 3)] / (std[q] * std[3]).max(1e-300)
    };
    let fitted = |q: usize, value: f64, designed: f64, param: BuildParam| {
        let limit = RESOLUTION
            .iter()
            .find(|(r, _)| *r == param)
            .map_or(f64::INFINITY, |r| r.1);
        let zero_correlation = correlation_with_zero(q);
        Fitted {
            value,
            std: std[q],
            designed,
            resolved: std[q].is_finite()
                && 3.0 * std[q] <= limit
                && zero_correlation.abs() <= MAX_ZERO_CORRELATION,
            fixed: !free[q],
            zero_correlation,
        }
    };
    let mut diagnosis = Diagnosis {
        force_delay: None,
        force_delay_screen: None,
        spring_rate_scale: fitted(
            0,
            1.0 + p[0],
            assembled.spring_rate_scale,
            BuildParam::SpringRate,
        ),
        preload_offset_mm: fitted(1, p[1], assembled.preload_offset_mm, BuildParam::Preload),
        friction: fitted(2, p[2].max(0.0), nominal_friction, BuildParam::Friction),
        zero_offset_mm: fitted(3, p[3], 0.0, BuildParam::Zero),
        m_n_s2_per_mm: p[4],
        d0_n: [p[5], std[5]],
        d1_n_s_per_mm: p[6],
        d2_n_s3_per_mm3: p[7],
        reduced_chi2: fit.reduced_chi2,
        fit: adequacy,
        samples: m,
        force_error_before_percent: f64::NAN,
        force_error_after_percent: f64::NAN,
        findings: Vec::new(),
        unresolved: Vec::new(),
        bins: Vec::new(),
        sg_window_s: window_s,
        windows_tried: candidates,
        outside_stroke_samples: outside_stroke,
        clipped_samples: clipped,
        stop_samples: stopped,
        // The moving samples' velocities, each signed as its friction is.
        reversal_travel_share: crate::estimate::identify::reversal_travel_share(
            s.xd.iter()
                .zip(&s.sgn)
                .filter(|(_, g)| **g != 0.0)
                .map(|(v, g)| v.abs().copysign(*g)),
        ),
    };
    if diagnosis.moves_one_way() {
        // The friction outside the cam is a constant on the one stroke logged: the build's
        // spring takes it up, and what the fit finds of them is the trade, not the build.
        // (Sweep draw 328 of the independent rig, a force-controlled rod that slides forward
        // only: d0 0.97 +- 0.05 N against 2.13, and "the springs are 78.7 % softer than
        // designed (+- 0.2 %)" for springs built as designed.)
        for f in [
            &mut diagnosis.spring_rate_scale,
            &mut diagnosis.preload_offset_mm,
            &mut diagnosis.friction,
        ] {
            f.resolved = false;
        }
        diagnosis.d0_n[1] = f64::INFINITY;
    }
    bin_curves(design, &s, &p, &fit.cov, &mut diagnosis);
    describe(&mut diagnosis);
    Ok(diagnosis)
}

/// The binned quasi-static curves on each stroke, and the force error before and after.
/// `cov` is the fit's covariance: a bin's standard error holds the dynamics' uncertainty too.
fn bin_curves(
    design: &Design,
    s: &Samples,
    p: &[f64; P],
    cov: &DMatrix<f64>,
    diagnosis: &mut Diagnosis,
) {
    let (lo, hi) =
        s.x.iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
    let width = ((hi - lo) / BINS as f64).max(1e-12);
    let bin_of = |x: f64| (((x - lo) / width) as usize).min(BINS - 1);
    let quasi_static =
        |i: usize| s.f[i] - p[4] * s.xdd[i] - p[5] * s.sgn[i] - p[6] * s.xd[i] - p[7] * s.cube(i);
    let mut sums = vec![[(0.0, 0.0, 0usize); 2]; BINS];
    // Per bin, the sums of the dynamic terms' regressors (xdd, sgn, xd, the cube): the mean
    // quasi-static force's gradient in m, d0, d1 and d2.
    let mut regressors = vec![[[0.0_f64; 4]; 2]; BINS];
    for i in 0..s.x.len() {
        let (k, side) = (bin_of(s.x[i]), usize::from(s.loading[i]));
        let e = &mut sums[k][side];
        e.0 += s.x[i];
        e.1 += quasi_static(i);
        e.2 += 1;
        let g = &mut regressors[k][side];
        g[0] += s.xdd[i];
        g[1] += s.sgn[i];
        g[2] += s.xd[i];
        g[3] += s.cube(i);
    }
    let a = AsBuilt::assembled(&design.spec);
    let nominal = [
        a.spring_rate_scale - 1.0,
        a.preload_offset_mm,
        a.friction,
        0.0,
    ];
    let build = [p[0], p[1], p[2], p[3]];
    // Each bin's passes: the sum and count of its samples' force about the refitted curve's
    // local slope, one entry per run of consecutive samples in the bin.
    let slope = |xm: f64, loading: bool| {
        let h = (0.1 * width).max(1e-6);
        (spring_force(design, &build, xm + h, loading)
            - spring_force(design, &build, xm - h, loading))
            / (2.0 * h)
    };
    let centre = |k: usize, side: usize| {
        let (sx, _, count) = sums[k][side];
        (count > 0).then(|| sx / count as f64)
    };
    let slopes: Vec<[f64; 2]> = (0..BINS)
        .map(|k| [0, 1].map(|side| centre(k, side).map_or(0.0, |xm| slope(xm, side == 1))))
        .collect();
    // Per pass: the sum of its samples' forces about the slope, their sum of squares, count.
    let mut passes = vec![[Vec::<(f64, f64, usize)>::new(), Vec::new()]; BINS];
    let mut previous: Option<(usize, usize)> = None;
    for i in 0..s.x.len() {
        let (k, side) = (bin_of(s.x[i]), usize::from(s.loading[i]));
        let xm = centre(k, side).unwrap_or(s.x[i]);
        let r = quasi_static(i) - slopes[k][side] * (s.x[i] - xm);
        let list = &mut passes[k][side];
        match list.last_mut() {
            Some(last) if previous == Some((k, side)) => {
                last.0 += r;
                last.1 += r * r;
                last.2 += 1;
            }
            _ => list.push((r, r * r, 1)),
        }
        previous = Some((k, side));
    }
    let shared = shared_factor(cov);
    let (mut before, mut after, mut scale) = (0.0, 0.0, 0.0);
    for (k, bin) in sums.iter().enumerate() {
        for (side, &(sx, sf, count)) in bin.iter().enumerate() {
            if count < 10 {
                continue;
            }
            let loading = side == 1;
            let xm = sx / count as f64;
            let mean = sf / count as f64;
            let list = &passes[k][side];
            let n = count as f64;
            let scatter_std_n = pass_scatter_std(list, mean);
            // The fitted dynamics' error moves every pass of the bin alike, so the passes'
            // scatter does not hold it: g' C g, g the bin's mean regressors of m, d0, d1 and
            // d2. Without it, on the independent rig's trapezoids of the heavy row (seed 1)
            // the 0.81 s window's d0, 0.22 +- 0.25 N against 0.5, put every loading bin about
            // 3 of its standard errors high and every unloading bin as far low, and the true
            // law failed (force_max 5.4 %).
            // (A parameter the log carries no information on, its variance unbounded, is
            // left out: its regressor is then nothing in the samples.)
            let g = regressors[k][side].map(|v| v / n);
            let shared_error_n = shared.map(|column| (0..4).map(|a| g[a] * column[a]).sum());
            let shared_var: f64 = shared_error_n.iter().map(|h: &f64| h * h).sum();
            let measured_std_n = scatter_std_n.hypot(shared_var.sqrt());
            let b = DiagnosisBin {
                x_mm: xm,
                loading,
                measured_n: mean,
                measured_std_n,
                pass_std_n: scatter_std_n,
                shared_error_n,
                designed_n: spring_force(design, &nominal, xm, loading),
                refitted_n: spring_force(design, &build, xm, loading),
                samples: count,
            };
            before += (b.measured_n - b.designed_n).powi(2);
            after += (b.measured_n - b.refitted_n).powi(2);
            scale += b.designed_n.powi(2);
            diagnosis.bins.push(b);
        }
    }
    diagnosis.force_error_before_percent = 100.0 * (before / scale.max(1e-300)).sqrt();
    diagnosis.force_error_after_percent = 100.0 * (after / scale.max(1e-300)).sqrt();
}

/// A factor of the fitted dynamics' covariance (m, d0, d1 and d2, the last four of the fit's
/// parameters): four columns v_c with C = sum_c v_c v_c', so that a bin with mean regressors g
/// has the shared error components g . v_c ([`DiagnosisBin::shared_error_n`]). A parameter
/// the log carries no information on (its variance unbounded) is left out: its regressor is
/// then nothing in the samples.
fn shared_factor(cov: &DMatrix<f64>) -> [[f64; 4]; 4] {
    let bounded = |a: usize| cov[(4 + a, 4 + a)].is_finite();
    let c = nalgebra::Matrix4::from_fn(|a, b| {
        let v = cov[(4 + a, 4 + b)];
        if bounded(a) && bounded(b) && v.is_finite() {
            v
        } else {
            0.0
        }
    });
    let eigen = c.symmetric_eigen();
    std::array::from_fn(|col| {
        let root = eigen.eigenvalues[col].max(0.0).sqrt();
        std::array::from_fn(|a| eigen.eigenvectors[(a, col)] * root)
    })
}

/// A bin's standard error from its passes, each (sum of its samples' forces about the curve's
/// slope, their sum of squares, count), about the bin's `mean`.
///
/// Within a pass the errors of the dynamic terms taken out are correlated over the smoothing
/// window, between passes they are not, so the scatter of the passes' means is what the bin's
/// mean varies by: their weighted spread, times v / (v - 1) for v passes. Passes are counted
/// by their weight, n^2 over the sum of the squared pass lengths: a pass that the position
/// noise breaks at the bin's edge leaves one-sample fragments, whose scatter says nothing of
/// the long pass that holds the mean. With fewer than [`MIN_WEIGHTED_PASSES`], the samples'
/// own scatter is taken, not divided down. (On the independent rig's sweep draw 223, a
/// force-controlled soft spring with 3.7 N of friction, two bins each held one slide of 28 and
/// 32 samples and four one-sample fragments: their standard errors were 0.025 N, a seventh of
/// their neighbours', their means 0.3 N off the law, and the true law failed force_max at
/// 5.6 %.)
fn pass_scatter_std(passes: &[(f64, f64, usize)], mean: f64) -> f64 {
    let n = passes.iter().map(|p| p.2).sum::<usize>() as f64;
    let squared_lengths: f64 = passes.iter().map(|p| (p.2 as f64).powi(2)).sum();
    if n < 2.0 {
        return 0.0;
    }
    if n * n / squared_lengths >= MIN_WEIGHTED_PASSES {
        let v = passes.len() as f64;
        let spread: f64 = passes
            .iter()
            .map(|&(sum, _, c)| (c as f64 / n).powi(2) * (sum / c as f64 - mean).powi(2))
            .sum();
        (spread * v / (v - 1.0)).sqrt()
    } else {
        let squares: f64 = passes.iter().map(|p| p.1).sum();
        ((squares - n * mean * mean).max(0.0) / (n - 1.0)).sqrt()
    }
}

/// The findings and the unresolved parameters, in words.
fn describe(d: &mut Diagnosis) {
    let significant = |f: &Fitted, limit: f64| {
        f.resolved && (f.value - f.designed).abs() > (3.0 * f.std).max(limit / 3.0)
    };
    let mut findings = Vec::new();
    let mut unresolved = Vec::new();
    if d.moves_one_way() {
        unresolved.push(format!(
            "the log moves one way only (its travel back is {:.1} % of its travel forward): the \
             friction outside the cam cannot be told from the spring's force on the one stroke \
             logged, so neither the springs, the preload, the contact friction nor the force \
             curve is resolved; a log that loads and unloads resolves them",
            100.0 * d.reversal_travel_share
        ));
    }
    for (param, limit) in RESOLUTION {
        let f = *d.get(param);
        if f.fixed {
            continue;
        }
        if !f.resolved {
            if d.moves_one_way() && param != BuildParam::Zero {
                // Said once, above.
                continue;
            }
            unresolved.push(if f.zero_correlation.abs() > MAX_ZERO_CORRELATION {
                format!(
                    "{}: not resolved apart from the encoder zero over this log (correlation \
                     {:+.3}): give the rig's zero (--position-offset VALUE) or log more of the stroke",
                    param.key(),
                    f.zero_correlation
                )
            } else {
                format!(
                    "{}: not resolved by this log (three standard deviations, {:.4}, exceed {limit}); \
                     a log that covers more of the stroke, loads and unloads, or runs longer resolves it",
                    param.key(),
                    3.0 * f.std
                )
            });
            continue;
        }
        if !significant(&f, limit) {
            continue;
        }
        findings.push(match param {
            BuildParam::SpringRate => format!(
                "the springs are {:.1} % {} than designed (+- {:.1} %)",
                100.0 * (f.value / f.designed - 1.0).abs(),
                if f.value > f.designed { "stiffer" } else { "softer" },
                100.0 * f.std / f.designed
            ),
            BuildParam::Preload => format!(
                "the preload is {:.3} mm {} (+- {:.3} mm of follower travel)",
                (f.value - f.designed).abs(),
                if f.value < f.designed { "short" } else { "long" },
                f.std
            ),
            BuildParam::Friction => format!(
                "the contact friction is {:.4} (+- {:.4}) against {:.4} designed",
                f.value, f.std, f.designed
            ),
            BuildParam::Zero => format!(
                "the encoder zero is {:+.3} mm off (+- {:.3} mm): the log reads the deflection plus this; \
                 validate and estimate take it out with --position-offset auto",
                f.value, f.std
            ),
        });
    }
    if d.d0_n[0].abs() > 3.0 * d.d0_n[1] && d.d0_n[0].abs() > 0.05 {
        findings.push(format!(
            "a Coulomb friction of {:.2} N (+- {:.2} N) acts outside the cam (rod guides, seals)",
            d.d0_n[0], d.d0_n[1]
        ));
    }
    d.findings = findings;
    d.unresolved = unresolved;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A diagnosis with every build parameter fitted at `friction` for the contact friction
    /// (designed 0) and on its design otherwise, each to +-`std` (the zero held), and the
    /// force re-timed by a fitted delay.
    fn fitted_friction(friction: f64, std: f64) -> Diagnosis {
        let fitted = |value: f64, designed: f64| Fitted {
            value,
            std,
            designed,
            resolved: true,
            fixed: false,
            zero_correlation: 0.0,
        };
        Diagnosis {
            force_delay: Some(crate::estimate::retime::ForceDelayFit {
                std_s: Some(0.003),
                fitted: true,
                ..crate::estimate::retime::ForceDelayFit::given(0.015)
            }),
            spring_rate_scale: fitted(1.0, 1.0),
            preload_offset_mm: fitted(0.0, 0.0),
            friction: fitted(friction, 0.0),
            zero_offset_mm: Fitted {
                fixed: true,
                ..fitted(0.0, 0.0)
            },
            ..Diagnosis::fixture(fitted(0.0, 0.0), Vec::new())
        }
    }

    #[test]
    fn a_fitted_delays_uncertainty_widens_the_build_and_can_unmake_a_finding() {
        // Contact friction 0.004 +- 0.0004 against 0 designed: a finding (10 standard
        // deviations). Re-timed by the delay -+ its standard deviation the friction is 0.0015
        // and 0.0065: half the change, 0.0025, joins its deviation in quadrature (0.00253),
        // three of which exceed the 0.005 that resolves the friction.
        let mut d = fitted_friction(0.004, 0.0004);
        describe(&mut d);
        assert_eq!(d.findings.len(), 1, "{:?}", d.findings);
        assert!(
            d.findings[0].contains("contact friction"),
            "{:?}",
            d.findings
        );
        let (minus, plus) = (
            fitted_friction(0.0015, 0.0004),
            fitted_friction(0.0065, 0.0004),
        );
        d.carry_delay_uncertainty(&plus, &minus);
        let expected = 0.0004_f64.hypot(0.0025);
        assert!(
            (d.friction.std - expected).abs() < 1e-12,
            "{:?}",
            d.friction
        );
        assert!(!d.friction.resolved, "{:?}", d.friction);
        assert!(d.findings.is_empty(), "{:?}", d.findings);
        assert!(
            d.unresolved.iter().any(|u| u.starts_with("friction")),
            "{:?}",
            d.unresolved
        );
        // The spring rate did not move with the delay: its deviation is as fitted. The change
        // each parameter took is reported with the delay; the held zero takes none.
        assert_eq!(d.spring_rate_scale.std, 0.0004);
        let delay = d.force_delay.as_ref().unwrap();
        assert!((delay.parameter_std["friction"] - 0.0025).abs() < 1e-12);
        assert!(!delay.parameter_std.contains_key("zero_offset_mm"));
    }

    /// One bin's passes from the given pass lengths: each pass's samples are its offset plus
    /// white noise (standard deviation `noise`).
    fn passes(
        lengths: &[usize],
        offsets: &[f64],
        noise: f64,
        rng: &mut impl rand::Rng,
    ) -> Vec<(f64, f64, usize)> {
        use rand_distr::{Distribution, Normal};
        let white = Normal::new(0.0, noise).expect("a positive standard deviation");
        lengths
            .iter()
            .zip(offsets)
            .map(|(&c, &offset)| {
                let samples: Vec<f64> = (0..c).map(|_| offset + white.sample(rng)).collect();
                (samples.iter().sum(), samples.iter().map(|v| v * v).sum(), c)
            })
            .collect()
    }

    fn mean_of(passes: &[(f64, f64, usize)]) -> f64 {
        passes.iter().map(|p| p.0).sum::<f64>() / passes.iter().map(|p| p.2).sum::<usize>() as f64
    }

    #[test]
    fn passes_whose_errors_differ_give_the_spread_of_the_bins_mean() {
        // Six passes of 20 samples, each off by its own error (0.3) plus white noise (0.1):
        // the bin's mean varies by sqrt(0.3^2 / 6 + 0.1^2 / 120), and the passes' scatter
        // estimates that variance without bias.
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let pass_error = Normal::new(0.0, 0.3).expect("a positive standard deviation");
        let truth = 0.3_f64.powi(2) / 6.0 + 0.1_f64.powi(2) / 120.0;
        let trials = 20_000;
        let mean_variance = (0..trials)
            .map(|_| {
                let offsets: Vec<f64> = (0..6).map(|_| pass_error.sample(&mut rng)).collect();
                let p = passes(&[20; 6], &offsets, 0.1, &mut rng);
                pass_scatter_std(&p, mean_of(&p)).powi(2)
            })
            .sum::<f64>()
            / trials as f64;
        assert!(
            (mean_variance / truth - 1.0).abs() < 0.03,
            "{mean_variance} against {truth}"
        );
    }

    #[test]
    fn a_pass_broken_at_the_bins_edge_counts_as_one() {
        // One slide of 32 samples and four one-sample fragments of it (the position noise
        // crossing the bin's edge), all off by the slide's error: five passes by count, 1.26
        // by weight. The standard error is the samples' own scatter, as for the unbroken pass
        // of 36 samples; the fragments' scatter about the slide (a fifth of it and less) was
        // taken before.
        use rand::SeedableRng;
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let broken = passes(&[32, 1, 1, 1, 1], &[0.3; 5], 0.1, &mut rng);
        let whole = vec![broken
            .iter()
            .fold((0.0, 0.0, 0), |a, p| (a.0 + p.0, a.1 + p.1, a.2 + p.2))];
        let mean = mean_of(&broken);
        let (b, w) = (
            pass_scatter_std(&broken, mean),
            pass_scatter_std(&whole, mean),
        );
        assert!((b - w).abs() <= 1e-12 * w, "{b} against {w}");
        assert!(
            (w / 0.1 - 1.0).abs() < 0.4,
            "{w}: the samples' scatter, 0.1"
        );
        // Three equal passes are passes.
        let three = passes(&[12, 12, 12], &[0.3, -0.3, 0.0], 0.1, &mut rng);
        assert!(pass_scatter_std(&three, mean_of(&three)) > 0.1);
    }

    /// A positive definite normal matrix with every parameter coupled to the friction.
    fn coupled() -> DMatrix<f64> {
        DMatrix::<f64>::from_fn(P, P, |u, v| {
            if u == v {
                4.0 + u as f64
            } else if u == 2 || v == 2 {
                1.5
            } else {
                0.3
            }
        })
    }

    #[test]
    fn a_step_that_would_take_the_friction_below_zero_holds_it_and_solves_for_the_rest() {
        let a = coupled();
        // The free step pushes the friction down: g's friction entry is strongly negative.
        let g = DVector::<f64>::from_fn(P, |k, _| if k == 2 { -10.0 } else { 0.5 });
        let free = [true; P];
        let free_step = solve_scaled(&a, &g, 0.0, &free).unwrap();
        assert!(free_step[2] < 0.0);
        let mut p = [0.0; P];
        p[2] = FRICTION_BOUNDS.0;
        let step = step_within_bounds(&a, &g, 0.0, &free, &p).unwrap();
        assert_eq!(step[2], 0.0);
        // The others solve their own block of the normal equations (the stationarity of the
        // objective with the friction held), which the clamped free step does not.
        let others: Vec<usize> = (0..P).filter(|&k| k != 2).collect();
        let residual = |s: &DVector<f64>| {
            others
                .iter()
                .map(|&u| {
                    let row: f64 = others.iter().map(|&v| a[(u, v)] * s[v]).sum();
                    (row - g[u]).abs()
                })
                .fold(0.0_f64, f64::max)
        };
        assert!(residual(&step) < 1e-12, "{}", residual(&step));
        let mut clamped = free_step.clone();
        clamped[2] = 0.0;
        assert!(residual(&clamped) > 0.1, "{}", residual(&clamped));
        // Away from the bound, or pushed back into the range, the step is the free one.
        p[2] = 0.2;
        assert_eq!(
            step_within_bounds(&a, &g, 0.0, &free, &p).unwrap(),
            free_step
        );
        p[2] = FRICTION_BOUNDS.0;
        let inward = -&g;
        assert_eq!(
            step_within_bounds(&a, &inward, 0.0, &free, &p).unwrap(),
            solve_scaled(&a, &inward, 0.0, &free).unwrap()
        );
    }

    #[test]
    fn the_friction_at_its_ceiling_and_the_rate_at_its_floor_are_held_too() {
        let a = coupled();
        let g = DVector::<f64>::from_fn(P, |k, _| match k {
            0 => -10.0,
            2 => 10.0,
            _ => 0.5,
        });
        let free = [true; P];
        let free_step = solve_scaled(&a, &g, 0.0, &free).unwrap();
        assert!(free_step[0] < 0.0 && free_step[2] > 0.0);
        let mut p = [0.0; P];
        p[0] = MIN_RATE_SCALE;
        p[2] = FRICTION_BOUNDS.1;
        let step = step_within_bounds(&a, &g, 0.0, &free, &p).unwrap();
        assert_eq!((step[0], step[2]), (0.0, 0.0));
        assert!(step.iter().any(|&v| v != 0.0));
    }
}
