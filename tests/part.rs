//! The part geometry against independent checks: truck's own B-spline evaluator against exact
//! ODE points, Green's-theorem area against a fine polygon, the STL mesh by edge counting and
//! the divergence theorem, the truck solid's shell condition, and hole validation.

use camspring::design::design;
use camspring::export::step::solid;
use camspring::part::mesh::{mesh, rings};
use camspring::part::{build, Part, PartError};
use camspring::{
    model::{Hole, Spec},
    spec::DEFAULT_SPEC_TOML,
};
use truck_modeling::{BSplineCurve, KnotVec, ParametricCurve, Point3};
use truck_topology::shell::ShellCondition;

fn paper() -> Spec {
    Spec::from_toml(DEFAULT_SPEC_TOML).unwrap()
}

fn ankle() -> Spec {
    Spec::from_toml(include_str!("../specs/ankle.toml")).unwrap()
}

fn part_of(spec: &Spec) -> (camspring::Design, Part) {
    let d = design(spec).unwrap();
    let p = build(&d).unwrap();
    (d, p)
}

#[test]
fn fitted_bspline_is_within_tolerance_of_the_exact_surface() {
    for spec in [paper(), ankle()] {
        let (d, part) = part_of(&spec);
        let r = spec.follower.roller_radius_mm;
        for edge in &part.cam_edges {
            let b = edge.bspline();
            let curve = BSplineCurve::new(
                KnotVec::from(b.knots.clone()),
                b.control_points
                    .iter()
                    .map(|p| Point3::new(p[0], p[1], 0.0))
                    .collect(),
            );
            let s_end = d.pitch_curve.samples.last().unwrap().s_mm;
            let mut worst = 0.0_f64;
            for k in 0..=2000 {
                let s = s_end * k as f64 / 2000.0;
                let exact = d.pitch_curve.exact_at_arc(s).unwrap();
                let (sin, cos) = exact.theta_rad.sin_cos();
                let p = part
                    .frame
                    .map(exact.x_mm + r * sin, exact.y_mm - r * cos, edge.mirrored);
                let q = curve.subs(s);
                worst = worst.max((q.x - p[0]).hypot(q.y - p[1]));
            }
            assert!(
                worst <= spec.output.fit_tolerance_mm,
                "deviation {worst:e} mm"
            );
            // The reported deviation is honest: the dense check finds nothing much larger.
            assert!(
                worst <= 1.5 * edge.fit_deviation_mm + 1e-9,
                "{worst:e} vs reported {:e}",
                edge.fit_deviation_mm
            );
        }
    }
}

