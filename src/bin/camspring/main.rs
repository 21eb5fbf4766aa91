//! The `camspring` command line: parses arguments ([`cli`]), calls the library's commands
//! ([`camspring::app`]), and prints one report through [`emit`].
//!
//! Exit codes: 0 done (warnings allowed), 1 a design check or a validation failed (outputs
//! still written), 2 bad input (spec, log, arguments), 3 an output could not be written.

mod cli;

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{CommandFactory, Parser};

use serde_json::json;

use camspring::app::{
    self, load_noise_json, parse_state_override, run_design, run_diagnose, run_estimate,
    run_identify, run_noise, run_revise, run_simulate, run_sweep, run_validate, BuildChange,
    DiagnoseOptions, InitSource, SimulateOptions, Verdict, EXIT_BAD_INPUT, EXIT_CHECK_FAILED,
    EXIT_IO, EXIT_OK, REVISION_JSON,
};
use camspring::cam::checks::Status;
use camspring::estimate::identify::FitStatus;
use camspring::estimate::log::{parse_column, parse_time_column, ColumnMap};
use camspring::estimate::noise::GivenNoise;
use camspring::estimate::sim::{Dynamics, Noise, SimSettings};
use camspring::export::ExportError;
use camspring::render::calibration::{
    estimate_json, format_consistency, format_curve_validation, format_diagnosis, format_estimate,
    format_identification, format_noise, format_revision, format_validation, identification_json,
    noise_json,
};
use camspring::render::design::format_design;
use camspring::units::Dimension;
use camspring::{Error, EstimateOptions};

use cli::{BuildFitArgs, CalibrationArgs, Cli, Columns, Command, FilterArgs, Sensors};

/// What a command has to say: its text, its JSON (already encoded, in the field order of its
/// type) and its exit code.
struct Report {
    text: String,
    json: String,
    code: u8,
    coloured: bool,
}

impl Report {
    fn new(text: String, json: String) -> Report {
        Report {
            text,
            json,
            code: EXIT_OK,
            coloured: false,
        }
    }

    /// A report of checks: PASS, WARN and FAIL are coloured on a terminal.
    fn of_checks(text: String, json: String, code: u8) -> Report {
        Report {
            code,
            coloured: true,
            ..Report::new(text, json)
        }
    }
}

/// Prints a report (its text, or its JSON with `--json`) or an error, and returns the exit
/// code; with `--json-to FILE` the JSON (the error's too) is also written to FILE first. A
/// closed pipe (`camspring ... | head`) ends quietly; any other failure to write stdout, or
/// FILE, is exit code 3.
fn emit(result: Result<Report, Error>, json: bool, json_to: Option<&Path>) -> ExitCode {
    let report = match result {
        Ok(r) => r,
        Err(e) => {
            let code = if e.is_bad_input() {
                EXIT_BAD_INPUT
            } else {
                EXIT_IO
            };
            // Every message already carries its cause (key, line, OS error).
            let message = sanitize(&e.to_string());
            eprintln!("error: {message}");
            let mut error = json!({ "kind": e.kind(), "message": message });
            if let Some(key) = e.key() {
                error["key"] = json!(key);
            }
            if let Some(line) = e.line() {
                error["line"] = json!(line);
            }
            if let Some(path) = json_to {
                if !write_json_to(path, &json_error_text(&error)) {
                    return ExitCode::from(EXIT_IO);
                }
            }
            if json {
                return print_json_error(error, code);
            }
            return ExitCode::from(code);
        }
    };
    if let Some(path) = json_to {
        if !write_json_to(path, &report.json) {
            return ExitCode::from(EXIT_IO);
        }
    }
    let text = if json {
        report.json + "\n"
    } else if report.coloured {
        colour(&report.text)
    } else {
        report.text
    };
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Ok(()) => ExitCode::from(report.code),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => ExitCode::from(report.code),
        Err(e) => {
            eprintln!("error: cannot write to stdout: {e}");
            ExitCode::from(EXIT_IO)
        }
    }
}

