//! Tool paths for milling the part from plate stock, and the G-code that runs them.
//!
//! The tool-centre path is computed here, never left to controller compensation (GRBL has no
//! G41/G42): the part outline offset outwards by the cutter radius (plus the stock allowance
//! for roughing). Straight edges offset to straight edges, convex corners get arcs about the
//! corner, and the cam edges are offset exactly (from ODE evaluations of the surface) and
//! fitted with biarcs within the tolerance minus the output rounding. Holes are circles of
//! the hole radius minus the offset.
//!
//! [`jobs`] puts the passes together: holes first (while the part is still held), then the
//! outline, each roughed in equal depth steps to the full thickness plus breakthrough with
//! the stock allowance left, then finished in one pass at full depth. Every pass enters and
//! leaves on tangential arcs. [`gcode`] writes the result for a dialect.

pub mod gcode;
pub mod path;

use serde::Serialize;

use crate::cam::pitch_curve::CamError;
use crate::design::Design;
use crate::geom::{add, cross, dist, left, norm, right, scale, sub, P2};
use crate::model::{MachiningSpec, Tool, ToolKind};
use crate::part::{exact_edge_point, Part, Segment};
use path::{fit_curve, Move, Path2};

/// Why no tool path can be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ToolpathError {
    /// Produced by [`jobs`] when the cutter cannot reach into a concave part of the cam.
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
    /// Produced by [`jobs`] when no tool can make a hole: no drill of its diameter, and no
    /// end mill smaller than it by the allowance.
    #[error(
        "part.holes[{index}] (diameter {diameter_mm} mm) is too small to mill with the smallest end mill \
         ({tool_diameter_mm} mm) and {allowance_mm} mm allowance; add a drill of {diameter_mm} mm \
         ([[machining.tools]] with kind = \"drill\"), or an end mill below {max_tool_mm:.3} mm"
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
    /// Produced by [`jobs`] when the tolerance is finer than the dialect's number format.
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
    /// Produced by [`jobs`] when the tabs do not fit on the outline's straight edges.
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
    /// Produced by [`jobs`] when a tool's flutes are shorter than its cut is deep.
    #[error(
        "tool {number} ({tool}) would cut {depth_mm:.3} mm deep (part.thickness {thickness_mm:.3} mm + \
         machining.breakthrough {breakthrough_mm:.3} mm{}), beyond its flute length of {flute_length_mm:.3} mm{}; \
         use a longer tool or a thinner plate",
        if (depth_mm - thickness_mm - breakthrough_mm).abs() > 1e-9 { " + the drill point" } else { "" },
        if *assumed { " (assumed: 3 diameters for an end mill, 8 for a drill; give flute_length if it is longer)" } else { "" }
    )]
    FluteLength {
        /// T number.
        number: u32,
        /// "3 mm end mill".
        tool: String,
        /// Flute length checked.
        flute_length_mm: f64,
        /// Whether the flute length was assumed.
        assumed: bool,
        /// Depth of the cut below the stock top.
        depth_mm: f64,
        /// Plate thickness.
        thickness_mm: f64,
        /// Breakthrough.
        breakthrough_mm: f64,
    },
    /// Produced by [`jobs`] when the tool list has no end mill for the outline.
    #[error("machining.tools has no end mill to mill the outline")]
    NoEndMill,
    /// Produced by [`jobs`] when an exact evaluation of the cam fails.
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

/// One move of a pass in space: a planar move whose height goes linearly from the previous
/// step's to `z_mm` (a ramp on a line, a helix on an arc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Step {
    /// The move in the plane.
    pub mv: Move,
    /// Height at its end.
    pub z_mm: f64,
    /// At the plunge feed (onto or off a holding tab) instead of the cutting feed.
    pub plunge: bool,
}

/// One cutting pass of a tool: a vertical descent in air to `entry_z_mm`, a ramped or helical
/// entry, a lead-in arc, the contour at depth `z_mm`, and a lead-out arc.
#[derive(Debug, Clone, PartialEq)]
pub struct Pass {
    /// What it cuts (for comments).
    pub label: String,
    /// Where the descent happens.
    pub entry: P2,
    /// How far the descent goes at the plunge feed: the floor already cut there (or the stock
    /// top), never into material.
    pub entry_z_mm: f64,
    /// Ramp (or helix), lead-in, contour and lead-out, in order.
    pub steps: Vec<Step>,
    /// How many of the steps are the ramped entry.
    pub ramp: usize,
    /// How many steps after the ramp are the lead-in.
    pub lead_in: usize,
    /// How many of the last steps are the lead-out.
    pub lead_out: usize,
    /// Steps that run over a holding tab (same length as `steps`).
    pub over_tab: Vec<bool>,
    /// Depth of the contour.
    pub z_mm: f64,
    /// Whether this is the finishing pass of its feature.
    pub finishing: bool,
}

