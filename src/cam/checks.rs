//! Design checks: pressure angle, self-locking, undercut, cutter fit and contact stress.
//!
//! Each check reports pass / warn / fail with its value, limit and where it happens. A failing
//! check says what to change and by how much: the advice is found by re-synthesising the
//! pitch curve with the changed spring rate or preload and solving (Brent's method) for the
//! value at which the check just passes, so following the advice does make the check pass.

use roots::{find_root_brent, SimpleConvergency};
use serde::Serialize;

use super::forces::{predict, ContactModel, RodForce};
use super::pitch_curve::{synthesize, PitchCurve, SynthesisOptions};
use super::surface::{offset, CamSurface};
use crate::model::ChecksSpec;
use crate::model::Follower;
use crate::model::ForceLaw;

/// Outcome of a check.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// Within the limit with margin.
    Pass,
    /// Within the limit but close, or a concern that does not stop the part being made.
    Warn,
    /// Outside the limit.
    Fail,
}

impl Status {
    /// Lower-case name.
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Pass => "pass",
            Status::Warn => "warn",
            Status::Fail => "fail",
        }
    }
}

/// One check's result.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Check {
    /// Check name: pressure_angle, self_locking, undercut, cutter_fit, contact_stress.
    pub name: &'static str,
    /// Outcome.
    pub status: Status,
    /// The measured value (None when the check does not apply).
    pub value: Option<f64>,
    /// The limit it is compared with.
    pub limit: f64,
    /// Unit of value and limit.
    pub unit: &'static str,
    /// Where along the stroke the value occurs.
    pub at_x_mm: Option<f64>,
    /// What was found, in words.
    pub message: String,
    /// What to change, with numbers (for warn and fail).
    pub advice: Option<String>,
    /// The same advice as spec changes a script can apply; any one of them is enough.
    pub suggestions: Vec<Suggestion>,
}

/// One spec change that makes a check pass.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Suggestion {
    /// Spec key, e.g. `follower.preload`.
    pub key: &'static str,
    /// The value to set, in `unit`.
    pub value: f64,
    /// Unit of the value.
    pub unit: &'static str,
}

/// Advice text with its suggestions.
#[derive(Debug, Clone, PartialEq)]
struct Advice {
    text: String,
    suggestions: Vec<Suggestion>,
}

impl Advice {
    fn text(text: impl Into<String>) -> Advice {
        Advice {
            text: text.into(),
            suggestions: Vec::new(),
        }
    }
}

/// Splits optional advice into the two fields of a [`Check`].
fn advice_fields(advice: Option<Advice>) -> (Option<String>, Vec<Suggestion>) {
    match advice {
        Some(a) => (Some(a.text), a.suggestions),
        None => (None, Vec::new()),
    }
}

/// Everything the checks need.
#[derive(Debug)]
pub struct CheckInput<'a> {
    /// The law.
    pub law: &'a ForceLaw,
    /// The followers.
    pub follower: &'a Follower,
    /// Stroke.
    pub xmax_mm: f64,
    /// Sampling used for the design (reused for advice searches).
    pub options: SynthesisOptions,
    /// Limits.
    pub limits: &'a ChecksSpec,
    /// Part thickness (contact length).
    pub plate_thickness_mm: f64,
    /// Width of the roller in contact (the contact line is the narrower of the two).
    pub roller_width_mm: f64,
    /// The contact model (E* and contact length), for the contact-stress advice.
    pub contact: ContactModel,
    /// Whether to search for advice (re-synthesising the cam); sweeps leave it out.
    pub advise: bool,
    /// Cutter radius.
    pub tool_radius_mm: f64,
    /// The pitch curve.
    pub pitch: &'a PitchCurve,
    /// The cam surface.
    pub surface: &'a CamSurface,
    /// The predicted forces.
    pub forces: &'a [RodForce],
}

/// Margin applied to advice so that following it passes with a little room.
const ADVICE_MARGIN: f64 = 1.01;
/// A pitch radius below this multiple of the roller radius is a warning.
const UNDERCUT_WARN_RATIO: f64 = 1.1;

/// A pressure angle within this of the limit is a warning (degrees).
pub const PRESSURE_ANGLE_WARN_DEG: f64 = 2.0;

/// A loading margin to jamming within this of the limit is a warning (degrees).
pub const LOCKING_WARN_DEG: f64 = 5.0;

