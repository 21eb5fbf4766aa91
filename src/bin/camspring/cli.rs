//! The command line as types: every choice is a `ValueEnum` or a typed value parser, so a
//! wrong value is refused by clap (exit code 2, naming the option and the choices) before any
//! work starts, and the commands receive typed options.

use std::path::PathBuf;

use camspring::estimate::pipeline::PositionOffset;
use camspring::estimate::retime::ForceDelay;
use clap::{Parser, Subcommand, ValueEnum};

use camspring::app::InitSource;
use camspring::estimate::ekf::{Discretization, ForceRate};
use camspring::estimate::sim::Profile;
use camspring::units::{parse_duration_s, parse_fraction, parse_rate_hz};

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

Exit codes: 0 done, 1 a check or the validation failed, 2 bad input (or a log that validate cannot judge), 3 an output could not be written.
More: README.md, docs/SPEC.md, docs/CALIBRATION.md, docs/JSON.md, `camspring <command> --help`."
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
    /// Also write the JSON report (what --json prints) to FILE, replaced whole, while the
    /// text goes to stdout: one run read both ways. The command's error is written there as
    /// --json prints it (not a usage error, found before the options are read). Not for
    /// `completions` and `man`, which have no report.
    #[arg(long, global = true, value_name = "FILE")]
    pub json_to: Option<PathBuf>,
}

