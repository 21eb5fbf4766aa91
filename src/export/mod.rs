//! Writing a design to files: `design.json`, `profile.csv`, `force.svg`, `profile.svg`.
//!
//! Exporters read the design and never change it. Every file is written to a temporary file
//! in the same folder and renamed into place, so an interrupted run leaves either the old file
//! or the new one, never a half-written one.

pub mod drawing;
pub mod dxf;
pub mod html;
pub mod plot;
pub mod step;
pub mod stl;

use std::io::Write;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::cam::checks::{Check, Status};
use crate::cam::follower::{FrictionCorrection, SpringArrangement};
use crate::design::Design;
use crate::error::{Error, Result};
use crate::law::Residuals;
use crate::part::{self, Part, PartError};
use crate::spec::Spec;
use crate::toolpath::{self, ToolpathError, ToolpathSummary};
use plot::{Panel, Series};

/// Writes `bytes` to `path` atomically (temporary file in the same folder, then rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let wrap = |source| Error::Write {
        path: path.to_path_buf(),
        source,
    };
    std::fs::create_dir_all(dir).map_err(wrap)?;
    let mut builder = tempfile::Builder::new();
    builder.prefix(".camspring-").suffix(".tmp");
    #[cfg(unix)]
    {
        // tempfile creates 0600; outputs are ordinary readable files.
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o644));
    }
    let mut tmp = builder.tempfile_in(dir).map_err(wrap)?;
    tmp.write_all(bytes).map_err(wrap)?;
    tmp.as_file().sync_all().map_err(wrap)?;
    tmp.persist(path).map_err(|e| wrap(e.error))?;
    Ok(())
}

