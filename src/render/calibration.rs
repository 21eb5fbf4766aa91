//! What the calibration commands print and write: JSON with unit-bearing keys, the text
//! summaries, the EKF time series CSV, and the Allan variance and validation plots.

use std::fmt::Write as _;

use serde_json::{json, Map, Value};

use super::plot::{self, Panel, Series};
use crate::estimate::ekf::{idx, EkfRow, EkfRun, EkfSettings, STATE_NAMES};
use crate::estimate::identify::{
    Identification, Param, Regression, WindowMethod, LOAD_FRICTION_SIGMAS, TRANSIENT_SIGMAS,
};
use crate::estimate::noise::{NoiseModel, NoiseOrigin, ResolvedNoise};
use crate::estimate::pipeline::EstimateRun;
use crate::estimate::retime::{ForceDelayFit, ForceDelayScreen};
use crate::verdict::validate::{spring_force_n, CurveValidation, Validation};

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
    noise: &ResolvedNoise,
    sample_rate_hz: f64,
    force_delay: Option<&ForceDelayFit>,
    force_delay_screen: Option<&ForceDelayScreen>,
) -> Value {
    let mut params = Map::new();
    for (p, e) in id.parameters.iter() {
        let name = p.key();
        params.insert(name.into(), json!(e.value));
        params.insert(format!("{name}_std"), json!(e.std));
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
        "log_samples": id.log_samples,
        "block_samples": id.block_samples,
        "dynamic_samples": id.dynamic_samples,
        "transient_samples": id.transient_samples,
        "reduced_chi2_with_transients": id.reduced_chi2_with_transients,
        "quasi_static_samples": id.quasi_static_samples,
        "sample_rate_hz": sample_rate_hz,
        "sg_window_samples": id.sg_window,
        "sg_window_s": id.sg_window_s,
        "window_choice": id.window_choice,
        "imprecise": id.imprecise().iter().map(|(p, rel, longer)| json!({
            "parameter": p.key(), "relative_std": rel, "log_length_factor_for_target": longer,
        })).collect::<Vec<_>>(),
        "filter_bias_std": id.filter_bias_std,
        "noise_std": id.noise_std,
        "signal_share": id.signal_share,
        "inertia_attenuation": id.inertia_attenuation,
        "regression": id.regression,
        "sign_fault": id.sign_fault,
        "position_stop": id.position_stop,
        "load_friction_left_out_n": id.load_friction_left_out,
        "fit": {
            "status": id.adequacy.status,
            "reduced_chi2": id.adequacy.reduced_chi2,
            "whiteness": id.adequacy.whiteness,
            "reasons": id.adequacy.reasons,
        },
        "noise": sensor_noise_json(noise),
        "force_delay": force_delay,
        "force_delay_screen": force_delay_screen,
    })
}

/// The sensor noise a run weighted with, where each channel's came from, and the log's own
/// estimate (JSON).
pub fn sensor_noise_json(noise: &ResolvedNoise) -> Value {
    json!({
        "force_variance_n2": noise.noise.force_variance_n2,
        "position_variance_mm2": noise.noise.position_variance_mm2,
        "force_origin": noise.force_origin,
        "position_origin": noise.position_origin,
        "log_force_variance_n2": noise.log.map(|l| l.force.variance),
        "log_force_variance_relative_std": noise.log.map(|l| l.force.relative_std),
        "log_position_variance_mm2": noise.log.map(|l| l.position.variance),
        "log_position_variance_relative_std": noise.log.map(|l| l.position.relative_std),
        "position_variance_relative_std": noise.noise.position_variance_relative_std,
        "position_quantum_mm": noise.log.and_then(|l| l.position.quantum),
        "position_dither_mm": noise.log.and_then(|l| {
            l.position.quantum.map(|q| q * l.position.dither_steps)
        }),
        "force_quantum_n": noise.log.and_then(|l| l.force.quantum),
        "warnings": noise.warnings,
    })
}

/// One line on the sensor noise a run weighted with and where it came from.
pub fn format_sensor_noise(noise: &ResolvedNoise) -> String {
    let origin = |o: NoiseOrigin| match o {
        NoiseOrigin::Given => "given",
        NoiseOrigin::Log => "from the log's differences",
        NoiseOrigin::Paper => "the paper's sensors; the log is too short to estimate it",
    };
    let mut s = format!(
        "  sensor noise: force {:.3e} N^2 ({}), position {:.3e} mm^2 ({})\n",
        noise.noise.force_variance_n2,
        origin(noise.force_origin),
        noise.noise.position_variance_mm2,
        origin(noise.position_origin)
    );
    if let (NoiseOrigin::Log, Some(q)) = (
        noise.position_origin,
        noise.log.and_then(|l| l.position.quantum),
    ) {
        let dither = noise.log.map_or(0.0, |l| l.position.dither_steps);
        if dither > 0.0 {
            s.push_str(&format!(
                "  the position is read in steps of {q:.4e} mm with noise of {:.2e} mm ({dither:.2} \
                 steps) before them: its error is that noise and the steps', partly white, so \
                 the position variance is known only to +-{:.0} %, which the standard deviations \
                 carry\n",
                q * dither,
                100.0 * noise.noise.position_variance_relative_std
            ));
        } else {
            s.push_str(&format!(
                "  the encoder reads in steps of {q:.4e} mm, larger than its noise: its error is \
                 not white (constant at rest), so the position variance is known only to \
                 +-{:.0} %, which the standard deviations carry\n",
                100.0 * noise.noise.position_variance_relative_std
            ));
        }
    }
    s
}

/// The line saying how the force was re-timed.
pub fn force_delay_line(d: &ForceDelayFit) -> String {
    let late = if d.delay_s >= 0.0 { "after" } else { "before" };
    match (d.fitted, d.std_s) {
        (true, Some(std)) => format!(
            "  force re-timed: read {:.2} +- {:.2} ms {late} the position (fitted over {} \
             delays, window held at {:.3} s{})\n",
            d.delay_s.abs() * 1e3,
            std * 1e3,
            d.trials.len(),
            d.window_s.unwrap_or(f64::NAN),
            d.window_spread_s
                .map(|w| format!(
                    "; the +- counts {:.2} ms, half the move to the next longer window's",
                    w * 1e3
                ))
                .unwrap_or_default()
        ),
        (true, None) => format!(
            "  force re-timed: read {:.2} ms {late} the position (fitted; the profile has no \
             curvature there, so its uncertainty is unknown)\n",
            d.delay_s.abs() * 1e3
        ),
        (false, _) => format!(
            "  force re-timed: read {:.2} ms {late} the position (as given)\n",
            d.delay_s.abs() * 1e3
        ),
    }
}