/// The commands, in workflow order: design first, then the other design-side commands, then
/// calibration from simulating a log to validating a built spring, then shell helpers.
#[derive(Subcommand, Debug)]
pub enum Command {
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
    /// Write a commented starter spec to edit (every key, with its default and unit).
    ///
    /// Examples:
    ///   camspring init my.toml && camspring design my.toml
    ///   camspring init ankle.toml --law conditions     # force and stiffness where you need them
    ///   camspring init curve.toml --law table          # also writes curve-table.csv to edit
    #[command(verbatim_doc_comment)]
    Init {
        /// Spec file to write.
        path: PathBuf,
        /// How the starter states the force law.
        #[arg(long, value_enum, default_value_t = LawArg::Paper)]
        law: LawArg,
        /// Overwrite an existing file.
        #[arg(long)]
        force: bool,
        /// Print what was written as JSON on stdout.
        #[arg(long)]
        json: bool,
    },
    /// Explore a grid of follower designs in parallel: pressure angle, lift and contact stress.
    ///
    /// Writes sweep.csv (one row per design) and sweep.svg.
    ///
    /// Examples:
    ///   camspring sweep specs/paper.toml --vary spring_rate=2..20 --vary preload=0..10
    ///   camspring sweep specs/paper.toml --vary roller_radius=1..5:9 --vary friction=0,0.01,0.05
    ///   camspring sweep specs/paper.toml --vary thickness=4..12:5 --vary cam_material=aluminium-6061-t6,steel-1045
    #[command(verbatim_doc_comment)]
    Sweep {
        /// Spec file (TOML); the built-in default spec when omitted.
        spec: Option<PathBuf>,
        /// An axis: KEY=A..B (10 values), KEY=A..B:N or KEY=V1,V2,...; keys spring_rate (N/mm),
        /// preload (mm), roller_radius (mm), friction, thickness (mm), roller_width (mm) and
        /// cam_material (preset names). Repeat for up to 3 axes.
        #[arg(long, required = true, value_parser = parse_axis)]
        vary: Vec<camspring::sweep::Axis>,
        /// Also search each failing check's advice at every point (slower: the searches
        /// re-synthesise the cam).
        #[arg(long)]
        advice: bool,
        /// Output folder (default out/<spec name>/sweep).
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// Print every grid point as JSON on stdout.
        #[arg(long)]
        json: bool,
    },
    /// Rank the springs of the spec's catalogue (follower.spring_catalogue) for this design.
    ///
    /// Each spring's rate re-synthesises the cam at the smallest preload that passes; springs
    /// that realise the design within their travel come first, ranked by the travel left.
    ///
    /// Examples:
    ///   camspring springs my.toml
    ///   camspring springs my.toml --apply CS-0820          # writes my-CS-0820.toml
    #[command(verbatim_doc_comment)]
    Springs {
        /// Spec file (TOML) naming a spring catalogue.
        spec: PathBuf,
        /// Write the spec with this part's rate and the preload it needs.
        #[arg(long, value_name = "PART")]
        apply: Option<String>,
        /// Where --apply writes (default: SPEC-PART.toml beside the spec).
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// Print the ranking as JSON on stdout.
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
    ///   camspring simulate out/paper-B/paper-B.toml --built -o b.csv   # a revision, built from its parts
    ///   camspring simulate -o off.csv --built-rate-scale 1.12 --built-friction 0.03
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
        /// Motion profile.
        #[arg(long, value_enum, default_value_t = ProfileArg::Sines)]
        profile: ProfileArg,
        /// Duration, e.g. 300s, 5min, 1h.
        #[arg(long, default_value = "300s", value_parser = duration)]
        duration: f64,
        /// Sampling rate, e.g. 100Hz, 1kHz.
        #[arg(long, default_value = "100Hz", value_parser = rate)]
        rate: f64,
        /// Random seed (noise and step levels).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Speed of the profile relative to its nominal one (0.25 for a heavy damper whose
        /// force would otherwise fall with speed; 0.01 to 10).
        #[arg(long, default_value_t = 1.0)]
        speed: f64,
        /// Inertia m in N s^2/mm.
        #[arg(long, default_value_t = 0.05, allow_hyphen_values = true)]
        m: f64,
        /// Coulomb friction d0 in N.
        #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
        d0: f64,
        /// Linear damping d1 in N s/mm.
        #[arg(long, default_value_t = 0.2, allow_hyphen_values = true)]
        d1: f64,
        /// Cubic damping d2 in N s^3/mm^3.
        #[arg(long, default_value_t = -1e-4, allow_hyphen_values = true)]
        d2: f64,
        /// Force noise variance in N^2 (the paper's 0.017).
        #[arg(long, default_value_t = 0.017, allow_hyphen_values = true)]
        force_variance: f64,
        /// Position noise variance in mm^2 (the paper's 0.01).
        #[arg(long, default_value_t = 0.01, allow_hyphen_values = true)]
        position_variance: f64,
        #[command(flatten)]
        built: BuiltArgs,
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
    ///   camspring identify rig.csv --force-delay auto   # a load cell read late
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
        /// Write every N-th filtered sample to the time series (a day at 1 kHz is 86 million
        /// rows, 21 GB): the filter still runs on every sample.
        #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=1_000_000_000))]
        every: u64,
        /// Print the final estimates as JSON on stdout.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        calibration: CalibrationArgs,
    },
    /// Check a built spring's calibration log against its design: one verdict.
    ///
    /// Exit code 0 pass (conclusive or not), 1 fail, 2 bad input or a log that judges nothing
    /// ("NOT JUDGED"). Writes validation.svg next to the log.
    ///
    /// Examples:
    ///   camspring validate specs/paper.toml out/paper/calib.csv
    ///   camspring validate specs/paper.toml calib.csv --json            # against the build band
    ///   camspring validate specs/paper.toml calib.csv --tolerance 3%     # flat, against the law
    #[command(verbatim_doc_comment)]
    Validate {
        /// Spec file (TOML) of the design.
        spec: PathBuf,
        /// Calibration log (CSV with a header).
        log: PathBuf,
        /// Judge the force curve against the law within this relative deviation, e.g. 3%,
        /// instead of against the band of builds the spec's [tolerances] allow (the default;
        /// k2 and the stiffness line are then held to 3 %).
        #[arg(long, value_parser = fraction)]
        tolerance: Option<f64>,
        /// Plot to write (default validation.svg next to the log).
        #[arg(long)]
        svg: Option<PathBuf>,
        /// Print the verdict as JSON on stdout.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        calibration: CalibrationArgs,
    },
    /// Explain a built spring's calibration log with the design's own forward model: which
    /// build parameters (spring rate, preload, contact friction, encoder zero) are off, and by
    /// how much.
    ///
    /// Writes diagnosis.svg (measured, designed and re-fitted force curves) next to the log.
    /// The encoder zero is taken as logged unless given (--position-offset 0.3mm) or fitted
    /// (--position-offset auto; on an exponential law it trades against the spring rate).
    ///
    /// Examples:
    ///   camspring diagnose specs/paper.toml out/paper/calib.csv
    ///   camspring diagnose specs/paper.toml calib.csv --json
    ///   camspring diagnose specs/paper.toml calib.csv --position-offset auto
    #[command(verbatim_doc_comment)]
    Diagnose {
        /// Spec file (TOML) of the design.
        spec: PathBuf,
        /// Calibration log (CSV with a header).
        log: PathBuf,
        /// Plot to write (default diagnosis.svg next to the log).
        #[arg(long)]
        svg: Option<PathBuf>,
        /// Print the diagnosis as JSON on stdout.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        build: BuildFitArgs,
    },
    /// Write a revision of the design that meets the original law with the parts as built.
    ///
    /// Tries, cheapest first: a new preload (shim) with the existing cam and springs, a
    /// catalogue spring (follower.spring_catalogue), a cam re-cut for the parts as built. Each
    /// option is given with its predicted force error and every design check; the first that
    /// passes is written as <name>-<revision>.toml with its note, plus the whole output set
    /// (CAD, G-code, report) for a re-cut. Exit code 0 revised, 1 refused, 2 bad input.
    ///
    /// Examples:
    ///   camspring revise specs/paper.toml out/paper/calib.csv -o out/paper-B
    ///   camspring revise specs/paper.toml calib.csv -o rev --tolerance 1% --json
    #[command(verbatim_doc_comment)]
    Revise {
        /// Spec file (TOML) of the design.
        spec: PathBuf,
        /// Calibration log (CSV with a header).
        log: PathBuf,
        /// Folder to write the revision to.
        #[arg(short, long)]
        out: PathBuf,
        /// Largest relative force error the revised build may have on the stroke, e.g. 2%.
        #[arg(long, default_value = "3%", value_parser = fraction)]
        tolerance: f64,
        /// Print the revision as JSON on stdout.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        build: BuildFitArgs,
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
}

/// The simulated motion.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProfileArg {
    /// Two superposed sines over most of the stroke.
    Sines,
    /// Slow ramps between levels with holds: quasi-static.
    RampHold,
    /// Quick smoothed steps between random levels.
    Steps,
    /// At rest at mid stroke (for noise models).
    Static,
}

