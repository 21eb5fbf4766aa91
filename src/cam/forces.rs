//! The forward model: rod force and contact stress predicted from the made geometry.
//!
//! Nothing here reads the target law's force. The rod force comes from the pitch curve's
//! tangent angle theta and lift Y only, through the follower springs and Coulomb friction:
//! loading F = q*tan(theta + phi), unloading F = q*tan(theta - phi), q = k_eff*(Y + Yp). A
//! cam corrected for a stroke must give back the law on that stroke, which is what the tests
//! check. The contact between one roller and the cam is a Hertz line contact of the part's
//! thickness, with normal force N = P*cos(phi)/cos(theta +/- phi) for the per-roller spring
//! force P, and effective radius 1/R' = 1/r - kappa_surface.

use serde::Serialize;

use super::pitch_curve::PitchCurve;
use super::surface::CamSurface;
use crate::model::Follower;
use crate::model::ForceLaw;
use crate::model::Material;

/// The predicted state of the transmission at one pitch sample.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RodForce {
    /// Deflection.
    pub x_mm: f64,
    /// The designed law's force (for comparison only).
    pub design_n: f64,
    /// Rod force while loading; `None` where the followers jam (theta + phi >= 90 deg).
    pub loading_n: Option<f64>,
    /// Rod force while unloading (negative where the spring cannot return the rod).
    pub unloading_n: f64,
    /// The designed stiffness dF/dx.
    pub stiffness_n_per_mm: f64,
    /// Pressure angle theta.
    pub pressure_angle_deg: f64,
    /// Normal force on one roller, the larger of loading and unloading.
    pub contact_normal_n: Option<f64>,
    /// Peak Hertz pressure on one roller.
    pub contact_stress_mpa: Option<f64>,
}

/// Rod force from geometry: q*tan(theta + phi) (loading) and q*tan(theta - phi) (unloading).
/// Returns `None` for loading where theta + phi >= 90 deg.
pub fn rod_force(q_n: f64, theta_rad: f64, phi_rad: f64) -> (Option<f64>, f64) {
    (
        loading_rod_force(q_n, theta_rad, phi_rad),
        unloading_rod_force(q_n, theta_rad, phi_rad),
    )
}

/// The rod force per unit spring load on one stroke: tan(theta + phi) loading, tan(theta -
/// phi) unloading; `None` where the loading stroke self-locks (theta + phi >= 90 deg). For
/// callers that apply many spring loads at one friction angle.
pub fn stroke_force_ratio(theta_rad: f64, phi_rad: f64, loading: bool) -> Option<f64> {
    if loading {
        let load_angle = theta_rad + phi_rad;
        (load_angle < std::f64::consts::FRAC_PI_2).then(|| load_angle.tan())
    } else {
        Some((theta_rad - phi_rad).tan())
    }
}

/// q*tan(theta + phi), `None` where the cam self-locks (theta + phi >= 90 deg).
fn loading_rod_force(q_n: f64, theta_rad: f64, phi_rad: f64) -> Option<f64> {
    stroke_force_ratio(theta_rad, phi_rad, true).map(|ratio| q_n * ratio)
}

/// q*tan(theta - phi).
fn unloading_rod_force(q_n: f64, theta_rad: f64, phi_rad: f64) -> f64 {
    q_n * (theta_rad - phi_rad).tan()
}

/// Plane-strain contact modulus E* from both materials: 1/E* = sum (1 - nu^2)/E.
pub fn contact_modulus_mpa(a: &Material, b: &Material) -> f64 {
    1.0 / ((1.0 - a.poisson_ratio.powi(2)) / a.youngs_modulus_mpa
        + (1.0 - b.poisson_ratio.powi(2)) / b.youngs_modulus_mpa)
}

