//! `drawing.svg`: a shop drawing of the part at 1:1 in mm.
//!
//! The outline is drawn with the same cubic spans as the STEP/DXF B-spline (SVG `C`
//! commands), the pitch curves dashed, the roller at the start, middle and end of the stroke,
//! the main dimensions (overall length and height, stroke, lift) and a title block with the
//! name, law, material, thickness and tolerances. The page size is given in mm, so printing at
//! 100 % gives a 1:1 template.

use std::fmt::Write as _;

use svg::node::element::{Circle, Group, Line, Path, Polyline, Rectangle, Text};
use svg::Document;

use crate::design::Design;
use crate::geom::P2;
use crate::part::{Part, Segment};

const MARGIN: f64 = 25.0;
const TITLE_H: f64 = 45.0;
const TITLE_W: f64 = 180.0;
const STROKE: &str = "#000";

/// Maps part coordinates (y up) to page coordinates (mm, y down).
#[derive(Debug, Clone, Copy)]
struct Page {
    x0: f64,
    y_top: f64,
}

impl Page {
    fn p(&self, p: P2) -> (f64, f64) {
        (p[0] - self.x0 + MARGIN, self.y_top - p[1] + MARGIN)
    }
}

fn fmt_pt(page: &Page, p: P2) -> String {
    let (x, y) = page.p(p);
    format!("{x:.5},{y:.5}")
}

fn outline_path(part: &Part, page: &Page) -> String {
    let mut d = String::new();
    let start = part.outline[0].ends(&part.cam_edges).0;
    let _ = write!(d, "M{}", fmt_pt(page, start));
    for seg in &part.outline {
        match seg {
            Segment::Line { to, .. } => {
                let _ = write!(d, " L{}", fmt_pt(page, *to));
            }
            Segment::Cam { edge, reversed } => {
                let b = part.cam_edges[*edge].bspline();
                // Control points come in Bezier spans of 3 after the first.
                let spans: Vec<[P2; 4]> = (0..(b.control_points.len() - 1) / 3)
                    .map(|k| {
                        let c = &b.control_points[3 * k..3 * k + 4];
                        [c[0], c[1], c[2], c[3]]
                    })
                    .collect();
                let ordered: Vec<[P2; 4]> = if *reversed {
                    spans
                        .iter()
                        .rev()
                        .map(|c| [c[3], c[2], c[1], c[0]])
                        .collect()
                } else {
                    spans
                };
                for c in ordered {
                    let _ = write!(
                        d,
                        " C{} {} {}",
                        fmt_pt(page, c[1]),
                        fmt_pt(page, c[2]),
                        fmt_pt(page, c[3])
                    );
                }
            }
        }
    }
    d.push_str(" Z");
    d
}

fn text(x: f64, y: f64, s: impl Into<String>, size: f64) -> Text {
    Text::new(s.into())
        .set("x", x)
        .set("y", y)
        .set("font-size", size)
        .set("font-family", "sans-serif")
}

fn thin_line(a: (f64, f64), b: (f64, f64)) -> Line {
    Line::new()
        .set("x1", a.0)
        .set("y1", a.1)
        .set("x2", b.0)
        .set("y2", b.1)
        .set("stroke", STROKE)
        .set("stroke-width", 0.18)
}

/// A linear dimension between page points a and b, drawn offset along `normal` (page units).
fn dimension(
    a: (f64, f64),
    b: (f64, f64),
    normal: (f64, f64),
    offset: f64,
    label: String,
) -> Group {
    let da = (a.0 + normal.0 * offset, a.1 + normal.1 * offset);
    let db = (b.0 + normal.0 * offset, b.1 + normal.1 * offset);
    let ext = |p: (f64, f64), q: (f64, f64)| {
        thin_line(
            (p.0 + normal.0 * 1.0, p.1 + normal.1 * 1.0),
            (q.0 + normal.0 * 2.0, q.1 + normal.1 * 2.0),
        )
    };
    let mid = (
        (da.0 + db.0) / 2.0 + normal.0 * 2.0,
        (da.1 + db.1) / 2.0 + normal.1 * 2.0,
    );
    let angle = (db.1 - da.1).atan2(db.0 - da.0).to_degrees();
    let angle = if !(-90.0..=90.0).contains(&angle) {
        angle + 180.0
    } else {
        angle
    };
    Group::new()
        .add(ext(a, da))
        .add(ext(b, db))
        .add(
            thin_line(da, db)
                .set("marker-start", "url(#arrow)")
                .set("marker-end", "url(#arrow)"),
        )
        .add(
            text(mid.0, mid.1, label, 3.0)
                .set("text-anchor", "middle")
                .set("dominant-baseline", "middle")
                .set(
                    "transform",
                    format!("rotate({angle:.3} {:.3} {:.3})", mid.0, mid.1),
                ),
        )
}

