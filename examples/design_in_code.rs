//! Design a spring in code: state a law by its targets, build the spec with the builder (two
//! opposed followers on one shared spring), design it, print the profile numbers and the
//! checks, and write the outputs.
//!
//! Run: `cargo run --example design_in_code`

use camspring::model::{FrictionCorrection, FrictionSource, SpringArrangement};
use camspring::{design, plan, write_design, Follower, LawSpec, LawTargets, Spec};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let law = LawSpec::Targets(LawTargets {
        fmax_n: 300.0,
        fmin_n: 8.0,
        xmax_mm: 15.0,
        l0_mm: 4.0,
        c0: 0.15,
        delta0_mm: 0.5,
    });
    let follower = Follower::new(4.0, 4.0)
        .with_count(2)
        .with_arrangement(SpringArrangement::Shared)
        .with_preload(2.0)
        .with_friction(FrictionSource::Coefficient { coefficient: 0.02 })
        .with_friction_correction(FrictionCorrection::Midline);
    // Every rule a TOML spec obeys is checked here too, naming the key.
    let spec = Spec::builder(law, follower).name("from-code").build()?;
    let d = design(&spec)?;
    println!("{}", d.law.law.describe());
    println!(
        "lift {:.3} mm, max pressure angle {:.2} deg",
        d.pitch_curve.lift_mm(),
        d.pitch_curve.max_pressure_angle().0
    );
    for c in &d.checks {
        println!(
            "{:<15} {:?} {}",
            c.name,
            c.status,
            c.advice.as_deref().unwrap_or("")
        );
    }
    let outputs = plan(&d)?;
    let dir = std::env::temp_dir().join("camspring-example");
    for p in write_design(&d, &outputs, &dir)? {
        println!("wrote {}", p.display());
    }
    Ok(())
}
