//! The part that carries the cam surfaces: plate, materials, lead-in and run-out, holes.

use serde::Serialize;

/// An isotropic elastic material with the strength needed for the contact check.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Material {
    /// Name (a preset's name, or "custom").
    pub name: String,
    /// Young's modulus.
    pub youngs_modulus_mpa: f64,
    /// Poisson's ratio.
    pub poisson_ratio: f64,
    /// Tensile yield strength.
    pub yield_strength_mpa: f64,
}

/// Preset materials: name, E (MPa), Poisson's ratio, yield strength (MPa).
pub const MATERIALS: &[(&str, f64, f64, f64)] = &[
    ("aluminium-6061-t6", 68_900.0, 0.33, 276.0),
    ("aluminium-7075-t6", 71_700.0, 0.33, 503.0),
    ("steel-1045", 205_000.0, 0.29, 530.0),
    ("bearing-steel", 210_000.0, 0.30, 1_700.0),
    ("stainless-303", 193_000.0, 0.29, 240.0),
    ("brass-360", 97_000.0, 0.31, 310.0),
    ("acetal", 2_900.0, 0.35, 65.0),
];

impl Material {
    /// Looks up a preset by name ("aluminum" is accepted for "aluminium").
    pub fn preset(name: &str) -> Option<Material> {
        let canonical = name
            .trim()
            .to_ascii_lowercase()
            .replace("aluminum", "aluminium");
        MATERIALS
            .iter()
            .find(|m| m.0 == canonical)
            .map(Material::from_row)
    }

    fn from_row(&(name, e, nu, sy): &(&str, f64, f64, f64)) -> Material {
        Material {
            name: name.to_string(),
            youngs_modulus_mpa: e,
            poisson_ratio: nu,
            yield_strength_mpa: sy,
        }
    }
}

/// A through hole in the part (part coordinates: x along the stroke from the roller centre at
/// x = 0, y = 0 on the part's centre line for two followers or at the cam surface's start for one).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Hole {
    /// Centre x.
    pub x_mm: f64,
    /// Centre y.
    pub y_mm: f64,
    /// Diameter.
    pub diameter_mm: f64,
}

/// The part that carries the cam surface(s).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PartSpec {
    /// Plate thickness, which is also the cam face width.
    pub thickness_mm: f64,
    /// Width of the roller in contact (defaults to the thickness).
    pub roller_width_mm: f64,
    /// Cam material.
    pub cam_material: Material,
    /// Roller material.
    pub roller_material: Material,
    /// Straight run before x = 0, tangent to the cam surface there.
    pub lead_in_mm: f64,
    /// Straight over-travel run after Xmax, tangent to the cam surface there.
    pub run_out_mm: f64,
    /// Material under the lowest point of the cam edge (one follower), or the width of the cam
    /// between its two surfaces at their narrowest (two followers).
    pub web_mm: f64,
    /// Mounting holes.
    pub holes: Vec<Hole>,
}

impl Material {
    /// The default cam material, aluminium 6061-T6.
    pub fn default_cam() -> Material {
        Material::from_row(&MATERIALS[0])
    }

    /// The default roller material, bearing steel.
    pub fn default_roller() -> Material {
        Material::from_row(&MATERIALS[3])
    }
}

impl Default for PartSpec {
    /// A 10 mm aluminium plate with a bearing-steel roller as wide as the plate, 2 mm lead-in
    /// and run-out, an 8 mm web and no holes.
    fn default() -> Self {
        PartSpec {
            thickness_mm: 10.0,
            roller_width_mm: 10.0,
            cam_material: Material::default_cam(),
            roller_material: Material::default_roller(),
            lead_in_mm: 2.0,
            run_out_mm: 2.0,
            web_mm: 8.0,
            holes: Vec::new(),
        }
    }
}

impl PartSpec {
    /// A copy with another plate thickness; a roller width that was as wide as the plate
    /// follows it (the default when no roller width is given).
    pub fn with_thickness(mut self, thickness_mm: f64) -> PartSpec {
        if self.roller_width_mm == self.thickness_mm {
            self.roller_width_mm = thickness_mm;
        }
        self.thickness_mm = thickness_mm;
        self
    }

    /// The length of the roller-on-cam line contact: the narrower of roller and plate.
    pub fn contact_length_mm(&self) -> f64 {
        self.thickness_mm.min(self.roller_width_mm)
    }
}