impl From<ProfileArg> for Profile {
    fn from(p: ProfileArg) -> Profile {
        match p {
            ProfileArg::Sines => Profile::Sines,
            ProfileArg::RampHold => Profile::RampHold,
            ProfileArg::Steps => Profile::Steps,
            ProfileArg::Static => Profile::Static,
        }
    }
}

/// How a starter spec states the force law.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum LawArg {
    /// The paper's targets (fmax, fmin, xmax, l0, c0, delta0).
    Paper,
    /// Three conditions: force or stiffness at a deflection, or stiffness at a force.
    Conditions,
    /// A given exponential law (mu, k2, f0).
    Given,
    /// A force table in a CSV file beside the spec.
    Table,
}

impl From<LawArg> for camspring::spec::StarterLaw {
    fn from(l: LawArg) -> Self {
        use camspring::spec::StarterLaw;
        match l {
            LawArg::Paper => StarterLaw::Paper,
            LawArg::Conditions => StarterLaw::Conditions,
            LawArg::Given => StarterLaw::Given,
            LawArg::Table => StarterLaw::Table,
        }
    }
}

/// The EKF's prediction step.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum DiscretizationArg {
    /// Classic Runge-Kutta (accurate).
    Rk4,
    /// The paper's forward Euler (biased; for comparison).
    Euler,
}