/// A message with its control characters (other than line breaks) escaped, so that nothing
/// echoed from a spec, a log or an argument can drive the terminal.
fn sanitize(message: &str) -> String {
    message
        .split('\n')
        .map(|l| camspring::units::printable(l, usize::MAX))
        .collect::<Vec<_>>()
        .join("\n")
}

/// Writes a JSON report to the `--json-to` file (with a final line break), replacing it
/// whole; false (the message printed) where it cannot be written.
fn write_json_to(path: &Path, json: &str) -> bool {
    match camspring::export::write_atomic(path, format!("{json}\n").as_bytes()) {
        Ok(()) => true,
        Err(e) => {
            eprintln!(
                "error: --json-to {}: {}",
                sanitize(&path.display().to_string()),
                sanitize(&e.to_string())
            );
            false
        }
    }
}

/// `{"error": {...}}`, as `--json` prints an error.
fn json_error_text(error: &serde_json::Value) -> String {
    serde_json::to_string_pretty(&json!({ "error": error })).unwrap_or_default()
}

/// `{"error": {...}}` on stdout, for `--json`; the exit code stays the error's.
fn print_json_error(error: serde_json::Value, code: u8) -> ExitCode {
    let text = json_error_text(&error);
    match writeln!(std::io::stdout().lock(), "{text}") {
        Ok(()) => ExitCode::from(code),
        Err(_) => ExitCode::from(EXIT_IO),
    }
}

/// Parses the arguments; a usage error is printed like every other error (sanitised, and as
/// JSON with `--json`) with clap's exit code 2.
fn parse_args() -> Result<Cli, ExitCode> {
    Cli::try_parse().map_err(|e| {
        use clap::error::ErrorKind;
        if matches!(
            e.kind(),
            ErrorKind::DisplayHelp
                | ErrorKind::DisplayVersion
                | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
        ) {
            let _ = e.print();
            return ExitCode::from(if e.use_stderr() {
                EXIT_BAD_INPUT
            } else {
                EXIT_OK
            });
        }
        let message = sanitize(e.render().to_string().trim_end());
        eprintln!("{message}");
        if std::env::args().any(|a| a == "--json") {
            let text = message.trim_start_matches("error: ").to_string();
            return print_json_error(
                json!({ "kind": "argument", "message": text }),
                EXIT_BAD_INPUT,
            );
        }
        ExitCode::from(EXIT_BAD_INPUT)
    })
}

/// Colours the status words PASS, WARN, FAIL and REFUSED, only when stdout is a terminal and
/// NO_COLOR is not set (https://no-color.org).
fn colour(text: &str) -> String {
    use std::io::IsTerminal;
    if !std::io::stdout().is_terminal() || std::env::var_os("NO_COLOR").is_some() {
        return text.to_string();
    }
    text.replace("PASS", "\x1b[32mPASS\x1b[0m")
        .replace("WARN", "\x1b[33mWARN\x1b[0m")
        .replace("FAIL", "\x1b[31mFAIL\x1b[0m")
        .replace("REFUSED", "\x1b[31mREFUSED\x1b[0m")
}

/// A command's JSON object with what reading its log found, as `log_reading`.
fn with_log_reading(
    v: impl serde::Serialize,
    reading: &camspring::app::LogReading,
) -> Result<serde_json::Value, Error> {
    let encode = |e: serde_json::Error| {
        Error::Export(ExportError::Encode {
            what: "the JSON result",
            message: e.to_string(),
        })
    };
    let mut v = serde_json::to_value(v).map_err(encode)?;
    if let Some(object) = v.as_object_mut() {
        object.insert(
            "log_reading".into(),
            serde_json::to_value(reading).map_err(encode)?,
        );
    }
    Ok(v)
}

fn to_json(v: &impl serde::Serialize) -> Result<String, Error> {
    serde_json::to_string_pretty(v).map_err(|e| {
        Error::Export(ExportError::Encode {
            what: "the JSON result",
            message: e.to_string(),
        })
    })
}

fn sensors(s: &Sensors) -> Result<GivenNoise, Error> {
    let mut sensor = match &s.noise {
        Some(p) => GivenNoise::from(load_noise_json(p)?),
        None => GivenNoise::default(),
    };
    if let Some(v) = s.force_variance {
        sensor.force_variance_n2 = Some(v);
    }
    if let Some(v) = s.position_variance {
        sensor.position_variance_mm2 = Some(v);
    }
    Ok(sensor)
}