/// A contact pressure above this fraction of the limit is a warning.
pub const CONTACT_WARN_FRACTION: f64 = 0.8;

/// Runs all checks.
pub fn run_checks(input: &CheckInput<'_>) -> Vec<Check> {
    let mut checks = vec![
        pressure_angle(input),
        self_locking(input),
        undercut(input),
        cutter_fit(input),
        contact_stress(input),
    ];
    checks.extend(roller_life(input));
    checks
}

/// A life within this factor of the duty is a warning.
pub const LIFE_WARN_FACTOR: f64 = 2.0;

/// What the roller sees over one stroke: the ISO 281 mean load (exponent 10/3 over the
/// revolutions) and the revolutions of a full stroke (out and back).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RollerDuty {
    /// The largest normal load on one roller (N) and where (mm).
    pub peak_load_n: f64,
    /// Where the peak is (mm).
    pub peak_at_x_mm: f64,
    /// ISO 281 mean equivalent load over a stroke (N).
    pub mean_load_n: f64,
    /// Roller revolutions per full stroke (out and back).
    pub revolutions_per_stroke: f64,
}

/// The roller's duty over a stroke, from the normal loads and the surface it rolls on (None
/// for a knife edge or an unbounded load).
pub fn roller_duty(
    follower: &Follower,
    surface: &CamSurface,
    forces: &[RodForce],
) -> Option<RollerDuty> {
    let r = follower.roller_radius_mm;
    if r <= 0.0 || forces.is_empty() || surface.points.len() != forces.len() {
        return None;
    }
    let (mut peak, mut at, mut sum_p, mut sum_s) = (0.0_f64, 0.0, 0.0, 0.0);
    for (w, f) in surface.points.windows(2).zip(forces.windows(2)) {
        let ds = (w[1].x_mm - w[0].x_mm).hypot(w[1].y_mm - w[0].y_mm);
        let (a, b) = (f[0].contact_normal_n?, f[1].contact_normal_n?);
        for (load, x) in [(a, f[0].x_mm), (b, f[1].x_mm)] {
            if load > peak {
                peak = load;
                at = x;
            }
        }
        sum_p += 0.5 * (a.powf(10.0 / 3.0) + b.powf(10.0 / 3.0)) * ds;
        sum_s += ds;
    }
    (sum_s > 0.0).then(|| RollerDuty {
        peak_load_n: peak,
        peak_at_x_mm: at,
        mean_load_n: (sum_p / sum_s).powf(0.3),
        revolutions_per_stroke: 2.0 * sum_s / (std::f64::consts::TAU * r),
    })
}

/// L10 life in strokes of a bearing with dynamic load rating `c_n` under `duty` (ISO 281 basic
/// rating life of a roller bearing: (C/P)^(10/3) million revolutions).
pub fn l10_strokes(c_n: f64, duty: &RollerDuty) -> f64 {
    (c_n / duty.mean_load_n).powf(10.0 / 3.0) * 1e6 / duty.revolutions_per_stroke
}

/// The roller-bearing life check, when the spec gives the bearing's rating and the duty.
fn roller_life(input: &CheckInput<'_>) -> Option<Check> {
    let b = input.follower.bearing;
    let (c, strokes) = (b.dynamic_load_n?, b.duty_strokes?);
    let duty = roller_duty(input.follower, input.surface, input.forces);
    let Some(duty) = duty else {
        return Some(Check {
            name: "roller_life",
            status: Status::Fail,
            value: None,
            limit: strokes,
            unit: "strokes",
            at_x_mm: None,
            message: "no roller life: a knife-edge follower or an unbounded contact load".into(),
            advice: Some(
                "Use a roller (roller_radius > 0) and clear the other checks first.".into(),
            ),
            suggestions: Vec::new(),
        });
    };
    let life = l10_strokes(c, &duty);
    let status = if life < strokes {
        Status::Fail
    } else if life < LIFE_WARN_FACTOR * strokes {
        Status::Warn
    } else {
        Status::Pass
    };
    let advice = (input.advise && status != Status::Pass).then(|| {
        let needed = round_up(
            duty.mean_load_n
                * (LIFE_WARN_FACTOR * strokes * duty.revolutions_per_stroke / 1e6).powf(0.3),
        );
        Advice {
            text: format!(
                "Use a roller bearing with a dynamic load rating C of at least {needed} N \
                 ({LIFE_WARN_FACTOR} x the duty of {strokes:.0} strokes at a mean load of {:.1} N), \
                 or lower the contact load (a larger roller, a lower pressure angle).",
                duty.mean_load_n
            ),
            suggestions: vec![Suggestion {
                key: "follower.roller_dynamic_load",
                value: needed,
                unit: "N",
            }],
        }
    });
    let (advice, suggestions) = advice_fields(advice);
    Some(Check {
        name: "roller_life",
        status,
        value: Some(life),
        limit: strokes,
        unit: "strokes",
        at_x_mm: Some(duty.peak_at_x_mm),
        message: format!(
            "roller bearing L10 life {life:.3e} strokes (C = {c} N, ISO 281 mean load {:.1} N, peak {:.1} N at x = {:.3} mm, {:.2} revolutions per stroke); duty {strokes:.3e} strokes",
            duty.mean_load_n, duty.peak_load_n, duty.peak_at_x_mm, duty.revolutions_per_stroke
        ),
        advice,
        suggestions,
    })
}

