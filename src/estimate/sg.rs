//! Savitzky-Golay smoothing differentiators: position, velocity and acceleration from local
//! least-squares polynomials (quintic) over a sliding window.
//!
//! Identification chooses its window from the data ([`super::window`]); the EKF's force rate
//! uses [`window_for_rate`], about 0.4 s of data
//! (41 samples at 100 Hz). That is long enough to average the position noise of the paper's
//! encoder (0.01 mm^2) into usable accelerations, and short enough to follow motions up to
//! about 0.5 Hz with a bias of the second derivative below 1 %.
//!
//! Identification uses four kernels whose noise is mutually independent ([`Differentiator`]):
//! the position is fitted to the window's odd offsets and the acceleration to its even offsets
//! (disjoint samples); the velocity regressor is the derivative fitted to the even offsets
//! (antisymmetric, so uncorrelated with the symmetric acceleration kernel on the same samples);
//! and the velocity that decides which samples move and their friction sign is the derivative
//! fitted to the odd offsets. With one shared kernel set the smoothed position and
//! acceleration would share noisy samples, which through the spring's stiffness biases the
//! inertia by many standard deviations; and choosing samples by the same noisy velocity that
//! enters the regression biases d0, d1 and d2. A fifth kernel, the derivative over the whole
//! window, gives the force rate (lowest noise; it is not a regressor).

use nalgebra::DMatrix;

/// Window span in seconds used by [`window_for_rate`].
pub const WINDOW_SECONDS: f64 = 0.4;

/// Polynomial order of the position filter.
pub const ORDER: usize = 5;

/// Polynomial order of the velocity and acceleration filters.
pub const ORDER_DERIVATIVES: usize = 5;

/// An odd window length of about [`WINDOW_SECONDS`] at `rate_hz`, at least [`MIN_WINDOW`]
/// samples.
pub fn window_for_rate(rate_hz: f64) -> usize {
    window_of(WINDOW_SECONDS, rate_hz)
}

/// An odd window length of about `seconds` at `rate_hz`, at least [`MIN_WINDOW`] samples.
pub fn window_of(seconds: f64, rate_hz: f64) -> usize {
    let n = (seconds * rate_hz).round().clamp(0.0, 1e6) as usize;
    (n | 1).max(MIN_WINDOW)
}

/// The shortest window (samples) the quintic kernels take: each of the odd and the even
/// offsets must hold at least six samples (a 13-sample window has 6 odd and 7 even offsets; an
/// 11-sample window has only 5 even ones, which a quintic cannot be fitted to).
pub const MIN_WINDOW: usize = 13;

/// Weights (per sample, unit spacing) of the `deriv`-th derivative at offset 0 of a polynomial
/// of `order` fitted by least squares to the samples at `offsets`; zero elsewhere in a window
/// of half width `half`.
///
/// The polynomial is fitted in the offset over the half width, so the normal matrix stays well
/// conditioned for any window length (in raw offsets its entries would span up to 10 powers of
/// the half width). Needs at least `order + 1` distinct offsets within `half`, which
/// [`MIN_WINDOW`] guarantees for every kernel of [`Differentiator`].
/// The quintic smoother over every sample of a window of `2 half + 1` (the value at offset 0
/// of the least-squares quintic), for a signal's motion where every sample's noise is to be
/// averaged (identification's [`POSITION`] kernel takes the odd offsets only).
pub fn quintic_smoother(half: usize) -> Vec<f64> {
    let h = half.max(MIN_WINDOW / 2) as i64;
    let all: Vec<i64> = (-h..=h).collect();
    kernel(h as usize, &all, ORDER, 0)
}

/// `y` through a centred `kernel` of odd length, for the samples whose whole window lies
/// inside the data (indices half .. n - half, as [`Differentiator::apply`]).
pub fn smooth(y: &[f64], kernel: &[f64]) -> Vec<f64> {
    let h = kernel.len() / 2;
    if kernel.is_empty() || y.len() < 2 * h + 1 {
        return Vec::new();
    }
    if kernel.len() >= FFT_MIN_TAPS {
        return correlate_by_fft(y, &[kernel]).swap_remove(0);
    }
    y.windows(2 * h + 1)
        .map(|w| w.iter().zip(kernel).map(|(a, b)| a * b).sum())
        .collect()
}