/// Holes drilled by one drill: a canned cycle (G81, or G83 with pecks) at each.
#[derive(Debug, Clone, PartialEq)]
pub struct Drilling {
    /// Index in part.holes and centre of each hole.
    pub holes: Vec<(usize, P2)>,
    /// Depth of the drill point: through the plate and the breakthrough with the full diameter.
    pub z_mm: f64,
    /// The retract plane (R), above the stock top.
    pub r_plane_mm: f64,
    /// Peck depth (G83) when the hole is deeper than three diameters; None: one feed (G81).
    pub peck_mm: Option<f64>,
}

/// Everything one tool does, in the order the program runs it.
#[derive(Debug, Clone, PartialEq)]
pub struct Job {
    /// The tool.
    pub tool: Tool,
    /// What it is for ("holes 0, 1", "outline").
    pub purpose: String,
    /// Drilled holes (drills only).
    pub drilling: Option<Drilling>,
    /// Milled passes (end mills only).
    pub passes: Vec<Pass>,
}

/// A tool of the program, for the header and design.json.
#[derive(Debug, Clone, Serialize)]
pub struct ToolUse {
    /// T number.
    pub number: u32,
    /// End mill or drill.
    pub kind: ToolKind,
    /// Diameter.
    pub diameter_mm: f64,
    /// Flutes, when given.
    pub flutes: Option<u32>,
    /// Flute length checked against the depth (given or assumed).
    pub flute_length_mm: f64,
    /// Whether the flute length was assumed (not given in the spec).
    pub flute_length_assumed: bool,
    /// Deepest cut of this tool below the stock top.
    pub depth_mm: f64,
    /// What it does.
    pub purpose: String,
}

/// The plate the program expects.
#[derive(Debug, Clone, Serialize)]
pub struct StockSummary {
    /// Smallest plate: the extent of every tool edge plus a 2 mm margin, by the part thickness.
    pub size_mm: [f64; 3],
    /// Its lower-left corner in program coordinates (the part's datum is X0 Y0).
    pub corner_mm: [f64; 2],
    /// Z of the stock top (Z0 by default).
    pub top_z_mm: f64,
    /// Material.
    pub material: String,
}

/// Statistics and the passes of a program.
#[derive(Debug, Clone, Serialize)]
pub struct ToolpathSummary {
    /// Roughing depth levels of the outline.
    pub rough_levels: usize,
    /// Depth of each roughing level.
    pub depth_step_mm: f64,
    /// Skin left by roughing above the part's bottom face (cut by the finishing pass).
    pub skin_mm: f64,
    /// Passes in total (milled; drilled holes count one each).
    pub passes: usize,
    /// Largest deviation of the fitted path from the exact offset, at the check points.
    pub max_fit_deviation_mm: f64,
    /// Fit budget (tolerance minus rounding).
    pub fit_budget_mm: f64,
    /// Cutting path length (feed moves, ramps and plunges included).
    pub cutting_length_mm: f64,
    /// Estimated cycle time: feed moves at their feeds, rapids at `machining.rapid`, spindle
    /// dwells; tool changes not counted.
    pub estimated_minutes: f64,
    /// The tools, in the order they are used.
    pub tools: Vec<ToolUse>,
    /// The stock.
    pub stock: StockSummary,
    /// Settings far outside milling practice (feeds, speeds, chip loads).
    pub warnings: Vec<String>,
}

/// Worst rounding error of a point written with `decimals` decimals.
pub fn rounding_mm(decimals: usize) -> f64 {
    0.5 * 10f64.powi(-(decimals as i32)) * std::f64::consts::SQRT_2
}

/// Length of a drill's 118 degree point, per unit diameter: the drill goes this much deeper
/// than the breakthrough so that the full diameter comes through.
pub const DRILL_POINT_PER_DIAMETER: f64 = 0.300_4;

/// Holes deeper than this many diameters are drilled with pecks (G83).
pub const PECK_DEPTH_DIAMETERS: f64 = 3.0;

/// How a hole is made.
enum HoleTool {
    Drill(usize),
    Mill(usize),
}

