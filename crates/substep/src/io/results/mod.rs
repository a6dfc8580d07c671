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
use std::path::{Path, PathBuf};

mod hdf5_writer;
pub mod mat5;
mod table;

pub use table::{BLOCK_ROWS, CsvTable, Metadata, column_unit, matlab_name, split_header};

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

#[cfg(test)]
mod tests {
    use super::table::asctime;
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
