//! The pitch curve: the roller-centre path Y(x) that makes the rod force follow the law.
//!
//! Virtual work (docs/THEORY.md section 2) gives, per unit follower spring force q = k_eff*(Y+Yp),
//! a required rod force F = q*tan(theta) without friction and q*tan(theta +/- phi) with it.
//! Solving for the tangent angle theta gives a direction field (a, b) with tan(theta) = b/a:
//!
//! | correction | a | b |
//! | --- | --- | --- |
//! | none | q | F |
//! | loading | q + mu*F | F - mu*q |
//! | unloading | q - mu*F | F + mu*q |
//! | midline | (1+mu^2) q + sqrt((1+mu^2)^2 q^2 + 4 F^2 mu^2) | 2F |
//!
//! The curve is integrated in arc length s, d(x, Y)/ds = (a, b)/|(a, b)|, which has no
//! singular start even where theta = 90 deg (no preload, no friction: Y ~ sqrt(x)). Each
//! sample is reached by an 8th-order Dormand-Prince integration (ode_solvers' DOP853) at
//! tolerance 1e-12, so samples carry no interpolation error; the sample spacing only
//! controls the chord error of the polyline through them. The last sample is placed exactly on
//! x = Xmax by root finding on the arc length of the final step. Curvature is analytic:
//! kappa = d(theta)/ds = (a b' - b a') / (a^2 + b^2).

use ode_solvers::{Dop853, OutputType, System, Vector2};
use roots::{find_root_brent, SimpleConvergency};
use serde::Serialize;

use crate::model::ForceLaw;
use crate::model::{Follower, FrictionCorrection};

/// Tolerance of the pitch-curve integration (relative and absolute, mm).
pub const ODE_TOLERANCE: f64 = 1e-12;

/// Upper bound on the number of samples of one curve.
const MAX_SAMPLES: usize = 200_000;

/// One sample of the pitch curve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PitchSample {
    /// Arc length from the start.
    pub s_mm: f64,
    /// Rod deflection (cam position).
    pub x_mm: f64,
    /// Follower lift Y (roller-centre height above its start).
    pub y_mm: f64,
    /// Tangent angle theta = pressure angle of the roller on the cam.
    pub theta_rad: f64,
    /// Signed curvature d(theta)/ds; negative where the curve bends towards the cam material.
    pub curvature_per_mm: f64,
}

/// How finely to sample the curve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SynthesisOptions {
    /// Largest chord error of the polylines through the samples (pitch curve and the cam
    /// surface at the roller offset).
    pub chord_tolerance_mm: f64,
    /// Largest arc length between samples.
    pub max_step_mm: f64,
}

/// Why a pitch curve could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CamError {
    /// Produced by [`synthesize`] when friction alone would exceed the target force, so the
    /// corrected curve would have to descend (loading correction).
    #[error(
        "at x = {x_mm:.4} mm the friction force {friction_n:.4} N exceeds the target force \
         {force_n:.4} N, so no rising cam can follow the law with the `{correction}` correction. {advice}"
    )]
    FrictionExceedsForce {
        /// Where it happens.
        x_mm: f64,
        /// mu * q.
        friction_n: f64,
        /// The target force there.
        force_n: f64,
        /// The correction in use.
        correction: String,
        /// What to change.
        advice: String,
    },
    /// Produced by [`synthesize`] when the correction needs a pressure angle of 90 deg or more
    /// (the returning follower would jam).
    #[error(
        "at x = {x_mm:.4} mm the `{correction}` correction needs a pressure angle of 90 deg or more \
         (the spring force {spring_n:.4} N is too small against friction {friction_n:.4} N). {advice}"
    )]
    CorrectionLocks {
        /// Where it happens.
        x_mm: f64,
        /// q there.
        spring_n: f64,
        /// mu * F there.
        friction_n: f64,
        /// The correction in use.
        correction: String,
        /// What to change.
        advice: String,
    },
    /// Produced by [`synthesize`] when the integrator fails or the curve would need too many samples.
    #[error(
        "the pitch curve cannot be followed near x = {x_mm:.4} mm ({message}); the law changes \
         too fast for these followers there: lower law.k2 (or the stroke law.xmax), or raise \
         follower.spring_rate or follower.preload"
    )]
    Integration {
        /// Where.
        x_mm: f64,
        /// The integrator's message.
        message: String,
    },
}

