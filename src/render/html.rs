//! Self-contained HTML pages a designer can send to a colleague: `report.html` for a design and
//! `validation.html` for a calibration check. Inline CSS and inline SVG only: no scripts, no
//! network, one file.

use std::fmt::Write as _;

use serde_json::Value;

use super::plot::{self, Panel, Series};
use crate::design::Design;
use crate::outputs::DesignSummary;

const STYLE: &str = "body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;\
max-width:1280px;margin:2em auto;padding:0 1em;color:#222;line-height:1.4}\
h1{margin-bottom:.2em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:2em}\
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:.25em .6em;\
text-align:left;vertical-align:top}th{background:#f4f4f4}td.num{text-align:right;\
font-variant-numeric:tabular-nums}.pass{color:#fff;background:#2a7d2a}.warn{color:#000;\
background:#f0c000}.fail{color:#fff;background:#b22222}.badge{padding:.1em .5em;\
border-radius:.3em;font-weight:bold;white-space:nowrap}figure{margin:1em 0}figure svg{max-width:100%;height:auto;\
border:1px solid #eee}nav a{margin-right:1em}code{background:#f4f4f4;padding:0 .2em}";

/// Escapes text for HTML.
pub(crate) fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn badge(status: &str) -> String {
    let class = match status {
        "pass" | "PASS" => "pass",
        "warn" | "WARN" | "NOT SHOWN" | "PASS, NOT CONCLUSIVE" | "NOT JUDGED" => "warn",
        _ => "fail",
    };
    format!(
        "<span class=\"badge {class}\">{}</span>",
        escape(&status.to_uppercase())
    )
}

/// An SVG document as an inline figure (the XML declaration, if any, dropped).
fn figure(svg: &str, caption: &str) -> String {
    let body = svg
        .trim_start()
        .strip_prefix("<?xml")
        .and_then(|rest| rest.split_once("?>").map(|(_, b)| b))
        .unwrap_or(svg);
    format!(
        "<figure>{}<figcaption>{}</figcaption></figure>\n",
        body.trim(),
        escape(caption)
    )
}

/// Rows `key | value` of a JSON object, nested keys joined with dots.
fn json_rows(prefix: &str, value: &Value, out: &mut String) {
    match value {
        Value::Object(map) => {
            for (k, v) in map {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                json_rows(&key, v, out);
            }
        }
        Value::Array(items) if items.iter().all(|v| !v.is_object() && !v.is_array()) => {
            let text: Vec<String> = items.iter().map(scalar).collect();
            let _ = writeln!(
                out,
                "<tr><td><code>{}</code></td><td>{}</td></tr>",
                escape(prefix),
                escape(&text.join(", "))
            );
        }
        Value::Array(items) => {
            for (i, v) in items.iter().enumerate() {
                json_rows(&format!("{prefix}[{i}]"), v, out);
            }
        }
        v => {
            let _ = writeln!(
                out,
                "<tr><td><code>{}</code></td><td class=\"num\">{}</td></tr>",
                escape(prefix),
                escape(&scalar(v))
            );
        }
    }
}

fn scalar(v: &Value) -> String {
    match v {
        Value::Null => "—".into(),
        Value::String(s) => s.clone(),
        Value::Number(n) => match n.as_f64() {
            Some(x) if x.fract() != 0.0 => format!("{}", (x * 1e9).round() / 1e9),
            _ => n.to_string(),
        },
        other => other.to_string(),
    }
}

fn json_table(value: &Value) -> String {
    let mut rows = String::new();
    json_rows("", value, &mut rows);
    format!("<table><tr><th>key</th><th>value</th></tr>\n{rows}</table>\n")
}

