//! What a design looks like to a person: the text summary, the force and profile plots, the
//! tool-path plot and `profile.csv`.

use std::fmt::Write as _;
use std::path::PathBuf;

use super::plot::{self, Panel, Series};
use crate::cam::forces::RodForce;
use crate::cam::tolerance::ForceBand;
use crate::design::Design;
use crate::outputs::DesignSummary;
use crate::part::Part;
use crate::toolpath::{self, Job, Pass};

/// The human-readable report of a design run.
pub fn format_design(s: &DesignSummary, written: &[PathBuf]) -> String {
    let mut o = String::new();
    let _ = writeln!(o, "camspring design '{}'", s.name);
    let l = &s.law;
    match (l.mu_n, l.k2_per_mm, l.f0_n, l.alpha) {
        (Some(mu), Some(k2), Some(f0), Some(a)) => {
            let _ = writeln!(
                o,
                "  law      F = {mu:.7} N * exp({k2:.7} /mm * x) + {f0:.7} N   (alpha = {a:.10})"
            );
        }
        (Some(mu), Some(k2), Some(f0), None) => {
            let _ = writeln!(
                o,
                "  law      F = {mu:.7} N * exp({k2:.7} /mm * x) + {f0:.7} N   ({})",
                l.form
            );
        }
        _ => {
            let _ = writeln!(
                o,
                "  law      {} ({}): F(0) = {:.4} N, F(Xmax) = {:.4} N",
                l.description, l.form, l.force_at_zero_n, l.force_at_xmax_n
            );
        }
    }
    if let Some(r) = &l.condition_residuals {
        let text: Vec<String> = r.iter().map(|v| format!("{v:.1e}")).collect();
        let _ = writeln!(
            o,
            "           residuals of the conditions: {} (relative)",
            text.join(", ")
        );
    }
    if let Some(e) = l.table_max_rel_error {
        let _ = writeln!(
            o,
            "           cam force against the table at its points: within {e:.1e} (relative)"
        );
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
    let sp = &s.springs;
    let _ = writeln!(
        o,
        "  springs  {} x {:.4} N/mm: {:.3} N at preload ({:.3} mm), {:.3} N at full stroke ({:.3} mm), travel {:.3} mm each",
        sp.count,
        sp.rate_n_per_mm,
        sp.force_at_preload_n,
        sp.deflection_at_preload_mm,
        sp.force_at_full_stroke_n,
        sp.deflection_at_full_stroke_mm,
        sp.travel_mm
    );
    if let Some(r) = &s.rollers {
        let mut line = format!(
            "  rollers  {} x: peak normal load {:.2} N at x = {:.3} mm, ISO 281 mean {:.2} N, {:.2} revolutions per stroke",
            r.count, r.peak_normal_load_n, r.peak_at_x_mm, r.mean_equivalent_load_n, r.revolutions_per_stroke
        );
        if let Some(rpm) = r.speed_rpm {
            line.push_str(&format!(", {rpm:.1} rpm"));
        }
        if let Some(l) = r.l10_strokes {
            line.push_str(&format!(", L10 {l:.3e} strokes"));
        }
        let _ = writeln!(o, "{line}");
    }
    if let Some(b) = &s.force_band {
        let end = |v: &[Option<f64>]| {
            v.last()
                .copied()
                .flatten()
                .map_or("-".into(), |v| format!("{v:.2}"))
        };
        let top = b.sensitivity.first().map_or("-", |s| s.tolerance);
        let _ = writeln!(
            o,
            "  band     95 % of {} builds load {} ... {} N at Xmax; largest share: {top}",
            b.samples,
            end(&b.loading_lo_n),
            end(&b.loading_hi_n)
        );
    }
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
            for t in &g.toolpath.tools {
                let _ = writeln!(
                    o,
                    "           T{} {} mm {}, {:.3} mm deep (flutes {:.3} mm{}): {}",
                    t.number,
                    t.diameter_mm,
                    t.kind.name(),
                    t.depth_mm,
                    t.flute_length_mm,
                    if t.flute_length_assumed {
                        ", assumed"
                    } else {
                        ""
                    },
                    t.purpose
                );
            }
            let st = &g.toolpath.stock;
            let _ = writeln!(
                o,
                "           stock at least {:.1} x {:.1} x {:.2} mm, corner at ({:.2}, {:.2}) mm",
                st.size_mm[0], st.size_mm[1], st.size_mm[2], st.corner_mm[0], st.corner_mm[1]
            );
            for w in &g.toolpath.warnings {
                let _ = writeln!(o, "  WARNING  {w}");
            }
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
    for w in written {
        let _ = writeln!(o, "    {}", w.display());
    }
    o
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
pub fn profile_csv(design: &Design) -> Result<Vec<u8>, csv::Error> {
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record(PROFILE_CSV_HEADER)?;
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
        ])?;
    }
    w.into_inner().map_err(|e| csv::Error::from(e.into_error()))
}

/// `force.svg`: force against deflection (design, loading, unloading) and stiffness against force.
pub fn force_svg(design: &Design, band: Option<&ForceBand>) -> String {
    let law = &design.law.law;
    let pts = |f: &dyn Fn(&RodForce) -> Option<(f64, f64)>| {
        design.forces.iter().filter_map(f).collect::<Vec<_>>()
    };
    let mut force = Panel {
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
    if let Some(b) = band {
        let line = |ys: Vec<Option<f64>>| -> Vec<(f64, f64)> {
            b.x_mm
                .iter()
                .zip(ys)
                .filter_map(|(&x, y)| y.map(|y| (x, y)))
                .collect()
        };
        for (label, ys, color) in [
            (
                "95 % band of builds (loading)",
                b.loading_hi_n.clone(),
                "#ef9a9a",
            ),
            ("", b.loading_lo_n.clone(), "#ef9a9a"),
            (
                "95 % band of builds (unloading)",
                b.unloading_hi_n.iter().map(|&v| Some(v)).collect(),
                "#90caf9",
            ),
            (
                "",
                b.unloading_lo_n.iter().map(|&v| Some(v)).collect(),
                "#90caf9",
            ),
        ] {
            force.series.push(Series {
                label: label.into(),
                points: line(ys),
                color,
                dashed: false,
                dots: false,
            });
        }
    }
    if let crate::model::ForceLaw::Table(t) = law {
        let xmax = design.xmax_mm();
        force.series.push(Series {
            label: "table points".into(),
            points: t.points().filter(|p| p.0 <= xmax).collect(),
            color: "#2e7d32",
            dashed: false,
            dots: true,
        });
    }
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
                label: match law.exponential() {
                    Some(l) => format!("designed: {:.4}/mm x (F - {:.3} N)", l.k2_per_mm, l.f0_n),
                    None => "designed (table)".into(),
                },
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

/// `toolpath.svg`: the part outline with the finishing and last roughing passes, to scale.
pub fn toolpath_svg(design: &Design, part: &Part, jobs: &[Job]) -> String {
    let passes: Vec<&Pass> = jobs.iter().flat_map(|j| &j.passes).collect();
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
        for mv in p.steps.iter().map(|s| &s.mv) {
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
