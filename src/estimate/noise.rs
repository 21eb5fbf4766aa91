//! The sensor noise of a log recorded at rest: Allan variance of force, position and the
//! filtered force rate, and the white-noise levels identification weights with.

use super::allan::{allan_variance, white_noise_fit, AllanPoint, WhiteNoiseFit};
use super::identify::SensorNoise;
use super::log::CalibrationLog;
use super::sg::Differentiator;

/// One channel's noise model.
#[derive(Debug, Clone)]
pub struct ChannelNoise {
    /// Channel name (force, position, force_rate).
    pub name: &'static str,
    /// Unit of the signal (N, mm, N/s).
    pub unit: &'static str,
    /// Unit suffix for JSON keys (n, mm, n_per_s).
    pub key_unit: &'static str,
    /// Allan curve.
    pub allan: Vec<AllanPoint>,
    /// White-noise fit over the first decade.
    pub fit: WhiteNoiseFit,
    /// Sample variance of the channel about its mean.
    pub sample_variance: f64,
}

/// Noise models of a log recorded at rest.
#[derive(Debug, Clone)]
pub struct NoiseModel {
    /// Force, position and force rate.
    pub channels: [ChannelNoise; 3],
    /// The force-rate variance the filter predicts from the force's white noise.
    pub force_rate_predicted_variance: f64,
    /// Sampling interval.
    pub dt_s: f64,
    /// The differentiator window (samples).
    pub window: usize,
}

impl NoiseModel {
    /// The sensor noise for identification: the white-noise variances of force and position.
    pub fn sensor_noise(&self) -> SensorNoise {
        SensorNoise {
            force_variance_n2: self.channels[0].fit.variance,
            position_variance_mm2: self.channels[1].fit.variance,
        }
    }
}

fn channel(
    name: &'static str,
    unit: &'static str,
    key_unit: &'static str,
    y: &[f64],
    dt: f64,
) -> ChannelNoise {
    let allan = allan_variance(y, dt);
    let fit = white_noise_fit(&allan, dt);
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    let sample_variance =
        y.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (y.len() as f64 - 1.0).max(1.0);
    ChannelNoise {
        name,
        unit,
        key_unit,
        allan,
        fit,
        sample_variance,
    }
}

/// Allan variance of force, position and the filtered force rate of a log at rest.
pub fn noise_model(log: &CalibrationLog) -> NoiseModel {
    let dt = log.dt_s();
    let diff = Differentiator::for_rate(1.0 / dt);
    let force_rate = diff.apply(&log.force_n, dt, super::sg::RATE);
    let force = channel("force", "N", "n", &log.force_n, dt);
    let predicted = diff.noise_variance(super::sg::RATE, force.fit.variance, dt);
    NoiseModel {
        channels: [
            force,
            channel("position", "mm", "mm", &log.position_mm, dt),
            channel("force_rate", "N/s", "n_per_s", &force_rate, dt),
        ],
        force_rate_predicted_variance: predicted,
        dt_s: dt,
        window: diff.window(),
    }
}
