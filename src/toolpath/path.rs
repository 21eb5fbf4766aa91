//! Planar tool paths: lines and circular arcs, their geometry, and biarc fitting of smooth
//! curves within a tolerance.

use crate::geom::P2;
use crate::geom::{add, cross, dist, dot, left, scale, sub};

/// One move of a planar path, from the previous end point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Move {
    /// Straight line.
    Line {
        /// End point.
        to: P2,
    },
    /// Circular arc about `center`.
    Arc {
        /// End point.
        to: P2,
        /// Centre.
        center: P2,
        /// Counter-clockwise (G3) or clockwise (G2).
        ccw: bool,
    },
}

impl Move {
    /// End point.
    pub fn to(&self) -> P2 {
        match self {
            Move::Line { to } | Move::Arc { to, .. } => *to,
        }
    }
}

/// A path: a start point and moves.
#[derive(Debug, Clone, PartialEq)]
pub struct Path2 {
    /// Start.
    pub start: P2,
    /// Moves.
    pub moves: Vec<Move>,
}

/// Signed sweep angle of an arc from `from` to `to` about `center` (positive counter-clockwise).
pub fn sweep(from: P2, to: P2, center: P2, ccw: bool) -> f64 {
    let a0 = (from[1] - center[1]).atan2(from[0] - center[0]);
    let a1 = (to[1] - center[1]).atan2(to[0] - center[0]);
    let mut d = a1 - a0;
    let tau = std::f64::consts::TAU;
    if ccw {
        while d <= 0.0 {
            d += tau;
        }
    } else {
        while d >= 0.0 {
            d -= tau;
        }
    }
    d
}

