//! Drawing settings: the sheet, the scale, and what the title block and notes say.

use serde::Serialize;

/// A standard drawing sheet, landscape.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum SheetSize {
    /// ISO A4, 297 x 210 mm.
    A4,
    /// ISO A3, 420 x 297 mm.
    A3,
    /// ANSI A (letter), 279.4 x 215.9 mm.
    AnsiA,
    /// ANSI B (ledger), 431.8 x 279.4 mm.
    AnsiB,
}

impl SheetSize {
    /// Width and height in mm, landscape.
    pub fn size_mm(self) -> (f64, f64) {
        match self {
            SheetSize::A4 => (297.0, 210.0),
            SheetSize::A3 => (420.0, 297.0),
            SheetSize::AnsiA => (279.4, 215.9),
            SheetSize::AnsiB => (431.8, 279.4),
        }
    }

    /// "A4", "ANSI B".
    pub fn name(self) -> &'static str {
        match self {
            SheetSize::A4 => "A4",
            SheetSize::A3 => "A3",
            SheetSize::AnsiA => "ANSI A",
            SheetSize::AnsiB => "ANSI B",
        }
    }
}

/// The scales a drawing may use (drawing units per part unit), largest first: 10:1 ... 1:10.
pub const STANDARD_SCALES: [f64; 9] = [10.0, 5.0, 2.0, 1.0, 0.5, 0.2, 0.1, 0.05, 0.02];

/// "2:1", "1:1", "1:5".
pub fn scale_label(scale: f64) -> String {
    if scale >= 1.0 {
        format!("{}:1", trim(scale))
    } else {
        format!("1:{}", trim(1.0 / scale))
    }
}

fn trim(v: f64) -> String {
    let s = format!("{v:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// What the shop drawing shows beyond the geometry (`[drawing]`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DrawingSpec {
    /// Sheet size.
    pub sheet: SheetSize,
    /// Scale (drawing units per part unit); None: the largest standard scale that fits.
    pub scale: Option<f64>,
    /// Drawing number; None: the spec name in capitals followed by "-001".
    pub number: Option<String>,
    /// Revision letter.
    pub revision: String,
    /// Date in the title block, as written (never the clock, so outputs stay reproducible);
    /// None leaves the field blank.
    pub date: Option<String>,
    /// Drawn by.
    pub drawn_by: Option<String>,
    /// General tolerance standard and class.
    pub general_tolerance: String,
    /// Roughness Ra of the cam faces.
    pub cam_finish_ra_um: f64,
    /// Roughness Ra of the other faces.
    pub finish_ra_um: f64,
    /// Step in X of the cam-face coordinate table; None: a round step that fits the sheet.
    pub coordinate_step_mm: Option<f64>,
}

impl Default for DrawingSpec {
    /// A4, scale to fit, revision A, no date, ISO 2768-m, Ra 0.8 on the cam faces, Ra 3.2
    /// elsewhere.
    fn default() -> Self {
        DrawingSpec {
            sheet: SheetSize::A4,
            scale: None,
            number: None,
            revision: "A".into(),
            date: None,
            drawn_by: None,
            general_tolerance: "ISO 2768-m".into(),
            cam_finish_ra_um: 0.8,
            finish_ra_um: 3.2,
            coordinate_step_mm: None,
        }
    }
}
