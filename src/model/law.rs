//! The force law as data: the exponential law F(x) = mu*exp(k2*x) + F0, a tabulated monotone
//! law, the forms a spec states a law in (the paper's targets, three conditions, a given law, a
//! table) and [`ForceLaw`], all the cam synthesis needs: force, stiffness and energy over the
//! stroke. Solving lives in [`crate::law`].

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

/// One condition on an exponential law, in the designer's terms.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Condition {
    /// The force at a deflection.
    Force {
        /// Deflection.
        at_mm: f64,
        /// Force there.
        force_n: f64,
    },
    /// The stiffness dF/dx at a deflection.
    Stiffness {
        /// Deflection.
        at_mm: f64,
        /// Stiffness there.
        stiffness_n_per_mm: f64,
    },
    /// The stiffness where the force has a value (stiffness is affine in force).
    StiffnessAtForce {
        /// Force.
        force_n: f64,
        /// Stiffness at that force.
        stiffness_n_per_mm: f64,
    },
}

impl std::fmt::Display for Condition {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Condition::Force { at_mm, force_n } => write!(f, "{force_n} N at {at_mm} mm"),
            Condition::Stiffness {
                at_mm,
                stiffness_n_per_mm,
            } => write!(f, "{stiffness_n_per_mm} N/mm at {at_mm} mm"),
            Condition::StiffnessAtForce {
                force_n,
                stiffness_n_per_mm,
            } => write!(f, "{stiffness_n_per_mm} N/mm at {force_n} N"),
        }
    }
}

/// A tabulated force law: points (x, F) joined by Steffen's monotone cubic, so the force is
/// monotone between the points and the stiffness continuous (C1). Beyond the last point the
/// law continues along its end tangent.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TableLaw {
    /// Deflections, strictly increasing, the first at 0.
    pub x_mm: Vec<f64>,
    /// Forces, positive and non-decreasing.
    pub force_n: Vec<f64>,
    /// Slopes dF/dx at the points (Steffen).
    #[serde(skip)]
    slopes: Vec<f64>,
    /// Work from 0 to each point (N mm).
    #[serde(skip)]
    energy: Vec<f64>,
}

impl TableLaw {
    /// The law through `points` (x mm, F N); the points must already be valid
    /// ([`crate::model::Spec::validate`] checks them, naming the row).
    pub fn new(points: &[(f64, f64)]) -> TableLaw {
        let x: Vec<f64> = points.iter().map(|p| p.0).collect();
        let y: Vec<f64> = points.iter().map(|p| p.1).collect();
        let slopes = steffen_slopes(&x, &y);
        let mut energy = vec![0.0; x.len()];
        for i in 1..x.len() {
            let h = x[i] - x[i - 1];
            energy[i] = energy[i - 1]
                + h * (y[i - 1] + y[i]) / 2.0
                + h * h * (slopes[i - 1] - slopes[i]) / 12.0;
        }
        TableLaw {
            x_mm: x,
            force_n: y,
            slopes,
            energy,
        }
    }

    /// The points as (x, F).
    pub fn points(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.x_mm.iter().copied().zip(self.force_n.iter().copied())
    }

    /// The segment holding `x` and the local coordinate t in [0, 1] (outside the table: None).
    fn segment(&self, x: f64) -> Option<(usize, f64, f64)> {
        let n = self.x_mm.len();
        if n < 2 || !(x >= self.x_mm[0] && x <= self.x_mm[n - 1]) {
            return None;
        }
        let i = self.x_mm.partition_point(|&xi| xi <= x).clamp(1, n - 1) - 1;
        let h = self.x_mm[i + 1] - self.x_mm[i];
        Some((i, h, (x - self.x_mm[i]) / h))
    }

    /// Force at deflection `x_mm`.
    pub fn force_n(&self, x_mm: f64) -> f64 {
        match self.segment(x_mm) {
            Some((i, h, t)) => {
                let (y0, y1, m0, m1) = self.ends(i);
                let (t2, t3) = (t * t, t * t * t);
                y0 * (2.0 * t3 - 3.0 * t2 + 1.0)
                    + h * m0 * (t3 - 2.0 * t2 + t)
                    + y1 * (-2.0 * t3 + 3.0 * t2)
                    + h * m1 * (t3 - t2)
            }
            None => {
                let k = self.nearest_end(x_mm);
                self.force_n[k] + self.slopes[k] * (x_mm - self.x_mm[k])
            }
        }
    }