/// Angle extremes of a re-synthesised curve, for the advice searches.
struct AngleMetrics {
    max_theta_deg: f64,
    min_theta_deg: f64,
    min_material_radius_mm: f64,
}

fn metrics(input: &CheckInput<'_>, follower: &Follower) -> Option<AngleMetrics> {
    let pitch = synthesize(input.law, follower, input.xmax_mm, &input.options).ok()?;
    Some(AngleMetrics {
        max_theta_deg: pitch.max_pressure_angle().0,
        min_theta_deg: pitch
            .samples
            .iter()
            .map(|s| s.theta_rad.to_degrees())
            .fold(f64::INFINITY, f64::min),
        min_material_radius_mm: pitch
            .min_material_side_radius()
            .map_or(f64::INFINITY, |m| m.0),
    })
}

/// Finds p in [lo, hi] where g(p) = 0, given g(lo) > 0 >= g(hi) (g is a metric minus its
/// target). Returns None when the interval does not bracket a sign change.
fn threshold(lo: f64, hi: f64, mut g: impl FnMut(f64) -> f64) -> Option<f64> {
    let (glo, ghi) = (g(lo), g(hi));
    if !(glo > 0.0 && ghi <= 0.0) {
        return None;
    }
    let mut conv = SimpleConvergency {
        eps: 1e-7 * hi.abs().max(1e-6),
        max_iter: 80,
    };
    find_root_brent(
        lo,
        hi,
        |p| {
            let v = g(p);
            if v.is_nan() {
                1.0
            } else {
                v
            }
        },
        &mut conv,
    )
    .ok()
}

/// The first p >= `start` (stepping through the increasing `candidates`) where g(p) <= 0,
/// refined by Brent's method. None when g is not positive at `start`, a candidate cannot be
/// evaluated (NaN: no curve there) before a sign change, or the candidates run out.
fn first_crossing(
    start: f64,
    candidates: impl IntoIterator<Item = f64>,
    mut g: impl FnMut(f64) -> f64,
) -> Option<f64> {
    let g0 = g(start);
    if g0.is_nan() || g0 <= 0.0 {
        return None;
    }
    let mut lo = start;
    for p in candidates {
        let v = g(p);
        if v.is_nan() {
            return None;
        }
        if v <= 0.0 {
            return threshold(lo, p, g);
        }
        lo = p;
    }
    None
}

/// Spring rates from `ks0` up by factors of 1.5 (to about 10^7 times).
fn rate_candidates(ks0: f64) -> impl Iterator<Item = f64> {
    (1..40).map(move |k| ks0 * 1.5_f64.powi(k))
}

/// Preloads from `yp0` up in doubling steps starting at 1 % of the stroke.
fn preload_candidates(yp0: f64, xmax: f64) -> impl Iterator<Item = f64> {
    (0..24).map(move |k| yp0 + 0.01 * xmax * 2_f64.powi(k))
}

fn round_up(v: f64) -> f64 {
    let scale = 10f64.powi(3 - v.abs().log10().ceil() as i32);
    (v * ADVICE_MARGIN * scale).ceil() / scale
}

fn round_down(v: f64) -> f64 {
    let scale = 10f64.powi(3 - v.abs().log10().ceil() as i32);
    (v / ADVICE_MARGIN * scale).floor() / scale
}

