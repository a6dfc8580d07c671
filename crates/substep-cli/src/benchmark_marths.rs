//! `substep benchmark marths`: the multi-axial RTHS benchmark (maRTHS) as a built-in. Thin: parse
//! the flags, call `substep::benchmark::marths`, print the table or one JSON object, write the
//! traces and `marths.md`.

use anyhow::{Context, Result};
use serde_json::{Value, json};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use substep::benchmark::marths::{
    COMMAND_LIMIT_V, ControllerKind, MarthsInput, MarthsOptions, Record, RecordChoice, Study, Transfer, compare,
    compare_markdown, criteria_json, names_a_record_file, reference, round1, run, run_with,
};

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

fn out(text: &str) {
    use std::io::Write;
    let _ = std::io::stdout().lock().write_all(text.as_bytes());
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

const LABELS: [(&str, &str, &[&str]); 10] = [
    ("J1", "delay [ms]", &["act. 1", "act. 2"]),
    ("J2", "NRMS tracking [%]", &["act. 1", "act. 2"]),
    ("J3", "peak tracking [%]", &["act. 1", "act. 2"]),
    ("J4", "delay, as coded = J1 [ms]", &["act. 1", "act. 2"]),
    ("J5", "NRMS frame vs numerical [%]", &["x", "θ"]),
    ("J6", "peak frame vs numerical [%]", &["x", "θ"]),
    ("J7", "NRMS frame vs reference [%]", &["x", "θ"]),
    ("J8", "NRMS storeys 2, 3 [%]", &["x₂", "θ₂", "x₃", "θ₃"]),
    ("J9", "peak frame vs reference [%]", &["x", "θ"]),
    ("J10", "peak storeys 2, 3 [%]", &["x₂", "θ₂", "x₃", "θ₃"]),
];

fn describe(args: &MarthsArgs, input: &MarthsInput) -> String {
    let transfer = match input.transfer {
        Transfer::Ideal => "ideal transfer system".to_string(),
        Transfer::Plant { noise_seed, .. } => format!(
            "{} plant, {}",
            if args.config.is_some() {
                "configured"
            } else {
                "the toolset's"
            },
            noise_seed.map_or("no sensor noise".to_string(), |s| format!("sensor noise (seed {s})"))
        ),
    };
    format!(
        "maRTHS benchmark: {} × {}, controller {}, algorithm {}, {transfer}",
        input.record.name,
        input.intensity,
        input.controller.name(),
        args.algorithm
    )
}

fn table(head: &str, study: &Study, trials: usize) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "{head}");
    let what = if trials == 0 {
        "nominal plant".to_string()
    } else {
        format!("mean over {trials} uncertain plants (nominal excluded), rounded as the toolset reports")
    };
    let _ = writeln!(s, "J1–J10: {what}");
    match study.reported() {
        Some(c) => {
            let c = c.map(round1);
            for ((name, values), (_, label, parts)) in c.lists().iter().zip(LABELS) {
                let cells: Vec<String> = values.iter().zip(parts).map(|(v, p)| format!("{p} {v:.1}")).collect();
                let _ = writeln!(s, "  {name:<4} {label:<30} {}", cells.join("   "));
            }
        }
        None => {
            let _ = writeln!(s, "  no score: a run diverged");
        }
    }
    let v = study.nominal.peak_volts;
    let _ = writeln!(
        s,
        "realizable: {} (peak command, nominal: {:.2} / {:.2} V; limit {COMMAND_LIMIT_V} V on both actuators)",
        if study.realizable() { "yes" } else { "NO" },
        v[0],
        v[1]
    );
    let diverged = study.diverged_runs();
    let _ = writeln!(
        s,
        "runs: 1 nominal + {} uncertain, {}",
        study.trials.len(),
        if diverged == 0 {
            "all stable".to_string()
        } else {
            format!("{diverged} DIVERGED")
        }
    );
    s
}