/// The direction field and its partial derivatives with respect to F and q.
#[derive(Debug, Clone, Copy)]
struct Direction {
    a: f64,
    b: f64,
    a_f: f64,
    a_q: f64,
    b_f: f64,
    b_q: f64,
}

fn direction(correction: FrictionCorrection, mu: f64, force: f64, q: f64) -> Direction {
    let correction = if mu == 0.0 {
        FrictionCorrection::None
    } else {
        correction
    };
    match correction {
        FrictionCorrection::None => Direction {
            a: q,
            b: force,
            a_f: 0.0,
            a_q: 1.0,
            b_f: 1.0,
            b_q: 0.0,
        },
        FrictionCorrection::Loading => Direction {
            a: q + mu * force,
            b: force - mu * q,
            a_f: mu,
            a_q: 1.0,
            b_f: 1.0,
            b_q: -mu,
        },
        FrictionCorrection::Unloading => Direction {
            a: q - mu * force,
            b: force + mu * q,
            a_f: -mu,
            a_q: 1.0,
            b_f: 1.0,
            b_q: mu,
        },
        FrictionCorrection::Midline => {
            let c = 1.0 + mu * mu;
            let w = (c * c * q * q + 4.0 * force * force * mu * mu).sqrt();
            Direction {
                a: c * q + w,
                b: 2.0 * force,
                a_f: 4.0 * force * mu * mu / w,
                a_q: c + c * c * q / w,
                b_f: 2.0,
                b_q: 0.0,
            }
        }
    }
}

/// The mechanics that define the pitch curve: law, followers and friction correction.
#[derive(Debug, Clone)]
pub struct PitchField {
    law: std::sync::Arc<ForceLaw>,
    k_eff: f64,
    preload: f64,
    mu: f64,
    correction: FrictionCorrection,
}

impl PitchField {
    /// The field for a law and follower arrangement.
    pub fn new(law: &ForceLaw, follower: &Follower) -> PitchField {
        PitchField {
            law: std::sync::Arc::new(law.clone()),
            k_eff: follower.k_eff_n_per_mm(),
            preload: follower.preload_mm,
            mu: follower.friction_coefficient(),
            correction: follower.friction_correction,
        }
    }

    fn direction_at(&self, x: f64, y: f64) -> Direction {
        direction(
            self.correction,
            self.mu,
            self.law.force_n(x),
            self.k_eff * (y + self.preload),
        )
    }

    /// Unit tangent (cos theta, sin theta) at a point of the curve.
    pub fn unit_tangent(&self, x: f64, y: f64) -> (f64, f64) {
        let d = self.direction_at(x, y);
        let h = d.a.hypot(d.b);
        (d.a / h, d.b / h)
    }

    /// Signed curvature d(theta)/ds at a point of the curve.
    pub fn curvature(&self, x: f64, y: f64) -> f64 {
        let d = self.direction_at(x, y);
        let h2 = d.a * d.a + d.b * d.b;
        let h = h2.sqrt();
        let (c, s) = (d.a / h, d.b / h);
        let df = self.law.stiffness_n_per_mm(x) * c;
        let dq = self.k_eff * s;
        let da = d.a_f * df + d.a_q * dq;
        let db = d.b_f * df + d.b_q * dq;
        (d.a * db - d.b * da) / h2
    }

    fn sample(&self, s: f64, x: f64, y: f64) -> PitchSample {
        let d = self.direction_at(x, y);
        PitchSample {
            s_mm: s,
            x_mm: x,
            y_mm: y,
            theta_rad: d.b.atan2(d.a),
            curvature_per_mm: self.curvature(x, y),
        }
    }

