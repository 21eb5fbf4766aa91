//! The exponential force law F(x) = mu*exp(k2*x) + F0 and its solver from design targets.
//!
//! Stiffness is affine in force: dF/dx = k2*(F - F0). From the targets (Fmax at Xmax, Fmin at
//! L0, relative force error C0 at L0 for a deflection error delta0) the exponent alpha = k2*L0
//! is the positive root of the paper's eq. (5), solved here in the better-conditioned form
//! h(alpha) = (Fr - 1) - Sr*(exp((Lr-1)*alpha) - 1)/alpha, which has the meaningless root
//! alpha = 0 divided out. See docs/THEORY.md ("The law") for why the root differs
//! from the value printed in the paper.

use roots::{find_root_brent, SimpleConvergency};
use serde::Serialize;

use crate::model::{limits::MAX_EXPONENT, Condition, ExpLaw, ForceLaw, LawTargets};

/// Relative residuals of the three design conditions for a solved law.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Residuals {
    /// (F(L0) - Fmin) / Fmin.
    pub force_at_l0: f64,
    /// (F(Xmax) - Fmax) / Fmax.
    pub force_at_xmax: f64,
    /// (C0 achieved - C0) / C0, with C0 achieved = F'(L0)*delta0/F(L0).
    pub c0: f64,
}

impl Residuals {
    /// The largest absolute residual.
    pub fn max_abs(&self) -> f64 {
        self.force_at_l0
            .abs()
            .max(self.force_at_xmax.abs())
            .max(self.c0.abs())
    }
}

/// A law with where it came from.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SolvedLaw {
    /// The law.
    pub law: ForceLaw,
    /// alpha = k2 * L0, when solved from targets.
    pub alpha: Option<f64>,
    /// Residuals of the design conditions, when solved from targets.
    pub residuals: Option<Residuals>,
    /// Relative residual of each condition, when solved from conditions.
    pub condition_residuals: Option<Vec<f64>>,
}

impl SolvedLaw {
    /// A law used as it is (given or tabulated): no residuals.
    pub fn as_given(law: ForceLaw) -> SolvedLaw {
        SolvedLaw {
            law,
            alpha: None,
            residuals: None,
            condition_residuals: None,
        }
    }

    /// The exponential law, when the law is one.
    pub fn exponential(&self) -> Option<&ExpLaw> {
        self.law.exponential()
    }
}

/// Why a law could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LawError {
    /// Produced by [`solve_conditions`] when no exponential law with k2 > 0 meets the
    /// conditions.
    #[error(
        "no exponential law F = mu exp(k2 x) + F0 with k2 > 0 and a positive force meets the \
         conditions {conditions}; {hint}"
    )]
    NoExponentialLaw {
        /// The conditions, as written.
        conditions: String,
        /// What range would work.
        hint: String,
    },
    /// Produced by [`solve`] when eq. (5) has no positive root: the targets describe a
    /// spring whose stiffness falls with force.
    #[error(
        "these targets ask for a softening spring: eq. (5) has no positive root because \
         Fr - 1 = {fr_minus_one:.6} is not greater than Sr*(Lr - 1) = {sr_lr:.6} \
         (Fr = Fmax/Fmin = {fr:.6}, Lr = Xmax/L0 = {lr:.6}, Sr = C0*L0/delta0 = {sr:.6}). \
         Raise fmax, or lower c0 (the stiffness at L0) to below {c0_max:.6}"
    )]
    Softening {
        /// Fr.
        fr: f64,
        /// Lr.
        lr: f64,
        /// Sr.
        sr: f64,
        /// Fr - 1.
        fr_minus_one: f64,
        /// Sr*(Lr - 1).
        sr_lr: f64,
        /// The largest C0 that still gives a stiffening spring.
        c0_max: f64,
    },
    /// Produced by [`solve`] when the root could not be bracketed or refined.
    #[error("the solver for alpha did not converge: {0}")]
    NoConvergence(String),
    /// Produced by [`solve`] and [`check_law`] when the law gives no positive force at x = 0.
    #[error(
        "the law gives F(0) = mu + F0 = {f_at_zero:.6} N, but the spring force must be positive \
         over the whole stroke; {fix}"
    )]
    NonPositiveStartForce {
        /// mu + F0.
        f_at_zero: f64,
        /// What to change, in the terms of the spec's form.
        fix: String,
    },
}