/// The line on what the screen for a force read late found, where no delay was asked for:
/// a warning where one is suspected, and a note where the profile's least moved with the
/// filter window (the model's misfit, not a delay).
pub fn force_delay_screen_line(screen: &ForceDelayScreen) -> String {
    let held = &screen.held;
    let late = if held.delay_s >= 0.0 {
        "after"
    } else {
        "before"
    };
    let at_least = if held.beyond { "at least " } else { "" };
    if screen.moves_with_window() {
        let longer = match &screen.longer_window {
            Some(l) => format!(
                "{:+.1} +- {:.1} ms at the {:.3} s window",
                l.delay_s * 1e3,
                l.std_s * 1e3,
                l.window_s
            ),
            None => "no least at the next longer window".to_string(),
        };
        return format!(
            "  force and position read together as far as the fit tells: the fit's chi-square \
             is least with the force re-timed by {:+.1} +- {:.1} ms at the {:.3} s window, but \
             {longer}; a delay in the log is the same through any filter, so this is the \
             model's misfit trading with the delay (the filter rounding the motion's corners), \
             not a delay\n",
            held.delay_s * 1e3,
            held.std_s * 1e3,
            held.window_s
        );
    }
    if !screen.suspected {
        return format!(
            "  force and position read together as far as the fit tells (screened: {:+.1} +- \
             {:.1} ms)\n",
            held.delay_s * 1e3,
            held.std_s * 1e3
        );
    }
    let confirmed = screen
        .longer_window
        .map(|l| {
            format!(
                ", and {:.1} ms at the {:.3} s window; the standard deviation counts half their \
                 difference",
                l.delay_s.abs() * 1e3,
                l.window_s
            )
        })
        .unwrap_or_default();
    format!(
        "  WARNING: the force looks read {at_least}{:.1} +- {:.1} ms {late} the position \
         ({:.1} standard deviations from none, by the fit's chi-square at the whole-sample \
         delays near zero{confirmed}): a fit read as logged takes such a delay as inertia and \
         damping. Give --force-delay auto to fit it and re-time the force.\n",
        held.delay_s.abs() * 1e3,
        screen.std_with_window_s() * 1e3,
        held.delay_s.abs() / screen.std_with_window_s()
    )
}

/// What the friction that grows with the spring's force (mu_f) is, as a share of the spring's
/// exponential part, where identification fitted it and it is clear of zero (beyond two of
/// its standard deviations).
fn load_friction_line(id: &Identification) -> Option<String> {
    let muf = id.get(Param::MuF);
    let (v, sd) = (muf.value?, muf.std?);
    let mu = id.get(Param::Mu).value?;
    (v.abs() > 2.0 * sd && mu > 0.0).then(|| {
        format!(
            "  friction grows with the load: muf exp(k2 x) in the sliding direction, {:.2} % of \
             the spring's exponential part mu exp(k2 x) (a cam's contact friction): the loading \
             stroke's exponential part is (mu + muf) exp(k2 x), the unloading stroke's \
             (mu - muf) exp(k2 x)\n",
            100.0 * v / mu,
        )
    })
}

/// Why the friction that grows with the load is not in an identification's model: left out
/// by the rule of [`LOAD_FRICTION_SIGMAS`] (with what the fit with it gave, and where that was
/// negative beyond the rule's standard deviations, what a negative one points to), or never
/// fitted.
fn load_friction_left_out(id: &Identification) -> String {
    let Some(e) = id.load_friction_left_out else {
        return "not in the model (the paper's constant friction d0 alone)".to_owned();
    };
    let mut line = format!(
        "left out, the paper's constant friction d0 fitted instead (fitted, muf came to {}, not \
         above zero by {LOAD_FRICTION_SIGMAS} of its standard deviations)",
        e.describe("N")
    );
    if let (Some(v), Some(sd)) = (e.value, e.std) {
        if v < -LOAD_FRICTION_SIGMAS * sd {
            line.push_str(
                "; a negative muf puts the loading stroke below the unloading one, which no \
                 friction does: a force read late (or a position read early) looks like that \
                 on a steady motion, and --force-delay auto fits such a delay",
            );
        }
    }
    line
}

