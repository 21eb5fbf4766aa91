//! The calibration acceptance matrix, shared by `tests/acceptance.rs` and
//! `examples/acceptance.rs`: light to heavy transmissions (the paper's Table I as one row),
//! four profiles, simulated with known truth; each case is identified, filtered and validated.

#![allow(dead_code)]

use std::fmt;

use camspring::estimate::identify::{Identification, Param};
use camspring::estimate::noise::{log_noise, GivenNoise};
use camspring::estimate::sim::{simulate, Dynamics, Profile, SimSettings};
use camspring::model::ExpLaw;
use camspring::verdict::validate::validate_with;
use camspring::{estimate, EstimateOptions};

/// Stroke of the simulated spring (mm).
pub const XMAX_MM: f64 = 15.0;

/// One transmission of the matrix.
#[derive(Debug, Clone, Copy)]
pub struct Row {
    /// Name.
    pub name: &'static str,
    /// Its dynamics.
    pub dynamics: Dynamics,
}

const fn row(name: &'static str, m: f64, d0: f64, d1: f64, d2: f64) -> Row {
    Row {
        name,
        dynamics: Dynamics {
            m_n_s2_per_mm: m,
            d0_n: d0,
            d1_n_s_per_mm: d1,
            d2_n_s3_per_mm3: d2,
        },
    }
}

/// The transmissions: m from 0.002 to 0.5 N s^2/mm, d1 from 0.05 to 3 N s/mm, d2 from 0 to
/// the paper's Table II value, d0 from 0 to 4 N, and the paper's Table I.
pub const ROWS: [Row; 6] = [
    row("light", 0.002, 0.0, 0.05, 0.0),
    row("default", 0.05, 0.0, 0.2, -1e-4),
    row("heavy", 0.25, 0.5, 1.5, -0.008),
    row("table-I", 0.39, 3.82, 1.84, -0.0108),
    row("table-II-d2", 0.055, 0.2, 1.84, -0.106),
    row("heaviest", 0.5, 4.0, 3.0, 0.0),
];

/// The profiles: sines, ramp-hold, steps, and a slow quasi-static ramp-hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Run {
    Sines,
    RampHold,
    Steps,
    Slow,
}

/// Every run kind.
pub const RUNS: [Run; 4] = [Run::Sines, Run::RampHold, Run::Steps, Run::Slow];

/// One case: a row, a run and a seed.
#[derive(Debug, Clone, Copy)]
pub struct Case {
    pub row: Row,
    pub run: Run,
    pub seed: u64,
}

/// The law of every row: mu exp(k2 x) + F0, with F0 raised with the Coulomb friction so that
/// the wire never has to push.
pub fn law(row: &Row) -> ExpLaw {
    ExpLaw {
        mu_n: 1.1,
        k2_per_mm: 0.24,
        f0_n: 2.0 + 2.5 * row.dynamics.d0_n,
    }
}

/// What one case gave.
#[derive(Debug, Clone)]
pub struct Outcome {
    pub case: Case,
    /// Profile speed used (the fastest of a ladder that the transmission allows).
    pub speed: f64,
    /// Identification's relative errors of k2 and mu, or the error.
    pub k2_error: f64,
    pub mu_error: f64,
    /// The largest |z| over the identified parameters, and which.
    pub worst_z: (f64, &'static str),
    /// Identification's own verdict on the fit (None: it fits).
    pub does_not_fit: Option<String>,
    /// Identification says k2 or mu is not precise enough for the target (a warning).
    pub imprecise: bool,
    pub not_identifiable: Vec<String>,
    pub window_s: f64,
    pub reduced_chi2: f64,
    /// Whether identify reports M as identifiable (relative std below 10 %).
    pub m_identifiable: bool,
    /// The EKF's relative errors of k2 and M, or why it failed.
    pub ekf: Result<(f64, f64, f64, f64), String>,
    /// The filter's own consistency verdict (None: consistent), and whether it recovered
    /// from a divergence.
    pub ekf_inconsistent: Option<String>,
    pub ekf_recovered: bool,
    /// The filter warns that its k2 or M is less precise than its target.
    pub ekf_imprecise: bool,
    /// validate of the true law passes, and of a law with k2 5 % high fails.
    pub validate_true: bool,
    pub validate_off: bool,
    /// The force-delay screen's z (None: not screened), and whether it suspected a delay
    /// (the simulator reads force and position together).
    pub delay_screen: Option<(f64, bool)>,
    pub error: Option<String>,
}

impl Outcome {
    /// Identification meets the bounds: k2 within 0.5 %, mu within 1.5 % and every
    /// |z| below 3, or it says the model does not fit.
    pub fn identify_ok(&self) -> bool {
        self.error.is_none()
            && (self.does_not_fit.is_some()
                || (self.imprecise && self.worst_z.0 < 3.0)
                || (self.k2_error.abs() < 0.005
                    && self.mu_error.abs() < 0.015
                    && self.worst_z.0 < 3.0))
    }

