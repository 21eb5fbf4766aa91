//! `sweep.csv` and `sweep.svg`: a grid of designs side by side.

use super::plot::{self, Panel, Series};
use crate::cam::checks::Status;
use crate::model::ChecksSpec;
use crate::sweep::{Axis, PointResult, SweepPoint};

/// `sweep.csv`: the axis values, then status, lift_mm, max_pressure_angle_deg,
/// max_contact_stress_mpa, failed_checks (space-separated) and error.
pub fn sweep_csv(axes: &[Axis], points: &[SweepPoint]) -> Vec<u8> {
    use std::fmt::Write as _;
    let mut out = String::new();
    for a in axes {
        let _ = write!(out, "{},", a.key.column());
    }
    out.push_str(
        "status,lift_mm,max_pressure_angle_deg,max_contact_stress_mpa,failed_checks,warned_checks,error\n",
    );
    for p in points {
        for (a, v) in axes.iter().zip(&p.values) {
            let _ = write!(out, "{},", a.key.value_text(*v));
        }
        match &p.result {
            Ok(r) => {
                let _ = writeln!(
                    out,
                    "{},{:.6},{:.4},{},{},{},",
                    r.status.as_str(),
                    r.lift_mm,
                    r.max_pressure_angle_deg,
                    r.max_contact_stress_mpa
                        .map_or(String::new(), |v| format!("{v:.3}")),
                    r.failed_checks.join(" "),
                    r.warned_checks.join(" ")
                );
            }
            Err(e) => {
                let _ = writeln!(out, "error,,,,,,\"{}\"", e.replace('"', "'"));
            }
        }
    }
    out.into_bytes()
}

/// `sweep.svg`: largest pressure angle, lift and contact stress against the first axis, one
/// line per value of the second axis (points of failing designs are left out of the lines
/// and drawn as dots).
pub fn sweep_svg(axes: &[Axis], points: &[SweepPoint], limits: &ChecksSpec) -> String {
    let colours = [
        "#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#7f7f7f",
        "#bcbd22", "#17becf",
    ];
    let groups: Vec<Option<f64>> = match axes.get(1) {
        Some(a) => a.values.iter().map(|&v| Some(v)).collect(),
        None => vec![None],
    };
    let first = &axes[0].values;
    let (x_lo, x_hi) = first
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let panel = |title: &str,
                 label: &str,
                 get: &dyn Fn(&PointResult) -> Option<f64>,
                 limit: Option<(f64, &str)>| {
        let mut series = Vec::new();
        for (i, g) in groups.iter().enumerate() {
            let in_group = |p: &&SweepPoint| g.is_none_or(|v| p.values.get(1) == Some(&v));
            let ok: Vec<(f64, f64)> = points
                .iter()
                .filter(in_group)
                .filter_map(|p| match &p.result {
                    Ok(r) if r.status != Status::Fail => get(r).map(|y| (p.values[0], y)),
                    _ => None,
                })
                .collect();
            let failing: Vec<(f64, f64)> = points
                .iter()
                .filter(in_group)
                .filter_map(|p| match &p.result {
                    Ok(r) if r.status == Status::Fail => get(r).map(|y| (p.values[0], y)),
                    _ => None,
                })
                .collect();
            let colour = colours[i % colours.len()];
            let name = match (g, axes.get(1)) {
                (Some(v), Some(a)) => format!("{} = {v:.4}", a.key.column()),
                _ => "makeable designs".into(),
            };
            series.push(Series {
                label: name,
                points: ok,
                color: colour,
                dashed: false,
                dots: false,
            });
            if !failing.is_empty() {
                series.push(Series {
                    label: String::new(),
                    points: failing,
                    color: colour,
                    dashed: false,
                    dots: true,
                });
            }
        }
        if let Some((y, name)) = limit {
            series.push(Series {
                label: name.to_string(),
                points: vec![(x_lo, y), (x_hi, y)],
                color: "#c62828",
                dashed: true,
                dots: false,
            });
        }
        Panel {
            title: format!("{title} (dots: a check fails)"),
            x_label: axes[0].key.label().into(),
            y_label: label.into(),
            series,
            ..Default::default()
        }
    };
    let panels = [
        panel(
            "Largest pressure angle",
            "pressure angle (deg)",
            &|r| Some(r.max_pressure_angle_deg),
            Some((limits.max_pressure_angle_deg, "limit")),
        ),
        panel(
            "Follower lift at Xmax",
            "lift (mm)",
            &|r| Some(r.lift_mm),
            None,
        ),
        panel(
            "Peak contact stress",
            "contact stress (MPa)",
            &|r| r.max_contact_stress_mpa,
            Some((limits.max_contact_stress_mpa, "limit")),
        ),
    ];
    plot::document(&panels, 520.0, 440.0).to_string()
}
