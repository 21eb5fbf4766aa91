//! What to buy: the forces, travel and loads of the physical springs and rollers, against
//! hand calculations from the law and the pitch curve's end (frictionless equilibrium).

use camspring::cam::checks::Status;
use camspring::model::{FrictionSource, RollerBearing, SpringArrangement};
use camspring::outputs::summarize;
use camspring::{design, spec::DEFAULT_SPEC_TOML, Spec};

fn frictionless(count: u8, arrangement: SpringArrangement) -> Spec {
    let mut spec = Spec::from_toml(DEFAULT_SPEC_TOML).unwrap();
    spec.follower.count = count;
    spec.follower.arrangement = arrangement;
    spec.follower.friction = FrictionSource::Coefficient { coefficient: 0.0 };
    if count == 1 {
        // One follower needs more preload to keep the start followable.
        spec.follower.preload_mm = 3.0;
    }
    spec
}

#[test]
fn spring_forces_and_roller_loads_match_the_equilibrium_at_the_stroke_end() {
    for (count, arrangement, springs, per_roller_share) in [
        // (followers, arrangement, physical springs, share of q on one roller)
        (2, SpringArrangement::PerFollower, 2, 0.5),
        (2, SpringArrangement::Shared, 1, 0.5),
        (1, SpringArrangement::PerFollower, 1, 1.0),
    ] {
        let spec = frictionless(count, arrangement);
        let d = design(&spec).unwrap();
        let s = summarize(&d, &[]);
        let last = d.pitch_curve.samples.last().unwrap();
        let theta = last.theta_rad;
        // Frictionless virtual work at x = xmax: F = q tan(theta), q the total spring force
        // along y.
        let f_end = d.law.law.force_n(spec.law.xmax_mm());
        let q = f_end / theta.tan();
        let ks = spec.follower.spring_rate_n_per_mm;
        // Each physical spring: per-follower springs each carry q / count; a shared spring's
        // tension acts on both rollers, so it is q / 2 as well.
        let per_spring = match arrangement {
            SpringArrangement::PerFollower => q / f64::from(count),
            SpringArrangement::Shared => q / 2.0,
        };
        let sp = &s.springs;
        assert_eq!(sp.count, springs, "{arrangement:?}");
        assert!(
            (sp.force_at_full_stroke_n / per_spring - 1.0).abs() < 1e-5,
            "{arrangement:?} x{count}: {} N against {per_spring} N",
            sp.force_at_full_stroke_n
        );
        // At preload: the rate times the preload (or twice it, stretched by both rollers).
        let stretch = if arrangement == SpringArrangement::Shared {
            2.0
        } else {
            1.0
        };
        assert!((sp.force_at_preload_n - ks * stretch * spec.follower.preload_mm).abs() < 1e-9);
        assert!((sp.travel_mm - stretch * last.y_mm).abs() < 1e-9);
        // The roller's normal load at the end: its share of q over cos(theta).
        let r = s.rollers.as_ref().unwrap();
        let normal_end = per_roller_share * q / theta.cos();
        let end = d.forces.last().unwrap().contact_normal_n.unwrap();
        assert!(
            (end / normal_end - 1.0).abs() < 1e-5,
            "{end} against {normal_end}"
        );
        assert!(r.peak_normal_load_n >= end - 1e-9);
        // Revolutions: out and back over the surface's length.
        let surface: f64 = d
            .cam_surface
            .points
            .windows(2)
            .map(|w| (w[1].x_mm - w[0].x_mm).hypot(w[1].y_mm - w[0].y_mm))
            .sum();
        let revs = 2.0 * surface / (std::f64::consts::TAU * spec.follower.roller_radius_mm);
        assert!((r.revolutions_per_stroke / revs - 1.0).abs() < 1e-12);
    }
}

