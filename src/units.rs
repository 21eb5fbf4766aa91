//! Physical quantities with units, as they appear in a spec.
//!
//! A quantity in a spec is either a bare number, read in the dimension's default unit
//! (mm, N, N/mm, 1/mm, deg, MPa), or a string such as `"0.8 in"` or `"45 lbf"`. This module
//! knows the accepted units of each dimension and converts to the default unit. It knows
//! nothing about TOML or keys; [`crate::spec`] adds the key and line to any error.

/// The physical dimension of a spec quantity, which fixes its default unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dimension {
    /// Length; default mm.
    Length,
    /// Force; default N.
    Force,
    /// Force per length (spring rate); default N/mm.
    Stiffness,
    /// Inverse length (the exponent rate k2); default 1/mm.
    InverseLength,
    /// Plane angle; default deg.
    Angle,
    /// Stress or elastic modulus; default MPa (= N/mm²).
    Stress,
    /// Feed rate; default mm/min.
    FeedRate,
    /// Rotational speed; default rev/min.
    RotationalSpeed,
    /// Time; default s.
    Time,
    /// Frequency (sampling rate); default Hz.
    Frequency,
    /// A percentage; default %.
    Percent,
    /// A pure number (ratios, coefficients).
    Dimensionless,
}

const LBF_N: f64 = 4.448_221_615_260_5;
const IN_MM: f64 = 25.4;

impl Dimension {
    /// The unit a bare number is read in.
    pub fn default_unit(self) -> &'static str {
        match self {
            Dimension::Length => "mm",
            Dimension::Force => "N",
            Dimension::Stiffness => "N/mm",
            Dimension::InverseLength => "1/mm",
            Dimension::Angle => "deg",
            Dimension::Stress => "MPa",
            Dimension::FeedRate => "mm/min",
            Dimension::RotationalSpeed => "rpm",
            Dimension::Time => "s",
            Dimension::Frequency => "Hz",
            Dimension::Percent => "%",
            Dimension::Dimensionless => "",
        }
    }

    /// A human name for error messages ("a length such as \"20 mm\"").
    pub fn describe(self) -> &'static str {
        match self {
            Dimension::Length => "a length such as \"20 mm\"",
            Dimension::Force => "a force such as \"200 N\"",
            Dimension::Stiffness => "a spring rate such as \"5 N/mm\"",
            Dimension::InverseLength => "an inverse length such as \"0.26 /mm\"",
            Dimension::Angle => "an angle such as \"60 deg\"",
            Dimension::Stress => "a stress such as \"460 MPa\"",
            Dimension::FeedRate => "a feed rate such as \"600 mm/min\"",
            Dimension::RotationalSpeed => "a spindle speed such as \"8000 rpm\"",
            Dimension::Time => "a duration such as \"300s\"",
            Dimension::Frequency => "a rate such as \"100Hz\"",
            Dimension::Percent => "a percentage such as \"10 %\"",
            Dimension::Dimensionless => "a plain number",
        }
    }

    /// Accepted unit spellings and their factor to the default unit.
    pub fn units(self) -> &'static [(&'static str, f64)] {
        match self {
            Dimension::Length => &[
                ("mm", 1.0),
                ("m", 1000.0),
                ("cm", 10.0),
                ("um", 1e-3),
                ("µm", 1e-3),
                ("in", IN_MM),
                ("inch", IN_MM),
                ("ft", 12.0 * IN_MM),
            ],
            Dimension::Force => &[
                ("N", 1.0),
                ("kN", 1000.0),
                ("mN", 1e-3),
                ("lbf", LBF_N),
                ("kgf", 9.806_65),
                ("ozf", LBF_N / 16.0),
            ],
            Dimension::Stiffness => &[
                ("N/mm", 1.0),
                ("N/m", 1e-3),
                ("N/cm", 0.1),
                ("kN/m", 1.0),
                ("kN/mm", 1000.0),
                ("lbf/in", LBF_N / IN_MM),
            ],
            Dimension::InverseLength => &[
                ("1/mm", 1.0),
                ("/mm", 1.0),
                ("1/m", 1e-3),
                ("/m", 1e-3),
                ("1/cm", 0.1),
                ("/cm", 0.1),
                ("1/in", 1.0 / IN_MM),
                ("/in", 1.0 / IN_MM),
            ],
            Dimension::Angle => &[
                ("deg", 1.0),
                ("°", 1.0),
                ("rad", 180.0 / std::f64::consts::PI),
            ],
            Dimension::Stress => &[
                ("MPa", 1.0),
                ("N/mm2", 1.0),
                ("N/mm^2", 1.0),
                ("N/mm²", 1.0),
                ("GPa", 1000.0),
                ("kPa", 1e-3),
                ("Pa", 1e-6),
                ("psi", LBF_N / (IN_MM * IN_MM)),
                ("ksi", 1000.0 * LBF_N / (IN_MM * IN_MM)),
            ],
            Dimension::FeedRate => &[
                ("mm/min", 1.0),
                ("mm/s", 60.0),
                ("m/min", 1000.0),
                ("in/min", IN_MM),
                ("ipm", IN_MM),
            ],
            Dimension::RotationalSpeed => &[
                ("rpm", 1.0),
                ("rev/min", 1.0),
                ("1/min", 1.0),
                ("rev/s", 60.0),
            ],
            Dimension::Time => &[
                ("s", 1.0),
                ("sec", 1.0),
                ("ms", 1e-3),
                ("us", 1e-6),
                ("µs", 1e-6),
                ("min", 60.0),
                ("h", 3600.0),
            ],
            Dimension::Frequency => &[("Hz", 1.0), ("hz", 1.0), ("kHz", 1e3), ("khz", 1e3)],
            Dimension::Percent => &[("%", 1.0)],
            Dimension::Dimensionless => &[],
        }
    }

    /// The accepted unit spellings, comma separated, for error messages.
    pub fn unit_list(self) -> String {
        self.units()
            .iter()
            .map(|(u, _)| *u)
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// Why a quantity string could not be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UnitError {
    /// Produced by [`parse_quantity`] when the text does not start with a number.
    #[error("no number at the start")]
    NoNumber,
    /// Produced by [`parse_quantity`] when the unit is not one of the dimension's units.
    #[error("unknown unit \"{unit}\" for {dimension}")]
    UnknownUnit {
        /// The unit text found.
        unit: String,
        /// What was expected, e.g. "a length such as \"20 mm\"".
        dimension: &'static str,
    },
    /// Produced by [`parse_quantity`] for a number of more than [`MAX_NUMBER_CHARS`]
    /// characters.
    #[error("a number of more than {MAX_NUMBER_CHARS} characters")]
    TooLong,
    /// Produced by [`parse_quantity`] and [`check_finite`] for NaN or infinity, also when
    /// the conversion to the default unit overflows.
    #[error("the value is not a finite number")]
    NotFinite,
}

