//! Overlapping Allan variance and the white-noise model it supports.
//!
//! For a signal y sampled every tau0 with averaging factor m (tau = m*tau0), the overlapping
//! Allan variance is `AVAR(tau) = sum_k (x[k+2m] - 2 x[k+m] + x[k])^2 / (2 tau^2 (N - 2m))`,
//! with x the running integral of y. White noise of variance s^2 gives AVAR(tau) = s^2 tau0 / tau:
//! a slope of -1 on a log-log plot and the sample variance at tau = tau0. [`white_noise_fit`]
//! fits the slope over the first decade of tau, and the white-noise level next to a tau^2 term
//! that takes smooth motion or drift.

use serde::Serialize;

/// One point of an Allan variance curve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AllanPoint {
    /// Averaging time.
    pub tau_s: f64,
    /// Allan variance (signal unit squared).
    pub avar: f64,
}

/// Overlapping Allan variance at about 10 log-spaced averaging factors per decade, up to N/4.
pub fn allan_variance(y: &[f64], tau0: f64) -> Vec<AllanPoint> {
    let n = y.len();
    let mut x = Vec::with_capacity(n + 1);
    x.push(0.0);
    for v in y {
        x.push(x.last().expect("non-empty") + v * tau0);
    }
    let mut ms: Vec<usize> = Vec::new();
    let mut k = 0.0_f64;
    loop {
        let m = 10f64.powf(k / 10.0).round() as usize;
        if m > n / 4 {
            break;
        }
        if ms.last() != Some(&m) {
            ms.push(m);
        }
        k += 1.0;
    }
    ms.iter()
        .map(|&m| {
            let tau = m as f64 * tau0;
            let terms = x.len() - 2 * m;
            let sum: f64 = (0..terms)
                .map(|i| (x[i + 2 * m] - 2.0 * x[i + m] + x[i]).powi(2))
                .sum();
            AllanPoint {
                tau_s: tau,
                avar: sum / (2.0 * tau * tau * terms as f64),
            }
        })
        .collect()
}

/// The white-noise reading of an Allan curve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct WhiteNoiseFit {
    /// Log-log slope over the first decade (-1 for white noise).
    pub slope: f64,
    /// White-noise variance: the level of the 1/tau term at the sampling interval (signal unit squared).
    pub variance: f64,
    /// Coefficient b of the b*tau^2 term fitted next to it (signal unit squared per s^2): smooth
    /// motion or drift adds (mean square rate)/2 * tau^2 to the Allan variance; 0 at rest.
    pub motion_coefficient_per_s2: f64,
}

/// Fits the first decade (tau0 ... 10 tau0) of an Allan curve with AVAR = q/tau + b tau^2
/// (white noise plus smooth motion or drift, b >= 0) by least squares in relative error, and
/// the free log-log slope. The white-noise variance is q/tau0. On a log at rest b is about 0 and
/// this is the classic reading at tau0; on a moving log the tau^2 term takes the motion, so the
/// noise of a calibration run itself can be read.
pub fn white_noise_fit(points: &[AllanPoint], tau0: f64) -> WhiteNoiseFit {
    let first: Vec<&AllanPoint> = points
        .iter()
        .filter(|p| p.tau_s <= 10.0 * tau0 * 1.0001 && p.avar > 0.0)
        .collect();
    if first.is_empty() {
        return WhiteNoiseFit {
            slope: f64::NAN,
            variance: f64::NAN,
            motion_coefficient_per_s2: f64::NAN,
        };
    }
    let (lx, ly): (Vec<f64>, Vec<f64>) = first.iter().map(|p| (p.tau_s.ln(), p.avar.ln())).unzip();
    let n = lx.len() as f64;
    let (mx, my) = (lx.iter().sum::<f64>() / n, ly.iter().sum::<f64>() / n);
    let sxy: f64 = lx.iter().zip(&ly).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = lx.iter().map(|a| (a - mx).powi(2)).sum();
    let slope = if sxx > 0.0 { sxy / sxx } else { f64::NAN };
    // Relative least squares: rows (1/tau, tau^2) / avar against 1.
    let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for p in &first {
        let (u, v) = (1.0 / (p.tau_s * p.avar), p.tau_s * p.tau_s / p.avar);
        a11 += u * u;
        a12 += u * v;
        a22 += v * v;
        b1 += u;
        b2 += v;
    }
    let det = a11 * a22 - a12 * a12;
    let (mut q, mut b) = if det > 1e-12 * a11 * a22 {
        ((a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det)
    } else {
        (b1 / a11, 0.0)
    };
    if b < 0.0 || q <= 0.0 {
        q = b1 / a11;
        b = 0.0;
    }
    WhiteNoiseFit {
        slope,
        variance: q / tau0,
        motion_coefficient_per_s2: b,
    }
}