/// Kernels of at least this many samples are applied by FFT ([`correlate_by_fft`]): a
/// direct sum costs a product per weight and output, the FFT a few dozen operations per
/// output whatever the kernel's length. Windows of identification at 1 kHz reach thousands
/// of samples, and their direct sums were a quarter of `validate`'s time on such logs.
pub const FFT_MIN_TAPS: usize = 128;

/// Each of `kernels` (one odd length, centred) applied to `y` at every sample whose whole
/// window lies inside the data: `out[k][c - h] = sum_j kernels[k][j] y[c - h + j]` for c in
/// h .. n - h, the sums [`Differentiator::apply`] and [`smooth`] take term by term.
///
/// Overlap-save: blocks of a power-of-two FFT at least eight kernels long, each block's
/// spectrum computed once and multiplied by every kernel's. The data's mean is taken out
/// before and put back after (times the kernel's sum), so the rounding error scales with the
/// signal's variation, not with its offset: a position logged around 100 mm keeps the digits
/// of its millimetre moves. The result differs from the direct sum by rounding only (about
/// 1e-15 of the kernel's norm times the signal's range; the tests below bound it).
pub fn correlate_by_fft(y: &[f64], kernels: &[&[f64]]) -> Vec<Vec<f64>> {
    use realfft::num_complex::Complex;
    let taps = kernels.first().map_or(0, |k| k.len());
    let n = y.len();
    if taps == 0 || n < taps {
        return vec![Vec::new(); kernels.len()];
    }
    let outputs = n - taps + 1;
    // The FFT's length: eight kernels or more, but no longer than the whole data needs.
    let size = (8 * taps)
        .max(1024)
        .min((n + taps).next_power_of_two())
        .next_power_of_two();
    let step = size - taps + 1;
    let mut planner = realfft::RealFftPlanner::<f64>::new();
    let forward = planner.plan_fft_forward(size);
    let inverse = planner.plan_fft_inverse(size);
    let mean = y.iter().sum::<f64>() / n as f64;
    // Each kernel reversed (a correlation is a convolution with the reversed kernel), padded,
    // transformed, and scaled by the inverse's 1 / size.
    let spectra: Vec<Vec<Complex<f64>>> = kernels
        .iter()
        .map(|k| {
            let mut padded = forward.make_input_vec();
            for (slot, w) in padded.iter_mut().zip(k.iter().rev()) {
                *slot = w / size as f64;
            }
            let mut spectrum = forward.make_output_vec();
            forward
                .process(&mut padded, &mut spectrum)
                .expect("buffers made by the plan");
            spectrum
        })
        .collect();
    let sums: Vec<f64> = kernels.iter().map(|k| k.iter().sum::<f64>()).collect();
    let mut out: Vec<Vec<f64>> = kernels
        .iter()
        .map(|_| Vec::with_capacity(outputs))
        .collect();
    let mut block = forward.make_input_vec();
    let mut spectrum = forward.make_output_vec();
    let mut product = forward.make_output_vec();
    let mut result = inverse.make_output_vec();
    let mut start = 0;
    while start < outputs {
        for (i, slot) in block.iter_mut().enumerate() {
            *slot = y.get(start + i).map_or(0.0, |v| v - mean);
        }
        forward
            .process(&mut block, &mut spectrum)
            .expect("buffers made by the plan");
        let count = step.min(outputs - start);
        for ((kernel_spectrum, o), sum) in spectra.iter().zip(out.iter_mut()).zip(&sums) {
            for ((p, a), b) in product.iter_mut().zip(&spectrum).zip(kernel_spectrum) {
                *p = a * b;
            }
            // The inverse of a real signal's spectrum has no imaginary part at 0 and at the
            // Nyquist frequency; rounding leaves a trace there, which the inverse refuses.
            product[0].im = 0.0;
            product[size / 2].im = 0.0;
            inverse
                .process(&mut product, &mut result)
                .expect("buffers made by the plan");
            o.extend(
                result[taps - 1..taps - 1 + count]
                    .iter()
                    .map(|v| v + mean * sum),
            );
        }
        start += step;
    }
    out
}

