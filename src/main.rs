//! The `camspring` command line: parses arguments, calls the library, prints, exits.
//!
//! Exit codes: 0 done (warnings allowed), 1 a design check failed (outputs still written),
//! 2 bad input (spec, arguments), 3 an output could not be written.

use std::io::Write as _;
use std::path::PathBuf;

/// Writes to stdout; a closed pipe (`camspring ... | head`) is not an error worth a panic.
macro_rules! out {
    ($($arg:tt)*) => {{
        let _ = write!(std::io::stdout().lock(), $($arg)*);
    }};
}

/// Like `out!` with a newline.
macro_rules! outln {
    ($($arg:tt)*) => {{
        let _ = writeln!(std::io::stdout().lock(), $($arg)*);
    }};
}
use std::process::ExitCode;

use clap::{CommandFactory, Parser, Subcommand};

use camspring::estimate::ekf::{Discretization, ForceRate};
use camspring::estimate::identify::SensorNoise;
use camspring::estimate::log::{parse_column, parse_time_column, ColumnMap};
use camspring::estimate::report::{estimate_json, format_estimate};
use camspring::estimate::report::{
    format_identification, format_noise, identification_json, noise_json,
};
use camspring::estimate::sim::{Dynamics, Noise, Profile, SimSettings};
use camspring::estimate::validate::format_validation;
use camspring::estimate::{parse_duration_s, parse_fraction, parse_rate_hz};
use camspring::run::{
    format_design, load_noise_json, parse_state_override, run_design, run_estimate, run_identify,
    run_noise, run_simulate, run_sweep, run_validate, EstimateInit, EstimateOptions,
    SimulateOptions, EXIT_BAD_INPUT, EXIT_IO,
};
use camspring::spec::STARTER_SPEC_TOML;

#[derive(Parser, Debug)]
#[command(
    name = "camspring",
    version,
    about = "Design exponential cam springs and check them",
    long_about = None,
    after_help = "Examples:
  camspring design                                  # the built-in default spec into out/paper/
  camspring init my.toml && camspring design my.toml
  camspring sweep my.toml --vary spring_rate=2..20 --vary preload=0..10
  camspring simulate -o calib.csv && camspring validate specs/paper.toml calib.csv

