//! Following a failing check's advice must make that check pass: each test breaks one
//! check, applies each suggestion to the spec, designs again and looks at the same check.

use camspring::cam::checks::{Check, Status, Suggestion};
use camspring::design::design;
use camspring::{spec::DEFAULT_SPEC_TOML, Spec};

fn paper() -> Spec {
    Spec::from_toml(DEFAULT_SPEC_TOML).unwrap()
}

fn literal() -> Spec {
    Spec::from_toml(include_str!("../specs/paper-literal.toml")).unwrap()
}

fn check(spec: &Spec, name: &str) -> Check {
    design(spec)
        .unwrap()
        .checks
        .into_iter()
        .find(|c| c.name == name)
        .unwrap()
}

fn apply(spec: &Spec, s: &Suggestion) -> Spec {
    let mut spec = spec.clone();
    match s.key {
        "follower.preload" => spec.follower.preload_mm = s.value,
        "follower.spring_rate" => spec.follower.spring_rate_n_per_mm = s.value,
        "follower.roller_radius" => spec.follower.roller_radius_mm = s.value,
        // A roller as wide as the plate follows the plate (PartSpec::with_thickness).
        "part.thickness" => spec.part = spec.part.clone().with_thickness(s.value),
        "part.roller_width" => spec.part.roller_width_mm = s.value,
        "machining.tool_diameter" => spec.machining.tool_diameter_mm = s.value,
        other => panic!("unexpected suggestion key {other}"),
    }
    spec
}

/// Breaks `name` in `spec`, then checks that every suggestion fixes it.
fn advice_fixes(spec: Spec, name: &str, expect_keys: &[&str]) {
    let broken = check(&spec, name);
    assert_eq!(broken.status, Status::Fail, "{broken:?}");
    assert!(broken.advice.is_some());
    let keys: Vec<&str> = broken.suggestions.iter().map(|s| s.key).collect();
    assert_eq!(keys, expect_keys, "{broken:?}");
    for s in &broken.suggestions {
        let fixed = check(&apply(&spec, s), name);
        // Advice aims below the warning band: following it gives a pass, not a warning.
        assert_eq!(fixed.status, Status::Pass, "after {s:?}: {fixed:?}");
    }
}

#[test]
fn literal_paper_design_undercuts_and_preload_or_smaller_roller_fixes_it() {
    let c = check(&literal(), "undercut");
    assert_eq!(c.status, Status::Fail);
    assert!(c.message.contains("cannot follow"), "{}", c.message);
    // rho(0) = F(0)/k_eff = 2.2242 N / 10 N/mm.
    assert!((c.value.unwrap() - 0.222_42).abs() < 1e-4, "{c:?}");
    advice_fixes(
        literal(),
        "undercut",
        &["follower.preload", "follower.roller_radius"],
    );
}

#[test]
fn pressure_angle_advice_gives_the_spring_rate_or_preload_that_meets_the_limit() {
    let mut spec = paper();
    spec.checks.max_pressure_angle_deg = 50.0;
    advice_fixes(
        spec.clone(),
        "pressure_angle",
        &["follower.spring_rate", "follower.preload"],
    );
    // The advice is tight: 5 % less than the advised spring rate no longer passes.
    let c = check(&spec, "pressure_angle");
    let ks = c.suggestions[0].value;
    let mut weaker = spec.clone();
    weaker.follower.spring_rate_n_per_mm = 0.95 * ks;
    assert_ne!(check(&weaker, "pressure_angle").status, Status::Pass);
}

#[test]
fn a_spring_that_cannot_return_the_rod_is_told_the_largest_preload() {
    let mut spec = paper();
    spec.follower.preload_mm = 4.0;
    spec.follower.friction = camspring::model::FrictionSource::Coefficient { coefficient: 0.1 };
    // A loading-corrected curve cannot exist here (friction 4 N > F(0) = 2.22 N): use `none`.
    spec.follower.friction_correction = camspring::model::FrictionCorrection::None;
    let c = check(&spec, "self_locking");
    assert!(c.value.unwrap() < 0.0, "{c:?}");
    advice_fixes(spec, "self_locking", &["follower.preload"]);
}

#[test]
fn contact_stress_advice_gives_the_thickness() {
    let mut spec = paper();
    spec.part.thickness_mm = 1.0;
    spec.part.roller_width_mm = 1.0;
    advice_fixes(
        spec,
        "contact_stress",
        &["part.thickness", "follower.roller_radius"],
    );
}

#[test]
fn cutter_fit_advice_gives_the_largest_end_mill() {
    let mut spec = paper();
    spec.machining.tool_diameter_mm = 60.0;
    advice_fixes(spec, "cutter_fit", &["machining.tool_diameter"]);
}

#[test]
fn the_default_design_passes_every_check() {
    let d = design(&paper()).unwrap();
    for c in &d.checks {
        assert_eq!(c.status, Status::Pass, "{c:?}");
    }
}

#[test]
fn a_narrow_roller_gets_roller_advice_not_a_thicker_plate() {
    // An ankle-like spring: 800 N at 15 mm on an 8 mm bearing 4 mm wide, in a 10 mm plate.
    let text = "[law]\nxmax = \"15 mm\"\nconditions = [\n  { at = \"0 mm\", force = \"40 N\" },\n  { at = \"15 mm\", force = \"800 N\" },\n  { at = \"15 mm\", stiffness = \"180 N/mm\" },\n]\n[follower]\ncount = 2\nspring_rate = \"40 N/mm\"\npreload = \"4 mm\"\nroller_radius = \"4 mm\"\n[part]\nthickness = \"10 mm\"\nroller_width = \"4 mm\"\n";
    let spec = Spec::from_toml(text).unwrap();
    let c = check(&spec, "contact_stress");
    assert_eq!(c.status, Status::Fail, "{c:?}");
    // A roller a little too narrow, in a plate with room: a wider roller is advised.
    let mut room = spec.clone();
    room.part.thickness_mm = 40.0;
    let r = check(&room, "contact_stress");
    let width = r.suggestions.iter().find(|s| s.key == "part.roller_width");
    let width = width.unwrap_or_else(|| panic!("{r:?}"));
    assert_eq!(
        check(&apply(&room, width), "contact_stress").status,
        Status::Pass
    );
    let keys: Vec<&str> = c.suggestions.iter().map(|s| s.key).collect();
    assert!(
        keys.contains(&"part.roller_width") || keys.contains(&"follower.roller_radius"),
        "{keys:?}"
    );
    assert!(
        !keys.contains(&"part.thickness"),
        "a thicker plate cannot help: {keys:?}"
    );
    for s in &c.suggestions {
        let fixed = check(&apply(&spec, s), "contact_stress");
        assert_eq!(fixed.status, Status::Pass, "after {s:?}: {fixed:?}");
    }
    // The independent reason: the stress does not move with the plate.
    let mut thick = spec.clone();
    thick.part.thickness_mm = 30.0;
    let same = check(&thick, "contact_stress").value.unwrap();
    assert!((same / c.value.unwrap() - 1.0).abs() < 1e-9);
}
