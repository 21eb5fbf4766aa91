//! Runs the paper's EKF on a calibration log, the way `camspring estimate` does: simulate a
//! log of the default spec's spring (or read one given as the first argument), identify the
//! parameters offline, then filter, and print the final estimates.
//!
//! Run: `cargo run --release --example ekf_on_log [calib.csv]`

use camspring::app::read_log_file;
use camspring::estimate::ekf::idx;
use camspring::estimate::sim::{simulate, Dynamics, Noise, Profile, SimSettings};
use camspring::{estimate, spec::DEFAULT_SPEC_TOML, ColumnMap, EstimateOptions, SensorNoise, Spec};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let log = match std::env::args().nth(1) {
        Some(path) => read_log_file(path.as_ref(), &ColumnMap::default(), 0.1, false)?,
        None => {
            let spec = Spec::from_toml(DEFAULT_SPEC_TOML)?;
            let law = camspring::design::law_of(&spec)?.law;
            let settings = SimSettings {
                speed: 1.0,
                profile: Profile::Sines,
                duration_s: 300.0,
                rate_hz: 100.0,
                seed: 1,
                dynamics: Dynamics::default(),
                noise: Noise::default(),
            };
            simulate(&law, 20.0, law.force_n(20.0), &settings)?.0
        }
    };
    let options = EstimateOptions::new(SensorNoise::default());
    let est = estimate(&log, &options, |_, _| {})?;
    let z = est.run.last.z;
    let sd = est.run.last.std();
    println!("{} samples filtered", est.run.samples);
    println!("k2 = {:.6} +- {:.6} 1/mm", z[idx::K2], sd[idx::K2]);
    println!("M  = {:.6} +- {:.6} N s^2/mm", z[idx::M], sd[idx::M]);
    println!("d2 = {:.3e} +- {:.1e} N s^3/mm^3", z[idx::D2], sd[idx::D2]);
    println!("sigma at the last sample = {:.4} N/mm", z[idx::SIGMA]);
    Ok(())
}
