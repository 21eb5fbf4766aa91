//! The force-delay profile of a log, row by row: identification at a held window with the
//! force re-timed by whole rows of delay from -8 to +8, and what each fit used (its reduced
//! chi-square, the moving and quasi-static samples, the transients it left out, and d0). The
//! screen (`estimate::retime::screen_force_delay`) places the delay at the least of such a
//! profile; where the samples a fit uses change from row to row, the rows compare fits over
//! different samples.
//!
//! Run: `cargo run --release --example delay_profile LOG WINDOW_S` (a log as `identify` reads
//! it, with the default columns; the window in seconds).

use camspring::estimate::identify::{identify_reduced, Param, Reduction};
use camspring::estimate::noise::{log_noise, GivenNoise};
use camspring::estimate::retime::retime_reduced;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    let (Some(path), Some(window)) = (a.get(1), a.get(2).and_then(|w| w.parse::<f64>().ok()))
    else {
        return Err("usage: delay_profile LOG WINDOW_S".into());
    };
    let log = camspring::app::read_log_file(
        std::path::Path::new(path),
        &Default::default(),
        0.05,
        false,
    )?;
    let noise = GivenNoise::default()
        .resolve(log_noise(&log).as_ref())
        .noise;
    let reduced = Reduction::of_log(&log);
    let dt = reduced.log.dt_s();
    for rows in -8i64..=8 {
        let (shifted, timed) = retime_reduced(&reduced, &noise, rows as f64 * dt);
        match identify_reduced(&shifted, &timed, Some(window)) {
            Ok(id) => println!(
                "{rows:+3} rows ({:+6.1} ms): reduced chi-square {:.4}, {} moving, {} quasi-static, \
                 {} transients left out, d0 {:.3} N",
                rows as f64 * dt * 1000.0,
                id.reduced_chi2,
                id.dynamic_samples,
                id.quasi_static_samples,
                id.transient_samples,
                id.get(Param::D0).value.unwrap_or(0.0),
            ),
            Err(e) => println!("{rows:+3} rows: {e}"),
        }
    }
    Ok(())
}
