//! Is the model right for this log? The reduced chi-square of a fit with the noise model's
//! weights, and a whiteness test of its residuals beyond the filter window ([`Adequacy`]). A fit
//! that fails either is reported as not fitting, with the likely cause, never as a result.

use serde::Serialize;

/// Largest reduced chi-square that counts as the model explaining the log: the noise model's
/// weights make it about 1 when the dynamic model and the noise model are right.
pub const MAX_REDUCED_CHI2: f64 = 1.5;

/// Smallest reduced chi-square that counts as the model explaining the log (below it the
/// noise model is larger than the log's noise).
pub const MIN_REDUCED_CHI2: f64 = 0.5;

/// Lags (in filter windows) of the whiteness test.
pub const WHITENESS_LAGS: usize = 20;

/// Significance level of the whiteness test.
pub const WHITENESS_LEVEL: f64 = 1e-3;

/// The residual whiteness test: the standardized residuals' autocorrelation at lags of whole
/// filter windows, where the noise model says they are independent.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Whiteness {
    /// Ljung-Box-type statistic: the sum over the tested lags of rho^2 / var(rho).
    pub statistic: f64,
    /// Degrees of freedom (lags tested).
    pub lags: usize,
    /// Spacing of the tested lags (samples): one filter window.
    pub lag_spacing_samples: usize,
    /// Probability of a statistic this large for residuals that are independent beyond one
    /// window.
    pub p_value: f64,
}

/// Whether the fitted model explains the log.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Adequacy {
    /// Reduced chi-square with the noise model's weights.
    pub reduced_chi2: f64,
    /// The residual whiteness test (None: too few samples).
    pub whiteness: Option<Whiteness>,
    /// `fits`, or `does-not-fit` with the reasons and the likely cause.
    pub status: FitStatus,
    /// Why the model does not fit, and the likely cause (empty when it fits).
    pub reasons: Vec<String>,
}

/// The adequacy verdict.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum FitStatus {
    /// Reduced chi-square near 1 and white residuals.
    Fits,
    /// The model does not explain this log.
    DoesNotFit,
}

impl Adequacy {
    /// Judges a fit by its reduced chi-square and whiteness test: it fits from
    /// [`MIN_REDUCED_CHI2`] to [`MAX_REDUCED_CHI2`], with white residuals.
    pub fn new(reduced_chi2: f64, whiteness: Option<Whiteness>) -> Adequacy {
        Adequacy::within(reduced_chi2, whiteness, MIN_REDUCED_CHI2..=MAX_REDUCED_CHI2)
    }

    /// Judges a fit by its reduced chi-square, which must lie in `range`, and its whiteness
    /// test.
    pub fn within(
        reduced_chi2: f64,
        whiteness: Option<Whiteness>,
        range: std::ops::RangeInclusive<f64>,
    ) -> Adequacy {
        let (low, high) = (*range.start(), *range.end());
        let mut reasons = Vec::new();
        let coloured = whiteness.is_some_and(|w| w.p_value < WHITENESS_LEVEL);
        if reduced_chi2 > high || !reduced_chi2.is_finite() {
            reasons.push(format!(
                "reduced chi-square {reduced_chi2:.2} is above {high}: the residuals are larger than \
                 the noise model allows; {}",
                if coloured {
                    "they are also correlated over time, so the likely cause is a force the model lacks \
                     (friction that is not Coulomb, hysteresis, a law that is not exponential, a slipping \
                     encoder), a force read at another instant than the position (channels scanned in \
                     turn, a converter's filter: try --force-delay auto) or a filter window too long \
                     for the motion"
                } else {
                    "they are white, so the likely cause is a noise model smaller than the sensors' noise: \
                     measure it with `camspring noise` on a log at rest and pass --noise"
                }
            ));
        } else if reduced_chi2 < low {
            reasons.push(format!(
                "reduced chi-square {reduced_chi2:.2} is below {low}: the noise model is larger \
                 than this log's noise, so the standard deviations are too wide; measure it with \
                 `camspring noise` on a log at rest and pass --noise"
            ));
        }
        if let Some(w) = whiteness.filter(|_| coloured) {
            reasons.push(format!(
                "the residuals are correlated beyond one filter window (whiteness statistic {:.1} over \
                 {} lags, p = {:.1e} < {WHITENESS_LEVEL}): the model leaves a slow force unexplained \
                 (friction that is not Coulomb, hysteresis, drift, a force read at another instant \
                 than the position, which --force-delay auto fits, or a filter window too long for \
                 the motion)",
                w.statistic, w.lags, w.p_value
            ));
        }
        Adequacy {
            reduced_chi2,
            whiteness,
            status: if reasons.is_empty() {
                FitStatus::Fits
            } else {
                FitStatus::DoesNotFit
            },
            reasons,
        }
    }