Exit codes: 0 done, 1 a check or the validation failed, 2 bad input, 3 an output could not be written.
More: README.md, docs/SPEC.md, docs/CALIBRATION.md, docs/JSON.md, `camspring <command> --help`."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Explore a grid of follower designs in parallel: pressure angle, lift and contact stress.
    ///
    /// Writes sweep.csv (one row per design) and sweep.svg.
    ///
    /// Examples:
    ///   camspring sweep specs/paper.toml --vary spring_rate=2..20 --vary preload=0..10
    ///   camspring sweep specs/paper.toml --vary roller_radius=1..5:9 --vary friction=0,0.01,0.05
    #[command(verbatim_doc_comment)]
    Sweep {
        /// Spec file (TOML); the built-in default spec when omitted.
        spec: Option<PathBuf>,
        /// An axis: KEY=A..B (10 values), KEY=A..B:N or KEY=V1,V2,...; keys spring_rate (N/mm),
        /// preload (mm), roller_radius (mm), friction. Repeat for up to 3 axes.
        #[arg(long, required = true)]
        vary: Vec<String>,
        /// Output folder (default out/<spec name>/sweep).
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// Print every grid point as JSON on stdout.
        #[arg(long)]
        json: bool,
    },
    /// Write a commented starter spec to edit (every key, with its default and unit).
    ///
    /// Examples:
    ///   camspring init my.toml && camspring design my.toml
    #[command(verbatim_doc_comment)]
    Init {
        /// Spec file to write.
        path: PathBuf,
        /// Overwrite an existing file.
        #[arg(long)]
        force: bool,
        /// Print what was written as JSON on stdout.
        #[arg(long)]
        json: bool,
    },
    /// Print a shell completion script.
    ///
    /// Examples:
    ///   camspring completions bash > ~/.local/share/bash-completion/completions/camspring
    ///   camspring completions zsh > ~/.zfunc/_camspring
    #[command(verbatim_doc_comment)]
    Completions {
        /// Shell: bash, zsh, fish, elvish or powershell.
        shell: clap_complete::Shell,
    },
    /// Write man pages (camspring.1 and one per subcommand), or print camspring.1.
    ///
    /// Examples:
    ///   camspring man -o /usr/local/share/man/man1
    ///   camspring man | man -l -
    #[command(verbatim_doc_comment)]
    Man {
        /// Folder to write the pages to (default: print camspring.1 on stdout).
        #[arg(short, long)]
        out: Option<PathBuf>,
    },
    /// Solve the law, synthesise the cam, run the checks and write the outputs.
    ///
    /// Examples:
    ///   camspring design                         # built-in default spec (specs/paper.toml)
    ///   camspring design specs/ankle.toml -o out/ankle
    ///   camspring design specs/paper.toml --json # summary on stdout
    #[command(verbatim_doc_comment)]
    Design {
        /// Spec file (TOML); the built-in default spec when omitted.
        spec: Option<PathBuf>,
        /// Output folder (default: out/<spec name>).
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// Print the design summary as JSON on stdout instead of the text report.
        #[arg(long)]
        json: bool,
    },
    /// Simulate a calibration run of the spec's designed spring, with known truth.
    ///
    /// The log is CSV (t_s,force_n,position_mm); the truth JSON holds the parameters and
    /// sigma(t), D(t), M at every sample.
    ///
    /// Examples:
    ///   camspring simulate specs/paper.toml -o out/paper/calib.csv --truth out/paper/truth.json
    ///   camspring simulate --profile static --duration 600s -o static.csv
    ///   camspring simulate --profile steps --d0 0.2 --seed 7 --rate 1kHz
    #[command(verbatim_doc_comment)]
    Simulate {
        /// Spec file (TOML); the built-in default spec when omitted.
        spec: Option<PathBuf>,
        /// Log to write (default out/<spec name>/calib.csv).
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// Truth JSON to write (default: the log's name with .truth.json).
        #[arg(long)]
        truth: Option<PathBuf>,
        /// Print what was written as JSON on stdout.
        #[arg(long)]
        json: bool,
        /// Motion: sines, ramp-hold, steps or static.
        #[arg(long, default_value = "sines")]
        profile: String,
        /// Duration, e.g. 300s, 5min, 1h.
        #[arg(long, default_value = "300s")]
        duration: String,
        /// Sampling rate, e.g. 100Hz, 1kHz.
        #[arg(long, default_value = "100Hz")]
        rate: String,
        /// Random seed (noise and step levels).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Inertia m in N s^2/mm.
        #[arg(long, default_value_t = 0.05)]
        m: f64,
        /// Coulomb friction d0 in N.
        #[arg(long, default_value_t = 0.0)]
        d0: f64,
        /// Linear damping d1 in N s/mm.
        #[arg(long, default_value_t = 0.2)]
        d1: f64,
        /// Cubic damping d2 in N s^3/mm^3.
        #[arg(long, default_value_t = -1e-4, allow_hyphen_values = true)]
        d2: f64,
        /// Force noise variance in N^2 (the paper's 0.017).
        #[arg(long, default_value_t = 0.017)]
        force_variance: f64,
        /// Position noise variance in mm^2 (the paper's 0.01).
        #[arg(long, default_value_t = 0.01)]
        position_variance: f64,
    },
    /// Sensor noise of a log recorded at rest: Allan variance of each channel, and allan.svg.
    ///
    /// Examples:
    ///   camspring noise static.csv
    ///   camspring noise static.csv --json > noise.json
    ///   camspring noise rig.csv --time t:ms --force F:lbf --position x:in
    #[command(verbatim_doc_comment)]
    Noise {
        /// Calibration log (CSV with a header).
        log: PathBuf,
        /// Allan plot to write (default allan.svg next to the log).
        #[arg(long)]
        svg: Option<PathBuf>,
        /// Print the noise model as JSON on stdout.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        columns: Columns,
    },
    /// Identify m, d0, d1, d2, mu, F0 and k2 from a calibration log (paper section V).
    ///
    /// Examples:
    ///   camspring identify out/paper/calib.csv
    ///   camspring identify calib.csv --noise noise.json --json
    ///   camspring identify rig.csv --time t:ms --force F:lbf --position x:in
    #[command(verbatim_doc_comment)]
    Identify {
        /// Calibration log (CSV with a header).
        log: PathBuf,
        /// Print the result as JSON on stdout.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        sensors: Sensors,
        #[command(flatten)]
        columns: Columns,
    },
    /// Run the paper's EKF over a log: stiffness, damping and inertia on-line.
    ///
    /// Writes the time series (t_s, each state and its 1-sigma bound, F0 and d0) as CSV and
    /// prints the final estimates (the paper's Table II).
    ///
    /// Examples:
    ///   camspring estimate out/paper/calib.csv -o out/paper/est.csv
    ///   camspring estimate calib.csv --init specs/paper.toml --json
    ///   camspring estimate calib.csv --discretization euler     # the paper's, for comparison
    #[command(verbatim_doc_comment)]
    Estimate {
        /// Calibration log (CSV with a header).
        log: PathBuf,
        /// Time series CSV to write (default: the log's name with .est.csv).
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// Print the final estimates as JSON on stdout.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        filter: FilterArgs,
        #[command(flatten)]
        sensors: Sensors,
        #[command(flatten)]
        columns: Columns,
    },
    /// Check a built spring's calibration log against its design: one verdict.
    ///
    /// Exit code 0 pass, 1 fail, 2 bad input. Writes validation.svg next to the log.
    ///
    /// Examples:
    ///   camspring validate specs/paper.toml out/paper/calib.csv
    ///   camspring validate specs/paper.toml calib.csv --tolerance 3% --json
    #[command(verbatim_doc_comment)]
    Validate {
        /// Spec file (TOML) of the design.
        spec: PathBuf,
        /// Calibration log (CSV with a header).
        log: PathBuf,
        /// Allowed relative deviation of each criterion, e.g. 3%.
        #[arg(long, default_value = "3%")]
        tolerance: String,
        /// Plot to write (default validation.svg next to the log).
        #[arg(long)]
        svg: Option<PathBuf>,
        /// Print the verdict as JSON on stdout.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        filter: FilterArgs,
        #[command(flatten)]
        sensors: Sensors,
        #[command(flatten)]
        columns: Columns,
    },
}

