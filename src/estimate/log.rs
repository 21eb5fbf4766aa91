//! Calibration logs: CSV with a header, columns for time, force and position.
//!
//! The default columns are `t_s,force_n,position_mm`; other names and units are mapped with
//! [`ColumnMap`] (`--time t --force F:lbf --position x:in`). [`LogReader`] streams the file
//! sample by sample in constant memory (what `identify` and `estimate` use); [`read_log`]
//! collects it into a [`CalibrationLog`].
//! Every error names the line and what was expected: a malformed or infinite number, a
//! missing column, time that does not increase, or a sampling interval that differs from the
//! mean so far by more than the stated tolerance (a gap or irregular sampling). A field that is
//! empty or NaN is a reading the logger lost, filled like a dropped sample; where the separator
//! is not a comma, decimal commas are read; a time column may hold clock time. The separator
//! is a comma, tab, semicolon or runs of blanks (detected, given, or named by a `sep=` line);
//! UTF-16 files are read transcoded.

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
    /// Field separator.
    pub delimiter: Delimiter,
    /// A log without a time column: its rows are samples at this rate (Hz), the first at
    /// t = 0, and `time` is not read. A row with no value is a dropped sample; a missing row
    /// cannot be seen.
    pub rows_at_hz: Option<f64>,
}

/// The field separator of a log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Delimiter {
    /// Detected from the header line: the most frequent of comma, tab and semicolon, or runs
    /// of blanks where the header has none of them or only they give the mapped columns (a
    /// `sep=;` line before the header, as spreadsheets write one, names it).
    #[default]
    Auto,
    /// `,`
    Comma,
    /// A tab.
    Tab,
    /// `;`
    Semicolon,
    /// Runs of spaces or tabs, as column-aligned text loggers write (a field cannot be empty).
    Whitespace,
}

impl Delimiter {
    /// The separator, detecting `Auto` from the header line.
    fn resolve(self, header: &str) -> Delimiter {
        if self != Delimiter::Auto {
            return self;
        }
        let count = |c: char| header.matches(c).count();
        [
            (Delimiter::Comma, count(',')),
            (Delimiter::Tab, count('\t')),
            (Delimiter::Semicolon, count(';')),
        ]
        .into_iter()
        .max_by_key(|&(_, n)| n)
        .filter(|&(_, n)| n > 0)
        .map(|(d, _)| d)
        .unwrap_or(if header.trim().contains(' ') {
            Delimiter::Whitespace
        } else {
            Delimiter::Comma
        })
    }

    /// The byte the CSV reader splits at (runs of blanks are first collapsed to one tab).
    fn byte(self) -> u8 {
        match self {
            Delimiter::Tab | Delimiter::Whitespace => b'\t',
            Delimiter::Semicolon => b';',
            Delimiter::Comma | Delimiter::Auto => b',',
        }
    }

    /// What a line is split at, in messages.
    fn name(self) -> &'static str {
        match self {
            Delimiter::Tab => "tabs",
            Delimiter::Semicolon => "semicolons",
            Delimiter::Whitespace => "runs of blanks",
            Delimiter::Comma | Delimiter::Auto => "commas",
        }
    }

    /// The separator a spreadsheet's `sep=X` line names.
    fn from_sep_line(line: &str) -> Option<Option<Delimiter>> {
        let rest = line.trim().strip_prefix("sep=")?;
        Some(match rest {
            "," => Some(Delimiter::Comma),
            ";" => Some(Delimiter::Semicolon),
            "\t" | "" => Some(Delimiter::Tab),
            _ => None,
        })
    }
}

/// A line of column-aligned text with each run of blanks made one tab, and leading and
/// trailing blanks dropped (its line break kept).
fn collapse_blanks(line: &[u8]) -> Vec<u8> {
    let end = line.len()
        - line
            .iter()
            .rev()
            .take_while(|b| **b == b'\n' || **b == b'\r')
            .count();
    let mut out = Vec::with_capacity(line.len());
    let mut blank = false;
    for &b in line[..end]
        .iter()
        .skip_while(|b| **b == b' ' || **b == b'\t')
    {
        if b == b' ' || b == b'\t' {
            blank = true;
            continue;
        }
        if blank {
            out.push(b'\t');
            blank = false;
        }
        out.push(b);
    }
    out.extend_from_slice(&line[end..]);
    out
}

/// Whether a line is a comment (`#` or `;` first, after blanks) or blank.
fn is_comment_or_blank(line: &[u8]) -> bool {
    match line.iter().find(|b| !b.is_ascii_whitespace()) {
        None => true,
        Some(b) => *b == b'#' || *b == b';',
    }
}

/// How many lines after the first line that could be a header a header that names the mapped
/// columns is looked for ([`LogReader::new`]): a DAQ's preamble of a few lines of test name,
/// date and rate is skipped, and a log whose header lacks a column is still refused at once.
pub const PREAMBLE_LINES: u64 = 64;

/// The separator of a header line: the map's, a `sep=` line's (`named`), or detected.
/// Column-aligned text may hold a stray tab or comma between blanks: where the detected
/// separator does not give the mapped columns and runs of blanks do, the blanks separate.
fn separator_of(header: &str, map: &ColumnMap, named: Option<Delimiter>) -> Delimiter {
    match (map.delimiter, named) {
        (Delimiter::Auto, Some(d)) => d,
        (Delimiter::Auto, None) => {
            let detected = Delimiter::Auto.resolve(header);
            let has_columns = |fields: Vec<&str>| {
                let fields: Vec<&str> = fields.iter().map(|f| f.trim().trim_matches('"')).collect();
                [&map.time, &map.force, &map.position]
                    .iter()
                    .all(|c| fields.contains(&c.name.as_str()))
            };
            let split = header.trim().split(char::from(detected.byte())).collect();
            if detected != Delimiter::Whitespace
                && !has_columns(split)
                && has_columns(header.split_whitespace().collect())
            {
                Delimiter::Whitespace
            } else {
                detected
            }
        }
        (given, _) => given.resolve(header),
    }
}

/// How many of the map's three columns a line split at `separator` names: each by its name,
/// or, where the map has a column's default name, by the one field whose name reads as it.
fn named_columns(line: &str, separator: Delimiter, map: &ColumnMap) -> usize {
    let fields: Vec<String> = if separator == Delimiter::Whitespace {
        line.split_whitespace().map(str::to_string).collect()
    } else {
        line.trim()
            .split(char::from(separator.byte()))
            .map(|f| f.trim().trim_matches('"').trim().to_string())
            .collect()
    };
    let defaults = ColumnMap::default();
    [
        ("time", &map.time, &defaults.time),
        ("force", &map.force, &defaults.force),
        ("position", &map.position, &defaults.position),
    ]
    .iter()
    .filter(|(what, column, default)| {
        (*what == "time" && map.rows_at_hz.is_some())
            || fields.contains(&column.name)
            || (column == default && reading_as(what, &fields).len() == 1)
    })
    .count()
}

/// A reader that blanks comment lines (keeping their line breaks, so that line numbers stay
/// those of the file; the CSV reader skips blank lines).
struct WithoutComments<R> {
    inner: R,
    line: Vec<u8>,
    at: usize,
    /// Whether runs of blanks are collapsed to one tab ([`Delimiter::Whitespace`]).
    collapse: bool,
}

impl<R: std::io::BufRead> Read for WithoutComments<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.at >= self.line.len() {
            self.line.clear();
            self.at = 0;
            if self.inner.read_until(b'\n', &mut self.line)? == 0 {
                return Ok(0);
            }
            if is_comment_or_blank(&self.line) {
                let ends_cr = self.line.ends_with(b"\r\n");
                self.line.clear();
                self.line
                    .extend_from_slice(if ends_cr { b"\r\n" } else { b"\n" });
            } else if self.collapse {
                self.line = collapse_blanks(&self.line);
            }
        }
        let n = buf.len().min(self.line.len() - self.at);
        buf[..n].copy_from_slice(&self.line[self.at..self.at + n]);
        self.at += n;
        Ok(n)
    }
}

/// Samples filled in by interpolation where a log dropped them.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FilledGap {
    /// Line of the sample after the gap.
    pub line: u64,
    /// Time of the last sample before the gap (s).
    pub after_s: f64,
    /// Samples filled.
    pub samples: usize,
    /// How many of them the log has as rows with no value (an empty field or NaN) rather
    /// than as missing rows.
    pub empty_rows: usize,
}

/// Whether a field holds no reading: empty, or NaN as loggers write it (`NaN`, `nan`, `-nan`,
/// `NA`, `N/A`, `null`). Such a row is a dropped sample, like a missing row.
pub fn is_no_value(text: &str) -> bool {
    const TOKENS: [&str; 7] = ["", "nan", "-nan", "+nan", "na", "n/a", "null"];
    TOKENS.iter().any(|t| text.eq_ignore_ascii_case(t))
}

/// Parses a log's number. Where the separator is not a comma, a decimal comma (`12,5`, as
/// loggers set to a European locale write) is read as a decimal point.
fn parse_number(text: &str, delimiter: u8) -> Option<f64> {
    let value = match text.parse::<f64>() {
        Ok(v) => v,
        Err(_) if delimiter != b',' && text.matches(',').count() == 1 && !text.contains('.') => {
            text.replace(',', ".").parse::<f64>().ok()?
        }
        Err(_) => return None,
    };
    value.is_finite().then_some(value)
}

