//! The EKF and `validate` against simulated truth: the analytic Jacobian, RK4 against the
//! paper's Euler on noise-free data, the converged bounds on noisy data, divergence
//! detection, and pass/fail verdicts.

mod common;

use camspring::app::estimate_log;
use camspring::estimate::ekf::{derivative, idx, jacobian, Discretization, ForceRate, State};
use camspring::estimate::identify::SensorNoise;
use camspring::estimate::log::CalibrationLog;
use camspring::estimate::pipeline::{EstimateInit, EstimateOptions, EstimateRun};
use camspring::estimate::sim::{simulate, Dynamics, Noise, Profile, SimSettings, Truth};
use camspring::model::ExpLaw;
use camspring::verdict::validate::validate;

/// The simulator's default transmission (of the order of the paper's Table II), so that the
/// EKF has something to estimate (the light one's m = 2e-3 is below the paper's noise).
fn heavy() -> Dynamics {
    Dynamics::default()
}

fn sim(
    law: &ExpLaw,
    profile: Profile,
    seconds: f64,
    seed: u64,
    noise: Noise,
) -> (CalibrationLog, Truth) {
    let settings = SimSettings {
        speed: 1.0,
        profile,
        duration_s: seconds,
        rate_hz: 100.0,
        seed,
        dynamics: heavy(),
        noise,
    };
    simulate(law, 20.0, 200.0, &settings).unwrap()
}

fn options(noise: Noise, discretization: Discretization) -> EstimateOptions {
    EstimateOptions {
        init: EstimateInit::Identify,
        discretization,
        force_rate: ForceRate::ZERO_PHASE,
        noise: SensorNoise::new(noise.force_variance_n2, noise.position_variance_mm2).into(),
        window_s: None,
        outlier_sigmas: None,
        q: Vec::new(),
        p0_std: Vec::new(),
        r_position_mm2: None,
        position_offset: camspring::estimate::pipeline::PositionOffset::None,
        force_delay: camspring::estimate::retime::ForceDelay::None,
        identify_span_s: camspring::estimate::pipeline::DEFAULT_IDENTIFY_SPAN_S,
        twins: camspring::estimate::pipeline::DEFAULT_TWINS,
    }
}

/// Relative RMS error of state k over the converged second half.
fn rms_error(est: &EstimateRun, k: usize, truth: &[f64]) -> f64 {
    let run = &est.run;
    let n = run.rows.len();
    let (mut num, mut den) = (0.0, 0.0);
    for j in n / 2..n {
        let t = truth[run.first_sample + j];
        num += (run.rows[j].state[k] - t).powi(2);
        den += t * t;
    }
    (num / den).sqrt()
}

#[test]
fn jacobian_matches_finite_differences() {
    let states = [
        State::from([5.0, 3.0, -2.0, 4.0, 0.2, 0.05, 0.26, -1e-4]),
        State::from([15.0, -8.0, 12.0, 20.0, 0.15, 0.002, 0.3, 2e-4]),
        State::from([1.0, 0.1, 0.0, 0.5, 0.02, 0.4, 0.1, -0.1]),
    ];
    for z in states {
        for u in [-30.0, 0.0, 55.0] {
            let a = jacobian(&z, u);
            for j in 0..8 {
                let h = 1e-6 * z[j].abs().max(1.0);
                let (mut zp, mut zm) = (z, z);
                zp[j] += h;
                zm[j] -= h;
                let col = (derivative(&zp, u) - derivative(&zm, u)) / (2.0 * h);
                for i in 0..8 {
                    let scale = col[i].abs().max(a[(i, j)].abs()).max(1e-9);
                    assert!(
                        (a[(i, j)] - col[i]).abs() < 1e-5 * scale + 1e-7,
                        "dF{i}/dZ{j} at {z:?}, u {u}: {} vs {}",
                        a[(i, j)],
                        col[i]
                    );
                }
            }
        }
    }
}

