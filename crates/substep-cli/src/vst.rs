//! `substep vst`: the virtual substructure test (VST) study of the dissertation's chapter 9.
//!
//! The study itself (set-up, methods, runs, error statistics, acceptance checks) is
//! [`substep::study::vst`], the files it writes (`vst.md`, `vst.csv`, the figures; with
//! `--damper-grid` `damper_grid.md`, `.csv`) are [`substep::study::vst::report`]; this file
//! parses the flags and prints.

use anyhow::Result;
use std::path::PathBuf;
use std::time::Instant;
use substep::study::vst::VstSettings;
use substep::study::vst::report::{self, Plots};

#[derive(Debug, Clone, clap::Args)]
pub struct VstArgs {
    /// Output directory
    #[arg(long, value_name = "DIR", default_value = "vst")]
    pub out: PathBuf,
    /// A shortened study (12 s instead of 60 s of ground motion)
    #[arg(long)]
    pub quick: bool,
    /// Pure delay of the actuator [s]
    #[arg(long, default_value_t = 0.010)]
    pub delay: f64,
    /// No plots
    #[arg(long)]
    pub no_plots: bool,
    /// Figure format: png, svg or pdf (vector, for papers)
    #[arg(long, value_enum, value_name = "FORMAT", default_value = "png")]
    pub plot_format: crate::plots::PlotFormat,
    /// No progress output
    #[arg(long, short)]
    pub quiet: bool,
    /// Instead of the study: the damper grid (phase-lag compensation by identification on 60
    /// damper tests behind a pure delay and behind a second-order actuator; damper_grid.md, .csv)
    #[arg(long, conflicts_with_all = ["quick", "delay"])]
    pub damper_grid: bool,
}

pub fn vst(args: &VstArgs) -> Result<()> {
    let quiet = args.quiet;
    let mut progress = |line: &str| {
        if !quiet {
            println!("{line}");
        }
    };
    // A figure format this build cannot draw is refused before the study runs.
    if !args.no_plots && !args.damper_grid {
        crate::plots::check_format(args.plot_format, "--plot-format")?;
    }
    let t0 = Instant::now();
    if args.damper_grid {
        let done = report::damper_grid_in_folder(&args.out, &mut progress)?;
        finish(quiet, &done.markdown, &done.files, t0);
        return Ok(());
    }
    if !(args.delay.is_finite() && args.delay >= 0.0 && args.delay <= 0.1) {
        return Err(substep::Error::invalid("--delay", format!("must be in [0, 0.1] s, got {}", args.delay)).into());
    }
    let settings = if args.quick {
        VstSettings::quick(args.delay)
    } else {
        VstSettings::full(args.delay)
    };
    let plots = (!args.no_plots).then(|| Plots {
        format: args.plot_format.library(),
        option: "--plot-format",
    });
    let done = report::study_in_folder(&settings, &args.out, plots, &mut progress)?;
    finish(quiet, &done.markdown, &done.files, t0);
    Ok(())
}

/// The table, the time taken and the files written (unless `--quiet`).
fn finish(quiet: bool, markdown: &str, files: &[PathBuf], t0: Instant) {
    if !quiet {
        println!("{markdown}");
        println!(
            "done in {:.1} s; wrote {}",
            t0.elapsed().as_secs_f64(),
            files
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
}