/// The resolution a time was written with, in the units it was written in: one unit of its
/// last written digit (`0.013` and `1.3e-2` are to 0.001; `13` is to 1). A clock time's is that
/// of its seconds (`08:35:31.12` is to 0.01 s).
fn written_resolution(text: &str) -> f64 {
    // Read on every row: bytes, not chars, and a table, not powi (together 6 % of a parse).
    let bytes = text.as_bytes();
    let (mantissa, exponent) = match bytes.iter().position(|&b| b == b'e' || b == b'E') {
        Some(i) => (&bytes[..i], text[i + 1..].parse::<i32>().unwrap_or(0)),
        None => (bytes, 0),
    };
    let decimals = mantissa
        .iter()
        .rposition(|&b| b == b'.' || b == b',')
        .map_or(0, |i| {
            mantissa[i + 1..]
                .iter()
                .take_while(|b| b.is_ascii_digit())
                .count()
        });
    power_of_ten(exponent.saturating_sub(i32::try_from(decimals).unwrap_or(i32::MAX)))
}

/// 10^k: exact from a table where 10^|k| is exact in f64 (|k| <= 22), as `powi` gives it.
fn power_of_ten(k: i32) -> f64 {
    const EXACT: [f64; 23] = [
        1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
        1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
    ];
    match usize::try_from(k.unsigned_abs())
        .ok()
        .and_then(|i| EXACT.get(i))
    {
        Some(&p) if k >= 0 => p,
        Some(&p) => 1.0 / p,
        None => 10f64.powi(k),
    }
}

/// A sampling interval in messages: in ms to five significant digits below a second
/// (`3.3333 ms`), else in s.
fn interval_text(seconds: f64) -> String {
    if seconds.abs() < 1.0 {
        let ms = seconds * 1e3;
        let decimals = (4 - ms.abs().log10().floor().clamp(-6.0, 4.0) as i32).max(0) as usize;
        format!("{ms:.decimals$} ms")
    } else {
        format!("{seconds:.4} s")
    }
}

/// The most consecutive dropped samples [`read_log`] fills by interpolation; a longer gap is
/// refused.
pub const MAX_FILLED_SAMPLES: usize = 3;

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
            delimiter: Delimiter::Auto,
            rows_at_hz: None,
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

/// The unit `text` names for a dimension, in the spelling the column options take, with its
/// factor to the default unit; case is ignored where that leaves one unit.
fn unit_of(text: &str, dim: Dimension) -> Option<(&'static str, f64)> {
    let units = dim.units();
    units.iter().find(|(u, _)| *u == text).copied().or_else(|| {
        let mut same = units.iter().filter(|(u, _)| u.eq_ignore_ascii_case(text));
        match (same.next(), same.next()) {
            (Some(u), None) => Some(*u),
            _ => None,
        }
    })
}

/// The unit a column name carries for a dimension (`t_ms`, `Force [N]`, `x (in)`).
fn unit_in_name(tokens: &[&str], dim: Dimension) -> Option<&'static str> {
    tokens
        .iter()
        .rev()
        .find_map(|t| unit_of(t, dim).map(|(u, _)| u))
}

/// The three quantities a log's columns give, in the order of a [`ColumnMap`], with their
/// dimensions.
const QUANTITIES: [(&str, Dimension); 3] = [
    ("time", Dimension::Time),
    ("force", Dimension::Force),
    ("position", Dimension::Length),
];

/// The dimension of a quantity of [`QUANTITIES`] (length for position).
fn dimension_of(what: &str) -> Dimension {
    QUANTITIES
        .iter()
        .find(|(q, _)| *q == what)
        .map_or(Dimension::Length, |(_, d)| *d)
}

/// The header's columns whose names read as a quantity (`time`, `force` or `position`): the
/// first word of the name is one of the quantity's (`Time [ms]`, `Load (N)`, `x_in`,
/// `Extension (mm)`), each with the unit its name carries, when it carries one of the
/// quantity's.
fn reading_as<'a>(what: &str, columns: &'a [String]) -> Vec<(&'a String, Option<&'static str>)> {
    let dim = dimension_of(what);
    let words: &[&str] = match what {
        "time" => &["t", "time", "timestamp", "elapsed"],
        "force" => &["f", "force", "load", "fz"],
        _ => &[
            "x",
            "pos",
            "position",
            "displacement",
            "deflection",
            "stroke",
            "travel",
            "extension",
            "elongation",
        ],
    };
    columns
        .iter()
        .filter(|c| !c.contains(':'))
        .filter_map(|c| {
            let tokens: Vec<&str> = c
                .split(|ch: char| " _-[]()".contains(ch))
                .filter(|t| !t.is_empty())
                .collect();
            let first = tokens.first()?.to_ascii_lowercase();
            words
                .contains(&first.as_str())
                .then(|| (c, unit_in_name(&tokens[1..], dim)))
        })
        .collect()
}

/// A hint for a missing column: the header's column whose name reads as the quantity, and the
/// option that maps it, with the unit its name carries.
fn column_hint(what: &str, columns: &[String]) -> String {
    let dim = dimension_of(what);
    match reading_as(what, columns).as_slice() {
        [(name, Some(unit))] => {
            format!("; \"{name}\" reads as the {what} in {unit}: give --{what} \"{name}:{unit}\"")
        }
        [(name, None)] => format!(
            "; \"{name}\" reads as the {what}: give --{what} \"{name}:UNIT\" with its unit ({})",
            dim.unit_list()
        ),
        _ if what == "time" => "; give --time NAME:UNIT to map the time column, or \
                                --sample-rate RATE for a log whose rows are samples at a rate \
                                and that has no time column"
            .to_string(),
        _ => format!("; give --{what} NAME:UNIT to map the {what} column"),
    }
}

