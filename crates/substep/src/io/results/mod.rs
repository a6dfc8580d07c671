//! Result containers: the CSV histories of a run gathered into one HDF5 file
//! (`results.h5`) or one MATLAB file (`results.mat`: level 5 for `mat`, v7.3 for `mat73`),
//! `[output] format`.
//!
//! The CSV files are always written first, row by row while the run steps (a run killed at any
//! moment keeps what it recorded); the container is built from them after the run, one table
//! per CSV file, streamed in blocks of [`BLOCK_ROWS`] rows so that its memory does not grow with
//! the length of the run. All three writers are pure Rust and in every build: the level-5
//! MAT-file is [`mat5`], HDF5 and MATLAB v7.3 are written with `hdf5-pure` (no libhdf5).
//!
//! Layout (both containers; see docs/config.md "Output formats"):
//! * `results.h5`: a group per table (`/history`, `/substeps`, `/response`, ...), in it one 1-D
//!   `f64` dataset per column (chunked, deflate-compressed) with a `units` attribute; the group
//!   has a `columns` attribute listing the columns in CSV order. The root holds the run
//!   summary as the JSON string attribute `summary` and the config text as `config`.
//! * `results.mat`: every table is a MATLAB struct of column vectors (`history.u1`), `summary`
//!   and `config` are char variables. `mat` writes a level-5 MAT-file (MATLAB's `-v7` without
//!   compression; 2 GB per table at most), with `units` (a struct of structs of char) besides;
//!   `mat73` writes MATLAB v7.3 (HDF5 with the 512-byte MATLAB user block) for larger runs.

use crate::error::{Error, Result};
use std::io::BufRead;
use std::path::{Path, PathBuf};

mod hdf5_writer;
pub mod mat5;

/// Rows converted per block (memory per column: 8 bytes × this).
pub const BLOCK_ROWS: usize = 8192;

/// The result tables in container order: CSV file stem (= group / struct name).
pub const TABLES: &[&str] = &[
    "history",
    "substeps",
    "response",
    "ground_motion",
    "fourier",
    "spectrum",
];

/// `[output] format`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Format {
    /// CSV files only.
    #[default]
    Csv,
    /// CSV files and `results.h5`.
    Hdf5,
    /// CSV files and `results.mat` (MATLAB level 5, pure Rust).
    Mat,
    /// CSV files and `results.mat` (MATLAB v7.3, an HDF5 file: for tables over 2 GB).
    Mat73,
}

impl Format {
    pub const NAMES: &'static [&'static str] = &["csv", "hdf5", "mat", "mat73"];

    /// The format named `name`; `what` (the config key or option) names it in errors.
    pub fn parse(what: &str, name: &str) -> Result<Self> {
        let f = match name {
            "csv" => Self::Csv,
            "hdf5" | "h5" => Self::Hdf5,
            "mat" => Self::Mat,
            "mat73" => Self::Mat73,
            other => {
                return Err(Error::invalid(
                    what,
                    format!("unknown output format `{other}` (expected csv, hdf5, mat or mat73)"),
                ));
            }
        };
        Ok(f)
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Csv => "csv",
            Self::Hdf5 => "hdf5",
            Self::Mat => "mat",
            Self::Mat73 => "mat73",
        }
    }

    /// The container's file name in the output directory (`None` for CSV).
    pub fn file_name(self) -> Option<&'static str> {
        match self {
            Self::Csv => None,
            Self::Hdf5 => Some("results.h5"),
            Self::Mat | Self::Mat73 => Some("results.mat"),
        }
    }
}

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

/// Gather the CSV tables of [`TABLES`] found in `dir` into the container of `format` in `dir`
/// (nothing for CSV). Returns the file written. The file is written under a temporary name
/// and renamed, so a failed conversion leaves no partial container.
pub fn write_container(dir: &Path, format: Format, meta: &Metadata) -> Result<Option<PathBuf>> {
    let Some(file_name) = format.file_name() else {
        return Ok(None);
    };
    let path = dir.join(file_name);
    let tables: Vec<(&str, PathBuf)> = TABLES
        .iter()
        .map(|t| (*t, dir.join(format!("{t}.csv"))))
        .filter(|(_, p)| p.is_file())
        .collect();
    write_impl(&path, format, &tables, meta)?;
    Ok(Some(path))
}

/// Write the CSV `tables` (`(name, csv path)`, in order) into the container of `format` at
/// `path` (under a temporary name, renamed: a failure leaves no partial file). Used for the
/// benchmark's traces; [`write_container`] for a run's results.
pub fn write_tables(path: &Path, format: Format, tables: &[(&str, PathBuf)], meta: &Metadata) -> Result<()> {
    if format == Format::Csv {
        return Err(Error::invalid("format", "csv is no container"));
    }
    write_impl(path, format, tables, meta)
}

