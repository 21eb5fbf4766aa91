//! Property tests: every accepted spec gives valid geometry or a clear error, never a panic.

use camspring::cam::checks::Status;
use camspring::design::design;
use camspring::export::step;
use camspring::model::FrictionCorrection;
use camspring::part::mesh;
use camspring::part::{build, PartError};
use camspring::units::{parse_quantity, Dimension};
use camspring::Spec;
use proptest::prelude::*;

#[derive(Debug, Clone)]
struct SpecParams {
    fmin: f64,
    force_ratio: f64,
    l0: f64,
    length_ratio: f64,
    c0: f64,
    delta0: f64,
    count: u8,
    shared: bool,
    spring_rate: f64,
    preload: f64,
    roller: f64,
    friction: f64,
    correction: &'static str,
    thickness: f64,
}

fn spec_params() -> impl Strategy<Value = SpecParams> {
    (
        (
            1.0..50.0f64,
            2.0..100.0f64,
            1.0..10.0f64,
            1.5..6.0f64,
            0.05..1.2f64,
            0.1..2.0f64,
        ),
        (
            1u8..=2,
            any::<bool>(),
            0.5..50.0f64,
            0.0..10.0f64,
            0.0..8.0f64,
            0.0..0.3f64,
        ),
        (
            prop::sample::select(vec!["loading", "unloading", "midline", "none"]),
            2.0..30.0f64,
        ),
    )
        .prop_map(
            |((fmin, fr, l0, lr, sr, delta0), (count, shared, ks, yp, r, mu), (corr, b))| {
                SpecParams {
                    fmin,
                    force_ratio: fr,
                    l0,
                    length_ratio: lr,
                    // Sr = c0*l0/delta0 < 1 keeps F(0) > 0; up to 1.2 also exercises that refusal.
                    c0: sr * delta0 / l0,
                    delta0,
                    count,
                    shared: shared && count == 2,
                    spring_rate: ks,
                    preload: yp,
                    roller: r,
                    friction: mu,
                    correction: corr,
                    thickness: b,
                }
            },
        )
}

/// Every directed edge appears once and its reverse once.
fn watertight(tris: &[stl_io::Triangle]) -> bool {
    use std::collections::HashMap;
    let key = |v: &stl_io::Vertex| [v[0].to_bits(), v[1].to_bits(), v[2].to_bits()];
    let mut edges: HashMap<([u32; 3], [u32; 3]), u32> = HashMap::new();
    for t in tris {
        for k in 0..3 {
            *edges
                .entry((key(&t.vertices[k]), key(&t.vertices[(k + 1) % 3])))
                .or_default() += 1;
        }
    }
    edges
        .iter()
        .all(|((a, b), n)| *n == 1 && edges.get(&(*b, *a)) == Some(&1))
}

