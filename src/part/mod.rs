//! The part: the plate outline carrying the cam surface(s), in part coordinates.
//!
//! The cam edge is the cam surface between x = 0 and Xmax, with a straight lead-in before
//! x = 0 and a straight run-out after Xmax, both tangent to the surface (so the outline has no
//! concave corner a cutter could not make). One follower: the cam edge is the top of a block
//! `web` deep under the edge's lowest point. Two followers: the edge and its mirror image about
//! the centre line y = 0, `web` apart at their narrowest. The outline runs counter-clockwise.
//!
//! Part coordinates: x along the stroke (x = 0 where the roller centre starts), y up; two
//! followers: y = 0 on the centre line; one follower: y = 0 at the cam surface at x = 0.
//!
//! Each cam edge keeps exact samples (ODE results) with their derivatives with respect to the
//! pitch arc length s. [`CamEdge::bspline`] is the C1 cubic Hermite B-spline through them,
//! refined until its deviation from the exact surface, checked at quarter points of every
//! span against fresh ODE evaluations, is within `output.fit_tolerance`.

use serde::Serialize;

use crate::cam::pitch_curve::{CamError, PitchCurve, PitchSample};
use crate::design::Design;
use crate::geom::{dist, P2};
use crate::model::Hole;

pub mod mesh;

/// Smallest wall left between a hole and the outline or another hole.
pub const MIN_LIGAMENT_MM: f64 = 1.0;

/// Why a part could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PartError {
    /// Produced by [`build`] when the roller cannot follow the pitch curve: the offset surface
    /// folds or is cut by other roller positions, so no valid solid exists.
    #[error(
        "the cam surface undercuts for x in {spans}, so no valid part exists; \
         cam.step, cam.stl, drawing.svg and cam.dxf are not written. {advice}"
    )]
    Undercut {
        /// Where.
        spans: String,
        /// The undercut check's advice.
        advice: String,
    },
    /// Produced by [`build`] for a hole that does not fit in the part.
    #[error("part.holes[{index}] at ({x_mm} mm, {y_mm} mm), diameter {diameter_mm} mm: {problem}")]
    Hole {
        /// Index in `part.holes`.
        index: usize,
        /// Centre x.
        x_mm: f64,
        /// Centre y.
        y_mm: f64,
        /// Diameter.
        diameter_mm: f64,
        /// What is wrong.
        problem: String,
    },
    /// Produced by [`build`] when an exact evaluation of the surface fails.
    #[error("cam edge: {0}")]
    Cam(#[from] CamError),
    /// Produced by [`build`] when the fit cannot reach the tolerance.
    #[error("the B-spline fit of the cam edge did not reach {tolerance_mm} mm (best {achieved_mm:e} mm)")]
    Fit {
        /// Asked.
        tolerance_mm: f64,
        /// Reached.
        achieved_mm: f64,
    },
}

/// One exact point of a cam edge.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgePoint {
    /// Pitch arc length s (the curve parameter).
    pub s_mm: f64,
    /// Surface point (part coordinates).
    pub p: P2,
    /// d(point)/ds.
    pub d: P2,
}

/// A cam edge in part coordinates, parametrised by pitch arc length.
#[derive(Debug, Clone)]
pub struct CamEdge {
    /// Exact points, increasing s, dense enough for the Hermite fit to be within tolerance.
    pub points: Vec<EdgePoint>,
    /// All exact samples of the design (chord error `output.chord_tolerance`), for meshing.
    pub points_dense: Vec<P2>,
    /// Whether this is the mirrored (lower) edge.
    pub mirrored: bool,
    /// Largest deviation of the Hermite B-spline from the exact surface, as checked.
    pub fit_deviation_mm: f64,
}

/// A cubic B-spline in the plane: clamped knot vector and control points.
#[derive(Debug, Clone, PartialEq)]
pub struct BSpline2 {
    /// Knots (length = control points + 4).
    pub knots: Vec<f64>,
    /// Control points.
    pub control_points: Vec<P2>,
}

fn hermite_controls(a: &EdgePoint, b: &EdgePoint) -> [P2; 4] {
    let h = (b.s_mm - a.s_mm) / 3.0;
    [
        a.p,
        [a.p[0] + h * a.d[0], a.p[1] + h * a.d[1]],
        [b.p[0] - h * b.d[0], b.p[1] - h * b.d[1]],
        b.p,
    ]
}