/// Peak Hertz pressure of a line contact: p = sqrt(N*E*/(pi*L*R')).
pub fn hertz_line_pressure_mpa(
    normal_n: f64,
    e_star_mpa: f64,
    length_mm: f64,
    r_eff_mm: f64,
) -> f64 {
    (normal_n * e_star_mpa / (std::f64::consts::PI * length_mm * r_eff_mm)).sqrt()
}

/// What the contact model needs besides the geometry.
#[derive(Debug, Clone, Copy)]
pub struct ContactModel {
    /// E* of cam and roller.
    pub e_star_mpa: f64,
    /// Contact line length (the smaller of part thickness and roller width).
    pub length_mm: f64,
}

/// Predicts rod forces and contact stress at every pitch sample.
pub fn predict(
    law: &ForceLaw,
    follower: &Follower,
    pitch: &PitchCurve,
    surface: &CamSurface,
    contact: &ContactModel,
) -> Vec<RodForce> {
    let phi = follower.friction_angle_rad();
    let r = follower.roller_radius_mm;
    pitch
        .samples
        .iter()
        .zip(&surface.points)
        .map(|(s, p)| {
            let q = follower.spring_force_n(s.y_mm);
            let (loading, unloading) = rod_force(q, s.theta_rad, phi);
            let per_roller = follower.spring_force_per_roller_n(s.y_mm);
            let n_load = (s.theta_rad + phi < std::f64::consts::FRAC_PI_2)
                .then(|| per_roller * phi.cos() / (s.theta_rad + phi).cos());
            let n_unload = per_roller * phi.cos() / (s.theta_rad - phi).cos();
            let normal = n_load.map(|n| n.max(n_unload));
            let inv_r_eff = if r > 0.0 && p.stretch > 0.0 {
                1.0 / r - p.curvature_per_mm
            } else {
                f64::NAN
            };
            let stress = match normal {
                Some(n) if inv_r_eff > 0.0 => Some(hertz_line_pressure_mpa(
                    n,
                    contact.e_star_mpa,
                    contact.length_mm,
                    1.0 / inv_r_eff,
                )),
                _ => None,
            };
            RodForce {
                x_mm: s.x_mm,
                design_n: law.force_n(s.x_mm),
                loading_n: loading,
                unloading_n: unloading,
                stiffness_n_per_mm: law.stiffness_n_per_mm(s.x_mm),
                pressure_angle_deg: s.theta_rad.to_degrees(),
                contact_normal_n: normal,
                contact_stress_mpa: stress,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hertz_pressure_agrees_with_half_width_form() {
        // Independent form: half-width a = sqrt(4 N R' / (pi L E*)), p = 2N / (pi a L).
        let (n, e, l, r) = (120.0, 57_988.0, 10.0, 3.0);
        let a = (4.0 * n * r / (std::f64::consts::PI * l * e)).sqrt();
        let p = 2.0 * n / (std::f64::consts::PI * a * l);
        assert!((hertz_line_pressure_mpa(n, e, l, r) - p).abs() < 1e-9 * p);
    }

    #[test]
    fn contact_modulus_of_aluminium_on_steel() {
        let al = Material {
            name: "al".into(),
            youngs_modulus_mpa: 69_000.0,
            poisson_ratio: 0.33,
            yield_strength_mpa: 276.0,
        };
        let st = Material {
            name: "st".into(),
            youngs_modulus_mpa: 210_000.0,
            poisson_ratio: 0.30,
            yield_strength_mpa: 1700.0,
        };
        // 1/E* = 0.8911/69000 + 0.91/210000 = 1.72481e-5
        assert!((contact_modulus_mpa(&al, &st) - 57_977.0).abs() < 2.0);
    }

    #[test]
    fn friction_splits_loading_and_unloading() {
        let (l, u) = rod_force(100.0, 0.5, 0.1);
        assert!((l.unwrap() - 100.0 * 0.6_f64.tan()).abs() < 1e-12);
        assert!((u - 100.0 * 0.4_f64.tan()).abs() < 1e-12);
        assert_eq!(rod_force(100.0, 1.5, 0.1).0, None);
    }
}
