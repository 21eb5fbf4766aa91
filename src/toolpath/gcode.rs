//! G-code emission: a modal machine state that writes words only when they change, and the
//! dialect rules (LinuxCNC, GRBL, Fanuc).
//!
//! Every program: a header of comments (spec, law, stock and origin, tool list, estimated
//! cycle time, tolerance, warnings), then units G21, absolute G90, plane G17, feed per minute
//! G94, no compensation or canned cycle (G40 G49 G80), the work offset. Each tool: the tool
//! change (`M6` and `G43`; GRBL, which has none, pauses with `M0`), a rapid of Z alone to the
//! safe height, spindle on with a dwell, coolant. Rapids only at or above the stock top (to
//! `safe_z`, then down to 1 mm above the stock), except a peck's return inside its own drilled
//! hole; descents in air at the plunge feed; ramps, helices and cutting moves at the cutting
//! feed; at the end spindle and coolant off and M2 (LinuxCNC, GRBL) or M30 (Fanuc).

use std::fmt::Write as _;

use super::path::Move;
use super::{Drilling, Job, ToolUse, ToolpathSummary};
use crate::design::Design;
use crate::model::{Coolant, Dialect, MachiningSpec, Tool};

/// Decimals written for coordinates in a dialect.
pub fn decimals(d: Dialect) -> usize {
    match d {
        Dialect::Linuxcnc => 5,
        Dialect::Grbl | Dialect::Fanuc => 3,
    }
}

/// The dialect's name.
pub fn dialect_name(d: Dialect) -> &'static str {
    match d {
        Dialect::Linuxcnc => "linuxcnc",
        Dialect::Grbl => "grbl",
        Dialect::Fanuc => "fanuc",
    }
}

/// Longest line GRBL's serial buffer takes (LINE_BUFFER_SIZE 80, less margin).
pub const GRBL_MAX_LINE: usize = 70;