    /// Refuses a point where the curve would descend or turn back.
    fn validate(&self, x: f64, y: f64) -> Result<(), CamError> {
        let force = self.law.force_n(x);
        let q = self.k_eff * (y + self.preload);
        let d = self.direction_at(x, y);
        let name = self.correction.to_string();
        if d.b.is_nan() || d.b <= 0.0 {
            let yp_max = force / (self.mu * self.k_eff) - y;
            return Err(CamError::FrictionExceedsForce {
                x_mm: x,
                friction_n: self.mu * q,
                force_n: force,
                correction: name,
                advice: if x == 0.0 {
                    format!(
                        "Reduce follower.preload below {yp_max:.4} mm, or reduce friction below {:.4}.",
                        force / q
                    )
                } else {
                    "Reduce friction or preload, or use the `none` correction.".into()
                },
            });
        }
        if d.a.is_nan() || d.a < 0.0 {
            return Err(CamError::CorrectionLocks {
                x_mm: x,
                spring_n: q,
                friction_n: self.mu * force,
                correction: name.clone(),
                advice: if x == 0.0 {
                    format!(
                        "Give follower.preload at least {:.4} mm, or use the `loading` or `midline` correction.",
                        self.mu * force / self.k_eff - y
                    )
                } else {
                    "Use the `loading` or `midline` correction, or more preload.".into()
                },
            });
        }
        Ok(())
    }
}

/// d(x, Y)/ds for the ODE solver.
struct ArcLengthSystem<'a> {
    field: &'a PitchField,
}

impl System<f64, Vector2<f64>> for ArcLengthSystem<'_> {
    fn system(&self, _s: f64, v: &Vector2<f64>, dv: &mut Vector2<f64>) {
        let (c, s) = self.field.unit_tangent(v[0], v[1]);
        dv[0] = c;
        dv[1] = s;
    }
}

/// Integrates from `state` at arc length `s0` over `ds`.
fn advance(
    field: &PitchField,
    s0: f64,
    state: Vector2<f64>,
    ds: f64,
) -> Result<Vector2<f64>, CamError> {
    if ds <= 0.0 {
        return Ok(state);
    }
    if ds < 1e-9 {
        // Below the integrator's resolution (it would report step underflow): one Euler step,
        // whose error ds^2 * kappa / 2 is far below 1e-12.
        let (c, s) = field.unit_tangent(state[0], state[1]);
        return Ok(Vector2::new(state[0] + ds * c, state[1] + ds * s));
    }
    let mut solver = Dop853::new(
        ArcLengthSystem { field },
        s0,
        s0 + ds,
        ds,
        state,
        ODE_TOLERANCE,
        ODE_TOLERANCE,
    );
    solver.set_output(OutputType::Sparse);
    solver.integrate().map_err(|e| CamError::Integration {
        x_mm: state[0],
        message: format!("the integrator reports: {e}"),
    })?;
    let end = *solver
        .y_out()
        .last()
        .expect("the solver stores the end point");
    if !(end[0].is_finite() && end[1].is_finite()) {
        return Err(CamError::Integration {
            x_mm: state[0],
            message: "non-finite state".into(),
        });
    }
    Ok(end)
}

/// The sampled pitch curve with the mechanics it was made from.
#[derive(Debug, Clone)]
pub struct PitchCurve {
    /// Samples from x = 0 to x = Xmax, increasing in x and Y.
    pub samples: Vec<PitchSample>,
    /// The field (law, followers, friction) it follows.
    pub field: PitchField,
}

impl PitchCurve {
    /// The exact sample at arc length `s_mm` (0 <= s <= the last sample's s), integrated from
    /// the nearest sample below at the synthesis tolerance: no interpolation.
    pub fn exact_at_arc(&self, s_mm: f64) -> Result<PitchSample, CamError> {
        let i = self
            .samples
            .partition_point(|q| q.s_mm <= s_mm)
            .saturating_sub(1);
        let base = self.samples[i];
        let end = advance(
            &self.field,
            base.s_mm,
            Vector2::new(base.x_mm, base.y_mm),
            s_mm - base.s_mm,
        )?;
        Ok(self.field.sample(s_mm, end[0], end[1]))
    }

    /// The final lift Y(Xmax).
    pub fn lift_mm(&self) -> f64 {
        self.samples.last().map_or(0.0, |s| s.y_mm)
    }