/// The text summary of `camspring identify`.
pub fn format_identification(
    id: &Identification,
    noise: &ResolvedNoise,
    force_delay: Option<&ForceDelayFit>,
    force_delay_screen: Option<&ForceDelayScreen>,
) -> String {
    let units = [
        ("m", "N s^2/mm"),
        ("d0", "N"),
        ("d1", "N s/mm"),
        ("d2", "N s^3/mm^3"),
        ("mu", "N"),
        ("F0", "N"),
        ("k2", "1/mm"),
        ("muf", "N"),
    ];
    let mut s = String::new();
    let chosen = match id.window_choice.method {
        WindowMethod::Given => "given".to_string(),
        WindowMethod::Balancing => format!(
            "chosen from {} windows by the balancing principle",
            id.window_choice.candidates.len()
        ),
    };
    let _ = writeln!(
        s,
        "Identified from {} samples ({} moving, {} quasi-static; Savitzky-Golay window {} samples = {:.3} s, {chosen})",
        id.samples, id.dynamic_samples, id.quasi_static_samples, id.sg_window, id.sg_window_s
    );
    if id.block_samples > 1 || id.samples * id.block_samples < id.log_samples {
        let _ = writeln!(
            s,
            "  (the log's {} samples averaged in blocks of {}{})",
            id.log_samples,
            id.block_samples,
            if id.samples * id.block_samples < id.log_samples {
                ", the first ones only: identification uses at most 2^21 samples"
            } else {
                ""
            }
        );
    }
    if let Some(d) = force_delay {
        s.push_str(&force_delay_line(d));
    }
    if let Some(screen) = force_delay_screen {
        s.push_str(&force_delay_screen_line(screen));
    }
    if let Some(problem) = id.adequacy.problem() {
        let _ = writeln!(
            s,
            "THE MODEL DOES NOT FIT THIS LOG: {problem}. The numbers below are the best fit of a \
             model that does not explain the data; do not use them as the transmission's parameters."
        );
    }
    for ((p, e), (sym, unit)) in id.parameters.iter().zip(units.iter()) {
        match e {
            crate::estimate::identify::Estimate {
                value: Some(v),
                std: Some(sd),
            } => {
                // d0 and mu_f (friction) may be small against their std without harm.
                let note = if sd > v.abs() && p != Param::D0 && p != Param::MuF {
                    "  (std exceeds the value: poorly resolved by this log)"
                } else {
                    ""
                };
                let _ = writeln!(s, "  {sym:<3} = {v:>12.5e} +- {sd:.2e} {unit}{note}");
            }
            _ if p == Param::MuF && !id.not_identifiable.iter().any(|n| n == p.key()) => {
                let _ = writeln!(s, "  {sym:<3} = {}", load_friction_left_out(id));
            }
            _ => {
                let _ = writeln!(s, "  {sym:<3} = not identifiable from this log");
            }
        }
    }
    if let Some(line) = load_friction_line(id) {
        s.push_str(&line);
    }
    if !id.not_identifiable.is_empty() {
        let _ = writeln!(
            s,
            "warning: not identifiable (poor excitation): {}. Record a run that moves faster and \
             reverses (for m, d0, d1, d2, mu_f) or covers more of the stroke (for mu, F0, k2); for m on a \
             slow run, a longer filter (--window 0.8s) lowers the acceleration noise. The \
             parameters left in the model absorb the removed ones (F0 takes d0 when the motion \
             never reverses).",
            id.not_identifiable.join(", ")
        );
    }
    if let Some(stop) = &id.position_stop {
        let _ = writeln!(s, "warning: {}", stop.reason());
    }
    if id.transient_samples > 0 {
        let _ = writeln!(
            s,
            "  transients: {} moving samples left out, within half a window of a force residual \
             beyond {} standard deviations (reduced chi-square {:.2} with them): starts and stops \
             sharper than the {:.3} s window resolves (a servo's velocity steps; a motion whose \
             speed changes smoothly lets m be identified from them), or glitches in the log.",
            id.transient_samples, TRANSIENT_SIGMAS, id.reduced_chi2_with_transients, id.sg_window_s
        );
    }
    if id.regression == Regression::ParallelFilter {
        let _ = writeln!(
            s,
            "  regression through the parallel filter: the force went through the acceleration \
             filter as well, so m carries no filter bias from the motion's corners"
        );
    }
    if let Some(r) = id.inertia_attenuation {
        let _ = writeln!(
            s,
            "  m is corrected for the {:.3} s window's loss of acceleration gain on this motion \
             ({:.2} %, measured from the log; half the correction is in its standard deviation)",
            id.sg_window_s,
            100.0 * r
        );
    }
    let _ = writeln!(
        s,
        "  fit: residual RMS {:.4} N, reduced chi-square {:.2}, condition number {:.1e}; k2 from the \
         quasi-static samples alone {:.5} 1/mm",
        id.residual_rms_n, id.reduced_chi2, id.condition_number, id.k2_quasi_static_per_mm
    );
    if !crate::estimate::identify::spring_resolved(id) {
        let _ = writeln!(
            s,
            "warning: this log does not resolve the spring's curvature ({}): their standard \
             deviations do not bound k2, or do not tell the exponential part from zero, and mu, \
             F0 and k2 trade off. Record a run over more of the stroke, slower (less inertia \
             force against the spring's) or with less sensor noise",
            crate::estimate::identify::describe_spring(&id.get(Param::K2), &id.get(Param::Mu))
        );
    }
    for (p, rel, longer) in id.imprecise() {
        let _ = writeln!(
            s,
            "warning: {} is determined only to +-{:.2} % (1 sigma) by this log; the calibration target \
             (k2 within 0.5 %, mu within 1.5 %, at 2 sigma) needs a log about {:.1} times longer, or \
             one that covers more of the stroke",
            p.key(),
            100.0 * rel,
            longer
        );
    }
    match &id.adequacy.whiteness {
        Some(w) => {
            let _ = writeln!(
                s,
                "  residual whiteness: statistic {:.1} over {} lags of {} samples, p = {} ({})",
                w.statistic,
                w.lags,
                w.lag_spacing_samples,
                if w.p_value >= 0.01 {
                    format!("{:.2}", w.p_value)
                } else {
                    format!("{:.1e}", w.p_value)
                },
                if w.p_value < crate::estimate::identify::WHITENESS_LEVEL {
                    "coloured"
                } else {
                    "white"
                }
            );
        }
        None => {
            let _ = writeln!(s, "  residual whiteness: too few samples to test");
        }
    }
    s.push_str(&format_sensor_noise(noise));
    s
}

/// The header line of the EKF time series (est.csv): `t_s`, each state and its 1-sigma
/// bound, then F0 and d0 from the parallel filter.
pub fn estimate_csv_header() -> String {
    let mut out = String::from("t_s");
    for name in STATE_NAMES {
        let _ = write!(out, ",{name},{name}_std");
    }
    out.push_str(",f0_n,f0_n_std,d0_n,d0_n_std\n");
    out
}

/// One line of the EKF time series, appended to `out` (rows are written as the filter makes
/// them: a day-long log's series never is in memory).
pub fn estimate_csv_row(row: &EkfRow, out: &mut String) {
    let _ = write!(out, "{:.6}", row.t_s);
    for k in 0..8 {
        let _ = write!(out, ",{:.9e},{:.3e}", row.state[k], row.std[k]);
    }
    let _ = writeln!(
        out,
        ",{:.6},{:.3e},{:.6},{:.3e}",
        row.offsets[0], row.offset_stds[0], row.offsets[1], row.offset_stds[1]
    );
}

/// The EKF time series of a run that kept its rows, as CSV ([`estimate_csv_header`],
/// [`estimate_csv_row`]).
pub fn estimate_csv(run: &EkfRun) -> Vec<u8> {
    let mut out = String::with_capacity(run.rows.len() * 260 + 512);
    out.push_str(&estimate_csv_header());
    for row in &run.rows {
        estimate_csv_row(row, &mut out);
    }
    out.into_bytes()
}