/// Distance from `q` to the move starting at `from`.
pub fn distance_to_move(q: P2, from: P2, m: &Move) -> f64 {
    match *m {
        Move::Line { to } => {
            let d = sub(to, from);
            let l2 = dot(d, d);
            let t = if l2 > 0.0 {
                (dot(sub(q, from), d) / l2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            dist(q, add(from, scale(d, t)))
        }
        Move::Arc { to, center, ccw } => {
            let total = sweep(from, to, center, ccw);
            let part = sweep(from, q, center, ccw);
            if part.abs() <= total.abs() {
                (dist(q, center) - dist(from, center)).abs()
            } else {
                dist(q, from).min(dist(q, to))
            }
        }
    }
}

/// Points along a move (for plots and tests), `n` intervals.
pub fn sample_move(from: P2, m: &Move, n: usize) -> Vec<P2> {
    match *m {
        Move::Line { to } => (0..=n)
            .map(|k| add(from, scale(sub(to, from), k as f64 / n as f64)))
            .collect(),
        Move::Arc { to, center, ccw } => {
            let r = dist(from, center);
            let a0 = (from[1] - center[1]).atan2(from[0] - center[0]);
            let sw = sweep(from, to, center, ccw);
            (0..=n)
                .map(|k| {
                    let a = a0 + sw * k as f64 / n as f64;
                    [center[0] + r * a.cos(), center[1] + r * a.sin()]
                })
                .collect()
        }
    }
}

/// Arc from `p` with start tangent `t` (unit) to `q`, or a line when nearly straight.
fn arc_from_tangent(p: P2, t: P2, q: P2) -> Move {
    let w = sub(q, p);
    let w2 = dot(w, w);
    let k = 2.0 * cross(t, w) / w2; // signed curvature
    if w2 == 0.0 || (k.abs() * w2.sqrt()) < 1e-9 {
        return Move::Line { to: q };
    }
    let center = add(p, scale(left(t), 1.0 / k));
    Move::Arc {
        to: q,
        center,
        ccw: k > 0.0,
    }
}

/// The equal-tangent-length biarc from (p0, t0) to (p1, t1), unit tangents.
pub fn biarc(p0: P2, t0: P2, p1: P2, t1: P2) -> [Move; 2] {
    let v = sub(p1, p0);
    let t = add(t0, t1);
    let a = 2.0 * (dot(t0, t1) - 1.0);
    let b = -2.0 * dot(v, t);
    let c = dot(v, v);
    let d = if a.abs() < 1e-12 {
        if b.abs() < 1e-300 {
            return [
                Move::Line {
                    to: scale(add(p0, p1), 0.5),
                },
                Move::Line { to: p1 },
            ];
        }
        -c / b
    } else {
        (b + (b * b - 4.0 * a * c).max(0.0).sqrt()) / (-2.0 * a)
    };
    let j = scale(add(add(p0, scale(t0, d)), sub(p1, scale(t1, d))), 0.5);
    let first = arc_from_tangent(p0, t0, j);
    // Second arc: built backwards from p1 with tangent -t1, then reversed.
    let second = match arc_from_tangent(p1, scale(t1, -1.0), j) {
        Move::Line { .. } => Move::Line { to: p1 },
        Move::Arc { center, ccw, .. } => Move::Arc {
            to: p1,
            center,
            ccw: !ccw,
        },
    };
    [first, second]
}

/// Fits a smooth curve, given by an exact evaluator of (point, unit tangent) over [u0, u1],
/// with biarcs (or lines when `arcs` is false) within `budget`, checked at 7 interior points
/// of every piece; pieces that miss are split in two. Returns the moves and the largest
/// deviation found at the check points.
pub fn fit_curve<E>(
    eval: &dyn Fn(f64) -> Result<(P2, P2), E>,
    u0: f64,
    u1: f64,
    budget: f64,
    arcs: bool,
) -> Result<(Vec<Move>, f64), E> {
    let mut out = Vec::new();
    let mut worst = 0.0_f64;
    let mut stack = vec![(u1, eval(u1)?)];
    let (mut ua, mut a) = (u0, eval(u0)?);
    while let Some(&(ub, b)) = stack.last() {
        let candidate: Vec<Move> = if arcs {
            biarc(a.0, a.1, b.0, b.1).to_vec()
        } else {
            vec![Move::Line { to: b.0 }]
        };
        let mut dev = 0.0_f64;
        for k in 1..8 {
            let q = eval(ua + (ub - ua) * k as f64 / 8.0)?.0;
            let mut from = a.0;
            let mut best = f64::INFINITY;
            for m in &candidate {
                best = best.min(distance_to_move(q, from, m));
                from = m.to();
            }
            dev = dev.max(best);
        }
        if dev <= budget || (ub - ua) < 1e-9 {
            out.extend(candidate);
            worst = worst.max(dev);
            stack.pop();
            ua = ub;
            a = b;
        } else {
            let um = 0.5 * (ua + ub);
            stack.push((um, eval(um)?));
        }
    }
    Ok((out, worst))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::norm;

    #[test]
    fn biarc_of_a_circle_is_exact() {
        // Two points on the unit circle with their tangents: the biarc is the circle itself.
        let (a0, a1): (f64, f64) = (0.2, 1.3);
        let p = |a: f64| [a.cos(), a.sin()];
        let t = |a: f64| [-a.sin(), a.cos()];
        let arcs = biarc(p(a0), t(a0), p(a1), t(a1));
        let mut from = p(a0);
        for m in &arcs {
            match *m {
                Move::Arc { to, center, ccw } => {
                    assert!(ccw);
                    assert!(norm(center) < 1e-9, "{center:?}");
                    assert!((dist(from, center) - 1.0).abs() < 1e-9);
                    from = to;
                }
                Move::Line { .. } => panic!("expected arcs"),
            }
        }
        assert!(dist(from, p(a1)) < 1e-12);
    }

    #[test]
    fn fitted_sine_stays_within_budget_on_dense_checks() {
        let eval = |u: f64| -> Result<(P2, P2), ()> {
            let d = [1.0, u.cos()];
            Ok(([u, u.sin()], scale(d, 1.0 / norm(d))))
        };
        for arcs in [true, false] {
            let (moves, _) = fit_curve(&eval, 0.0, 3.0, 1e-4, arcs).unwrap();
            let mut from = [0.0, 0.0];
            let mut worst = 0.0_f64;
            for m in &moves {
                // Dense check against the true curve in both directions.
                for q in sample_move(from, m, 20) {
                    let u = q[0];
                    worst =
                        worst.max((q[1] - u.sin()).abs() * (1.0 / (1.0 + u.cos().powi(2)).sqrt()));
                }
                from = m.to();
            }
            assert!(worst < 1.2e-4, "arcs {arcs}: {worst:e}");
        }
    }

    #[test]
    fn sweep_and_distance_respect_direction() {
        let c = [0.0, 0.0];
        let cw = Move::Arc {
            to: [0.0, -1.0],
            center: c,
            ccw: false,
        };
        // Clockwise from (1,0) to (0,-1) is a quarter turn; (0,1) is not on it.
        assert!(
            (sweep([1.0, 0.0], [0.0, -1.0], c, false) + std::f64::consts::FRAC_PI_2).abs() < 1e-12
        );
        assert!(distance_to_move([0.0, 1.0], [1.0, 0.0], &cw) > 1.0);
        assert!(distance_to_move([0.6, -0.8], [1.0, 0.0], &cw) < 1e-12);
    }
}
