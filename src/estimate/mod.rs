//! Calibration logs of a built spring: reading ([`log`]), simulating with known truth
//! ([`sim`]), sensor noise by Allan variance ([`allan`]), smoothing differentiators ([`sg`]) and
//! offline identification of the transmission parameters ([`identify`], paper sections IV-V).
//! The paper's EKF ([`ekf`]) estimates stiffness, damping and inertia on-line, and
//! [`validate`] compares a log with the design. [`report`] turns the results into the JSON,
//! text, CSV and SVG the commands write.

pub mod allan;
pub mod ekf;
pub mod identify;
pub mod log;
pub mod report;
pub mod sg;
pub mod sim;
pub mod validate;

/// Parses a positive number with an optional unit suffix from `units` (name, factor), the
/// empty unit meaning `units[0]`'s factor of 1. `example` goes into the error message.
fn parse_scaled(text: &str, units: &[(&str, f64)], example: &str) -> Result<f64, String> {
    let t = text.trim();
    let split = t.find(|c: char| c.is_ascii_alphabetic()).unwrap_or(t.len());
    let (num, unit) = (t[..split].trim(), t[split..].trim());
    let factor = if unit.is_empty() {
        1.0
    } else {
        units
            .iter()
            .find(|(name, _)| *name == unit)
            .map(|(_, f)| *f)
            .ok_or_else(|| {
                let names: Vec<&str> = units.iter().map(|(n, _)| *n).collect();
                format!(
                    "\"{text}\": unknown unit \"{unit}\" (units: {})",
                    names.join(", ")
                )
            })?
    };
    match num.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v * factor),
        _ => Err(format!(
            "\"{text}\": expected a positive value such as \"{example}\""
        )),
    }
}

/// Parses a duration such as "300s", "300 s", "5min", "1h", "250ms" or a plain number of seconds.
pub fn parse_duration_s(text: &str) -> Result<f64, String> {
    parse_scaled(
        text,
        &[("s", 1.0), ("ms", 1e-3), ("min", 60.0), ("h", 3600.0)],
        "300s",
    )
}

/// Parses a rate such as "100Hz", "1 kHz" or a plain number of hertz.
pub fn parse_rate_hz(text: &str) -> Result<f64, String> {
    parse_scaled(
        text,
        &[("Hz", 1.0), ("hz", 1.0), ("kHz", 1e3), ("khz", 1e3)],
        "100Hz",
    )
}

/// Parses a relative tolerance such as "10%" or "0.1".
pub fn parse_fraction(text: &str) -> Result<f64, String> {
    let t = text.trim();
    let v = match t.strip_suffix('%') {
        Some(p) => p.trim().parse::<f64>().map(|v| v / 100.0),
        None => t.parse::<f64>(),
    };
    match v {
        Ok(v) if v.is_finite() && v > 0.0 && v < 1.0 => Ok(v),
        _ => Err(format!(
            "\"{text}\": expected a fraction between 0 and 100 %, such as \"10%\""
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_durations_rates_and_fractions() {
        assert_eq!(parse_duration_s("300s").unwrap(), 300.0);
        assert_eq!(parse_duration_s("2 min").unwrap(), 120.0);
        assert_eq!(parse_rate_hz("1kHz").unwrap(), 1000.0);
        assert_eq!(parse_fraction("10%").unwrap(), 0.1);
        assert!(parse_duration_s("-1s").is_err());
        assert!(parse_duration_s("3 fortnights").is_err());
        assert!(parse_rate_hz("NaN").is_err());
        assert!(parse_fraction("150%").is_err());
    }
}