/// The drawing of a design's part.
pub fn drawing_svg(design: &Design, part: &Part) -> String {
    let (lo, hi) = part.bounding_box_mm;
    let page = Page {
        x0: lo[0],
        y_top: hi[1],
    };
    let part_w = hi[0] - lo[0];
    let part_h = hi[1] - lo[1];
    let width = (part_w + 2.0 * MARGIN + 20.0).max(TITLE_W + 2.0 * 10.0);
    let height = part_h + 2.0 * MARGIN + TITLE_H + 10.0;
    let spec = &design.spec;
    let law = &design.law.law;
    let xmax = design.xmax_mm();

    let defs = svg::node::element::Definitions::new().add(
        svg::node::element::Marker::new()
            .set("id", "arrow")
            .set("viewBox", "0 0 10 10")
            .set("refX", 10)
            .set("refY", 5)
            .set("markerWidth", 2.2)
            .set("markerHeight", 2.2)
            .set("orient", "auto-start-reverse")
            .set("markerUnits", "userSpaceOnUse")
            .add(
                Path::new()
                    .set("d", "M0,0 L10,5 L0,10 z")
                    .set("fill", STROKE),
            ),
    );
    let mut doc = Document::new()
        .set("width", format!("{width:.3}mm"))
        .set("height", format!("{height:.3}mm"))
        .set("viewBox", (0.0, 0.0, width, height))
        .add(defs)
        .add(
            Rectangle::new()
                .set("width", width)
                .set("height", height)
                .set("fill", "white"),
        )
        .add(
            Path::new()
                .set("id", "outline")
                .set("d", outline_path(part, &page))
                .set("fill", "#e8eef5")
                .set("stroke", STROKE)
                .set("stroke-width", 0.35),
        );
    for h in &part.holes {
        let (cx, cy) = page.p([h.x_mm, h.y_mm]);
        doc = doc.add(
            Circle::new()
                .set("class", "hole")
                .set("cx", cx)
                .set("cy", cy)
                .set("r", h.diameter_mm / 2.0)
                .set("fill", "white")
                .set("stroke", STROKE)
                .set("stroke-width", 0.35),
        );
        doc = doc.add(text(
            cx + h.diameter_mm / 2.0 + 1.0,
            cy - 1.0,
            format!("⌀{:.2}", h.diameter_mm),
            2.5,
        ));
    }
    if spec.follower.count == 2 {
        let (a, b) = (page.p([lo[0] - 5.0, 0.0]), page.p([hi[0] + 5.0, 0.0]));
        doc = doc.add(thin_line(a, b).set("stroke-dasharray", "8,2,1,2"));
    }
    for pitch in &part.pitch_curves {
        let pts: Vec<String> = pitch.iter().map(|&p| fmt_pt(&page, p)).collect();
        doc = doc.add(
            Polyline::new()
                .set("class", "pitch")
                .set("points", pts.join(" "))
                .set("fill", "none")
                .set("stroke", "#1565c0")
                .set("stroke-width", 0.25)
                .set("stroke-dasharray", "2,1"),
        );
        for k in [0, pitch.len() / 2, pitch.len() - 1] {
            let (cx, cy) = page.p(pitch[k]);
            doc = doc
                .add(
                    Circle::new()
                        .set("class", "roller")
                        .set("cx", cx)
                        .set("cy", cy)
                        .set("r", part.roller_radius_mm)
                        .set("fill", "none")
                        .set("stroke", "#888")
                        .set("stroke-width", 0.2),
                )
                .add(
                    Circle::new()
                        .set("cx", cx)
                        .set("cy", cy)
                        .set("r", 0.3)
                        .set("fill", "#888"),
                );
        }
    }
    // Dimensions.
    let (bl, br, tl) = (
        page.p([lo[0], lo[1]]),
        page.p([hi[0], lo[1]]),
        page.p([hi[0], hi[1]]),
    );
    doc = doc
        .add(dimension(bl, br, (0.0, 1.0), 8.0, format!("{part_w:.3}")))
        .add(dimension(br, tl, (1.0, 0.0), 8.0, format!("{part_h:.3}")));
    let upper = &part.pitch_curves[0];
    let (p0, p1) = (upper[0], *upper.last().expect("non-empty"));
    let y_above = hi[1];
    doc = doc.add(dimension(
        page.p([p0[0], y_above]),
        page.p([p1[0], y_above]),
        (0.0, -1.0),
        6.0,
        format!("stroke {xmax:.3}"),
    ));
    doc = doc.add(dimension(
        page.p([lo[0], p0[1]]),
        page.p([lo[0], p1[1]]),
        (-1.0, 0.0),
        8.0,
        format!("lift {:.3}", p1[1] - p0[1]),
    ));

    // Title block.
    let tx = width - TITLE_W - 10.0;
    let ty = height - TITLE_H - 5.0;
    let cam = &spec.part.cam_material;
    let targets = match &spec.law {
        crate::model::LawSpec::Targets(t) => format!(
            "spec: fmax {} N at xmax {} mm, fmin {} N at l0 {} mm, c0 {} at delta0 {} mm",
            t.fmax_n, t.xmax_mm, t.fmin_n, t.l0_mm, t.c0, t.delta0_mm
        ),
        crate::model::LawSpec::Given { .. } => "spec: law given directly (mu, k2, f0)".to_string(),
        crate::model::LawSpec::Conditions { conditions, .. } => format!(
            "spec: law from the conditions {}",
            conditions
                .iter()
                .map(|c| c.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
        crate::model::LawSpec::Table { source, .. } => format!("spec: law tabulated in {source}"),
        crate::model::LawSpec::Polynomial { .. } => "spec: polynomial law".to_string(),
    };
    let rows = [
        format!("camspring cam part: {}", spec.name),
        targets,
        match law.exponential() {
            Some(l) => format!(
                "law: F = {:.6} N x exp({:.6} /mm x x) + {:.6} N over x = 0 ... {xmax} mm",
                l.mu_n, l.k2_per_mm, l.f0_n
            ),
            None => format!("law: {} over x = 0 ... {xmax} mm", law.describe()),
        },
        format!(
            "material {} (E {:.0} MPa); thickness {} mm; roller radius {} mm; {} follower(s)",
            cam.name,
            cam.youngs_modulus_mpa,
            spec.part.thickness_mm,
            spec.follower.roller_radius_mm,
            spec.follower.count
        ),
        format!(
            "cam edge: cubic B-spline within {} mm of the exact surface (checked {:.2e} mm)",
            spec.output.fit_tolerance_mm,
            part.cam_edges
                .iter()
                .map(|e| e.fit_deviation_mm)
                .fold(0.0, f64::max)
        ),
        format!(
            "scale 1:1, units mm, pitch curve dashed; camspring {}",
            env!("CARGO_PKG_VERSION")
        ),
    ];
    let mut block = Group::new().set("id", "title-block").add(
        Rectangle::new()
            .set("x", tx)
            .set("y", ty)
            .set("width", TITLE_W)
            .set("height", TITLE_H)
            .set("fill", "none")
            .set("stroke", STROKE)
            .set("stroke-width", 0.35),
    );
    for (i, row) in rows.iter().enumerate() {
        let y = ty + 6.5 + 7.0 * i as f64;
        block = block.add(text(
            tx + 3.0,
            y,
            row.clone(),
            if i == 0 { 4.0 } else { 2.8 },
        ));
        if i > 0 {
            block = block.add(thin_line((tx, y - 4.8), (tx + TITLE_W, y - 4.8)));
        }
    }
    doc.add(block).to_string()
}
