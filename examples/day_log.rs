//! Writes a long simulated calibration log without holding it (the scale benchmark in
//! docs/BENCHMARKS.md): the default transmission and the paper's sensor noise, sines, at a
//! given rate for a given number of hours.
//!
//! Run: `cargo run --release --example day_log -- day.csv [hours] [rate_hz]` (default 24 h at
//! 1000 Hz: 86.4 million rows, about 3 GB).

use std::io::Write;

use camspring::estimate::sim::{SimSettings, Simulator};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args.next().unwrap_or_else(|| "day.csv".into());
    let hours: f64 = args.next().map_or(Ok(24.0), |a| a.parse())?;
    let rate_hz: f64 = args.next().map_or(Ok(1000.0), |a| a.parse())?;
    let spec = camspring::app::load_spec(None)?;
    let law = camspring::app::designed_law(&spec)?;
    let settings = SimSettings {
        duration_s: hours * 3600.0,
        rate_hz,
        seed: 24,
        ..SimSettings::default()
    };
    let mut sim = Simulator::new(law, spec.law.xmax_mm(), 200.0, &settings)?;
    let mut out = std::io::BufWriter::with_capacity(1 << 20, std::fs::File::create(&path)?);
    writeln!(out, "t_s,force_n,position_mm")?;
    let n = sim.samples();
    for i in 0..n {
        let s = sim.sample(i)?.logged;
        writeln!(out, "{:.6},{:.6},{:.6}", s.t_s, s.force_n, s.position_mm)?;
    }
    out.flush()?;
    println!("{path}: {n} samples ({hours} h at {rate_hz} Hz)");
    Ok(())
}
