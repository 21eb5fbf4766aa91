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
//! [`kernel_shares`] is that share for each kernel, from the speeds the log moves at: the
//! sawtooth's harmonics at each speed, through the block mean identification reduces a fast
//! log by and the kernel, against white noise of variance q^2 / 12 through the same. Against
//! the rig's true error it came within 5 to 15 %; against sines read in steps (the speed
//! sweeping through every alias) within a factor 1.5.

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
    /// What identification's kernels at one window pass of the error, as shares of white
    /// noise of the uniform error's variance (position, velocity, acceleration, motion
    /// velocity, the parallel filter's velocity), once worked out for that window; `None`:
    /// worked out at each fit.
    pub kernel_shares: Option<[f64; 5]>,
}

impl Quantisation {
    /// The variance (mm^2, per sample identification fits) of white noise with the uniform
    /// error's power, q^2 / 12 of a logged sample averaged over the block: the reference the
    /// kernels' shares are taken against.
    pub fn white_variance_mm2(&self) -> f64 {
        self.variance_scale * self.step_mm * self.step_mm / 12.0 / self.block.max(1) as f64
    }
}

/// Harmonics of the sawtooth summed exactly; the rest (a share 6 / (pi^2 N) of its power,
/// 0.2 %) are counted as white noise.
pub const HARMONICS: usize = 256;

/// Points of the kernel's power response tabulated over [0, pi] (linear interpolation).
pub const RESPONSE_POINTS: usize = 2048;

/// Speed classes (logarithmic) the moving samples are counted in, each taken at its samples'
/// mean speed. Where the sawtooth's harmonics alias, the share swings with the speed: a class
/// spans a part in a thousand of a speed range of four decades, so an alias moves by a few
/// hundredths of the band across one at ten steps a sample. A motion controller's cruise
/// speed, held for whole moves, falls into one class and is taken at its own value.
pub const SPEED_CLASSES: usize = 2048;

