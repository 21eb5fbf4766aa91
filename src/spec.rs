//! The TOML design spec: reading, unit conversion and validation.
//!
//! [`Spec::from_toml`] turns the text of a spec into a validated [`Spec`] whose every quantity
//! is in the default unit (mm, N, N/mm, 1/mm, deg, MPa) and carries that unit in its field
//! name. Every error names the key (`follower.spring_rate`), the line, the value found and what
//! was expected. Unknown keys are errors too, so a misspelt key never silently falls back to a
//! default. The built-in default spec is [`DEFAULT_SPEC_TOML`], a copy of `specs/paper.toml`.

use serde::{Deserialize, Serialize};
use toml::Spanned;

use crate::cam::follower::{
    Follower, FrictionCorrection, FrictionSource, SpringArrangement, MAX_FRICTION,
};
use crate::law::{ExpLaw, LawTargets};
use crate::units::{parse_quantity, Dimension, UnitError};

/// The commented starter spec that `camspring init` writes (a copy of `specs/starter.toml`).
pub const STARTER_SPEC_TOML: &str = include_str!("../specs/starter.toml");

/// The built-in default spec (`specs/paper.toml`): the paper's law on two opposed followers.
pub const DEFAULT_SPEC_TOML: &str = include_str!("../specs/paper.toml");

/// Why a spec was refused. Every variant names the key it is about.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpecError {
    /// Produced by [`Spec::from_toml`] for TOML syntax errors, unknown keys and wrong value
    /// types; the message from the TOML reader gives line, column and the key.
    #[error("{0}")]
    Toml(String),
    /// Produced by [`Spec::from_toml`] for a value of the wrong unit, out of range or not finite.
    #[error("{}`{key}` = {found}: expected {expected}", line_prefix(*.line))]
    Invalid {
        /// Dotted key path, e.g. `follower.spring_rate`.
        key: String,
        /// 1-based line of the value in the spec, when known.
        line: Option<usize>,
        /// The value as written.
        found: String,
        /// What would have been accepted.
        expected: String,
    },
    /// Produced by [`Spec::from_toml`] when a required key is absent.
    #[error("missing `{key}`: expected {expected}")]
    Missing {
        /// Dotted key path.
        key: String,
        /// What to write there.
        expected: String,
    },
}

fn line_prefix(line: Option<usize>) -> String {
    line.map(|l| format!("line {l}: ")).unwrap_or_default()
}

/// How the force law is given.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum LawSpec {
    /// Design targets, solved for the law (paper eq. 5).
    Targets(LawTargets),
    /// A known law, used as given over the stroke.
    Given {
        /// The law.
        law: ExpLaw,
        /// The stroke (maximum deflection).
        xmax_mm: f64,
    },
}

impl LawSpec {
    /// The maximum deflection of the stroke.
    pub fn xmax_mm(&self) -> f64 {
        match self {
            LawSpec::Targets(t) => t.xmax_mm,
            LawSpec::Given { xmax_mm, .. } => *xmax_mm,
        }
    }
}

/// An isotropic elastic material with the strength needed for the contact check.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Material {
    /// Name (a preset's name, or "custom").
    pub name: String,
    /// Young's modulus.
    pub youngs_modulus_mpa: f64,
    /// Poisson's ratio.
    pub poisson_ratio: f64,
    /// Tensile yield strength.
    pub yield_strength_mpa: f64,
}

/// Preset materials: name, E (MPa), Poisson's ratio, yield strength (MPa).
pub const MATERIALS: &[(&str, f64, f64, f64)] = &[
    ("aluminium-6061-t6", 68_900.0, 0.33, 276.0),
    ("aluminium-7075-t6", 71_700.0, 0.33, 503.0),
    ("steel-1045", 205_000.0, 0.29, 530.0),
    ("bearing-steel", 210_000.0, 0.30, 1_700.0),
    ("stainless-303", 193_000.0, 0.29, 240.0),
    ("brass-360", 97_000.0, 0.31, 310.0),
    ("acetal", 2_900.0, 0.35, 65.0),
];

impl Material {
    /// Looks up a preset by name ("aluminum" is accepted for "aluminium").
    pub fn preset(name: &str) -> Option<Material> {
        let canonical = name
            .trim()
            .to_ascii_lowercase()
            .replace("aluminum", "aluminium");
        MATERIALS
            .iter()
            .find(|m| m.0 == canonical)
            .map(|&(n, e, nu, sy)| Material {
                name: n.to_string(),
                youngs_modulus_mpa: e,
                poisson_ratio: nu,
                yield_strength_mpa: sy,
            })
    }
}

/// A through hole in the part (part coordinates: x along the stroke from the roller centre at
/// x = 0, y = 0 on the part's centre line for two followers or at the cam surface's start for one).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Hole {
    /// Centre x.
    pub x_mm: f64,
    /// Centre y.
    pub y_mm: f64,
    /// Diameter.
    pub diameter_mm: f64,
}

