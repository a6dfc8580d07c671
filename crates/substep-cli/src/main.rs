//! `substep`: run and benchmark real-time substructure tests with sub-step control.
//!
//! Exit codes (offline and `--realtime` alike): 0 success, 1 a run that diverged or stopped
//! (safety limit, failing remote site; also outputs that could not be written while running),
//! 2 bad input (config, files, parameters, an output directory that cannot be created or
//! cleared). Errors are printed as one line `error: ...`.

mod analyze;
mod bench;
mod bench_compare;
mod bench_models;
mod benchmark;
mod benchmark_marths;
mod lab;
mod model_export;
mod plots;
mod realtime;
mod run;
mod site;
mod study;
mod vst;

use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

/// The embedded default example (`examples/default.toml`).
pub const DEFAULT_CONFIG: &str = include_str!("../../../examples/default.toml");
/// How the embedded example is named in outputs and messages.
pub const DEFAULT_CONFIG_NAME: &str = "embedded default";

#[derive(Debug, Parser)]
#[command(
    name = "substep",
    version,
    about = "Real-time substructure testing (hybrid simulation) with Dorka's sub-step control",
    long_about = "Real-time substructure testing (hybrid simulation) with Dorka's sub-step control.\n\n\
                  Without a subcommand, runs the embedded default example (`substep run`)."
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run a test definition (TOML, see docs/config.md); without CONFIG, the embedded default example
    Run(RunArgs),
    /// Accuracy and stability analysis of the sub-step algorithm: stability, accuracy, verify, plan
    Analyze(analyze::AnalyzeArgs),
    /// Measure µs per step of the integrator and the sub-step controller
    Bench(bench::BenchArgs),
    /// Host an experimental substructure for remote clients (`site serve SITE.toml`)
    Site(site::SiteArgs),
    /// The virtual substructure test study (3-storey frame, TMD specimen, delayed actuator,
    /// 1 % force noise): every compensation method against the exact reference
    Vst(vst::VstArgs),
    /// Parameter study: every variant of a base test on all cores, `study.csv` and plots (`study STUDY.toml`)
    Study(study::StudyArgs),
    /// Community benchmarks reproduced: `benchmark rths` (the virtual RTHS benchmark, docs/benchmark.md)
    Benchmark(benchmark::BenchmarkArgs),
    /// The numerical model of a test definition: `model export CONFIG --mtx DIR` (MatrixMarket)
    Model(model_export::ModelArgs),
    /// Lab targets: `lab emulate TARGET.toml` serves a test's [substructure.lab] protocol with its virtual lab behind it (docs/lab.md)
    Lab(lab::LabArgs),
}

#[derive(Debug, Clone, Default, clap::Args)]
pub struct RunArgs {
    /// Test definition (TOML); default: the embedded example `examples/default.toml`
    pub config: Option<PathBuf>,
    /// Output directory (default: `[output] dir` of the config, else `results`)
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// No progress bar and no summary on stdout (errors are still printed)
    #[arg(long, short)]
    pub quiet: bool,
    /// Do not draw figures (overrides `[output] plots`)
    #[arg(long)]
    pub no_plots: bool,
    /// Figure format: png, svg or pdf (overrides `[output.plots] format`; default png)
    #[arg(long, value_enum, value_name = "FORMAT")]
    pub plot_format: Option<plots::PlotFormat>,
    /// Result container besides the CSV files: csv (none), hdf5 (results.h5), mat (MATLAB
    /// results.mat, level 5) or mat73 (MATLAB v7.3, for runs over 2 GB); overrides
    /// `[output] format`
    #[arg(long, value_name = "FORMAT")]
    pub format: Option<String>,
    /// Run against the wall clock (sub-steps paced at Δt/k_sub, see docs/realtime.md)
    #[arg(long)]
    pub realtime: bool,
    /// With --realtime: lock memory (mlockall); reported when not permitted
    #[arg(long, requires = "realtime")]
    pub lock_memory: bool,
    /// With --realtime: SCHED_FIFO priority of the sub-step thread; reported when not permitted
    #[arg(long, requires = "realtime", value_name = "PRIO")]
    pub fifo_priority: Option<i32>,
    /// With --realtime: the share of sub-step deadlines (0–1) that may be missed before the run
    /// counts as failed (exit 1); overrides `[realtime] max_missed` (default 0.01 = 1 %)
    #[arg(long, requires = "realtime", value_name = "SHARE")]
    pub max_missed: Option<f64>,
    /// With --realtime: when the next step's predictor is late, `hold` the actuator (keep the
    /// wall clock) or `wait` for it (the run equals the offline run); overrides
    /// `[realtime] late_policy` (default hold)
    #[arg(long, requires = "realtime", value_name = "POLICY")]
    pub late_policy: Option<String>,
    /// Serve a live monitor page during the run at ADDR (default: `[monitor] address`, else
    /// 127.0.0.1:8080; see docs/monitor.md)
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "")]
    pub monitor: Option<String>,
    /// With --monitor: allow an address that is not loopback (controls still need the token)
    #[arg(long, requires = "monitor")]
    pub monitor_public: bool,
    /// With --monitor: the token the controls need, at least 16 printable ASCII characters
    /// (default: `[monitor] token`, else a random one, printed at start)
    #[arg(long, requires = "monitor", value_name = "TOKEN")]
    pub monitor_token: Option<String>,
    /// With --monitor: seconds the page keeps showing the final state after the run
    #[arg(long, requires = "monitor", value_name = "SECONDS", default_value_t = 30.0)]
    pub monitor_linger: f64,
    /// On-line stability indicator: warn, stop with the controlled ramp-down, or off (overrides
    /// `[substructure.limits] stability`; offline it runs by default)
    #[arg(long, value_enum, value_name = "ACTION")]
    pub stability: Option<StabilityArg>,
    /// Pace an offline run at FACTOR × real time (1 = wall clock)
    #[arg(long, value_name = "FACTOR", conflicts_with = "realtime")]
    pub pace: Option<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum StabilityArg {
    Warn,
    Stop,
    /// No indicator (it runs by default offline).
    Off,
}

