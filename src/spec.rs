//! The TOML spec format: reading a spec file into a [`model::Spec`](crate::model::Spec).
//!
//! [`parse`] (also [`Spec::from_toml`]) reads the text, converts every quantity to its default
//! unit (mm, N, N/mm, 1/mm, deg, MPa), fills the documented defaults and then calls
//! [`Spec::validate`], the model's single home of the range rules. Every error names the key
//! (`follower.spring_rate`), the line, the value as written and what was expected. Unknown
//! keys are errors too, so a misspelt key never silently falls back to a default. The built-in
//! default spec is [`DEFAULT_SPEC_TOML`], a copy of `specs/paper.toml`.

use std::collections::HashMap;
use std::path::Path;

use serde::Deserialize;
use toml::Spanned;

use crate::model::{
    ChecksSpec, Condition, Coolant, Dialect, DrawingSpec, ExpLaw, Follower, FrictionCorrection,
    FrictionSource, Hole, LawSpec, LawTargets, MachiningSpec, Material, OutputSpec, PartSpec,
    SheetSize, Spec, SpecError, SpringArrangement, TolerancesSpec, Tool, ToolKind, WorkOffset,
    MATERIALS, MAX_FRICTION,
};
use crate::units::{parse_quantity, quoted, Dimension, UnitError};

/// The commented starter spec that `camspring init` writes (a copy of `specs/starter.toml`).
pub const STARTER_SPEC_TOML: &str = include_str!("../specs/starter.toml");

/// The law forms `camspring init --law` can start from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StarterLaw {
    /// The paper's targets (fmax, fmin, xmax, l0, c0, delta0).
    Paper,
    /// Three conditions in the designer's terms.
    Conditions,
    /// A given exponential law (mu, k2, f0).
    Given,
    /// A table in a CSV file beside the spec.
    Table,
}

/// The starter table `camspring init --law table` writes beside the spec: a soft-then-stiff
/// curve with a knee, in mm and N.
pub const STARTER_TABLE_CSV: &str =
    "# x_mm: deflection, force_n: force; strictly increasing x from 0, forces never decreasing\n\
x_mm,force_n\n0,20\n2,30\n4,42\n6,58\n8,85\n10,130\n12,200\n14,300\n15,370\n";

/// The starter spec with its `[law]` section in the form asked; `table` names the CSV file
/// the table form reads (written beside the spec).
pub fn starter_spec(form: StarterLaw, table: &str) -> String {
    let law = match form {
        StarterLaw::Paper => return STARTER_SPEC_TOML.to_string(),
        StarterLaw::Conditions => "[law]\n\
# Three conditions on F = mu*exp(k2*x) + F0; camspring solves mu, k2 and F0. Each is a force or a\n\
# stiffness at a deflection, or a stiffness at a force (stiffness is affine in force).\n\
xmax = \"15 mm\"    # stroke\n\
conditions = [\n\
  { at = \"0 mm\",  force = \"40 N\" },\n\
  { at = \"15 mm\", force = \"800 N\" },\n\
  { at = \"15 mm\", stiffness = \"180 N/mm\" },\n\
  # or { force = \"400 N\", stiffness = \"90 N/mm\" }\n\
]\n"
        .to_string(),
        StarterLaw::Given => "[law]\n\
# A known law F = mu*exp(k2*x) + F0, used as given over the stroke.\n\
mu = \"1.0 N\"\nk2 = \"0.26 /mm\"\nf0 = \"1.2 N\"\nxmax = \"20 mm\"\n"
            .to_string(),
        StarterLaw::Table => format!(
            "[law]\n\
# A measured or wanted force curve: a CSV file beside this spec with columns x_<unit>,force_<unit>\n\
# (x_mm,force_n or x_in,force_lbf), joined by a monotone cubic. xmax defaults to the last row.\n\
table = \"{table}\"\n\
# xmax = \"15 mm\"\n"
        ),
    };
    let start = STARTER_SPEC_TOML.find("[law]").unwrap_or(0);
    let end = STARTER_SPEC_TOML
        .find("[follower]")
        .unwrap_or(STARTER_SPEC_TOML.len());
    format!(
        "{}{law}\n{}",
        &STARTER_SPEC_TOML[..start],
        &STARTER_SPEC_TOML[end..]
    )
}

/// The built-in default spec (`specs/paper.toml`): the paper's law on two opposed followers.
pub const DEFAULT_SPEC_TOML: &str = include_str!("../specs/paper.toml");

// ---------------------------------------------------------------------------------------------
// Raw TOML shape

#[derive(Debug, Clone)]
enum RawValue {
    Number(f64),
    Text(String),
}

