//! The calibration acceptance matrix (docs/CALIBRATION.md): six transmissions from light to the
//! paper's Table I, four runs (sines, ramp-hold, steps, a slow quasi-static ramp-hold), three
//! seeds: 72 simulated 300 s logs with known truth, each identified, filtered and validated.
//! `cargo run --release --example acceptance` prints every case.

mod acceptance_matrix;

use acceptance_matrix::{run_case, Case, Outcome, ROWS, RUNS};
use rayon::prelude::*;

fn outcomes() -> Vec<Outcome> {
    let mut cases = Vec::new();
    for row in ROWS {
        for run in RUNS {
            for seed in 0..3 {
                cases.push(Case { row, run, seed });
            }
        }
    }
    cases.par_iter().map(run_case).collect()
}

#[test]
fn the_acceptance_matrix() {
    let out = outcomes();
    assert_eq!(out.len(), 72);
    for o in &out {
        eprintln!("{o}");
    }
    // Identification succeeds on every log, and on each it either meets the target (k2 within
    // 0.5 %, mu within 1.5 %) or says that this log does not determine them that well.
    for o in &out {
        assert!(o.error.is_none(), "{o}");
        assert!(o.does_not_fit.is_none(), "{o}");
        assert!(
            o.imprecise || (o.k2_error.abs() < 0.005 && o.mu_error.abs() < 0.015),
            "{o}"
        );
        // Its standard deviations are honest: no estimate 5 of them off...
        assert!(o.worst_z.0 < 5.0, "{o}");
    }
    // ...and few beyond 3: one (F0 at 3.4). Before the filter's bias was counted as twice the
    // change from the next shorter window, six were (m on the heavy rows' sines up to 4.9).
    let beyond_3 = out.iter().filter(|o| o.worst_z.0 >= 3.0).count();
    assert!(
        beyond_3 <= 2,
        "{beyond_3} of 72 cases have an estimate beyond 3 sigma"
    );
    // The simulator reads force and position together: the screen for a force read late
    // runs on every log and suspects none (its |z| was at most 1.3 over the 72, Coulomb
    // friction of 4 N included).
    for o in &out {
        let (z, suspected) = o.delay_screen.expect("a 300 s log is screened");
        assert!(!suspected && z.abs() < 3.0, "{o}");
    }
    // validate passes the true law and fails a law with k2 5 % high, judging through the
    // filter where it is consistent and through identification where it is not.
    // (The filter's stiffness path is checked against identification's law: on a slow run
    // of the light transmission it was biased at low stiffness, and its stiffness line failed
    // the true law, until that run was flagged and identification judged.)
    let true_fails = out.iter().filter(|o| !o.validate_true).count();
    assert_eq!(true_fails, 0, "the true law fails in {true_fails} cases");
    for o in &out {
        assert!(!o.validate_off, "a law 5 % off passes: {o}");
    }
    // The filter never diverges.
    for o in &out {
        assert!(o.ekf.is_ok(), "{o}");
    }
    // It meets its target (k2 within 0.5 %, M within 2 % where identification resolves M,
    // both within 3 sigma), or says that it does not: flagged not consistent, or a warning that
    // this log determines k2 or M less precisely, with honest errors. Before the twins took
    // the filter's k2 bias out, five runs missed silently, by k2 errors of 3.0-3.7 of its
    // standard deviations (the light transmission's ramp-hold and steps, and slow runs), and
    // one by its M (below).
    let silent = out.iter().filter(|o| !o.estimate_meets_or_says()).count();
    assert_eq!(
        silent, 0,
        "{silent} of 72 runs miss the filter's target silently"
    );
    // Its standard deviations are honest wherever it says it is consistent: k2 within 3 of
    // them on every run, and M wherever identification resolves it (relative standard
    // deviation below 10 %).
    // (A heavy steps run's M was 2.8 % off at 0.4 % claimed, z -6.8, until the filter's
    // standard deviation of M was held to at least its disagreement with identification over
    // sqrt(2).)
    for o in out.iter().filter(|o| o.ekf_inconsistent.is_none()) {
        if let Ok((_, _, zk, zm)) = o.ekf {
            assert!(zk.abs() < 3.0, "{o}");
            if o.m_identifiable {
                assert!(zm.abs() < 3.0, "{o}");
            }
        }
    }
    // Strong Coulomb friction (the paper's Table I, d0 3.8 N, and 4 N) no longer leaves it
    // inconsistent: its sign is read from the force (estimate::pipeline). With the sign from
    // the velocity alone, 21 of these 24 runs were flagged and 2 diverged.
    let strong = out.iter().filter(|o| o.case.row.dynamics.d0_n >= 1.0);
    let flagged = strong.filter(|o| o.ekf_inconsistent.is_some()).count();
    assert!(
        flagged <= 3,
        "{flagged} of 24 runs with strong friction flagged"
    );
    // Where the filter is consistent and identification resolves the inertia, on the runs
    // with motion (not the slow one), the filter's k2 is within 1.5 %. (It was 1 % until the
    // twins carried identification's error through the friction stage into k2's standard
    // deviation and bias: the heaviest row's steps then came out 1.10 % off at z 0.2.)
    for o in &out {
        if let Ok((k2, ..)) = o.ekf {
            if o.ekf_inconsistent.is_none()
                && o.m_identifiable
                && o.case.run != acceptance_matrix::Run::Slow
            {
                assert!(k2.abs() < 0.015, "{o}");
            }
        }
    }
}
