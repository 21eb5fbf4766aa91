//! The domain model: what a design is made from, in default units (mm, N, N/mm, 1/mm, deg,
//! MPa), and the rules a usable spec obeys.
//!
//! Everything above imports this layer; it imports nothing but [`crate::units`]. A [`Spec`]
//! can come from TOML ([`crate::spec::parse`]) or from code ([`Spec::builder`]); both end in
//! [`Spec::validate`], the single home of every range rule, so the same mistake gets the same
//! error naming the same key whichever way the spec was made.
//!
//! ```
//! use camspring::model::{Follower, LawSpec, LawTargets, PartSpec, Spec};
//! let law = LawSpec::Targets(LawTargets {
//!     fmax_n: 200.0, fmin_n: 5.0, xmax_mm: 20.0, l0_mm: 5.0, c0: 0.2, delta0_mm: 1.0,
//! });
//! let spec = Spec::builder(law.clone(), Follower::new(5.0, 3.0).with_count(2).with_preload(1.5))
//!     .name("mine")
//!     .part(PartSpec::default().with_thickness(12.0))
//!     .build()
//!     .unwrap();
//! assert_eq!(spec.part.roller_width_mm, 12.0);
//! // The same rules as a TOML spec, naming the same key:
//! let err = Spec::builder(law, Follower::new(-5.0, 3.0)).build().unwrap_err();
//! assert!(err.to_string().contains("follower.spring_rate"));
//! ```

pub mod drawing;
pub mod follower;
pub mod law;
pub mod machining;
pub mod part;

use serde::Serialize;

pub use drawing::{DrawingSpec, SheetSize};
pub use follower::{
    CatalogueSpring, Follower, FrictionCorrection, FrictionSource, RollerBearing,
    SpringArrangement, SpringCatalogue, MAX_FRICTION,
};
pub use law::{Condition, ExpLaw, ForceLaw, LawSpec, LawTargets, PolyLaw, TableLaw};
pub use machining::{Coolant, Dialect, MachiningSpec, Tool, ToolKind, WorkOffset};
pub use part::{Hole, Material, PartSpec, MATERIALS};

/// Line contact between cylinders first yields below the surface when the peak Hertz pressure
/// reaches about 1.67 times the tensile yield strength (Tresca, nu = 0.3; K. L. Johnson,
/// *Contact Mechanics*, 1985, section 4.2).
pub const HERTZ_YIELD_FACTOR: f64 = 1.67;

/// The most holding tabs a program may leave on the outline.
pub const MAX_TABS: usize = 16;

/// Limits that keep every accepted spec within bounded work and physical sense (docs/SPEC.md
/// lists them). A value beyond them is refused naming its key.
pub mod limits {
    /// Shortest stroke (mm): below it the part is a speck and its B-spline degenerates.
    pub const MIN_STROKE_MM: f64 = 0.01;
    /// Longest stroke (mm).
    pub const MAX_STROKE_MM: f64 = 10_000.0;
    /// Largest force anywhere in the law (N).
    pub const MAX_FORCE_N: f64 = 1e8;
    /// Largest exponent k2 * Xmax of the law (e^200 is far beyond any spring).
    pub const MAX_EXPONENT: f64 = 200.0;
    /// Largest spring rate (N/mm).
    pub const MAX_SPRING_RATE_N_PER_MM: f64 = 1e7;
    /// Largest length of the part or follower: preload, roller, plate, web, lead-in (mm).
    pub const MAX_LENGTH_MM: f64 = 10_000.0;
    /// Thickest plate (mm).
    pub const MAX_THICKNESS_MM: f64 = 1_000.0;
    /// Most coefficients of a polynomial law (degree 7).
    pub const MAX_POLYNOMIAL_TERMS: usize = 8;
    /// Most mounting holes.
    pub const MAX_HOLES: usize = 100;
    /// Largest cutter (mm).
    pub const MAX_TOOL_DIAMETER_MM: f64 = 100.0;
    /// Most depth levels a program may cut (thickness plus breakthrough over depth per pass).
    pub const MAX_DEPTH_LEVELS: f64 = 500.0;
    /// Longest design name (it names a folder).
    pub const MAX_NAME_CHARS: usize = 100;
}

use limits::*;

/// Why a spec was refused. Every variant names the key it is about.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpecError {
    /// Produced by the TOML reader ([`crate::spec::parse`]) for syntax errors, unknown keys
    /// and wrong value types; the message gives line, column and the key.
    #[error("{0}")]
    Syntax(String),
    /// Produced by [`Spec::validate`] (and the TOML reader, for a wrong unit) for a value out
    /// of range, not finite, or inconsistent with another key.
    #[error("{}`{key}` = {found}: expected {expected}", line_prefix(*.line))]
    Invalid {
        /// Dotted key path, e.g. `follower.spring_rate`.
        key: String,
        /// 1-based line of the value in the spec, when known.
        line: Option<usize>,
        /// The value as written (TOML) or in default units (code).
        found: String,
        /// What would have been accepted.
        expected: String,
    },
    /// Produced by the TOML reader when a required key is absent.
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

impl SpecError {
    /// The 1-based line of the spec the error is about, when known.
    pub fn line(&self) -> Option<usize> {
        match self {
            SpecError::Invalid { line, .. } => *line,
            SpecError::Syntax(message) => message
                .strip_prefix("TOML parse error at line ")
                .and_then(|r| r.split(',').next())
                .and_then(|n| n.trim().parse().ok()),
            SpecError::Missing { .. } => None,
        }
    }

