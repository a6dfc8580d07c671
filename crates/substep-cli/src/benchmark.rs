//! `substep benchmark rths`: the RTHS benchmark control problem (Silva et al. 2020) as a
//! built-in. Thin: parse the flags, call `substep::benchmark::rths` (its `report` writes
//! `benchmark.md`, the traces and the plots), print.

use anyhow::Result;
use std::path::PathBuf;
use substep::benchmark::rths::report::{self, RunOptions};
use substep::benchmark::rths::{StudyOptions, StudySetup};
use substep::io::results::Format;

#[derive(Debug, clap::Args)]
pub struct BenchmarkArgs {
    #[command(subcommand)]
    pub which: Which,
}

#[derive(Debug, clap::Subcommand)]
pub enum Which {
    /// The virtual RTHS benchmark (Silva et al. 2020): 3-storey frame, servo-hydraulic actuator
    /// with CSI, J1–J9 against the exact reference (docs/benchmark.md)
    Rths(RthsArgs),
    /// The multi-axial RTHS benchmark (maRTHS, Condori Uribe et al. 2023): two actuators on a
    /// coupler drive x and θ of a frame node; J1–J10 as the public toolset codes them
    /// (docs/benchmark.md)
    Marths(crate::benchmark_marths::MarthsArgs),
}

#[derive(Debug, Clone, clap::Args)]
pub struct RthsArgs {
    /// Reference structure 1..4 (default: all four)
    #[arg(long)]
    pub case: Option<u8>,
    /// Ground motion: `elcentro` (shipped) or a two-column `t,a_g` CSV in m/s²
    #[arg(long, default_value = "elcentro")]
    pub record: String,
    /// Scale of the record (eq_intensity)
    #[arg(long, default_value_t = 0.4)]
    pub intensity: f64,
    /// Tracking controller: none, sample, arx, polynomial, ats, amb (default: the config's, else sample;
    /// inverse_fir is refused on this benchmark, with the reason)
    #[arg(long)]
    pub controller: Option<String>,
    /// Settings of the controller and the sub-step algorithm (TOML, docs/benchmark.md)
    #[arg(long, value_name = "FILE.toml")]
    pub config: Option<PathBuf>,
    /// Also run N perturbed plants per case (in parallel)
    #[arg(long, value_name = "N")]
    pub perturbed: Option<usize>,
    /// Seed of the plant perturbations
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// benchmark (the original loop) or substep (the numerical substructure by the sub-step algorithm)
    #[arg(long, default_value = "benchmark")]
    pub algorithm: String,
    /// With --algorithm substep: run these k_sub values (comma-separated) and print J4–J9 per k_sub
    #[arg(long, value_name = "LIST", value_delimiter = ',')]
    pub k_sub: Vec<usize>,
    /// Every controller side by side (none, sample, polynomial, ats, amb, arx; each with its one
    /// preset setting), with and without sensor noise, nominal and on --perturbed N plants
    /// (default 20): J2, J4, peak force, stable and under-capacity counts, CPU time per sample;
    /// prints the table and writes comparison.md to --out (with --json: one JSON object, no file)
    #[arg(long)]
    pub compare: bool,
    /// Print one JSON object instead of the table (no files written)
    #[arg(long)]
    pub json: bool,
    /// Output directory for benchmark.md and the plots
    #[arg(long, value_name = "DIR", default_value = "results")]
    pub out: PathBuf,
    /// No plots
    #[arg(long)]
    pub no_plots: bool,
    /// Figure format: png, svg or pdf (vector, for papers)
    #[arg(long, value_enum, value_name = "FORMAT", default_value = "png")]
    pub plot_format: crate::plots::PlotFormat,
    /// The traces also in one file: hdf5 (traces.h5), mat or mat73 (traces.mat; MATLAB); the CSV
    /// files are always written
    #[arg(long, value_name = "FORMAT", default_value = "csv")]
    pub format: String,
}

pub fn benchmark(args: &BenchmarkArgs) -> Result<()> {
    match &args.which {
        Which::Rths(a) => rths(a),
        Which::Marths(a) => crate::benchmark_marths::marths(a),
    }
}

