//! The Savitzky-Golay window of identification, chosen from the data by the balancing
//! principle ([`choose_window`]), and the filter's remaining bias added to the reported
//! variances.

use rayon::prelude::*;
use serde::Serialize;

use super::adequacy::FitStatus;
use super::identify::{
    fit, fit_model, quantisation_shares, Estimates, Identification, IdentifyError, Inertia,
    LoadFriction, Param, SensorNoise,
};
use super::log::CalibrationLog;
use super::quantisation::Quantisation;
use super::sg::{self, Differentiator};

/// Shortest window tried by [`choose_window`] (s).
pub const SHORTEST_WINDOW_S: f64 = 0.1;

/// Fewest samples in a window tried by [`choose_window`]: the quintic kernels fitted to half
/// the window's offsets are poorly conditioned on fewer.
pub const SHORTEST_WINDOW_SAMPLES: usize = 15;

/// Longest window tried by [`choose_window`] (s).
pub const LONGEST_WINDOW_S: f64 = 6.4;

/// Ratio between neighbouring windows tried by [`choose_window`].
pub const WINDOW_RATIO: f64 = std::f64::consts::SQRT_2;

/// How many combined standard deviations two windows' estimates may differ by before
/// [`choose_window`] takes the longer one as distorted.
pub const BALANCING_SIGMAS: f64 = 3.0;

/// Smallest share of signal in the information of m, d1 and d2 (`signal_share`) at which a
/// window is compared by [`choose_window`] (lowered to half the best share of a log on which no
/// window reaches it). Below it the errors-in-variables correction removes more than three
/// quarters of a parameter's information, and the fit's standard deviations understate its
/// error: on a kilohertz log averaged to 100 Hz, the shortest window (share 0.03) put m, F0
/// and mu 3 of their standard deviations off, and the balancing principle, trusting it, kept it.
pub const MIN_SIGNAL_SHARE: f64 = 0.25;

/// The least signal share, as a fraction of the one windows are compared at
/// ([`MIN_SIGNAL_SHARE`]), of a shorter window whose fit shows that the shortest admissible
/// one distorts ([`choose_window`], step 4). On the independent rig's Table I trapezoids
/// (d0 3.8 N, m 0.39) the 0.43 s window's share is 0.23 to 0.26 from one noise to the next:
/// where it fell below 0.25, the choice went on to 0.61 s, whose reduced chi-square is 10 to
/// 15 % higher (the moves' corners), and k2 was 1.4 % low, at 1.3 of its deviations, on 17 of
/// 24 redraws of one motion.
pub const WITNESS_SHARE_RATIO: f64 = 0.5;

/// The filter's bias at the chosen window, per change of the estimate from the next shorter
/// window: 1 / (1 - 2^(-p/2)) for a bias growing as the window to the power p, with p = 2.
/// Counting the change once left m on the heavy acceptance rows' sines up to 4.9 standard
/// deviations off (docs/CALIBRATION.md).
pub const BIAS_PER_CHANGE: f64 = 2.0;

/// The filter's bias at the chosen window, per change of the estimate to the next longer
/// window: 1 / (2^(p/2) - 1) for a bias growing as the window to the power p, with p = 2.
pub const BIAS_PER_LONGER_CHANGE: f64 = 1.0;

/// The most filter's bias the longer window's change is taken to show at the chosen window,
/// in the chosen window's standard deviations. The longer window is the first the balancing
/// principle turned down, often where the distortion starts to rise steeply (a power of the
/// window far above 2), and its change then overstates the chosen window's bias: on the
/// simulator's own sines (120 s, 16 seeds, chosen at 1.21 s) mu, F0 and k2 agree from 0.43 to
/// 1.21 s and drop at 1.71 s, and the uncapped allowance made their deviations 2.7 times the
/// fit's, their z spread over the seeds 0.39. The balancing principle stops about where the
/// bias reaches the noise; over the independent rig's sweep draws a cap of 1.5 gave an rms z
/// of 1.00 (0.93 uncapped, 1.03 at 1.25) with as few estimates beyond 3 as uncapped.
pub const LONGER_BIAS_MAX_SIGMAS: f64 = 1.5;

