//! What the calibration commands print and write: JSON with unit-bearing keys, the text
//! summary and the Allan variance plot.

use std::fmt::Write as _;

use serde_json::{json, Map, Value};

use super::allan::{allan_variance, white_noise_fit, AllanPoint, WhiteNoiseFit};
use super::identify::{Identification, SensorNoise, PARAMS};
use super::log::CalibrationLog;
use super::sg::Differentiator;
use crate::export::plot::{self, Panel, Series};

/// One channel's noise model.
#[derive(Debug, Clone)]
pub struct ChannelNoise {
    /// Channel name (force, position, force_rate).
    pub name: &'static str,
    /// Unit of the signal (N, mm, N/s).
    pub unit: &'static str,
    /// Unit suffix for JSON keys (n, mm, n_per_s).
    pub key_unit: &'static str,
    /// Allan curve.
    pub allan: Vec<AllanPoint>,
    /// White-noise fit over the first decade.
    pub fit: WhiteNoiseFit,
    /// Sample variance of the channel about its mean.
    pub sample_variance: f64,
}

/// Noise models of a log recorded at rest.
#[derive(Debug, Clone)]
pub struct NoiseModel {
    /// Force, position and force rate.
    pub channels: [ChannelNoise; 3],
    /// The force-rate variance the filter predicts from the force's white noise.
    pub force_rate_predicted_variance: f64,
    /// Sampling interval.
    pub dt_s: f64,
    /// The differentiator window (samples).
    pub window: usize,
}

impl NoiseModel {
    /// The sensor noise for identification: the white-noise variances of force and position.
    pub fn sensor_noise(&self) -> SensorNoise {
        SensorNoise {
            force_variance_n2: self.channels[0].fit.variance,
            position_variance_mm2: self.channels[1].fit.variance,
        }
    }
}

fn channel(
    name: &'static str,
    unit: &'static str,
    key_unit: &'static str,
    y: &[f64],
    dt: f64,
) -> ChannelNoise {
    let allan = allan_variance(y, dt);
    let fit = white_noise_fit(&allan, dt);
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    let sample_variance =
        y.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (y.len() as f64 - 1.0).max(1.0);
    ChannelNoise {
        name,
        unit,
        key_unit,
        allan,
        fit,
        sample_variance,
    }
}

/// Allan variance of force, position and the filtered force rate of a log at rest.
pub fn noise_model(log: &CalibrationLog) -> NoiseModel {
    let dt = log.dt_s();
    let diff = Differentiator::for_rate(1.0 / dt);
    let force_rate = diff.apply(&log.force_n, dt, super::sg::RATE);
    let force = channel("force", "N", "n", &log.force_n, dt);
    let predicted = diff.noise_variance(super::sg::RATE, force.fit.variance, dt);
    NoiseModel {
        channels: [
            force,
            channel("position", "mm", "mm", &log.position_mm, dt),
            channel("force_rate", "N/s", "n_per_s", &force_rate, dt),
        ],
        force_rate_predicted_variance: predicted,
        dt_s: dt,
        window: diff.window(),
    }
}

/// `camspring noise --json`.
pub fn noise_json(model: &NoiseModel) -> Value {
    let mut out = Map::new();
    out.insert("sample_interval_s".into(), json!(model.dt_s));
    for c in &model.channels {
        let u = c.key_unit;
        let sq = if u == "n_per_s" {
            "n2_per_s2".to_string()
        } else {
            format!("{u}2")
        };
        let mut ch = Map::new();
        if c.name != "force_rate" {
            ch.insert(format!("white_noise_variance_{sq}"), json!(c.fit.variance));
        }
        ch.insert(format!("sample_variance_{sq}"), json!(c.sample_variance));
        ch.insert("allan_slope".into(), json!(c.fit.slope));
        if c.name != "force_rate" {
            ch.insert(
                format!("motion_coefficient_{sq}_per_s2"),
                json!(c.fit.motion_coefficient_per_s2),
            );
        }
        ch.insert(
            "allan".into(),
            Value::Array(
                c.allan
                    .iter()
                    .map(|p| json!({"tau_s": p.tau_s, format!("avar_{sq}"): p.avar}))
                    .collect(),
            ),
        );
        if c.name == "force_rate" {
            ch.insert(
                "filter_predicted_variance_n2_per_s2".into(),
                json!(model.force_rate_predicted_variance),
            );
            ch.insert("filter_window_samples".into(), json!(model.window));
        }
        out.insert(c.name.into(), Value::Object(ch));
    }
    Value::Object(out)
}