/// The shares, relative to white noise of the uniform error's variance, of the quantisation
/// error's power that each of `kernels` (at the fitted samples' spacing `dt_s`, unit sample
/// spacing as in [`super::sg::Differentiator`]) passes, averaged over the samples moving at
/// `speeds_mm_s` (their absolute values are used; zero speeds pass nothing). 1 for an empty
/// set of speeds or a kernel of no power. The harmonics' frequencies and the block mean's
/// response are computed once for all the kernels.
pub fn kernel_shares(
    kernels: &[&[f64]],
    speeds_mm_s: &[f64],
    q: Quantisation,
    dt_s: f64,
) -> Vec<f64> {
    let moving: Vec<f64> = speeds_mm_s
        .iter()
        .map(|v| v.abs())
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    let powers: Vec<f64> = kernels
        .iter()
        .map(|w| w.iter().map(|c| c * c).sum())
        .collect();
    if moving.is_empty() || q.step_mm.is_nan() || q.step_mm <= 0.0 {
        return vec![1.0; kernels.len()];
    }
    let block = q.block.max(1);
    let b = block as f64;
    // |H(w)|^2 of each kernel at the fitted samples' frequency w in [0, pi]; e^{-i w k} by
    // rotation, renormalised each sample.
    let step = PI / (RESPONSE_POINTS - 1) as f64;
    let responses: Vec<Vec<f64>> = kernels
        .iter()
        .map(|weights| {
            (0..RESPONSE_POINTS)
                .map(|j| {
                    let w = j as f64 * step;
                    let (rot_re, rot_im) = (w.cos(), -w.sin());
                    let (mut z_re, mut z_im) = (1.0, 0.0);
                    let (mut re, mut im) = (0.0, 0.0);
                    for c in weights.iter() {
                        re += c * z_re;
                        im += c * z_im;
                        (z_re, z_im) =
                            (z_re * rot_re - z_im * rot_im, z_re * rot_im + z_im * rot_re);
                    }
                    re * re + im * im
                })
                .collect()
        })
        .collect();
    let raw_dt = dt_s / b;
    // Analog noise of s steps before the steps leaves harmonic n of the sawtooth (its mean
    // over the noise) exp(-2 pi^2 n^2 s^2) of its amplitude; the power it loses, the
    // harmonics beyond the last summed, and the noise's own s^2 steps^2 are white.
    let dither = q.dither_steps.max(0.0);
    let kept: Vec<f64> = (1..=HARMONICS)
        .map(|n| (-4.0 * PI * PI * (n * n) as f64 * dither * dither).exp())
        .collect();
    let tail = 1.0
        - 6.0 / (PI * PI)
            * (1..=HARMONICS)
                .zip(&kept)
                .map(|(n, k)| k / (n * n) as f64)
                .sum::<f64>()
        + 12.0 * dither * dither;
    // Each kernel's passed power over the white reference (power / b: white noise of the
    // logged samples' variance through the block mean and the kernel), at one speed.
    let shares_at = |v: f64, out: &mut [f64]| {
        let cycles = v / q.step_mm * raw_dt;
        out.iter_mut().for_each(|o| *o = 0.0);
        for (n, kept) in (1..=HARMONICS).zip(&kept) {
            let n = n as f64;
            // The harmonic at the logged samples' frequency, folded into [0, 2 pi).
            let w = (2.0 * PI * n * cycles).rem_euclid(2.0 * PI);
            let half = 0.5 * w;
            let box2 = if block == 1 || half.sin().abs() < 1e-12 {
                1.0
            } else {
                ((b * half).sin() / (b * half.sin())).powi(2)
            };
            // The kernel at b w, folded into [0, pi] (even and 2 pi periodic).
            let k = (b * w).rem_euclid(2.0 * PI);
            let k = if k > PI { 2.0 * PI - k } else { k };
            let x = k / step;
            let i = (x.floor() as usize).min(RESPONSE_POINTS - 2);
            let f = x - i as f64;
            let weight = 6.0 / (PI * PI * n * n) * box2 * kept;
            for (o, r) in out.iter_mut().zip(&responses) {
                *o += weight * (r[i] * (1.0 - f) + r[i + 1] * f);
            }
        }
        for (o, p) in out.iter_mut().zip(&powers) {
            *o = if *p > 0.0 { *o / (p / b) + tail } else { 1.0 };
        }
    };
    // Speeds counted in logarithmic classes, each taken at its samples' mean speed.
    let (lo, hi) = moving
        .iter()
        .fold((f64::INFINITY, 0.0_f64), |(a, b), &v| (a.min(v), b.max(v)));
    let span = (hi / lo).ln().max(1e-12);
    let mut classes = vec![(0usize, 0.0_f64); SPEED_CLASSES];
    for v in &moving {
        let c = ((v / lo).ln() / span * SPEED_CLASSES as f64) as usize;
        let class = &mut classes[c.min(SPEED_CLASSES - 1)];
        class.0 += 1;
        class.1 += v;
    }
    let mut total = vec![0.0; kernels.len()];
    let mut at = vec![0.0; kernels.len()];
    for &(count, sum) in classes.iter().filter(|(count, _)| *count > 0) {
        shares_at(sum / count as f64, &mut at);
        for (t, a) in total.iter_mut().zip(&at) {
            *t += count as f64 * a;
        }
    }
    total.iter().map(|t| t / moving.len() as f64).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::sg::{self, Differentiator};

    /// A sine of `amplitude` (mm) at `hz` read in steps `q`, block-averaged: the block means'
    /// quantisation error and the block-mean speeds.
    fn quantised_sine(
        amplitude: f64,
        hz: f64,
        q: f64,
        raw_dt: f64,
        block: usize,
    ) -> (Vec<f64>, Vec<f64>) {
        let n = 600_000;
        let w = 2.0 * PI * hz;
        let (error, speed): (Vec<f64>, Vec<f64>) = (0..n)
            .map(|i| {
                let t = i as f64 * raw_dt;
                let x = 7.0 + amplitude * (w * t).sin();
                ((x / q).round() * q - x, amplitude * w * (w * t).cos())
            })
            .unzip();
        let mean = |c: &[f64]| c.iter().sum::<f64>() / block as f64;
        (
            error.chunks_exact(block).map(mean).collect(),
            speed.chunks_exact(block).map(mean).collect(),
        )
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

    #[test]
    fn the_share_matches_a_quantised_sine_through_the_kernels_slow_and_fast() {
        // 1 kHz averaged by 10 to 100 Hz, and 200 Hz by 2; a 0.43 s window; a 2 um and a
        // 7 um step; sines from a few steps a second to several steps a sample at their
        // fastest. Where the sine turns, the rod moves slower than a step a window.
        let diff = Differentiator::new(43);
        for (q, raw_dt, block) in [(0.002, 0.001, 10), (0.007, 0.005, 2)] {
            let quantisation = Quantisation {
                step_mm: q,
                dither_steps: 0.0,
                block,
                variance_scale: 1.0,
                kernel_shares: None,
            };
            for (amplitude, hz) in [(0.05, 0.013), (0.5, 0.07), (5.0, 0.31)] {
                let (error, speed) = quantised_sine(amplitude, hz, q, raw_dt, block);
                for kernel in [sg::VELOCITY, sg::ACCELERATION, sg::POSITION] {
                    let w = &diff.weights[kernel];
                    let h = diff.half;
                    let model = kernel_shares(
                        &[w],
                        &speed[h..speed.len() - h],
                        quantisation,
                        raw_dt * block as f64,
                    )[0];
                    let measured = measured_share(w, &error, quantisation.white_variance_mm2());
                    // Where the speed sweeps through the aliases (the middle sines), the
                    // model sums the harmonics' powers where the sampled sawtooth's
                    // interfere, and overstates what passes by up to half.
                    assert!(
                        (model / measured).ln().abs() <= 1.6_f64.ln(),
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
        let error: Vec<f64> = (0..400_000)
            .map(|i| {
                let x = 1.0 + speed * i as f64 * dt;
                ((x + noise.sample(&mut rng)) / q).round() * q - x
            })
            .collect();
        let speeds = vec![speed; 1000];
        let with = |dither_steps: f64| Quantisation {
            step_mm: q,
            dither_steps,
            block: 1,
            variance_scale: 1.0,
            kernel_shares: None,
        };
        for kernel in [sg::POSITION, sg::VELOCITY, sg::ACCELERATION] {
            let w = &diff.weights[kernel];
            let measured = measured_share(w, &error, with(0.0).white_variance_mm2());
            let model = kernel_shares(&[w], &speeds, with(0.2), dt)[0];
            let noiseless = kernel_shares(&[w], &speeds, with(0.0), dt)[0];
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
}
