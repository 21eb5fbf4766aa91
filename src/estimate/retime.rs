//! Re-timing the force channel of a log whose load cell is read at another instant than its
//! encoder: channels scanned one after the other, or a converter's filter delay.
//!
//! A force read `delay` late (the reading at time t is the force at t - `delay`) is brought
//! back to its position's instant: the force at row k becomes the force read at the
//! fractional row k + `delay`/dt. A whole number of rows is an exact re-pairing of the
//! readings; a fraction of a row is a band-limited interpolation by a Kaiser-windowed sinc of
//! [`KERNEL_TAPS`] taps (flat within 1 % up to 0.78 of the Nyquist frequency, far above any
//! motion a spring rig makes). The rows at the log's ends that lack a partner are left out.
//! The interpolation passes white force noise with the variance factor
//! [`RowDelay::noise_variance_factor`] (0.86 half-way between rows, 1 on a row), which
//! identification weights with.

use std::borrow::Cow;
use std::collections::VecDeque;

use serde::Serialize;

use super::identify::{
    identify_reduced, identify_reduced_with, Identification, IdentifyError, LoadFriction,
    ReducedLog, SensorNoise,
};
use super::log::{CalibrationLog, LogError, Sample};
use super::window::WINDOW_RATIO;

/// How the force channel's delay behind the position is set.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum ForceDelay {
    /// Read together (as logged).
    #[default]
    None,
    /// Given (s; positive when the force is read late).
    Seconds(f64),
    /// Fitted by identification ([`fit_force_delay`]).
    Auto,
    /// Already taken out of the log by the caller (re-timed in memory): nothing is applied
    /// again, fitted or screened for ([`screen_force_delay`]).
    Applied,
}

impl ForceDelay {
    /// The delay to apply: none, as given, or what `fit` finds ([`fit_force_delay`], called
    /// only for [`ForceDelay::Auto`]); none for one already applied.
    pub fn resolve(
        self,
        fit: impl FnOnce() -> Result<ForceDelayFit, IdentifyError>,
    ) -> Result<Option<ForceDelayFit>, IdentifyError> {
        Ok(match self {
            ForceDelay::None | ForceDelay::Applied => None,
            ForceDelay::Seconds(s) => Some(ForceDelayFit::given(s)),
            ForceDelay::Auto => Some(fit()?),
        })
    }

    /// Whether a log read with this setting is screened for a delay ([`screen_force_delay`]):
    /// only where none was asked for.
    pub fn screened(self) -> bool {
        self == ForceDelay::None
    }
}

/// One delay the profile of [`fit_force_delay`] tried.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DelayTrial {
    /// The delay tried (s).
    pub delay_s: f64,
    /// Identification's reduced chi-square with it (None where identification failed).
    pub reduced_chi2: Option<f64>,
}

/// The force channel's delay behind the position, as applied.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ForceDelayFit {
    /// The delay (s; positive when the force is read late).
    pub delay_s: f64,
    /// Its standard deviation (s) where it was fitted.
    pub std_s: Option<f64>,
    /// Whether it was fitted (else given).
    pub fitted: bool,
    /// The filter window (s) the profile held fixed, where fitted.
    pub window_s: Option<f64>,
    /// Half the difference (s) between the delays the profile finds at the held window and
    /// at the next longer one, where fitted and that profile curves upward: the filter's
    /// share, included in `std_s` in quadrature.
    pub window_spread_s: Option<f64>,
    /// The delays the profile tried, in the order tried.
    pub trials: Vec<DelayTrial>,
    /// What the delay's standard deviation adds to each identified parameter's, already
    /// included in identification's standard deviations (by parameter key; empty where the
    /// delay was given, or where it was not carried).
    pub parameter_std: std::collections::BTreeMap<&'static str, f64>,
}

impl ForceDelayFit {
    /// A delay as given.
    pub fn given(delay_s: f64) -> ForceDelayFit {
        ForceDelayFit {
            delay_s,
            std_s: None,
            fitted: false,
            window_s: None,
            window_spread_s: None,
            trials: Vec::new(),
            parameter_std: Default::default(),
        }
    }
}

/// How far (s) either side of zero [`fit_force_delay`] searches.
pub const SEARCH_S: f64 = 0.25;

/// The standard deviation (rows) of the fraction of a row the parabola gives: a uniform error
/// over a row, 1/sqrt(12).
pub const ROW_RESOLUTION: f64 = 0.288_675_134_594_812_9;

/// The most rows of identification's samples (block means at 100 to 200 Hz) the delay's
/// profile is taken over: 20 minutes at 100 Hz.
pub const PROFILE_ROWS: usize = 120_000;

/// The fewest filter windows a log must span for its delay to be fitted.
pub const MIN_PROFILE_WINDOWS: f64 = 10.0;

/// The fewest times the searched rows either side a log must span for its delay to be fitted.
pub const MIN_PROFILE_SEARCHES: i64 = 40;

/// A fitted delay's standard deviation (s) beyond which the log is said not to determine it.
pub const UNDETERMINED_STD_S: f64 = 0.05;

/// Rows either side of the best whole row that the profile's parabola is fitted to.
pub const LOCAL_ROWS: i64 = 3;

/// A least-squares parabola a + b u + c u^2 through a profile's points (u in rows from the
/// best row).
#[derive(Debug, Clone, Copy)]
struct Parabola {
    /// Where it is least (rows from the best row).
    vertex: f64,
    /// Its value there.
    least: f64,
    /// c, half its second derivative (per row^2).
    curvature: f64,
    /// The vertex's standard deviation from the points' scatter about the parabola (rows).
    vertex_std: f64,
}

