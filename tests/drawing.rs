//! The shop drawing: no text overlaps another, the holes and the cam-face coordinates are
//! there and right (against the spec and the exact surface), the sheet and scale follow the
//! rules, the title block says what the spec says, and the PDF is made.

use camspring::design::design;
use camspring::export::drawing::{drawing_pdf, drawing_svg, text_boxes};
use camspring::model::{SheetSize, Spec};
use camspring::part::build;
use camspring::spec::DEFAULT_SPEC_TOML;

mod common;

fn paper() -> Spec {
    Spec::from_toml(DEFAULT_SPEC_TOML).unwrap()
}

fn with_holes(mut spec: Spec) -> Spec {
    spec.part.holes = common::three_holes();
    spec
}

fn specs() -> Vec<(String, Spec)> {
    let mut out = vec![
        ("paper".to_string(), paper()),
        ("paper with holes".to_string(), with_holes(paper())),
        (
            "ankle".to_string(),
            Spec::from_toml(include_str!("../specs/ankle.toml")).unwrap(),
        ),
    ];
    for sheet in [SheetSize::A3, SheetSize::AnsiA, SheetSize::AnsiB] {
        let mut s = with_holes(paper());
        s.drawing.sheet = sheet;
        out.push((format!("{sheet:?}"), s));
    }
    let mut long = paper();
    if let camspring::model::LawSpec::Targets(t) = &mut long.law {
        t.xmax_mm = 120.0;
        t.fmax_n = 900.0;
    }
    long.follower.spring_rate_n_per_mm = 8.0;
    out.push(("long stroke".to_string(), long));
    out
}

/// The text between `<text ...>` and `</text>` of every text element.
fn texts(svg: &str) -> Vec<String> {
    svg.split("<text")
        .skip(1)
        .filter_map(|el| {
            el.split_once('>')
                .and_then(|(_, r)| r.split_once("</text>"))
        })
        .map(|(t, _)| t.trim().to_string())
        .collect()
}

#[test]
fn no_text_overlaps_another() {
    for (name, spec) in specs() {
        let d = match design(&spec) {
            Ok(d) => d,
            Err(e) => panic!("{name}: {e}"),
        };
        let part = build(&d).unwrap();
        let boxes = text_boxes(&d, &part);
        assert!(boxes.len() > 40, "{name}: {} texts", boxes.len());
        let (w, h) = spec.drawing.sheet.size_mm();
        for (i, a) in boxes.iter().enumerate() {
            assert!(
                a.x0 >= 10.0 && a.x1 <= w - 10.0 && a.y0 >= 10.0 && a.y1 <= h - 10.0,
                "{name}: text {i} outside the border: {a:?}"
            );
            for (j, b) in boxes.iter().enumerate().skip(i + 1) {
                let overlap = a.x0 < b.x1 && b.x0 < a.x1 && a.y0 < b.y1 && b.y0 < a.y1;
                assert!(!overlap, "{name}: texts {i} and {j} overlap: {a:?} {b:?}");
            }
        }
    }
}

