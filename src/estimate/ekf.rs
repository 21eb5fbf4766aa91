//! On-line impedance estimation: the paper's Extended Kalman Filter (section VI), built from
//! the derivation in docs/THEORY.md section 3 rather than the printed discrete equations.
//!
//! State Z = [x, xd, xdd, sigma, D, M, k2, d2] (mm, mm/s, mm/s^2, N/mm, N s/mm, N s^2/mm, 1/mm,
//! N s^3/mm^3). Input: the force rate u = Fdot (N/s). Measurement: the encoder position x.
//!
//! ```text
//! x' = xd;  xd' = xdd;  xdd' = (u - sigma*xd - D*xdd)/M
//! sigma' = k2*sigma*xd;  D' = 6*d2*xd*xdd;  M' = k2' = d2' = 0
//! ```
//!
//! Prediction integrates this with one classic RK4 step per sample (the input interpolated
//! linearly between samples), or with the paper's forward Euler for comparison. Forward Euler
//! lags half a sample and biases D and M (docs/THEORY.md). The covariance goes through the
//! transition matrix Phi = I + A T + (A T)^2 / 2 of the analytic Jacobian A; process noise is
//! Q T (the product exploits that only five rows of A are non-zero). The update is the Joseph
//! form written out for the position-only measurement, symmetrised. The covariance the filter
//! reports is a second one, propagated with the same transition matrices and gains but less
//! process noise on xdd ([`GAIN_NOISE_INFLATION`]). Bounds: M and sigma stay above a small
//! positive floor. Divergence (a non-finite value, a covariance that is no longer positive
//! definite, or innovations far outside their covariance for many samples in a row) stops the
//! filter with the sample index.
//!
//! The paper's parallel, slower filter for F0 and d0 ([`OffsetFilter`]) runs next to it: a
//! recursive least squares with forgetting on F - (M xdd + d1 xd + d2 xd^3 + sigma/k2) =
//! F0 + d0 sgn(xd), where d1 = D - 3 d2 xd^2 and sigma/k2 = F_S - F0 (the affine relation).
//!
//! The filter step uses only nalgebra static matrices and allocates nothing.

use nalgebra::{SMatrix, SVector};
use serde::Serialize;

use super::identify::{Identification, Param};

/// The filter state.
pub type State = SVector<f64, 8>;
/// An 8x8 matrix.
pub type Mat8 = SMatrix<f64, 8, 8>;

/// State names with units, in state order (the CSV and JSON keys).
pub const STATE_NAMES: [&str; 8] = [
    "x_mm",
    "xd_mm_per_s",
    "xdd_mm_per_s2",
    "sigma_n_per_mm",
    "d_n_s_per_mm",
    "m_n_s2_per_mm",
    "k2_per_mm",
    "d2_n_s3_per_mm3",
];

/// Index of each state.
pub mod idx {
    /// Position.
    pub const X: usize = 0;
    /// Velocity.
    pub const XD: usize = 1;
    /// Acceleration.
    pub const XDD: usize = 2;
    /// Generalised stiffness.
    pub const SIGMA: usize = 3;
    /// Generalised damping.
    pub const D: usize = 4;
    /// Generalised inertia.
    pub const M: usize = 5;
    /// Exponent rate.
    pub const K2: usize = 6;
    /// Cubic damping.
    pub const D2: usize = 7;
}

/// How the prediction integrates the model over one sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Discretization {
    /// One classic Runge-Kutta step (default).
    Rk4,
    /// The paper's forward Euler, for comparison.
    Euler,
}

/// Continuous model derivative f(Z, u).
pub fn derivative(z: &State, u: f64) -> State {
    let (xd, xdd, sigma, d, m, k2, d2) = (z[1], z[2], z[3], z[4], z[5], z[6], z[7]);
    State::from([
        xd,
        xdd,
        (u - sigma * xd - d * xdd) / m,
        k2 * sigma * xd,
        6.0 * d2 * xd * xdd,
        0.0,
        0.0,
        0.0,
    ])
}

/// Analytic Jacobian A = df/dZ.
pub fn jacobian(z: &State, u: f64) -> Mat8 {
    let mut a = Mat8::zeros();
    a.fixed_rows_mut::<5>(0).copy_from(&jacobian_rows(z, u));
    a
}

/// The first five rows of the Jacobian (the others are zero: M, k2 and d2 are constant).
pub fn jacobian_rows(z: &State, u: f64) -> SMatrix<f64, 5, 8> {
    let (xd, xdd, sigma, d, m, k2, d2) = (z[1], z[2], z[3], z[4], z[5], z[6], z[7]);
    let mut a = SMatrix::<f64, 5, 8>::zeros();
    a[(0, 1)] = 1.0;
    a[(1, 2)] = 1.0;
    a[(2, 1)] = -sigma / m;
    a[(2, 2)] = -d / m;
    a[(2, 3)] = -xd / m;
    a[(2, 4)] = -xdd / m;
    a[(2, 5)] = -(u - sigma * xd - d * xdd) / (m * m);
    a[(3, 1)] = k2 * sigma;
    a[(3, 3)] = k2 * xd;
    a[(3, 6)] = sigma * xd;
    a[(4, 1)] = 6.0 * d2 * xdd;
    a[(4, 2)] = 6.0 * d2 * xd;
    a[(4, 7)] = 6.0 * xd * xdd;
    a
}

/// The largest product of the prediction's fastest rate and one (sub)step: well inside RK4's
/// stability limit (about 2.8 on the real axis) and the second-order transition matrix's (2).
pub const STABLE_STEP: f64 = 1.0;

/// The most substeps one sample's prediction is split into (bounded work per sample).
pub const MAX_SUBSTEPS: usize = 64;

/// How many substeps keep the prediction over `dt` stable at state `z` ([`STABLE_STEP`]).
fn substeps(z: &State, dt: f64) -> usize {
    let m = z[idx::M].abs().max(1e-300);
    let rate = (z[idx::D].abs() / m).max((z[idx::SIGMA].abs() / m).sqrt());
    let n = (rate * dt / STABLE_STEP).ceil();
    if n.is_finite() {
        n.clamp(1.0, MAX_SUBSTEPS as f64) as usize
    } else {
        MAX_SUBSTEPS
    }
}

/// P <- Phi P Phi^T + Q dt for Phi = I + [G5; 0]: only the first five rows of the Jacobian are
/// non-zero (M, k2 and d2 are constant), so with B = G5 P,
/// Phi P Phi^T = P + [B; 0] + [B; 0]^T + [[B G5^T, 0], [0, 0]].
fn propagate(p: &mut Mat8, g5: &SMatrix<f64, 5, 8>, q: &[f64; 8], dt: f64) {
    let b = g5 * *p;
    let c = b * g5.transpose();
    let mut rows = p.fixed_rows_mut::<5>(0);
    rows += b;
    let mut cols = p.fixed_columns_mut::<5>(0);
    cols += b.transpose();
    let mut block = p.fixed_view_mut::<5, 5>(0, 0);
    block += c;
    for (i, q) in q.iter().enumerate() {
        p[(i, i)] += q * dt;
    }
}

/// Tuning of the filter.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct EkfSettings {
    /// Discretization of the prediction.
    pub discretization: Discretization,
    /// Continuous process noise spectral density of each state (unit^2 per s).
    pub q: [f64; 8],
    /// Position measurement variance (mm^2).
    pub r_position_mm2: f64,
    /// Initial standard deviation of each state.
    pub p0_std: [f64; 8],
    /// Smallest inertia allowed (N s^2/mm).
    pub m_floor: f64,
    /// Smallest stiffness allowed (N/mm).
    pub sigma_floor: f64,
    /// Smallest generalised damping allowed (N s/mm): a damper whose force falls with speed
    /// makes the acceleration's dynamics unstable, and the model assumes one that rises.
    pub d_floor: f64,
    /// An innovation beyond this many of its standard deviations counts as an outlier.
    pub outlier_sigmas: f64,
    /// This many outliers in a row stop the filter as diverged.
    pub max_outliers_in_a_row: usize,
    /// Where identification does not resolve the inertia and left transients out (the
    /// inertia's force was in them): M's start (N s^2/mm). The filter then estimates M only to
    /// keep its model whole; its M is not reported ([`EkfSettings::reports`]). `None`: M is
    /// held, or estimated and reported.
    pub m_nuisance_from: Option<f64>,
    /// The acceleration's process noise ((mm/s^2)^2 per s) of the error covariance the filter
    /// reports for its final state, where it differs from the one its gains are computed with
    /// (`q[2]`): that covariance is propagated alongside the filter's own, with the filter's
    /// gains ([`Ekf::p_reported`]), and becomes the run's at its end ([`Filter::finish`]). The
    /// rows along the run keep the filter's own standard deviations. `None`: the filter reports
    /// its own covariance.
    pub reported_xdd_q: Option<f64>,
}

/// Why the filter stopped.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EkfError {
    /// Produced by [`Ekf::step`] when a state or the covariance is no longer finite.
    #[error("the filter diverged at sample {sample} (t = {t_s:.3} s): {what}")]
    Diverged {
        /// Sample index (0-based, in the log).
        sample: usize,
        /// Its time.
        t_s: f64,
        /// What went wrong.
        what: String,
    },
    /// Produced by [`run`] for unusable settings or logs.
    #[error("{0}")]
    Input(String),
}