/// The CLI's flags as the library's study options, and the `--config` text; files read here.
fn setup(args: &RthsArgs) -> Result<(StudySetup, Option<String>)> {
    let record = match args.record.as_str() {
        "elcentro" => None,
        // Through the same bounded reader as every record: a regular file within the default
        // [limits] max_file_bytes and max_record_values (counted before it is kept), never a
        // device or FIFO.
        path => Some((
            path,
            substep::io::limits::read_record_text(std::path::Path::new(path), &substep::io::limits::Limits::default())?,
        )),
    };
    let config = match &args.config {
        Some(path) => {
            let name = path.display().to_string();
            let text = substep::io::limits::read_text(path, substep::io::limits::CONFIG_MAX_BYTES)?;
            Some((name, text))
        }
        None => None,
    };
    let options = StudyOptions {
        case: args.case,
        record: record.as_ref().map(|(n, t)| (*n, t.as_str())),
        intensity: args.intensity,
        controller: args.controller.as_deref(),
        config: config.as_ref().map(|(n, t)| (n.as_str(), t.as_str())),
        algorithm: &args.algorithm,
        perturbed: args.perturbed,
        seed: args.seed,
        k_sub: &args.k_sub,
    };
    let setup = options.setup(|name| format!("--{}", name.replace('_', "-")))?;
    Ok((setup, config.map(|(_, text)| text)))
}

/// The command line as typed, quoted in the written Markdown.
pub(crate) fn command() -> String {
    std::iter::once("substep".to_string())
        .chain(std::env::args().skip(1))
        .collect::<Vec<_>>()
        .join(" ")
}

/// `--compare`: the controllers side by side (substep::benchmark::rths::compare).
fn comparison(args: &RthsArgs) -> Result<()> {
    let conflicting = [
        ("--controller", args.controller.is_some()),
        ("--config", args.config.is_some()),
        ("--k-sub", !args.k_sub.is_empty()),
        ("--algorithm", args.algorithm != "benchmark"),
    ];
    if let Some((flag, _)) = conflicting.iter().find(|(_, set)| *set) {
        anyhow::bail!(substep::Error::invalid(
            "--compare",
            format!(
                "compares every controller with its preset setting on the benchmark loop; {flag} is not used with it"
            )
        ));
    }
    let args = RthsArgs {
        perturbed: Some(args.perturbed.unwrap_or(20)),
        ..args.clone()
    };
    let (setup, _) = setup(&args)?;
    let t0 = std::time::Instant::now();
    let rows = setup.compare()?;
    let elapsed = t0.elapsed().as_secs_f64();
    if args.json {
        out(&format!(
            "{}\n",
            serde_json::to_string_pretty(&setup.comparison_json(&rows))?
        ));
        return Ok(());
    }
    let written = report::write_comparison(&setup, &rows, &args.out, &command(), &mut |t| out(t))?;
    out(&written.summary(&setup, &rows, elapsed));
    Ok(())
}

/// Write to stdout; a closed pipe (`| head`) is not an error worth a panic.
pub(crate) fn out(text: &str) {
    use std::io::Write;
    let _ = std::io::stdout().lock().write_all(text.as_bytes());
}

pub fn rths(args: &RthsArgs) -> Result<()> {
    let format = Format::parse("--format", &args.format)?;
    if format != Format::Csv && (args.compare || args.json) {
        return Err(substep::Error::invalid(
            "--format",
            "writes the traces of a run to --out: not with --compare or --json",
        )
        .into());
    }
    if args.compare {
        return comparison(args);
    }
    // A figure format this build cannot draw is refused before the benchmark runs.
    if !args.no_plots && !args.json {
        crate::plots::check_format(args.plot_format, "--plot-format")?;
    }
    let (setup, config) = setup(args)?;
    let t0 = std::time::Instant::now();
    let rows = setup.run()?;
    let elapsed = t0.elapsed().as_secs_f64();
    // Warnings on stderr (the JSON and benchmark.md carry them too); a nominal run without a
    // score is a failure (exit 1), said after the outputs are written.
    for row in &rows {
        for w in row.nominal.warnings() {
            eprintln!("warning: {w}");
        }
    }
    let verdict = || match report::no_score(&rows) {
        Some(message) => Err(anyhow::anyhow!(message)),
        None => Ok(()),
    };
    if args.json {
        out(&format!("{}\n", serde_json::to_string_pretty(&setup.json(&rows))?));
        return verdict();
    }
    let options = RunOptions {
        out: &args.out,
        plots: (!args.no_plots).then(|| args.plot_format.library()),
        plot_option: "--plot-format",
        format,
        command: &command(),
        config: config.as_deref(),
    };
    let written = report::write_run(&setup, &rows, &options, &mut |t| out(t))?;
    out(&written.summary(rows.len() * (1 + setup.perturbed.unwrap_or(0)), elapsed));
    verdict()
}