/// Checks that a given law can be realised by a spring over x >= 0.
pub fn check_law(law: &ExpLaw) -> Result<(), LawError> {
    let f_at_zero = law.force_n(0.0);
    if f_at_zero > 0.0 {
        Ok(())
    } else {
        Err(LawError::NonPositiveStartForce {
            f_at_zero,
            fix: format!(
                "raise law.f0 above {:.6} N (= -mu) or raise law.mu",
                -law.mu_n
            ),
        })
    }
}

/// The positive root alpha of eq. (5), or why there is none.
pub fn solve_alpha(t: &LawTargets) -> Result<f64, LawError> {
    let (fr, lr, sr) = (t.force_ratio(), t.length_ratio(), t.sensitivity_ratio());
    // h(alpha) = g(alpha)/alpha, with h(0+) = (Fr - 1) - Sr*(Lr - 1) and h strictly decreasing.
    let h = |alpha: f64| (fr - 1.0) - sr * ((lr - 1.0) * alpha).exp_m1() / alpha;
    let h0 = (fr - 1.0) - sr * (lr - 1.0);
    if h0.is_nan() || h0 <= 0.0 || lr <= 1.0 {
        return Err(LawError::Softening {
            fr,
            lr,
            sr,
            fr_minus_one: fr - 1.0,
            sr_lr: sr * (lr - 1.0),
            c0_max: (fr - 1.0) / (lr - 1.0) * t.delta0_mm / t.l0_mm,
        });
    }
    // Bracket: h(lo) > 0 near 0; grow hi until h(hi) < 0 (h -> -inf since Lr > 1).
    let lo = 1e-9 / (lr - 1.0);
    let mut hi = 1.0 / (lr - 1.0);
    let mut grow = 0;
    while h(hi) > 0.0 {
        hi *= 2.0;
        grow += 1;
        if grow > 200 || !hi.is_finite() {
            return Err(LawError::NoConvergence(
                "could not bracket the positive root".into(),
            ));
        }
    }
    // Tolerance relative to the bracket: an absolute 1e-15 is below the spacing of doubles
    // for alpha > 4. Newton polishing below brings alpha to full precision.
    let mut conv = SimpleConvergency {
        eps: 1e-14 * hi,
        max_iter: 200,
    };
    let alpha = find_root_brent(lo, hi, h, &mut conv)
        .map_err(|e| LawError::NoConvergence(e.to_string()))?;
    // Two Newton polishing steps on g(alpha) = alpha*h(alpha) to reach full precision.
    let g = |a: f64| a * (fr - 1.0) + sr - sr * ((lr - 1.0) * a).exp();
    let dg = |a: f64| (fr - 1.0) - sr * (lr - 1.0) * ((lr - 1.0) * a).exp();
    let mut alpha = alpha;
    for _ in 0..2 {
        let d = dg(alpha);
        if d != 0.0 {
            let next = alpha - g(alpha) / d;
            if next.is_finite() && next > 0.0 {
                alpha = next;
            }
        }
    }
    Ok(alpha)
}