    /// The EKF does not diverge, k2 within 0.5 %, M within 2 % where identify says M is
    /// identifiable, and |z| below 3 for both.
    pub fn estimate_ok(&self) -> bool {
        match self.ekf {
            Ok((k2, m, zk, zm)) => {
                k2.abs() < 0.005
                    && zk.abs() < 3.0
                    && (!self.m_identifiable || (m.abs() < 0.02 && zm.abs() < 3.0))
            }
            Err(_) => false,
        }
    }

    /// The filter meets its target, or says that it does not: it flags itself not consistent,
    /// or it warns that this log determines its k2 or M less precisely than the target, with
    /// errors within 3 of its standard deviations (honest).
    pub fn estimate_meets_or_says(&self) -> bool {
        match self.ekf {
            Ok((_, _, zk, zm)) => {
                self.estimate_ok()
                    || self.ekf_inconsistent.is_some()
                    || (self.ekf_imprecise
                        && zk.abs() < 3.0
                        && (!self.m_identifiable || zm.abs() < 3.0))
            }
            Err(_) => false,
        }
    }
}

impl fmt::Display for Outcome {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{:12} {:9?} seed {} speed {:.2}: ",
            self.case.row.name, self.case.run, self.case.seed, self.speed
        )?;
        if let Some(e) = &self.error {
            return write!(f, "ERROR {e}");
        }
        write!(
            f,
            "w {:.2}s chi2 {:.2} delay z {} k2 {:+.3}% mu {:+.2}% worst |z| {:.1} ({}) drop {:?}{}{} ",
            self.window_s,
            self.reduced_chi2,
            match self.delay_screen {
                Some((z, suspected)) => format!("{z:+.1}{}", if suspected { " SUSPECTED" } else { "" }),
                None => "-".into(),
            },
            100.0 * self.k2_error,
            100.0 * self.mu_error,
            self.worst_z.0,
            self.worst_z.1,
            self.not_identifiable,
            if self.imprecise { " IMPRECISE" } else { "" },
            match &self.does_not_fit {
                Some(r) => format!(" DOES NOT FIT: {r}"),
                None => String::new(),
            }
        )?;
        match &self.ekf {
            Ok((k2, m, zk, zm)) => write!(
                f,
                "| ekf k2 {:+.3}% (z {zk:+.1}) M {:+.2}% (z {zm:+.1}){}{}{}{} ",
                100.0 * k2,
                100.0 * m,
                if self.m_identifiable { "" } else { " [M n.i.]" },
                if self.ekf_recovered { " RECOVERED" } else { "" },
                if self.ekf_imprecise {
                    " EKF-IMPRECISE"
                } else {
                    ""
                },
                if self.ekf_inconsistent.is_some() {
                    " FLAGGED"
                } else {
                    ""
                },
            )?,
            Err(e) => write!(f, "| ekf FAILED {e} ")?,
        }
        write!(
            f,
            "| validate true {} off {}",
            if self.validate_true { "pass" } else { "FAIL" },
            if self.validate_off { "pass" } else { "fail" }
        )
    }
}

/// Seconds of each simulated log.
pub const SECONDS: f64 = 300.0;