    /// The two measures in a few words: "reduced chi-square 2.61, residual whiteness p =
    /// 4.2e-8".
    pub fn measures(&self) -> String {
        match &self.whiteness {
            Some(w) => format!(
                "reduced chi-square {:.2}, residual whiteness p = {:.1e}",
                self.reduced_chi2, w.p_value
            ),
            None => format!("reduced chi-square {:.2}", self.reduced_chi2),
        }
    }

    /// Why the model does not fit this log, or None when it does.
    pub fn problem(&self) -> Option<String> {
        (self.status == FitStatus::DoesNotFit).then(|| self.reasons.join("; "))
    }
}

/// The whiteness test of standardized residuals `u` at sample indices `index` (increasing),
/// with the filter window `window` (samples).
///
/// Neighbouring residuals share the filtered position noise, so they are correlated up to one
/// window apart even when the model is right; beyond that the noise model makes them
/// independent. The test takes the autocorrelation rho at lags of 1, 2, ... [`WHITENESS_LAGS`]
/// windows. For a series that is independent beyond q = window - 1 samples, Bartlett's formula
/// gives var(rho(L)) = (1 + 2 sum_{j=1..q} rho(j)^2) / n_L for L > q, and estimates at lags
/// more than q apart are uncorrelated; so the sum of rho^2 / var(rho) is chi-square with one
/// degree of freedom per lag.
pub fn whiteness(u: &[f64], index: &[usize], window: usize) -> Option<Whiteness> {
    let n = u.len();
    let span = index.last().map_or(0, |&l| l + 1);
    if n < 10 * window || window == 0 {
        return None;
    }
    let mut dense = vec![f64::NAN; span];
    for (&i, &v) in index.iter().zip(u) {
        dense[i] = v;
    }
    let variance = u.iter().map(|v| v * v).sum::<f64>() / n as f64;
    if variance <= 0.0 || !variance.is_finite() {
        return None;
    }
    // The near lags (up to one window) are estimated from a prefix of the rows, which bounds
    // the work at about window * 1e5 products however long the log.
    let rho_over = |lag: usize, rows: usize| -> Option<(f64, usize)> {
        let (mut sum, mut count) = (0.0, 0usize);
        for (&i, &a) in index.iter().zip(u).take(rows) {
            if let Some(&b) = dense.get(i + lag) {
                if b.is_finite() {
                    sum += a * b;
                    count += 1;
                }
            }
        }
        (count > 0).then(|| (sum / count as f64 / variance, count))
    };
    let rho = |lag: usize| rho_over(lag, n);
    let q = window - 1;
    let near: f64 = (1..=q)
        .filter_map(|lag| rho_over(lag, 100_000))
        .map(|(r, _)| r * r)
        .sum();
    let mut statistic = 0.0;
    let mut lags = 0;
    for k in 1..=WHITENESS_LAGS {
        let Some((r, count)) = rho(k * window) else {
            break;
        };
        if count < 5 * window {
            break;
        }
        statistic += r * r * count as f64 / (1.0 + 2.0 * near);
        lags += 1;
    }
    if lags == 0 {
        return None;
    }
    use statrs::distribution::{ChiSquared, ContinuousCDF};
    let p_value = ChiSquared::new(lags as f64)
        .map(|d| d.sf(statistic))
        .unwrap_or(f64::NAN);
    Some(Whiteness {
        statistic,
        lags,
        lag_spacing_samples: window,
        p_value,
    })
}