fn kernel(half: usize, offsets: &[i64], order: usize, deriv: usize) -> Vec<f64> {
    let scale = half.max(1) as f64;
    let a = DMatrix::from_fn(offsets.len(), order + 1, |i, j| {
        (offsets[i] as f64 / scale).powi(j as i32)
    });
    let ata = a.transpose() * &a;
    // The normal matrix of at least order + 1 distinct points is positive definite.
    let pinv = ata
        .cholesky()
        .expect("a polynomial kernel needs order + 1 distinct offsets (MIN_WINDOW)")
        .inverse()
        * a.transpose();
    let factorial = (1..=deriv).product::<usize>() as f64;
    let mut w = vec![0.0; 2 * half + 1];
    for (i, &o) in offsets.iter().enumerate() {
        w[(o + half as i64) as usize] = pinv[(deriv, i)] * factorial / scale.powi(deriv as i32);
    }
    w
}

/// Kernel index: position (odd offsets).
pub const POSITION: usize = 0;
/// Kernel index: velocity regressor (even offsets).
pub const VELOCITY: usize = 1;
/// Kernel index: acceleration (even offsets).
pub const ACCELERATION: usize = 2;
/// Kernel index: velocity for motion detection and friction sign (odd offsets).
pub const MOTION_VELOCITY: usize = 3;
/// Kernel index: derivative over the whole window (force rate).
pub const RATE: usize = 4;

/// A log's position smoothed and differentiated with the default kernels for its rate
/// ([`Differentiator::for_rate`]), and the sign of its velocity where that lies beyond three
/// standard deviations of the velocity's noise (0 within): what the regressions on the
/// quasi-static curve and on the encoder zero take the rod's dynamics and friction from.
/// Sample i belongs to the log's sample `half + i`.
#[derive(Debug, Clone)]
pub struct DefaultMotion {
    /// Smoothed position (mm).
    pub x: Vec<f64>,
    /// Velocity (mm/s).
    pub xd: Vec<f64>,
    /// Acceleration (mm/s^2).
    pub xdd: Vec<f64>,
    /// The velocity's sign beyond its noise band, else 0.
    pub sgn: Vec<f64>,
    /// The kernels' half window: the log's samples before the first smoothed one.
    pub half: usize,
}

/// [`DefaultMotion`] of positions `position_mm` sampled every `dt` seconds, read with noise of
/// variance `position_variance_mm2`.
pub fn default_motion(position_mm: &[f64], dt: f64, position_variance_mm2: f64) -> DefaultMotion {
    let diff = Differentiator::for_rate(1.0 / dt);
    let xd = diff.apply(position_mm, dt, VELOCITY);
    let band = 3.0
        * diff
            .noise_variance(VELOCITY, position_variance_mm2, dt)
            .sqrt();
    let sgn = xd
        .iter()
        .map(|&v| {
            if v > band {
                1.0
            } else if v < -band {
                -1.0
            } else {
                0.0
            }
        })
        .collect();
    DefaultMotion {
        x: diff.apply(position_mm, dt, POSITION),
        xdd: diff.apply(position_mm, dt, ACCELERATION),
        xd,
        sgn,
        half: diff.half,
    }
}

/// The five kernels; see the module documentation.
#[derive(Debug, Clone)]
pub struct Differentiator {
    /// Half width: the window is 2*half + 1 samples.
    pub half: usize,
    /// Weights of [`POSITION`], [`VELOCITY`], [`ACCELERATION`], [`MOTION_VELOCITY`] and
    /// [`RATE`] (unit sample spacing).
    pub weights: [Vec<f64>; 5],
}

