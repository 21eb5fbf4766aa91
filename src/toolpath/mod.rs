//! Tool paths for milling the part from plate stock, and the G-code that runs them.
//!
//! The tool-centre path is computed here, never left to controller compensation (GRBL has no
//! G41/G42): the part outline offset outwards by the cutter radius (plus the stock allowance
//! for roughing). Straight edges offset to straight edges, convex corners get arcs about the
//! corner, and the cam edges are offset exactly (from ODE evaluations of the surface) and
//! fitted with biarcs within the tolerance minus the output rounding. Holes are circles of
//! the hole radius minus the offset.
//!
//! [`passes`] puts the passes together: holes first (while the part is still held), then the
//! outline, each roughed in equal depth steps to the full thickness plus breakthrough with
//! the stock allowance left, then finished in one pass at full depth. Every pass enters and
//! leaves on tangential arcs. [`gcode`] writes the result for a dialect.

pub mod gcode;
pub mod path;

use serde::Serialize;

use crate::cam::pitch_curve::CamError;
use crate::design::Design;
use crate::geom::{add, cross, dist, left, norm, right, scale, sub, P2};
use crate::part::{exact_edge_point, Part, Segment};
use path::{fit_curve, Move, Path2};

/// Why no tool path can be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ToolpathError {
    /// Produced by [`passes`] when the cutter cannot reach into a concave part of the cam.
    #[error(
        "the cutter (radius {tool_radius_mm} mm) cannot make the cam surface: its smallest concave \
         radius is {concave_radius_mm:.4} mm at x = {at_x_mm:.3} mm; use an end mill of at most {max_diameter_mm:.3} mm \
         diameter (machining.tool_diameter)"
    )]
    ToolTooLarge {
        /// Tool radius.
        tool_radius_mm: f64,
        /// Smallest concave radius.
        concave_radius_mm: f64,
        /// Where.
        at_x_mm: f64,
        /// Largest diameter that fits.
        max_diameter_mm: f64,
    },
    /// Produced by [`passes`] when a hole is not larger than the cutter plus allowance.
    #[error(
        "part.holes[{index}] (diameter {diameter_mm} mm) is too small to mill with a {tool_diameter_mm} mm cutter \
         and {allowance_mm} mm allowance; drill it, or use a cutter below {max_tool_mm:.3} mm"
    )]
    HoleTooSmall {
        /// Index in part.holes.
        index: usize,
        /// Hole diameter.
        diameter_mm: f64,
        /// Tool diameter.
        tool_diameter_mm: f64,
        /// Stock allowance.
        allowance_mm: f64,
        /// Largest tool that can mill it.
        max_tool_mm: f64,
    },
    /// Produced by [`passes`] when the tolerance is finer than the dialect's number format.
    #[error(
        "machining.tolerance = {tolerance_mm} mm is finer than the {dialect} output resolution \
         ({decimals} decimals, rounding up to {rounding_mm:.2e} mm); raise the tolerance"
    )]
    Resolution {
        /// Asked tolerance.
        tolerance_mm: f64,
        /// Dialect.
        dialect: &'static str,
        /// Decimals written.
        decimals: usize,
        /// Worst rounding of a point.
        rounding_mm: f64,
    },
    /// Produced by [`passes`] when the tabs do not fit on the outline's straight edges.
    #[error(
        "{tabs} holding tabs of {tab_width_mm} mm need straight edges of at least {needed_mm:.3} mm \
         (tab width plus cutter diameter) each; the longest is {longest_mm:.3} mm. Use fewer or \
         narrower tabs (machining.tabs, machining.tab_width)"
    )]
    Tabs {
        /// Tabs asked.
        tabs: usize,
        /// Tab width.
        tab_width_mm: f64,
        /// Path length one tab needs.
        needed_mm: f64,
        /// Longest straight edge of the path.
        longest_mm: f64,
    },
    /// Produced by [`passes`] when an exact evaluation of the cam fails.
    #[error("cam edge: {0}")]
    Cam(#[from] CamError),
}

/// Unit tangent of a traversed outline segment at its start (`end` false) or end.
fn segment_tangent(part: &Part, seg: &Segment, end: bool) -> P2 {
    match seg {
        Segment::Line { from, to } => {
            let d = sub(*to, *from);
            scale(d, 1.0 / norm(d))
        }
        Segment::Cam { edge, reversed } => {
            let e = &part.cam_edges[*edge];
            let at_last = end != *reversed;
            let q = if at_last {
                e.points[e.points.len() - 1]
            } else {
                e.points[0]
            };
            let t = scale(q.d, 1.0 / norm(q.d));
            if *reversed {
                scale(t, -1.0)
            } else {
                t
            }
        }
    }
}