#[test]
fn rk4_recovers_noise_free_parameters_and_euler_shows_its_bias() {
    let law = common::paper_law();
    // Nearly noise-free: 1 um and 1 mN (the filter needs some measurement noise).
    let quiet = Noise {
        force_variance_n2: 1e-6,
        position_variance_mm2: 1e-6,
    };
    let (log, truth) = sim(&law, Profile::Sines, 300.0, 0, quiet);
    let d = heavy();
    let rk4 = estimate_log(&log, &options(quiet, Discretization::Rk4), false).unwrap();
    let z = rk4.run.last.z;
    assert!(
        (z[idx::K2] / law.k2_per_mm - 1.0).abs() < 2e-3,
        "k2 {}",
        z[idx::K2]
    );
    assert!(
        (z[idx::M] / d.m_n_s2_per_mm - 1.0).abs() < 2e-3,
        "M {}",
        z[idx::M]
    );
    assert!(
        (z[idx::D2] / d.d2_n_s3_per_mm3 - 1.0).abs() < 2e-2,
        "d2 {}",
        z[idx::D2]
    );
    assert!(rms_error(&rk4, idx::SIGMA, &truth.sigma_n_per_mm) < 2e-3);
    assert!(rms_error(&rk4, idx::D, &truth.d_n_s_per_mm) < 2e-3);

    // docs/THEORY.md: Euler lags half a sample, so D comes out near D - (T/2) sigma, M is off
    // and d2 is not identified.
    // Its half-sample lag leaves innovations far outside their covariance, which the
    // divergence check would stop: widen it to see where Euler settles.
    let euler_options = EstimateOptions {
        outlier_sigmas: Some(1e6),
        ..options(quiet, Discretization::Euler)
    };
    let euler = estimate_log(&log, &euler_options, false).unwrap();
    let z = euler.run.last.z;
    let m_error = (z[idx::M] / d.m_n_s2_per_mm - 1.0).abs();
    let d_error = rms_error(&euler, idx::D, &truth.d_n_s_per_mm);
    let d2_error = (z[idx::D2] / d.d2_n_s3_per_mm3 - 1.0).abs();
    eprintln!(
        "noise-free: RK4 k2 {:.4} %, M {:.4} %, d2 {:.3} %; Euler M {:.2} %, D RMS {:.2} %, d2 {:.1} %",
        100.0 * (rk4.run.last.z[idx::K2] / law.k2_per_mm - 1.0),
        100.0 * (rk4.run.last.z[idx::M] / d.m_n_s2_per_mm - 1.0),
        100.0 * (rk4.run.last.z[idx::D2] / d.d2_n_s3_per_mm3 - 1.0),
        100.0 * m_error,
        100.0 * d_error,
        100.0 * d2_error
    );
    assert!(m_error > 0.02, "Euler M error {m_error}");
    assert!(d_error > 0.05, "Euler D error {d_error}");
    assert!(d2_error > 0.3, "Euler d2 error {d2_error}");
}

#[test]
fn converged_estimates_meet_the_bounds_on_noisy_logs() {
    let law = common::paper_law();
    let d = heavy();
    for (profile, seconds) in [(Profile::Sines, 600.0), (Profile::Steps, 600.0)] {
        for seed in 0..3 {
            let (log, truth) = sim(&law, profile, seconds, seed, Noise::default());
            let est =
                estimate_log(&log, &options(Noise::default(), Discretization::Rk4), false).unwrap();
            let z = est.run.last.z;
            let k2 = (z[idx::K2] / law.k2_per_mm - 1.0).abs();
            let m = (z[idx::M] / d.m_n_s2_per_mm - 1.0).abs();
            let sigma = rms_error(&est, idx::SIGMA, &truth.sigma_n_per_mm);
            let damping = rms_error(&est, idx::D, &truth.d_n_s_per_mm);
            let d2 = (z[idx::D2] / d.d2_n_s3_per_mm3 - 1.0).abs();
            eprintln!(
                "{profile:?} seed {seed}: k2 {:.3} %, M {:.3} %, sigma RMS {:.3} %, D RMS {:.3} %, d2 {:.1} %",
                100.0 * k2, 100.0 * m, 100.0 * sigma, 100.0 * damping, 100.0 * d2
            );
            assert!(k2 < 0.005, "{profile:?} seed {seed}: k2 off by {k2}");
            assert!(m < 0.01, "{profile:?} seed {seed}: M off by {m}");
            assert!(sigma < 0.01, "{profile:?} seed {seed}: sigma RMS {sigma}");
            assert!(damping < 0.02, "{profile:?} seed {seed}: D RMS {damping}");
            // d2 is the weakest-observed state: within 40 % here (see docs/CALIBRATION.md).
            assert!(d2 < 0.4, "{profile:?} seed {seed}: d2 off by {d2}");
            assert_eq!(est.run.outliers, 0);
        }
    }
}