/// The filter: state, covariance and settings.
#[derive(Debug, Clone)]
pub struct Ekf {
    /// State estimate.
    pub z: State,
    /// State covariance: the filter's own, which its gains come from, until the run ends;
    /// then the one it reports ([`Filter::finish`]).
    pub p: Mat8,
    /// The error covariance the filter reports, where the settings give it its own process
    /// noise ([`EkfSettings::reported_xdd_q`]): propagated like `p`, but with that noise, and
    /// updated with the gains `p` gives (Joseph form, which holds for any gain).
    pub p_reported: Option<Mat8>,
    /// Settings.
    pub settings: EkfSettings,
    outliers_in_a_row: usize,
}

/// What one step saw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepInfo {
    /// Innovation y - x_predicted (mm).
    pub innovation_mm: f64,
    /// Its predicted variance (mm^2).
    pub innovation_variance_mm2: f64,
}

impl EkfSettings {
    /// Whether the filter reports its own estimate of state `k`: it is neither held nor an
    /// inertia carried free only to keep the model whole ([`EkfSettings::m_nuisance_from`]).
    pub fn reports(&self, k: usize) -> bool {
        let nuisance = k == idx::M && self.m_nuisance_from.is_some();
        !(self.holds(k) || nuisance)
    }

    /// Whether the filter holds state `k` at its initial value: no initial variance and no
    /// process noise (an M or d2 identification does not resolve).
    pub fn holds(&self, k: usize) -> bool {
        self.p0_std[k] == 0.0 && self.q[k] == 0.0
    }
}

impl Ekf {
    /// A filter at `z0` with the settings' initial covariance.
    pub fn new(z0: State, settings: EkfSettings) -> Ekf {
        let p = Mat8::from_diagonal(&State::from(settings.p0_std.map(|s| s * s)));
        Ekf {
            z: z0,
            p,
            p_reported: settings.reported_xdd_q.map(|_| p),
            settings,
            outliers_in_a_row: 0,
        }
    }

    /// Prediction over `dt` with the input going from `u0` to `u1` (linearly).
    ///
    /// RK4 and the second-order transition matrix are stable while the fastest rate of the
    /// prediction (D / M, or sqrt(sigma / M)) times the step stays below about 2; the inertia's
    /// floor keeps the start there, but the filter's D or sigma can grow on the way (a
    /// transient the model does not follow). The step is then split into up to
    /// [`MAX_SUBSTEPS`] equal substeps of at most [`STABLE_STEP`] each, so the prediction stays
    /// finite instead of blowing up within a few samples.
    pub fn predict(&mut self, u0: f64, u1: f64, dt: f64) {
        let n = match self.settings.discretization {
            Discretization::Euler => 1,
            Discretization::Rk4 => substeps(&self.z, dt),
        };
        let h = dt / n as f64;
        for j in 0..n {
            let ua = u0 + (u1 - u0) * (j as f64 / n as f64);
            let ub = u0 + (u1 - u0) * ((j + 1) as f64 / n as f64);
            self.predict_step(ua, ub, h);
        }
    }

    /// One prediction step of `dt` (see [`Self::predict`]).
    fn predict_step(&mut self, u0: f64, u1: f64, dt: f64) {
        let z = self.z;
        let a5 = jacobian_rows(&z, u0) * dt;
        self.z = match self.settings.discretization {
            Discretization::Euler => z + derivative(&z, u0) * dt,
            Discretization::Rk4 => {
                let um = 0.5 * (u0 + u1);
                let k1 = derivative(&z, u0);
                let k2 = derivative(&(z + k1 * (0.5 * dt)), um);
                let k3 = derivative(&(z + k2 * (0.5 * dt)), um);
                let k4 = derivative(&(z + k3 * dt), u1);
                z + (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (dt / 6.0)
            }
        };
        // Phi = I + G with G = A T (Euler) or A T + (A T)^2 / 2 (RK4); only G's first five
        // rows, G5, are non-zero ([`propagate`]).
        let g5 = match self.settings.discretization {
            Discretization::Euler => a5,
            // (A^2) rows 0..5 = A5 A = A5[:, 0..5] A5, since A's other rows are zero.
            Discretization::Rk4 => a5 + (a5.fixed_columns::<5>(0) * a5) * 0.5,
        };
        propagate(&mut self.p, &g5, &self.settings.q, dt);
        if let (Some(p), Some(q_xdd)) = (&mut self.p_reported, self.settings.reported_xdd_q) {
            let mut q = self.settings.q;
            q[idx::XDD] = q_xdd;
            propagate(p, &g5, &q, dt);
        }
        self.bound();
    }

    /// Measurement update with the position `y_mm` (Joseph form for H = [1, 0, ...]).
    pub fn update(&mut self, y_mm: f64) -> StepInfo {
        let r = self.settings.r_position_mm2;
        let s = self.p[(0, 0)] + r;
        let k: State = self.p.column(0) / s;
        let nu = y_mm - self.z[0];
        self.z += k * nu;
        // Joseph form (I - K H) P (I - K H)^T + K R K^T with H = e0, written out:
        // P - K P0^T - P0 K^T + (P00 + R) K K^T, where P0 is P's first column.
        let p0: State = self.p.column(0).into();
        self.p = self.p - k * p0.transpose() - p0 * k.transpose() + k * k.transpose() * s;
        self.p = (self.p + self.p.transpose()) * 0.5;
        if let Some(p) = &mut self.p_reported {
            // The same gain on the reported covariance: (I - K H) P (I - K H)^T + K R K^T,
            // written out on one triangle and mirrored (symmetric by construction).
            let p0: State = p.column(0).into();
            let s_reported = p[(0, 0)] + r;
            for j in 0..8 {
                for i in 0..=j {
                    let v = p[(i, j)] - k[i] * p0[j] - p0[i] * k[j] + k[i] * k[j] * s_reported;
                    p[(i, j)] = v;
                    p[(j, i)] = v;
                }
            }
        }
        self.bound();
        StepInfo {
            innovation_mm: nu,
            innovation_variance_mm2: s,
        }
    }

    fn bound(&mut self) {
        if self.z[idx::M] < self.settings.m_floor {
            self.z[idx::M] = self.settings.m_floor;
        }
        if self.z[idx::SIGMA] < self.settings.sigma_floor {
            self.z[idx::SIGMA] = self.settings.sigma_floor;
        }
        if self.z[idx::D] < self.settings.d_floor {
            self.z[idx::D] = self.settings.d_floor;
        }
    }

    /// Takes the filter past `gap_s` seconds whose force was not the spring's (a clipped load
    /// cell, a rod against a stop), where it neither predicted nor updated: the motion
    /// becomes `motion` = [x, xd, xdd] fitted to the positions after the gap, with covariance
    /// `motion_cov`; the stiffness follows the spring's law to the new position (sigma =
    /// k2 (F_S - F0) grows as exp(k2 x)), the generalised damping the damper's to the new
    /// speed (D = d1 + 3 d2 xd^2), and the constants M, k2 and d2 are kept. The covariance
    /// goes through the same map's Jacobian, plus the process noise of sigma and D over the
    /// gap.
    pub fn resume(&mut self, motion: [f64; 3], motion_cov: &nalgebra::Matrix3<f64>, gap_s: f64) {
        let z = self.z;
        let [x, xd, xdd] = motion;
        let grow = (z[idx::K2] * (x - z[idx::X])).exp();
        let sigma = z[idx::SIGMA] * grow;
        let d = z[idx::D] + 3.0 * z[idx::D2] * (xd * xd - z[idx::XD] * z[idx::XD]);
        // Jacobians of the new state in the old state and in the fitted motion.
        let mut jz = Mat8::identity();
        for i in [idx::X, idx::XD, idx::XDD, idx::SIGMA, idx::D] {
            jz.row_mut(i).fill(0.0);
        }
        jz[(idx::SIGMA, idx::SIGMA)] = grow;
        jz[(idx::SIGMA, idx::K2)] = sigma * (x - z[idx::X]);
        jz[(idx::SIGMA, idx::X)] = -z[idx::K2] * sigma;
        jz[(idx::D, idx::D)] = 1.0;
        jz[(idx::D, idx::D2)] = 3.0 * (xd * xd - z[idx::XD] * z[idx::XD]);
        jz[(idx::D, idx::XD)] = -6.0 * z[idx::D2] * z[idx::XD];
        let mut jw = SMatrix::<f64, 8, 3>::zeros();
        jw[(idx::X, 0)] = 1.0;
        jw[(idx::XD, 1)] = 1.0;
        jw[(idx::XDD, 2)] = 1.0;
        jw[(idx::SIGMA, 0)] = z[idx::K2] * sigma;
        jw[(idx::D, 1)] = 6.0 * z[idx::D2] * xd;
        let mut q = Mat8::zeros();
        for i in [idx::SIGMA, idx::D] {
            q[(i, i)] = self.settings.q[i] * gap_s.max(0.0);
        }
        let through = |p: &Mat8| {
            let p = jz * p * jz.transpose() + jw * motion_cov * jw.transpose() + q;
            (p + p.transpose()) * 0.5
        };
        self.p = through(&self.p);
        if let Some(p) = &mut self.p_reported {
            *p = through(p);
        }
        self.z[idx::X] = x;
        self.z[idx::XD] = xd;
        self.z[idx::XDD] = xdd;
        self.z[idx::SIGMA] = sigma;
        self.z[idx::D] = d;
        self.outliers_in_a_row = 0;
        self.bound();
    }

    /// One sample: predict from the previous sample, update with `y_mm`, check for divergence.
    pub fn step(
        &mut self,
        u0: f64,
        u1: f64,
        dt: f64,
        y_mm: f64,
        sample: usize,
        t_s: f64,
    ) -> Result<StepInfo, EkfError> {
        self.predict(u0, u1, dt);
        let info = self.update(y_mm);
        let diverged = |what: String| EkfError::Diverged { sample, t_s, what };
        if !self.z.iter().all(|v| v.is_finite()) || !self.p.iter().all(|v| v.is_finite()) {
            return Err(diverged("a state or its covariance is not finite".into()));
        }
        for (i, name) in STATE_NAMES.iter().enumerate() {
            let variance = self.p[(i, i)];
            // A state held at its initial value (no initial variance, no process noise) stays
            // at zero variance.
            let held = self.settings.holds(i);
            if variance <= 0.0 && !held {
                return Err(diverged(format!(
                    "the variance of {name} is {variance} (no longer positive definite)"
                )));
            }
        }
        if sample.is_multiple_of(64) && !self.positive_definite() {
            return Err(diverged(
                "the covariance is no longer positive definite".into(),
            ));
        }
        if info.innovation_mm.abs()
            > self.settings.outlier_sigmas * info.innovation_variance_mm2.sqrt()
        {
            self.outliers_in_a_row += 1;
            if self.outliers_in_a_row >= self.settings.max_outliers_in_a_row {
                return Err(diverged(format!(
                    "{} innovations in a row beyond {} standard deviations (last {:.4} mm against {:.4} mm)",
                    self.outliers_in_a_row,
                    self.settings.outlier_sigmas,
                    info.innovation_mm,
                    info.innovation_variance_mm2.sqrt()
                )));
            }
        } else {
            self.outliers_in_a_row = 0;
        }
        Ok(info)
    }

    /// Whether the covariance of the states that are not held is positive definite.
    fn positive_definite(&self) -> bool {
        let free: Vec<usize> = (0..8).filter(|&i| !self.settings.holds(i)).collect();
        nalgebra::DMatrix::from_fn(free.len(), free.len(), |a, b| self.p[(free[a], free[b])])
            .cholesky()
            .is_some()
    }

    /// Standard deviation of each state (the filter's own covariance during the run).
    pub fn std(&self) -> State {
        State::from_fn(|i, _| self.p[(i, i)].max(0.0).sqrt())
    }

    /// How far the constants [M, k2, d2] lie from known values (a simulated log's truth), in
    /// the covariance `p` (the reported one once the run has finished, [`Filter::finish`]):
    /// their z-scores and the normalised estimation error squared e^T P^-1 e. A held constant
    /// (no variance) counts neither in the NEES nor in its degrees of freedom, and its z is
    /// NaN. None if the free constants' covariance is not positive definite.
    pub fn constants_error(&self, truth: [f64; 3]) -> Option<ConstantsError> {
        let ids = [idx::M, idx::K2, idx::D2];
        let free: Vec<usize> = (0..3).filter(|&i| self.p[(ids[i], ids[i])] > 0.0).collect();
        let e =
            nalgebra::DVector::from_fn(free.len(), |a, _| self.z[ids[free[a]]] - truth[free[a]]);
        let cov = nalgebra::DMatrix::from_fn(free.len(), free.len(), |a, b| {
            self.p[(ids[free[a]], ids[free[b]])]
        });
        let nees = cov.cholesky()?.solve(&e).dot(&e);
        let z = [0, 1, 2].map(|i| {
            let var = self.p[(ids[i], ids[i])];
            if var > 0.0 {
                (self.z[ids[i]] - truth[i]) / var.sqrt()
            } else {
                f64::NAN
            }
        });
        Some(ConstantsError {
            z,
            nees,
            free: free.len(),
        })
    }
}

/// The filter's constants [M, k2, d2] against known values ([`Ekf::constants_error`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConstantsError {
    /// z-scores of M, k2 and d2: error over standard deviation (NaN where held).
    pub z: [f64; 3],
    /// Normalised estimation error squared over the free constants: chi-square with `free`
    /// degrees of freedom when the covariance is right.
    pub nees: f64,
    /// Constants the filter estimates (not held).
    pub free: usize,
}