/// The least-squares parabola through `points`; None without an upward curvature (a profile
/// that does not determine its least value).
fn local_parabola(points: &[(f64, f64)]) -> Option<Parabola> {
    use nalgebra::{Matrix3, Vector3};
    if points.len() < 4 {
        return None;
    }
    let (mut ata, mut aty) = (Matrix3::<f64>::zeros(), Vector3::<f64>::zeros());
    for &(u, f) in points {
        let row = Vector3::new(1.0, u, u * u);
        ata += row * row.transpose();
        aty += row * f;
    }
    let inv = ata.try_inverse()?;
    let p = inv * aty;
    let (a, b, c) = (p[0], p[1], p[2]);
    if c.is_nan() || c <= 0.0 || !c.is_finite() {
        return None;
    }
    let rss: f64 = points
        .iter()
        .map(|&(u, f)| (f - a - b * u - c * u * u).powi(2))
        .sum();
    let s2 = rss / (points.len() - 3) as f64;
    let vertex = -b / (2.0 * c);
    // The delta method: d vertex / d(b, c) = (-1 / 2c, b / 2c^2).
    let g = Vector3::new(0.0, -1.0 / (2.0 * c), b / (2.0 * c * c));
    let vertex_var = s2 * (g.transpose() * inv * g)[0];
    Some(Parabola {
        vertex,
        least: a + b * vertex + c * vertex * vertex,
        curvature: c,
        vertex_std: vertex_var.max(0.0).sqrt(),
    })
}

/// The standard deviation (rows) of a profile's least value: the profile's own, where the
/// total chi-square (`at`'s moving samples times the reduced one, `at` identified at the best
/// row) rises by the fit's reduced chi-square (at least 1), its variance scaled by
/// [`correlation_inflation`]; the vertex's from the points' scatter about the parabola; and
/// [`ROW_RESOLUTION`] of a row; all in quadrature. None without moving samples.
fn vertex_std_rows(fit: &Parabola, at: &RowFit) -> Option<f64> {
    if at.dof <= 0.0 {
        return None;
    }
    let profile = (fit.least.max(1.0) * at.inflation / (fit.curvature * at.dof)).sqrt();
    Some((profile.powi(2) + fit.vertex_std.powi(2) + ROW_RESOLUTION.powi(2)).sqrt())
}

/// Identification at one whole-row delay.
#[derive(Debug, Clone, Copy)]
struct RowFit {
    /// Its reduced chi-square.
    chi2: f64,
    /// Its moving samples.
    dof: f64,
    /// Its [`correlation_inflation`].
    inflation: f64,
}

/// Identification's reduced chi-square over whole-row delays of one log, the filter window
/// held: each an exact re-pairing of the readings.
struct DelayProfile<'a> {
    reduced: &'a ReducedLog,
    noise: &'a SensorNoise,
    dt: f64,
    window: f64,
    /// The model every delay is fitted with: the log's own identification's, so that the
    /// delays are compared on one model (decided again at each delay, the friction that grows
    /// with the load would take up part of the delay where it helps and not elsewhere).
    load_friction: LoadFriction,
    /// The rows tried, in the order tried (None where identification failed).
    tried: Vec<(i64, Option<RowFit>)>,
}