/// Builds every job of a program for a design and its part: drilled holes first, then holes
/// milled by smaller end mills, then the outline tool's holes and the outline.
pub fn jobs(design: &Design, part: &Part) -> Result<(Vec<Job>, ToolpathSummary), ToolpathError> {
    let m = &design.spec.machining;
    let tools = m.tool_list();
    let outline_index = tools
        .iter()
        .position(|t| t.kind == ToolKind::EndMill)
        .ok_or(ToolpathError::NoEndMill)?;
    let outline_tool = &tools[outline_index];
    let radius = outline_tool.diameter_mm / 2.0;
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
    let top = m.stock_top_z_mm;
    let total = part.thickness_mm + m.breakthrough_mm;
    let z_final = top - total;
    // Roughing stops `skin` above the bottom face: only the finishing passes cut through.
    let z_rough = top - part.thickness_mm + m.skin_mm;
    let rough_depth = top - z_rough;
    let levels = ((rough_depth / m.depth_per_pass_mm) - 1e-9).ceil().max(1.0) as usize;
    let step = rough_depth / levels as f64;
    let clearance = (top + 1.0).min(m.safe_z_mm);
    let tan_ramp = m.ramp_angle_deg.to_radians().tan();

    // Which tool makes each hole: a drill of its diameter, else the largest end mill that fits.
    let mut hole_tools = Vec::with_capacity(part.holes.len());
    for (index, h) in part.holes.iter().enumerate() {
        if let Some(k) = tools.iter().position(|t| {
            t.kind == ToolKind::Drill && (t.diameter_mm - h.diameter_mm).abs() <= 0.01
        }) {
            hole_tools.push(HoleTool::Drill(k));
            continue;
        }
        let fits =
            |t: &Tool| h.diameter_mm / 2.0 - t.diameter_mm / 2.0 - m.stock_allowance_mm > 0.05;
        let best = tools
            .iter()
            .enumerate()
            .filter(|(_, t)| t.kind == ToolKind::EndMill && fits(t))
            .max_by(|a, b| a.1.diameter_mm.total_cmp(&b.1.diameter_mm));
        match best {
            Some((k, _)) => hole_tools.push(HoleTool::Mill(k)),
            None => {
                let smallest = tools
                    .iter()
                    .filter(|t| t.kind == ToolKind::EndMill)
                    .map(|t| t.diameter_mm)
                    .fold(f64::INFINITY, f64::min);
                return Err(ToolpathError::HoleTooSmall {
                    index,
                    diameter_mm: h.diameter_mm,
                    tool_diameter_mm: smallest,
                    allowance_mm: m.stock_allowance_mm,
                    max_tool_mm: h.diameter_mm - 2.0 * m.stock_allowance_mm - 0.1,
                });
            }
        }
    }

    // The order of the tools: drills, then other end mills, then the outline tool (list order).
    let mut order: Vec<usize> = (0..tools.len())
        .filter(|&k| tools[k].kind == ToolKind::Drill)
        .collect();
    order.extend(
        (0..tools.len()).filter(|&k| tools[k].kind == ToolKind::EndMill && k != outline_index),
    );
    order.push(outline_index);

    let mut jobs = Vec::new();
    let mut worst = 0.0_f64;
    let mut tool_uses = Vec::new();
    for &k in &order {
        let tool = &tools[k];
        let holes: Vec<usize> = hole_tools
            .iter()
            .enumerate()
            .filter(|(_, h)| match h {
                HoleTool::Drill(j) | HoleTool::Mill(j) => *j == k,
            })
            .map(|(i, _)| i)
            .collect();
        let does_outline = k == outline_index;
        if holes.is_empty() && !does_outline {
            continue;
        }
        let depth = match tool.kind {
            ToolKind::Drill => total + DRILL_POINT_PER_DIAMETER * tool.diameter_mm,
            ToolKind::EndMill => total,
        };
        if depth > tool.usable_length_mm() {
            return Err(ToolpathError::FluteLength {
                number: tool.number,
                tool: tool.describe(),
                flute_length_mm: tool.usable_length_mm(),
                assumed: tool.flute_length_mm.is_none(),
                depth_mm: depth,
                thickness_mm: part.thickness_mm,
                breakthrough_mm: m.breakthrough_mm,
            });
        }
        let mut purpose: Vec<String> = Vec::new();
        if !holes.is_empty() {
            let list: Vec<String> = holes.iter().map(|i| i.to_string()).collect();
            purpose.push(format!(
                "{} hole{} {}",
                if tool.kind == ToolKind::Drill {
                    "drills"
                } else {
                    "mills"
                },
                if holes.len() > 1 { "s" } else { "" },
                list.join(", ")
            ));
        }
        if does_outline {
            purpose.push("mills the outline".into());
        }
        let purpose = purpose.join(", ");
        let mut job = Job {
            tool: tool.clone(),
            purpose: purpose.clone(),
            drilling: None,
            passes: Vec::new(),
        };
        match tool.kind {
            ToolKind::Drill => {
                let deep = depth > PECK_DEPTH_DIAMETERS * tool.diameter_mm;
                job.drilling = Some(Drilling {
                    holes: holes
                        .iter()
                        .map(|&i| (i, [part.holes[i].x_mm, part.holes[i].y_mm]))
                        .collect(),
                    z_mm: top - depth,
                    r_plane_mm: clearance,
                    peck_mm: deep.then(|| tool.peck_mm.unwrap_or(tool.diameter_mm)),
                });
            }
            ToolKind::EndMill => {
                for &i in &holes {
                    let h = &part.holes[i];
                    job.passes.extend(hole_passes(
                        i,
                        [h.x_mm, h.y_mm],
                        h.diameter_mm / 2.0,
                        tool.diameter_mm / 2.0,
                        m,
                        HoleLevels {
                            top,
                            z_rough,
                            z_final,
                            tan_ramp,
                        },
                        budget,
                    ));
                }
                if does_outline {
                    let (passes, dev) = outline_passes(
                        design,
                        part,
                        OutlineLevels {
                            top,
                            levels,
                            step,
                            z_final,
                            tan_ramp,
                        },
                        budget,
                    )?;
                    worst = worst.max(dev);
                    job.passes.extend(passes);
                }
            }
        }
        tool_uses.push(ToolUse {
            number: tool.number,
            kind: tool.kind,
            diameter_mm: tool.diameter_mm,
            flutes: tool.flutes,
            flute_length_mm: tool.usable_length_mm(),
            flute_length_assumed: tool.flute_length_mm.is_none(),
            depth_mm: depth,
            purpose,
        });
        jobs.push(job);
    }

    let (cutting_length_mm, estimated_minutes) = cycle(&jobs, m, clearance);
    let summary = ToolpathSummary {
        rough_levels: levels,
        depth_step_mm: step,
        skin_mm: m.skin_mm,
        passes: jobs
            .iter()
            .map(|j| j.passes.len() + j.drilling.as_ref().map_or(0, |d| d.holes.len()))
            .sum(),
        max_fit_deviation_mm: worst,
        fit_budget_mm: budget,
        cutting_length_mm,
        estimated_minutes,
        tools: tool_uses,
        stock: stock(&jobs, part, design),
        warnings: sanity_warnings(m, &tools),
    };
    Ok((jobs, summary))
}

