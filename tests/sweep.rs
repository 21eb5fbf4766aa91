//! `camspring sweep`: the grid's results are the single designs' results, and the axes parse
//! or are refused with the reason.

use camspring::cam::checks::Status;
use camspring::design::design;
use camspring::render::sweep::sweep_csv;
use camspring::sweep::{check_axes, parse_axis, sweep, SweepKey};
use camspring::{spec::DEFAULT_SPEC_TOML, Spec};

#[test]
fn axes_parse_ranges_counts_and_lists() {
    let a = parse_axis("spring_rate=2..20").unwrap();
    assert_eq!(a.key, SweepKey::SpringRate);
    assert_eq!(a.values.len(), 10);
    assert_eq!((a.values[0], a.values[9]), (2.0, 20.0));
    assert_eq!(
        parse_axis("preload=0..10:5").unwrap().values,
        vec![0.0, 2.5, 5.0, 7.5, 10.0]
    );
    assert_eq!(
        parse_axis("friction=0,0.01,0.05").unwrap().values,
        vec![0.0, 0.01, 0.05]
    );
    for (bad, why) in [
        ("stiffness=1..2", "unknown key"),
        ("preload=a..b", "not a number"),
        ("preload=0..1:1", "2 to 200"),
        ("preload", "expected KEY="),
    ] {
        let e = parse_axis(bad).unwrap_err();
        assert!(e.contains(why), "{bad}: {e}");
    }
}

#[test]
fn axis_values_meet_the_spec_rules_naming_the_key() {
    let paper = Spec::from_toml(DEFAULT_SPEC_TOML).unwrap();
    let ankle = Spec::from_toml(include_str!("../specs/ankle.toml")).unwrap();
    for (spec, axis, key) in [
        (&paper, "spring_rate=0..10", "follower.spring_rate"),
        (&paper, "friction=0..1.5", "follower.friction"),
        // The ankle's roller turns on a pin: a roller smaller than the pin is refused.
        (&ankle, "roller_radius=1..9", "follower.pin_radius"),
    ] {
        let e = check_axes(spec, &[parse_axis(axis).unwrap()]).unwrap_err();
        assert!(e.contains(key), "{axis}: {e}");
    }
    assert!(check_axes(&paper, &[parse_axis("friction=0..0.5").unwrap()]).is_ok());
    let twice = [
        parse_axis("preload=0..1").unwrap(),
        parse_axis("preload=2..3").unwrap(),
    ];
    assert!(check_axes(&paper, &twice).unwrap_err().contains("twice"));
}

#[test]
fn every_grid_point_is_the_design_of_that_spec() {
    let spec = Spec::from_toml(DEFAULT_SPEC_TOML).unwrap();
    let axes = [
        parse_axis("spring_rate=3..12:4").unwrap(),
        parse_axis("preload=0.5,1.5,3").unwrap(),
    ];
    let points = sweep(&spec, &axes, false, &|| {});
    assert_eq!(points.len(), 12);
    for p in &points {
        let mut s = spec.clone();
        s.follower.spring_rate_n_per_mm = p.values[0];
        s.follower.preload_mm = p.values[1];
        let d = design(&s);
        match (&p.result, d) {
            (Ok(r), Ok(d)) => {
                assert_eq!(r.lift_mm, d.pitch_curve.lift_mm());
                assert_eq!(
                    r.max_pressure_angle_deg,
                    d.pitch_curve.max_pressure_angle().0
                );
                assert_eq!(r.status, d.status());
                // The checks that fail and warn are named per point.
                for c in &d.checks {
                    assert_eq!(r.failed_checks.contains(&c.name), c.status == Status::Fail);
                    assert_eq!(r.warned_checks.contains(&c.name), c.status == Status::Warn);
                }
            }
            (Err(e), Err(de)) => assert_eq!(e, &de.to_string()),
            (r, d) => panic!("sweep {r:?} but design {:?}", d.map(|_| ())),
        }
    }
    // The default spec's own point passes, and stiffer springs lower the pressure angle.
    let own = points.iter().find(|p| p.values == vec![6.0, 1.5]).unwrap();
    let stiff = points.iter().find(|p| p.values == vec![12.0, 1.5]).unwrap();
    let (a, b) = (own.result.as_ref().unwrap(), stiff.result.as_ref().unwrap());
    assert!(b.max_pressure_angle_deg < a.max_pressure_angle_deg);
    let csv = String::from_utf8(sweep_csv(&axes, &points)).unwrap();
    assert!(
        csv.starts_with("spring_rate_n_per_mm,preload_mm,status,lift_mm,max_pressure_angle_deg,")
    );
    assert_eq!(csv.lines().count(), 13);
}

#[test]
fn plate_roller_and_material_axes_are_the_designs_of_those_specs() {
    let spec = Spec::from_toml(DEFAULT_SPEC_TOML).unwrap();
    let axes = [
        parse_axis("thickness=4..12:3").unwrap(),
        parse_axis("cam_material=aluminium-6061-t6,steel-1045").unwrap(),
    ];
    let points = sweep(&spec, &axes, false, &|| {});
    assert_eq!(points.len(), 6);
    for p in &points {
        let mut s = spec.clone();
        s.part = s.part.clone().with_thickness(p.values[0]);
        let name = ["aluminium-6061-t6", "steel-1045"][p.values[1] as usize / 2];
        s.part.cam_material = camspring::model::Material::preset(name).unwrap();
        s.checks = camspring::model::ChecksSpec::for_materials(
            &s.part.cam_material,
            &s.part.roller_material,
        );
        let d = design(&s).unwrap();
        let r = p.result.as_ref().unwrap();
        assert_eq!(r.max_contact_stress_mpa, d.max_contact_stress_mpa());
        assert_eq!(r.status, d.status());
    }
    let csv = String::from_utf8(sweep_csv(&axes, &points)).unwrap();
    assert!(csv.contains(",steel-1045,"), "{csv}");
    assert!(csv.lines().next().unwrap().contains("warned_checks"));
    // Thicker plates lower the contact stress.
    let at = |t: f64| {
        points
            .iter()
            .find(|p| p.values == vec![t, 0.0])
            .unwrap()
            .result
            .as_ref()
            .unwrap()
            .max_contact_stress_mpa
            .unwrap()
    };
    assert!(at(12.0) < at(4.0));
}
