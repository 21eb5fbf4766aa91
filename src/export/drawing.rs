//! `drawing.svg` and `drawing.pdf`: the shop drawing of the part on a standard sheet.
//!
//! One sheet (`[drawing] sheet`, A4 by default, landscape) at the largest standard scale that
//! fits (or `[drawing] scale`), in third-angle projection:
//!
//! - **Front view**: the outline (the cam edges with the same cubic spans as the STEP/DXF
//!   B-spline), the holes with their tags, the pitch curves and rollers thin for reference.
//!   Ordinate dimensions from one datum: X0 (datum A) is the roller centre at the start of the
//!   stroke, Y0 (datum B) the centre line (two followers) or the cam surface's start (one). The
//!   ordinates name the lead-in, cam, stroke, run-out, web and roller features; the stroke
//!   also has a linear dimension between the roller centres.
//! - **Side view** (right): the thickness, with hidden lines for the holes and edges.
//! - **Tables**: the cam face as X, Y coordinates at a stated step with its profile
//!   tolerance, and the holes (tag, X, Y, diameter) from the same datum.
//! - **Notes and title block**: general tolerance (ISO 2768-m by default), finishes,
//!   datums; name, drawing number, revision, material, date (from the spec, never the
//!   clock), scale, sheet, units, projection.
//!
//! Every text is placed in a box that is checked against the boxes already placed and the
//! part's geometry, so that no text overlaps another or the part. The page size is given in
//! mm, so printing at 100 % gives the stated scale. The PDF is the same SVG converted by
//! svg2pdf with an embedded font (DejaVu Sans), so it does not depend on the machine's fonts.

use std::fmt::Write as _;

use svg::node::element::{
    Circle, Definitions, Group, Line, Marker, Path, Polyline, Rectangle, Text,
};
use svg::Document;

use crate::design::Design;
use crate::geom::P2;
use crate::model::drawing::{scale_label, STANDARD_SCALES};
use crate::model::LawSpec;
use crate::part::{exact_edge_point, Part, Segment};

/// Distance of the border from the sheet's edge.
const FRAME: f64 = 10.0;
/// Title block size (ISO 7200 width).
const TB_W: f64 = 180.0;
const TB_H: f64 = 32.0;
/// Width of the table column on the right.
const COL_W: f64 = 62.0;
/// Text height of dimensions, tables and notes.
const TEXT_H: f64 = 2.5;
/// Row height of the tables.
const ROW_H: f64 = 3.6;
/// Line spacing of the notes.
const NOTE_H: f64 = 4.0;
const STROKE: &str = "#000";
/// The font every text is set in (embedded in the PDF).
pub const FONT_FAMILY: &str = "DejaVu Sans, sans-serif";

/// Advance widths of DejaVu Sans for ASCII 32 ... 126, in em (0.318 is the space's width,
/// not 1/pi).
#[allow(clippy::approx_constant)]
const ASCII_EM: [f64; 95] = [
    0.318, 0.401, 0.460, 0.838, 0.636, 0.950, 0.780, 0.275, 0.390, 0.390, 0.500, 0.838, 0.318,
    0.361, 0.318, 0.337, 0.636, 0.636, 0.636, 0.636, 0.636, 0.636, 0.636, 0.636, 0.636, 0.636,
    0.337, 0.337, 0.838, 0.838, 0.838, 0.531, 1.000, 0.684, 0.686, 0.698, 0.770, 0.632, 0.575,
    0.775, 0.752, 0.295, 0.295, 0.656, 0.557, 0.863, 0.748, 0.787, 0.603, 0.787, 0.695, 0.635,
    0.611, 0.732, 0.684, 0.989, 0.685, 0.611, 0.685, 0.390, 0.337, 0.390, 0.838, 0.500, 0.500,
    0.613, 0.635, 0.550, 0.635, 0.615, 0.352, 0.635, 0.634, 0.278, 0.278, 0.579, 0.278, 0.974,
    0.634, 0.612, 0.635, 0.635, 0.411, 0.521, 0.392, 0.634, 0.592, 0.818, 0.592, 0.592, 0.525,
    0.636, 0.337, 0.636, 0.838,
];

/// Width of a text at a height (font size) in mm, from the font's advance widths.
pub fn text_width(s: &str, size: f64) -> f64 {
    s.chars()
        .map(|c| match c as u32 {
            32..=126 => ASCII_EM[(c as u32 - 32) as usize],
            0x2300 => 0.602, // diameter sign
            0x2212 | 0xB1 | 0xD7 => 0.838,
            _ => 1.0,
        })
        .sum::<f64>()
        * size
}

/// An axis-aligned box on the page (mm, y down).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TextBox {
    /// Left.
    pub x0: f64,
    /// Top.
    pub y0: f64,
    /// Right.
    pub x1: f64,
    /// Bottom.
    pub y1: f64,
}

impl TextBox {
    fn overlaps(&self, o: &TextBox) -> bool {
        self.x0 < o.x1 && o.x0 < self.x1 && self.y0 < o.y1 && o.y0 < self.y1
    }

    fn hits_segment(&self, a: (f64, f64), b: (f64, f64)) -> bool {
        // Liang-Barsky clipping of the segment against the box.
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let mut t0 = 0.0_f64;
        let mut t1 = 1.0_f64;
        for (p, q) in [
            (-dx, a.0 - self.x0),
            (dx, self.x1 - a.0),
            (-dy, a.1 - self.y0),
            (dy, self.y1 - a.1),
        ] {
            if p.abs() < 1e-12 {
                if q < 0.0 {
                    return false;
                }
            } else {
                let t = q / p;
                if p < 0.0 {
                    t0 = t0.max(t);
                } else {
                    t1 = t1.min(t);
                }
                if t0 > t1 {
                    return false;
                }
            }
        }
        true
    }
}

