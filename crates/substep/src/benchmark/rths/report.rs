//! The report of `substep benchmark rths` (and of Python's benchmark), written from the rows of
//! a study: the criteria table printed to the terminal, the output folder of a run
//! (`benchmark.md`; `trace_caseN.csv` at every controller sample and `floors_caseN.csv` on the
//! numerical substructure's grid; optionally `traces.h5` / `traces.mat`; the figures
//! `tracking_caseN`, `tracking_zoom_caseN`, `floors_caseN`) and `comparison.md` of the
//! controllers side by side. Units SI (time s, displacement m, force N) in the files; the
//! figures show displacements in mm; J1 in ms, J2–J9 in %.
//!
//! Nothing here prints: the text the front end shows is handed to a callback or returned.

use super::{
    Algorithm, COMPARED, Case, ComparisonRow, FORCE_CAPACITY, PUBLISHED_SAMPLE, RthsInput, RthsRow, RunHistory,
    StudySetup,
};
use super::{perturbed_stats, run};
use crate::atomic_file::write_atomic;
use crate::error::{Error, Result};
use crate::figure::{Curve, PlotFormat, check_format, line_chart};
use crate::io::results::{Format, Metadata, write_tables};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// What [`write_run`] writes, and how the caller names things in messages.
#[derive(Debug, Clone)]
pub struct RunOptions<'a> {
    /// The output folder (created).
    pub out: &'a Path,
    /// The figures' format; `None`: no figures.
    pub plots: Option<PlotFormat>,
    /// How the caller names the figure format in the message refusing one this build cannot
    /// draw (`--plot-format`).
    pub plot_option: &'a str,
    /// The traces also in one container (`traces.h5`, `traces.mat`); CSV: none.
    pub format: Format,
    /// The command line quoted in `benchmark.md`.
    pub command: &'a str,
    /// The settings file's text, stored in the container (`config`); empty when none.
    pub config: Option<&'a str>,
}

/// The files [`write_run`] wrote.
#[derive(Debug, Clone)]
pub struct RunReport {
    /// `benchmark.md`.
    pub markdown: PathBuf,
    /// The trace CSV files, `trace_caseN.csv` and `floors_caseN.csv` per case.
    pub traces: Vec<PathBuf>,
    /// `traces.h5` or `traces.mat` when asked for.
    pub container: Option<PathBuf>,
    /// The figures.
    pub figures: Vec<PathBuf>,
}

impl RunReport {
    /// Every written file: the traces, the container, the figures, `benchmark.md`.
    pub fn files(&self) -> Vec<PathBuf> {
        let mut files = self.traces.clone();
        files.extend(self.container.clone());
        files.extend(self.figures.iter().cloned());
        files.push(self.markdown.clone());
        files
    }

    /// The closing line: `runs` runs in `elapsed` seconds and what was written.
    pub fn summary(&self, runs: usize, elapsed: f64) -> String {
        format!(
            "{runs} run(s) in {elapsed:.2} s; wrote {}, {} trace files (CSV{}){}\n",
            self.markdown.display(),
            self.traces.len(),
            self.container
                .as_ref()
                .map_or(String::new(), |p| format!(", and {}", p.display())),
            if self.figures.is_empty() {
                String::new()
            } else {
                format!(" and {} plots", self.figures.len())
            }
        )
    }
}

/// The output folder of a study's run: `progress` gets the criteria table ([`table`]) first,
/// then the folder is created, the nominal runs are repeated with their histories kept (the
/// same numbers as the scored runs) and the traces, the container, the figures and
/// `benchmark.md` are written.
pub fn write_run(
    setup: &StudySetup,
    rows: &[RthsRow],
    options: &RunOptions<'_>,
    progress: &mut dyn FnMut(&str),
) -> Result<RunReport> {
    progress(&table(setup, rows));
    create_dir(options.out)?;
    if let Some(format) = options.plots {
        check_format(format, options.plot_option)?;
    }
    let base = setup.base.with_k_sub(setup.k_subs.first().copied().flatten());
    let histories = histories(&base, &setup.cases)?;
    let traces = write_traces(&histories, options.out)?;
    let container = match options.format {
        Format::Csv => None,
        format => Some(write_trace_container(
            options.out,
            format,
            &traces,
            &setup.json(rows),
            options.config.unwrap_or_default(),
        )?),
    };
    let figures = match options.plots {
        None => Vec::new(),
        Some(format) => write_figures(&histories, options.out, format)?,
    };
    let md = markdown(setup, rows, options.command, &figures);
    let path = options.out.join("benchmark.md");
    write_file(&path, md.as_bytes())?;
    Ok(RunReport {
        markdown: path,
        traces,
        container,
        figures,
    })
}