/// The final estimates (the paper's Table II) under the unit-bearing keys of `identify`,
/// each with `_std`: k2_per_mm, m_n_s2_per_mm, d2_n_s3_per_mm3, sigma_n_per_mm (at the last
/// sample), d_n_s_per_mm (at the last sample), f0_n and d0_n (parallel filter).
pub fn estimate_json(est: &EstimateRun) -> Value {
    let (run, settings) = (&est.run, &est.settings);
    let (z, sd) = est.reported_constants();
    let f = run.offset_filter.theta;
    let fs = run.offset_filter.std();
    // A held state that identification does not resolve has no standard deviation (null),
    // not a zero one.
    let std_of = |k: usize| (settings.reports(k) || sd[k] != 0.0).then_some(sd[k]);
    json!({
        "final": {
            "k2_per_mm": z[idx::K2], "k2_per_mm_std": sd[idx::K2],
            "m_n_s2_per_mm": z[idx::M], "m_n_s2_per_mm_std": std_of(idx::M),
            "d2_n_s3_per_mm3": z[idx::D2], "d2_n_s3_per_mm3_std": std_of(idx::D2),
            "sigma_n_per_mm": z[idx::SIGMA], "sigma_n_per_mm_std": sd[idx::SIGMA],
            "d_n_s_per_mm": z[idx::D], "d_n_s_per_mm_std": sd[idx::D],
            "f0_n": f[0], "f0_n_std": fs[0],
            "d0_n": f[1], "d0_n_std": fs[1],
        },
        "t_end_s": run.t_end_s,
        "samples": run.samples,
        "position_offset_mm": est.position_offset_mm,
        "force_delay": est.force_delay,
        "force_delay_screen": est.force_delay_screen,
        "noise": sensor_noise_json(&est.noise),
        "first_sample": run.first_sample,
        "outliers": run.outliers,
        "passed_over_samples": run.passed_over,
        "resumes": run.resumes,
        "held": held_states(settings),
        "imprecise": est.imprecise().iter().map(|w| json!({
            "state": w.state, "relative_std": w.relative_std,
            "log_length_factor_for_target": w.log_length_factor,
            "relative_disagreement_with_identification": w.relative_disagreement,
            "relative_identification_filter_bias": w.relative_identification_bias,
            "identification_law_imprecise": w.identification_law_imprecise,
        })).collect::<Vec<_>>(),
        "recovery": est.recovery,
        "unresolved_friction_sign": est.unresolved_friction_sign,
        "filter_k2": est.filter_k2,
        "inertia_unidentified": est.inertia_unidentified(),
        "twins": est.twins,
        "consistency": est.consistency,
        "settings": settings,
    })
}

/// The states the filter does not report: held at their initial value (no initial variance,
/// no process noise), or an inertia carried free only to keep its model whole.
fn held_states(settings: &EkfSettings) -> Vec<&'static str> {
    (0..8)
        .filter(|&i| !settings.reports(i))
        .map(|i| STATE_NAMES[i])
        .collect()
}

/// The text on how far `estimate`'s numbers can be trusted: held states, a recovery from
/// divergence, and the consistency verdict.
pub fn format_consistency(est: &EstimateRun) -> String {
    let mut s = String::new();
    let held = held_states(&est.settings);
    for name in held {
        let why = match name {
            "m_n_s2_per_mm" if est.settings.m_nuisance_from.is_some() => {
                "identification does not resolve it, having left out as transients the samples \
                 that carry the inertia's force; the filter carried it free to keep its model \
                 whole, and it is reported at its start without a standard deviation"
            }
            "m_n_s2_per_mm" => {
                "identification does not resolve it; held at its value, reported with its \
                 standard deviation"
            }
            "d2_n_s3_per_mm3" => {
                "identification does not resolve it and its force at the log's top speed is \
                 below three times the force noise; held at zero, reported at identification's \
                 value"
            }
            _ => "held at its initial value",
        };
        let _ = writeln!(s, "  {name}: not estimated ({why})");
    }
    if let Some(r) = &est.recovery {
        let _ = writeln!(s, "note: {r}");
    }
    if let Some(stop) = est
        .identification
        .as_ref()
        .and_then(|id| id.position_stop.as_ref())
    {
        let _ = writeln!(s, "warning: {}", stop.reason());
    }
    if est.run.passed_over > 0 {
        let _ = writeln!(
            s,
            "note: the filter passed over {} samples whose force rate reaches a force that is \
             not the spring's (a clipped load cell, a rod against a stop), and resumed {} \
             time{} from the motion fitted to the positions past them, keeping what it had \
             learnt of M, k2 and d2",
            est.run.passed_over,
            est.run.resumes,
            if est.run.resumes == 1 { "" } else { "s" }
        );
    }
    if let Some(u) = &est.unresolved_friction_sign {
        let _ = writeln!(
            s,
            "note: the friction d0 = {:.3} N is within four standard deviations of the force \
             the frictionless model leaves ({:.3} N), so its sign at starts and stops is read \
             wrong at times, by identification and the filter alike: {}{}d2 carries its \
             whole difference from identification's in its standard deviation",
            u.d0_n,
            u.frictionless_force_std_n,
            if est.settings.reports(idx::M) {
                "M is claimed no more precisely than identification's (the filter's M shares \
                 its error), "
            } else {
                ""
            },
            match &est.filter_k2 {
                Some(k) => format!(
                    "k2 is identification's (the filter's own, {:.5} +- {:.5} 1/mm, also \
                     reads the rod as sliding after it stops, and leans high), and ",
                    k.k2_per_mm, k.k2_per_mm_std
                ),
                None => "k2 carries its whole difference from identification's, and ".into(),
            }
        );
    }
    if est.inertia_unidentified() {
        let _ = writeln!(
            s,
            "note: k2 is claimed no more precisely than identification's: identification left \
             the inertia m out of its model, so the filter's model of the motion's dynamics, \
             which its k2 leans on, is not checked against the log"
        );
    }
    if let Some(t) = &est.twins {
        for c in &t.states {
            let _ = writeln!(
                s,
                "  {}: the filter's bias, {:+.3} %, measured on {} twins of the log (simulated \
                 with identification's transmission, {:.0} s each) and taken out; \
                 identification's error moves it by {:.3} % (1 sigma, included):\n    {:.6} +- \
                 {:.6} before, {:.6} +- {:.6} after",
                c.state,
                100.0 * c.bias / c.corrected.abs().max(1e-300),
                c.errors.len(),
                t.span_s,
                100.0 * c.excess_scatter / c.corrected.abs().max(1e-300),
                c.filter,
                c.filter_std,
                c.corrected,
                c.corrected_std
            );
        }
        if t.diverged > 0 {
            let _ = writeln!(
                s,
                "note: the filter diverged on {} of {} twins of the log (left out)",
                t.diverged, t.twins
            );
        }
    }
    for w in est.imprecise() {
        if w.identification_law_imprecise {
            let _ = writeln!(
                s,
                "warning: k2 is identification's (+-{:.2} %, 1 sigma), and identification \
                 determines the spring law on this log less precisely than its target (k2 \
                 within 0.5 %, mu within 1.5 %, at 2 sigma): {}",
                100.0 * w.relative_std,
                match w.log_length_factor {
                    Some(longer) => format!(
                        "a log about {longer:.1} times longer, or one with more motion, meets it"
                    ),
                    None => "a log with more motion meets it".into(),
                }
            );
            continue;
        }
        let mut remedy = match w.log_length_factor {
            Some(longer) => {
                format!("needs a log about {longer:.1} times longer, or one with more motion")
            }
            None if w.relative_identification_bias.is_some() => String::new(),
            None => "is met by the filter's own standard deviation".to_string(),
        };
        if let Some(b) = w.relative_identification_bias {
            remedy.push_str(&format!(
                "is not met: the filter's own standard deviation is held to 1/{} of \
                 identification's, which is mostly the allowance for identification's \
                 differentiating filter's bias ({:.2} %); a longer log reduces that only where \
                 it is noise, and a log with smoother accelerations (sines) or more motion \
                 resolves it better",
                est.m_precision_gain_max(),
                100.0 * b
            ));
        }
        if let Some(d) = w.relative_disagreement {
            remedy.push_str(&format!(
                "; the standard deviation is held to the filter's disagreement with \
                 identification on it ({:.2} %), which a longer log reduces only if it is \
                 random, and a log with more motion (sines or steps) resolves it better",
                100.0 * d
            ));
        }
        let _ = writeln!(
            s,
            "warning: the filter determines {} only to +-{:.2} % (1 sigma) on this log; the \
             target (k2 within 0.5 %, M within 2 %, at 2 sigma) {remedy}",
            w.state,
            100.0 * w.relative_std,
        );
    }
    let c = &est.consistency;
    let _ = writeln!(
        s,
        "  consistency: mean normalised innovation squared {:.2}{}",
        c.nis_mean,
        c.agreement
            .iter()
            .map(|a| format!("; {} {:.1} sigma from identification", a.state, a.sigmas))
            .collect::<String>()
    );
    if !c.consistent {
        let _ = writeln!(
            s,
            "THE FILTER IS NOT CONSISTENT ON THIS LOG: {}",
            c.reasons.join("; ")
        );
    }
    s
}