/// Solves the targets for alpha, mu, F0 and k2.
///
/// ```
/// use camspring::{law::solve, LawTargets};
/// let t = LawTargets { fmax_n: 200.0, fmin_n: 5.0, xmax_mm: 20.0, l0_mm: 5.0, c0: 0.2, delta0_mm: 1.0 };
/// let solved = solve(&t).unwrap();
/// assert!((solved.alpha.unwrap() - 1.3201914760).abs() < 1e-9);
/// // A request for a softening spring is refused with the numbers:
/// let soft = LawTargets { c0: 3.0, ..t };
/// assert!(solve(&soft).unwrap_err().to_string().contains("softening"));
/// ```
pub fn solve(t: &LawTargets) -> Result<SolvedLaw, LawError> {
    let alpha = solve_alpha(t)?;
    let sr = t.sensitivity_ratio();
    let mu = sr * t.fmin_n / (alpha * alpha.exp());
    let f0 = t.fmin_n - mu * alpha.exp();
    let law = ExpLaw {
        mu_n: mu,
        k2_per_mm: alpha / t.l0_mm,
        f0_n: f0,
    };
    if law.force_n(0.0) <= 0.0 {
        return Err(LawError::NonPositiveStartForce {
            f_at_zero: law.force_n(0.0),
            fix: "raise law.fmin or lower law.c0".into(),
        });
    }
    let c0_achieved = law.stiffness_n_per_mm(t.l0_mm) * t.delta0_mm / law.force_n(t.l0_mm);
    let residuals = Residuals {
        force_at_l0: (law.force_n(t.l0_mm) - t.fmin_n) / t.fmin_n,
        force_at_xmax: (law.force_n(t.xmax_mm) - t.fmax_n) / t.fmax_n,
        c0: (c0_achieved - t.c0) / t.c0,
    };
    Ok(SolvedLaw {
        law: ForceLaw::Exponential(law),
        alpha: Some(alpha),
        residuals: Some(residuals),
        condition_residuals: None,
    })
}

/// The conditions' rows [a_mu, a_f0 | b] of A(k2) [mu, F0] = b at exponent rate `k`, each
/// scaled to unit size (the scale does not change where the system is consistent).
fn condition_rows(conditions: &[Condition], k: f64) -> Vec<[f64; 3]> {
    conditions
        .iter()
        .map(|c| {
            let row = match *c {
                Condition::Force { at_mm, force_n } => [(k * at_mm).exp(), 1.0, force_n],
                Condition::Stiffness {
                    at_mm,
                    stiffness_n_per_mm,
                } => [k * (k * at_mm).exp(), 0.0, stiffness_n_per_mm],
                Condition::StiffnessAtForce {
                    force_n,
                    stiffness_n_per_mm,
                } => [0.0, k, k * force_n - stiffness_n_per_mm],
            };
            let scale = row.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
            if scale > 0.0 {
                row.map(|v| v / scale)
            } else {
                row
            }
        })
        .collect()
}

fn det3(r: &[[f64; 3]]) -> f64 {
    r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
        - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
        + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0])
}

/// (mu, F0) from the best-conditioned pair of rows at `k`, or None when every pair is singular.
fn mu_f0(rows: &[[f64; 3]]) -> Option<(f64, f64)> {
    let mut best: Option<(f64, (f64, f64))> = None;
    for (i, j) in [(0, 1), (0, 2), (1, 2)] {
        let (a, b) = (rows[i], rows[j]);
        let det = a[0] * b[1] - a[1] * b[0];
        let size = det.abs();
        if size > 1e-12 && best.is_none_or(|(s, _)| size > s) {
            let mu = (a[2] * b[1] - a[1] * b[2]) / det;
            let f0 = (a[0] * b[2] - a[2] * b[0]) / det;
            best = Some((size, (mu, f0)));
        }
    }
    best.map(|b| b.1)
}

/// The relative residual of one condition for a law.
fn condition_residual(law: &ExpLaw, c: &Condition) -> f64 {
    match *c {
        Condition::Force { at_mm, force_n } => (law.force_n(at_mm) - force_n) / force_n,
        Condition::Stiffness {
            at_mm,
            stiffness_n_per_mm,
        } => (law.stiffness_n_per_mm(at_mm) - stiffness_n_per_mm) / stiffness_n_per_mm,
        Condition::StiffnessAtForce {
            force_n,
            stiffness_n_per_mm,
        } => (law.k2_per_mm * (force_n - law.f0_n) - stiffness_n_per_mm) / stiffness_n_per_mm,
    }
}

/// The quantity a condition fixes (a force or a stiffness), for the law.
fn condition_value(law: &ExpLaw, c: &Condition) -> f64 {
    match *c {
        Condition::Force { at_mm, .. } => law.force_n(at_mm),
        Condition::Stiffness { at_mm, .. } => law.stiffness_n_per_mm(at_mm),
        Condition::StiffnessAtForce { force_n, .. } => law.k2_per_mm * (force_n - law.f0_n),
    }
}