/// How a text is anchored at its point.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Anchor {
    Start,
    Middle,
    End,
}

/// The sheet being laid out: its SVG nodes, and the boxes of the texts and of the part's
/// geometry that later texts must keep clear of.
struct Sheet {
    doc: Document,
    texts: Vec<TextBox>,
    /// Part geometry on the page, as segments.
    geometry: Vec<((f64, f64), (f64, f64))>,
}

impl Sheet {
    fn add(&mut self, node: impl Into<Box<dyn svg::Node>>) {
        let doc = std::mem::replace(&mut self.doc, Document::new());
        self.doc = doc.add(node);
    }

    /// The box of a text: horizontal, or rotated by -90 degrees (reading upwards) about its point.
    fn text_box(x: f64, y: f64, s: &str, size: f64, anchor: Anchor, vertical: bool) -> TextBox {
        let w = text_width(s, size);
        let (ascent, descent) = (0.93 * size, 0.24 * size);
        let start = match anchor {
            Anchor::Start => 0.0,
            Anchor::Middle => -w / 2.0,
            Anchor::End => -w,
        };
        if vertical {
            // Rotated -90 about (x, y): the text runs from y - start upwards.
            TextBox {
                x0: x - ascent,
                y0: y - start - w,
                x1: x + descent,
                y1: y - start,
            }
        } else {
            TextBox {
                x0: x + start,
                y0: y - ascent,
                x1: x + start + w,
                y1: y + descent,
            }
        }
    }

    fn is_free(&self, b: &TextBox) -> bool {
        let pad = TextBox {
            x0: b.x0 - 0.3,
            y0: b.y0 - 0.3,
            x1: b.x1 + 0.3,
            y1: b.y1 + 0.3,
        };
        !self.texts.iter().any(|t| t.overlaps(&pad))
            && !self.geometry.iter().any(|&(a, c)| pad.hits_segment(a, c))
    }

    /// Places a text and remembers its box.
    #[allow(clippy::too_many_arguments)]
    fn text(
        &mut self,
        x: f64,
        y: f64,
        s: &str,
        size: f64,
        anchor: Anchor,
        vertical: bool,
        class: &str,
    ) {
        if s.trim().is_empty() {
            return;
        }
        let b = Self::text_box(x, y, s, size, anchor, vertical);
        self.texts.push(b);
        let mut t = Text::new(s.to_string())
            .set("x", fmt(x))
            .set("y", fmt(y))
            .set("font-size", size)
            .set("font-family", FONT_FAMILY)
            .set("class", class);
        match anchor {
            Anchor::Start => {}
            Anchor::Middle => t = t.set("text-anchor", "middle"),
            Anchor::End => t = t.set("text-anchor", "end"),
        }
        if vertical {
            t = t.set("transform", format!("rotate(-90 {} {})", fmt(x), fmt(y)));
        }
        self.add(t);
    }
}

fn fmt(v: f64) -> String {
    format!("{v:.3}")
}

fn line(a: (f64, f64), b: (f64, f64), width: f64) -> Line {
    Line::new()
        .set("x1", fmt(a.0))
        .set("y1", fmt(a.1))
        .set("x2", fmt(b.0))
        .set("y2", fmt(b.1))
        .set("stroke", STROKE)
        .set("stroke-width", width)
}

fn polyline(points: &[(f64, f64)], width: f64) -> Polyline {
    let pts: Vec<String> = points
        .iter()
        .map(|p| format!("{},{}", fmt(p.0), fmt(p.1)))
        .collect();
    Polyline::new()
        .set("points", pts.join(" "))
        .set("fill", "none")
        .set("stroke", STROKE)
        .set("stroke-width", width)
}

fn rect(x: f64, y: f64, w: f64, h: f64, width: f64) -> Rectangle {
    Rectangle::new()
        .set("x", fmt(x))
        .set("y", fmt(y))
        .set("width", fmt(w))
        .set("height", fmt(h))
        .set("fill", "none")
        .set("stroke", STROKE)
        .set("stroke-width", width)
}

/// "12.345", "-1.571", "0".
fn mm(v: f64) -> String {
    if v.abs() < 5e-4 {
        "0".into()
    } else {
        format!("{v:.3}")
    }
}

/// Maps part coordinates (mm, y up) to the page (mm, y down) at a scale.
#[derive(Debug, Clone, Copy)]
struct View {
    scale: f64,
    /// Page position of the part point (0, 0).
    ox: f64,
    oy: f64,
}

impl View {
    fn p(&self, p: P2) -> (f64, f64) {
        (self.ox + p[0] * self.scale, self.oy - p[1] * self.scale)
    }
}

fn outline_path(part: &Part, view: &View) -> String {
    let pt = |p: P2| {
        let (x, y) = view.p(p);
        format!("{x:.5},{y:.5}")
    };
    let mut d = String::new();
    let start = part.outline[0].ends(&part.cam_edges).0;
    let _ = write!(d, "M{}", pt(start));
    for seg in &part.outline {
        match seg {
            Segment::Line { to, .. } => {
                let _ = write!(d, " L{}", pt(*to));
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
                    let _ = write!(d, " C{} {} {}", pt(c[1]), pt(c[2]), pt(c[3]));
                }
            }
        }
    }
    d.push_str(" Z");
    d
}

/// A feature dimensioned by an ordinate from the datum: its coordinate, where its extension
/// line starts (part coordinates), and a name.
#[derive(Debug, Clone)]
struct Ordinate {
    value: f64,
    from: P2,
    tag: &'static str,
}