/// The text summary of `camspring noise`.
pub fn format_noise(model: &NoiseModel) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Sensor noise (overlapping Allan variance, sample interval {:.6} s)",
        model.dt_s
    );
    for c in &model.channels[..2] {
        let _ = writeln!(
            s,
            "  {:<10} white-noise variance {:.4e} ({})^2, Allan slope {:+.2}{}",
            c.name,
            c.fit.variance,
            c.unit,
            c.fit.slope,
            if (c.fit.slope + 1.0).abs() < 0.15 {
                " (white)"
            } else {
                " (not white)"
            }
        );
    }
    if model.channels[..2].iter().any(|c| c.fit.slope > -0.7) {
        let _ = writeln!(
            s,
            "note: force or position is not white over the first decade (slope above -0.7): the log \
             moves or drifts. The white-noise variances above are separated from a tau^2 motion term; \
             a log recorded at rest is the cleaner measurement"
        );
    }
    let _ = writeln!(
        s,
        "  force rate through the {}-sample differentiator (filtered, so not white; Allan slope {:+.2}): \
         variance predicted from the force noise {:.4e} (N/s)^2, measured {:.4e} (N/s)^2",
        model.window,
        model.channels[2].fit.slope,
        model.force_rate_predicted_variance,
        model.channels[2].sample_variance
    );
    s
}

/// The log-log Allan plot (`allan.svg`).
pub fn allan_svg(model: &NoiseModel) -> String {
    let colors = ["#1f77b4", "#d62728", "#2ca02c"];
    let series = model
        .channels
        .iter()
        .zip(colors)
        .map(|(c, color)| Series {
            label: if c.name == "force_rate" {
                format!(
                    "{} ({})^2, filtered, variance {:.3e}",
                    c.name, c.unit, c.sample_variance
                )
            } else {
                format!(
                    "{} ({})^2, white {:.3e}, slope {:+.2}",
                    c.name, c.unit, c.fit.variance, c.fit.slope
                )
            },
            points: c
                .allan
                .iter()
                .filter(|p| p.avar > 0.0)
                .map(|p| (p.tau_s.log10(), p.avar.log10()))
                .collect(),
            color,
            dashed: false,
            dots: false,
        })
        .collect();
    let panel = Panel {
        title: "Overlapping Allan variance".into(),
        x_label: "averaging time tau (s), log scale".into(),
        y_label: "Allan variance (channel unit^2), log scale".into(),
        series,
        log_axes: true,
        ..Default::default()
    };
    plot::document(&[panel], 760.0, 520.0).to_string()
}

/// `camspring identify --json`: parameters under unit-bearing keys, each with `_std`.
pub fn identification_json(
    id: &Identification,
    noise: &SensorNoise,
    log: &CalibrationLog,
) -> Value {
    let mut params = Map::new();
    for name in PARAMS {
        let e = id.get(name);
        params.insert(name.into(), json!(e.and_then(|e| e.value)));
        params.insert(format!("{name}_std"), json!(e.and_then(|e| e.std)));
    }
    json!({
        "parameters": params,
        "not_identifiable": id.not_identifiable,
        "covariance": {"parameters": id.covariance_parameters, "matrix": id.covariance, "method": id.covariance_method},
        "paper_covariance_k2_fixed": id.paper_covariance_k2_fixed,
        "k2_quasi_static_per_mm": id.k2_quasi_static_per_mm,
        "condition_number": id.condition_number,
        "reduced_chi2": id.reduced_chi2,
        "residual_rms_n": id.residual_rms_n,
        "samples": id.samples,
        "dynamic_samples": id.dynamic_samples,
        "quasi_static_samples": id.quasi_static_samples,
        "sample_rate_hz": 1.0 / log.dt_s(),
        "sg_window_samples": id.sg_window,
        "sg_window_s": id.sg_window_s,
        "noise": {
            "force_variance_n2": noise.force_variance_n2,
            "position_variance_mm2": noise.position_variance_mm2,
        },
    })
}

/// The text summary of `camspring identify`.
pub fn format_identification(id: &Identification) -> String {
    let units = [
        ("m", "N s^2/mm"),
        ("d0", "N"),
        ("d1", "N s/mm"),
        ("d2", "N s^3/mm^3"),
        ("mu", "N"),
        ("F0", "N"),
        ("k2", "1/mm"),
    ];
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Identified from {} samples ({} moving, {} quasi-static; Savitzky-Golay window {} samples = {:.3} s)",
        id.samples, id.dynamic_samples, id.quasi_static_samples, id.sg_window, id.sg_window_s
    );
    for (k, (sym, unit)) in units.iter().enumerate() {
        match id.get(PARAMS[k]) {
            Some(super::identify::Estimate {
                value: Some(v),
                std: Some(sd),
            }) => {
                let note = if sd > v.abs() && k != 1 {
                    "  (std exceeds the value: poorly resolved by this log)"
                } else {
                    ""
                };
                let _ = writeln!(s, "  {sym:<3} = {v:>12.5e} +- {sd:.2e} {unit}{note}");
            }
            _ => {
                let _ = writeln!(s, "  {sym:<3} = not identifiable from this log");
            }
        }
    }
    if !id.not_identifiable.is_empty() {
        let _ = writeln!(
            s,
            "warning: not identifiable (poor excitation): {}. Record a run that moves faster and \
             reverses (for m, d0, d1, d2) or covers more of the stroke (for mu, F0, k2); for m on a \
             slow run, a longer filter (--window 0.8s) lowers the acceleration noise. The \
             parameters left in the model absorb the removed ones (F0 takes d0 when the motion \
             never reverses).",
            id.not_identifiable.join(", ")
        );
    }
    let _ = writeln!(
        s,
        "  fit: residual RMS {:.4} N, reduced chi-square {:.2}, condition number {:.1e}; k2 from the \
         quasi-static samples alone {:.5} 1/mm",
        id.residual_rms_n, id.reduced_chi2, id.condition_number, id.k2_quasi_static_per_mm
    );
    s
}