fn polygon_area(points: &[[f64; 2]]) -> f64 {
    let n = points.len();
    (0..n)
        .map(|i| {
            let (a, b) = (points[i], points[(i + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum::<f64>()
        / 2.0
}

#[test]
fn green_area_agrees_with_a_fine_polygon() {
    let mut spec = paper();
    spec.output.chord_tolerance_mm = 1e-5;
    let (_, part) = part_of(&spec);
    let poly = part.outline_polygon();
    let inscribed = polygon_area(&poly);
    // Chords of sagitta <= 1e-5 mm along ~50 mm of cam edge change the area by < 2/3 * 1e-5 * 50.
    let bound = 2.0 / 3.0 * 1e-5 * part.cam_edge_length_mm;
    assert!(inscribed > 0.0, "counter-clockwise outline");
    assert!(
        (part.area_mm2 - inscribed).abs() <= bound,
        "{} vs {} (bound {bound})",
        part.area_mm2,
        inscribed
    );
}

#[test]
fn outline_is_closed_and_counter_clockwise() {
    for spec in [paper(), ankle()] {
        let (_, part) = part_of(&spec);
        let n = part.outline.len();
        for i in 0..n {
            let end = part.outline[i].ends(&part.cam_edges).1;
            let next = part.outline[(i + 1) % n].ends(&part.cam_edges).0;
            assert!((end[0] - next[0]).hypot(end[1] - next[1]) < 1e-12);
        }
        assert!(part.area_mm2 > 0.0);
    }
}

/// Every undirected edge used by exactly two triangles, in opposite directions.
fn assert_closed_and_oriented(tris: &[stl_io::Triangle]) {
    use std::collections::HashMap;
    let key = |v: &stl_io::Vertex| [v[0].to_bits(), v[1].to_bits(), v[2].to_bits()];
    let mut edges: HashMap<([u32; 3], [u32; 3]), i32> = HashMap::new();
    for t in tris {
        for k in 0..3 {
            let (a, b) = (key(&t.vertices[k]), key(&t.vertices[(k + 1) % 3]));
            *edges.entry((a, b)).or_default() += 1;
        }
    }
    for ((a, b), n) in &edges {
        assert_eq!(*n, 1, "directed edge used {n} times");
        assert_eq!(
            edges.get(&(*b, *a)),
            Some(&1),
            "edge without its opposite: not watertight"
        );
    }
}

fn signed_volume(tris: &[stl_io::Triangle]) -> f64 {
    tris.iter()
        .map(|t| {
            let [a, b, c] = t.vertices.map(|v| [v[0] as f64, v[1] as f64, v[2] as f64]);
            (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                + a[2] * (b[0] * c[1] - b[1] * c[0]))
                / 6.0
        })
        .sum()
}

#[test]
fn stl_mesh_is_watertight_outward_and_has_the_right_volume() {
    let mut spec = paper();
    spec.part.holes = vec![Hole {
        x_mm: 10.0,
        y_mm: 0.0,
        diameter_mm: 5.0,
    }];
    for spec in [spec, ankle()] {
        let (_, part) = part_of(&spec);
        let tol = spec.output.stl_tolerance_mm;
        let tris = mesh(
            &rings(&part, tol, spec.output.chord_tolerance_mm),
            part.thickness_mm,
        )
        .unwrap();
        assert_closed_and_oriented(&tris);
        let v = signed_volume(&tris);
        let exact = part.area_mm2 * part.thickness_mm;
        let holes: f64 = part
            .holes
            .iter()
            .map(|h| std::f64::consts::PI * h.diameter_mm)
            .sum();
        let bound = tol * part.thickness_mm * (part.cam_edge_length_mm + holes) + 1e-3;
        assert!(v > 0.0);
        assert!((v - exact).abs() <= bound, "{v} vs {exact} (bound {bound})");
    }
}

#[test]
fn truck_solid_has_a_closed_shell() {
    let (_, part) = part_of(&paper());
    let s = solid(&part).unwrap();
    assert_eq!(s.boundaries().len(), 1);
    assert_eq!(s.boundaries()[0].shell_condition(), ShellCondition::Closed);
}

#[test]
fn holes_that_do_not_fit_are_refused_with_their_index() {
    let mut spec = paper();
    spec.part.holes = vec![
        Hole {
            x_mm: 10.0,
            y_mm: 0.0,
            diameter_mm: 4.0,
        },
        Hole {
            x_mm: 200.0,
            y_mm: 0.0,
            diameter_mm: 4.0,
        },
    ];
    let d = design(&spec).unwrap();
    match build(&d) {
        Err(PartError::Hole {
            index: 1, problem, ..
        }) => assert!(problem.contains("outside"), "{problem}"),
        other => panic!("{other:?}"),
    }
    spec.part.holes = vec![
        Hole {
            x_mm: 10.0,
            y_mm: 0.0,
            diameter_mm: 10.0,
        },
        Hole {
            x_mm: 16.0,
            y_mm: 0.0,
            diameter_mm: 3.0,
        },
    ];
    match build(&design(&spec).unwrap()) {
        Err(PartError::Hole { index, problem, .. }) => {
            assert!(problem.contains("at least 1 mm"), "{index} {problem}")
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn an_undercut_design_has_no_part() {
    let spec = Spec::from_toml(include_str!("../specs/paper-literal.toml")).unwrap();
    match build(&design(&spec).unwrap()) {
        Err(PartError::Undercut { advice, .. }) => assert!(advice.contains("follower.preload")),
        other => panic!("{other:?}"),
    }
}