impl Differentiator {
    /// The differentiator over `window` samples (odd, at least [`MIN_WINDOW`]) with quintic
    /// polynomials.
    pub fn new(window: usize) -> Differentiator {
        let half = (window.max(MIN_WINDOW)) / 2;
        let h = half as i64;
        let all: Vec<i64> = (-h..=h).collect();
        let odd: Vec<i64> = all.iter().copied().filter(|o| o % 2 != 0).collect();
        let even: Vec<i64> = all.iter().copied().filter(|o| o % 2 == 0).collect();
        Differentiator {
            half,
            weights: [
                kernel(half, &odd, ORDER, 0),
                kernel(half, &even, ORDER_DERIVATIVES, 1),
                kernel(half, &even, ORDER_DERIVATIVES, 2),
                kernel(half, &odd, ORDER_DERIVATIVES, 1),
                kernel(half, &all, ORDER_DERIVATIVES, 1),
            ],
        }
    }

    /// The differentiator for a sampling rate ([`window_for_rate`]).
    pub fn for_rate(rate_hz: f64) -> Differentiator {
        Differentiator::new(window_for_rate(rate_hz))
    }

    /// Window length in samples.
    pub fn window(&self) -> usize {
        2 * self.half + 1
    }

    /// Output of kernel `k` (see the index constants) of `y` sampled every `dt`, for the
    /// samples whose whole window lies inside the data (indices half .. n - half).
    pub fn apply(&self, y: &[f64], dt: f64, k: usize) -> Vec<f64> {
        let n = y.len();
        let h = self.half;
        if n < 2 * h + 1 {
            return Vec::new();
        }
        self.apply_each(y, dt, &[k]).swap_remove(0)
    }

    /// [`Differentiator::apply`] of each kernel in `ks` to the same `y`: a long window's
    /// kernels share one FFT of each block of the data ([`correlate_by_fft`]).
    pub fn apply_each(&self, y: &[f64], dt: f64, ks: &[usize]) -> Vec<Vec<f64>> {
        let n = y.len();
        let h = self.half;
        if n < 2 * h + 1 {
            return vec![Vec::new(); ks.len()];
        }
        if self.window() >= FFT_MIN_TAPS {
            let kernels: Vec<&[f64]> = ks.iter().map(|&k| self.weights[k].as_slice()).collect();
            let mut out = correlate_by_fft(y, &kernels);
            for (o, &k) in out.iter_mut().zip(ks) {
                let scale = 1.0 / dt.powi(Self::order(k));
                o.iter_mut().for_each(|v| *v *= scale);
            }
            return out;
        }
        ks.iter()
            .map(|&k| {
                let scale = 1.0 / dt.powi(Self::order(k));
                let (w, taps) = (&self.weights[k], self.taps(k));
                (h..n - h)
                    .map(|c| strided_sum(w, taps, &y[c - h..=c + h], 1) * scale)
                    .collect()
            })
            .collect()
    }

    /// Where kernel `k`'s weights may be nonzero: every `stride`-th from index `first`. The
    /// kernels on odd or even offsets are zero at every other sample, and a sum that skips
    /// those products is the same sum in half the time.
    pub fn taps(&self, k: usize) -> (usize, usize) {
        let h = self.half;
        match k {
            RATE => (0, 1),
            POSITION | MOTION_VELOCITY => (1 - h % 2, 2),
            _ => (h % 2, 2),
        }
    }

    /// Variance of output `k` for white input noise of variance `var` sampled every `dt`.
    pub fn noise_variance(&self, k: usize, var: f64, dt: f64) -> f64 {
        var * self.weights[k].iter().map(|w| w * w).sum::<f64>() / dt.powi(2 * Self::order(k))
    }

    /// Variance, for white input noise of variance `var` sampled every `dt`, of `smoother`
    /// (weights at consecutive samples, centred) applied to output `k`: the noise of a
    /// regressor filtered in parallel with the force.
    pub fn smoothed_noise_variance(&self, k: usize, smoother: &[f64], var: f64, dt: f64) -> f64 {
        let w = &self.weights[k];
        let mut combined = vec![0.0; w.len() + smoother.len() - 1];
        for (j, q) in smoother.iter().enumerate() {
            for (i, wi) in w.iter().enumerate() {
                combined[i + j] += q * wi;
            }
        }
        var * combined.iter().map(|v| v * v).sum::<f64>() / dt.powi(2 * Self::order(k))
    }

