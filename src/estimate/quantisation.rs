//! What a quantised position's error passes through identification's smoothing kernels.
//!
//! An encoder that reads the position in steps q, with no noise of its own, errs by
//! e = Q(x) - x: a function of the position, not of time. At rest it is constant; moving at a
//! speed v it is a sawtooth of amplitude q / 2 whose fundamental frequency is |v| / q, with
//! harmonics n of power q^2 / (2 pi^2 n^2), summing to the uniform error's q^2 / 12. Where
//! that power lands decides what the smoothing kernels pass: a rod creeping a step in many
//! samples puts it all at low frequency, inside the kernels' band, and they pass many times
//! what white noise of the same variance would; at a steady cruise of several steps a sample
//! the harmonics alias to frequencies set by the speed, in or out of the band. White noise of
//! the variance the log's differences suggest is then wrong either way, and identification's
//! errors-in-variables correction, which subtracts it, biases m and the damping: on the
//! independent rig's S-curves read in 6.8 um steps at 200 Hz (m 0.074, d0 0.7 N), the
//! kernels passed 0.4 to 0.5 of it and m came out 20 % high at z +3.2 to +4.2 over 15
//! redraws of the force noise; in 15.6 um steps at 100 Hz they passed 1.1 to 3.3 times it
//! (docs/CALIBRATION.md, "A quantised position through the kernels").
//!
//! [`trajectory_shares`] is that share for each kernel, summed along the path the rod
//! followed: with the error's phase on a step unknown (uniform), harmonic n through a kernel
//! at a sample has the variance of its amplitude times |sum_j w_j z_n(j)|^2, z_n the block
//! mean of exp(2 pi i n x / q) over the sample's logged samples. That is exact for a known
//! path; the path identification uses is the log's own, smoothed over a second. Against the
//! rig's true error (with its true path) it came within 15 % on S-curves, trapezoids, servo
//! ramps, multisines and a force-controlled rod at 100 Hz to 1 kHz, where a share worked out
//! at each sample's steady speed overstated by up to 2.1 times; on sines, averaged over where
//! their turns fall on a step, within 10 %.
//!
//! What passes depends on the speed: nothing of a rest's constant error through a derivative
//! kernel, many times white noise's share where the rod creeps a step in many samples. So
//! each fitted row takes the shares of its speed class ([`SpeedShares`], [`RowShares`]), not
//! one average over the log.

use std::f64::consts::PI;

/// A position read in steps, as identification sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quantisation {
    /// The step (mm).
    pub step_mm: f64,
    /// The standard deviation, in steps, of analog noise before the steps (0: none).
    pub dither_steps: f64,
    /// The logged samples averaged into each sample identification fits (1 unless reduced).
    pub block: usize,
    /// A factor on the error's variance: 1, or raised to carry the model's uncertainty
    /// ([`super::window::fit_with_noise_uncertainty`]).
    pub variance_scale: f64,
    /// What identification's kernels at one window pass of the error at each speed, as
    /// shares of white noise of the uniform error's variance (position, velocity,
    /// acceleration, motion velocity, the parallel filter's velocity), once worked out for
    /// that window; `None`: worked out at each fit.
    pub kernel_shares: Option<SpeedShares>,
}

impl Quantisation {
    /// A position read in steps of `step_mm` with analog noise of `dither_steps` steps before
    /// them, at the logged samples (a block of 1), its variance unscaled, its kernels' shares
    /// not yet worked out.
    pub fn new(step_mm: f64, dither_steps: f64) -> Quantisation {
        Quantisation {
            step_mm,
            dither_steps,
            block: 1,
            variance_scale: 1.0,
            kernel_shares: None,
        }
    }

    /// The variance (mm^2, per sample identification fits) of white noise with the uniform
    /// error's power, q^2 / 12 of a logged sample averaged over the block: the reference the
    /// kernels' shares are taken against.
    pub fn white_variance_mm2(&self) -> f64 {
        self.variance_scale * self.step_mm * self.step_mm / 12.0 / self.block.max(1) as f64
    }
}