    /// The largest pressure angle, in degrees, and where.
    pub fn max_pressure_angle(&self) -> (f64, f64) {
        self.samples
            .iter()
            .map(|s| (s.theta_rad.to_degrees(), s.x_mm))
            .fold(
                (f64::NEG_INFINITY, 0.0),
                |m, v| if v.0 > m.0 { v } else { m },
            )
    }

    /// The smallest radius of curvature on the material side (where the curve bends towards
    /// the cam), and where; `None` if the curve never bends that way.
    pub fn min_material_side_radius(&self) -> Option<(f64, f64)> {
        self.samples
            .iter()
            .filter(|s| s.curvature_per_mm < 0.0)
            .map(|s| (-1.0 / s.curvature_per_mm, s.x_mm))
            .fold(None, |m: Option<(f64, f64)>, v| match m {
                Some(m) if m.0 <= v.0 => Some(m),
                _ => Some(v),
            })
    }
}

/// The largest arc-length step whose chord error stays within `tol` on the pitch curve
/// (curvature `kappa`) and on its offset by `r` towards the material (chord error scales
/// with |kappa*(1 + r*kappa)| * ds^2 / 8).
fn step_for_tolerance(kappa: f64, r: f64, tol: f64, max_step: f64) -> f64 {
    let bend = kappa.abs().max((kappa * (1.0 + r * kappa)).abs());
    if bend <= 0.0 {
        max_step
    } else {
        (8.0 * tol / bend).sqrt().min(max_step)
    }
}

/// Makes the pitch curve of `law` for `follower` over 0 <= x <= `xmax_mm`.
pub fn synthesize(
    law: impl Into<ForceLaw>,
    follower: &Follower,
    xmax_mm: f64,
    options: &SynthesisOptions,
) -> Result<PitchCurve, CamError> {
    let field = PitchField::new(&law.into(), follower);
    let r = follower.roller_radius_mm;
    let tol = options.chord_tolerance_mm;
    let min_step = (tol * 1e-3).max(1e-9);
    field.validate(0.0, 0.0)?;
    let mut samples = vec![field.sample(0.0, 0.0, 0.0)];
    loop {
        let cur = *samples.last().expect("non-empty");
        let state = Vector2::new(cur.x_mm, cur.y_mm);
        let mut ds =
            step_for_tolerance(cur.curvature_per_mm, r, tol, options.max_step_mm).max(min_step);
        let (next, next_state) = loop {
            let next_state = advance(&field, cur.s_mm, state, ds)?;
            let next = field.sample(cur.s_mm + ds, next_state[0], next_state[1]);
            let ds_end = step_for_tolerance(next.curvature_per_mm, r, tol, options.max_step_mm);
            if ds_end >= 0.9 * ds || ds <= min_step {
                break (next, next_state);
            }
            ds = ds_end.max(min_step);
        };
        if next_state[0] >= xmax_mm {
            // Land exactly on x = Xmax: x(s) increases, so find the arc length where it is Xmax.
            let mut conv = SimpleConvergency {
                eps: 1e-14,
                max_iter: 100,
            };
            let mut failure = None;
            let ds_end = find_root_brent(
                0.0,
                ds,
                |h| match advance(&field, cur.s_mm, state, h) {
                    Ok(v) => v[0] - xmax_mm,
                    Err(e) => {
                        failure = Some(e);
                        f64::NAN
                    }
                },
                &mut conv,
            )
            .map_err(|e| CamError::Integration {
                x_mm: cur.x_mm,
                message: format!("end point: {e}"),
            })?;
            if let Some(e) = failure {
                return Err(e);
            }
            let end = advance(&field, cur.s_mm, state, ds_end)?;
            field.validate(xmax_mm, end[1])?;
            samples.push(field.sample(cur.s_mm + ds_end, xmax_mm, end[1]));
            break;
        }
        field.validate(next.x_mm, next.y_mm)?;
        if next.x_mm < cur.x_mm || next.y_mm < cur.y_mm {
            return Err(CamError::Integration {
                x_mm: cur.x_mm,
                message: "the curve turned back".into(),
            });
        }
        samples.push(next);
        if samples.len() > MAX_SAMPLES {
            return Err(CamError::Integration {
                x_mm: next.x_mm,
                message: format!(
                    "more than {MAX_SAMPLES} samples needed; raise output.chord_tolerance"
                ),
            });
        }
    }
    Ok(PitchCurve { samples, field })
}

