//! The calibration-log reader on arbitrary bytes, then what `estimate` runs on whatever it
//! accepts: identification and the EKF from it.
#![no_main]
use camspring::estimate::log::{read_log, ColumnMap};
use camspring::{estimate, EstimateOptions, SensorNoise};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(log) = read_log(data, &ColumnMap::default(), 0.1, |_| {}) {
        let _ = estimate(&log, &EstimateOptions::new(SensorNoise::default()), |_, _| {});
    }
});
