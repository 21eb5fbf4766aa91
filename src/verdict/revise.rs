//! `camspring revise`: a revision of the design that meets the original law with the parts
//! as built, from a [`Diagnosis`].
//!
//! Options are tried cheapest first, each predicted with the design's forward model for the
//! parts as diagnosed (spring rate, preload and contact friction; the rig's encoder zero is
//! not a part and plays no role):
//!
//! 1. **Shim**: the existing cam and springs with a new preload. The force is linear in the
//!    preload, F = A(x) + dYp B(x), so the shim that minimises the relative force error over
//!    the stroke is a closed form; it is rounded to 0.01 mm.
//! 2. **Catalogue spring**: each spring of the spec's catalogue on the existing cam, each
//!    with its best shim, within the spring's travel.
//! 3. **Re-cut cam**: the cam re-synthesised for the springs, preload and friction as built,
//!    which meets the law on its corrected stroke by construction, and is checked like any
//!    design.
//!
//! An option passes when its predicted force on the corrected stroke is within the tolerance
//! of the law everywhere on the stroke and no design check fails. The first that passes is
//! chosen; when none does, the revision is refused with each option's reason.

use serde::Serialize;

use super::diagnose::{AsBuilt, BuildParam, Diagnosis};
use crate::cam::checks::{run_checks, Check, CheckInput, Status};
use crate::cam::forces::{contact_modulus_mpa, predict, ContactModel};
use crate::cam::tolerance::{build_force_at, Build};
use crate::design::{design_with, synthesis_options, Design};
use crate::model::{FrictionCorrection, FrictionSource, Spec};

/// Stations along the stroke where the predicted force is compared with the law.
pub const STATIONS: usize = 101;

/// Shims are made to this step (mm).
pub const SHIM_STEP_MM: f64 = 0.01;

/// The kind of change an option makes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ChangeKind {
    /// A new preload (shim) on the existing cam and springs.
    Shim,
    /// A catalogue spring, with its shim, on the existing cam.
    CatalogueSpring,
    /// A cam re-synthesised for the parts as built.
    RecutCam,
}

impl ChangeKind {
    /// The option's name in words.
    pub fn name(self) -> &'static str {
        match self {
            ChangeKind::Shim => "shim",
            ChangeKind::CatalogueSpring => "catalogue spring",
            ChangeKind::RecutCam => "re-cut cam",
        }
    }
}

/// One check of an option, in brief.
#[derive(Debug, Clone, Serialize)]
pub struct CheckBrief {
    /// Check name.
    pub name: &'static str,
    /// Its status.
    pub status: Status,
    /// What was found.
    pub message: String,
    /// What to change, when it does not pass.
    pub advice: Option<String>,
}

impl From<&Check> for CheckBrief {
    fn from(c: &Check) -> CheckBrief {
        CheckBrief {
            name: c.name,
            status: c.status,
            message: c.message.clone(),
            advice: c.advice.clone(),
        }
    }
}

/// One option of the revision.
#[derive(Debug, Clone, Serialize)]
pub struct RevisionOption {
    /// What kind of change.
    pub kind: ChangeKind,
    /// The change in words.
    pub change: String,
    /// The shim added to the present assembly (mm of follower travel; shim and catalogue).
    pub shim_mm: Option<f64>,
    /// The spring rate fitted (N/mm; catalogue) or the cam is cut for (re-cut).
    pub spring_rate_n_per_mm: Option<f64>,
    /// The catalogue part.
    pub spring_part: Option<String>,
    /// Predicted largest relative force error on the corrected stroke after the change (%),
    /// the largest over the parts as diagnosed and [`UNCERTAINTY_SIGMAS`] standard deviations
    /// off them in each of spring rate, preload and friction.
    pub predicted_error_max_percent: f64,
    /// Predicted RMS relative force error after the change (%).
    pub predicted_error_rms_percent: f64,
    /// Every design check with the change.
    pub checks: Vec<CheckBrief>,
    /// Whether it meets the law within the tolerance with no failing check.
    pub passes: bool,
    /// Why it does not pass.
    pub why_not: Option<String>,
    /// The revised spec (the cam is re-synthesised only for a re-cut).
    #[serde(skip)]
    pub spec: Spec,
}