/// Parses a `name` or `name:unit` column option for a dimension.
pub fn parse_column(text: &str, dim: Dimension, what: &str) -> Result<Column, LogError> {
    let (name, unit) = split_column(text, what)?;
    // A unit with a minus sign reads the column with the opposite sign: a load cell or an
    // encoder that counts the other way.
    let (sign, unit) = match unit.map(|u| u.strip_prefix('-').map(str::trim)) {
        Some(Some(_)) if dim == Dimension::Time => {
            return Err(LogError::Option(format!(
                "--{what} {text}: time cannot be read reversed; expected a unit such as s or ms"
            )))
        }
        Some(Some(u)) => (-1.0, (!u.is_empty()).then_some(u)),
        _ => (1.0, unit),
    };
    let factor = sign
        * match unit {
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
    /// Produced by [`read_log`] for a spreadsheet's separator line (`sep=X`) that names a
    /// separator other than a comma, semicolon or tab.
    #[error(
        "line {line}: the separator line {} names a separator camspring does not read; expected sep=, sep=; or sep= and a tab",
        quoted(found)
    )]
    SeparatorLine {
        /// Line of the separator line.
        line: u64,
        /// The line as found.
        found: String,
    },
    /// Produced by [`read_log`] for a header without a needed column.
    #[error(
        "line {line}: no column \"{name}\" for {what}; the header, split at {delimiter}, has the columns {}{}",
        columns.iter().map(|c| quoted(c)).collect::<Vec<_>>().join(", "),
        if header.contains(name.as_str()) && !columns.iter().any(|c| c == name) {
            format!("; the header line contains \"{name}\" but not as a field of its own: give --delimiter comma, tab, semicolon or whitespace")
        } else {
            column_hint(what, columns)
        }
    )]
    MissingColumn {
        /// Line of the header.
        line: u64,
        /// Column asked for.
        name: String,
        /// time, force or position.
        what: &'static str,
        /// The header found.
        header: String,
        /// The columns read from it.
        columns: Vec<String>,
        /// The separator used.
        delimiter: &'static str,
    },
    /// Produced by [`read_log`] for dropped samples it does not fill: more than
    /// [`MAX_FILLED_SAMPLES`] in a row.
    #[error(
        "the log has {} gap(s) longer than {MAX_FILLED_SAMPLES} samples, which are not filled: {}; \
         expected an evenly sampled log with at most {MAX_FILLED_SAMPLES} dropped samples in a row",
        gaps.len(),
        gaps.iter().take(10).map(|g| format!("line {} ({} samples missing after t = {} s{})", g.line, g.samples, g.after_s, if g.empty_rows > 0 { format!(", {} of them rows with no value", g.empty_rows) } else { String::new() })).collect::<Vec<_>>().join(", ")
    )]
    Gaps {
        /// The gaps (at most the first 100).
        gaps: Vec<FilledGap>,
    },
    /// Produced by [`read_log`] for a value that is not a finite number.
    #[error(
        "line {line}: column {} = {}: expected a finite number{}",
        quoted(column),
        quoted(found),
        if *time { " or a clock time (2026-11-27T08:35:31.120, or 08:35:31.120)" } else { "" }
    )]
    BadNumber {
        /// 1-based line.
        line: u64,
        /// Column name.
        column: String,
        /// The text found.
        found: String,
        /// Whether it is the time column, which may also hold clock time.
        time: bool,
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
        "line {line}: the header has {count} columns named \"{name}\" (the {what} column); \
         expected exactly one, so that the column read is not a guess"
    )]
    DuplicateColumn {
        /// Line of the header.
        line: u64,
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
    /// Produced by [`read_log`] for a row with more fields than the header.
    #[error(
        "line {line}: {found} fields, expected {expected} as in the header (a decimal comma in a \
         comma-separated log splits each number in two: write decimal points, or separate the \
         fields with semicolons or tabs)"
    )]
    LongRow {
        /// 1-based line.
        line: u64,
        /// Fields found.
        found: usize,
        /// Fields in the header.
        expected: usize,
    },
    /// Produced by [`read_log`] when time does not increase.
    #[error(
        "line {line}: time {t_s} s does not increase (previous sample at {previous_s} s){}",
        if *restarted {
            "; the time starts again near the log's first, so the log holds more than one run \
             (a logger that restarted, or files joined): give each run as its own log"
        } else {
            ""
        }
    )]
    TimeNotIncreasing {
        /// 1-based line.
        line: u64,
        /// Time found.
        t_s: f64,
        /// Previous time.
        previous_s: f64,
        /// Whether the time went back to within a few intervals of the log's first.
        restarted: bool,
    },
    /// Produced by [`read_log`] for a row that repeats the header.
    #[error(
        "line {line} repeats the header: the log holds more than one run (a logger that \
         restarted, or files joined); give each run as its own log"
    )]
    RepeatedHeader {
        /// 1-based line.
        line: u64,
    },
    /// Produced by [`read_log`] when an interval differs from the mean so far beyond
    /// tolerance.
    #[error(
        "line {line}: sampling interval {} differs from the log's {} by more than \
         {tolerance_percent} % (a gap or irregular sampling); expected evenly sampled data (a \
         rig whose clock stamps evenly taken samples with jitter needs a wider \
         --sampling-tolerance; samples taken at uneven times are read as evenly spaced there, \
         which biases the inertia and damping)",
        interval_text(*dt_s),
        interval_text(*nominal_s)
    )]
    Irregular {
        /// 1-based line.
        line: u64,
        /// Interval found.
        dt_s: f64,
        /// The mean interval so far.
        nominal_s: f64,
        /// Tolerance.
        tolerance_percent: f64,
    },
    /// Produced by [`read_log`] when too few rows have all three values.
    #[error(
        "line {line}: column {} has no value (empty or NaN), as have {rows} row(s) in all; \
         expected a number in each of the time, force and position columns on at least \
         {MIN_LOG_SAMPLES} rows",
        quoted(column)
    )]
    NoValues {
        /// The first row with no value.
        line: u64,
        /// Its column.
        column: String,
        /// Rows with no value that were left out.
        rows: usize,
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
            | LogError::LongRow { line, .. }
            | LogError::TimeNotIncreasing { line, .. }
            | LogError::RepeatedHeader { line, .. }
            | LogError::Irregular { line, .. }
            | LogError::OutOfRange { line, .. }
            | LogError::DuplicateColumn { line, .. }
            | LogError::MissingColumn { line, .. }
            | LogError::NoValues { line, .. }
            | LogError::SeparatorLine { line, .. } => Some(*line),
            LogError::Gaps { gaps } => gaps.first().map(|g| g.line),
            // The reader's own messages start with the line they are about.
            LogError::Io(message) => message
                .strip_prefix("line ")
                .and_then(|rest| rest.split(':').next())
                .and_then(|n| n.parse().ok()),
            _ => None,
        }
    }
}

/// The largest force (N) or position (mm) magnitude a log may hold: far beyond any load cell
/// or encoder, so a larger value is a fault, not a measurement.
pub const MAX_MAGNITUDE: f64 = 1e9;

/// An evenly sampled calibration log in s, N and mm.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct CalibrationLog {
    /// Time.
    pub t_s: Vec<f64>,
    /// Rod force.
    pub force_n: Vec<f64>,
    /// Deflection.
    pub position_mm: Vec<f64>,
    /// Dropped samples that the reader filled by interpolation (a warning for the user).
    #[serde(skip)]
    pub filled: Vec<FilledGap>,
    /// Rows with no value that could not be filled (at the log's start or end), as
    /// [`LogReader::left_out`] and [`LogReader::left_out_count`] give them.
    #[serde(skip)]
    pub left_out: (Vec<u64>, usize),
    /// The units row under the header, when the log had one ([`LogReader::units_row`]).
    #[serde(skip)]
    pub units_row: Option<(u64, [String; 3])>,
    /// Columns read by their names, the header lacking the default ones
    /// ([`LogReader::recognised`]).
    #[serde(skip)]
    pub recognised: Vec<RecognisedColumn>,
    /// The sampling intervals' scatter about their mean beyond the times' rounding, as a
    /// fraction of the mean ([`LogReader::interval_scatter`]).
    #[serde(skip)]
    pub interval_scatter: Option<f64>,
    /// The lines skipped before the header ([`LogReader::preamble`]).
    #[serde(skip)]
    pub preamble: Option<(u64, u64)>,
    /// The rate its rows were read at, for a log without a time column
    /// ([`ColumnMap::rows_at_hz`]).
    #[serde(skip)]
    pub rows_at_hz: Option<f64>,
}

/// A force channel flat at its largest (or smallest) value while the rod moves: a load cell or
/// its amplifier at the end of its range ([`ClipWatch`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ForceClip {
    /// The value the force sticks at (N).
    pub force_n: f64,
    /// At the log's largest force (true) or its smallest.
    pub high: bool,
    /// Samples at that value.
    pub samples: usize,
    /// The positions those samples span (mm).
    pub from_mm: f64,
    /// Their end (mm).
    pub to_mm: f64,
}

/// How near an end of the logged deflections (as a share of their range) a clipped force's
/// positions must reach for [`measured_span`] to take that end off.
pub const CLIP_EDGE_SHARE: f64 = 0.02;

/// The logged deflections `lo ... hi` (mm) where the force was measured: a force clipped at
/// the top or bottom of the load cell's range ([`ForceClip`]) over positions that reach an
/// end of the log's takes that end off, from the first clipped position on (a spring's force
/// rises with deflection, so the clip holds the stroke's end). validate's coverage counts
/// what is left, and identification and the diagnosis fit only the samples inside it
/// ([`CalibrationLog::unmeasured_force`]): the stroke beyond a clip is not measured, though
/// the rod travelled it. A clip inside the range (neither end) leaves it as it is. Returns the
/// span and, where it was narrowed, the clip that narrowed it.
pub fn measured_span(
    lo: f64,
    hi: f64,
    clips: &[Option<ForceClip>],
) -> (f64, f64, Option<ForceClip>) {
    let edge = CLIP_EDGE_SHARE * (hi - lo).max(0.0);
    let (mut from, mut to, mut by) = (lo, hi, None);
    for c in clips.iter().flatten() {
        if c.to_mm >= hi - edge && c.from_mm < to {
            to = c.from_mm;
            by = Some(*c);
        } else if c.from_mm <= lo + edge && c.to_mm > from {
            from = c.to_mm;
            by = Some(*c);
        }
    }
    (from, to.max(from), by)
}

/// Which samples read a force that is not the spring's, by their force and position: a
/// reading at a clip's value, and every sample at or beyond a position where the rod's force
/// stops being measured (a clip's onset at an end of the stroke, [`measured_span`], or a stop
/// the rod stands against). The default measures everything.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct UnmeasuredForce {
    /// Forces a load cell sticks at (N).
    pub clip_values_n: Vec<f64>,
    /// Samples at or below this position are not measured (mm).
    pub below_mm: Option<f64>,
    /// Samples at or above this position are not measured (mm).
    pub above_mm: Option<f64>,
}

impl UnmeasuredForce {
    /// Whether a sample with this force and position reads something other than the spring.
    pub fn holds(&self, force_n: f64, position_mm: f64) -> bool {
        self.above_mm.is_some_and(|a| position_mm >= a)
            || self.below_mm.is_some_and(|b| position_mm <= b)
            || self.clip_values_n.contains(&force_n)
    }

    /// Whether every sample is measured.
    pub fn is_empty(&self) -> bool {
        self.clip_values_n.is_empty() && self.below_mm.is_none() && self.above_mm.is_none()
    }

    /// Also leaves out the samples beyond `from_mm`: above it (`high`) or below it.
    pub fn beyond(mut self, from_mm: f64, high: bool) -> UnmeasuredForce {
        if high {
            self.above_mm = Some(self.above_mm.map_or(from_mm, |a| a.min(from_mm)));
        } else {
            self.below_mm = Some(self.below_mm.map_or(from_mm, |b| b.max(from_mm)));
        }
        self
    }
}

/// The fewest samples at a force extreme that [`ClipWatch`] calls a clip (and at least
/// [`CLIP_MIN_SHARE`] of the log).
pub const CLIP_MIN_SAMPLES: usize = 10;

/// The least share of a log's samples at a force extreme that [`ClipWatch`] calls a clip.
pub const CLIP_MIN_SHARE: f64 = 0.005;