/// Sensor noise and filter window for identification and estimation.
#[derive(clap::Args, Debug)]
struct Sensors {
    /// Sensor noise from `camspring noise --json` (default: the paper's sensors).
    #[arg(long)]
    noise: Option<PathBuf>,
    /// Force noise variance in N^2 (overrides --noise).
    #[arg(long)]
    force_variance: Option<f64>,
    /// Position noise variance in mm^2 (overrides --noise).
    #[arg(long)]
    position_variance: Option<f64>,
    /// Savitzky-Golay window, e.g. 0.8s (default about 0.4 s); longer for slow runs.
    #[arg(long)]
    window: Option<String>,
}

impl Sensors {
    fn parse(&self) -> Result<(SensorNoise, Option<f64>), camspring::Error> {
        let window_s = self
            .window
            .as_deref()
            .map(parse_duration_s)
            .transpose()
            .map_err(|e| camspring::Error::Argument(format!("--window {e}")))?;
        let mut sensor = match &self.noise {
            Some(p) => load_noise_json(p)?,
            None => SensorNoise::default(),
        };
        for (v, name) in [
            (self.force_variance, "--force-variance"),
            (self.position_variance, "--position-variance"),
        ] {
            if let Some(v) = v {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(camspring::Error::Argument(format!(
                        "{name} {v}: expected a variance >= 0"
                    )));
                }
            }
        }
        if let Some(v) = self.force_variance {
            sensor.force_variance_n2 = v;
        }
        if let Some(v) = self.position_variance {
            sensor.position_variance_mm2 = v;
        }
        Ok((sensor, window_s))
    }
}

/// EKF options.
#[derive(clap::Args, Debug)]
struct FilterArgs {
    /// Initial state: `identify` (offline identification of the same log) or a spec file.
    #[arg(long, default_value = "identify")]
    init: String,
    /// Prediction: rk4 (accurate) or euler (the paper's, biased).
    #[arg(long, default_value = "rk4")]
    discretization: String,
    /// Force-rate input: zero-phase (offline) or first-order[:TIME] (the paper's filter; TIME defaults to 0.02s).
    #[arg(long, default_value = "zero-phase")]
    force_rate: String,
    /// Process noise density of a state, e.g. --q xdd=0.5 --q sigma=1e-3 (repeatable;
    /// states x, xd, xdd, sigma, d, m, k2, d2; units^2 per s).
    #[arg(long, value_name = "STATE=VALUE")]
    q: Vec<String>,
    /// Initial standard deviation of a state, e.g. --p0 m=0.01 (repeatable).
    #[arg(long, value_name = "STATE=VALUE")]
    p0: Vec<String>,
    /// Position measurement variance R in mm^2 (default: the position noise).
    #[arg(long)]
    r: Option<f64>,
}

