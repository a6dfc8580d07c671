//! The report of `substep benchmark marths`: the criteria table J1–J10 printed to the terminal,
//! the output folder of a run (`trace.csv`: the nominal run at every sample, time in s, strokes
//! and translations in mm, rotations in rad; `marths.md`: the command and the table) and the
//! controllers side by side (`--compare`: a Markdown table or JSON, no files). J1 and J4 in ms,
//! J2, J3 and J5–J10 in %.
//!
//! Nothing here prints: the text the front end shows is returned.

use super::{
    COMMAND_LIMIT_V, CompareRow, ControllerKind, MarthsInput, Record, SAMPLE_TIME, Study, Transfer, compare,
    compare_markdown, criteria_json, reference, round1, run,
};
use crate::atomic_file::write_atomic;
use crate::error::{Error, Result};
use serde_json::{Value, json};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

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

/// The heading line of a run: record, intensity, controller, `algorithm` (as the caller named
/// it) and the transfer system (`configured`: the plant comes from a settings file).
pub fn describe(input: &MarthsInput, configured: bool, algorithm: &str) -> String {
    let transfer = match input.transfer {
        Transfer::Ideal => "ideal transfer system".to_string(),
        Transfer::Plant { noise_seed, .. } => format!(
            "{} plant, {}",
            if configured { "configured" } else { "the toolset's" },
            noise_seed.map_or("no sensor noise".to_string(), |s| format!("sensor noise (seed {s})"))
        ),
    };
    format!(
        "maRTHS benchmark: {} × {}, controller {}, algorithm {algorithm}, {transfer}",
        input.record.name,
        input.intensity,
        input.controller.name(),
    )
}

/// The criteria of `study` under `head` ([`describe`]): the nominal plant's with `trials` = 0,
/// else the mean over the uncertain plants; the peak commands and the runs' stability.
pub fn table(head: &str, study: &Study, trials: usize) -> String {
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

/// What [`write_run`] wrote.
#[derive(Debug, Clone)]
pub struct RunReport {
    /// `marths.md`.
    pub markdown: PathBuf,
    /// `trace.csv`.
    pub trace: PathBuf,
}

impl RunReport {
    /// Every written file.
    pub fn files(&self) -> Vec<PathBuf> {
        vec![self.trace.clone(), self.markdown.clone()]
    }

    /// The closing line naming the files.
    pub fn summary(&self) -> String {
        format!("wrote {} and {}\n", self.markdown.display(), self.trace.display())
    }
}

/// The output folder `dir` of a run (created): `trace.csv` of the nominal run again with its
/// history kept, and `marths.md` quoting `command` and `table` (the printed [`table`]).
pub fn write_run(input: &MarthsInput, table: &str, dir: &Path, command: &str) -> Result<RunReport> {
    std::fs::create_dir_all(dir).map_err(|e| {
        Error::file(
            dir.display().to_string(),
            format!("cannot create the output directory: {e}"),
        )
    })?;
    let trace = write_trace(input, dir)?;
    let md = format!(
        "# maRTHS benchmark\n\nCommand: `{command}`\n\n```text\n{table}```\n\nTraces of the nominal run: `trace.csv` (every sample).\n"
    );
    let path = dir.join("marths.md");
    write_file(&path, md.as_bytes())?;
    Ok(RunReport { markdown: path, trace })
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, bytes).map_err(|e| Error::write(path, e))
}

/// `dir/trace.csv`: the nominal run of `input` at every sample (targets, measured strokes and
/// commands of both actuators; the frame's `x`, `θ` measured, numerical and reference).
pub fn write_trace(input: &MarthsInput, dir: &Path) -> Result<PathBuf> {
    let mut one = input.clone();
    one.keep_history = true;
    let reference = reference(&one)?;
    let result = run(&one, &reference)?;
    let h = result
        .history
        .ok_or_else(|| Error::numerical("benchmark marths", "the run kept no history"))?;
    let n = h.len();
    let mut text = String::with_capacity(n * 300);
    text.push_str(
        "t [s],target 1 [mm],target 2 [mm],measured 1 [mm],measured 2 [mm],command 1 [mm],command 2 [mm],x measured [mm],θ measured [rad],x numerical [mm],θ numerical [rad],x reference [mm],θ reference [rad]\n",
    );
    for k in 0..n {
        let _ = writeln!(
            text,
            "{},{},{},{},{},{},{},{},{},{},{},{},{}",
            k as f64 * SAMPLE_TIME,
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
    write_file(&path, text.as_bytes())?;
    Ok(path)
}

/// The compared controllers: RoDeAC, ARX per actuator, ARX over both channels.
pub const COMPARED: [&str; 3] = ["rodeac", "arx", "arx_mimo"];

/// The controllers side by side ([`comparison`]).
#[derive(Debug, Clone)]
pub struct Comparison {
    pub rows: Vec<CompareRow>,
    /// Uncertain plants per record and controller.
    pub trials: usize,
    pub seed: u64,
    pub noise: bool,
    /// Wall-clock time of the runs \[s\].
    pub elapsed: f64,
}

/// [`COMPARED`] on every shipped record at intensity 0.4, the nominal plant and `trials`
/// uncertain ones (seeded by `seed`, sensor noise when `noise`).
pub fn comparison(trials: usize, seed: u64, noise: bool) -> Result<Comparison> {
    let controllers = COMPARED.map(|c| ControllerKind::parse(c).expect("a known controller"));
    let t0 = std::time::Instant::now();
    let rows = compare(&Record::all(), &controllers, trials, seed, noise)?;
    Ok(Comparison {
        rows,
        trials,
        seed,
        noise,
        elapsed: t0.elapsed().as_secs_f64(),
    })
}

impl Comparison {
    /// The rows as one JSON object (`rows`, `noise`, `seed`).
    pub fn json(&self) -> Value {
        let rows: Vec<Value> = self
            .rows
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
        json!({ "rows": rows, "noise": self.noise, "seed": self.seed })
    }

    /// The heading, the Markdown table ([`compare_markdown`]) and the runs' count and time.
    pub fn text(&self) -> String {
        format!(
            "maRTHS: controllers side by side, intensity 0.4, {}, {} uncertain plants (seed {})\n\n{}\n{} runs in {:.1} s\n",
            if self.noise { "sensor noise" } else { "no sensor noise" },
            self.trials,
            self.seed,
            compare_markdown(&self.rows),
            self.rows.len() * (self.trials + 1),
            self.elapsed
        )
    }

    /// A failure (exit code 1) when any run diverged.
    pub fn verdict(&self) -> Result<()> {
        let unstable: usize = self
            .rows
            .iter()
            .map(|r| r.trials - r.stable_trials + usize::from(r.nominal.is_none()))
            .sum();
        if unstable > 0 {
            return Err(Error::Diverged {
                step: 0,
                time: 0.0,
                reason: format!("benchmark marths --compare: {unstable} run(s) diverged"),
            });
        }
        Ok(())
    }
}