/// How many standard deviations of the reduced chi-square a longer window's may exceed a
/// shorter one's by before [`choose_window`] takes the longer one as distorted.
pub const CHI2_RISE_SIGMAS: f64 = 4.0;

/// The least relative rise of the reduced chi-square that [`choose_window`] takes as a
/// distortion. Between windows that do not distort, the reduced chi-square moves by up to
/// about 5 % (the acceptance matrix's ramp-holds; at a 2 % floor the choice fell on needlessly
/// short windows and the filter's k2 lost precision); the corners of the independent rig's
/// moves raised it by 10 to 30 %.
pub const CHI2_RISE_MIN: f64 = 0.07;

/// How the Savitzky-Golay window was chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum WindowMethod {
    /// Given by the user (`--window`).
    Given,
    /// Chosen from the data by the balancing principle ([`choose_window`]).
    Balancing,
}

/// One window tried by [`choose_window`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WindowCandidate {
    /// Window (s).
    pub window_s: f64,
    /// Window (samples).
    pub window_samples: usize,
    /// The fit's k2 (1/mm), when it succeeded.
    pub k2_per_mm: Option<f64>,
    /// The fit's estimates with their standard deviations at this window alone (before the
    /// chosen window's filter-bias allowance), when it succeeded.
    pub parameters: Option<Estimates>,
    /// Reduced chi-square of the fit.
    pub reduced_chi2: Option<f64>,
    /// Share of the noisy parameters' information that is signal (`signal_share`).
    pub signal_share: Option<f64>,
    /// Parameters that this window could not identify.
    pub not_identifiable: Vec<String>,
    /// Whether the window identifies as many parameters as the best one (only those are
    /// compared).
    pub admissible: bool,
    /// Why the fit failed, if it did.
    pub error: Option<String>,
}

/// The window choice, with every candidate tried.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WindowChoice {
    /// How the window was chosen.
    pub method: WindowMethod,
    /// Every window tried (empty when given).
    pub candidates: Vec<WindowCandidate>,
}

/// The windows (samples, odd) that [`choose_window`] tries for a log of `n` samples every `dt`.
pub fn candidate_windows(n: usize, dt: f64) -> Vec<usize> {
    let longest = (LONGEST_WINDOW_S / dt).min(n as f64 / 4.0);
    let mut out: Vec<usize> = Vec::new();
    let mut w = (SHORTEST_WINDOW_S / dt).max(SHORTEST_WINDOW_SAMPLES as f64);
    while w <= longest {
        let k = (w.round() as usize) | 1;
        if out.last() != Some(&k) {
            out.push(k);
        }
        w *= WINDOW_RATIO;
    }
    out
}