fn bezier(c: &[P2; 4], t: f64) -> P2 {
    let u = 1.0 - t;
    let (b0, b1, b2, b3) = (u * u * u, 3.0 * u * u * t, 3.0 * u * t * t, t * t * t);
    [
        b0 * c[0][0] + b1 * c[1][0] + b2 * c[2][0] + b3 * c[3][0],
        b0 * c[0][1] + b1 * c[1][1] + b2 * c[2][1] + b3 * c[3][1],
    ]
}

impl CamEdge {
    /// The C1 cubic B-spline (triple interior knots) through the exact points.
    pub fn bspline(&self) -> BSpline2 {
        let n = self.points.len() - 1;
        let mut knots = Vec::with_capacity(3 * n + 5);
        let mut control_points = Vec::with_capacity(3 * n + 1);
        knots.extend([self.points[0].s_mm; 4]);
        control_points.push(self.points[0].p);
        for (i, w) in self.points.windows(2).enumerate() {
            let c = hermite_controls(&w[0], &w[1]);
            control_points.extend([c[1], c[2], c[3]]);
            knots.extend([w[1].s_mm; 3]);
            if i + 1 == n {
                knots.push(w[1].s_mm);
            }
        }
        BSpline2 {
            knots,
            control_points,
        }
    }

    /// The fitted curve at parameter s (evaluated on its Bezier span).
    pub fn fitted_at(&self, s: f64) -> P2 {
        let i = self
            .points
            .partition_point(|q| q.s_mm <= s)
            .clamp(1, self.points.len() - 1)
            - 1;
        let (a, b) = (&self.points[i], &self.points[i + 1]);
        bezier(&hermite_controls(a, b), (s - a.s_mm) / (b.s_mm - a.s_mm))
    }

    /// First and last point.
    pub fn ends(&self) -> (P2, P2) {
        (self.points[0].p, self.points[self.points.len() - 1].p)
    }
}

/// One piece of the outline, in counter-clockwise order.
#[derive(Debug, Clone, PartialEq)]
pub enum Segment {
    /// A straight edge.
    Line {
        /// Start.
        from: P2,
        /// End.
        to: P2,
    },
    /// A cam edge, traversed along increasing s or reversed.
    Cam {
        /// Index into [`Part::cam_edges`].
        edge: usize,
        /// Traversed from its end to its start.
        reversed: bool,
    },
}

/// Maps the design frame (surface and pitch points) to part coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PartFrame {
    /// Added to design y for the upper edge: part y = design y + dy (mirrored: -(design y + dy)).
    pub dy_mm: f64,
}

impl PartFrame {
    /// A design-frame point in part coordinates, on the upper or the mirrored edge.
    pub fn map(&self, x: f64, y: f64, mirrored: bool) -> P2 {
        let y = y + self.dy_mm;
        [x, if mirrored { -y } else { y }]
    }
}

/// The part.
#[derive(Debug, Clone)]
pub struct Part {
    /// Closed counter-clockwise outline.
    pub outline: Vec<Segment>,
    /// Cam edges (one per follower).
    pub cam_edges: Vec<CamEdge>,
    /// Holes.
    pub holes: Vec<Hole>,
    /// Plate thickness.
    pub thickness_mm: f64,
    /// Design-to-part mapping.
    pub frame: PartFrame,
    /// Pitch curves (roller-centre paths) in part coordinates, one per follower.
    pub pitch_curves: Vec<Vec<P2>>,
    /// Roller radius.
    pub roller_radius_mm: f64,
    /// Area of the outline minus the holes, from Green's theorem on the exact edges.
    pub area_mm2: f64,
    /// Bounding box (min, max).
    pub bounding_box_mm: (P2, P2),
    /// Length of all cam edges.
    pub cam_edge_length_mm: f64,
}

impl Part {
    /// The outline as a closed polygon (no repeated first point) through the corners and every
    /// exact cam-edge sample (chord error `output.chord_tolerance`), counter-clockwise.
    pub fn outline_polygon(&self) -> Vec<P2> {
        outline_polygon(&self.outline, &self.cam_edges)
    }
}

impl Segment {
    /// Start and end points.
    pub fn ends(&self, part_edges: &[CamEdge]) -> (P2, P2) {
        match self {
            Segment::Line { from, to } => (*from, *to),
            Segment::Cam { edge, reversed } => {
                let (a, b) = part_edges[*edge].ends();
                if *reversed {
                    (b, a)
                } else {
                    (a, b)
                }
            }
        }
    }
}

