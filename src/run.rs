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

/// Options of `camspring simulate`.
#[derive(Debug, Clone)]
pub struct SimulateOptions {
    /// The run: profile, duration, rate, seed, dynamics, noise.
    pub settings: crate::estimate::sim::SimSettings,
    /// Where the log goes (default `out/<spec name>/calib.csv`).
    pub log_path: Option<PathBuf>,
    /// Where the truth goes (default next to the log, `truth.json`).
    pub truth_path: Option<PathBuf>,
}

/// What `camspring simulate` wrote.
#[derive(Debug, Clone)]
pub struct SimulateRun {
    /// The log.
    pub log_path: PathBuf,
    /// The truth.
    pub truth_path: PathBuf,
    /// Samples written.
    pub samples: usize,
    /// The spring law simulated.
    pub law: crate::law::ExpLaw,
}

/// Runs `camspring simulate`: a calibration log of the spec's designed spring with known truth.
pub fn run_simulate(spec_path: Option<&Path>, opts: &SimulateOptions) -> Result<SimulateRun> {
    use crate::estimate::{log::write_log, sim::simulate};
    let spec = load_spec(spec_path)?;
    let law = crate::design::law_of(&spec)
        .map_err(|e| Error::Design(e.into()))?
        .law;
    let xmax = spec.law.xmax_mm();
    let (log, truth) = simulate(&law, xmax, law.force_n(xmax), &opts.settings)?;
    let log_path = opts
        .log_path
        .clone()
        .unwrap_or_else(|| Path::new("out").join(&spec.name).join("calib.csv"));
    let truth_path = opts
        .truth_path
        .clone()
        .unwrap_or_else(|| log_path.with_extension("truth.json"));
    let truth_json = serde_json::to_vec(&truth).map_err(|e| Error::Encode {
        what: "truth.json",
        message: e.to_string(),
    })?;
    crate::export::write_atomic(&log_path, &write_log(&log))?;
    crate::export::write_atomic(&truth_path, &truth_json)?;
    Ok(SimulateRun {
        log_path,
        truth_path,
        samples: log.len(),
        law,
    })
}