/// The closed tool-centre contour around the part at offset `d`, counter-clockwise, with
/// curves fitted within `budget`. Returns the path and the largest fit deviation checked.
pub fn contour(
    design: &Design,
    part: &Part,
    d: f64,
    budget: f64,
    arcs: bool,
) -> Result<(Path2, f64), ToolpathError> {
    let pitch = &design.pitch_curve;
    let r = design.spec.follower.roller_radius_mm;
    let n = part.outline.len();
    let mut moves = Vec::new();
    let mut worst = 0.0_f64;
    let first = &part.outline[0];
    let start_pt = first.ends(&part.cam_edges).0;
    let start = add(
        start_pt,
        scale(right(segment_tangent(part, first, false)), d),
    );
    for (i, seg) in part.outline.iter().enumerate() {
        match seg {
            Segment::Line { to, .. } => {
                let t = segment_tangent(part, seg, false);
                moves.push(Move::Line {
                    to: add(*to, scale(right(t), d)),
                });
            }
            Segment::Cam { edge, reversed } => {
                let e = &part.cam_edges[*edge];
                let (s0, s1) = (e.points[0].s_mm, e.points[e.points.len() - 1].s_mm);
                let sign = if *reversed { -1.0 } else { 1.0 };
                let eval = |u: f64| -> Result<(P2, P2), CamError> {
                    let s = if *reversed { s1 - u } else { s0 + u };
                    let q = exact_edge_point(pitch, r, &part.frame, e.mirrored, s.clamp(s0, s1))?;
                    let t = scale(q.d, sign / norm(q.d));
                    Ok((add(q.p, scale(right(t), d)), t))
                };
                // One piece over the whole edge, split where the fit misses: coarse tolerances
                // get long arcs, fine ones as many as they need.
                let (ms, dev) = fit_curve(&eval, 0.0, s1 - s0, budget, arcs)?;
                moves.extend(ms);
                worst = worst.max(dev);
            }
        }
        // Join to the next segment around the shared corner (convex: a left turn).
        let next = &part.outline[(i + 1) % n];
        let corner = next.ends(&part.cam_edges).0;
        let t_out = segment_tangent(part, seg, true);
        let t_in = segment_tangent(part, next, false);
        let a = add(corner, scale(right(t_out), d));
        let b = add(corner, scale(right(t_in), d));
        if dist(a, b) > 1e-9 {
            debug_assert!(
                cross(t_out, t_in) > -1e-9,
                "the outline has only convex corners"
            );
            if arcs {
                moves.push(Move::Arc {
                    to: b,
                    center: corner,
                    ccw: true,
                });
            } else {
                let (ms, dev) = fit_curve(
                    &|u: f64| -> Result<(P2, P2), CamError> {
                        let a0 = (a[1] - corner[1]).atan2(a[0] - corner[0]);
                        let sw = path::sweep(a, b, corner, true);
                        let ang = a0 + sw * u;
                        Ok((
                            [corner[0] + d * ang.cos(), corner[1] + d * ang.sin()],
                            [-ang.sin(), ang.cos()],
                        ))
                    },
                    0.0,
                    1.0,
                    budget,
                    false,
                )?;
                moves.extend(ms);
                worst = worst.max(dev);
            }
        }
    }
    // Close exactly on the start point (the last join ends there up to rounding).
    if let Some(last) = moves.last_mut() {
        match last {
            Move::Line { to } | Move::Arc { to, .. } => *to = start,
        }
    }
    Ok((Path2 { start, moves }, worst))
}

/// The same closed path run the other way.
pub fn reversed(p: &Path2) -> Path2 {
    let mut points = vec![p.start];
    points.extend(p.moves.iter().map(Move::to));
    let mut moves = Vec::with_capacity(p.moves.len());
    for (k, m) in p.moves.iter().enumerate().rev() {
        let to = points[k];
        moves.push(match *m {
            Move::Line { .. } => Move::Line { to },
            Move::Arc { center, ccw, .. } => Move::Arc {
                to,
                center,
                ccw: !ccw,
            },
        });
    }
    Path2 {
        start: *points.last().expect("non-empty"),
        moves,
    }
}