/// Sorts ordinates by value and merges those within half a micron, keeping a datum's.
fn merge_ordinates(mut v: Vec<Ordinate>) -> Vec<Ordinate> {
    v.sort_by(|a, b| a.value.total_cmp(&b.value));
    let mut out: Vec<Ordinate> = Vec::with_capacity(v.len());
    for o in v {
        match out.last_mut() {
            Some(last) if (last.value - o.value).abs() < 5e-4 => {
                if o.tag.starts_with('(') {
                    *last = o;
                }
            }
            _ => out.push(o),
        }
    }
    out
}

/// The cam face's surface point at part X = `x` on an edge: Newton on the pitch arc length
/// from the edge's samples (the exact evaluation, not the fit).
fn surface_at_x(design: &Design, part: &Part, edge: usize, x: f64) -> Option<P2> {
    let e = &part.cam_edges[edge];
    let r = design.spec.follower.roller_radius_mm;
    let k = e.points.windows(2).position(|w| {
        (w[0].p[0] - x) * (w[1].p[0] - x) <= 0.0 && (w[0].p[0] - w[1].p[0]).abs() > 0.0
    })?;
    let (a, b) = (&e.points[k], &e.points[k + 1]);
    let (s_lo, s_hi) = (a.s_mm, b.s_mm);
    let mut s = s_lo + (x - a.p[0]) / (b.p[0] - a.p[0]) * (s_hi - s_lo);
    for _ in 0..8 {
        let q = exact_edge_point(&design.pitch_curve, r, &part.frame, e.mirrored, s).ok()?;
        let err = q.p[0] - x;
        if err.abs() < 1e-9 || q.d[0].abs() < 1e-12 {
            return Some(q.p);
        }
        s = (s - err / q.d[0]).clamp(s_lo, s_hi);
    }
    exact_edge_point(&design.pitch_curve, r, &part.frame, e.mirrored, s)
        .ok()
        .map(|q| q.p)
}

/// The cam-face table: rows (X, Y) of the upper face at `step` in X, both ends included.
fn coordinate_rows(design: &Design, part: &Part, step: f64) -> Vec<P2> {
    let Some(edge) = part.cam_edges.iter().position(|e| !e.mirrored) else {
        return Vec::new();
    };
    let e = &part.cam_edges[edge];
    let (x0, x1) = (e.points[0].p[0], e.points[e.points.len() - 1].p[0]);
    let (lo, hi) = (x0.min(x1), x0.max(x1));
    let mut xs = vec![lo];
    let mut k = (lo / step).floor() + 1.0;
    while k * step < hi - 1e-6 {
        if k * step > lo + 1e-6 {
            xs.push(k * step);
        }
        k += 1.0;
    }
    xs.push(hi);
    xs.iter()
        .filter_map(|&x| {
            if (x - e.points[0].p[0]).abs() < 1e-9 {
                Some(e.points[0].p)
            } else if (x - e.points[e.points.len() - 1].p[0]).abs() < 1e-9 {
                Some(e.points[e.points.len() - 1].p)
            } else {
                surface_at_x(design, part, edge, x)
            }
        })
        .collect()
}

/// How many rows a table column holds in a height, after its header rows.
fn rows_in(height: f64, header_rows: usize) -> usize {
    ((height / ROW_H).floor() as usize).saturating_sub(header_rows)
}

/// The drawing of a design's part.
pub fn drawing_svg(design: &Design, part: &Part) -> String {
    layout(design, part).doc.to_string()
}

/// Every text box of a drawing, as the layout placed them (for the layout tests).
pub fn text_boxes(design: &Design, part: &Part) -> Vec<TextBox> {
    layout(design, part).texts
}

