//! Where the filter's raw k2 moves over a run: its change from sample to sample, summed over
//! the samples where the simulated rod stands (by the time since it stopped) and where it
//! moves, over seeds of one row (twins off, so the raw filter is seen).
//!
//! Run: `cargo run --release --example k2_drift [seeds] [m d0 d1 d2] [sines|steps|ramp-hold]
//! [speed]` (the law of `examples/nees.rs`). Each seed prints k2 at the filter's start (from
//! identification) and at its end, then the drift while moving and while standing 0-0.1,
//! 0.1-0.2, 0.2-0.4, 0.4-0.8, 0.8-1.6 and beyond 1.6 s after a stop (at 100 Hz).

use camspring::estimate::ekf::idx;
use camspring::estimate::sim::{simulate, Dynamics, Profile, SimSettings};
use camspring::model::ExpLaw;
use camspring::{estimate, EstimateOptions, SensorNoise};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    let f = |i: usize, d: f64| a.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let dynamics = Dynamics {
        m_n_s2_per_mm: f(2, 0.25),
        d0_n: f(3, 0.5),
        d1_n_s_per_mm: f(4, 1.5),
        d2_n_s3_per_mm3: f(5, -0.008),
    };
    let law = ExpLaw {
        mu_n: 1.1,
        k2_per_mm: 0.24,
        f0_n: 2.0 + 2.5 * dynamics.d0_n,
    };
    let profile = match a.get(6).map(String::as_str) {
        Some("steps") => Profile::Steps,
        Some("ramp-hold") => Profile::RampHold,
        _ => Profile::Sines,
    };
    // Bin edges in samples since the stop.
    let edges = [0usize, 10, 20, 40, 80, 160, usize::MAX];
    for seed in 0..f(1, 8.0) as u64 {
        let settings = SimSettings {
            profile,
            seed,
            speed: f(7, 0.5),
            dynamics,
            ..SimSettings::default()
        };
        let Ok((log, truth)) = simulate(law, 15.0, 500.0, &settings) else {
            println!("seed {seed}: not simulated");
            continue;
        };
        let mut opts = EstimateOptions::new(SensorNoise::default());
        opts.twins = 0;
        let run = match estimate(&log, &opts, |_, _| {}) {
            Ok(run) => run,
            Err(e) => {
                println!("seed {seed}: no estimate: {e}");
                continue;
            }
        };
        let rows = &run.run.rows;
        let (Some(first), Some(last)) = (rows.first(), rows.last()) else {
            continue;
        };
        let position = &truth.position_mm;
        let (mut moving, mut standing) = (0.0, [0.0; 6]);
        let mut since_stop = 0usize;
        for (i, pair) in rows.windows(2).enumerate() {
            let j = run.run.first_sample + i + 1;
            if j >= position.len() {
                break;
            }
            let dk2 = pair[1].state[idx::K2] - pair[0].state[idx::K2];
            if position[j] == position[j - 1] {
                since_stop += 1;
                let bin = edges.iter().rposition(|&e| since_stop > e).unwrap_or(0);
                standing[bin.min(5)] += dk2;
            } else {
                since_stop = 0;
                moving += dk2;
            }
        }
        println!(
            "seed {seed}: k2 {:.5} -> {:.5} (truth {:.5}); moving {:+.5}, standing {}",
            first.state[idx::K2],
            last.state[idx::K2],
            law.k2_per_mm,
            moving,
            standing
                .iter()
                .map(|d| format!("{d:+.5}"))
                .collect::<Vec<_>>()
                .join(" ")
        );
    }
    Ok(())
}