/// The failure of a study in which a nominal run has no score (it diverged): the message, or
/// `None` when every case is scored.
pub fn no_score(rows: &[RthsRow]) -> Option<String> {
    let cases: Vec<String> = rows
        .iter()
        .filter(|r| r.nominal.criteria.is_none())
        .map(|r| r.case.to_string())
        .collect();
    (!cases.is_empty()).then(|| {
        format!(
            "benchmark rths: no score for case {}: the run diverged (see the warnings)",
            cases.join(", ")
        )
    })
}

fn create_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| {
        Error::file(
            dir.display().to_string(),
            format!("cannot create the output directory: {e}"),
        )
    })
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, bytes).map_err(|e| Error::write(path, e))
}

fn fmt_j(j: Option<[f64; 9]>) -> String {
    match j {
        Some(j) => j.iter().map(|v| format!("{v:>6.2}")).collect::<Vec<_>>().join(" "),
        None => format!("{:>62}", "diverged"),
    }
}

/// The criteria per case (and k_sub) as a fixed-width table, with the published values of the
/// published setting and the perturbed plants' mean and maximum.
pub fn table(setup: &StudySetup, rows: &[RthsRow]) -> String {
    let mut s = String::new();
    let alg = match &setup.base.algorithm {
        Algorithm::Benchmark => "benchmark loop (RK4 at 1/4096 s)".to_string(),
        Algorithm::Substep(sp) => format!(
            "sub-step algorithm (Δt = {} s, error force {})",
            sp.dt,
            sp.error_force.kind()
        ),
    };
    let _ = writeln!(
        s,
        "RTHS benchmark: controller {}, record {} × {}, {}",
        setup.kind.name(),
        setup.base.record.name,
        crate::format::sig(setup.base.intensity, 6),
        alg
    );
    let head = "    J1     J2     J3     J4     J5     J6     J7     J8     J9";
    let _ = writeln!(s, "case k_sub {head}  max F [N] stable capacity");
    for row in rows {
        let r = &row.nominal;
        let _ = writeln!(
            s,
            "{:>4} {:>5} {}  {:>9.1} {:>6} {:>8}",
            row.case,
            row.k_sub.map_or("-".into(), |k| k.to_string()),
            fmt_j(r.criteria.map(|c| c.j)),
            r.max_force,
            if r.stable { "yes" } else { "no" },
            if r.capacity_exceeded { "exceeded" } else { "ok" }
        );
        if setup.base.is_published_setting() {
            let _ = writeln!(
                s,
                "{:>10} {}",
                "published",
                fmt_j(Some(PUBLISHED_SAMPLE[row.case as usize - 1]))
            );
        }
        if !row.perturbed.is_empty() {
            let st = perturbed_stats(&row.perturbed);
            let _ = writeln!(s, "{:>10} {}", "pert. mean", fmt_j(Some(st.mean)));
            let _ = writeln!(
                s,
                "{:>10} {}  {:>9.1}  {}/{n} stable, {}/{n} under 8900 N",
                "pert. max",
                fmt_j(Some(st.max)),
                st.max_force,
                st.stable,
                st.under_capacity,
                n = row.perturbed.len()
            );
        }
    }
    s.push_str("J1 [ms]; J2–J9 [%] (J2/J3 tracking, J4/J5 floor 1, J6/J7 NRMS and J8/J9 peak of floors 2/3 vs the exact reference)\n");
    s
}