/// The text summary of `camspring estimate` (held constants at identification's value and
/// standard deviation, [`EstimateRun::reported_constants`]).
pub fn format_estimate(est: &EstimateRun) -> String {
    let run = &est.run;
    let (z, sd) = est.reported_constants();
    let f = run.offset_filter.theta;
    let fs = run.offset_filter.std();
    let mut s = String::new();
    let _ = writeln!(
        s,
        "EKF over {} samples (to t = {:.3} s); final estimates (1-sigma):",
        run.samples, run.t_end_s
    );
    if let Some(d) = &est.force_delay {
        s.push_str(&force_delay_line(d));
    }
    if let Some(screen) = &est.force_delay_screen {
        s.push_str(&force_delay_screen_line(screen));
    }
    for (name, k, unit) in [
        ("k2", idx::K2, "1/mm"),
        ("M", idx::M, "N s^2/mm"),
        ("d2", idx::D2, "N s^3/mm^3"),
        ("sigma", idx::SIGMA, "N/mm (last sample)"),
        ("D", idx::D, "N s/mm (last sample)"),
    ] {
        if !est.settings.reports(k) && sd[k] == 0.0 {
            let how = if est.settings.holds(k) {
                "held, not estimated"
            } else {
                "its start; not estimated"
            };
            let _ = writeln!(
                s,
                "  {name:<5} = {:>12.5e} {unit} ({how}: no standard deviation)",
                z[k]
            );
        } else {
            let _ = writeln!(s, "  {name:<5} = {:>12.5e} +- {:.2e} {unit}", z[k], sd[k]);
        }
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
    s.push_str(&format_sensor_noise(&est.noise));
    s
}

/// The text verdict.
pub fn format_validation(v: &Validation) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{}  against F = {:.6} N * exp({:.6} /mm * x) + {:.6} N over x = {:.3} ... {:.3} mm",
        crate::verdict::validate::verdict_word(v.pass, v.conclusive, v.judged),
        v.designed.mu_n,
        v.designed.k2_per_mm,
        v.designed.f0_n,
        v.range_min_mm,
        v.range_max_mm
    );
    s.push_str(&criteria_lines(&v.criteria));
    let _ = writeln!(
        s,
        "  identified F = {:.6} N * exp({:.6} /mm * x) + {}; {} k2 = {:.6} +- {:.6} /mm",
        v.identified.mu_n,
        v.identified.k2_per_mm,
        if v.identified.f0_n.is_finite() {
            format!("{:.6} N", v.identified.f0_n)
        } else {
            // Identification left F0 out (not identifiable from this log).
            "F0 (not identified)".to_string()
        },
        if v.ekf_consistent {
            "EKF"
        } else {
            "identified (the EKF was not consistent on this log)"
        },
        v.ekf_k2_per_mm,
        v.ekf_k2_per_mm_std
    );
    if let Some(e) = v.exponents {
        let _ = writeln!(
            s,
            "  the designed build's exponents over this range (contact friction): loading {:.6}, unloading {:.6}, mean {:.6} /mm",
            e.loading_k2_per_mm, e.unloading_k2_per_mm, e.mean.k2_per_mm
        );
    }
    if let Some(strokes) = &v.stroke_exponents {
        let _ = writeln!(
            s,
            "  k2 judged from each stroke's curve (the diagnosis's bins): {}",
            crate::verdict::validate::stroke_exponents_text(strokes)
        );
    }
    s.push_str(&band_exit_lines(&v.band_exits));
    s.push_str(&coverage_lines(v.coverage.as_ref(), v.position_offset_mm));
    if let Some(d) = &v.force_delay {
        s.push_str(&force_delay_line(d));
    }
    if let Some(screen) = &v.force_delay_screen {
        s.push_str(&force_delay_screen_line(screen));
    }
    s
}