impl<'a> DelayProfile<'a> {
    fn new(
        reduced: &'a ReducedLog,
        noise: &'a SensorNoise,
        window: f64,
        load_friction: LoadFriction,
    ) -> DelayProfile<'a> {
        DelayProfile {
            reduced,
            noise,
            dt: reduced.log.dt_s(),
            window,
            load_friction,
            tried: Vec::new(),
        }
    }

    /// Tries the whole-row delays `rows` (in parallel); the best of them and its reduced
    /// chi-square (infinite where none fits).
    fn scan(&mut self, rows: Vec<i64>) -> (i64, f64) {
        use rayon::prelude::*;
        let (reduced, noise, dt, window) = (self.reduced, self.noise, self.dt, self.window);
        let load_friction = self.load_friction;
        let found: Vec<(i64, Option<RowFit>)> = rows
            .into_par_iter()
            .map(|d| {
                let (log, timed) = retime_reduced(reduced, noise, d as f64 * dt);
                let fit = identify_reduced_with(&log, &timed, Some(window), load_friction)
                    .ok()
                    .filter(|id| id.reduced_chi2.is_finite())
                    .map(|id| RowFit {
                        chi2: id.reduced_chi2,
                        dof: id.dynamic_samples as f64,
                        inflation: correlation_inflation(&id),
                    });
                (d, fit)
            })
            .collect();
        let best = found
            .iter()
            .map(|(d, r)| (*d, r.map_or(f64::INFINITY, |r| r.chi2)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap_or((0, f64::INFINITY));
        self.tried.extend(found);
        best
    }

    /// The fit last tried at `row`.
    fn latest(&self, row: i64) -> Option<&RowFit> {
        self.tried
            .iter()
            .rev()
            .find(|(d, _)| *d == row)
            .and_then(|(_, f)| f.as_ref())
    }

    /// The fraction of a row: the least-squares parabola through the rows within
    /// [`LOCAL_ROWS`] of `best` (tried where not yet), re-centred once where its vertex lies
    /// beyond half a row of it and within `limit`. The row it is centred on and the
    /// parabola; None where a parabola does not curve upward.
    fn vertex(&mut self, mut best: i64, limit: i64) -> Option<(i64, Parabola)> {
        let mut vertex = None;
        for _ in 0..2 {
            let missing: Vec<i64> = (best - LOCAL_ROWS..=best + LOCAL_ROWS)
                .filter(|d| !self.tried.iter().any(|(t, _)| t == d))
                .collect();
            if !missing.is_empty() {
                self.scan(missing);
            }
            let points: Vec<(f64, f64)> = (best - LOCAL_ROWS..=best + LOCAL_ROWS)
                .filter_map(|d| self.latest(d).map(|f| ((d - best) as f64, f.chi2)))
                .collect();
            let fit = local_parabola(&points)?;
            let shifted = fit.vertex.round() as i64;
            vertex = Some((best, fit));
            if shifted == 0 || (best + shifted).abs() >= limit {
                break;
            }
            best += shifted;
        }
        vertex
    }

    /// The least near the row `centre`: the rows within [`LOCAL_ROWS`] of it tried, then the
    /// parabola around the best of them ([`DelayProfile::vertex`]). The row it is centred on,
    /// the parabola, and the least (rows, held within [`LOCAL_ROWS`] of that row).
    fn least_near(&mut self, centre: i64, limit: i64) -> Option<(i64, Parabola, f64)> {
        let (best, _) = self.scan((centre - LOCAL_ROWS..=centre + LOCAL_ROWS).collect());
        let (best, fit) = self.vertex(best, limit)?;
        let rows = best as f64 + fit.vertex.clamp(-(LOCAL_ROWS as f64), LOCAL_ROWS as f64);
        Some((best, fit, rows))
    }

    /// The delays tried, in order of delay.
    fn trials(&self) -> Vec<DelayTrial> {
        let mut trials: Vec<DelayTrial> = self
            .tried
            .iter()
            .map(|(d, f)| DelayTrial {
                delay_s: *d as f64 * self.dt,
                reduced_chi2: f.map(|f| f.chi2),
            })
            .collect();
        trials.sort_by(|a, b| a.delay_s.total_cmp(&b.delay_s));
        trials
    }
}

/// The fewest rows either side of zero [`fit_force_delay`] searches.
pub const SEARCH_ROWS_MIN: i64 = 5;

/// The rows either side of zero a delay is searched over at a window `window_s` and interval
/// `dt`, and the fewest rows a log must have for its delay to be profiled: on a log a few
/// windows long, re-pairing shifts a large share of it out at the ends, and the profile
/// follows that rather than the delay (a 4 s log put a 15 ms delay at 177 +- 36 ms).
fn profile_extent(window_s: f64, dt: f64) -> (i64, f64) {
    let limit = ((SEARCH_S / dt).ceil() as i64).max(SEARCH_ROWS_MIN);
    let min_rows = (MIN_PROFILE_WINDOWS * window_s / dt).max((MIN_PROFILE_SEARCHES * limit) as f64);
    (limit, min_rows)
}

/// The force channel's delay behind the position, fitted by identification: the delay
/// (in rows of `reduced`) that brings identification's reduced chi-square, with the filter
/// window held, to its least value.
///
/// 1. The window is the one chosen without a delay (or the given one), held fixed while
///    delays are compared: a window chosen anew for each delay hides part of it (the chooser
///    trades the delay's misfit against the filter's).
/// 2. Every whole-row delay within [`SEARCH_S`] (at least [`SEARCH_ROWS_MIN`] rows) either
///    way is tried, each an exact re-pairing of the readings; a least value at the search's
///    edge is an error.
/// 3. Where the window was chosen, it is chosen again on the log re-timed by the best whole
///    row (a log read with a large delay chooses a poor one), and the rows around the best
///    are tried again with it.
/// 4. The fraction of a row: the vertex of the least-squares parabola through the rows within
///    [`LOCAL_ROWS`] of the best (a profile can alternate between odd and even rows by more
///    than its curvature over a row; the parabola averages that). A parabola that does not
///    curve upward is an error: the log does not determine the delay. Interpolated delays
///    are not compared: the interpolation lowers the force noise between rows (by up to
///    14 %), which moves the reduced chi-square more than a fraction of a row of delay does
///    (on the independent rig's multisine at 100 Hz, a 10 ms delay profiled through
///    interpolated ones had its least chi-square half a row off).
/// 5. The standard deviation: the profile's, where the total chi-square rises by the fit's
///    reduced chi-square (at least 1), its variance scaled by [`correlation_inflation`]; the
///    vertex's own from the points' scatter about the parabola; [`ROW_RESOLUTION`] of a
///    row; and half the difference from the delay the same profile finds at the next longer
///    window (a delay in the log is the same through any filter, a least the model's misfit
///    puts there moves with it: [`screen_force_delay`]), all in quadrature. One beyond
///    [`UNDETERMINED_STD_S`] is an error too.
/// 6. The profile is taken over the first [`PROFILE_ROWS`] rows (the delay is the rig's), so
///    that its identifications are bounded on a day-long log. A log shorter than
///    [`MIN_PROFILE_WINDOWS`] windows or [`MIN_PROFILE_SEARCHES`] times the rows searched
///    either way is an error.
pub fn fit_force_delay(
    reduced: &ReducedLog,
    noise: &SensorNoise,
    window_s: Option<f64>,
) -> Result<ForceDelayFit, IdentifyError> {
    let profiled = profiled_rows(reduced);
    let reduced = &*profiled;
    let dt = reduced.log.dt_s();
    let first = identify_reduced(reduced, noise, window_s)?;
    let load_friction = first.load_friction();
    let mut window = window_s.unwrap_or(first.sg_window_s);
    let (limit, min_rows) = profile_extent(window, dt);
    if (reduced.log.len() as f64) < min_rows {
        return Err(IdentifyError::ForceDelayLogTooShort {
            log_s: reduced.log.len() as f64 * dt,
            min_s: min_rows * dt,
        });
    }
    let beyond = || IdentifyError::ForceDelayBeyondSearch {
        limit_s: limit as f64 * dt,
    };
    let mut profile = DelayProfile::new(reduced, noise, window, load_friction);
    let (mut best, least) = profile.scan((-limit..=limit).collect());
    if !least.is_finite() {
        // No delay gives a fit: identification's own error says why.
        identify_reduced_with(reduced, noise, Some(window), load_friction)?;
    }
    if best.abs() >= limit {
        return Err(beyond());
    }
    if window_s.is_none() && best != 0 {
        let (log, timed) = retime_reduced(reduced, noise, best as f64 * dt);
        let chosen = identify_reduced_with(&log, &timed, None, load_friction)?.sg_window_s;
        if (chosen - window).abs() > 0.5 * dt {
            window = chosen;
            profile = DelayProfile::new(reduced, noise, window, load_friction);
            let mut around = best;
            loop {
                let (b, _) = profile.scan((around - 2..=around + 2).collect());
                if (b - around).abs() < 2 {
                    best = b;
                    break;
                }
                around = b;
                if around.abs() >= limit {
                    return Err(beyond());
                }
            }
        }
    }
    let undetermined = IdentifyError::ForceDelayUndetermined { window_s: window };
    let (best, fit) = profile.vertex(best, limit).ok_or(undetermined.clone())?;
    let rows = best as f64 + fit.vertex.clamp(-(LOCAL_ROWS as f64), LOCAL_ROWS as f64);
    let std_rows = profile
        .latest(best)
        .and_then(|at| vertex_std_rows(&fit, at))
        .ok_or(undetermined)?;
    let spread_rows = window_spread_rows(reduced, noise, window, best, rows, limit, load_friction);
    let std_rows = std_rows.hypot(spread_rows.unwrap_or(0.0));
    if std_rows * dt > UNDETERMINED_STD_S {
        return Err(IdentifyError::ForceDelayUndetermined { window_s: window });
    }
    Ok(ForceDelayFit {
        delay_s: rows * dt,
        std_s: Some(std_rows * dt),
        fitted: true,
        window_s: Some(window),
        window_spread_s: spread_rows.map(|r| r * dt),
        trials: profile.trials(),
        parameter_std: Default::default(),
    })
}

/// Half the difference (rows) between the delay `rows` found at `window` around the row
/// `best` and the one the same profile finds at the next longer window ([`WINDOW_RATIO`]
/// times it): the filter's share of the delay, which a delay in the log does not have. None
/// where the longer window's profile does not curve upward.
fn window_spread_rows(
    reduced: &ReducedLog,
    noise: &SensorNoise,
    window: f64,
    best: i64,
    rows: f64,
    limit: i64,
    load_friction: LoadFriction,
) -> Option<f64> {
    let (_, _, at) = DelayProfile::new(reduced, noise, window * WINDOW_RATIO, load_friction)
        .least_near(best, limit)?;
    Some(0.5 * (at - rows).abs())
}

/// What identification's profile says about a force delay where none was asked for
/// ([`screen_force_delay`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ForceDelayScreen {
    /// The profile at identification's window.
    #[serde(flatten)]
    pub held: ScreenedDelay,
    /// The same profile at the next longer window ([`WINDOW_RATIO`] times the held one),
    /// taken where the delay at the held window is `significant` (None elsewhere, or where
    /// that profile does not curve upward).
    pub longer_window: Option<ScreenedDelay>,
    /// Half the difference (s) between the two windows' delays, where the longer one was
    /// taken: the filter's share of the delay, which a delay in the log does not have.
    pub window_spread_s: Option<f64>,
    /// Whether the delay is significant, with the same sign, at both windows, and beyond
    /// [`SCREEN_Z`] times the held window's standard deviation and `window_spread_s` in
    /// quadrature: the log looks read with its force late (or early), and
    /// `--force-delay auto` should be given.
    pub suspected: bool,
}