fn toml_of(p: &SpecParams) -> String {
    format!(
        "name = \"prop\"\n[law]\nfmax = {}\nfmin = {}\nxmax = {}\nl0 = {}\nc0 = {}\ndelta0 = {}\n\
         [follower]\ncount = {}\nspring = \"{}\"\nspring_rate = {}\npreload = {}\nroller_radius = {}\n\
         friction = {}\nfriction_correction = \"{}\"\n[part]\nthickness = {}\n",
        p.fmin * p.force_ratio,
        p.fmin,
        p.l0 * p.length_ratio,
        p.l0,
        p.c0,
        p.delta0,
        p.count,
        if p.shared { "shared" } else { "per-follower" },
        p.spring_rate,
        p.preload,
        p.roller,
        p.friction,
        p.correction,
        p.thickness
    )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, ..ProptestConfig::default() })]

    #[test]
    fn accepted_specs_give_valid_geometry_or_a_clear_error(p in spec_params()) {
        let spec = Spec::from_toml(&toml_of(&p)).expect("the generated spec is well-formed");
        match design(&spec) {
            Err(e) => {
                let msg = e.to_string();
                prop_assert!(msg.len() > 30, "{msg}");
                prop_assert!(msg.contains("softening") || msg.contains("friction") || msg.contains("correction")
                    || msg.contains("F(0)"), "unexpected error: {msg}");
            }
            Ok(d) => {
                let xmax = spec.law.xmax_mm();
                let s = &d.pitch_curve.samples;
                prop_assert_eq!(s[0].x_mm, 0.0);
                prop_assert_eq!(s[0].y_mm, 0.0);
                prop_assert_eq!(s.last().unwrap().x_mm, xmax);
                for w in s.windows(2) {
                    prop_assert!(w[1].x_mm > w[0].x_mm, "x increases");
                    prop_assert!(w[1].y_mm >= w[0].y_mm, "the pitch curve is monotone");
                }
                for q in s {
                    prop_assert!(q.theta_rad >= 0.0 && q.theta_rad <= std::f64::consts::FRAC_PI_2 + 1e-12);
                }
                for pt in &d.cam_surface.points {
                    prop_assert!(pt.x_mm.is_finite() && pt.y_mm.is_finite());
                }
                if let Some(r) = d.law.residuals {
                    prop_assert!(r.max_abs() < 1e-9, "{r:?}");
                }
                // The corrected stroke reproduces the law from the geometry.
                let phi = spec.follower.friction_angle_rad();
                for (q, f) in s.iter().zip(&d.forces) {
                    if q.x_mm == 0.0 && spec.follower.preload_mm == 0.0 {
                        continue; // 0 * inf at the singular start
                    }
                    let predicted = match (spec.follower.friction_correction, phi == 0.0) {
                        (_, true) | (FrictionCorrection::Loading, _) => f.loading_n,
                        (FrictionCorrection::Unloading, _) => Some(f.unloading_n),
                        (FrictionCorrection::Midline, _) => f.loading_n.map(|l| 0.5 * (l + f.unloading_n)),
                        (FrictionCorrection::None, false) => None,
                    };
                    if let Some(pred) = predicted {
                        prop_assert!(((pred - f.design_n) / f.design_n).abs() < 1e-6,
                            "x = {}: predicted {pred} vs law {}", q.x_mm, f.design_n);
                    }
                }
                // The part: a closed solid and a watertight mesh, or a refusal for an undercut.
                match build(&d) {
                    Ok(part) => {
                        prop_assert!(d.cam_surface.is_followable());
                        let solid = step::solid(&part).expect("a followable design gives a solid");
                        prop_assert_eq!(
                            solid.boundaries()[0].shell_condition(),
                            truck_topology::shell::ShellCondition::Closed
                        );
                        let rings = mesh::rings(&part, spec.output.stl_tolerance_mm, spec.output.chord_tolerance_mm);
                        let tris = mesh::mesh(&rings, part.thickness_mm).expect("mesh");
                        prop_assert!(watertight(&tris), "mesh not watertight");
                        prop_assert!(part.area_mm2 > 0.0);
                        for e in &part.cam_edges {
                            prop_assert!(e.fit_deviation_mm <= spec.output.fit_tolerance_mm);
                        }
                        // Machining: a program, or a refusal that names what to change.
                        match camspring::toolpath::jobs(&d, &part) {
                            Ok((jobs, summary)) => {
                                prop_assert!(summary.max_fit_deviation_mm <= summary.fit_budget_mm);
                                let (text, _) = camspring::toolpath::gcode::write(&d, &jobs, &summary);
                                prop_assert!(text.ends_with("M2\n"));
                            }
                            Err(e) => prop_assert!(e.to_string().contains("machining.tool_diameter")
                                || e.to_string().contains("add a drill")
                                || e.to_string().contains("flute length"), "{e}"),
                        }
                    }
                    Err(PartError::Undercut { advice, .. }) => {
                        prop_assert!(!d.cam_surface.is_followable());
                        prop_assert!(!advice.is_empty());
                    }
                    Err(e) => prop_assert!(false, "unexpected part error: {e}"),
                }
                prop_assert_eq!(d.checks.len(), 5);
                for c in &d.checks {
                    if c.status == Status::Fail {
                        prop_assert!(c.advice.is_some(), "{:?}", c);
                    }
                }
            }
        }
    }

    #[test]
    fn any_text_as_a_spec_is_an_error_or_a_spec_never_a_panic(text in "\\PC{0,400}") {
        let _ = Spec::from_toml(&text);
    }

    #[test]
    fn mutated_specs_never_panic(cut in 0usize..900, insert in "[\\[\\]=\" a-z0-9.#\\n-]{0,12}") {
        let base = include_str!("../specs/paper.toml");
        let cut = cut.min(base.len());
        let cut = (0..=cut).rev().find(|&i| base.is_char_boundary(i)).unwrap();
        let text = format!("{}{}{}", &base[..cut], insert, &base[cut..]);
        if let Ok(spec) = Spec::from_toml(&text) {
            let _ = design(&spec);
        }
    }

    #[test]
    fn quantity_parser_never_panics(text in "\\PC{0,30}") {
        for d in [Dimension::Length, Dimension::Force, Dimension::Stiffness, Dimension::Angle, Dimension::Stress] {
            if let Ok(v) = parse_quantity(&text, d) {
                prop_assert!(v.is_finite());
            }
        }
    }
}

/// Applies a machine-applicable suggestion the way a user edits the spec (a roller as wide as
/// the plate follows the plate).
fn apply_suggestion(spec: &Spec, key: &str, value: f64) -> Spec {
    let mut s = spec.clone();
    match key {
        "follower.preload" => s.follower.preload_mm = value,
        "follower.spring_rate" => s.follower.spring_rate_n_per_mm = value,
        "follower.roller_radius" => s.follower.roller_radius_mm = value,
        "part.thickness" => s.part = s.part.clone().with_thickness(value),
        "part.roller_width" => s.part.roller_width_mm = value,
        "machining.tool_diameter" => s.machining.tool_diameter_mm = value,
        other => panic!("unknown suggestion key {other}"),
    }
    s
}