/// The coverage and encoder-zero lines of a verdict.
fn coverage_lines(c: Option<&crate::verdict::validate::Coverage>, offset: Option<f64>) -> String {
    let mut s = String::new();
    if let Some(o) = offset {
        let _ = writeln!(
            s,
            "  encoder zero: {o:+.3} mm taken out of the log's positions (x = x_logged - offset)"
        );
    }
    if let Some(c) = c {
        let _ = writeln!(s, "  coverage: {}", c.summary());
        for w in &c.warnings {
            let _ = writeln!(s, "warning: {w}");
        }
    }
    s
}

/// `validation.svg`: stiffness against force (scatter and designed line) and the estimates
/// converging over time.
pub fn validation_svg(v: &Validation, run: &EkfRun) -> String {
    let n = run.rows.len();
    let stride = (n / 1500).max(1);
    let scatter: Vec<(f64, f64)> = run.rows[n / 2..]
        .iter()
        .step_by(stride)
        .map(|r| (spring_force_n(&r.state, &r.offsets), r.state[idx::SIGMA]))
        .collect();
    let fmax = scatter.iter().fold(0.0_f64, |m, p| m.max(p.0));
    let fmin = scatter.iter().fold(f64::INFINITY, |m, p| m.min(p.0));
    let line: Vec<(f64, f64)> = (0..=50)
        .map(|i| {
            let f = fmin + (fmax - fmin) * i as f64 / 50.0;
            (f, v.designed.k2_per_mm * (f - v.designed.f0_n))
        })
        .collect();
    let stiffness = Panel {
        title: "Stiffness against force (converged half of the run)".into(),
        x_label: "spring force F (N)".into(),
        y_label: "stiffness sigma (N/mm)".into(),
        series: vec![
            Series {
                label: "EKF estimate".into(),
                points: scatter,
                color: "#1f77b4",
                dashed: false,
                dots: true,
            },
            Series {
                label: format!(
                    "design: sigma = {:.4} /mm (F - {:.3} N)",
                    v.designed.k2_per_mm, v.designed.f0_n
                ),
                points: line,
                color: "#000",
                dashed: false,
                dots: false,
            },
        ],
        ..Default::default()
    };
    let pct = |k: usize, reference: f64| -> Vec<(f64, f64)> {
        run.rows
            .iter()
            .step_by(stride)
            .map(|r| (r.t_s, 100.0 * (r.state[k] / reference - 1.0)))
            .collect()
    };
    let last = run.last.z;
    let mut k2 = pct(idx::K2, v.designed.k2_per_mm);
    let mut m = pct(idx::M, last[idx::M]);
    // Clip the first transient so that the converged part stays readable.
    for p in k2.iter_mut().chain(m.iter_mut()) {
        p.1 = p.1.clamp(-20.0, 20.0);
    }
    let t_end = run.t_end_s;
    let t_start = run.rows.first().map_or(0.0, |r| r.t_s);
    let tol = v.criteria.first().map_or(0.0, |c| c.tolerance_percent);
    let convergence = Panel {
        title: "Estimates over time".into(),
        x_label: "time t (s)".into(),
        y_label: "deviation (%)".into(),
        series: vec![
            Series {
                label: "k2 against the design".into(),
                points: k2,
                color: "#d62728",
                dashed: false,
                dots: false,
            },
            Series {
                label: "M against its final value".into(),
                points: m,
                color: "#2ca02c",
                dashed: false,
                dots: false,
            },
            Series {
                label: format!("tolerance +-{tol:.2} %"),
                points: vec![(t_start, tol), (t_end, tol)],
                color: "#888",
                dashed: true,
                dots: false,
            },
            Series {
                label: String::new(),
                points: vec![(t_start, -tol), (t_end, -tol)],
                color: "#888",
                dashed: true,
                dots: false,
            },
        ],
        ..Default::default()
    };
    plot::document(&[stiffness, convergence], 620.0, 460.0).to_string()
}

/// A verdict's criteria, one line each (with the deviation's upper bound where it has one),
/// then what the log leaves open.
fn criteria_lines(criteria: &[crate::verdict::validate::Criterion]) -> String {
    use crate::verdict::validate::{criterion_word, not_shown_notes};
    let mut s: String = criteria
        .iter()
        .map(|c| {
            format!(
                "  {:<9} {:<22} {:>8.3} % ({}tolerance {:.3} %)  {}\n",
                criterion_word(c),
                c.name,
                c.deviation_percent,
                c.deviation_upper_percent
                    .map_or(String::new(), |u| if u.is_finite() {
                        format!("up to {u:.3} %; ")
                    } else {
                        "unbounded; ".to_string()
                    }),
                c.tolerance_percent,
                c.what
            )
        })
        .collect();
    for note in not_shown_notes(criteria) {
        s.push_str(&format!("  not conclusive: {note}\n"));
    }
    s
}

/// Where a measured curve leaves the band of builds, one line each.
fn band_exit_lines(exits: &[crate::verdict::validate::BandExit]) -> String {
    exits
        .iter()
        .map(|e| {
            format!(
                "  leaves the band of builds {} it at x = {:.2} ... {:.2} mm, by up to {:.2} N\n",
                e.side, e.from_mm, e.to_mm, e.worst_n
            )
        })
        .collect()
}

/// The text verdict on a law of any form (the quasi-static curve).
pub fn format_curve_validation(v: &CurveValidation) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{}  quasi-static force curve against the designed law over x = {:.3} ... {:.3} mm",
        crate::verdict::validate::verdict_word(v.pass, v.conclusive, v.judged),
        v.range_min_mm,
        v.range_max_mm
    );
    s.push_str(&criteria_lines(&v.criteria));
    let _ = writeln!(
        s,
        "  taken out of the force: m = {:.4e} N s^2/mm, d0 = {:.4} N, d1 = {:.4} N s/mm, d2 = {:.3e} N s^3/mm^3; {} bins",
        v.removed_m_n_s2_per_mm,
        v.removed_d0_n,
        v.removed_d1_n_s_per_mm,
        v.removed_d2_n_s3_per_mm3,
        v.bins.len()
    );
    s.push_str(&band_exit_lines(&v.band_exits));
    s.push_str(&coverage_lines(v.coverage.as_ref(), v.position_offset_mm));
    if let Some(d) = &v.force_delay {
        s.push_str(&force_delay_line(d));
    }
    s
}