impl From<DiscretizationArg> for Discretization {
    fn from(d: DiscretizationArg) -> Discretization {
        match d {
            DiscretizationArg::Rk4 => Discretization::Rk4,
            DiscretizationArg::Euler => Discretization::Euler,
        }
    }
}

/// A build off its design, for `simulate`: any of these simulates the design's own cam
/// through its forward model, with loading and unloading curves apart by the contact friction.
#[derive(clap::Args, Debug, Default)]
pub struct BuiltArgs {
    /// Simulate the spring as built from the design's parts: the cam's loading and unloading
    /// curves through its forward model (the contact friction's hysteresis), not the law
    /// itself. Implied by any --built-* value and by the spec's [assembly].
    #[arg(long)]
    pub built: bool,
    /// The built springs' rate over the designed rate, e.g. 1.12 for springs 12 % stiffer.
    #[arg(long, value_name = "FACTOR")]
    pub built_rate_scale: Option<f64>,
    /// Preload as assembled minus the designed preload, as follower travel, e.g. -0.3mm.
    #[arg(long, value_name = "LENGTH", value_parser = length, allow_hyphen_values = true)]
    pub built_preload_offset: Option<f64>,
    /// The build's contact friction coefficient (default: the design's).
    #[arg(long, value_name = "COEFFICIENT")]
    pub built_friction: Option<f64>,
    /// The rig's encoder reads the deflection plus this, e.g. 0.5mm.
    #[arg(long, value_name = "LENGTH", value_parser = length, allow_hyphen_values = true)]
    pub built_zero_offset: Option<f64>,
}

fn length(text: &str) -> Result<f64, String> {
    camspring::units::parse_quantity(text.trim(), camspring::units::Dimension::Length)
        .map_err(|e| format!("\"{text}\": expected a length such as 0.5mm ({e})"))
}

/// What `diagnose` and `revise` read: the sensors, the log's columns and the encoder zero.
#[derive(clap::Args, Debug)]
pub struct BuildFitArgs {
    /// Encoder zero: none (as logged), a length such as 0.3mm (subtracted), or auto (fitted).
    #[arg(long, value_name = "auto|LENGTH", default_value = "none", value_parser = position_offset)]
    pub position_offset: PositionOffset,
    #[command(flatten)]
    pub sensors: Sensors,
    #[command(flatten)]
    pub columns: Columns,
}

/// What estimation and validation read: the filter, the sensors and the log's columns.
#[derive(clap::Args, Debug)]
pub struct CalibrationArgs {
    #[command(flatten)]
    pub filter: FilterArgs,
    #[command(flatten)]
    pub sensors: Sensors,
    #[command(flatten)]
    pub columns: Columns,
}

/// Sensor noise and filter window for identification and estimation.
#[derive(clap::Args, Debug)]
pub struct Sensors {
    /// Sensor noise from `camspring noise --json` (default: estimated from the log's own
    /// higher differences; the paper's sensors on a log too short for that).
    #[arg(long)]
    pub noise: Option<PathBuf>,
    /// Force noise variance in N^2 (overrides --noise and the log's own estimate).
    #[arg(long, value_parser = variance)]
    pub force_variance: Option<f64>,
    /// Position noise variance in mm^2 (overrides --noise and the log's own estimate).
    #[arg(long, value_parser = variance)]
    pub position_variance: Option<f64>,
    /// Savitzky-Golay window, e.g. 0.8s (default: chosen from the log by the balancing principle).
    #[arg(long, value_parser = duration)]
    pub window: Option<f64>,
    /// How late the force is read after the position: none (read together), a duration such
    /// as 10ms (negative when the force is read first), or auto (fitted by identification).
    /// The force is re-timed to its position's instant.
    #[arg(long, value_name = "auto|DURATION", default_value = "none", value_parser = force_delay, allow_hyphen_values = true)]
    pub force_delay: ForceDelay,
}