/// The paper's parallel, slower filter for F0 and d0: recursive least squares with forgetting
/// on r = F0 + d0 sgn(xd).
#[derive(Debug, Clone, Copy)]
pub struct OffsetFilter {
    /// [F0, d0] (N).
    pub theta: SVector<f64, 2>,
    /// Their covariance (scaled by the residual variance).
    pub p: SMatrix<f64, 2, 2>,
    /// Forgetting factor per sample (1 - dt / memory).
    pub lambda: f64,
    /// Residual variance (N^2) for the covariance scale.
    pub residual_variance: f64,
}

impl OffsetFilter {
    /// A filter with memory `memory_s` at sampling interval `dt`, starting from `f0`, `d0`.
    pub fn new(f0: f64, d0: f64, memory_s: f64, dt: f64, residual_variance: f64) -> Self {
        OffsetFilter {
            theta: SVector::<f64, 2>::new(f0, d0),
            p: SMatrix::<f64, 2, 2>::identity() * 1e3,
            lambda: (1.0 - dt / memory_s).clamp(0.5, 1.0),
            residual_variance,
        }
    }

    /// Adds one residual r with the friction sign `sgn` (0 at rest: only F0 learns).
    pub fn update(&mut self, r: f64, sgn: f64) {
        let h = SVector::<f64, 2>::new(1.0, sgn);
        let ph = self.p * h;
        let denom = self.lambda + h.dot(&ph);
        let k = ph / denom;
        self.theta += k * (r - h.dot(&self.theta));
        self.p = (self.p - k * ph.transpose()) / self.lambda;
        self.p = (self.p + self.p.transpose()) * 0.5;
    }

    /// Standard deviations of F0 and d0.
    pub fn std(&self) -> [f64; 2] {
        [
            (self.p[(0, 0)] * self.residual_variance).max(0.0).sqrt(),
            (self.p[(1, 1)] * self.residual_variance).max(0.0).sqrt(),
        ]
    }
}

/// Where the force rate comes from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ForceRate {
    /// The derivative of the force through a first-order low-pass filter of this time constant
    /// (the paper's on-line filter). It lags by about the time constant, so the position is
    /// delayed by as many samples to match.
    FirstOrder {
        /// Time constant (s).
        time_constant_s: f64,
    },
    /// The Savitzky-Golay velocity kernel of identification over a window of about this
    /// length: zero phase, offline only (it looks half a window ahead).
    ZeroPhase {
        /// Window (s); [`super::sg::WINDOW_SECONDS`] by default ([`ForceRate::ZERO_PHASE`]).
        window_s: f64,
    },
}

impl ForceRate {
    /// The default force rate: zero phase over identification's default window.
    pub const ZERO_PHASE: ForceRate = ForceRate::ZeroPhase {
        window_s: super::sg::WINDOW_SECONDS,
    };

    /// The zero-phase window tried when the default one loses the motion (s): an eighth of
    /// the default. A servo's velocity step puts a force step of m a into the log; over 0.4 s
    /// the kernel spreads it over the whole window, so the rate the filter is driven with
    /// starts 0.06 s early and peaks at a third of the true one, and a fine encoder then sees
    /// the predicted motion lag by many standard deviations (encoder draw 29: diverged at
    /// 60.9 s; over 0.05 s it converges, k2 within 0.9 of its deviation).
    pub const SHORT_ZERO_PHASE_S: f64 = 0.05;

    /// The longest zero-phase window taken (s): each sample's rate costs a window of work,
    /// and a force rate smoothed over more than the longest identification window (3.2 s)
    /// has lost the motion it is there to follow. Longer windows are taken as this.
    pub const MAX_ZERO_PHASE_S: f64 = 5.0;

    /// A zero-phase force rate over a shorter window than this one at step `dt` (in
    /// samples), the one of [`ForceRate::SHORT_ZERO_PHASE_S`]; None when this one is
    /// first-order or already as short.
    pub fn shorter(self, dt: f64) -> Option<ForceRate> {
        let short = ForceRate::ZeroPhase {
            window_s: ForceRate::SHORT_ZERO_PHASE_S,
        };
        (short.window_taken_s(dt)? < self.window_taken_s(dt)?).then_some(short)
    }