/// Pressure angle and contact stress along the stroke (two panels).
pub fn stroke_svg(design: &Design) -> String {
    let angle = Panel {
        title: "Pressure angle along the stroke".into(),
        x_label: "deflection x (mm)".into(),
        y_label: "pressure angle theta (deg)".into(),
        series: vec![Series {
            label: "pressure angle".into(),
            points: design
                .forces
                .iter()
                .map(|f| (f.x_mm, f.pressure_angle_deg))
                .collect(),
            color: "#1f77b4",
            dashed: false,
            dots: false,
        }],
        ..Default::default()
    };
    let stress = Panel {
        title: "Peak Hertz contact stress on one roller".into(),
        x_label: "deflection x (mm)".into(),
        y_label: "contact stress (MPa)".into(),
        series: vec![Series {
            label: "contact stress".into(),
            points: design
                .forces
                .iter()
                .filter_map(|f| f.contact_stress_mpa.map(|s| (f.x_mm, s)))
                .collect(),
            color: "#d62728",
            dashed: false,
            dots: false,
        }],
        ..Default::default()
    };
    plot::document(&[angle, stress], 560.0, 420.0).to_string()
}

/// `report.html` of a design.
pub fn report_html(
    design: &Design,
    summary: &DesignSummary,
    force_svg: &str,
    profile_svg: &str,
) -> String {
    let mut h = String::with_capacity(256 * 1024);
    let name = escape(&summary.name);
    let run = escape(&summary.run_id);
    let kind = match summary.law.form {
        "table" => "Tabulated",
        "polynomial" => "Polynomial",
        _ => "Exponential",
    };
    let status = summary.status.as_str();
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\
         <meta name=\"camspring-run\" content=\"{run}\">\
         <title>camspring report: {name}</title><style>{STYLE}</style></head><body>\n\
         <h1>{kind} cam spring '{name}' {}</h1>\n\
         <p>camspring {} design report (run {run}). Every number carries its unit; the same data is in \
         <a href=\"design.json\">design.json</a>.</p>\n\
         <nav><a href=\"#law\">Law</a><a href=\"#curves\">Force</a><a href=\"#profile\">Cam</a>\
         <a href=\"#stroke\">Pressure angle and stress</a><a href=\"#checks\">Checks</a>\
         <a href=\"#buy\">To buy</a><a href=\"#part\">Part</a><a href=\"#files\">Files</a><a href=\"#spec\">Spec</a></nav>\n",
        badge(status),
        summary.camspring_version
    );

    // Law.
    let law = &summary.law;
    match (law.mu_n, law.k2_per_mm, law.f0_n) {
        (Some(mu), Some(k2), Some(f0)) => {
            let _ = write!(
                h,
                "<h2 id=\"law\">Force law</h2>\n<p><b>F(x) = {mu:.7} N &middot; exp({k2:.7} /mm &middot; x) + {f0:.7} N</b> (stated as: {})",
                law.form
            );
        }
        _ if law.form == "table" => {
            let _ = write!(
                h,
                "<h2 id=\"law\">Force law</h2>\n<p><b>Tabulated law</b>, {} points joined by a monotone cubic (Steffen); the force plot shows the points. The cam's predicted force meets the table at its points within {:.1e} (relative)",
                law.table_points.unwrap_or(0),
                law.table_max_rel_error.unwrap_or(f64::NAN)
            );
        }
        _ => {
            let _ = write!(
                h,
                "<h2 id=\"law\">Force law</h2>\n<p><b>{}</b> (stated as: {})",
                escape(&law.description),
                law.form
            );
        }
    }
    if let Some(alpha) = law.alpha {
        let _ = write!(h, ", alpha = k2 &middot; L0 = {alpha:.10}");
    }
    let _ = writeln!(
        h,
        ". F(0) = {:.4} N, F(Xmax) = {:.4} N.</p>",
        law.force_at_zero_n, law.force_at_xmax_n
    );
    if let Some(r) = &law.residuals {
        let value = serde_json::to_value(r).unwrap_or(Value::Null);
        let _ = write!(
            h,
            "<p>Residuals of the design conditions (relative):</p>{}",
            json_table(&value)
        );
    }
    if law.form == "targets" {
        h.push_str(
            "<p>Note on the paper's printed values: the paper prints alpha = 1.3288, which is not a \
             root of its eq. (5) (the residual there is about -3.9); the law above is the exact root \
             for this spec, derived in <code>docs/THEORY.md</code> and checked by the \
             test suite.</p>\n",
        );
    }
    if let Some(r) = &law.condition_residuals {
        let cells: Vec<String> = r.iter().map(|v| format!("{v:.1e}")).collect();
        let _ = writeln!(
            h,
            "<p>Solved from three conditions; their relative residuals: {}.</p>",
            cells.join(", ")
        );
    }

    // Curves.
    h.push_str("<h2 id=\"curves\">Force and stiffness</h2>\n");
    h.push_str(&figure(
        force_svg,
        "Designed force, predicted loading and unloading force (friction hysteresis) against \
         deflection, with the 95 % band of builds within the tolerances; stiffness against force.",
    ));
    if let Some(b) = &summary.force_band {
        let t = &summary.spec.tolerances;
        let _ = writeln!(
            h,
            "<h3>What a build may deliver</h3>\n<p>{} builds drawn within the tolerances (springs \
             &plusmn;{} %, preload &plusmn;{} mm, roller &plusmn;{} mm, profile &plusmn;{} mm, friction \
             {} to {}): at Xmax the loading force lies between {} and {} N in 95 % of them. Each \
             tolerance alone moves it by:</p>\n<table><tr><th>tolerance</th><th>&plusmn; loading force at Xmax</th></tr>",
            b.samples,
            t.spring_rate_percent,
            t.preload_mm,
            t.roller_radius_mm,
            t.profile_mm,
            t.friction_min,
            t.friction_max,
            b.loading_lo_n.last().copied().flatten().map_or("-".into(), |v| format!("{v:.2}")),
            b.loading_hi_n.last().copied().flatten().map_or("-".into(), |v| format!("{v:.2}")),
        );
        for s in &b.sensitivity {
            let _ = writeln!(
                h,
                "<tr><td>{}</td><td class=\"num\">{:.2} N</td></tr>",
                s.tolerance, s.loading_half_range_n
            );
        }
        h.push_str("</table>\n");
    }
    h.push_str("<h2 id=\"profile\">Cam profile</h2>\n");
    h.push_str(&figure(
        profile_svg,
        "Pitch curve (roller centre), machined cam surface and the roller at five positions, to scale.",
    ));
    h.push_str("<h2 id=\"stroke\">Pressure angle and contact stress</h2>\n");
    h.push_str(&figure(
        &stroke_svg(design),
        "Pressure angle and peak Hertz contact stress along the stroke.",
    ));

    // Checks.
    h.push_str(
        "<h2 id=\"checks\">Checks</h2>\n<table><tr><th>status</th><th>check</th><th>value</th>\
         <th>limit</th><th>at x</th><th>finding</th><th>advice</th></tr>\n",
    );
    for c in &summary.checks {
        let value = c.value.map_or("—".into(), |v| format!("{v:.4} {}", c.unit));
        let at = c.at_x_mm.map_or("—".into(), |x| format!("{x:.3} mm"));
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td>{}</td><td class=\"num\">{}</td><td class=\"num\">{:.4} {}</td>\
             <td class=\"num\">{}</td><td>{}</td><td>{}</td></tr>",
            badge(c.status.as_str()),
            escape(c.name),
            escape(&value),
            c.limit,
            escape(c.unit),
            escape(&at),
            escape(&c.message),
            escape(c.advice.as_deref().unwrap_or(""))
        );
    }
    h.push_str("</table>\n");

    // Part.
    // Parts to buy.
    let sp = &summary.springs;
    let _ = writeln!(
        h,
        "<h2 id=\"buy\">Springs and rollers to buy</h2>\n<table>\
         <tr><th>item</th><th>count</th><th>what it must do</th></tr>\n\
         <tr><td>spring, {:.4} N/mm</td><td class=\"num\">{}</td><td>{:.3} N at preload ({:.3} mm), \
         {:.3} N at full stroke ({:.3} mm): {:.3} mm of working travel</td></tr>",
        sp.rate_n_per_mm,
        sp.count,
        sp.force_at_preload_n,
        sp.deflection_at_preload_mm,
        sp.force_at_full_stroke_n,
        sp.deflection_at_full_stroke_mm,
        sp.travel_mm
    );
    if let Some(r) = &summary.rollers {
        let mut what = format!(
            "peak normal load {:.2} N at x = {:.3} mm, ISO 281 mean load {:.2} N, {:.2} revolutions per stroke",
            r.peak_normal_load_n, r.peak_at_x_mm, r.mean_equivalent_load_n, r.revolutions_per_stroke
        );
        if let Some(rpm) = r.speed_rpm {
            what.push_str(&format!(", {rpm:.1} rpm"));
        }
        if let Some(l) = r.l10_strokes {
            what.push_str(&format!(", L10 life {l:.3e} strokes"));
        }
        let _ = writeln!(
            h,
            "<tr><td>roller, radius {} mm</td><td class=\"num\">{}</td><td>{what}</td></tr>",
            summary.follower.roller_radius_mm, r.count
        );
    }
    h.push_str("</table>\n");
    h.push_str("<h2 id=\"part\">Part</h2>\n");
    match (&summary.part, &summary.part_refused) {
        (Some(part), _) => {
            let value = serde_json::to_value(part).unwrap_or(Value::Null);
            h.push_str(&json_table(&value));
        }
        (None, Some(why)) => {
            let _ = writeln!(h, "<p>No part files: {}</p>", escape(why));
        }
        (None, None) => h.push_str("<p>No part.</p>\n"),
    }
    if let Some(g) = &summary.gcode {
        for w in &g.toolpath.warnings {
            let _ = writeln!(h, "<p class=\"warn\">G-code warning: {}</p>", escape(w));
        }
        let _ = writeln!(
            h,
            "<p>Estimated cycle time {:.1} min (tool changes not counted), {} tools, stock at least {:.1} x {:.1} x {:.2} mm.</p>",
            g.toolpath.estimated_minutes,
            g.toolpath.tools.len(),
            g.toolpath.stock.size_mm[0],
            g.toolpath.stock.size_mm[1],
            g.toolpath.stock.size_mm[2]
        );
        let value = serde_json::to_value(g).unwrap_or(Value::Null);
        h.push_str("<p>G-code program:</p>");
        h.push_str(&json_table(&value));
    }
    if let Some(why) = &summary.gcode_refused {
        let _ = writeln!(h, "<p>{}</p>", escape(why));
    }

    // Files.
    h.push_str("<h2 id=\"files\">Files</h2>\n<ul>\n");
    for f in &summary.outputs {
        let _ = writeln!(h, "<li><a href=\"{0}\">{0}</a></li>", escape(f));
    }
    h.push_str("</ul>\n");

    // Spec.
    let spec = serde_json::to_value(&summary.spec).unwrap_or(Value::Null);
    h.push_str("<h2 id=\"spec\">Spec (as understood, default units)</h2>\n");
    h.push_str(&json_table(&spec));
    h.push_str("</body></html>\n");
    h
}

