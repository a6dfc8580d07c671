//! `substep benchmark rths`: the RTHS benchmark control problem (Silva et al. 2020) as a
//! built-in. Thin: parse the flags, call `substep::benchmark::rths`, print, write
//! `benchmark.md` and plots.

use crate::plots::{Curve, line_chart};
use anyhow::{Context, Result};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use substep::benchmark::rths::{
    Algorithm, COMPARED, Case, FORCE_CAPACITY, PUBLISHED_SAMPLE, RthsInput, RthsRow, RunHistory, StudyOptions,
    StudySetup, perturbed_stats, run,
};
use substep::io::results::{Format, Metadata, write_tables};

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

/// The CLI's flags as the library's study options; files read here.
fn setup(args: &RthsArgs) -> Result<StudySetup> {
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
    Ok(options.setup(|name| format!("--{}", name.replace('_', "-")))?)
}

fn fmt_j(j: Option<[f64; 9]>) -> String {
    match j {
        Some(j) => j.iter().map(|v| format!("{v:>6.2}")).collect::<Vec<_>>().join(" "),
        None => format!("{:>62}", "diverged"),
    }
}

fn table(setup: &StudySetup, rows: &[RthsRow]) -> String {
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
        substep::format::sig(setup.base.intensity, 6),
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

fn markdown(setup: &StudySetup, rows: &[RthsRow], command: &str, plots: &[PathBuf]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# RTHS benchmark results\n\nCommand: `{command}`\n");
    let _ = writeln!(
        s,
        "Controller `{}`, record `{}` × {}.\n",
        setup.kind.name(),
        setup.base.record.name,
        substep::format::sig(setup.base.intensity, 6)
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
fn histories(base: &RthsInput, cases: &[Case]) -> Result<Vec<(Case, RunHistory)>> {
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
/// substructure's grid) for comparisons sample by sample; SI units, numbers in their shortest
/// exact form.
fn traces(histories: &[(Case, RunHistory)], dir: &Path) -> Result<Vec<PathBuf>> {
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
        std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;
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
        std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;
        files.push(path);
    }
    Ok(files)
}

/// The trace CSV files gathered into `traces.h5` / `traces.mat` (one group or struct per file:
/// `trace_case1`, `floors_case1`, …; a dataset or field per column with its unit), with the
/// results as JSON (`summary`) and the `--config` text (`config`).
fn trace_container(args: &RthsArgs, format: Format, files: &[PathBuf], results: &serde_json::Value) -> Result<PathBuf> {
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
    let config = match &args.config {
        Some(path) => substep::io::limits::read_text(path, substep::io::limits::CONFIG_MAX_BYTES)?,
        None => String::new(),
    };
    let meta = Metadata {
        summary_json: serde_json::to_string_pretty(results)?,
        config,
    };
    let name = if format == Format::Hdf5 {
        "traces.h5"
    } else {
        "traces.mat"
    };
    let path = args.out.join(name);
    write_tables(&path, format, &tables, &meta)?;
    Ok(path)
}

fn plots(histories: &[(Case, RunHistory)], dir: &Path) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for (case, hist) in histories {
        let h = hist.h;
        let n = hist.desired.len();
        let c = case.number;
        let path = dir.join(format!("tracking_case{c}.png"));
        let written = line_chart(
            &path,
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
            &format!("case {c}: floor displacements vs the exact reference (3 s around the peak)"),
            "t [s]",
            "displacement [mm]",
            &curves,
        )?;
        files.push(written);
    }
    Ok(files)
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
    let setup = setup(&args)?;
    let perturbed = setup.perturbed.unwrap_or(0);
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
    for r in &rows {
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
    out(&md);
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?;
    let command = std::iter::once("substep".to_string())
        .chain(std::env::args().skip(1))
        .collect::<Vec<_>>()
        .join(" ");
    let path = args.out.join("comparison.md");
    let text = format!(
        "# RTHS benchmark: the controllers side by side\n\n`{command}`\n\nRecord {} × {}; {perturbed} perturbed plants per case (seed {}). Each controller with its one preset setting (docs/benchmark.md). J2, J4 of the nominal plant; worst J2, J4 and force over the stable perturbed runs; CPU time of the controller alone per sample (replayed on the nominal run's signals, median of 5).\n\n{md}",
        setup.base.record.name, setup.base.intensity, setup.seed
    );
    std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;
    out(&format!(
        "{} controllers × 2 noise settings × {} case(s), {} runs in {elapsed:.1} s; wrote {}\n",
        COMPARED.len(),
        setup.cases.len(),
        rows.len() * (1 + perturbed),
        path.display()
    ));
    Ok(())
}

/// Write to stdout; a closed pipe (`| head`) is not an error worth a panic.
fn out(text: &str) {
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
    let setup = setup(args)?;
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
    let no_score: Vec<u8> = rows
        .iter()
        .filter(|r| r.nominal.criteria.is_none())
        .map(|r| r.case)
        .collect();
    let verdict = || -> Result<()> {
        if no_score.is_empty() {
            return Ok(());
        }
        let cases: Vec<String> = no_score.iter().map(u8::to_string).collect();
        Err(anyhow::anyhow!(
            "benchmark rths: no score for case {}: the run diverged (see the warnings)",
            cases.join(", ")
        ))
    };
    if args.json {
        out(&format!("{}\n", serde_json::to_string_pretty(&setup.json(&rows))?));
        return verdict();
    }
    out(&table(&setup, &rows));
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?;
    if !args.no_plots {
        crate::plots::check_format(args.plot_format, "--plot-format")?;
    }
    let base = setup.base.with_k_sub(setup.k_subs.first().copied().flatten());
    let histories = histories(&base, &setup.cases)?;
    let trace_files = traces(&histories, &args.out)?;
    let container = match format {
        Format::Csv => None,
        _ => Some(trace_container(args, format, &trace_files, &setup.json(&rows))?),
    };
    let files = if args.no_plots {
        Vec::new()
    } else {
        crate::plots::set_format(args.plot_format);
        plots(&histories, &args.out)?
    };
    let command = std::iter::once("substep".to_string())
        .chain(std::env::args().skip(1))
        .collect::<Vec<_>>()
        .join(" ");
    let md = markdown(&setup, &rows, &command, &files);
    let path = args.out.join("benchmark.md");
    std::fs::write(&path, md).with_context(|| format!("cannot write {}", path.display()))?;
    out(&format!(
        "{} run(s) in {elapsed:.2} s; wrote {}, {} trace files (CSV{}){}\n",
        rows.len() * (1 + args.perturbed.unwrap_or(0)),
        path.display(),
        trace_files.len(),
        container.map_or(String::new(), |p| format!(", and {}", p.display())),
        if files.is_empty() {
            String::new()
        } else {
            format!(" and {} plots", files.len())
        }
    ));
    verdict()
}