    /// Stiffness dF/dx at `x_mm`.
    pub fn stiffness_n_per_mm(&self, x_mm: f64) -> f64 {
        match self.segment(x_mm) {
            Some((i, h, t)) => {
                let (y0, y1, m0, m1) = self.ends(i);
                let t2 = t * t;
                (y0 * (6.0 * t2 - 6.0 * t) + y1 * (6.0 * t - 6.0 * t2)) / h
                    + m0 * (3.0 * t2 - 4.0 * t + 1.0)
                    + m1 * (3.0 * t2 - 2.0 * t)
            }
            None => self.slopes[self.nearest_end(x_mm)],
        }
    }

    /// Work from 0 to `x_mm` (N mm), integrated exactly over the cubic pieces.
    pub fn energy_nmm(&self, x_mm: f64) -> f64 {
        match self.segment(x_mm) {
            Some((i, h, t)) => {
                let (y0, y1, m0, m1) = self.ends(i);
                let (t2, t3, t4) = (t * t, t * t * t, t * t * t * t);
                self.energy[i]
                    + h * (y0 * (t4 / 2.0 - t3 + t)
                        + h * m0 * (t4 / 4.0 - 2.0 * t3 / 3.0 + t2 / 2.0)
                        + y1 * (-t4 / 2.0 + t3)
                        + h * m1 * (t4 / 4.0 - t3 / 3.0))
            }
            None => {
                let k = self.nearest_end(x_mm);
                let d = x_mm - self.x_mm[k];
                self.energy[k] + self.force_n[k] * d + self.slopes[k] * d * d / 2.0
            }
        }
    }

    fn ends(&self, i: usize) -> (f64, f64, f64, f64) {
        (
            self.force_n[i],
            self.force_n[i + 1],
            self.slopes[i],
            self.slopes[i + 1],
        )
    }

    fn nearest_end(&self, x: f64) -> usize {
        if x < self.x_mm[0] {
            0
        } else {
            self.x_mm.len() - 1
        }
    }
}

/// Steffen's slopes (M. Steffen, A&A 239, 1990): monotone between the points, C1, and no
/// overshoot; one point's slope is zero where the data turn or flatten.
fn steffen_slopes(x: &[f64], y: &[f64]) -> Vec<f64> {
    let n = x.len();
    if n < 2 {
        return vec![0.0; n];
    }
    let h: Vec<f64> = x.windows(2).map(|w| w[1] - w[0]).collect();
    let d: Vec<f64> = (0..n - 1).map(|i| (y[i + 1] - y[i]) / h[i]).collect();
    if n == 2 {
        return vec![d[0]; 2];
    }
    let mut m = vec![0.0; n];
    for i in 1..n - 1 {
        let p = (d[i - 1] * h[i] + d[i] * h[i - 1]) / (h[i - 1] + h[i]);
        m[i] =
            (d[i - 1].signum() + d[i].signum()) * d[i - 1].abs().min(d[i].abs()).min(0.5 * p.abs());
    }
    let end = |d0: f64, d1: f64, h0: f64, h1: f64| {
        let p = d0 * (1.0 + h0 / (h0 + h1)) - d1 * h0 / (h0 + h1);
        if p * d0 <= 0.0 {
            0.0
        } else if p.abs() > 2.0 * d0.abs() {
            2.0 * d0
        } else {
            p
        }
    };
    m[0] = end(d[0], d[1], h[0], h[1]);
    m[n - 1] = end(d[n - 2], d[n - 3], h[n - 2], h[n - 3]);
    m
}

/// A polynomial force law F(x) = c0 + c1 x + c2 x^2 + ... (N, N/mm, N/mm^2, ...): a quadratic
/// for antagonistic actuators, or any smooth stiffening curve.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PolyLaw {
    /// Coefficients from the constant up: c_k in N/mm^k.
    pub coefficients: Vec<f64>,
}

impl PolyLaw {
    /// Force at `x_mm` (Horner).
    pub fn force_n(&self, x_mm: f64) -> f64 {
        self.coefficients
            .iter()
            .rev()
            .fold(0.0, |acc, c| acc * x_mm + c)
    }

    /// Stiffness dF/dx at `x_mm`.
    pub fn stiffness_n_per_mm(&self, x_mm: f64) -> f64 {
        self.coefficients
            .iter()
            .enumerate()
            .skip(1)
            .rev()
            .fold(0.0, |acc, (k, c)| acc * x_mm + k as f64 * c)
    }

