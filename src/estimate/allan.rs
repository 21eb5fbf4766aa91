//! Overlapping Allan variance and the white-noise model it supports.
//!
//! For a signal y sampled every tau0 with averaging factor m (tau = m*tau0), the overlapping
//! Allan variance is `AVAR(tau) = sum_k (x[k+2m] - 2 x[k+m] + x[k])^2 / (2 tau^2 (N - 2m))`,
//! with x the running integral of y. White noise of variance s^2 gives AVAR(tau) = s^2 tau0 / tau:
//! a slope of -1 on a log-log plot and the sample variance at tau = tau0. [`white_noise_fit`]
//! fits the slope over the first decade of tau and the level s^2 assuming slope -1.

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
    /// Variance at the sampling interval assuming slope -1 (signal unit squared).
    pub variance: f64,
}

/// Fits slope and white-noise variance over tau0 ... 10 tau0.
pub fn white_noise_fit(points: &[AllanPoint], tau0: f64) -> WhiteNoiseFit {
    let first: Vec<&AllanPoint> = points
        .iter()
        .filter(|p| p.tau_s <= 10.0 * tau0 * 1.0001)
        .collect();
    let (lx, ly): (Vec<f64>, Vec<f64>) = first.iter().map(|p| (p.tau_s.ln(), p.avar.ln())).unzip();
    let n = lx.len() as f64;
    let (mx, my) = (lx.iter().sum::<f64>() / n, ly.iter().sum::<f64>() / n);
    let sxy: f64 = lx.iter().zip(&ly).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = lx.iter().map(|a| (a - mx).powi(2)).sum();
    let slope = if sxx > 0.0 { sxy / sxx } else { f64::NAN };
    // With slope -1: avar * tau / tau0 is the variance; average over the first decade.
    let variance = first.iter().map(|p| p.avar * p.tau_s / tau0).sum::<f64>() / n;
    WhiteNoiseFit { slope, variance }
}