/// Exact surface point and derivative at pitch arc length s for a sample.
fn edge_point(sample: &PitchSample, r: f64, frame: &PartFrame, mirrored: bool) -> EdgePoint {
    let (sin, cos) = sample.theta_rad.sin_cos();
    let stretch = 1.0 + r * sample.curvature_per_mm;
    let p = frame.map(sample.x_mm + r * sin, sample.y_mm - r * cos, mirrored);
    let sign = if mirrored { -1.0 } else { 1.0 };
    EdgePoint {
        s_mm: sample.s_mm,
        p,
        d: [stretch * cos, sign * stretch * sin],
    }
}

/// The exact point of a cam edge at pitch arc length `s_mm`, with d(point)/ds: evaluated by
/// integrating the pitch-curve ODE, not from the fit.
pub fn exact_edge_point(
    pitch: &PitchCurve,
    r: f64,
    frame: &PartFrame,
    mirrored: bool,
    s_mm: f64,
) -> Result<EdgePoint, CamError> {
    Ok(edge_point(&pitch.exact_at_arc(s_mm)?, r, frame, mirrored))
}

/// Keeps as few of the exact points as possible such that each Hermite span between kept
/// points passes within `tol` of every dropped point (greedy, left to right).
fn decimate(points: &[EdgePoint], tol: f64) -> Vec<EdgePoint> {
    let mut kept = vec![points[0]];
    let mut i = 0;
    while i + 1 < points.len() {
        let mut j = i + 1;
        while j + 1 < points.len() {
            let c = hermite_controls(&points[i], &points[j + 1]);
            let h = points[j + 1].s_mm - points[i].s_mm;
            let fits = points[i + 1..=j]
                .iter()
                .all(|q| dist(bezier(&c, (q.s_mm - points[i].s_mm) / h), q.p) <= tol);
            if !fits {
                break;
            }
            j += 1;
        }
        kept.push(points[j]);
        i = j;
    }
    kept
}

/// Refines the exact points until the Hermite fit is within `tol` at the quarter points of
/// every span; returns the points and the largest deviation found.
fn refine(
    pitch: &PitchCurve,
    r: f64,
    frame: &PartFrame,
    mirrored: bool,
    tol: f64,
) -> Result<(Vec<EdgePoint>, Vec<P2>, f64), PartError> {
    let all: Vec<EdgePoint> = pitch
        .samples
        .iter()
        .map(|s| edge_point(s, r, frame, mirrored))
        .collect();
    // Decimate to a twentieth of the tolerance: a Hermite span's error has one sign, so the
    // area between fit and surface grows with length x deviation; at tol/20 the solid's
    // volume stays within 1e-5 of the exact one while the file stays small.
    let mut points = decimate(&all, tol / 20.0);
    let mut worst_ok = 0.0_f64;
    for _round in 0..12 {
        let mut next = Vec::with_capacity(points.len() * 2);
        let mut refined = false;
        worst_ok = 0.0;
        for w in points.windows(2) {
            next.push(w[0]);
            let c = hermite_controls(&w[0], &w[1]);
            let mut worst = 0.0_f64;
            for t in [0.25, 0.5, 0.75] {
                let s = w[0].s_mm + t * (w[1].s_mm - w[0].s_mm);
                let exact = edge_point(&pitch.exact_at_arc(s)?, r, frame, mirrored);
                worst = worst.max(dist(bezier(&c, t), exact.p));
            }
            if worst > tol {
                let s = 0.5 * (w[0].s_mm + w[1].s_mm);
                next.push(edge_point(&pitch.exact_at_arc(s)?, r, frame, mirrored));
                refined = true;
            } else {
                worst_ok = worst_ok.max(worst);
            }
        }
        next.push(*points.last().expect("non-empty"));
        points = next;
        if !refined {
            return Ok((points, all.iter().map(|q| q.p).collect(), worst_ok));
        }
    }
    Err(PartError::Fit {
        tolerance_mm: tol,
        achieved_mm: worst_ok,
    })
}

/// Gauss-Legendre nodes and weights on [0, 1] (4 points, exact to degree 7).
const GAUSS4: [(f64, f64); 4] = [
    (0.069_431_844_202_973_71, 0.173_927_422_568_726_93),
    (0.330_009_478_207_571_87, 0.326_072_577_431_273_07),
    (0.669_990_521_792_428_1, 0.326_072_577_431_273_07),
    (0.930_568_155_797_026_3, 0.173_927_422_568_726_93),
];