/// A verdict's criteria table (after its header row), closed, then what the log leaves open.
fn criteria_rows(h: &mut String, criteria: &[crate::verdict::validate::Criterion]) {
    use crate::verdict::validate::{criterion_word, not_shown_notes};
    for c in criteria {
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td>{}</td><td class=\"num\">{:.3} %</td><td class=\"num\">{}</td><td class=\"num\">{:.3} %</td><td>{}</td></tr>",
            badge(criterion_word(c)),
            escape(c.name),
            c.deviation_percent,
            c.deviation_upper_percent
                .map_or("&ndash;".to_string(), |u| if u.is_finite() {
                    format!("{u:.3} %")
                } else {
                    "unbounded".to_string()
                }),
            c.tolerance_percent,
            escape(c.what)
        );
    }
    h.push_str("</table>\n");
    let notes = not_shown_notes(criteria);
    if !notes.is_empty() {
        h.push_str("<p><strong>Not conclusive:</strong></p>\n<ul>\n");
        for n in notes {
            let _ = writeln!(h, "<li>{}</li>", escape(&n));
        }
        h.push_str("</ul>\n");
    }
}

/// The section of a validation page on how its log was read: the reader's notes (columns
/// read by their names, a units row) and warnings (dropped samples filled, rows left out,
/// samples taken at uneven times); empty when it has none.
pub fn log_reading_section(notes: &[String], warnings: &[String]) -> String {
    if notes.is_empty() && warnings.is_empty() {
        return String::new();
    }
    // The reader's messages run on from a path on stderr; here each opens a paragraph.
    let sentence = |m: &str| {
        let mut chars = m.chars();
        chars.next().map_or(String::new(), |c| {
            escape(&(c.to_uppercase().collect::<String>() + chars.as_str()))
        })
    };
    let mut h = String::from("<h2>Reading the log</h2>\n");
    for n in notes {
        let _ = writeln!(h, "<p>{}.</p>", sentence(n));
    }
    for w in warnings {
        let _ = writeln!(
            h,
            "<p><span class=\"warn\">Warning</span> {}.</p>",
            sentence(w)
        );
    }
    h
}

