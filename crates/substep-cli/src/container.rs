//! `--format hdf5|mat` (`[output] format`): after a run has written its CSV tables and
//! `summary.json`, gather them into `results.h5` or `results.mat` (substep::io::results).

use crate::{DEFAULT_CONFIG, RunArgs};
use anyhow::{Result, anyhow};
use std::path::{Path, PathBuf};
use substep::io::results::{Format, Metadata, write_container};

/// The container format of a run: `--format` over the config's `[output] format`.
pub fn format(cli: Option<&str>, config: Format) -> Result<Format> {
    Ok(match cli {
        Some(name) => Format::parse("--format", name)?,
        None => config,
    })
}

/// After a run: gather its outputs in `dir` into the container of `format` when the run got as
/// far as writing them (it completed, diverged or stopped; not when its input was refused, which
/// leaves an earlier run's files in place). The run's own error stays the result; a container
/// that cannot be written is a runtime failure (exit code 1) naming the file.
pub fn finish(args: &RunArgs, dir: &Path, format: Format, run: Result<()>) -> Result<()> {
    if format == Format::Csv {
        return run;
    }
    let ran = match &run {
        Ok(()) => true,
        Err(e) => matches!(
            e.downcast_ref::<substep::Error>(),
            Some(substep::Error::Diverged { .. } | substep::Error::Stopped { .. })
        ),
    };
    if !ran {
        return run;
    }
    let written = write(dir, format, config_text(args)).map_err(|e| anyhow!("{e:#}"));
    match (run, written) {
        (Err(e), _) => Err(e),
        (Ok(()), Err(e)) => Err(e),
        (Ok(()), Ok(path)) => {
            if !args.quiet {
                println!("  {} written (CSV tables and summary)", path.display());
            }
            Ok(())
        }
    }
}

/// The container of `format` from the CSV tables and `summary.json` in `dir`.
fn write(dir: &Path, format: Format, config: String) -> Result<PathBuf> {
    let summary_path = dir.join("summary.json");
    let summary_json = substep::io::limits::read_text(&summary_path, SUMMARY_MAX_BYTES)?;
    let meta = Metadata { summary_json, config };
    let path = write_container(dir, format, &meta)?;
    path.ok_or_else(|| anyhow!("no container for format csv"))
}

/// `summary.json` is small (peaks and errors per DOF); more than this is not ours.
const SUMMARY_MAX_BYTES: f64 = 256.0 * 1024.0 * 1024.0;

/// The test definition's text as the run read it.
fn config_text(args: &RunArgs) -> String {
    match &args.config {
        None => DEFAULT_CONFIG.to_string(),
        Some(p) => substep::io::limits::read_text(p, substep::io::limits::CONFIG_MAX_BYTES).unwrap_or_default(),
    }
}