/// Integral of (x dy - y dx)/2 along the exact cam edge (increasing s), by 4-point
/// Gauss-Legendre on each span with exact ODE evaluations.
fn edge_green(
    pitch: &PitchCurve,
    edge: &CamEdge,
    r: f64,
    frame: &PartFrame,
) -> Result<f64, PartError> {
    let mut sum = 0.0;
    for w in edge.points.windows(2) {
        let h = w[1].s_mm - w[0].s_mm;
        for (t, wt) in GAUSS4 {
            let q = edge_point(
                &pitch.exact_at_arc(w[0].s_mm + t * h)?,
                r,
                frame,
                edge.mirrored,
            );
            sum += wt * h * 0.5 * (q.p[0] * q.d[1] - q.p[1] * q.d[0]);
        }
    }
    Ok(sum)
}

fn green_line(a: P2, b: P2) -> f64 {
    0.5 * (a[0] * b[1] - b[0] * a[1])
}

/// The outline as a closed polygon (no repeated first point) through the corners and every
/// exact cam-edge sample, counter-clockwise.
fn outline_polygon(outline: &[Segment], edges: &[CamEdge]) -> Vec<P2> {
    let mut poly = Vec::new();
    for seg in outline {
        match seg {
            Segment::Line { from, .. } => poly.push(*from),
            Segment::Cam { edge, reversed } => {
                let pts = &edges[*edge].points_dense;
                if *reversed {
                    poly.extend(pts.iter().rev().take(pts.len() - 1));
                } else {
                    poly.extend(pts.iter().take(pts.len() - 1));
                }
            }
        }
    }
    poly
}

fn point_in_polygon(p: P2, poly: &[P2]) -> bool {
    let mut inside = false;
    let mut j = poly.len() - 1;
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[j]);
        if (a[1] > p[1]) != (b[1] > p[1])
            && p[0] < (b[0] - a[0]) * (p[1] - a[1]) / (b[1] - a[1]) + a[0]
        {
            inside = !inside;
        }
        j = i;
    }
    inside
}