/// `validation.html`: the verdict, the criteria and the plots of `validation.svg`.
pub fn validation_html(
    v: &crate::verdict::validate::Validation,
    validation_svg: Option<&str>,
    log_name: &str,
    force_svg: &str,
    diagnosis_html: &str,
) -> String {
    let mut h = String::with_capacity(128 * 1024);
    let verdict = crate::verdict::validate::verdict_word(v.pass, v.conclusive, v.judged);
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <title>camspring validation: {log}</title><style>{STYLE}</style></head><body>\n\
         <h1>Validation of {log} {}</h1>\n\
         <p>Designed law: F(x) = {:.7} N &middot; exp({:.7} /mm &middot; x) + {:.7} N. \
         Identified from the log: F(x) = {:.7} N &middot; exp({:.7} /mm &middot; x) + {:.7} N. \
         {} k2 = {:.7} &plusmn; {:.7} /mm. Deflections in the log: {:.3} to {:.3} mm.</p>\n",
        badge(verdict),
        v.designed.mu_n,
        v.designed.k2_per_mm,
        v.designed.f0_n,
        v.identified.mu_n,
        v.identified.k2_per_mm,
        v.identified.f0_n,
        if v.ekf_consistent {
            "EKF"
        } else {
            "Identified (the filter did not run, or was not consistent on this log)"
        },
        v.ekf_k2_per_mm,
        v.ekf_k2_per_mm_std,
        v.range_min_mm,
        v.range_max_mm,
        log = escape(log_name),
    );
    if let (Some(strokes), Some(e)) = (&v.stroke_exponents, &v.exponents) {
        let _ = writeln!(
            h,
            "<p>k2 is judged from each stroke's curve (the diagnosis's bins, the rod's dynamics \
             taken out), which the filter's and identification's constant friction cannot \
             follow here: {}, against the designed build's loading {:.6} and unloading {:.6} \
             /mm.</p>",
            escape(&crate::verdict::validate::stroke_exponents_text(strokes))
                .replace("+-", "&plusmn;"),
            e.loading_k2_per_mm,
            e.unloading_k2_per_mm
        );
    }
    if let Some(screen) = v.force_delay_screen.as_ref().filter(|s| s.suspected) {
        let held = &screen.held;
        let late = if held.delay_s >= 0.0 {
            "after"
        } else {
            "before"
        };
        let std = screen.std_with_window_s();
        let _ = writeln!(
            h,
            "<p><span class=\"warn\">Warning</span> The force looks read {:.1} &plusmn; {:.1} ms \
             {late} the position ({:.1} standard deviations from none, at two filter windows): \
             a fit read as logged takes such a delay as inertia and damping. Run again with \
             <code>--force-delay auto</code> to fit it and re-time the force.</p>",
            held.delay_s.abs() * 1e3,
            std * 1e3,
            held.delay_s.abs() / std
        );
    }
    h.push_str(
        "<h2>Criteria</h2>\n<table><tr><th>status</th><th>criterion</th><th>deviation</th>\
         <th>upper bound</th><th>tolerance</th><th>what</th></tr>\n",
    );
    criteria_rows(&mut h, &v.criteria);
    if let Some(svg) = validation_svg {
        h.push_str("<h2>Stiffness against force, and convergence</h2>\n");
        h.push_str(&figure(
            svg,
            "Left: EKF stiffness against spring force over the converged half of the run, with \
             the designed line. Right: k2 against the design and M against its final value over \
             time.",
        ));
    }
    h.push_str("<h2>Measured force against deflection</h2>\n");
    coverage_paragraph(
        &mut h,
        v.coverage.as_ref(),
        v.position_offset_mm,
        v.force_delay.as_ref(),
    );
    h.push_str(&figure(
        force_svg,
        "The log's quasi-static force (inertia, damping and Coulomb friction fitted and taken out, \
         averaged in bins of deflection) over the designed law across the whole stroke, with the \
         band of builds that the spec's tolerances allow.",
    ));
    h.push_str(diagnosis_html);
    h.push_str("</body></html>\n");
    h
}