/// `validation.svg` for a law of any form: the quasi-static force curve against the design,
/// and the relative deviation per bin.
pub fn curve_validation_svg(v: &CurveValidation) -> String {
    let curve = Panel {
        title: "Quasi-static force against the design".into(),
        x_label: "deflection x (mm)".into(),
        y_label: "force F (N)".into(),
        series: vec![
            Series {
                label: "measured (dynamics removed, binned)".into(),
                points: v.bins.iter().map(|b| (b.x_mm, b.measured_n)).collect(),
                color: "#1f77b4",
                dashed: false,
                dots: true,
            },
            Series {
                label: "designed law".into(),
                points: v.bins.iter().map(|b| (b.x_mm, b.designed_n)).collect(),
                color: "#000",
                dashed: false,
                dots: false,
            },
        ],
        ..Default::default()
    };
    let tol = v.criteria.first().map_or(0.0, |c| c.tolerance_percent);
    let (lo, hi) = (v.range_min_mm, v.range_max_mm);
    let deviation = Panel {
        title: "Deviation from the design".into(),
        x_label: "deflection x (mm)".into(),
        y_label: "deviation (%)".into(),
        series: vec![
            Series {
                label: "measured against designed".into(),
                points: v
                    .bins
                    .iter()
                    .map(|b| (b.x_mm, 100.0 * (b.measured_n / b.designed_n - 1.0)))
                    .collect(),
                color: "#d62728",
                dashed: false,
                dots: true,
            },
            Series {
                label: format!("tolerance +-{tol:.2} %"),
                points: vec![(lo, tol), (hi, tol)],
                color: "#888",
                dashed: true,
                dots: false,
            },
            Series {
                label: String::new(),
                points: vec![(lo, -tol), (hi, -tol)],
                color: "#888",
                dashed: true,
                dots: false,
            },
        ],
        ..Default::default()
    };
    plot::document(&[curve, deviation], 620.0, 460.0).to_string()
}

/// The measured force against deflection (quasi-static, binned, dynamics taken out) over the
/// designed law across the whole stroke, with the band of builds when there is one: what the
/// log shows of the spring, and which part of the stroke it covers.
pub fn force_points_svg(
    v: &CurveValidation,
    law: &crate::model::ForceLaw,
    xmax_mm: f64,
    band: Option<&crate::cam::tolerance::ForceBand>,
) -> String {
    let design: Vec<(f64, f64)> = (0..=100)
        .map(|i| {
            let x = xmax_mm * i as f64 / 100.0;
            (x, law.force_n(x))
        })
        .collect();
    let mut series = vec![
        Series {
            label: "designed law".into(),
            points: design,
            color: "#000",
            dashed: false,
            dots: false,
        },
        Series {
            label: "measured (quasi-static, dynamics removed, binned)".into(),
            points: v.bins.iter().map(|b| (b.x_mm, b.measured_n)).collect(),
            color: "#d62728",
            dashed: false,
            dots: true,
        },
    ];
    if let Some(b) = band {
        let upper: Vec<(f64, f64)> = b
            .x_mm
            .iter()
            .zip(&b.loading_hi_n)
            .filter_map(|(&x, f)| f.map(|f| (x, f)))
            .collect();
        let lower: Vec<(f64, f64)> = b
            .x_mm
            .iter()
            .copied()
            .zip(b.unloading_lo_n.iter().copied())
            .collect();
        series.push(Series {
            label: "band of builds: highest loading force".into(),
            points: upper,
            color: "#888",
            dashed: true,
            dots: false,
        });
        series.push(Series {
            label: "band of builds: lowest unloading force".into(),
            points: lower,
            color: "#bbb",
            dashed: true,
            dots: false,
        });
    }
    let panel = Panel {
        title: "Measured force against deflection over the designed stroke".into(),
        x_label: "deflection x (mm)".into(),
        y_label: "force F (N)".into(),
        series,
        ..Default::default()
    };
    plot::document(&[panel], 760.0, 460.0).to_string()
}

/// The diagnosis plot: the measured quasi-static force on each stroke, the design's forward
/// model built as designed, and the model with the fitted build.
pub fn diagnosis_svg(d: &crate::verdict::diagnose::Diagnosis) -> String {
    use crate::verdict::diagnose::DiagnosisBin;
    let pick = |loading: bool, f: &dyn Fn(&DiagnosisBin) -> f64| {
        d.bins
            .iter()
            .filter(|b| b.loading == loading)
            .map(|b| (b.x_mm, f(b)))
            .collect::<Vec<_>>()
    };
    let series = |what: &dyn Fn(&DiagnosisBin, f64) -> f64| {
        let s =
            |label: &str, loading, color, dashed, dots, value: &dyn Fn(&DiagnosisBin) -> f64| {
                Series {
                    label: label.into(),
                    points: pick(loading, &|b| what(b, value(b))),
                    color,
                    dashed,
                    dots,
                }
            };
        vec![
            s(
                "designed, loading (forward model, as designed)",
                true,
                "#888",
                true,
                false,
                &|b| b.designed_n,
            ),
            s("designed, unloading", false, "#bbb", true, false, &|b| {
                b.designed_n
            }),
            s(
                "re-fitted build, loading",
                true,
                "#000",
                false,
                false,
                &|b| b.refitted_n,
            ),
            s(
                "re-fitted build, unloading",
                false,
                "#555",
                false,
                false,
                &|b| b.refitted_n,
            ),
            s(
                "measured, loading (dynamics removed, binned)",
                true,
                "#d62728",
                false,
                true,
                &|b| b.measured_n,
            ),
            s("measured, unloading", false, "#1f77b4", false, true, &|b| {
                b.measured_n
            }),
        ]
    };
    let force = Panel {
        title: "Force against logged deflection".into(),
        x_label: "logged deflection x (mm)".into(),
        y_label: "force F (N)".into(),
        series: series(&|_, f| f),
        ..Default::default()
    };
    let deviation = Panel {
        title: "Against the design's own forward model".into(),
        x_label: "logged deflection x (mm)".into(),
        y_label: "deviation from the design, same stroke (%)".into(),
        // The left panel's legend serves both.
        series: series(&|b, f| 100.0 * (f / b.designed_n - 1.0))
            .into_iter()
            .map(|s| Series {
                label: String::new(),
                ..s
            })
            .collect(),
        ..Default::default()
    };
    plot::document(&[force, deviation], 620.0, 460.0).to_string()
}