/// `benchmark.md`: the command, the criteria table, the warnings and links to the figures.
pub fn markdown(setup: &StudySetup, rows: &[RthsRow], command: &str, plots: &[PathBuf]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# RTHS benchmark results\n\nCommand: `{command}`\n");
    let _ = writeln!(
        s,
        "Controller `{}`, record `{}` × {}.\n",
        setup.kind.name(),
        setup.base.record.name,
        crate::format::sig(setup.base.intensity, 6)
    );
    let _ = writeln!(
        s,
        "| case | k_sub | J1 | J2 | J3 | J4 | J5 | J6 | J7 | J8 | J9 | max F [N] | stable | capacity |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let cells = |j: Option<[f64; 9]>| match j {
        Some(j) => j.iter().map(|v| format!("{v:.2}")).collect::<Vec<_>>().join(" | "),
        None => ["–"; 9].join(" | "),
    };
    for row in rows {
        let r = &row.nominal;
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.1} | {} | {} |",
            row.case,
            row.k_sub.map_or("–".into(), |k| k.to_string()),
            cells(r.criteria.map(|c| c.j)),
            r.max_force,
            if r.stable { "yes" } else { "no" },
            if r.capacity_exceeded { "exceeded" } else { "ok" }
        );
        if setup.base.is_published_setting() {
            let _ = writeln!(
                s,
                "| {} published | | {} | | | |",
                row.case,
                cells(Some(PUBLISHED_SAMPLE[row.case as usize - 1]))
            );
        }
        if !row.perturbed.is_empty() {
            let st = perturbed_stats(&row.perturbed);
            let n = row.perturbed.len();
            let _ = writeln!(
                s,
                "| {} perturbed mean | | {} | | {}/{n} | |",
                row.case,
                cells(Some(st.mean)),
                st.stable
            );
            let _ = writeln!(
                s,
                "| {} perturbed max | | {} | {:.1} | | {}/{n} under 8900 N |",
                row.case,
                cells(Some(st.max)),
                st.max_force,
                st.under_capacity
            );
        }
    }
    s.push_str("\nJ1 [ms]; J2–J9 [%], rounded as the benchmark rounds.\n");
    let warnings: Vec<String> = rows.iter().flat_map(|r| r.nominal.warnings()).collect();
    if !warnings.is_empty() {
        s.push_str("\n**Warnings**\n\n");
        for w in warnings {
            let _ = writeln!(s, "* {w}");
        }
    }
    if !plots.is_empty() {
        s.push_str("\nPlots:\n\n");
        for p in plots {
            let name = p
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let _ = writeln!(s, "* [{name}]({name})");
        }
    }
    s
}

/// At most `max` points of `(t, y)` (every n-th sample) for full-length plots.
fn decimate(h: f64, stride: usize, y: &[f64], from: usize, to: usize, max: usize) -> (Vec<f64>, Vec<f64>) {
    let step = ((to - from) / max).max(1);
    let idx: Vec<usize> = (from..to).step_by(step).collect();
    (
        idx.iter().map(|&i| i as f64 * h * stride as f64).collect(),
        idx.iter().map(|&i| y[i]).collect(),
    )
}

fn curve(label: &str, xy: (Vec<f64>, Vec<f64>), scale: f64) -> Curve {
    Curve {
        label: label.into(),
        x: xy.0,
        y: xy.1.into_iter().map(|v| v * scale).collect(),
    }
}

/// The nominal run of every case again with its time histories kept (deterministic: the same
/// numbers as the scored run); a case that diverged has none.
pub fn histories(base: &RthsInput, cases: &[Case]) -> Result<Vec<(Case, RunHistory)>> {
    let mut out = Vec::new();
    for case in cases {
        let mut input = base.clone();
        input.case = *case;
        input.keep_history = true;
        if let Some(hist) = run(&input)?.history {
            out.push((*case, hist));
        }
    }
    Ok(out)
}

/// `trace_caseN.csv` (every controller sample) and `floors_caseN.csv` (the numerical
/// substructure's grid) in `dir` for comparisons sample by sample; SI units, numbers in their
/// shortest exact form.
pub fn write_traces(histories: &[(Case, RunHistory)], dir: &Path) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for (case, hist) in histories {
        let c = case.number;
        let n = hist.desired.len();
        let mut text = String::with_capacity(n * 160);
        text.push_str(
            "t [s],target y_n [m],command u [m],measured x_m [m],actuator force F [N],reference floor 1 [m],reference floor 2 [m],reference floor 3 [m]\n",
        );
        for k in 0..n {
            let _ = writeln!(
                text,
                "{},{},{},{},{},{},{},{}",
                k as f64 * hist.h,
                hist.desired[k],
                hist.command[k],
                hist.measured[k],
                hist.actuator_force[k],
                hist.reference[0][k],
                hist.reference[1][k],
                hist.reference[2][k]
            );
        }
        let path = dir.join(format!("trace_case{c}.csv"));
        write_file(&path, text.as_bytes())?;
        files.push(path);
        let stride = hist.floor_stride;
        let m = hist.floors[0].len();
        let mut text = String::with_capacity(m * 140);
        text.push_str(
            "t [s],floor 1 [m],floor 2 [m],floor 3 [m],reference floor 1 [m],reference floor 2 [m],reference floor 3 [m]\n",
        );
        for j in 0..m {
            let k = j * stride;
            let r = |i: usize| hist.reference[i].get(k).copied().unwrap_or(f64::NAN);
            let _ = writeln!(
                text,
                "{},{},{},{},{},{},{}",
                k as f64 * hist.h,
                hist.floors[0][j],
                hist.floors[1][j],
                hist.floors[2][j],
                r(0),
                r(1),
                r(2)
            );
        }
        let path = dir.join(format!("floors_case{c}.csv"));
        write_file(&path, text.as_bytes())?;
        files.push(path);
    }
    Ok(files)
}