/// The part that carries the cam surface(s).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PartSpec {
    /// Plate thickness, which is also the cam face width.
    pub thickness_mm: f64,
    /// Width of the roller in contact (defaults to the thickness).
    pub roller_width_mm: f64,
    /// Cam material.
    pub cam_material: Material,
    /// Roller material.
    pub roller_material: Material,
    /// Straight run before x = 0, tangent to the cam surface there.
    pub lead_in_mm: f64,
    /// Straight over-travel run after Xmax, tangent to the cam surface there.
    pub run_out_mm: f64,
    /// Material under the lowest point of the cam edge (one follower), or the width of the cam
    /// between its two surfaces at their narrowest (two followers).
    pub web_mm: f64,
    /// Mounting holes.
    pub holes: Vec<Hole>,
}

/// The G-code dialect to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Dialect {
    /// LinuxCNC (rs274ngc).
    Linuxcnc,
    /// GRBL 1.1 (no tool change, short lines).
    Grbl,
    /// Fanuc-style (%, O number, G43, M30, upper-case comments).
    Fanuc,
}

/// Coolant command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Coolant {
    /// M8.
    Flood,
    /// M7.
    Mist,
    /// None.
    Off,
}

/// Machining settings: the cutter (which also decides what concave radius can be made) and
/// how the G-code mills the part.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MachiningSpec {
    /// End mill diameter.
    pub tool_diameter_mm: f64,
    /// Spindle speed.
    pub spindle_rpm: f64,
    /// Cutting feed.
    pub feed_mm_per_min: f64,
    /// Plunge feed.
    pub plunge_feed_mm_per_min: f64,
    /// Depth of each roughing pass.
    pub depth_per_pass_mm: f64,
    /// Material left by roughing for the finishing pass.
    pub stock_allowance_mm: f64,
    /// Height for rapid moves.
    pub safe_z_mm: f64,
    /// Top of the stock.
    pub stock_top_z_mm: f64,
    /// Cut below the part's bottom face.
    pub breakthrough_mm: f64,
    /// Largest deviation of the programmed path from the ideal tool-centre path.
    pub tolerance_mm: f64,
    /// Climb milling (with a clockwise spindle) instead of conventional.
    pub climb: bool,
    /// Radius of the tangential lead-in and lead-out arcs.
    pub lead_in_radius_mm: f64,
    /// G-code dialect.
    pub dialect: Dialect,
    /// Work offset (G54 ... G59).
    pub work_offset: String,
    /// Coolant.
    pub coolant: Coolant,
    /// G2/G3 arcs (false: G1 lines only, for controllers without arcs).
    pub arcs: bool,
    /// Holding tabs left on the outline's straight edges (0: none).
    pub tabs: usize,
    /// Width of each tab (the bridge left between part and stock).
    pub tab_width_mm: f64,
    /// Height of each tab above the part's bottom face.
    pub tab_height_mm: f64,
}

/// Limits for the design checks.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ChecksSpec {
    /// Largest acceptable pressure angle.
    pub max_pressure_angle_deg: f64,
    /// Smallest acceptable margin from self-locking (loading: 90 deg - (theta + phi);
    /// unloading: theta - phi).
    pub min_locking_margin_deg: f64,
    /// Largest acceptable Hertz contact pressure (default: 1.67 x the weaker yield strength,
    /// the onset of subsurface yield in a line contact).
    pub max_contact_stress_mpa: f64,
}

/// Output sampling settings.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OutputSpec {
    /// Largest chord error of the sampled pitch curve and cam surface polylines.
    pub chord_tolerance_mm: f64,
    /// Largest deviation of the STEP/DXF B-spline cam edge from the exact cam surface.
    pub fit_tolerance_mm: f64,
    /// Largest chord error of the STL mesh from the exact part.
    pub stl_tolerance_mm: f64,
}

/// A validated design spec in default units.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Spec {
    /// Design name (used for the default output folder).
    pub name: String,
    /// The force law, as targets or given.
    pub law: LawSpec,
    /// Follower arrangement, springs, roller and friction.
    pub follower: Follower,
    /// The part.
    pub part: PartSpec,
    /// Machining settings.
    pub machining: MachiningSpec,
    /// Check limits.
    pub checks: ChecksSpec,
    /// Output settings.
    pub output: OutputSpec,
}

// ---------------------------------------------------------------------------------------------
// Raw TOML shape

#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
enum RawValue {
    Number(f64),
    Text(String),
}