/// Closed-form frictionless lift: Y(x) = sqrt(Yp^2 + 2E(x)/k_eff) - Yp (docs/THEORY.md section 2),
/// written to avoid cancellation for small E.
pub fn frictionless_lift_mm(law: &ForceLaw, k_eff: f64, preload_mm: f64, x_mm: f64) -> f64 {
    let e2 = 2.0 * law.energy_nmm(x_mm) / k_eff;
    e2 / ((preload_mm * preload_mm + e2).sqrt() + preload_mm)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{FrictionSource, SpringArrangement};

    #[test]
    fn directions_reproduce_the_friction_relations() {
        // For each correction, the force relation it is built on must hold for tan(theta) = b/a.
        let (force, q, mu): (f64, f64, f64) = (37.0, 21.0, 0.13);
        let phi = mu.atan();
        let theta = |d: Direction| d.b.atan2(d.a);
        let load = theta(direction(FrictionCorrection::Loading, mu, force, q));
        assert!((q * (load + phi).tan() - force).abs() < 1e-12 * force);
        let unload = theta(direction(FrictionCorrection::Unloading, mu, force, q));
        assert!((q * (unload - phi).tan() - force).abs() < 1e-12 * force);
        let mid = theta(direction(FrictionCorrection::Midline, mu, force, q));
        let mean = 0.5 * q * ((mid + phi).tan() + (mid - phi).tan());
        assert!((mean - force).abs() < 1e-12 * force);
    }

    #[test]
    fn partials_match_finite_differences() {
        for corr in [
            FrictionCorrection::Loading,
            FrictionCorrection::Unloading,
            FrictionCorrection::Midline,
        ] {
            let (f, q, mu, h) = (12.0, 7.0, 0.2, 1e-6);
            let d = direction(corr, mu, f, q);
            let df = direction(corr, mu, f + h, q);
            let dq = direction(corr, mu, f, q + h);
            assert!(((df.a - d.a) / h - d.a_f).abs() < 1e-5);
            assert!(((df.b - d.b) / h - d.b_f).abs() < 1e-5);
            assert!(((dq.a - d.a) / h - d.a_q).abs() < 1e-5);
            assert!(((dq.b - d.b) / h - d.b_q).abs() < 1e-5);
        }
    }

    #[test]
    fn step_rule_bounds_the_sagitta() {
        let ds = step_for_tolerance(1.0 / 0.5, 0.0, 1e-3, 10.0);
        let sagitta = 0.5 * (1.0 - (ds / (2.0 * 0.5)).cos());
        assert!(sagitta <= 1e-3 * 1.0001);
    }

    #[test]
    fn unloading_correction_without_preload_is_refused_with_the_needed_preload() {
        let law = ForceLaw::Exponential(crate::model::ExpLaw {
            mu_n: 1.0,
            k2_per_mm: 0.26,
            f0_n: 1.2,
        });
        let f = Follower {
            count: 1,
            arrangement: SpringArrangement::PerFollower,
            spring_rate_n_per_mm: 5.0,
            preload_mm: 0.0,
            roller_radius_mm: 0.0,
            friction: FrictionSource::Coefficient { coefficient: 0.1 },
            friction_correction: FrictionCorrection::Unloading,
            bearing: Default::default(),
        };
        let opts = SynthesisOptions {
            chord_tolerance_mm: 1e-3,
            max_step_mm: 0.1,
        };
        let e = synthesize(&law, &f, 20.0, &opts).unwrap_err();
        assert!(e.to_string().contains("at least 0.0440 mm"), "{e}");
        // With that preload it works.
        assert!(synthesize(&law, &f.with_preload(0.045), 20.0, &opts).is_ok());
    }
}
