//! Machining settings: the cutter, feeds and depths, and how the G-code is written.

use serde::Serialize;

/// The G-code dialect to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Dialect {
    /// LinuxCNC (rs274ngc).
    Linuxcnc,
    /// GRBL 1.1 (no tool change, short lines).
    Grbl,
    /// Fanuc-style (%, O number, G43, M30, upper-case comments).
    Fanuc,
}

/// Coolant command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Coolant {
    /// M8.
    Flood,
    /// M7.
    Mist,
    /// None.
    Off,
}

/// Machining settings: the cutter (which also decides what concave radius can be made) and
/// how the G-code mills the part.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MachiningSpec {
    /// End mill diameter.
    pub tool_diameter_mm: f64,
    /// Spindle speed.
    pub spindle_rpm: f64,
    /// Cutting feed.
    pub feed_mm_per_min: f64,
    /// Plunge feed.
    pub plunge_feed_mm_per_min: f64,
    /// Depth of each roughing pass.
    pub depth_per_pass_mm: f64,
    /// Material left by roughing for the finishing pass.
    pub stock_allowance_mm: f64,
    /// Height for rapid moves.
    pub safe_z_mm: f64,
    /// Top of the stock.
    pub stock_top_z_mm: f64,
    /// Cut below the part's bottom face.
    pub breakthrough_mm: f64,
    /// Largest deviation of the programmed path from the ideal tool-centre path.
    pub tolerance_mm: f64,
    /// Climb milling (with a clockwise spindle) instead of conventional.
    pub climb: bool,
    /// Radius of the tangential lead-in and lead-out arcs.
    pub lead_in_radius_mm: f64,
    /// G-code dialect.
    pub dialect: Dialect,
    /// Work offset.
    pub work_offset: WorkOffset,
    /// Coolant.
    pub coolant: Coolant,
    /// G2/G3 arcs (false: G1 lines only, for controllers without arcs).
    pub arcs: bool,
    /// Holding tabs left on the outline's straight edges (0: none).
    pub tabs: usize,
    /// Width of each tab (the bridge left between part and stock).
    pub tab_width_mm: f64,
    /// Height of each tab above the part's bottom face.
    pub tab_height_mm: f64,
}

/// The work coordinate system the program runs in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum WorkOffset {
    /// G54 (the usual first work offset).
    G54,
    /// G55.
    G55,
    /// G56.
    G56,
    /// G57.
    G57,
    /// G58.
    G58,
    /// G59.
    G59,
}

impl WorkOffset {
    /// Every work offset, in order.
    pub const ALL: [WorkOffset; 6] = [
        WorkOffset::G54,
        WorkOffset::G55,
        WorkOffset::G56,
        WorkOffset::G57,
        WorkOffset::G58,
        WorkOffset::G59,
    ];

    /// The G word, e.g. "G54".
    pub fn word(self) -> &'static str {
        match self {
            WorkOffset::G54 => "G54",
            WorkOffset::G55 => "G55",
            WorkOffset::G56 => "G56",
            WorkOffset::G57 => "G57",
            WorkOffset::G58 => "G58",
            WorkOffset::G59 => "G59",
        }
    }
}

impl std::fmt::Display for WorkOffset {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.word())
    }
}

impl Dialect {
    /// Path tolerance used when the spec gives none: 1 um where 5 decimals are written
    /// (LinuxCNC), 2 um where 3 decimals are (GRBL, Fanuc), leaving room for the rounding of
    /// the output.
    pub fn default_tolerance_mm(self) -> f64 {
        match self {
            Dialect::Linuxcnc => 1e-3,
            Dialect::Grbl | Dialect::Fanuc => 2e-3,
        }
    }
}

impl Default for MachiningSpec {
    /// A 6 mm end mill at 8000 rpm and 600 mm/min, 1 mm per roughing pass, LinuxCNC.
    fn default() -> Self {
        MachiningSpec {
            tool_diameter_mm: 6.0,
            spindle_rpm: 8000.0,
            feed_mm_per_min: 600.0,
            plunge_feed_mm_per_min: 150.0,
            depth_per_pass_mm: 1.0,
            stock_allowance_mm: 0.2,
            safe_z_mm: 5.0,
            stock_top_z_mm: 0.0,
            breakthrough_mm: 0.5,
            tolerance_mm: Dialect::Linuxcnc.default_tolerance_mm(),
            climb: true,
            lead_in_radius_mm: 2.0,
            dialect: Dialect::Linuxcnc,
            work_offset: WorkOffset::G54,
            coolant: Coolant::Flood,
            arcs: true,
            tabs: 0,
            tab_width_mm: 3.0,
            tab_height_mm: 1.0,
        }
    }
}