/// Exit code of a failed command: 1 for a diverged or stopped run and for runtime failures
/// (e.g. outputs that cannot be written), 2 for bad input (any other library error: config,
/// files, parameters, the output directory). Every driver reports an experimental side that
/// fails mid-run as `Error::Stopped`, so a killed site is 1 offline and in real time.
fn exit_code(e: &anyhow::Error) -> u8 {
    match e.downcast_ref::<substep::Error>() {
        // A run that diverged or stopped, and outputs that could not be written: runtime failures.
        Some(substep::Error::Diverged { .. } | substep::Error::Stopped { .. } | substep::Error::Output { .. }) => 1,
        Some(_) => 2,
        None => 1,
    }
}

/// Clap's message for a bad command line in one line: the error, its details and tip joined,
/// without the usage block (`--help` has it).
fn one_line_usage_error(rendered: &str) -> String {
    let mut parts: Vec<String> = Vec::new();
    for line in rendered.lines() {
        let l = line.trim();
        if l.starts_with("Usage:") || l.starts_with("For more information") {
            break;
        }
        if !l.is_empty() {
            parts.push(l.trim_start_matches("error: ").to_string());
        }
    }
    let message = match parts.split_first() {
        Some((head, [])) => head.clone(),
        Some((head, rest)) if head.ends_with(':') => format!("{head} {}", rest.join(", ")),
        Some((head, rest)) => format!("{head} ({})", rest.join("; ")),
        None => "invalid command line".to_string(),
    };
    format!("error: {message} (see --help)")
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            use clap::error::ErrorKind;
            if matches!(
                e.kind(),
                ErrorKind::DisplayHelp
                    | ErrorKind::DisplayVersion
                    | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
            ) {
                e.exit();
            }
            eprintln!("{}", one_line_usage_error(&e.render().to_string()));
            return ExitCode::from(2);
        }
    };
    let result = match cli.command {
        None => run::run(&RunArgs::default()),
        Some(Command::Run(args)) => run::run(&args),
        Some(Command::Analyze(args)) => analyze::analyze(&args),
        Some(Command::Bench(args)) => bench::bench(&args),
        Some(Command::Site(args)) => site::site(&args),
        Some(Command::Vst(args)) => vst::vst(&args),
        Some(Command::Benchmark(args)) => benchmark::benchmark(&args),
        Some(Command::Study(args)) => study::study(&args),
        Some(Command::Model(args)) => model_export::model(&args),
        Some(Command::Lab(args)) => lab::lab(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // `{:#}` joins the context chain with ": "; the line breaks of any part are folded.
            let message = format!("{e:#}");
            eprintln!("error: {}", message.split_whitespace().collect::<Vec<_>>().join(" "));
            ExitCode::from(exit_code(&e))
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn usage_errors_are_one_line() {
        let clap = "error: unexpected argument '--fomat' found\n\n  tip: a similar argument exists: '--format'\n\nUsage: substep run --format <FORMAT> [CONFIG]\n\nFor more information, try '--help'.\n";
        assert_eq!(
            super::one_line_usage_error(clap),
            "error: unexpected argument '--fomat' found (tip: a similar argument exists: '--format') (see --help)"
        );
        let clap = "error: the following required arguments were not provided:\n  --realtime\n\nUsage: substep run --realtime --max-missed <SHARE> [CONFIG]\n\nFor more information, try '--help'.\n";
        assert_eq!(
            super::one_line_usage_error(clap),
            "error: the following required arguments were not provided: --realtime (see --help)"
        );
    }
}