    /// The key the error is about, if it names one.
    pub fn key(&self) -> Option<&str> {
        match self {
            SpecError::Syntax(_) => None,
            SpecError::Invalid { key, .. } | SpecError::Missing { key, .. } => Some(key),
        }
    }
}

/// Limits for the design checks.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ChecksSpec {
    /// Largest acceptable pressure angle.
    pub max_pressure_angle_deg: f64,
    /// Smallest acceptable margin from self-locking (loading: 90 deg - (theta + phi);
    /// unloading: theta - phi).
    pub min_locking_margin_deg: f64,
    /// Largest acceptable Hertz contact pressure (default: [`HERTZ_YIELD_FACTOR`] x the weaker
    /// yield strength, the onset of subsurface yield in a line contact).
    pub max_contact_stress_mpa: f64,
}

impl ChecksSpec {
    /// The default limits for a cam and roller of these materials.
    pub fn for_materials(cam: &Material, roller: &Material) -> ChecksSpec {
        ChecksSpec {
            max_pressure_angle_deg: 60.0,
            min_locking_margin_deg: 5.0,
            max_contact_stress_mpa: HERTZ_YIELD_FACTOR
                * cam.yield_strength_mpa.min(roller.yield_strength_mpa),
        }
    }
}

impl Default for ChecksSpec {
    /// 60 deg, 5 deg, and the contact limit of the default materials.
    fn default() -> Self {
        ChecksSpec::for_materials(&Material::default_cam(), &Material::default_roller())
    }
}

/// How far a built spring may be from the design: the tolerances of its parts. Each is
/// drawn uniformly within its range by the Monte Carlo of [`crate::cam::tolerance`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TolerancesSpec {
    /// Spring rate, +- percent of the rate (springs: +-10 %).
    pub spring_rate_percent: f64,
    /// Preload, +- mm (shims: +-0.1 mm).
    pub preload_mm: f64,
    /// Roller radius, +- mm.
    pub roller_radius_mm: f64,
    /// Cam profile, +- mm normal to the surface (milling: +-0.02 mm).
    pub profile_mm: f64,
    /// Smallest contact friction coefficient of a build.
    pub friction_min: f64,
    /// Largest contact friction coefficient of a build.
    pub friction_max: f64,
    /// Builds drawn.
    pub samples: usize,
    /// Seed of the draw (the band is reproducible).
    pub seed: u64,
}

impl Default for TolerancesSpec {
    /// Catalogue springs (+-10 %), shims (+-0.1 mm), a bearing's outer ring (+-0.01 mm), a
    /// milled profile (+-0.02 mm), friction from 0.005 to 0.05 (a spec's reading widens it to
    /// hold the design's own friction), 2000 builds, seed 1.
    fn default() -> Self {
        TolerancesSpec {
            spring_rate_percent: 10.0,
            preload_mm: 0.1,
            roller_radius_mm: 0.01,
            profile_mm: 0.02,
            friction_min: 0.005,
            friction_max: 0.05,
            samples: 2000,
            seed: 1,
        }
    }
}

/// The most builds a tolerance band draws.
pub const MAX_TOLERANCE_SAMPLES: usize = 1_000_000;

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

impl Default for OutputSpec {
    /// 1 um chords and B-spline fit, 5 um STL.
    fn default() -> Self {
        OutputSpec {
            chord_tolerance_mm: 1e-3,
            fit_tolerance_mm: 1e-3,
            stl_tolerance_mm: 5e-3,
        }
    }
}

/// A design spec in default units.
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
    /// Tolerances of the build, for the force band.
    pub tolerances: TolerancesSpec,
    /// The shop drawing's sheet, scale, title block and notes.
    pub drawing: DrawingSpec,
    /// Springs to choose from (`follower.spring_catalogue`), for `camspring springs`.
    pub spring_catalogue: Option<SpringCatalogue>,
    /// The design's revision (`revision`, e.g. "B" from `camspring revise`).
    pub revision: Option<String>,
    /// What the revision changed and why (`revision_note`).
    pub revision_note: Option<String>,
    /// The parts the cam is assembled with, where they differ from those it was cut for.
    pub assembly: Assembly,
}

/// The parts a cam is assembled with, where they differ from the `[follower]` it was cut for
/// (`[assembly]`, written by `camspring revise` for a shim or a catalogue spring). The cam
/// itself is always synthesised for `[follower]`.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Assembly {
    /// The preload as assembled minus `follower.preload`, as follower travel (mm; negative is
    /// less compression): the build's measured preload error plus the shims a revision adds.
    pub shim_mm: f64,
    /// Rate of each physical spring fitted, when another than `follower.spring_rate`.
    pub spring_rate_n_per_mm: Option<f64>,
    /// The fitted spring's catalogue part, if any.
    pub spring_part: Option<String>,
    /// The contact friction coefficient as measured on the build, when another than the
    /// follower's (it changes what the build's force curves look like, not the cam).
    pub friction: Option<f64>,
}

impl Assembly {
    /// Whether anything differs from the follower the cam was cut for.
    pub fn is_changed(&self) -> bool {
        self.shim_mm != 0.0 || self.spring_rate_n_per_mm.is_some() || self.friction.is_some()
    }
}

/// Builds a [`Spec`] in code: the law and the followers are required, every other section
/// takes its `Default` unless given. [`SpecBuilder::build`] validates.
#[derive(Debug, Clone)]
pub struct SpecBuilder {
    spec: Spec,
    checks_given: bool,
}

impl SpecBuilder {
    /// The design name (default "design").
    pub fn name(mut self, name: impl Into<String>) -> Self {
        self.spec.name = name.into();
        self
    }

    /// The part.
    pub fn part(mut self, part: PartSpec) -> Self {
        self.spec.part = part;
        self
    }

