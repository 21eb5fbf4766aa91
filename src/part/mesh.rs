//! The part as a watertight, consistently wound triangle mesh (written as `cam.stl`).
//!
//! The part is a prism, so the mesh is built from the outline sampled to the chord tolerance:
//! the exact cam-edge samples thinned so that every chord stays within the budget, hole
//! circles as inscribed polygons, two caps triangulated by ear clipping (earcutr) and side
//! walls as quads. Every vertex is shared bit-for-bit by its neighbours, so the mesh is closed;
//! caps and walls are wound so that normals point out of the part.

use stl_io::{Normal, Triangle, Vertex};

use super::{Part, Segment};
use crate::geom::P2;

/// Why the mesh could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StlError {
    /// Produced by [`mesh`] when the cap cannot be triangulated.
    #[error("the part outline could not be triangulated: {0}")]
    Triangulation(String),
}

/// The outline polygon (counter-clockwise) and hole polygons (clockwise) used for the mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct Rings {
    /// Outer boundary, counter-clockwise, no repeated closing point.
    pub outer: Vec<P2>,
    /// Hole boundaries, clockwise.
    pub holes: Vec<Vec<P2>>,
}

fn chord_deviation(a: P2, b: P2, p: P2) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len = dx.hypot(dy);
    if len == 0.0 {
        return (p[0] - a[0]).hypot(p[1] - a[1]);
    }
    ((p[0] - a[0]) * dy - (p[1] - a[1]) * dx).abs() / len
}

/// Thins exact, densely sampled points (chord error `sample_tol`) to a polyline whose chords
/// stay within `tol`: every dropped point lies within `tol - sample_tol` of its chord, and the
/// true curve between samples lies within `sample_tol` of the dropped points' polyline.
pub(crate) fn thin(points: &[P2], tol: f64, sample_tol: f64) -> Vec<P2> {
    let budget = (tol - sample_tol).max(0.0);
    let mut kept = vec![points[0]];
    let mut i = 0;
    while i + 1 < points.len() {
        let mut j = i + 1;
        while j + 1 < points.len()
            && points[i + 1..=j]
                .iter()
                .all(|&p| chord_deviation(points[i], points[j + 1], p) <= budget)
        {
            j += 1;
        }
        kept.push(points[j]);
        i = j;
    }
    kept
}

/// Number of sides of an inscribed polygon whose sagitta on a circle of radius r is <= tol.
pub(crate) fn circle_sides(r: f64, tol: f64) -> usize {
    let half = (1.0 - (tol / r).min(1.0)).acos();
    ((std::f64::consts::PI / half).ceil() as usize).max(8)
}

/// Samples the part outline and holes for meshing.
pub fn rings(part: &Part, tol: f64, sample_tol: f64) -> Rings {
    let mut outer = Vec::new();
    for seg in &part.outline {
        match seg {
            Segment::Line { from, .. } => outer.push(*from),
            Segment::Cam { edge, reversed } => {
                let pts: Vec<P2> = part.cam_edges[*edge].points_dense.clone();
                let mut thinned = thin(&pts, tol, sample_tol);
                if *reversed {
                    thinned.reverse();
                }
                thinned.pop(); // the next segment starts here
                outer.extend(thinned);
            }
        }
    }
    let holes = part
        .holes
        .iter()
        .map(|h| {
            let r = h.diameter_mm / 2.0;
            let n = circle_sides(r, tol);
            (0..n)
                .map(|k| {
                    let a = -2.0 * std::f64::consts::PI * k as f64 / n as f64;
                    [h.x_mm + r * a.cos(), h.y_mm + r * a.sin()]
                })
                .collect()
        })
        .collect();
    Rings { outer, holes }
}

fn normal(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> Normal {
    let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    let n = [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ];
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
        .sqrt()
        .max(f32::MIN_POSITIVE);
    Normal::new([n[0] / len, n[1] / len, n[2] / len])
}

fn tri(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> Triangle {
    Triangle {
        normal: normal(a, b, c),
        vertices: [Vertex::new(a), Vertex::new(b), Vertex::new(c)],
    }
}

/// The mesh of the part: a prism over `rings` of height `thickness`.
pub fn mesh(rings: &Rings, thickness: f64) -> Result<Vec<Triangle>, StlError> {
    let mut flat: Vec<f64> = rings.outer.iter().flat_map(|p| [p[0], p[1]]).collect();
    let mut hole_starts = Vec::new();
    let mut all: Vec<P2> = rings.outer.clone();
    for h in &rings.holes {
        hole_starts.push(all.len());
        all.extend(h);
        flat.extend(h.iter().flat_map(|p| [p[0], p[1]]));
    }
    let idx = earcutr::earcut(&flat, &hole_starts, 2)
        .map_err(|e| StlError::Triangulation(format!("{e:?}")))?;
    if idx.is_empty() {
        return Err(StlError::Triangulation("no triangles".into()));
    }
    let z1 = thickness as f32;
    let at = |p: P2, z: f32| [p[0] as f32, p[1] as f32, z];
    let mut tris = Vec::with_capacity(idx.len() / 3 * 2 + 2 * all.len());
    for t in idx.chunks(3) {
        let (a, b, c) = (all[t[0]], all[t[1]], all[t[2]]);
        let ccw = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]) > 0.0;
        let (b, c) = if ccw { (b, c) } else { (c, b) };
        tris.push(tri(at(a, z1), at(b, z1), at(c, z1))); // top, normal +z
        tris.push(tri(at(a, 0.0), at(c, 0.0), at(b, 0.0))); // bottom, normal -z
    }
    // Walls: along a counter-clockwise outer ring (and clockwise hole rings) the material is on
    // the left, so (a0, b0, b1) faces outwards.
    for ring in std::iter::once(&rings.outer).chain(&rings.holes) {
        for i in 0..ring.len() {
            let (a, b) = (ring[i], ring[(i + 1) % ring.len()]);
            tris.push(tri(at(a, 0.0), at(b, 0.0), at(b, z1)));
            tris.push(tri(at(a, 0.0), at(b, z1), at(a, z1)));
        }
    }
    Ok(tris)
}