impl RevisionOption {
    /// The parts of a build (`as_built`, against `original`'s follower) once this option is
    /// applied to it, described against the option's own spec: the same springs and friction
    /// with the shim added, a catalogue spring at its nominal rate, or the same parts on a
    /// re-cut cam. The rig's zero is kept. This is what `simulate` builds to check a revision
    /// with the parts as they really are, not as diagnosed.
    pub fn parts_as_built(&self, original: &Spec, as_built: &AsBuilt) -> AsBuilt {
        let (from, to) = (&original.follower, &self.spec.follower);
        let rate_n_per_mm = match (self.kind, self.spring_rate_n_per_mm) {
            (ChangeKind::CatalogueSpring, Some(k)) => k,
            _ => from.spring_rate_n_per_mm * as_built.spring_rate_scale,
        };
        let preload_mm = from.preload_mm + as_built.preload_offset_mm + self.shim_mm.unwrap_or(0.0);
        AsBuilt {
            spring_rate_scale: rate_n_per_mm / to.spring_rate_n_per_mm,
            preload_offset_mm: preload_mm - to.preload_mm,
            ..*as_built
        }
    }
}

/// The revision: every option tried, the chosen one, or why none.
#[derive(Debug, Clone, Serialize)]
pub struct Revision {
    /// The revision letter given to the revised spec.
    pub revision: String,
    /// The predicted force error of the build as it is (%), largest and RMS.
    pub error_as_built_max_percent: f64,
    /// RMS (%).
    pub error_as_built_rms_percent: f64,
    /// The tolerance an option must meet (%).
    pub tolerance_percent: f64,
    /// Options in the order tried.
    pub options: Vec<RevisionOption>,
    /// Index of the chosen option.
    pub chosen: Option<usize>,
    /// Why no revision is written, when none is.
    pub refusal: Option<String>,
    /// The note written into the revised spec.
    pub note: String,
}

impl Revision {
    /// The chosen option.
    pub fn chosen(&self) -> Option<&RevisionOption> {
        self.chosen.and_then(|i| self.options.get(i))
    }
}

/// The relative force error of a build on the design's corrected stroke: (largest, RMS), in
/// percent, over [`STATIONS`] stations. A jammed loading stroke is an infinite error.
pub fn force_error(
    design: &Design,
    follower: &crate::model::Follower,
    build: &Build,
) -> (f64, f64) {
    let xmax = design.xmax_mm();
    let law = &design.law.law;
    let (mut max, mut sq) = (0.0_f64, 0.0);
    for j in 0..STATIONS {
        let x = xmax * j as f64 / (STATIONS - 1) as f64;
        let (l, u) = build_force_at(&design.pitch_curve, follower, build, x);
        let Some(l) = l else {
            return (f64::INFINITY, f64::INFINITY);
        };
        let f = corrected_stroke(design.spec.follower.friction_correction, l, u);
        let target = law.force_n(x);
        let e = (f - target) / target;
        max = max.max(e.abs());
        sq += e * e;
    }
    (100.0 * max, 100.0 * (sq / STATIONS as f64).sqrt())
}

/// The force error of `build` as [`force_error`], and of the builds two standard deviations
/// off it in each of spring rate, preload and friction (`sigmas`, in [`Build`]'s terms): the
/// largest of them, so that a prediction carries what the diagnosis does not know.
fn uncertain_error(
    design: &Design,
    follower: &crate::model::Follower,
    build: &Build,
    sigmas: [f64; 3],
) -> (f64, f64) {
    let (mut max, mut rms) = force_error(design, follower, build);
    for (i, &s) in sigmas.iter().enumerate() {
        if !(s.is_finite() && s > 0.0) {
            continue;
        }
        for k in [-UNCERTAINTY_SIGMAS, UNCERTAINTY_SIGMAS] {
            let mut b = *build;
            match i {
                0 => b.rate += k * s,
                1 => b.preload_mm += k * s,
                _ => b.friction = (b.friction + k * s).max(0.0),
            }
            let (m, r) = force_error(design, follower, &b);
            max = max.max(m);
            rms = rms.max(r);
        }
    }
    (max, rms)
}

/// Standard deviations of the diagnosed parts a prediction allows for.
pub const UNCERTAINTY_SIGMAS: f64 = 2.0;

/// The force the design makes follow the law: loading, unloading, or their mean.
fn corrected_stroke(correction: FrictionCorrection, loading: f64, unloading: f64) -> f64 {
    match correction {
        FrictionCorrection::Loading => loading,
        FrictionCorrection::Unloading => unloading,
        FrictionCorrection::Midline | FrictionCorrection::None => 0.5 * (loading + unloading),
    }
}

