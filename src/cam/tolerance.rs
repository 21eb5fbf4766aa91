//! The force band of a built spring: a seeded Monte Carlo of builds within the parts'
//! tolerances, each through the forward force model.
//!
//! A build draws, uniformly within the spec's `[tolerances]`: the spring rate (relative), the
//! preload, the roller radius, the cam profile (normal to the surface) and the contact friction.
//! The machined surface is the design's; a larger roller or a profile with more material moves
//! the roller centre out along the contact normal, so the follower rises by (dr + dp)/cos(theta)
//! at the same pressure angle (to first order). The rod force of the build is then
//! q' tan(theta +- phi') with q' = k_eff (1 + ds) (Y + (dr + dp)/cos(theta) + Yp + dYp). The band
//! is the 2.5 % and 97.5 % quantiles over the builds at each station of the stroke.

use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use serde::Serialize;

use super::pitch_curve::PitchCurve;
use crate::model::{Follower, TolerancesSpec};

/// Stations along the stroke where the band is given.
pub const STATIONS: usize = 41;

/// One build's deviations from the design.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Build {
    /// Relative spring-rate error.
    pub rate: f64,
    /// Preload error (mm).
    pub preload_mm: f64,
    /// Roller-radius error (mm).
    pub roller_mm: f64,
    /// Profile error normal to the surface (mm).
    pub profile_mm: f64,
    /// The build's contact friction coefficient.
    pub friction: f64,
}

impl Build {
    /// The design as drawn, with the tolerances' mid friction.
    pub fn nominal(t: &TolerancesSpec) -> Build {
        Build {
            rate: 0.0,
            preload_mm: 0.0,
            roller_mm: 0.0,
            profile_mm: 0.0,
            friction: 0.5 * (t.friction_min + t.friction_max),
        }
    }

    /// Build `index` of the draw seeded by `seed`: its own generator, so the band does not
    /// depend on how the builds are spread over threads.
    pub fn draw(t: &TolerancesSpec, seed: u64, index: u64) -> Build {
        let mut rng = rand::rngs::StdRng::seed_from_u64(
            seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ index.wrapping_add(1),
        );
        let mut sym = |half: f64| {
            if half > 0.0 {
                rng.random_range(-half..=half)
            } else {
                0.0
            }
        };
        Build {
            rate: sym(t.spring_rate_percent / 100.0),
            preload_mm: sym(t.preload_mm),
            roller_mm: sym(t.roller_radius_mm),
            profile_mm: sym(t.profile_mm),
            friction: if t.friction_max > t.friction_min {
                rng.random_range(t.friction_min..=t.friction_max)
            } else {
                t.friction_min
            },
        }
    }
}

/// Loading and unloading rod force of a build at pitch sample `i` (loading None: jammed).
pub fn build_force(
    pitch: &PitchCurve,
    follower: &Follower,
    build: &Build,
    i: usize,
) -> (Option<f64>, f64) {
    let s = &pitch.samples[i];
    let q = spring_load_n(follower, build, s.y_mm, s.theta_rad);
    super::forces::rod_force(q, s.theta_rad, build.friction.atan())
}

/// The build's spring load q (N) where the made cam's pitch curve has lift `y_mm` and pressure
/// angle `theta_rad`: the springs' rate times their compression, the pitch lift moved out by
/// the roller's and the profile's error along the normal.
pub fn spring_load_n(follower: &Follower, build: &Build, y_mm: f64, theta_rad: f64) -> f64 {
    let offset = build.roller_mm + build.profile_mm;
    let y = if offset == 0.0 {
        y_mm
    } else {
        y_mm + offset / theta_rad.cos().max(1e-9)
    };
    follower.k_eff_n_per_mm()
        * (1.0 + build.rate)
        * (y + follower.preload_mm + build.preload_mm).max(0.0)
}

