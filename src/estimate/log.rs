//! Calibration logs: CSV with a header, columns for time, force and position.
//!
//! The default columns are `t_s,force_n,position_mm`; other names and units are mapped with
//! [`ColumnMap`] (`--time t --force F:lbf --position x:in`). The reader streams the file
//! record by record and keeps only the three columns, so hour-long kHz logs are read once.
//! Every error names the line and what was expected: a malformed or non-finite number, a
//! missing column, time that does not increase, or a sampling interval that differs from the
//! first one by more than the stated tolerance (a gap or irregular sampling).

use std::io::Read;

use serde::Serialize;

use crate::units::{parse_quantity, quoted, Dimension};

/// A column name with the factor to the default unit.
#[derive(Debug, Clone, PartialEq)]
pub struct Column {
    /// Header name.
    pub name: String,
    /// Multiply values by this to get s, N or mm.
    pub factor: f64,
}

/// Which columns hold time, force and position, and in which units.
#[derive(Debug, Clone, PartialEq)]
pub struct ColumnMap {
    /// Time (to s).
    pub time: Column,
    /// Force (to N).
    pub force: Column,
    /// Position (to mm).
    pub position: Column,
}

impl Default for ColumnMap {
    fn default() -> Self {
        ColumnMap {
            time: Column {
                name: "t_s".into(),
                factor: 1.0,
            },
            force: Column {
                name: "force_n".into(),
                factor: 1.0,
            },
            position: Column {
                name: "position_mm".into(),
                factor: 1.0,
            },
        }
    }
}

/// Splits a `name` or `name:unit` column option; the name must not be empty.
fn split_column<'a>(text: &'a str, what: &str) -> Result<(&'a str, Option<&'a str>), LogError> {
    let (name, unit) = match text.split_once(':') {
        Some((n, u)) => (n.trim(), Some(u.trim())),
        None => (text.trim(), None),
    };
    if name.is_empty() {
        return Err(LogError::Option(format!(
            "--{what}: empty column name in \"{text}\""
        )));
    }
    Ok((name, unit))
}

/// Parses a `name` or `name:unit` column option for a dimension.
pub fn parse_column(text: &str, dim: Dimension, what: &str) -> Result<Column, LogError> {
    let (name, unit) = split_column(text, what)?;
    let factor = match unit {
        None => 1.0,
        Some(u) => parse_quantity(&format!("1 {u}"), dim).map_err(|_| {
            LogError::Option(format!(
                "--{what} {text}: unknown unit \"{u}\" (units: {})",
                dim.unit_list()
            ))
        })?,
    };
    Ok(Column {
        name: name.into(),
        factor,
    })
}

/// Parses a time column option (units s, ms, us, min, h).
pub fn parse_time_column(text: &str) -> Result<Column, LogError> {
    parse_column(text, Dimension::Time, "time")
}