/// The trace CSV files gathered into `dir/traces.h5` / `dir/traces.mat` (one group or struct per
/// file: `trace_case1`, `floors_case1`, …; a dataset or field per column with its unit), with
/// the results as JSON (`summary`) and the settings file's text (`config`).
pub fn write_trace_container(
    dir: &Path,
    format: Format,
    files: &[PathBuf],
    results: &serde_json::Value,
    config: &str,
) -> Result<PathBuf> {
    let tables: Vec<(String, PathBuf)> = files
        .iter()
        .map(|p| {
            let stem = p
                .file_stem()
                .map_or(String::new(), |s| s.to_string_lossy().into_owned());
            (stem, p.clone())
        })
        .collect();
    let tables: Vec<(&str, PathBuf)> = tables.iter().map(|(n, p)| (n.as_str(), p.clone())).collect();
    let meta = Metadata {
        summary_json: serde_json::to_string_pretty(results)
            .map_err(|e| Error::invalid("the benchmark's results", e.to_string()))?,
        config: config.to_string(),
    };
    let name = if format == Format::Hdf5 {
        "traces.h5"
    } else {
        "traces.mat"
    };
    let path = dir.join(name);
    write_tables(&path, format, &tables, &meta)?;
    Ok(path)
}

/// Per case in `dir`: `tracking_caseN` (desired vs measured actuator displacement, the whole
/// record), `tracking_zoom_caseN` (0.5 s around the largest desired displacement) and
/// `floors_caseN` (the floors against the exact reference, 3 s around the top floor's peak);
/// displacements in mm.
pub fn write_figures(histories: &[(Case, RunHistory)], dir: &Path, format: PlotFormat) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for (case, hist) in histories {
        let h = hist.h;
        let n = hist.desired.len();
        let c = case.number;
        let path = dir.join(format!("tracking_case{c}.png"));
        let written = line_chart(
            &path,
            format,
            &format!("case {c}: desired vs measured actuator displacement"),
            "t [s]",
            "displacement [mm]",
            &[
                curve("desired y_n", decimate(h, 1, &hist.desired, 0, n, 8000), 1e3),
                curve("measured x_m", decimate(h, 1, &hist.measured, 0, n, 8000), 1e3),
            ],
        )?;
        files.push(written);
        // Zoom: 0.5 s around the largest desired displacement.
        let peak = (0..n)
            .max_by(|&a, &b| hist.desired[a].abs().total_cmp(&hist.desired[b].abs()))
            .unwrap_or(0);
        let half = (0.25 / h) as usize;
        let (from, to) = (peak.saturating_sub(half), (peak + half).min(n));
        let path = dir.join(format!("tracking_zoom_case{c}.png"));
        let written = line_chart(
            &path,
            format,
            &format!("case {c}: tracking, 0.5 s around the peak"),
            "t [s]",
            "displacement [mm]",
            &[
                curve("desired y_n", decimate(h, 1, &hist.desired, from, to, 4000), 1e3),
                curve("measured x_m", decimate(h, 1, &hist.measured, from, to, 4000), 1e3),
            ],
        )?;
        files.push(written);
        // Floors: 3 s around the peak of the top floor's reference (the whole record is too dense).
        let stride = hist.floor_stride;
        let m = hist.floors[0].len();
        let top: Vec<f64> = hist.reference[2].iter().step_by(stride).copied().take(m).collect();
        let peak = (0..m)
            .max_by(|&a, &b| top[a].abs().total_cmp(&top[b].abs()))
            .unwrap_or(0);
        let half = (1.5 / (h * stride as f64)) as usize;
        let (from, to) = (peak.saturating_sub(half), (peak + half).min(m));
        let mut curves = Vec::new();
        for i in 0..3 {
            let reference: Vec<f64> = hist.reference[i].iter().step_by(stride).copied().take(m).collect();
            curves.push(curve(
                &format!("floor {} reference", i + 1),
                decimate(h, stride, &reference, from, to, 4000),
                1e3,
            ));
            curves.push(curve(
                &format!("floor {} RTHS", i + 1),
                decimate(h, stride, &hist.floors[i], from, to, 4000),
                1e3,
            ));
        }
        let path = dir.join(format!("floors_case{c}.png"));
        let written = line_chart(
            &path,
            format,
            &format!("case {c}: floor displacements vs the exact reference (3 s around the peak)"),
            "t [s]",
            "displacement [mm]",
            &curves,
        )?;
        files.push(written);
    }
    Ok(files)
}

