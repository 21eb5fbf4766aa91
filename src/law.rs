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

use crate::model::{ExpLaw, LawTargets};

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
    #[serde(flatten)]
    pub law: ExpLaw,
    /// alpha = k2 * L0, when solved from targets.
    pub alpha: Option<f64>,
    /// Residuals of the design conditions, when solved from targets.
    pub residuals: Option<Residuals>,
}

/// Why a law could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LawError {
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
        law,
        alpha: Some(alpha),
        residuals: Some(residuals),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paper() -> LawTargets {
        LawTargets::PAPER_EXAMPLE
    }

    #[test]
    fn paper_example_matches_the_exact_root_from_physics_md() {
        let s = solve(&paper()).unwrap();
        assert!((s.alpha.unwrap() - 1.320_191_476_0).abs() < 1e-9);
        assert!((s.law.k2_per_mm - 0.264_038_3).abs() < 1e-7);
        assert!((s.law.mu_n - 1.011_535_7).abs() < 1e-7);
        assert!((s.law.f0_n - 1.212_670_6).abs() < 1e-7);
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
        let law = solve(&paper()).unwrap().law;
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