/// Why a log was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LogError {
    /// Produced by [`read_log`] when the file cannot be read or is not CSV.
    #[error("{0}")]
    Io(String),
    /// Produced by [`read_log`] for a header without a needed column.
    #[error("line 1: no column \"{name}\" for {what}; the header has: {header}")]
    MissingColumn {
        /// Column asked for.
        name: String,
        /// time, force or position.
        what: &'static str,
        /// The header found.
        header: String,
    },
    /// Produced by [`read_log`] for a value that is not a finite number.
    #[error(
        "line {line}: column {} = {}: expected a finite number",
        quoted(column),
        quoted(found)
    )]
    BadNumber {
        /// 1-based line.
        line: u64,
        /// Column name.
        column: String,
        /// The text found.
        found: String,
    },
    /// Produced by [`read_log`] for a value that leaves the physical range after conversion to
    /// N or mm (or overflows).
    #[error(
        "line {line}: column {} = {} is {value:e} {unit} after conversion: \
         expected a magnitude below {limit:e} {unit} (a sensor fault or a wrong unit?)",
        quoted(column),
        quoted(found)
    )]
    OutOfRange {
        /// 1-based line.
        line: u64,
        /// Column name.
        column: String,
        /// The text found.
        found: String,
        /// The value in default units.
        value: f64,
        /// N or mm.
        unit: &'static str,
        /// The largest magnitude accepted.
        limit: f64,
    },
    /// Produced by [`read_log`] when the header names a mapped column more than once.
    #[error(
        "line 1: the header has {count} columns named \"{name}\" (the {what} column); \
         expected exactly one, so that the column read is not a guess"
    )]
    DuplicateColumn {
        /// Column name.
        name: String,
        /// time, force or position.
        what: &'static str,
        /// How many.
        count: usize,
    },
    /// Produced by [`read_log`] for a row with too few fields.
    #[error("line {line}: {found} fields, expected {expected} as in the header")]
    ShortRow {
        /// 1-based line.
        line: u64,
        /// Fields found.
        found: usize,
        /// Fields in the header.
        expected: usize,
    },
    /// Produced by [`read_log`] when time does not increase.
    #[error("line {line}: time {t_s} s does not increase (previous sample at {previous_s} s)")]
    TimeNotIncreasing {
        /// 1-based line.
        line: u64,
        /// Time found.
        t_s: f64,
        /// Previous time.
        previous_s: f64,
    },
    /// Produced by [`read_log`] when an interval differs from the first one beyond tolerance.
    #[error(
        "line {line}: sampling interval {dt_s} s differs from the log's {nominal_s} s by more than \
         {tolerance_percent} % (a gap or irregular sampling); expected evenly sampled data"
    )]
    Irregular {
        /// 1-based line.
        line: u64,
        /// Interval found.
        dt_s: f64,
        /// The first interval.
        nominal_s: f64,
        /// Tolerance.
        tolerance_percent: f64,
    },
    /// Produced by [`read_log`] for logs too short to use.
    #[error("the log has {found} samples; at least {needed} are needed")]
    TooShort {
        /// Samples read.
        found: usize,
        /// Samples needed.
        needed: usize,
    },
    /// Produced by the column options.
    #[error("{0}")]
    Option(String),
}

impl LogError {
    /// The 1-based line of the log the error is about, when it names one.
    pub fn line(&self) -> Option<u64> {
        match self {
            LogError::BadNumber { line, .. }
            | LogError::ShortRow { line, .. }
            | LogError::TimeNotIncreasing { line, .. }
            | LogError::Irregular { line, .. }
            | LogError::OutOfRange { line, .. } => Some(*line),
            LogError::DuplicateColumn { .. } | LogError::MissingColumn { .. } => Some(1),
            _ => None,
        }
    }
}

/// The largest force (N) or position (mm) magnitude a log may hold: far beyond any load cell
/// or encoder, so a larger value is a fault, not a measurement.
pub const MAX_MAGNITUDE: f64 = 1e9;

/// An evenly sampled calibration log in s, N and mm.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CalibrationLog {
    /// Time.
    pub t_s: Vec<f64>,
    /// Rod force.
    pub force_n: Vec<f64>,
    /// Deflection.
    pub position_mm: Vec<f64>,
}

impl CalibrationLog {
    /// Sampling interval (mean).
    pub fn dt_s(&self) -> f64 {
        (self.t_s[self.t_s.len() - 1] - self.t_s[0]) / (self.t_s.len() - 1) as f64
    }
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t_s.len()
    }
    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }
}

