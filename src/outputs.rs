//! What a design run makes, decided in one place: [`plan`] builds the part and the tool path
//! from a [`Design`], decides which files exist and sets the overall status (a refused part or
//! program is recorded with its reason; a refused program fails the design). Pure: exporters
//! only serialise what the plan holds (see [`crate::export::write_design`]).

use serde::Serialize;
use stl_io::Triangle;

use crate::cam::checks::{l10_strokes, roller_duty, Check, Status};
use crate::cam::tolerance::{force_band, ForceBand};
use crate::design::Design;
use crate::law::Residuals;
use crate::model::{Dialect, ForceLaw, FrictionCorrection, Spec, SpringArrangement};
use crate::part::mesh::{self, StlError};
use crate::part::{self, Part, PartError};
use crate::toolpath::{self, Job, ToolpathError, ToolpathSummary};

/// The design files every run writes.
pub const DESIGN_OUTPUTS: [&str; 5] = [
    "design.json",
    "report.html",
    "profile.csv",
    "force.svg",
    "profile.svg",
];

/// The part files, written when the cam surface can be followed.
pub const PART_OUTPUTS: [&str; 5] = [
    "cam.step",
    "cam.stl",
    "cam.dxf",
    "drawing.svg",
    "drawing.pdf",
];

/// The machining files, written when the part can be milled with the cutter.
pub const GCODE_OUTPUTS: [&str; 2] = ["cam.ngc", "toolpath.svg"];

/// Every file a design run can make.
pub const ALL_OUTPUTS: [&str; 12] = [
    "design.json",
    "report.html",
    "profile.csv",
    "force.svg",
    "profile.svg",
    "cam.step",
    "cam.stl",
    "cam.dxf",
    "drawing.svg",
    "drawing.pdf",
    "cam.ngc",
    "toolpath.svg",
];

/// Why no plan could be made (as opposed to a part or program refused with a reason).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// Produced by [`plan`] when the part cannot be built (a hole that does not fit, or a
    /// fit that cannot reach its tolerance).
    #[error("part: {0}")]
    Part(PartError),
    /// Produced by [`plan`] when the machining settings are unusable (a tolerance finer than
    /// the dialect writes).
    #[error("machining: {0}")]
    Toolpath(ToolpathError),
    /// Produced by [`plan`] when the part's outline cannot be meshed.
    #[error("cannot encode cam.stl: {0}")]
    Mesh(#[from] StlError),
}

/// The part and its mesh.
#[derive(Debug, Clone)]
pub struct PartPlan {
    /// The part outline with its B-spline cam edges.
    pub part: Part,
    /// The watertight mesh of `cam.stl`.
    pub mesh: Vec<Triangle>,
}

/// The machining program.
#[derive(Debug, Clone)]
pub struct Program {
    /// Each tool's drilling and tool-centre passes, in the order they run.
    pub jobs: Vec<Job>,
    /// The G-code text of `cam.ngc`.
    pub text: String,
}

/// Everything a design run makes, before any file is written.
#[derive(Debug, Clone)]
pub struct Outputs {
    /// What `design.json` holds, with the files to write and the overall status.
    pub summary: DesignSummary,
    /// The part, unless refused (`summary.part_refused` says why).
    pub part: Option<PartPlan>,
    /// The program, unless refused (`summary.gcode_refused` says why).
    pub program: Option<Program>,
}

impl Outputs {
    /// The overall status: the worst check, or Fail when the program was refused.
    pub fn status(&self) -> Status {
        self.summary.status
    }
}