/// Lays the sheet out: its SVG and the boxes of its texts.
fn layout(design: &Design, part: &Part) -> Sheet {
    let spec = &design.spec;
    let dr = &spec.drawing;
    let (sheet_w, sheet_h) = dr.sheet.size_mm();
    let (lo, hi) = part.bounding_box_mm;
    let xmax = design.xmax_mm();
    let two = spec.follower.count == 2;

    // --- Regions of the sheet.
    let tb = (sheet_w - FRAME - TB_W, sheet_h - FRAME - TB_H);
    let notes_h = 7.0 * NOTE_H + 2.0;
    let notes_top = tb.1 - notes_h;
    let col_x = sheet_w - FRAME - COL_W;
    // Views: left of the table column, above the notes.
    let region = (FRAME + 2.0, FRAME + 2.0, col_x - 4.0, notes_top - 2.0);

    // --- Ordinates.
    let upper = &part.pitch_curves[0];
    let roller_start = upper[0];
    let roller_end = *upper.last().expect("non-empty pitch curve");
    let verts: Vec<P2> = part
        .outline
        .iter()
        .map(|s| s.ends(&part.cam_edges).0)
        .collect();
    let lowest_at = |x: f64| -> P2 {
        verts
            .iter()
            .filter(|v| (v[0] - x).abs() < 1e-9)
            .copied()
            .min_by(|a, b| a[1].total_cmp(&b[1]))
            .unwrap_or([x, lo[1]])
    };
    let leftmost_at = |y: f64| -> P2 {
        verts
            .iter()
            .filter(|v| (v[1] - y).abs() < 1e-9)
            .copied()
            .min_by(|a, b| a[0].total_cmp(&b[0]))
            .unwrap_or([lo[0], y])
    };
    let cam_start = part
        .cam_edges
        .iter()
        .find(|e| !e.mirrored)
        .map(|e| e.points[0].p)
        .unwrap_or(verts[0]);
    let cam_end = part
        .cam_edges
        .iter()
        .find(|e| !e.mirrored)
        .map(|e| e.points[e.points.len() - 1].p)
        .unwrap_or(verts[0]);
    let poly = part.outline_polygon();
    // The lowest point at x of the part, or of the roller there when it is lower: an
    // extension line going down from it stays off the part.
    let lowest_boundary = |x: f64| -> f64 {
        (0..poly.len())
            .filter_map(|i| {
                let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
                ((a[0] - x) * (b[0] - x) <= 0.0 && (a[0] - b[0]).abs() > 1e-12)
                    .then(|| a[1] + (b[1] - a[1]) * (x - a[0]) / (b[0] - a[0]))
            })
            .fold(f64::INFINITY, f64::min)
    };
    let lower_roller = |p: P2| {
        let roller = if two { [p[0], -p[1]] } else { p };
        let edge = lowest_boundary(p[0]);
        if roller[1] < edge {
            roller
        } else {
            [p[0], edge]
        }
    };
    let xs = vec![
        Ordinate {
            value: lo[0],
            from: lowest_at(lo[0]),
            tag: "LEAD-IN",
        },
        Ordinate {
            value: 0.0,
            from: lower_roller(roller_start),
            tag: "(A)",
        },
        Ordinate {
            value: cam_start[0],
            from: lowest_at(cam_start[0]),
            tag: "CAM",
        },
        Ordinate {
            value: xmax,
            from: lower_roller(roller_end),
            tag: "STROKE",
        },
        Ordinate {
            value: cam_end[0],
            from: lowest_at(cam_end[0]),
            tag: "CAM END",
        },
        Ordinate {
            value: hi[0],
            from: lowest_at(hi[0]),
            tag: "RUN-OUT",
        },
    ];
    let xs = merge_ordinates(xs);
    let mut ys = vec![
        Ordinate {
            value: lo[1],
            from: leftmost_at(lo[1]),
            tag: "",
        },
        Ordinate {
            value: hi[1],
            from: leftmost_at(hi[1]),
            tag: "",
        },
        Ordinate {
            value: roller_start[1],
            from: roller_start,
            tag: "ROLLER",
        },
        Ordinate {
            value: cam_start[1],
            from: leftmost_at(cam_start[1]),
            tag: "CAM",
        },
    ];
    if two {
        // The web: the narrowest width between the cam faces, at the lead-in's start.
        let web = verts
            .iter()
            .filter(|v| (v[0] - lo[0]).abs() < 1e-9)
            .map(|v| v[1])
            .fold(f64::NEG_INFINITY, f64::max);
        for (value, tag) in [
            (web, "WEB"),
            (-web, "WEB"),
            (0.0, "(B)"),
            (-roller_start[1], "ROLLER"),
            (-cam_start[1], "CAM"),
        ] {
            ys.push(Ordinate {
                value,
                from: if tag == "ROLLER" {
                    [roller_start[0], value]
                } else if tag == "(B)" {
                    [lo[0], 0.0]
                } else {
                    leftmost_at(value)
                },
                tag,
            });
        }
    } else {
        ys.push(Ordinate {
            value: 0.0,
            from: leftmost_at(0.0),
            tag: "(B)",
        });
    }
    let ys = merge_ordinates(ys);
    let label = |o: &Ordinate| {
        if o.tag.is_empty() {
            mm(o.value)
        } else {
            format!("{} {}", mm(o.value), o.tag)
        }
    };
    let x_label_len = xs
        .iter()
        .map(|o| text_width(&label(o), TEXT_H))
        .fold(0.0, f64::max);
    let y_label_len = ys
        .iter()
        .map(|o| text_width(&label(o), TEXT_H))
        .fold(0.0, f64::max);

    // --- Scale: the largest standard one at which both views and their dimensions fit.
    let (part_w, part_h) = (hi[0] - lo[0], hi[1] - lo[1]);
    let t = part.thickness_mm;
    let left_margin = y_label_len + 10.0;
    let bottom_margin = x_label_len + 12.0;
    let top_margin = 20.0;
    let gap = 22.0;
    let side_margin = 6.0;
    // The front view may reach down to the border where it is clear of the notes; the side
    // view needs room only for its thickness dimension below it.
    let fits = |s: f64| {
        let front_right = region.0 + left_margin + part_w * s;
        let side_right = front_right + gap + t * s + side_margin;
        let bottom = |right: f64| {
            if right <= tb.0 - 2.0 {
                sheet_h - FRAME - 2.0
            } else {
                region.3
            }
        };
        side_right <= region.2
            && region.1 + top_margin + part_h * s + bottom_margin <= bottom(front_right)
            && region.1 + top_margin + part_h * s + 14.0 <= bottom(side_right)
    };
    let scale = dr.scale.unwrap_or_else(|| {
        STANDARD_SCALES
            .iter()
            .copied()
            .find(|&s| fits(s))
            .unwrap_or(STANDARD_SCALES[STANDARD_SCALES.len() - 1])
    });
    let view = View {
        scale,
        ox: region.0 + left_margin - lo[0] * scale,
        oy: region.1 + top_margin + hi[1] * scale,
    };
    let side_x = view.p([hi[0], 0.0]).0 + gap;

    // --- The sheet.
    let defs = Definitions::new().add(
        Marker::new()
            .set("id", "arrow")
            .set("viewBox", "0 0 10 10")
            .set("refX", 10)
            .set("refY", 5)
            .set("markerWidth", 2.5)
            .set("markerHeight", 2.5)
            .set("orient", "auto-start-reverse")
            .set("markerUnits", "userSpaceOnUse")
            .add(
                Path::new()
                    .set("d", "M0,0 L10,5 L0,10 z")
                    .set("fill", STROKE),
            ),
    );
    let doc = Document::new()
        .set("width", format!("{sheet_w}mm"))
        .set("height", format!("{sheet_h}mm"))
        .set("viewBox", (0.0, 0.0, sheet_w, sheet_h))
        .add(defs)
        .add(
            Rectangle::new()
                .set("width", sheet_w)
                .set("height", sheet_h)
                .set("fill", "white"),
        );
    let mut sh = Sheet {
        doc,
        texts: Vec::new(),
        geometry: Vec::new(),
    };
    sh.add(
        rect(
            FRAME,
            FRAME,
            sheet_w - 2.0 * FRAME,
            sheet_h - 2.0 * FRAME,
            0.5,
        )
        .set("id", "frame"),
    );

    // Part geometry that texts keep clear of: the outline, the holes, the side view.
    for i in 0..poly.len() {
        sh.geometry
            .push((view.p(poly[i]), view.p(poly[(i + 1) % poly.len()])));
    }
    for h in &part.holes {
        let n = 24;
        for k in 0..n {
            let a = |k: usize| std::f64::consts::TAU * k as f64 / n as f64;
            let r = h.diameter_mm / 2.0;
            sh.geometry.push((
                view.p([h.x_mm + r * a(k).cos(), h.y_mm + r * a(k).sin()]),
                view.p([h.x_mm + r * a(k + 1).cos(), h.y_mm + r * a(k + 1).sin()]),
            ));
        }
    }
    let (side_top, side_bottom) = (view.p([0.0, hi[1]]).1, view.p([0.0, lo[1]]).1);
    let side_r = side_x + t * scale;
    for (a, b) in [
        ((side_x, side_top), (side_r, side_top)),
        ((side_r, side_top), (side_r, side_bottom)),
        ((side_r, side_bottom), (side_x, side_bottom)),
        ((side_x, side_bottom), (side_x, side_top)),
    ] {
        sh.geometry.push((a, b));
    }

    // --- Front view.
    sh.add(
        Path::new()
            .set("id", "outline")
            .set("d", outline_path(part, &view))
            .set("fill", "#e8eef5")
            .set("stroke", STROKE)
            .set("stroke-width", 0.5),
    );
    for (i, h) in part.holes.iter().enumerate() {
        let (cx, cy) = view.p([h.x_mm, h.y_mm]);
        let r = h.diameter_mm / 2.0 * scale;
        sh.add(
            Circle::new()
                .set("class", "hole")
                .set("cx", fmt(cx))
                .set("cy", fmt(cy))
                .set("r", fmt(r))
                .set("fill", "white")
                .set("stroke", STROKE)
                .set("stroke-width", 0.5),
        );
        // Centre marks.
        let c = r + 1.5;
        sh.add(line((cx - c, cy), (cx + c, cy), 0.18).set("stroke-dasharray", "4,1,1,1"));
        sh.add(line((cx, cy - c), (cx, cy + c), 0.18).set("stroke-dasharray", "4,1,1,1"));
        // The tag: inside a large hole, else the first free place around it.
        let tag = format!("H{}", i + 1);
        let w = text_width(&tag, TEXT_H);
        let mut placed = false;
        for k in 0..16 {
            let ang = std::f64::consts::FRAC_PI_4 * (k % 8) as f64 + 0.3;
            let d = r + 2.0 + 3.0 * (k / 8) as f64 + w / 2.0;
            let (x, y) = (cx + d * ang.cos(), cy - d * ang.sin() + TEXT_H * 0.35);
            let b = Sheet::text_box(x, y, &tag, TEXT_H, Anchor::Middle, false);
            if sh.is_free(&b)
                && b.x0 > region.0
                && b.x1 < region.2
                && b.y0 > region.1
                && b.y1 < region.3
            {
                sh.text(x, y, &tag, TEXT_H, Anchor::Middle, false, "hole-tag");
                placed = true;
                break;
            }
        }
        if !placed {
            let (x, y) = (cx + r + 1.0, cy - r - 1.0);
            sh.text(x, y, &tag, TEXT_H, Anchor::Start, false, "hole-tag");
        }
    }
    if two {
        let (a, b) = (view.p([lo[0] - 3.0, 0.0]), view.p([hi[0] + 3.0, 0.0]));
        sh.add(line(a, b, 0.18).set("stroke-dasharray", "8,2,1,2"));
    }
    for pitch in &part.pitch_curves {
        let pts: Vec<(f64, f64)> = pitch.iter().map(|&p| view.p(p)).collect();
        sh.add(
            polyline(&pts, 0.18)
                .set("class", "pitch")
                .set("stroke", "#1565c0")
                .set("stroke-dasharray", "2,1"),
        );
        for k in [0, pitch.len() / 2, pitch.len() - 1] {
            let (cx, cy) = view.p(pitch[k]);
            sh.add(
                Circle::new()
                    .set("class", "roller")
                    .set("cx", fmt(cx))
                    .set("cy", fmt(cy))
                    .set("r", fmt(part.roller_radius_mm * scale))
                    .set("fill", "none")
                    .set("stroke", "#888")
                    .set("stroke-width", 0.18),
            );
        }
    }
    let view_top = view.p([0.0, hi[1]]).1;
    let view_bottom = view.p([0.0, lo[1]]).1;
    let view_left = view.p([lo[0], 0.0]).0;
    sh.text(
        view.p([(lo[0] + hi[0]) / 2.0, 0.0]).0,
        region.1 + 4.0,
        &format!("FRONT VIEW  {}", scale_label(scale)),
        3.0,
        Anchor::Middle,
        false,
        "view-label",
    );

    // The stroke: a linear dimension between the roller centres, above the view.
    {
        let (a, b) = (view.p(roller_start), view.p(roller_end));
        let y = view_top - 7.0;
        sh.add(line((a.0, a.1 - 1.0), (a.0, y - 1.5), 0.18));
        sh.add(line((b.0, b.1 - 1.0), (b.0, y - 1.5), 0.18));
        sh.add(
            line((a.0, y), (b.0, y), 0.18)
                .set("marker-start", "url(#arrow)")
                .set("marker-end", "url(#arrow)"),
        );
        let text = format!("STROKE {}", mm(xmax));
        sh.text(
            (a.0 + b.0) / 2.0,
            y - 1.0,
            &text,
            TEXT_H,
            Anchor::Middle,
            false,
            "dimension",
        );
    }

    // X ordinates below the view: extension lines down from each feature, labels reading
    // upwards, spread apart where features are close.
    {
        let base = view_bottom + 3.0;
        let label_y = base + 6.0;
        let pitch = TEXT_H + 1.2;
        let mut at: Vec<f64> = xs.iter().map(|o| view.p([o.value, 0.0]).0).collect();
        for i in 1..at.len() {
            at[i] = at[i].max(at[i - 1] + pitch);
        }
        for (o, &lx) in xs.iter().zip(&at) {
            let f = view.p(o.from);
            let x = view.p([o.value, 0.0]).0;
            sh.add(polyline(
                &[
                    (x, f.1 + 1.0),
                    (x, base),
                    (lx, base + 3.0),
                    (lx, label_y - 0.5),
                ],
                0.18,
            ));
            let text = label(o);
            sh.text(
                lx + TEXT_H * 0.35,
                label_y,
                &text,
                TEXT_H,
                Anchor::End,
                true,
                "ordinate",
            );
        }
    }
    // Y ordinates left of the view.
    {
        let base = view_left - 3.0;
        let label_x = base - 6.0;
        let pitch = TEXT_H + 1.2;
        let mut at: Vec<f64> = ys.iter().map(|o| view.p([0.0, o.value]).1).collect();
        // Page y grows downwards: ys are sorted by value, so page positions decrease.
        for i in 1..at.len() {
            at[i] = at[i].min(at[i - 1] - pitch);
        }
        for (o, &ly) in ys.iter().zip(&at) {
            let f = view.p(o.from);
            let y = view.p([0.0, o.value]).1;
            sh.add(polyline(
                &[
                    (f.0 - 1.0, y),
                    (base, y),
                    (base - 3.0, ly),
                    (label_x + 0.5, ly),
                ],
                0.18,
            ));
            sh.text(
                label_x,
                ly + TEXT_H * 0.35,
                &label(o),
                TEXT_H,
                Anchor::End,
                false,
                "ordinate",
            );
        }
    }

    // --- Side view (third angle: to the right), with hidden edges and holes.
    sh.add(
        Rectangle::new()
            .set("id", "side-view")
            .set("x", fmt(side_x))
            .set("y", fmt(side_top))
            .set("width", fmt(t * scale))
            .set("height", fmt(side_bottom - side_top))
            .set("fill", "#e8eef5")
            .set("stroke", STROKE)
            .set("stroke-width", 0.5),
    );
    let mut hidden: Vec<f64> = verts
        .iter()
        .map(|v| v[1])
        .filter(|y| *y > lo[1] + 1e-6 && *y < hi[1] - 1e-6)
        .collect();
    for h in &part.holes {
        hidden.push(h.y_mm + h.diameter_mm / 2.0);
        hidden.push(h.y_mm - h.diameter_mm / 2.0);
    }
    hidden.sort_by(f64::total_cmp);
    hidden.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
    for y in hidden {
        let py = view.p([0.0, y]).1;
        sh.add(line((side_x, py), (side_r, py), 0.25).set("stroke-dasharray", "1.5,1"));
    }
    for h in &part.holes {
        let py = view.p([0.0, h.y_mm]).1;
        sh.add(
            line((side_x - 1.5, py), (side_r + 1.5, py), 0.18).set("stroke-dasharray", "4,1,1,1"),
        );
    }
    {
        let y = side_bottom + 8.0;
        sh.add(line((side_x, side_bottom + 1.0), (side_x, y + 1.5), 0.18));
        sh.add(line((side_r, side_bottom + 1.0), (side_r, y + 1.5), 0.18));
        sh.add(line((side_x - 6.0, y), (side_x, y), 0.18).set("marker-end", "url(#arrow)"));
        sh.add(line((side_r + 6.0, y), (side_r, y), 0.18).set("marker-end", "url(#arrow)"));
        sh.add(line((side_x, y), (side_r, y), 0.18));
        sh.text(
            side_r + 7.0,
            y + TEXT_H * 0.35,
            &mm(t),
            TEXT_H,
            Anchor::Start,
            false,
            "dimension",
        );
        sh.text(
            (side_x + side_r) / 2.0,
            region.1 + 4.0,
            "RIGHT VIEW",
            3.0,
            Anchor::Middle,
            false,
            "view-label",
        );
    }

    // --- Cam-face coordinate table, top of the right column.
    let profile = spec.tolerances.profile_mm;
    let header = [
        "CAM FACE COORDINATES".to_string(),
        if two {
            "UPPER FACE; LOWER: Y MIRRORED".to_string()
        } else {
            "CAM FACE".to_string()
        },
        format!("PROFILE {} (±{}) TO A, B", mm(2.0 * profile), mm(profile)),
    ];
    let hole_rows = part.holes.len();
    let holes_h = if hole_rows > 0 {
        (hole_rows as f64 + 2.0) * ROW_H + 4.0
    } else {
        0.0
    };
    let table_top = FRAME + 4.0;
    let table_bottom = notes_top - 3.0 - holes_h;
    let holes_top;
    // Rows per column: header lines, the step line and the column heading.
    let capacity = rows_in(table_bottom - table_top, header.len() + 2);
    let cam_len = (cam_end[0] - cam_start[0]).abs();
    let steps = [
        0.1, 0.2, 0.25, 0.5, 1.0, 2.0, 2.5, 5.0, 10.0, 20.0, 25.0, 50.0, 100.0, 200.0,
    ];
    let count = |s: f64| (cam_len / s).floor() as usize + 2;
    let step = match dr.coordinate_step_mm {
        Some(s) if count(s) <= 2 * capacity => s,
        _ => steps
            .iter()
            .copied()
            .find(|&s| count(s) <= 2 * capacity)
            .unwrap_or(steps[steps.len() - 1]),
    };
    let rows = coordinate_rows(design, part, step);
    let columns = if rows.len() > capacity { 2 } else { 1 };
    let per_column = rows.len().div_ceil(columns);
    {
        let x = col_x;
        let mut y = table_top;
        for (i, h) in header.iter().enumerate() {
            y += ROW_H;
            sh.text(
                x + 1.0,
                y - 0.8,
                h,
                if i == 0 { 2.8 } else { 2.2 },
                Anchor::Start,
                false,
                "table",
            );
        }
        y += ROW_H;
        sh.text(
            x + 1.0,
            y - 0.8,
            &format!("STEP {} IN X", mm(step)),
            2.2,
            Anchor::Start,
            false,
            "table",
        );
        let grid_top = y;
        let col_w = COL_W / (2 * columns) as f64;
        y += ROW_H;
        for c in 0..columns {
            for (k, name) in ["X", "Y"].iter().enumerate() {
                let cx = x + col_w * (2 * c + k) as f64;
                sh.text(
                    cx + col_w - 1.0,
                    y - 0.8,
                    name,
                    TEXT_H,
                    Anchor::End,
                    false,
                    "table",
                );
            }
        }
        let rows_top = y;
        for (i, p) in rows.iter().enumerate() {
            let c = i / per_column;
            let ry = rows_top + ROW_H * ((i % per_column) + 1) as f64;
            for (k, v) in [p[0], p[1]].iter().enumerate() {
                let cx = x + col_w * (2 * c + k) as f64;
                sh.text(
                    cx + col_w - 1.0,
                    ry - 0.8,
                    &mm(*v),
                    TEXT_H,
                    Anchor::End,
                    false,
                    "coordinate",
                );
            }
        }
        let grid_bottom = rows_top + ROW_H * per_column as f64;
        holes_top = grid_bottom + 4.0;
        sh.add(rect(x, table_top, COL_W, grid_bottom - table_top, 0.35));
        sh.add(line((x, grid_top), (x + COL_W, grid_top), 0.25));
        sh.add(line((x, rows_top), (x + COL_W, rows_top), 0.25));
        for c in 1..2 * columns {
            let cx = x + col_w * c as f64;
            sh.add(line(
                (cx, grid_top),
                (cx, grid_bottom),
                if c % 2 == 0 { 0.35 } else { 0.18 },
            ));
        }
    }

    // --- Hole table, below the coordinate table.
    if hole_rows > 0 {
        let x = col_x;
        let top = holes_top;
        let widths = [12.0, 17.0, 17.0, 16.0];
        let heads = ["HOLE", "X", "Y", "⌀"];
        let mut cx = x;
        let y = top + ROW_H;
        for (w, h) in widths.iter().zip(heads) {
            sh.text(
                cx + w - 1.0,
                y - 0.8,
                h,
                TEXT_H,
                Anchor::End,
                false,
                "table",
            );
            cx += w;
        }
        for (i, h) in part.holes.iter().enumerate() {
            let ry = top + ROW_H * (i + 2) as f64;
            let cells = [
                format!("H{}", i + 1),
                mm(h.x_mm),
                mm(h.y_mm),
                format!("{:.3} H7", h.diameter_mm),
            ];
            let mut cx = x;
            for (w, c) in widths.iter().zip(&cells) {
                sh.text(
                    cx + w - 1.0,
                    ry - 0.8,
                    c,
                    TEXT_H,
                    Anchor::End,
                    false,
                    "hole-table",
                );
                cx += w;
            }
        }
        let bottom = top + ROW_H * (hole_rows + 1) as f64;
        sh.add(rect(x, top, COL_W, bottom - top, 0.35).set("id", "hole-table"));
        sh.add(line((x, top + ROW_H), (x + COL_W, top + ROW_H), 0.25));
        let mut cx = x;
        for w in &widths[..3] {
            cx += w;
            sh.add(line((cx, top), (cx, bottom), 0.18));
        }
    }

    // --- Notes, above the title block.
    let law = &design.law.law;
    let law_line = match law.exponential() {
        Some(l) => format!(
            "F = {:.4} N exp({:.6}/mm x) {} {:.4} N, x = 0 ... {} mm",
            l.mu_n,
            l.k2_per_mm,
            if l.f0_n < 0.0 { "-" } else { "+" },
            l.f0_n.abs(),
            mm(xmax)
        ),
        None => format!("{} over x = 0 ... {} mm", law.describe(), mm(xmax)),
    };
    let source = match &spec.law {
        LawSpec::Targets(_) => "targets",
        LawSpec::Given { .. } => "given",
        LawSpec::Conditions { .. } => "conditions",
        LawSpec::Table { .. } => "table",
        LawSpec::Polynomial { .. } => "polynomial",
    };
    let notes = [
        "NOTES".to_string(),
        format!(
            "1. GENERAL TOLERANCES {} UNLESS STATED. DIMENSIONS IN MM.",
            dr.general_tolerance
        ),
        format!(
            "2. CAM FACES: PROFILE {} TO A, B PER THE COORDINATE TABLE; Ra {} µm. HOLES H7.",
            mm(2.0 * profile),
            dr.cam_finish_ra_um
        ),
        format!(
            "3. OTHER SURFACES Ra {} µm. BREAK SHARP EDGES 0.2 MAX, EXCEPT THE CAM FACES.",
            dr.finish_ra_um
        ),
        "4. DATUM A: X0 = ROLLER CENTRE AT STROKE START. B: Y0. TOP FACE Z0 (G-CODE ZERO)."
            .to_string(),
        "5. PITCH CURVES (DASHED) AND ROLLERS (THIN) ARE FOR REFERENCE.".to_string(),
        format!("6. LAW ({source}): {law_line}"),
    ];
    for (i, n) in notes.iter().enumerate() {
        sh.text(
            tb.0 + 1.0,
            notes_top + NOTE_H * (i + 1) as f64 - 0.8,
            n,
            if i == 0 { 3.0 } else { TEXT_H },
            Anchor::Start,
            false,
            "note",
        );
    }

    // --- Title block.
    let cam = &spec.part.cam_material;
    let number = dr
        .number
        .clone()
        .unwrap_or_else(|| format!("{}-001", spec.name.to_uppercase()));
    let (w, h) = dr.sheet.size_mm();
    // Each row: its height, and its cells (width, caption, value).
    type Cells<'a> = Vec<(f64, &'a str, String)>;
    let rows: [(f64, Cells<'_>); 3] = [
        (
            11.0,
            vec![
                (
                    110.0,
                    "TITLE",
                    format!("CAM PLATE {}", spec.name.to_uppercase()),
                ),
                (70.0, "DRAWING NO.", number),
            ],
        ),
        (
            10.5,
            vec![
                (62.0, "MATERIAL", cam.name.to_uppercase()),
                (28.0, "THICKNESS", format!("{} mm", mm(t))),
                (22.0, "SCALE", scale_label(scale)),
                (
                    38.0,
                    "SHEET",
                    format!("{} {:.0}x{:.0}", dr.sheet.name(), w, h),
                ),
                (30.0, "REVISION", dr.revision.clone()),
            ],
        ),
        (
            10.5,
            vec![
                (40.0, "DATE", dr.date.clone().unwrap_or_default()),
                (40.0, "DRAWN", dr.drawn_by.clone().unwrap_or_default()),
                (22.0, "UNITS", "mm".into()),
                (38.0, "PROJECTION", "THIRD ANGLE".into()),
                (
                    40.0,
                    "CAMSPRING",
                    format!("{} {}", env!("CARGO_PKG_VERSION"), &spec.run_id()[..8]),
                ),
            ],
        ),
    ];
    let mut block = Group::new().set("id", "title-block");
    block = block.add(rect(tb.0, tb.1, TB_W, TB_H, 0.5));
    sh.add(block);
    let mut y = tb.1;
    for (i, (row_h, cells)) in rows.iter().enumerate() {
        if i > 0 {
            sh.add(line((tb.0, y), (tb.0 + TB_W, y), 0.35));
        }
        let mut x = tb.0;
        for (k, (cw, caption, value)) in cells.iter().enumerate() {
            if k > 0 {
                sh.add(line((x, y), (x, y + row_h), 0.35));
            }
            sh.text(
                x + 1.0,
                y + 2.4,
                caption,
                1.8,
                Anchor::Start,
                false,
                "caption",
            );
            let size = if i == 0 { 4.0 } else { 3.0 };
            // Shrink a long value to fit its cell.
            let fit = ((cw - 2.0) / text_width(value, size)).min(1.0);
            sh.text(
                x + 1.0,
                y + row_h - 1.6,
                value,
                size * fit,
                Anchor::Start,
                false,
                "title",
            );
            x += cw;
        }
        y += row_h;
    }
    sh
}

