//! `substep analyze`: stability maps, accuracy (peak errors), verification runs and a test
//! planner (docs/theory.md §9). See docs/analysis.md for the contract and a reading of the results.
//! The drivers are in `substep::analysis`; this module holds the shared flags and parsers, one
//! file per subcommand prints and writes the results.

use crate::plots::{Curve, line_chart, rho_heatmap};
use anyhow::{Context, Result, bail};

/// A bad command-line value: a `substep::Error` so that the exit code is 2 (bad input).
macro_rules! bad {
    ($flag:expr, $($arg:tt)*) => {
        return Err(substep::Error::invalid($flag, format!($($arg)*)).into())
    };
}
use clap::{Args, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use substep::analysis::accuracy::{AccuracyGrid, AccuracyRow, accuracy_rows, transfer_functions};
use substep::analysis::stability::{linear_grid, stability_study};
use substep::analysis::verification::{VerifySettings, verify_analysis};
use substep::analysis::{AnalysisCase, AnalysisScheme, FrozenPhaseLag, Parameter, Stability};
use substep::io::config::TestDefinition;
use substep::substructure::ErrorForceSpec;

mod accuracy;
mod plan;
mod stability;
mod verify;

pub use accuracy::AccuracyArgs;
pub use plan::PlanArgs;
pub use stability::StabilityArgs;
pub use verify::VerifyArgs;

#[derive(Debug, Args)]
pub struct AnalyzeArgs {
    #[command(subcommand)]
    pub command: AnalyzeCommand,
    /// Figure format: png, svg or pdf
    #[arg(long, global = true, value_enum, value_name = "FORMAT", default_value = "png")]
    pub plot_format: crate::plots::PlotFormat,
}

#[derive(Debug, Subcommand)]
pub enum AnalyzeCommand {
    /// Spectral radius over a grid of Ω and one other parameter, per k_sub (CSV + heat maps)
    Stability(StabilityArgs),
    /// Peaks of the transfer function: amplitude and period errors against the exact system
    Accuracy(AccuracyArgs),
    /// Time-domain runs that check the frequency-domain peaks and the stability predictions
    Verify(VerifyArgs),
    /// For your own test definition: scan Δt, k_sub and actuator delay, recommend settings
    Plan(PlanArgs),
}

/// The analysis model of docs/theory.md §9.3 (dimensionless: m = 1, ω = 1).
#[derive(Debug, Clone, Args)]
pub struct CaseArgs {
    /// Base case: `typical` (η_m 5 %, ζ 5 %, ζ_s 10 %, η_f 1) or `large_mass_ratio` (η_m 50 %, ζ = ζ_s = 5 %)
    #[arg(long, default_value = "typical")]
    pub case: String,
    /// Mass ratio η_m = m_s/m
    #[arg(long)]
    pub eta_m: Option<f64>,
    /// Frequency ratio η_f = ω_s/ω
    #[arg(long)]
    pub eta_f: Option<f64>,
    /// Damping ratio ζ of the numerical substructure
    #[arg(long)]
    pub zeta: Option<f64>,
    /// Damping ratio ζ_s of the specimen
    #[arg(long)]
    pub zeta_s: Option<f64>,
    /// Error-force compensation: `none`, `pid:P`, `pid:P:I:D`
    #[arg(long, default_value = "none")]
    pub error_force: String,
}

impl CaseArgs {
    fn case(&self) -> Result<AnalysisCase> {
        let mut c = match self.case.as_str() {
            "typical" => AnalysisCase::typical_tmd(),
            "large_mass_ratio" => AnalysisCase::large_mass_ratio(),
            other => bad!(
                "--case",
                "unknown case '{other}' (expected typical or large_mass_ratio)"
            ),
        };
        if let Some(v) = self.eta_m {
            c.eta_m = v;
        }
        if let Some(v) = self.eta_f {
            c.eta_f = v;
        }
        if let Some(v) = self.zeta {
            c.zeta = v;
        }
        if let Some(v) = self.zeta_s {
            c.zeta_s = v;
        }
        c.error_force = parse_error_force(&self.error_force)?;
        c.validate()?;
        Ok(c)
    }
}

fn parse_error_force(s: &str) -> Result<ErrorForceSpec> {
    if s == "none" {
        return Ok(ErrorForceSpec::None);
    }
    let parts: Vec<&str> = s.split(':').collect();
    if parts[0] != "pid" || !(parts.len() == 2 || parts.len() == 4) {
        bad!("--error-force", "expected none, pid:P or pid:P:I:D, got '{s}'");
    }
    let num = |t: &str| -> Result<f64> {
        match t.parse::<f64>().ok().filter(|v| v.is_finite()) {
            Some(v) => Ok(v),
            None => bad!("--error-force", "'{t}' is not a number"),
        }
    };
    let p = num(parts[1])?;
    let (i, d) = if parts.len() == 4 {
        (num(parts[2])?, num(parts[3])?)
    } else {
        (0.0, 0.0)
    };
    Ok(ErrorForceSpec::Pid { p, i, d })
}

fn parse_f64_list(flag: &str, s: &str) -> Result<Vec<f64>> {
    let Some(v) = s
        .split(',')
        .map(|t| t.trim().parse::<f64>().ok().filter(|x| x.is_finite()))
        .collect::<Option<Vec<f64>>>()
    else {
        bad!(flag, "expected a comma-separated list of numbers, got '{s}'");
    };
    if v.is_empty() {
        bad!(flag, "the list is empty");
    }
    Ok(v)
}

fn parse_usize_list(flag: &str, s: &str) -> Result<Vec<usize>> {
    match s
        .split(',')
        .map(|t| t.trim().parse::<usize>().ok().filter(|&k| k >= 1))
        .collect::<Option<Vec<usize>>>()
    {
        Some(v) => Ok(v),
        None => bad!(flag, "expected a comma-separated list of integers >= 1, got '{s}'"),
    }
}

/// `a:b:n`, an inclusive linear grid.
fn parse_grid(flag: &str, s: &str) -> Result<Vec<f64>> {
    let parts: Vec<&str> = s.split(':').collect();
    if parts.len() != 3 {
        bad!(flag, "expected a grid a:b:n, got '{s}'");
    }
    let (Ok(a), Ok(b), Ok(n)) = (
        parts[0].trim().parse::<f64>(),
        parts[1].trim().parse::<f64>(),
        parts[2].trim().parse::<usize>(),
    ) else {
        bad!(flag, "expected numbers a:b and a count n in '{s}'");
    };
    Ok(linear_grid(flag, a, b, n)?)
}

/// `name=a:b:n`.
fn parse_vary(s: &str) -> Result<(Parameter, Vec<f64>)> {
    let Some((name, grid)) = s.split_once('=') else {
        bad!("--vary", "expected name=a:b:n, got '{s}'");
    };
    let p = match Parameter::from_name(name.trim()) {
        Ok(p) => p,
        Err(e) => bad!("--vary", "{e}"),
    };
    if matches!(p, Parameter::Omega | Parameter::EtaT) {
        bad!(
            "--vary",
            "'{name}' is the x axis already; vary zeta_s, zeta, eta_f, eta_m or eta_p"
        );
    }
    Ok((p, parse_grid("--vary", grid)?))
}

fn progress(total: usize, quiet: bool, what: &str) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new(total as u64);
    if let Ok(style) = ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} ({eta})") {
        pb.set_style(style.progress_chars("=> "));
    }
    pb.set_message(what.to_string());
    pb
}

fn create_out(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create output directory {}", dir.display()))
}

fn write_file(path: &Path, text: &str) -> Result<()> {
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

pub fn analyze(args: &AnalyzeArgs) -> Result<()> {
    crate::plots::check_format(args.plot_format, "--plot-format")?;
    crate::plots::set_format(args.plot_format);
    match &args.command {
        AnalyzeCommand::Stability(a) => stability::stability(a),
        AnalyzeCommand::Accuracy(a) => accuracy::accuracy(a),
        AnalyzeCommand::Verify(a) => verify::verify(a),
        AnalyzeCommand::Plan(a) => plan::plan(a),
    }
}