/// The heights of a milled hole.
#[derive(Clone, Copy)]
struct HoleLevels {
    top: f64,
    z_rough: f64,
    z_final: f64,
    tan_ramp: f64,
}

/// A milled hole: a roughing helix at the allowance from the stock top down to the skin, a
/// flat circle there; then the finishing helix at the hole's radius through the skin, a flat
/// circle at full depth, and a lead-out arc to the centre.
fn hole_passes(
    index: usize,
    c: P2,
    hole_radius: f64,
    radius: f64,
    m: &MachiningSpec,
    lv: HoleLevels,
    budget: f64,
) -> Vec<Pass> {
    // Inside a hole, climb milling with a clockwise spindle runs counter-clockwise.
    let ccw = m.climb;
    let rho_r = hole_radius - radius - m.stock_allowance_mm;
    let rho_f = hole_radius - radius;
    let on = |rho: f64, angle: f64| [c[0] + rho * angle.cos(), c[1] + rho * angle.sin()];
    let start_r = on(rho_r, 0.0);
    // Full turns at the ramp angle (at most one depth step per turn), as half circles.
    let helix = |rho: f64, at: P2, from_z: f64, to_z: f64| -> Vec<Step> {
        let pitch = (std::f64::consts::TAU * rho * lv.tan_ramp).min(m.depth_per_pass_mm);
        let turns = (((from_z - to_z) / pitch) - 1e-9).ceil().max(1.0) as usize;
        let opposite = [2.0 * c[0] - at[0], 2.0 * c[1] - at[1]];
        let mut steps = Vec::new();
        for h in 1..=2 * turns {
            let z = from_z - (from_z - to_z) * h as f64 / (2 * turns) as f64;
            let to = if h % 2 == 1 { opposite } else { at };
            let from = steps.last().map_or(at, |s: &Step| s.mv.to());
            steps.extend(arc_steps(c, to, ccw, z, m.arcs, budget, from));
        }
        steps
    };
    let circle = |at: P2, z: f64| -> Vec<Step> {
        let opposite = [2.0 * c[0] - at[0], 2.0 * c[1] - at[1]];
        let mut s = arc_steps(c, opposite, ccw, z, m.arcs, budget, at);
        s.extend(arc_steps(c, at, ccw, z, m.arcs, budget, opposite));
        s
    };
    let flat = |steps: &[Step]| vec![false; steps.len()];
    // Roughing.
    let ramp = helix(rho_r, start_r, lv.top, lv.z_rough);
    let body = circle(start_r, lv.z_rough);
    let mut rough_steps: Vec<Step> = ramp.iter().chain(&body).copied().collect();
    spread_heights(&mut rough_steps, start_r, lv.top);
    let rough = Pass {
        label: format!("hole {index} rough"),
        entry: start_r,
        entry_z_mm: lv.top,
        over_tab: flat(&rough_steps),
        ramp: ramp.len(),
        lead_in: 0,
        lead_out: 0,
        steps: rough_steps,
        z_mm: lv.z_rough,
        finishing: false,
    };
    // Finishing: a half circle from the roughing radius out to the hole's, tangent to both.
    let start_f = on(rho_f, std::f64::consts::PI);
    let e = [c[0] + (rho_r - rho_f) / 2.0, c[1]];
    let lead = arc_steps(e, start_f, ccw, lv.z_rough, m.arcs, budget, start_r);
    let ramp = helix(rho_f, start_f, lv.z_rough, lv.z_final);
    let body = circle(start_f, lv.z_final);
    let back = arc_steps(
        scale(add(c, start_f), 0.5),
        c,
        ccw,
        lv.z_final,
        m.arcs,
        budget,
        start_f,
    );
    let (n_lead, n_ramp, n_back) = (lead.len(), ramp.len(), back.len());
    // The order in the program: lead to the finishing radius, helix down, circle, lead out.
    let mut steps: Vec<Step> = lead
        .into_iter()
        .chain(ramp)
        .chain(body)
        .chain(back)
        .collect();
    spread_heights(&mut steps, start_r, lv.z_rough);
    let finish = Pass {
        label: format!("hole {index} finish"),
        entry: start_r,
        entry_z_mm: lv.z_rough,
        over_tab: flat(&steps),
        ramp: n_lead + n_ramp,
        lead_in: 0,
        lead_out: n_back,
        steps,
        z_mm: lv.z_final,
        finishing: true,
    };
    vec![rough, finish]
}

