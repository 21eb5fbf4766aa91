//! `cam.step`: the part as one closed solid with true B-spline cam faces (truck-modeling,
//! written by truck-stepio).
//!
//! The planar face bounded by the outline (lines and the cam B-spline curves) and the hole
//! circles is swept along +z by the thickness; sweeping a B-spline edge gives a B-spline
//! surface, so each cam face is an exact extrusion of the fitted curve. truck-stepio's header
//! is replaced by a well-formed one with a fixed time stamp, so repeated runs give identical
//! files and OpenCASCADE resolves every header entry.

use truck_modeling::{
    builder, BSplineCurve, Curve, Edge, KnotVec, ParametricSurface3D, Point3, Solid, Vector3,
    Vertex, Wire,
};
use truck_stepio::out::{CompleteStepDisplay, StepHeaderDescriptor, StepModel};

use crate::geom::P2;
use crate::part::{Part, Segment};

/// Why the solid could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StepError {
    /// Produced by [`solid`] when truck refuses the face or the sweep.
    #[error("the part's solid could not be built: {0}")]
    Modeling(String),
}

fn p3(p: P2, z: f64) -> Point3 {
    Point3::new(p[0], p[1], z)
}

/// The time stamp written into every file: fixed, so that outputs are reproducible.
pub const STEP_TIME_STAMP: &str = "2000-01-01T00:00:00";

/// Builds the truck solid of the part.
pub fn solid(part: &Part) -> Result<Solid, StepError> {
    // One vertex per outline corner, shared by the two segments meeting there.
    let n = part.outline.len();
    let starts: Vec<P2> = part
        .outline
        .iter()
        .map(|s| s.ends(&part.cam_edges).0)
        .collect();
    let vertices: Vec<Vertex> = starts
        .iter()
        .map(|&p| builder::vertex(p3(p, 0.0)))
        .collect();
    let mut edges: Vec<Edge> = Vec::with_capacity(n);
    for (i, seg) in part.outline.iter().enumerate() {
        let (v0, v1) = (&vertices[i], &vertices[(i + 1) % n]);
        let edge = match seg {
            Segment::Line { .. } => builder::line(v0, v1),
            Segment::Cam { edge, reversed } => {
                let spline = part.cam_edges[*edge].bspline();
                let curve = BSplineCurve::new(
                    KnotVec::from(spline.knots),
                    spline.control_points.iter().map(|&p| p3(p, 0.0)).collect(),
                );
                if *reversed {
                    Edge::new(v1, v0, Curve::BSplineCurve(curve)).inverse()
                } else {
                    Edge::new(v0, v1, Curve::BSplineCurve(curve))
                }
            }
        };
        edges.push(edge);
    }
    let mut wires = vec![Wire::from(edges)];
    for h in &part.holes {
        // A hole is two half circles, run clockwise (opposite to the outline).
        let r = h.diameter_mm / 2.0;
        let c = [h.x_mm, h.y_mm];
        let a = builder::vertex(p3([c[0] + r, c[1]], 0.0));
        let b = builder::vertex(p3([c[0] - r, c[1]], 0.0));
        let lower = builder::circle_arc(&a, &b, p3([c[0], c[1] - r], 0.0));
        let upper = builder::circle_arc(&b, &a, p3([c[0], c[1] + r], 0.0));
        wires.push(Wire::from(vec![lower, upper]));
    }
    let face = builder::try_attach_plane(&wires).map_err(|e| StepError::Modeling(e.to_string()))?;
    // The face normal must point down (-z) for the +z sweep to give an outward-facing solid.
    let face = if face.oriented_surface().normal(0.0, 0.0).z > 0.0 {
        face.inverse()
    } else {
        face
    };
    Ok(builder::tsweep(
        &face,
        Vector3::new(0.0, 0.0, part.thickness_mm),
    ))
}

/// The STEP text of the part.
pub fn step_text(part: &Part, design_name: &str, run_id: &str) -> Result<String, StepError> {
    let solid = solid(part)?;
    let compressed = solid.compress();
    let body = CompleteStepDisplay::new(
        StepModel::from(&compressed),
        StepHeaderDescriptor::default(),
    )
    .to_string();
    // Replace truck-stepio's header (its author/organisation lists come out as (( '' )), an
    // unresolved reference for OpenCASCADE, and its time stamp is the clock).
    let data = body
        .find("DATA;")
        .ok_or_else(|| StepError::Modeling("no DATA section".into()))?;
    let name = design_name.replace('\'', "");
    Ok(format!(
        "ISO-10303-21;\nHEADER;\nFILE_DESCRIPTION(('camspring cam part {name}', 'camspring run {run_id}'), '2;1');\n\
         FILE_NAME('cam.step', '{STEP_TIME_STAMP}', ('camspring'), ('camspring'), \
         'camspring {} with truck-stepio 0.3', 'camspring', '');\n\
         FILE_SCHEMA(('ISO-10303-042'));\nENDSEC;\n{}",
        env!("CARGO_PKG_VERSION"),
        &body[data..]
    ))
}