impl ForceDelayScreen {
    /// Whether the delay at the held window is significant but the longer window does not
    /// confirm it: the profile's least moves with the filter, which a delay in the log does
    /// not do.
    pub fn moves_with_window(&self) -> bool {
        self.held.significant && !self.suspected
    }

    /// The held window's delay's standard deviation (s) with the two windows' spread in
    /// quadrature (the held window's alone where the longer one was not taken).
    pub fn std_with_window_s(&self) -> f64 {
        self.held.std_s.hypot(self.window_spread_s.unwrap_or(0.0))
    }
}

/// The least of a delay profile at one held window ([`screen_force_delay`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ScreenedDelay {
    /// The least of the profile's parabola (s; positive when the force looks read late),
    /// held within [`LOCAL_ROWS`] rows of the row the parabola is centred on.
    pub delay_s: f64,
    /// Its standard deviation (s), as [`fit_force_delay`] gives it.
    pub std_s: f64,
    /// The delay over its standard deviation.
    pub z: f64,
    /// Whether the parabola's least lies beyond the rows screened (the delay is then at
    /// least that).
    pub beyond: bool,
    /// The filter window (s) held.
    pub window_s: f64,
    /// Whether the delay is beyond [`SCREEN_Z`] standard deviations and half a row from none.
    pub significant: bool,
}

/// How many standard deviations from zero a screened delay must lie to be suspected. On 69
/// lag-free logs of the independent rig's sweep (every profile, 100 Hz to 1 kHz, light to
/// heavy transmissions) the largest |z| was 2.73 and the RMS 0.99, on the acceptance
/// matrix's 72 at most 1.3; a 10 ms delay at 100 Hz on the rig's default transmission, which
/// put m at z -7 on one seed, gave 3.5 and 3.7.
pub const SCREEN_Z: f64 = 3.0;