    /// The machining settings.
    pub fn machining(mut self, machining: MachiningSpec) -> Self {
        self.spec.machining = machining;
        self
    }

    /// The check limits (default: [`ChecksSpec::for_materials`] of the part's materials).
    pub fn checks(mut self, checks: ChecksSpec) -> Self {
        self.spec.checks = checks;
        self.checks_given = true;
        self
    }

    /// The output sampling settings.
    pub fn output(mut self, output: OutputSpec) -> Self {
        self.spec.output = output;
        self
    }

    /// The validated spec, or the first rule it breaks.
    pub fn build(mut self) -> Result<Spec, SpecError> {
        if !self.checks_given {
            let p = &self.spec.part;
            self.spec.checks = ChecksSpec::for_materials(&p.cam_material, &p.roller_material);
        }
        self.spec.validate()?;
        Ok(self.spec)
    }
}

/// An allowed range of a quantity, in default units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Range {
    /// value > 0
    Positive,
    /// value >= 0
    NonNegative,
    /// any finite value
    Any,
    /// lo < value < hi
    Open(f64, f64),
    /// lo <= value < hi
    HalfOpen(f64, f64),
    /// lo <= value <= hi
    Closed(f64, f64),
}

impl Range {
    /// Whether `v` is finite and in the range.
    pub fn contains(self, v: f64) -> bool {
        v.is_finite()
            && match self {
                Range::Positive => v > 0.0,
                Range::NonNegative => v >= 0.0,
                Range::Any => true,
                Range::Open(lo, hi) => v > lo && v < hi,
                Range::HalfOpen(lo, hi) => v >= lo && v < hi,
                Range::Closed(lo, hi) => v >= lo && v <= hi,
            }
    }

