//! `substep bench --model chain|frame --dofs N`: the cost of one full substructure step
//! (predictor solve, `k_sub` sub-steps with a spring specimen behind an ideal actuator, closing
//! the step) on a large sparse model, timed step by step (median, p99, max), with the peak
//! resident memory of the process. `--sweep` runs a list of sizes, each in its own process
//! (so that each peak RSS is its own), and reports the largest model that fits a 1 ms and a
//! 10 ms budget; `--compare` runs the 5000-DOF chain against OpenSees and a SciPy banded loop.

use anyhow::{Context, Result, bail};
use serde::Serialize;
pub use substep::bench::{BenchModel, ModelBench, ModelBenchOptions, bench_model};

/// `--model NAME` (clap value parser).
pub fn parse_model(s: &str) -> std::result::Result<BenchModel, String> {
    BenchModel::from_name(s).map_err(|e| e.to_string())
}

pub fn print_model_bench(r: &ModelBench) {
    println!(
        "substep bench: {} model, {} DOFs ({}), k_sub = {}, n_c = 1 (spring specimen, ideal actuator), dt = {} s",
        r.model.name(),
        r.dofs,
        r.layout,
        r.substeps,
        r.dt
    );
    println!(
        "  K: {} stored entries, half-bandwidth {}; solver: {}{}",
        r.nnz_k,
        r.half_bandwidth,
        r.solver,
        if r.second_core { ", two cores" } else { "" }
    );
    println!("  one solve reads {:.1} MB of the factor", r.solve_bytes as f64 / 1e6);
    println!(
        "  setup (assembly, damping, factorisation, gain columns): {:.1} ms",
        r.setup_ms
    );
    println!(
        "  full step over {} steps: median {:.1} µs, p99 {:.1} µs, max {:.1} µs (CPU median {:.1} µs); {:.4} x real time",
        r.steps, r.us_per_step_median, r.us_per_step_p99, r.us_per_step_max, r.cpu_us_per_step_median, r.realtime_ratio
    );
    if r.yielding {
        println!(
            "  hysteretic springs (operator splitting in the full step): {} past their yield point at the end",
            r.springs_yielded
        );
        println!(
            "  monolithic Newmark + Newton step: median {:.1} µs ({:.2} iterations per step)",
            r.us_per_step_monolithic_median, r.newton_iterations_per_step
        );
    } else {
        println!(
            "  monolithic Newmark step: median {:.1} µs",
            r.us_per_step_monolithic_median
        );
    }
    println!("  peak RSS: {:.1} MiB", r.peak_rss_bytes as f64 / (1024.0 * 1024.0));
}

/// Sizes of `--sweep`.
pub const SWEEP_DOFS: [usize; 7] = [100, 300, 1_000, 3_000, 10_000, 30_000, 100_000];

#[derive(Debug, Serialize)]
pub struct Sweep {
    pub model: BenchModel,
    pub substeps: usize,
    pub steps: usize,
    pub runs: Vec<ModelBench>,
    /// The largest measured model whose p99 full-step time fits 1 ms / 10 ms.
    pub largest_dofs_within_1ms: Option<usize>,
    pub largest_dofs_within_10ms: Option<usize>,
    /// The same by the median (what a quiet machine gives; the p99 suffers from other load).
    pub largest_dofs_within_1ms_median: Option<usize>,
    pub largest_dofs_within_10ms_median: Option<usize>,
}

/// Each size in a child process `substep bench --model M --dofs N ... --json`.
pub fn sweep(model: BenchModel, sizes: &[usize], steps: usize, substeps: usize, two_cores: bool) -> Result<Sweep> {
    let exe = std::env::current_exe().context("cannot find the substep executable for --sweep")?;
    let mut runs = Vec::new();
    for &n in sizes {
        let mut cmd = std::process::Command::new(&exe);
        cmd.args(["bench", "--model", model.name(), "--dofs", &n.to_string()]);
        if two_cores {
            cmd.arg("--two-cores");
        }
        let out = cmd
            .args([
                "--steps",
                &steps.to_string(),
                "--substeps",
                &substeps.to_string(),
                "--json",
            ])
            .output()
            .with_context(|| format!("cannot run {}", exe.display()))?;
        if !out.status.success() {
            bail!(
                "bench of {n} DOFs failed: {}",
                String::from_utf8_lossy(&out.stderr).trim()
            );
        }
        let r: ModelBench = serde_json::from_slice(&out.stdout).context("child bench printed no JSON")?;
        eprintln!(
            "  {:>7} DOFs: median {:>9.1} µs, p99 {:>9.1} µs, {:>7.1} MiB",
            r.dofs,
            r.us_per_step_median,
            r.us_per_step_p99,
            r.peak_rss_bytes as f64 / 1048576.0
        );
        runs.push(r);
    }
    let within = |budget_us: f64, median: bool| {
        runs.iter()
            .filter(|r| if median { r.us_per_step_median } else { r.us_per_step_p99 } <= budget_us)
            .map(|r| r.dofs)
            .max()
    };
    Ok(Sweep {
        model,
        substeps,
        steps,
        largest_dofs_within_1ms: within(1000.0, false),
        largest_dofs_within_10ms: within(10_000.0, false),
        largest_dofs_within_1ms_median: within(1000.0, true),
        largest_dofs_within_10ms_median: within(10_000.0, true),
        runs,
    })
}

pub fn print_sweep(s: &Sweep) {
    println!(
        "substep bench --sweep: {} model, k_sub = {}, {} steps per size, each size in its own process",
        s.model.name(),
        s.substeps,
        s.steps
    );
    println!(
        "  {:>7} {:>10} {:>10} {:>10} {:>10} {:>10} {:>9}  solver",
        "DOFs", "median µs", "p99 µs", "max µs", "mono µs", "floor µs", "RSS MiB"
    );
    for r in &s.runs {
        println!(
            "  {:>7} {:>10.1} {:>10.1} {:>10.1} {:>10.1} {:>10.1} {:>9.1}  {}",
            r.dofs,
            r.us_per_step_median,
            r.us_per_step_p99,
            r.us_per_step_max,
            r.us_per_step_monolithic_median,
            r.solve_floor_us,
            r.peak_rss_bytes as f64 / 1048576.0,
            r.solver
        );
    }
    let show = |v: Option<usize>| v.map_or("none measured".to_string(), |n| n.to_string());
    println!(
        "  largest N with p99 within 1 ms: {}; within 10 ms: {} (by the median: {}; {})",
        show(s.largest_dofs_within_1ms),
        show(s.largest_dofs_within_10ms),
        show(s.largest_dofs_within_1ms_median),
        show(s.largest_dofs_within_10ms_median)
    );
}