/// Screens a log identified as logged (`id`, on `reduced`) for a force read at another
/// instant than the position. A delay is absorbed by the fit (a force read late is the force
/// less the delay times its rate, which looks like damping and inertia), so the fit alone
/// does not show it.
///
/// 1. Identification's reduced chi-square is taken at the whole-row delays within
///    [`LOCAL_ROWS`] of zero, `id`'s window held; the least is then found as
///    [`fit_force_delay`] finds it around its best row (a parabola, re-centred once), with its
///    standard deviation.
/// 2. Where that least is beyond [`SCREEN_Z`] standard deviations and half a row, the profile
///    is taken again at the next longer window ([`WINDOW_RATIO`] times `id`'s). A delay in
///    the log is a re-pairing of its readings, the same through any filter; a least that the
///    model's misfit puts there moves with the filter, because the misfit is the filter's
///    rounding of the motion's corners. A delay is suspected only where both windows find it
///    significant, with the same sign, and where it is beyond [`SCREEN_Z`] times the held
///    window's standard deviation and half the two windows' difference in quadrature. (On
///    the independent rig's servo logs, whose velocity steps the filter rounds, the held
///    window alone warned on 18 of 116 read together, both windows on 6, and with their
///    spread on 2; on its other profiles read 10 to 30 ms late, all 27 the held window
///    warned on are still warned.)
///
/// Seven identifications where the log shows no delay, at most 42. None where the log is too
/// short for [`fit_force_delay`], or the profile at `id`'s window does not curve upward.
pub fn screen_force_delay(
    reduced: &ReducedLog,
    noise: &SensorNoise,
    id: &Identification,
) -> Option<ForceDelayScreen> {
    let profiled = profiled_rows(reduced);
    let reduced = &*profiled;
    let model = id.load_friction();
    let held = screen_at(reduced, noise, id.sg_window_s, model)?;
    let longer_window = if held.significant {
        screen_at(reduced, noise, id.sg_window_s * WINDOW_RATIO, model)
    } else {
        None
    };
    let mut screen = ForceDelayScreen {
        held,
        longer_window,
        window_spread_s: longer_window.map(|l| 0.5 * (l.delay_s - held.delay_s).abs()),
        suspected: false,
    };
    screen.suspected = longer_window
        .is_some_and(|l| l.significant && l.delay_s.signum() == held.delay_s.signum())
        && held.delay_s.abs() > SCREEN_Z * screen.std_with_window_s();
    Some(screen)
}

/// The least of the delay profile at `window` ([`screen_force_delay`], step 1).
fn screen_at(
    reduced: &ReducedLog,
    noise: &SensorNoise,
    window: f64,
    load_friction: LoadFriction,
) -> Option<ScreenedDelay> {
    let dt = reduced.log.dt_s();
    let (limit, min_rows) = profile_extent(window, dt);
    if !dt.is_finite() || dt <= 0.0 || (reduced.log.len() as f64) < min_rows {
        return None;
    }
    let mut profile = DelayProfile::new(reduced, noise, window, load_friction);
    let (best, fit, rows) = profile.least_near(0, limit)?;
    let std_rows = vertex_std_rows(&fit, profile.latest(best)?)?;
    let beyond = fit.vertex.abs() > LOCAL_ROWS as f64;
    let z = rows / std_rows;
    Some(ScreenedDelay {
        delay_s: rows * dt,
        std_s: std_rows * dt,
        z,
        beyond,
        window_s: window,
        significant: z.abs() > SCREEN_Z && rows.abs() >= 0.5,
    })
}

/// The rows a delay is profiled over: the first [`PROFILE_ROWS`] of `reduced`. The delay is
/// the rig's, so they determine it as well as a day does, and each of the profile's
/// identifications is then bounded.
fn profiled_rows(reduced: &ReducedLog) -> Cow<'_, ReducedLog> {
    if reduced.log.len() <= PROFILE_ROWS {
        return Cow::Borrowed(reduced);
    }
    let log = &reduced.log;
    Cow::Owned(ReducedLog {
        log: CalibrationLog {
            t_s: log.t_s[..PROFILE_ROWS].to_vec(),
            force_n: log.force_n[..PROFILE_ROWS].to_vec(),
            position_mm: log.position_mm[..PROFILE_ROWS].to_vec(),
            ..CalibrationLog::default()
        },
        block: reduced.block,
        log_samples: PROFILE_ROWS * reduced.block,
    })
}

/// Carries a fitted delay's standard deviation into `id`, identified on `reduced` re-timed by
/// the delay: `reduced` is identified again (the window held at `id`'s) re-timed by the delay
/// plus and minus its standard deviation, and half of each parameter's change is added to its
/// standard deviation in quadrature, and to the covariance as the outer product. A small
/// error in the delay moves m by d1 times it and d1 by the stiffness times it, which on a
/// precisely known m is many of its standard deviations (on the independent rig's heavy
/// transmission, a delay 7 ms off put m at z -5.4).
pub fn carry_delay_uncertainty(
    id: &mut Identification,
    reduced: &ReducedLog,
    noise: &SensorNoise,
    fit: &mut ForceDelayFit,
) {
    use super::identify::Param;
    let Some(std) = fit.std_s.filter(|s| *s > 0.0 && fit.fitted) else {
        return;
    };
    let at = |delay_s: f64| {
        let (log, timed) = retime_reduced(reduced, noise, delay_s);
        identify_reduced_with(&log, &timed, Some(id.sg_window_s), id.load_friction()).ok()
    };
    let (Some(plus), Some(minus)) = (at(fit.delay_s + std), at(fit.delay_s - std)) else {
        return;
    };
    let mut change = [0.0; Param::ALL.len()];
    for p in Param::ALL {
        if let (Some(a), Some(b), Some(s)) = (
            plus.parameters.value(p),
            minus.parameters.value(p),
            id.parameters.get(p).std,
        ) {
            let c = 0.5 * (a - b);
            if c.is_finite() {
                change[p.index()] = c;
                id.parameters.set_std(p, s.hypot(c));
                fit.parameter_std.insert(p.key(), c.abs());
            }
        }
    }
    let names = id.covariance_parameters.clone();
    let index = |name: &str| {
        Param::ALL
            .iter()
            .find(|p| p.key() == name)
            .map(|p| p.index())
    };
    for (i, a) in names.iter().enumerate() {
        for (j, b) in names.iter().enumerate() {
            if let (Some(pa), Some(pb)) = (index(a), index(b)) {
                if let Some(v) = id.covariance.get_mut(i).and_then(|r| r.get_mut(j)) {
                    *v += change[pa] * change[pb];
                }
            }
        }
    }
}