impl FilterArgs {
    fn parse(&self, sensors: &Sensors) -> Result<EstimateOptions, camspring::Error> {
        let (noise, window_s) = sensors.parse()?;
        let arg = camspring::Error::Argument;
        let discretization = match self.discretization.as_str() {
            "rk4" => Discretization::Rk4,
            "euler" => Discretization::Euler,
            other => {
                return Err(arg(format!(
                    "--discretization \"{other}\": expected rk4 or euler"
                )))
            }
        };
        let force_rate = match self.force_rate.split_once(':') {
            None if self.force_rate == "zero-phase" => ForceRate::ZeroPhase,
            None if self.force_rate == "first-order" => ForceRate::FirstOrder {
                time_constant_s: 0.02,
            },
            Some(("first-order", t)) => ForceRate::FirstOrder {
                time_constant_s: parse_duration_s(t)
                    .map_err(|e| arg(format!("--force-rate {e}")))?,
            },
            _ => {
                return Err(arg(format!(
                    "--force-rate \"{}\": expected zero-phase or first-order[:TIME]",
                    self.force_rate
                )))
            }
        };
        let init = if self.init == "identify" {
            EstimateInit::Identify
        } else {
            EstimateInit::Spec(PathBuf::from(&self.init))
        };
        Ok(EstimateOptions {
            init,
            discretization,
            force_rate,
            noise,
            window_s,
            outlier_sigmas: None,
            q: self
                .q
                .iter()
                .map(|t| parse_state_override(t, "--q"))
                .collect::<Result<_, _>>()?,
            p0_std: self
                .p0
                .iter()
                .map(|t| parse_state_override(t, "--p0"))
                .collect::<Result<_, _>>()?,
            r_position_mm2: match self.r {
                Some(r) if !(r.is_finite() && r > 0.0) => {
                    return Err(arg(format!("--r {r}: expected a variance > 0 (mm^2)")))
                }
                other => other,
            },
        })
    }
}

/// Column mapping of a calibration log.
#[derive(clap::Args, Debug)]
struct Columns {
    /// Time column and unit (s, ms, us).
    #[arg(long, default_value = "t_s")]
    time: String,
    /// Force column and unit (N, kN, lbf).
    #[arg(long, default_value = "force_n")]
    force: String,
    /// Position column and unit (mm, m, in).
    #[arg(long, default_value = "position_mm")]
    position: String,
    /// Allowed deviation of each sampling interval from the first, e.g. 10%.
    #[arg(long, default_value = "10%")]
    sampling_tolerance: String,
}

impl Columns {
    fn parse(&self) -> Result<(ColumnMap, f64), camspring::Error> {
        use camspring::units::Dimension;
        let arg = |e: camspring::estimate::log::LogError| camspring::Error::Argument(e.to_string());
        let map = ColumnMap {
            time: parse_time_column(&self.time).map_err(arg)?,
            force: parse_column(&self.force, Dimension::Force, "force").map_err(arg)?,
            position: parse_column(&self.position, Dimension::Length, "position").map_err(arg)?,
        };
        let tol = parse_fraction(&self.sampling_tolerance)
            .map_err(|e| camspring::Error::Argument(format!("--sampling-tolerance {e}")))?;
        Ok((map, tol))
    }
}