    /// The zero-phase window this force rate takes at step `dt` (s): a whole odd number of
    /// samples, at least [`super::sg::MIN_WINDOW`], at most [`ForceRate::MAX_ZERO_PHASE_S`]
    /// (None for the first-order filter).
    pub fn window_taken_s(self, dt: f64) -> Option<f64> {
        match self {
            ForceRate::ZeroPhase { window_s } => Some(zero_phase_samples(window_s, dt) as f64 * dt),
            ForceRate::FirstOrder { .. } => None,
        }
    }
}

/// The zero-phase differentiator over about `window_s` at sampling step `dt`.
fn zero_phase(window_s: f64, dt: f64) -> super::sg::Differentiator {
    super::sg::Differentiator::new(zero_phase_samples(window_s, dt))
}

/// The samples of the zero-phase window of about `window_s` (at most
/// [`ForceRate::MAX_ZERO_PHASE_S`]) at sampling step `dt`.
fn zero_phase_samples(window_s: f64, dt: f64) -> usize {
    super::sg::window_of(window_s.min(ForceRate::MAX_ZERO_PHASE_S), 1.0 / dt)
}

/// The force rate of a force signal sampled every `dt`, aligned with the samples
/// `first .. first + len` of the log (zero-phase drops half a window at each end).
pub fn force_rate(force_n: &[f64], dt: f64, how: ForceRate) -> (Vec<f64>, usize) {
    match how {
        ForceRate::ZeroPhase { window_s } => {
            let d = zero_phase(window_s, dt);
            (d.apply(force_n, dt, super::sg::RATE), d.half)
        }
        ForceRate::FirstOrder { time_constant_s } => {
            let tau = time_constant_s.max(dt);
            let a = dt / (tau + dt);
            let mut low = force_n.first().copied().unwrap_or(0.0);
            let rate: Vec<f64> = force_n
                .iter()
                .map(|&f| {
                    low += a * (f - low);
                    (f - low) / tau
                })
                .collect();
            // The filter delays the force rate by about tau at the motion's frequencies; the
            // position is delayed to match (an on-line filter buffers it): sample k's input is
            // the rate computed at k + delay.
            let delay = ((tau / dt).round() as usize).min(rate.len());
            (rate[delay..].to_vec(), 0)
        }
    }
}

/// One filtered sample: the state, its standard deviations, and the parallel filter's
/// offsets with theirs (a row of est.csv).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EkfRow {
    /// Time (s).
    pub t_s: f64,
    /// State estimate after the sample.
    pub state: State,
    /// Its standard deviation.
    pub std: State,
    /// F0 and d0 from the parallel filter (N).
    pub offsets: [f64; 2],
    /// Their standard deviations (N).
    pub offset_stds: [f64; 2],
}

/// A run of the filter over a log.
#[derive(Debug, Clone)]
pub struct EkfRun {
    /// Every filtered sample, when the run collected them ([`run`]); empty when they were
    /// streamed to a sink instead ([`Filter`]).
    pub rows: Vec<EkfRow>,
    /// Index in the log of the first filtered sample.
    pub first_sample: usize,
    /// Samples filtered.
    pub samples: usize,
    /// Time of the last filtered sample (s).
    pub t_end_s: f64,
    /// Final filter: its state, and the covariance it reports ([`Ekf::p`]).
    pub last: Ekf,
    /// Final offset filter.
    pub offset_filter: OffsetFilter,
    /// Innovations beyond the outlier threshold.
    pub outliers: usize,
    /// Mean normalised innovation squared (nu^2 / S) over the second half of the run: about 1
    /// when the filter's model and its covariance are right.
    pub nis_mean: f64,
    /// Samples the filter passed over because a force in their rate's window was not the
    /// spring's ([`Filter::push_marked`]).
    pub passed_over: usize,
    /// The spans of such samples it resumed after ([`Ekf::resume`]).
    pub resumes: usize,
}

/// Memory of the parallel F0, d0 filter: the offsets it tracks drift over tens of seconds
/// (temperature, wear), far slower than the impedance states.
pub const OFFSET_MEMORY_S: f64 = 30.0;

/// Where the filter starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Start {
    /// At this state.
    State(State),
    /// At rest at the first filtered sample's position, from an init ([`initial_state`]):
    /// sigma's initial standard deviation follows k2's over the stroke (mm).
    Init {
        /// The init.
        init: EkfInit,
        /// Stroke (mm).
        stroke_mm: f64,
    },
}

/// What the filter runs over and how it starts.
#[derive(Debug, Clone, Copy)]
pub struct EkfInput<'a> {
    /// Sample times (s), uniformly spaced.
    pub t_s: &'a [f64],
    /// Measured force (N), the input after differentiation.
    pub force_n: &'a [f64],
    /// Measured position (mm), the measurement.
    pub position_mm: &'a [f64],
    /// How the force rate is computed from the force.
    pub force_rate: ForceRate,
    /// Initial state.
    pub start: Start,
    /// Tuning: Q, P0, R, bounds and outlier threshold.
    pub settings: EkfSettings,
    /// Initial [F0, d0] of the parallel offset filter (N).
    pub offsets0: [f64; 2],
    /// Memory of the parallel offset filter (s), usually [`OFFSET_MEMORY_S`].
    pub offset_memory_s: f64,
}

/// The force rate computed as samples arrive, paired with the sample it belongs to.
#[derive(Debug, Clone)]
enum RateStage {
    /// Savitzky-Golay rate kernel: the rate of the window's centre sample (lag: half a window).
    ZeroPhase {
        weights: Vec<f64>,
        scale: f64,
        buffer: std::collections::VecDeque<(usize, super::log::Sample, bool)>,
        /// Samples in the buffer whose force is not the spring's.
        unmeasured: usize,
    },
    /// First-order low-pass: the rate at sample k belongs to sample k - delay.
    FirstOrder {
        a: f64,
        tau: f64,
        low: Option<f64>,
        delay: usize,
        buffer: std::collections::VecDeque<(usize, super::log::Sample, bool)>,
        /// The last input sample whose force is not the spring's.
        last_unmeasured: Option<usize>,
    },
}

impl RateStage {
    fn new(how: ForceRate, dt: f64) -> RateStage {
        match how {
            ForceRate::ZeroPhase { window_s } => {
                let d = zero_phase(window_s, dt);
                RateStage::ZeroPhase {
                    weights: d.weights[super::sg::RATE].clone(),
                    scale: 1.0 / dt,
                    buffer: std::collections::VecDeque::with_capacity(d.window() + 1),
                    unmeasured: 0,
                }
            }
            ForceRate::FirstOrder { time_constant_s } => {
                let tau = time_constant_s.max(dt);
                let delay = (tau / dt).round().clamp(0.0, 1e7) as usize;
                RateStage::FirstOrder {
                    a: dt / (tau + dt),
                    tau,
                    low: None,
                    delay,
                    buffer: std::collections::VecDeque::with_capacity(delay.min(1 << 16) + 1),
                    last_unmeasured: None,
                }
            }
        }
    }

    /// Samples of a log of `n` that get a rate.
    fn outputs(&self, n: usize) -> usize {
        match self {
            RateStage::ZeroPhase { weights, .. } => n.saturating_sub(weights.len() - 1),
            RateStage::FirstOrder { delay, .. } => n.saturating_sub(*delay),
        }
    }

    /// Takes input sample `i`, `measured` where its force is the spring's; returns the sample
    /// the rate now belongs to, the rate, and whether every force it was computed from was
    /// measured.
    fn push(
        &mut self,
        i: usize,
        s: super::log::Sample,
        measured: bool,
    ) -> Option<(usize, super::log::Sample, f64, bool)> {
        match self {
            RateStage::ZeroPhase {
                weights,
                scale,
                buffer,
                unmeasured,
            } => {
                buffer.push_back((i, s, measured));
                *unmeasured += usize::from(!measured);
                if buffer.len() > weights.len() {
                    if let Some((_, _, false)) = buffer.pop_front() {
                        *unmeasured -= 1;
                    }
                }
                if buffer.len() < weights.len() {
                    return None;
                }
                let rate = weights
                    .iter()
                    .zip(buffer.iter())
                    .map(|(w, (_, b, _))| w * b.force_n)
                    .sum::<f64>()
                    * *scale;
                let (j, c, _) = buffer[weights.len() / 2];
                Some((j, c, rate, *unmeasured == 0))
            }
            RateStage::FirstOrder {
                a,
                tau,
                low,
                delay,
                buffer,
                last_unmeasured,
            } => {
                if !measured {
                    // The low-pass starts again from the first measured force after a gap.
                    *last_unmeasured = Some(i);
                    *low = None;
                }
                let l = low.get_or_insert(s.force_n);
                *l += *a * (s.force_n - *l);
                let rate = (s.force_n - *l) / *tau;
                // The filter delays the force rate by about tau at the motion's frequencies;
                // the position is delayed to match (an on-line filter buffers it).
                buffer.push_back((i, s, measured));
                if buffer.len() > *delay {
                    let (j, c, _) = buffer.pop_front()?;
                    // The low-pass remembers a force for a few time constants: the rate is
                    // the spring's three of them after the last unmeasured sample.
                    let settled = last_unmeasured.is_none_or(|u| i - u > 3 * (*delay).max(1));
                    Some((j, c, rate, settled))
                } else {
                    None
                }
            }
        }
    }