/// Chooses the Savitzky-Golay window from the data by the balancing principle (Lepski's
/// method) and returns the identification at that window.
///
/// A short window passes much position noise into the velocity and acceleration, so the
/// estimates are unbiased (the errors-in-variables correction) but noisy; a long one lowers the
/// noise but distorts the motion, which biases them. The fit is made at windows from
/// [`SHORTEST_WINDOW_S`] to [`LONGEST_WINDOW_S`] (ratio [`WINDOW_RATIO`]). Compared are, in
/// turn: the windows whose fit explains the log ([`super::adequacy::Adequacy`]; all, if none
/// does); of those, the ones where m's, d1's and d2's information is at least
/// [`MIN_SIGNAL_SHARE`] signal (a window where m's is less is fitted again without m); of
/// those, the ones that identify as many parameters as the best, and at which at least a
/// quarter as many samples move: leaving out a force the log carries, or most of the motion
/// (transients left out at a long window), biases the rest; samples the velocity's noise band
/// hides at a short window are left out without bias. A shorter window whose share is below
/// the threshold but at least [`WITNESS_SHARE_RATIO`] of it, and that fits the same
/// parameters, is compared too when the shortest of those windows fits clearly worse than it
/// (its reduced chi-square higher by at least [`CHI2_RISE_MIN`]): the nearest one then leads.
/// Among the others, in order of length, the chosen window is the longest whose every
/// estimate agrees with the estimate of every shorter window within [`BALANCING_SIGMAS`]
/// standard deviations of their difference, taken as sqrt(s_short^2 - s_long^2) (at least
/// half of s_short): the longer window's estimate is the more precise, and the difference of
/// two estimates of the same quantity has about that spread.
pub fn choose_window(
    log: &CalibrationLog,
    noise: &SensorNoise,
    load_friction: LoadFriction,
) -> Result<Identification, IdentifyError> {
    let dt = log.dt_s();
    let windows = candidate_windows(log.len(), dt);
    if windows.is_empty() {
        // Too short a log for the shortest window: the fixed-window fit says why.
        return fit(
            log,
            noise,
            &Differentiator::new(sg::MIN_WINDOW),
            load_friction,
        );
    }
    // The fits are independent: one per core.
    let fits: Vec<Result<Identification, IdentifyError>> = windows
        .par_iter()
        .map(|&w| fit_with_noise_uncertainty(log, noise, &Differentiator::new(w), load_friction))
        .collect();
    // The windows compared are chosen in three steps, each among the windows the one before
    // left:
    // 1. A window whose fit explains the log is preferred to one that does not, even if that
    //    keeps more parameters (at a long window, unresolved transients can no longer be left
    //    out, and the fit that keeps m then misplaces its force). Unless no window fits.
    // 2. The errors-in-variables correction is a first-order one: at a window where the noise
    //    of the filtered acceleration or velocity makes up most of a parameter's information,
    //    it leaves a bias that the fit's standard deviations do not show. Such windows are not
    //    compared; a parameter is rather given up at a shorter window (the threshold is
    //    lowered for a log on which no window reaches it).
    // 3. The windows that keep the most parameters, and of those the ones that move at least
    //    a quarter as many samples as the most (transients left out at a long window cost
    //    many). The velocity's noise band hides slow motion at short windows; the samples it
    //    hides are chosen by a kernel whose noise the regressors do not share, so leaving them
    //    out costs precision, not bias. At half (until 2026-11-26) a noisy light trapezoid log
    //    compared only windows from 1.7 s, which round the moves' corners: m at z +3.5.
    let ok = || fits.iter().filter_map(|f| f.as_ref().ok());
    let fits_somewhere = ok().any(|id| id.adequacy.status == FitStatus::Fits);
    let explains = |id: &Identification| !fits_somewhere || id.adequacy.status == FitStatus::Fits;
    let best_share = ok()
        .filter(|id| explains(id))
        .map(|id| id.signal_share)
        .fold(0.0_f64, f64::max);
    let min_share = MIN_SIGNAL_SHARE.min(0.5 * best_share);
    // The fit at window i without m, taken where it explains the log.
    let without_m = |i: usize| {
        let diff = Differentiator::new(windows[i]);
        fit_inertia_with_noise_uncertainty(log, noise, &diff, Inertia::LeftOut, load_friction)
    };
    let mut fits = fits;
    let give_up_m = |fits: &mut [Result<Identification, IdentifyError>], i, refit| {
        if matches!(&refit, Ok(id) if explains(id)) {
            fits[i] = refit;
        }
    };
    // Where m's information is mostly noise, the window is fitted again without it: the other
    // parameters are then compared at that window, and m is given up there instead.
    let refits: Vec<(usize, Result<Identification, IdentifyError>)> = (0..fits.len())
        .into_par_iter()
        .filter_map(|i| {
            let id = fits[i].as_ref().ok()?;
            (explains(id) && id.signal_share < min_share && id.get(Param::M).value.is_some())
                .then(|| (i, without_m(i)))
        })
        .collect();
    for (i, refit) in refits {
        give_up_m(&mut fits, i, refit);
    }
    // Where one window alone keeps m among those that explain the log, and a shorter and a
    // longer one both give it up, m is given up there too: the windows about it lost m's
    // signal with the transients they left out, and this one missed them and read their
    // force as inertia. (2026-11-28: on five servo logs of the independent rig's random sweep,
    // 200 Hz to 1 kHz, the only window that kept m had it 3.1 to 4.7 standard deviations
    // high, 16 and 27 % on two; and on a force-controlled rod that slips through the stroke
    // in short jumps, draw 253.)
    if let Some(i) = lone_inertia(&fits, &explains) {
        give_up_m(&mut fits, i, without_m(i));
    }
    let ok = || fits.iter().filter_map(|f| f.as_ref().ok());
    let resolved = |id: &Identification| explains(id) && id.signal_share >= min_share;
    let fewest_missing = ok()
        .filter(|id| resolved(id))
        .map(|id| id.not_identifiable.len())
        .min();
    let Some(fewest_missing) = fewest_missing else {
        // Every window failed: report the failure at the shortest one.
        return fits.into_iter().next().unwrap_or_else(|| {
            fit(
                log,
                noise,
                &Differentiator::new(sg::MIN_WINDOW),
                load_friction,
            )
        });
    };
    let most_moving = ok()
        .filter(|id| resolved(id) && id.not_identifiable.len() == fewest_missing)
        .map(|id| id.dynamic_samples)
        .max()
        .unwrap_or(0);
    let admissible: Vec<usize> = (0..fits.len())
        .filter(|&i| {
            fits[i].as_ref().is_ok_and(|id| {
                resolved(id)
                    && id.not_identifiable.len() == fewest_missing
                    && 4 * id.dynamic_samples >= most_moving
            })
        })
        .collect();
    if admissible.is_empty() {
        return Err(IdentifyError::NoConvergence(
            "no window was admissible".into(),
        ));
    }
    // 4. A window whose signal share is just short of the threshold still shows, by its
    //    reduced chi-square, whether the shortest admissible window distorts. Where that one
    //    fits the same parameters clearly worse, the nearest such shorter window is put
    //    first, and the balancing starts from it.
    let mut admissible = admissible;
    let first = admissible[0];
    if let Ok(long) = &fits[first] {
        let witness = (0..first).rev().find(|&i| {
            fits[i].as_ref().is_ok_and(|short| {
                explains(short)
                    && short.signal_share >= WITNESS_SHARE_RATIO * min_share
                    && same_parameters(short, long)
                    && 4 * short.dynamic_samples >= most_moving
                    && distorted(short, long)
            })
        });
        if let Some(i) = witness {
            admissible.insert(0, i);
        }
    }
    let mut chosen = admissible[0];
    'longer: for (j, &long) in admissible.iter().enumerate().skip(1) {
        let Ok(b) = &fits[long] else { continue };
        for &short in &admissible[..j] {
            let Ok(a) = &fits[short] else { continue };
            if !agree(a, b) || distorted(a, b) {
                break 'longer;
            }
        }
        chosen = long;
    }
    let candidates = windows
        .iter()
        .zip(&fits)
        .enumerate()
        .map(|(i, (&w, f))| WindowCandidate {
            window_s: w as f64 * dt,
            window_samples: w,
            k2_per_mm: f.as_ref().ok().and_then(|id| id.get(Param::K2).value),
            parameters: f.as_ref().ok().map(|id| id.parameters),
            reduced_chi2: f.as_ref().ok().map(|id| id.reduced_chi2),
            signal_share: f.as_ref().ok().map(|id| id.signal_share),
            not_identifiable: f
                .as_ref()
                .map(|id| id.not_identifiable.clone())
                .unwrap_or_default(),
            admissible: admissible.contains(&i),
            error: f.as_ref().err().map(|e| e.to_string()),
        })
        .collect();
    // The next shorter and the next longer admissible windows, whose estimates bound the
    // filter's bias at the chosen one.
    let estimates = |i: usize| fits[i].as_ref().ok().map(|id| id.parameters);
    let shorter = admissible
        .iter()
        .rev()
        .find(|&&i| i < chosen)
        .and_then(|&i| estimates(i));
    let longer = admissible
        .iter()
        .find(|&&i| i > chosen)
        .and_then(|&i| estimates(i));
    let mut id = fits
        .into_iter()
        .nth(chosen)
        .and_then(Result::ok)
        .ok_or_else(|| IdentifyError::NoConvergence("no window was chosen".into()))?;
    add_filter_bias(&mut id, shorter.as_ref(), longer.as_ref());
    id.window_choice = WindowChoice {
        method: WindowMethod::Balancing,
        candidates,
    };
    Ok(id)
}