/// Harmonics of the sawtooth summed along the trajectory; the rest (a share
/// 6 / (pi^2 N) of its power, 1.9 %) are counted as white noise.
pub const HARMONICS: usize = 32;

/// The shares, relative to white noise of the uniform error's variance, of the quantisation
/// error's power that each of `kernels` (odd lengths, centred, unit sample spacing as in
/// [`super::sg::Differentiator`]) passes at the fitted samples `rows`, on average, for a rod
/// that followed `position_mm` at `speed_mm_s` (one value per fitted sample, spaced `dt_s`;
/// each sample the mean of `q.block` logged ones).
///
/// The error is a function of the position, e(x) = sum_n a_n sin(2 pi n x / q) with
/// a_n^2 / 2 = q^2 / (2 pi^2 n^2); where on a step the rod started is unknown, so the error's
/// phase is uniform and its harmonics are uncorrelated. A kernel w at a row passes harmonic n
/// with variance a_n^2 / 2 |sum_j w_j z_n(j)|^2, where z_n(j) is the block mean of
/// exp(2 pi i n x / q) over sample j's logged samples: exp(2 pi i n x_j / q) times the
/// Dirichlet kernel at the sample's speed. Summed along the trajectory, the speed may change
/// within a window, as it does on sines, S-curves and a force-controlled rod, where a share
/// worked out at each row's steady speed overstated what passed by up to 2.1 times.
/// Rows whose windows reach beyond the trajectory, or where it is not finite, are skipped;
/// every other is summed (a caller bounds the work by the rows it asks for:
/// [`SpeedShares`]). None when no row is left, there are no kernels, or the step is not
/// positive.
pub fn trajectory_shares(
    kernels: &[&[f64]],
    position_mm: &[f64],
    speed_mm_s: &[f64],
    rows: &[usize],
    q: Quantisation,
    dt_s: f64,
) -> Option<Vec<f64>> {
    let k_count = kernels.len();
    if !(q.step_mm > 0.0 && q.step_mm.is_finite()) || k_count == 0 {
        return None;
    }
    let n = position_mm.len().min(speed_mm_s.len());
    let reach = kernels.iter().map(|w| w.len() / 2).max().unwrap_or(0);
    let usable: Vec<usize> = rows
        .iter()
        .copied()
        .filter(|&r| r >= reach && r + reach < n)
        .filter(|&r| {
            (r - reach..=r + reach).all(|j| position_mm[j].is_finite() && speed_mm_s[j].is_finite())
        })
        .collect();
    if usable.is_empty() {
        return None;
    }
    let picked = usable;
    let block = q.block.max(1);
    let b = block as f64;
    let raw_dt = dt_s / b;
    // Analog noise of s steps before the steps leaves harmonic n of the sawtooth (its mean
    // over the noise) exp(-2 pi^2 n^2 s^2) of its amplitude; the power it loses, the
    // harmonics beyond the last summed, and the noise's own s^2 steps^2 are white.
    let dither = q.dither_steps.max(0.0);
    let kept: Vec<f64> = (1..=HARMONICS)
        .map(|h| (-4.0 * PI * PI * (h * h) as f64 * dither * dither).exp())
        .collect();
    let tail = 1.0
        - 6.0 / (PI * PI)
            * (1..=HARMONICS)
                .zip(&kept)
                .map(|(h, k)| k / (h * h) as f64)
                .sum::<f64>()
        + 12.0 * dither * dither;
    let powers: Vec<f64> = kernels
        .iter()
        .map(|w| w.iter().map(|c| c * c).sum())
        .collect();
    // sum_j w_j z_n(j) for each kernel and harmonic, at one row.
    let mut sums = vec![(0.0_f64, 0.0_f64); k_count * HARMONICS];
    let mut taps = vec![0.0; k_count];
    let mut total = vec![0.0; k_count];
    for &row in &picked {
        sums.iter_mut().for_each(|s| *s = (0.0, 0.0));
        for j in row - reach..=row + reach {
            // Each kernel's tap at sample j (0 beyond its own reach).
            for (t, w) in taps.iter_mut().zip(kernels) {
                let half = w.len() / 2;
                *t = (j + half)
                    .checked_sub(row)
                    .and_then(|i| w.get(i))
                    .copied()
                    .unwrap_or(0.0);
            }
            let theta = 2.0 * PI * position_mm[j] / q.step_mm;
            let (base_im, base_re) = theta.sin_cos();
            // The block mean's Dirichlet kernel D_n = sin(n b a) / (b sin(n a)), a the half
            // phase step per logged sample, by rotation in n.
            let a = PI * speed_mm_s[j] * raw_dt / q.step_mm;
            let (rot_a_im, rot_a_re) = a.sin_cos();
            let (rot_ba_im, rot_ba_re) = (b * a).sin_cos();
            let (mut z_re, mut z_im) = (1.0, 0.0);
            let (mut na_re, mut na_im) = (1.0, 0.0);
            let (mut nba_re, mut nba_im) = (1.0, 0.0);
            for h in 0..HARMONICS {
                (z_re, z_im) = (
                    z_re * base_re - z_im * base_im,
                    z_re * base_im + z_im * base_re,
                );
                (na_re, na_im) = (
                    na_re * rot_a_re - na_im * rot_a_im,
                    na_re * rot_a_im + na_im * rot_a_re,
                );
                (nba_re, nba_im) = (
                    nba_re * rot_ba_re - nba_im * rot_ba_im,
                    nba_re * rot_ba_im + nba_im * rot_ba_re,
                );
                let dirichlet = if block == 1 || na_im.abs() < 1e-12 {
                    1.0
                } else {
                    nba_im / (b * na_im)
                };
                let (zr, zi) = (z_re * dirichlet, z_im * dirichlet);
                for (k, &c) in taps.iter().enumerate() {
                    let s = &mut sums[k * HARMONICS + h];
                    s.0 += c * zr;
                    s.1 += c * zi;
                }
            }
        }
        for (k, t) in total.iter_mut().enumerate() {
            *t += (0..HARMONICS)
                .map(|h| {
                    let (re, im) = sums[k * HARMONICS + h];
                    let n = (h + 1) as f64;
                    6.0 / (PI * PI * n * n) * kept[h] * (re * re + im * im)
                })
                .sum::<f64>();
        }
    }
    Some(
        total
            .iter()
            .zip(&powers)
            .map(|(t, p)| {
                if *p > 0.0 {
                    t / picked.len() as f64 / (p / b) + tail
                } else {
                    1.0
                }
            })
            .collect(),
    )
}

