//! G-code emission: a modal machine state that writes words only when they change, and the
//! dialect rules (LinuxCNC, GRBL, Fanuc).
//!
//! Every program: a header of comments (spec, law, tool, tolerance), units G21, absolute G90,
//! plane G17, feed per minute G94, the work offset, the tool, spindle on before the first cut,
//! coolant; rapids only at or above the stock top (to `safe_z`, then down to 1 mm above the
//! stock); plunges at the plunge feed; cutting moves at the cutting feed; at the end spindle and
//! coolant off and M2 (LinuxCNC, GRBL) or M30 (Fanuc).

use std::fmt::Write as _;

use super::path::Move;
use super::{Pass, ToolpathSummary};
use crate::design::Design;
use crate::model::{Coolant, Dialect};

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
        if self.dialect == Dialect::Grbl && t.len() + 2 > GRBL_MAX_LINE {
            t.truncate(GRBL_MAX_LINE - 2);
        }
        let line = format!("({t})");
        self.out.push_str(&line);
        self.out.push('\n');
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

/// The G-code program text and its block count.
pub fn write(design: &Design, passes: &[Pass], summary: &ToolpathSummary) -> (String, usize) {
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
    w.comment(&format!(
        "tool 1: {} mm flat end mill, {} rpm",
        m.tool_diameter_mm, m.spindle_rpm
    ));
    w.comment(&format!(
        "stock top Z{} thickness {} breakthrough {} mm",
        m.stock_top_z_mm, spec.part.thickness_mm, m.breakthrough_mm
    ));
    w.comment(&format!(
        "tolerance {} mm, {} rough levels + finish, allowance {} mm",
        m.tolerance_mm, summary.rough_levels, m.stock_allowance_mm
    ));
    w.comment(&format!(
        "units mm, {}, dialect {}",
        if m.climb { "climb" } else { "conventional" },
        dialect_name(m.dialect)
    ));
    w.line(&format!("G21 G90 G17 G94 {}", m.work_offset));
    match m.dialect {
        Dialect::Linuxcnc => w.line("T1 M6"),
        Dialect::Fanuc => {
            w.line("T1 M6");
            w.line(&format!("G43 H1 Z{}", num(m.safe_z_mm, w.decimals)));
            w.machine.z = Some(m.safe_z_mm);
        }
        Dialect::Grbl => w.comment("load tool 1 now (GRBL has no tool change)"),
    }
    w.line(&format!(
        "S{} M3",
        num(m.spindle_rpm, 0).trim_end_matches('.')
    ));
    match m.coolant {
        Coolant::Flood => w.line("M8"),
        Coolant::Mist => w.line("M7"),
        Coolant::Off => {}
    }
    let clearance = (m.stock_top_z_mm + 1.0).min(m.safe_z_mm);
    let (x0, y0) = passes
        .first()
        .map_or((0.0, 0.0), |p| (p.entry[0], p.entry[1]));
    w.rapid(
        w.machine.x.unwrap_or(x0),
        w.machine.y.unwrap_or(y0),
        m.safe_z_mm,
    );
    for p in passes {
        w.comment(&format!("{} at Z{}", p.label, num(p.z_mm, 3)));
        let z_now = w.machine.z.unwrap_or(m.safe_z_mm);
        w.rapid(
            w.machine.x.unwrap_or(p.entry[0]),
            w.machine.y.unwrap_or(p.entry[1]),
            z_now.max(m.safe_z_mm),
        );
        w.rapid(p.entry[0], p.entry[1], m.safe_z_mm);
        w.rapid(p.entry[0], p.entry[1], clearance);
        w.words(
            Motion::Feed,
            p.entry[0],
            p.entry[1],
            p.z_mm,
            None,
            Some(m.plunge_feed_mm_per_min),
        );
        let mut from = p.entry;
        for (k, mv) in p.moves.iter().enumerate() {
            let z = if p.over_tab[k] { p.tab_z_mm } else { p.z_mm };
            let was_over = k > 0 && p.over_tab[k - 1];
            if p.over_tab[k] != was_over {
                // Onto or off a holding tab: a vertical move at the plunge feed.
                if p.over_tab[k] {
                    w.comment("tab");
                }
                w.words(
                    Motion::Feed,
                    from[0],
                    from[1],
                    z,
                    None,
                    Some(m.plunge_feed_mm_per_min),
                );
            }
            if k == 0 {
                w.comment("lead-in");
            }
            if k == p.lead_in {
                w.comment("contour");
            }
            if k + p.lead_out == p.moves.len() {
                w.comment("lead-out");
            }
            match *mv {
                Move::Line { to } => {
                    w.words(Motion::Feed, to[0], to[1], z, None, Some(m.feed_mm_per_min))
                }
                Move::Arc { to, center, ccw } => {
                    let motion = if ccw { Motion::Ccw } else { Motion::Cw };
                    w.words(
                        motion,
                        to[0],
                        to[1],
                        z,
                        Some((center[0] - from[0], center[1] - from[1])),
                        Some(m.feed_mm_per_min),
                    );
                }
            }
            from = mv.to();
        }
        w.rapid(from[0], from[1], m.safe_z_mm);
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