fn filter_options(f: &FilterArgs, s: &Sensors) -> Result<EstimateOptions, Error> {
    let mut opts = EstimateOptions::new(sensors(s)?);
    opts.window_s = s.window;
    opts.force_delay = s.force_delay;
    opts.discretization = f.discretization.into();
    opts.force_rate = f.force_rate;
    opts.q =
        f.q.iter()
            .map(|t| parse_state_override(t, "--q"))
            .collect::<Result<_, _>>()?;
    opts.p0_std =
        f.p0.iter()
            .map(|t| parse_state_override(t, "--p0"))
            .collect::<Result<_, _>>()?;
    opts.r_position_mm2 = f.r;
    opts.position_offset = f.position_offset;
    opts.identify_span_s = f.identify_span;
    opts.twins = f.twins.into();
    app::with_init(opts, &f.init)
}

/// The column map, sampling tolerance and estimation options of `estimate` and `validate`.
fn diagnose_options(b: &BuildFitArgs) -> Result<DiagnoseOptions, Error> {
    Ok(DiagnoseOptions {
        map: columns(&b.columns)?,
        sampling_tolerance: b.columns.sampling_tolerance,
        noise: sensors(&b.sensors)?,
        window_s: b.sensors.window,
        force_delay: b.sensors.force_delay,
        zero: b.position_offset,
    })
}

fn calibration_options(c: &CalibrationArgs) -> Result<(ColumnMap, f64, EstimateOptions), Error> {
    Ok((
        columns(&c.columns)?,
        c.columns.sampling_tolerance,
        filter_options(&c.filter, &c.sensors)?,
    ))
}

fn columns(c: &Columns) -> Result<ColumnMap, Error> {
    let arg = |e: camspring::estimate::log::LogError| Error::Argument(e.to_string());
    Ok(ColumnMap {
        time: parse_time_column(&c.time).map_err(arg)?,
        force: parse_column(&c.force, Dimension::Force, "force").map_err(arg)?,
        position: parse_column(&c.position, Dimension::Length, "position").map_err(arg)?,
        delimiter: c.delimiter.into(),
        rows_at_hz: c.sample_rate,
    })
}

/// `camspring man`: camspring.1 on stdout, or every page into a folder.
fn man_pages(out: Option<&Path>) -> Result<Report, Error> {
    let cmd = Cli::command();
    let render = |c: &clap::Command| -> Result<Vec<u8>, Error> {
        let mut buf = Vec::new();
        clap_mangen::Man::new(c.clone())
            .render(&mut buf)
            .map_err(|e| {
                Error::Export(ExportError::Encode {
                    what: "man page",
                    message: e.to_string(),
                })
            })?;
        Ok(buf)
    };
    let Some(dir) = out else {
        let page = String::from_utf8_lossy(&render(&cmd)?).into_owned();
        return Ok(Report::new(page, String::new()));
    };
    let mut pages = vec![("camspring.1".to_string(), cmd.clone())];
    for sub in cmd.get_subcommands() {
        // clap names are 'static; a few page names live until the process ends.
        let name: &'static str =
            Box::leak(format!("camspring-{}", sub.get_name()).into_boxed_str());
        pages.push((format!("{name}.1"), sub.clone().name(name)));
    }
    let mut text = String::new();
    let mut written = Vec::new();
    for (file, c) in pages {
        let path = dir.join(&file);
        camspring::write_atomic(&path, &render(&c)?)?;
        text.push_str(&format!("  {}\n", path.display()));
        written.push(path);
    }
    Ok(Report::new(text, to_json(&json!({ "written": written }))?))
}