/// The preload change that minimises the relative force error of `build` on the existing cam
/// (least squares; the force is linear in it), no lower than what leaves the spring unloaded,
/// rounded to [`SHIM_STEP_MM`].
fn best_shim(design: &Design, build: &Build) -> f64 {
    let follower = &design.spec.follower;
    let xmax = design.xmax_mm();
    let law = &design.law.law;
    let (mut num, mut den) = (0.0, 0.0);
    for j in 0..STATIONS {
        let x = xmax * j as f64 / (STATIONS - 1) as f64;
        let at = |shim: f64| {
            let b = Build {
                preload_mm: build.preload_mm + shim,
                ..*build
            };
            let (l, u) = build_force_at(&design.pitch_curve, follower, &b, x);
            corrected_stroke(follower.friction_correction, l.unwrap_or(f64::NAN), u)
        };
        let (f0, f1) = (at(0.0), at(1.0));
        let (a, b) = (f0, f1 - f0);
        let target = law.force_n(x);
        if !(a.is_finite() && b.is_finite()) {
            continue;
        }
        let w = 1.0 / (target * target);
        num += w * (target - a) * b;
        den += w * b * b;
    }
    let shim = if den > 0.0 { num / den } else { 0.0 };
    let lowest = -(follower.preload_mm + build.preload_mm);
    ((shim.max(lowest) / SHIM_STEP_MM).round() * SHIM_STEP_MM).max(lowest)
}

/// The design checks of the existing cam with another follower (springs, preload, friction).
fn checks_on_existing_cam(design: &Design, follower: &crate::model::Follower) -> Vec<Check> {
    let spec = &design.spec;
    let contact = ContactModel {
        e_star_mpa: contact_modulus_mpa(&spec.part.cam_material, &spec.part.roller_material),
        length_mm: spec.part.contact_length_mm(),
    };
    let forces = predict(
        &design.law.law,
        follower,
        &design.pitch_curve,
        &design.cam_surface,
        &contact,
    );
    run_checks(&CheckInput {
        law: &design.law.law,
        follower,
        xmax_mm: design.xmax_mm(),
        options: synthesis_options(spec),
        limits: &spec.checks,
        plate_thickness_mm: spec.part.thickness_mm,
        roller_width_mm: spec.part.roller_width_mm,
        contact,
        advise: false,
        tool_radius_mm: spec.machining.tool_diameter_mm / 2.0,
        pitch: &design.pitch_curve,
        surface: &design.cam_surface,
        forces: &forces,
    })
}

/// The follower as assembled with `build` on the cam cut for `design`'s follower.
fn assembled_follower(design: &Design, build: &Build) -> crate::model::Follower {
    let f = design.spec.follower;
    crate::model::Follower {
        spring_rate_n_per_mm: f.spring_rate_n_per_mm * (1.0 + build.rate),
        preload_mm: f.preload_mm + build.preload_mm,
        friction: FrictionSource::Coefficient {
            coefficient: build.friction,
        },
        ..f
    }
}

/// Judges an option: within the tolerance, and no check fails.
fn judge(option: &mut RevisionOption, tolerance_percent: f64) {
    let failing: Vec<&CheckBrief> = option
        .checks
        .iter()
        .filter(|c| c.status == Status::Fail)
        .collect();
    let within = option.predicted_error_max_percent <= tolerance_percent;
    option.passes = within && failing.is_empty();
    option.why_not = if option.passes {
        None
    } else if !failing.is_empty() {
        Some(
            failing
                .iter()
                .map(|c| {
                    format!(
                        "{} fails: {}{}",
                        c.name,
                        c.message,
                        c.advice
                            .as_ref()
                            .map_or(String::new(), |a| format!(" ({a})"))
                    )
                })
                .collect::<Vec<_>>()
                .join("; "),
        )
    } else {
        Some(format!(
            "the force would still be up to {:.2} % off the law (tolerance {:.2} %)",
            option.predicted_error_max_percent, tolerance_percent
        ))
    };
}

/// The next revision letter after `current` (none: "B", the first revision of "A").
pub fn next_revision(current: Option<&str>) -> String {
    match current.map(str::trim) {
        None | Some("") => "B".into(),
        Some(r) => {
            let mut chars: Vec<char> = r.chars().collect();
            match chars.last_mut() {
                Some(c) if c.is_ascii_uppercase() && *c != 'Z' => {
                    *c = (*c as u8 + 1) as char;
                    chars.into_iter().collect()
                }
                Some(c) if c.is_ascii_digit() && *c != '9' => {
                    *c = (*c as u8 + 1) as char;
                    chars.into_iter().collect()
                }
                _ => format!("{r}-1"),
            }
        }
    }
}