fn force_delay(text: &str) -> Result<ForceDelay, String> {
    use camspring::estimate::retime::MAX_FORCE_DELAY_S;
    match text.trim() {
        "none" => Ok(ForceDelay::None),
        "auto" => Ok(ForceDelay::Auto),
        t => {
            let s = camspring::units::parse_quantity(t, camspring::units::Dimension::Time)
                .map_err(|e| {
                    format!("\"{t}\": expected auto, none or a duration such as 10ms ({e})")
                })?;
            if s.abs() > MAX_FORCE_DELAY_S {
                return Err(format!(
                    "\"{t}\": a force read {:.3} s from its position; expected at most \
                     {MAX_FORCE_DELAY_S} s either way (a channel scan or a converter's filter \
                     delays by milliseconds)",
                    s.abs()
                ));
            }
            Ok(ForceDelay::Seconds(s))
        }
    }
}

/// EKF options.
#[derive(clap::Args, Debug)]
pub struct FilterArgs {
    /// Initial state: `identify` (offline identification of the same log) or a spec file.
    #[arg(long, default_value = "identify", value_parser = init_source)]
    pub init: InitSource,
    /// Prediction method.
    #[arg(long, value_enum, default_value_t = DiscretizationArg::Rk4)]
    pub discretization: DiscretizationArg,
    /// Force-rate input: zero-phase[:TIME] (offline; TIME defaults to 0.4s) or first-order[:TIME] (the paper's filter; TIME defaults to 0.02s).
    #[arg(long, default_value = "zero-phase", value_parser = force_rate)]
    pub force_rate: ForceRate,
    /// Process noise density of a state, e.g. --q xdd=0.5 --q sigma=1e-3 (repeatable;
    /// states x, xd, xdd, sigma, d, m, k2, d2; units^2 per s).
    #[arg(long, value_name = "STATE=VALUE")]
    pub q: Vec<String>,
    /// Initial standard deviation of a state, e.g. --p0 m=0.01 (repeatable).
    #[arg(long, value_name = "STATE=VALUE")]
    pub p0: Vec<String>,
    /// Position measurement variance R in mm^2 (default: the position noise).
    #[arg(long, value_parser = positive_variance)]
    pub r: Option<f64>,
    /// Encoder zero: `auto` fits it against the designed law (validate, or estimate --init
    /// SPEC); a length such as 0.5mm is subtracted from every position.
    #[arg(long, value_name = "auto|LENGTH", default_value = "none", value_parser = position_offset)]
    pub position_offset: PositionOffset,
    /// Identification, the filter's init, uses the first this much of the log, e.g. 10min
    /// (a day-long log's init then takes bounded memory and time).
    #[arg(long, default_value = "1h", value_parser = duration)]
    pub identify_span: f64,
    /// Twins of the log (simulated copies with known truth, 0 to 64, each identified as the
    /// log was; at least 2 for a correction) on which the filter's bias in k2 is measured and
    /// taken out, and identification's error carried into its standard deviation; 0 reports
    /// the filter's raw constants.
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u16).range(0..=64))]
    pub twins: u16,
}

fn position_offset(text: &str) -> Result<PositionOffset, String> {
    match text.trim() {
        "none" => Ok(PositionOffset::None),
        "auto" => Ok(PositionOffset::Auto),
        t => camspring::units::parse_quantity(t, camspring::units::Dimension::Length)
            .map(PositionOffset::Mm)
            .map_err(|e| format!("\"{t}\": expected auto, none or a length such as 0.5mm ({e})")),
    }
}