/// An arc from `from` to `to` about `center` at height `z` (a helix when the previous height
/// differs): one arc step, or lines within `budget` when arcs are off.
fn arc_steps(
    center: P2,
    to: P2,
    ccw: bool,
    z: f64,
    arcs: bool,
    budget: f64,
    from: P2,
) -> Vec<Step> {
    if arcs {
        return vec![Step {
            mv: Move::Arc { to, center, ccw },
            z_mm: z,
            plunge: false,
        }];
    }
    let lines = polyline_arc(from, center, to, ccw, budget);
    let n = lines.len();
    lines
        .into_iter()
        .enumerate()
        .map(|(k, mv)| Step {
            mv,
            // Heights are filled in by the caller's interpolation: lines of a helix descend
            // evenly; see `spread_heights`.
            z_mm: if k + 1 == n { z } else { f64::NAN },
            plunge: false,
        })
        .collect()
}

/// Fills the heights left open by [`arc_steps`] (lines of a helix) by interpolating along the
/// path length between the known heights.
fn spread_heights(steps: &mut [Step], from: P2, from_z: f64) {
    let mut k = 0;
    let (mut at, mut z0) = (from, from_z);
    while k < steps.len() {
        let mut j = k;
        while steps[j].z_mm.is_nan() {
            j += 1;
        }
        let mut lengths = Vec::with_capacity(j - k + 1);
        let mut p = at;
        for s in &steps[k..=j] {
            lengths.push(dist(p, s.mv.to()));
            p = s.mv.to();
        }
        let total: f64 = lengths.iter().sum();
        let z1 = steps[j].z_mm;
        let mut run = 0.0;
        for (s, l) in steps[k..j].iter_mut().zip(&lengths) {
            run += l;
            s.z_mm = z0 + (z1 - z0) * if total > 0.0 { run / total } else { 1.0 };
        }
        at = steps[j].mv.to();
        z0 = z1;
        k = j + 1;
    }
}