/// Advice to bring the largest pressure angle to at most `target_deg`, by spring rate or preload.
/// Advice for a largest pressure angle of at most `target_deg`; with `min_theta_floor_deg`
/// the smallest angle must also stay at or above it (a stiffer or more preloaded spring lowers
/// every angle, and a too-small angle near the start cannot return the rod).
fn angle_advice(
    input: &CheckInput<'_>,
    target_deg: f64,
    min_theta_floor_deg: Option<f64>,
) -> Advice {
    let f = input.follower;
    let deficit = |m: AngleMetrics| {
        let floor = min_theta_floor_deg.map_or(f64::NEG_INFINITY, |fl| fl - m.min_theta_deg);
        (m.max_theta_deg - target_deg).max(floor)
    };
    let ks0 = f.spring_rate_n_per_mm;
    let (ks_now, yp_now) = (short(ks0), short(f.preload_mm));
    let by_rate = first_crossing(ks0, rate_candidates(ks0), |ks| {
        metrics(input, &f.with_spring_rate(ks)).map_or(f64::NAN, deficit)
    });
    let yp0 = f.preload_mm;
    let by_preload = first_crossing(yp0, preload_candidates(yp0, input.xmax_mm), |yp| {
        metrics(input, &f.with_preload(yp)).map_or(f64::NAN, deficit)
    });
    let keep = format!("to keep the pressure angle at or below {target_deg:.2} deg");
    let by_rate = by_rate.map(round_up);
    let by_preload = by_preload.map(round_up);
    let text = match (by_rate, by_preload) {
        (Some(ks), Some(yp)) => format!(
            "Raise follower.spring_rate from {ks_now} to at least {ks} N/mm, or follower.preload from {yp_now} to at least {yp} mm, {keep}."
        ),
        (Some(ks), None) => format!("Raise follower.spring_rate from {ks_now} to at least {ks} N/mm {keep}."),
        (None, Some(yp)) => format!(
            "Raise follower.preload from {yp_now} to at least {yp} mm {keep}; no spring rate alone can, because \
             the angle near x = 0 is set by the preload."
        ),
        (None, None) => format!("Neither a stiffer spring nor more preload alone can keep the pressure angle at or below {target_deg:.2} deg \
             (the curve cannot be made with so much spring force against friction); lower fmax, raise xmax or reduce friction."),
    };
    let mut suggestions = Vec::new();
    if let Some(ks) = by_rate {
        suggestions.push(Suggestion {
            key: "follower.spring_rate",
            value: ks,
            unit: "N/mm",
        });
    }
    if let Some(yp) = by_preload {
        suggestions.push(Suggestion {
            key: "follower.preload",
            value: yp,
            unit: "mm",
        });
    }
    Advice { text, suggestions }
}

/// The peak contact pressure of the cam re-synthesised for `follower` (None: no curve).
fn peak_contact_mpa(
    input: &CheckInput<'_>,
    follower: &Follower,
    contact: &ContactModel,
) -> Option<f64> {
    let pitch = synthesize(input.law, follower, input.xmax_mm, &input.options).ok()?;
    let surface = offset(
        &pitch,
        follower.roller_radius_mm,
        2.0 * input.options.chord_tolerance_mm,
    );
    predict(input.law, follower, &pitch, &surface, contact)
        .iter()
        .map(|f| f.contact_stress_mpa)
        .try_fold(0.0_f64, |m, v| v.map(|v| m.max(v)))
}