fn init(path: &Path, force: bool, law: cli::LawArg) -> Result<Report, Error> {
    use camspring::spec::{starter_spec, StarterLaw, STARTER_TABLE_CSV};
    let form = StarterLaw::from(law);
    let stem = path
        .file_stem()
        .map_or("spec".into(), |s| s.to_string_lossy().into_owned());
    let table_name = format!("{stem}-table.csv");
    let table = (form == StarterLaw::Table).then(|| path.with_file_name(&table_name));
    for p in std::iter::once(path).chain(table.as_deref()) {
        if p.exists() && !force {
            return Err(Error::Argument(format!(
                "{} exists; choose another name or pass --force to overwrite it",
                p.display()
            )));
        }
    }
    if let Some(t) = &table {
        camspring::write_atomic(t, STARTER_TABLE_CSV.as_bytes())?;
    }
    camspring::write_atomic(path, starter_spec(form, &table_name).as_bytes())?;
    let mut text = format!("wrote {}", path.display());
    if let Some(t) = &table {
        text.push_str(&format!(" and {}", t.display()));
    }
    text.push_str(&format!(
        "; edit it, then: camspring design {}\n",
        path.display()
    ));
    Ok(Report::new(
        text,
        to_json(&json!({ "spec": path, "table": table }))?,
    ))
}

