//! `substep benchmark marths`: the multi-axial RTHS benchmark (maRTHS) as a built-in. Thin: parse
//! the flags, call `substep::benchmark::marths` (its `report` writes the traces and
//! `marths.md`), print the table or one JSON object.

use crate::benchmark::{command, out};
use anyhow::Result;
use std::path::{Path, PathBuf};
use substep::benchmark::marths::{MarthsOptions, RecordChoice, names_a_record_file, reference, report, run_with};

#[derive(Debug, Clone, clap::Args)]
pub struct MarthsArgs {
    /// Ground motion: elcentro, kobe, morgan (shipped, unscaled) or a two-column `t,a_g` CSV in m/s²
    #[arg(long, default_value = "elcentro")]
    pub record: String,
    /// Scale of the record (the toolset's EQ_intensity)
    #[arg(long, default_value_t = 0.4)]
    pub intensity: f64,
    /// Tracking controller: none, rodeac (the toolset's), arx (substep's phase-lag compensation
    /// per actuator after the kinematics) or arx_mimo (the ARX identification over both actuators)
    #[arg(long, default_value = "rodeac")]
    pub controller: String,
    /// Uncertain plants: with 0 the J are the nominal plant's, otherwise the mean over the N
    /// trials (nominal excluded), as the toolset reports
    #[arg(long, default_value_t = 0)]
    pub trials: usize,
    /// Seed of the uncertain plants and of the sensor noise
    #[arg(long, default_value_t = 123)]
    pub seed: u64,
    /// No sensor noise (for sample-by-sample comparisons with other implementations)
    #[arg(long)]
    pub no_noise: bool,
    /// An ideal transfer system instead of the plant: measured = target in the same sample, no
    /// noise (J1–J6 vanish; J7–J10 show the benchmark's floor)
    #[arg(long)]
    pub ideal: bool,
    /// benchmark (the toolset's loop) or substep (the numerical substructure by the sub-step
    /// algorithm)
    #[arg(long, default_value = "benchmark")]
    pub algorithm: String,
    /// Density of the partition taken out of the frame [kg/m³]: the toolset codes 785e3 (100 ×
    /// steel, 902.5 kg off floor 1); 7850 is steel
    #[arg(long, value_name = "KG_PER_M3")]
    pub partition_density: Option<f64>,
    /// Plant, coupler, ARX and sub-step settings (TOML, docs/benchmark.md)
    #[arg(long, value_name = "FILE.toml")]
    pub config: Option<PathBuf>,
    /// Print one JSON object instead of the table (no files written)
    #[arg(long)]
    pub json: bool,
    /// Write the nominal run's traces (trace.csv, every sample) and marths.md here
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// RoDeAC, ARX (decentralised) and ARX over both channels side by side on the three
    /// records, nominal and --trials uncertain plants (default 20): J2, J7, stability; prints a
    /// Markdown table (with --json: the rows)
    #[arg(long)]
    pub compare: bool,
}

/// The flags as the library's options (files read here, through the bounded readers).
fn options<'a>(
    args: &'a MarthsArgs,
    record_text: &'a Option<String>,
    config_text: &'a Option<(String, String)>,
) -> MarthsOptions<'a> {
    MarthsOptions {
        record: match record_text {
            Some(text) => RecordChoice::File {
                name: &args.record,
                text,
            },
            None => RecordChoice::Shipped(&args.record),
        },
        intensity: args.intensity,
        controller: &args.controller,
        trials: args.trials,
        seed: args.seed,
        noise: !args.no_noise,
        ideal: args.ideal,
        algorithm: &args.algorithm,
        partition_density: args.partition_density,
        config: config_text.as_ref().map(|(n, t)| (n.as_str(), t.as_str())),
    }
}

/// The record's text when `--record` names a file (not a shipped record); a name that is
/// neither is refused by the library with the list.
fn record_text(name: &str) -> Result<Option<String>> {
    if !names_a_record_file(name) {
        return Ok(None);
    }
    Ok(Some(substep::io::limits::read_record_text(
        Path::new(name),
        &substep::io::limits::Limits::default(),
    )?))
}

fn config_text(args: &MarthsArgs) -> Result<Option<(String, String)>> {
    Ok(match &args.config {
        Some(path) => Some((
            path.display().to_string(),
            substep::io::limits::read_text(path, substep::io::limits::CONFIG_MAX_BYTES)?,
        )),
        None => None,
    })
}

fn comparison(args: &MarthsArgs) -> Result<()> {
    let trials = if args.trials == 0 { 20 } else { args.trials };
    let comparison = report::comparison(trials, args.seed, !args.no_noise)?;
    if args.json {
        out(&format!("{}\n", serde_json::to_string_pretty(&comparison.json())?));
    } else {
        out(&comparison.text());
    }
    Ok(comparison.verdict()?)
}

pub fn marths(args: &MarthsArgs) -> Result<()> {
    if args.compare {
        return comparison(args);
    }
    let (record, config) = (record_text(&args.record)?, config_text(args)?);
    let options = options(args, &record, &config);
    let input = options.input(|name| format!("--{}", name.replace('_', "-")))?;
    let t0 = std::time::Instant::now();
    let reference = reference(&input)?;
    let study = run_with(&input, &reference, args.trials, args.seed)?;
    let elapsed = t0.elapsed().as_secs_f64();
    let verdict = || -> Result<()> {
        match study.divergence() {
            Some(e) => Err(e.into()),
            None => Ok(()),
        }
    };
    if args.json {
        out(&format!(
            "{}\n",
            serde_json::to_string_pretty(&options.json(&input, &study, elapsed))?
        ));
        return verdict();
    }
    let head = report::describe(&input, args.config.is_some(), &args.algorithm);
    let text = report::table(&head, &study, args.trials);
    out(&text);
    out(&format!("{} run(s) in {elapsed:.2} s\n", 1 + study.trials.len()));
    if let Some(dir) = &args.out {
        out(&report::write_run(&input, &text, dir, &command())?.summary());
    }
    verdict()
}