    /// "a value greater than 0", "a value from 1 mm to 2 mm", ...
    pub fn describe(self, unit: &str) -> String {
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

/// The value as [`Spec::validate`] reports it: the number and its default unit.
pub fn found_value(value: f64, unit: &str) -> String {
    if unit.is_empty() {
        format!("{value}")
    } else {
        format!("{value} {unit}")
    }
}

/// An error for `key` = `found`, expecting `expected`.
fn invalid(key: &str, found: String, expected: String) -> SpecError {
    SpecError::Invalid {
        key: key.to_string(),
        line: None,
        found,
        expected,
    }
}

/// `value` must lie in `range`; the error names `key`.
fn check(key: &str, value: f64, range: Range, unit: &str) -> Result<(), SpecError> {
    if range.contains(value) {
        Ok(())
    } else {
        let expected = if value.is_finite() {
            range.describe(unit)
        } else {
            "a finite value".to_string()
        };
        Err(invalid(key, found_value(value, unit), expected))
    }
}

/// Whether `name` can name an output folder: letters, digits, '-', '_' or '.', not starting
/// with '.'.
pub fn is_valid_name(name: &str) -> bool {
    !name.is_empty()
        && name.chars().count() <= MAX_NAME_CHARS
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
        && !name.starts_with('.')
}

impl Spec {
    /// A builder for a spec made in code; see the module example.
    pub fn builder(law: LawSpec, follower: Follower) -> SpecBuilder {
        SpecBuilder {
            spec: Spec {
                name: "design".into(),
                law,
                follower,
                part: PartSpec::default(),
                machining: MachiningSpec::default(),
                checks: ChecksSpec::default(),
                output: OutputSpec::default(),
                tolerances: TolerancesSpec::default(),
                drawing: DrawingSpec::default(),
                spring_catalogue: None,
                revision: None,
                revision_note: None,
                assembly: Assembly::default(),
            },
            checks_given: false,
        }
    }

    /// The run's identity: the first 16 hex digits of the SHA-256 of the camspring version and
    /// the spec as understood. Every output of a run carries it (design.json, and the header of
    /// every format that has one), so a file from another run is detectable.
    pub fn run_id(&self) -> String {
        use sha2::{Digest, Sha256};
        let mut h = Sha256::new();
        h.update(env!("CARGO_PKG_VERSION").as_bytes());
        h.update(b"\n");
        // Serialising plain numbers, strings and enums cannot fail; an empty text would
        // still give an identity of the version alone.
        h.update(serde_json::to_vec(self).unwrap_or_default());
        h.finalize()[..8]
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect()
    }

    /// Checks every range rule and every rule between keys, section by section, and returns
    /// the first broken one, naming its key. A spec from TOML, from the builder or changed by
    /// a sweep all pass through here.
    pub fn validate(&self) -> Result<(), SpecError> {
        if !is_valid_name(&self.name) {
            return Err(invalid(
                "name",
                crate::units::quoted(&self.name),
                format!("a name of 1 to {MAX_NAME_CHARS} letters, digits, '-', '_' or '.', not starting with '.' (it names the output folder)"),
            ));
        }
        validate_law(&self.law)?;
        validate_follower(&self.follower)?;
        validate_part(&self.part)?;
        validate_machining(&self.machining, &self.part)?;
        validate_checks(&self.checks)?;
        validate_output(&self.output)?;
        validate_tolerances(&self.tolerances)?;
        validate_drawing(&self.drawing)?;
        validate_assembly(&self.assembly, &self.follower)
    }
}

fn validate_assembly(a: &Assembly, f: &Follower) -> Result<(), SpecError> {
    if !a.shim_mm.is_finite() || f.preload_mm + a.shim_mm < 0.0 {
        return Err(invalid(
            "assembly.shim",
            found_value(a.shim_mm, "mm"),
            format!(
                "a length of at least -{} mm (follower.preload: a spring cannot be less than unloaded)",
                f.preload_mm
            ),
        ));
    }
    if let Some(rate) = a.spring_rate_n_per_mm {
        check(
            "assembly.spring_rate",
            rate,
            Range::Open(0.0, MAX_SPRING_RATE_N_PER_MM),
            "N/mm",
        )?;
    }
    if let Some(mu) = a.friction {
        check(
            "assembly.friction",
            mu,
            Range::HalfOpen(0.0, MAX_FRICTION),
            "",
        )?;
    }
    Ok(())
}

fn stroke() -> Range {
    Range::Closed(MIN_STROKE_MM, MAX_STROKE_MM)
}

fn validate_law(law: &LawSpec) -> Result<(), SpecError> {
    match law {
        LawSpec::Targets(t) => {
            let force = Range::Open(0.0, MAX_FORCE_N);
            check("law.fmax", t.fmax_n, force, "N")?;
            check("law.fmin", t.fmin_n, force, "N")?;
            check("law.xmax", t.xmax_mm, stroke(), "mm")?;
            if !Range::Positive.contains(t.l0_mm) {
                return Err(invalid(
                    "law.l0",
                    found_value(t.l0_mm, "mm"),
                    "a rest length greater than 0 (the paper's targets hold Fmin at L0 > 0); for a \
                     force at zero deflection state the law as conditions, e.g. \
                     conditions = [{ at = \"0 mm\", force = \"40 N\" }, ...] (docs/SPEC.md)"
                        .into(),
                ));
            }
            check("law.c0", t.c0, Range::Positive, "")?;
            check("law.delta0", t.delta0_mm, Range::Positive, "mm")?;
            if t.fmax_n <= t.fmin_n {
                return Err(invalid(
                    "law.fmax",
                    found_value(t.fmax_n, "N"),
                    format!("a force greater than law.fmin = {} N", t.fmin_n),
                ));
            }
            if t.xmax_mm <= t.l0_mm {
                return Err(invalid(
                    "law.xmax",
                    found_value(t.xmax_mm, "mm"),
                    format!("a deflection greater than law.l0 = {} mm", t.l0_mm),
                ));
            }
            Ok(())
        }
        LawSpec::Conditions {
            conditions,
            xmax_mm,
        } => {
            check("law.xmax", *xmax_mm, stroke(), "mm")?;
            if conditions.len() != 3 {
                return Err(invalid(
                    "law.conditions",
                    format!("{} conditions", conditions.len()),
                    "exactly three: force or stiffness at a deflection, or stiffness at a force"
                        .into(),
                ));
            }
            let force = Range::Open(0.0, MAX_FORCE_N);
            let stiffness = Range::Open(0.0, MAX_SPRING_RATE_N_PER_MM);
            let at = Range::Closed(0.0, *xmax_mm);
            for (i, c) in conditions.iter().enumerate() {
                let key = |k: &str| format!("law.conditions[{i}].{k}");
                match *c {
                    Condition::Force { at_mm, force_n } => {
                        check(&key("at"), at_mm, at, "mm")?;
                        check(&key("force"), force_n, force, "N")?;
                    }
                    Condition::Stiffness {
                        at_mm,
                        stiffness_n_per_mm,
                    } => {
                        check(&key("at"), at_mm, at, "mm")?;
                        check(&key("stiffness"), stiffness_n_per_mm, stiffness, "N/mm")?;
                    }
                    Condition::StiffnessAtForce {
                        force_n,
                        stiffness_n_per_mm,
                    } => {
                        check(&key("force"), force_n, force, "N")?;
                        check(&key("stiffness"), stiffness_n_per_mm, stiffness, "N/mm")?;
                    }
                }
            }
            Ok(())
        }
        LawSpec::Polynomial { law, xmax_mm } => {
            check("law.xmax", *xmax_mm, stroke(), "mm")?;
            let n = law.coefficients.len();
            if !(1..=MAX_POLYNOMIAL_TERMS).contains(&n) {
                return Err(invalid(
                    "law.polynomial",
                    format!("{n} coefficients"),
                    format!("1 to {MAX_POLYNOMIAL_TERMS} coefficients, from the constant (N) up"),
                ));
            }
            for (k, c) in law.coefficients.iter().enumerate() {
                check(&format!("law.polynomial[{k}]"), *c, Range::Any, "")?;
            }
            // Positive and never softening over the stroke, checked on a fine grid (a
            // polynomial of this degree cannot turn between grid points this close).
            let steps = 2000;
            for i in 0..=steps {
                let x = xmax_mm * i as f64 / steps as f64;
                let (f, s) = (law.force_n(x), law.stiffness_n_per_mm(x));
                let fails = if !(f > 0.0 && f < MAX_FORCE_N) {
                    Some(format!("a force of {f:.6} N at x = {x} mm"))
                } else if s < 0.0 {
                    Some(format!(
                        "a falling force (stiffness {s:.6} N/mm) at x = {x} mm"
                    ))
                } else {
                    None
                };
                if let Some(found) = fails {
                    return Err(invalid(
                        "law.polynomial",
                        found,
                        format!("a positive force below {MAX_FORCE_N:e} N that never decreases over 0 ... law.xmax"),
                    ));
                }
            }
            Ok(())
        }
        LawSpec::Table { table, xmax_mm, .. } => {
            let n = table.x_mm.len();
            if n < 2 {
                return Err(invalid(
                    "law.table",
                    format!("{n} row(s)"),
                    "at least two rows (x, force), the first at x = 0".into(),
                ));
            }
            let row = |k: usize| format!("data row {}", k + 1);
            for (k, (x, f)) in table.points().enumerate() {
                if !(x.is_finite() && f.is_finite()) {
                    return Err(invalid("law.table", row(k), "finite numbers".into()));
                }
                if k == 0 && x != 0.0 {
                    return Err(invalid(
                        "law.table",
                        format!("{}: x = {x} mm", row(k)),
                        "the first row at x = 0 (the law starts at no deflection)".into(),
                    ));
                }
                if !(f > 0.0 && f < MAX_FORCE_N) {
                    return Err(invalid(
                        "law.table",
                        format!("{}: force {f} N", row(k)),
                        format!("a positive force below {MAX_FORCE_N:e} N"),
                    ));
                }
                if k > 0 {
                    let (x0, f0) = (table.x_mm[k - 1], table.force_n[k - 1]);
                    if x <= x0 {
                        return Err(invalid(
                            "law.table",
                            format!("{}: x = {x} mm after {x0} mm", row(k)),
                            "deflections strictly increasing".into(),
                        ));
                    }
                    if f < f0 {
                        return Err(invalid(
                            "law.table",
                            format!("{}: force {f} N after {f0} N", row(k)),
                            "forces that never decrease (a spring's force grows with deflection)"
                                .into(),
                        ));
                    }
                }
            }
            let last = table.x_mm[n - 1];
            check(
                "law.xmax",
                *xmax_mm,
                Range::Closed(MIN_STROKE_MM, last.min(MAX_STROKE_MM)),
                "mm",
            )
        }
        LawSpec::Given { law, xmax_mm } => {
            check("law.xmax", *xmax_mm, stroke(), "mm")?;
            check("law.mu", law.mu_n, Range::Open(0.0, MAX_FORCE_N), "N")?;
            check(
                "law.k2",
                law.k2_per_mm,
                Range::Open(0.0, MAX_EXPONENT / xmax_mm),
                "1/mm",
            )?;
            check(
                "law.f0",
                law.f0_n,
                Range::Open(-MAX_FORCE_N, MAX_FORCE_N),
                "N",
            )?;
            let fmax = law.force_n(*xmax_mm);
            if !fmax.is_finite() || fmax.abs() >= MAX_FORCE_N {
                return Err(invalid(
                    "law.mu",
                    found_value(law.mu_n, "N"),
                    format!(
                        "a law whose force at law.xmax stays below {MAX_FORCE_N:e} N (it reaches {fmax:e} N)"
                    ),
                ));
            }
            Ok(())
        }
    }
}

fn validate_follower(f: &Follower) -> Result<(), SpecError> {
    if !matches!(f.count, 1 | 2) {
        return Err(invalid(
            "follower.count",
            f.count.to_string(),
            "1 (one follower) or 2 (two followers on opposed cam surfaces)".into(),
        ));
    }
    if f.arrangement == SpringArrangement::Shared && f.count != 2 {
        return Err(invalid(
            "follower.spring",
            "\"shared\" with follower.count = 1".into(),
            "\"per-follower\", or count = 2: a shared spring joins two opposed followers".into(),
        ));
    }
    check(
        "follower.spring_rate",
        f.spring_rate_n_per_mm,
        Range::Open(0.0, MAX_SPRING_RATE_N_PER_MM),
        "N/mm",
    )?;
    let length = Range::Closed(0.0, MAX_LENGTH_MM);
    check("follower.preload", f.preload_mm, length, "mm")?;
    check("follower.roller_radius", f.roller_radius_mm, length, "mm")?;
    let b = &f.bearing;
    for (key, value, range, unit) in [
        (
            "follower.roller_dynamic_load",
            b.dynamic_load_n,
            Range::Open(0.0, MAX_FORCE_N),
            "N",
        ),
        (
            "follower.duty_strokes",
            b.duty_strokes,
            Range::Open(0.0, 1e15),
            "",
        ),
        (
            "follower.stroke_rate",
            b.stroke_rate_hz,
            Range::Open(0.0, 1e4),
            "Hz",
        ),
    ] {
        if let Some(v) = value {
            check(key, v, range, unit)?;
        }
    }
    let friction_range = Range::HalfOpen(0.0, MAX_FRICTION);
    match f.friction {
        FrictionSource::Coefficient { coefficient } => {
            check("follower.friction", coefficient, friction_range, "")?
        }
        FrictionSource::Pin {
            pin_friction,
            pin_radius_mm,
            rolling_resistance_mm,
        } => {
            check("follower.pin_friction", pin_friction, friction_range, "")?;
            check("follower.pin_radius", pin_radius_mm, Range::Positive, "mm")?;
            if pin_radius_mm >= f.roller_radius_mm {
                return Err(invalid(
                    "follower.pin_radius",
                    found_value(pin_radius_mm, "mm"),
                    format!(
                        "a pin radius smaller than follower.roller_radius = {} mm",
                        f.roller_radius_mm
                    ),
                ));
            }
            check(
                "follower.rolling_resistance",
                rolling_resistance_mm,
                Range::NonNegative,
                "mm",
            )?;
            let mu_f = f.friction_coefficient();
            if mu_f >= MAX_FRICTION {
                return Err(invalid(
                    "follower.pin_friction",
                    format!("an effective contact coefficient of {mu_f:.4}"),
                    format!("an effective coefficient below {MAX_FRICTION} (pin_friction * pin_radius / roller_radius + rolling_resistance / roller_radius)"),
                ));
            }
        }
    }
    Ok(())
}

fn validate_material(key: &str, m: &Material) -> Result<(), SpecError> {
    check(
        &format!("{key}.youngs_modulus"),
        m.youngs_modulus_mpa,
        Range::Positive,
        "MPa",
    )?;
    check(
        &format!("{key}.poisson_ratio"),
        m.poisson_ratio,
        Range::Open(-1.0, 0.5),
        "",
    )?;
    check(
        &format!("{key}.yield_strength"),
        m.yield_strength_mpa,
        Range::Positive,
        "MPa",
    )
}

fn validate_part(p: &PartSpec) -> Result<(), SpecError> {
    check("part.thickness", p.thickness_mm, Range::Positive, "mm")?;
    check(
        "part.roller_width",
        p.roller_width_mm,
        Range::Positive,
        "mm",
    )?;
    validate_material("part.cam_material", &p.cam_material)?;
    validate_material("part.roller_material", &p.roller_material)?;
    let length = Range::Closed(0.0, MAX_LENGTH_MM);
    check("part.lead_in", p.lead_in_mm, length, "mm")?;
    check("part.run_out", p.run_out_mm, length, "mm")?;
    check("part.web", p.web_mm, Range::Open(0.0, MAX_LENGTH_MM), "mm")?;
    if p.holes.len() > MAX_HOLES {
        return Err(invalid(
            "part.holes",
            format!("{} holes", p.holes.len()),
            format!("at most {MAX_HOLES} holes"),
        ));
    }
    let place = Range::Closed(-MAX_LENGTH_MM, MAX_LENGTH_MM);
    for (i, h) in p.holes.iter().enumerate() {
        check(&format!("part.holes[{i}].x"), h.x_mm, place, "mm")?;
        check(&format!("part.holes[{i}].y"), h.y_mm, place, "mm")?;
        check(
            &format!("part.holes[{i}].diameter"),
            h.diameter_mm,
            Range::Open(0.0, MAX_LENGTH_MM),
            "mm",
        )?;
    }
    Ok(())
}

fn validate_machining(m: &MachiningSpec, part: &PartSpec) -> Result<(), SpecError> {
    check(
        "machining.tool_diameter",
        m.tool_diameter_mm,
        Range::Closed(0.01, MAX_TOOL_DIAMETER_MM),
        "mm",
    )?;
    check(
        "machining.spindle_rpm",
        m.spindle_rpm,
        Range::Open(0.0, 200_000.0),
        "rpm",
    )?;
    check(
        "machining.feed",
        m.feed_mm_per_min,
        Range::Positive,
        "mm/min",
    )?;
    check(
        "machining.plunge_feed",
        m.plunge_feed_mm_per_min,
        Range::Positive,
        "mm/min",
    )?;
    check(
        "machining.depth_per_pass",
        m.depth_per_pass_mm,
        Range::Positive,
        "mm",
    )?;
    // A pass deeper than the cutter diameter overloads an end mill slotting full width.
    if m.depth_per_pass_mm > m.tool_diameter_mm {
        return Err(invalid(
            "machining.depth_per_pass",
            found_value(m.depth_per_pass_mm, "mm"),
            format!(
                "at most the tool diameter, {} mm (full-width slotting)",
                m.tool_diameter_mm
            ),
        ));
    }
    let length = Range::Closed(0.0, MAX_LENGTH_MM);
    let height = Range::Closed(-MAX_LENGTH_MM, MAX_LENGTH_MM);
    check(
        "machining.stock_allowance",
        m.stock_allowance_mm,
        length,
        "mm",
    )?;
    check("machining.safe_z", m.safe_z_mm, height, "mm")?;
    check("machining.stock_top_z", m.stock_top_z_mm, height, "mm")?;
    if m.safe_z_mm <= m.stock_top_z_mm {
        return Err(invalid(
            "machining.safe_z",
            found_value(m.safe_z_mm, "mm"),
            format!(
                "a height above machining.stock_top_z = {} mm",
                m.stock_top_z_mm
            ),
        ));
    }
    check(
        "machining.breakthrough",
        m.breakthrough_mm,
        Range::Closed(0.0, MAX_THICKNESS_MM),
        "mm",
    )?;
    let levels = ((part.thickness_mm + m.breakthrough_mm) / m.depth_per_pass_mm).ceil();
    if levels > MAX_DEPTH_LEVELS {
        return Err(invalid(
            "machining.depth_per_pass",
            found_value(m.depth_per_pass_mm, "mm"),
            format!(
                "at least {:.4} mm: part.thickness + machining.breakthrough = {} mm would take {levels} depth levels (at most {MAX_DEPTH_LEVELS})",
                (part.thickness_mm + m.breakthrough_mm) / MAX_DEPTH_LEVELS,
                part.thickness_mm + m.breakthrough_mm
            ),
        ));
    }
    check(
        "machining.tolerance",
        m.tolerance_mm,
        Range::Closed(1e-5, 0.5),
        "mm",
    )?;
    check(
        "machining.lead_in_radius",
        m.lead_in_radius_mm,
        Range::Open(0.0, MAX_LENGTH_MM),
        "mm",
    )?;
    if m.tabs > MAX_TABS {
        return Err(invalid(
            "machining.tabs",
            m.tabs.to_string(),
            format!("a number of tabs from 0 to {MAX_TABS}"),
        ));
    }
    check("machining.tab_width", m.tab_width_mm, Range::Positive, "mm")?;
    check(
        "machining.tab_height",
        m.tab_height_mm,
        Range::Positive,
        "mm",
    )?;
    // Tab height matters only when tabs are left.
    if m.tabs > 0 && m.tab_height_mm >= part.thickness_mm {
        return Err(invalid(
            "machining.tab_height",
            found_value(m.tab_height_mm, "mm"),
            format!("less than part.thickness = {} mm", part.thickness_mm),
        ));
    }
    check(
        "machining.skin",
        m.skin_mm,
        Range::HalfOpen(0.0, part.thickness_mm),
        "mm",
    )?;
    check(
        "machining.spindle_dwell",
        m.spindle_dwell_s,
        Range::Closed(0.0, 600.0),
        "s",
    )?;
    check(
        "machining.ramp_angle",
        m.ramp_angle_deg,
        Range::Closed(0.5, 45.0),
        "deg",
    )?;
    check(
        "machining.rapid",
        m.rapid_mm_per_min,
        Range::Positive,
        "mm/min",
    )?;
    if let Some(l) = m.flute_length_mm {
        check(
            "machining.flute_length",
            l,
            Range::Open(0.0, MAX_LENGTH_MM),
            "mm",
        )?;
    }
    if let Some(n) = m.flutes {
        check_flutes("machining.flutes", n)?;
    }
    let mut numbers = std::collections::BTreeSet::new();
    for (i, t) in m.tools.iter().enumerate() {
        let key = |k: &str| format!("machining.tools[{i}].{k}");
        if !(1..=MAX_TOOL_NUMBER).contains(&t.number) {
            return Err(invalid(
                &key("number"),
                t.number.to_string(),
                format!("a tool number from 1 to {MAX_TOOL_NUMBER}"),
            ));
        }
        if !numbers.insert(t.number) {
            return Err(invalid(
                &key("number"),
                t.number.to_string(),
                "a number no other tool of the list has".into(),
            ));
        }
        check(
            &key("diameter"),
            t.diameter_mm,
            Range::Closed(0.01, MAX_TOOL_DIAMETER_MM),
            "mm",
        )?;
        if let Some(l) = t.flute_length_mm {
            check(
                &key("flute_length"),
                l,
                Range::Open(0.0, MAX_LENGTH_MM),
                "mm",
            )?;
        }
        if let Some(n) = t.flutes {
            check_flutes(&key("flutes"), n)?;
        }
        check(
            &key("spindle_rpm"),
            t.spindle_rpm,
            Range::Open(0.0, 200_000.0),
            "rpm",
        )?;
        check(&key("feed"), t.feed_mm_per_min, Range::Positive, "mm/min")?;
        check(
            &key("plunge_feed"),
            t.plunge_feed_mm_per_min,
            Range::Positive,
            "mm/min",
        )?;
        if let Some(q) = t.peck_mm {
            check(&key("peck"), q, Range::Open(0.0, MAX_LENGTH_MM), "mm")?;
        }
    }
    if !m.tools.is_empty() && !m.tools.iter().any(|t| t.kind == ToolKind::EndMill) {
        return Err(invalid(
            "machining.tools",
            format!("{} drills and no end mill", m.tools.len()),
            "at least one end mill (kind = \"end-mill\"): the first mills the outline".into(),
        ));
    }
    Ok(())
}

/// Largest tool number (T word) accepted.
pub const MAX_TOOL_NUMBER: u32 = 99;

fn check_flutes(key: &str, n: u32) -> Result<(), SpecError> {
    if !(1..=12).contains(&n) {
        return Err(invalid(key, n.to_string(), "from 1 to 12 flutes".into()));
    }
    Ok(())
}

/// Longest text accepted in a title-block field.
pub const MAX_TITLE_FIELD_CHARS: usize = 40;

fn validate_drawing(d: &DrawingSpec) -> Result<(), SpecError> {
    if let Some(s) = d.scale {
        if !drawing::STANDARD_SCALES
            .iter()
            .any(|v| (v - s).abs() < 1e-9)
        {
            return Err(invalid(
                "drawing.scale",
                drawing::scale_label(s),
                "a standard scale: 10:1, 5:1, 2:1, 1:1, 1:2, 1:5, 1:10, 1:20 or 1:50".into(),
            ));
        }
    }
    for (key, text) in [
        ("drawing.number", d.number.as_deref()),
        ("drawing.revision", Some(d.revision.as_str())),
        ("drawing.date", d.date.as_deref()),
        ("drawing.drawn_by", d.drawn_by.as_deref()),
        (
            "drawing.general_tolerance",
            Some(d.general_tolerance.as_str()),
        ),
    ] {
        if let Some(t) = text {
            if t.chars().count() > MAX_TITLE_FIELD_CHARS || t.chars().any(char::is_control) {
                return Err(invalid(
                    key,
                    crate::units::quoted(t),
                    format!("a line of at most {MAX_TITLE_FIELD_CHARS} characters"),
                ));
            }
        }
    }
    check(
        "drawing.cam_finish",
        d.cam_finish_ra_um,
        Range::Closed(0.025, 50.0),
        "um",
    )?;
    check(
        "drawing.finish",
        d.finish_ra_um,
        Range::Closed(0.025, 50.0),
        "um",
    )?;
    if let Some(s) = d.coordinate_step_mm {
        check(
            "drawing.coordinate_step",
            s,
            Range::Closed(0.01, 100.0),
            "mm",
        )?;
    }
    Ok(())
}

fn validate_checks(c: &ChecksSpec) -> Result<(), SpecError> {
    check(
        "checks.max_pressure_angle",
        c.max_pressure_angle_deg,
        Range::Open(0.0, 90.0),
        "deg",
    )?;
    check(
        "checks.min_locking_margin",
        c.min_locking_margin_deg,
        Range::HalfOpen(0.0, 45.0),
        "deg",
    )?;
    check(
        "checks.max_contact_stress",
        c.max_contact_stress_mpa,
        Range::Positive,
        "MPa",
    )
}

fn validate_tolerances(t: &TolerancesSpec) -> Result<(), SpecError> {
    check(
        "tolerances.spring_rate",
        t.spring_rate_percent,
        Range::HalfOpen(0.0, 100.0),
        "%",
    )?;
    check(
        "tolerances.preload",
        t.preload_mm,
        Range::Closed(0.0, MAX_LENGTH_MM),
        "mm",
    )?;
    // The band caps it at the roller's radius (a knife edge has no radius to vary).
    check(
        "tolerances.roller_radius",
        t.roller_radius_mm,
        Range::Closed(0.0, MAX_LENGTH_MM),
        "mm",
    )?;
    check(
        "tolerances.profile",
        t.profile_mm,
        Range::Closed(0.0, MAX_LENGTH_MM),
        "mm",
    )?;
    check(
        "tolerances.friction_min",
        t.friction_min,
        Range::HalfOpen(0.0, MAX_FRICTION),
        "",
    )?;
    check(
        "tolerances.friction_max",
        t.friction_max,
        Range::HalfOpen(t.friction_min, MAX_FRICTION),
        "",
    )?;
    if !(1..=MAX_TOLERANCE_SAMPLES).contains(&t.samples) {
        return Err(invalid(
            "tolerances.samples",
            t.samples.to_string(),
            format!("from 1 to {MAX_TOLERANCE_SAMPLES} builds"),
        ));
    }
    Ok(())
}

fn validate_output(o: &OutputSpec) -> Result<(), SpecError> {
    check(
        "output.chord_tolerance",
        o.chord_tolerance_mm,
        Range::Closed(1e-5, 0.1),
        "mm",
    )?;
    check(
        "output.fit_tolerance",
        o.fit_tolerance_mm,
        Range::Closed(1e-5, 0.1),
        "mm",
    )?;
    check(
        "output.stl_tolerance",
        o.stl_tolerance_mm,
        Range::Closed(1e-4, 1.0),
        "mm",
    )?;
    if o.chord_tolerance_mm >= o.stl_tolerance_mm {
        return Err(invalid(
            "output.chord_tolerance",
            format!(
                "{} mm with output.stl_tolerance = {} mm",
                o.chord_tolerance_mm, o.stl_tolerance_mm
            ),
            "a chord tolerance smaller than the STL tolerance (the mesh is decimated from the samples)".into(),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paper() -> SpecBuilder {
        Spec::builder(
            LawSpec::Targets(LawTargets::PAPER_EXAMPLE),
            Follower::new(5.0, 3.0),
        )
    }

    #[test]
    fn builder_takes_the_documented_defaults() {
        let s = paper().build().unwrap();
        assert_eq!(s.name, "design");
        assert_eq!(s.part.thickness_mm, 10.0);
        assert_eq!(s.part.roller_width_mm, 10.0);
        assert_eq!(s.machining.tool_diameter_mm, 6.0);
        assert_eq!(s.checks.max_pressure_angle_deg, 60.0);
        assert!((s.checks.max_contact_stress_mpa - 1.67 * 276.0).abs() < 1e-9);
        assert_eq!(s.output.chord_tolerance_mm, 1e-3);
    }

    #[test]
    fn contact_limit_follows_the_materials_unless_given() {
        let brass = Material::preset("brass-360").unwrap();
        let part = PartSpec {
            cam_material: brass,
            ..PartSpec::default()
        };
        let s = paper().part(part.clone()).build().unwrap();
        assert!((s.checks.max_contact_stress_mpa - 1.67 * 310.0).abs() < 1e-9);
        let given = ChecksSpec {
            max_contact_stress_mpa: 100.0,
            ..ChecksSpec::default()
        };
        let s = paper().part(part).checks(given).build().unwrap();
        assert_eq!(s.checks.max_contact_stress_mpa, 100.0);
    }

    #[test]
    fn every_section_rule_names_its_key() {
        let key = |b: SpecBuilder| b.build().unwrap_err().key().map(str::to_string);
        let part = |p: PartSpec| paper().part(p);
        assert_eq!(key(paper().name("")).as_deref(), Some("name"));
        assert_eq!(
            key(part(PartSpec::default().with_thickness(f64::NAN))).as_deref(),
            Some("part.thickness")
        );
        let pin = Follower::new(5.0, 3.0).with_friction(FrictionSource::Pin {
            pin_friction: 0.1,
            pin_radius_mm: 4.0,
            rolling_resistance_mm: 0.0,
        });
        let b = Spec::builder(paper().spec.law.clone(), pin);
        assert_eq!(key(b).as_deref(), Some("follower.pin_radius"));
        let m = MachiningSpec {
            depth_per_pass_mm: 7.0,
            ..MachiningSpec::default()
        };
        assert_eq!(
            key(paper().machining(m)).as_deref(),
            Some("machining.depth_per_pass")
        );
        let m = MachiningSpec {
            tabs: 17,
            ..MachiningSpec::default()
        };
        assert_eq!(key(paper().machining(m)).as_deref(), Some("machining.tabs"));
        let o = OutputSpec {
            chord_tolerance_mm: 0.05,
            ..OutputSpec::default()
        };
        assert_eq!(
            key(paper().output(o)).as_deref(),
            Some("output.chord_tolerance")
        );
    }

    #[test]
    fn thickness_carries_a_roller_as_wide_as_the_plate() {
        let p = PartSpec::default().with_thickness(12.0);
        assert_eq!(p.roller_width_mm, 12.0);
        let narrow = PartSpec {
            roller_width_mm: 4.0,
            ..PartSpec::default()
        }
        .with_thickness(12.0);
        assert_eq!(narrow.roller_width_mm, 4.0);
        assert_eq!(narrow.contact_length_mm(), 4.0);
    }
}