/// The EKF time series as CSV: `t_s`, each state and its 1-sigma bound, then F0 and d0 from
/// the parallel filter.
pub fn estimate_csv(run: &super::ekf::EkfRun) -> Vec<u8> {
    use super::ekf::STATE_NAMES;
    let mut out = String::with_capacity(run.states.len() * 260 + 512);
    out.push_str("t_s");
    for name in STATE_NAMES {
        let _ = write!(out, ",{name},{name}_std");
    }
    out.push_str(",f0_n,f0_n_std,d0_n,d0_n_std\n");
    for i in 0..run.states.len() {
        let _ = write!(out, "{:.6}", run.t_s[i]);
        for k in 0..8 {
            let _ = write!(out, ",{:.9e},{:.3e}", run.states[i][k], run.stds[i][k]);
        }
        let _ = writeln!(
            out,
            ",{:.6},{:.3e},{:.6},{:.3e}",
            run.offsets[i][0], run.offset_stds[i][0], run.offsets[i][1], run.offset_stds[i][1]
        );
    }
    out.into_bytes()
}

/// The final estimates (the paper's Table II) under the unit-bearing keys of `identify`,
/// each with `_std`: k2_per_mm, m_n_s2_per_mm, d2_n_s3_per_mm3, sigma_n_per_mm (at the last
/// sample), d_n_s_per_mm (at the last sample), f0_n and d0_n (parallel filter).
pub fn estimate_json(run: &super::ekf::EkfRun, settings: &super::ekf::EkfSettings) -> Value {
    use super::ekf::idx;
    let z = run.last.z;
    let sd = run.last.std();
    let f = run.offset_filter.theta;
    let fs = run.offset_filter.std();
    json!({
        "final": {
            "k2_per_mm": z[idx::K2], "k2_per_mm_std": sd[idx::K2],
            "m_n_s2_per_mm": z[idx::M], "m_n_s2_per_mm_std": sd[idx::M],
            "d2_n_s3_per_mm3": z[idx::D2], "d2_n_s3_per_mm3_std": sd[idx::D2],
            "sigma_n_per_mm": z[idx::SIGMA], "sigma_n_per_mm_std": sd[idx::SIGMA],
            "d_n_s_per_mm": z[idx::D], "d_n_s_per_mm_std": sd[idx::D],
            "f0_n": f[0], "f0_n_std": fs[0],
            "d0_n": f[1], "d0_n_std": fs[1],
        },
        "t_end_s": run.t_s.last(),
        "samples": run.states.len(),
        "first_sample": run.first_sample,
        "outliers": run.outliers,
        "settings": settings,
    })
}

/// The text summary of `camspring estimate`.
pub fn format_estimate(run: &super::ekf::EkfRun) -> String {
    use super::ekf::idx;
    let z = run.last.z;
    let sd = run.last.std();
    let f = run.offset_filter.theta;
    let fs = run.offset_filter.std();
    let mut s = String::new();
    let _ = writeln!(
        s,
        "EKF over {} samples (to t = {:.3} s); final estimates (1-sigma):",
        run.states.len(),
        run.t_s.last().copied().unwrap_or(0.0)
    );
    for (name, k, unit) in [
        ("k2", idx::K2, "1/mm"),
        ("M", idx::M, "N s^2/mm"),
        ("d2", idx::D2, "N s^3/mm^3"),
        ("sigma", idx::SIGMA, "N/mm (last sample)"),
        ("D", idx::D, "N s/mm (last sample)"),
    ] {
        let _ = writeln!(s, "  {name:<5} = {:>12.5e} +- {:.2e} {unit}", z[k], sd[k]);
    }
    let _ = writeln!(
        s,
        "  F0    = {:>12.5e} +- {:.2e} N (parallel filter)",
        f[0], fs[0]
    );
    let _ = writeln!(
        s,
        "  d0    = {:>12.5e} +- {:.2e} N (parallel filter)",
        f[1], fs[1]
    );
    if run.outliers > 0 {
        let _ = writeln!(
            s,
            "  note: {} innovations beyond the outlier threshold",
            run.outliers
        );
    }
    s
}