fn distance_to_polygon(p: P2, poly: &[P2]) -> f64 {
    let mut best = f64::INFINITY;
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let l2 = dx * dx + dy * dy;
        let t = if l2 > 0.0 {
            (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        best = best.min(dist(p, [a[0] + t * dx, a[1] + t * dy]));
    }
    best
}

/// Builds the part of a design.
pub fn build(design: &Design) -> Result<Part, PartError> {
    let spec = &design.spec;
    let surface = &design.cam_surface;
    if !surface.is_followable() {
        let spans = surface
            .unfollowable_spans()
            .iter()
            .map(|s| format!("[{:.3}, {:.3}] mm", s.x_start_mm, s.x_end_mm))
            .collect::<Vec<_>>()
            .join(", ");
        let advice = design
            .checks
            .iter()
            .find(|c| c.name == "undercut")
            .and_then(|c| c.advice.clone())
            .unwrap_or_default();
        return Err(PartError::Undercut { spans, advice });
    }
    let pitch = &design.pitch_curve;
    let r = spec.follower.roller_radius_mm;
    let part = &spec.part;
    let first = pitch.samples[0];
    let last = *pitch.samples.last().expect("non-empty");
    let (sin0, cos0) = first.theta_rad.sin_cos();
    let (sin1, cos1) = last.theta_rad.sin_cos();
    let surface_y0 = first.y_mm - r * cos0;
    let lead_drop = part.lead_in_mm * sin0;
    let two = spec.follower.count == 2;
    let frame = PartFrame {
        dy_mm: if two {
            -surface_y0 + part.web_mm / 2.0 + lead_drop
        } else {
            -surface_y0
        },
    };
    let mut cam_edges = Vec::new();
    for mirrored in if two { vec![false, true] } else { vec![false] } {
        let (points, points_dense, dev) =
            refine(pitch, r, &frame, mirrored, spec.output.fit_tolerance_mm)?;
        cam_edges.push(CamEdge {
            points,
            points_dense,
            mirrored,
            fit_deviation_mm: dev,
        });
    }
    // Lead-in start and run-out end on the upper edge.
    let (s0, s1) = cam_edges[0].ends();
    let lead_start = [
        s0[0] - part.lead_in_mm * cos0,
        s0[1] - part.lead_in_mm * sin0,
    ];
    let run_end = [
        s1[0] + part.run_out_mm * cos1,
        s1[1] + part.run_out_mm * sin1,
    ];
    let mirror = |p: P2| [p[0], -p[1]];
    let mut outline = Vec::new();
    let push_line = |outline: &mut Vec<Segment>, from: P2, to: P2| {
        if dist(from, to) > 1e-9 {
            outline.push(Segment::Line { from, to });
        }
    };
    if two {
        push_line(&mut outline, mirror(lead_start), mirror(s0));
        outline.push(Segment::Cam {
            edge: 1,
            reversed: false,
        });
        push_line(&mut outline, mirror(s1), mirror(run_end));
        push_line(&mut outline, mirror(run_end), run_end);
    } else {
        let bottom = lead_start[1] - part.web_mm;
        push_line(&mut outline, [lead_start[0], bottom], [run_end[0], bottom]);
        push_line(&mut outline, [run_end[0], bottom], run_end);
    }
    push_line(&mut outline, run_end, s1);
    outline.push(Segment::Cam {
        edge: 0,
        reversed: true,
    });
    push_line(&mut outline, s0, lead_start);
    if two {
        push_line(&mut outline, lead_start, mirror(lead_start));
    } else {
        let bottom = lead_start[1] - part.web_mm;
        push_line(&mut outline, lead_start, [lead_start[0], bottom]);
    }

    // Holes must sit inside with a ligament to the outline and to each other.
    let poly = outline_polygon(&outline, &cam_edges);
    for (index, h) in part.holes.iter().enumerate() {
        let c = [h.x_mm, h.y_mm];
        let err = |problem: String| PartError::Hole {
            index,
            x_mm: h.x_mm,
            y_mm: h.y_mm,
            diameter_mm: h.diameter_mm,
            problem,
        };
        if !point_in_polygon(c, &poly) {
            return Err(err("its centre is outside the part".into()));
        }
        let wall = distance_to_polygon(c, &poly) - h.diameter_mm / 2.0;
        if wall < MIN_LIGAMENT_MM {
            return Err(err(format!(
                "it leaves {wall:.3} mm to the outline; at least {MIN_LIGAMENT_MM} mm is needed"
            )));
        }
        for (j, o) in part.holes.iter().enumerate().take(index) {
            let wall = dist(c, [o.x_mm, o.y_mm]) - (h.diameter_mm + o.diameter_mm) / 2.0;
            if wall < MIN_LIGAMENT_MM {
                return Err(err(format!("it leaves {wall:.3} mm to part.holes[{j}]; at least {MIN_LIGAMENT_MM} mm is needed")));
            }
        }
    }

    // Area by Green's theorem: lines exactly, cam edges by quadrature on exact points.
    let mut area = 0.0;
    for seg in &outline {
        area += match seg {
            Segment::Line { from, to } => green_line(*from, *to),
            Segment::Cam { edge, reversed } => {
                let a = edge_green(pitch, &cam_edges[*edge], r, &frame)?;
                if *reversed {
                    -a
                } else {
                    a
                }
            }
        };
    }
    area -= part
        .holes
        .iter()
        .map(|h| std::f64::consts::PI * h.diameter_mm.powi(2) / 4.0)
        .sum::<f64>();

    // The cam edges are monotone in x and y, so the outline vertices bound the part.
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for seg in &outline {
        let (a, b) = seg.ends(&cam_edges);
        for p in [a, b] {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
    }
    let pitch_curves = cam_edges
        .iter()
        .map(|e| {
            pitch
                .samples
                .iter()
                .map(|s| frame.map(s.x_mm, s.y_mm, e.mirrored))
                .collect()
        })
        .collect();
    let cam_edge_length_mm = cam_edges
        .iter()
        .map(|e| {
            e.points
                .windows(2)
                .map(|w| dist(w[0].p, w[1].p))
                .sum::<f64>()
        })
        .sum();
    Ok(Part {
        outline,
        cam_edges,
        holes: part.holes.clone(),
        thickness_mm: part.thickness_mm,
        frame,
        pitch_curves,
        roller_radius_mm: r,
        area_mm2: area,
        bounding_box_mm: (lo, hi),
        cam_edge_length_mm,
    })
}
