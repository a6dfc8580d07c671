//! What the container writers share: the CSV table reader that streams a run's tables in
//! blocks, the column names and units, and the metadata (summary, config, creation date) that go
//! into every container.

use crate::error::{Error, Result};
use std::io::BufRead;

/// Rows converted per block (memory per column: 8 bytes × this).
pub const BLOCK_ROWS: usize = 8192;

/// A CSV header `name [unit]` (the benchmark's traces) split into its name and unit; a header
/// without the bracketed unit is all name.
pub fn split_header(column: &str) -> (&str, Option<&str>) {
    match column.strip_suffix(']').and_then(|c| c.rsplit_once(" [")) {
        Some((name, unit)) => (name, Some(unit)),
        None => (column, None),
    }
}

/// SI unit of a result column: the bracketed unit of a `name [unit]` header, else from its name
/// (the CSV headers of `substep run`): `m`, `m/s`, `m/s^2`, `N`, `N/m`, `N*s/m`, `J`, `s`, `Hz`,
/// or `1` for counts, indices and ratios.
pub fn column_unit<'a>(table: &str, column: &'a str) -> &'a str {
    if let (_, Some(unit)) = split_header(column) {
        return unit;
    }
    let stem = column.trim_end_matches(|c: char| c.is_ascii_digit());
    match (table, stem) {
        ("fourier", "f_hz") => "Hz",
        ("fourier", _) => "m/s^2",
        ("spectrum", "period_s") => "s",
        ("spectrum", "sd_m") => "m",
        ("spectrum", "psv_m_s") => "m/s",
        ("spectrum", _) => "m/s^2",
        (_, "t") => "s",
        (_, "step" | "substep" | "ramp" | "eta" | "margin") => "1",
        (_, "k_id") => "N/m",
        (_, "c_id") => "N*s/m",
        (_, "lag_id") => "s",
        (_, "u" | "uref" | "dm" | "cmd" | "te" | "du" | "drift") => "m",
        (_, "v") => "m/s",
        (_, "a" | "ag" | "a_abs") => "m/s^2",
        (_, "fc" | "fe" | "fu" | "fei" | "fm" | "shear" | "base_shear") => "N",
        (_, s) if s.starts_with("E_") => "J",
        _ => "",
    }
}

/// A CSV result table read back in blocks: header names, then rows of numbers.
pub struct CsvTable<R> {
    name: String,
    columns: Vec<String>,
    reader: R,
    line: String,
    line_no: usize,
}

/// The longest CSV line accepted (a table of 10⁵ DOFs is about 10 MB a row in the worst case).
const MAX_LINE: usize = 64 << 20;

impl<R: BufRead> CsvTable<R> {
    /// Read the header of `reader`; `name` is the file named in errors.
    pub fn new(name: impl Into<String>, mut reader: R) -> Result<Self> {
        let name = name.into();
        let mut line = String::new();
        read_line(&mut reader, &mut line, &name, 1)?;
        let columns: Vec<String> = line.trim_end().split(',').map(str::to_owned).collect();
        if line.trim().is_empty() {
            return Err(Error::file(&name, "has no header line"));
        }
        Ok(Self {
            name,
            columns,
            reader,
            line,
            line_no: 1,
        })
    }

    pub fn columns(&self) -> &[String] {
        &self.columns
    }

    /// Append up to `max_rows` rows, column-major, to `columns` (one `Vec` per column); the
    /// number of rows read (0 at the end).
    pub fn read_block(&mut self, columns: &mut [Vec<f64>], max_rows: usize) -> Result<usize> {
        let n = self.columns.len();
        let mut rows = 0;
        while rows < max_rows {
            self.line_no += 1;
            if !read_line(&mut self.reader, &mut self.line, &self.name, self.line_no)? {
                break;
            }
            let text = self.line.trim_end();
            if text.is_empty() {
                continue;
            }
            let mut k = 0;
            for field in text.split(',') {
                if k == n {
                    break;
                }
                let x: f64 = field.parse().map_err(|_| {
                    Error::file(
                        format!("{}:{}", self.name, self.line_no),
                        format!("column `{}`: `{field}` is not a number", self.columns[k]),
                    )
                })?;
                columns[k].push(x);
                k += 1;
            }
            if k != n || text.split(',').count() != n {
                return Err(Error::file(
                    format!("{}:{}", self.name, self.line_no),
                    format!("{} fields, the header has {n}", text.split(',').count()),
                ));
            }
            rows += 1;
        }
        Ok(rows)
    }
}

/// One line into `line` (cleared first); `false` at the end of the input.
fn read_line<R: BufRead>(reader: &mut R, line: &mut String, name: &str, line_no: usize) -> Result<bool> {
    line.clear();
    let n = std::io::Read::take(&mut *reader, MAX_LINE as u64 + 1)
        .read_line(line)
        .map_err(|e| Error::file(format!("{name}:{line_no}"), format!("cannot read: {e}")))?;
    if n > MAX_LINE {
        return Err(Error::file(
            format!("{name}:{line_no}"),
            format!("line longer than {MAX_LINE} bytes"),
        ));
    }
    Ok(n > 0)
}

/// What goes into a container besides the tables.
#[derive(Debug, Clone, Default)]
pub struct Metadata {
    /// The run summary (`summary.json`) as a JSON string.
    pub summary_json: String,
    /// The test definition's TOML text (empty when not known).
    pub config: String,
}

/// A MATLAB identifier for a column name: letters, digits and `_`, starting with a letter (other
/// characters become `_`, a leading non-letter gets an `x` in front), at most 63 characters.
pub fn matlab_name(name: &str) -> String {
    let mut s: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() || c == '_' { c } else { '_' })
        .collect();
    if !s.starts_with(|c: char| c.is_ascii_alphabetic()) {
        s.insert(0, 'x');
    }
    s.truncate(63);
    s
}

/// `Tue Dec  1 22:29:17 2026` (UTC, C `asctime` style as MATLAB writes it), from
/// `SOURCE_DATE_EPOCH` when set (reproducible builds of result files), else the clock.
pub(crate) fn created_on() -> String {
    let secs = std::env::var("SOURCE_DATE_EPOCH")
        .ok()
        .and_then(|s| s.parse::<i64>().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs() as i64)
        });
    asctime(secs)
}

pub(crate) fn asctime(secs: i64) -> String {
    let days = secs.div_euclid(86_400);
    let rem = secs.rem_euclid(86_400);
    // Civil date from days since 1970-01-01 (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    const WD: [&str; 7] = ["Thu", "Fri", "Sat", "Sun", "Mon", "Tue", "Wed"];
    const MO: [&str; 12] = [
        "Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec",
    ];
    format!(
        "{} {} {:2} {:02}:{:02}:{:02} {year}",
        WD[days.rem_euclid(7) as usize],
        MO[(month - 1) as usize],
        day,
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}