/// Decides what a design run makes: the part (refused on an undercut), its mesh, the program
/// (refused when the cutter does not fit), the list of files and the status.
pub fn plan(design: &Design) -> Result<Outputs, PlanError> {
    let spec = &design.spec;
    let mut names: Vec<&str> = DESIGN_OUTPUTS.to_vec();
    let (part, part_refused) = match part::build(design) {
        Ok(part) => {
            let rings = mesh::rings(
                &part,
                spec.output.stl_tolerance_mm,
                spec.output.chord_tolerance_mm,
            );
            let mesh = mesh::mesh(&rings, part.thickness_mm)?;
            names.extend(PART_OUTPUTS);
            (Some(PartPlan { part, mesh }), None)
        }
        Err(e @ PartError::Undercut { .. }) => (None, Some(e.to_string())),
        Err(e) => return Err(PlanError::Part(e)),
    };
    let (program, gcode, gcode_refused) = match &part {
        None => (None, None, None),
        Some(p) => match toolpath::jobs(design, &p.part) {
            Ok((jobs, stats)) => {
                let (text, blocks) = toolpath::gcode::write(design, &jobs, &stats);
                names.extend(GCODE_OUTPUTS);
                let m = &spec.machining;
                let summary = GcodeSummary {
                    dialect: m.dialect,
                    arcs: m.arcs,
                    blocks,
                    toolpath: stats,
                };
                (Some(Program { jobs, text }), Some(summary), None)
            }
            Err(e @ ToolpathError::Resolution { .. }) => return Err(PlanError::Toolpath(e)),
            Err(e) => (
                None,
                None,
                Some(format!("cam.ngc and toolpath.svg are not written: {e}")),
            ),
        },
    };
    let mut summary = summarize(design, &names);
    summary.force_band = Some(force_band(
        &design.pitch_curve,
        &spec.follower,
        &spec.tolerances,
    ));
    summary.part = part.as_ref().map(|p| part_summary(spec, p));
    summary.part_refused = part_refused;
    summary.gcode = gcode;
    if gcode_refused.is_some() {
        summary.status = Status::Fail;
    }
    summary.gcode_refused = gcode_refused;
    Ok(Outputs {
        summary,
        part,
        program,
    })
}

fn part_summary(spec: &Spec, plan: &PartPlan) -> PartSummary {
    let part = &plan.part;
    let (lo, hi) = part.bounding_box_mm;
    PartSummary {
        area_mm2: part.area_mm2,
        volume_mm3: part.area_mm2 * part.thickness_mm,
        thickness_mm: part.thickness_mm,
        bounding_box_min_mm: [lo[0], lo[1], 0.0],
        bounding_box_max_mm: [hi[0], hi[1], part.thickness_mm],
        frame_dy_mm: part.frame.dy_mm,
        cam_edge_length_mm: part.cam_edge_length_mm,
        cam_edge_spans: part.cam_edges.iter().map(|e| e.points.len() - 1).collect(),
        cam_edge_fit_deviation_mm: part
            .cam_edges
            .iter()
            .map(|e| e.fit_deviation_mm)
            .fold(0.0, f64::max),
        fit_tolerance_mm: spec.output.fit_tolerance_mm,
        stl_tolerance_mm: spec.output.stl_tolerance_mm,
        stl_triangles: plan.mesh.len(),
        outline_vertices_mm: part
            .outline
            .iter()
            .map(|s| s.ends(&part.cam_edges).0)
            .collect(),
    }
}

/// The law block of `design.json`.
#[derive(Debug, Clone, Serialize)]
pub struct LawSummary {
    /// alpha = k2 * L0 (null for a given law).
    pub alpha: Option<f64>,
    /// mu (null for a table).
    pub mu_n: Option<f64>,
    /// F0 (null for a table).
    pub f0_n: Option<f64>,
    /// k2 (null for a table).
    pub k2_per_mm: Option<f64>,
    /// F(0).
    pub force_at_zero_n: f64,
    /// F(Xmax).
    pub force_at_xmax_n: f64,
    /// Relative residuals of the paper's design conditions (targets form).
    pub residuals: Option<Residuals>,
    /// How the spec states the law: `targets`, `given`, `conditions`, `polynomial` or `table`.
    pub form: &'static str,
    /// The law in one line (the formula, or the table's size and end forces).
    pub description: String,
    /// Relative residual of each condition (conditions form).
    pub condition_residuals: Option<Vec<f64>>,
    /// Table points (table form).
    pub table_points: Option<usize>,
    /// Largest relative deviation of the corrected stroke's predicted force (forward model,
    /// from the cam's geometry) from the table at the table's points (table form).
    pub table_max_rel_error: Option<f64>,
}

/// The follower block of `design.json`.
#[derive(Debug, Clone, Serialize)]
pub struct FollowerSummary {
    /// Number of followers.
    pub count: u8,
    /// Spring arrangement.
    pub spring: SpringArrangement,
    /// Rate of each spring.
    pub spring_rate_n_per_mm: f64,
    /// k_eff.
    pub k_eff_n_per_mm: f64,
    /// Preload.
    pub preload_mm: f64,
    /// Preload force of the springs, k_eff * Yp.
    pub preload_force_n: f64,
    /// Roller radius.
    pub roller_radius_mm: f64,
    /// Effective contact friction coefficient.
    pub friction_coefficient: f64,
    /// Friction angle.
    pub friction_angle_deg: f64,
    /// Correction.
    pub friction_correction: FrictionCorrection,
}