/// The controllers side by side as a Markdown table: J2, J4 (%), peak force (N), stability of
/// the nominal and perturbed plants, the worst perturbed J2, J4 and force, CPU time per sample
/// (µs).
pub fn comparison_table(rows: &[ComparisonRow]) -> String {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "| controller | noise | case | J2 [%] | J4 [%] | max F [N] | stable | perturbed stable | under {FORCE_CAPACITY} N | worst J2 [%] | worst J4 [%] | worst F [N] | CPU [µs/sample] |"
    );
    md.push_str("|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    let num = |x: f64, digits: usize| {
        if x.is_finite() {
            format!("{x:.digits$}")
        } else {
            "–".to_string()
        }
    };
    for r in rows {
        let j = r.nominal.criteria.map(|c| c.j);
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {} | {}/{} | {}/{} | {} | {} | {} | {} |",
            r.kind.name(),
            if r.noise { "on" } else { "off" },
            r.case,
            j.map_or("–".into(), |j| num(j[1], 2)),
            j.map_or("–".into(), |j| num(j[3], 2)),
            num(r.nominal.max_force, 0),
            if r.nominal.stable { "yes" } else { "no" },
            r.stable,
            r.perturbed,
            r.under_capacity,
            r.perturbed,
            num(r.worst_j2, 2),
            num(r.worst_j4, 2),
            num(r.worst_force, 0),
            num(r.cpu_per_sample * 1e6, 3),
        );
    }
    md
}

/// What [`write_comparison`] wrote.
#[derive(Debug, Clone)]
pub struct ComparisonReport {
    /// `comparison.md`.
    pub markdown: PathBuf,
}

impl ComparisonReport {
    /// The closing line: how many runs of how many controllers in `elapsed` seconds.
    pub fn summary(&self, setup: &StudySetup, rows: &[ComparisonRow], elapsed: f64) -> String {
        format!(
            "{} controllers × 2 noise settings × {} case(s), {} runs in {elapsed:.1} s; wrote {}\n",
            COMPARED.len(),
            setup.cases.len(),
            rows.len() * (1 + setup.perturbed.unwrap_or(0)),
            self.markdown.display()
        )
    }
}

/// `out/comparison.md` of the controllers side by side (the rows of [`super::compare`]):
/// `progress` gets the table ([`comparison_table`]) first; `command` is quoted in the file.
pub fn write_comparison(
    setup: &StudySetup,
    rows: &[ComparisonRow],
    out: &Path,
    command: &str,
    progress: &mut dyn FnMut(&str),
) -> Result<ComparisonReport> {
    let md = comparison_table(rows);
    progress(&md);
    create_dir(out)?;
    let path = out.join("comparison.md");
    let text = format!(
        "# RTHS benchmark: the controllers side by side\n\n`{command}`\n\nRecord {} × {}; {} perturbed plants per case (seed {}). Each controller with its one preset setting (docs/benchmark.md). J2, J4 of the nominal plant; worst J2, J4 and force over the stable perturbed runs; CPU time of the controller alone per sample (replayed on the nominal run's signals, median of 5).\n\n{md}",
        setup.base.record.name,
        setup.base.intensity,
        setup.perturbed.unwrap_or(0),
        setup.seed
    );
    write_file(&path, text.as_bytes())?;
    Ok(ComparisonReport { markdown: path })
}