    /// Work from 0 to `x_mm` (N mm): the sum of c_k x^(k+1) / (k+1).
    pub fn energy_nmm(&self, x_mm: f64) -> f64 {
        self.coefficients
            .iter()
            .enumerate()
            .rev()
            .fold(0.0, |acc, (k, c)| acc * x_mm + c / (k + 1) as f64)
            * x_mm
    }
}

/// A force law over the stroke: what the cam synthesis, the forward model and the plots read.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "form", rename_all = "snake_case")]
pub enum ForceLaw {
    /// F = mu exp(k2 x) + F0 (solved from targets or conditions, or given).
    Exponential(ExpLaw),
    /// A tabulated monotone law.
    Table(TableLaw),
    /// A polynomial law.
    Polynomial(PolyLaw),
}

impl ForceLaw {
    /// Force at deflection `x_mm`.
    pub fn force_n(&self, x_mm: f64) -> f64 {
        match self {
            ForceLaw::Exponential(l) => l.force_n(x_mm),
            ForceLaw::Table(t) => t.force_n(x_mm),
            ForceLaw::Polynomial(p) => p.force_n(x_mm),
        }
    }

    /// Stiffness dF/dx at `x_mm`.
    pub fn stiffness_n_per_mm(&self, x_mm: f64) -> f64 {
        match self {
            ForceLaw::Exponential(l) => l.stiffness_n_per_mm(x_mm),
            ForceLaw::Table(t) => t.stiffness_n_per_mm(x_mm),
            ForceLaw::Polynomial(p) => p.stiffness_n_per_mm(x_mm),
        }
    }

    /// Work from 0 to `x_mm` (N mm).
    pub fn energy_nmm(&self, x_mm: f64) -> f64 {
        match self {
            ForceLaw::Exponential(l) => l.energy_nmm(x_mm),
            ForceLaw::Table(t) => t.energy_nmm(x_mm),
            ForceLaw::Polynomial(p) => p.energy_nmm(x_mm),
        }
    }

    /// One line for reports and file headers: the formula of an exponential law (6 decimals),
    /// or the table's size and end forces.
    pub fn describe(&self) -> String {
        match self {
            ForceLaw::Exponential(l) => format!(
                "F = {:.6} N exp({:.6}/mm x) + {:.6} N",
                l.mu_n, l.k2_per_mm, l.f0_n
            ),
            ForceLaw::Table(t) => {
                let n = t.x_mm.len();
                format!(
                    "F tabulated at {n} points from {} N at {} mm to {} N at {} mm (monotone cubic)",
                    t.force_n[0], t.x_mm[0], t.force_n[n - 1], t.x_mm[n - 1]
                )
            }
            ForceLaw::Polynomial(p) => {
                let terms: Vec<String> = p
                    .coefficients
                    .iter()
                    .enumerate()
                    .map(|(k, c)| match k {
                        0 => format!("{c} N"),
                        1 => format!("{c} N/mm x"),
                        _ => format!("{c} N/mm^{k} x^{k}"),
                    })
                    .collect();
                format!("F = {}", terms.join(" + "))
            }
        }
    }

    /// The exponential law, when this is one (the estimator's affine-stiffness model needs it).
    pub fn exponential(&self) -> Option<&ExpLaw> {
        match self {
            ForceLaw::Exponential(l) => Some(l),
            ForceLaw::Table(_) | ForceLaw::Polynomial(_) => None,
        }
    }
}

impl From<ExpLaw> for ForceLaw {
    fn from(l: ExpLaw) -> ForceLaw {
        ForceLaw::Exponential(l)
    }
}

impl From<&ExpLaw> for ForceLaw {
    fn from(l: &ExpLaw) -> ForceLaw {
        ForceLaw::Exponential(*l)
    }
}

impl From<&ForceLaw> for ForceLaw {
    fn from(l: &ForceLaw) -> ForceLaw {
        l.clone()
    }
}

/// How the force law is given.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum LawSpec {
    /// The paper's design targets, solved for the law (eq. 5).
    Targets(LawTargets),
    /// A known exponential law, used as given over the stroke.
    Given {
        /// The law.
        law: ExpLaw,
        /// The stroke (maximum deflection).
        xmax_mm: f64,
    },
    /// Three independent conditions on an exponential law (force or stiffness at a
    /// deflection, or stiffness at a force), solved for the law.
    Conditions {
        /// The conditions.
        conditions: Vec<Condition>,
        /// The stroke.
        xmax_mm: f64,
    },
    /// A polynomial force law.
    Polynomial {
        /// The law.
        law: PolyLaw,
        /// The stroke.
        xmax_mm: f64,
    },
    /// A tabulated force curve.
    Table {
        /// The law through the table's points.
        table: TableLaw,
        /// Where the table came from (the file named in the spec).
        source: String,
        /// The stroke (default: the last row).
        xmax_mm: f64,
    },
}