/// Reads a log. `sampling_tolerance` is the allowed relative deviation of each interval from
/// the first (0.1 = 10 %). `progress` is called with the bytes read so far.
pub fn read_log<R: Read>(
    reader: R,
    map: &ColumnMap,
    sampling_tolerance: f64,
    mut progress: impl FnMut(u64),
) -> Result<CalibrationLog, LogError> {
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(true)
        .from_reader(reader);
    let header = rdr
        .headers()
        .map_err(|e| LogError::Io(format!("line 1: {e}")))?
        .clone();
    let find = |c: &Column, what: &'static str| {
        let count = header.iter().filter(|h| h.trim() == c.name).count();
        if count > 1 {
            return Err(LogError::DuplicateColumn {
                name: c.name.clone(),
                what,
                count,
            });
        }
        header
            .iter()
            .position(|h| h.trim() == c.name)
            .ok_or_else(|| LogError::MissingColumn {
                name: c.name.clone(),
                what,
                header: header.iter().collect::<Vec<_>>().join(","),
            })
    };
    let cols = [
        find(&map.time, "time")?,
        find(&map.force, "force")?,
        find(&map.position, "position")?,
    ];
    let factors = [map.time.factor, map.force.factor, map.position.factor];
    let names = [&map.time.name, &map.force.name, &map.position.name];
    let mut log = CalibrationLog {
        t_s: Vec::new(),
        force_n: Vec::new(),
        position_mm: Vec::new(),
    };
    let mut record = csv::StringRecord::new();
    let mut nominal: Option<f64> = None;
    loop {
        match rdr.read_record(&mut record) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => {
                let line = e.position().map_or(0, |p| p.line());
                return Err(LogError::Io(format!("line {line}: {e}")));
            }
        }
        let line = record.position().map_or(0, |p| p.line());
        if record.len() < header.len() {
            return Err(LogError::ShortRow {
                line,
                found: record.len(),
                expected: header.len(),
            });
        }
        let mut v = [0.0; 3];
        for k in 0..3 {
            let text = record.get(cols[k]).unwrap_or("").trim();
            let x: f64 = text
                .parse()
                .ok()
                .filter(|x: &f64| x.is_finite())
                .ok_or_else(|| LogError::BadNumber {
                    line,
                    column: names[k].clone(),
                    found: text.to_string(),
                })?;
            v[k] = x * factors[k];
            // Time may be a clock (epoch seconds); force and position have physical bounds.
            let limit = if k == 0 { f64::MAX } else { MAX_MAGNITUDE };
            if !v[k].is_finite() || v[k].abs() >= limit {
                return Err(LogError::OutOfRange {
                    line,
                    column: names[k].clone(),
                    found: text.to_string(),
                    value: v[k],
                    unit: ["s", "N", "mm"][k],
                    limit,
                });
            }
        }
        if let Some(&prev) = log.t_s.last() {
            let dt = v[0] - prev;
            if dt <= 0.0 {
                return Err(LogError::TimeNotIncreasing {
                    line,
                    t_s: v[0],
                    previous_s: prev,
                });
            }
            match nominal {
                None => nominal = Some(dt),
                Some(n) if (dt - n).abs() > sampling_tolerance * n => {
                    return Err(LogError::Irregular {
                        line,
                        dt_s: dt,
                        nominal_s: n,
                        tolerance_percent: sampling_tolerance * 100.0,
                    })
                }
                Some(_) => {}
            }
        }
        log.t_s.push(v[0]);
        log.force_n.push(v[1]);
        log.position_mm.push(v[2]);
        if log.t_s.len().is_multiple_of(65_536) {
            progress(record.position().map_or(0, |p| p.byte()));
        }
    }
    if log.len() < 16 {
        return Err(LogError::TooShort {
            found: log.len(),
            needed: 16,
        });
    }
    Ok(log)
}

/// Writes a log as CSV with the default header.
pub fn write_log(log: &CalibrationLog) -> Vec<u8> {
    let mut out = String::with_capacity(40 * log.len() + 32);
    out.push_str("t_s,force_n,position_mm\n");
    for i in 0..log.len() {
        out.push_str(&format!(
            "{:.6},{:.6},{:.6}\n",
            log.t_s[i], log.force_n[i], log.position_mm[i]
        ));
    }
    out.into_bytes()
}
