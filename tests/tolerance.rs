//! The force band holds what it promises: builds drawn from the same tolerances, each
//! evaluated by an independent construction (the machined surface offset by the build's own
//! roller and profile error, the pressure angle from that curve's slope), land inside the 95 %
//! band at the end of the stroke about 95 % of the time.

use camspring::cam::tolerance::force_band;
use camspring::{design, spec::DEFAULT_SPEC_TOML, Spec};
use rand::{Rng, SeedableRng};

/// The loading force at the stroke's end of one build, from the geometry.
fn build_end_force(d: &camspring::Design, dr: f64, dp: f64, ds: f64, dyp: f64, mu: f64) -> f64 {
    let f = &d.spec.follower;
    let r = f.roller_radius_mm;
    // The roller centre path of the build: the surface moved out along its normal by r + dr
    // (more material, dp, pushes the same way).
    let pts: Vec<(f64, f64)> = d
        .pitch_curve
        .samples
        .iter()
        .zip(&d.cam_surface.points)
        .map(|(p, s)| {
            let (nx, ny) = ((p.x_mm - s.x_mm) / r, (p.y_mm - s.y_mm) / r);
            (s.x_mm + (r + dr + dp) * nx, s.y_mm + (r + dr + dp) * ny)
        })
        .collect();
    let xmax = d.xmax_mm();
    // The segment where the build's curve reaches x = xmax (extended by the last segment).
    let i = pts.partition_point(|p| p.0 < xmax).clamp(1, pts.len() - 1);
    let (a, b) = (pts[i - 1], pts[i]);
    let w = (xmax - a.0) / (b.0 - a.0);
    let y = a.1 + w * (b.1 - a.1);
    let theta = (b.1 - a.1).atan2(b.0 - a.0);
    let q = f.k_eff_n_per_mm() * (1.0 + ds) * (y + f.preload_mm + dyp);
    q * (theta + mu.atan()).tan()
}

#[test]
fn about_95_percent_of_independent_builds_lie_inside_the_95_percent_band() {
    let spec = Spec::from_toml(DEFAULT_SPEC_TOML).unwrap();
    let d = design(&spec).unwrap();
    let t = &spec.tolerances;
    let band = force_band(&d.pitch_curve, &spec.follower, t);
    let (lo, hi) = (
        band.loading_lo_n.last().unwrap().unwrap(),
        band.loading_hi_n.last().unwrap().unwrap(),
    );
    assert!(*band.x_mm.last().unwrap() == d.xmax_mm());
    let mut rng = rand::rngs::StdRng::seed_from_u64(2026);
    let n = 400;
    let inside = (0..n)
        .filter(|_| {
            let ds = rng.random_range(-1.0..=1.0) * t.spring_rate_percent / 100.0;
            let dyp = rng.random_range(-t.preload_mm..=t.preload_mm);
            let dr = rng.random_range(-t.roller_radius_mm..=t.roller_radius_mm);
            let dp = rng.random_range(-t.profile_mm..=t.profile_mm);
            let mu = rng.random_range(t.friction_min..=t.friction_max);
            let f = build_end_force(&d, dr, dp, ds, dyp, mu);
            (lo..=hi).contains(&f)
        })
        .count();
    let share = inside as f64 / n as f64;
    // Binomial, p = 0.95, n = 400: sigma = 1.09 %; three sigma either side.
    eprintln!("{inside} of {n} builds inside [{lo:.2}, {hi:.2}] N");
    assert!((0.917..=0.983).contains(&share), "{share}");
}