/// The least share of the log's position range that the samples at a force extreme must span
/// for [`ClipWatch`] to call it a clip: a rod that moves on while the force stands still. A
/// coarse load cell's top reading repeats too, at a hold or a turn, but there the rod stands
/// within the position noise, and a spring's force moves by a quantum within a fraction of a
/// millimetre.
pub const CLIP_MIN_SPAN_SHARE: f64 = 0.1;

/// One extreme of the force seen so far, as `value` = the force times `sign` (+1 for the
/// largest, -1 for the smallest): how many samples hold it exactly, the positions they span,
/// and the next value short of it with its count since it became the next.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Extreme {
    sign: f64,
    value: f64,
    samples: usize,
    from_mm: f64,
    to_mm: f64,
    next_value: f64,
    next_samples: usize,
}

impl Extreme {
    fn new(sign: f64) -> Extreme {
        Extreme {
            sign,
            value: f64::NAN,
            samples: 0,
            from_mm: f64::NAN,
            to_mm: f64::NAN,
            next_value: f64::NAN,
            next_samples: 0,
        }
    }

    /// Takes a sample: a new extreme starts over (the old one becomes the next), the same
    /// value is counted, and a value between the two becomes the next.
    fn push(&mut self, force_n: f64, position_mm: f64) {
        let v = self.sign * force_n;
        if self.samples == 0 || v > self.value {
            if self.samples > 0 {
                (self.next_value, self.next_samples) = (self.value, self.samples);
            }
            (self.value, self.samples) = (v, 1);
            (self.from_mm, self.to_mm) = (position_mm, position_mm);
        } else if v == self.value {
            self.samples += 1;
            self.from_mm = self.from_mm.min(position_mm);
            self.to_mm = self.to_mm.max(position_mm);
        } else if v == self.next_value {
            self.next_samples += 1;
        } else if self.next_samples == 0 || v > self.next_value {
            (self.next_value, self.next_samples) = (v, 1);
        }
    }
}

/// How many times the samples at the value next to an extreme the extreme's must be for
/// [`ClipWatch`] to call it a clip. A force read in coarse steps holds each of its values on
/// many samples, at the soft end of the stroke over millimetres, and its extreme about as
/// often as the step next to it; a load cell at the end of its range holds its last value
/// while the force it would read goes on rising, and the value next to it is one of the many
/// a finely resolved force passes once or twice.
pub const CLIP_NEXT_RATIO: usize = 10;

/// Watches a log's force for a value it sticks at while the position moves: the largest force
/// read exactly on many samples spread over the stroke, far more often than the value next to
/// it, is a load cell (or its amplifier, or its converter) at the end of its range, which the
/// fit then takes out as transients or bends the law to. Constant memory, one pass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClipWatch {
    high: Extreme,
    low: Extreme,
    samples: usize,
    position_mm: (f64, f64),
}

impl Default for ClipWatch {
    fn default() -> ClipWatch {
        ClipWatch {
            high: Extreme::new(1.0),
            low: Extreme::new(-1.0),
            samples: 0,
            position_mm: (f64::INFINITY, f64::NEG_INFINITY),
        }
    }
}

impl ClipWatch {
    /// Takes one sample.
    pub fn push(&mut self, force_n: f64, position_mm: f64) {
        self.samples += 1;
        self.position_mm = (
            self.position_mm.0.min(position_mm),
            self.position_mm.1.max(position_mm),
        );
        self.high.push(force_n, position_mm);
        self.low.push(force_n, position_mm);
    }

    /// The clips found: the largest force, then the smallest, where at least
    /// [`CLIP_MIN_SAMPLES`] and [`CLIP_MIN_SHARE`] of the samples hold it, over at least
    /// [`CLIP_MIN_SPAN_SHARE`] of the position range, [`CLIP_NEXT_RATIO`] times as many as
    /// hold the value next to it.
    pub fn clips(&self) -> [Option<ForceClip>; 2] {
        let range = self.position_mm.1 - self.position_mm.0;
        let needed = CLIP_MIN_SAMPLES.max((CLIP_MIN_SHARE * self.samples as f64).ceil() as usize);
        let clip = |e: &Extreme| {
            (e.samples >= needed
                && e.samples >= CLIP_NEXT_RATIO * e.next_samples
                && range > 0.0
                && e.to_mm - e.from_mm >= CLIP_MIN_SPAN_SHARE * range)
                .then_some(ForceClip {
                    force_n: e.sign * e.value,
                    high: e.sign > 0.0,
                    samples: e.samples,
                    from_mm: e.from_mm,
                    to_mm: e.to_mm,
                })
        };
        [clip(&self.high), clip(&self.low)]
    }

    /// The watch over every sample of `log`.
    pub fn of(log: &CalibrationLog) -> ClipWatch {
        let mut w = ClipWatch::default();
        for (&f, &x) in log.force_n.iter().zip(&log.position_mm) {
            w.push(f, x);
        }
        w
    }
}

/// What reading a log found besides its samples, as the reader streaming it
/// ([`LogReader::reading`]) and the log read whole ([`CalibrationLog::reading`]) both hold it:
/// the lines skipped, the columns read by name or in a units row's units, the gaps filled, the
/// rows left out and the intervals' scatter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading<'a> {
    /// The lines skipped before the header ([`LogReader::preamble`]).
    pub preamble: Option<(u64, u64)>,
    /// The rate the rows were read at, for a log without a time column.
    pub rows_at_hz: Option<f64>,
    /// The columns read by their names ([`LogReader::recognised`]).
    pub recognised: &'a [RecognisedColumn],
    /// The units row under the header ([`LogReader::units_row`]).
    pub units_row: Option<&'a (u64, [String; 3])>,
    /// Dropped samples filled by interpolation.
    pub filled: &'a [FilledGap],
    /// The lines of the first rows left out ([`LogReader::left_out`]).
    pub left_out: &'a [u64],
    /// How many rows were left out.
    pub left_out_count: usize,
    /// The sampling intervals' scatter ([`LogReader::interval_scatter`]).
    pub interval_scatter: Option<f64>,
    /// The mean sampling interval (s), once there are two samples.
    pub mean_interval_s: Option<f64>,
    /// Where the force sticks at its largest or smallest value while the rod moves.
    pub force_clips: [Option<ForceClip>; 2],
}

/// A column the reader took for a quantity by its name, the header lacking the column the map
/// names for it by default (`t_s`, `force_n`, `position_mm`): the one column whose name reads
/// as that quantity (`Time [ms]`, `Load (kN)`, `Extension (mm)`), in the unit its name carries
/// or, for a name that carries none (`Time`), the unit of a units row under the header.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecognisedColumn {
    /// `time`, `force` or `position`.
    pub quantity: &'static str,
    /// The column's name in the header.
    pub name: String,
    /// The unit it is read in.
    pub unit: String,
    /// Whether the unit came from a units row rather than the name.
    pub from_units_row: bool,
}

impl CalibrationLog {
    /// What reading the log found besides its samples.
    pub fn reading(&self) -> Reading<'_> {
        Reading {
            preamble: self.preamble,
            rows_at_hz: self.rows_at_hz,
            recognised: &self.recognised,
            units_row: self.units_row.as_ref(),
            filled: &self.filled,
            left_out: &self.left_out.0,
            left_out_count: self.left_out.1,
            interval_scatter: self.interval_scatter,
            mean_interval_s: Some(self.dt_s()).filter(|dt| dt.is_finite()),
            force_clips: ClipWatch::of(self).clips(),
        }
    }

    /// Which of the log's samples `offset .. offset + n` read a force that is not the spring's:
    /// those at a clip's value ([`ForceClip`]), and, where a clip holds an
    /// end of the logged positions, every sample from its first clipped position on
    /// ([`measured_span`]). There no sample is clipped below the clip's
    /// onset, so those fitted are not cut off at the load cell's top.
    pub fn unmeasured_force(&self, offset: usize, n: usize) -> Vec<bool> {
        let rule = self.force_clip_rule();
        (offset..offset + n)
            .map(|i| rule.holds(self.force_n[i], self.position_mm[i]))
            .collect()
    }

    /// The rule [`CalibrationLog::unmeasured_force`] applies to each sample, for samples read
    /// as a stream (the EKF's passes).
    pub fn force_clip_rule(&self) -> UnmeasuredForce {
        let clips = self.reading().force_clips;
        if clips.iter().all(Option::is_none) {
            return UnmeasuredForce::default();
        }
        let (lo, hi) = self.position_range_mm();
        let (from, to, _) = measured_span(lo, hi, &clips);
        UnmeasuredForce {
            clip_values_n: clips.iter().flatten().map(|c| c.force_n).collect(),
            below_mm: (from > lo).then_some(from),
            above_mm: (to < hi).then_some(to),
        }
    }

    /// Moves the encoder zero: every position becomes x - `offset_mm`.
    pub fn shift_position(&mut self, offset_mm: f64) {
        for x in self.position_mm.iter_mut() {
            *x -= offset_mm;
        }
    }

    /// The smallest and largest position (mm).
    pub fn position_range_mm(&self) -> (f64, f64) {
        self.position_mm
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            })
    }

    /// Sampling interval (mean).
    pub fn dt_s(&self) -> f64 {
        if self.t_s.len() < 2 {
            return f64::NAN;
        }
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

/// One sample of a log, in s, N and mm.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sample {
    /// Time.
    pub t_s: f64,
    /// Rod force.
    pub force_n: f64,
    /// Deflection.
    pub position_mm: f64,
}

