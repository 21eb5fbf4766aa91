//! Pitch-curve accuracy against independent truth: the closed-form frictionless lift, a
//! separate fixed-step RK4 of the friction ODE in docs/THEORY.md, and the forward force model.

mod common;

use camspring::cam::forces::rod_force;
use camspring::cam::pitch_curve::{frictionless_lift_mm, synthesize, SynthesisOptions};
use camspring::model::FrictionCorrection as FC;
use common::*;

#[test]
fn frictionless_curve_matches_the_closed_form_everywhere() {
    let law = paper_law();
    for (count, preload) in [(1, 0.0), (2, 0.0), (2, 1.5), (1, 6.0)] {
        let f = follower(count, 5.0, preload, 3.0, 0.0, FC::None);
        let pitch = synthesize(law, &f, 20.0, &fine()).unwrap();
        let mut worst = 0.0_f64;
        for s in &pitch.samples {
            let exact = frictionless_lift_mm(&law.into(), f.k_eff_n_per_mm(), preload, s.x_mm);
            worst = worst.max((s.y_mm - exact).abs());
        }
        // Well below 0.1 um.
        assert!(
            worst < 1e-8,
            "count {count} preload {preload}: max |Y - Y_exact| = {worst:e} mm"
        );
        assert_eq!(
            pitch.samples.last().unwrap().x_mm,
            20.0,
            "ends exactly at Xmax"
        );
    }
}

#[test]
fn friction_corrected_curves_match_an_independent_rk4() {
    let law = paper_law();
    let k = 10.0;
    let yp = 1.5;
    for (corr, mu) in [
        (FC::Loading, 0.1),
        (FC::Unloading, 0.05),
        (FC::Midline, 0.1),
    ] {
        let f = follower(2, 5.0, yp, 3.0, mu, corr);
        let pitch = synthesize(law, &f, 20.0, &fine()).unwrap();
        // dY/dx written from the force relations of docs/THEORY.md, independently of the crate:
        let slope = |x: f64, y: f64| {
            let force = law.force_n(x);
            let q = k * (y + yp);
            match corr {
                FC::Loading => (force - mu * q) / (q + mu * force),
                FC::Unloading => (force + mu * q) / (q - mu * force),
                _ => {
                    // q/2 (tan(t+phi) + tan(t-phi)) = F, solved for tan t.
                    let r = force / q;
                    let c = 1.0 + mu * mu;
                    2.0 * r / (c + (c * c + 4.0 * r * r * mu * mu).sqrt())
                }
            }
        };
        let mut y = 0.0;
        let mut x = 0.0;
        let mut worst = 0.0_f64;
        for s in pitch.samples.iter().skip(1) {
            let steps = ((s.x_mm - x) / 2e-3).ceil().max(1.0) as usize;
            y = rk4(slope, x, y, s.x_mm, steps);
            x = s.x_mm;
            worst = worst.max((s.y_mm - y).abs());
        }
        assert!(worst < 1e-7, "{corr:?}: max |Y - Y_rk4| = {worst:e} mm");
    }
}

#[test]
fn corrected_stroke_reproduces_the_law_from_geometry() {
    let law = paper_law();
    for (corr, mu, preload) in [
        (FC::None, 0.0, 0.0),
        (FC::Loading, 0.1, 0.0),
        (FC::Loading, 0.02, 2.0),
        (FC::Unloading, 0.05, 1.0),
        (FC::Midline, 0.15, 0.5),
    ] {
        let f = follower(1, 5.0, preload, 2.0, mu, corr);
        let pitch = synthesize(law, &f, 20.0, &fine()).unwrap();
        let phi = f.friction_angle_rad();
        let mut worst = 0.0_f64;
        for s in &pitch.samples {
            if s.x_mm == 0.0 && preload == 0.0 {
                continue; // q = 0 and theta + phi = 90 deg: the force is a 0 * inf limit
            }
            let (load, unload) = rod_force(f.spring_force_n(s.y_mm), s.theta_rad, phi);
            let predicted = match corr {
                FC::None | FC::Loading => load.unwrap(),
                FC::Unloading => unload,
                FC::Midline => 0.5 * (load.unwrap() + unload),
            };
            let target = law.force_n(s.x_mm);
            worst = worst.max(((predicted - target) / target).abs());
        }
        assert!(
            worst < 1e-6,
            "{corr:?} mu {mu} preload {preload}: relative force error {worst:e}"
        );
    }
}

#[test]
fn stored_tangents_agree_with_the_positions() {
    // The forward force model uses the sample tangent; check it against the geometry itself:
    // the chord direction between close samples converges to the tangent at the midpoint.
    let law = paper_law();
    let f = follower(2, 5.0, 1.5, 3.0, 0.01, FC::Loading);
    let dense = SynthesisOptions {
        chord_tolerance_mm: 1e-7,
        max_step_mm: 0.01,
    };
    let pitch = synthesize(law, &f, 20.0, &dense).unwrap();
    let mut worst = 0.0_f64;
    for w in pitch.samples.windows(2) {
        let chord = (w[1].y_mm - w[0].y_mm).atan2(w[1].x_mm - w[0].x_mm);
        let mid = 0.5 * (w[0].theta_rad + w[1].theta_rad);
        worst = worst.max((chord - mid).abs());
    }
    assert!(
        worst < 1e-6,
        "max angle between chord and tangent {worst:e} rad"
    );
}

#[test]
fn analytic_curvature_agrees_with_the_change_of_tangent() {
    let law = paper_law();
    for f in [
        follower(1, 5.0, 0.0, 3.0, 0.0, FC::None),
        follower(2, 5.0, 1.5, 3.0, 0.1, FC::Midline),
    ] {
        let dense = SynthesisOptions {
            chord_tolerance_mm: 1e-7,
            max_step_mm: 0.01,
        };
        let pitch = synthesize(law, &f, 20.0, &dense).unwrap();
        for w in pitch.samples.windows(2) {
            let ds = w[1].s_mm - w[0].s_mm;
            let fd = (w[1].theta_rad - w[0].theta_rad) / ds;
            let mid = 0.5 * (w[0].curvature_per_mm + w[1].curvature_per_mm);
            assert!(
                (fd - mid).abs() <= 1e-4 * mid.abs().max(1e-2),
                "at x = {}: {fd} vs {mid}",
                w[0].x_mm
            );
        }
    }
}

#[test]
fn arc_length_is_the_polyline_length() {
    let law = paper_law();
    let pitch = synthesize(
        law,
        &follower(1, 5.0, 0.0, 0.0, 0.0, FC::None),
        20.0,
        &fine(),
    )
    .unwrap();
    let poly: f64 = pitch
        .samples
        .windows(2)
        .map(|w| (w[1].x_mm - w[0].x_mm).hypot(w[1].y_mm - w[0].y_mm))
        .sum();
    let s_end = pitch.samples.last().unwrap().s_mm;
    assert!(
        s_end >= poly && s_end - poly < 1e-4 * s_end,
        "{s_end} vs {poly}"
    );
}