/// Simulates a 300 s sines log of `built`, estimates it and validates it against `designed`
/// at 3 %.
fn validate_built_against(
    built: &ExpLaw,
    designed: &ExpLaw,
) -> camspring::verdict::validate::Validation {
    let (log, _) = sim(built, Profile::Sines, 300.0, 4, Noise::default());
    let est = estimate_log(&log, &options(Noise::default(), Discretization::Rk4), false).unwrap();
    validate(
        designed,
        est.identification.as_ref().unwrap(),
        &est,
        &log.position_mm,
        0.03,
        None,
    )
}

#[test]
fn validate_passes_the_designed_spring_and_fails_a_different_one() {
    let law = common::paper_law();
    let v = validate_built_against(&law, &law);
    assert!(v.pass, "{v:?}");

    // A spring whose exponent is 5 % higher than designed.
    let stiff = ExpLaw {
        k2_per_mm: law.k2_per_mm * 1.05,
        ..law
    };
    let v = validate_built_against(&stiff, &law);
    assert!(!v.pass);
    let failed: Vec<&str> = v
        .criteria
        .iter()
        .filter(|c| !c.pass)
        .map(|c| c.name)
        .collect();
    assert!(failed.contains(&"k2"), "{failed:?}");
    assert!(failed.contains(&"stiffness_force_line"), "{failed:?}");
    let k2 = v.criteria.iter().find(|c| c.name == "k2").unwrap();
    assert!(
        (k2.deviation_percent - 5.0).abs() < 0.5,
        "{}",
        k2.deviation_percent
    );
}

#[test]
fn divergence_stops_with_the_sample_index() {
    let law = common::paper_law();
    let (mut log, _) = sim(&law, Profile::Sines, 120.0, 5, Noise::default());
    // The encoder slips by 40 mm at sample 6000 and stays there.
    for x in log.position_mm[6000..].iter_mut() {
        *x += 40.0;
    }
    let opts = EstimateOptions {
        init: EstimateInit::Law {
            law: common::paper_law(),
            xmax_mm: 20.0,
        },
        ..options(Noise::default(), Discretization::Rk4)
    };
    let err = estimate_log(&log, &opts, false).unwrap_err().to_string();
    assert!(err.contains("diverged at sample 60"), "{err}");
}

/// The z-scores of the final [M, k2, d2] of one run, its NEES over the constants the run
/// estimates, and their number (`Ekf::constants_error`).
fn constants_nees(est: &EstimateRun, truth: [f64; 3]) -> ([f64; 3], f64, usize) {
    let c = est.run.last.constants_error(truth).unwrap();
    (c.z, c.nees, c.free)
}

/// Asserts that the NEES summed over the runs lies in the 95 % band of chi-square with the
/// runs' degrees of freedom, as it does when the covariance is right.
fn assert_nees_in_band(runs: &[([f64; 3], f64, usize)], what: &str) {
    use statrs::distribution::{ChiSquared, ContinuousCDF};
    let total: f64 = runs.iter().map(|r| r.1).sum();
    let dof: usize = runs.iter().map(|r| r.2).sum();
    let chi = ChiSquared::new(dof as f64).unwrap();
    let (lo, hi) = (chi.inverse_cdf(0.025), chi.inverse_cdf(0.975));
    eprintln!("{what}: NEES {total:.1} over {dof} degrees of freedom, band {lo:.1} ... {hi:.1}");
    assert!(
        (lo..=hi).contains(&total),
        "{what}: NEES {total} over {dof} degrees of freedom, band {lo} ... {hi}"
    );
}