    /// The motion at time `t_s` fitted to the positions the stage holds (the force-rate window
    /// round the sample the rate belongs to, or the samples after it): position, velocity and
    /// acceleration, and their covariance for a position variance `r_mm2`. A cubic in time,
    /// least squares, whose covariance is taken four times larger for what a cubic leaves
    /// out. None with fewer than six samples.
    fn motion_at(&self, t_s: f64, r_mm2: f64) -> Option<([f64; 3], nalgebra::Matrix3<f64>)> {
        let buffer = match self {
            RateStage::ZeroPhase { buffer, .. } | RateStage::FirstOrder { buffer, .. } => buffer,
        };
        if buffer.len() < 6 {
            return None;
        }
        let h = buffer
            .iter()
            .map(|(_, b, _)| (b.t_s - t_s).abs())
            .fold(0.0, f64::max);
        if h.is_nan() || h <= 0.0 {
            return None;
        }
        let mut normal = nalgebra::Matrix4::<f64>::zeros();
        let mut rhs = nalgebra::Vector4::<f64>::zeros();
        for (_, b, _) in buffer {
            let u = (b.t_s - t_s) / h;
            let row = nalgebra::Vector4::new(1.0, u, u * u, u * u * u);
            normal += row * row.transpose();
            rhs += row * b.position_mm;
        }
        let inverse = normal.try_inverse()?;
        let c = inverse * rhs;
        // x = c0, xd = c1 / h, xdd = 2 c2 / h^2.
        let scale = nalgebra::Matrix3x4::new(
            1.0,
            0.0,
            0.0,
            0.0,
            0.0,
            1.0 / h,
            0.0,
            0.0,
            0.0,
            0.0,
            2.0 / (h * h),
            0.0,
        );
        let motion = scale * c;
        let covariance = scale * inverse * scale.transpose() * (4.0 * r_mm2);
        Some(([motion[0], motion[1], motion[2]], covariance))
    }
}

/// The filter run as samples arrive: the force rate, the EKF and the parallel offset filter.
/// Its memory is constant (the force-rate window); each filtered sample comes out of
/// [`Filter::push`] as an [`EkfRow`], lagging the input by the force-rate filter's delay.
#[derive(Debug, Clone)]
pub struct Filter {
    rate: RateStage,
    start: Start,
    settings: EkfSettings,
    ekf: Option<Ekf>,
    offsets: OffsetFilter,
    outputs: usize,
    k: usize,
    previous: Option<(f64, f64)>,
    nis: (f64, usize),
    residual: (f64, f64),
    outliers: usize,
    first_sample: usize,
    t_end_s: f64,
    passed_over: usize,
    resumes: usize,
    /// Time of the last sample filtered before the current gap, while in one.
    gap_from_s: Option<f64>,
}

impl Filter {
    /// A filter over a log of `samples` samples every `dt` seconds.
    pub fn new(
        samples: usize,
        dt: f64,
        how: ForceRate,
        start: Start,
        settings: EkfSettings,
        offsets0: [f64; 2],
        offset_memory_s: f64,
    ) -> Result<Filter, EkfError> {
        if samples < 3 || !(dt.is_finite() && dt > 0.0) {
            return Err(EkfError::Input(format!(
                "{samples} samples; the filter needs at least 3 with force and position"
            )));
        }
        let rate = RateStage::new(how, dt);
        let outputs = rate.outputs(samples);
        if outputs < 3 {
            return Err(EkfError::Input(format!(
                "{samples} samples are fewer than the force-rate filter's window"
            )));
        }
        Ok(Filter {
            rate,
            start,
            settings,
            ekf: None,
            offsets: OffsetFilter::new(
                offsets0[0],
                offsets0[1],
                offset_memory_s,
                dt,
                settings.r_position_mm2.max(1e-12),
            ),
            outputs,
            k: 0,
            previous: None,
            nis: (0.0, 0),
            residual: (0.0, 0.0),
            outliers: 0,
            first_sample: 0,
            t_end_s: f64::NAN,
            passed_over: 0,
            resumes: 0,
            gap_from_s: None,
        })
    }

    /// The settings, with sigma's initial standard deviation once the filter has started.
    pub fn settings(&self) -> EkfSettings {
        self.ekf.as_ref().map_or(self.settings, |e| e.settings)
    }

    /// Takes log sample `i` (in order from 0); returns the row of the sample it filtered, if
    /// any (the first ones only fill the force-rate window).
    pub fn push(
        &mut self,
        i: usize,
        sample: super::log::Sample,
    ) -> Result<Option<EkfRow>, EkfError> {
        self.push_marked(i, sample, true)
    }

    /// [`Filter::push`] for a sample whose force may not be the spring's (`measured` false: a
    /// clipped load cell, a rod against a stop). A sample whose force rate reaches back or
    /// ahead to such a force is passed over: no prediction, no update, no row. After a span of
    /// them the filter resumes from the motion fitted to the positions round the first
    /// sample past it ([`Ekf::resume`]), keeping what it learnt of the constants. (Run
    /// through, the filter took the clipped force's standstill, or the stop's force, for the
    /// spring's: on the paper spec's log clipped at 60 N, k2 came out 47 of its standard
    /// deviations off identification's.)
    pub fn push_marked(
        &mut self,
        i: usize,
        sample: super::log::Sample,
        measured: bool,
    ) -> Result<Option<EkfRow>, EkfError> {
        let Some((i, s, rate, usable)) = self.rate.push(i, sample, measured) else {
            return Ok(None);
        };
        let k = self.k;
        self.k += 1;
        if !usable {
            self.passed_over += 1;
            if self.ekf.is_some() && self.previous.is_some() {
                self.gap_from_s = Some(self.t_end_s);
                self.previous = None;
            }
            return Ok(None);
        }
        if let (Some(ekf), Some(from)) = (&mut self.ekf, self.gap_from_s.take()) {
            let r = ekf.settings.r_position_mm2;
            let (motion, cov) = self.rate.motion_at(s.t_s, r).unwrap_or_else(|| {
                let p0 = ekf.settings.p0_std;
                (
                    [s.position_mm, 0.0, 0.0],
                    nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::new(
                        r,
                        p0[idx::XD] * p0[idx::XD],
                        p0[idx::XDD] * p0[idx::XDD],
                    )),
                )
            });
            ekf.resume(motion, &cov, s.t_s - from);
            self.resumes += 1;
        }
        let ekf = match (&mut self.ekf, self.previous) {
            (Some(ekf), Some((t_prev, rate_prev))) => {
                let info = ekf.step(rate_prev, rate, s.t_s - t_prev, s.position_mm, i, s.t_s)?;
                if info.innovation_mm.abs()
                    > self.settings.outlier_sigmas * info.innovation_variance_mm2.sqrt()
                {
                    self.outliers += 1;
                }
                if 2 * k >= self.outputs {
                    self.nis.0 +=
                        info.innovation_mm * info.innovation_mm / info.innovation_variance_mm2;
                    self.nis.1 += 1;
                }
                ekf
            }
            (Some(ekf), None) => {
                // The first sample after a gap: resumed from its own window's motion above.
                ekf
            }
            (slot @ None, _) => {
                // The first filtered sample initialises; its measurement is used without a
                // prediction.
                let (z0, settings) = match self.start {
                    Start::State(z) => (z, self.settings),
                    Start::Init { init, stroke_mm } => {
                        let (z, sigma_std) = initial_state(&init, s.position_mm, stroke_mm);
                        let mut settings = self.settings;
                        settings.p0_std[idx::SIGMA] = sigma_std;
                        (z, settings)
                    }
                };
                self.first_sample = i;
                let ekf = slot.insert(Ekf::new(z0, settings));
                ekf.update(s.position_mm);
                ekf
            }
        };
        self.previous = Some((s.t_s, rate));
        self.t_end_s = s.t_s;
        let z = ekf.z;
        // Parallel filter: what the impedance model does not explain is F0 + d0 sgn(xd).
        let d1 = z[idx::D] - 3.0 * z[idx::D2] * z[idx::XD] * z[idx::XD];
        let spring_minus_f0 = z[idx::SIGMA] / z[idx::K2];
        let explained = z[idx::M] * z[idx::XDD]
            + d1 * z[idx::XD]
            + z[idx::D2] * z[idx::XD].powi(3)
            + spring_minus_f0;
        let residual = s.force_n - explained;
        let band = 3.0 * ekf.p[(1, 1)].max(0.0).sqrt();
        let sgn = if z[idx::XD] > band {
            1.0
        } else if z[idx::XD] < -band {
            -1.0
        } else {
            0.0
        };
        let offsets = &mut self.offsets;
        let before = offsets.theta[0] + offsets.theta[1] * sgn;
        self.residual.0 += (residual - before).powi(2);
        self.residual.1 += 1.0;
        offsets.residual_variance = self.residual.0 / self.residual.1;
        offsets.update(residual, sgn);
        Ok(Some(EkfRow {
            t_s: s.t_s,
            state: z,
            std: ekf.std(),
            offsets: [offsets.theta[0], offsets.theta[1]],
            offset_stds: offsets.std(),
        }))
    }

    /// Samples filtered so far, and how many the log gives.
    pub fn progress(&self) -> (usize, usize) {
        (self.k, self.outputs)
    }

    /// The run's summary after the last sample (no rows).
    pub fn finish(self) -> Result<EkfRun, EkfError> {
        let Some(mut last) = self.ekf else {
            return Err(EkfError::Input(
                "no sample reached the filter (fewer samples than its force-rate window)".into(),
            ));
        };
        if self.k != self.outputs {
            return Err(EkfError::Input(format!(
                "the filter saw {} samples where the log gave {} before (did the log change while \
                 it was read?)",
                self.k, self.outputs
            )));
        }
        // From here on the run's covariance is the one it reports.
        if let Some(p) = last.p_reported.take() {
            last.p = p;
        }
        Ok(EkfRun {
            rows: Vec::new(),
            first_sample: self.first_sample,
            samples: self.k,
            t_end_s: self.t_end_s,
            last,
            offset_filter: self.offsets,
            outliers: self.outliers,
            nis_mean: self.nis.0 / self.nis.1.max(1) as f64,
            passed_over: self.passed_over,
            resumes: self.resumes,
        })
    }
}