/// Rotates a closed path to start at the middle of its longest straight move. Returns the new
/// path and the unit direction at its start.
pub fn start_on_longest_line(p: &Path2) -> (Path2, P2) {
    let mut from = p.start;
    let mut best: Option<(usize, f64, P2)> = None;
    for (k, m) in p.moves.iter().enumerate() {
        if let Move::Line { to } = *m {
            let len = dist(from, to);
            if best.is_none_or(|b| len > b.1) {
                best = Some((k, len, from));
            }
        }
        from = m.to();
    }
    let Some((k, _, a)) = best else {
        // No straight move: start where it starts, with the chord direction of the first move.
        let d = sub(p.moves[0].to(), p.start);
        return (p.clone(), scale(d, 1.0 / norm(d)));
    };
    let b = p.moves[k].to();
    let mid = scale(add(a, b), 0.5);
    let mut moves = vec![Move::Line { to: b }];
    moves.extend_from_slice(&p.moves[k + 1..]);
    moves.extend_from_slice(&p.moves[..k]);
    moves.push(Move::Line { to: mid });
    let d = sub(b, a);
    (Path2 { start: mid, moves }, scale(d, 1.0 / norm(d)))
}

/// One cutting pass: a closed path entered and left on arcs, at depth `z`.
#[derive(Debug, Clone, PartialEq)]
pub struct Pass {
    /// What it cuts (for comments).
    pub label: String,
    /// Where the plunge happens.
    pub entry: P2,
    /// Lead-in, contour and lead-out moves.
    pub moves: Vec<Move>,
    /// How many of the moves are the lead-in (the rest up to `lead_out` is the contour).
    pub lead_in: usize,
    /// How many of the last moves are the lead-out.
    pub lead_out: usize,
    /// Moves that run over a holding tab, at `tab_z_mm` instead of `z_mm` (same length as `moves`).
    pub over_tab: Vec<bool>,
    /// Height of the tab tops.
    pub tab_z_mm: f64,
    /// Depth.
    pub z_mm: f64,
    /// Whether this is the finishing pass of its feature.
    pub finishing: bool,
}

/// Statistics and the passes of a program.
#[derive(Debug, Clone, Serialize)]
pub struct ToolpathSummary {
    /// Roughing depth levels.
    pub rough_levels: usize,
    /// Depth of each roughing level.
    pub depth_step_mm: f64,
    /// Passes in total.
    pub passes: usize,
    /// Largest deviation of the fitted path from the exact offset, at the check points.
    pub max_fit_deviation_mm: f64,
    /// Fit budget (tolerance minus rounding).
    pub fit_budget_mm: f64,
    /// Cutting path length (feed moves in the plane, plus plunges).
    pub cutting_length_mm: f64,
    /// Estimated cutting time at the programmed feeds.
    pub estimated_minutes: f64,
}

/// Worst rounding error of a point written with `decimals` decimals.
pub fn rounding_mm(decimals: usize) -> f64 {
    0.5 * 10f64.powi(-(decimals as i32)) * std::f64::consts::SQRT_2
}