/// A progress bar on stderr for `len` units, only on a terminal, never when `CI` is set, and
/// only for work of more than `threshold` units.
fn progress_bar(len: u64, threshold: u64, template: &str) -> Option<indicatif::ProgressBar> {
    use std::io::IsTerminal;
    let show =
        std::io::stderr().is_terminal() && std::env::var_os("CI").is_none() && len > threshold;
    show.then(|| {
        let bar = indicatif::ProgressBar::new(len);
        bar.set_style(
            indicatif::ProgressStyle::with_template(template)
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar
    })
}

/// Reads a calibration log file, with a progress bar on stderr when `progress` is set and
/// stderr is a terminal (never on a pipe or when `CI` is set).
pub fn read_log_file(
    path: &Path,
    map: &crate::estimate::log::ColumnMap,
    sampling_tolerance: f64,
    progress: bool,
) -> Result<crate::estimate::log::CalibrationLog> {
    let file = std::fs::File::open(path).map_err(|source| Error::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let size = file.metadata().map(|m| m.len()).unwrap_or(0);
    let bar = progress
        .then(|| {
            progress_bar(
                size,
                8 << 20,
                "reading {msg} {bar:40} {bytes}/{total_bytes} ({bytes_per_sec})",
            )
        })
        .flatten();
    if let Some(b) = &bar {
        b.set_message(path.display().to_string());
    }
    let result = crate::estimate::log::read_log(
        std::io::BufReader::with_capacity(1 << 20, file),
        map,
        sampling_tolerance,
        |bytes| {
            if let Some(b) = &bar {
                b.set_position(bytes);
            }
        },
    );
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    result.map_err(|source| Error::Log {
        path: path.to_path_buf(),
        source,
    })
}

/// What `camspring noise` found and wrote.
#[derive(Debug, Clone)]
pub struct NoiseRun {
    /// The noise model.
    pub model: crate::estimate::report::NoiseModel,
    /// The Allan plot written.
    pub svg_path: PathBuf,
}

/// Runs `camspring noise`: Allan variance of a log at rest, and `allan.svg`.
pub fn run_noise(
    log_path: &Path,
    map: &crate::estimate::log::ColumnMap,
    sampling_tolerance: f64,
    svg_path: Option<&Path>,
) -> Result<NoiseRun> {
    use crate::estimate::report::{allan_svg, noise_model};
    let log = read_log_file(log_path, map, sampling_tolerance, true)?;
    let model = noise_model(&log);
    let svg_path = svg_path.map(Path::to_path_buf).unwrap_or_else(|| {
        log_path
            .parent()
            .unwrap_or(Path::new("."))
            .join("allan.svg")
    });
    crate::export::write_atomic(&svg_path, allan_svg(&model).as_bytes())?;
    Ok(NoiseRun { model, svg_path })
}

/// Reads the sensor noise from a `camspring noise --json` file.
pub fn load_noise_json(path: &Path) -> Result<crate::estimate::identify::SensorNoise> {
    let text = std::fs::read_to_string(path).map_err(|source| Error::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let v: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| Error::Argument(format!("--noise {}: not JSON: {e}", path.display())))?;
    let get = |a: &str, b: &str| {
        v.get(a)
            .and_then(|c| c.get(b))
            .and_then(|x| x.as_f64())
            .filter(|x| x.is_finite() && *x > 0.0)
            .ok_or_else(|| {
                Error::Argument(format!(
                    "--noise {}: no positive {a}.{b}; expected the output of `camspring noise --json`",
                    path.display()
                ))
            })
    };
    Ok(crate::estimate::identify::SensorNoise {
        force_variance_n2: get("force", "white_noise_variance_n2")?,
        position_variance_mm2: get("position", "white_noise_variance_mm2")?,
    })
}

/// Runs `camspring identify` on a log file.
pub fn run_identify(
    log_path: &Path,
    map: &crate::estimate::log::ColumnMap,
    sampling_tolerance: f64,
    noise: &crate::estimate::identify::SensorNoise,
    window_s: Option<f64>,
) -> Result<(
    crate::estimate::identify::Identification,
    crate::estimate::log::CalibrationLog,
)> {
    let log = read_log_file(log_path, map, sampling_tolerance, true)?;
    let id = crate::estimate::identify::identify_with_window(&log, noise, window_s)?;
    Ok((id, log))
}

/// Where `camspring estimate` takes the filter's initial state from.
#[derive(Debug, Clone)]
pub enum EstimateInit {
    /// Offline identification of the same log (the paper's procedure; default).
    Identify,
    /// A spec's designed law (k2, mu, F0); the dynamics start wide.
    Spec(PathBuf),
}

/// Options of `camspring estimate`.
#[derive(Debug, Clone)]
pub struct EstimateOptions {
    /// Initial state.
    pub init: EstimateInit,
    /// Prediction method.
    pub discretization: crate::estimate::ekf::Discretization,
    /// Force-rate input.
    pub force_rate: crate::estimate::ekf::ForceRate,
    /// Sensor noise (R and the force-rate noise).
    pub noise: crate::estimate::identify::SensorNoise,
    /// Identification window (s), when identifying.
    pub window_s: Option<f64>,
    /// Innovations beyond this many standard deviations count as outliers; 50 in a row stop
    /// the filter (None: 8).
    pub outlier_sigmas: Option<f64>,
    /// Overrides of the process noise density Q of states (index, value).
    pub q: Vec<(usize, f64)>,
    /// Overrides of the initial standard deviation of states (index, value).
    pub p0_std: Vec<(usize, f64)>,
    /// Override of the position measurement variance R (mm^2).
    pub r_position_mm2: Option<f64>,
}

/// Parses a `STATE=VALUE` override; STATE is a short name (x, xd, xdd, sigma, d, m, k2, d2)
/// or the unit-bearing one of [`crate::estimate::ekf::STATE_NAMES`].
pub fn parse_state_override(text: &str, option: &str) -> Result<(usize, f64)> {
    use crate::estimate::ekf::STATE_NAMES;
    const SHORT: [&str; 8] = ["x", "xd", "xdd", "sigma", "d", "m", "k2", "d2"];
    let bad = |why: String| Error::Argument(format!("{option} {text}: {why}"));
    let (name, value) = text
        .split_once('=')
        .ok_or_else(|| bad("expected STATE=VALUE, for example xdd=0.5".into()))?;
    let name = name.trim();
    let k = SHORT
        .iter()
        .position(|s| s.eq_ignore_ascii_case(name))
        .or_else(|| STATE_NAMES.iter().position(|s| *s == name))
        .ok_or_else(|| {
            bad(format!(
                "unknown state \"{name}\" (states: {})",
                SHORT.join(", ")
            ))
        })?;
    let v: f64 = value
        .trim()
        .parse()
        .ok()
        .filter(|v: &f64| v.is_finite() && *v >= 0.0)
        .ok_or_else(|| bad(format!("\"{}\" is not a number >= 0", value.trim())))?;
    Ok((k, v))
}

/// What `camspring estimate` computed.
#[derive(Debug, Clone)]
pub struct EstimateRun {
    /// The filter run.
    pub run: crate::estimate::ekf::EkfRun,
    /// The settings used.
    pub settings: crate::estimate::ekf::EkfSettings,
    /// The identification, when the init came from it.
    pub identification: Option<crate::estimate::identify::Identification>,
}

/// Runs the EKF over a log already read.
pub fn estimate_log(
    log: &crate::estimate::log::CalibrationLog,
    opts: &EstimateOptions,
    progress: bool,
) -> Result<EstimateRun> {
    use crate::estimate::ekf::{self, EkfInit};
    use crate::estimate::identify::identify_with_window;
    use crate::estimate::sg;
    let (init, identification, stroke) = match &opts.init {
        EstimateInit::Identify => {
            let id = identify_with_window(log, &opts.noise, opts.window_s)?;
            let stroke = log.position_mm.iter().fold(0.0_f64, |m, &x| m.max(x.abs()));
            (EkfInit::from_identification(&id), Some(id), stroke)
        }
        EstimateInit::Spec(path) => {
            let spec = load_spec(Some(path))?;
            let law = crate::design::law_of(&spec)
                .map_err(|e| Error::Design(e.into()))?
                .law;
            (EkfInit::from_law(&law), None, spec.law.xmax_mm())
        }
    };
    let dt = log.dt_s();
    let mut settings =
        ekf::default_settings(&init, &opts.noise, dt, opts.discretization, opts.force_rate);
    // Coulomb friction steps the force at every reversal; its derivative is not in the
    // filter's model. Take the initial d0 out of the force first (sign of the motion velocity).
    let mut force = log.force_n.clone();
    if init.d0_n != 0.0 {
        let diff = sg::Differentiator::for_rate(1.0 / dt);
        let v = diff.apply(&log.position_mm, dt, sg::MOTION_VELOCITY);
        let band = 3.0
            * diff
                .noise_variance(sg::MOTION_VELOCITY, opts.noise.position_variance_mm2, dt)
                .sqrt();
        let mut sign = 0.0;
        for (i, f) in force.iter_mut().enumerate() {
            let vi = v.get(i.saturating_sub(diff.half).min(v.len().saturating_sub(1)));
            if let Some(&vi) = vi {
                if vi > band {
                    sign = 1.0;
                } else if vi < -band {
                    sign = -1.0;
                }
            }
            *f -= init.d0_n * sign;
        }
    }
    let first = ekf::force_rate_first_sample(dt, opts.force_rate);
    let x0 = log.position_mm.get(first).copied().unwrap_or(0.0);
    let (z0, sigma_std) = ekf::initial_state(&init, x0, stroke);
    settings.p0_std[ekf::idx::SIGMA] = sigma_std;
    if let Some(k) = opts.outlier_sigmas {
        settings.outlier_sigmas = k;
    }
    for &(k, v) in &opts.q {
        settings.q[k] = v;
    }
    for &(k, v) in &opts.p0_std {
        settings.p0_std[k] = v;
    }
    if let Some(r) = opts.r_position_mm2 {
        settings.r_position_mm2 = r.max(1e-12);
    }
    let bar = progress
        .then(|| {
            progress_bar(
                log.len() as u64,
                200_000,
                "EKF {bar:40} {pos}/{len} samples ({per_sec})",
            )
        })
        .flatten();
    let run = ekf::run(
        &log.t_s,
        &force,
        &log.position_mm,
        opts.force_rate,
        z0,
        settings,
        [init.f0_n, init.d0_n],
        30.0,
        |k, _| {
            if let Some(b) = &bar {
                b.set_position(k as u64);
            }
        },
    );
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let mut run = run.map_err(Error::Estimate)?;
    // The parallel filter saw the force with the initial d0 taken out: add it back.
    for o in run.offsets.iter_mut() {
        o[1] += init.d0_n;
    }
    run.offset_filter.theta[1] += init.d0_n;
    Ok(EstimateRun {
        run,
        settings,
        identification,
    })
}

/// Runs `camspring estimate`: reads the log, runs the EKF and writes the time series CSV
/// (default `<log>.est.csv`). Returns the run and the path written.
pub fn run_estimate(
    log_path: &Path,
    map: &crate::estimate::log::ColumnMap,
    sampling_tolerance: f64,
    opts: &EstimateOptions,
    out: Option<&Path>,
) -> Result<(EstimateRun, PathBuf)> {
    let log = read_log_file(log_path, map, sampling_tolerance, true)?;
    let est = estimate_log(&log, opts, true)?;
    let out = out
        .map(Path::to_path_buf)
        .unwrap_or_else(|| log_path.with_extension("est.csv"));
    crate::export::write_atomic(&out, &crate::estimate::report::estimate_csv(&est.run))?;
    Ok((est, out))
}

/// Runs `camspring validate`: the log against the spec's designed law; writes
/// `validation.svg` (default next to the log).
pub fn run_validate(
    spec_path: Option<&Path>,
    log_path: &Path,
    map: &crate::estimate::log::ColumnMap,
    sampling_tolerance: f64,
    opts: &EstimateOptions,
    tolerance: f64,
    svg: Option<&Path>,
) -> Result<(crate::estimate::validate::Validation, PathBuf)> {
    use crate::estimate::validate::{validate, validation_svg};
    let spec = load_spec(spec_path)?;
    let designed = crate::design::law_of(&spec)
        .map_err(|e| Error::Design(e.into()))?
        .law;
    let log = read_log_file(log_path, map, sampling_tolerance, true)?;
    let est = estimate_log(&log, opts, true)?;
    let id = est
        .identification
        .as_ref()
        .ok_or_else(|| Error::Argument("validate needs the identification init".into()))?;
    let v = validate(&designed, id, &est.run, &log.position_mm, tolerance);
    let svg_path = svg.map(Path::to_path_buf).unwrap_or_else(|| {
        log_path
            .parent()
            .unwrap_or(Path::new("."))
            .join("validation.svg")
    });
    let svg_text = validation_svg(&v, &est.run);
    let html = crate::export::html::validation_html(
        &v,
        &svg_text,
        &log_path
            .file_name()
            .map_or(String::new(), |n| n.to_string_lossy().into_owned()),
    );
    crate::export::write_atomic(&svg_path, svg_text.as_bytes())?;
    crate::export::write_atomic(&svg_path.with_file_name("validation.html"), html.as_bytes())?;
    Ok((v, svg_path))
}

/// What `camspring sweep` wrote.
#[derive(Debug, Clone)]
pub struct SweepRun {
    /// The grid points and their results.
    pub points: Vec<crate::sweep::SweepPoint>,
    /// sweep.csv and sweep.svg.
    pub written: Vec<PathBuf>,
}

/// Runs `camspring sweep`: the design at every point of the grid, in parallel; writes
/// `sweep.csv` and `sweep.svg` into `out_dir` (default `out/<spec name>/sweep`).
pub fn run_sweep(
    spec_path: Option<&Path>,
    axes: &[crate::sweep::Axis],
    out_dir: Option<&Path>,
) -> Result<SweepRun> {
    use crate::sweep::{sweep, sweep_csv, sweep_svg};
    if axes.is_empty() || axes.len() > 3 {
        return Err(Error::Argument(format!(
            "sweep: {} --vary axes given; expected 1 to 3",
            axes.len()
        )));
    }
    let spec = load_spec(spec_path)?;
    let total: usize = axes.iter().map(|a| a.values.len()).product();
    let bar = progress_bar(
        total as u64,
        16,
        "sweep {bar:40} {pos}/{len} designs ({eta})",
    );
    let points = sweep(&spec, axes, &|| {
        if let Some(b) = &bar {
            b.inc(1);
        }
    });
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let dir = out_dir
        .map(Path::to_path_buf)
        .unwrap_or_else(|| Path::new("out").join(&spec.name).join("sweep"));
    let csv = dir.join("sweep.csv");
    let svg = dir.join("sweep.svg");
    crate::export::write_atomic(&csv, &sweep_csv(axes, &points))?;
    crate::export::write_atomic(&svg, sweep_svg(axes, &points).as_bytes())?;
    Ok(SweepRun {
        points,
        written: vec![csv, svg],
    })
}