/// Runs the filter over a log held in memory, collecting every row;
/// `progress(k, n)` is called as samples are processed.
pub fn run(
    input: EkfInput<'_>,
    mut progress: impl FnMut(usize, usize),
) -> Result<EkfRun, EkfError> {
    let EkfInput {
        t_s,
        force_n,
        position_mm,
        force_rate: how,
        start,
        settings,
        offsets0,
        offset_memory_s,
    } = input;
    let n = t_s.len();
    if n < 3 || force_n.len() != n || position_mm.len() != n {
        return Err(EkfError::Input(format!(
            "{n} samples; the filter needs at least 3 with force and position"
        )));
    }
    let dt = (t_s[n - 1] - t_s[0]) / (n - 1) as f64;
    let mut filter = Filter::new(n, dt, how, start, settings, offsets0, offset_memory_s)?;
    let mut rows = Vec::with_capacity(filter.outputs);
    for i in 0..n {
        let sample = super::log::Sample {
            t_s: t_s[i],
            force_n: force_n[i],
            position_mm: position_mm[i],
        };
        if let Some(row) = filter.push(i, sample)? {
            rows.push(row);
            if rows.len() % 65_536 == 1 {
                progress(rows.len() - 1, filter.outputs);
            }
        }
    }
    let mut run = filter.finish()?;
    run.rows = rows;
    Ok(run)
}

/// Where the filter's initial state comes from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct EkfInit {
    /// k2 (1/mm) and its standard deviation.
    pub k2_per_mm: (f64, f64),
    /// mu (N), for sigma at the first sample.
    pub mu_n: f64,
    /// F0 (N) and d0 (N), for the parallel filter.
    pub f0_n: f64,
    /// Coulomb friction (N).
    pub d0_n: f64,
    /// Inertia (N s^2/mm) and its standard deviation.
    pub m_n_s2_per_mm: (f64, f64),
    /// Linear damping (N s/mm) and its standard deviation.
    pub d1_n_s_per_mm: (f64, f64),
    /// Cubic damping (N s^3/mm^3) and its standard deviation.
    pub d2_n_s3_per_mm3: (f64, f64),
}

impl EkfInit {
    /// From an identification (the paper's initialisation). Standard deviations are the
    /// identification's, at least 1 % of k2 and 10 % of M and d1, so that the filter can move.
    pub fn from_identification(id: &Identification, force_variance_n2: f64) -> EkfInit {
        let g = |p: Param| {
            let e = id.get(p);
            e.value.zip(e.std)
        };
        let k2 =
            g(Param::K2).unwrap_or((id.k2_quasi_static_per_mm, 0.05 * id.k2_quasi_static_per_mm));
        // An inertia that identification does not resolve (standard deviation above half the
        // value) is held, not estimated: the filter cannot resolve it either, and a wide prior
        // on it lets the prediction go unstable. It is held at identification's value (at least
        // zero: the pipeline's floor applies), unless the pipeline carries it free as a
        // nuisance (`EkfSettings::m_nuisance_from`).
        let m = match g(Param::M) {
            Some((v, s)) if v > 0.0 && s < 0.5 * v => (v, s.max(0.1 * v)),
            Some((v, _)) => (v.max(0.0), 0.0),
            None => (0.0, 0.0),
        };
        let d1 = g(Param::D1);
        let d2 = match g(Param::D2) {
            Some((v, s)) if s < 0.5 * v.abs() => (v, s.max(1e-6)),
            // A cubic damping that identification does not resolve is still estimated when its
            // force at the log's top speed v is several times the force noise: held at zero, a d2
            // whose force is newtons (the paper's Table I at 6 mm/s: 2.3 N) biased k2 by 3.6 % on
            // trapezoidal moves. It starts from identification's value within the range where
            // the damper force rises with speed (d1 + 3 d2 v^2 > 0), with a prior of at most a
            // quarter of that range, so that D stays positive and the prediction stable. A d2
            // whose force is below that is held at zero (estimating it made slow runs diverge).
            Some((v, s)) => match d1 {
                Some((d1, _)) if d1 > 0.0 && id.speed_max_mm_per_s > 0.0 => {
                    let speed = id.speed_max_mm_per_s;
                    let range = d1 / (3.0 * speed * speed);
                    let v = v.clamp(-0.5 * range, range);
                    if v.abs() * speed.powi(3) > 3.0 * force_variance_n2.sqrt() {
                        (v, s.min(0.25 * range))
                    } else {
                        (0.0, 0.0)
                    }
                }
                _ => (0.0, 0.0),
            },
            None => (0.0, 0.0),
        };
        EkfInit {
            k2_per_mm: (k2.0, k2.1.max(0.01 * k2.0.abs())),
            mu_n: g(Param::Mu).map_or(1.0, |v| v.0),
            f0_n: g(Param::F0).map_or(0.0, |v| v.0),
            d0_n: g(Param::D0).map_or(0.0, |v| v.0),
            m_n_s2_per_mm: m,
            // A damper whose identified d1 is negative (noise on a slow run) starts at zero.
            d1_n_s_per_mm: d1.map_or((0.05, 0.05), |(v, s)| {
                (v.max(0.0), s.max(0.1 * v.abs()).max(1e-3))
            }),
            d2_n_s3_per_mm3: d2,
        }
    }

    /// From a designed law: k2 and mu exact to the design, the dynamics unknown (wide).
    pub fn from_law(law: &crate::model::ExpLaw) -> EkfInit {
        EkfInit {
            k2_per_mm: (law.k2_per_mm, 0.05 * law.k2_per_mm),
            mu_n: law.mu_n,
            f0_n: law.f0_n,
            d0_n: 0.0,
            m_n_s2_per_mm: (1e-2, 1e-2),
            d1_n_s_per_mm: (0.05, 0.05),
            d2_n_s3_per_mm3: (0.0, 1e-3),
        }
    }
}

/// Documented default tuning for a log sampled every `dt` with the given sensor noise,
/// starting from `init`:
///
/// - R: the position variance.
/// - Q: no process noise on x and xd (exact kinematics); on xdd the force-rate noise over one
///   sample, var(u) dt / (8 M^2), with var(u) the force variance through the force-rate
///   filter (the factor chosen on simulated runs: from 4 to 16 the results barely move); sigma
///   1e-4 (N/mm)^2/s and D 1e-8 (N s/mm)^2/s, enough to follow a model that is not exact; none
///   on the constants M, k2 and d2.
/// - The reported covariance: the same, but with [`GAIN_NOISE_INFLATION`] times less noise on
///   xdd ([`EkfSettings::reported_xdd_q`]).
/// - P0: the position variance; 5 mm/s and 20 mm/s^2 on the velocity and acceleration;
///   sigma from k2's standard deviation over the stroke (at least 5 %); the init's standard
///   deviations for D, M, k2 and d2.
pub fn default_settings(
    init: &EkfInit,
    noise: &super::identify::SensorNoise,
    dt: f64,
    discretization: Discretization,
    how: ForceRate,
) -> EkfSettings {
    let rate_variance = match how {
        ForceRate::ZeroPhase { window_s } => {
            zero_phase(window_s, dt).noise_variance(super::sg::RATE, noise.force_variance_n2, dt)
        }
        ForceRate::FirstOrder { time_constant_s } => {
            // Discrete first-order filter: var(u) = var(F) (2 - a)^-1 a ... approximately var(F) / (2 tau dt).
            noise.force_variance_n2 / (2.0 * time_constant_s.max(dt) * dt)
        }
    };
    let m = init.m_n_s2_per_mm.0.max(1e-6);
    let q_xdd = rate_variance * dt / (8.0 * m * m);
    EkfSettings {
        discretization,
        q: [0.0, 0.0, q_xdd, 1e-4, 1e-8, 0.0, 0.0, 0.0],
        r_position_mm2: noise.position_variance_mm2.max(1e-12),
        p0_std: [
            noise.position_variance_mm2.max(1e-12).sqrt(),
            5.0,
            20.0,
            0.0, // set per log from sigma at the start
            init.d1_n_s_per_mm.1,
            init.m_n_s2_per_mm.1,
            init.k2_per_mm.1,
            init.d2_n_s3_per_mm3.1,
        ],
        m_floor: 1e-6,
        sigma_floor: 1e-6,
        d_floor: 0.0,
        outlier_sigmas: 8.0,
        max_outliers_in_a_row: 50,
        m_nuisance_from: None,
        reported_xdd_q: Some(q_xdd / GAIN_NOISE_INFLATION),
    }
}

