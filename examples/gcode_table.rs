//! Block count and measured path deviation of G2/G3 arc output against G1-only output at
//! 10, 1 and 0.1 um tolerance, for the default spec (the table in docs/BENCHMARKS.md).
//!
//! Run: `cargo run --release --example gcode_table`
//!
//! The deviation is measured, not taken from the fitter: the finishing contour's moves are
//! sampled densely and compared with the exact part outline (ODE samples at 10 nm chords);
//! |distance - cutter radius| is the error of the programmed tool-centre path. Output
//! rounding (at most 0.007 um at LinuxCNC's 5 decimals) comes on top and is budgeted for.

use camspring::design::design;
use camspring::part::build;
use camspring::toolpath::path::sample_move;
use camspring::toolpath::{gcode, jobs};
use camspring::{spec::DEFAULT_SPEC_TOML, Spec};

fn main() {
    let mut reference = Spec::from_toml(DEFAULT_SPEC_TOML).unwrap();
    reference.output.chord_tolerance_mm = 1e-5;
    let d = design(&reference).unwrap();
    let part = build(&d).unwrap();
    let poly = part.outline_polygon();
    let dist = |p: [f64; 2]| {
        (0..poly.len())
            .map(|i| {
                let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                let t = (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / (dx * dx + dy * dy))
                    .clamp(0.0, 1.0);
                (a[0] + t * dx - p[0]).hypot(a[1] + t * dy - p[1])
            })
            .fold(f64::INFINITY, f64::min)
    };
    println!("| tolerance | output | blocks | contour moves (finish) | measured max deviation |");
    println!("| --- | --- | --- | --- | --- |");
    for tol in [0.01, 0.001, 0.0001] {
        for arcs in [true, false] {
            let mut spec = Spec::from_toml(DEFAULT_SPEC_TOML).unwrap();
            spec.machining.tolerance_mm = tol;
            spec.machining.arcs = arcs;
            let d = design(&spec).unwrap();
            let part = build(&d).unwrap();
            let (js, summary) = jobs(&d, &part).unwrap();
            let (_, blocks) = gcode::write(&d, &js, &summary);
            let finish = js
                .iter()
                .flat_map(|j| &j.passes)
                .find(|p| p.finishing && p.label.starts_with("outline"))
                .unwrap();
            let radius = spec.machining.tool_diameter_mm / 2.0;
            let mut from = finish.entry;
            let mut worst = 0.0_f64;
            let contour = finish.ramp + finish.lead_in..finish.steps.len() - finish.lead_out;
            for (k, m) in finish.steps.iter().map(|s| &s.mv).enumerate() {
                if contour.contains(&k) {
                    for q in sample_move(from, m, 32) {
                        worst = worst.max((dist(q) - radius).abs());
                    }
                }
                from = m.to();
            }
            println!(
                "| {} um | {} | {} | {} | {:.3} um |",
                tol * 1e3,
                if arcs { "G2/G3 arcs" } else { "G1 only" },
                blocks,
                contour.len(),
                worst * 1e3
            );
        }
    }
}
