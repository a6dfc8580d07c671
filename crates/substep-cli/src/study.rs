//! `substep study STUDY.toml`: every run of a parameter study (substep::study) on all cores,
//! with a progress bar; writes `study.csv` (one row per run) and one figure per metric with a
//! panel per varied parameter (`study_<metric>.png`).

use crate::plots::{Curve, Figure, Panel};
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::path::{Path, PathBuf};
use std::time::Instant;
use substep::output::files::write_atomic;
use substep::study::{Row, Study, summary_runner, to_csv};

#[derive(Debug, Clone, clap::Args)]
pub struct StudyArgs {
    /// Study file (TOML: base, [grid], [samples], seeds, metrics; see docs/config.md)
    pub study: PathBuf,
    /// Output directory
    #[arg(long, value_name = "DIR", default_value = "study")]
    pub out: PathBuf,
    /// Threads (0: all cores; at most 256)
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// No progress bar and no summary on stdout
    #[arg(long, short)]
    pub quiet: bool,
    /// Do not draw figures
    #[arg(long)]
    pub no_plots: bool,
    /// Figure format: png, svg or pdf (vector, for papers)
    #[arg(long, value_enum, value_name = "FORMAT", default_value = "png")]
    pub plot_format: crate::plots::PlotFormat,
}

pub fn study(args: &StudyArgs) -> Result<()> {
    let study = Study::from_file(&args.study)?;
    std::fs::create_dir_all(&args.out)
        .map_err(|e| substep::Error::file(args.out.display().to_string(), format!("cannot create: {e}")))?;
    let n = study.len();
    let bar = if args.quiet {
        ProgressBar::hidden()
    } else {
        let b = ProgressBar::with_draw_target(Some(n as u64), ProgressDrawTarget::stderr());
        b.set_style(
            ProgressStyle::with_template("{spinner} {elapsed_precise} [{wide_bar}] {pos}/{len} runs, ETA {eta}")
                .expect("valid template")
                .progress_chars("=> "),
        );
        b
    };
    if !args.quiet {
        println!(
            "substep study {}: {n} runs of {} parameter(s) ({}), metrics {}",
            args.study.display(),
            study.parameters().len(),
            study.parameters().join(", "),
            study.metrics().iter().map(|m| m.name()).collect::<Vec<_>>().join(", ")
        );
    }
    let started = Instant::now();
    let rows = study.run_all(args.threads, &summary_runner, &|| bar.inc(1))?;
    bar.finish_and_clear();
    let wall = started.elapsed().as_secs_f64();
    let csv_path = args.out.join("study.csv");
    write_atomic(&csv_path, to_csv(&study, &rows).as_bytes())
        .with_context(|| format!("cannot write {}", csv_path.display()))?;
    let mut outputs = vec![csv_path];
    if !args.no_plots {
        crate::plots::check_format(args.plot_format, "--plot-format")?;
        crate::plots::set_format(args.plot_format);
        outputs.extend(figures(&study, &rows, &args.out)?);
    }
    let failed: Vec<&Row> = rows.iter().filter(|r| !r.completed).collect();
    if !args.quiet {
        println!(
            "  {n} runs in {wall:.2} s ({:.1} ms per run)",
            wall * 1e3 / n.max(1) as f64
        );
        if !failed.is_empty() {
            println!("  {} of {n} runs did not complete (column `error`), e.g.", failed.len());
            for r in failed.iter().take(3) {
                println!("    {}", r.error);
            }
        }
        let names: Vec<String> = outputs
            .iter()
            .filter_map(|p| p.file_name().map(|f| f.to_string_lossy().into_owned()))
            .collect();
        println!("  outputs in {}: {}", args.out.display(), names.join(", "));
    }
    // A study whose runs failed is not a success (exit 1), though study.csv has every row.
    if !failed.is_empty() {
        anyhow::bail!(
            "{} of {n} runs did not complete (study.csv, column `error`; the first: {})",
            failed.len(),
            failed[0].error
        );
    }
    Ok(())
}

/// `name [unit]`, or the name alone when the unit is not known.
fn with_unit(name: &str, unit: &str) -> String {
    if unit.is_empty() {
        name.to_string()
    } else {
        format!("{name} [{unit}]")
    }
}

/// The SI unit of a config key a study varies, from its last component (docs/config.md).
fn parameter_unit(key: &str) -> &'static str {
    let last = key.rsplit('.').next().unwrap_or(key);
    match last {
        "delay" | "dt" | "time_constant" | "duration" | "lead" | "noise_sample_time" => "s",
        "stiffness" | "k_e" => "N/m",
        "damping" | "c_e" => "N·s/m",
        "mass" | "m_e" => "kg",
        "frequency" | "f0" | "f1" | "valve_frequency" => "Hz",
        "amplitude" | "pga" => "m/s²",
        "force_noise" | "slip_force" => "N",
        "displacement_noise" | "yield_displacement" => "m",
        "zeta" | "scale" | "forgetting_factor" | "alpha" | "valve_damping" => "–",
        "substeps" | "inner_steps" | "seed" | "n_u" | "k_lag" | "span" | "order" | "taps" => "–",
        _ => "",
    }
}

/// One figure per metric, a panel per numeric parameter: every completed run as a point.
fn figures(study: &Study, rows: &[Row], dir: &Path) -> Result<Vec<PathBuf>> {
    let params = study.parameters();
    let mut out = Vec::new();
    for (m, metric) in study.metrics().iter().enumerate() {
        let mut fig = Figure::new(&format!("{} over {} runs", metric.name(), rows.len()));
        let mut panels = 0;
        for (p, name) in params.iter().enumerate() {
            // A NaN between points: each point is its own run, drawn as a marker (no lines).
            let (mut x, mut y) = (Vec::new(), Vec::new());
            let mut counts = true;
            for r in rows.iter().filter(|r| r.completed) {
                let xv = match r.values.get(p) {
                    Some(toml::Value::Float(f)) => {
                        counts = false;
                        *f
                    }
                    Some(toml::Value::Integer(i)) => *i as f64,
                    _ => continue,
                };
                x.extend([xv, f64::NAN]);
                y.extend([r.metrics[m], f64::NAN]);
            }
            if x.iter().all(|v| v.is_nan()) || y.iter().all(|v| v.is_nan()) {
                continue;
            }
            fig = fig.panel(
                Panel::new(
                    &with_unit(name, parameter_unit(name)),
                    &with_unit(metric.name(), metric.unit()),
                )
                .curves(vec![Curve {
                    label: String::new(),
                    x,
                    y,
                }])
                .integer_axis_x(counts),
            );
            panels += 1;
        }
        if panels == 0 {
            continue;
        }
        let file = format!("study_{}", metric.name().replace('.', "_"));
        out.push(crate::plots::figure(&dir.join(file), &fig.columns(panels.min(2)))?);
    }
    Ok(out)
}
