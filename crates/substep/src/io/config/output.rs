//! `[output]` and `[output.plots]` (docs/config.md, section `[output]`): output directory and
//! figures.

use crate::error::{Error, Result};
use serde::Deserialize;
use std::fmt;
use std::path::PathBuf;

#[derive(Debug, Clone, PartialEq)]
pub struct OutputSettings {
    /// Output directory from `[output] dir`, if given.
    pub dir: Option<PathBuf>,
    /// Whether to draw figures.
    pub plots: bool,
    /// `[output.plots]`: format, time window and which figures.
    pub plot_options: PlotOptions,
}

/// Figure names accepted by `[output.plots] figures` (the file names without extension).
pub const PLOT_FIGURES: &[&str] = &[
    "displacement",
    "acceleration",
    "coupling_force",
    "error_force",
    "hysteresis",
    "reference",
    "compensation_force",
    "tracking_error",
    "energy",
    "base_shear",
    "storeys",
    "ground_motion",
    "response_spectrum",
];

/// The `[output.plots]` table (all optional).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PlotOptions {
    /// `png`, `svg` or `pdf`.
    pub format: Option<String>,
    /// Time window `[t0, t1]` \[s\] of the hysteresis plot and the zoom panel.
    pub window: Option<(f64, f64)>,
    /// Only these figures (names from [`PLOT_FIGURES`]); all when `None`.
    pub figures: Option<Vec<String>>,
}

impl PlotOptions {
    /// Whether figure `name` is to be drawn.
    pub fn wants(&self, name: &str) -> bool {
        self.figures.as_ref().is_none_or(|f| f.iter().any(|n| n == name))
    }
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawOutput {
    pub(crate) dir: Option<String>,
    #[serde(default)]
    pub(crate) plots: RawPlots,
}

/// `[output] plots = true | false`, or the table `[output.plots]`.
#[derive(Debug)]
pub(crate) enum RawPlots {
    Enabled(bool),
    Table(RawPlotTable),
}

impl Default for RawPlots {
    fn default() -> Self {
        RawPlots::Enabled(true)
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawPlotTable {
    pub(crate) enabled: Option<bool>,
    pub(crate) format: Option<String>,
    pub(crate) window: Option<[f64; 2]>,
    pub(crate) figures: Option<Vec<String>>,
}

impl<'de> Deserialize<'de> for RawPlots {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = RawPlots;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("true, false or a table [output.plots] with enabled, format, window, figures")
            }
            fn visit_bool<E: serde::de::Error>(self, v: bool) -> std::result::Result<RawPlots, E> {
                Ok(RawPlots::Enabled(v))
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(self, map: A) -> std::result::Result<RawPlots, A::Error> {
                RawPlotTable::deserialize(serde::de::value::MapAccessDeserializer::new(map)).map(RawPlots::Table)
            }
        }
        d.deserialize_any(V)
    }
}

impl RawPlots {
    pub(crate) fn build(&self) -> Result<(bool, PlotOptions)> {
        let t = match self {
            RawPlots::Enabled(b) => return Ok((*b, PlotOptions::default())),
            RawPlots::Table(t) => t,
        };
        if let Some(f) = &t.format
            && !["png", "svg", "pdf"].contains(&f.as_str())
        {
            return Err(Error::invalid(
                "output.plots.format",
                format!("unknown format '{f}' (expected \"png\", \"svg\" or \"pdf\")"),
            ));
        }
        if let Some([a, b]) = t.window
            && !(a.is_finite() && b.is_finite() && a >= 0.0 && b > a)
        {
            return Err(Error::invalid(
                "output.plots.window",
                format!("must be [t0, t1] with 0 ≤ t0 < t1 [s], got [{a}, {b}]"),
            ));
        }
        if let Some(figs) = &t.figures
            && let Some(bad) = figs.iter().find(|f| !PLOT_FIGURES.contains(&f.as_str()))
        {
            return Err(Error::invalid(
                "output.plots.figures",
                format!("unknown figure '{bad}' (expected some of {})", PLOT_FIGURES.join(", ")),
            ));
        }
        Ok((
            t.enabled.unwrap_or(true),
            PlotOptions {
                format: t.format.clone(),
                window: t.window.map(|[a, b]| (a, b)),
                figures: t.figures.clone(),
            },
        ))
    }
}