/// The filter's reported standard deviations of M and k2 match its errors over seeds (the RMS
/// of the z-scores near 1); d2's do not yet (docs/CALIBRATION.md).
#[test]
fn reported_standard_deviations_of_m_k2_and_d2_match_the_errors_over_seeds() {
    use rayon::prelude::*;
    let law = common::paper_law();
    let d = heavy();
    let runs: Vec<([f64; 3], f64, usize)> = (0..12u64)
        .into_par_iter()
        .map(|seed| {
            let (log, _) = sim(&law, Profile::Sines, 300.0, 100 + seed, Noise::default());
            let est =
                estimate_log(&log, &options(Noise::default(), Discretization::Rk4), false).unwrap();
            assert!(est.consistency.consistent, "{:?}", est.consistency);
            constants_nees(&est, [d.m_n_s2_per_mm, law.k2_per_mm, d.d2_n_s3_per_mm3])
        })
        .collect();
    for (k, name) in ["M", "k2", "d2"].iter().enumerate() {
        let z: Vec<f64> = runs.iter().map(|r| r.0[k]).collect();
        let rms = (z.iter().map(|z| z * z).sum::<f64>() / z.len() as f64).sqrt();
        let worst = z.iter().map(|z| z.abs()).fold(0.0, f64::max);
        eprintln!("{name}: RMS z {rms:.2}, worst {worst:.2}");
        // For 12 honest z-scores the RMS lies in 0.6 ... 1.4 with about 95 % probability.
        assert!((0.5..1.6).contains(&rms), "{name}: RMS z {rms}");
        assert!(worst < 3.5, "{name}: worst |z| {worst}");
    }
    // (Before d2's standard deviation was held to identification's, the mean NEES was 8.6 on
    // these runs, d2's errors 2.6 times its claimed standard deviation.)
    assert_nees_in_band(&runs, "sines");
}

/// On slow ramp-hold runs the filter's M leans high beyond its own standard deviation, where
/// identification's M does not: with M held only to half the squared disagreement between the
/// two, the NEES of 12 runs of the default transmission was above its band (40.7 over its 25
/// free constants against a top of 40.6). Holding it to all of the disagreement that identification's own
/// variance does not explain brings it inside.
#[test]
fn the_nees_of_slow_ramp_hold_runs_lies_in_its_band() {
    use rayon::prelude::*;
    let law = ExpLaw {
        mu_n: 1.1,
        k2_per_mm: 0.24,
        f0_n: 2.0,
    };
    let d = Dynamics::default();
    let runs: Vec<([f64; 3], f64, usize)> = (0..12u64)
        .into_par_iter()
        .map(|seed| {
            let settings = SimSettings {
                profile: Profile::RampHold,
                seed,
                dynamics: d,
                ..SimSettings::default()
            };
            let (log, _) = simulate(law, 15.0, 500.0, &settings).unwrap();
            let est =
                estimate_log(&log, &options(Noise::default(), Discretization::Rk4), false).unwrap();
            constants_nees(&est, [d.m_n_s2_per_mm, law.k2_per_mm, d.d2_n_s3_per_mm3])
        })
        .collect();
    assert_nees_in_band(&runs, "ramp-hold");
}