/// The window that alone keeps m among the fits that `explain` the log, where a shorter and a
/// longer one that explain it both give m up ([`choose_window`]).
fn lone_inertia(
    fits: &[Result<Identification, IdentifyError>],
    explains: &dyn Fn(&Identification) -> bool,
) -> Option<usize> {
    let explaining = |i: usize| fits[i].as_ref().ok().filter(|id| explains(id));
    let keeps_m = |id: &Identification| id.get(Param::M).value.is_some();
    let mut keeping = (0..fits.len()).filter(|&i| explaining(i).is_some_and(keeps_m));
    let i = keeping.next()?;
    if keeping.next().is_some() {
        return None;
    }
    let gives_up = |j: usize| explaining(j).is_some_and(|id| !keeps_m(id));
    ((0..i).any(gives_up) && (i + 1..fits.len()).any(gives_up)).then_some(i)
}

/// Adds an estimate of the filter's bias to the chosen window's variances.
///
/// The distortion of a Savitzky-Golay filter grows as a power p of its window, so the bias at
/// the chosen window shows in the change to the next admissible window, a factor sqrt(2)
/// longer or shorter. For p = 2 the change to the longer one is the bias itself
/// ([`BIAS_PER_LONGER_CHANGE`]) and the change from the shorter one half of it
/// ([`BIAS_PER_CHANGE`]). The change also carries noise, of variance about the difference of
/// the two windows' variances; what the bias's square exceeds it by is counted as systematic
/// and added to the parameter's variance (`filter_bias_std`). The longer window is the
/// witness where there is one: a longer window's estimates are the less noisy, so its change
/// shows the bias where the shorter one's noise hides it. With the shorter window alone, the
/// allowance on the independent rig's force-controlled sweep draw 338 was nothing on 5 of 24
/// redraws of the noise and up to 14 times k2's deviation on others, while the bias, the same
/// on all, was 1.2 deviations (k2 at z -4.6 on one redraw). Over the rig's sweep draws 0 to
/// 269 and five later ones, estimates beyond 3 of their deviations went from 19 to 10 of
/// 1 784 and beyond 4 from 7 to 1, the rms z staying 1.00, with the longer window's
/// allowance at most [`LONGER_BIAS_MAX_SIGMAS`] (docs/CALIBRATION.md, "The filter's bias
/// from the longer window"). m keeps the shorter witness: its change to a longer window holds
/// that window's greater loss of acceleration gain, which
/// [`super::identify::correct_inertia`] takes out of the chosen one alone; with the longer
/// witness, capped as for the others, m's estimates beyond 3 deviations on the sweep went from
/// 2 to 4. Where no shorter admissible window keeps m, its witness is the longer one (capped):
/// with none, sweep draws 358 and 471 had m at z -3.5 and +3.3 with no allowance at all; over
/// 1 805 estimates of draws 0 to 269 and later ones, m's beyond 3 went from 3 to 1 and its rms
/// z from 0.99 to 0.89. On a log the filter follows, the allowance is zero on average.
fn add_filter_bias(
    id: &mut Identification,
    shorter: Option<&Estimates>,
    longer: Option<&Estimates>,
) {
    let names = id.covariance_parameters.clone();
    for p in Param::ALL {
        let b = id.get(p);
        let (Some(vb), Some(sb)) = (b.value, b.std) else {
            continue;
        };
        // The change's noise: the difference of the two windows' variances (nested fits), as
        // it stands for the shorter window and either way round for the longer.
        let witness = |w: Option<&Estimates>, per_change: f64, is_longer: bool| {
            let a = w?.get(p);
            let (va, sa) = (a.value?, a.std?);
            let noise = if is_longer {
                (sa * sa - sb * sb).abs()
            } else {
                (sa * sa - sb * sb).max(0.0)
            };
            let systematic = ((per_change * (va - vb)).powi(2) - noise).max(0.0);
            Some(if is_longer {
                systematic.min((LONGER_BIAS_MAX_SIGMAS * sb).powi(2))
            } else {
                systematic
            })
        };
        let from_longer = || witness(longer, BIAS_PER_LONGER_CHANGE, true);
        let from_shorter = || witness(shorter, BIAS_PER_CHANGE, false);
        let systematic = if p == Param::M {
            from_shorter().or_else(from_longer)
        } else {
            from_longer().or_else(from_shorter)
        };
        let Some(systematic) = systematic else {
            continue;
        };
        if systematic == 0.0 {
            continue;
        }
        id.filter_bias_std[p.index()] = systematic.sqrt();
        add_systematic(id, &names, p, sb, systematic);
    }
}