/// Why a log's diagnosis cannot support a revision: a part parameter it does not resolve.
pub fn unresolved_parts(d: &Diagnosis) -> Vec<String> {
    [
        BuildParam::SpringRate,
        BuildParam::Preload,
        BuildParam::Friction,
    ]
    .into_iter()
    .filter(|&p| !d.get(p).resolved)
    .map(|p| p.key().to_string())
    .collect()
}

/// Revises `design` for the parts `diagnosis` found, within `tolerance` (relative).
pub fn revise(design: &Design, diagnosis: &Diagnosis, tolerance: f64) -> Revision {
    let spec = &design.spec;
    let tolerance_percent = 100.0 * tolerance;
    let revision = next_revision(spec.revision.as_deref().or(Some(&spec.drawing.revision)));
    let built = AsBuilt {
        zero_offset_mm: 0.0,
        ..diagnosis.as_built()
    }
    .build();
    let (err_max, err_rms) = force_error(design, &spec.follower, &built);
    let sigmas = [
        diagnosis.spring_rate_scale.std,
        diagnosis.preload_offset_mm.std,
        diagnosis.friction.std,
    ];
    let ks = spec.follower.spring_rate_n_per_mm;
    let mut options = Vec::new();

    // 1. A shim on the existing cam and springs.
    {
        let shim = best_shim(design, &built);
        let b = Build {
            preload_mm: built.preload_mm + shim,
            ..built
        };
        let (max, rms) = uncertain_error(design, &spec.follower, &b, sigmas);
        // The revised spec says what is installed: the springs and the friction as measured,
        // with the new shim.
        let mut revised = spec.clone();
        revised.assembly.shim_mm = built.preload_mm + shim;
        revised.assembly.spring_rate_n_per_mm = Some(ks * (1.0 + built.rate));
        revised.assembly.friction = Some(built.friction);
        let mut o = RevisionOption {
            kind: ChangeKind::Shim,
            change: format!(
                "{} the preload by {:.2} mm of follower travel ({} shim), keeping the cam and the springs",
                if shim >= 0.0 { "raise" } else { "lower" },
                shim.abs(),
                if shim >= 0.0 { "add a" } else { "remove" }
            ),
            shim_mm: Some(shim),
            spring_rate_n_per_mm: None,
            spring_part: None,
            predicted_error_max_percent: max,
            predicted_error_rms_percent: rms,
            checks: checks_on_existing_cam(design, &assembled_follower(design, &b))
                .iter()
                .map(CheckBrief::from)
                .collect(),
            passes: false,
            why_not: None,
            spec: revised,
        };
        judge(&mut o, tolerance_percent);
        options.push(o);
    }

    // 2. Each catalogue spring on the existing cam, with its best shim; the best one that
    //    fits its travel.
    if let Some(catalogue) = &spec.spring_catalogue {
        let mut best: Option<RevisionOption> = None;
        for c in &catalogue.springs {
            let b0 = Build {
                rate: c.rate_n_per_mm / ks - 1.0,
                ..built
            };
            let shim = best_shim(design, &b0);
            let b = Build {
                preload_mm: built.preload_mm + shim,
                ..b0
            };
            let follower = assembled_follower(design, &b);
            let (_, deflection) = follower.springs(design.pitch_curve.lift_mm());
            // A catalogue spring's rate is its nominal one: only the preload and the friction
            // carry the diagnosis's uncertainty.
            let (max, rms) =
                uncertain_error(design, &spec.follower, &b, [0.0, sigmas[1], sigmas[2]]);
            let mut revised = spec.clone();
            revised.assembly.shim_mm = built.preload_mm + shim;
            revised.assembly.spring_rate_n_per_mm = Some(c.rate_n_per_mm);
            revised.assembly.spring_part = Some(c.part.clone());
            revised.assembly.friction = Some(built.friction);
            let mut o = RevisionOption {
                kind: ChangeKind::CatalogueSpring,
                change: format!(
                    "fit catalogue spring {} ({} N/mm) with the preload {} by {:.2} mm, keeping the cam",
                    c.part,
                    c.rate_n_per_mm,
                    if shim >= 0.0 { "raised" } else { "lowered" },
                    shim.abs()
                ),
                shim_mm: Some(shim),
                spring_rate_n_per_mm: Some(c.rate_n_per_mm),
                spring_part: Some(c.part.clone()),
                predicted_error_max_percent: max,
                predicted_error_rms_percent: rms,
                checks: checks_on_existing_cam(design, &follower)
                    .iter()
                    .map(CheckBrief::from)
                    .collect(),
                passes: false,
                why_not: None,
                spec: revised,
            };
            judge(&mut o, tolerance_percent);
            if o.passes && deflection > c.max_deflection_mm {
                o.passes = false;
                o.why_not = Some(format!(
                    "it would deflect {deflection:.2} mm at the full stroke, beyond its {} mm",
                    c.max_deflection_mm
                ));
            }
            let better = match &best {
                None => true,
                Some(b) => {
                    (o.passes, -o.predicted_error_max_percent)
                        > (b.passes, -b.predicted_error_max_percent)
                }
            };
            if better {
                best = Some(o);
            }
        }
        options.extend(best);
    }

    // 3. A cam re-cut for the parts as built.
    {
        let mut revised = spec.clone();
        revised.follower.spring_rate_n_per_mm = ks * (1.0 + built.rate);
        revised.follower.preload_mm = spec.follower.preload_mm + built.preload_mm;
        revised.follower.friction = FrictionSource::Coefficient {
            coefficient: built.friction,
        };
        revised.assembly = crate::model::Assembly::default();
        let mut o = RevisionOption {
            kind: ChangeKind::RecutCam,
            change: format!(
                "re-cut the cam for springs of {:.3} N/mm, a preload of {:.3} mm and a contact friction of {:.4}, as built",
                revised.follower.spring_rate_n_per_mm,
                revised.follower.preload_mm,
                built.friction
            ),
            shim_mm: None,
            spring_rate_n_per_mm: Some(revised.follower.spring_rate_n_per_mm),
            spring_part: None,
            predicted_error_max_percent: f64::INFINITY,
            predicted_error_rms_percent: f64::INFINITY,
            checks: Vec::new(),
            passes: false,
            why_not: None,
            spec: revised.clone(),
        };
        match design_with(&revised, true) {
            Ok(d) => {
                let nominal = AsBuilt::nominal(&d.spec.follower).build();
                // The springs' rate is known to its standard deviation relative to the rate
                // the cam is cut for.
                let relative = [sigmas[0] / (1.0 + built.rate), sigmas[1], sigmas[2]];
                let (max, rms) = uncertain_error(&d, &d.spec.follower, &nominal, relative);
                o.predicted_error_max_percent = max;
                o.predicted_error_rms_percent = rms;
                o.checks = d.checks.iter().map(CheckBrief::from).collect();
                judge(&mut o, tolerance_percent);
            }
            Err(e) => {
                o.why_not = Some(format!("no cam can be synthesised for these parts: {e}"));
            }
        }
        options.push(o);
    }

    let chosen = options.iter().position(|o| o.passes);
    let refusal = chosen.is_none().then(|| {
        format!(
            "no option meets the law within {tolerance_percent:.2} % within physical limits: {}",
            options
                .iter()
                .map(|o| format!(
                    "{}: {}",
                    o.kind.name(),
                    o.why_not.as_deref().unwrap_or("does not pass")
                ))
                .collect::<Vec<_>>()
                .join("; ")
        )
    });
    let findings = if diagnosis.findings.is_empty() {
        "no deviation beyond its uncertainty".to_string()
    } else {
        diagnosis.findings.join("; ")
    };
    let note = match chosen.and_then(|i| options.get(i)) {
        Some(o) => format!(
            "Revision {revision}: {}. Why: the build as calibrated ({findings}) misses the law by up to {err_max:.2} %; \
             predicted after the change: {:.2} % (largest), {:.2} % (RMS).",
            o.change, o.predicted_error_max_percent, o.predicted_error_rms_percent
        ),
        None => String::new(),
    };
    for o in &mut options {
        o.spec.revision = Some(revision.clone());
        o.spec.drawing.revision = revision.clone();
        o.spec.revision_note = Some(note.clone());
    }
    Revision {
        revision,
        error_as_built_max_percent: err_max,
        error_as_built_rms_percent: err_rms,
        tolerance_percent,
        options,
        chosen,
        refusal,
        note,
    }
}