/// How much the residuals' correlation widens a velocity-like parameter beyond what the
/// chi-square's curvature says: the variance of d1 from identification's covariance (which
/// allows for correlated residuals) over the paper's (A^T R^-1 A)^-1, at least 1. A delay's
/// misfit is the force rate, the velocity times the stiffness, so the delay's profile is
/// widened alike: the position noise, smoothed over the filter's window, enters every
/// residual within it. On the independent rig's heavy transmission (m 0.25 N s^2/mm, a 4.8 s
/// window) the factor was 14, on the default one (0.4 s) 2.3.
pub fn correlation_inflation(id: &super::identify::Identification) -> f64 {
    use super::identify::Param;
    let names = &id.covariance_parameters;
    let Some(i) = names.iter().position(|n| n == Param::D1.key()) else {
        return 1.0;
    };
    // The paper's covariance is over X = [m, d0, d1, d2, mu, F0] and mu_f (every parameter
    // but k2, in model order), the identifiable ones; D1 comes before mu_f.
    let x = &Param::ALL[..Param::K2.index()];
    let Some(j) = x
        .iter()
        .filter(|p| names.iter().any(|n| n == p.key()))
        .position(|p| *p == Param::D1)
    else {
        return 1.0;
    };
    let full = id.covariance.get(i).and_then(|r| r.get(i)).copied();
    let paper = id
        .paper_covariance_k2_fixed
        .get(j)
        .and_then(|r| r.get(j))
        .copied();
    match (full, paper) {
        (Some(a), Some(b)) if a.is_finite() && b > 0.0 => (a / b).max(1.0),
        _ => 1.0,
    }
}

/// `reduced` with its force re-timed by `delay_s`, and `noise` with the force variance the
/// interpolation leaves ([`RowDelay::noise_variance_factor`]); the rows it loses at the log's
/// ends are no longer counted as the log's.
pub fn retime_reduced(
    reduced: &ReducedLog,
    noise: &SensorNoise,
    delay_s: f64,
) -> (ReducedLog, SensorNoise) {
    let delay = RowDelay::new(delay_s / reduced.log.dt_s());
    let noise = SensorNoise {
        force_variance_n2: noise.force_variance_n2 * delay.noise_variance_factor(),
        ..*noise
    };
    let log_samples = reduced
        .log_samples
        .saturating_sub(delay.rows_lost() * reduced.block);
    let log = retime_log(&reduced.log, delay);
    (
        ReducedLog {
            log,
            log_samples,
            block: reduced.block,
        },
        noise,
    )
}

/// Half the number of interpolation taps.
pub const KERNEL_HALF: usize = 8;

/// Interpolation taps for a fraction of a row.
pub const KERNEL_TAPS: usize = 2 * KERNEL_HALF;

/// The Kaiser window's shape parameter.
const KAISER_BETA: f64 = 10.0;

/// The largest delay (s) a log may be re-timed by: far beyond a channel scan or a converter's
/// filter, so a larger value is a mistake (and would hold that many rows in memory).
pub const MAX_FORCE_DELAY_S: f64 = 1.0;

/// The largest delay in rows (the rows held while re-timing a stream).
pub const MAX_FORCE_DELAY_ROWS: f64 = 100_000.0;

/// The delay of the force channel, in rows of the log: a whole part and the interpolation
/// kernel of the fraction (one tap of weight 1 when there is none).
#[derive(Debug, Clone, PartialEq)]
pub struct RowDelay {
    whole: i64,
    /// Offset of the kernel's first tap from the whole row.
    first: i64,
    kernel: Vec<f64>,
}

impl RowDelay {
    /// The delay of `delay_s` in a log sampled every `dt_s`, or why it cannot be held: more
    /// than [`MAX_FORCE_DELAY_ROWS`] rows.
    pub fn of_log(delay_s: f64, dt_s: f64) -> Result<RowDelay, String> {
        let rows = delay_s / dt_s;
        if rows.is_nan() || rows.abs() > MAX_FORCE_DELAY_ROWS {
            return Err(format!(
                "a force delay of {delay_s:.3} s is {rows:.0} samples of this log; at most \
                 {MAX_FORCE_DELAY_ROWS:.0} are held while the force is re-timed"
            ));
        }
        Ok(RowDelay::new(rows))
    }

    /// The delay of `rows` (finite, |rows| at most [`MAX_FORCE_DELAY_ROWS`]).
    pub fn new(rows: f64) -> RowDelay {
        let rows = if rows.is_finite() {
            rows.clamp(-MAX_FORCE_DELAY_ROWS, MAX_FORCE_DELAY_ROWS)
        } else {
            0.0
        };
        let whole = rows.floor();
        let phi = rows - whole;
        // A fraction below a millionth of a row is no interpolation.
        if !(1e-6..=1.0 - 1e-6).contains(&phi) {
            return RowDelay {
                whole: rows.round() as i64,
                first: 0,
                kernel: vec![1.0],
            };
        }
        RowDelay {
            whole: whole as i64,
            first: 1 - KERNEL_HALF as i64,
            kernel: fractional_kernel(phi),
        }
    }