impl LawSpec {
    /// The maximum deflection of the stroke.
    pub fn xmax_mm(&self) -> f64 {
        match self {
            LawSpec::Targets(t) => t.xmax_mm,
            LawSpec::Given { xmax_mm, .. }
            | LawSpec::Conditions { xmax_mm, .. }
            | LawSpec::Polynomial { xmax_mm, .. }
            | LawSpec::Table { xmax_mm, .. } => *xmax_mm,
        }
    }

    /// The form's name: `targets`, `given`, `conditions`, `polynomial` or `table`.
    pub fn form(&self) -> &'static str {
        match self {
            LawSpec::Targets(_) => "targets",
            LawSpec::Given { .. } => "given",
            LawSpec::Conditions { .. } => "conditions",
            LawSpec::Polynomial { .. } => "polynomial",
            LawSpec::Table { .. } => "table",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paper() -> ExpLaw {
        ExpLaw {
            mu_n: 1.0115357,
            k2_per_mm: 0.2640383,
            f0_n: 1.2126706,
        }
    }

    #[test]
    fn a_dense_table_of_the_exponential_law_reproduces_it() {
        let law = paper();
        let points: Vec<(f64, f64)> = (0..=40)
            .map(|i| {
                let x = 0.5 * i as f64;
                (x, law.force_n(x))
            })
            .collect();
        let t = TableLaw::new(&points);
        for k in 0..=400 {
            let x = 0.05 * k as f64;
            let rel = |a: f64, b: f64| ((a - b) / b).abs();
            assert!(rel(t.force_n(x), law.force_n(x)) < 2e-4, "force at {x}");
            assert!(rel(t.energy_nmm(x).max(1e-12), law.energy_nmm(x).max(1e-12)) < 2e-4);
            assert!(
                rel(t.stiffness_n_per_mm(x), law.stiffness_n_per_mm(x)) < 2e-2,
                "stiffness at {x}"
            );
        }
        // Exact at the points.
        for (x, f) in points {
            assert!((t.force_n(x) - f).abs() < 1e-12 * f);
        }
    }

    #[test]
    fn a_polynomial_has_consistent_force_stiffness_and_energy() {
        let p = PolyLaw {
            coefficients: vec![20.0, 10.0, 2.0, 0.1],
        };
        let x: f64 = 7.5;
        assert!((p.force_n(x) - (20.0 + 10.0 * x + 2.0 * x * x + 0.1 * x.powi(3))).abs() < 1e-12);
        assert!((p.stiffness_n_per_mm(x) - (10.0 + 4.0 * x + 0.3 * x * x)).abs() < 1e-12);
        let e = 20.0 * x + 5.0 * x * x + 2.0 * x.powi(3) / 3.0 + 0.025 * x.powi(4);
        assert!((p.energy_nmm(x) - e).abs() < 1e-9);
    }

    #[test]
    fn the_interpolant_is_monotone_and_c1_with_exact_energy() {
        // A soft-then-stiff curve with a knee and a flat run.
        let points = [
            (0.0, 10.0),
            (2.0, 12.0),
            (4.0, 12.0),
            (5.0, 40.0),
            (8.0, 200.0),
        ];
        let t = TableLaw::new(&points);
        let mut last = t.force_n(0.0);
        for k in 1..=8000 {
            let x = k as f64 * 1e-3;
            let f = t.force_n(x);
            assert!(f >= last - 1e-12, "not monotone at {x}");
            assert!(t.stiffness_n_per_mm(x) >= -1e-12);
            last = f;
        }
        for &(x, _) in &points[1..4] {
            let (a, b) = (
                t.stiffness_n_per_mm(x - 1e-9),
                t.stiffness_n_per_mm(x + 1e-9),
            );
            assert!(
                (a - b).abs() < 1e-5 * (1.0 + a.abs()),
                "stiffness jumps at {x}"
            );
        }
        // Energy against a fine Simpson rule.
        let n = 8000;
        let h = 8.0 / n as f64;
        let mut sum = t.force_n(0.0) + t.force_n(8.0);
        for i in 1..n {
            sum += t.force_n(i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        assert!((t.energy_nmm(8.0) - sum * h / 3.0).abs() < 1e-9 * t.energy_nmm(8.0));
    }
}