#[test]
fn holes_and_cam_coordinates_are_tabulated_from_the_datum() {
    let spec = with_holes(paper());
    let d = design(&spec).unwrap();
    let part = build(&d).unwrap();
    let svg = drawing_svg(&d, &part);
    let t = texts(&svg);
    for (i, h) in spec.part.holes.iter().enumerate() {
        let tag = format!("H{}", i + 1);
        // The tag in the view and in the table, and the table's row: X, Y, diameter.
        assert!(t.iter().filter(|s| **s == tag).count() >= 2, "{tag}");
        assert!(t.contains(&format!("{:.3}", h.x_mm)));
        assert!(t.contains(&format!("{:.3} H7", h.diameter_mm)));
    }
    // The coordinate table: pairs of numbers in class "coordinate", on the exact surface.
    let mut fine = spec.clone();
    fine.output.chord_tolerance_mm = 1e-4;
    let fd = design(&fine).unwrap();
    let poly = build(&fd).unwrap().outline_polygon();
    let values: Vec<f64> = svg
        .split("<text")
        .filter(|el| el.contains("class=\"coordinate\""))
        .filter_map(|el| {
            el.split_once('>')
                .and_then(|(_, r)| r.split_once("</text>"))
        })
        .map(|(v, _)| v.trim().parse::<f64>().unwrap())
        .collect();
    assert!(values.len() >= 2 * 21, "{} values", values.len());
    let xmax = d.xmax_mm();
    let mut worst = 0.0_f64;
    for p in values.chunks(2) {
        let q = [p[0], p[1]];
        let dist = (0..poly.len())
            .map(|i| {
                let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                let t = (((q[0] - a[0]) * dx + (q[1] - a[1]) * dy) / (dx * dx + dy * dy))
                    .clamp(0.0, 1.0);
                (a[0] + t * dx - q[0]).hypot(a[1] + t * dy - q[1])
            })
            .fold(f64::INFINITY, f64::min);
        worst = worst.max(dist);
        assert!(q[0] > -1.0 && q[0] < xmax + 4.0 && q[1] > 0.0);
    }
    // Three decimals: within half a micron plus the reference's chords.
    assert!(worst < 1e-3, "{worst}");
    assert!(svg.contains("STEP 1.000 IN X"));
    assert!(svg.contains("PROFILE 0.040 (±0.020) TO A, B"));
}

#[test]
fn the_scale_is_standard_and_fits_and_a_given_one_is_kept() {
    let spec = paper();
    let d = design(&spec).unwrap();
    let part = build(&d).unwrap();
    let svg = drawing_svg(&d, &part);
    // The paper part (25 x 36 mm) fits A4 at 2:1 with its dimensions, not at 5:1.
    assert!(svg.contains("FRONT VIEW  2:1"), "{}", &svg[..200]);
    assert!(svg.contains("width=\"297mm\"") && svg.contains("height=\"210mm\""));
    let mut big = spec.clone();
    big.drawing.sheet = SheetSize::A3;
    let d3 = design(&big).unwrap();
    assert!(drawing_svg(&d3, &build(&d3).unwrap()).contains("width=\"420mm\""));
    let mut given = spec.clone();
    given.drawing.scale = Some(1.0);
    let dg = design(&given).unwrap();
    assert!(drawing_svg(&dg, &build(&dg).unwrap()).contains("FRONT VIEW  1:1"));
}

#[test]
fn the_title_block_says_what_the_spec_says_and_never_reads_the_clock() {
    let mut spec = paper();
    spec.drawing.number = Some("CS-0042".into());
    spec.drawing.revision = "C".into();
    spec.drawing.date = Some("2026-11-23".into());
    spec.drawing.drawn_by = Some("A. Designer".into());
    let d = design(&spec).unwrap();
    let part = build(&d).unwrap();
    let t = texts(&drawing_svg(&d, &part));
    for want in [
        "CS-0042",
        "C",
        "2026-11-23",
        "A. Designer",
        "ALUMINIUM-6061-T6",
        "2:1",
        "mm",
        "THIRD ANGLE",
        "10.000 mm",
        "CAM PLATE PAPER",
    ] {
        assert!(t.iter().any(|s| s == want), "{want} missing");
    }
    assert!(t.iter().any(|s| s.contains("ISO 2768-m")));
    // Without a date the field is blank, and two runs give the same bytes.
    let d = design(&paper()).unwrap();
    let part = build(&d).unwrap();
    let a = drawing_svg(&d, &part);
    assert!(!a.contains("2026"));
    assert_eq!(a, drawing_svg(&d, &part));
}

#[test]
fn the_pdf_is_one_page_of_the_sheet_with_the_text_embedded() {
    let d = design(&with_holes(paper())).unwrap();
    let part = build(&d).unwrap();
    let pdf = drawing_pdf(&drawing_svg(&d, &part)).unwrap();
    assert!(pdf.starts_with(b"%PDF-"));
    let text = String::from_utf8_lossy(&pdf);
    // A4 landscape in points: 297 mm = 841.89 pt, 210 mm = 595.28 pt.
    let head: String = text.chars().take(2000).collect();
    assert!(text.contains("/MediaBox [0 0 841.8"), "{head}");
    assert!(text.contains("DejaVu"), "the font is embedded");
}