/// Checks that a number is finite.
pub fn check_finite(value: f64) -> Result<f64, UnitError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(UnitError::NotFinite)
    }
}

/// Parses `"<number> <unit>"` (the space is optional; a bare number means the default unit)
/// and returns the value in the dimension's default unit.
///
/// ```
/// use camspring::units::{parse_quantity, Dimension};
/// assert_eq!(parse_quantity("0.5 in", Dimension::Length).unwrap(), 12.7);
/// assert!(parse_quantity("5 N", Dimension::Length).is_err());
/// ```
pub fn parse_quantity(text: &str, dimension: Dimension) -> Result<f64, UnitError> {
    let text = text.trim();
    let split = number_prefix_len(text);
    if split > MAX_NUMBER_CHARS {
        return Err(UnitError::TooLong);
    }
    if split == 0 {
        return Err(UnitError::NoNumber);
    }
    let (number, unit) = text.split_at(split);
    let value: f64 = number.parse().map_err(|_| UnitError::NoNumber)?;
    let value = check_finite(value)?;
    let unit = unit.trim();
    if unit.is_empty() {
        return Ok(value);
    }
    dimension
        .units()
        .iter()
        .find(|(name, _)| *name == unit)
        .map(|(_, factor)| value * factor)
        .ok_or_else(|| UnitError::UnknownUnit {
            unit: unit.to_string(),
            dimension: dimension.describe(),
        })
        .and_then(check_finite)
}

/// The longest number a quantity may spell (longer ones are refused without parsing).
pub const MAX_NUMBER_CHARS: usize = 100;

/// Length of the longest prefix of `text` that parses as a float, looking at no more than
/// [`MAX_NUMBER_CHARS`] + 1 characters (so the work is bounded whatever the input).
fn number_prefix_len(text: &str) -> usize {
    let run = text
        .bytes()
        .take(MAX_NUMBER_CHARS + 1)
        .take_while(|c| c.is_ascii_digit() || matches!(c, b'.' | b'+' | b'-' | b'e' | b'E'))
        .count();
    (1..=run)
        .rev()
        .find(|&end| text[..end].parse::<f64>().is_ok())
        .unwrap_or(0)
}

/// How a value read from a file is quoted in a message: in double quotes, cut to 60
/// characters, with control characters (terminal escapes, newlines) written as escapes so a
/// message can never drive the terminal.
pub fn quoted(text: &str) -> String {
    format!("\"{}\"", printable(text, 60))
}