/// Builds all passes for a design and its part.
pub fn passes(design: &Design, part: &Part) -> Result<(Vec<Pass>, ToolpathSummary), ToolpathError> {
    let m = &design.spec.machining;
    let radius = m.tool_diameter_mm / 2.0;
    if let Some((rad, at)) = design.cam_surface.min_concave_radius(&design.pitch_curve) {
        if rad < radius {
            return Err(ToolpathError::ToolTooLarge {
                tool_radius_mm: radius,
                concave_radius_mm: rad,
                at_x_mm: at,
                max_diameter_mm: 2.0 * rad,
            });
        }
    }
    let decimals = gcode::decimals(m.dialect);
    let rounding = rounding_mm(decimals);
    if m.tolerance_mm <= 2.0 * rounding {
        return Err(ToolpathError::Resolution {
            tolerance_mm: m.tolerance_mm,
            dialect: gcode::dialect_name(m.dialect),
            decimals,
            rounding_mm: rounding,
        });
    }
    let budget = m.tolerance_mm - rounding;
    let total = part.thickness_mm + m.breakthrough_mm;
    let levels = ((total / m.depth_per_pass_mm) - 1e-9).ceil().max(1.0) as usize;
    let step = total / levels as f64;
    let z_final = m.stock_top_z_mm - total;
    let mut out = Vec::new();
    let mut worst = 0.0_f64;

    // Holes first, while the part is still attached to the stock.
    for (index, h) in part.holes.iter().enumerate() {
        let rough = h.diameter_mm / 2.0 - radius - m.stock_allowance_mm;
        if rough <= 0.05 {
            return Err(ToolpathError::HoleTooSmall {
                index,
                diameter_mm: h.diameter_mm,
                tool_diameter_mm: m.tool_diameter_mm,
                allowance_mm: m.stock_allowance_mm,
                max_tool_mm: h.diameter_mm - 2.0 * m.stock_allowance_mm - 0.1,
            });
        }
        let c = [h.x_mm, h.y_mm];
        for (k, (rho, z, finishing)) in (1..=levels)
            .map(|k| (rough, m.stock_top_z_mm - step * k as f64, false))
            .chain(std::iter::once((
                h.diameter_mm / 2.0 - radius,
                z_final,
                true,
            )))
            .enumerate()
        {
            // Inside a hole, climb milling with a clockwise spindle runs counter-clockwise.
            let ccw = m.climb;
            let s = [c[0] + rho, c[1]];
            let opposite = [c[0] - rho, c[1]];
            // Lead-in and lead-out: half circles between the centre and the wall, tangent to it.
            let lead_center = scale(add(c, s), 0.5);
            let (lead, body, back) = if m.arcs {
                (
                    vec![Move::Arc {
                        to: s,
                        center: lead_center,
                        ccw,
                    }],
                    vec![
                        Move::Arc {
                            to: opposite,
                            center: c,
                            ccw,
                        },
                        Move::Arc {
                            to: s,
                            center: c,
                            ccw,
                        },
                    ],
                    vec![Move::Arc {
                        to: c,
                        center: lead_center,
                        ccw,
                    }],
                )
            } else {
                let mut body = polyline_arc(s, c, opposite, ccw, budget);
                body.extend(polyline_arc(opposite, c, s, ccw, budget));
                (
                    polyline_arc(c, lead_center, s, ccw, budget),
                    body,
                    polyline_arc(s, lead_center, c, ccw, budget),
                )
            };
            let (lead_in, lead_out) = (lead.len(), back.len());
            let moves: Vec<Move> = lead.into_iter().chain(body).chain(back).collect();
            let over_tab = vec![false; moves.len()];
            out.push(Pass {
                label: pass_label(&format!("hole {index}"), finishing, k, levels),
                entry: c,
                moves,
                lead_in,
                lead_out,
                over_tab,
                tab_z_mm: z,
                z_mm: z,
                finishing,
            });
        }
    }

    // Tabs stand `tab_height` above the part's bottom face.
    let tab_z = m.stock_top_z_mm - part.thickness_mm + m.tab_height_mm;
    // The outline: one contour per offset (all roughing levels share theirs).
    let rough_contour = contour(design, part, radius + m.stock_allowance_mm, budget, m.arcs)?;
    let finish_contour = contour(design, part, radius, budget, m.arcs)?;
    for (k, (z, finishing)) in (1..=levels)
        .map(|k| (m.stock_top_z_mm - step * k as f64, false))
        .chain(std::iter::once((z_final, true)))
        .enumerate()
    {
        let (ccw_path, dev) = if finishing {
            &finish_contour
        } else {
            &rough_contour
        };
        worst = worst.max(*dev);
        // Outside a part, climb milling with a clockwise spindle runs clockwise.
        let path = if m.climb {
            reversed(ccw_path)
        } else {
            ccw_path.clone()
        };
        let (path, t) = start_on_longest_line(&path);
        let outward = if m.climb { left(t) } else { right(t) };
        let rho = m.lead_in_radius_mm;
        let center = add(path.start, scale(outward, rho));
        let entry = sub(center, scale(t, rho));
        let exit = add(center, scale(t, rho));
        // Turning from -t about the centre towards the start: clockwise if outward is right of t.
        let ccw = cross(t, outward) > 0.0;
        let (lead, back) = if m.arcs {
            (
                vec![Move::Arc {
                    to: path.start,
                    center,
                    ccw,
                }],
                vec![Move::Arc {
                    to: exit,
                    center,
                    ccw,
                }],
            )
        } else {
            (
                polyline_arc(entry, center, path.start, ccw, budget),
                polyline_arc(path.start, center, exit, ccw, budget),
            )
        };
        let (lead_in, lead_out) = (lead.len(), back.len());
        let (contour_moves, contour_tabs) = if m.tabs > 0 && z < tab_z - 1e-9 {
            with_tabs(
                &path,
                m.tabs,
                m.tab_width_mm + m.tool_diameter_mm,
                m.tab_width_mm,
            )?
        } else {
            (path.moves.clone(), vec![false; path.moves.len()])
        };
        let over_tab: Vec<bool> = std::iter::repeat_n(false, lead_in)
            .chain(contour_tabs)
            .chain(std::iter::repeat_n(false, lead_out))
            .collect();
        let moves: Vec<Move> = lead.into_iter().chain(contour_moves).chain(back).collect();
        out.push(Pass {
            label: pass_label("outline", finishing, k, levels),
            entry,
            moves,
            lead_in,
            lead_out,
            over_tab,
            tab_z_mm: tab_z,
            z_mm: z,
            finishing,
        });
    }

    let mut length = 0.0;
    let mut plunge = 0.0;
    for p in &out {
        let mut from = p.entry;
        for mv in &p.moves {
            let pts = path::sample_move(from, mv, 16);
            length += pts.windows(2).map(|w| dist(w[0], w[1])).sum::<f64>();
            from = mv.to();
        }
        plunge += m.stock_top_z_mm + 1.0 - p.z_mm;
    }
    let summary = ToolpathSummary {
        rough_levels: levels,
        depth_step_mm: step,
        passes: out.len(),
        max_fit_deviation_mm: worst,
        fit_budget_mm: budget,
        cutting_length_mm: length + plunge,
        estimated_minutes: length / m.feed_mm_per_min + plunge / m.plunge_feed_mm_per_min,
    };
    Ok((out, summary))
}