/// The heights of the outline's passes.
#[derive(Clone, Copy)]
struct OutlineLevels {
    top: f64,
    levels: usize,
    step: f64,
    z_final: f64,
    tan_ramp: f64,
}

/// The outline: roughing levels at the allowance down to the skin, then the finishing pass at
/// full depth. Each pass descends in air to the floor above, zig-zags down a ramp on a line
/// parallel to the longest straight edge, and enters and leaves the contour on arcs.
fn outline_passes(
    design: &Design,
    part: &Part,
    lv: OutlineLevels,
    budget: f64,
) -> Result<(Vec<Pass>, f64), ToolpathError> {
    let m = &design.spec.machining;
    let radius = m.tool_diameter_mm / 2.0;
    // Tabs stand `tab_height` above the part's bottom face.
    let tab_z = lv.top - part.thickness_mm + m.tab_height_mm;
    let rough_contour = contour(design, part, radius + m.stock_allowance_mm, budget, m.arcs)?;
    let finish_contour = contour(design, part, radius, budget, m.arcs)?;
    let worst = rough_contour.1.max(finish_contour.1);
    // The ramp runs along the longest straight edge, behind the lead-in; its length makes one
    // zig-zag per roughing step at the ramp angle, within half the edge.
    let (longest, _) = start_on_longest_line(&rough_contour.0);
    let half_edge = dist(longest.start, longest.moves[0].to());
    let needed = lv.step / (2.0 * lv.tan_ramp);
    let ramp_len = needed.min((half_edge - m.lead_in_radius_mm).max(radius));
    let mut out = Vec::new();
    let mut floor = lv.top;
    for k in 0..=lv.levels {
        let finishing = k == lv.levels;
        let z = if finishing {
            lv.z_final
        } else {
            lv.top - lv.step * (k + 1) as f64
        };
        let (ccw_path, allowance) = if finishing {
            (&finish_contour.0, 0.0)
        } else {
            (&rough_contour.0, m.stock_allowance_mm)
        };
        // Outside a part, climb milling with a clockwise spindle runs clockwise.
        let path = if m.climb {
            reversed(ccw_path)
        } else {
            ccw_path.clone()
        };
        let (path, t) = start_on_longest_line(&path);
        let outward = if m.climb { left(t) } else { right(t) };
        // The finishing lead-in is wider by the allowance, so that it starts on the roughing
        // passes' ramp line, which is cleared down to the last roughing level.
        let rho = m.lead_in_radius_mm + (m.stock_allowance_mm - allowance);
        let center = add(path.start, scale(outward, rho));
        let entry = sub(center, scale(t, rho));
        let exit = add(center, scale(t, rho));
        let ccw = cross(t, outward) > 0.0;
        let this_ramp = if finishing {
            (ramp_len - m.stock_allowance_mm).max(0.5 * ramp_len)
        } else {
            ramp_len
        };
        let back_pt = sub(entry, scale(t, this_ramp));
        // The finishing entry lies the allowance back along the roughing ramp, which is that
        // much (at most the ramp angle) above the last roughing floor there.
        let start_z = if finishing {
            floor + m.stock_allowance_mm * lv.tan_ramp
        } else {
            floor
        };
        let zigzags = (((start_z - z) / (2.0 * this_ramp * lv.tan_ramp)) - 1e-9)
            .ceil()
            .max(1.0) as usize;
        let mut steps = Vec::new();
        for j in 1..=2 * zigzags {
            let zj = start_z - (start_z - z) * j as f64 / (2 * zigzags) as f64;
            steps.push(Step {
                mv: Move::Line {
                    to: if j % 2 == 1 { back_pt } else { entry },
                },
                z_mm: zj,
                plunge: false,
            });
        }
        let ramp = steps.len();
        let lead = arc_steps(center, path.start, ccw, z, m.arcs, budget, entry);
        let lead_in = lead.len();
        steps.extend(lead);
        let mut over_tab = vec![false; steps.len()];
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
        let mut from = path.start;
        let mut was_over = false;
        for (mv, over) in contour_moves.into_iter().zip(contour_tabs) {
            let zk = if over { tab_z } else { z };
            if over && !was_over {
                // Onto a holding tab: straight up at the plunge feed.
                steps.push(Step {
                    mv: Move::Line { to: from },
                    z_mm: zk,
                    plunge: true,
                });
                over_tab.push(over);
            } else if !over && was_over {
                // Off it: zig-zag down along the next straight move at the ramp angle, then
                // back to the tab's end at depth, so that the bridge stays the tab's width.
                let to = mv.to();
                let len = dist(from, to);
                let drop = tab_z - z;
                let ramp_len = len.min(drop / lv.tan_ramp).max(1e-9);
                let far = add(from, scale(sub(to, from), ramp_len / len.max(1e-12)));
                let legs = ((drop / (ramp_len * lv.tan_ramp)) - 1e-9).ceil().max(1.0) as usize;
                for j in 1..=legs {
                    steps.push(Step {
                        mv: Move::Line {
                            to: if j % 2 == 1 { far } else { from },
                        },
                        z_mm: tab_z - drop * j as f64 / legs as f64,
                        plunge: false,
                    });
                    over_tab.push(false);
                }
                if legs % 2 == 1 {
                    steps.push(Step {
                        mv: Move::Line { to: from },
                        z_mm: z,
                        plunge: false,
                    });
                    over_tab.push(false);
                }
            }
            steps.push(Step {
                mv,
                z_mm: zk,
                plunge: false,
            });
            over_tab.push(over);
            from = mv.to();
            was_over = over;
        }
        let back = arc_steps(center, exit, ccw, z, m.arcs, budget, path.start);
        let lead_out = back.len();
        over_tab.extend(std::iter::repeat_n(false, lead_out));
        steps.extend(back);
        spread_heights(&mut steps, entry, start_z);
        out.push(Pass {
            label: pass_label("outline", finishing, k, lv.levels),
            entry,
            entry_z_mm: start_z,
            steps,
            ramp,
            lead_in,
            lead_out,
            over_tab,
            z_mm: z,
            finishing,
        });
        if !finishing {
            floor = z;
        }
    }
    Ok((out, worst))
}