/// Why drawing.pdf could not be made.
#[derive(Debug, thiserror::Error)]
pub enum PdfError {
    /// The SVG did not parse (a bug: the drawing is ours).
    #[error("drawing.svg does not parse for the PDF: {0}")]
    Svg(String),
    /// The conversion failed.
    #[error("drawing.pdf: {0}")]
    Convert(String),
}

/// The embedded font of the PDF.
const DEJAVU_SANS: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

/// `drawing.pdf`: the drawing's SVG as a vector PDF page of the same size, its text in the
/// embedded DejaVu Sans.
pub fn drawing_pdf(svg: &str) -> Result<Vec<u8>, PdfError> {
    let mut options = svg2pdf::usvg::Options::default();
    let db = options.fontdb_mut();
    db.load_font_data(DEJAVU_SANS.to_vec());
    db.set_sans_serif_family("DejaVu Sans");
    options.font_family = "DejaVu Sans".into();
    let tree =
        svg2pdf::usvg::Tree::from_str(svg, &options).map_err(|e| PdfError::Svg(e.to_string()))?;
    svg2pdf::to_pdf(
        &tree,
        svg2pdf::ConversionOptions::default(),
        // usvg reads the page's mm at 96 px per inch: the same dpi gives the sheet in points.
        svg2pdf::PageOptions { dpi: 96.0 },
    )
    .map_err(|e| PdfError::Convert(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_width_follows_the_font() {
        // "0" is 0.636 em in DejaVu Sans; a 10-digit number at 2.5 mm is 15.9 mm.
        assert!((text_width("0123456789", 2.5) - 15.9).abs() < 1e-9);
    }

    #[test]
    fn boxes_overlap_and_segments_hit() {
        let a = TextBox {
            x0: 0.0,
            y0: 0.0,
            x1: 2.0,
            y1: 1.0,
        };
        let b = TextBox {
            x0: 1.9,
            y0: 0.9,
            x1: 3.0,
            y1: 2.0,
        };
        assert!(a.overlaps(&b));
        assert!(!a.overlaps(&TextBox { x0: 2.1, ..b }));
        assert!(a.hits_segment((-1.0, 0.5), (3.0, 0.5)));
        assert!(!a.hits_segment((-1.0, 1.5), (3.0, 1.5)));
        assert!(a.hits_segment((1.0, 0.5), (1.2, 0.6)));
    }
}