/// The units of a units row (the row under the header of some loggers: `s;N;mm`, `[s] [N]
/// [mm]`): each mapped field a unit of its column's dimension, brackets allowed, with its
/// factor to s, N or mm (without a time column, `timed` false, force and position only).
/// None when any field is not one.
fn units_row(
    record: &csv::StringRecord,
    cols: &[usize; 3],
    timed: bool,
) -> Option<[(String, f64); 3]> {
    let mut out: [(String, f64); 3] = Default::default();
    // Without a time column, the time's unit is the seconds the rows' times are in.
    if !timed {
        out[0] = ("s".to_string(), 1.0);
    }
    for k in usize::from(!timed)..3 {
        let text = record.get(cols[k])?.trim();
        let unit = text
            .trim_start_matches(['[', '('])
            .trim_end_matches([']', ')'])
            .trim();
        if unit.is_empty() || unit.parse::<f64>().is_ok() {
            return None;
        }
        let (name, factor) = unit_of(unit, QUANTITIES[k].1)?;
        out[k] = (name.to_string(), factor);
    }
    Some(out)
}

/// A time column written as clock time, read as seconds from the first row's: a date and time
/// (`2026-11-27T08:35:31.120`, `2026-11-27 08:35:31.120`, `2026/11/27 08:35:31.120`, with an
/// optional UTC offset as RFC 3339 gives it), or a time of day (`08:35:31.120`) that may pass
/// midnight.
#[derive(Debug, Default)]
struct Clock {
    /// The first row's clock.
    origin: Option<chrono::NaiveDateTime>,
    /// Whole days a time of day has wrapped past midnight.
    days: i64,
    /// The last time of day read (s after midnight).
    last_of_day: Option<f64>,
}

impl Clock {
    /// Seconds from the first row's clock, or None when `text` is not a clock.
    fn seconds(&mut self, text: &str, delimiter: u8) -> Option<f64> {
        use chrono::{NaiveDate, NaiveDateTime, NaiveTime, Timelike};
        // ISO 8601 allows a decimal comma before the fraction of a second.
        let text = if delimiter != b',' {
            std::borrow::Cow::Owned(text.replace(',', "."))
        } else {
            std::borrow::Cow::Borrowed(text)
        };
        let date_time = chrono::DateTime::parse_from_rfc3339(&text)
            .map(|d| d.naive_utc())
            .ok()
            .or_else(|| {
                [
                    "%Y-%m-%dT%H:%M:%S%.f",
                    "%Y-%m-%d %H:%M:%S%.f",
                    "%Y/%m/%d %H:%M:%S%.f",
                ]
                .iter()
                .find_map(|f| NaiveDateTime::parse_from_str(&text, f).ok())
            });
        let at = match date_time {
            Some(d) => d,
            None => {
                let time = NaiveTime::parse_from_str(&text, "%H:%M:%S%.f").ok()?;
                let of_day = f64::from(time.num_seconds_from_midnight())
                    + f64::from(time.nanosecond()) * 1e-9;
                // A time of day that falls by more than half a day has passed midnight.
                if self
                    .last_of_day
                    .is_some_and(|last| of_day < last - 43_200.0)
                {
                    self.days += 1;
                }
                self.last_of_day = Some(of_day);
                NaiveDate::from_ymd_opt(1970, 1, 1)?.and_time(time)
                    + chrono::Duration::days(self.days)
            }
        };
        let origin = *self.origin.get_or_insert(at);
        let since = at - origin;
        Some(since.num_seconds() as f64 + f64::from(since.subsec_nanos()) * 1e-9)
    }
}

/// The file as UTF-8 text: transcoded from UTF-16 where it is that.
type Decoded<R> = encoding_rs_io::DecodeReaderBytes<std::io::BufReader<R>, Vec<u8>>;

/// The source of the CSV records: the header line, then the rest with comments blanked.
type Records<R> = csv::Reader<
    std::io::Chain<
        std::io::Cursor<Vec<u8>>,
        WithoutComments<std::io::Chain<std::io::Cursor<Vec<u8>>, std::io::BufReader<Decoded<R>>>>,
    >,
>;

/// The file read as UTF-8 text, and whether it was UTF-16. A byte-order mark names UTF-8 or
/// UTF-16 (as Windows tools write them); without one, text whose first characters have a zero
/// byte each, first or second, is UTF-16 (big- or little-endian); anything else is read as it
/// is (UTF-8 or ASCII).
fn decode<R: Read>(reader: R) -> std::io::Result<(Decoded<R>, bool)> {
    let mut raw = std::io::BufReader::new(reader);
    let head = std::io::BufRead::fill_buf(&mut raw)?;
    let pairs: Vec<(u8, u8)> = head.chunks_exact(2).take(8).map(|c| (c[0], c[1])).collect();
    let all = |f: fn(&(u8, u8)) -> bool| pairs.len() >= 2 && pairs.iter().all(f);
    let guess = if all(|&(a, b)| a != 0 && b == 0) {
        Some(encoding_rs::UTF_16LE)
    } else if all(|&(a, b)| a == 0 && b != 0) {
        Some(encoding_rs::UTF_16BE)
    } else {
        None
    };
    let bom = if head.starts_with(&[0xFF, 0xFE]) {
        Some(encoding_rs::UTF_16LE)
    } else if head.starts_with(&[0xFE, 0xFF]) {
        Some(encoding_rs::UTF_16BE)
    } else {
        None
    };
    let utf16 = bom.or(guess).is_some();
    let decoded = encoding_rs_io::DecodeReaderBytesBuilder::new()
        .encoding(guess)
        .bom_override(true)
        .strip_bom(true)
        .build(raw);
    Ok((decoded, utf16))
}

/// A log read sample by sample: the streaming form of [`read_log`], for logs too long to hold
/// (a day at 1 kHz is 86 million rows). Memory is constant: one CSV record, the samples of a
/// filled gap, and the list of gaps.
///
/// It yields the samples in order, dropped samples filled in (listed by
/// [`LogReader::filled`]). Errors end the iteration: a malformed row at once; gaps too long
/// to fill, and a log too short to use, after the last sample, so that every long gap is named.
pub struct LogReader<R: Read> {
    rdr: Records<R>,
    offset: u64,
    header_fields: usize,
    /// The header's fields (trimmed), to know a repeated header.
    header: Vec<String>,
    /// Whether the file is UTF-16 (read transcoded; its bytes are twice the text's).
    utf16: bool,
    cols: [usize; 3],
    factors: [f64; 3],
    names: [String; 3],
    sampling_tolerance: f64,
    record: csv::StringRecord,
    nominal: Option<f64>,
    /// Time of the first sample, and the sampling intervals since it.
    first_t_s: Option<f64>,
    /// The finest resolution (s) the times were written with so far (a writer that drops
    /// trailing zeros writes some coarser than it keeps).
    time_resolution_s: f64,
    intervals: u64,
    previous: Option<Sample>,
    queued: std::collections::VecDeque<Sample>,
    long_gaps: Vec<FilledGap>,
    filled: Vec<FilledGap>,
    delimiter: u8,
    clock: Clock,
    /// Whether the first record after the header was looked at for a units row.
    units_checked: bool,
    /// A units row under the header: its line and the units it gives time, force and position.
    units_row: Option<(u64, [String; 3])>,
    /// Columns read by their names ([`LogReader::recognised`]).
    recognised: Vec<RecognisedColumn>,
    /// For a column read by a name that carries no unit: the missing column's error, raised
    /// when no units row gives the unit.
    unit_pending: Option<LogError>,
    /// The single sampling intervals (no gap in them): their sum, sum of squares and count.
    interval_sums: (f64, f64, u64),
    /// The force's extremes, for a load cell at the end of its range.
    clip_watch: ClipWatch,
    /// The lines skipped before the header ([`LogReader::preamble`]).
    preamble: Option<(u64, u64)>,
    /// Rows at a given rate, with no time column ([`ColumnMap::rows_at_hz`]), and the data
    /// rows read so far.
    rows_at_hz: Option<f64>,
    rows: u64,
    /// Rows with no value since the last complete one: their lines (the first few) and count.
    empty: (Vec<u64>, usize),
    /// Rows with no value before the first complete row or after the last: not filled.
    left_out: Vec<u64>,
    left_out_count: usize,
    /// The first field with no value: (line, column).
    first_empty: Option<(u64, usize)>,
    samples: usize,
    done: bool,
}

impl<R: Read> std::fmt::Debug for LogReader<R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LogReader")
            .field("columns", &self.names)
            .field("samples", &self.samples)
            .field("filled", &self.filled.len())
            .field("done", &self.done)
            .finish()
    }
}