/// The springs to buy: per physical spring.
#[derive(Debug, Clone, Serialize)]
pub struct SpringSummary {
    /// Physical springs (one per follower, or one shared by two).
    pub count: u8,
    /// Rate of each.
    pub rate_n_per_mm: f64,
    /// Deflection of each at preload (the stroke's start).
    pub deflection_at_preload_mm: f64,
    /// Deflection of each at the full stroke.
    pub deflection_at_full_stroke_mm: f64,
    /// Working travel of each over the stroke.
    pub travel_mm: f64,
    /// Force of each at preload.
    pub force_at_preload_n: f64,
    /// Force of each at the full stroke.
    pub force_at_full_stroke_n: f64,
}

/// The rollers to buy: per roller.
#[derive(Debug, Clone, Serialize)]
pub struct RollerSummary {
    /// Rollers.
    pub count: u8,
    /// Largest normal load on one roller over the stroke.
    pub peak_normal_load_n: f64,
    /// Where.
    pub peak_at_x_mm: f64,
    /// ISO 281 mean equivalent load over a stroke (exponent 10/3 over the revolutions).
    pub mean_equivalent_load_n: f64,
    /// Revolutions per full stroke (out and back).
    pub revolutions_per_stroke: f64,
    /// Roller speed at `follower.stroke_rate` (null when not given).
    pub speed_rpm: Option<f64>,
    /// Basic rating life at `follower.roller_dynamic_load` (null when not given).
    pub l10_strokes: Option<f64>,
}

/// The profile block of `design.json`.
#[derive(Debug, Clone, Serialize)]
pub struct ProfileSummary {
    /// Stroke.
    pub xmax_mm: f64,
    /// Follower lift at Xmax.
    pub lift_mm: f64,
    /// Largest pressure angle.
    pub max_pressure_angle_deg: f64,
    /// Where.
    pub max_pressure_angle_at_x_mm: f64,
    /// Smallest pitch-curve radius towards the material (null: never bends that way).
    pub min_pitch_radius_material_side_mm: Option<f64>,
    /// Smallest concave radius of the surface (largest cutter radius).
    pub min_concave_surface_radius_mm: Option<f64>,
    /// Smallest convex radius of the surface.
    pub min_convex_surface_radius_mm: Option<f64>,
    /// Predicted loading force at Xmax (null: jammed).
    pub loading_force_at_xmax_n: Option<f64>,
    /// Predicted unloading force at Xmax.
    pub unloading_force_at_xmax_n: f64,
    /// Largest relative deviation of the corrected stroke's predicted force from the law.
    pub corrected_stroke_max_rel_error: Option<f64>,
    /// Peak contact pressure over the stroke.
    pub max_contact_stress_mpa: Option<f64>,
    /// Number of samples.
    pub samples: usize,
    /// Chord tolerance of the sampled curves.
    pub chord_tolerance_mm: f64,
}

/// The part block of `design.json`.
#[derive(Debug, Clone, Serialize)]
pub struct PartSummary {
    /// Outline area minus holes (Green's theorem on the exact edges).
    pub area_mm2: f64,
    /// Area times thickness.
    pub volume_mm3: f64,
    /// Plate thickness.
    pub thickness_mm: f64,
    /// Bounding box minimum corner (x, y, z).
    pub bounding_box_min_mm: [f64; 3],
    /// Bounding box maximum corner (x, y, z).
    pub bounding_box_max_mm: [f64; 3],
    /// Added to design-frame y to get part y (mirrored for the lower edge).
    pub frame_dy_mm: f64,
    /// Length of the cam edges.
    pub cam_edge_length_mm: f64,
    /// Bezier spans of each cam edge's B-spline.
    pub cam_edge_spans: Vec<usize>,
    /// Largest deviation of the B-spline from the exact surface, as checked.
    pub cam_edge_fit_deviation_mm: f64,
    /// Fit tolerance asked.
    pub fit_tolerance_mm: f64,
    /// STL chord tolerance asked.
    pub stl_tolerance_mm: f64,
    /// Outline corner points, counter-clockwise, where segments meet.
    pub outline_vertices_mm: Vec<[f64; 2]>,
    /// Triangles in cam.stl.
    pub stl_triangles: usize,
}

