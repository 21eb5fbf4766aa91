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

/// What a tool does to the part.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ToolKind {
    /// A flat end mill: the outline, and holes by helical interpolation.
    EndMill,
    /// A twist drill (118 degree point): holes of its own diameter, by G81 or G83.
    Drill,
}

impl ToolKind {
    /// "end mill", "drill".
    pub fn name(self) -> &'static str {
        match self {
            ToolKind::EndMill => "end mill",
            ToolKind::Drill => "drill",
        }
    }
}

/// One tool of the program's list (`[[machining.tools]]`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Tool {
    /// Tool number (T word, H offset).
    pub number: u32,
    /// End mill or drill.
    pub kind: ToolKind,
    /// Diameter.
    pub diameter_mm: f64,
    /// Length of the cutting flutes; when not given, 3 diameters (a standard-length end mill)
    /// or 8 diameters (a jobber drill) is assumed for the depth check.
    pub flute_length_mm: Option<f64>,
    /// Number of flutes (for the chip load).
    pub flutes: Option<u32>,
    /// Spindle speed.
    pub spindle_rpm: f64,
    /// Cutting feed.
    pub feed_mm_per_min: f64,
    /// Plunge (and drilling) feed.
    pub plunge_feed_mm_per_min: f64,
    /// Peck depth for deep drilling (G83); default one diameter.
    pub peck_mm: Option<f64>,
}

impl Tool {
    /// The flute length the depth check uses: the given one, or the assumed standard.
    pub fn usable_length_mm(&self) -> f64 {
        self.flute_length_mm.unwrap_or(match self.kind {
            ToolKind::EndMill => 3.0 * self.diameter_mm,
            ToolKind::Drill => 8.0 * self.diameter_mm,
        })
    }

    /// "6 mm end mill", "3.3 mm drill".
    pub fn describe(&self) -> String {
        format!("{} mm {}", self.diameter_mm, self.kind.name())
    }
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
    /// The skin roughing leaves: it stops this far above the part's bottom face, so that only
    /// the finishing pass cuts the part (and the slugs of milled holes) free.
    pub skin_mm: f64,
    /// Dwell after every spindle start, for the spindle to reach speed.
    pub spindle_dwell_s: f64,
    /// Largest angle of a ramped or helical entry to the horizontal.
    pub ramp_angle_deg: f64,
    /// Rapid traverse rate, for the cycle-time estimate.
    pub rapid_mm_per_min: f64,
    /// Flute length of the single tool (when `tools` is empty).
    pub flute_length_mm: Option<f64>,
    /// Flutes of the single tool (when `tools` is empty).
    pub flutes: Option<u32>,
    /// The tool list; empty: one end mill of `tool_diameter_mm` at the feeds above.
    pub tools: Vec<Tool>,
}

impl MachiningSpec {
    /// The tools the program may use: the list, or the one end mill the settings describe.
    pub fn tool_list(&self) -> Vec<Tool> {
        if !self.tools.is_empty() {
            return self.tools.clone();
        }
        vec![Tool {
            number: 1,
            kind: ToolKind::EndMill,
            diameter_mm: self.tool_diameter_mm,
            flute_length_mm: self.flute_length_mm,
            flutes: self.flutes,
            spindle_rpm: self.spindle_rpm,
            feed_mm_per_min: self.feed_mm_per_min,
            plunge_feed_mm_per_min: self.plunge_feed_mm_per_min,
            peck_mm: None,
        }]
    }
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
            skin_mm: 0.5,
            spindle_dwell_s: 3.0,
            ramp_angle_deg: 3.0,
            rapid_mm_per_min: 3000.0,
            flute_length_mm: None,
            flutes: None,
            tools: Vec::new(),
        }
    }
}
