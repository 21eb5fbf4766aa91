//! Shared helpers for the integration tests: the paper's law, follower builders, tolerances.
#![allow(dead_code)]

use camspring::cam::pitch_curve::SynthesisOptions;
use camspring::model::{Follower, FrictionCorrection, FrictionSource, Hole, SpringArrangement};
use camspring::{
    law::solve,
    model::{ExpLaw, LawTargets},
};

/// The paper's targets (docs/THEORY.md section 1).
pub fn paper_targets() -> LawTargets {
    LawTargets {
        fmax_n: 200.0,
        fmin_n: 5.0,
        xmax_mm: 20.0,
        l0_mm: 5.0,
        c0: 0.2,
        delta0_mm: 1.0,
    }
}

/// The paper's law, solved exactly.
pub fn paper_law() -> ExpLaw {
    *solve(&paper_targets()).unwrap().exponential().unwrap()
}

/// A follower arrangement.
pub fn follower(
    count: u8,
    ks: f64,
    preload: f64,
    roller: f64,
    mu: f64,
    corr: FrictionCorrection,
) -> Follower {
    Follower {
        count,
        arrangement: SpringArrangement::PerFollower,
        spring_rate_n_per_mm: ks,
        preload_mm: preload,
        roller_radius_mm: roller,
        friction: FrictionSource::Coefficient { coefficient: mu },
        friction_correction: corr,
        bearing: Default::default(),
    }
}

/// Fine sampling for accuracy tests.
pub fn fine() -> SynthesisOptions {
    SynthesisOptions {
        chord_tolerance_mm: 1e-4,
        max_step_mm: 0.05,
    }
}

/// |a - b| <= tol, with a message.
#[track_caller]
pub fn assert_near(a: f64, b: f64, tol: f64, what: &str) {
    assert!(
        (a - b).abs() <= tol,
        "{what}: {a} vs {b} (difference {:e}, tolerance {tol:e})",
        (a - b).abs()
    );
}

/// Classic fixed-step RK4 for dY/dx = f(x, Y): an independent integrator for the tests.
pub fn rk4(f: impl Fn(f64, f64) -> f64, x0: f64, y0: f64, x1: f64, steps: usize) -> f64 {
    let h = (x1 - x0) / steps as f64;
    let (mut x, mut y) = (x0, y0);
    for _ in 0..steps {
        let k1 = f(x, y);
        let k2 = f(x + h / 2.0, y + h / 2.0 * k1);
        let k3 = f(x + h / 2.0, y + h / 2.0 * k2);
        let k4 = f(x + h, y + h * k3);
        y += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
        x += h;
    }
    y
}

/// Runs the real binary in `dir` and prints what it said (shown when a test fails).
pub fn camspring(dir: &std::path::Path, args: &[&str]) -> std::process::Output {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_camspring"))
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap();
    eprintln!(
        "camspring {args:?} -> {:?}\n--- stdout\n{}\n--- stderr\n{}",
        out.status.code(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Three holes that fit the paper's part: 8 mm and 5 mm on the centre line, 3.3 mm below it
/// (a pin hole, a bolt hole and a tapping drill's).
pub fn three_holes() -> Vec<Hole> {
    [(12.0, 0.0, 8.0), (3.0, 0.0, 5.0), (18.0, -5.5, 3.3)]
        .iter()
        .map(|&(x_mm, y_mm, diameter_mm)| Hole {
            x_mm,
            y_mm,
            diameter_mm,
        })
        .collect()
}

/// The column map of `--time`, `--force` and `--position` options (`name:unit`), the
/// separator detected.
pub fn column_map(time: &str, force: &str, position: &str) -> camspring::estimate::log::ColumnMap {
    use camspring::estimate::log::{parse_column, parse_time_column, ColumnMap};
    use camspring::units::Dimension;
    ColumnMap {
        time: parse_time_column(time).unwrap(),
        force: parse_column(force, Dimension::Force, "force").unwrap(),
        position: parse_column(position, Dimension::Length, "position").unwrap(),
        ..ColumnMap::default()
    }
}

/// The criterion named `name` in a `validate --json` report (its `criteria[]`).
pub fn criterion<'a>(report: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    report["criteria"]
        .as_array()
        .and_then(|all| all.iter().find(|c| c["name"] == name))
        .unwrap_or_else(|| panic!("no criterion {name} in {report}"))
}