/// What part of the stroke the log covers, the encoder zero applied, and the warnings.
fn coverage_paragraph(
    h: &mut String,
    c: Option<&crate::verdict::validate::Coverage>,
    offset: Option<f64>,
    delay: Option<&crate::estimate::retime::ForceDelayFit>,
) {
    if let Some(o) = offset {
        let _ = writeln!(
            h,
            "<p>Encoder zero: {o:+.3} mm taken out of the logged positions.</p>"
        );
    }
    if let Some(d) = delay {
        let late = if d.delay_s >= 0.0 { "after" } else { "before" };
        let how = match d.std_s {
            Some(s) if d.fitted => format!(" (+- {:.2} ms, fitted by identification)", s * 1e3),
            _ => " (as given)".to_owned(),
        };
        let _ = writeln!(
            h,
            "<p>Force channel: read {:.2} ms {late} the position{how}; each force was re-timed \
             to its position's instant before judging.</p>",
            d.delay_s.abs() * 1e3
        );
    }
    if let Some(c) = c {
        let _ = writeln!(h, "<p>Coverage: {}.</p>", escape(&c.summary()));
        for w in &c.warnings {
            let _ = writeln!(
                h,
                "<p><span class=\"warn\">Warning</span> {}</p>",
                escape(w)
            );
        }
    }
}