#[test]
fn the_roller_life_check_advises_a_rating_that_passes() {
    let mut spec = Spec::from_toml(DEFAULT_SPEC_TOML).unwrap();
    spec.follower.bearing = RollerBearing {
        dynamic_load_n: Some(300.0),
        duty_strokes: Some(1e9),
        stroke_rate_hz: Some(2.0),
    };
    let d = design(&spec).unwrap();
    let c = d.checks.iter().find(|c| c.name == "roller_life").unwrap();
    assert_eq!(c.status, Status::Fail, "{c:?}");
    // Independently: (C/P)^(10/3) million revolutions over the revolutions of a stroke.
    let s = summarize(&d, &[]);
    let r = s.rollers.unwrap();
    let expected =
        (300.0 / r.mean_equivalent_load_n).powf(10.0 / 3.0) * 1e6 / r.revolutions_per_stroke;
    assert!((c.value.unwrap() / expected - 1.0).abs() < 1e-12);
    assert!((r.speed_rpm.unwrap() - r.revolutions_per_stroke * 120.0).abs() < 1e-9);
    let rating = c.suggestions[0].value;
    spec.follower.bearing.dynamic_load_n = Some(rating);
    let again = design(&spec).unwrap();
    let c = again
        .checks
        .iter()
        .find(|c| c.name == "roller_life")
        .unwrap();
    assert_eq!(c.status, Status::Pass, "C = {rating} N: {c:?}");
    // Without a rating the check is not made.
    spec.follower.bearing = RollerBearing::default();
    assert!(design(&spec)
        .unwrap()
        .checks
        .iter()
        .all(|c| c.name != "roller_life"));
}

#[test]
fn catalogue_springs_are_ranked_and_the_applied_one_designs_as_listed() {
    use std::process::Command;
    let d = tempfile::tempdir().unwrap();
    let root = env!("CARGO_MANIFEST_DIR");
    std::fs::copy(
        format!("{root}/specs/springs.csv"),
        d.path().join("springs.csv"),
    )
    .unwrap();
    let spec = std::fs::read_to_string(format!("{root}/specs/paper.toml"))
        .unwrap()
        .replace("[part]", "spring_catalogue = \"springs.csv\"\n\n[part]");
    std::fs::write(d.path().join("s.toml"), spec).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_camspring"))
        .args(["springs", "s.toml", "--json", "--apply", "CS-0505"])
        .current_dir(d.path())
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let choices = v["choices"].as_array().unwrap();
    assert_eq!(choices.len(), 10);
    // Ranked: the workable ones first, passing before warning, then by travel left.
    let key = |c: &serde_json::Value| match c["status"].as_str() {
        Some("pass") => 0,
        Some("warn") => 1,
        _ => 2,
    };
    for w in choices.windows(2) {
        assert!(key(&w[0]) <= key(&w[1]));
        if key(&w[0]) == key(&w[1]) && key(&w[0]) < 2 {
            assert!(w[0]["margin_mm"].as_f64() >= w[1]["margin_mm"].as_f64());
        }
    }
    // The applied spec: the part's rate and the listed preload; designed anew it has the
    // listed status, and its springs deflect by preload + lift, within the maker's travel.
    let chosen = choices
        .iter()
        .find(|c| c["spring"]["part"] == "CS-0505")
        .unwrap();
    let written = d.path().join("s-CS-0505.toml");
    let text = std::fs::read_to_string(&written).unwrap();
    let spec = camspring::spec::parse_in(&text, d.path()).unwrap();
    assert_eq!(spec.follower.spring_rate_n_per_mm, 5.05);
    assert_eq!(
        Some(spec.follower.preload_mm),
        chosen["preload_mm"].as_f64()
    );
    let des = design(&spec).unwrap();
    assert_eq!(des.status().as_str(), chosen["status"].as_str().unwrap());
    let deflection = spec.follower.preload_mm + des.pitch_curve.lift_mm();
    assert!((deflection - chosen["deflection_at_full_stroke_mm"].as_f64().unwrap()).abs() < 1e-9);
    assert!(deflection <= 23.0);
}