/// Column mapping of a calibration log.
#[derive(clap::Args, Debug)]
pub struct Columns {
    /// Time column and unit (s, ms, us, min, h). Where the header has no t_s, the one column
    /// whose name reads as time with its unit ("Time [ms]") is read, and a note says so.
    #[arg(long, default_value = "t_s")]
    pub time: String,
    /// Force column and unit (N, kN, lbf); a minus sign reads it reversed (load:-N). Where
    /// the header has no force_n, the one column whose name reads as force with its unit
    /// ("Load (kN)") is read.
    #[arg(long, default_value = "force_n")]
    pub force: String,
    /// Position column and unit (mm, m, in); a minus sign reads it reversed (x:-mm). Where
    /// the header has no position_mm, the one column whose name reads as position with its
    /// unit ("x_in") is read.
    #[arg(long, default_value = "position_mm")]
    pub position: String,
    /// Allowed deviation of each sampling interval from the mean interval so far, e.g. 10%.
    #[arg(long, default_value = "10%", value_parser = fraction)]
    pub sampling_tolerance: f64,
    /// Field separator of the log (auto: detected from the header line).
    #[arg(long, value_enum, default_value_t = DelimiterArg::Auto)]
    pub delimiter: DelimiterArg,
    /// A log without a time column, e.g. 1kHz: its rows are samples at this rate, the first
    /// at t = 0 (a row with no value is a dropped sample; a missing row cannot be seen).
    #[arg(long, value_name = "RATE", value_parser = rate, conflicts_with = "time")]
    pub sample_rate: Option<f64>,
}

/// Field separator of a log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum DelimiterArg {
    /// The most frequent of comma, tab and semicolon in the header line (runs of blanks where
    /// it has none; a spreadsheet's sep= line names it).
    Auto,
    /// ,
    Comma,
    /// A tab.
    Tab,
    /// ;
    Semicolon,
    /// Runs of spaces or tabs (column-aligned text).
    Whitespace,
}

impl From<DelimiterArg> for camspring::estimate::log::Delimiter {
    fn from(d: DelimiterArg) -> Self {
        use camspring::estimate::log::Delimiter;
        match d {
            DelimiterArg::Auto => Delimiter::Auto,
            DelimiterArg::Comma => Delimiter::Comma,
            DelimiterArg::Tab => Delimiter::Tab,
            DelimiterArg::Semicolon => Delimiter::Semicolon,
            DelimiterArg::Whitespace => Delimiter::Whitespace,
        }
    }
}

fn duration(text: &str) -> Result<f64, String> {
    parse_duration_s(text)
}

fn rate(text: &str) -> Result<f64, String> {
    parse_rate_hz(text)
}

fn fraction(text: &str) -> Result<f64, String> {
    parse_fraction(text)
}

fn variance(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("\"{text}\": expected a variance >= 0")),
    }
}

fn positive_variance(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("\"{text}\": expected a variance > 0 (mm^2)")),
    }
}

fn parse_axis(text: &str) -> Result<camspring::sweep::Axis, String> {
    camspring::sweep::parse_axis(text)
}

fn init_source(text: &str) -> Result<InitSource, String> {
    Ok(if text == "identify" {
        InitSource::Identify
    } else {
        InitSource::Spec(PathBuf::from(text))
    })
}

fn force_rate(text: &str) -> Result<ForceRate, String> {
    match text.split_once(':') {
        None if text == "zero-phase" => Ok(ForceRate::ZERO_PHASE),
        Some(("zero-phase", t)) => match parse_duration_s(t)? {
            w if w <= ForceRate::MAX_ZERO_PHASE_S => Ok(ForceRate::ZeroPhase { window_s: w }),
            w => Err(format!(
                "\"{t}\": a zero-phase window of {w} s; expected at most {} s",
                ForceRate::MAX_ZERO_PHASE_S
            )),
        },
        None if text == "first-order" => Ok(ForceRate::FirstOrder {
            time_constant_s: 0.02,
        }),
        Some(("first-order", t)) => Ok(ForceRate::FirstOrder {
            time_constant_s: parse_duration_s(t)?,
        }),
        _ => Err(format!(
            "\"{text}\": expected zero-phase[:TIME] or first-order[:TIME]"
        )),
    }
}