/// How many times the acceleration's process noise the filter's gains are computed with
/// exceeds the one its reported error covariance is propagated with.
///
/// The filter's input, the zero-phase force rate, is the derivative of a smoothed force: its
/// noise integrates to the smoothed force noise over M, which stays bounded, not to a random
/// walk, so white process noise at the rate's variance overstates what the noise does to the
/// constants. Gains computed with that much noise keep k2 accurate where the model is not
/// exact (a friction held at rest, for one), and were kept; with 16 times less
/// noise in the gains too, the acceptance matrix's filter met its k2 target on 50 runs of 72
/// instead of 54, and its heaviest steps' k2 went from +0.86 % to +1.72 %. The covariance
/// the filter reports is propagated with its gains (a sensitivity analysis of a filter tuned
/// away from its noise model) and the smaller noise: its NEES of [M, k2, d2] over simulated
/// runs is then inside its 95 % band on seven of the nine rows of docs/CALIBRATION.md (four
/// were outside before), and barely moves for factors from 4 to 64 (docs/CALIBRATION.md, "The
/// reported covariance").
pub const GAIN_NOISE_INFLATION: f64 = 16.0;

/// The initial state at position `x0_mm` (at rest) and sigma's initial standard deviation.
pub fn initial_state(init: &EkfInit, x0_mm: f64, stroke_mm: f64) -> (State, f64) {
    let (k2, k2_std) = init.k2_per_mm;
    let sigma = k2 * init.mu_n * (k2 * x0_mm).exp();
    // sigma = k2 mu exp(k2 x): a k2 error moves it by (1 + k2 x) dk2 / k2 relative.
    let rel = (k2_std / k2.abs().max(1e-12)) * (1.0 + k2.abs() * stroke_mm);
    let z = State::from([
        x0_mm,
        0.0,
        0.0,
        sigma,
        init.d1_n_s_per_mm.0,
        init.m_n_s2_per_mm.0,
        k2,
        init.d2_n_s3_per_mm3.0,
    ]);
    (z, sigma * rel.max(0.05))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::log::Sample;

    /// A force with motion and noise-like wiggles, sampled every 10 ms.
    fn signal(n: usize) -> Vec<Sample> {
        (0..n)
            .map(|i| {
                let t = i as f64 * 0.01;
                Sample {
                    t_s: t,
                    force_n: 5.0 + 3.0 * (0.9 * t).sin() + 0.01 * ((i * 7919) % 13) as f64,
                    position_mm: 4.0 + (0.9 * t).sin(),
                }
            })
            .collect()
    }

    #[test]
    fn a_resumed_filter_moves_sigma_along_the_law_and_its_covariance_through_the_map() {
        let (k2, mu, x0, x1): (f64, f64, f64, f64) = (0.25, 1.2, 6.0, 9.0);
        let settings = EkfSettings {
            discretization: Discretization::Rk4,
            q: [0.0, 0.0, 1.0, 1e-4, 1e-8, 0.0, 0.0, 0.0],
            r_position_mm2: 1e-2,
            p0_std: [0.1, 2.0, 10.0, 0.3, 0.02, 0.004, 0.003, 1e-4],
            m_floor: 1e-6,
            sigma_floor: 1e-6,
            d_floor: 0.0,
            outlier_sigmas: 8.0,
            max_outliers_in_a_row: 50,
            m_nuisance_from: None,
            reported_xdd_q: None,
        };
        let z0 = State::from([
            x0,
            4.0,
            -3.0,
            k2 * mu * (k2 * x0).exp(),
            0.3,
            0.05,
            k2,
            -1e-3,
        ]);
        let (motion, gap) = ([x1, -7.0, 12.0], 0.8);
        let motion_cov = nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::new(4e-3, 0.5, 9.0));
        let resumed = |z: State, motion: [f64; 3]| {
            let mut e = Ekf::new(z, settings);
            e.resume(motion, &motion_cov, gap);
            e
        };
        let e = resumed(z0, motion);
        // sigma = k2 mu exp(k2 x) at the new position; D = d1 + 3 d2 xd^2 at the new speed;
        // the constants kept; the motion the fitted one.
        assert!((e.z[idx::SIGMA] - k2 * mu * (k2 * x1).exp()).abs() < 1e-12);
        let d1 = z0[idx::D] - 3.0 * z0[idx::D2] * z0[idx::XD].powi(2);
        assert!((e.z[idx::D] - (d1 + 3.0 * z0[idx::D2] * 49.0)).abs() < 1e-12);
        for i in [idx::M, idx::K2, idx::D2] {
            assert_eq!(e.z[i], z0[i]);
        }
        assert_eq!([e.z[0], e.z[1], e.z[2]], motion);
        // The covariance against the map differentiated numerically: the old state's
        // variances (diagonal P0) and the motion's, plus sigma's and D's process noise.
        for (k, noise) in [(idx::SIGMA, 1e-4 * gap), (idx::D, 1e-8 * gap)] {
            let mut expected = noise;
            for j in 0..8 {
                let h = 1e-6 * z0[j].abs().max(1e-3);
                let (mut up, mut down) = (z0, z0);
                up[j] += h;
                down[j] -= h;
                let slope = (resumed(up, motion).z[k] - resumed(down, motion).z[k]) / (2.0 * h);
                expected += slope * slope * settings.p0_std[j].powi(2);
            }
            for j in 0..3 {
                let h = 1e-6 * motion[j].abs().max(1e-3);
                let (mut up, mut down) = (motion, motion);
                up[j] += h;
                down[j] -= h;
                let slope = (resumed(z0, up).z[k] - resumed(z0, down).z[k]) / (2.0 * h);
                expected += slope * slope * motion_cov[(j, j)];
            }
            let got = e.p[(k, k)];
            assert!(
                (got - expected).abs() < 1e-6 * expected,
                "{}: {got} against {expected}",
                STATE_NAMES[k]
            );
        }
        // The motion's covariance is the fitted one, the constants' untouched.
        assert!((e.p[(idx::XD, idx::XD)] - 0.5).abs() < 1e-12);
        assert!((e.p[(idx::K2, idx::K2)] - 0.003f64.powi(2)).abs() < 1e-15);
    }

    #[test]
    fn a_force_rate_window_holding_an_unmeasured_force_is_not_used_and_the_motion_is_fitted() {
        // A rod on a known cubic motion; one sample in the middle reads a force that is not
        // the spring's. Every rate whose window holds it is marked unusable, the others not;
        // and the motion fitted round a sample is the cubic's.
        let dt = 0.01;
        let motion = |t: f64| 3.0 + 2.0 * t - 0.5 * t * t + 0.1 * t * t * t;
        let mut stage = RateStage::new(ForceRate::ZERO_PHASE, dt);
        let bad = 200;
        let mut usable = Vec::new();
        let mut fitted = None;
        for i in 0..400 {
            let t = i as f64 * dt;
            let s = Sample {
                t_s: t,
                force_n: 1.0,
                position_mm: motion(t),
            };
            if let Some((j, c, _, ok)) = stage.push(i, s, i != bad) {
                usable.push((j, ok));
                if j == 300 {
                    fitted = stage.motion_at(c.t_s, 1e-4);
                }
            }
        }
        let half = zero_phase_samples(crate::estimate::sg::WINDOW_SECONDS, dt) / 2;
        for (j, ok) in usable {
            assert_eq!(ok, j.abs_diff(bad) > half, "sample {j}");
        }
        let (m, cov) = fitted.unwrap();
        let t = 3.0;
        let truth = [motion(t), 2.0 - t + 0.3 * t * t, -1.0 + 0.6 * t];
        for k in 0..3 {
            assert!(
                (m[k] - truth[k]).abs() < 1e-8,
                "{k}: {} against {}",
                m[k],
                truth[k]
            );
            assert!(cov[(k, k)] > 0.0);
        }
    }

    #[test]
    fn the_streamed_force_rate_is_the_batch_one_on_the_same_samples() {
        let samples = signal(1000);
        let force: Vec<f64> = samples.iter().map(|s| s.force_n).collect();
        for how in [
            ForceRate::ZERO_PHASE,
            ForceRate::FirstOrder {
                time_constant_s: 0.05,
            },
        ] {
            let (batch, first) = force_rate(&force, 0.01, how);
            let mut stage = RateStage::new(how, 0.01);
            let streamed: Vec<(usize, f64)> = samples
                .iter()
                .enumerate()
                .filter_map(|(i, s)| stage.push(i, *s, true).map(|(j, _, r, _)| (j, r)))
                .collect();
            assert_eq!(streamed.len(), batch.len(), "{how:?}");
            assert_eq!(stage.outputs(samples.len()), batch.len(), "{how:?}");
            for (k, (j, r)) in streamed.iter().enumerate() {
                assert_eq!(*j, first + k, "{how:?}");
                assert!(
                    (r - batch[k]).abs() <= 1e-9 * batch[k].abs().max(1.0),
                    "{how:?} {k}"
                );
            }
        }
    }

    /// The default settings (RK4, zero-phase rate, force variance 1e-3 N^2) for a spring of
    /// exponent rate `k2` (value, std), a linear damper `d1` (value, std) and a held inertia `m`,
    /// with no friction or cubic damping, read with position variance `r`; no stiffness floor.
    fn spring_damper_mass(k2: (f64, f64), d1: (f64, f64), m: f64, r: f64, dt: f64) -> EkfSettings {
        let init = EkfInit {
            k2_per_mm: k2,
            mu_n: 1.0,
            f0_n: 0.0,
            d0_n: 0.0,
            m_n_s2_per_mm: (m, 0.0),
            d1_n_s_per_mm: d1,
            d2_n_s3_per_mm3: (0.0, 0.0),
        };
        let noise = crate::estimate::identify::SensorNoise::new(1e-3, r);
        EkfSettings {
            sigma_floor: 0.0,
            ..default_settings(
                &init,
                &noise,
                dt,
                Discretization::Rk4,
                ForceRate::ZERO_PHASE,
            )
        }
    }

    /// A prediction whose damping rate D / M times the sample interval is 50: one RK4 step
    /// multiplies the acceleration's transient by about 2.4e5 (the filter lost a servo's
    /// ramp-hold log this way when its D grew), the substeps follow the closed form
    /// xdd = U / D (1 - exp(-D t / M)) of a constant force rate U with no stiffness.
    #[test]
    fn a_stiff_prediction_is_split_into_substeps_and_follows_the_closed_form() {
        let (u, d, m, dt) = (3.0, 5.0, 0.001, 0.01);
        let mut settings = spring_damper_mass((0.2, 0.01), (d, 0.1), m, 1e-4, dt);
        settings.m_floor = 0.0;
        assert_eq!(
            substeps(&State::from([0.0, 0.0, 0.0, 0.0, d, m, 0.0, 0.0]), dt),
            50
        );
        let mut ekf = Ekf::new(State::from([0.0, 0.0, 0.0, 0.0, d, m, 0.0, 0.0]), settings);
        ekf.predict(u, u, dt);
        let rate = d / m;
        let xdd = u / d * (1.0 - (-rate * dt).exp());
        let xd = u / d * (dt - (1.0 - (-rate * dt).exp()) / rate);
        assert!(
            (ekf.z[idx::XDD] - xdd).abs() < 1e-6 * xdd,
            "{} against {xdd}",
            ekf.z[idx::XDD]
        );
        assert!(
            (ekf.z[idx::XD] - xd).abs() < 1e-4 * xd,
            "{} against {xd}",
            ekf.z[idx::XD]
        );
        assert!(ekf.p.iter().all(|v| v.is_finite()));
        assert!((0..8).all(|i| ekf.p[(i, i)] >= 0.0));
    }

    #[test]
    fn a_log_shorter_than_the_rate_window_is_refused_before_filtering() {
        let init = EkfInit {
            k2_per_mm: (0.2, 0.01),
            mu_n: 1.0,
            f0_n: 0.0,
            d0_n: 0.0,
            m_n_s2_per_mm: (0.05, 0.005),
            d1_n_s_per_mm: (0.2, 0.02),
            d2_n_s3_per_mm3: (0.0, 0.0),
        };
        let noise = crate::estimate::identify::SensorNoise::new(1e-3, 1e-4);
        let settings = default_settings(
            &init,
            &noise,
            0.01,
            Discretization::Rk4,
            ForceRate::ZERO_PHASE,
        );
        let start = Start::Init {
            init,
            stroke_mm: 10.0,
        };
        // The zero-phase window at 100 Hz is 41 samples: 42 give one rate, 43 give three.
        for (n, ok) in [(2, false), (42, false), (43, true)] {
            let r = Filter::new(
                n,
                0.01,
                ForceRate::ZERO_PHASE,
                start,
                settings,
                [0.0, 0.0],
                30.0,
            );
            assert_eq!(r.is_ok(), ok, "{n} samples");
        }
    }

    #[test]
    fn the_short_force_rate_follows_a_ramp_the_default_one_smears() {
        // A force at rest that starts to rise at 5 N/s at t = 1 s, at 500 Hz: its rate is 0
        // before and exactly 5 N/s after. A quintic kernel whose whole window lies on the ramp
        // gives the slope exactly; 30 ms after the start the short window (25 samples) lies on
        // it and the default one (201 samples) still reaches back into the rest.
        let dt = 0.002;
        let force: Vec<f64> = (0..2000)
            .map(|i| 5.0 * (i as f64 * dt - 1.0).max(0.0))
            .collect();
        let short = ForceRate::ZERO_PHASE.shorter(dt).unwrap();
        assert_eq!(short.window_taken_s(dt), Some(0.05));
        let at = 515; // 1.030 s
        let (rate, first) = force_rate(&force, dt, short);
        assert!(
            (rate[at - first] - 5.0).abs() < 1e-9,
            "{}",
            rate[at - first]
        );
        let (rate, first) = force_rate(&force, dt, ForceRate::ZERO_PHASE);
        assert!((rate[at - first] - 5.0).abs() > 0.5, "{}", rate[at - first]);
        // Where the short window is no shorter than the default one, there is none; nor for
        // the first-order filter.
        assert!(ForceRate::ZERO_PHASE.shorter(0.05).is_none());
        assert!(ForceRate::FirstOrder {
            time_constant_s: 0.02
        }
        .shorter(dt)
        .is_none());
        // At 100 Hz the short window is the shortest kernel, 13 samples.
        assert_eq!(
            ForceRate::ZERO_PHASE
                .shorter(0.01)
                .and_then(|r| r.window_taken_s(0.01)),
            Some(0.13)
        );
    }

    /// The reported covariance is the filter's error covariance when the world's process noise
    /// is the reported one and the gains come from more: on a linear system (x, xd, xdd with
    /// constant sigma, D and M; k2 = d2 = 0) driven by white noise on xdd at q, filtered with 16 q
    /// in its gains, the final errors over 6 000 runs have the variances of the reported
    /// covariance (within the chi-square scatter), not of the filter's own, which overstates
    /// them.
    #[test]
    fn the_reported_covariance_matches_the_errors_of_a_filter_tuned_with_more_noise() {
        use rand::{rngs::StdRng, SeedableRng};
        use rand_distr::{Distribution, StandardNormal};
        let (m, d, sigma, dt, r, q) = (0.05, 0.2, 2.0, 0.01, 1e-4, 1e4);
        let mut settings = spring_damper_mass((0.0, 0.0), (d, 0.0), m, r, dt);
        settings.q = [0.0, 0.0, 16.0 * q, 0.0, 0.0, 0.0, 0.0, 0.0];
        settings.reported_xdd_q = Some(q);
        settings.p0_std = [0.01, 1.0, 10.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let (runs, steps) = (6000, 300);
        let mut rng = StdRng::seed_from_u64(7);
        let mut normal = move || -> f64 { StandardNormal.sample(&mut rng) };
        let mut sum = [0.0; 3];
        let mut last = None;
        for _ in 0..runs {
            let truth0 = State::from([
                0.01 * normal(),
                normal(),
                10.0 * normal(),
                sigma,
                d,
                m,
                0.0,
                0.0,
            ]);
            let mut truth = truth0;
            let mut ekf = Ekf::new(
                State::from([0.0, 0.0, 0.0, sigma, d, m, 0.0, 0.0]),
                settings,
            );
            ekf.update(truth[0] + r.sqrt() * normal());
            for _ in 0..steps {
                // The world: one RK4 step of the model, then the process noise over the step.
                let mut world = Ekf::new(truth, settings);
                world.predict(0.0, 0.0, dt);
                truth = world.z;
                truth[idx::XDD] += (q * dt).sqrt() * normal();
                ekf.predict(0.0, 0.0, dt);
                ekf.update(truth[0] + r.sqrt() * normal());
            }
            for (k, s) in sum.iter_mut().enumerate() {
                *s += (ekf.z[k] - truth[k]).powi(2);
            }
            last = Some(ekf);
        }
        let ekf = last.expect("runs");
        let reported = ekf.p_reported.expect("a reported covariance");
        for k in 0..3 {
            let observed = sum[k] / runs as f64;
            let ratio = observed / reported[(k, k)];
            // 6 000 squared normal errors: the ratio's standard deviation is sqrt(2 / 6000) = 0.018.
            assert!(
                (ratio - 1.0).abs() < 0.08,
                "state {k}: observed / reported variance {ratio}"
            );
            let own = observed / ekf.p[(k, k)];
            eprintln!("state {k}: observed / reported {ratio:.3}, / own {own:.3}");
            // The position is read every sample; its error is the measurement's either way.
            if k > 0 {
                assert!(
                    own < 0.8,
                    "state {k}: observed / own variance {own} (should overstate)"
                );
            }
        }
    }
}