fn trace(input: &MarthsInput, dir: &Path) -> Result<PathBuf> {
    let mut one = input.clone();
    one.keep_history = true;
    let reference = reference(&one)?;
    let result = run(&one, &reference)?;
    let h = result.history.context("the run kept no history")?;
    let n = h.len();
    let mut text = String::with_capacity(n * 300);
    text.push_str(
        "t [s],target 1 [mm],target 2 [mm],measured 1 [mm],measured 2 [mm],command 1 [mm],command 2 [mm],x measured [mm],θ measured [rad],x numerical [mm],θ numerical [rad],x reference [mm],θ reference [rad]\n",
    );
    for k in 0..n {
        let _ = writeln!(
            text,
            "{},{},{},{},{},{},{},{},{},{},{},{},{}",
            k as f64 * substep::benchmark::marths::SAMPLE_TIME,
            h.target[0][k],
            h.target[1][k],
            h.measured[0][k],
            h.measured[1][k],
            h.command[0][k],
            h.command[1][k],
            h.frame_measured[0][k],
            h.frame_measured[1][k],
            h.frame_numerical[0][k],
            h.frame_numerical[1][k],
            h.frame_reference[0][k],
            h.frame_reference[1][k],
        );
    }
    let path = dir.join("trace.csv");
    std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(path)
}

fn comparison(args: &MarthsArgs) -> Result<()> {
    let trials = if args.trials == 0 { 20 } else { args.trials };
    let controllers = ["rodeac", "arx", "arx_mimo"].map(|c| ControllerKind::parse(c).expect("a known controller"));
    let t0 = std::time::Instant::now();
    let rows = compare(&Record::all(), &controllers, trials, args.seed, !args.no_noise)?;
    let elapsed = t0.elapsed().as_secs_f64();
    let unstable: usize = rows
        .iter()
        .map(|r| r.trials - r.stable_trials + usize::from(r.nominal.is_none()))
        .sum();
    if args.json {
        let rows: Vec<Value> = rows
            .iter()
            .map(|r| {
                json!({
                    "record": r.record,
                    "controller": r.controller,
                    "nominal": r.nominal.as_ref().map_or(Value::Null, criteria_json),
                    "mean": r.mean.as_ref().map_or(Value::Null, criteria_json),
                    "worst_J2": r.worst_j2,
                    "worst_J7": r.worst_j7,
                    "stable_trials": r.stable_trials,
                    "trials": r.trials,
                    "backed_off": r.backed_off,
                    "realizable": r.realizable,
                })
            })
            .collect();
        out(&format!(
            "{}\n",
            serde_json::to_string_pretty(&json!({ "rows": rows, "noise": !args.no_noise, "seed": args.seed }))?
        ));
    } else {
        out(&format!(
            "maRTHS: controllers side by side, intensity 0.4, {}, {trials} uncertain plants (seed {})\n\n{}\n{} runs in {elapsed:.1} s\n",
            if args.no_noise {
                "no sensor noise"
            } else {
                "sensor noise"
            },
            args.seed,
            compare_markdown(&rows),
            rows.len() * (trials + 1)
        ));
    }
    if unstable > 0 {
        return Err(substep::Error::Diverged {
            step: 0,
            time: 0.0,
            reason: format!("benchmark marths --compare: {unstable} run(s) diverged"),
        }
        .into());
    }
    Ok(())
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
    let head = describe(args, &input);
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
    let text = table(&head, &study, args.trials);
    out(&text);
    out(&format!("{} run(s) in {elapsed:.2} s\n", 1 + study.trials.len()));
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let trace = trace(&input, dir)?;
        let command = std::iter::once("substep".to_string())
            .chain(std::env::args().skip(1))
            .collect::<Vec<_>>()
            .join(" ");
        let md = format!(
            "# maRTHS benchmark\n\nCommand: `{command}`\n\n```text\n{text}```\n\nTraces of the nominal run: `trace.csv` (every sample).\n"
        );
        let path = dir.join("marths.md");
        std::fs::write(&path, md).with_context(|| format!("cannot write {}", path.display()))?;
        out(&format!("wrote {} and {}\n", path.display(), trace.display()));
    }
    verdict()
}
