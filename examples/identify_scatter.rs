//! Measures offline identification over many simulated logs: for each profile, the mean and
//! spread of the z-scores (estimate - truth) / reported std of every parameter, and the worst
//! relative error of k2 and mu. A spread near 1 means the reported std matches the scatter.
//!
//! Run: `cargo run --release --example identify_scatter [seeds] [seconds] [m d1 d2]`
//! (default 20, 300 and `Dynamics::light()`).

use camspring::estimate::identify::{identify, Param, SensorNoise, PARAMS};
use camspring::estimate::sim::{simulate, Dynamics, Noise, Profile, SimSettings};
use camspring::{spec::DEFAULT_SPEC_TOML, Spec};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let seeds: u64 = args.get(1).map_or(Ok(20), |s| s.parse())?;
    let seconds: f64 = args.get(2).map_or(Ok(300.0), |s| s.parse())?;
    let spec = Spec::from_toml(DEFAULT_SPEC_TOML)?;
    let law = *camspring::design::law_of(&spec)?
        .exponential()
        .ok_or("an exponential law")?;
    let xmax = spec.law.xmax_mm();
    println!(
        "{seeds} seeds x {seconds} s at 100 Hz, paper noise (force 0.017 N^2, position 0.01 mm^2)"
    );
    println!(
        "| profile | d0 (N) | parameter | mean z | spread of z | max abs z | not identifiable |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    for (profile, d0) in [
        (Profile::Sines, 0.0),
        (Profile::Sines, 0.3),
        (Profile::Steps, 0.0),
        (Profile::RampHold, 0.2),
    ] {
        let base = Dynamics::light();
        let arg = |i: usize, d: f64| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
        let dynamics = Dynamics {
            m_n_s2_per_mm: arg(3, base.m_n_s2_per_mm),
            d0_n: d0,
            d1_n_s_per_mm: arg(4, base.d1_n_s_per_mm),
            d2_n_s3_per_mm3: arg(5, base.d2_n_s3_per_mm3),
        };
        let truth = [
            dynamics.m_n_s2_per_mm,
            d0,
            dynamics.d1_n_s_per_mm,
            dynamics.d2_n_s3_per_mm3,
            law.mu_n,
            law.f0_n,
            law.k2_per_mm,
            0.0,
        ];
        let mut z: Vec<Vec<f64>> = vec![Vec::new(); 8];
        let mut missing = [0usize; 8];
        let (mut worst_k2, mut worst_mu) = (0.0f64, 0.0f64);
        for seed in 0..seeds {
            let settings = SimSettings {
                speed: 1.0,
                profile,
                duration_s: seconds,
                rate_hz: 100.0,
                seed,
                dynamics,
                noise: Noise::default(),
            };
            let (log, _) = simulate(law, xmax, law.force_n(xmax), &settings)?;
            let id = identify(&log, &SensorNoise::default())?;
            for (p, e) in id.parameters.iter() {
                let k = p.index();
                match e.value.zip(e.std) {
                    Some((v, s)) => z[k].push((v - truth[k]) / s),
                    None => missing[k] += 1,
                }
            }
            let rel = |p: Param| {
                id.parameters
                    .value(p)
                    .map_or(f64::NAN, |v| v / truth[p.index()] - 1.0)
            };
            worst_k2 = worst_k2.max(rel(Param::K2).abs());
            worst_mu = worst_mu.max(rel(Param::Mu).abs());
        }
        for (k, zk) in z.iter().enumerate() {
            let n = zk.len() as f64;
            let (mean, spread, max) = if zk.len() > 1 {
                let mean = zk.iter().sum::<f64>() / n;
                let sd = (zk.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
                (
                    format!("{mean:+.2}"),
                    format!("{sd:.2}"),
                    format!("{:.2}", zk.iter().fold(0.0f64, |a, v| a.max(v.abs()))),
                )
            } else {
                ("-".into(), "-".into(), "-".into())
            };
            println!(
                "| {profile:?} | {d0} | {} | {mean} | {spread} | {max} | {}/{seeds} |",
                PARAMS[k], missing[k]
            );
        }
        println!(
            "| {profile:?} | {d0} | worst k2 error {:.2} %, worst mu error {:.2} % | | | | |",
            100.0 * worst_k2,
            100.0 * worst_mu
        );
    }
    Ok(())
}
