//! The calibration-log reader on arbitrary bytes, and identification of whatever it accepts.
#![no_main]
use camspring::estimate::identify::{identify, SensorNoise};
use camspring::estimate::log::{read_log, ColumnMap};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(log) = read_log(data, &ColumnMap::default(), 0.1, |_| {}) {
        let _ = identify(&log, &SensorNoise::default());
    }
});
