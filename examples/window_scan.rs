//! Scans identification over Savitzky-Golay windows on one simulated log (a development aid).
//!
//! Run: `cargo run --release --example window_scan PROFILE SPEED m d0 d1 d2 [seed] [seconds]`.
//! With `NOISEFREE=1` the log has (almost) no noise; with `EKF=1` it runs `estimate` instead
//! and prints the filter's final M, k2 and d2 against the truth (`QX=VALUE` sets Q of xdd).

use camspring::estimate::identify::{identify, identify_with_window, Param, SensorNoise};
use camspring::estimate::sim::{simulate, Dynamics, Profile, SimSettings};
use camspring::model::ExpLaw;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    let f = |i: usize, d: f64| a.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let profile = match a.get(1).map(String::as_str) {
        Some("ramp-hold") => Profile::RampHold,
        Some("steps") => Profile::Steps,
        _ => Profile::Sines,
    };
    let law = ExpLaw {
        mu_n: 1.1,
        k2_per_mm: 0.24,
        f0_n: 2.0 + 2.5 * f(4, 0.0),
    };
    let dynamics = Dynamics {
        m_n_s2_per_mm: f(3, 0.25),
        d0_n: f(4, 0.0),
        d1_n_s_per_mm: f(5, 1.5),
        d2_n_s3_per_mm3: f(6, -0.008),
    };
    let settings = SimSettings {
        profile,
        speed: f(2, 1.0),
        seed: f(7, 0.0) as u64,
        duration_s: f(8, 300.0),
        noise: if std::env::var("NOISEFREE").is_ok() {
            camspring::estimate::sim::Noise {
                force_variance_n2: 1e-14,
                position_variance_mm2: 1e-14,
            }
        } else {
            camspring::estimate::sim::Noise::default()
        },
        dynamics,
        ..SimSettings::default()
    };
    let (log, _) = simulate(law, 15.0, 500.0, &settings)?;
    let truth = [
        dynamics.m_n_s2_per_mm,
        dynamics.d0_n,
        dynamics.d1_n_s_per_mm,
        dynamics.d2_n_s3_per_mm3,
        law.mu_n,
        law.f0_n,
        law.k2_per_mm,
        0.0,
    ];
    let noise = if std::env::var("NOISEFREE").is_ok() {
        SensorNoise::new(1e-14, 1e-14)
    } else {
        SensorNoise::default()
    };
    if std::env::var("EKF").is_ok() {
        let mut opts = camspring::EstimateOptions::new(noise);
        if let Some(q) = std::env::var("QX").ok().and_then(|v| v.parse::<f64>().ok()) {
            opts.q
                .push((camspring::estimate::pipeline::StateName::Xdd, q));
        }
        let run = camspring::estimate(&log, &opts, |_, _| {})?;
        use camspring::estimate::ekf::idx;
        let z = run.run.last.z;
        let sd = run.run.last.std();
        println!(
            "q_xdd {:.3e} nis {:.3}",
            run.settings.q[idx::XDD],
            run.run.nis_mean
        );
        for (i, t) in [
            (idx::M, dynamics.m_n_s2_per_mm),
            (idx::K2, law.k2_per_mm),
            (idx::D2, dynamics.d2_n_s3_per_mm3),
        ] {
            println!(
                "state {i}: {:.5} truth {:.5} err {:+.2}% z {:+.1}",
                z[i],
                t,
                100.0 * (z[i] / t - 1.0),
                (z[i] - t) / sd[i]
            );
        }
        let n = run.run.rows.len();
        for k in (0..n).step_by((n / 10).max(1)) {
            let s = run.run.rows[k].state;
            println!(
                "t {:.0}: M {:.4} k2 {:.4} sigma {:.3} D {:.3}",
                run.run.rows[k].t_s,
                s[idx::M],
                s[idx::K2],
                s[idx::SIGMA],
                s[idx::D]
            );
        }
        return Ok(());
    }
    let mut windows: Vec<Option<f64>> = vec![None];
    windows.extend([0.2, 0.3, 0.4, 0.6, 0.8, 1.2, 1.6, 2.4, 3.2].map(Some));
    for w in windows {
        let id = match w {
            None => identify(&log, &noise),
            Some(w) => identify_with_window(&log, &noise, Some(w)),
        };
        let id = match id {
            Ok(id) => id,
            Err(e) => {
                println!("{w:?}: {e}");
                continue;
            }
        };
        let mut line = format!(
            "{} w {:.2} n {:5} chi2 {:6.2} ",
            if w.is_none() { "AUTO" } else { "    " },
            id.sg_window_s,
            id.dynamic_samples,
            id.reduced_chi2
        );
        for p in Param::ALL {
            let e = id.get(p);
            match (e.value, e.std) {
                (Some(v), Some(s)) => {
                    let t = truth[p.index()];
                    line += &format!(
                        "{}:{:+.2}%/z{:+.1} ",
                        &p.key()[..2],
                        100.0 * (v / t - 1.0),
                        (v - t) / s
                    )
                }
                _ => line += &format!("{}:-- ", &p.key()[..2]),
            }
        }
        if let Some(w) = id.adequacy.whiteness {
            line += &format!("white p {:.1e} ", w.p_value);
        }
        println!("{line}");
    }
    Ok(())
}