#[test]
fn the_band_is_reproducible_and_the_spring_rate_dominates_the_paper_spring() {
    let spec = Spec::from_toml(DEFAULT_SPEC_TOML).unwrap();
    let d = design(&spec).unwrap();
    let a = force_band(&d.pitch_curve, &spec.follower, &spec.tolerances);
    let b = force_band(&d.pitch_curve, &spec.follower, &spec.tolerances);
    assert_eq!(a.loading_hi_n, b.loading_hi_n);
    assert_eq!(a.sensitivity[0].tolerance, "spring_rate");
    // +-10 % on the springs moves the end force by about +-10 % of 200 N.
    let s = a.sensitivity[0].loading_half_range_n;
    assert!((s / 20.0 - 1.0).abs() < 0.1, "{s}");
    // With no tolerance at all the band collapses onto the design's loading force.
    let exact = camspring::model::TolerancesSpec {
        spring_rate_percent: 0.0,
        preload_mm: 0.0,
        roller_radius_mm: 0.0,
        profile_mm: 0.0,
        friction_min: 0.01,
        friction_max: 0.01,
        samples: 50,
        seed: 3,
    };
    let c = force_band(&d.pitch_curve, &spec.follower, &exact);
    let end = d.forces.last().unwrap().loading_n.unwrap();
    assert!((c.loading_lo_n.last().unwrap().unwrap() - end).abs() < 1e-9);
    assert!((c.loading_hi_n.last().unwrap().unwrap() - end).abs() < 1e-9);
}

#[test]
fn validate_judges_builds_against_the_band_and_says_where_they_leave_it() {
    use camspring::estimate::sim::{simulate, SimSettings};
    use camspring::verdict::validate::validate;
    use camspring::{estimate, EstimateOptions, SensorNoise};
    let spec = Spec::from_toml(DEFAULT_SPEC_TOML).unwrap();
    let d = design(&spec).unwrap();
    let designed = *d.law.exponential().unwrap();
    let band = force_band(&d.pitch_curve, &spec.follower, &spec.tolerances);
    let verdict = |scale: f64| {
        // A build whose springs are `scale` times stiffer: every force scales.
        let built = camspring::ExpLaw {
            mu_n: scale * designed.mu_n,
            k2_per_mm: designed.k2_per_mm,
            f0_n: scale * designed.f0_n,
        };
        let settings = SimSettings {
            seed: 5,
            ..SimSettings::default()
        };
        let (log, _) = simulate(built, 20.0, 230.0, &settings).unwrap();
        let run = estimate(
            &log,
            &EstimateOptions::new(SensorNoise::default()),
            |_, _| {},
        )
        .unwrap();
        let id = run.identification.as_ref().unwrap();
        let banded = validate(&designed, id, &run, &log.position_mm, 0.03, Some(&band));
        let flat = validate(&designed, id, &run, &log.position_mm, 0.03, None);
        (banded, flat)
    };
    // 5 % stiffer springs: inside what +-10 % springs allow, but more than a flat 3 %.
    let (banded, flat) = verdict(1.05);
    assert!(banded.pass, "{:?}", banded.criteria);
    assert!(banded.band_exits.is_empty());
    assert!(!flat.pass);
    // The band's upper edge is the loading force of the stiffest, highest-friction builds
    // (+16.5 % at Xmax here), the lower edge the unloading force of the softest: 25 % stiffer
    // or softer springs leave it, named with the side and where.
    for (scale, side) in [(1.25, "above"), (0.75, "below")] {
        let (banded, _) = verdict(scale);
        assert!(!banded.pass, "{scale}");
        let c = banded
            .criteria
            .iter()
            .find(|c| c.name == "force_band")
            .unwrap();
        assert!(!c.pass && c.deviation_percent > 0.0);
        assert!(!banded.band_exits.is_empty());
        assert!(
            banded.band_exits.iter().all(|e| e.side == side),
            "{:?}",
            banded.band_exits
        );
        let last = banded.band_exits.last().unwrap();
        assert!(last.to_mm >= last.from_mm && last.worst_n > 0.0);
    }
}

#[test]
fn a_knife_edge_keeps_the_default_tolerances_and_gets_a_band() {
    // The default +-0.01 mm roller tolerance is capped at the radius, not refused.
    let text = DEFAULT_SPEC_TOML.replace("roller_radius = \"3 mm\"", "roller_radius = \"0 mm\"");
    let spec = Spec::from_toml(&text).unwrap();
    assert_eq!(spec.follower.roller_radius_mm, 0.0);
    let d = design(&spec).unwrap();
    let band = force_band(&d.pitch_curve, &spec.follower, &spec.tolerances);
    let s = band
        .sensitivity
        .iter()
        .find(|s| s.tolerance == "roller_radius")
        .unwrap();
    assert_eq!(s.loading_half_range_n, 0.0);
}
