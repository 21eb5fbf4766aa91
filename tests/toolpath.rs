//! Tool paths against the exact part (independently of rs274, which the interop tests use),
//! refusals, and the G-code text rules.

use camspring::design::design;
use camspring::part::build;
use camspring::toolpath::path::{sample_move, Move};
use camspring::toolpath::{contour, gcode, jobs, Pass, ToolpathError};
use camspring::{
    model::{Hole, Spec},
    spec::DEFAULT_SPEC_TOML,
};

mod common;

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

/// Every milled pass of a program, in order.
fn passes(
    d: &camspring::design::Design,
    part: &camspring::part::Part,
) -> Result<(Vec<Pass>, camspring::toolpath::ToolpathSummary), ToolpathError> {
    let (js, summary) = jobs(d, part)?;
    Ok((js.into_iter().flat_map(|j| j.passes).collect(), summary))
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
    // Roughing stops at the skin above the bottom face.
    let rough = spec.part.thickness_mm - spec.machining.skin_mm;
    assert_eq!(
        summary.rough_levels,
        (rough / spec.machining.depth_per_pass_mm).ceil() as usize
    );
    assert!(summary.depth_step_mm <= spec.machining.depth_per_pass_mm);
    let poly = boundary(&spec);
    let radius = spec.machining.tool_diameter_mm / 2.0;
    for p in &ps {
        // No move anywhere comes closer than the radius (less the tolerance): no gouge.
        let mut from = p.entry;
        let mut closest = f64::INFINITY;
        for m in p.steps.iter().map(|s| &s.mv) {
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

/// The program of a spec: its text and summary.
fn program(spec: &Spec) -> (String, usize, camspring::toolpath::ToolpathSummary) {
    let d = design(spec).unwrap();
    let part = build(&d).unwrap();
    let (js, summary) = jobs(&d, &part).unwrap();
    let (text, blocks) = gcode::write(&d, &js, &summary);
    (text, blocks, summary)
}

/// The axis words of a code line, e.g. "G0 X1. Z5." -> ['X', 'Z'].
fn axes(line: &str) -> Vec<char> {
    line.split_whitespace()
        .filter_map(|w| w.chars().next())
        .filter(|c| matches!(c, 'X' | 'Y' | 'Z'))
        .collect()
}

/// A spec with three holes and three tools: a 6 mm end mill (outline and the 8 mm hole), a
/// 3 mm end mill (the 5 mm hole, by helix) and a 3.3 mm drill (the 3.3 mm hole).
fn three_tools(dialect: camspring::model::Dialect) -> Spec {
    use camspring::model::{Tool, ToolKind};
    let mut spec = paper();
    spec.part.holes = common::three_holes();
    let tool = |number, kind, diameter_mm, flute_length_mm| Tool {
        number,
        kind,
        diameter_mm,
        flute_length_mm,
        flutes: Some(2),
        spindle_rpm: 12000.0,
        feed_mm_per_min: 600.0,
        plunge_feed_mm_per_min: 120.0,
        peck_mm: None,
    };
    spec.machining.tools = vec![
        tool(1, ToolKind::EndMill, 6.0, Some(16.0)),
        tool(2, ToolKind::EndMill, 3.0, Some(12.0)),
        tool(3, ToolKind::Drill, 3.3, None),
    ];
    spec.machining.dialect = dialect;
    spec.machining.tolerance_mm = dialect.default_tolerance_mm();
    spec
}

#[test]
fn program_text_follows_the_rules() {
    let spec = paper();
    let (text, blocks, _) = program(&spec);
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
fn every_tool_starts_with_z_alone_and_a_spindle_dwell() {
    use camspring::model::Dialect;
    for dialect in [Dialect::Linuxcnc, Dialect::Grbl, Dialect::Fanuc] {
        for spec in [
            {
                let mut s = paper();
                s.machining.dialect = dialect;
                s.machining.tolerance_mm = dialect.default_tolerance_mm();
                s
            },
            three_tools(dialect),
        ] {
            let (text, _, summary) = program(&spec);
            let code: Vec<&str> = text.lines().filter(|l| !l.starts_with('(')).collect();
            // Where each tool starts: its change (M6), or for GRBL the pause (M0) and the
            // program start.
            let mut starts: Vec<usize> = code
                .iter()
                .enumerate()
                .filter(|(_, l)| l.contains("M6") || **l == "M0")
                .map(|(i, _)| i)
                .collect();
            if dialect == Dialect::Grbl {
                assert!(!text.contains("M6"), "GRBL has no tool change");
                starts.insert(0, 0);
            }
            assert_eq!(starts.len(), summary.tools.len(), "{dialect:?}");
            for &i in &starts {
                let motion = code[i + 1..].iter().find(|l| !axes(l).is_empty()).unwrap();
                assert_eq!(axes(motion), vec!['Z'], "{dialect:?}: {motion}");
                let z: f64 = motion.split('Z').nth(1).unwrap().parse().unwrap();
                assert_eq!(z, spec.machining.safe_z_mm);
            }
            let dwell = match dialect {
                Dialect::Fanuc => "G4 P3000",
                _ => "G4 P3.",
            };
            let mut m3 = 0;
            for (i, l) in code.iter().enumerate() {
                if l.split_whitespace().any(|w| w == "M3") {
                    m3 += 1;
                    assert_eq!(code[i + 1], dwell, "{dialect:?}");
                }
            }
            assert_eq!(m3, summary.tools.len());
        }
    }
}

#[test]
fn tools_are_chosen_per_hole_and_ordered_drills_first() {
    use camspring::model::{Dialect, ToolKind};
    let spec = three_tools(Dialect::Linuxcnc);
    let d = design(&spec).unwrap();
    let (js, summary) = jobs(&d, &build(&d).unwrap()).unwrap();
    let order: Vec<u32> = js.iter().map(|j| j.tool.number).collect();
    assert_eq!(order, vec![3, 2, 1]);
    assert_eq!(js[0].tool.kind, ToolKind::Drill);
    let drill = js[0].drilling.as_ref().unwrap();
    assert_eq!(drill.holes.len(), 1);
    assert_eq!(drill.holes[0].0, 2);
    // Through the plate and the breakthrough with the full diameter: the 118 degree point
    // adds d / (2 tan 59 deg).
    let point = 3.3 / (2.0 * 59f64.to_radians().tan());
    assert!(
        (drill.z_mm - (-10.5 - point)).abs() < 1e-3,
        "{}",
        drill.z_mm
    );
    // 11.5 mm is deeper than three diameters: pecks of one diameter.
    assert_eq!(drill.peck_mm, Some(3.3));
    assert!(js[1].passes.iter().all(|p| p.label.starts_with("hole 1")));
    assert!(js[2].passes.iter().any(|p| p.label.starts_with("hole 0")));
    assert!(js[2]
        .passes
        .last()
        .unwrap()
        .label
        .starts_with("outline finish"));
    assert_eq!(summary.tools.len(), 3);
    let (text, _, _) = program(&spec);
    assert!(text.contains("G98 G83 X18. Y-5.5"), "{text}");
    assert!(text.contains("T2 M6") && text.contains("T3 M6"));
}

#[test]
fn a_tool_too_short_for_the_depth_is_refused_naming_both() {
    let mut spec = paper();
    spec.machining.tool_diameter_mm = 3.0;
    spec.machining.depth_per_pass_mm = 1.0;
    let d = design(&spec).unwrap();
    let e = jobs(&d, &build(&d).unwrap()).unwrap_err();
    assert!(
        matches!(e, ToolpathError::FluteLength { assumed: true, .. }),
        "{e:?}"
    );
    let text = e.to_string();
    // 10 mm plate + 0.5 mm breakthrough against the assumed 3 diameters.
    assert!(
        text.contains("10.500 mm deep") && text.contains("9.000 mm"),
        "{text}"
    );
    assert!(text.contains("flute_length"), "{text}");
    spec.machining.flute_length_mm = Some(12.0);
    let d = design(&spec).unwrap();
    assert!(jobs(&d, &build(&d).unwrap()).is_ok());
    spec.machining.flute_length_mm = Some(8.0);
    let d = design(&spec).unwrap();
    let text = jobs(&d, &build(&d).unwrap()).unwrap_err().to_string();
    assert!(
        text.contains("8.000 mm") && !text.contains("assumed"),
        "{text}"
    );
}

#[test]
fn feeds_far_from_practice_are_warned_in_the_program() {
    // "800 mm/s" is a valid feed rate, 48000 mm/min: written as asked, and warned.
    let base = include_str!("../specs/paper.toml");
    let spec = Spec::from_toml(&base.replace(
        "tool_diameter = \"6 mm\"",
        "tool_diameter = \"6 mm\"\nfeed = \"800 mm/s\"\nflutes = 2",
    ))
    .unwrap();
    assert_eq!(spec.machining.feed_mm_per_min, 48000.0);
    let (text, _, summary) = program(&spec);
    assert!(
        summary
            .warnings
            .iter()
            .any(|w| w.contains("machining.feed = 48000")),
        "{:?}",
        summary.warnings
    );
    // 48000 / (8000 rpm x 2) = 3 mm per tooth, beyond 6 / 40.
    assert!(summary
        .warnings
        .iter()
        .any(|w| w.contains("chip load 3.0000")));
    assert!(text.contains("(WARNING: machining.feed = 48000"));
    // The default settings are within practice.
    assert!(program(&paper()).2.warnings.is_empty());
}

#[test]
fn entries_ramp_within_the_angle_and_roughing_never_cuts_through() {
    use camspring::model::Dialect;
    let spec = three_tools(Dialect::Linuxcnc);
    let d = design(&spec).unwrap();
    let part = build(&d).unwrap();
    let (js, _) = jobs(&d, &part).unwrap();
    let m = &spec.machining;
    let bottom = m.stock_top_z_mm - spec.part.thickness_mm;
    let tan = m.ramp_angle_deg.to_radians().tan();
    let mut finished = false;
    for p in js.iter().flat_map(|j| &j.passes) {
        assert!(!finished, "{} after the outline's finishing pass", p.label);
        let mut from = p.entry;
        let mut z = p.entry_z_mm;
        for s in &p.steps {
            let planar: f64 = sample_move(from, &s.mv, 64)
                .windows(2)
                .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
                .sum();
            let drop = z - s.z_mm;
            if drop > 1e-9 && !s.plunge {
                assert!(
                    drop <= tan * planar * (1.0 + 1e-6),
                    "{}: {drop} over {planar}",
                    p.label
                );
            }
            from = s.mv.to();
            z = s.z_mm;
        }
        // Before the outline's finishing pass nothing reaches the bottom face outside a hole.
        if !p.label.starts_with("outline finish") && !p.label.contains("finish") {
            let lowest = p.steps.iter().map(|s| s.z_mm).fold(f64::INFINITY, f64::min);
            assert!(lowest >= bottom + m.skin_mm - 1e-9, "{}: {lowest}", p.label);
        }
        finished = p.label.starts_with("outline finish");
    }
    assert!(finished);
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
            .steps
            .iter()
            .enumerate()
            .filter(|(k, s)| p.over_tab[*k] && !s.plunge)
            .map(|(k, s)| {
                let from = if k == 0 {
                    p.entry
                } else {
                    p.steps[k - 1].mv.to()
                };
                let to = s.mv.to();
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

#[test]
fn tool_lists_and_drawing_settings_are_checked_naming_the_key() {
    let base = include_str!("../specs/paper.toml");
    let tools = base.replace("tool_diameter = \"6 mm\"\n", "");
    for (text, key, expected) in [
        (
            format!("{base}\n[[machining.tools]]\ndiameter = \"6 mm\"\n"),
            "machining.tool_diameter",
            "[[machining.tools]]",
        ),
        (
            format!("{tools}\n[[machining.tools]]\nkind = \"reamer\"\ndiameter = \"6 mm\"\n"),
            "machining.tools[0].kind",
            "\"end-mill\", \"drill\"",
        ),
        (
            format!("{tools}\n[[machining.tools]]\nnumber = 2\ndiameter = \"6 mm\"\n[[machining.tools]]\nnumber = 2\ndiameter = \"3 mm\"\n"),
            "machining.tools[1].number",
            "no other tool",
        ),
        (
            format!("{tools}\n[[machining.tools]]\nkind = \"drill\"\ndiameter = \"6 mm\"\n"),
            "machining.tools",
            "end mill",
        ),
        (
            format!("{tools}\n[[machining.tools]]\ndiameter = \"6 mm\"\nflutes = 0\n"),
            "machining.tools[0].flutes",
            "1 to 12",
        ),
        (
            format!("{base}\n[drawing]\nscale = \"3:1\"\n"),
            "drawing.scale",
            "standard scale",
        ),
        (
            format!("{base}\n[drawing]\nscale = \"big\"\n"),
            "drawing.scale",
            "2:1",
        ),
        (
            format!("{base}\n[drawing]\nsheet = \"a0\"\n"),
            "drawing.sheet",
            "\"a4\"",
        ),
        (
            format!("{base}\n[drawing]\ncam_finish = \"0.8 mm\"\n"),
            "drawing.cam_finish",
            "um",
        ),
        (
            base.replace("[machining]", "[machining]\nramp_angle = \"60 deg\""),
            "machining.ramp_angle",
            "deg",
        ),
        (
            base.replace("[machining]", "[machining]\nskin = \"10 mm\""),
            "machining.skin",
            "mm",
        ),
    ] {
        let e = Spec::from_toml(&text).unwrap_err().to_string();
        assert!(e.contains(key) && e.contains(expected), "{key}: {e}");
    }
    // A valid list and drawing section are read as written.
    let spec = Spec::from_toml(&format!(
        "{tools}\n[[machining.tools]]\ndiameter = \"5 mm\"\nflute_length = \"20 mm\"\n[[machining.tools]]\nkind = \"drill\"\ndiameter = \"3.3 mm\"\npeck = \"2 mm\"\n[drawing]\nsheet = \"ansi-b\"\nscale = \"1:2\"\ndate = \"2026-11-23\"\ncam_finish = \"0.4 um\"\n"
    ))
    .unwrap();
    assert_eq!(spec.machining.tool_diameter_mm, 5.0);
    assert_eq!(spec.machining.tools[1].number, 2);
    assert_eq!(spec.machining.tools[1].peck_mm, Some(2.0));
    assert_eq!(spec.drawing.sheet, camspring::model::SheetSize::AnsiB);
    assert_eq!(spec.drawing.scale, Some(0.5));
    assert!((spec.drawing.cam_finish_ra_um - 0.4).abs() < 1e-12);
    assert_eq!(spec.drawing.date.as_deref(), Some("2026-11-23"));
}