/// At most `count` of `rows`, spread over them by the golden ratio's multiples (a
/// low-discrepancy sequence), in order. An even stride can fall in step with a periodic
/// motion (a rod creeping a step every so many samples) and sum its rows at one phase of it:
/// on a creep of 0.02 steps a sample, every 78th row's shares were 37 % above the mean over
/// every tenth. All of them where there are no more than `count`.
fn spread_over(rows: &[usize], count: usize) -> Vec<usize> {
    if rows.len() <= count {
        return rows.to_vec();
    }
    let golden = (5.0_f64.sqrt() - 1.0) / 2.0;
    let mut picked: Vec<usize> = (0..count)
        .map(|k| {
            rows[(((k as f64 * golden).fract() * rows.len() as f64) as usize).min(rows.len() - 1)]
        })
        .collect();
    picked.sort_unstable();
    picked
}

/// Speed classes (logarithmic, four to a decade) a log's samples are grouped in by
/// [`SpeedShares`], from [`REST_SPEED_SHARE`] of the fastest speed up.
pub const SPEED_CLASSES: usize = 20;

/// The speed, as a share of the fastest, below which a sample counts as at rest in
/// [`SpeedShares`].
pub const REST_SPEED_SHARE: f64 = 1e-5;

/// At most this many samples of each speed class are summed along the trajectory
/// ([`trajectory_shares`]).
pub const CLASS_ROWS: usize = 256;