    /// The factor on a white force noise's variance after re-timing (the kernel's sum of
    /// squares).
    pub fn noise_variance_factor(&self) -> f64 {
        self.kernel.iter().map(|h| h * h).sum()
    }

    /// Rows of the log the re-timed log lacks (its ends).
    pub fn rows_lost(&self) -> usize {
        let last = self.first + self.kernel.len() as i64 - 1;
        let before = (self.whole + self.first).min(0).unsigned_abs();
        let after = (self.whole + last).max(0).unsigned_abs();
        (before + after) as usize
    }
}

/// The weights, at offsets 1 - [`KERNEL_HALF`] ..= [`KERNEL_HALF`] from the row before, of the
/// value a fraction `phi` (0 < phi < 1) of a row later: a Kaiser-windowed sinc whose weights
/// sum to 1.
fn fractional_kernel(phi: f64) -> Vec<f64> {
    let h = KERNEL_HALF as f64;
    let mut w: Vec<f64> = (1 - KERNEL_HALF as i64..=KERNEL_HALF as i64)
        .map(|j| {
            let u = j as f64 - phi;
            let sinc = if u.abs() < 1e-12 {
                1.0
            } else {
                (std::f64::consts::PI * u).sin() / (std::f64::consts::PI * u)
            };
            let r = (1.0 - (u / h).powi(2)).max(0.0);
            sinc * bessel_i0(KAISER_BETA * r.sqrt()) / bessel_i0(KAISER_BETA)
        })
        .collect();
    let sum: f64 = w.iter().sum();
    for v in w.iter_mut() {
        *v /= sum;
    }
    w
}

/// The modified Bessel function of the first kind, order 0 (power series; converges for the
/// window's arguments, at most [`KAISER_BETA`]).
fn bessel_i0(x: f64) -> f64 {
    let q = x * x / 4.0;
    let (mut term, mut sum) = (1.0, 1.0);
    for k in 1..60 {
        term *= q / (k * k) as f64;
        sum += term;
        if term < 1e-17 * sum {
            break;
        }
    }
    sum
}

/// A stream of samples with the force re-timed by a [`RowDelay`]: each position keeps its
/// time, and takes the force read `delay` rows later. Holds about |delay| + [`KERNEL_TAPS`]
/// rows.
#[derive(Debug)]
pub struct ForceRetimer<I> {
    inner: I,
    delay: RowDelay,
    /// Times and positions from row `pos_start`.
    positions: VecDeque<(f64, f64)>,
    pos_start: i64,
    /// Forces from row `force_start`.
    forces: VecDeque<f64>,
    force_start: i64,
    /// Rows read.
    read: i64,
    /// The next row to give.
    next: i64,
}

impl<I> ForceRetimer<I>
where
    I: Iterator<Item = Result<Sample, LogError>>,
{
    /// Re-times `inner`'s force by `delay`.
    pub fn new(inner: I, delay: RowDelay) -> ForceRetimer<I> {
        // The first row whose kernel starts inside the log.
        let next = (-(delay.whole + delay.first)).max(0);
        let force_start = next + delay.whole + delay.first;
        ForceRetimer {
            inner,
            delay,
            positions: VecDeque::new(),
            pos_start: next,
            forces: VecDeque::new(),
            force_start,
            read: 0,
            next,
        }
    }
}

impl<I> Iterator for ForceRetimer<I>
where
    I: Iterator<Item = Result<Sample, LogError>>,
{
    type Item = Result<Sample, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            let k = self.next;
            let first = k + self.delay.whole + self.delay.first;
            let last = first + self.delay.kernel.len() as i64 - 1;
            if k < self.read && last < self.read {
                let (t_s, position_mm) = self.positions[(k - self.pos_start) as usize];
                let force_n = self
                    .delay
                    .kernel
                    .iter()
                    .enumerate()
                    .map(|(j, h)| h * self.forces[(first - self.force_start) as usize + j])
                    .sum();
                self.next += 1;
                while self.pos_start <= k {
                    self.positions.pop_front();
                    self.pos_start += 1;
                }
                while self.force_start <= first {
                    self.forces.pop_front();
                    self.force_start += 1;
                }
                return Some(Ok(Sample {
                    t_s,
                    force_n,
                    position_mm,
                }));
            }
            match self.inner.next()? {
                Err(e) => return Some(Err(e)),
                Ok(s) => {
                    // Rows before the first that is given, or whose force no row takes, are
                    // not held.
                    if self.read >= self.pos_start {
                        self.positions.push_back((s.t_s, s.position_mm));
                    }
                    if self.read >= self.force_start {
                        self.forces.push_back(s.force_n);
                    }
                    self.read += 1;
                }
            }
        }
    }
}

