//! The figures of the CLI's commands, drawn by [`substep::figure`]: `--plot-format` as a clap
//! value, chosen once per process ([`set_format`]) for the commands' many chart calls.

use anyhow::Result;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU8, Ordering};
pub use substep::figure::{Curve, Figure, Panel};

/// `--plot-format`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PlotFormat {
    Png,
    Svg,
    Pdf,
}

impl PlotFormat {
    pub fn library(self) -> substep::figure::PlotFormat {
        match self {
            PlotFormat::Png => substep::figure::PlotFormat::Png,
            PlotFormat::Svg => substep::figure::PlotFormat::Svg,
            PlotFormat::Pdf => substep::figure::PlotFormat::Pdf,
        }
    }
}

static FORMAT: AtomicU8 = AtomicU8::new(0);

/// Refuse a format this build cannot draw, before any work: `what` names the option.
pub fn check_format(f: PlotFormat, what: &str) -> Result<()> {
    Ok(substep::figure::check_format(f.library(), what)?)
}

/// Choose the format of all figures drawn from now on (default PNG).
pub fn set_format(f: PlotFormat) {
    FORMAT.store(f as u8, Ordering::Relaxed);
}

/// [`set_format`] from the library's format (a run's `[output.plots] format`).
pub fn set_library_format(f: substep::figure::PlotFormat) {
    set_format(match f {
        substep::figure::PlotFormat::Png => PlotFormat::Png,
        substep::figure::PlotFormat::Svg => PlotFormat::Svg,
        substep::figure::PlotFormat::Pdf => PlotFormat::Pdf,
    });
}

/// The format chosen last.
pub fn format() -> substep::figure::PlotFormat {
    match FORMAT.load(Ordering::Relaxed) {
        1 => PlotFormat::Svg,
        2 => PlotFormat::Pdf,
        _ => PlotFormat::Png,
    }
    .library()
}

/// Draw `fig` to `path` in the current format; returns the written path.
pub fn figure(path: &Path, fig: &Figure) -> Result<PathBuf> {
    Ok(substep::figure::figure(path, fig, format())?)
}

/// One panel of `curves` at `path` in the current format; returns the written path.
pub fn line_chart(path: &Path, title: &str, x_label: &str, y_label: &str, curves: &[Curve]) -> Result<PathBuf> {
    Ok(substep::figure::line_chart(
        path,
        format(),
        title,
        x_label,
        y_label,
        curves,
    )?)
}

/// The spectral-radius heat map ([`substep::figure::rho_heatmap`]) in the current format.
pub fn rho_heatmap(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    xs: &[f64],
    ys: &[f64],
    rho: &[Vec<f64>],
) -> Result<()> {
    Ok(substep::figure::rho_heatmap(
        path,
        format(),
        title,
        x_label,
        y_label,
        xs,
        ys,
        rho,
    )?)
}
