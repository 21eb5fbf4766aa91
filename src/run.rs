//! The commands behind the CLI, as library functions: load a spec, run a design, write its
//! outputs and format what the user reads. `main.rs` only parses arguments and prints.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::cam::checks::Status;
use crate::design::design;
use crate::error::{Error, Result};
use crate::export::{write_design, DesignSummary};
use crate::spec::{Spec, DEFAULT_SPEC_TOML};

/// Exit code: design done, all checks pass or warn.
pub const EXIT_OK: u8 = 0;
/// Exit code: a design check failed (outputs are still written and marked).
pub const EXIT_CHECK_FAILED: u8 = 1;
/// Exit code: bad input (spec, log or arguments).
pub const EXIT_BAD_INPUT: u8 = 2;
/// Exit code: the machine failed us (an output could not be written).
pub const EXIT_IO: u8 = 3;

/// Reads a spec file, or the built-in default spec when `path` is None.
pub fn load_spec(path: Option<&Path>) -> Result<Spec> {
    match path {
        None => Spec::from_toml(DEFAULT_SPEC_TOML).map_err(|source| Error::Spec {
            path: "built-in default (specs/paper.toml)".into(),
            source,
        }),
        Some(p) => {
            let text = std::fs::read_to_string(p).map_err(|source| Error::Read {
                path: p.to_path_buf(),
                source,
            })?;
            Spec::from_toml(&text).map_err(|source| Error::Spec {
                path: p.display().to_string(),
                source,
            })
        }
    }
}

/// The result of `camspring design`.
#[derive(Debug, Clone)]
pub struct DesignRun {
    /// What design.json holds.
    pub summary: DesignSummary,
    /// The folder written to.
    pub out_dir: PathBuf,
    /// The files written.
    pub written: Vec<PathBuf>,
}

impl DesignRun {
    /// The exit code for this run.
    pub fn exit_code(&self) -> u8 {
        if self.summary.status == Status::Fail {
            EXIT_CHECK_FAILED
        } else {
            EXIT_OK
        }
    }
}

/// Runs `camspring design`: spec (or the default) to outputs in `out_dir` (default `out/<name>`).
pub fn run_design(spec_path: Option<&Path>, out_dir: Option<&Path>) -> Result<DesignRun> {
    let spec = load_spec(spec_path)?;
    let design = design(&spec)?;
    let out_dir = out_dir
        .map(Path::to_path_buf)
        .unwrap_or_else(|| Path::new("out").join(&spec.name));
    let (summary, written) = write_design(&design, &out_dir)?;
    Ok(DesignRun {
        summary,
        out_dir,
        written,
    })
}

/// The human-readable report of a design run.
pub fn format_design(run: &DesignRun) -> String {
    let s = &run.summary;
    let mut o = String::new();
    let _ = writeln!(o, "camspring design '{}'", s.name);
    let l = &s.law;
    match l.alpha {
        Some(a) => {
            let _ = writeln!(
                o,
                "  law      F = {:.7} N * exp({:.7} /mm * x) + {:.7} N   (alpha = {:.10})",
                l.mu_n, l.k2_per_mm, l.f0_n, a
            );
        }
        None => {
            let _ = writeln!(
                o,
                "  law      F = {:.7} N * exp({:.7} /mm * x) + {:.7} N   (given)",
                l.mu_n, l.k2_per_mm, l.f0_n
            );
        }
    }
    if let Some(r) = &l.residuals {
        let _ = writeln!(
            o,
            "           residuals: F(L0) {:.1e}, F(Xmax) {:.1e}, C0 {:.1e} (relative)",
            r.force_at_l0, r.force_at_xmax, r.c0
        );
    }
    let f = &s.follower;
    let _ = writeln!(
        o,
        "  follower {} x roller r = {:.4} mm, springs {:.4} N/mm ({}), k_eff = {:.4} N/mm, preload {:.4} mm, friction {:.4} ({} correction)",
        f.count, f.roller_radius_mm, f.spring_rate_n_per_mm, f.spring, f.k_eff_n_per_mm, f.preload_mm, f.friction_coefficient, f.friction_correction
    );
    let p = &s.profile;
    let _ = writeln!(
        o,
        "  profile  lift {:.4} mm over {} mm, max pressure angle {:.2} deg at x = {:.3} mm, {} samples",
        p.lift_mm, p.xmax_mm, p.max_pressure_angle_deg, p.max_pressure_angle_at_x_mm, p.samples
    );
    let _ = writeln!(
        o,
        "  force    at Xmax: loading {} N, unloading {:.3} N",
        p.loading_force_at_xmax_n
            .map_or("jammed".to_string(), |v| format!("{v:.3}")),
        p.unloading_force_at_xmax_n
    );
    match (&s.part, &s.part_refused) {
        (Some(part), _) => {
            let _ = writeln!(
                o,
                "  part     area {:.4} mm2 x {:.3} mm = {:.3} mm3, box {:.3} x {:.3} mm, cam B-spline {} spans within {:.1e} mm, STL {} triangles",
                part.area_mm2,
                part.thickness_mm,
                part.volume_mm3,
                part.bounding_box_max_mm[0] - part.bounding_box_min_mm[0],
                part.bounding_box_max_mm[1] - part.bounding_box_min_mm[1],
                part.cam_edge_spans.iter().sum::<usize>(),
                part.cam_edge_fit_deviation_mm,
                part.stl_triangles
            );
        }
        (None, Some(why)) => {
            let _ = writeln!(o, "  part     REFUSED: {why}");
        }
        (None, None) => {}
    }
    match (&s.gcode, &s.gcode_refused) {
        (Some(g), _) => {
            let _ = writeln!(
                o,
                "  gcode    {} blocks ({:?}, {}), {} rough levels of {:.3} mm + finish, fit within {:.1e} mm (budget {:.1e}), about {:.1} min",
                g.blocks,
                g.dialect,
                if g.arcs { "arcs" } else { "lines only" },
                g.toolpath.rough_levels,
                g.toolpath.depth_step_mm,
                g.toolpath.max_fit_deviation_mm,
                g.toolpath.fit_budget_mm,
                g.toolpath.estimated_minutes
            );
        }
        (None, Some(why)) => {
            let _ = writeln!(o, "  gcode    REFUSED: {why}");
        }
        (None, None) => {}
    }
    let _ = writeln!(o, "  checks");
    for c in &s.checks {
        let _ = writeln!(
            o,
            "    {:<5} {:<15} {}",
            c.status.as_str().to_uppercase(),
            c.name,
            c.message
        );
        if let Some(a) = &c.advice {
            let _ = writeln!(o, "          advice: {a}");
        }
    }
    let _ = writeln!(o, "  status   {}", s.status.as_str().to_uppercase());
    let _ = writeln!(o, "  wrote");
    for w in &run.written {
        let _ = writeln!(o, "    {}", w.display());
    }
    o
}