/// `text` cut to `max` characters (marked with "..."), control characters escaped.
pub fn printable(text: &str, max: usize) -> String {
    let mut out = String::new();
    for (i, c) in text.chars().enumerate() {
        if i == max {
            out.push_str("...");
            break;
        }
        if c.is_control() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    out
}

/// Parses a positive quantity of `dimension`, such as a duration or a rate; the message says
/// what was found and what is expected.
fn parse_positive(text: &str, dimension: Dimension) -> Result<f64, String> {
    match parse_quantity(text, dimension) {
        Ok(v) if v > 0.0 => Ok(v),
        Err(UnitError::UnknownUnit { unit, .. }) => Err(format!(
            "\"{text}\": unknown unit \"{unit}\" (units: {})",
            dimension.unit_list()
        )),
        _ => Err(format!(
            "\"{text}\": expected a positive value, {}",
            dimension.describe()
        )),
    }
}

/// Parses a duration such as "300s", "300 s", "5min", "1h", "250ms" or a plain number of
/// seconds.
pub fn parse_duration_s(text: &str) -> Result<f64, String> {
    parse_positive(text, Dimension::Time)
}

/// Parses a rate such as "100Hz", "1 kHz" or a plain number of hertz.
pub fn parse_rate_hz(text: &str) -> Result<f64, String> {
    parse_positive(text, Dimension::Frequency)
}

/// Parses a relative tolerance such as "10%" or "0.1", strictly between 0 and 1.
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
    fn long_numbers_are_refused_in_linear_time_and_overflow_is_caught() {
        let long = "1".repeat(200_000) + " mm";
        assert_eq!(
            parse_quantity(&long, Dimension::Length),
            Err(UnitError::TooLong)
        );
        let ok = "1".repeat(MAX_NUMBER_CHARS) + " mm";
        assert!(parse_quantity(&ok, Dimension::Length).is_ok());
        assert_eq!(
            parse_quantity("1e308 kN", Dimension::Force),
            Err(UnitError::NotFinite)
        );
        assert_eq!(parse_quantity("-2.5e1mm", Dimension::Length), Ok(-25.0));
    }

    #[test]
    fn quoted_values_cannot_drive_the_terminal() {
        assert_eq!(
            quoted("a\u{1b}]0;pwned\u{7}b"),
            "\"a\\u{1b}]0;pwned\\u{7}b\""
        );
        assert_eq!(
            quoted(&"x".repeat(100)),
            format!("\"{}...\"", "x".repeat(60))
        );
    }

    #[test]
    fn parses_durations_rates_and_fractions() {
        assert_eq!(parse_duration_s("300s").unwrap(), 300.0);
        assert_eq!(parse_duration_s("2 min").unwrap(), 120.0);
        assert_eq!(parse_duration_s("250ms").unwrap(), 0.25);
        assert_eq!(parse_rate_hz("1kHz").unwrap(), 1000.0);
        assert_eq!(parse_fraction("10%").unwrap(), 0.1);
        assert!(parse_duration_s("-1s").is_err());
        assert!(parse_duration_s("3 fortnights")
            .unwrap_err()
            .contains("fortnights"));
        assert!(parse_rate_hz("NaN").is_err());
        assert!(parse_fraction("150%").is_err());
    }

    #[test]
    fn converts_to_default_units() {
        assert_eq!(parse_quantity("20 mm", Dimension::Length).unwrap(), 20.0);
        assert_eq!(parse_quantity("20", Dimension::Length).unwrap(), 20.0);
        assert_eq!(
            parse_quantity("0.8in", Dimension::Length).unwrap(),
            0.8 * 25.4
        );
        assert!((parse_quantity("45 lbf", Dimension::Force).unwrap() - 200.169_97).abs() < 1e-4);
        assert!(
            (parse_quantity("1 lbf/in", Dimension::Stiffness).unwrap() - 0.175_126_8).abs() < 1e-6
        );
        assert_eq!(
            parse_quantity("5000 N/m", Dimension::Stiffness).unwrap(),
            5.0
        );
        assert_eq!(
            parse_quantity("0.5 /mm", Dimension::InverseLength).unwrap(),
            0.5
        );
        assert!((parse_quantity("1 rad", Dimension::Angle).unwrap() - 57.295_779_513).abs() < 1e-8);
        assert_eq!(
            parse_quantity("69 GPa", Dimension::Stress).unwrap(),
            69_000.0
        );
        assert_eq!(parse_quantity("-1.5e1 N", Dimension::Force).unwrap(), -15.0);
    }

    #[test]
    fn rejects_wrong_units_and_garbage() {
        assert!(matches!(
            parse_quantity("5 N", Dimension::Length),
            Err(UnitError::UnknownUnit { .. })
        ));
        assert_eq!(
            parse_quantity("mm", Dimension::Length),
            Err(UnitError::NoNumber)
        );
        assert_eq!(
            parse_quantity("", Dimension::Length),
            Err(UnitError::NoNumber)
        );
        assert_eq!(
            parse_quantity("inf mm", Dimension::Length),
            Err(UnitError::NoNumber)
        );
        assert_eq!(
            parse_quantity("1e999 mm", Dimension::Length),
            Err(UnitError::NotFinite)
        );
    }
}
