//! Criterion benchmarks of the calibration-log path: CSV parsing (MB/s) and offline
//! identification of a 1-hour, 100 Hz log. Run with `cargo bench --bench calibration`;
//! results go in docs/BENCHMARKS.md.

use std::hint::black_box;

use camspring::design::law_of;
use camspring::estimate::identify::{identify, SensorNoise};
use camspring::estimate::log::{read_log, write_log, ColumnMap};
use camspring::estimate::noise::noise_model;
use camspring::estimate::sim::{simulate, Dynamics, Noise, Profile, SimSettings};
use camspring::{spec::DEFAULT_SPEC_TOML, Spec};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};

fn hour_log(profile: Profile) -> camspring::estimate::log::CalibrationLog {
    let spec = Spec::from_toml(DEFAULT_SPEC_TOML).unwrap();
    let law = law_of(&spec).unwrap().law;
    let settings = SimSettings {
        speed: 1.0,
        profile,
        duration_s: 3600.0,
        rate_hz: 100.0,
        seed: 1,
        dynamics: Dynamics::default(),
        noise: Noise::default(),
    };
    simulate(&law, 20.0, law.force_n(20.0), &settings)
        .unwrap()
        .0
}

fn benches(c: &mut Criterion) {
    let log = hour_log(Profile::Sines);
    let bytes = write_log(&log);
    let mut group = c.benchmark_group("log");
    group.throughput(Throughput::Bytes(bytes.len() as u64));
    group.sample_size(10);
    group.bench_function("parse (1 h at 100 Hz, 360000 rows)", |b| {
        b.iter(|| read_log(black_box(&bytes[..]), &ColumnMap::default(), 0.1, |_| {}).unwrap())
    });
    group.finish();

    let mut group = c.benchmark_group("estimate");
    group.sample_size(10);
    group.bench_function("identify (1 h at 100 Hz, sines)", |b| {
        b.iter(|| identify(black_box(&log), &SensorNoise::default()).unwrap())
    });
    // The EKF itself: predict + Joseph update + checks per sample, no CSV, no identification.
    {
        use camspring::estimate::ekf::{
            default_settings, force_rate, initial_state, Discretization, Ekf, EkfInit, ForceRate,
        };
        let id = identify(&log, &SensorNoise::default()).unwrap();
        let init = EkfInit::from_identification(&id, SensorNoise::default().force_variance_n2);
        let dt = log.dt_s();
        let (rate, first) = force_rate(&log.force_n, dt, ForceRate::ZERO_PHASE);
        let (z0, sigma_std) = initial_state(&init, log.position_mm[first], 20.0);
        for (name, discretization) in [
            ("ekf step, rk4 (1 h at 100 Hz)", Discretization::Rk4),
            ("ekf step, euler (1 h at 100 Hz)", Discretization::Euler),
        ] {
            let mut settings = default_settings(
                &init,
                &SensorNoise::default(),
                dt,
                discretization,
                ForceRate::ZERO_PHASE,
            );
            settings.p0_std[3] = sigma_std;
            group.throughput(Throughput::Elements(rate.len() as u64 - 1));
            group.bench_function(name, |b| {
                b.iter(|| {
                    let mut ekf = Ekf::new(z0, settings);
                    for k in 1..rate.len() {
                        let i = first + k;
                        let _ = ekf
                            .step(rate[k - 1], rate[k], dt, log.position_mm[i], i, log.t_s[i])
                            .unwrap();
                    }
                    black_box(ekf.z)
                })
            });
        }
    }
    let rest = hour_log(Profile::Static);
    group.bench_function("noise model (1 h at 100 Hz, 3 channels)", |b| {
        b.iter(|| noise_model(black_box(&rest)))
    });
    group.finish();
}

criterion_group!(calibration, benches);
criterion_main!(calibration);
