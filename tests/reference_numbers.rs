//! The reference numbers of docs/THEORY.md, computed independently of this crate
//! (closed forms and a separate SciPy DOP853 run recorded in the note), reproduced here.

mod common;

use camspring::cam::forces::rod_force;
use camspring::cam::pitch_curve::synthesize;
use camspring::cam::surface::offset;
use camspring::model::FrictionCorrection as FC;
use common::*;

#[test]
fn paper_law_exact_root() {
    let s = camspring::law::solve(&paper_targets()).unwrap();
    assert_near(s.alpha.unwrap(), 1.320_191_476_0, 1e-10, "alpha");
    let l = s.exponential().unwrap();
    assert_near(l.k2_per_mm, 0.264_038_3, 1e-7, "k2");
    assert_near(l.mu_n, 1.011_535_7, 1e-7, "mu");
    assert_near(l.f0_n, 1.212_670_6, 1e-7, "F0");
    let r = s.residuals.unwrap();
    assert!(r.max_abs() < 1e-9, "{r:?}");
}

#[test]
fn lift_and_pressure_angle_at_xmax() {
    let law = paper_law();
    // Single follower, ks = 5 N/mm, no preload: Y(20) = 17.587 mm, pressure angle 66.3 deg.
    let single = synthesize(
        law,
        &follower(1, 5.0, 0.0, 0.0, 0.0, FC::None),
        20.0,
        &fine(),
    )
    .unwrap();
    assert_near(single.lift_mm(), 17.587, 5e-4, "Y(20), k_eff = 5");
    let end = single.samples.last().unwrap();
    assert_near(
        end.theta_rad.to_degrees(),
        66.3,
        0.05,
        "pressure angle at Xmax",
    );
    // Two opposed followers, one spring each: k_eff = 10 N/mm, Y(20) = 12.436 mm.
    let double = synthesize(
        law,
        &follower(2, 5.0, 0.0, 0.0, 0.0, FC::None),
        20.0,
        &fine(),
    )
    .unwrap();
    assert_near(double.lift_mm(), 12.436, 5e-4, "Y(20), k_eff = 10");
}

#[test]
fn start_curvature_without_preload_is_force_over_rate() {
    // rho(0) = F_S(0)/k_eff = 0.445 mm for a single 5 N/mm follower.
    let law = paper_law();
    let pitch = synthesize(
        law,
        &follower(1, 5.0, 0.0, 5.0, 0.0, FC::None),
        20.0,
        &fine(),
    )
    .unwrap();
    let rho0 = -1.0 / pitch.samples[0].curvature_per_mm;
    assert_near(rho0, law.force_n(0.0) / 5.0, 1e-12, "rho(0) = F(0)/ks");
    assert_near(rho0, 0.445, 5e-4, "rho(0) from docs/THEORY.md");
}

#[test]
fn five_mm_roller_undercuts_near_the_start() {
    // docs/THEORY.md: a 5 mm roller on the single-follower paper cam undercuts over x in [0, 0.7] mm
    // (rounded). The closed form Y = sqrt(2E/ks) gives rho(x) = 5 mm at x = 0.78709 mm (root of
    // the analytic radius of curvature, computed with SciPy's brentq).
    let law = paper_law();
    let f = follower(1, 5.0, 0.0, 5.0, 0.0, FC::None);
    let pitch = synthesize(law, &f, 20.0, &fine()).unwrap();
    let surface = offset(&pitch, 5.0, 2e-4);
    let folds = surface.folds.clone();
    assert_eq!(folds.len(), 1, "{folds:?}");
    assert_eq!(folds[0].x_start_mm, 0.0);
    assert_near(
        folds[0].x_end_mm,
        0.787_09,
        2e-3,
        "end of the fold (1 + r*kappa <= 0)",
    );
    // Beyond the local fold, other roller positions still cut into the offset (the
    // swallowtail): the surface is only followable well after the fold ends.
    let spans = surface.unfollowable_spans();
    assert_eq!(spans.len(), 1);
    assert!(spans[0].x_end_mm > 1.5, "{spans:?}");
    assert!(!surface.is_followable());
}

#[test]
fn hysteresis_of_a_loading_corrected_cam() {
    // docs/THEORY.md: mu_f = 0.1 on the paper example (single follower, ks = 5, no preload),
    // cam corrected for loading: the unloading force at Xmax falls from 200 N to about 121.5 N.
    // (A SciPy DOP853 integration of the same ODE gives 121.524 N.)
    let law = paper_law();
    let f = follower(1, 5.0, 0.0, 0.0, 0.1, FC::Loading);
    let pitch = synthesize(law, &f, 20.0, &fine()).unwrap();
    let end = pitch.samples.last().unwrap();
    let (loading, unloading) = rod_force(
        f.spring_force_n(end.y_mm),
        end.theta_rad,
        f.friction_angle_rad(),
    );
    assert_near(
        loading.unwrap(),
        200.0,
        1e-6 * 200.0,
        "loading force at Xmax",
    );
    assert_near(unloading, 121.524, 2e-3, "unloading force at Xmax");
    assert_near(
        pitch.lift_mm(),
        15.676_928,
        1e-5,
        "corrected lift (SciPy DOP853)",
    );
}
