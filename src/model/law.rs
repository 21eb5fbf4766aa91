//! The force law as data: the exponential law F(x) = mu*exp(k2*x) + F0, the paper's design
//! targets it is solved from, and how a spec states the law. Solving lives in [`crate::law`].

use serde::Serialize;

/// The force law F(x) = mu*exp(k2*x) + F0 over deflection x >= 0 (N, mm).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ExpLaw {
    /// Coefficient mu.
    pub mu_n: f64,
    /// Exponent rate k2 = alpha / L0.
    pub k2_per_mm: f64,
    /// Offset F0.
    pub f0_n: f64,
}

impl ExpLaw {
    /// Force at deflection `x_mm`.
    pub fn force_n(&self, x_mm: f64) -> f64 {
        self.mu_n * (self.k2_per_mm * x_mm).exp() + self.f0_n
    }

    /// Stiffness dF/dx at deflection `x_mm` (= k2*(F - F0)).
    pub fn stiffness_n_per_mm(&self, x_mm: f64) -> f64 {
        self.k2_per_mm * self.mu_n * (self.k2_per_mm * x_mm).exp()
    }

    /// Work done from 0 to `x_mm`: E(x) = (mu/k2)*(exp(k2 x) - 1) + F0*x, in N*mm.
    pub fn energy_nmm(&self, x_mm: f64) -> f64 {
        self.mu_n / self.k2_per_mm * (self.k2_per_mm * x_mm).exp_m1() + self.f0_n * x_mm
    }
}

/// Design targets for the law (paper section II-B).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LawTargets {
    /// Force at the maximum deflection.
    pub fmax_n: f64,
    /// Force at the rest length L0.
    pub fmin_n: f64,
    /// Maximum deflection.
    pub xmax_mm: f64,
    /// Rest length L0 (the deflection at which Fmin and C0 hold).
    pub l0_mm: f64,
    /// Relative force error at L0 for a deflection error delta0.
    pub c0: f64,
    /// Minimum sensible deflection (the deflection error behind C0).
    pub delta0_mm: f64,
}

impl LawTargets {
    /// The paper's example: 200 N at 20 mm, 5 N at L0 = 5 mm, C0 = 0.2 for delta0 = 1 mm.
    pub const PAPER_EXAMPLE: LawTargets = LawTargets {
        fmax_n: 200.0,
        fmin_n: 5.0,
        xmax_mm: 20.0,
        l0_mm: 5.0,
        c0: 0.2,
        delta0_mm: 1.0,
    };

    /// Fr = Fmax / Fmin.
    pub fn force_ratio(&self) -> f64 {
        self.fmax_n / self.fmin_n
    }
    /// Lr = Xmax / L0.
    pub fn length_ratio(&self) -> f64 {
        self.xmax_mm / self.l0_mm
    }
    /// Sr = C0 * L0 / delta0.
    pub fn sensitivity_ratio(&self) -> f64 {
        self.c0 * self.l0_mm / self.delta0_mm
    }
}

/// How the force law is given.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum LawSpec {
    /// Design targets, solved for the law (paper eq. 5).
    Targets(LawTargets),
    /// A known law, used as given over the stroke.
    Given {
        /// The law.
        law: ExpLaw,
        /// The stroke (maximum deflection).
        xmax_mm: f64,
    },
}

impl LawSpec {
    /// The maximum deflection of the stroke.
    pub fn xmax_mm(&self) -> f64 {
        match self {
            LawSpec::Targets(t) => t.xmax_mm,
            LawSpec::Given { xmax_mm, .. } => *xmax_mm,
        }
    }
}