/// What brings the peak pressure `p` below the warning band: a longer contact line (the key
/// that limits it: the roller's width or the plate's thickness; p scales with 1/sqrt(length)),
/// or a larger roller (found by re-synthesis).
fn contact_advice(input: &CheckInput<'_>, p: f64) -> Advice {
    let target = CONTACT_WARN_FRACTION * input.limits.max_contact_stress_mpa;
    let length = input.contact.length_mm;
    let needed = round_up(length * (p / target).powi(2));
    let (plate, roller) = (input.plate_thickness_mm, input.roller_width_mm);
    let mut parts = Vec::new();
    let mut suggestions = Vec::new();
    if roller < plate {
        if needed <= plate {
            parts.push(format!(
                "use a roller at least {needed} mm wide (the contact is the roller's {roller} mm)"
            ));
            suggestions.push(Suggestion {
                key: "part.roller_width",
                value: needed,
                unit: "mm",
            });
        } else {
            parts.push(format!(
                "make the contact at least {needed} mm long: a roller that wide and a plate that thick"
            ));
        }
    } else if roller > plate && needed > roller {
        parts.push(format!(
            "make the contact at least {needed} mm long: a plate that thick and a roller that wide"
        ));
    } else {
        // The plate limits (a roller as wide as the plate follows it).
        parts.push(format!(
            "make part.thickness at least {needed} mm (the contact is the plate's {plate} mm; p scales with 1/sqrt(length))"
        ));
        suggestions.push(Suggestion {
            key: "part.thickness",
            value: needed,
            unit: "mm",
        });
    }
    let f = input.follower;
    let r0 = f.roller_radius_mm;
    if r0 > 0.0 {
        let candidates = (1..=24).map(|k| r0 * 1.15_f64.powi(k));
        let by_radius = first_crossing(r0, candidates, |r| {
            peak_contact_mpa(input, &f.with_roller_radius(r), &input.contact)
                .map_or(f64::NAN, |pr| pr - target)
        })
        .map(round_up);
        if let Some(r) = by_radius {
            // The larger roller must still follow the cam and fit the checks it affects.
            let follows = synthesize(
                input.law,
                &f.with_roller_radius(r),
                input.xmax_mm,
                &input.options,
            )
            .is_ok_and(|pitch| {
                offset(&pitch, r, 2.0 * input.options.chord_tolerance_mm).is_followable()
            });
            if follows {
                parts.push(format!("use a roller radius of at least {r} mm"));
                suggestions.push(Suggestion {
                    key: "follower.roller_radius",
                    value: r,
                    unit: "mm",
                });
            }
        }
    }
    parts.push(
        "a stronger cam and roller material (checks.max_contact_stress follows the weaker yield)"
            .into(),
    );
    Advice {
        text: capitalise(parts.join(", or ")) + ".",
        suggestions,
    }
}

fn capitalise(mut s: String) -> String {
    if let Some(first) = s.get(..1) {
        let upper = first.to_uppercase();
        s.replace_range(..1, &upper);
    }
    s
}

fn pressure_angle(input: &CheckInput<'_>) -> Check {
    let (theta, at) = input.pitch.max_pressure_angle();
    let limit = input.limits.max_pressure_angle_deg;
    let status = if theta > limit {
        Status::Fail
    } else if theta > limit - PRESSURE_ANGLE_WARN_DEG {
        Status::Warn
    } else {
        Status::Pass
    };
    let (advice, suggestions) =
        // The advice aims at a pass, below the warning band.
        advice_fields((input.advise && status == Status::Fail).then(|| angle_advice(input, limit - PRESSURE_ANGLE_WARN_DEG, None)));
    Check {
        name: "pressure_angle",
        status,
        value: Some(theta),
        limit,
        unit: "deg",
        at_x_mm: Some(at),
        message: format!(
            "largest pressure angle {theta:.2} deg at x = {at:.3} mm (limit {limit} deg)"
        ),
        advice,
        suggestions,
    }
}

