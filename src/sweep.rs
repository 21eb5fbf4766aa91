//! `camspring sweep`: a grid of follower designs around one spec, run in parallel (rayon), so a
//! designer can pick a makeable combination of spring rate, preload, roller and friction.
//!
//! Each axis is `key=a..b` (10 values from a to b), `key=a..b:n` (n values) or `key=v1,v2,...`,
//! in the spec's default units: `spring_rate` (N/mm), `preload` (mm), `roller_radius` (mm),
//! `friction` (contact coefficient). Every grid point runs the full design (law, cam synthesis,
//! the five checks); `sweep.csv` has one row per point and `sweep.svg` plots the largest
//! pressure angle, the lift and the peak contact stress against the first axis, one line per
//! value of the second.

use rayon::prelude::*;
use serde::Serialize;

use crate::cam::checks::Status;
use crate::model::{ChecksSpec, FrictionSource, Material, Spec, MATERIALS};

/// The most designs one sweep runs.
pub const MAX_POINTS: usize = 10_000;

/// A follower setting the sweep can vary.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SweepKey {
    /// `follower.spring_rate` (N/mm).
    SpringRate,
    /// `follower.preload` (mm).
    Preload,
    /// `follower.roller_radius` (mm).
    RollerRadius,
    /// `follower.friction` (coefficient).
    Friction,
    /// `part.thickness` (mm); a roller as wide as the plate follows it.
    Thickness,
    /// `part.roller_width` (mm).
    RollerWidth,
    /// `part.cam_material`: preset names, by their index in [`MATERIALS`].
    CamMaterial,
}

impl SweepKey {
    /// Name and unit as used in CSV headers.
    pub fn column(self) -> &'static str {
        match self {
            SweepKey::SpringRate => "spring_rate_n_per_mm",
            SweepKey::Preload => "preload_mm",
            SweepKey::RollerRadius => "roller_radius_mm",
            SweepKey::Friction => "friction",
            SweepKey::Thickness => "thickness_mm",
            SweepKey::RollerWidth => "roller_width_mm",
            SweepKey::CamMaterial => "cam_material",
        }
    }

    /// Axis label with unit.
    pub fn label(self) -> &'static str {
        match self {
            SweepKey::SpringRate => "spring rate ks (N/mm)",
            SweepKey::Preload => "preload Yp (mm)",
            SweepKey::RollerRadius => "roller radius r (mm)",
            SweepKey::Friction => "friction coefficient",
            SweepKey::Thickness => "plate thickness (mm)",
            SweepKey::RollerWidth => "roller width (mm)",
            SweepKey::CamMaterial => "cam material (preset number)",
        }
    }

    fn apply(self, spec: &mut Spec, v: f64) {
        let f = &mut spec.follower;
        match self {
            SweepKey::SpringRate => f.spring_rate_n_per_mm = v,
            SweepKey::Preload => f.preload_mm = v,
            SweepKey::RollerRadius => f.roller_radius_mm = v,
            SweepKey::Friction => f.friction = FrictionSource::Coefficient { coefficient: v },
            SweepKey::Thickness => spec.part = spec.part.clone().with_thickness(v),
            SweepKey::RollerWidth => spec.part.roller_width_mm = v,
            SweepKey::CamMaterial => {
                let row = MATERIALS.get(v as usize).unwrap_or(&MATERIALS[0]);
                if let Some(m) = Material::preset(row.0) {
                    spec.part.cam_material = m;
                }
                // The contact limit follows the weaker of the materials, as in a spec file.
                spec.checks.max_contact_stress_mpa =
                    ChecksSpec::for_materials(&spec.part.cam_material, &spec.part.roller_material)
                        .max_contact_stress_mpa;
            }
        }
    }

    /// How a value of this axis is written: a preset's name for the material, else the number.
    pub fn value_text(self, v: f64) -> String {
        match self {
            SweepKey::CamMaterial => MATERIALS
                .get(v as usize)
                .map_or_else(|| v.to_string(), |m| m.0.to_string()),
            _ => v.to_string(),
        }
    }
}

/// One axis of the grid.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Axis {
    /// What varies.
    pub key: SweepKey,
    /// Its values.
    pub values: Vec<f64>,
}