    /// Derivative order of kernel `k`.
    fn order(k: usize) -> i32 {
        match k {
            POSITION => 0,
            ACCELERATION => 2,
            _ => 1,
        }
    }
}

/// The last `span` values of a stream, oldest first, as one contiguous slice: each value is
/// kept twice in a buffer of two spans, so a streaming kernel reads a plain slice rather than
/// a ring's wrapped indices.
#[derive(Debug, Clone)]
pub struct SlidingWindow {
    buf: Vec<f64>,
    span: usize,
    next: usize,
    len: usize,
}

impl SlidingWindow {
    /// An empty window of `span` values (at least one).
    pub fn new(span: usize) -> SlidingWindow {
        let span = span.max(1);
        SlidingWindow {
            buf: vec![0.0; 2 * span],
            span,
            next: 0,
            len: 0,
        }
    }

    /// Appends `value`, dropping the oldest once the window is full.
    pub fn push(&mut self, value: f64) {
        self.buf[self.next] = value;
        self.buf[self.next + self.span] = value;
        self.next = (self.next + 1) % self.span;
        self.len = (self.len + 1).min(self.span);
    }

    /// How many values the window holds.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether the window holds nothing yet.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The values held, oldest first.
    pub fn values(&self) -> &[f64] {
        &self.buf[self.next + self.span - self.len..self.next + self.span]
    }
}

/// The least-squares polynomial of [`ORDER`] through one window of a record (every
/// `stride`-th sample, centred), kept as coefficients so that it can be read anywhere in the
/// window, not only at its centre.
///
/// A streamed record's first and last half window have no window centred on them. They take
/// the fit of the first and of the last window at their own offsets, Savitzky-Golay's usual
/// treatment of a record's ends. The centre's value held over the half window instead is a
/// position that stands still: on a slow run with a window of two seconds it was a millimetre
/// off at the record's start, enough to read the friction's sign wrong there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WindowFit {
    /// Coefficients of u^0 ..= u^ORDER, with u the offset (samples) over `scale`.
    coefficients: [f64; ORDER + 1],
    /// Half the window (samples).
    scale: f64,
}

impl WindowFit {
    /// The fit to `values` (oldest first, an odd count whose half is a multiple of `stride`),
    /// read at every `stride`-th value from the first. None where the window holds fewer than
    /// [`ORDER`] + 1 points or is not centred.
    pub fn new(values: &[f64], stride: usize) -> Option<WindowFit> {
        let stride = stride.max(1);
        let n = values.len();
        let centre = n.checked_sub(1)? / 2;
        if n.is_multiple_of(2) || !centre.is_multiple_of(stride) {
            return None;
        }
        let points = n.div_ceil(stride);
        if points < ORDER + 1 {
            return None;
        }
        let scale = centre.max(1) as f64;
        let a = DMatrix::from_fn(points, ORDER + 1, |i, j| {
            ((i * stride) as f64 / scale - centre as f64 / scale).powi(j as i32)
        });
        let b = DMatrix::from_fn(points, 1, |i, _| values[i * stride]);
        let solution = (a.transpose() * &a).cholesky()?.solve(&(a.transpose() * b));
        let mut coefficients = [0.0; ORDER + 1];
        for (c, v) in coefficients.iter_mut().zip(solution.iter()) {
            *c = *v;
        }
        coefficients
            .iter()
            .all(|c| c.is_finite())
            .then_some(WindowFit {
                coefficients,
                scale,
            })
    }

    /// The fitted value at `offset` samples from the window's centre.
    pub fn value(&self, offset: f64) -> f64 {
        self.motion(offset, 1.0)[0]
    }