/// Splits the longest straight moves of a closed path so that `tabs` pieces of length `lift`
/// (tab width plus cutter diameter) can run over holding tabs, evenly spaced on their lines.
/// Returns the moves and which of them are over a tab.
fn with_tabs(
    path: &Path2,
    tabs: usize,
    lift: f64,
    tab_width: f64,
) -> Result<(Vec<Move>, Vec<bool>), ToolpathError> {
    let mut lines: Vec<(usize, f64)> = Vec::new();
    let mut from = path.start;
    let mut starts = Vec::with_capacity(path.moves.len());
    for (k, mv) in path.moves.iter().enumerate() {
        starts.push(from);
        if let Move::Line { to } = *mv {
            lines.push((k, dist(from, to)));
        }
        from = mv.to();
    }
    lines.sort_by(|a, b| b.1.total_cmp(&a.1));
    let longest = lines.first().map_or(0.0, |l| l.1);
    // Give the tabs to the longest lines in turn, each line taking as many as fit.
    let mut count = vec![0usize; path.moves.len()];
    for i in 0..tabs {
        let pick = (0..lines.len())
            .map(|j| lines[(i + j) % lines.len()])
            .find(|(k, len)| (count[*k] + 1) as f64 * lift <= *len);
        match pick {
            Some((k, _)) => count[k] += 1,
            None => {
                return Err(ToolpathError::Tabs {
                    tabs,
                    tab_width_mm: tab_width,
                    needed_mm: lift,
                    longest_mm: longest,
                })
            }
        }
    }
    let mut moves = Vec::new();
    let mut over = Vec::new();
    for (k, mv) in path.moves.iter().enumerate() {
        let n = count[k];
        if n == 0 {
            moves.push(*mv);
            over.push(false);
            continue;
        }
        let (a, b) = (starts[k], mv.to());
        let len = dist(a, b);
        let dir = scale(sub(b, a), 1.0 / len);
        for j in 0..n {
            let centre = len * (j as f64 + 0.5) / n as f64;
            moves.push(Move::Line {
                to: add(a, scale(dir, centre - lift / 2.0)),
            });
            over.push(false);
            moves.push(Move::Line {
                to: add(a, scale(dir, centre + lift / 2.0)),
            });
            over.push(true);
        }
        moves.push(Move::Line { to: b });
        over.push(false);
    }
    Ok((moves, over))
}

/// "outline rough 3/11", "hole 0 finish": the pass name written into the program.
fn pass_label(feature: &str, finishing: bool, k: usize, levels: usize) -> String {
    if finishing {
        format!("{feature} finish")
    } else {
        format!("{feature} rough {}/{levels}", k + 1)
    }
}

/// An arc from `from` to `to` about `center` as lines within `budget` (chord sagitta).
fn polyline_arc(from: P2, center: P2, to: P2, ccw: bool, budget: f64) -> Vec<Move> {
    let r = dist(from, center);
    let sw = path::sweep(from, to, center, ccw);
    let max_step = 2.0 * (1.0 - (budget / r).min(1.0)).acos();
    let n = ((sw.abs() / max_step).ceil() as usize).max(1);
    let a0 = (from[1] - center[1]).atan2(from[0] - center[0]);
    (1..=n)
        .map(|k| {
            let a = a0 + sw * k as f64 / n as f64;
            Move::Line {
                to: if k == n {
                    to
                } else {
                    [center[0] + r * a.cos(), center[1] + r * a.sin()]
                },
            }
        })
        .collect()
}
