//! The design pipeline: a [`Spec`] in, validated, and a complete [`Design`] out.
//!
//! Spec -> law (solved or given) -> pitch curve (virtual work with preload and friction
//! correction) -> cam surface (roller offset) -> predicted forces -> checks. Pure computation:
//! no files, no printing.

use crate::cam::checks::{run_checks, Check, CheckInput, Status};
use crate::cam::forces::{contact_modulus_mpa, predict, ContactModel, RodForce};
use crate::cam::pitch_curve::{synthesize, CamError, PitchCurve, SynthesisOptions};
use crate::cam::surface::{offset, CamSurface};
use crate::law::{check_law, solve, solve_conditions, LawError, SolvedLaw};
use crate::model::{ForceLaw, LawSpec, Spec, SpecError};

/// Number of arc-length steps the stroke is at least divided into (for smooth plots).
pub const MIN_SAMPLES_PER_STROKE: f64 = 250.0;

/// Why a spec could not be turned into a design.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DesignError {
    /// Produced by [`design`] when the spec breaks a rule of [`Spec::validate`].
    #[error("spec: {0}")]
    Spec(#[from] SpecError),
    /// Produced by [`design`] when the law cannot be solved or realised.
    #[error("force law: {0}")]
    Law(#[from] LawError),
    /// Produced by [`design`] when no pitch curve can follow the law with these followers.
    #[error("cam synthesis: {0}")]
    Cam(#[from] CamError),
}

/// A complete design.
#[derive(Debug, Clone)]
pub struct Design {
    /// The spec it was made from.
    pub spec: Spec,
    /// The law.
    pub law: SolvedLaw,
    /// The roller-centre path.
    pub pitch_curve: PitchCurve,
    /// The machined surface.
    pub cam_surface: CamSurface,
    /// Predicted forces and contact stress at each sample.
    pub forces: Vec<RodForce>,
    /// Check results.
    pub checks: Vec<Check>,
}

impl Design {
    /// The worst status over all checks.
    pub fn status(&self) -> Status {
        self.checks
            .iter()
            .map(|c| c.status)
            .max()
            .unwrap_or(Status::Pass)
    }

    /// The stroke.
    pub fn xmax_mm(&self) -> f64 {
        self.spec.law.xmax_mm()
    }

    /// The peak Hertz contact pressure over the stroke (None where a sample has none).
    pub fn max_contact_stress_mpa(&self) -> Option<f64> {
        self.forces
            .iter()
            .map(|f| f.contact_stress_mpa)
            .try_fold(0.0_f64, |m, p| p.map(|p| m.max(p)))
    }
}

/// The sampling options a spec asks for.
pub fn synthesis_options(spec: &Spec) -> SynthesisOptions {
    SynthesisOptions {
        chord_tolerance_mm: spec.output.chord_tolerance_mm,
        max_step_mm: spec.law.xmax_mm() / MIN_SAMPLES_PER_STROKE,
    }
}

/// Solves or takes the law of a spec.
pub fn law_of(spec: &Spec) -> Result<SolvedLaw, LawError> {
    match &spec.law {
        LawSpec::Targets(t) => solve(t),
        LawSpec::Given { law, .. } => {
            check_law(law)?;
            Ok(SolvedLaw::as_given(ForceLaw::Exponential(*law)))
        }
        LawSpec::Conditions {
            conditions,
            xmax_mm,
        } => solve_conditions(conditions, *xmax_mm),
        LawSpec::Table { table, .. } => Ok(SolvedLaw::as_given(ForceLaw::Table(table.clone()))),
        LawSpec::Polynomial { law, .. } => {
            Ok(SolvedLaw::as_given(ForceLaw::Polynomial(law.clone())))
        }
    }
}

/// Runs the whole design.
///
/// ```
/// use camspring::{design, spec::DEFAULT_SPEC_TOML, Spec};
/// let d = design(&Spec::from_toml(DEFAULT_SPEC_TOML).unwrap()).unwrap();
/// assert!((d.law.alpha.unwrap() - 1.3201914760).abs() < 1e-9);
/// assert!(d.pitch_curve.lift_mm() > 0.0);
/// ```
pub fn design(spec: &Spec) -> Result<Design, DesignError> {
    design_with(spec, true)
}

/// Runs the whole design; with `advise` false a failing check gets no advice (no
/// re-synthesis), which is what a sweep over many designs wants.
pub fn design_with(spec: &Spec, advise: bool) -> Result<Design, DesignError> {
    spec.validate()?;
    let law = law_of(spec)?;
    let options = synthesis_options(spec);
    let follower = &spec.follower;
    let xmax = spec.law.xmax_mm();
    let pitch_curve = synthesize(&law.law, follower, xmax, &options)?;
    let cam_surface = offset(
        &pitch_curve,
        follower.roller_radius_mm,
        2.0 * options.chord_tolerance_mm,
    );
    let contact = ContactModel {
        e_star_mpa: contact_modulus_mpa(&spec.part.cam_material, &spec.part.roller_material),
        length_mm: spec.part.contact_length_mm(),
    };
    let forces = predict(&law.law, follower, &pitch_curve, &cam_surface, &contact);
    let checks = run_checks(&CheckInput {
        law: &law.law,
        follower,
        xmax_mm: xmax,
        options,
        limits: &spec.checks,
        plate_thickness_mm: spec.part.thickness_mm,
        roller_width_mm: spec.part.roller_width_mm,
        contact,
        advise,
        tool_radius_mm: spec.machining.tool_diameter_mm / 2.0,
        pitch: &pitch_curve,
        surface: &cam_surface,
        forces: &forces,
    });
    Ok(Design {
        spec: spec.clone(),
        law,
        pitch_curve,
        cam_surface,
        forces,
        checks,
    })
}