    /// The fitted value, its first and its second derivative in time at `offset` samples from
    /// the window's centre, for samples `dt` apart.
    pub fn motion(&self, offset: f64, dt: f64) -> [f64; 3] {
        let u = offset / self.scale;
        // Horner's rule for the polynomial p, p' and p'' / 2 in u.
        let (mut p, mut dp, mut half_ddp) = (0.0, 0.0, 0.0);
        for &c in self.coefficients.iter().rev() {
            half_ddp = half_ddp * u + dp;
            dp = dp * u + p;
            p = p * u + c;
        }
        let per_time = 1.0 / (self.scale * dt);
        [p, dp * per_time, 2.0 * half_ddp * per_time * per_time]
    }
}

/// Kernel `k`'s weights `w` (every `taps`-th from its first, [`Differentiator::taps`]) against
/// every `stride`-th value of `values` (oldest first): the same sum as over all weights.
pub fn strided_sum(w: &[f64], (first, step): (usize, usize), values: &[f64], stride: usize) -> f64 {
    w[first..]
        .iter()
        .step_by(step)
        .zip(values[first * stride..].iter().step_by(step * stride))
        .map(|(a, b)| a * b)
        .sum::<f64>()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_fit_reads_a_quintic_exactly_anywhere_in_the_window() {
        // x(t) = 1 + 2t - 3t^2 + 0.5t^3 - 0.2t^4 + 0.05t^5, sampled every 0.01 s; the window
        // of 201 samples read at every 4th, centred on t = 1.
        let dt = 0.01;
        let x = |t: f64| {
            1.0 + 2.0 * t - 3.0 * t * t + 0.5 * t.powi(3) - 0.2 * t.powi(4) + 0.05 * t.powi(5)
        };
        let v = |t: f64| 2.0 - 6.0 * t + 1.5 * t * t - 0.8 * t.powi(3) + 0.25 * t.powi(4);
        let a = |t: f64| -6.0 + 3.0 * t - 2.4 * t * t + t.powi(3);
        let values: Vec<f64> = (0..201).map(|i| x(i as f64 * dt)).collect();
        let fit = WindowFit::new(&values, 4).expect("a centred window of 51 points");
        for offset in [-100.0, -73.0, -1.0, 0.0, 37.5, 100.0] {
            let t = 1.0 + offset * dt;
            let [xf, vf, af] = fit.motion(offset, dt);
            assert!((xf - x(t)).abs() < 1e-9, "x at {offset}: {xf} vs {}", x(t));
            assert!((vf - v(t)).abs() < 1e-7, "v at {offset}: {vf} vs {}", v(t));
            assert!((af - a(t)).abs() < 1e-5, "a at {offset}: {af} vs {}", a(t));
            assert_eq!(fit.value(offset), xf);
        }
        // Not centred on a strided point, an even count, or too few points: no fit.
        assert!(WindowFit::new(&values[..199], 4).is_none());
        assert!(WindowFit::new(&values[..200], 1).is_none());
        assert!(WindowFit::new(&values[..9], 2).is_none());
    }

    #[test]
    fn kernels_are_exact_on_cubics() {
        let d = Differentiator::new(21);
        let dt = 0.01;
        let f = |t: f64| 2.0 + 3.0 * t - 4.0 * t * t + 0.5 * t * t * t;
        let y: Vec<f64> = (0..200).map(|i| f(i as f64 * dt)).collect();
        let t = (50 + d.half) as f64 * dt;
        assert!((d.apply(&y, dt, POSITION)[50] - f(t)).abs() < 1e-9);
        for k in [VELOCITY, MOTION_VELOCITY, RATE] {
            assert!((d.apply(&y, dt, k)[50] - (3.0 - 8.0 * t + 1.5 * t * t)).abs() < 1e-7);
        }
        assert!((d.apply(&y, dt, ACCELERATION)[50] - (-8.0 + 3.0 * t)).abs() < 1e-5);
    }

    #[test]
    fn every_window_from_the_shortest_differentiates_a_quintic_exactly() {
        // A quintic is inside every kernel's polynomial space, so each kernel returns its
        // value or derivative exactly, from the shortest window (whose odd and even offsets
        // just hold a quintic) to one of 200 001 samples (whose raw-offset normal matrix
        // would span 10^53).
        let dt = 0.01;
        for window in (MIN_WINDOW..=41).step_by(2).chain([1001, 200_001]) {
            let d = Differentiator::new(window);
            assert_eq!(d.window(), window);
            let h = d.half as f64;
            // Scaled to the window so every term matters across it.
            let u = |t: f64| (t - h * dt) / (h * dt);
            let f = |t: f64| {
                let x = u(t);
                1.0 + 2.0 * x - 3.0 * x.powi(2) + 0.5 * x.powi(3) + 1.5 * x.powi(4) - x.powi(5)
            };
            let df = |t: f64| {
                let x = u(t);
                (2.0 - 6.0 * x + 1.5 * x * x + 6.0 * x.powi(3) - 5.0 * x.powi(4)) / (h * dt)
            };
            let d2f = |t: f64| {
                let x = u(t);
                (-6.0 + 3.0 * x + 18.0 * x * x - 20.0 * x.powi(3)) / (h * dt).powi(2)
            };
            let n = d.window() + 4;
            let y: Vec<f64> = (0..n).map(|i| f(i as f64 * dt)).collect();
            for c in 0..5 {
                let t = (c as f64 + h) * dt;
                let pos = d.apply(&y, dt, POSITION)[c];
                assert!(
                    (pos - f(t)).abs() < 1e-7,
                    "{window} position {pos} {}",
                    f(t)
                );
                for k in [VELOCITY, MOTION_VELOCITY, RATE] {
                    let v = d.apply(&y, dt, k)[c];
                    let tol = 1e-6 * df(t).abs().max(1.0 / (h * dt));
                    assert!(
                        (v - df(t)).abs() < tol,
                        "{window} kernel {k}: {v} {}",
                        df(t)
                    );
                }
                let a = d.apply(&y, dt, ACCELERATION)[c];
                let tol = 1e-5 * d2f(t).abs().max(1.0 / (h * dt).powi(2));
                assert!(
                    (a - d2f(t)).abs() < tol,
                    "{window} acceleration {a} {}",
                    d2f(t)
                );
            }
        }
    }

    #[test]
    fn kernels_have_uncorrelated_noise() {
        let d = Differentiator::new(41);
        // Every pair used together in identification is uncorrelated (hence independent for
        // Gaussian noise): position, velocity, acceleration and the motion velocity.
        for (a, b) in [(0, 1), (0, 2), (1, 2), (0, 3), (1, 3), (2, 3)] {
            let dot: f64 = d.weights[a]
                .iter()
                .zip(&d.weights[b])
                .map(|(x, y)| x * y)
                .sum();
            assert!(dot.abs() < 1e-12, "kernels {a} and {b}: {dot}");
        }
    }

    #[test]
    fn the_strided_sum_skips_only_zero_weights() {
        // Windows with an even and an odd half width: every skipped weight is zero, and the
        // output is the full convolution's.
        let y: Vec<f64> = (0..300)
            .map(|i| (i as f64 * 0.37).sin() * 3.0 + i as f64)
            .collect();
        for window in [21, 23, 41, 43] {
            let d = Differentiator::new(window);
            let h = d.half;
            for k in [POSITION, VELOCITY, ACCELERATION, MOTION_VELOCITY, RATE] {
                let (first, stride) = d.taps(k);
                let skipped = d.weights[k]
                    .iter()
                    .enumerate()
                    .filter(|(j, _)| *j < first || (j - first) % stride != 0);
                assert!(skipped.clone().all(|(_, w)| *w == 0.0), "{window} {k}");
                assert!(d.weights[k].iter().filter(|w| **w != 0.0).count() >= h - 1);
                let full: Vec<f64> = (h..y.len() - h)
                    .map(|c| {
                        (0..=2 * h)
                            .map(|j| d.weights[k][j] * y[c - h + j])
                            .sum::<f64>()
                            / 0.01f64.powi(Differentiator::order(k))
                    })
                    .collect();
                let fast = d.apply(&y, 0.01, k);
                assert_eq!(fast.len(), full.len());
                for (a, b) in fast.iter().zip(&full) {
                    assert!(
                        (a - b).abs() <= 1e-9 * b.abs().max(1.0),
                        "{window} {k}: {a} {b}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_sliding_window_holds_the_last_values_in_order() {
        let mut w = SlidingWindow::new(5);
        assert!(w.is_empty() && w.values().is_empty());
        for v in 0..13u32 {
            w.push(v as f64);
            let expected: Vec<f64> = (v.saturating_sub(4)..=v).map(|u| u as f64).collect();
            assert_eq!(w.values(), expected.as_slice());
            assert_eq!(w.len(), expected.len());
        }
    }

    #[test]
    fn the_strided_sum_is_the_sum_over_every_weight() {
        let d = Differentiator::new(41);
        let stride = 3;
        let values: Vec<f64> = (0..(2 * d.half) * stride + 1)
            .map(|i| (i as f64 * 0.11).cos() + 0.01 * i as f64)
            .collect();
        for k in [POSITION, VELOCITY, ACCELERATION, MOTION_VELOCITY, RATE] {
            let full: f64 = d.weights[k]
                .iter()
                .enumerate()
                .map(|(j, w)| w * values[j * stride])
                .sum();
            let fast = strided_sum(&d.weights[k], d.taps(k), &values, stride);
            assert!(
                (fast - full).abs() <= 1e-12 * full.abs().max(1.0),
                "{k}: {fast} {full}"
            );
        }
    }

    #[test]
    fn the_fft_gives_the_direct_sums_to_rounding_on_noisy_data_far_from_zero() {
        // Every kernel of windows either side of the FFT's threshold and one of 4001 samples,
        // on a noisy sine logged around 100 mm: each output against the term-by-term sum of
        // its kernel's weights, within 1e-12 of the kernel's absolute sum times the data's
        // range (the mean taken out keeps the offset's digits away). The lengths give
        // outputs that fill several blocks and end inside one.
        let mut state = 12345u64;
        let mut noise = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for (window, n) in [
            (FFT_MIN_TAPS - 1, 5000),
            (FFT_MIN_TAPS + 1, 9001),
            (4001, 70_003),
        ] {
            let d = Differentiator::new(window);
            let dt = 0.001;
            let y: Vec<f64> = (0..n)
                .map(|i| 100.0 + 5.0 * (i as f64 * 0.003).sin() + 0.1 * noise())
                .collect();
            let range = 10.2;
            let ks = [POSITION, VELOCITY, ACCELERATION, MOTION_VELOCITY, RATE];
            let out = d.apply_each(&y, dt, &ks);
            for (o, &k) in out.iter().zip(&ks) {
                assert_eq!(o.len(), n - d.window() + 1);
                let w = &d.weights[k];
                let scale = 1.0 / dt.powi(Differentiator::order(k));
                let bound = 1e-12 * w.iter().map(|v| v.abs()).sum::<f64>() * range * scale;
                for c in [0, 1, o.len() / 3, o.len() / 2 + 7, o.len() - 2, o.len() - 1] {
                    let direct: f64 =
                        w.iter().zip(&y[c..]).map(|(a, b)| a * b).sum::<f64>() * scale;
                    assert!(
                        (o[c] - direct).abs() <= bound,
                        "window {window} kernel {k} output {c}: {} against {direct} (bound {bound})",
                        o[c]
                    );
                }
            }
            let smoother = quintic_smoother(d.half);
            let smoothed = smooth(&y, &smoother);
            let c = smoothed.len() / 2;
            let direct: f64 = smoother.iter().zip(&y[c..]).map(|(a, b)| a * b).sum();
            assert!(
                (smoothed[c] - direct).abs() <= 1e-12 * range * 2.0,
                "{window}"
            );
        }
    }

    #[test]
    fn window_follows_the_rate() {
        assert_eq!(window_for_rate(100.0), 41);
        assert_eq!(window_for_rate(1000.0), 401);
        // 0.4 s is 4 samples at 10 Hz: the shortest window a quintic takes instead.
        assert_eq!(window_for_rate(10.0), 13);
    }
}