impl<'de> Deserialize<'de> for RawValue {
    /// A number, or a string with a unit; anything else is refused saying so (with the key
    /// and line the TOML reader adds).
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl serde::de::Visitor<'_> for Visitor {
            type Value = RawValue;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a number, or a quantity with its unit such as \"20 mm\"")
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<RawValue, E> {
                Ok(RawValue::Number(v as f64))
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<RawValue, E> {
                Ok(RawValue::Number(v as f64))
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<RawValue, E> {
                Ok(RawValue::Number(v))
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<RawValue, E> {
                Ok(RawValue::Text(v.to_string()))
            }
        }
        d.deserialize_any(Visitor)
    }
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
    tolerances: Option<RawTolerances>,
    drawing: Option<RawDrawing>,
    revision: Option<Spanned<String>>,
    revision_note: Option<Spanned<String>>,
    assembly: Option<RawAssembly>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAssembly {
    shim: Q,
    spring_rate: Q,
    spring_part: Option<Spanned<String>>,
    friction: Q,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDrawing {
    sheet: Option<Spanned<String>>,
    scale: Option<Spanned<String>>,
    number: Option<Spanned<String>>,
    revision: Option<Spanned<String>>,
    date: Option<Spanned<String>>,
    drawn_by: Option<Spanned<String>>,
    general_tolerance: Option<Spanned<String>>,
    cam_finish: Q,
    finish: Q,
    coordinate_step: Q,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTolerances {
    spring_rate: Q,
    preload: Q,
    roller_radius: Q,
    profile: Q,
    friction_min: Q,
    friction_max: Q,
    samples: Option<Spanned<i64>>,
    seed: Option<Spanned<i64>>,
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
    conditions: Option<Spanned<Vec<RawCondition>>>,
    table: Option<Spanned<String>>,
    polynomial: Option<Spanned<Vec<Spanned<RawValue>>>>,
}

/// `{ at = "15 mm", force = "800 N" }`, `{ at = ..., stiffness = ... }` or
/// `{ force = ..., stiffness = ... }`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCondition {
    at: Q,
    force: Q,
    stiffness: Q,
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
    roller_dynamic_load: Q,
    duty_strokes: Q,
    stroke_rate: Q,
    spring_catalogue: Option<Spanned<String>>,
}

/// A material: a preset name, or a table { youngs_modulus, poisson_ratio, yield_strength }.
type RawMaterial = Spanned<toml::Value>;

#[derive(Debug, Default, Deserialize)]
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

#[derive(Debug, Default, Deserialize)]
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
    skin: Q,
    spindle_dwell: Q,
    ramp_angle: Q,
    rapid: Q,
    flute_length: Q,
    flutes: Option<Spanned<i64>>,
    tools: Option<Vec<RawTool>>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTool {
    number: Option<Spanned<i64>>,
    kind: Option<Spanned<String>>,
    diameter: Q,
    flute_length: Q,
    flutes: Option<Spanned<i64>>,
    spindle_rpm: Q,
    feed: Q,
    plunge_feed: Q,
    peck: Q,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawChecks {
    max_pressure_angle: Q,
    min_locking_margin: Q,
    max_contact_stress: Q,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawOutput {
    chord_tolerance: Q,
    fit_tolerance: Q,
    stl_tolerance: Q,
}

/// Where a value stood in the text: its line, how it was written, and how
/// [`Spec::validate`] would print it, so a validation error can quote the text.
struct Written {
    line: usize,
    as_written: String,
    as_validated: String,
}

/// Reads raw values, converting units and remembering where each key stood.
struct Reader<'a> {
    source: &'a str,
    /// The folder files named in the spec (a law table) are relative to.
    base: &'a Path,
    written: HashMap<String, Written>,
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

    fn invalid(&self, key: &str, span_start: usize, found: String, expected: String) -> SpecError {
        SpecError::Invalid {
            key: key.to_string(),
            line: Some(self.line(span_start)),
            found,
            expected,
        }
    }

    fn remember(&mut self, key: &str, span_start: usize, as_written: String, as_validated: String) {
        let line = self.line(span_start);
        self.written.insert(
            key.to_string(),
            Written {
                line,
                as_written,
                as_validated,
            },
        );
    }

    /// A quantity in the dimension's default unit; unit errors are reported here, range
    /// errors by [`Spec::validate`].
    fn quantity_value(
        &mut self,
        key: &str,
        raw: &Spanned<RawValue>,
        dim: Dimension,
    ) -> Result<f64, SpecError> {
        let start = raw.span().start;
        let (value, found) = match raw.get_ref() {
            RawValue::Number(n) => (*n, format!("{n}")),
            RawValue::Text(t) => {
                let found = quoted(t);
                let parsed = parse_quantity(t, dim).map_err(|e| {
                    let expected = match (&e, dim) {
                        (UnitError::TooLong, _) => format!(
                            "a number of at most {} characters",
                            crate::units::MAX_NUMBER_CHARS
                        ),
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
        let validated = crate::model::found_value(value, dim.default_unit());
        self.remember(key, start, found, validated);
        Ok(value)
    }

    fn required(&mut self, key: &str, raw: &Q, dim: Dimension) -> Result<f64, SpecError> {
        match raw {
            Some(r) => self.quantity_value(key, r, dim),
            None => Err(SpecError::Missing {
                key: key.to_string(),
                expected: dim.describe().to_string(),
            }),
        }
    }

    fn optional(&mut self, key: &str, raw: &Q, dim: Dimension) -> Result<Option<f64>, SpecError> {
        raw.as_ref()
            .map(|r| self.quantity_value(key, r, dim))
            .transpose()
    }

    /// An optional quantity, or `default` in the default unit.
    fn or(&mut self, key: &str, raw: &Q, dim: Dimension, default: f64) -> Result<f64, SpecError> {
        Ok(self.optional(key, raw, dim)?.unwrap_or(default))
    }

    /// A whole number the model stores as `T`; a value that does not fit is passed on as
    /// `T::MAX` for [`Spec::validate`] to refuse, quoting the text.
    fn count<T: TryFrom<i64> + std::fmt::Display + Copy>(
        &mut self,
        key: &str,
        raw: &Option<Spanned<i64>>,
        max: T,
        default: T,
    ) -> T {
        match raw {
            None => default,
            Some(v) => {
                let n = T::try_from(*v.get_ref()).unwrap_or(max);
                self.remember(key, v.span().start, v.get_ref().to_string(), n.to_string());
                n
            }
        }
    }

    fn material(
        &mut self,
        key: &str,
        raw: &Option<RawMaterial>,
        default: Material,
    ) -> Result<Material, SpecError> {
        let names: Vec<&str> = MATERIALS.iter().map(|m| m.0).collect();
        let expected = format!(
            "one of {} or a table {{ youngs_modulus, poisson_ratio, yield_strength }}",
            names.join(", ")
        );
        let Some(raw) = raw else {
            return Ok(default);
        };
        let start = raw.span().start;
        match raw.get_ref() {
            toml::Value::String(name) => Material::preset(name)
                .ok_or_else(|| self.invalid(key, start, quoted(name), expected)),
            toml::Value::Table(table) => {
                if let Some(unknown) = table.keys().find(|k| {
                    !["youngs_modulus", "poisson_ratio", "yield_strength"].contains(&k.as_str())
                }) {
                    return Err(self.invalid(
                        &format!("{key}.{unknown}"),
                        start,
                        "an unknown key".into(),
                        expected,
                    ));
                }
                let mut field = |name: &str, dim: Dimension| -> Result<f64, SpecError> {
                    let full = format!("{key}.{name}");
                    let value = match table.get(name) {
                        Some(toml::Value::Float(f)) => RawValue::Number(*f),
                        Some(toml::Value::Integer(i)) => RawValue::Number(*i as f64),
                        Some(toml::Value::String(t)) => RawValue::Text(t.clone()),
                        Some(other) => {
                            return Err(self.invalid(
                                &full,
                                start,
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
                    self.quantity_value(&full, &Spanned::new(start..start, value), dim)
                };
                Ok(Material {
                    name: "custom".into(),
                    youngs_modulus_mpa: field("youngs_modulus", Dimension::Stress)?,
                    poisson_ratio: field("poisson_ratio", Dimension::Dimensionless)?,
                    yield_strength_mpa: field("yield_strength", Dimension::Stress)?,
                })
            }
            other => Err(self.invalid(key, start, other.to_string(), expected)),
        }
    }

    /// One of `choices` (text, value), or `default` when absent.
    fn choice<T: Copy>(
        &self,
        key: &str,
        raw: &Option<Spanned<String>>,
        choices: &[(&str, T)],
        default: T,
    ) -> Result<T, SpecError> {
        let Some(s) = raw else {
            return Ok(default);
        };
        let text = s.get_ref().trim();
        choices
            .iter()
            .find(|(name, _)| name.eq_ignore_ascii_case(text))
            .map(|&(_, v)| v)
            .ok_or_else(|| {
                let names: Vec<String> = choices.iter().map(|(c, _)| format!("\"{c}\"")).collect();
                self.invalid(
                    key,
                    s.span().start,
                    quoted(s.get_ref()),
                    format!("one of {}", names.join(", ")),
                )
            })
    }

    /// A validation error with the line and the value as written, when the key was written.
    fn locate(&self, e: SpecError) -> SpecError {
        match e {
            SpecError::Invalid {
                key,
                line: None,
                found,
                expected,
            } => match self.written.get(&key) {
                Some(w) => SpecError::Invalid {
                    line: Some(w.line),
                    found: if found == w.as_validated {
                        w.as_written.clone()
                    } else {
                        found
                    },
                    key,
                    expected,
                },
                None => SpecError::Invalid {
                    key,
                    line: None,
                    found,
                    expected,
                },
            },
            other => other,
        }
    }
}

impl Spec {
    /// Reads and validates a spec from TOML text; the same as [`parse`].
    ///
    /// ```
    /// use camspring::{spec::DEFAULT_SPEC_TOML, Spec};
    /// let spec = Spec::from_toml(DEFAULT_SPEC_TOML).unwrap();
    /// assert_eq!(spec.name, "paper");
    /// let err = Spec::from_toml("[law]\nxmax = \"20 N\"\n").unwrap_err();
    /// assert!(err.to_string().contains("law.xmax"));
    /// ```
    pub fn from_toml(source: &str) -> Result<Spec, SpecError> {
        parse(source)
    }
}

/// Reads a spec from TOML text, fills the defaults and validates it; a law table it names is
/// read relative to the current folder.
pub fn parse(source: &str) -> Result<Spec, SpecError> {
    parse_in(source, Path::new("."))
}

/// Reads a spec from TOML text whose files (a law table) are relative to `base`, usually the
/// spec file's folder.
pub fn parse_in(source: &str, base: &Path) -> Result<Spec, SpecError> {
    let raw: RawSpec = toml::from_str(source).map_err(|e| SpecError::Syntax(e.to_string()))?;
    let mut r = Reader {
        source,
        base,
        written: HashMap::new(),
    };
    let spec = read(&raw, &mut r)?;
    spec.validate().map_err(|e| r.locate(e))?;
    Ok(spec)
}

/// The spec as written, with defaults for what is not; not yet validated.
fn read(raw: &RawSpec, r: &mut Reader<'_>) -> Result<Spec, SpecError> {
    use Dimension as D;
    let name = match &raw.name {
        None => "design".to_string(),
        Some(n) => {
            let trimmed = n.get_ref().trim().to_string();
            r.remember(
                "name",
                n.span().start,
                quoted(n.get_ref()),
                quoted(&trimmed),
            );
            trimmed
        }
    };
    let law = read_law(raw, r)?;
    let follower = read_follower(raw, r)?;

    let default_part = RawPart::default();
    let p = raw.part.as_ref().unwrap_or(&default_part);
    let defaults = PartSpec::default();
    let thickness = r.or(
        "part.thickness",
        &p.thickness,
        D::Length,
        defaults.thickness_mm,
    )?;
    let part = PartSpec {
        thickness_mm: thickness,
        // A roller as wide as the plate unless its width is given.
        roller_width_mm: r.or("part.roller_width", &p.roller_width, D::Length, thickness)?,
        cam_material: r.material("part.cam_material", &p.cam_material, defaults.cam_material)?,
        roller_material: r.material(
            "part.roller_material",
            &p.roller_material,
            defaults.roller_material,
        )?,
        lead_in_mm: r.or("part.lead_in", &p.lead_in, D::Length, defaults.lead_in_mm)?,
        run_out_mm: r.or("part.run_out", &p.run_out, D::Length, defaults.run_out_mm)?,
        web_mm: r.or("part.web", &p.web, D::Length, defaults.web_mm)?,
        holes: p
            .holes
            .iter()
            .flatten()
            .enumerate()
            .map(|(i, h)| {
                let key = |k: &str| format!("part.holes[{i}].{k}");
                Ok(Hole {
                    x_mm: r.required(&key("x"), &h.x, D::Length)?,
                    y_mm: r.required(&key("y"), &h.y, D::Length)?,
                    diameter_mm: r.required(&key("diameter"), &h.diameter, D::Length)?,
                })
            })
            .collect::<Result<Vec<Hole>, SpecError>>()?,
    };
    let machining = read_machining(raw, r)?;

    let default_checks = RawChecks::default();
    let c = raw.checks.as_ref().unwrap_or(&default_checks);
    let defaults = ChecksSpec::for_materials(&part.cam_material, &part.roller_material);
    let checks = ChecksSpec {
        max_pressure_angle_deg: r.or(
            "checks.max_pressure_angle",
            &c.max_pressure_angle,
            D::Angle,
            defaults.max_pressure_angle_deg,
        )?,
        min_locking_margin_deg: r.or(
            "checks.min_locking_margin",
            &c.min_locking_margin,
            D::Angle,
            defaults.min_locking_margin_deg,
        )?,
        max_contact_stress_mpa: r.or(
            "checks.max_contact_stress",
            &c.max_contact_stress,
            D::Stress,
            defaults.max_contact_stress_mpa,
        )?,
    };

    let default_output = RawOutput::default();
    let o = raw.output.as_ref().unwrap_or(&default_output);
    let defaults = OutputSpec::default();
    let output = OutputSpec {
        chord_tolerance_mm: r.or(
            "output.chord_tolerance",
            &o.chord_tolerance,
            D::Length,
            defaults.chord_tolerance_mm,
        )?,
        fit_tolerance_mm: r.or(
            "output.fit_tolerance",
            &o.fit_tolerance,
            D::Length,
            defaults.fit_tolerance_mm,
        )?,
        stl_tolerance_mm: r.or(
            "output.stl_tolerance",
            &o.stl_tolerance,
            D::Length,
            defaults.stl_tolerance_mm,
        )?,
    };
    let default_tol = RawTolerances::default();
    let t = raw.tolerances.as_ref().unwrap_or(&default_tol);
    let d = TolerancesSpec::default();
    // The band's friction range holds the design's own contact friction unless given: a
    // pin bush's effective coefficient (the ankle spec's, 0.075) lies above the default
    // range, and a part built exactly as designed fell outside its own band of builds (its
    // loading stroke above, its unloading one below, by 5.7 %). Where the design's friction
    // reaches outside the default range, the range reaches from half of it to one and a half
    // times it.
    let design_friction = follower.friction_coefficient();
    let (friction_min, friction_max) = if design_friction.is_finite() && design_friction > 0.0 {
        (
            d.friction_min.min(0.5 * design_friction),
            d.friction_max
                .max((1.5 * design_friction).min(MAX_FRICTION)),
        )
    } else {
        (d.friction_min, d.friction_max)
    };
    let tolerances = TolerancesSpec {
        spring_rate_percent: r.or(
            "tolerances.spring_rate",
            &t.spring_rate,
            D::Percent,
            d.spring_rate_percent,
        )?,
        preload_mm: r.or("tolerances.preload", &t.preload, D::Length, d.preload_mm)?,
        roller_radius_mm: r.or(
            "tolerances.roller_radius",
            &t.roller_radius,
            D::Length,
            d.roller_radius_mm,
        )?,
        profile_mm: r.or("tolerances.profile", &t.profile, D::Length, d.profile_mm)?,
        friction_min: r.or(
            "tolerances.friction_min",
            &t.friction_min,
            D::Dimensionless,
            friction_min,
        )?,
        friction_max: r.or(
            "tolerances.friction_max",
            &t.friction_max,
            D::Dimensionless,
            friction_max,
        )?,
        samples: r.count("tolerances.samples", &t.samples, usize::MAX, d.samples),
        seed: r.count("tolerances.seed", &t.seed, u64::MAX, d.seed),
    };
    let spring_catalogue = match raw
        .follower
        .as_ref()
        .and_then(|f| f.spring_catalogue.as_ref())
    {
        Some(c) => Some(read_catalogue(r, c)?),
        None => None,
    };
    let mut drawing = read_drawing(raw, r)?;
    let revision = raw
        .revision
        .as_ref()
        .map(|t| t.get_ref().trim().to_string());
    // The title block shows the spec's revision unless the drawing names its own.
    if let (Some(rev), None) = (
        &revision,
        raw.drawing.as_ref().and_then(|d| d.revision.as_ref()),
    ) {
        drawing.revision = rev.clone();
    }
    let default_assembly = RawAssembly::default();
    let a = raw.assembly.as_ref().unwrap_or(&default_assembly);
    let assembly = crate::model::Assembly {
        shim_mm: r.or("assembly.shim", &a.shim, D::Length, 0.0)?,
        spring_rate_n_per_mm: r.optional("assembly.spring_rate", &a.spring_rate, D::Stiffness)?,
        spring_part: a
            .spring_part
            .as_ref()
            .map(|t| t.get_ref().trim().to_string()),
        friction: r.optional("assembly.friction", &a.friction, D::Dimensionless)?,
    };
    Ok(Spec {
        revision,
        revision_note: raw
            .revision_note
            .as_ref()
            .map(|t| t.get_ref().trim().to_string()),
        assembly,
        name,
        law,
        follower,
        part,
        machining,
        checks,
        output,
        tolerances,
        drawing,
        spring_catalogue,
    })
}

fn read_law(raw: &RawSpec, r: &mut Reader<'_>) -> Result<LawSpec, SpecError> {
    use Dimension as D;
    let law_raw = raw.law.as_ref().ok_or_else(|| SpecError::Missing {
        key: "law".into(),
        expected: "a [law] table with fmax, fmin, xmax, l0, c0, delta0 (or mu, k2, f0, xmax)"
            .into(),
    })?;
    // One form only: targets, a given law, conditions or a table.
    let forms = [
        (
            "targets (fmax, fmin, l0, c0, delta0)",
            [
                &law_raw.fmax,
                &law_raw.fmin,
                &law_raw.l0,
                &law_raw.c0,
                &law_raw.delta0,
            ]
            .iter()
            .find_map(|q| q.as_ref().map(|q| q.span().start)),
        ),
        (
            "a given law (mu, k2, f0)",
            [&law_raw.mu, &law_raw.k2, &law_raw.f0]
                .iter()
                .find_map(|q| q.as_ref().map(|q| q.span().start)),
        ),
        (
            "conditions",
            law_raw.conditions.as_ref().map(|c| c.span().start),
        ),
        ("table", law_raw.table.as_ref().map(|t| t.span().start)),
        (
            "polynomial",
            law_raw.polynomial.as_ref().map(|p| p.span().start),
        ),
    ];
    let given_forms: Vec<(&str, usize)> = forms
        .iter()
        .filter_map(|(name, at)| at.map(|a| (*name, a)))
        .collect();
    if given_forms.len() > 1 {
        let names: Vec<&str> = given_forms.iter().map(|f| f.0).collect();
        return Err(r.invalid(
            "law",
            given_forms[1].1,
            format!("{} together", names.join(" and ")),
            "one way of stating the law: the paper's targets, a given law mu, k2, f0, three \
             conditions, or a table (docs/SPEC.md)"
                .into(),
        ));
    }
    if let Some(conditions) = &law_raw.conditions {
        let xmax = r.required("law.xmax", &law_raw.xmax, D::Length)?;
        let conditions = conditions
            .get_ref()
            .iter()
            .enumerate()
            .map(|(i, c)| read_condition(r, i, c))
            .collect::<Result<Vec<_>, _>>()?;
        return Ok(LawSpec::Conditions {
            conditions,
            xmax_mm: xmax,
        });
    }
    if let Some(poly) = &law_raw.polynomial {
        // The rules on the whole polynomial name `law.polynomial`: give it this line.
        r.remember(
            "law.polynomial",
            poly.span().start,
            String::new(),
            String::new(),
        );
        let xmax = r.required("law.xmax", &law_raw.xmax, D::Length)?;
        let coefficients = poly
            .get_ref()
            .iter()
            .enumerate()
            .map(|(k, c)| polynomial_coefficient(r, k, c))
            .collect::<Result<Vec<f64>, _>>()?;
        return Ok(LawSpec::Polynomial {
            law: crate::model::PolyLaw { coefficients },
            xmax_mm: xmax,
        });
    }
    if let Some(table) = &law_raw.table {
        let points = read_table(r, table)?;
        let last = points.last().map_or(0.0, |p| p.0);
        let xmax = r.or("law.xmax", &law_raw.xmax, D::Length, last)?;
        return Ok(LawSpec::Table {
            table: crate::model::TableLaw::new(&points),
            source: table.get_ref().clone(),
            xmax_mm: xmax,
        });
    }
    let xmax = r.required("law.xmax", &law_raw.xmax, D::Length)?;
    let given = [&law_raw.mu, &law_raw.k2, &law_raw.f0];
    if given.iter().any(|k| k.is_some()) {
        return Ok(LawSpec::Given {
            law: ExpLaw {
                mu_n: r.required("law.mu", &law_raw.mu, D::Force)?,
                k2_per_mm: r.required("law.k2", &law_raw.k2, D::InverseLength)?,
                f0_n: r.required("law.f0", &law_raw.f0, D::Force)?,
            },
            xmax_mm: xmax,
        });
    }
    Ok(LawSpec::Targets(LawTargets {
        fmax_n: r.required("law.fmax", &law_raw.fmax, D::Force)?,
        fmin_n: r.required("law.fmin", &law_raw.fmin, D::Force)?,
        xmax_mm: xmax,
        l0_mm: r.required("law.l0", &law_raw.l0, D::Length)?,
        c0: r.required("law.c0", &law_raw.c0, D::Dimensionless)?,
        delta0_mm: r.required("law.delta0", &law_raw.delta0, D::Length)?,
    }))
}

/// Coefficient `k` of a polynomial law: N for k = 0, N/mm for k = 1, N/mm^k above (a bare
/// number is read in that unit; `N/mm2` and `N/mm^2` are both accepted).
fn polynomial_coefficient(
    r: &mut Reader<'_>,
    k: usize,
    raw: &Spanned<RawValue>,
) -> Result<f64, SpecError> {
    let key = format!("law.polynomial[{k}]");
    match k {
        0 => r.quantity_value(&key, raw, Dimension::Force),
        1 => r.quantity_value(&key, raw, Dimension::Stiffness),
        _ => {
            let start = raw.span().start;
            let unit = format!("N/mm^{k}");
            let (value, found) = match raw.get_ref() {
                RawValue::Number(n) => (Some(*n), format!("{n}")),
                RawValue::Text(t) => {
                    let text = t.trim();
                    let split = text
                        .find(|c: char| c.is_ascii_alphabetic())
                        .unwrap_or(text.len());
                    let (number, written_unit) = (text[..split].trim(), text[split..].trim());
                    let unit_ok = written_unit.is_empty()
                        || written_unit == unit
                        || written_unit == format!("N/mm{k}");
                    let value = number
                        .parse::<f64>()
                        .ok()
                        .filter(|_| unit_ok && number.len() <= crate::units::MAX_NUMBER_CHARS);
                    (value, quoted(t))
                }
            };
            match value.filter(|v| v.is_finite()) {
                Some(v) => {
                    r.remember(&key, start, found, crate::model::found_value(v, ""));
                    Ok(v)
                }
                None => Err(r.invalid(
                    &key,
                    start,
                    found,
                    format!("a number in {unit}, such as \"2 {unit}\""),
                )),
            }
        }
    }
}

fn read_condition(r: &mut Reader<'_>, i: usize, c: &RawCondition) -> Result<Condition, SpecError> {
    use Dimension as D;
    let key = |k: &str| format!("law.conditions[{i}].{k}");
    match (&c.at, &c.force, &c.stiffness) {
        (Some(_), Some(_), None) => Ok(Condition::Force {
            at_mm: r.required(&key("at"), &c.at, D::Length)?,
            force_n: r.required(&key("force"), &c.force, D::Force)?,
        }),
        (Some(_), None, Some(_)) => Ok(Condition::Stiffness {
            at_mm: r.required(&key("at"), &c.at, D::Length)?,
            stiffness_n_per_mm: r.required(&key("stiffness"), &c.stiffness, D::Stiffness)?,
        }),
        (None, Some(_), Some(_)) => Ok(Condition::StiffnessAtForce {
            force_n: r.required(&key("force"), &c.force, D::Force)?,
            stiffness_n_per_mm: r.required(&key("stiffness"), &c.stiffness, D::Stiffness)?,
        }),
        _ => Err(SpecError::Invalid {
            key: format!("law.conditions[{i}]"),
            line: [&c.at, &c.force, &c.stiffness]
                .iter()
                .find_map(|q| q.as_ref().map(|q| r.line(q.span().start))),
            found: format!(
                "{{ {}}}",
                [
                    ("at", &c.at),
                    ("force", &c.force),
                    ("stiffness", &c.stiffness)
                ]
                .iter()
                .filter(|(_, q)| q.is_some())
                .map(|(n, _)| format!("{n} = ..., "))
                .collect::<String>()
            ),
            expected:
                "a force or a stiffness at a deflection ({ at, force } or { at, stiffness }), \
                       or a stiffness at a force ({ force, stiffness })"
                    .into(),
        }),
    }
}

/// A CSV file named in the spec (a law table, a spring catalogue): its text, read to at
/// most [`MAX_TABLE_BYTES`], and the errors about it, which name the spec's key and line.
struct SpecFile {
    key: &'static str,
    name: String,
    line: usize,
    text: String,
}

impl SpecFile {
    /// Reads the file `name` (relative to the spec's folder) that `key` names.
    fn read(
        r: &Reader<'_>,
        key: &'static str,
        name: &Spanned<String>,
        what: &str,
    ) -> Result<SpecFile, SpecError> {
        use std::io::Read;
        let mut file = SpecFile {
            key,
            name: name.get_ref().clone(),
            line: r.line(name.span().start),
            text: String::new(),
        };
        let path = r.base.join(&file.name);
        let mut text = String::new();
        std::fs::File::open(&path)
            .and_then(|f| f.take(MAX_TABLE_BYTES + 1).read_to_string(&mut text))
            .map_err(|e| {
                file.fail(
                    format!("{}: {e}", path.display()),
                    &format!("a readable CSV file ({what}), relative to the spec's folder"),
                )
            })?;
        if text.len() as u64 > MAX_TABLE_BYTES {
            return Err(file.fail(
                format!(
                    "{}: larger than {} KiB",
                    path.display(),
                    MAX_TABLE_BYTES >> 10
                ),
                "a file of a few thousand rows at most",
            ));
        }
        file.text = text;
        Ok(file)
    }

    /// An error about the file, at the spec's line naming it.
    fn fail(&self, found: String, expected: &str) -> SpecError {
        SpecError::Invalid {
            key: self.key.into(),
            line: Some(self.line),
            found,
            expected: expected.to_string(),
        }
    }

    /// A CSV reader over the text: a header, `#` comments, cells trimmed.
    fn csv(&self) -> csv::Reader<&[u8]> {
        csv::ReaderBuilder::new()
            .comment(Some(b'#'))
            .trim(csv::Trim::All)
            .from_reader(self.text.as_bytes())
    }
}

/// The largest law table read.
const MAX_TABLE_BYTES: u64 = 4 << 20;

/// Reads the law table named in the spec: a CSV file with a column `x_<length unit>` and a
/// column `force_<force unit>` (`x_mm,force_n`, `x_in,force_lbf`, ...), `#` comment lines
/// allowed. Every error names the spec's `law.table` line and the table's line.
fn read_table(r: &mut Reader<'_>, table: &Spanned<String>) -> Result<Vec<(f64, f64)>, SpecError> {
    // Validation of the rows names `law.table`: give it this line.
    r.remember(
        "law.table",
        table.span().start,
        quoted(table.get_ref()),
        String::new(),
    );
    let file = SpecFile::read(r, "law.table", table, "x_mm,force_n")?;
    let name = &file.name;
    let fail = |found: String, expected: &str| file.fail(found, expected);
    let mut rdr = file.csv();
    let header = rdr
        .headers()
        .map_err(|e| fail(format!("{name}: {e}"), "a header x_mm,force_n"))?
        .clone();
    let column = |prefix: &str, dim: Dimension| -> Result<(usize, f64), SpecError> {
        let found: Vec<(usize, &str)> = header
            .iter()
            .enumerate()
            .filter(|(_, h)| h.to_ascii_lowercase().starts_with(prefix))
            .collect();
        let expected = format!(
            "one column {prefix}<unit> with a unit of {} ({})",
            dim.describe(),
            dim.unit_list()
        );
        let [(i, h)] = found[..] else {
            return Err(fail(
                format!(
                    "{name} line 1: header {}",
                    quoted(&header.iter().collect::<Vec<_>>().join(","))
                ),
                &expected,
            ));
        };
        let unit = &h[prefix.len()..];
        dim.units()
            .iter()
            .find(|(u, _)| u.eq_ignore_ascii_case(unit))
            .map(|(_, f)| (i, *f))
            .ok_or_else(|| fail(format!("{name} line 1: column {}", quoted(h)), &expected))
    };
    let (xc, xf) = column("x_", Dimension::Length)?;
    let (fc, ff) = column("force_", Dimension::Force)?;
    let mut points = Vec::new();
    for record in rdr.records() {
        let record = record.map_err(|e| fail(format!("{name}: {e}"), "rows of two numbers"))?;
        let line = record.position().map_or(0, |p| p.line());
        let number = |col: usize, factor: f64| {
            let cell = record.get(col).unwrap_or("");
            cell.parse::<f64>()
                .ok()
                .map(|v| v * factor)
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    fail(
                        format!("{name} line {line}: {}", quoted(cell)),
                        "a finite number in every x and force cell",
                    )
                })
        };
        points.push((number(xc, xf)?, number(fc, ff)?));
    }
    Ok(points)
}

/// The unit a column header names after its prefix: `rate_n_per_mm` -> "N/mm", `x_in` -> "in";
/// matched against the dimension's units without regard to case.
fn header_unit(suffix: &str, dim: Dimension) -> Option<f64> {
    let spelled = suffix.replace("_per_", "/");
    dim.units()
        .iter()
        .find(|(u, _)| u.eq_ignore_ascii_case(&spelled))
        .map(|(_, f)| *f)
}

/// Reads the spring catalogue named in the spec: a CSV file (relative to the spec's folder)
/// with columns `part`, `rate_<unit>`, `free_length_<unit>`, `solid_length_<unit>`,
/// `max_deflection_<unit>`, `outer_diameter_<unit>`; `#` comments allowed.
fn read_catalogue(
    r: &mut Reader<'_>,
    name: &Spanned<String>,
) -> Result<crate::model::SpringCatalogue, SpecError> {
    let spec_file = SpecFile::read(
        r,
        "follower.spring_catalogue",
        name,
        "part,rate_n_per_mm,...",
    )?;
    let file = &spec_file.name;
    let fail = |found: String, expected: &str| spec_file.fail(found, expected);
    let mut rdr = spec_file.csv();
    let header = rdr
        .headers()
        .map_err(|e| fail(format!("{file}: {e}"), "a header"))?
        .clone();
    let expected = "columns part, rate_<unit> (N/mm, lbf/in: rate_n_per_mm), free_length_<unit>, solid_length_<unit>, max_deflection_<unit>, outer_diameter_<unit>";
    let part_col = header
        .iter()
        .position(|h| h.eq_ignore_ascii_case("part"))
        .ok_or_else(|| fail(format!("{file} line 1: no column \"part\""), expected))?;
    let column = |prefix: &str, dim: Dimension| -> Result<(usize, f64), SpecError> {
        header
            .iter()
            .enumerate()
            .find_map(|(i, h)| {
                let lower = h.to_ascii_lowercase();
                let suffix = lower.strip_prefix(prefix)?;
                header_unit(suffix, dim).map(|f| (i, f))
            })
            .ok_or_else(|| fail(format!("{file} line 1: no column {prefix}<unit>"), expected))
    };
    let rate = column("rate_", Dimension::Stiffness)?;
    let free = column("free_length_", Dimension::Length)?;
    let solid = column("solid_length_", Dimension::Length)?;
    let travel = column("max_deflection_", Dimension::Length)?;
    let od = column("outer_diameter_", Dimension::Length)?;
    let mut springs = Vec::new();
    for record in rdr.records() {
        let record = record.map_err(|e| fail(format!("{file}: {e}"), expected))?;
        let line = record.position().map_or(0, |p| p.line());
        let number = |(col, factor): (usize, f64)| {
            let cell = record.get(col).unwrap_or("");
            cell.parse::<f64>()
                .ok()
                .map(|v| v * factor)
                .filter(|v| v.is_finite() && *v > 0.0)
                .ok_or_else(|| {
                    fail(
                        format!("{file} line {line}: {}", quoted(cell)),
                        "a positive number",
                    )
                })
        };
        let spring = crate::model::CatalogueSpring {
            part: record.get(part_col).unwrap_or("").to_string(),
            rate_n_per_mm: number(rate)?,
            free_length_mm: number(free)?,
            solid_length_mm: number(solid)?,
            max_deflection_mm: number(travel)?,
            outer_diameter_mm: number(od)?,
        };
        if spring.part.is_empty() {
            return Err(fail(
                format!("{file} line {line}: an empty part number"),
                "a part number in every row",
            ));
        }
        springs.push(spring);
    }
    if springs.is_empty() {
        return Err(fail(format!("{file}: no springs"), "at least one spring"));
    }
    Ok(crate::model::SpringCatalogue {
        source: file.to_string(),
        springs,
    })
}

fn read_follower(raw: &RawSpec, r: &mut Reader<'_>) -> Result<Follower, SpecError> {
    use Dimension as D;
    let f = raw.follower.as_ref().ok_or_else(|| SpecError::Missing {
        key: "follower".into(),
        expected: "a [follower] table with at least spring_rate and roller_radius".into(),
    })?;
    let count = r.count("follower.count", &f.count, u8::MAX, 1);
    let arrangement = r.choice(
        "follower.spring",
        &f.spring,
        &[
            ("per-follower", SpringArrangement::PerFollower),
            ("shared", SpringArrangement::Shared),
        ],
        SpringArrangement::PerFollower,
    )?;
    let spring_rate = r.required("follower.spring_rate", &f.spring_rate, D::Stiffness)?;
    let preload = r.or("follower.preload", &f.preload, D::Length, 0.0)?;
    let roller_radius = r.required("follower.roller_radius", &f.roller_radius, D::Length)?;
    let friction = match (&f.friction, &f.pin_friction) {
        (Some(q), Some(_)) => {
            return Err(r.invalid(
                "follower.friction",
                q.span().start,
                "both friction and pin_friction".into(),
                "either an effective contact coefficient `friction`, or `pin_friction` with `pin_radius`".into(),
            ))
        }
        (Some(_), None) => FrictionSource::Coefficient {
            coefficient: r.required("follower.friction", &f.friction, D::Dimensionless)?,
        },
        (None, Some(_)) => FrictionSource::Pin {
            pin_friction: r.required("follower.pin_friction", &f.pin_friction, D::Dimensionless)?,
            pin_radius_mm: r.required("follower.pin_radius", &f.pin_radius, D::Length)?,
            rolling_resistance_mm: r.or(
                "follower.rolling_resistance",
                &f.rolling_resistance,
                D::Length,
                0.0,
            )?,
        },
        (None, None) => {
            if let Some(q) = f.pin_radius.as_ref().or(f.rolling_resistance.as_ref()) {
                return Err(r.invalid(
                    "follower.pin_radius",
                    q.span().start,
                    "pin_radius or rolling_resistance without pin_friction".into(),
                    "pin_friction next to pin_radius".into(),
                ));
            }
            FrictionSource::Coefficient { coefficient: 0.0 }
        }
    };
    let friction_correction = r.choice(
        "follower.friction_correction",
        &f.friction_correction,
        &[
            ("loading", FrictionCorrection::Loading),
            ("unloading", FrictionCorrection::Unloading),
            ("midline", FrictionCorrection::Midline),
            ("none", FrictionCorrection::None),
        ],
        FrictionCorrection::Loading,
    )?;
    let bearing = crate::model::RollerBearing {
        dynamic_load_n: r.optional(
            "follower.roller_dynamic_load",
            &f.roller_dynamic_load,
            D::Force,
        )?,
        duty_strokes: r.optional("follower.duty_strokes", &f.duty_strokes, D::Dimensionless)?,
        stroke_rate_hz: r.optional("follower.stroke_rate", &f.stroke_rate, D::Frequency)?,
    };
    Ok(Follower {
        count,
        arrangement,
        spring_rate_n_per_mm: spring_rate,
        preload_mm: preload,
        roller_radius_mm: roller_radius,
        friction,
        friction_correction,
        bearing,
    })
}

fn read_drawing(raw: &RawSpec, r: &mut Reader<'_>) -> Result<DrawingSpec, SpecError> {
    let default_raw = RawDrawing::default();
    let g = raw.drawing.as_ref().unwrap_or(&default_raw);
    let d = DrawingSpec::default();
    let sheet = r.choice(
        "drawing.sheet",
        &g.sheet,
        &[
            ("a4", SheetSize::A4),
            ("a3", SheetSize::A3),
            ("ansi-a", SheetSize::AnsiA),
            ("ansi-b", SheetSize::AnsiB),
        ],
        d.sheet,
    )?;
    let scale = match &g.scale {
        None => None,
        Some(s) if s.get_ref().trim().eq_ignore_ascii_case("auto") => None,
        Some(s) => {
            let text = s.get_ref().trim();
            let parsed = text.split_once(':').and_then(|(a, b)| {
                let (a, b) = (a.trim().parse::<f64>().ok()?, b.trim().parse::<f64>().ok()?);
                (a > 0.0 && b > 0.0 && a.is_finite() && b.is_finite()).then_some(a / b)
            });
            match parsed {
                Some(v) => Some(v),
                None => {
                    return Err(r.invalid(
                        "drawing.scale",
                        s.span().start,
                        quoted(text),
                        "\"auto\" or a ratio such as \"2:1\" or \"1:2\"".into(),
                    ))
                }
            }
        }
    };
    let text = |v: &Option<Spanned<String>>| v.as_ref().map(|s| s.get_ref().trim().to_string());
    let um = |v: Option<f64>, default: f64| v.map_or(default, |mm| mm * 1000.0);
    Ok(DrawingSpec {
        sheet,
        scale,
        number: text(&g.number),
        revision: text(&g.revision).unwrap_or(d.revision),
        date: text(&g.date),
        drawn_by: text(&g.drawn_by),
        general_tolerance: text(&g.general_tolerance).unwrap_or(d.general_tolerance),
        cam_finish_ra_um: um(
            r.optional("drawing.cam_finish", &g.cam_finish, Dimension::Length)?,
            d.cam_finish_ra_um,
        ),
        finish_ra_um: um(
            r.optional("drawing.finish", &g.finish, Dimension::Length)?,
            d.finish_ra_um,
        ),
        coordinate_step_mm: r.optional(
            "drawing.coordinate_step",
            &g.coordinate_step,
            Dimension::Length,
        )?,
    })
}

fn read_machining(raw: &RawSpec, r: &mut Reader<'_>) -> Result<MachiningSpec, SpecError> {
    use Dimension as D;
    let default_raw = RawMachining::default();
    let m = raw.machining.as_ref().unwrap_or(&default_raw);
    let d = MachiningSpec::default();
    let dialect = r.choice(
        "machining.dialect",
        &m.dialect,
        &[
            ("linuxcnc", Dialect::Linuxcnc),
            ("grbl", Dialect::Grbl),
            ("fanuc", Dialect::Fanuc),
        ],
        d.dialect,
    )?;
    let work_offsets: Vec<(&str, WorkOffset)> =
        WorkOffset::ALL.iter().map(|w| (w.word(), *w)).collect();
    let mut len =
        |key: &str, q: &Q, default: f64| r.or(&format!("machining.{key}"), q, D::Length, default);
    let tool_diameter_mm = len("tool_diameter", &m.tool_diameter, d.tool_diameter_mm)?;
    let stock_allowance_mm = len("stock_allowance", &m.stock_allowance, d.stock_allowance_mm)?;
    let safe_z_mm = len("safe_z", &m.safe_z, d.safe_z_mm)?;
    let stock_top_z_mm = len("stock_top_z", &m.stock_top_z, d.stock_top_z_mm)?;
    let breakthrough_mm = len("breakthrough", &m.breakthrough, d.breakthrough_mm)?;
    let tolerance_mm = len("tolerance", &m.tolerance, dialect.default_tolerance_mm())?;
    let lead_in_radius_mm = len("lead_in_radius", &m.lead_in_radius, d.lead_in_radius_mm)?;
    let tab_width_mm = len("tab_width", &m.tab_width, d.tab_width_mm)?;
    let tab_height_mm = len("tab_height", &m.tab_height, d.tab_height_mm)?;
    let skin_mm = len("skin", &m.skin, d.skin_mm)?;
    let flute_length_mm = r.optional("machining.flute_length", &m.flute_length, D::Length)?;
    let spindle_rpm = r.or(
        "machining.spindle_rpm",
        &m.spindle_rpm,
        D::RotationalSpeed,
        d.spindle_rpm,
    )?;
    let feed_mm_per_min = r.or("machining.feed", &m.feed, D::FeedRate, d.feed_mm_per_min)?;
    let plunge_feed_mm_per_min = r.or(
        "machining.plunge_feed",
        &m.plunge_feed,
        D::FeedRate,
        d.plunge_feed_mm_per_min,
    )?;
    let flutes = m
        .flutes
        .as_ref()
        .map(|_| r.count("machining.flutes", &m.flutes, u32::MAX, 0));
    let mut tools = Vec::new();
    if let Some(list) = &m.tools {
        // The list replaces the single tool: its diameter and flutes belong to each tool.
        for (key, given) in [
            (
                "machining.tool_diameter",
                m.tool_diameter.as_ref().map(|v| v.span().start),
            ),
            (
                "machining.flute_length",
                m.flute_length.as_ref().map(|v| v.span().start),
            ),
            (
                "machining.flutes",
                m.flutes.as_ref().map(|v| v.span().start),
            ),
        ] {
            if let Some(at) = given {
                return Err(r.invalid(
                    key,
                    at,
                    "a value next to [[machining.tools]]".into(),
                    "the value on each tool of [[machining.tools]] instead".into(),
                ));
            }
        }
        for (i, t) in list.iter().enumerate() {
            let key = |k: &str| format!("machining.tools[{i}].{k}");
            let number = match &t.number {
                Some(_) => r.count(&key("number"), &t.number, u32::MAX, 0),
                None => i as u32 + 1,
            };
            tools.push(Tool {
                number,
                kind: r.choice(
                    &key("kind"),
                    &t.kind,
                    &[("end-mill", ToolKind::EndMill), ("drill", ToolKind::Drill)],
                    ToolKind::EndMill,
                )?,
                diameter_mm: r.required(&key("diameter"), &t.diameter, D::Length)?,
                flute_length_mm: r.optional(&key("flute_length"), &t.flute_length, D::Length)?,
                flutes: t
                    .flutes
                    .as_ref()
                    .map(|_| r.count(&key("flutes"), &t.flutes, u32::MAX, 0)),
                spindle_rpm: r.or(
                    &key("spindle_rpm"),
                    &t.spindle_rpm,
                    D::RotationalSpeed,
                    spindle_rpm,
                )?,
                feed_mm_per_min: r.or(&key("feed"), &t.feed, D::FeedRate, feed_mm_per_min)?,
                plunge_feed_mm_per_min: r.or(
                    &key("plunge_feed"),
                    &t.plunge_feed,
                    D::FeedRate,
                    plunge_feed_mm_per_min,
                )?,
                peck_mm: r.optional(&key("peck"), &t.peck, D::Length)?,
            });
        }
    }
    // The outline is milled by the first end mill of the list; its diameter decides what
    // concave radius can be made.
    let outline_tool = tools.iter().find(|t| t.kind == ToolKind::EndMill);
    let (tool_diameter_mm, spindle_rpm, feed_mm_per_min, plunge_feed_mm_per_min) =
        match outline_tool {
            Some(t) => (
                t.diameter_mm,
                t.spindle_rpm,
                t.feed_mm_per_min,
                t.plunge_feed_mm_per_min,
            ),
            None => (
                tool_diameter_mm,
                spindle_rpm,
                feed_mm_per_min,
                plunge_feed_mm_per_min,
            ),
        };
    // By default a pass is half the cutter deep, at most 1 mm.
    let depth_default = d.depth_per_pass_mm.min(tool_diameter_mm / 2.0);
    let depth_per_pass_mm = r.or(
        "machining.depth_per_pass",
        &m.depth_per_pass,
        D::Length,
        depth_default,
    )?;
    Ok(MachiningSpec {
        tool_diameter_mm,
        spindle_rpm,
        feed_mm_per_min,
        plunge_feed_mm_per_min,
        depth_per_pass_mm,
        stock_allowance_mm,
        safe_z_mm,
        stock_top_z_mm,
        breakthrough_mm,
        tolerance_mm,
        climb: m.climb.unwrap_or(d.climb),
        lead_in_radius_mm,
        dialect,
        work_offset: r.choice(
            "machining.work_offset",
            &m.work_offset,
            &work_offsets,
            d.work_offset,
        )?,
        coolant: r.choice(
            "machining.coolant",
            &m.coolant,
            &[
                ("flood", Coolant::Flood),
                ("mist", Coolant::Mist),
                ("off", Coolant::Off),
            ],
            d.coolant,
        )?,
        arcs: m.arcs.unwrap_or(d.arcs),
        tabs: r.count("machining.tabs", &m.tabs, usize::MAX, d.tabs),
        tab_width_mm,
        tab_height_mm,
        skin_mm,
        spindle_dwell_s: r.or(
            "machining.spindle_dwell",
            &m.spindle_dwell,
            D::Time,
            d.spindle_dwell_s,
        )?,
        ramp_angle_deg: r.or(
            "machining.ramp_angle",
            &m.ramp_angle,
            D::Angle,
            d.ramp_angle_deg,
        )?,
        rapid_mm_per_min: r.or("machining.rapid", &m.rapid, D::FeedRate, d.rapid_mm_per_min)?,
        flute_length_mm,
        flutes,
        tools,
    })
}

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
    fn every_starter_form_is_a_valid_spec() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("curve.csv"), STARTER_TABLE_CSV).unwrap();
        for form in [
            StarterLaw::Paper,
            StarterLaw::Conditions,
            StarterLaw::Given,
            StarterLaw::Table,
        ] {
            let text = starter_spec(form, "curve.csv");
            let spec = parse_in(&text, dir.path()).unwrap_or_else(|e| panic!("{form:?}: {e}"));
            let expected = match form {
                StarterLaw::Paper => "targets",
                StarterLaw::Conditions => "conditions",
                StarterLaw::Given => "given",
                StarterLaw::Table => "table",
            };
            assert_eq!(spec.law.form(), expected);
            crate::design::design(&spec).unwrap_or_else(|e| panic!("{form:?}: {e}"));
        }
    }

    #[test]
    fn given_law_and_targets_conflict() {
        let e = err(&MINIMAL.replace("[follower]", "mu = 1\n[follower]"));
        assert!(e.contains("one way of stating the law"), "{e}");
        assert!(e.contains("line 8"), "{e}");
    }

    #[test]
    fn shared_spring_needs_two_followers() {
        let e = err(&format!("{MINIMAL}spring = \"shared\"\n"));
        assert!(e.contains("follower.spring"), "{e}");
    }
}