/// `camspring man`: camspring.1 on stdout, or every page into a folder.
fn man_pages(out: Option<&std::path::Path>) -> ExitCode {
    let cmd = Cli::command();
    let render = |c: &clap::Command| -> std::io::Result<Vec<u8>> {
        let mut buf = Vec::new();
        clap_mangen::Man::new(c.clone()).render(&mut buf)?;
        Ok(buf)
    };
    let Some(dir) = out else {
        return match render(&cmd) {
            Ok(page) => {
                let _ = std::io::stdout().lock().write_all(&page);
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("error: cannot render the man page: {e}");
                ExitCode::from(EXIT_IO)
            }
        };
    };
    let mut pages = vec![("camspring.1".to_string(), cmd.clone())];
    for sub in cmd.get_subcommands() {
        let name: &'static str =
            Box::leak(format!("camspring-{}", sub.get_name()).into_boxed_str());
        pages.push((format!("{name}.1"), sub.clone().name(name)));
    }
    for (file, c) in pages {
        let result = render(&c)
            .map_err(|e| camspring::Error::Encode {
                what: "man page",
                message: e.to_string(),
            })
            .and_then(|page| camspring::export::write_atomic(&dir.join(&file), &page));
        match result {
            Ok(()) => outln!("  {}", dir.join(&file).display()),
            Err(e) => return fail(&e),
        }
    }
    ExitCode::SUCCESS
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

fn fail(e: &camspring::Error) -> ExitCode {
    // Every message already carries its cause (key, line, OS error).
    eprintln!("error: {e}");
    ExitCode::from(if e.is_bad_input() {
        EXIT_BAD_INPUT
    } else {
        EXIT_IO
    })
}

fn print_json(v: &impl serde::Serialize) -> ExitCode {
    match serde_json::to_string_pretty(v) {
        Ok(s) => {
            outln!("{s}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: cannot encode the result: {e}");
            ExitCode::from(EXIT_IO)
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn simulate(
    spec: Option<PathBuf>,
    out: Option<PathBuf>,
    truth: Option<PathBuf>,
    profile: &str,
    duration: &str,
    rate: &str,
    seed: u64,
    dynamics: Dynamics,
    noise: Noise,
) -> Result<camspring::run::SimulateRun, camspring::Error> {
    let arg = camspring::Error::Argument;
    let profile = match profile {
        "sines" => Profile::Sines,
        "ramp-hold" => Profile::RampHold,
        "steps" => Profile::Steps,
        "static" => Profile::Static,
        other => {
            return Err(arg(format!(
                "--profile \"{other}\": expected sines, ramp-hold, steps or static"
            )))
        }
    };
    let settings = SimSettings {
        profile,
        duration_s: parse_duration_s(duration).map_err(|e| arg(format!("--duration {e}")))?,
        rate_hz: parse_rate_hz(rate).map_err(|e| arg(format!("--rate {e}")))?,
        seed,
        dynamics,
        noise,
    };
    run_simulate(
        spec.as_deref(),
        &SimulateOptions {
            settings,
            log_path: out,
            truth_path: truth,
        },
    )
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Init { path, force, json } => {
            if path.exists() && !force {
                eprintln!(
                    "error: {} exists; choose another name or pass --force to overwrite it",
                    path.display()
                );
                return ExitCode::from(EXIT_BAD_INPUT);
            }
            match camspring::export::write_atomic(&path, STARTER_SPEC_TOML.as_bytes()) {
                Ok(()) if json => print_json(&serde_json::json!({ "spec": path })),
                Ok(()) => {
                    outln!(
                        "wrote {}; edit it, then: camspring design {}",
                        path.display(),
                        path.display()
                    );
                    ExitCode::SUCCESS
                }
                Err(e) => fail(&e),
            }
        }
        Command::Completions { shell } => {
            let mut cmd = Cli::command();
            let mut buf = Vec::new();
            clap_complete::generate(shell, &mut cmd, "camspring", &mut buf);
            let _ = std::io::stdout().lock().write_all(&buf);
            ExitCode::SUCCESS
        }
        Command::Man { out } => man_pages(out.as_deref()),
        Command::Sweep {
            spec,
            vary,
            out,
            json,
        } => {
            let run = vary
                .iter()
                .map(|v| camspring::sweep::parse_axis(v).map_err(camspring::Error::Argument))
                .collect::<Result<Vec<_>, _>>()
                .and_then(|axes| run_sweep(spec.as_deref(), &axes, out.as_deref()));
            match run {
                Ok(run) if json => print_json(&run.points),
                Ok(run) => {
                    let n = run.points.len();
                    let count = |s: camspring::cam::checks::Status| {
                        run.points
                            .iter()
                            .filter(|p| p.result.as_ref().is_ok_and(|r| r.status == s))
                            .count()
                    };
                    use camspring::cam::checks::Status;
                    outln!(
                        "{n} designs: {} pass, {} warn, {} fail, {} without a design",
                        count(Status::Pass),
                        count(Status::Warn),
                        count(Status::Fail),
                        run.points.iter().filter(|p| p.result.is_err()).count()
                    );
                    for p in &run.written {
                        outln!("  {}", p.display());
                    }
                    ExitCode::SUCCESS
                }
                Err(e) => fail(&e),
            }
        }
        Command::Design { spec, out, json } => match run_design(spec.as_deref(), out.as_deref()) {
            Ok(run) => {
                if json {
                    match serde_json::to_string_pretty(&run.summary) {
                        Ok(s) => outln!("{s}"),
                        Err(e) => {
                            eprintln!("error: cannot encode the summary: {e}");
                            return ExitCode::from(EXIT_IO);
                        }
                    }
                } else {
                    out!("{}", colour(&format_design(&run)));
                }
                ExitCode::from(run.exit_code())
            }
            Err(e) => fail(&e),
        },
        Command::Simulate {
            spec,
            out,
            truth,
            json,
            profile,
            duration,
            rate,
            seed,
            m,
            d0,
            d1,
            d2,
            force_variance,
            position_variance,
        } => {
            let dynamics = Dynamics {
                m_n_s2_per_mm: m,
                d0_n: d0,
                d1_n_s_per_mm: d1,
                d2_n_s3_per_mm3: d2,
            };
            let noise = Noise {
                force_variance_n2: force_variance,
                position_variance_mm2: position_variance,
            };
            match simulate(
                spec, out, truth, &profile, &duration, &rate, seed, dynamics, noise,
            ) {
                Ok(run) if json => print_json(&serde_json::json!({
                    "log": run.log_path,
                    "truth": run.truth_path,
                    "samples": run.samples,
                    "law": run.law,
                })),
                Ok(run) => {
                    outln!(
                        "simulated {} samples of F = {:.6} N * exp({:.6} /mm * x) + {:.6} N",
                        run.samples,
                        run.law.mu_n,
                        run.law.k2_per_mm,
                        run.law.f0_n
                    );
                    outln!("  log:   {}", run.log_path.display());
                    outln!("  truth: {}", run.truth_path.display());
                    ExitCode::SUCCESS
                }
                Err(e) => fail(&e),
            }
        }
        Command::Noise {
            log,
            svg,
            json,
            columns,
        } => {
            let run = columns
                .parse()
                .and_then(|(map, tol)| run_noise(&log, &map, tol, svg.as_deref()));
            match run {
                Ok(run) if json => print_json(&noise_json(&run.model)),
                Ok(run) => {
                    out!("{}", format_noise(&run.model));
                    outln!("  plot: {}", run.svg_path.display());
                    ExitCode::SUCCESS
                }
                Err(e) => fail(&e),
            }
        }
        Command::Identify {
            log,
            json,
            sensors,
            columns,
        } => {
            let run = (|| {
                let (map, tol) = columns.parse()?;
                let (sensor, window_s) = sensors.parse()?;
                let (id, log) = run_identify(&log, &map, tol, &sensor, window_s)?;
                Ok((id, log, sensor))
            })();
            match run {
                Ok((id, log, sensor)) if json => {
                    print_json(&identification_json(&id, &sensor, &log))
                }
                Ok((id, _, _)) => {
                    out!("{}", format_identification(&id));
                    ExitCode::SUCCESS
                }
                Err(e) => fail(&e),
            }
        }
        Command::Estimate {
            log,
            out,
            json,
            filter,
            sensors,
            columns,
        } => {
            let run = (|| {
                let (map, tol) = columns.parse()?;
                let opts = filter.parse(&sensors)?;
                run_estimate(&log, &map, tol, &opts, out.as_deref())
            })();
            match run {
                Ok((est, _)) if json => print_json(&estimate_json(&est.run, &est.settings)),
                Ok((est, path)) => {
                    out!("{}", format_estimate(&est.run));
                    outln!("  time series: {}", path.display());
                    ExitCode::SUCCESS
                }
                Err(e) => fail(&e),
            }
        }
        Command::Validate {
            spec,
            log,
            tolerance,
            svg,
            json,
            filter,
            sensors,
            columns,
        } => {
            let run = (|| {
                let (map, tol) = columns.parse()?;
                let opts = filter.parse(&sensors)?;
                if !matches!(opts.init, EstimateInit::Identify) {
                    return Err(camspring::Error::Argument(
                        "validate: --init must be identify (the design is what is checked)".into(),
                    ));
                }
                let tolerance = parse_fraction(&tolerance)
                    .map_err(|e| camspring::Error::Argument(format!("--tolerance {e}")))?;
                run_validate(
                    Some(&spec),
                    &log,
                    &map,
                    tol,
                    &opts,
                    tolerance,
                    svg.as_deref(),
                )
            })();
            match run {
                Ok((v, path)) => {
                    let code = if v.pass {
                        ExitCode::SUCCESS
                    } else {
                        ExitCode::from(1)
                    };
                    if json {
                        let _ = print_json(&v);
                    } else {
                        out!("{}", colour(&format_validation(&v)));
                        outln!("  plot: {}", path.display());
                    }
                    code
                }
                Err(e) => fail(&e),
            }
        }
    }
}
