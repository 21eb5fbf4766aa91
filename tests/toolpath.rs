//! Tool paths against the exact part (independently of rs274, which the interop tests use),
//! refusals, and the G-code text rules.

use camspring::design::design;
use camspring::part::build;
use camspring::toolpath::path::{sample_move, Move};
use camspring::toolpath::{contour, gcode, passes, ToolpathError};
use camspring::{
    model::{Hole, Spec},
    spec::DEFAULT_SPEC_TOML,
};

fn paper() -> Spec {
    Spec::from_toml(DEFAULT_SPEC_TOML).unwrap()
}

/// Dense exact outline of the part (ODE samples at 0.1 um chords, plus corners).
fn boundary(spec: &Spec) -> Vec<[f64; 2]> {
    let mut fine = spec.clone();
    fine.output.chord_tolerance_mm = 1e-4;
    let d = design(&fine).unwrap();
    build(&d).unwrap().outline_polygon()
}

fn dist_to_polygon(p: [f64; 2], poly: &[[f64; 2]]) -> f64 {
    (0..poly.len())
        .map(|i| {
            let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let l2 = dx * dx + dy * dy;
            let t = if l2 > 0.0 {
                (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            (a[0] + t * dx - p[0]).hypot(a[1] + t * dy - p[1])
        })
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn finishing_contour_is_the_exact_offset_within_tolerance() {
    for arcs in [true, false] {
        let mut spec = paper();
        spec.machining.arcs = arcs;
        let d = design(&spec).unwrap();
        let part = build(&d).unwrap();
        let radius = spec.machining.tool_diameter_mm / 2.0;
        let tol = spec.machining.tolerance_mm;
        let (path, _) = contour(&d, &part, radius, tol - gcode_rounding(&spec), arcs).unwrap();
        let poly = boundary(&spec);
        let mut from = path.start;
        let mut worst = 0.0_f64;
        for m in &path.moves {
            for q in sample_move(from, m, 24) {
                worst = worst.max((dist_to_polygon(q, &poly) - radius).abs());
            }
            from = m.to();
        }
        // 0.1 um reference chords; the path is within the tolerance of the exact offset.
        assert!(worst <= tol, "arcs {arcs}: {worst:e} mm");
        assert!(
            (from[0] - path.start[0]).hypot(from[1] - path.start[1]) < 1e-12,
            "closed"
        );
        assert_eq!(
            path.moves.iter().any(|m| matches!(m, Move::Arc { .. })),
            arcs
        );
    }
}

fn gcode_rounding(spec: &Spec) -> f64 {
    camspring::toolpath::rounding_mm(gcode::decimals(spec.machining.dialect))
}

#[test]
fn roughing_leaves_the_allowance_and_steps_down_evenly() {
    let spec = paper();
    let d = design(&spec).unwrap();
    let part = build(&d).unwrap();
    let (ps, summary) = passes(&d, &part).unwrap();
    let total = spec.part.thickness_mm + spec.machining.breakthrough_mm;
    assert_eq!(
        summary.rough_levels,
        (total / spec.machining.depth_per_pass_mm).ceil() as usize
    );
    assert!(summary.depth_step_mm <= spec.machining.depth_per_pass_mm);
    let poly = boundary(&spec);
    let radius = spec.machining.tool_diameter_mm / 2.0;
    for p in &ps {
        // No move anywhere comes closer than the radius (less the tolerance): no gouge.
        let mut from = p.entry;
        let mut closest = f64::INFINITY;
        for m in &p.moves {
            for q in sample_move(from, m, 12) {
                closest = closest.min(dist_to_polygon(q, &poly));
            }
            from = m.to();
        }
        let want = if p.finishing {
            radius
        } else {
            radius + spec.machining.stock_allowance_mm
        };
        assert!(
            closest >= want - spec.machining.tolerance_mm,
            "{}: {closest}",
            p.label
        );
    }
    assert_eq!(ps.last().unwrap().z_mm, -total);
}

#[test]
fn refusals_say_what_to_change() {
    let mut spec = paper();
    spec.machining.tool_diameter_mm = 50.0;
    let d = design(&spec).unwrap();
    match passes(&d, &build(&d).unwrap()) {
        Err(ToolpathError::ToolTooLarge {
            max_diameter_mm, ..
        }) => {
            let concave = d.cam_surface.min_concave_radius(&d.pitch_curve).unwrap().0;
            assert!((max_diameter_mm - 2.0 * concave).abs() < 1e-12);
        }
        other => panic!("{other:?}"),
    }
    let mut spec = paper();
    spec.part.holes = vec![Hole {
        x_mm: 12.0,
        y_mm: 0.0,
        diameter_mm: 6.0,
    }];
    let d = design(&spec).unwrap();
    assert!(matches!(
        passes(&d, &build(&d).unwrap()),
        Err(ToolpathError::HoleTooSmall { index: 0, .. })
    ));
    let mut spec = paper();
    spec.machining.tolerance_mm = 1e-4;
    spec.machining.dialect = camspring::model::Dialect::Grbl;
    let d = design(&spec).unwrap();
    assert!(matches!(
        passes(&d, &build(&d).unwrap()),
        Err(ToolpathError::Resolution { decimals: 3, .. })
    ));
}

#[test]
fn spec_refuses_unsafe_machining_settings() {
    let base = include_str!("../specs/paper.toml");
    for (from, to, key) in [
        (
            "tool_diameter = \"6 mm\"",
            "tool_diameter = \"6 mm\"\ndepth_per_pass = \"7 mm\"",
            "machining.depth_per_pass",
        ),
        (
            "tool_diameter = \"6 mm\"",
            "tool_diameter = \"6 mm\"\nsafe_z = -1",
            "machining.safe_z",
        ),
        (
            "tool_diameter = \"6 mm\"",
            "tool_diameter = \"6 mm\"\nwork_offset = \"G60\"",
            "machining.work_offset",
        ),
        (
            "tool_diameter = \"6 mm\"",
            "tool_diameter = \"6 mm\"\nfeed = \"600 N\"",
            "machining.feed",
        ),
    ] {
        let e = Spec::from_toml(&base.replace(from, to))
            .unwrap_err()
            .to_string();
        assert!(e.contains(key), "{e}");
    }
}

#[test]
fn program_text_follows_the_rules() {
    let spec = paper();
    let d = design(&spec).unwrap();
    let part = build(&d).unwrap();
    let (ps, summary) = passes(&d, &part).unwrap();
    let (text, blocks) = gcode::write(&d, &ps, &summary);
    let code: Vec<&str> = text.lines().filter(|l| !l.starts_with('(')).collect();
    assert_eq!(code.len(), blocks);
    assert!(
        code[0].contains("G21")
            && code[0].contains("G90")
            && code[0].contains("G17")
            && code[0].contains("G54")
    );
    assert_eq!(*code.last().unwrap(), "M2");
    let spindle = code.iter().position(|l| l.starts_with("S8000 M3")).unwrap();
    let first_cut = code
        .iter()
        .position(|l| matches!(l.split_whitespace().next(), Some("G1" | "G2" | "G3")))
        .unwrap();
    assert!(spindle < first_cut);
    assert!(
        code[first_cut].contains('F'),
        "the first cut sets its feed: {}",
        code[first_cut]
    );
    // Modal: a line that only repeats the previous motion word does not occur, and nothing is empty.
    for w in code.windows(2) {
        assert!(!w[1].is_empty());
        assert!(!(w[1] == w[0] && w[0].starts_with("G1")), "{w:?}");
    }
    assert!(!text.contains("G41") && !text.contains("G42"));
}

#[test]
fn tabs_lift_over_the_straight_edges_or_are_refused() {
    let mut spec = paper();
    spec.machining.tabs = 2;
    spec.machining.tab_width_mm = 3.0;
    let d = design(&spec).unwrap();
    let part = build(&d).unwrap();
    let (ps, _) = passes(&d, &part).unwrap();
    let tab_z =
        spec.machining.stock_top_z_mm - spec.part.thickness_mm + spec.machining.tab_height_mm;
    for p in ps.iter().filter(|p| p.label.starts_with("outline")) {
        let lifts: Vec<f64> = p
            .moves
            .iter()
            .enumerate()
            .filter(|(k, _)| p.over_tab[*k])
            .map(|(k, m)| {
                let from = if k == 0 { p.entry } else { p.moves[k - 1].to() };
                let to = m.to();
                (to[0] - from[0]).hypot(to[1] - from[1])
            })
            .collect();
        if p.z_mm < tab_z {
            assert_eq!(lifts.len(), 2, "{}", p.label);
            for l in lifts {
                assert!((l - (3.0 + spec.machining.tool_diameter_mm)).abs() < 1e-9);
            }
        } else {
            assert!(lifts.is_empty());
        }
    }
    spec.machining.tabs = 16;
    spec.machining.tab_width_mm = 10.0;
    let d = design(&spec).unwrap();
    match passes(&d, &build(&d).unwrap()) {
        Err(ToolpathError::Tabs { needed_mm, .. }) => assert_eq!(needed_mm, 16.0),
        other => panic!("{other:?}"),
    }
}