/// Formats a coordinate: fixed decimals, trailing zeros dropped, the decimal point kept
/// ("10." not "10", which Fanuc would read in least input increments).
pub(crate) fn num(v: f64, decimals: usize) -> String {
    let mut s = format!("{:.*}", decimals, v);
    if s.contains('.') {
        while s.ends_with('0') {
            s.pop();
        }
    }
    if s == "-0." {
        s = "0.".into();
    }
    s
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Motion {
    Rapid,
    Feed,
    Cw,
    Ccw,
}

/// The controller's modal state as the program leaves it.
#[derive(Debug, Default)]
struct Machine {
    motion: Option<Motion>,
    x: Option<f64>,
    y: Option<f64>,
    z: Option<f64>,
    feed: Option<f64>,
}

/// Writes the program text.
struct Writer {
    out: String,
    dialect: Dialect,
    decimals: usize,
    machine: Machine,
    blocks: usize,
}

impl Writer {
    fn line(&mut self, s: &str) {
        self.out.push_str(s);
        self.out.push('\n');
        self.blocks += 1;
    }

    fn comment(&mut self, text: &str) {
        // Parentheses end a comment: write brackets instead.
        let mut t: String = text.replace('(', "[").replace(')', "]");
        if self.dialect == Dialect::Fanuc {
            t = t.to_uppercase();
        }
        // GRBL's line buffer is short: a long comment goes on several lines, split at spaces.
        let width = if self.dialect == Dialect::Grbl {
            GRBL_MAX_LINE - 2
        } else {
            usize::MAX
        };
        let mut line = String::new();
        for word in t.split(' ') {
            let word: String = word.chars().take(width).collect();
            if !line.is_empty() && line.len() + 1 + word.len() > width {
                self.out.push_str(&format!("({line})\n"));
                line.clear();
            }
            if !line.is_empty() {
                line.push(' ');
            }
            line.push_str(&word);
        }
        self.out.push_str(&format!("({line})\n"));
    }

    fn words(
        &mut self,
        motion: Motion,
        x: f64,
        y: f64,
        z: f64,
        ij: Option<(f64, f64)>,
        feed: Option<f64>,
    ) {
        let d = self.decimals;
        let mut s = String::new();
        let same = |a: Option<f64>, b: f64| a.is_some_and(|a| num(a, d) == num(b, d));
        if ij.is_none()
            && same(self.machine.x, x)
            && same(self.machine.y, y)
            && same(self.machine.z, z)
        {
            return; // no motion: write nothing, change nothing
        }
        if self.machine.motion != Some(motion) || ij.is_some() {
            s.push_str(match motion {
                Motion::Rapid => "G0",
                Motion::Feed => "G1",
                Motion::Cw => "G2",
                Motion::Ccw => "G3",
            });
            self.machine.motion = Some(motion);
        }
        for (axis, v, old) in [
            ("X", x, self.machine.x),
            ("Y", y, self.machine.y),
            ("Z", z, self.machine.z),
        ] {
            if !same(old, v) || (ij.is_some() && axis != "Z") {
                let _ = write!(s, " {axis}{}", num(v, d));
            }
        }
        self.machine.x = Some(x);
        self.machine.y = Some(y);
        self.machine.z = Some(z);
        if let Some((i, j)) = ij {
            let _ = write!(s, " I{} J{}", num(i, d), num(j, d));
        }
        if let Some(f) = feed {
            if self.machine.feed != Some(f) {
                let _ = write!(s, " F{}", num(f, 1));
                self.machine.feed = Some(f);
            }
        }
        let s = s.trim_start().to_string();
        self.line(&s);
    }

    fn rapid(&mut self, x: f64, y: f64, z: f64) {
        self.words(Motion::Rapid, x, y, z, None, None);
    }
}

/// A number for a comment: as [`num`], without a trailing decimal point ("6", "10.5").
pub(crate) fn txt(v: f64, decimals: usize) -> String {
    num(v, decimals).trim_end_matches('.').to_string()
}

/// A dwell of `seconds` in the dialect: P in seconds (LinuxCNC, GRBL) or milliseconds (Fanuc).
fn dwell(d: Dialect, seconds: f64) -> String {
    match d {
        Dialect::Fanuc => format!("G4 P{}", (seconds * 1000.0).round() as u64),
        _ => format!("G4 P{}", num(seconds, 3)),
    }
}

impl Writer {
    /// A rapid of Z alone (the X and Y words are not written, whether known or not).
    fn retract(&mut self, z: f64) {
        let d = self.decimals;
        if self.machine.z.is_some_and(|old| num(old, d) == num(z, d)) {
            return;
        }
        let word = if self.machine.motion == Some(Motion::Rapid) {
            ""
        } else {
            "G0 "
        };
        self.machine.motion = Some(Motion::Rapid);
        self.machine.z = Some(z);
        self.line(&format!("{word}Z{}", num(z, d)));
    }

    /// The controller forgets where it is (after a tool change or a pause): the next move
    /// writes every axis.
    fn forget_position(&mut self) {
        self.machine = Machine::default();
    }

    fn spindle_on(&mut self, tool: &Tool, dwell_s: f64, coolant: Coolant) {
        self.line(&format!(
            "S{} M3",
            num(tool.spindle_rpm, 0).trim_end_matches('.')
        ));
        if dwell_s > 0.0 {
            self.line(&dwell(self.dialect, dwell_s));
        }
        match coolant {
            Coolant::Flood => self.line("M8"),
            Coolant::Mist => self.line("M7"),
            Coolant::Off => {}
        }
    }
}

/// "T1: 6 mm end mill, 4 flutes, flutes 18 mm (assumed), 10.5 mm deep: mills the outline".
fn tool_line(t: &ToolUse) -> String {
    format!(
        "T{}: {} mm {}{}, flutes {} mm{}, {} mm deep: {}",
        t.number,
        txt(t.diameter_mm, 3),
        t.kind.name(),
        t.flutes.map_or(String::new(), |n| format!(" {n}-flute")),
        txt(t.flute_length_mm, 2),
        if t.flute_length_assumed {
            " assumed"
        } else {
            ""
        },
        txt(t.depth_mm, 3),
        t.purpose
    )
}

/// The G-code program text and its block count.
///
/// Every tool starts the same way: the tool change (`M6`, or for GRBL a pause `M0` after a
/// comment naming the tool), then a rapid of Z alone to the safe height, then the spindle with
/// a dwell, then coolant. Passes start with Z alone up to the safe height, X and Y across,
/// rapid down to 1 mm above the stock, and a feed down to the floor already cut there.
pub fn write(design: &Design, jobs: &[Job], summary: &ToolpathSummary) -> (String, usize) {
    let spec = &design.spec;
    let m = &spec.machining;
    let law = &design.law.law;
    let mut w = Writer {
        out: String::new(),
        dialect: m.dialect,
        decimals: decimals(m.dialect),
        machine: Machine::default(),
        blocks: 0,
    };
    let d = w.decimals;
    if m.dialect == Dialect::Fanuc {
        w.line("%");
        w.line("O1000");
    }
    w.comment(&format!(
        "camspring {} cam part {}",
        env!("CARGO_PKG_VERSION"),
        spec.name
    ));
    w.comment(&format!("camspring run {}", spec.run_id()));
    w.comment(&format!("law {}", law.describe()));
    let st = &summary.stock;
    w.comment(&format!(
        "stock {} plate, at least {} x {} x {} mm",
        st.material,
        txt(st.size_mm[0], 1),
        txt(st.size_mm[1], 1),
        txt(st.size_mm[2], 2)
    ));
    w.comment(&format!(
        "stock corner X{} Y{}, top Z{}; X0 Y0 = the drawing datum",
        txt(st.corner_mm[0], 2),
        txt(st.corner_mm[1], 2),
        txt(st.top_z_mm, 3)
    ));
    for t in &summary.tools {
        w.comment(&tool_line(t));
    }
    w.comment(&format!(
        "estimated cycle time {:.1} min [tool changes not counted]",
        summary.estimated_minutes
    ));
    w.comment(&format!(
        "tolerance {} mm; outline: {} rough levels to a {} mm skin, allowance {} mm, then finish",
        m.tolerance_mm, summary.rough_levels, m.skin_mm, m.stock_allowance_mm
    ));
    w.comment(&format!(
        "units mm, {}, ramp {} deg, dialect {}",
        if m.climb { "climb" } else { "conventional" },
        m.ramp_angle_deg,
        dialect_name(m.dialect)
    ));
    for warning in &summary.warnings {
        w.comment(&format!("WARNING: {warning}"));
    }
    w.line(&format!("G21 G90 G17 G94 G40 G49 G80 {}", m.work_offset));
    let clearance = (m.stock_top_z_mm + 1.0).min(m.safe_z_mm);
    for (n, job) in jobs.iter().enumerate() {
        let t = &job.tool;
        if n > 0 {
            w.line("M5");
            if m.coolant != Coolant::Off {
                w.line("M9");
            }
            w.retract(m.safe_z_mm);
        }
        let what = format!("T{} {}: {}", t.number, t.describe(), job.purpose);
        match m.dialect {
            Dialect::Linuxcnc => {
                w.comment(&what);
                w.line(&format!("T{} M6", t.number));
                w.line(&format!("G43 H{}", t.number));
                w.forget_position();
                w.retract(m.safe_z_mm);
            }
            Dialect::Fanuc => {
                w.comment(&what);
                w.line(&format!("T{} M6", t.number));
                w.line(&format!("G0 G43 H{} Z{}", t.number, num(m.safe_z_mm, d)));
                w.forget_position();
                w.machine.z = Some(m.safe_z_mm);
                w.machine.motion = Some(Motion::Rapid);
            }
            Dialect::Grbl => {
                // GRBL has no tool change: pause for the operator (the first tool is loaded
                // before the start).
                w.comment(&what);
                if n > 0 {
                    w.comment(&format!(
                        "load T{} and set its Z zero, then resume",
                        t.number
                    ));
                    w.line("M0");
                }
                w.forget_position();
                w.retract(m.safe_z_mm);
            }
        }
        w.spindle_on(t, m.spindle_dwell_s, m.coolant);
        if let Some(drill) = &job.drilling {
            drilling(&mut w, t, drill, m);
        }
        for p in &job.passes {
            w.comment(&format!("{} at Z{}", p.label, num(p.z_mm, 3)));
            w.retract(m.safe_z_mm);
            w.rapid(p.entry[0], p.entry[1], m.safe_z_mm);
            w.rapid(p.entry[0], p.entry[1], clearance);
            if p.entry_z_mm < clearance {
                w.words(
                    Motion::Feed,
                    p.entry[0],
                    p.entry[1],
                    p.entry_z_mm,
                    None,
                    Some(t.plunge_feed_mm_per_min),
                );
            }
            let mut from = p.entry;
            let n_steps = p.steps.len();
            for (k, s) in p.steps.iter().enumerate() {
                if k == 0 && p.ramp > 0 {
                    w.comment("ramp");
                }
                if k == p.ramp && p.lead_in > 0 {
                    w.comment("lead-in");
                }
                if k == p.ramp + p.lead_in {
                    w.comment("contour");
                }
                if k + p.lead_out == n_steps && p.lead_out > 0 {
                    w.comment("lead-out");
                }
                if p.over_tab[k] && (k == 0 || !p.over_tab[k - 1]) {
                    w.comment("tab");
                }
                let feed = if s.plunge {
                    t.plunge_feed_mm_per_min
                } else {
                    t.feed_mm_per_min
                };
                match s.mv {
                    Move::Line { to } => {
                        w.words(Motion::Feed, to[0], to[1], s.z_mm, None, Some(feed))
                    }
                    Move::Arc { to, center, ccw } => {
                        let motion = if ccw { Motion::Ccw } else { Motion::Cw };
                        w.words(
                            motion,
                            to[0],
                            to[1],
                            s.z_mm,
                            Some((center[0] - from[0], center[1] - from[1])),
                            Some(feed),
                        );
                    }
                }
                from = s.mv.to();
            }
            w.retract(m.safe_z_mm);
        }
    }
    w.line("M5");
    if m.coolant != Coolant::Off {
        w.line("M9");
    }
    match m.dialect {
        Dialect::Fanuc => {
            w.line("M30");
            w.line("%");
        }
        _ => w.line("M2"),
    }
    let blocks = w.blocks;
    (w.out, blocks)
}

/// Drilled holes: `G98 G81` (or `G83` with pecks) from the safe height for LinuxCNC and Fanuc;
/// for GRBL, which has no canned cycles, the same moves written out.
fn drilling(w: &mut Writer, t: &Tool, drill: &Drilling, m: &MachiningSpec) {
    let d = w.decimals;
    w.comment(&format!(
        "drill holes {} to Z{}",
        drill
            .holes
            .iter()
            .map(|h| h.0.to_string())
            .collect::<Vec<_>>()
            .join(", "),
        num(drill.z_mm, 3)
    ));
    let feed = t.plunge_feed_mm_per_min;
    if w.dialect == Dialect::Grbl {
        let top = drill.r_plane_mm;
        for &(_, c) in &drill.holes {
            w.retract(m.safe_z_mm);
            w.rapid(c[0], c[1], m.safe_z_mm);
            w.rapid(c[0], c[1], top);
            let depth = top - drill.z_mm;
            let pecks = drill
                .peck_mm
                .map_or(1, |q| ((depth / q) - 1e-9).ceil().max(1.0) as usize);
            for k in 1..=pecks {
                let z = top - depth * k as f64 / pecks as f64;
                if k > 1 {
                    // Back down in the hole already drilled, to just above its bottom.
                    let above = top - depth * (k - 1) as f64 / pecks as f64 + PECK_CLEARANCE_MM;
                    w.rapid(c[0], c[1], above.min(top));
                }
                w.words(Motion::Feed, c[0], c[1], z, None, Some(feed));
                w.rapid(c[0], c[1], top);
            }
            w.retract(m.safe_z_mm);
        }
        return;
    }
    w.retract(m.safe_z_mm);
    for (k, &(_, c)) in drill.holes.iter().enumerate() {
        let xy = format!("X{} Y{}", num(c[0], d), num(c[1], d));
        if k == 0 {
            let cycle = match drill.peck_mm {
                Some(q) => format!(
                    "G98 G83 {xy} Z{} R{} Q{}",
                    num(drill.z_mm, d),
                    num(drill.r_plane_mm, d),
                    num(q, d)
                ),
                None => format!(
                    "G98 G81 {xy} Z{} R{}",
                    num(drill.z_mm, d),
                    num(drill.r_plane_mm, d)
                ),
            };
            w.line(&format!("{cycle} F{}", num(feed, 1)));
            w.machine.feed = Some(feed);
        } else {
            w.line(&xy);
        }
        w.machine.x = Some(c[0]);
        w.machine.y = Some(c[1]);
    }
    w.line("G80");
    w.machine.motion = None;
    w.machine.z = Some(m.safe_z_mm);
}

/// How far above the bottom already drilled a peck's rapid return stops (LinuxCNC's G83 uses
/// 0.254 mm).
pub const PECK_CLEARANCE_MM: f64 = 0.254;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_keep_the_decimal_point_and_drop_zeros() {
        assert_eq!(num(10.0, 3), "10.");
        assert_eq!(num(-0.00001, 3), "0.");
        assert_eq!(num(1.23456, 4), "1.2346");
        assert_eq!(num(-2.5, 4), "-2.5");
    }
}
