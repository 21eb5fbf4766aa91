//! The machined cam surface: the envelope of the roller circles along the pitch curve.
//!
//! For a smooth pitch curve P(s) with unit tangent t = (cos theta, sin theta), the envelope of
//! the circles of radius r centred on P(s) is P + r*n, with n the normal on the material side
//! (the right of the direction of travel, (sin theta, -cos theta)). Its arc length is
//! (1 + r*kappa) ds, so where 1 + r*kappa <= 0 (the pitch curve bends towards the material
//! more tightly than the roller) the offset folds back: undercut. A fold is local; a roller
//! position could also cut into the surface elsewhere, so every surface point is also checked
//! to be no closer than r to the whole pitch curve. Only then is the offset the true boundary
//! of the swept roller, i.e. the surface the roller can actually follow.

use serde::Serialize;

use super::pitch_curve::PitchCurve;

/// One point of the cam surface, made from the pitch sample of the same index.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SurfacePoint {
    /// Surface x (cam coordinates).
    pub x_mm: f64,
    /// Surface y.
    pub y_mm: f64,
    /// Arc-length ratio 1 + r*kappa of the surface to the pitch curve; <= 0 means a fold.
    pub stretch: f64,
    /// Signed surface curvature kappa/(1 + r*kappa): positive where the surface is concave
    /// (material wraps around the roller), negative where convex.
    pub curvature_per_mm: f64,
}

/// An interval of the stroke (pitch-curve x) where something happens.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Span {
    /// Start of the interval.
    pub x_start_mm: f64,
    /// End of the interval.
    pub x_end_mm: f64,
}

/// The cam surface offset from a pitch curve by the roller radius.
#[derive(Debug, Clone)]
pub struct CamSurface {
    /// Surface points, one per pitch sample.
    pub points: Vec<SurfacePoint>,
    /// The roller radius used.
    pub roller_radius_mm: f64,
    /// Where the offset folds over itself (1 + r*kappa <= 0).
    pub folds: Vec<Span>,
    /// Where another roller position cuts into the surface by more than the chord tolerance.
    pub interference: Vec<Span>,
}

impl CamSurface {
    /// Whether the roller can follow the pitch curve everywhere.
    pub fn is_followable(&self) -> bool {
        self.folds.is_empty() && self.interference.is_empty()
    }

    /// The stretches of the stroke where the roller cannot follow: folds and interference, merged.
    pub fn unfollowable_spans(&self) -> Vec<Span> {
        let mut all: Vec<Span> = self
            .folds
            .iter()
            .chain(&self.interference)
            .copied()
            .collect();
        all.sort_by(|a, b| a.x_start_mm.total_cmp(&b.x_start_mm));
        let mut merged: Vec<Span> = Vec::new();
        for s in all {
            match merged.last_mut() {
                Some(last) if s.x_start_mm <= last.x_end_mm => {
                    last.x_end_mm = last.x_end_mm.max(s.x_end_mm)
                }
                _ => merged.push(s),
            }
        }
        merged
    }

    /// The smallest concave radius (what the largest cutter must fit), and where (pitch x).
    pub fn min_concave_radius(&self, pitch: &PitchCurve) -> Option<(f64, f64)> {
        self.extreme_radius(pitch, |k| k > 0.0)
    }

    /// The smallest convex radius, and where (pitch x).
    pub fn min_convex_radius(&self, pitch: &PitchCurve) -> Option<(f64, f64)> {
        self.extreme_radius(pitch, |k| k < 0.0)
    }

    fn extreme_radius(&self, pitch: &PitchCurve, keep: impl Fn(f64) -> bool) -> Option<(f64, f64)> {
        self.points
            .iter()
            .zip(&pitch.samples)
            .filter(|(p, _)| p.stretch > 0.0 && keep(p.curvature_per_mm))
            .map(|(p, s)| (1.0 / p.curvature_per_mm.abs(), s.x_mm))
            .fold(None, |m: Option<(f64, f64)>, v| match m {
                Some(m) if m.0 <= v.0 => Some(m),
                _ => Some(v),
            })
    }
}

/// Offsets `pitch` by `roller_radius_mm` towards the material and checks the envelope.
/// `slack_mm` is how far a surface point may sit inside another roller position before it
/// counts as interference (the chord error of the sampled pitch curve).
pub fn offset(pitch: &PitchCurve, roller_radius_mm: f64, slack_mm: f64) -> CamSurface {
    let r = roller_radius_mm;
    let points: Vec<SurfacePoint> = pitch
        .samples
        .iter()
        .map(|s| {
            let (sin, cos) = s.theta_rad.sin_cos();
            let stretch = 1.0 + r * s.curvature_per_mm;
            SurfacePoint {
                x_mm: s.x_mm + r * sin,
                y_mm: s.y_mm - r * cos,
                stretch,
                curvature_per_mm: s.curvature_per_mm / stretch,
            }
        })
        .collect();
    let stretch: Vec<f64> = points.iter().map(|p| p.stretch).collect();
    let clearance: Vec<f64> = if r > 0.0 {
        points
            .iter()
            .map(|p| min_distance_to_polyline(pitch, p.x_mm, p.y_mm, r) - (r - slack_mm))
            .collect()
    } else {
        vec![1.0; points.len()]
    };
    CamSurface {
        folds: spans(pitch, &stretch),
        interference: spans(pitch, &clearance),
        points,
        roller_radius_mm: r,
    }
}

/// The smallest distance from (px, py) to the pitch polyline, searching the samples whose x is
/// within `reach` of px (pitch x increases along the curve, so the window is found by bisection).
pub fn min_distance_to_polyline(pitch: &PitchCurve, px: f64, py: f64, reach: f64) -> f64 {
    let s = &pitch.samples;
    let lo = s.partition_point(|q| q.x_mm < px - reach).saturating_sub(1);
    let end = s.partition_point(|q| q.x_mm <= px + reach).min(s.len() - 1);
    let mut best = f64::INFINITY;
    for j in lo..end {
        let (ax, ay, bx, by) = (s[j].x_mm, s[j].y_mm, s[j + 1].x_mm, s[j + 1].y_mm);
        let (dx, dy) = (bx - ax, by - ay);
        let len2 = dx * dx + dy * dy;
        let t = if len2 > 0.0 {
            (((px - ax) * dx + (py - ay) * dy) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        best = best.min((ax + t * dx - px).hypot(ay + t * dy - py));
    }
    if s.len() == 1 {
        best = (s[0].x_mm - px).hypot(s[0].y_mm - py);
    }
    best
}

/// The intervals of pitch x where `value` <= 0, with the ends placed at the linearly
/// interpolated zero crossings between samples.
fn spans(pitch: &PitchCurve, value: &[f64]) -> Vec<Span> {
    let x = |i: usize| pitch.samples[i].x_mm;
    let crossing = |i: usize, j: usize| {
        let (a, b) = (value[i], value[j]);
        if a == b {
            x(i)
        } else {
            x(i) + (x(j) - x(i)) * a / (a - b)
        }
    };
    let mut out = Vec::new();
    let mut start: Option<f64> = None;
    for (i, v) in value.iter().enumerate() {
        let inside = *v <= 0.0;
        match (inside, start) {
            (true, None) => start = Some(if i == 0 { x(0) } else { crossing(i - 1, i) }),
            (false, Some(s)) => {
                out.push(Span {
                    x_start_mm: s,
                    x_end_mm: crossing(i - 1, i),
                });
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push(Span {
            x_start_mm: s,
            x_end_mm: x(value.len() - 1),
        });
    }
    out
}