/// The law block of `design.json`.
#[derive(Debug, Clone, Serialize)]
pub struct LawSummary {
    /// alpha = k2 * L0 (null for a given law).
    pub alpha: Option<f64>,
    /// mu.
    pub mu_n: f64,
    /// F0.
    pub f0_n: f64,
    /// k2.
    pub k2_per_mm: f64,
    /// F(0) = mu + F0.
    pub force_at_zero_n: f64,
    /// F(Xmax).
    pub force_at_xmax_n: f64,
    /// Relative residuals of the design conditions.
    pub residuals: Option<Residuals>,
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
    pub dialect: crate::spec::Dialect,
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
    /// Overall status: the worst check.
    pub status: Status,
    /// The spec as understood, in default units.
    pub spec: Spec,
    /// The law.
    pub law: LawSummary,
    /// The followers.
    pub follower: FollowerSummary,
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
        status: design.status(),
        spec: spec.clone(),
        law: LawSummary {
            alpha: design.law.alpha,
            mu_n: law.mu_n,
            f0_n: law.f0_n,
            k2_per_mm: law.k2_per_mm,
            force_at_zero_n: law.force_n(0.0),
            force_at_xmax_n: law.force_n(xmax),
            residuals: design.law.residuals,
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
            max_contact_stress_mpa: design
                .forces
                .iter()
                .map(|f| f.contact_stress_mpa)
                .try_fold(0.0_f64, |m, p| p.map(|p| m.max(p))),
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

/// The header of `profile.csv`.
pub const PROFILE_CSV_HEADER: [&str; 9] = [
    "x_mm",
    "pitch_y_mm",
    "surface_x_mm",
    "surface_y_mm",
    "pressure_angle_deg",
    "force_design_n",
    "force_loading_n",
    "force_unloading_n",
    "stiffness_n_per_mm",
];

/// `profile.csv`: one row per pitch sample.
pub fn profile_csv(design: &Design) -> Result<Vec<u8>> {
    let enc = |e: csv::Error| Error::Encode {
        what: "profile.csv",
        message: e.to_string(),
    };
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record(PROFILE_CSV_HEADER).map_err(enc)?;
    for ((s, p), f) in design
        .pitch_curve
        .samples
        .iter()
        .zip(&design.cam_surface.points)
        .zip(&design.forces)
    {
        let num = |v: f64| format!("{v:.9}");
        w.write_record([
            num(s.x_mm),
            num(s.y_mm),
            num(p.x_mm),
            num(p.y_mm),
            num(s.theta_rad.to_degrees()),
            num(f.design_n),
            f.loading_n.map(num).unwrap_or_default(),
            num(f.unloading_n),
            num(f.stiffness_n_per_mm),
        ])
        .map_err(enc)?;
    }
    w.into_inner().map_err(|e| Error::Encode {
        what: "profile.csv",
        message: e.to_string(),
    })
}

/// `force.svg`: force against deflection (design, loading, unloading) and stiffness against force.
pub fn force_svg(design: &Design) -> String {
    let law = &design.law.law;
    let pts = |f: &dyn Fn(&crate::cam::forces::RodForce) -> Option<(f64, f64)>| {
        design.forces.iter().filter_map(f).collect::<Vec<_>>()
    };
    let force = Panel {
        title: "Rod force".into(),
        x_label: "deflection x (mm)".into(),
        y_label: "force F (N)".into(),
        series: vec![
            Series {
                label: "designed law".into(),
                points: pts(&|f| Some((f.x_mm, f.design_n))),
                color: "#000",
                dashed: false,
                dots: false,
            },
            Series {
                label: "predicted loading".into(),
                points: pts(&|f| f.loading_n.map(|l| (f.x_mm, l))),
                color: "#c62828",
                dashed: true,
                dots: false,
            },
            Series {
                label: "predicted unloading".into(),
                points: pts(&|f| Some((f.x_mm, f.unloading_n))),
                color: "#1565c0",
                dashed: true,
                dots: false,
            },
        ],
        ..Panel::default()
    };
    // Loading stiffness from central differences of the predicted loading force.
    let loading_stiffness: Vec<(f64, f64)> = design
        .forces
        .windows(3)
        .filter_map(|w| match (w[0].loading_n, w[1].loading_n, w[2].loading_n) {
            (Some(a), Some(b), Some(c)) if w[2].x_mm > w[0].x_mm => {
                Some((b, (c - a) / (w[2].x_mm - w[0].x_mm)))
            }
            _ => None,
        })
        .collect();
    let stiffness = Panel {
        title: "Stiffness against force".into(),
        x_label: "force F (N)".into(),
        y_label: "stiffness dF/dx (N/mm)".into(),
        series: vec![
            Series {
                label: format!(
                    "designed: {:.4}/mm x (F - {:.3} N)",
                    law.k2_per_mm, law.f0_n
                ),
                points: pts(&|f| Some((f.design_n, f.stiffness_n_per_mm))),
                color: "#000",
                dashed: false,
                dots: false,
            },
            Series {
                label: "predicted loading".into(),
                points: loading_stiffness,
                color: "#c62828",
                dashed: true,
                dots: false,
            },
        ],
        ..Panel::default()
    };
    plot::document(&[force, stiffness], 560.0, 420.0).to_string()
}

/// `profile.svg`: pitch curve, cam surface and the roller at a few positions, to scale.
pub fn profile_svg(design: &Design) -> String {
    let samples = &design.pitch_curve.samples;
    let r = design.spec.follower.roller_radius_mm;
    let circles = (0..=4)
        .map(|i| {
            let idx = (samples.len() - 1) * i / 4;
            (samples[idx].x_mm, samples[idx].y_mm, r)
        })
        .filter(|c| c.2 > 0.0)
        .collect();
    let panel = Panel {
        title: format!(
            "Cam profile of '{}' (roller radius {} mm)",
            design.spec.name, r
        ),
        x_label: "cam x (mm)".into(),
        y_label: "follower lift y (mm)".into(),
        series: vec![
            Series {
                label: "pitch curve (roller centre)".into(),
                points: samples.iter().map(|s| (s.x_mm, s.y_mm)).collect(),
                color: "#1565c0",
                dashed: true,
                dots: false,
            },
            Series {
                label: "cam surface".into(),
                points: design
                    .cam_surface
                    .points
                    .iter()
                    .map(|p| (p.x_mm, p.y_mm))
                    .collect(),
                color: "#000",
                dashed: false,
                dots: false,
            },
        ],
        circles,
        equal_aspect: true,
        log_axes: false,
    };
    plot::document(&[panel], 760.0, 560.0).to_string()
}

/// Names of the design files [`write_design`] always writes.
pub const DESIGN_OUTPUTS: [&str; 5] = [
    "design.json",
    "report.html",
    "profile.csv",
    "force.svg",
    "profile.svg",
];

/// The G-code program and tool-path plot of a part, in memory.
pub fn gcode_files(
    design: &Design,
    part: &Part,
) -> Result<(GcodeSummary, Vec<NamedFile>), ToolpathError> {
    let (passes, stats) = toolpath::passes(design, part)?;
    let (text, blocks) = toolpath::gcode::write(design, &passes, &stats);
    let svg = toolpath_svg(design, part, &passes);
    let m = &design.spec.machining;
    Ok((
        GcodeSummary {
            dialect: m.dialect,
            arcs: m.arcs,
            blocks,
            toolpath: stats,
        },
        vec![
            ("cam.ngc", text.into_bytes()),
            ("toolpath.svg", svg.into_bytes()),
        ],
    ))
}

/// `toolpath.svg`: the part outline with the finishing and last roughing passes, to scale.
pub fn toolpath_svg(design: &Design, part: &Part, passes: &[toolpath::Pass]) -> String {
    let mut outline: Vec<(f64, f64)> = part
        .outline_polygon()
        .iter()
        .map(|p| (p[0], p[1]))
        .collect();
    if let Some(&first) = outline.first() {
        outline.push(first);
    }
    let mut series = vec![Series {
        label: "part outline".into(),
        points: outline,
        color: "#000",
        dashed: false,
        dots: false,
    }];
    let deepest_rough = passes
        .iter()
        .filter(|p| !p.finishing)
        .map(|p| p.z_mm)
        .fold(f64::INFINITY, f64::min);
    let mut rapids = Vec::new();
    for p in passes
        .iter()
        .filter(|p| p.finishing || p.z_mm == deepest_rough)
    {
        let mut pts = vec![(p.entry[0], p.entry[1])];
        let mut from = p.entry;
        for mv in &p.moves {
            pts.extend(
                toolpath::path::sample_move(from, mv, 12)
                    .into_iter()
                    .skip(1)
                    .map(|q| (q[0], q[1])),
            );
            from = mv.to();
        }
        rapids.push((from[0], from[1]));
        rapids.push((p.entry[0], p.entry[1]));
        let (label, color) = if p.finishing {
            ("finishing (tool centre)", "#c62828")
        } else {
            ("roughing (tool centre)", "#1565c0")
        };
        let label = if series.iter().any(|s| s.label == label) {
            String::new()
        } else {
            label.to_string()
        };
        series.push(Series {
            label,
            points: pts,
            color,
            dashed: false,
            dots: false,
        });
    }
    series.push(Series {
        label: "rapids".into(),
        points: rapids,
        color: "#999",
        dashed: true,
        dots: false,
    });
    let panel = Panel {
        title: format!(
            "Tool path of '{}': {} mm cutter, {} ({} dialect)",
            design.spec.name,
            design.spec.machining.tool_diameter_mm,
            if design.spec.machining.climb {
                "climb"
            } else {
                "conventional"
            },
            toolpath::gcode::dialect_name(design.spec.machining.dialect)
        ),
        x_label: "x (mm)".into(),
        y_label: "y (mm)".into(),
        series,
        equal_aspect: true,
        log_axes: false,
        ..Panel::default()
    };
    plot::document(&[panel], 820.0, 640.0).to_string()
}

/// An output file in memory: its name in the output folder and its bytes.
pub type NamedFile = (&'static str, Vec<u8>);

/// The part files of a design, in memory, with the part's summary.
pub fn part_files(design: &Design, part: &Part) -> Result<(PartSummary, Vec<NamedFile>)> {
    let enc = |what: &'static str| move |e: String| Error::Encode { what, message: e };
    let spec = &design.spec;
    let step = step::step_text(part, &spec.name).map_err(|e| enc("cam.step")(e.to_string()))?;
    let rings = stl::rings(
        part,
        spec.output.stl_tolerance_mm,
        spec.output.chord_tolerance_mm,
    );
    let tris = stl::mesh(&rings, part.thickness_mm).map_err(|e| enc("cam.stl")(e.to_string()))?;
    let dxf = dxf::dxf_bytes(part).map_err(enc("cam.dxf"))?;
    let drawing = drawing::drawing_svg(design, part);
    let (lo, hi) = part.bounding_box_mm;
    let summary = PartSummary {
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
        stl_triangles: tris.len(),
        outline_vertices_mm: part
            .outline
            .iter()
            .map(|s| s.ends(&part.cam_edges).0)
            .collect(),
    };
    let files = vec![
        ("cam.step", step.into_bytes()),
        ("cam.stl", stl::stl_bytes(&tris)),
        ("cam.dxf", dxf),
        ("drawing.svg", drawing.into_bytes()),
    ];
    Ok((summary, files))
}

/// Writes all outputs into `dir` and returns the summary and the paths written. The part
/// files are refused (not written, and the reason recorded) when the cam surface undercuts.
pub fn write_design(design: &Design, dir: &Path) -> Result<(DesignSummary, Vec<PathBuf>)> {
    let mut gcode = (None, None);
    let (part_summary, part_refused, mut part_files) = match part::build(design) {
        Ok(part) => {
            let (summary, files) = part_files(design, &part)?;
            gcode = match gcode_files(design, &part) {
                Ok((g, f)) => (Some((g, f)), None),
                Err(e @ ToolpathError::Resolution { .. }) => return Err(Error::Toolpath(e)),
                Err(e) => (
                    None,
                    Some(format!("cam.ngc and toolpath.svg are not written: {e}")),
                ),
            };
            (Some(summary), None, files)
        }
        Err(e @ PartError::Undercut { .. }) => (None, Some(e.to_string()), Vec::new()),
        Err(e) => return Err(Error::Part(e)),
    };
    let (gcode_summary, gcode_refused) = match gcode {
        (Some((g, files)), r) => {
            part_files.extend(files);
            (Some(g), r)
        }
        (None, r) => (None, r),
    };
    let mut names: Vec<&str> = DESIGN_OUTPUTS.to_vec();
    names.extend(part_files.iter().map(|f| f.0));
    let mut summary = summarize(design, &names);
    summary.part = part_summary;
    summary.part_refused = part_refused;
    summary.gcode = gcode_summary;
    if gcode_refused.is_some() {
        summary.status = Status::Fail;
    }
    summary.gcode_refused = gcode_refused;
    let json = serde_json::to_vec_pretty(&summary).map_err(|e| Error::Encode {
        what: "design.json",
        message: e.to_string(),
    })?;
    let (force, profile) = (force_svg(design), profile_svg(design));
    let report = html::report_html(design, &summary, &force, &profile);
    let mut files: Vec<(&str, Vec<u8>)> = vec![
        ("profile.csv", profile_csv(design)?),
        ("force.svg", force.into_bytes()),
        ("profile.svg", profile.into_bytes()),
    ];
    files.extend(part_files);
    files.push(("report.html", report.into_bytes()));
    // design.json last: its presence with this run's content marks a complete set.
    files.push(("design.json", json));
    let mut written = Vec::new();
    for (name, bytes) in files {
        let path = dir.join(name);
        write_atomic(&path, &bytes)?;
        written.push(path);
    }
    Ok((summary, written))
}