/// Adds a systematic variance to parameter `p`'s (standard deviation `std` before) and to
/// the covariance's diagonal.
fn add_systematic(id: &mut Identification, names: &[String], p: Param, std: f64, variance: f64) {
    id.parameters.set_std(p, (std * std + variance).sqrt());
    if let Some(k) = names.iter().position(|n| n == p.key()) {
        id.covariance[k][k] += variance;
    }
}

/// The relative standard deviation of the position noise's variance above which
/// identification carries it into its estimates ([`fit_with_noise_uncertainty`]). The noise
/// read from 30 000 samples of a log is known to about 1.2 %, which moves the estimates by a
/// small part of their spread; a quantised encoder's, to 30 % and more.
pub const NOISE_UNCERTAINTY_MIN: f64 = 0.03;

/// The fit at one window, with the position noise's uncertainty carried into the standard
/// deviations.
///
/// The errors-in-variables correction subtracts the noise the kernels pass into the velocity
/// and acceleration, in proportion to the stated position variance: a variance off by a
/// fraction e moves the information on m by e (1 - s) / s of its signal part, where s is the
/// signal share. Where the variance's relative standard deviation exceeds
/// [`NOISE_UNCERTAINTY_MIN`], the fit is made again with the variance raised by one standard
/// deviation, and each parameter's change is added to its variance as a systematic error
/// (`noise_std`). Windows where the correction is large then lose precision, and the window
/// choice moves to where the noise matters less.
pub fn fit_with_noise_uncertainty(
    log: &CalibrationLog,
    noise: &SensorNoise,
    diff: &Differentiator,
    load_friction: LoadFriction,
) -> Result<Identification, IdentifyError> {
    fit_inertia_with_noise_uncertainty(log, noise, diff, Inertia::Fitted, load_friction)
}