/// A heavy transmission (m 0.25, d1 1.5, d2 -0.008) whose Coulomb friction, 0.5 N, is
/// within four standard deviations of the force the frictionless model leaves: its sign at
/// starts and stops is read wrong at times, by identification and the filter alike, and the
/// filter's M carried identification's error while it claimed up to four times its precision
/// (mean NEES 5.64 per three constants over 24 seeds, band 2.10 ... 4.06; M at RMS z 1.87).
/// The run says the sign is not resolved and claims M no more precisely than
/// identification; the NEES of 12 ramp-hold runs is inside its band. Table I's 3.82 N is
/// resolved, and the run says nothing.
#[test]
fn m_is_claimed_no_more_precisely_than_identification_where_the_frictions_sign_is_not_resolved() {
    use camspring::estimate::identify::Param;
    use rayon::prelude::*;
    let run = |dynamics: Dynamics, seed: u64| {
        let law = ExpLaw {
            mu_n: 1.1,
            k2_per_mm: 0.24,
            f0_n: 2.0 + 2.5 * dynamics.d0_n,
        };
        let settings = SimSettings {
            profile: Profile::RampHold,
            seed,
            dynamics,
            ..SimSettings::default()
        };
        let (log, _) = simulate(law, 15.0, 500.0, &settings).unwrap();
        let est =
            estimate_log(&log, &options(Noise::default(), Discretization::Rk4), false).unwrap();
        (est, law)
    };
    let heavy = Dynamics {
        m_n_s2_per_mm: 0.25,
        d0_n: 0.5,
        d1_n_s_per_mm: 1.5,
        d2_n_s3_per_mm3: -0.008,
    };
    let runs: Vec<([f64; 3], f64, usize)> = (0..12u64)
        .into_par_iter()
        .map(|seed| {
            let (est, law) = run(heavy, seed);
            let u = est
                .unresolved_friction_sign
                .expect("d0 0.5 N against 0.13 N of force noise is not resolved");
            assert!(
                (u.frictionless_force_std_n..4.0 * u.frictionless_force_std_n)
                    .contains(&u.d0_n.abs()),
                "{u:?}"
            );
            let id = est.identification.as_ref().unwrap();
            let s_id = id.get(Param::M).std.unwrap();
            let s_m = est.run.last.p[(idx::M, idx::M)].sqrt();
            assert!(
                s_m >= s_id * (1.0 - 1e-9),
                "seed {seed}: M +- {s_m} against {s_id}"
            );
            constants_nees(
                &est,
                [heavy.m_n_s2_per_mm, law.k2_per_mm, heavy.d2_n_s3_per_mm3],
            )
        })
        .collect();
    assert_nees_in_band(&runs, "heavy ramp-hold, d0 0.5 N");
    let table_i = Dynamics {
        m_n_s2_per_mm: 0.39,
        d0_n: 3.82,
        d1_n_s_per_mm: 1.84,
        d2_n_s3_per_mm3: -0.0108,
    };
    let (est, _) = run(table_i, 0);
    assert_eq!(est.unresolved_friction_sign, None);
}