/// Cutting length and estimated minutes of the jobs: feed moves at their feeds, rapids at the
/// rapid rate between passes (up to the safe height, across, down to the clearance), drilling
/// cycles, and a spindle dwell per tool.
fn cycle(jobs: &[Job], m: &MachiningSpec, clearance: f64) -> (f64, f64) {
    let mut cut = 0.0;
    let mut minutes = 0.0;
    let mut rapid = 0.0;
    let mut at: Option<(P2, f64)> = None;
    let go = |to: P2, at: &mut Option<(P2, f64)>, rapid: &mut f64| {
        if let Some((p, z)) = *at {
            *rapid += (m.safe_z_mm - z).max(0.0) + dist(p, to) + (m.safe_z_mm - clearance);
        }
        *at = Some((to, clearance));
    };
    for job in jobs {
        let t = &job.tool;
        minutes += m.spindle_dwell_s / 60.0;
        if let Some(d) = &job.drilling {
            for &(_, c) in &d.holes {
                go(c, &mut at, &mut rapid);
                let depth = d.r_plane_mm - d.z_mm;
                let pecks = d.peck_mm.map_or(1.0, |q| (depth / q).ceil());
                // The drill feeds the depth once; each peck's retract and return are rapids
                // of about half the depth on average each.
                cut += depth;
                minutes += depth / t.plunge_feed_mm_per_min;
                rapid += pecks * depth;
                at = Some((c, d.r_plane_mm));
            }
        }
        for p in &job.passes {
            go(p.entry, &mut at, &mut rapid);
            let descent = clearance - p.entry_z_mm;
            cut += descent;
            minutes += descent / t.plunge_feed_mm_per_min;
            let (mut from, mut z) = (p.entry, p.entry_z_mm);
            for s in &p.steps {
                let pts = path::sample_move(from, &s.mv, 16);
                let planar: f64 = pts.windows(2).map(|w| dist(w[0], w[1])).sum();
                let len = planar.hypot(s.z_mm - z);
                cut += len;
                minutes += len
                    / if s.plunge {
                        t.plunge_feed_mm_per_min
                    } else {
                        t.feed_mm_per_min
                    };
                from = s.mv.to();
                z = s.z_mm;
            }
            at = Some((from, z));
        }
    }
    (cut, minutes + rapid / m.rapid_mm_per_min)
}