/// [`fit_with_noise_uncertainty`] with or without the inertia.
fn fit_inertia_with_noise_uncertainty(
    log: &CalibrationLog,
    noise: &SensorNoise,
    diff: &Differentiator,
    inertia: Inertia,
    load_friction: LoadFriction,
) -> Result<Identification, IdentifyError> {
    // A quantised position's kernel shares depend on the window and the log alone: worked
    // out once for every fit at this window.
    let with_shares;
    let noise = match noise.position_quantisation {
        Some(q) if q.kernel_shares.is_none() => {
            with_shares = SensorNoise {
                position_quantisation: Some(Quantisation {
                    kernel_shares: Some(quantisation_shares(log, diff, q)),
                    ..q
                }),
                ..*noise
            };
            &with_shares
        }
        _ => noise,
    };
    let mut id = fit_model(log, noise, diff, inertia, load_friction)?;
    let rel = noise.position_variance_relative_std;
    if rel > NOISE_UNCERTAINTY_MIN {
        let raised = noise.position_scaled(1.0 + rel);
        // The same model as the fit's: the friction that grows with the load is in both or
        // in neither.
        if let Ok(other) = fit_model(log, &raised, diff, inertia, id.load_friction()) {
            add_noise_uncertainty(&mut id, &other.parameters);
            id.reduced_chi2_noise_change = other.reduced_chi2 - id.reduced_chi2;
        }
    }
    Ok(id)
}