fn write_impl(path: &Path, format: Format, tables: &[(&str, PathBuf)], meta: &Metadata) -> Result<()> {
    match format {
        // No container: both callers return before this (the CSV files are the result).
        Format::Csv => Ok(()),
        Format::Mat => write_via_temp(path, |tmp, shown| mat5::write_file(tmp, tables, meta, shown)),
        Format::Hdf5 => write_via_temp(path, |tmp, shown| hdf5_writer::write_h5(tmp, tables, meta, shown)),
        Format::Mat73 => write_via_temp(path, |tmp, shown| hdf5_writer::write_mat(tmp, tables, meta, shown)),
    }
}

/// Write the container at `path` through `write(tmp, shown)` into a temporary file beside it,
/// renamed into place: a failed conversion leaves no partial container (both writers).
fn write_via_temp(path: &Path, write: impl FnOnce(&Path, &str) -> Result<()>) -> Result<()> {
    let shown = path.display().to_string();
    let tmp = path.with_file_name(format!(
        ".{}.tmp",
        path.file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned())
    ));
    let result = write(&tmp, &shown).and_then(|()| {
        std::fs::rename(&tmp, path).map_err(|e| Error::file(&shown, format!("cannot rename into place: {e}")))
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn asctime_matches_known_dates() {
        assert_eq!(asctime(0), "Thu Jan  1 00:00:00 1970");
        // 2026-12-01T22:29:17Z (date -d @1796164157 -u)
        assert_eq!(asctime(1_796_164_157), "Tue Dec  1 22:29:17 2026");
        // leap day
        assert_eq!(asctime(951_782_400), "Tue Feb 29 00:00:00 2000");
    }

    #[test]
    fn units_of_the_run_columns() {
        assert_eq!(column_unit("history", "t"), "s");
        assert_eq!(column_unit("history", "u12"), "m");
        assert_eq!(column_unit("history", "uref3"), "m");
        assert_eq!(column_unit("history", "a2"), "m/s^2");
        assert_eq!(column_unit("history", "fei1"), "N");
        assert_eq!(column_unit("response", "E_kinetic"), "J");
        assert_eq!(column_unit("response", "a_abs4"), "m/s^2");
        assert_eq!(column_unit("spectrum", "psv_m_s"), "m/s");
        assert_eq!(column_unit("fourier", "f_hz"), "Hz");
        assert_eq!(column_unit("substeps", "substep"), "1");
    }

    #[test]
    fn csv_blocks_and_bad_rows() {
        let text = "t,u1\n0,1.5\n0.01,NaN\n0.02,-2e-3\n";
        let mut t = CsvTable::new("h.csv", text.as_bytes()).unwrap();
        assert_eq!(t.columns(), ["t", "u1"]);
        let mut cols = vec![Vec::new(), Vec::new()];
        assert_eq!(t.read_block(&mut cols, 2).unwrap(), 2);
        assert_eq!(t.read_block(&mut cols, 2).unwrap(), 1);
        assert_eq!(t.read_block(&mut cols, 2).unwrap(), 0);
        assert_eq!(cols[0], [0.0, 0.01, 0.02]);
        assert_eq!(cols[1][0], 1.5);
        assert!(cols[1][1].is_nan());
        assert_eq!(cols[1][2], -2e-3);
        let mut t = CsvTable::new("h.csv", "t,u1\n0,1\n1,x\n".as_bytes()).unwrap();
        let e = t.read_block(&mut cols, 10).unwrap_err().to_string();
        assert_eq!(e, "h.csv:3: column `u1`: `x` is not a number");
        let mut t = CsvTable::new("h.csv", "t,u1\n0,1,2\n".as_bytes()).unwrap();
        let e = t.read_block(&mut cols, 10).unwrap_err().to_string();
        assert_eq!(e, "h.csv:2: 3 fields, the header has 2");
    }

    #[test]
    fn formats_and_matlab_names() {
        assert_eq!(Format::parse("output.format", "csv").unwrap(), Format::Csv);
        let e = Format::parse("output.format", "xlsx").unwrap_err().to_string();
        assert!(e.starts_with("output.format: unknown output format `xlsx`"), "{e}");
        assert_eq!(Format::parse("output.format", "hdf5").unwrap(), Format::Hdf5);
        assert_eq!(Format::parse("output.format", "mat73").unwrap(), Format::Mat73);
        assert_eq!(matlab_name("u1"), "u1");
        assert_eq!(matlab_name("1a-b"), "x1a_b");
    }
}