/// `validation.html` for a law of any form: the verdict on the quasi-static force curve.
pub fn curve_validation_html(
    v: &crate::verdict::validate::CurveValidation,
    validation_svg: &str,
    log_name: &str,
    diagnosis_html: &str,
) -> String {
    let mut h = String::with_capacity(64 * 1024);
    let verdict = crate::verdict::validate::verdict_word(v.pass, v.conclusive, v.judged);
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <title>camspring validation: {log}</title><style>{STYLE}</style></head><body>\n\
         <h1>Validation of {log} {}</h1>\n\
         <p>The designed law is not exponential, so the log is judged by its quasi-static \
         force-deflection curve: inertia (m = {:.4e} N s&sup2;/mm), damping (d1 = {:.4} N s/mm, \
         d2 = {:.3e} N s&sup3;/mm&sup3;) and Coulomb friction (d0 = {:.4} N) fitted and taken out, \
         the rest averaged in {} bins over {:.3} to {:.3} mm.</p>\n\
         <h2>Criteria</h2>\n<table><tr><th>status</th><th>criterion</th><th>deviation</th>\
         <th>upper bound</th><th>tolerance</th><th>what</th></tr>\n",
        badge(verdict),
        v.removed_m_n_s2_per_mm,
        v.removed_d1_n_s_per_mm,
        v.removed_d2_n_s3_per_mm3,
        v.removed_d0_n,
        v.bins.len(),
        v.range_min_mm,
        v.range_max_mm,
        log = escape(log_name),
    );
    criteria_rows(&mut h, &v.criteria);
    h.push_str("<h2>Force curve</h2>\n");
    h.push_str(&figure(
        validation_svg,
        "Left: the measured force with the dynamics removed, binned, and the designed law. \
         Right: the relative deviation per bin and the tolerance.",
    ));
    coverage_paragraph(
        &mut h,
        v.coverage.as_ref(),
        v.position_offset_mm,
        v.force_delay.as_ref(),
    );
    h.push_str(diagnosis_html);
    h.push_str("</body></html>\n");
    h
}

