//! `cam.dxf`: the 2D outline for laser, waterjet or wire EDM, in mm (DXF R2000).
//!
//! Layer `OUTLINE`: straight edges as LINE and each cam edge as one cubic SPLINE, the same
//! B-spline as in the STEP file. Layer `HOLES`: CIRCLE. Layer `PITCH` (not to be cut): the
//! roller-centre paths as LWPOLYLINE, for checking and fixturing.

use dxf::entities::{Circle, Entity, EntityType, Line, LwPolyline, Spline};
use dxf::enums::{AcadVersion, DrawingUnits, Units};
use dxf::LwPolylineVertex;
use dxf::{Drawing, Point};

use crate::part::{Part, Segment};

fn entity(specific: EntityType, layer: &str) -> Entity {
    let mut e = Entity::new(specific);
    e.common.layer = layer.to_string();
    e
}

/// The DXF text of the part outline, starting with a comment that names the run.
pub fn dxf_bytes(part: &Part, run_id: &str) -> Result<Vec<u8>, String> {
    let mut d = Drawing::new();
    d.header.version = AcadVersion::R2000;
    d.header.default_drawing_units = Units::Millimeters;
    d.header.drawing_units = DrawingUnits::Metric;
    // Fixed dates and ids, so that repeated runs give identical files.
    let epoch = chrono::DateTime::<chrono::Utc>::from_timestamp(946_684_800, 0)
        .expect("2000-01-01 is a valid time");
    d.header.creation_date = epoch.with_timezone(&chrono::Local);
    d.header.creation_date_universal = epoch;
    d.header.update_date = epoch.with_timezone(&chrono::Local);
    d.header.update_date_universal = epoch;
    d.header.fingerprint_guid = uuid::Uuid::from_u128(0x6361_6d73_7072_696e_6700_0000_0000_0001);
    d.header.version_guid = uuid::Uuid::from_u128(0x6361_6d73_7072_696e_6700_0000_0000_0002);
    for seg in &part.outline {
        match seg {
            Segment::Line { from, to } => {
                let line = Line::new(
                    Point::new(from[0], from[1], 0.0),
                    Point::new(to[0], to[1], 0.0),
                );
                d.add_entity(entity(EntityType::Line(line), "OUTLINE"));
            }
            Segment::Cam { edge, .. } => {
                let b = part.cam_edges[*edge].bspline();
                let spline = Spline {
                    degree_of_curve: 3,
                    knot_values: b.knots,
                    control_points: b
                        .control_points
                        .iter()
                        .map(|p| Point::new(p[0], p[1], 0.0))
                        .collect(),
                    // Bit 8: planar.
                    flags: 8,
                    ..Default::default()
                };
                d.add_entity(entity(EntityType::Spline(spline), "OUTLINE"));
            }
        }
    }
    for h in &part.holes {
        let circle = Circle::new(Point::new(h.x_mm, h.y_mm, 0.0), h.diameter_mm / 2.0);
        d.add_entity(entity(EntityType::Circle(circle), "HOLES"));
    }
    for pitch in &part.pitch_curves {
        let poly = LwPolyline {
            vertices: pitch
                .iter()
                .map(|p| LwPolylineVertex {
                    x: p[0],
                    y: p[1],
                    ..Default::default()
                })
                .collect(),
            ..Default::default()
        };
        d.add_entity(entity(EntityType::LwPolyline(poly), "PITCH"));
    }
    let mut out = Vec::new();
    d.save(&mut out).map_err(|e| e.to_string())?;
    // A 999 comment group names the run; readers skip comments anywhere in the file.
    let mut marked = format!("999\ncamspring run {run_id}\n").into_bytes();
    marked.extend(out);
    Ok(marked)
}