/// Adds each parameter's change under the raised noise to its variance (see
/// [`fit_with_noise_uncertainty`]). A parameter the raised noise leaves unidentifiable (its
/// noise-corrected information no longer positive) is then indistinguishable from zero: its
/// change is its whole value. (On an S-curve log read in 15.6 um steps at 100 Hz, m at a
/// 0.31 s window was 0.0088 +- 0.0010 against a true 0.0030, and dropped at the noise's
/// upper bound; the window choice took that window for its precision.)
fn add_noise_uncertainty(id: &mut Identification, raised: &Estimates) {
    let names = id.covariance_parameters.clone();
    for p in Param::ALL {
        let (Some(v), Some(s)) = (id.get(p).value, id.get(p).std) else {
            continue;
        };
        let r = raised.get(p).value.unwrap_or(0.0);
        let change = (r - v).abs();
        if !change.is_finite() || change == 0.0 {
            continue;
        }
        id.noise_std[p.index()] = change;
        add_systematic(id, &names, p, s, change * change);
    }
}

/// Whether the longer window's fit explains the log worse than the shorter one's: its reduced
/// chi-square is higher by more than [`CHI2_RISE_SIGMAS`] of the statistic's standard
/// deviation sqrt(2 / dof) (relative, at least [`CHI2_RISE_MIN`]).
///
/// A filter that rounds the motion's corners (a motion controller's steps in acceleration)
/// leaves a force the model cannot fit, long before the estimates move by their shorter
/// windows' spread: the inertia's precision grows about as the window cubed, so a bias far
/// inside the shorter window's spread can be many of the longer window's standard
/// deviations. On a jerk-limited log of the paper's Table I, m at 0.85 s was 4.4 standard
/// deviations high and within a third of one of the 0.61 s window's, while the reduced
/// chi-square rose from 1.03 to 1.35 (26 of its standard deviations).
///
/// Where the position noise is uncertain ([`fit_with_noise_uncertainty`]), the reduced
/// chi-squares move with it, a short window's (more of whose residual is position noise)
/// more than a long one's: the rise may then also be twice the difference of their changes
/// under the raised noise. On a Table I trapezoid read in 20 um steps the rise from 0.15 to
/// 0.21 s (1.20 to 1.33) vanished at the top of the noise's range (0.96 to 0.99).
///
/// The reduced chi-squares compared are those before unresolved transients were left out
/// ([`Identification::reduced_chi2_with_transients`]): a window that needs transients left
/// out to fit does not follow the whole motion, and a longer one leaves out more. (Compared
/// after, a slow ramp-hold's wrong friction signs at reversals, left out at 3.4 s, let the
/// choice go on to 4.8 s, where k2's deviation is about 1.3 times too small.)
fn distorted(short: &Identification, long: &Identification) -> bool {
    let rise = chi2_rise_tolerance(long.dynamic_samples);
    let noise = 2.0 * (long.reduced_chi2_noise_change - short.reduced_chi2_noise_change).abs();
    long.reduced_chi2_with_transients > short.reduced_chi2_with_transients * (1.0 + rise) + noise
}

/// The relative rise of a reduced chi-square over `rows` rows beyond which a fit explains them
/// clearly worse: [`CHI2_RISE_SIGMAS`] of the statistic's standard deviation sqrt(2 / rows), and
/// at least [`CHI2_RISE_MIN`].
pub fn chi2_rise_tolerance(rows: usize) -> f64 {
    (CHI2_RISE_SIGMAS * (2.0 / rows.max(1) as f64).sqrt()).max(CHI2_RISE_MIN)
}

/// Whether two fits identify the same parameters.
fn same_parameters(a: &Identification, b: &Identification) -> bool {
    let mut x = a.not_identifiable.clone();
    let mut y = b.not_identifiable.clone();
    x.sort();
    y.sort();
    x == y
}

/// Whether every parameter that both fits identify agrees within [`BALANCING_SIGMAS`]
/// standard deviations of the difference (`short` at the shorter window).
fn agree(short: &Identification, long: &Identification) -> bool {
    Param::ALL.into_iter().all(|p| {
        let (a, b) = (short.get(p), long.get(p));
        match (a.value, a.std, b.value, b.std) {
            (Some(va), Some(sa), Some(vb), Some(sb)) => {
                let spread = (sa * sa - sb * sb).max(0.25 * sa * sa).sqrt();
                (va - vb).abs() <= BALANCING_SIGMAS * spread
            }
            _ => true,
        }
    })
}