/// Parses `key=a..b`, `key=a..b:n` or `key=v1,v2,...`.
pub fn parse_axis(text: &str) -> Result<Axis, String> {
    let (name, spec) = text
        .split_once('=')
        .ok_or_else(|| format!("--vary {text}: expected KEY=A..B, KEY=A..B:N or KEY=V1,V2,..."))?;
    let key = match name.trim() {
        "spring_rate" => SweepKey::SpringRate,
        "preload" => SweepKey::Preload,
        "roller_radius" => SweepKey::RollerRadius,
        "friction" => SweepKey::Friction,
        "thickness" => SweepKey::Thickness,
        "roller_width" => SweepKey::RollerWidth,
        "cam_material" => SweepKey::CamMaterial,
        other => {
            return Err(format!(
                "--vary {text}: unknown key \"{other}\" (keys: spring_rate, preload, roller_radius, friction, thickness, roller_width, cam_material)"
            ))
        }
    };
    if key == SweepKey::CamMaterial {
        // Names of presets, not numbers.
        let values = spec
            .split(',')
            .map(|name| {
                MATERIALS
                    .iter()
                    .position(|m| m.0 == name.trim())
                    .map(|i| i as f64)
                    .ok_or_else(|| {
                        let names: Vec<&str> = MATERIALS.iter().map(|m| m.0).collect();
                        format!(
                            "--vary {text}: unknown material \"{}\" (presets: {})",
                            name.trim(),
                            names.join(", ")
                        )
                    })
            })
            .collect::<Result<Vec<f64>, String>>()?;
        return Ok(Axis { key, values });
    }
    let number = |s: &str| {
        s.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("--vary {text}: \"{}\" is not a number", s.trim()))
    };
    let values = if let Some((range, count)) = spec.split_once("..").map(|(a, rest)| {
        let (b, n) = rest.split_once(':').unwrap_or((rest, "10"));
        ((a, b), n)
    }) {
        let (a, b) = (number(range.0)?, number(range.1)?);
        let n: usize = count
            .trim()
            .parse()
            .ok()
            .filter(|n| (2..=200).contains(n))
            .ok_or_else(|| format!("--vary {text}: the count \"{count}\" must be 2 to 200"))?;
        (0..n)
            .map(|i| a + (b - a) * i as f64 / (n - 1) as f64)
            .collect()
    } else {
        spec.split(',').map(number).collect::<Result<Vec<_>, _>>()?
    };
    Ok(Axis { key, values })
}

/// Checks every value of every axis against the spec's own rules ([`Spec::validate`]), so a
/// sweep refuses exactly what a spec file would, naming the key.
pub fn check_axes(spec: &Spec, axes: &[Axis]) -> Result<(), String> {
    let points: usize = axes.iter().map(|a| a.values.len()).product();
    if points > MAX_POINTS {
        return Err(format!(
            "the axes make {points} designs; expected at most {MAX_POINTS} (fewer values per --vary)"
        ));
    }
    for (i, axis) in axes.iter().enumerate() {
        if axes[..i].iter().any(|a| a.key == axis.key) {
            return Err(format!(
                "--vary {} is given twice; expected each key once (up to 3 different keys)",
                axis.key.column()
            ));
        }
        for &v in &axis.values {
            let mut s = spec.clone();
            axis.key.apply(&mut s, v);
            s.validate()
                .map_err(|e| format!("--vary {}={v}: {e}", axis.key.column()))?;
        }
    }
    Ok(())
}

/// What one grid point gave.
#[derive(Debug, Clone, Serialize)]
pub struct PointResult {
    /// Overall status of the checks.
    pub status: Status,
    /// Follower lift at Xmax (mm).
    pub lift_mm: f64,
    /// Largest pressure angle (deg).
    pub max_pressure_angle_deg: f64,
    /// Peak Hertz contact stress (MPa).
    pub max_contact_stress_mpa: Option<f64>,
    /// Names of the failing checks.
    pub failed_checks: Vec<&'static str>,
    /// Names of the checks that warn.
    pub warned_checks: Vec<&'static str>,
}

/// One grid point: its axis values and the design's result or why there is none.
#[derive(Debug, Clone, Serialize)]
pub struct SweepPoint {
    /// Axis values, in axis order.
    pub values: Vec<f64>,
    /// The result, or the error that stopped the design.
    pub result: Result<PointResult, String>,
}