/// Where the friction's sign is not resolved, the filter's friction stage reads the rod as
/// sliding for a while after each stop, and its k2 leans high: on the heavy transmission's
/// steps (d0 0.5 N, half speed) +0.6 % on average, beyond the 0.5 % target, while
/// identification's k2 is unbiased with honest deviations. The reported k2 is then
/// identification's, with its standard deviation, and the filter's own is kept beside it.
/// Judged against the simulator's truth: the reported k2's mean error over the seeds is within
/// 0.25 %, each within 3 of its deviations, where the filter's own leans high.
#[test]
fn k2_is_identifications_where_the_frictions_sign_is_not_resolved() {
    use camspring::estimate::identify::Param;
    use rayon::prelude::*;
    let dynamics = Dynamics {
        m_n_s2_per_mm: 0.25,
        d0_n: 0.5,
        d1_n_s_per_mm: 1.5,
        d2_n_s3_per_mm3: -0.008,
    };
    let law = ExpLaw {
        mu_n: 1.1,
        k2_per_mm: 0.24,
        f0_n: 2.0 + 2.5 * dynamics.d0_n,
    };
    // (reported k2's relative error, its z, the filter's own relative error)
    let runs: Vec<(f64, f64, f64)> = (0..12u64)
        .into_par_iter()
        .filter_map(|seed| {
            let settings = SimSettings {
                profile: Profile::Steps,
                seed,
                speed: 0.5,
                dynamics,
                ..SimSettings::default()
            };
            // Some seeds' steps would need the wire to push; the simulator refuses them.
            let (log, _) = simulate(law, 15.0, 500.0, &settings).ok()?;
            let est =
                estimate_log(&log, &options(Noise::default(), Discretization::Rk4), false).unwrap();
            assert!(est.unresolved_friction_sign.is_some(), "seed {seed}");
            let own = est.filter_k2.expect("the filter's own k2 is kept");
            let id = est.identification.as_ref().unwrap().get(Param::K2);
            let (k2, sd) = (est.run.last.z[idx::K2], est.run.last.std()[idx::K2]);
            assert_eq!(Some(k2), id.value, "seed {seed}");
            assert!(
                (sd / id.std.unwrap() - 1.0).abs() < 1e-9,
                "seed {seed}: {sd}"
            );
            let truth = law.k2_per_mm;
            Some((
                k2 / truth - 1.0,
                (k2 - truth) / sd,
                own.k2_per_mm / truth - 1.0,
            ))
        })
        .collect();
    assert!(runs.len() >= 8, "{} runs simulated", runs.len());
    let n = runs.len() as f64;
    let mean = runs.iter().map(|r| r.0).sum::<f64>() / n;
    let own_mean = runs.iter().map(|r| r.2).sum::<f64>() / n;
    eprintln!(
        "heavy steps, {} runs: reported k2 mean error {:+.3} %, the filter's own {:+.3} %",
        runs.len(),
        100.0 * mean,
        100.0 * own_mean
    );
    assert!(mean.abs() < 0.0025, "mean error {mean}");
    assert!(
        own_mean > mean.abs(),
        "the filter's own k2 no longer leans high: {own_mean}"
    );
    for r in &runs {
        assert!(r.1.abs() < 3.0, "{r:?}");
    }
}

/// Rigs log from 100 Hz to kilohertz rates. Identification averages fast logs in blocks down
/// to about 100 Hz, where the noise is smaller: its shortest windows then carry almost no
/// signal in the inertia's information (an 800 Hz log once had m, F0 and mu 3 sigma off at
/// 0.15 s, and the window choice kept it, which left the filter inconsistent). At every rate,
/// identification and the filter must meet their bounds against the simulated truth.
#[test]
fn identification_and_the_filter_hold_from_100_hz_to_2_khz() {
    use camspring::estimate::identify::Param;
    use camspring::estimate::pipeline::estimate;
    let law = common::paper_law();
    let noise = Noise::default();
    for rate_hz in [100.0, 250.0, 800.0, 1000.0, 2000.0] {
        let settings = SimSettings {
            speed: 1.0,
            profile: Profile::Sines,
            duration_s: 300.0,
            rate_hz,
            seed: 1,
            dynamics: heavy(),
            noise,
        };
        let (log, _) = simulate(law, 20.0, 200.0, &settings).unwrap();
        let est = estimate(&log, &options(noise, Discretization::Rk4), |_, _| {}).unwrap();
        let id = est.identification.as_ref().unwrap();
        let d = heavy();
        for (p, truth) in [
            (Param::M, d.m_n_s2_per_mm),
            (Param::D1, d.d1_n_s_per_mm),
            (Param::Mu, law.mu_n),
            (Param::F0, law.f0_n),
            (Param::K2, law.k2_per_mm),
        ] {
            let e = id.get(p);
            let (v, s) = (e.value.unwrap(), e.std.unwrap());
            assert!(
                (v - truth).abs() < 3.0 * s,
                "{rate_hz} Hz: identified {} = {v} +- {s}, truth {truth}",
                p.key()
            );
        }
        assert!(
            est.consistency.consistent,
            "{rate_hz} Hz: {:?}",
            est.consistency.reasons
        );
        let z = est.run.last.z;
        let sd = est.run.last.std();
        for (k, truth, bound) in [
            (idx::K2, law.k2_per_mm, 0.005),
            (idx::M, d.m_n_s2_per_mm, 0.02),
        ] {
            let err = z[k] - truth;
            assert!(
                err.abs() < 3.0 * sd[k] && err.abs() < bound * truth,
                "{rate_hz} Hz: filter state {k} = {} +- {}, truth {truth}",
                z[k],
                sd[k]
            );
        }
    }
}

