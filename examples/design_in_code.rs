//! Design a spring in code: solve a law from targets, synthesise the cam for two opposed
//! followers, print the profile numbers and the checks, and write the outputs.
//!
//! Run: `cargo run --example design_in_code`

use camspring::cam::follower::{Follower, FrictionCorrection, FrictionSource, SpringArrangement};
use camspring::design::design;
use camspring::export::write_design;
use camspring::law::LawTargets;
use camspring::spec::{LawSpec, Spec, DEFAULT_SPEC_TOML};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // Start from the default spec for the part, material and check settings...
    let mut spec = Spec::from_toml(DEFAULT_SPEC_TOML)?;
    spec.name = "from-code".into();
    // ...and set a stiffer law and a different follower arrangement in code.
    spec.law = LawSpec::Targets(LawTargets {
        fmax_n: 300.0,
        fmin_n: 8.0,
        xmax_mm: 15.0,
        l0_mm: 4.0,
        c0: 0.15,
        delta0_mm: 0.5,
    });
    spec.follower = Follower {
        count: 2,
        arrangement: SpringArrangement::Shared,
        spring_rate_n_per_mm: 4.0,
        preload_mm: 2.0,
        roller_radius_mm: 4.0,
        friction: FrictionSource::Coefficient { coefficient: 0.02 },
        friction_correction: FrictionCorrection::Midline,
    };
    let d = design(&spec)?;
    println!(
        "F = {:.4} N * exp({:.5} /mm * x) + {:.4} N",
        d.law.law.mu_n, d.law.law.k2_per_mm, d.law.law.f0_n
    );
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
    let dir = std::env::temp_dir().join("camspring-example");
    let (_, written) = write_design(&d, &dir)?;
    for p in written {
        println!("wrote {}", p.display());
    }
    Ok(())
}