/// Runs the design at every point of the grid (all combinations of the axes), in parallel.
/// `progress` is called from the workers after each point.
pub fn sweep(
    spec: &Spec,
    axes: &[Axis],
    advise: bool,
    progress: &(dyn Fn() + Sync),
) -> Vec<SweepPoint> {
    let mut grid: Vec<Vec<f64>> = vec![Vec::new()];
    for axis in axes {
        grid = grid
            .into_iter()
            .flat_map(|p| {
                axis.values.iter().map(move |&v| {
                    let mut q = p.clone();
                    q.push(v);
                    q
                })
            })
            .collect();
    }
    grid.into_par_iter()
        .map(|values| {
            let mut s = spec.clone();
            for (axis, &v) in axes.iter().zip(&values) {
                axis.key.apply(&mut s, v);
            }
            let result = crate::design::design_with(&s, advise)
                .map(|d| PointResult {
                    status: d.status(),
                    lift_mm: d.pitch_curve.lift_mm(),
                    max_pressure_angle_deg: d.pitch_curve.max_pressure_angle().0,
                    max_contact_stress_mpa: d.max_contact_stress_mpa(),
                    failed_checks: d
                        .checks
                        .iter()
                        .filter(|c| c.status == Status::Fail)
                        .map(|c| c.name)
                        .collect(),
                    warned_checks: d
                        .checks
                        .iter()
                        .filter(|c| c.status == Status::Warn)
                        .map(|c| c.name)
                        .collect(),
                })
                .map_err(|e| e.to_string());
            progress();
            SweepPoint { values, result }
        })
        .collect()
}

/// How one catalogue spring realises the design.
#[derive(Debug, Clone, Serialize)]
pub struct SpringChoice {
    /// The catalogue's spring.
    pub spring: crate::model::CatalogueSpring,
    /// The preload it needs (mm): the smallest that passes the checks, or that only warns;
    /// null when none works within its travel.
    pub preload_mm: Option<f64>,
    /// The re-synthesised design's status at that preload.
    pub status: Option<Status>,
    /// The spring's deflection at the full stroke (mm).
    pub deflection_at_full_stroke_mm: Option<f64>,
    /// Travel left before the maker's limit (mm): the ranking.
    pub margin_mm: Option<f64>,
    /// Why it cannot, when it cannot.
    pub why: Option<String>,
}

/// Preloads tried per spring, from none to the spring's whole travel.
pub const PRELOAD_STEPS: usize = 40;

/// Ranks the spec's catalogue springs: for each, the design re-synthesised with its rate at
/// the smallest preload (on a grid of [`PRELOAD_STEPS`] over its travel) whose checks pass, or
/// else only warn, with the spring's deflection at the full stroke within its allowed travel
/// and above its solid length. Springs that work come first, passing before warning, then by
/// the travel they have left.
pub fn choose_springs(spec: &Spec) -> Vec<SpringChoice> {
    let Some(catalogue) = &spec.spring_catalogue else {
        return Vec::new();
    };
    let mut choices: Vec<SpringChoice> = catalogue
        .springs
        .par_iter()
        .map(|c| {
            let mut best: Option<(Status, f64, f64)> = None;
            let mut reason = "no preload within its travel gives a design whose checks pass";
            for k in 0..PRELOAD_STEPS {
                let preload = c.max_deflection_mm * k as f64 / PRELOAD_STEPS as f64;
                let mut s = spec.clone();
                s.follower.spring_rate_n_per_mm = c.rate_n_per_mm;
                s.follower.preload_mm = preload;
                let Ok(d) = crate::design::design_with(&s, false) else {
                    continue;
                };
                let status = d.status();
                if status == Status::Fail {
                    continue;
                }
                let (_, deflection) = s.follower.springs(d.pitch_curve.lift_mm());
                if deflection > c.max_deflection_mm
                    || c.free_length_mm - deflection < c.solid_length_mm
                {
                    reason = "the stroke needs more deflection than the spring allows";
                    break;
                }
                if best.is_none_or(|b| status < b.0) {
                    best = Some((status, preload, deflection));
                }
                if status == Status::Pass {
                    break;
                }
            }
            match best {
                Some((status, preload, deflection)) => SpringChoice {
                    spring: c.clone(),
                    preload_mm: Some(preload),
                    status: Some(status),
                    deflection_at_full_stroke_mm: Some(deflection),
                    margin_mm: Some(c.max_deflection_mm - deflection),
                    why: None,
                },
                None => SpringChoice {
                    spring: c.clone(),
                    preload_mm: None,
                    status: None,
                    deflection_at_full_stroke_mm: None,
                    margin_mm: None,
                    why: Some(reason.into()),
                },
            }
        })
        .collect();
    choices.sort_by(|a, b| {
        let key = |c: &SpringChoice| (c.status.is_none(), c.status.unwrap_or(Status::Fail));
        key(a).cmp(&key(b)).then(
            b.margin_mm
                .unwrap_or(f64::NEG_INFINITY)
                .total_cmp(&a.margin_mm.unwrap_or(f64::NEG_INFINITY)),
        )
    });
    choices
}