fn main() -> ExitCode {
    let cli = match parse_args() {
        Ok(cli) => cli,
        Err(code) => return code,
    };
    let json_to = cli.json_to.clone();
    if json_to.is_some()
        && matches!(
            cli.command,
            Command::Completions { .. } | Command::Man { .. }
        )
    {
        eprintln!("error: --json-to: `completions` and `man` have no JSON report");
        return ExitCode::from(EXIT_BAD_INPUT);
    }
    let emit = |result: Result<Report, Error>, json: bool| emit(result, json, json_to.as_deref());
    match cli.command {
        Command::Design { spec, out, json } => emit(
            run_design(spec.as_deref(), out.as_deref()).and_then(|run| {
                Ok(Report::of_checks(
                    format_design(&run.summary, &run.written),
                    to_json(&run.summary)?,
                    run.exit_code(),
                ))
            }),
            json,
        ),
        Command::Init {
            path,
            force,
            law,
            json,
        } => emit(init(&path, force, law), json),
        Command::Sweep {
            spec,
            vary,
            out,
            advice,
            json,
        } => emit(
            run_sweep(spec.as_deref(), &vary, out.as_deref(), advice).and_then(|run| {
                let count = |s: Status| {
                    run.points
                        .iter()
                        .filter(|p| p.result.as_ref().is_ok_and(|r| r.status == s))
                        .count()
                };
                let mut text = format!(
                    "{} designs: {} pass, {} warn, {} fail, {} without a design\n",
                    run.points.len(),
                    count(Status::Pass),
                    count(Status::Warn),
                    count(Status::Fail),
                    run.points.iter().filter(|p| p.result.is_err()).count()
                );
                for p in &run.written {
                    text.push_str(&format!("  {}\n", p.display()));
                }
                Ok(Report::new(text, to_json(&run.points)?))
            }),
            json,
        ),
        Command::Springs {
            spec,
            apply,
            out,
            json,
        } => emit(
            camspring::app::run_springs(&spec, apply.as_deref(), out.as_deref()).and_then(|run| {
                let mut text = String::from(
                    "part      rate N/mm  preload mm  status  deflection mm  margin mm\n",
                );
                for c in &run.choices {
                    match (
                        c.preload_mm,
                        c.status,
                        c.deflection_at_full_stroke_mm,
                        c.margin_mm,
                    ) {
                        (Some(p), Some(st), Some(d), Some(m)) => text.push_str(&format!(
                            "{:<9} {:>9.3} {:>11.3}  {:<6} {:>13.3} {:>10.3}\n",
                            c.spring.part,
                            c.spring.rate_n_per_mm,
                            p,
                            st.as_str().to_uppercase(),
                            d,
                            m
                        )),
                        _ => text.push_str(&format!(
                            "{:<9} {:>9.3}  cannot: {}\n",
                            c.spring.part,
                            c.spring.rate_n_per_mm,
                            c.why.as_deref().unwrap_or("")
                        )),
                    }
                }
                if let Some(p) = &run.written {
                    text.push_str(&format!("wrote {}\n", p.display()));
                }
                Ok(Report::of_checks(
                    text,
                    to_json(&json!({ "choices": run.choices, "written": run.written }))?,
                    EXIT_OK,
                ))
            }),
            json,
        ),
        Command::Simulate {
            spec,
            out,
            truth,
            json,
            profile,
            duration,
            rate,
            seed,
            speed,
            m,
            d0,
            d1,
            d2,
            force_variance,
            position_variance,
            built,
        } => {
            let change = BuildChange {
                rate_scale: built.built_rate_scale,
                preload_offset_mm: built.built_preload_offset,
                friction: built.built_friction,
                zero_offset_mm: built.built_zero_offset,
            };
            let settings = SimSettings {
                profile: profile.into(),
                duration_s: duration,
                rate_hz: rate,
                seed,
                speed,
                dynamics: Dynamics {
                    m_n_s2_per_mm: m,
                    d0_n: d0,
                    d1_n_s_per_mm: d1,
                    d2_n_s3_per_mm3: d2,
                },
                noise: Noise {
                    force_variance_n2: force_variance,
                    position_variance_mm2: position_variance,
                },
            };
            let opts = SimulateOptions {
                settings,
                log_path: out,
                truth_path: truth,
                build: (built.built || change != BuildChange::default()).then_some(change),
            };
            emit(
                run_simulate(spec.as_deref(), &opts).and_then(|run| {
                    let law = match run.law.exponential() {
                        Some(l) => format!(
                            "F = {:.6} N * exp({:.6} /mm * x) + {:.6} N",
                            l.mu_n, l.k2_per_mm, l.f0_n
                        ),
                        None => run.law.describe(),
                    };
                    let built = run.as_built.map_or(String::new(), |b| {
                        format!(
                            " built off the design (springs x{:.4}, preload {:+.3} mm, friction {:.4}, encoder zero {:+.3} mm)",
                            b.spring_rate_scale, b.preload_offset_mm, b.friction, b.zero_offset_mm
                        )
                    });
                    let text = format!(
                        "simulated {} samples of {law}{built}\n  log:   {}\n  truth: {}\n",
                        run.samples,
                        run.log_path.display(),
                        run.truth_path.display()
                    );
                    let json = json!({
                        "log": run.log_path,
                        "truth": run.truth_path,
                        "samples": run.samples,
                        "law": run.law,
                        "as_built": run.as_built,
                    });
                    Ok(Report::new(text, to_json(&json)?))
                }),
                json,
            )
        }
        Command::Noise {
            log,
            svg,
            json,
            columns: c,
        } => emit(
            columns(&c)
                .and_then(|map| run_noise(&log, &map, c.sampling_tolerance, svg.as_deref()))
                .and_then(|run| {
                    let text = format!(
                        "{}  plot: {}\n",
                        format_noise(&run.model),
                        run.svg_path.display()
                    );
                    Ok(Report::new(
                        text,
                        to_json(&with_log_reading(noise_json(&run.model), &run.log_reading)?)?,
                    ))
                }),
            json,
        ),
        Command::Identify {
            log,
            json,
            sensors: s,
            columns: c,
        } => emit(
            (|| {
                let map = columns(&c)?;
                let sensor = sensors(&s)?;
                let run = run_identify(
                    &log,
                    &map,
                    c.sampling_tolerance,
                    &sensor,
                    s.window,
                    s.force_delay,
                )?;
                let id = &run.identification;
                let code = if id.adequacy.status == FitStatus::DoesNotFit {
                    EXIT_CHECK_FAILED
                } else {
                    EXIT_OK
                };
                Ok(Report::of_checks(
                    format_identification(
                        id,
                        &run.noise,
                        run.force_delay.as_ref(),
                        run.force_delay_screen.as_ref(),
                    ),
                    to_json(&with_log_reading(
                        identification_json(
                            id,
                            &run.noise,
                            run.sample_rate_hz,
                            run.force_delay.as_ref(),
                            run.force_delay_screen.as_ref(),
                        ),
                        &run.log_reading,
                    )?)?,
                    code,
                ))
            })(),
            json,
        ),
        Command::Estimate {
            log,
            out,
            every,
            json,
            calibration,
        } => emit(
            (|| {
                let (map, tol, opts) = calibration_options(&calibration)?;
                let (est, path, reading) =
                    run_estimate(&log, &map, tol, &opts, out.as_deref(), every)?;
                let code = if est.consistency.consistent {
                    EXIT_OK
                } else {
                    EXIT_CHECK_FAILED
                };
                Ok(Report::of_checks(
                    format!(
                        "{}{}  time series: {}\n",
                        format_estimate(&est),
                        format_consistency(&est),
                        path.display()
                    ),
                    to_json(&with_log_reading(estimate_json(&est), &reading)?)?,
                    code,
                ))
            })(),
            json,
        ),
        Command::Validate {
            spec,
            log,
            tolerance,
            svg,
            json,
            calibration,
        } => emit(
            (|| {
                if !matches!(calibration.filter.init, InitSource::Identify) {
                    return Err(Error::Argument(
                        "validate: --init must be identify (the design is what is checked)".into(),
                    ));
                }
                let (map, tol, opts) = calibration_options(&calibration)?;
                let (v, path, reading) = run_validate(
                    Some(&spec),
                    &log,
                    &map,
                    tol,
                    &opts,
                    tolerance,
                    svg.as_deref(),
                )?;
                let code = v.exit_code();
                let verdict = match &v {
                    Verdict::Law(v) => format_validation(v),
                    Verdict::Curve(v) => format_curve_validation(v),
                };
                let text = format!("{verdict}  plot: {}\n", path.display());
                Ok(Report::of_checks(
                    text,
                    to_json(&with_log_reading(&v, &reading)?)?,
                    code,
                ))
            })(),
            json,
        ),
        Command::Diagnose {
            spec,
            log,
            svg,
            json,
            build,
        } => emit(
            (|| {
                let opts = diagnose_options(&build)?;
                let run = run_diagnose(&spec, &log, &opts, svg.as_deref())?;
                let text = format!(
                    "{}  plot: {}\n",
                    format_diagnosis(&run.diagnosis),
                    run.svg_path.display()
                );
                let code = if run.diagnosis.fit.status == FitStatus::DoesNotFit {
                    EXIT_CHECK_FAILED
                } else {
                    EXIT_OK
                };
                Ok(Report::of_checks(
                    text,
                    to_json(&with_log_reading(&run.diagnosis, &run.log_reading)?)?,
                    code,
                ))
            })(),
            json,
        ),
        Command::Revise {
            spec,
            log,
            out,
            tolerance,
            json,
            build,
        } => emit(
            (|| {
                let opts = diagnose_options(&build)?;
                let run = run_revise(&spec, &log, &opts, tolerance, &out)?;
                let code = if run.revision.chosen.is_some() {
                    EXIT_OK
                } else {
                    EXIT_CHECK_FAILED
                };
                let mut text = format!(
                    "{}{}  written: {}\n",
                    format_diagnosis(&run.diagnosis),
                    format_revision(&run.revision),
                    run.spec_path
                        .as_ref()
                        .map_or(run.out_dir.join(REVISION_JSON), |p| p.clone())
                        .display()
                );
                if let Some(p) = &run.spec_path {
                    // Next to the revision's folder, which holds exactly one run of `revise`.
                    let log = PathBuf::from(format!("built-{}.csv", run.revision.revision));
                    text.push_str(&format!(
                        "  check it on the simulator: camspring simulate {} --built -o {}; camspring validate {} {}\n",
                        p.display(),
                        log.display(),
                        p.display(),
                        log.display()
                    ));
                }
                let json = json!({
                    "diagnosis": run.diagnosis,
                    "revision": run.revision,
                    "spec": run.spec_path,
                    "written": run.written,
                    "log_reading": run.log_reading,
                });
                Ok(Report::of_checks(text, to_json(&json)?, code))
            })(),
            json,
        ),
        Command::Completions { shell } => {
            let mut buf = Vec::new();
            clap_complete::generate(shell, &mut Cli::command(), "camspring", &mut buf);
            emit(
                Ok(Report::new(
                    String::from_utf8_lossy(&buf).into_owned(),
                    String::new(),
                )),
                false,
            )
        }
        Command::Man { out } => emit(man_pages(out.as_deref()), false),
    }
}
