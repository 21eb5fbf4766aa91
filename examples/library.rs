//! The README's "Using the library" section, compiled: a given law through the builder, the
//! outputs planned and written, a calibration log with mapped columns read, and the spring
//! validated against its design from Rust.
//!
//! Run: `cargo run --release --example library`

use camspring::estimate::log::{parse_column, parse_time_column, write_log};
use camspring::estimate::sim::{simulate, SimSettings};
use camspring::units::Dimension;
use camspring::{
    design, estimate, plan, read_log, validate, write_design, ColumnMap, EstimateOptions, ExpLaw,
    Follower, LawSpec, PartSpec, SensorNoise, Spec,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // A spring given as a law: F = 1.2 N * exp(0.25 /mm * x) + 2 N over 18 mm.
    let law = ExpLaw {
        mu_n: 1.2,
        k2_per_mm: 0.25,
        f0_n: 2.0,
    };
    let follower = Follower::new(6.0, 3.0).with_count(2).with_preload(2.0);
    let spec = Spec::builder(LawSpec::Given { law, xmax_mm: 18.0 }, follower)
        .name("given-law")
        .part(PartSpec::default().with_thickness(8.0))
        .build()?; // the same rules as a spec file, naming the key
    let d = design(&spec)?;
    let outputs = plan(&d)?; // what is made and the status
    let dir = std::env::temp_dir().join("camspring-library");
    write_design(&d, &outputs, &dir)?;
    println!("{:?}: {}", outputs.status(), dir.display());

    // A rig log whose columns are time_ms (ms), F (lbf) and x (in): here simulated and
    // renamed, as a rig would write it.
    let (log, _truth) = simulate(law, 18.0, law.force_n(18.0), &SimSettings::default())?;
    let csv =
        String::from_utf8(write_log(&log))?.replacen("t_s,force_n,position_mm", "time_ms,F,x", 1);
    let rig: String = csv
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i == 0 {
                return format!("{l}\n");
            }
            let v: Vec<f64> = l.split(',').map(|s| s.parse().unwrap_or(0.0)).collect();
            format!(
                "{},{},{}\n",
                v[0] * 1e3,
                v[1] / 4.448_221_615_260_5,
                v[2] / 25.4
            )
        })
        .collect();
    let map = ColumnMap {
        time: parse_time_column("time_ms:ms")?,
        force: parse_column("F:lbf", Dimension::Force, "force")?,
        position: parse_column("x:in", Dimension::Length, "position")?,
        ..ColumnMap::default()
    };
    let log = read_log(rig.as_bytes(), &map, 0.1, |_| {})?;

    // Validate the built spring against its design.
    let run = estimate(
        &log,
        &EstimateOptions::new(SensorNoise::default()),
        |_, _| {},
    )?;
    let id = run.identification.as_ref().ok_or("identification ran")?;
    let designed = d.law.exponential().ok_or("an exponential law")?;
    let verdict = validate(designed, id, &run, &log.position_mm, 0.03, None);
    println!("validate: {}", if verdict.pass { "PASS" } else { "FAIL" });
    Ok(())
}
