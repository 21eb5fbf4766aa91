//! The cam surface is the envelope of the roller: checked by brute force against the whole
//! pitch curve, independently of the crate's windowed search.

mod common;

use camspring::cam::pitch_curve::synthesize;
use camspring::cam::surface::offset;
use camspring::model::FrictionCorrection as FC;
use common::*;

/// Distance from a point to a segment.
fn seg_dist(p: (f64, f64), a: (f64, f64), b: (f64, f64)) -> f64 {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let l2 = dx * dx + dy * dy;
    let t = if l2 > 0.0 {
        (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a.0 + t * dx - p.0).hypot(a.1 + t * dy - p.1)
}

#[test]
fn every_surface_point_touches_its_roller_and_no_other_roller_cuts_in() {
    let law = paper_law();
    let tol = 1e-4;
    for (f, r) in [
        (follower(2, 5.0, 1.5, 3.0, 0.01, FC::Loading), 3.0),
        (follower(1, 8.0, 3.0, 6.0, 0.05, FC::Midline), 6.0),
    ] {
        let pitch = synthesize(law, &f, 20.0, &fine()).unwrap();
        let surface = offset(&pitch, r, 2.0 * tol);
        assert!(surface.is_followable());
        let poly: Vec<(f64, f64)> = pitch.samples.iter().map(|s| (s.x_mm, s.y_mm)).collect();
        for (p, s) in surface.points.iter().zip(&pitch.samples) {
            // Touches its own roller, on the material side (below the roller centre).
            assert_near(
                (p.x_mm - s.x_mm).hypot(p.y_mm - s.y_mm),
                r,
                1e-12,
                "own roller distance",
            );
            assert!(p.y_mm < s.y_mm);
            // The normal is perpendicular to the tangent.
            let dot = (p.x_mm - s.x_mm) * s.theta_rad.cos() + (p.y_mm - s.y_mm) * s.theta_rad.sin();
            assert!(dot.abs() < 1e-12);
            // No roller position along the whole stroke comes closer than r (minus chord error).
            let d = poly
                .windows(2)
                .map(|w| seg_dist((p.x_mm, p.y_mm), w[0], w[1]))
                .fold(f64::INFINITY, f64::min);
            assert!(
                d > r - 2.0 * tol,
                "surface point at x = {} is {d} from the pitch curve",
                p.x_mm
            );
        }
    }
}

#[test]
fn a_roller_larger_than_the_pitch_radius_is_caught_by_both_tests() {
    let law = paper_law();
    let f = follower(2, 5.0, 0.0, 3.0, 0.0, FC::None);
    let pitch = synthesize(law, &f, 20.0, &fine()).unwrap();
    let surface = offset(&pitch, 3.0, 2e-4);
    assert!(!surface.folds.is_empty());
    assert!(!surface.interference.is_empty());
    // Brute force agrees: some surface point near the start sits inside another roller position.
    let poly: Vec<(f64, f64)> = pitch.samples.iter().map(|s| (s.x_mm, s.y_mm)).collect();
    let inside = surface.points.iter().filter(|p| {
        poly.windows(2)
            .map(|w| seg_dist((p.x_mm, p.y_mm), w[0], w[1]))
            .fold(f64::INFINITY, f64::min)
            < 3.0 - 1e-3
    });
    assert!(inside.count() > 0);
}

#[test]
fn concave_radius_is_pitch_radius_plus_roller() {
    let law = paper_law();
    let f = follower(2, 5.0, 1.5, 3.0, 0.0, FC::None);
    let pitch = synthesize(law, &f, 20.0, &fine()).unwrap();
    let surface = offset(&pitch, 3.0, 2e-4);
    for (p, s) in surface.points.iter().zip(&pitch.samples) {
        if s.curvature_per_mm > 1e-6 {
            assert_near(
                1.0 / p.curvature_per_mm,
                1.0 / s.curvature_per_mm + 3.0,
                1e-9,
                "concave radius",
            );
        }
    }
}
