//! `[output] format = "hdf5" | "mat"` (`--format`): after a run has written its CSV tables and
//! `summary.json`, gather them into `results.h5` or `results.mat` ([`crate::io::results`]).

use crate::io::results::{Format, Metadata, write_container};
use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// `summary.json` is small (peaks and errors per DOF); more than this is not ours.
const SUMMARY_MAX_BYTES: f64 = 256.0 * 1024.0 * 1024.0;

/// Whether a run that ended with `failure` (`None`: it completed) got as far as writing its
/// outputs: it completed, diverged or stopped (not when its input was refused, which leaves an
/// earlier run's files in place). Only then is a container gathered.
pub fn ran(failure: Option<&Error>) -> bool {
    failure.is_none_or(|e| matches!(e, Error::Diverged { .. } | Error::Stopped { .. }))
}

/// The container of `format` from the CSV tables and `summary.json` in `dir`, with the test
/// definition's text `config`; `None` for CSV (no container). A container that cannot be
/// written is an error naming the file.
pub fn write(dir: &Path, format: Format, config: String) -> Result<Option<PathBuf>> {
    if format == Format::Csv {
        return Ok(None);
    }
    let summary_path = dir.join("summary.json");
    let summary_json = crate::io::limits::read_text(&summary_path, SUMMARY_MAX_BYTES)?;
    let meta = Metadata { summary_json, config };
    write_container(dir, format, &meta)
}