/// Solves three independent conditions (force or stiffness at a deflection, stiffness at a
/// force) for the exponential law over a stroke of `xmax_mm`.
///
/// For a fixed k2 every condition is linear in (mu, F0), so the three are consistent exactly
/// where the determinant of the augmented 3x3 system vanishes: a bracketed root in k2 (a
/// log-spaced scan over 0 < k2 * xmax <= 200, then Brent's method). mu and F0 follow from two of
/// the conditions; all three residuals are reported.
///
/// ```
/// use camspring::law::solve_conditions;
/// use camspring::model::Condition;
/// let law = solve_conditions(&[
///     Condition::Force { at_mm: 0.0, force_n: 40.0 },
///     Condition::Force { at_mm: 15.0, force_n: 800.0 },
///     Condition::Stiffness { at_mm: 15.0, stiffness_n_per_mm: 180.0 },
/// ], 15.0).unwrap();
/// assert!(law.condition_residuals.unwrap().iter().all(|r| r.abs() < 1e-9));
/// ```
pub fn solve_conditions(conditions: &[Condition], xmax_mm: f64) -> Result<SolvedLaw, LawError> {
    let listed = conditions
        .iter()
        .map(|c| c.to_string())
        .collect::<Vec<_>>()
        .join(", ");
    let none = |hint: String| LawError::NoExponentialLaw {
        conditions: listed.clone(),
        hint,
    };
    if conditions.len() != 3 {
        return Err(none(format!(
            "exactly three conditions are needed, {} given",
            conditions.len()
        )));
    }
    let g = |k: f64| det3(&condition_rows(conditions, k));
    let (k_lo, k_hi) = (1e-6 / xmax_mm, MAX_EXPONENT / xmax_mm);
    let steps = 600;
    let grid: Vec<f64> = (0..=steps)
        .map(|i| k_lo * (k_hi / k_lo).powf(i as f64 / steps as f64))
        .collect();
    // Rows are scaled to unit size, so independent conditions give a determinant of order
    // one somewhere; one that vanishes everywhere means two conditions fix the same thing.
    let largest = grid
        .iter()
        .map(|&k| g(k).abs())
        .fold(0.0_f64, |m, v| m.max(v));
    if largest.is_nan() || largest <= 1e-9 {
        return Err(none(
            "the conditions are not independent (two of them fix the same thing); give a force \
             and a stiffness, or forces at two deflections"
                .into(),
        ));
    }
    let law_at = |k: f64| {
        mu_f0(&condition_rows(conditions, k)).map(|(mu, f0)| ExpLaw {
            mu_n: mu,
            k2_per_mm: k,
            f0_n: f0,
        })
    };
    for w in grid.windows(2) {
        let (ga, gb) = (g(w[0]), g(w[1]));
        if !(ga.is_finite() && gb.is_finite()) || ga * gb > 0.0 {
            continue;
        }
        let mut conv = SimpleConvergency {
            eps: 1e-15 * w[1],
            max_iter: 200,
        };
        let Ok(k) = find_root_brent(w[0], w[1], g, &mut conv) else {
            continue;
        };
        let Some(law) = law_at(k) else {
            continue;
        };
        let residuals: Vec<f64> = conditions
            .iter()
            .map(|c| condition_residual(&law, c))
            .collect();
        if law.mu_n > 0.0 && law.force_n(0.0) > 0.0 && residuals.iter().all(|r| r.abs() < 1e-6) {
            return Ok(SolvedLaw {
                law: ForceLaw::Exponential(law),
                alpha: None,
                residuals: None,
                condition_residuals: Some(residuals),
            });
        }
    }
    // What would work: the third condition's value over the family the first two allow,
    // from nearly straight (k2 -> 0) to the steepest law accepted.
    let hint = (0..3)
        .rev()
        .find_map(|m| {
            let others: Vec<Condition> = (0..3).filter(|&i| i != m).map(|i| conditions[i]).collect();
            let at = |k: f64| {
                let rows = condition_rows(&others, k);
                let (a, b) = (rows[0], rows[1]);
                let det = a[0] * b[1] - a[1] * b[0];
                (det.abs() > 1e-12).then(|| {
                    let law = ExpLaw {
                        mu_n: (a[2] * b[1] - a[1] * b[2]) / det,
                        k2_per_mm: k,
                        f0_n: (a[0] * b[2] - a[2] * b[0]) / det,
                    };
                    condition_value(&law, &conditions[m])
                })
            };
            let (a, b) = (at(k_lo)?, at(k_hi)?);
            (a.is_finite() && b.is_finite()).then(|| {
                let unit = match conditions[m] {
                    Condition::Force { .. } => "N",
                    _ => "N/mm",
                };
                format!(
                    "with the other two, condition {} ({}) would need a value between {:.6} {unit} (a straight line) and {:.6e} {unit} (k2 * xmax = {MAX_EXPONENT}): an exponential law stiffens as its force grows",
                    m + 1,
                    conditions[m],
                    a.min(b),
                    a.max(b)
                )
            })
        })
        .unwrap_or_else(|| {
            "the conditions are not independent (two of them fix the same thing); give a force \
             and a stiffness, or forces at two deflections"
                .to_string()
        });
    Err(none(hint))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conditions_on_the_papers_design_reproduce_the_paper_form_law() {
        let t = paper();
        let exact = solve(&t).unwrap();
        let e = *exact.exponential().unwrap();
        // The paper's three conditions restated: F(L0) = Fmin, F(Xmax) = Fmax, and the
        // stiffness at L0 that gives C0.
        let s_l0 = t.c0 * t.fmin_n / t.delta0_mm;
        let c = solve_conditions(
            &[
                Condition::Force {
                    at_mm: t.l0_mm,
                    force_n: t.fmin_n,
                },
                Condition::Force {
                    at_mm: t.xmax_mm,
                    force_n: t.fmax_n,
                },
                Condition::Stiffness {
                    at_mm: t.l0_mm,
                    stiffness_n_per_mm: s_l0,
                },
            ],
            t.xmax_mm,
        )
        .unwrap();
        let l = c.exponential().unwrap();
        assert!((l.k2_per_mm / e.k2_per_mm - 1.0).abs() < 1e-9);
        assert!((l.mu_n / e.mu_n - 1.0).abs() < 1e-9);
        assert!((l.f0_n / e.f0_n - 1.0).abs() < 1e-9);
    }

    #[test]
    fn the_designers_example_solves_and_softening_conditions_say_what_would_work() {
        let c = solve_conditions(
            &[
                Condition::Force {
                    at_mm: 0.0,
                    force_n: 40.0,
                },
                Condition::Force {
                    at_mm: 15.0,
                    force_n: 800.0,
                },
                Condition::StiffnessAtForce {
                    force_n: 800.0,
                    stiffness_n_per_mm: 180.0,
                },
            ],
            15.0,
        )
        .unwrap();
        assert!(c
            .condition_residuals
            .as_ref()
            .unwrap()
            .iter()
            .all(|r| r.abs() < 1e-9));
        let l = c.exponential().unwrap();
        // Independent check: stiffness is affine in force with slope k2.
        assert!((l.stiffness_n_per_mm(15.0) - 180.0).abs() < 1e-7);
        assert!((l.force_n(0.0) - 40.0).abs() < 1e-9);
        // 760 N over 15 mm is a mean slope of 50.67 N/mm: a stiffness of 40 N/mm at the end
        // would be a softening spring.
        let e = solve_conditions(
            &[
                Condition::Force {
                    at_mm: 0.0,
                    force_n: 40.0,
                },
                Condition::Force {
                    at_mm: 15.0,
                    force_n: 800.0,
                },
                Condition::Stiffness {
                    at_mm: 15.0,
                    stiffness_n_per_mm: 40.0,
                },
            ],
            15.0,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("40 N/mm at 15 mm") && e.contains("50.66"), "{e}");
        // Dependent conditions are named as such.
        let e = solve_conditions(
            &[
                Condition::Force {
                    at_mm: 5.0,
                    force_n: 40.0,
                },
                Condition::Force {
                    at_mm: 5.0,
                    force_n: 40.0,
                },
                Condition::Force {
                    at_mm: 15.0,
                    force_n: 800.0,
                },
            ],
            15.0,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("not independent"), "{e}");
    }

    fn paper() -> LawTargets {
        LawTargets::PAPER_EXAMPLE
    }

    #[test]
    fn paper_example_matches_the_exact_root_from_physics_md() {
        let s = solve(&paper()).unwrap();
        assert!((s.alpha.unwrap() - 1.320_191_476_0).abs() < 1e-9);
        let l = s.exponential().unwrap();
        assert!((l.k2_per_mm - 0.264_038_3).abs() < 1e-7);
        assert!((l.mu_n - 1.011_535_7).abs() < 1e-7);
        assert!((l.f0_n - 1.212_670_6).abs() < 1e-7);
        assert!(s.residuals.unwrap().max_abs() < 1e-12);
    }

    #[test]
    fn printed_paper_alpha_is_not_a_root() {
        // The paper prints alpha = 1.3288; docs/THEORY.md: residual of eq. (5) there is about -3.9.
        let (fr, lr, sr) = (40.0_f64, 4.0_f64, 1.0_f64);
        let a = 1.3288_f64;
        let eq5 = a * a.exp() * (fr - 1.0) + sr * a.exp() - sr * (lr * a).exp();
        assert!((eq5 + 3.9).abs() < 0.1, "{eq5}");
    }

    #[test]
    fn the_root_satisfies_eq5_directly() {
        for t in [
            paper(),
            LawTargets {
                fmax_n: 900.0,
                fmin_n: 20.0,
                xmax_mm: 12.0,
                l0_mm: 2.0,
                c0: 0.1,
                delta0_mm: 0.1,
            },
            // A large root (alpha ~ 18), found by proptest: needs a relative tolerance.
            LawTargets {
                fmax_n: 53.191_061_150_798_745,
                fmin_n: 1.0,
                xmax_mm: 1.5,
                l0_mm: 1.0,
                c0: 0.01,
                delta0_mm: 0.1,
            },
            LawTargets {
                fmax_n: 50.0,
                fmin_n: 10.0,
                xmax_mm: 8.0,
                l0_mm: 4.0,
                c0: 0.3,
                delta0_mm: 1.0,
            },
        ] {
            let a = solve_alpha(&t).unwrap();
            let (fr, lr, sr) = (t.force_ratio(), t.length_ratio(), t.sensitivity_ratio());
            let eq5 = a * a.exp() * (fr - 1.0) + sr * a.exp() - sr * (lr * a).exp();
            let scale = sr * (lr * a).exp();
            assert!(a > 0.0);
            assert!((eq5 / scale).abs() < 1e-12, "{eq5}");
            // Where the law is realisable, the three design conditions hold too.
            if let Ok(s) = solve(&t) {
                assert!(s.residuals.unwrap().max_abs() < 1e-9);
            }
        }
    }

    #[test]
    fn softening_request_is_explained() {
        let t = LawTargets { c0: 3.0, ..paper() };
        match solve(&t) {
            Err(LawError::Softening {
                fr_minus_one,
                sr_lr,
                c0_max,
                ..
            }) => {
                assert_eq!(fr_minus_one, 39.0);
                assert_eq!(sr_lr, 45.0);
                assert!((c0_max - 2.6).abs() < 1e-12);
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn energy_is_the_integral_of_force() {
        let law = *solve(&paper()).unwrap().exponential().unwrap();
        // Composite Simpson on [0, 20] with 2000 intervals.
        let n = 2000;
        let h = 20.0 / n as f64;
        let mut sum = law.force_n(0.0) + law.force_n(20.0);
        for i in 1..n {
            sum += law.force_n(i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        let simpson = sum * h / 3.0;
        assert!((law.energy_nmm(20.0) - simpson).abs() < 1e-9 * simpson);
        // Stiffness is affine in force: sigma = k2*(F - F0).
        for x in [0.0, 3.0, 17.0] {
            let s = law.stiffness_n_per_mm(x);
            assert!((s - law.k2_per_mm * (law.force_n(x) - law.f0_n)).abs() < 1e-12 * s);
        }
    }
}