impl<R: Read> LogReader<R> {
    /// Reads the header (the first line that is not a comment or blank) and finds the mapped
    /// columns. `sampling_tolerance` is the allowed relative deviation of each interval from
    /// the first (0.1 = 10 %).
    pub fn new(reader: R, map: &ColumnMap, sampling_tolerance: f64) -> Result<Self, LogError> {
        let (decoded, utf16) = decode(reader).map_err(|e| LogError::Io(format!("line 1: {e}")))?;
        let mut lines = std::io::BufReader::new(decoded);
        // The header is the first line that is not a comment or blank (or a spreadsheet's
        // `sep=X` line, which names the separator) and names the mapped columns. Where that
        // line does not, a line within the next [`PREAMBLE_LINES`] that does is the header,
        // and the lines before it a preamble (a DAQ's test name, date and rate, uncommented).
        // Where none does, the line that names the most of them (the first of equals) is,
        // refused for the column it lacks, and the lines read after it are read again.
        let mut line = 0u64;
        let mut text = Vec::new();
        let mut named = None;
        let mut first_line = None;
        let mut best: Option<(usize, u64, Vec<u8>)> = None;
        let mut after_best = Vec::new();
        let (header_line, mut header_text, replay, preamble) = loop {
            text.clear();
            let n = std::io::BufRead::read_until(&mut lines, b'\n', &mut text)
                .map_err(|e| LogError::Io(format!("line {}: {e}", line + 1)))?;
            line += 1;
            let looked_ahead = first_line.is_some_and(|f| line - f > PREAMBLE_LINES);
            if n == 0 || looked_ahead {
                let Some((_, at, header)) = best.take() else {
                    return Err(LogError::Io(format!(
                        "line {line}: no header line (the log is empty or holds only comments); \
                         expected a header such as t_s,force_n,position_mm"
                    )));
                };
                after_best.extend_from_slice(&text);
                break (at, header, std::mem::take(&mut after_best), None);
            }
            if best.is_some() {
                after_best.extend_from_slice(&text);
            }
            if is_comment_or_blank(&text) {
                continue;
            }
            let line_str = String::from_utf8_lossy(&text).into_owned();
            if first_line.is_none() {
                match Delimiter::from_sep_line(&line_str) {
                    Some(Some(d)) if named.is_none() => {
                        named = Some(d);
                        continue;
                    }
                    Some(None) => {
                        return Err(LogError::SeparatorLine {
                            line,
                            found: line_str.trim().to_string(),
                        })
                    }
                    _ => {}
                }
            }
            let count = named_columns(&line_str, separator_of(&line_str, map, named), map);
            if count == 3 {
                let preamble = first_line.map(|f| (f, line - 1));
                break (line, text.clone(), Vec::new(), preamble);
            }
            first_line.get_or_insert(line);
            if best.as_ref().is_none_or(|(most, _, _)| count > *most) {
                best = Some((count, line, text.clone()));
                after_best.clear();
            }
        };
        let header_str = String::from_utf8_lossy(&header_text).into_owned();
        let separator = separator_of(&header_str, map, named);
        let delimiter = separator.byte();
        let collapse = separator == Delimiter::Whitespace;
        if collapse {
            header_text = collapse_blanks(&header_text);
        }
        // The CSV reader sees the header, then the rest with comments blanked; its line numbers
        // are offset by the lines before the header.
        let body = WithoutComments {
            inner: std::io::Cursor::new(replay).chain(lines),
            line: Vec::new(),
            at: 0,
            collapse,
        };
        let mut rdr = csv::ReaderBuilder::new()
            .has_headers(true)
            .flexible(true)
            .delimiter(delimiter)
            .from_reader(std::io::Cursor::new(header_text.clone()).chain(body));
        let offset = header_line - 1;
        let header = rdr
            .headers()
            .map_err(|e| LogError::Io(format!("line {header_line}: {e}")))?
            .clone();
        let columns: Vec<String> = header.iter().map(|h| h.trim().to_string()).collect();
        // A column left at its default name that the header lacks is the header's one column
        // whose name reads as the quantity, in the unit the name carries (or, for a name that
        // carries none, a units row's: refused when there is no units row).
        let defaults = ColumnMap::default();
        let mut map = map.clone();
        let mut recognised = Vec::new();
        let mut unit_pending = None;
        for (what, dim) in QUANTITIES {
            // A column another quantity is mapped to is not a candidate.
            let taken = [&map.time.name, &map.force.name, &map.position.name].map(String::clone);
            let (column, default) = match what {
                "time" => (&mut map.time, &defaults.time),
                "force" => (&mut map.force, &defaults.force),
                _ => (&mut map.position, &defaults.position),
            };
            if column != default
                || columns.contains(&column.name)
                || (what == "time" && map.rows_at_hz.is_some())
            {
                continue;
            }
            let candidates: Vec<_> = reading_as(what, &columns)
                .into_iter()
                .filter(|(name, _)| !taken.contains(name))
                .collect();
            let [(name, unit)] = candidates[..] else {
                continue;
            };
            if unit.is_none() && unit_pending.is_none() {
                unit_pending = Some(LogError::MissingColumn {
                    line: header_line,
                    name: column.name.clone(),
                    what,
                    header: header_str.trim_end().to_string(),
                    columns: columns.clone(),
                    delimiter: separator.name(),
                });
            }
            *column = Column {
                name: name.clone(),
                factor: unit
                    .and_then(|u| unit_of(u, dim))
                    .map_or(1.0, |(_, factor)| factor),
            };
            recognised.push(RecognisedColumn {
                quantity: what,
                name: name.clone(),
                unit: unit.unwrap_or(dim.units()[0].0).to_string(),
                from_units_row: unit.is_none(),
            });
        }
        let map = &map;
        let find = |c: &Column, what: &'static str| {
            let count = columns.iter().filter(|h| **h == c.name).count();
            if count > 1 {
                return Err(LogError::DuplicateColumn {
                    line: header_line,
                    name: c.name.clone(),
                    what,
                    count,
                });
            }
            columns
                .iter()
                .position(|h| *h == c.name)
                .ok_or_else(|| LogError::MissingColumn {
                    line: header_line,
                    name: c.name.clone(),
                    what,
                    header: header_str.trim_end().to_string(),
                    columns: columns.clone(),
                    delimiter: separator.name(),
                })
        };
        // A header line that ends in a separator names no column there: rows may or may not
        // end in one too.
        let header_fields = if columns.len() > 1 && columns.last().is_some_and(String::is_empty) {
            columns.len() - 1
        } else {
            columns.len()
        };
        let cols = [
            match map.rows_at_hz {
                Some(_) => usize::MAX,
                None => find(&map.time, "time")?,
            },
            find(&map.force, "force")?,
            find(&map.position, "position")?,
        ];
        Ok(LogReader {
            rdr,
            offset,
            header_fields,
            header: columns.clone(),
            utf16,
            cols,
            factors: [map.time.factor, map.force.factor, map.position.factor],
            names: [
                map.time.name.clone(),
                map.force.name.clone(),
                map.position.name.clone(),
            ],
            sampling_tolerance,
            record: csv::StringRecord::new(),
            nominal: None,
            first_t_s: None,
            time_resolution_s: f64::INFINITY,
            intervals: 0,
            previous: None,
            queued: std::collections::VecDeque::new(),
            long_gaps: Vec::new(),
            filled: Vec::new(),
            delimiter,
            clock: Clock::default(),
            units_checked: false,
            units_row: None,
            recognised,
            unit_pending,
            interval_sums: (0.0, 0.0, 0),
            clip_watch: ClipWatch::default(),
            preamble,
            rows_at_hz: map.rows_at_hz,
            rows: 0,
            empty: (Vec::new(), 0),
            left_out: Vec::new(),
            left_out_count: 0,
            first_empty: None,
            samples: 0,
            done: false,
        })
    }

    /// A units row under the header (`s;N;mm`, as some loggers write one), when there was
    /// one: its line and the units read for time, force and position. A column read in its
    /// default unit (s, N, mm) is read in the row's; one given another unit keeps it.
    pub fn units_row(&self) -> Option<&(u64, [String; 3])> {
        self.units_row.as_ref()
    }

    /// The columns read by their names: where the header lacks a column the map names by its
    /// default (`t_s`, `force_n`, `position_mm`) and exactly one of its columns reads as that
    /// quantity ([`RecognisedColumn`]). Empty when every column was found as mapped.
    pub fn recognised(&self) -> &[RecognisedColumn] {
        &self.recognised
    }

    /// The scatter of the single sampling intervals read so far about their mean, beyond what
    /// the times' written rounding explains (its largest, a quarter of the resolution squared,
    /// is taken out of the variance), as a fraction of the mean interval; None before two
    /// intervals. Samples are read as evenly spaced: right where only a clock's stamps jitter,
    /// and a bias in inertia and damping where the samples were taken at the stamped times.
    pub fn interval_scatter(&self) -> Option<f64> {
        let (sum, sum_sq, n) = self.interval_sums;
        if n < 2 {
            return None;
        }
        let mean = sum / n as f64;
        let variance = (sum_sq / n as f64 - mean * mean).max(0.0);
        let resolution = if self.time_resolution_s < mean {
            self.time_resolution_s
        } else {
            0.0
        };
        Some((variance - 0.25 * resolution * resolution).max(0.0).sqrt() / mean)
    }

    /// The first and last line of a preamble before the header: lines that were neither
    /// comments nor a header naming the mapped columns, followed within [`PREAMBLE_LINES`] by
    /// one that is. None where the header was the first such line.
    pub fn preamble(&self) -> Option<(u64, u64)> {
        self.preamble
    }

    /// The rate the rows are read at, for a log without a time column
    /// ([`ColumnMap::rows_at_hz`]).
    pub fn rows_at_hz(&self) -> Option<f64> {
        self.rows_at_hz
    }

    /// Dropped samples filled in so far.
    pub fn filled(&self) -> &[FilledGap] {
        &self.filled
    }

    /// Lines of rows with no value (empty or NaN) that could not be filled, because no complete
    /// row comes before them (the log's start) or after them (its end): left out.
    pub fn left_out(&self) -> &[u64] {
        &self.left_out
    }

    /// Bytes of the file read so far (for progress).
    pub fn bytes_read(&self) -> u64 {
        let text = self.record.position().map_or(0, |p| p.byte());
        if self.utf16 {
            2 * text
        } else {
            text
        }
    }

    /// Samples yielded so far, filled ones included.
    pub fn samples(&self) -> usize {
        self.samples
    }

    /// Reads the next record into the queue (with the samples of a filled gap before it);
    /// `Ok(false)` at the end of the file.
    fn read_next(&mut self) -> Result<bool, LogError> {
        match self.rdr.read_record(&mut self.record) {
            Ok(false) => {
                // A column read by a name without a unit, and no units row to give it one.
                if let Some(e) = self.unit_pending.take() {
                    return Err(e);
                }
                return Ok(false);
            }
            Ok(true) => {}
            Err(e) => {
                let line = e.position().map_or(0, |p| p.line()) + self.offset;
                return Err(LogError::Io(format!("line {line}: {e}")));
            }
        }
        let record = &self.record;
        let line = record.position().map_or(0, |p| p.line()) + self.offset;
        if record.len() < self.header_fields {
            return Err(LogError::ShortRow {
                line,
                found: record.len(),
                expected: self.header_fields,
            });
        }
        // More fields than the header: a decimal comma in a comma-separated log reads as two
        // fields, so a row with more is refused (empty ones, a trailing separator, are not).
        if (self.header_fields..record.len()).any(|i| !record[i].trim().is_empty()) {
            return Err(LogError::LongRow {
                line,
                found: record.len(),
                expected: self.header_fields,
            });
        }
        // A row that repeats the header: two runs in one file.
        if record.get(self.cols[1]).map(str::trim) == Some(self.header[self.cols[1]].as_str())
            && record
                .iter()
                .zip(&self.header)
                .all(|(field, name)| field.trim() == name)
        {
            return Err(LogError::RepeatedHeader { line });
        }
        if !self.units_checked {
            self.units_checked = true;
            if let Some(units) = units_row(record, &self.cols, self.rows_at_hz.is_none()) {
                for (k, (_, factor)) in units.iter().enumerate() {
                    if self.factors[k] == 1.0 {
                        self.factors[k] = *factor;
                    }
                }
                for r in self.recognised.iter_mut().filter(|r| r.from_units_row) {
                    let k = QUANTITIES
                        .iter()
                        .position(|(q, _)| *q == r.quantity)
                        .unwrap_or(0);
                    r.unit = units[k].0.clone();
                }
                self.unit_pending = None;
                self.units_row = Some((line, units.map(|(u, _)| u)));
                return Ok(true);
            }
            if let Some(e) = self.unit_pending.take() {
                return Err(e);
            }
        }
        let mut v = [0.0; 3];
        let mut resolution_s = 0.0;
        let mut no_value = false;
        self.rows += 1;
        for k in 0..3 {
            if let (0, Some(rate)) = (k, self.rows_at_hz) {
                // No time column: the row's number at the given rate.
                v[0] = (self.rows - 1) as f64 / rate;
                continue;
            }
            let text = record.get(self.cols[k]).unwrap_or("").trim();
            if is_no_value(text) {
                no_value = true;
                self.first_empty.get_or_insert((line, k));
                v[k] = f64::NAN;
                continue;
            }
            let number = parse_number(text, self.delimiter);
            let clock = match (k, number) {
                (0, None) => self.clock.seconds(text, self.delimiter),
                _ => None,
            };
            if k == 0 {
                resolution_s = written_resolution(text)
                    * if clock.is_some() {
                        1.0
                    } else {
                        self.factors[0]
                    };
            }
            v[k] = match (number, clock) {
                (Some(x), _) => x * self.factors[k],
                (None, Some(seconds)) => seconds,
                (None, None) => {
                    return Err(LogError::BadNumber {
                        line,
                        column: self.names[k].clone(),
                        found: text.to_string(),
                        time: k == 0,
                    })
                }
            };
            // Time may be a clock (epoch seconds); force and position have physical bounds.
            let limit = if k == 0 { f64::MAX } else { MAX_MAGNITUDE };
            if !v[k].is_finite() || v[k].abs() >= limit {
                return Err(LogError::OutOfRange {
                    line,
                    column: self.names[k].clone(),
                    found: text.to_string(),
                    value: v[k],
                    unit: ["s", "N", "mm"][k],
                    limit,
                });
            }
        }
        if no_value {
            // A dropped reading: filled with the samples of a gap when a complete row follows.
            if self.previous.is_none() {
                self.push_left_out(line);
            } else {
                if self.empty.0.len() <= MAX_FILLED_SAMPLES {
                    self.empty.0.push(line);
                }
                self.empty.1 += 1;
            }
            return Ok(true);
        }
        let sample = Sample {
            t_s: v[0],
            force_n: v[1],
            position_mm: v[2],
        };
        if let Some(prev) = self.previous {
            let dt = sample.t_s - prev.t_s;
            if dt <= 0.0 {
                let first = self.first_t_s.unwrap_or(prev.t_s);
                let interval = self.nominal.unwrap_or(0.0);
                return Err(LogError::TimeNotIncreasing {
                    line,
                    t_s: sample.t_s,
                    previous_s: prev.t_s,
                    restarted: self.intervals > 10
                        && sample.t_s <= first + 10.0 * interval.max(0.0),
                });
            }
            let tolerance = self.sampling_tolerance;
            // An interval is known only to the times' written resolution: a rig at 300 Hz that
            // writes milliseconds has intervals of 3 and 4 ms. Where that resolution is finer
            // than an interval, its rounding is allowed on top of the tolerance, up to 0.4
            // intervals (beyond, one and two intervals could not be told apart). Times written
            // to the interval itself or coarser are whole intervals: nothing is rounded.
            self.time_resolution_s = self.time_resolution_s.min(resolution_s);
            let resolution = self.time_resolution_s;
            let allowed = |n: f64| {
                tolerance * n
                    + if resolution < n {
                        resolution.min(0.4 * n)
                    } else {
                        0.0
                    }
            };
            // Rows with no value between the two are dropped samples. When they fall before the
            // sampling interval is known, it is the time between the two complete rows shared
            // by the rows in between.
            let (empty, empty_rows) = std::mem::take(&mut self.empty);
            if self.nominal.is_none() {
                self.nominal = Some(dt / (empty_rows + 1) as f64);
            }
            // Sampling intervals from the previous sample to this one.
            let mut intervals = 1u64;
            match self.nominal {
                None => {}
                Some(n) if empty_rows > 0 && (dt - n).abs() <= allowed(n) => {
                    // No sample is missing: the rows with no value held none.
                    for l in empty {
                        self.push_left_out(l);
                    }
                    self.left_out_count += empty_rows.saturating_sub(MAX_FILLED_SAMPLES + 1);
                }
                // Over the first intervals the mean is still mostly the first one's jitter: an
                // interval within the tolerance of the mean with it counted is regular too (not
                // the first, and not one with rows of no value in it: those span a gap).
                Some(_)
                    if (1..EARLY_INTERVALS).contains(&self.intervals) && empty_rows == 0 && {
                        let with_this = (sample.t_s - self.first_t_s.unwrap_or(prev.t_s))
                            / (self.intervals + 1) as f64;
                        (dt - with_this).abs() <= allowed(with_this)
                    } => {}
                Some(n) if (dt - n).abs() > allowed(n) => {
                    // Dropped samples: a whole number of intervals, within the tolerance.
                    let k = (dt / n).round();
                    if k < 2.0 || (dt - k * n).abs() > allowed(n) {
                        return Err(LogError::Irregular {
                            line,
                            dt_s: dt,
                            nominal_s: n,
                            tolerance_percent: tolerance * 100.0,
                        });
                    }
                    let missing = (k as usize).saturating_sub(1);
                    intervals = k as u64;
                    let gap = FilledGap {
                        line,
                        after_s: prev.t_s,
                        samples: missing,
                        empty_rows: empty_rows.min(missing),
                    };
                    if missing > MAX_FILLED_SAMPLES {
                        if self.long_gaps.len() < 100 {
                            self.long_gaps.push(gap);
                        }
                    } else {
                        for j in 1..=missing {
                            let a = j as f64 / (missing + 1) as f64;
                            self.queued.push_back(Sample {
                                t_s: prev.t_s + a * dt,
                                force_n: prev.force_n + a * (sample.force_n - prev.force_n),
                                position_mm: prev.position_mm
                                    + a * (sample.position_mm - prev.position_mm),
                            });
                        }
                        self.filled.push(gap);
                    }
                }
                Some(_) => {}
            }
            if intervals == 1 && empty_rows == 0 {
                let (sum, sum_sq, n) = &mut self.interval_sums;
                *sum += dt;
                *sum_sq += dt * dt;
                *n += 1;
            }
            // The interval a sample is held to is the mean so far, not the first alone: a rig
            // whose clock jitters may start with an interval at the edge of the tolerance.
            self.intervals += intervals;
            let (first, count) = (self.first_t_s.unwrap_or(prev.t_s), self.intervals);
            self.nominal = Some((sample.t_s - first) / count as f64);
        } else {
            self.first_t_s = Some(sample.t_s);
            self.time_resolution_s = resolution_s;
        }
        self.previous = Some(sample);
        self.queued.push_back(sample);
        Ok(true)
    }

    /// Lists a row with no value that is not filled (the first 100).
    fn push_left_out(&mut self, line: u64) {
        if self.left_out.len() < 100 {
            self.left_out.push(line);
        }
        self.left_out_count += 1;
    }

    /// How many rows with no value were left out ([`LogReader::left_out`] lists the first 100).
    pub fn left_out_count(&self) -> usize {
        self.left_out_count
    }

    /// What reading the log has found so far besides its samples.
    pub fn reading(&self) -> Reading<'_> {
        Reading {
            preamble: self.preamble(),
            rows_at_hz: self.rows_at_hz(),
            recognised: self.recognised(),
            units_row: self.units_row(),
            filled: self.filled(),
            left_out: self.left_out(),
            left_out_count: self.left_out_count(),
            interval_scatter: self.interval_scatter(),
            mean_interval_s: {
                let (sum, _, n) = self.interval_sums;
                (n > 0).then(|| sum / n as f64)
            },
            force_clips: self.clip_watch.clips(),
        }
    }
}