/// Simulates and checks one case.
pub fn run_case(case: &Case) -> Outcome {
    let law = law(&case.row);
    let profile = match case.run {
        Run::Sines => Profile::Sines,
        Run::Steps => Profile::Steps,
        Run::RampHold | Run::Slow => Profile::RampHold,
    };
    let slow = if case.run == Run::Slow { 0.25 } else { 1.0 };
    let mut outcome = Outcome {
        case: *case,
        speed: 0.0,
        k2_error: f64::NAN,
        mu_error: f64::NAN,
        worst_z: (0.0, ""),
        does_not_fit: None,
        imprecise: false,
        not_identifiable: Vec::new(),
        window_s: 0.0,
        reduced_chi2: f64::NAN,
        m_identifiable: false,
        ekf: Err("not run".into()),
        ekf_inconsistent: None,
        ekf_recovered: false,
        ekf_imprecise: false,
        validate_true: false,
        validate_off: false,
        delay_screen: None,
        error: None,
    };
    let mut log = None;
    for speed in [1.0, 0.7, 0.5, 0.35, 0.25, 0.18, 0.12] {
        let settings = SimSettings {
            profile,
            duration_s: SECONDS,
            seed: case.seed,
            speed: speed * slow,
            dynamics: case.row.dynamics,
            ..SimSettings::default()
        };
        if let Ok((l, _)) = simulate(law, XMAX_MM, 500.0, &settings) {
            outcome.speed = speed * slow;
            log = Some(l);
            break;
        }
    }
    let Some(log) = log else {
        outcome.error = Some("no speed is feasible".into());
        return outcome;
    };
    // As `camspring estimate` does by default: the sensor noise from the log's own differences.
    let run = match estimate(
        &log,
        &EstimateOptions::new(GivenNoise::default()),
        |_, _| {},
    ) {
        Ok(run) => run,
        Err(e) => {
            // Identification alone, to tell what failed.
            let noise = GivenNoise::default()
                .resolve(log_noise(&log).as_ref())
                .noise;
            match camspring::estimate::identify::identify(&log, &noise) {
                Ok(id) => {
                    record_identification(&mut outcome, &id, &law, case);
                    outcome.ekf = Err(e.to_string());
                    // As `camspring validate` does: identification judges.
                    let off = ExpLaw {
                        k2_per_mm: 1.05 * law.k2_per_mm,
                        ..law
                    };
                    outcome.validate_true =
                        validate_with(&law, &id, None, &log.position_mm, 0.03, None).pass;
                    outcome.validate_off =
                        validate_with(&off, &id, None, &log.position_mm, 0.03, None).pass;
                }
                Err(e) => outcome.error = Some(e.to_string()),
            }
            return outcome;
        }
    };
    let id = run.identification.as_ref().expect("identified");
    outcome.delay_screen = run
        .force_delay_screen
        .as_ref()
        .map(|s| (s.held.z, s.suspected));
    outcome.ekf_recovered = run.recovery.is_some();
    outcome.ekf_imprecise = !run.imprecise().is_empty();
    if !run.consistency.consistent {
        outcome.ekf_inconsistent = Some(run.consistency.reasons.join("; "));
    }
    record_identification(&mut outcome, id, &law, case);
    let z = run.run.last.z;
    let s = run.run.last.p.diagonal().map(f64::sqrt);
    use camspring::estimate::ekf::idx;
    let m = case.row.dynamics.m_n_s2_per_mm;
    outcome.ekf = Ok((
        z[idx::K2] / law.k2_per_mm - 1.0,
        z[idx::M] / m - 1.0,
        (z[idx::K2] - law.k2_per_mm) / s[idx::K2],
        (z[idx::M] - m) / s[idx::M],
    ));
    let off = ExpLaw {
        k2_per_mm: 1.05 * law.k2_per_mm,
        ..law
    };
    // As `camspring validate` does: a filter that is not consistent does not judge.
    let ekf = run.consistency.consistent.then_some(&run);
    outcome.validate_true = validate_with(&law, id, ekf, &log.position_mm, 0.03, None).pass;
    outcome.validate_off = validate_with(&off, id, ekf, &log.position_mm, 0.03, None).pass;
    outcome
}

fn record_identification(o: &mut Outcome, id: &Identification, law: &ExpLaw, case: &Case) {
    let d = case.row.dynamics;
    let truth = [
        d.m_n_s2_per_mm,
        d.d0_n,
        d.d1_n_s_per_mm,
        d.d2_n_s3_per_mm3,
        law.mu_n,
        law.f0_n,
        law.k2_per_mm,
    ];
    o.window_s = id.sg_window_s;
    o.reduced_chi2 = id.reduced_chi2;
    o.not_identifiable = id.not_identifiable.clone();
    o.does_not_fit = id.adequacy.problem();
    o.imprecise = !id.imprecise().is_empty();
    if let Some(k2) = id.get(Param::K2).value {
        o.k2_error = k2 / law.k2_per_mm - 1.0;
    }
    if let Some(mu) = id.get(Param::Mu).value {
        o.mu_error = mu / law.mu_n - 1.0;
    }
    for (p, e) in id.parameters.iter() {
        if let (Some(v), Some(s)) = (e.value, e.std) {
            let z = ((v - truth.get(p.index()).copied().unwrap_or(0.0)) / s).abs();
            if z > o.worst_z.0 {
                o.worst_z = (z, &p.key()[..p.key().find('_').unwrap_or(2)]);
            }
        }
    }
    let m = id.get(Param::M);
    o.m_identifiable = matches!((m.value, m.std), (Some(v), Some(s)) if s < 0.1 * v.abs());
}