/// A short log: the filter warns that it determines k2 or M less precisely than its target
/// (k2 within 0.5 %, M within 2 %, at 2 sigma), its errors stay within 3 of its standard
/// deviations, and a log as many times longer as the warning says brings the filter's own
/// standard deviations to the target.
#[test]
fn estimate_warns_when_the_log_is_too_short_for_its_target_and_says_how_much_longer() {
    use camspring::estimate::pipeline::estimate;
    let law = common::paper_law();
    let d = heavy();
    let run = |seconds: f64| {
        let (log, _) = sim(&law, Profile::Steps, seconds, 5, Noise::default());
        estimate(
            &log,
            &options(Noise::default(), Discretization::Rk4),
            |_, _| {},
        )
        .unwrap()
    };
    let short = run(30.0);
    let warned = short.imprecise();
    assert!(!warned.is_empty(), "30 s of steps meet the target?");
    let (z, sd) = (short.run.last.z, short.run.last.std());
    for (k, truth) in [(idx::K2, law.k2_per_mm), (idx::M, d.m_n_s2_per_mm)] {
        assert!(
            (z[k] - truth).abs() < 3.0 * sd[k],
            "state {k}: {} +- {}",
            z[k],
            sd[k]
        );
    }
    let longest = warned
        .iter()
        .filter_map(|w| w.log_length_factor)
        .fold(1.0, f64::max);
    assert!(longest > 1.0, "{warned:?}");
    assert!(longest < 40.0, "{warned:?}");
    let long = run(30.0 * longest * 1.5);
    // The filter's own standard deviations of the constants the warning promised a length for
    // reach the target. One may still be held above it by the filter's disagreement with
    // identification, which a longer log shrinks only if it is random, or (M) by
    // identification's own deviation where that is mostly the allowance for its
    // differentiating filter's bias; the warning then says so, and promises no length. (Seed
    // 5's 148 s log: identification's m 0.0504 +- 0.0036, nearly all of it that allowance,
    // held the filter's M at 1.8 %, where the 30 s log had promised the target at 1.9 times
    // its length.) A constant the short log promised nothing for (held there) may be warned
    // again: seed 5's M, held on 30 s by identification's bias, is at identification's
    // deviation over 4 on 126 s, mostly noise there, and the warning asks for 2.2 times that.
    let promised: Vec<&str> = warned
        .iter()
        .filter(|w| w.log_length_factor.is_some())
        .map(|w| w.state)
        .collect();
    let left = long.imprecise();
    assert!(
        left.iter()
            .filter(|w| promised.contains(&w.state))
            .all(|w| w.log_length_factor.is_none()
                && (w.relative_disagreement.is_some() || w.relative_identification_bias.is_some())),
        "{left:?} (promised: {promised:?})"
    );
}