/// The G-code block of `design.json`.
#[derive(Debug, Clone, Serialize)]
pub struct GcodeSummary {
    /// Dialect written.
    pub dialect: Dialect,
    /// Arcs (G2/G3) or lines only.
    pub arcs: bool,
    /// Blocks (lines that are not comments).
    pub blocks: usize,
    /// Path statistics.
    #[serde(flatten)]
    pub toolpath: ToolpathSummary,
}

/// Everything in `design.json` (and `design --json`).
#[derive(Debug, Clone, Serialize)]
pub struct DesignSummary {
    /// Tool version.
    pub camspring_version: &'static str,
    /// Design name.
    pub name: String,
    /// The run's identity ([`Spec::run_id`]), also in the header of every output file that
    /// has one.
    pub run_id: String,
    /// Overall status: the worst check.
    pub status: Status,
    /// The spec as understood, in default units.
    pub spec: Spec,
    /// The law.
    pub law: LawSummary,
    /// The followers.
    pub follower: FollowerSummary,
    /// The springs to buy, per physical spring.
    pub springs: SpringSummary,
    /// The rollers to buy, per roller (null for a knife edge).
    pub rollers: Option<RollerSummary>,
    /// The 95 % band of the rod force over builds within the spec's tolerances (null until
    /// [`plan`] computes it).
    pub force_band: Option<ForceBand>,
    /// Profile numbers.
    pub profile: ProfileSummary,
    /// Checks.
    pub checks: Vec<Check>,
    /// The part (null when refused).
    pub part: Option<PartSummary>,
    /// Why the part files were not written (an undercut), if they were not.
    pub part_refused: Option<String>,
    /// The G-code program (null when refused or no part).
    pub gcode: Option<GcodeSummary>,
    /// Why cam.ngc was not written, if it was not.
    pub gcode_refused: Option<String>,
    /// Files written, relative to the output folder.
    pub outputs: Vec<String>,
}

/// The largest relative deviation of the corrected stroke's predicted force from the law.
pub fn corrected_stroke_error(design: &Design) -> Option<f64> {
    let corr = design.spec.follower.friction_correction;
    let frictionless = design.spec.follower.friction_coefficient() == 0.0;
    design
        .forces
        .iter()
        .map(|f| {
            let predicted = match (corr, frictionless) {
                (_, true) | (FrictionCorrection::Loading, _) => f.loading_n,
                (FrictionCorrection::Unloading, _) => Some(f.unloading_n),
                (FrictionCorrection::Midline, _) => f.loading_n.map(|l| 0.5 * (l + f.unloading_n)),
                (FrictionCorrection::None, false) => return None,
            };
            predicted.map(|p| ((p - f.design_n) / f.design_n).abs())
        })
        .try_fold(0.0_f64, |m, e| e.map(|e| m.max(e)))
}

/// The largest relative deviation of the corrected stroke's predicted force from a table law
/// at the table's points within the stroke (forward model at the pitch samples, linearly
/// between the two samples around each point).
pub fn table_error(design: &Design) -> Option<f64> {
    let ForceLaw::Table(t) = &design.law.law else {
        return None;
    };
    let corr = design.spec.follower.friction_correction;
    let predicted = |f: &crate::cam::forces::RodForce| match corr {
        FrictionCorrection::Unloading => Some(f.unloading_n),
        FrictionCorrection::Midline => f.loading_n.map(|l| 0.5 * (l + f.unloading_n)),
        FrictionCorrection::Loading | FrictionCorrection::None => f.loading_n,
    };
    let xmax = design.xmax_mm();
    t.points()
        .filter(|&(x, _)| x <= xmax)
        .map(|(x, force)| {
            let i = design.forces.partition_point(|f| f.x_mm < x);
            let (a, b) = (
                &design.forces[i.saturating_sub(1)],
                &design.forces[i.min(design.forces.len() - 1)],
            );
            let (pa, pb) = (predicted(a)?, predicted(b)?);
            let w = if b.x_mm > a.x_mm {
                (x - a.x_mm) / (b.x_mm - a.x_mm)
            } else {
                0.0
            };
            Some(((pa + w * (pb - pa) - force) / force).abs())
        })
        .try_fold(0.0_f64, |m, e| e.map(|e| m.max(e)))
}