/// Follower lift Y and pressure angle theta at any deflection: a cubic Hermite through the
/// pitch samples with their slopes tan(theta); beyond the ends, the end tangent.
pub fn pitch_at(pitch: &PitchCurve, x_mm: f64) -> (f64, f64) {
    let s = &pitch.samples;
    let n = s.len();
    if n == 0 {
        return (0.0, 0.0);
    }
    let (first, last) = (&s[0], &s[n - 1]);
    if n == 1 || x_mm <= first.x_mm {
        return (
            first.y_mm + first.theta_rad.tan() * (x_mm - first.x_mm),
            first.theta_rad,
        );
    }
    if x_mm >= last.x_mm {
        return (
            last.y_mm + last.theta_rad.tan() * (x_mm - last.x_mm),
            last.theta_rad,
        );
    }
    let i = s.partition_point(|p| p.x_mm <= x_mm).clamp(1, n - 1) - 1;
    let (a, b) = (&s[i], &s[i + 1]);
    let h = b.x_mm - a.x_mm;
    if h <= 0.0 {
        return (a.y_mm, a.theta_rad);
    }
    let t = (x_mm - a.x_mm) / h;
    let (m0, m1) = (a.theta_rad.tan(), b.theta_rad.tan());
    let (t2, t3) = (t * t, t * t * t);
    let y = a.y_mm * (2.0 * t3 - 3.0 * t2 + 1.0)
        + h * m0 * (t3 - 2.0 * t2 + t)
        + b.y_mm * (-2.0 * t3 + 3.0 * t2)
        + h * m1 * (t3 - t2);
    let slope = (a.y_mm * (6.0 * t2 - 6.0 * t) + b.y_mm * (6.0 * t - 6.0 * t2)) / h
        + m0 * (3.0 * t2 - 4.0 * t + 1.0)
        + m1 * (3.0 * t2 - 2.0 * t);
    (y, slope.atan())
}

/// Loading and unloading rod force of a build at any deflection `x_mm` of the made cam
/// ([`pitch_at`]; loading None where the followers jam).
pub fn build_force_at(
    pitch: &PitchCurve,
    follower: &Follower,
    build: &Build,
    x_mm: f64,
) -> (Option<f64>, f64) {
    let (y, theta) = pitch_at(pitch, x_mm);
    let q = spring_load_n(follower, build, y, theta);
    super::forces::rod_force(q, theta, build.friction.atan())
}

/// The loading and unloading force curves of one build as (x, F) points at the pitch samples,
/// or the deflection where its followers jam on loading.
#[allow(clippy::type_complexity)]
pub fn build_curves(
    pitch: &PitchCurve,
    follower: &Follower,
    build: &Build,
) -> Result<(Vec<(f64, f64)>, Vec<(f64, f64)>), f64> {
    let (mut loading, mut unloading) = (Vec::new(), Vec::new());
    for (i, s) in pitch.samples.iter().enumerate() {
        if loading
            .last()
            .is_some_and(|&(x, _): &(f64, f64)| s.x_mm <= x + 1e-9)
        {
            continue;
        }
        let (l, u) = build_force(pitch, follower, build, i);
        loading.push((s.x_mm, l.ok_or(s.x_mm)?));
        unloading.push((s.x_mm, u));
    }
    Ok((loading, unloading))
}

/// A tolerance's share of the spread at the end of the stroke.
#[derive(Debug, Clone, Serialize)]
pub struct Sensitivity {
    /// Which tolerance.
    pub tolerance: &'static str,
    /// Half the range of the loading force at Xmax when only it varies over its range (N).
    pub loading_half_range_n: f64,
}

/// The force band over the stroke.
#[derive(Debug, Clone, Serialize)]
pub struct ForceBand {
    /// Builds drawn.
    pub samples: usize,
    /// Seed of the draw.
    pub seed: u64,
    /// Lower and upper quantiles of the band.
    pub quantiles: [f64; 2],
    /// Stations along the stroke (mm).
    pub x_mm: Vec<f64>,
    /// Loading force, lower quantile (N); null where some builds jam.
    pub loading_lo_n: Vec<Option<f64>>,
    /// Loading force, upper quantile (N).
    pub loading_hi_n: Vec<Option<f64>>,
    /// Unloading force, lower quantile (N).
    pub unloading_lo_n: Vec<f64>,
    /// Unloading force, upper quantile (N).
    pub unloading_hi_n: Vec<f64>,
    /// Which tolerance moves the loading force at Xmax most, largest first.
    pub sensitivity: Vec<Sensitivity>,
}

fn quantile(sorted: &[f64], q: f64) -> f64 {
    let pos = q * (sorted.len() - 1) as f64;
    let (i, frac) = (pos.floor() as usize, pos.fract());
    match sorted.get(i + 1) {
        Some(next) => sorted[i] + frac * (next - sorted[i]),
        None => sorted[i],
    }
}

