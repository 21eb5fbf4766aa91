//! The calibration acceptance matrix (development aid and the numbers in
//! docs/CALIBRATION.md): every row, run and seed, identified, filtered and validated.
//!
//! Run: `cargo run --release --example acceptance [seeds]` (default 3).

#[path = "../tests/acceptance_matrix/mod.rs"]
mod matrix;

use matrix::{run_case, Case, ROWS, RUNS};
use rayon::prelude::*;

fn main() {
    let seeds: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(3);
    let mut cases = Vec::new();
    for row in ROWS {
        for run in RUNS {
            for seed in 0..seeds {
                cases.push(Case { row, run, seed });
            }
        }
    }
    let out: Vec<matrix::Outcome> = cases.par_iter().map(run_case).collect();
    for o in &out {
        println!("{o}");
    }
    let count = |f: &dyn Fn(&matrix::Outcome) -> bool| out.iter().filter(|o| f(o)).count();
    println!(
        "{} cases: identify meets its bounds (or says it is imprecise, with honest z) in {}, says the model does not fit in {}, imprecise in {}; estimate meets its bounds in {}, misses them but flags itself in {}, misses them but says it is imprecise (honest z) in {}, misses them silently in {}, diverged in {}; validate right in {}",
        out.len(),
        count(&|o| o.identify_ok()),
        count(&|o| o.does_not_fit.is_some()),
        count(&|o| o.imprecise),
        count(&|o| o.estimate_ok()),
        count(&|o| !o.estimate_ok() && o.ekf.is_ok() && o.ekf_inconsistent.is_some()),
        count(&|o| !o.estimate_ok() && o.ekf_inconsistent.is_none() && o.estimate_meets_or_says()),
        count(&|o| o.ekf.is_ok() && !o.estimate_meets_or_says()),
        count(&|o| o.ekf.is_err()),
        count(&|o| o.validate_true && !o.validate_off),
    );
}
