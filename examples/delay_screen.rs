//! The force-delay screen of a log as `identify` runs it: the profile's least at the held
//! window, and at the next longer window where the held one finds a delay
//! (`estimate::retime::screen_force_delay`), one line per log.
//!
//! Run: `cargo run --release --example delay_screen LOG [WINDOW_S]` (a log as `identify` reads
//! it, with the default columns; the window chosen from the data unless given, in seconds).

use camspring::estimate::identify::{identify_reduced, Reduction};
use camspring::estimate::noise::{log_noise, GivenNoise};
use camspring::estimate::retime::{screen_force_delay, ScreenedDelay};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    let Some(path) = a.get(1) else {
        return Err("usage: delay_screen LOG [WINDOW_S]".into());
    };
    let window = match a.get(2) {
        Some(w) => Some(
            w.parse::<f64>()
                .map_err(|e| format!("WINDOW_S {w:?}: {e}"))?,
        ),
        None => None,
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
    let id = identify_reduced(&reduced, &noise, window)?;
    let at = |s: &ScreenedDelay| {
        format!(
            "window {:.3} s: {:+.1} +- {:.1} ms, z {:+.1}{}",
            s.window_s,
            s.delay_s * 1e3,
            s.std_s * 1e3,
            s.z,
            if s.significant { ", significant" } else { "" }
        )
    };
    match screen_force_delay(&reduced, &noise, &id) {
        Some(s) => {
            let longer = match (&s.longer_window, s.held.significant) {
                (Some(l), _) => format!(" | {}", at(l)),
                (None, true) => " | longer window: no least".to_string(),
                (None, false) => String::new(),
            };
            let spread = match s.window_spread_s {
                Some(w) => format!(
                    " | spread {:.1} ms, z with it {:+.1}",
                    w * 1e3,
                    s.held.delay_s / s.std_with_window_s()
                ),
                None => String::new(),
            };
            println!(
                "{path}: {}{longer}{spread} | suspected {}, moves with the window {}",
                at(&s.held),
                s.suspected,
                s.moves_with_window()
            );
        }
        None => println!("{path}: not screened (too short, or no least at the held window)"),
    }
    Ok(())
}