/// The kernels [`SpeedShares`] holds shares for.
pub const SHARE_KERNELS: usize = 5;

/// What the kernels pass of the quantisation error at each speed: [`trajectory_shares`]
/// averaged over the samples of each speed class. The error is not stationary: a rod at rest
/// holds a constant error that no derivative kernel passes, a rod creeping a step in many
/// samples puts it all inside the kernels' band, and a fast one spreads it over the aliases;
/// one share averaged over a log's samples weighs slow and fast samples alike, and is wrong
/// for any set of samples but the one it was averaged over. Each sample takes its class's
/// shares instead.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedShares {
    /// The fastest speed (mm/s) the classes are drawn from.
    pub fastest_mm_s: f64,
    /// The shares at rest (index 0) and in each class, one per kernel.
    pub table: [[f64; SHARE_KERNELS]; SPEED_CLASSES + 1],
}

impl SpeedShares {
    /// The shares of `kernels` for a rod that followed `position_mm` at `speed_mm_s` (one
    /// value per fitted sample), at the samples `rows` (their centres), grouped by their
    /// speeds `row_speeds_mm_s` (one per row). A class none of whose samples can be summed
    /// takes the nearest class's shares below it, else above it, else 1.
    pub fn new(
        kernels: &[&[f64]; SHARE_KERNELS],
        position_mm: &[f64],
        speed_mm_s: &[f64],
        rows: &[usize],
        row_speeds_mm_s: &[f64],
        q: Quantisation,
        dt_s: f64,
    ) -> SpeedShares {
        let fastest = row_speeds_mm_s
            .iter()
            .map(|v| v.abs())
            .filter(|v| v.is_finite())
            .fold(0.0_f64, f64::max);
        let mut shares = SpeedShares {
            fastest_mm_s: fastest,
            table: [[1.0; SHARE_KERNELS]; SPEED_CLASSES + 1],
        };
        let mut members: Vec<Vec<usize>> = vec![Vec::new(); SPEED_CLASSES + 1];
        for (&r, &v) in rows.iter().zip(row_speeds_mm_s) {
            members[shares.class_of(v)].push(r);
        }
        let mut known = [false; SPEED_CLASSES + 1];
        for (c, rows) in members.iter().enumerate() {
            if rows.is_empty() {
                continue;
            }
            let picked = spread_over(rows, CLASS_ROWS);
            if let Some(at) = trajectory_shares(kernels, position_mm, speed_mm_s, &picked, q, dt_s)
            {
                shares.table[c].copy_from_slice(&at);
                known[c] = true;
            }
        }
        for c in 0..=SPEED_CLASSES {
            if !known[c] {
                let below = (0..c).rev().find(|&b| known[b]);
                let above = (c + 1..=SPEED_CLASSES).find(|&a| known[a]);
                if let Some(from) = below.or(above) {
                    shares.table[c] = shares.table[from];
                }
            }
        }
        shares
    }

    /// The class of a sample moving at `speed_mm_s` (0: at rest, or not finite).
    pub fn class_of(&self, speed_mm_s: f64) -> usize {
        let v = speed_mm_s.abs();
        let lo = self.fastest_mm_s * REST_SPEED_SHARE;
        if !(v.is_finite() && lo > 0.0 && v >= lo) {
            return 0;
        }
        let span = (1.0 / REST_SPEED_SHARE).ln();
        1 + (((v / lo).ln() / span * SPEED_CLASSES as f64) as usize).min(SPEED_CLASSES - 1)
    }