type Q = Option<Spanned<RawValue>>;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSpec {
    name: Option<Spanned<String>>,
    law: Option<RawLaw>,
    follower: Option<RawFollower>,
    part: Option<RawPart>,
    machining: Option<RawMachining>,
    checks: Option<RawChecks>,
    output: Option<RawOutput>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLaw {
    fmax: Q,
    fmin: Q,
    xmax: Q,
    l0: Q,
    c0: Q,
    delta0: Q,
    mu: Q,
    k2: Q,
    f0: Q,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFollower {
    count: Option<Spanned<i64>>,
    spring: Option<Spanned<String>>,
    spring_rate: Q,
    preload: Q,
    roller_radius: Q,
    friction: Q,
    pin_friction: Q,
    pin_radius: Q,
    rolling_resistance: Q,
    friction_correction: Option<Spanned<String>>,
}

/// A material: a preset name, or a table { youngs_modulus, poisson_ratio, yield_strength }.
type RawMaterial = Spanned<toml::Value>;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPart {
    thickness: Q,
    roller_width: Q,
    cam_material: Option<RawMaterial>,
    roller_material: Option<RawMaterial>,
    lead_in: Q,
    run_out: Q,
    web: Q,
    holes: Option<Vec<RawHole>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawHole {
    x: Q,
    y: Q,
    diameter: Q,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMachining {
    tool_diameter: Q,
    spindle_rpm: Q,
    feed: Q,
    plunge_feed: Q,
    depth_per_pass: Q,
    stock_allowance: Q,
    safe_z: Q,
    stock_top_z: Q,
    breakthrough: Q,
    tolerance: Q,
    climb: Option<bool>,
    lead_in_radius: Q,
    dialect: Option<Spanned<String>>,
    work_offset: Option<Spanned<String>>,
    coolant: Option<Spanned<String>>,
    arcs: Option<bool>,
    tabs: Option<Spanned<i64>>,
    tab_width: Q,
    tab_height: Q,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawChecks {
    max_pressure_angle: Q,
    min_locking_margin: Q,
    max_contact_stress: Q,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawOutput {
    chord_tolerance: Q,
    fit_tolerance: Q,
    stl_tolerance: Q,
}

/// Reads raw values with their key paths and line numbers.
struct Reader<'a> {
    source: &'a str,
}

/// An allowed range of a quantity, in default units.
#[derive(Clone, Copy)]
enum Range {
    Positive,
    NonNegative,
    Any,
    /// lo < value < hi
    Open(f64, f64),
    /// lo <= value < hi
    HalfOpen(f64, f64),
    /// lo <= value <= hi
    Closed(f64, f64),
}

impl Range {
    fn contains(self, v: f64) -> bool {
        match self {
            Range::Positive => v > 0.0,
            Range::NonNegative => v >= 0.0,
            Range::Any => true,
            Range::Open(lo, hi) => v > lo && v < hi,
            Range::HalfOpen(lo, hi) => v >= lo && v < hi,
            Range::Closed(lo, hi) => v >= lo && v <= hi,
        }
    }
    fn describe(self, unit: &str) -> String {
        let u = if unit.is_empty() {
            String::new()
        } else {
            format!(" {unit}")
        };
        match self {
            Range::Positive => "a value greater than 0".into(),
            Range::NonNegative => "a value of 0 or more".into(),
            Range::Any => "any finite value".into(),
            Range::Open(lo, hi) => format!("a value between {lo}{u} and {hi}{u} (exclusive)"),
            Range::HalfOpen(lo, hi) => {
                format!("a value from {lo}{u} up to (not including) {hi}{u}")
            }
            Range::Closed(lo, hi) => format!("a value from {lo}{u} to {hi}{u}"),
        }
    }
}

impl<'a> Reader<'a> {
    fn line(&self, offset: usize) -> usize {
        let end = offset.min(self.source.len());
        self.source.as_bytes()[..end]
            .iter()
            .filter(|&&b| b == b'\n')
            .count()
            + 1
    }

    fn invalid(
        &self,
        key: &str,
        span_start: Option<usize>,
        found: String,
        expected: String,
    ) -> SpecError {
        SpecError::Invalid {
            key: key.to_string(),
            line: span_start.map(|s| self.line(s)),
            found,
            expected,
        }
    }

    fn quantity_value(
        &self,
        key: &str,
        raw: &Spanned<RawValue>,
        dim: Dimension,
        range: Range,
    ) -> Result<f64, SpecError> {
        let start = Some(raw.span().start);
        let (value, found) = match raw.get_ref() {
            RawValue::Number(n) => (*n, format!("{n}")),
            RawValue::Text(t) => {
                let found = format!("\"{t}\"");
                let parsed = parse_quantity(t, dim).map_err(|e| {
                    let expected = match (&e, dim) {
                        (_, Dimension::Dimensionless) => "a plain number".to_string(),
                        (UnitError::NotFinite, _) => format!("a finite value, {}", dim.describe()),
                        _ => format!("{} (units: {})", dim.describe(), dim.unit_list()),
                    };
                    self.invalid(key, start, found.clone(), expected)
                })?;
                (parsed, found)
            }
        };
        if !value.is_finite() {
            return Err(self.invalid(
                key,
                start,
                found,
                format!("a finite value, {}", dim.describe()),
            ));
        }
        if !range.contains(value) {
            return Err(self.invalid(key, start, found, range.describe(dim.default_unit())));
        }
        Ok(value)
    }

    fn required(&self, key: &str, raw: &Q, dim: Dimension, range: Range) -> Result<f64, SpecError> {
        match raw {
            Some(r) => self.quantity_value(key, r, dim, range),
            None => Err(SpecError::Missing {
                key: key.to_string(),
                expected: dim.describe().to_string(),
            }),
        }
    }

    fn optional(
        &self,
        key: &str,
        raw: &Q,
        dim: Dimension,
        range: Range,
    ) -> Result<Option<f64>, SpecError> {
        raw.as_ref()
            .map(|r| self.quantity_value(key, r, dim, range))
            .transpose()
    }

    fn material(
        &self,
        key: &str,
        raw: &Option<RawMaterial>,
        default: &str,
    ) -> Result<Material, SpecError> {
        let names: Vec<&str> = MATERIALS.iter().map(|m| m.0).collect();
        let expected = format!(
            "one of {} or a table {{ youngs_modulus, poisson_ratio, yield_strength }}",
            names.join(", ")
        );
        let Some(raw) = raw else {
            return Ok(Material::preset(default).expect("default material is a preset"));
        };
        let start = raw.span().start;
        match raw.get_ref() {
            toml::Value::String(name) => Material::preset(name)
                .ok_or_else(|| self.invalid(key, Some(start), format!("\"{name}\""), expected)),
            toml::Value::Table(table) => {
                if let Some(unknown) = table.keys().find(|k| {
                    !["youngs_modulus", "poisson_ratio", "yield_strength"].contains(&k.as_str())
                }) {
                    return Err(self.invalid(
                        &format!("{key}.{unknown}"),
                        Some(start),
                        "an unknown key".into(),
                        expected,
                    ));
                }
                let field = |name: &str, dim: Dimension, range: Range| -> Result<f64, SpecError> {
                    let full = format!("{key}.{name}");
                    let value = match table.get(name) {
                        Some(toml::Value::Float(f)) => RawValue::Number(*f),
                        Some(toml::Value::Integer(i)) => RawValue::Number(*i as f64),
                        Some(toml::Value::String(t)) => RawValue::Text(t.clone()),
                        Some(other) => {
                            return Err(self.invalid(
                                &full,
                                Some(start),
                                other.to_string(),
                                dim.describe().into(),
                            ))
                        }
                        None => {
                            return Err(SpecError::Missing {
                                key: full,
                                expected: dim.describe().into(),
                            })
                        }
                    };
                    self.quantity_value(&full, &Spanned::new(start..start, value), dim, range)
                };
                Ok(Material {
                    name: "custom".into(),
                    youngs_modulus_mpa: field(
                        "youngs_modulus",
                        Dimension::Stress,
                        Range::Positive,
                    )?,
                    poisson_ratio: field(
                        "poisson_ratio",
                        Dimension::Dimensionless,
                        Range::Open(-1.0, 0.5),
                    )?,
                    yield_strength_mpa: field(
                        "yield_strength",
                        Dimension::Stress,
                        Range::Positive,
                    )?,
                })
            }
            other => Err(self.invalid(key, Some(start), other.to_string(), expected)),
        }
    }

    fn choice<'c>(
        &self,
        key: &str,
        raw: &Option<Spanned<String>>,
        choices: &[&'c str],
        default: &'c str,
    ) -> Result<&'c str, SpecError> {
        match raw {
            None => Ok(default),
            Some(s) => choices
                .iter()
                .find(|c| **c == s.get_ref().as_str())
                .copied()
                .ok_or_else(|| {
                    self.invalid(
                        key,
                        Some(s.span().start),
                        format!("\"{}\"", s.get_ref()),
                        format!(
                            "one of {}",
                            choices
                                .iter()
                                .map(|c| format!("\"{c}\""))
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    )
                }),
        }
    }
}

impl Spec {
    /// Reads and validates a spec from TOML text.
    ///
    /// ```
    /// let spec = camspring::spec::Spec::from_toml(camspring::spec::DEFAULT_SPEC_TOML).unwrap();
    /// assert_eq!(spec.name, "paper");
    /// let err = camspring::spec::Spec::from_toml("[law]\nxmax = \"20 N\"\n").unwrap_err();
    /// assert!(err.to_string().contains("law.xmax"));
    /// ```
    pub fn from_toml(source: &str) -> Result<Spec, SpecError> {
        let raw: RawSpec = toml::from_str(source).map_err(|e| SpecError::Toml(e.to_string()))?;
        let r = Reader { source };
        use Dimension as D;

        let name = match &raw.name {
            None => "design".to_string(),
            Some(n) => {
                let v = n.get_ref().trim();
                let ok = !v.is_empty()
                    && v.chars()
                        .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
                    && !v.starts_with('.');
                if !ok {
                    return Err(r.invalid(
                        "name",
                        Some(n.span().start),
                        format!("\"{}\"", n.get_ref()),
                        "a non-empty name of letters, digits, '-', '_' or '.' (it names the output folder)".into(),
                    ));
                }
                v.to_string()
            }
        };

        let law_raw = raw.law.as_ref().ok_or_else(|| SpecError::Missing {
            key: "law".into(),
            expected: "a [law] table with fmax, fmin, xmax, l0, c0, delta0 (or mu, k2, f0, xmax)"
                .into(),
        })?;
        let xmax = r.required("law.xmax", &law_raw.xmax, D::Length, Range::Positive)?;
        let given_keys = [&law_raw.mu, &law_raw.k2, &law_raw.f0];
        let target_keys = [
            &law_raw.fmax,
            &law_raw.fmin,
            &law_raw.l0,
            &law_raw.c0,
            &law_raw.delta0,
        ];
        let law = if given_keys.iter().any(|k| k.is_some()) {
            if let Some((name, q)) = ["fmax", "fmin", "l0", "c0", "delta0"]
                .iter()
                .zip(target_keys.iter())
                .find(|(_, q)| q.is_some())
            {
                let q = q.as_ref().expect("found as some");
                return Err(r.invalid(
                    &format!("law.{name}"),
                    Some(q.span().start),
                    "a design target next to a given law (mu, k2, f0)".into(),
                    "either the targets fmax, fmin, xmax, l0, c0, delta0 or a given law mu, k2, f0 with xmax, not both".into(),
                ));
            }
            LawSpec::Given {
                law: ExpLaw {
                    mu_n: r.required("law.mu", &law_raw.mu, D::Force, Range::Positive)?,
                    k2_per_mm: r.required(
                        "law.k2",
                        &law_raw.k2,
                        D::InverseLength,
                        Range::Positive,
                    )?,
                    f0_n: r.required("law.f0", &law_raw.f0, D::Force, Range::Any)?,
                },
                xmax_mm: xmax,
            }
        } else {
            let fmax = r.required("law.fmax", &law_raw.fmax, D::Force, Range::Positive)?;
            let fmin = r.required("law.fmin", &law_raw.fmin, D::Force, Range::Positive)?;
            let l0 = r.required("law.l0", &law_raw.l0, D::Length, Range::Positive)?;
            let c0 = r.required("law.c0", &law_raw.c0, D::Dimensionless, Range::Positive)?;
            let delta0 = r.required("law.delta0", &law_raw.delta0, D::Length, Range::Positive)?;
            if fmax <= fmin {
                let q = law_raw.fmax.as_ref().expect("required above");
                return Err(r.invalid(
                    "law.fmax",
                    Some(q.span().start),
                    format!("{fmax} N"),
                    format!("a force greater than law.fmin = {fmin} N"),
                ));
            }
            if xmax <= l0 {
                let q = law_raw.xmax.as_ref().expect("required above");
                return Err(r.invalid(
                    "law.xmax",
                    Some(q.span().start),
                    format!("{xmax} mm"),
                    format!("a deflection greater than law.l0 = {l0} mm"),
                ));
            }
            LawSpec::Targets(LawTargets {
                fmax_n: fmax,
                fmin_n: fmin,
                xmax_mm: xmax,
                l0_mm: l0,
                c0,
                delta0_mm: delta0,
            })
        };

        let f = raw.follower.as_ref().ok_or_else(|| SpecError::Missing {
            key: "follower".into(),
            expected: "a [follower] table with at least spring_rate and roller_radius".into(),
        })?;
        let count = match &f.count {
            None => 1,
            Some(c) if matches!(c.get_ref(), 1 | 2) => *c.get_ref() as u8,
            Some(c) => {
                return Err(r.invalid(
                    "follower.count",
                    Some(c.span().start),
                    c.get_ref().to_string(),
                    "1 (one follower) or 2 (two followers on opposed cam surfaces)".into(),
                ))
            }
        };
        let arrangement = match r.choice(
            "follower.spring",
            &f.spring,
            &["per-follower", "shared"],
            "per-follower",
        )? {
            "shared" => {
                if count != 2 {
                    let s = f.spring.as_ref().expect("given");
                    return Err(r.invalid(
                        "follower.spring",
                        Some(s.span().start),
                        "\"shared\" with follower.count = 1".into(),
                        "\"per-follower\", or count = 2: a shared spring joins two opposed followers".into(),
                    ));
                }
                SpringArrangement::Shared
            }
            _ => SpringArrangement::PerFollower,
        };
        let spring_rate = r.required(
            "follower.spring_rate",
            &f.spring_rate,
            D::Stiffness,
            Range::Positive,
        )?;
        let preload = r
            .optional(
                "follower.preload",
                &f.preload,
                D::Length,
                Range::NonNegative,
            )?
            .unwrap_or(0.0);
        let roller_radius = r.required(
            "follower.roller_radius",
            &f.roller_radius,
            D::Length,
            Range::NonNegative,
        )?;
        let friction_source = match (&f.friction, &f.pin_friction) {
            (Some(q), Some(_)) => {
                return Err(r.invalid(
                    "follower.friction",
                    Some(q.span().start),
                    "both friction and pin_friction".into(),
                    "either an effective contact coefficient `friction`, or `pin_friction` with `pin_radius`".into(),
                ))
            }
            (Some(_), None) => FrictionSource::Coefficient {
                coefficient: r.required("follower.friction", &f.friction, D::Dimensionless, Range::HalfOpen(0.0, MAX_FRICTION))?,
            },
            (None, Some(_)) => {
                let pin_friction =
                    r.required("follower.pin_friction", &f.pin_friction, D::Dimensionless, Range::HalfOpen(0.0, MAX_FRICTION))?;
                let pin_radius = r.required("follower.pin_radius", &f.pin_radius, D::Length, Range::Positive)?;
                if pin_radius >= roller_radius {
                    let q = f.pin_radius.as_ref().expect("required above");
                    return Err(r.invalid(
                        "follower.pin_radius",
                        Some(q.span().start),
                        format!("{pin_radius} mm"),
                        format!("a pin radius smaller than follower.roller_radius = {roller_radius} mm"),
                    ));
                }
                let rolling = r
                    .optional("follower.rolling_resistance", &f.rolling_resistance, D::Length, Range::NonNegative)?
                    .unwrap_or(0.0);
                FrictionSource::Pin {
                    pin_friction,
                    pin_radius_mm: pin_radius,
                    rolling_resistance_mm: rolling,
                }
            }
            (None, None) => {
                if let Some(q) = f.pin_radius.as_ref().or(f.rolling_resistance.as_ref()) {
                    return Err(r.invalid(
                        "follower.pin_radius",
                        Some(q.span().start),
                        "pin_radius or rolling_resistance without pin_friction".into(),
                        "pin_friction next to pin_radius".into(),
                    ));
                }
                FrictionSource::Coefficient { coefficient: 0.0 }
            }
        };
        let correction = match r.choice(
            "follower.friction_correction",
            &f.friction_correction,
            &["loading", "unloading", "midline", "none"],
            "loading",
        )? {
            "unloading" => FrictionCorrection::Unloading,
            "midline" => FrictionCorrection::Midline,
            "none" => FrictionCorrection::None,
            _ => FrictionCorrection::Loading,
        };
        let follower = Follower {
            count,
            arrangement,
            spring_rate_n_per_mm: spring_rate,
            preload_mm: preload,
            roller_radius_mm: roller_radius,
            friction: friction_source,
            friction_correction: correction,
        };
        let mu_f = follower.friction_coefficient();
        if mu_f >= MAX_FRICTION {
            return Err(SpecError::Invalid {
                key: "follower.pin_friction".into(),
                line: None,
                found: format!("an effective contact coefficient of {mu_f:.4}"),
                expected: format!("an effective coefficient below {MAX_FRICTION} (pin_friction * pin_radius / roller_radius + rolling_resistance / roller_radius)"),
            });
        }

        let empty_part = RawPart {
            thickness: None,
            roller_width: None,
            cam_material: None,
            roller_material: None,
            lead_in: None,
            run_out: None,
            web: None,
            holes: None,
        };
        let p = raw.part.as_ref().unwrap_or(&empty_part);
        let thickness = r
            .optional("part.thickness", &p.thickness, D::Length, Range::Positive)?
            .unwrap_or(10.0);
        let roller_width = r
            .optional(
                "part.roller_width",
                &p.roller_width,
                D::Length,
                Range::Positive,
            )?
            .unwrap_or(thickness);
        let part = PartSpec {
            thickness_mm: thickness,
            roller_width_mm: roller_width,
            cam_material: r.material("part.cam_material", &p.cam_material, "aluminium-6061-t6")?,
            roller_material: r.material(
                "part.roller_material",
                &p.roller_material,
                "bearing-steel",
            )?,
            lead_in_mm: r
                .optional("part.lead_in", &p.lead_in, D::Length, Range::NonNegative)?
                .unwrap_or(2.0),
            run_out_mm: r
                .optional("part.run_out", &p.run_out, D::Length, Range::NonNegative)?
                .unwrap_or(2.0),
            web_mm: r
                .optional("part.web", &p.web, D::Length, Range::Positive)?
                .unwrap_or(8.0),
            holes: p
                .holes
                .iter()
                .flatten()
                .enumerate()
                .map(|(i, h)| {
                    let key = |k: &str| format!("part.holes[{i}].{k}");
                    Ok(Hole {
                        x_mm: r.required(&key("x"), &h.x, D::Length, Range::Any)?,
                        y_mm: r.required(&key("y"), &h.y, D::Length, Range::Any)?,
                        diameter_mm: r.required(
                            &key("diameter"),
                            &h.diameter,
                            D::Length,
                            Range::Positive,
                        )?,
                    })
                })
                .collect::<Result<Vec<Hole>, SpecError>>()?,
        };

        let machining = {
            let empty = RawMachining {
                tool_diameter: None,
                spindle_rpm: None,
                feed: None,
                plunge_feed: None,
                depth_per_pass: None,
                stock_allowance: None,
                safe_z: None,
                stock_top_z: None,
                breakthrough: None,
                tolerance: None,
                climb: None,
                lead_in_radius: None,
                dialect: None,
                work_offset: None,
                coolant: None,
                arcs: None,
                tabs: None,
                tab_width: None,
                tab_height: None,
            };
            let m = raw.machining.as_ref().unwrap_or(&empty);
            let len = |key: &str, q: &Q, range: Range, default: f64| -> Result<f64, SpecError> {
                Ok(
                    r.optional(&format!("machining.{key}"), q, D::Length, range)?
                        .unwrap_or(default),
                )
            };
            let tool_diameter = len("tool_diameter", &m.tool_diameter, Range::Positive, 6.0)?;
            let depth_per_pass = len("depth_per_pass", &m.depth_per_pass, Range::Positive, 1.0)?;
            // A pass deeper than the cutter diameter overloads an end mill slotting full width.
            if depth_per_pass > tool_diameter {
                let q = m
                    .depth_per_pass
                    .as_ref()
                    .expect("larger than the default needs a value");
                return Err(r.invalid(
                    "machining.depth_per_pass",
                    Some(q.span().start),
                    format!("{depth_per_pass} mm"),
                    format!("at most the tool diameter, {tool_diameter} mm (full-width slotting)"),
                ));
            }
            let safe_z = len("safe_z", &m.safe_z, Range::Any, 5.0)?;
            let stock_top_z = len("stock_top_z", &m.stock_top_z, Range::Any, 0.0)?;
            if safe_z <= stock_top_z {
                return Err(SpecError::Invalid {
                    key: "machining.safe_z".into(),
                    line: m.safe_z.as_ref().map(|q| r.line(q.span().start)),
                    found: format!("{safe_z} mm"),
                    expected: format!("a height above machining.stock_top_z = {stock_top_z} mm"),
                });
            }
            let work_offset = match &m.work_offset {
                None => "G54".to_string(),
                Some(w) => {
                    let v = w.get_ref().trim().to_ascii_uppercase();
                    if !["G54", "G55", "G56", "G57", "G58", "G59"].contains(&v.as_str()) {
                        return Err(r.invalid(
                            "machining.work_offset",
                            Some(w.span().start),
                            format!("\"{}\"", w.get_ref()),
                            "one of G54, G55, G56, G57, G58, G59".into(),
                        ));
                    }
                    v
                }
            };
            let dialect = match r.choice(
                "machining.dialect",
                &m.dialect,
                &["linuxcnc", "grbl", "fanuc"],
                "linuxcnc",
            )? {
                "grbl" => Dialect::Grbl,
                "fanuc" => Dialect::Fanuc,
                _ => Dialect::Linuxcnc,
            };
            // Default path tolerance: 1 um where 5 decimals are written (LinuxCNC), 2 um where
            // 3 decimals are (GRBL, Fanuc), leaving room for the rounding of the output.
            let default_tolerance = if dialect == Dialect::Linuxcnc {
                1e-3
            } else {
                2e-3
            };
            MachiningSpec {
                tool_diameter_mm: tool_diameter,
                spindle_rpm: r
                    .optional(
                        "machining.spindle_rpm",
                        &m.spindle_rpm,
                        D::RotationalSpeed,
                        Range::Open(0.0, 200_000.0),
                    )?
                    .unwrap_or(8000.0),
                feed_mm_per_min: r
                    .optional("machining.feed", &m.feed, D::FeedRate, Range::Positive)?
                    .unwrap_or(600.0),
                plunge_feed_mm_per_min: r
                    .optional(
                        "machining.plunge_feed",
                        &m.plunge_feed,
                        D::FeedRate,
                        Range::Positive,
                    )?
                    .unwrap_or(150.0),
                depth_per_pass_mm: depth_per_pass,
                stock_allowance_mm: len(
                    "stock_allowance",
                    &m.stock_allowance,
                    Range::NonNegative,
                    0.2,
                )?,
                safe_z_mm: safe_z,
                stock_top_z_mm: stock_top_z,
                breakthrough_mm: len("breakthrough", &m.breakthrough, Range::NonNegative, 0.5)?,
                tolerance_mm: len(
                    "tolerance",
                    &m.tolerance,
                    Range::Closed(1e-5, 0.5),
                    default_tolerance,
                )?,
                climb: m.climb.unwrap_or(true),
                lead_in_radius_mm: len("lead_in_radius", &m.lead_in_radius, Range::Positive, 2.0)?,
                dialect,
                work_offset,
                coolant: match r.choice(
                    "machining.coolant",
                    &m.coolant,
                    &["flood", "mist", "off"],
                    "flood",
                )? {
                    "mist" => Coolant::Mist,
                    "off" => Coolant::Off,
                    _ => Coolant::Flood,
                },
                arcs: m.arcs.unwrap_or(true),
                tabs: match &m.tabs {
                    None => 0,
                    Some(t) if (0..=16).contains(t.get_ref()) => *t.get_ref() as usize,
                    Some(t) => {
                        return Err(r.invalid(
                            "machining.tabs",
                            Some(t.span().start),
                            t.get_ref().to_string(),
                            "a number of tabs from 0 to 16".into(),
                        ))
                    }
                },
                tab_width_mm: len("tab_width", &m.tab_width, Range::Positive, 3.0)?,
                tab_height_mm: {
                    let h = len("tab_height", &m.tab_height, Range::Positive, 1.0)?;
                    if h >= part.thickness_mm {
                        return Err(SpecError::Invalid {
                            key: "machining.tab_height".into(),
                            line: m.tab_height.as_ref().map(|q| r.line(q.span().start)),
                            found: format!("{h} mm"),
                            expected: format!(
                                "less than part.thickness = {} mm",
                                part.thickness_mm
                            ),
                        });
                    }
                    h
                },
            }
        };

        let empty_checks = RawChecks {
            max_pressure_angle: None,
            min_locking_margin: None,
            max_contact_stress: None,
        };
        let c = raw.checks.as_ref().unwrap_or(&empty_checks);
        let weaker_yield = part
            .cam_material
            .yield_strength_mpa
            .min(part.roller_material.yield_strength_mpa);
        let checks = ChecksSpec {
            max_pressure_angle_deg: r
                .optional(
                    "checks.max_pressure_angle",
                    &c.max_pressure_angle,
                    D::Angle,
                    Range::Open(0.0, 90.0),
                )?
                .unwrap_or(60.0),
            min_locking_margin_deg: r
                .optional(
                    "checks.min_locking_margin",
                    &c.min_locking_margin,
                    D::Angle,
                    Range::HalfOpen(0.0, 45.0),
                )?
                .unwrap_or(5.0),
            max_contact_stress_mpa: r
                .optional(
                    "checks.max_contact_stress",
                    &c.max_contact_stress,
                    D::Stress,
                    Range::Positive,
                )?
                .unwrap_or(HERTZ_YIELD_FACTOR * weaker_yield),
        };

        let chord_tolerance = match &raw.output {
            Some(o) => r.optional(
                "output.chord_tolerance",
                &o.chord_tolerance,
                D::Length,
                Range::Closed(1e-5, 0.1),
            )?,
            None => None,
        }
        .unwrap_or(1e-3);
        let (fit_tolerance, stl_tolerance) = match &raw.output {
            Some(o) => (
                r.optional(
                    "output.fit_tolerance",
                    &o.fit_tolerance,
                    D::Length,
                    Range::Closed(1e-5, 0.1),
                )?,
                r.optional(
                    "output.stl_tolerance",
                    &o.stl_tolerance,
                    D::Length,
                    Range::Closed(1e-4, 1.0),
                )?,
            ),
            None => (None, None),
        };
        let fit_tolerance = fit_tolerance.unwrap_or(1e-3);
        let stl_tolerance = stl_tolerance.unwrap_or(5e-3);
        if chord_tolerance >= stl_tolerance {
            return Err(SpecError::Invalid {
                key: "output.chord_tolerance".into(),
                line: None,
                found: format!("{chord_tolerance} mm with output.stl_tolerance = {stl_tolerance} mm"),
                expected: "a chord tolerance smaller than the STL tolerance (the mesh is decimated from the samples)".into(),
            });
        }

        Ok(Spec {
            name,
            law,
            follower,
            part,
            machining,
            checks,
            output: OutputSpec {
                chord_tolerance_mm: chord_tolerance,
                fit_tolerance_mm: fit_tolerance,
                stl_tolerance_mm: stl_tolerance,
            },
        })
    }
}

/// Line contact between cylinders first yields below the surface when the peak Hertz pressure
/// reaches about 1.67 times the tensile yield strength (Tresca, nu = 0.3; K. L. Johnson,
/// *Contact Mechanics*, 1985, section 4.2).
pub const HERTZ_YIELD_FACTOR: f64 = 1.67;

#[cfg(test)]
mod tests {
    use super::*;

    fn err(src: &str) -> String {
        Spec::from_toml(src).unwrap_err().to_string()
    }

    const MINIMAL: &str = "[law]\nfmax = 200\nfmin = 5\nxmax = 20\nl0 = 5\nc0 = 0.2\ndelta0 = 1\n[follower]\nspring_rate = 5\nroller_radius = 3\n";

    #[test]
    fn minimal_spec_takes_documented_defaults() {
        let s = Spec::from_toml(MINIMAL).unwrap();
        assert_eq!(s.follower.count, 1);
        assert_eq!(s.follower.preload_mm, 0.0);
        assert_eq!(s.part.thickness_mm, 10.0);
        assert_eq!(s.checks.max_pressure_angle_deg, 60.0);
        assert!((s.checks.max_contact_stress_mpa - 1.67 * 276.0).abs() < 1e-9);
        assert_eq!(s.output.chord_tolerance_mm, 1e-3);
    }

    #[test]
    fn units_are_converted() {
        let src = MINIMAL
            .replace("spring_rate = 5", "spring_rate = \"5000 N/m\"")
            .replace("xmax = 20", "xmax = \"2 cm\"");
        let s = Spec::from_toml(&src).unwrap();
        assert_eq!(s.follower.spring_rate_n_per_mm, 5.0);
        assert_eq!(s.law.xmax_mm(), 20.0);
    }

    #[test]
    fn wrong_unit_names_key_line_value_and_expectation() {
        let src = MINIMAL.replace("spring_rate = 5", "spring_rate = \"5 N\"");
        let e = err(&src);
        assert!(e.contains("follower.spring_rate"), "{e}");
        assert!(e.contains("line 9"), "{e}");
        assert!(e.contains("\"5 N\""), "{e}");
        assert!(e.contains("N/mm"), "{e}");
    }

    #[test]
    fn unknown_key_is_an_error_naming_it() {
        let e = err(&format!("{MINIMAL}spring_rat = 3\n"));
        assert!(e.contains("spring_rat"), "{e}");
        assert!(e.contains("line 11"), "{e}");
    }

    #[test]
    fn missing_key_is_named() {
        let e = err(&MINIMAL.replace("l0 = 5\n", ""));
        assert!(e.contains("law.l0"), "{e}");
    }

    #[test]
    fn out_of_range_values_are_refused() {
        assert!(err(&MINIMAL.replace("fmin = 5", "fmin = -5")).contains("law.fmin"));
        assert!(err(&MINIMAL.replace("fmax = 200", "fmax = 4")).contains("greater than law.fmin"));
        assert!(err(&MINIMAL.replace("xmax = 20", "xmax = 4")).contains("greater than law.l0"));
        assert!(err(&MINIMAL.replace("fmax = 200", "fmax = nan")).contains("finite"));
        assert!(err(&MINIMAL.replace("fmax = 200", "fmax = inf")).contains("finite"));
        assert!(err(&format!("{MINIMAL}count = 3\n")).contains("follower.count"));
        assert!(err(&format!("{MINIMAL}friction = 1.5\n")).contains("follower.friction"));
    }

    #[test]
    fn given_law_and_targets_conflict() {
        let e = err(&MINIMAL.replace("[follower]", "mu = 1\n[follower]"));
        assert!(e.contains("not both"), "{e}");
    }

    #[test]
    fn shared_spring_needs_two_followers() {
        let e = err(&format!("{MINIMAL}spring = \"shared\"\n"));
        assert!(e.contains("follower.spring"), "{e}");
    }
}