proptest! {
    // Each case re-designs once per suggestion, and the advice searches re-synthesise the
    // cam many times: few cases, each a whole round trip.
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// No suggestion lands on a warning: applied alone, it makes its check pass.
    #[test]
    fn every_suggestion_applied_alone_makes_its_check_pass(p in spec_params()) {
        let Ok(spec) = Spec::from_toml(&toml_of(&p)) else { return Ok(()); };
        let Ok(d) = design(&spec) else { return Ok(()); };
        for c in d.checks.iter().filter(|c| c.status != Status::Pass) {
            for s in &c.suggestions {
                let fixed = apply_suggestion(&spec, s.key, s.value);
                // A suggestion may make another check's spec invalid (then it is refused, not
                // a silent pass); only a design that exists is judged.
                let Ok(again) = design(&fixed) else { continue; };
                let after = again.checks.iter().find(|k| k.name == c.name).unwrap();
                prop_assert_eq!(
                    after.status,
                    Status::Pass,
                    "{} = {} for {}: {:?}",
                    s.key,
                    s.value,
                    c.name,
                    after
                );
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Any signal read in steps, moving or at rest, with or without noise before the steps,
    /// gives a noise before the steps that is finite, between 0 and 2 steps, and a noise
    /// estimate whose variance is finite and not negative: never a panic.
    #[test]
    fn the_noise_before_an_encoders_steps_is_always_a_finite_share_of_a_step(
        step in 1e-4f64..0.05,
        speed in prop::collection::vec(-3.0f64..3.0, 1..8),
        noise in 0.0f64..1.5,
        seed in 0u64..1000,
        samples in 0usize..3000,
    ) {
        use camspring::estimate::noise::{dither_steps, DifferenceNoise};
        let mut state = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
        let mut uniform = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        // Piecewise-constant speeds (steps a sample), noise uniform of the given share of a
        // step on each side, read in steps.
        let mut x = 1.0;
        let y: Vec<f64> = (0..samples)
            .map(|i| {
                x += speed[i * speed.len() / samples.max(1)] * step;
                let n = (uniform() - 0.5) * 2.0 * noise * step;
                ((x + n) / step).round() * step
            })
            .collect();
        let differences: Vec<f32> = y.windows(2).map(|w| (w[1] - w[0]) as f32).collect();
        let s = dither_steps(&differences, step);
        prop_assert!(s.is_finite() && (0.0..=2.0).contains(&s), "{s}");
        if let Some(e) = DifferenceNoise::of(&y) {
            prop_assert!(e.variance.is_finite() && e.variance >= 0.0, "{e:?}");
            prop_assert!(e.dither_steps.is_finite() && e.dither_steps >= 0.0, "{e:?}");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Any trajectory, moving or at rest, fast or slow, through any kernels, with any step,
    /// noise before the steps and block: every speed class's share of the steps' error is
    /// finite and not negative, and every sample takes a class's shares: never a panic.
    #[test]
    fn the_steps_error_through_the_kernels_is_always_a_finite_share(
        step in 1e-4f64..0.05,
        speed in prop::collection::vec(-50.0f64..50.0, 1..8),
        dither in 0.0f64..1.5,
        block in 1usize..20,
        half in 0usize..30,
        samples in 0usize..1500,
    ) {
        use camspring::estimate::quantisation::{
            Quantisation, RowShares, SpeedShares, SHARE_KERNELS, SPEED_CLASSES,
        };
        use camspring::estimate::sg::Differentiator;
        let dt = 0.01;
        let speeds: Vec<f64> = (0..samples)
            .map(|i| speed[i * speed.len() / samples.max(1)])
            .collect();
        let mut x = 2.0;
        let position: Vec<f64> = speeds
            .iter()
            .map(|v| {
                x += v * dt;
                x
            })
            .collect();
        let diff = Differentiator::new(2 * half + 1);
        let kernels: [&[f64]; SHARE_KERNELS] = [
            &diff.weights[0],
            &diff.weights[1],
            &diff.weights[2],
            &diff.weights[3],
            &diff.weights[4],
        ];
        let q = Quantisation {
            block,
            ..Quantisation::new(step, dither)
        };
        let rows: Vec<usize> = (0..samples).collect();
        let table = SpeedShares::new(&kernels, &position, &speeds, &rows, &speeds, q, dt);
        prop_assert_eq!(table.table.len(), SPEED_CLASSES + 1);
        for class in &table.table {
            for s in class {
                prop_assert!(s.is_finite() && *s >= 0.0, "{table:?}");
            }
        }
        let shares = RowShares::new(table, &speeds);
        for i in 0..samples {
            for k in 0..SHARE_KERNELS {
                prop_assert!(shares.share(i, k).is_finite());
            }
        }
    }
}