/// On a light transmission's ramp-hold runs the force noise dominates the motion's forces, and
/// the filter's raw k2 comes out low by several of its standard deviations (the errors in the
/// force rate, which it takes as a known input, attenuate the stiffness's change with
/// deflection). The twins of each log measure that bias, and the corrected k2 lies within
/// its standard deviation's reach of the truth.
#[test]
fn the_twins_take_the_filters_k2_bias_out_on_a_light_transmission() {
    use rayon::prelude::*;
    let law = ExpLaw {
        mu_n: 1.1,
        k2_per_mm: 0.24,
        f0_n: 2.0,
    };
    let dynamics = Dynamics {
        m_n_s2_per_mm: 0.002,
        d0_n: 0.0,
        d1_n_s_per_mm: 0.05,
        d2_n_s3_per_mm3: 0.0,
    };
    let z: Vec<(f64, f64, usize)> = (0..4u64)
        .into_par_iter()
        .map(|seed| {
            let settings = SimSettings {
                profile: Profile::RampHold,
                duration_s: 300.0,
                seed,
                dynamics,
                ..SimSettings::default()
            };
            let (log, _) = simulate(law, 15.0, 500.0, &settings).unwrap();
            let mut opts = EstimateOptions::new(SensorNoise::default());
            opts.twins = 0;
            let raw = camspring::estimate(&log, &opts, |_, _| {}).unwrap();
            opts.twins = 6;
            let twins = camspring::estimate(&log, &opts, |_, _| {}).unwrap();
            // Against the filter's own standard deviation, before it is held to its
            // disagreement with identification (which would hide the raw bias).
            let zk = |e: &EstimateRun| {
                (e.run.last.z[idx::K2] - law.k2_per_mm) / e.std_before_disagreement[idx::K2]
            };
            let bias = twins.twins.as_ref().expect("twins ran");
            assert_eq!(bias.diverged, 0);
            (zk(&raw), zk(&twins), bias.states.len())
        })
        .collect();
    eprintln!("z of k2 (raw, with twins, constants corrected): {z:?}");
    let mean = |f: fn(&(f64, f64, usize)) -> f64| z.iter().map(f).sum::<f64>() / z.len() as f64;
    // Raw: biased low (mean z about -4 over these seeds).
    assert!(mean(|r| r.0) < -2.5, "{z:?}");
    // Corrected: every |z| below 3 and no bias left beyond the mean's own spread.
    for r in &z {
        assert_eq!(r.2, 1, "only k2 is corrected");
        assert!(r.1.abs() < 3.0, "{z:?}");
    }
    assert!(mean(|r| r.1).abs() < 1.5, "{z:?}");
}

/// An encoder zeroed at the other end of the stroke logs every position below zero (here
/// -20 to 0 mm): the same run, with mu and F0 re-expressed for the shifted zero. The filter's
/// stiffness ceiling (its inertia floor and the friction stage's noise) is taken where the
/// stiffness is greatest over the logged positions. Taken at the largest |x| instead, it was
/// the law's stiffness 20 mm beyond the stroke: the inertia floor rose above the rod's inertia
/// and the filter diverged. Both logs now give the same k2 and M within a tenth of their
/// standard deviations, each within three of them of the truth.
#[test]
fn a_log_whose_positions_lie_below_zero_is_estimated_as_the_same_log_above_it() {
    let law = common::paper_law();
    let d = heavy();
    let (log, _) = sim(&law, Profile::Sines, 300.0, 0, Noise::default());
    let mut below = log.clone();
    below.shift_position(20.0);
    let (lo, hi) = below.position_range_mm();
    assert!(
        hi <= 0.0 && lo < -15.0,
        "the shifted log spans {lo} .. {hi} mm"
    );
    let opts = options(Noise::default(), Discretization::Rk4);
    let (z, sd) = estimate_log(&log, &opts, false)
        .unwrap()
        .reported_constants();
    let (zb, sdb) = estimate_log(&below, &opts, false)
        .unwrap()
        .reported_constants();
    for (k, truth) in [(idx::K2, law.k2_per_mm), (idx::M, d.m_n_s2_per_mm)] {
        eprintln!(
            "state {k}: above {:.6} +- {:.2e}, below {:.6} +- {:.2e}, truth {truth}",
            z[k], sd[k], zb[k], sdb[k]
        );
        assert!((z[k] - truth).abs() < 3.0 * sd[k], "state {k} above zero");
        assert!((zb[k] - truth).abs() < 3.0 * sdb[k], "state {k} below zero");
        assert!(
            (zb[k] - z[k]).abs() < 0.1 * sd[k],
            "state {k}: {} below zero against {} above",
            zb[k],
            z[k]
        );
    }
}
