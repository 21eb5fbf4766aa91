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
    let points = sweep(&spec, &axes, &|| {});
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
                assert_eq!(r.status == Status::Fail, d.status() == Status::Fail);
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