impl<R: Read> Iterator for LogReader<R> {
    type Item = Result<Sample, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        // A row with no value queues nothing: read on until a sample is queued or the end.
        while self.queued.is_empty() && !self.done {
            match self.read_next() {
                Ok(true) => {}
                Ok(false) => {
                    self.done = true;
                    let (lines, count) = std::mem::take(&mut self.empty);
                    for line in lines {
                        self.push_left_out(line);
                    }
                    self.left_out_count += count.saturating_sub(MAX_FILLED_SAMPLES + 1);
                    if !self.long_gaps.is_empty() {
                        return Some(Err(LogError::Gaps {
                            gaps: std::mem::take(&mut self.long_gaps),
                        }));
                    }
                    if self.samples < MIN_LOG_SAMPLES {
                        if let Some((line, k)) = self.first_empty {
                            return Some(Err(LogError::NoValues {
                                line,
                                column: self.names[k].clone(),
                                rows: self.left_out_count,
                            }));
                        }
                        return Some(Err(LogError::TooShort {
                            found: self.samples,
                            needed: MIN_LOG_SAMPLES,
                        }));
                    }
                }
                Err(e) => {
                    self.done = true;
                    self.queued.clear();
                    return Some(Err(e));
                }
            }
        }
        let s = self.queued.pop_front()?;
        self.samples += 1;
        self.clip_watch.push(s.force_n, s.position_mm);
        Some(Ok(s))
    }
}

