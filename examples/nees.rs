//! The EKF's normalised estimation error squared (NEES) of its constants [M, k2, d2] over many
//! simulated runs: e^T P^-1 e at the end of each run over the constants the filter estimates
//! (a held one, with no variance, is left out). Summed over the runs it is chi-square with as
//! many degrees of freedom as free constants for a consistent filter; it is printed per three
//! free constants (a run's mean when all three are free) with that chi-square's 95 % band.
//!
//! Run: `cargo run --release --example nees [seeds] [m d0 d1 d2] [sines|steps|ramp-hold] [speed]`.
//! The environment variables `Q_D`, `Q_XDD` and `Q_SIGMA` override the process noise of those
//! states (tuning experiments), `FORCE_RATE_S` the zero-phase force rate's window (s), and
//! `TWINS` the number of twins (0: the filter's raw constants).
//! `NEES_DEBUG` prints, per seed, the filter's d2 and M with the standard deviation it reports and
//! its own (before it is held to its disagreement with identification), beside identification's,
//! and k2 through the twins (the filter's own value, the twins' bias, scatter and excess scatter).

use camspring::estimate::ekf::{idx, ConstantsError};
use camspring::estimate::sim::{simulate, Dynamics, Profile, SimSettings};
use camspring::model::ExpLaw;
use camspring::{estimate, EstimateOptions, SensorNoise};
use rayon::prelude::*;
use statrs::distribution::{ChiSquared, ContinuousCDF};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    let f = |i: usize, d: f64| a.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let seeds = f(1, 20.0) as u64;
    let dynamics = Dynamics {
        m_n_s2_per_mm: f(2, 0.05),
        d0_n: f(3, 0.0),
        d1_n_s_per_mm: f(4, 0.2),
        d2_n_s3_per_mm3: f(5, -1e-4),
    };
    let profile = match a.get(6).map(String::as_str) {
        Some("steps") => Profile::Steps,
        Some("ramp-hold") => Profile::RampHold,
        _ => Profile::Sines,
    };
    let law = ExpLaw {
        mu_n: 1.1,
        k2_per_mm: 0.24,
        f0_n: 2.0 + 2.5 * dynamics.d0_n,
    };
    let results: Vec<Option<(ConstantsError, bool)>> = (0..seeds)
        .into_par_iter()
        .map(|seed| {
            let settings = SimSettings {
                profile,
                seed,
                speed: f(7, 1.0),
                dynamics,
                ..SimSettings::default()
            };
            let debug = std::env::var_os("NEES_DEBUG").is_some();
            let (log, _) = match simulate(law, 15.0, 500.0, &settings) {
                Ok(made) => made,
                Err(e) => {
                    if debug {
                        eprintln!("seed {seed}: not simulated: {e}");
                    }
                    return None;
                }
            };
            let mut opts = EstimateOptions::new(SensorNoise::default());
            for (name, state) in [
                ("Q_D", camspring::estimate::pipeline::StateName::D),
                ("Q_XDD", camspring::estimate::pipeline::StateName::Xdd),
                ("Q_SIGMA", camspring::estimate::pipeline::StateName::Sigma),
            ] {
                if let Some(v) = std::env::var(name).ok().and_then(|v| v.parse().ok()) {
                    opts.q.push((state, v));
                }
            }
            if let Some(w) = std::env::var("FORCE_RATE_S").ok().and_then(|v| v.parse().ok()) {
                opts.force_rate = camspring::estimate::ekf::ForceRate::ZeroPhase { window_s: w };
            }
            if let Some(n) = std::env::var("TWINS").ok().and_then(|v| v.parse().ok()) {
                opts.twins = n;
            }
            let run = match estimate(&log, &opts, |_, _| {}) {
                Ok(run) => run,
                Err(e) => {
                    if debug {
                        eprintln!("seed {seed}: no estimate: {e}");
                    }
                    return None;
                }
            };
            let z = run.run.last.z;
            let p = run.run.last.p;
            let truth = [
                dynamics.m_n_s2_per_mm,
                law.k2_per_mm,
                dynamics.d2_n_s3_per_mm3,
            ];
            if debug {
                use camspring::estimate::identify::Param;
                let id = run.identification.as_ref()?;
                let own = run.std_before_disagreement;
                eprintln!(
                    "seed {seed}: d2 filter {:.3e} +- {:.2e} (own {:.2e}) id {:.3e} +- {:.2e} truth {:.3e} | M filter {:.4} +- {:.4} (own {:.4}) id {:.4} +- {:.4}",
                    z[idx::D2], p[(idx::D2, idx::D2)].sqrt(), own[idx::D2],
                    id.get(Param::D2).value.unwrap_or(f64::NAN), id.get(Param::D2).std.unwrap_or(f64::NAN),
                    dynamics.d2_n_s3_per_mm3,
                    z[idx::M], p[(idx::M, idx::M)].sqrt(), own[idx::M],
                    id.get(Param::M).value.unwrap_or(f64::NAN), id.get(Param::M).std.unwrap_or(f64::NAN),
                );
            }
            if debug {
                // k2 through the twins: the filter's own value, the twins' bias, scatter and
                // scatter beyond the filter's own, the reported value, and identification's.
                use camspring::estimate::identify::Param;
                let k2 = Param::K2;
                if let (Some(id), Some(t)) = (
                    run.identification.as_ref(),
                    run.twins
                        .as_ref()
                        .and_then(|t| t.states.iter().find(|s| s.state == "k2_per_mm")),
                ) {
                    eprintln!(
                        "seed {seed}: k2 filter {:.5} +- {:.5}, twins' bias {:+.5} scatter {:.5} excess {:.5}, reported {:.5} +- {:.5} | id {:.5} +- {:.5} | truth {:.5}",
                        t.filter,
                        t.filter_std,
                        t.bias,
                        t.scatter,
                        t.excess_scatter,
                        z[idx::K2],
                        p[(idx::K2, idx::K2)].sqrt(),
                        id.get(k2).value.unwrap_or(f64::NAN),
                        id.get(k2).std.unwrap_or(f64::NAN),
                        law.k2_per_mm,
                    );
                }
            }
            let Some(error) = run.run.last.constants_error(truth) else {
                if debug {
                    eprintln!("seed {seed}: the constants' covariance is not positive definite");
                }
                return None;
            };
            Some((error, run.consistency.consistent))
        })
        .collect();
    let ok: Vec<_> = results.iter().flatten().collect();
    let n = ok.len();
    // The NEES summed over the runs has as many degrees of freedom as free constants; it is
    // reported per run on the scale of three (a run with every constant free).
    let dof: usize = ok.iter().map(|r| r.0.free).sum();
    let scale = 3.0 / dof.max(1) as f64;
    let mean = ok.iter().map(|r| r.0.nees).sum::<f64>() * scale;
    let chi = ChiSquared::new(dof.max(1) as f64)?;
    let (lo, hi) = (
        chi.inverse_cdf(0.025) * scale,
        chi.inverse_cdf(0.975) * scale,
    );
    println!(
        "{n} runs ({} consistent, {dof} free constants): mean NEES of [M, k2, d2] per 3 free {mean:.2}, 95 % band {lo:.2} ... {hi:.2}",
        ok.iter().filter(|r| r.1).count()
    );
    for (i, name) in ["M", "k2", "d2"].iter().enumerate() {
        let z: Vec<f64> = ok
            .iter()
            .map(|r| r.0.z[i])
            .filter(|z| z.is_finite())
            .collect();
        let worst = z.iter().map(|z| z.abs()).fold(0.0, f64::max);
        let rms = (z.iter().map(|z| z * z).sum::<f64>() / z.len().max(1) as f64).sqrt();
        let mean = z.iter().sum::<f64>() / z.len().max(1) as f64;
        println!(
            "  {name}: estimated in {} runs (held in the others), mean z {mean:+.2}, RMS z {rms:.2}, worst |z| {worst:.2}",
            z.len()
        );
    }
    Ok(())
}