/// `log` with its force re-timed by `delay` rows ([`ForceRetimer`]); the filled gaps, rows
/// left out, units row and columns read by their names are kept as read.
pub fn retime_log(log: &CalibrationLog, delay: RowDelay) -> CalibrationLog {
    let samples = (0..log.len()).map(|i| {
        Ok(Sample {
            t_s: log.t_s[i],
            force_n: log.force_n[i],
            position_mm: log.position_mm[i],
        })
    });
    let mut out = CalibrationLog {
        filled: log.filled.clone(),
        left_out: log.left_out.clone(),
        units_row: log.units_row.clone(),
        recognised: log.recognised.clone(),
        interval_scatter: log.interval_scatter,
        preamble: log.preamble,
        rows_at_hz: log.rows_at_hz,
        ..CalibrationLog::default()
    };
    for s in ForceRetimer::new(samples, delay).flatten() {
        out.t_s.push(s.t_s);
        out.force_n.push(s.force_n);
        out.position_mm.push(s.position_mm);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn log_of(f: impl Fn(f64) -> f64, x: impl Fn(f64) -> f64, n: usize, dt: f64) -> CalibrationLog {
        let t: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
        CalibrationLog {
            force_n: t.iter().map(|&t| f(t)).collect(),
            position_mm: t.iter().map(|&t| x(t)).collect(),
            t_s: t,
            ..CalibrationLog::default()
        }
    }

    #[test]
    fn a_whole_row_delay_re_pairs_the_readings_exactly() {
        let log = log_of(|t| t * 100.0, |t| -t, 50, 0.01);
        for d in [-3i64, 0, 2, 7] {
            let out = retime_log(&log, RowDelay::new(d as f64));
            assert_eq!(out.len(), 50 - d.unsigned_abs() as usize, "delay {d}");
            for k in 0..out.len() {
                let row = (out.t_s[k] / 0.01).round() as i64;
                assert_eq!(out.position_mm[k], log.position_mm[row as usize]);
                assert_eq!(out.force_n[k], log.force_n[(row + d) as usize]);
            }
        }
    }

    #[test]
    fn a_fractional_delay_recovers_a_smooth_force_at_the_later_instant() {
        // A 2 Hz sine sampled at 100 Hz (0.04 of the Nyquist frequency).
        let w = 2.0 * std::f64::consts::PI * 2.0;
        let log = log_of(|t| (w * t).sin(), |t| t, 400, 0.01);
        for rows in [0.25, 0.5, -1.7, 3.4] {
            let out = retime_log(&log, RowDelay::new(rows));
            assert!(out.len() >= 400 - KERNEL_TAPS - 4);
            for k in 0..out.len() {
                let want = (w * (out.t_s[k] + rows * 0.01)).sin();
                assert!(
                    (out.force_n[k] - want).abs() < 1e-4,
                    "{rows}: {k}: {} {want}",
                    out.force_n[k]
                );
                assert_eq!(out.position_mm[k], out.t_s[k]);
            }
        }
    }

    #[test]
    fn the_noise_factor_is_the_kernels_sum_of_squares() {
        assert_eq!(RowDelay::new(2.0).noise_variance_factor(), 1.0);
        let half = RowDelay::new(0.5).noise_variance_factor();
        assert!((0.83..0.9).contains(&half), "{half}");
        // White noise through the kernel has that variance.
        let mut state = 12345u64;
        let mut gauss = || {
            let mut s = 0.0;
            for _ in 0..12 {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                s += (state >> 11) as f64 / (1u64 << 53) as f64;
            }
            s - 6.0
        };
        let n = 200_000;
        let log = CalibrationLog {
            t_s: (0..n).map(|i| i as f64).collect(),
            force_n: (0..n).map(|_| gauss()).collect(),
            position_mm: vec![0.0; n],
            ..CalibrationLog::default()
        };
        let out = retime_log(&log, RowDelay::new(0.5));
        let var = out.force_n.iter().map(|f| f * f).sum::<f64>() / out.len() as f64;
        assert!((var / half - 1.0).abs() < 0.02, "{var} against {half}");
    }

    #[test]
    fn the_profiles_parabola_finds_its_vertex_and_how_well_the_points_fix_it() {
        let exact: Vec<(f64, f64)> = (-3..=3)
            .map(|u| (u as f64, 1.0 + 0.01 * (u as f64 - 0.4).powi(2)))
            .collect();
        let p = local_parabola(&exact).expect("curves upward");
        assert!((p.vertex - 0.4).abs() < 1e-9, "{p:?}");
        assert!((p.curvature - 0.01).abs() < 1e-12 && (p.least - 1.0).abs() < 1e-12);
        assert!(p.vertex_std < 1e-6, "{p:?}");
        // Odd and even rows apart by more than the curvature over a row: the vertex stays
        // near, and its standard deviation says how loosely the points fix it.
        let jagged: Vec<(f64, f64)> = exact
            .iter()
            .map(|&(u, f)| (u, f + if (u as i64) % 2 == 0 { 0.0 } else { 0.012 }))
            .collect();
        let q = local_parabola(&jagged).expect("curves upward");
        assert!((q.vertex - 0.4).abs() < 3.0 * q.vertex_std, "{q:?}");
        assert!(q.vertex_std > 0.05, "{q:?}");
        // A flat or downward profile determines nothing.
        let flat: Vec<(f64, f64)> = (-3..=3)
            .map(|u| (u as f64, 1.0 - 0.001 * (u * u) as f64))
            .collect();
        assert!(local_parabola(&flat).is_none());
        assert!(local_parabola(&exact[..3]).is_none());
    }

    #[test]
    fn errors_pass_through_and_memory_stays_bounded() {
        let rows = (0..10_000).map(|i| {
            if i == 5000 {
                Err(LogError::Io("lost".into()))
            } else {
                Ok(Sample {
                    t_s: i as f64,
                    force_n: 0.0,
                    position_mm: 0.0,
                })
            }
        });
        let mut r = ForceRetimer::new(rows, RowDelay::new(30.5));
        let mut errors = 0;
        for s in r.by_ref() {
            errors += s.is_err() as usize;
        }
        assert_eq!(errors, 1);
        assert!(
            r.positions.len() <= 30 + KERNEL_TAPS + 2,
            "{}",
            r.positions.len()
        );
        assert!(r.forces.len() <= KERNEL_TAPS + 2);
    }
}