/// One fitted build parameter as text: value, standard deviation, design, and whether the
/// log resolves it.
fn fitted_line(name: &str, unit: &str, f: &crate::verdict::diagnose::Fitted) -> String {
    let state = if f.fixed {
        "given".to_string()
    } else if f.resolved {
        "resolved".to_string()
    } else {
        "NOT RESOLVED by this log".to_string()
    };
    if !(f.fixed || f.resolved) {
        // No number for what the log does not say.
        return format!(
            "  {name:<22} {:>21} {unit:<4} designed {:.4}  ({state})\n",
            "-", f.designed
        );
    }
    format!(
        "  {name:<22} {:>10.4} +- {:<8.4}{unit:<4} designed {:.4}  ({state})\n",
        f.value, f.std, f.designed
    )
}

/// `camspring diagnose` as text.
pub fn format_diagnosis(d: &crate::verdict::diagnose::Diagnosis) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "diagnosis: the force misses the design's forward model by {:.2} % RMS; the fitted build leaves {:.2} % unexplained",
        d.force_error_before_percent, d.force_error_after_percent
    );
    if let Some(problem) = d.fit.problem() {
        let _ = writeln!(
            s,
            "THE DESIGN'S FORWARD MODEL DOES NOT FIT THIS LOG: {problem}. The findings below are \
             the best fit of a model that does not explain the log; do not revise the design on them."
        );
    }
    if let Some(delay) = &d.force_delay {
        s.push_str(&force_delay_line(delay));
        if !delay.parameter_std.is_empty() {
            let parts: Vec<String> = delay
                .parameter_std
                .iter()
                .map(|(k, v)| format!("{k} +- {v:.4}"))
                .collect();
            let _ = writeln!(
                s,
                "  its uncertainty is carried into the standard deviations below ({})",
                parts.join(", ")
            );
        }
    }
    if let Some(screen) = &d.force_delay_screen {
        s.push_str(&force_delay_screen_line(screen));
    }
    if d.findings.is_empty() {
        s.push_str("  no build parameter is off its design beyond its uncertainty\n");
    }
    for f in &d.findings {
        let _ = writeln!(s, "  - {f}");
    }
    for u in &d.unresolved {
        let _ = writeln!(s, "  ? {u}");
    }
    s.push_str("build parameters:\n");
    s.push_str(&fitted_line("spring_rate_scale", "", &d.spring_rate_scale));
    s.push_str(&fitted_line(
        "preload_offset_mm",
        "mm",
        &d.preload_offset_mm,
    ));
    s.push_str(&fitted_line("friction", "", &d.friction));
    s.push_str(&fitted_line("zero_offset_mm", "mm", &d.zero_offset_mm));
    let _ = writeln!(
        s,
        "dynamics taken out: m {:.4} N s^2/mm, d0 {:.3} +- {:.3} N, d1 {:.4} N s/mm, d2 {:.3e} N s^3/mm^3",
        d.m_n_s2_per_mm, d.d0_n[0], d.d0_n[1], d.d1_n_s_per_mm, d.d2_n_s3_per_mm3
    );
    let _ = writeln!(
        s,
        "fit: {} samples, window {:.2} s (by the window rule, of {} tried), reduced chi-square {:.2}{}",
        d.samples,
        d.sg_window_s,
        d.windows_tried.len(),
        d.reduced_chi2,
        match &d.fit.whiteness {
            Some(w) => format!(
                ", residual whiteness {:.1} over {} lags (p = {:.2e})",
                w.statistic, w.lags, w.p_value
            ),
            None => String::new(),
        }
    );
    if d.outside_stroke_samples > 0 {
        let _ = writeln!(
            s,
            "  {} samples beyond the designed stroke left out: the design's forward model does \
             not reach them",
            d.outside_stroke_samples
        );
    }
    if d.clipped_samples > 0 {
        let _ = writeln!(
            s,
            "  {} samples where the force stands clipped left out: the load cell did not \
             measure the spring's force there",
            d.clipped_samples
        );
    }
    if d.stop_samples > 0 {
        let _ = writeln!(
            s,
            "  {} samples against the stop identification found, and within half a window of \
             it, left out",
            d.stop_samples
        );
    }
    s
}

/// `camspring revise` as text.
pub fn format_revision(r: &crate::verdict::revise::Revision) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    if r.error_as_built_max_percent.is_finite() {
        let _ = writeln!(
            s,
            "as built, the force misses the law by up to {:.2} % ({:.2} % RMS) on the corrected stroke; tolerance {:.2} %",
            r.error_as_built_max_percent, r.error_as_built_rms_percent, r.tolerance_percent
        );
    }
    for (i, o) in r.options.iter().enumerate() {
        let mark = if Some(i) == r.chosen {
            "CHOSEN"
        } else if o.passes {
            "passes"
        } else {
            "no"
        };
        let _ = writeln!(
            s,
            "  [{mark}] {}: {}\n      predicted force error after: {:.2} % largest, {:.2} % RMS; checks: {}",
            o.kind.name(),
            o.change,
            o.predicted_error_max_percent,
            o.predicted_error_rms_percent,
            o.checks
                .iter()
                .map(|c| format!("{} {}", c.name, c.status.as_str()))
                .collect::<Vec<_>>()
                .join(", ")
        );
        if let Some(w) = &o.why_not {
            let _ = writeln!(s, "      why not: {w}");
        }
    }
    match (&r.refusal, r.chosen()) {
        (Some(why), _) => {
            let _ = writeln!(s, "REFUSED: {why}");
        }
        (None, Some(o)) => {
            let _ = writeln!(s, "revision {}: {}", r.revision, o.change);
        }
        _ => {}
    }
    s
}