fn self_locking(input: &CheckInput<'_>) -> Check {
    let phi = input.follower.friction_angle_rad().to_degrees();
    let (max_theta, at_max) = input.pitch.max_pressure_angle();
    let (min_theta, at_min) = input
        .pitch
        .samples
        .iter()
        .map(|s| (s.theta_rad.to_degrees(), s.x_mm))
        .fold((f64::INFINITY, 0.0), |m, v| if v.0 < m.0 { v } else { m });
    let load_margin = 90.0 - (max_theta + phi);
    let unload_margin = min_theta - phi;
    let limit = input.limits.min_locking_margin_deg;
    // Loading must keep the margin; unloading only has to return the rod (theta - phi > 0),
    // with a warning when the return is weak (below the margin).
    let load_fails = load_margin < limit;
    let unload_fails = unload_margin <= 0.0;
    let loading_worse = load_fails || (!unload_fails && load_margin <= unload_margin);
    let (value, at) = if loading_worse {
        (load_margin, at_max)
    } else {
        (unload_margin, at_min)
    };
    let status = if load_fails || unload_fails {
        Status::Fail
    } else if load_margin < limit + LOCKING_WARN_DEG || unload_margin < limit {
        Status::Warn
    } else {
        Status::Pass
    };
    let message = format!(
        "loading margin to jamming 90 - (theta + phi) = {load_margin:.2} deg at x = {at_max:.3} mm; \
         unloading return margin theta - phi = {unload_margin:.2} deg at x = {at_min:.3} mm \
         (phi = {phi:.2} deg; below 0 the spring cannot push the rod back)"
    );
    let advice = (input.advise && status != Status::Pass).then(|| {
        if loading_worse {
            // Less jamming, while the spring still returns the rod with the margin.
            angle_advice(input, 90.0 - phi - limit - LOCKING_WARN_DEG, Some(phi + limit))
        } else {
            // theta is large near x = 0 with little preload, so the largest acceptable preload
            // is where target - min_theta(yp) changes sign between the current preload and 0.
            let f = input.follower;
            let target = phi + limit;
            let largest = threshold(f.preload_mm, 0.0, |yp| {
                metrics(input, &f.with_preload(yp)).map_or(f64::NAN, |m| target - m.min_theta_deg)
            });
            // The lower preload must not make loading jam instead.
            let keeps_loading = |yp: f64| {
                metrics(input, &f.with_preload(yp))
                    .is_some_and(|m| m.max_theta_deg <= 90.0 - phi - limit - LOCKING_WARN_DEG)
            };
            match largest.map(round_down).filter(|&yp| keeps_loading(yp)) {
                Some(yp) => Advice {
                    text: format!(
                        "Lower follower.preload from {} to at most {yp} mm, or reduce friction, so that the \
                         spring returns the rod with theta - phi >= {limit} deg.",
                        f.preload_mm
                    ),
                    suggestions: vec![Suggestion { key: "follower.preload", value: yp, unit: "mm" }],
                },
                None => Advice::text("Reduce friction: the pressure angle near the start is too small to overcome it, and no preload alone both returns the rod and keeps loading clear of jamming."),
            }
        }
    });
    let (advice, suggestions) = advice_fields(advice);
    Check {
        name: "self_locking",
        status,
        value: Some(value),
        limit,
        unit: "deg",
        at_x_mm: Some(at),
        message,
        advice,
        suggestions,
    }
}

fn undercut(input: &CheckInput<'_>) -> Check {
    let r = input.follower.roller_radius_mm;
    let rho = input.pitch.min_material_side_radius();
    let folded = !input.surface.is_followable();
    let status = if folded || rho.is_some_and(|(rho, _)| rho <= r) {
        Status::Fail
    } else if rho.is_some_and(|(rho, _)| rho < UNDERCUT_WARN_RATIO * r) {
        Status::Warn
    } else {
        Status::Pass
    };
    let spans: Vec<String> = input
        .surface
        .unfollowable_spans()
        .iter()
        .map(|s| format!("[{:.3}, {:.3}] mm", s.x_start_mm, s.x_end_mm))
        .collect();
    let message = match (rho, status) {
        (None, _) => "the pitch curve never bends towards the cam material; no undercut possible".to_string(),
        (Some((rho, at)), Status::Fail) => format!(
            "undercut: the pitch curve bends towards the material with radius {rho:.4} mm at x = {at:.3} mm, \
             tighter than the roller radius {r} mm; the roller cannot follow for x in {}",
            if spans.is_empty() { "a short stretch".to_string() } else { spans.join(", ") }
        ),
        (Some((rho, at)), _) => format!(
            "smallest pitch-curve radius on the material side {rho:.4} mm at x = {at:.3} mm (roller radius {r} mm)"
        ),
    };
    let advice = (input.advise && status != Status::Pass).then(|| {
        let f = input.follower;
        let wanted = UNDERCUT_WARN_RATIO * r;
        let by_preload = first_crossing(f.preload_mm, preload_candidates(f.preload_mm, input.xmax_mm), |yp| {
            metrics(input, &f.with_preload(yp)).map_or(f64::NAN, |m| wanted - m.min_material_radius_mm)
        })
        .map(round_up);
        let by_roller = rho.map(|(rho, _)| round_down(rho / UNDERCUT_WARN_RATIO));
        let mut parts = Vec::new();
        let mut suggestions = Vec::new();
        if let Some(yp) = by_preload {
            parts.push(format!(
                "raise follower.preload from {} to at least {yp} mm (the smallest preload that removes the undercut with {:.0} % margin)",
                short(f.preload_mm),
                (UNDERCUT_WARN_RATIO - 1.0) * 100.0
            ));
            suggestions.push(Suggestion { key: "follower.preload", value: yp, unit: "mm" });
        }
        if let Some(rr) = by_roller {
            parts.push(format!("use a roller radius of at most {rr} mm"));
            suggestions.push(Suggestion { key: "follower.roller_radius", value: rr, unit: "mm" });
        }
        Advice { text: capitalise(parts.join(", or ")) + ".", suggestions }
    });
    let (advice, suggestions) = advice_fields(advice);
    Check {
        name: "undercut",
        status,
        value: rho.map(|r| r.0),
        limit: r,
        unit: "mm",
        at_x_mm: rho.map(|r| r.1),
        message,
        advice,
        suggestions,
    }
}