/// The smallest plate that holds every cut: the extent of the tool edges plus 2 mm.
fn stock(jobs: &[Job], part: &Part, design: &Design) -> StockSummary {
    let (mut lo, mut hi) = part.bounding_box_mm;
    for job in jobs {
        let r = job.tool.diameter_mm / 2.0;
        for p in &job.passes {
            let mut from = p.entry;
            for s in &p.steps {
                for q in path::sample_move(from, &s.mv, 8) {
                    lo = [lo[0].min(q[0] - r), lo[1].min(q[1] - r)];
                    hi = [hi[0].max(q[0] + r), hi[1].max(q[1] + r)];
                }
                from = s.mv.to();
            }
        }
    }
    let margin = 2.0;
    StockSummary {
        size_mm: [
            hi[0] - lo[0] + 2.0 * margin,
            hi[1] - lo[1] + 2.0 * margin,
            part.thickness_mm,
        ],
        corner_mm: [lo[0] - margin, lo[1] - margin],
        top_z_mm: design.spec.machining.stock_top_z_mm,
        material: design.spec.part.cam_material.name.clone(),
    }
}

/// Feed rates in practice on milling machines, mm/min: below, a unit was probably mistaken
/// (mm/s for mm/min is 60 times off); above, beyond most machines.
pub const FEED_PRACTICE_MM_PER_MIN: (f64, f64) = (10.0, 15_000.0);
/// Spindle speeds in practice, rpm.
pub const SPINDLE_PRACTICE_RPM: (f64, f64) = (500.0, 60_000.0);
/// Chip load per tooth in practice: from 5 um (below, the edge rubs) to a fortieth of the
/// diameter.
pub const CHIP_LOAD_MIN_MM: f64 = 0.005;
/// Largest chip load per tooth, per unit diameter.
pub const CHIP_LOAD_MAX_PER_DIAMETER: f64 = 1.0 / 40.0;

/// Warnings for feeds, speeds and chip loads far outside milling practice.
pub fn sanity_warnings(m: &MachiningSpec, tools: &[Tool]) -> Vec<String> {
    let mut out = Vec::new();
    let listed = !m.tools.is_empty();
    for (i, t) in tools.iter().enumerate() {
        let key = |k: &str| {
            if listed {
                format!("machining.tools[{i}].{k}")
            } else {
                format!("machining.{k}")
            }
        };
        for (name, v) in [
            ("feed", t.feed_mm_per_min),
            ("plunge_feed", t.plunge_feed_mm_per_min),
        ] {
            let (lo, hi) = FEED_PRACTICE_MM_PER_MIN;
            if !(lo..=hi).contains(&v) {
                out.push(format!(
                    "{} = {} mm/min is outside milling practice ({lo} to {hi} mm/min); check its unit (\"mm/min\", not \"mm/s\")",
                    key(name),
                    gcode::txt(v, 1)
                ));
            }
        }
        let (lo, hi) = SPINDLE_PRACTICE_RPM;
        if !(lo..=hi).contains(&t.spindle_rpm) {
            out.push(format!(
                "{} = {} rpm is outside milling practice ({lo} to {hi} rpm)",
                key("spindle_rpm"),
                gcode::txt(t.spindle_rpm, 0)
            ));
        }
        if t.plunge_feed_mm_per_min > t.feed_mm_per_min {
            out.push(format!(
                "{} = {} mm/min is faster than the cutting feed ({} mm/min)",
                key("plunge_feed"),
                gcode::txt(t.plunge_feed_mm_per_min, 1),
                gcode::txt(t.feed_mm_per_min, 1)
            ));
        }
        if let (ToolKind::EndMill, Some(n)) = (t.kind, t.flutes) {
            let load = t.feed_mm_per_min / (t.spindle_rpm * n as f64);
            let max = CHIP_LOAD_MAX_PER_DIAMETER * t.diameter_mm;
            if load < CHIP_LOAD_MIN_MM || load > max {
                out.push(format!(
                    "tool {} ({}, {n} flutes): chip load {:.4} mm per tooth at {} mm/min and {} rpm is outside {CHIP_LOAD_MIN_MM} to {:.3} mm (a fortieth of the diameter); {}",
                    t.number,
                    t.describe(),
                    load,
                    gcode::txt(t.feed_mm_per_min, 1),
                    gcode::txt(t.spindle_rpm, 0),
                    max,
                    if load < CHIP_LOAD_MIN_MM {
                        "the edge rubs: raise the feed or lower the speed"
                    } else {
                        "the edge may break: lower the feed or raise the speed"
                    }
                ));
            }
        }
    }
    out
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