/// The 95 % force band of builds within `t` (2.5 % and 97.5 % quantiles).
pub fn force_band(pitch: &PitchCurve, follower: &Follower, t: &TolerancesSpec) -> ForceBand {
    // A roller cannot shrink below nothing: its tolerance is capped at its radius.
    let capped = TolerancesSpec {
        roller_radius_mm: t.roller_radius_mm.min(follower.roller_radius_mm),
        ..t.clone()
    };
    let t = &capped;
    let n = pitch.samples.len();
    let xmax = pitch.samples[n - 1].x_mm;
    // The pitch sample at or just below each station.
    let stations: Vec<usize> = (0..STATIONS)
        .map(|k| {
            let x = xmax * k as f64 / (STATIONS - 1) as f64;
            pitch
                .samples
                .partition_point(|s| s.x_mm <= x + 1e-12)
                .saturating_sub(1)
        })
        .collect();
    // Per build, loading (NaN when jammed) and unloading at every station.
    let builds: Vec<Vec<(f64, f64)>> = (0..t.samples as u64)
        .into_par_iter()
        .map(|k| {
            let b = Build::draw(t, t.seed, k);
            stations
                .iter()
                .map(|&i| {
                    let (l, u) = build_force(pitch, follower, &b, i);
                    (l.unwrap_or(f64::NAN), u)
                })
                .collect()
        })
        .collect();
    let quantiles = [0.025, 0.975];
    let mut band = ForceBand {
        samples: t.samples,
        seed: t.seed,
        quantiles,
        x_mm: stations.iter().map(|&i| pitch.samples[i].x_mm).collect(),
        loading_lo_n: Vec::new(),
        loading_hi_n: Vec::new(),
        unloading_lo_n: Vec::new(),
        unloading_hi_n: Vec::new(),
        sensitivity: Vec::new(),
    };
    for j in 0..stations.len() {
        let mut load: Vec<f64> = builds.iter().map(|b| b[j].0).collect();
        let mut unload: Vec<f64> = builds.iter().map(|b| b[j].1).collect();
        let jammed = load.iter().any(|v| v.is_nan());
        load.sort_by(f64::total_cmp);
        unload.sort_by(f64::total_cmp);
        band.loading_lo_n
            .push((!jammed).then(|| quantile(&load, quantiles[0])));
        band.loading_hi_n
            .push((!jammed).then(|| quantile(&load, quantiles[1])));
        band.unloading_lo_n.push(quantile(&unload, quantiles[0]));
        band.unloading_hi_n.push(quantile(&unload, quantiles[1]));
    }
    // One tolerance at a time over its range, the others nominal, at the end of the stroke.
    let end = n - 1;
    let nominal = Build::nominal(t);
    let at = |b: Build| build_force(pitch, follower, &b, end).0.unwrap_or(f64::NAN);
    let half = |lo: Build, hi: Build| 0.5 * (at(hi) - at(lo)).abs();
    let mut sensitivity = vec![
        Sensitivity {
            tolerance: "spring_rate",
            loading_half_range_n: half(
                Build {
                    rate: -t.spring_rate_percent / 100.0,
                    ..nominal
                },
                Build {
                    rate: t.spring_rate_percent / 100.0,
                    ..nominal
                },
            ),
        },
        Sensitivity {
            tolerance: "preload",
            loading_half_range_n: half(
                Build {
                    preload_mm: -t.preload_mm,
                    ..nominal
                },
                Build {
                    preload_mm: t.preload_mm,
                    ..nominal
                },
            ),
        },
        Sensitivity {
            tolerance: "roller_radius",
            loading_half_range_n: half(
                Build {
                    roller_mm: -t.roller_radius_mm,
                    ..nominal
                },
                Build {
                    roller_mm: t.roller_radius_mm,
                    ..nominal
                },
            ),
        },
        Sensitivity {
            tolerance: "profile",
            loading_half_range_n: half(
                Build {
                    profile_mm: -t.profile_mm,
                    ..nominal
                },
                Build {
                    profile_mm: t.profile_mm,
                    ..nominal
                },
            ),
        },
        Sensitivity {
            tolerance: "friction",
            loading_half_range_n: half(
                Build {
                    friction: t.friction_min,
                    ..nominal
                },
                Build {
                    friction: t.friction_max,
                    ..nominal
                },
            ),
        },
    ];
    sensitivity.sort_by(|a, b| b.loading_half_range_n.total_cmp(&a.loading_half_range_n));
    band.sensitivity = sensitivity;
    band
}