fn cutter_fit(input: &CheckInput<'_>) -> Check {
    let tool = input.tool_radius_mm;
    let concave = input.surface.min_concave_radius(input.pitch);
    let status = match concave {
        Some((rad, _)) if rad < tool => Status::Fail,
        _ => Status::Pass,
    };
    let message = match concave {
        None => format!("the cam surface has no concave part; any cutter fits (tool radius {tool} mm)"),
        Some((rad, at)) => format!(
            "smallest concave radius of the cam surface {rad:.4} mm at x = {at:.3} mm: cutters up to {:.3} mm diameter fit (tool radius {tool} mm)",
            2.0 * rad
        ),
    };
    let advice = (input.advise && status == Status::Fail).then(|| {
        let d = round_down(2.0 * concave.map_or(0.0, |c| c.0));
        Advice {
            text: format!(
                "Use an end mill of at most {d} mm diameter, or a larger roller (the concave radius is the pitch radius plus the roller radius)."
            ),
            suggestions: vec![Suggestion { key: "machining.tool_diameter", value: d, unit: "mm" }],
        }
    });
    let (advice, suggestions) = advice_fields(advice);
    Check {
        name: "cutter_fit",
        status,
        value: concave.map(|c| c.0),
        limit: tool,
        unit: "mm",
        at_x_mm: concave.map(|c| c.1),
        message,
        advice,
        suggestions,
    }
}

fn contact_stress(input: &CheckInput<'_>) -> Check {
    let limit = input.limits.max_contact_stress_mpa;
    let unbounded = input.forces.iter().find(|f| f.contact_stress_mpa.is_none());
    let worst = input
        .forces
        .iter()
        .filter_map(|f| f.contact_stress_mpa.map(|p| (p, f.x_mm)))
        .fold(None, |m: Option<(f64, f64)>, v| match m {
            Some(m) if m.0 >= v.0 => Some(m),
            _ => Some(v),
        });
    if let Some(at) = unbounded {
        return Check {
            name: "contact_stress",
            status: Status::Fail,
            value: None,
            limit,
            unit: "MPa",
            at_x_mm: Some(at.x_mm),
            message: format!(
                "contact stress is unbounded at x = {:.3} mm (knife-edge follower, folded surface, or jammed followers)",
                at.x_mm
            ),
            advice: Some("Use a roller (roller_radius > 0) and clear the undercut and self-locking checks first.".into()),
            suggestions: Vec::new(),
        };
    }
    let (p, at) = worst.unwrap_or((0.0, 0.0));
    let status = if p > limit {
        Status::Fail
    } else if p > CONTACT_WARN_FRACTION * limit {
        Status::Warn
    } else {
        Status::Pass
    };
    let advice = (input.advise && status != Status::Pass).then(|| contact_advice(input, p));
    let (advice, suggestions) = advice_fields(advice);
    Check {
        name: "contact_stress",
        status,
        value: Some(p),
        limit,
        unit: "MPa",
        at_x_mm: Some(at),
        message: format!(
            "peak Hertz line-contact pressure {p:.1} MPa at x = {at:.3} mm (limit {limit:.1} MPa)"
        ),
        advice,
        suggestions,
    }
}

/// A present value as advice quotes it: at most four decimals, trailing zeros dropped.
fn short(v: f64) -> String {
    let t = format!("{v:.4}");
    let t = t.trim_end_matches('0').trim_end_matches('.');
    t.to_string()
}