/// Builds the summary of a design.
pub fn summarize(design: &Design, outputs: &[&str]) -> DesignSummary {
    let spec = &design.spec;
    let f = &spec.follower;
    let law = &design.law.law;
    let xmax = design.xmax_mm();
    let (theta, theta_at) = design.pitch_curve.max_pressure_angle();
    let last = design.forces.last().expect("a design has samples");
    DesignSummary {
        camspring_version: env!("CARGO_PKG_VERSION"),
        name: spec.name.clone(),
        run_id: spec.run_id(),
        status: design.status(),
        spec: spec.clone(),
        law: LawSummary {
            alpha: design.law.alpha,
            mu_n: law.exponential().map(|l| l.mu_n),
            f0_n: law.exponential().map(|l| l.f0_n),
            k2_per_mm: law.exponential().map(|l| l.k2_per_mm),
            force_at_zero_n: law.force_n(0.0),
            force_at_xmax_n: law.force_n(xmax),
            residuals: design.law.residuals,
            form: spec.law.form(),
            description: law.describe(),
            condition_residuals: design.law.condition_residuals.clone(),
            table_points: match law {
                ForceLaw::Table(t) => Some(t.x_mm.len()),
                ForceLaw::Exponential(_) | ForceLaw::Polynomial(_) => None,
            },
            table_max_rel_error: table_error(design),
        },
        follower: FollowerSummary {
            count: f.count,
            spring: f.arrangement,
            spring_rate_n_per_mm: f.spring_rate_n_per_mm,
            k_eff_n_per_mm: f.k_eff_n_per_mm(),
            preload_mm: f.preload_mm,
            preload_force_n: f.k_eff_n_per_mm() * f.preload_mm,
            roller_radius_mm: f.roller_radius_mm,
            friction_coefficient: f.friction_coefficient(),
            friction_angle_deg: f.friction_angle_rad().to_degrees(),
            friction_correction: f.friction_correction,
        },
        springs: {
            let (count, at_preload) = f.springs(0.0);
            let (_, at_full) = f.springs(design.pitch_curve.lift_mm());
            SpringSummary {
                count,
                rate_n_per_mm: f.spring_rate_n_per_mm,
                deflection_at_preload_mm: at_preload,
                deflection_at_full_stroke_mm: at_full,
                travel_mm: at_full - at_preload,
                force_at_preload_n: f.spring_rate_n_per_mm * at_preload,
                force_at_full_stroke_n: f.spring_rate_n_per_mm * at_full,
            }
        },
        rollers: roller_duty(f, &design.cam_surface, &design.forces).map(|d| RollerSummary {
            count: f.count,
            peak_normal_load_n: d.peak_load_n,
            peak_at_x_mm: d.peak_at_x_mm,
            mean_equivalent_load_n: d.mean_load_n,
            revolutions_per_stroke: d.revolutions_per_stroke,
            speed_rpm: f
                .bearing
                .stroke_rate_hz
                .map(|hz| d.revolutions_per_stroke * hz * 60.0),
            l10_strokes: f.bearing.dynamic_load_n.map(|c| l10_strokes(c, &d)),
        }),
        force_band: None,
        profile: ProfileSummary {
            xmax_mm: xmax,
            lift_mm: design.pitch_curve.lift_mm(),
            max_pressure_angle_deg: theta,
            max_pressure_angle_at_x_mm: theta_at,
            min_pitch_radius_material_side_mm: design
                .pitch_curve
                .min_material_side_radius()
                .map(|r| r.0),
            min_concave_surface_radius_mm: design
                .cam_surface
                .min_concave_radius(&design.pitch_curve)
                .map(|r| r.0),
            min_convex_surface_radius_mm: design
                .cam_surface
                .min_convex_radius(&design.pitch_curve)
                .map(|r| r.0),
            loading_force_at_xmax_n: last.loading_n,
            unloading_force_at_xmax_n: last.unloading_n,
            corrected_stroke_max_rel_error: corrected_stroke_error(design),
            max_contact_stress_mpa: design.max_contact_stress_mpa(),
            samples: design.pitch_curve.samples.len(),
            chord_tolerance_mm: spec.output.chord_tolerance_mm,
        },
        checks: design.checks.clone(),
        part: None,
        part_refused: None,
        gcode: None,
        gcode_refused: None,
        outputs: outputs.iter().map(|s| s.to_string()).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_planned_name_is_one_of_all_outputs_and_each_once() {
        let planned: Vec<&str> = DESIGN_OUTPUTS
            .iter()
            .chain(&PART_OUTPUTS)
            .chain(&GCODE_OUTPUTS)
            .copied()
            .collect();
        let mut sorted = planned.clone();
        sorted.sort();
        sorted.dedup();
        assert_eq!(sorted.len(), planned.len());
        let mut all = ALL_OUTPUTS.to_vec();
        all.sort();
        assert_eq!(sorted, all);
    }
}