/// The diagnosis as a section of validation.html: what the build got wrong, the fitted
/// build parameters, and the measured, designed and re-fitted curves.
pub fn diagnosis_section(d: &crate::verdict::diagnose::Diagnosis, svg: &str) -> String {
    let mut h = String::new();
    let _ = write!(
        h,
        "<h2>Diagnosis: what the build got wrong</h2>\n<p>The measured force (dynamics taken out, \
         loading and unloading apart) misses the design's forward model by {:.2} % RMS; with the \
         build parameters fitted, {:.2} % is left unexplained (reduced chi-square {:.2}).</p>\n<ul>\n",
        d.force_error_before_percent, d.force_error_after_percent, d.reduced_chi2
    );
    if let Some(problem) = d.fit.problem() {
        let _ = writeln!(
            h,
            "<li><b>The design's forward model does not fit this log:</b> {}. \
             The findings below are the best fit of a model that does not explain the log.</li>",
            escape(&problem)
        );
    }
    if d.findings.is_empty() {
        h.push_str("<li>No build parameter is off its design beyond its uncertainty.</li>\n");
    }
    for f in &d.findings {
        let _ = writeln!(h, "<li>{}</li>", escape(f));
    }
    for u in &d.unresolved {
        let _ = writeln!(h, "<li>Not resolved: {}</li>", escape(u));
    }
    h.push_str(
        "</ul>\n<table><tr><th>build parameter</th><th>fitted</th><th>&plusmn; 1 sigma</th>\
         <th>designed</th><th>state</th></tr>\n",
    );
    for (name, f) in [
        ("spring rate / designed", &d.spring_rate_scale),
        ("preload offset (mm)", &d.preload_offset_mm),
        ("contact friction", &d.friction),
        ("encoder zero (mm)", &d.zero_offset_mm),
    ] {
        let state = if f.fixed {
            "given"
        } else if f.resolved {
            "resolved"
        } else {
            "not resolved"
        };
        let (value, std) = if f.fixed || f.resolved {
            (format!("{:.4}", f.value), format!("{:.4}", f.std))
        } else {
            // No number for what the log does not say.
            ("&ndash;".to_string(), "&ndash;".to_string())
        };
        let _ = writeln!(
            h,
            "<tr><td>{name}</td><td>{value}</td><td>{std}</td><td>{:.4}</td><td>{state}</td></tr>",
            f.designed
        );
    }
    h.push_str("</table>\n");
    h.push_str(&figure(
        svg,
        "The measured quasi-static force on each stroke (dots), the design's forward model as \
         designed (dashed) and with the fitted build (lines), against the logged deflection.",
    ));
    h
}