/// Intervals over which [`LogReader`] also holds an interval to the mean with it counted.
const EARLY_INTERVALS: u64 = 16;

/// The fewest samples a log may have.
pub const MIN_LOG_SAMPLES: usize = 16;

/// Reads a log. `sampling_tolerance` is the allowed relative deviation of each interval from
/// the first (0.1 = 10 %). `progress` is called with the bytes read so far.
///
/// Rig logs come as they are: lines that start with `#` or `;` (after blanks) and blank lines
/// are skipped anywhere; the field separator is the map's, or detected from the header line
/// (comma, tab or semicolon). An interval of k nominal intervals (within the tolerance) is k - 1
/// dropped samples: up to [`MAX_FILLED_SAMPLES`] in a row are filled by linear interpolation
/// and listed in [`CalibrationLog::filled`]; longer gaps are refused, all of them named.
/// [`LogReader`] reads the same logs sample by sample.
pub fn read_log<R: Read>(
    reader: R,
    map: &ColumnMap,
    sampling_tolerance: f64,
    progress: impl FnMut(u64),
) -> Result<CalibrationLog, LogError> {
    collect_log(LogReader::new(reader, map, sampling_tolerance)?, progress)
}

/// Reads the rest of a [`LogReader`] into a [`CalibrationLog`], with the gaps it filled;
/// `progress` is called with the bytes read so far.
pub fn collect_log<R: Read>(
    mut reader: LogReader<R>,
    mut progress: impl FnMut(u64),
) -> Result<CalibrationLog, LogError> {
    let mut log = CalibrationLog::default();
    while let Some(sample) = reader.next() {
        let s = sample?;
        log.t_s.push(s.t_s);
        log.force_n.push(s.force_n);
        log.position_mm.push(s.position_mm);
        if log.t_s.len().is_multiple_of(65_536) {
            progress(reader.bytes_read());
        }
    }
    log.left_out = (reader.left_out().to_vec(), reader.left_out_count());
    log.units_row = reader.units_row().cloned();
    log.recognised = reader.recognised.clone();
    log.interval_scatter = reader.interval_scatter();
    log.preamble = reader.preamble();
    log.rows_at_hz = reader.rows_at_hz();
    log.filled = reader.filled;
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

#[cfg(test)]
mod tests {
    use super::{power_of_ten, written_resolution};

    #[test]
    fn a_force_that_stands_at_its_end_while_the_rod_moves_is_a_clip_and_coarse_steps_are_not() {
        use super::{ClipWatch, ForceClip};
        // A spring F = exp(0.2 x) + 1 (2 to 21 N) swept sinusoidally over 0 ... 15 mm, 10 000
        // samples, with a deterministic noise of about 0.1 N written to 1e-6 N.
        let sweep = |read: &dyn Fn(f64) -> f64| {
            let mut w = ClipWatch::default();
            for i in 0..10_000 {
                let x = 7.5 - 7.5 * (i as f64 * 0.005).cos();
                let noise = 0.1 * ((i as f64 * 12.9898).sin() * 43_758.545).fract();
                let f = (0.2 * x).exp() + 1.0 + noise;
                w.push(read((f * 1e6).round() / 1e6), x);
            }
            w.clips()
        };
        assert_eq!(sweep(&|f| f), [None, None]);
        // A load cell that reads no more than 12 N: the force stands there from x = 12.0 mm
        // (e^2.4 + 1 = 12.0) to the end of the sweep.
        let [high, low] = sweep(&|f| f.min(12.0));
        let ForceClip {
            force_n,
            high: true,
            samples,
            from_mm,
            to_mm,
        } = high.unwrap()
        else {
            panic!("{high:?}")
        };
        assert_eq!(force_n, 12.0);
        assert!(
            samples > 1000 && (from_mm - 12.0).abs() < 0.1 && to_mm > 14.99,
            "{high:?}"
        );
        assert_eq!(low, None);
        // One that reads no less than 3 N (e^(0.2 x) + 1 = 3 at x = 3.47 mm): the smallest.
        let [high, low] = sweep(&|f| f.max(3.0));
        assert!(
            high.is_none() && low.is_some_and(|c| !c.high && c.force_n == 3.0 && c.from_mm < 0.01)
        );
        // Read in steps of 2 N, the smallest step (2 N) holds 0 ... 2.7 mm of the stroke, as
        // the one next to it holds the next 2 mm: not a clip. In steps of 0.5 N and clipped
        // at 12 N, the clip holds ten times the samples of the step below it: one.
        let stepped = |f: f64, q: f64| (f / q).round() * q;
        assert_eq!(sweep(&|f| stepped(f, 2.0)), [None, None]);
        assert_eq!(sweep(&|f| stepped(f, 0.5)), [None, None]);
        assert!(sweep(&|f| stepped(f, 0.5).min(12.0))[0].is_some());
    }

    #[test]
    fn intervals_in_messages_read_to_five_significant_digits() {
        assert_eq!(super::interval_text(1.0 / 300.0), "3.3333 ms");
        assert_eq!(super::interval_text(0.01), "10.000 ms");
        assert_eq!(super::interval_text(0.000_05), "0.050000 ms");
        assert_eq!(super::interval_text(2.5), "2.5000 s");
    }

    #[test]
    fn a_power_of_ten_from_the_table_is_the_one_powi_gives() {
        for k in -40..=40 {
            assert_eq!(power_of_ten(k).to_bits(), 10f64.powi(k).to_bits(), "10^{k}");
        }
    }

    #[test]
    fn a_times_resolution_is_one_unit_of_its_last_written_digit() {
        for (text, resolution) in [
            ("0.013", 1e-3),
            ("13", 1.0),
            ("1.3e-2", 1e-3),
            ("1.30E+3", 10.0),
            ("12,25", 1e-2),
            ("08:35:31.12", 1e-2),
            ("2026-11-27T08:35:31.120Z", 1e-3),
        ] {
            let r = written_resolution(text);
            assert!((r / resolution - 1.0).abs() < 1e-9, "{text}: {r}");
        }
    }
}