    /// The shares at `speed_mm_s`.
    pub fn at(&self, speed_mm_s: f64) -> [f64; SHARE_KERNELS] {
        self.table[self.class_of(speed_mm_s)]
    }
}

/// Each of a set of samples' shares ([`SpeedShares`] at the sample's speed).
#[derive(Debug, Clone, PartialEq)]
pub struct RowShares {
    /// Each sample's speed class.
    pub class: Vec<u8>,
    /// The classes' shares.
    pub speeds: SpeedShares,
}

impl RowShares {
    /// The shares of samples moving at `speeds_mm_s`.
    pub fn new(speeds: SpeedShares, speeds_mm_s: &[f64]) -> RowShares {
        RowShares {
            class: speeds_mm_s
                .iter()
                .map(|&v| speeds.class_of(v) as u8)
                .collect(),
            speeds,
        }
    }

    /// Sample `i`'s share through kernel `k`.
    pub fn share(&self, i: usize, k: usize) -> f64 {
        self.speeds.table[self.class[i] as usize][k]
    }

    /// The shares of the samples `keep`, in that order.
    pub fn pick(&self, keep: &[usize]) -> RowShares {
        RowShares {
            class: keep.iter().map(|&i| self.class[i]).collect(),
            speeds: self.speeds,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::sg::{self, Differentiator};

    /// A sine of `amplitude` (mm) about 7 mm + `offset` at `hz` read in steps `q`,
    /// block-averaged: the block means' quantisation error, positions and speeds.
    fn quantised_sine(
        amplitude: f64,
        hz: f64,
        q: f64,
        raw_dt: f64,
        block: usize,
        offset: f64,
    ) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let n = 600_000;
        let w = 2.0 * PI * hz;
        let mut error = Vec::with_capacity(n);
        let mut position = Vec::with_capacity(n);
        let mut speed = Vec::with_capacity(n);
        for i in 0..n {
            let t = i as f64 * raw_dt;
            let x = 7.0 + offset + amplitude * (w * t).sin();
            error.push((x / q).round() * q - x);
            position.push(x);
            speed.push(amplitude * w * (w * t).cos());
        }
        let mean = |c: &[f64]| c.iter().sum::<f64>() / block as f64;
        let blocks = |v: Vec<f64>| v.chunks_exact(block).map(mean).collect::<Vec<f64>>();
        (blocks(error), blocks(position), blocks(speed))
    }

    /// The mean square of `weights` through `error`, against white noise of variance
    /// `white` through the same.
    fn measured_share(weights: &[f64], error: &[f64], white: f64) -> f64 {
        let out: Vec<f64> = error
            .windows(weights.len())
            .map(|w| w.iter().zip(weights).map(|(a, b)| a * b).sum::<f64>())
            .collect();
        let mean_square = out.iter().map(|v| v * v).sum::<f64>() / out.len() as f64;
        mean_square / (white * weights.iter().map(|w| w * w).sum::<f64>())
    }

    /// The centres of every window of half width `h` over `n` samples.
    fn every_row(n: usize, h: usize) -> Vec<usize> {
        (h..n - h).collect()
    }

    #[test]
    fn the_share_matches_a_quantised_sine_through_the_kernels_slow_and_fast() {
        // 1 kHz averaged by 10 to 100 Hz, and 200 Hz by 2; a 0.43 s window; a 2 um and a
        // 7 um step; sines from a few steps a second to several steps a sample at their
        // fastest. Where the sine turns, the rod moves slower than a step a window.
        let diff = Differentiator::new(43);
        for (q, raw_dt, block) in [(0.002, 0.001, 10), (0.007, 0.005, 2)] {
            let quantisation = Quantisation {
                block,
                ..Quantisation::new(q, 0.0)
            };
            for (amplitude, hz) in [(0.05, 0.013), (0.5, 0.07), (5.0, 0.31)] {
                // A sine turns at the same two positions every cycle, so what passes at its
                // turns is one draw over where they fall on a step (on the middle sine 1.54
                // to 2.77 of white noise's share over eight offsets): the model is the mean
                // over them, and is compared with the mean over eight.
                let offsets: Vec<f64> = (0..8).map(|k| k as f64 / 8.0 * q).collect();
                let sines: Vec<_> = offsets
                    .iter()
                    .map(|&o| quantised_sine(amplitude, hz, q, raw_dt, block, o))
                    .collect();
                let (_, position, speed) = &sines[0];
                for kernel in [sg::VELOCITY, sg::ACCELERATION, sg::POSITION] {
                    let w = &diff.weights[kernel];
                    let model = trajectory_shares(
                        &[w],
                        position,
                        speed,
                        &spread_over(&every_row(position.len(), diff.half), 1024),
                        quantisation,
                        raw_dt * block as f64,
                    )
                    .expect("rows to sum")[0];
                    let measured = sines
                        .iter()
                        .map(|(error, _, _)| {
                            measured_share(w, error, quantisation.white_variance_mm2())
                        })
                        .sum::<f64>()
                        / sines.len() as f64;
                    // Summed along the sine, the speed sweeping through the aliases within a
                    // window is followed (a share at each sample's steady speed overstated
                    // the middle sines by up to half).
                    assert!(
                        (model / measured).ln().abs() <= 1.1_f64.ln(),
                        "step {q} mm, sine {amplitude} mm at {hz} Hz, kernel {kernel}: model \
                         {model}, measured {measured}"
                    );
                }
            }
        }
    }

    #[test]
    fn noise_before_the_steps_whitens_the_sawtooth_as_modelled() {
        // A rod creeping at 0.3 steps a sample (a 5 um step at 200 Hz) read with analog noise
        // of 0.2 steps before the steps: the sawtooth's harmonics lie inside the kernels'
        // band, so a noiseless quantiser's error passes many times white noise's share, and
        // the noise leaves its first harmonic a fifth of its power.
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let (q, dt, speed) = (0.005, 0.005, 0.3 * 0.005 / 0.005);
        let diff = Differentiator::new(43);
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let noise = Normal::new(0.0, 0.2 * q).unwrap();
        let n = 400_000;
        let position: Vec<f64> = (0..n).map(|i| 1.0 + speed * i as f64 * dt).collect();
        let error: Vec<f64> = position
            .iter()
            .map(|x| ((x + noise.sample(&mut rng)) / q).round() * q - x)
            .collect();
        let speeds = vec![speed; n];
        let rows = spread_over(&every_row(n, diff.half), 1024);
        let with = |dither_steps: f64| Quantisation::new(q, dither_steps);
        for kernel in [sg::POSITION, sg::VELOCITY, sg::ACCELERATION] {
            let w = &diff.weights[kernel];
            let measured = measured_share(w, &error, with(0.0).white_variance_mm2());
            let share = |dither: f64| {
                trajectory_shares(&[w], &position, &speeds, &rows, with(dither), dt)
                    .expect("rows to sum")[0]
            };
            let (model, noiseless) = (share(0.2), share(0.0));
            assert!(
                (model / measured).ln().abs() <= 1.15_f64.ln(),
                "kernel {kernel}: model {model}, measured {measured}"
            );
            // The noiseless model is far off: the test can tell the two apart.
            assert!(
                (noiseless / measured).ln().abs() >= 2.0_f64.ln(),
                "kernel {kernel}: noiseless model {noiseless}, measured {measured}"
            );
        }
    }

    #[test]
    fn a_rod_at_rest_passes_its_constant_error_through_the_position_kernel_alone() {
        // At rest the error is one constant: the derivative kernels pass only the white
        // remainder of the harmonics not summed (1.9 %), the position kernel the whole error,
        // q^2 / 12 against white noise's q^2 / 12 sum w^2.
        let diff = Differentiator::new(43);
        let q = Quantisation::new(0.01, 0.0);
        let n = 2000;
        let position = vec![3.0; n];
        let speed = vec![0.0; n];
        let kernels: Vec<&[f64]> = (0..4).map(|k| &diff.weights[k][..]).collect();
        let shares = trajectory_shares(
            &kernels,
            &position,
            &speed,
            &every_row(n, diff.half),
            q,
            0.01,
        )
        .expect("rows to sum");
        let tail =
            1.0 - 6.0 / (PI * PI) * (1..=HARMONICS).map(|h| 1.0 / (h * h) as f64).sum::<f64>();
        for k in [sg::VELOCITY, sg::ACCELERATION, sg::MOTION_VELOCITY] {
            assert!((shares[k] - tail).abs() < 1e-6, "kernel {k}: {}", shares[k]);
        }
        let power: f64 = diff.weights[sg::POSITION].iter().map(|w| w * w).sum();
        assert!(
            (shares[sg::POSITION] / (1.0 / power) - 1.0).abs() < 0.02,
            "position: {} against {}",
            shares[sg::POSITION],
            1.0 / power
        );
    }

    #[test]
    fn each_speed_class_takes_its_own_samples_shares() {
        // Half the log creeps (0.02 steps a sample: the harmonics inside the band), half
        // cruises (3.3 steps a sample): a sample of either takes its own half's shares, not
        // their mean.
        let diff = Differentiator::new(43);
        let q = Quantisation::new(0.006, 0.0);
        let (dt, n) = (0.01, 20_000);
        let (slow, fast) = (0.02 * 0.006 / dt, 3.3 * 0.006 / dt);
        let mut position = Vec::with_capacity(n);
        let mut speed = Vec::with_capacity(n);
        let mut x = 0.0;
        for i in 0..n {
            let v = if i < n / 2 { slow } else { fast };
            x += v * dt;
            position.push(x);
            speed.push(v);
        }
        let kernels: [&[f64]; SHARE_KERNELS] = [
            &diff.weights[0],
            &diff.weights[1],
            &diff.weights[2],
            &diff.weights[3],
            &diff.weights[1],
        ];
        // The rows whose windows lie wholly in one half.
        let slow_rows: Vec<usize> = (diff.half..n / 2 - diff.half).collect();
        let fast_rows: Vec<usize> = (n / 2 + diff.half..n - diff.half).collect();
        let rows = [slow_rows.clone(), fast_rows.clone()].concat();
        let row_speeds: Vec<f64> = rows.iter().map(|&r| speed[r]).collect();
        let table = SpeedShares::new(&kernels, &position, &speed, &rows, &row_speeds, q, dt);
        let own = |rows: &[usize]| {
            trajectory_shares(&kernels, &position, &speed, rows, q, dt).expect("rows")
        };
        let (slow_own, fast_own) = (own(&slow_rows), own(&fast_rows));
        for k in [sg::VELOCITY, sg::ACCELERATION] {
            let (at_slow, at_fast) = (table.at(slow)[k], table.at(fast)[k]);
            assert!(
                (at_slow / slow_own[k] - 1.0).abs() < 0.05,
                "{k}: {at_slow} {slow_own:?}"
            );
            assert!(
                (at_fast / fast_own[k] - 1.0).abs() < 0.05,
                "{k}: {at_fast} {fast_own:?}"
            );
            // The two differ by far more than the tolerance: the test tells them apart.
            assert!(
                (at_slow / at_fast).ln().abs() > 2.0_f64.ln(),
                "{k}: {at_slow} {at_fast}"
            );
        }
        // Samples take their class's shares; a class none of the log's samples fell in (here
        // rest) takes the nearest one's.
        let shares = RowShares::new(table, &[0.0, slow, fast]);
        for k in 0..SHARE_KERNELS {
            assert_eq!(shares.share(1, k), table.at(slow)[k]);
            assert_eq!(shares.share(2, k), table.at(fast)[k]);
            assert_eq!(shares.share(0, k), table.at(slow)[k]);
        }
    }
}
