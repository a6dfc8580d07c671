//! `substep bench --model chain|frame --dofs N`: the cost of one full substructure step
//! (predictor solve, `k_sub` sub-steps with a spring specimen behind an ideal actuator, closing
//! the step) on a large sparse model, timed step by step (median, p99, max), with the peak
//! resident memory of the process. `--sweep` runs a list of sizes, each in its own process
//! (so that each peak RSS is its own), and reports the largest model that fits a 1 ms and a
//! 10 ms budget; `--compare` runs the 5000-DOF chain against OpenSees and a SciPy banded loop.

use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use std::time::Instant;
use substep::integrate::Scheme;
use substep::model::{DampingSpec, Frame2d, FrameDof, ShearBuilding, SparseModel, frame_2d, shear_building_sparse};
use substep::specimen::SpecimenSpec;
use substep::substructure::{ErrorForceSpec, ExperimentalSubstructure, SubstepController, SubstepSettings};
use substep::transfer::{ActuatorSpec, SensorSpec, VirtualLab};

pub const DT: f64 = 0.01;
const ZETA: f64 = 0.05;
const WARMUP_STEPS: usize = 20;

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BenchModel {
    /// Uniform shear building (tridiagonal K, diagonal M)
    Chain,
    /// 2-D steel moment frame (3 DOFs per node), twice as many stories as bays
    Frame,
}

/// The result of one model benchmark (one JSON object).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ModelBench {
    pub model: BenchModel,
    /// DOFs of the numerical model (the frame's is the nearest to `--dofs` its layout allows).
    pub dofs: usize,
    pub requested_dofs: usize,
    pub bays: Option<usize>,
    pub stories: usize,
    pub steps: usize,
    pub substeps: usize,
    pub n_c: usize,
    pub dt: f64,
    /// Stored entries of K and the half-bandwidth of K (natural DOF order).
    pub nnz_k: usize,
    pub half_bandwidth: usize,
    /// The factorisation of the effective stiffness.
    pub solver: String,
    /// Model assembly + damping + factorisation + gain columns [ms].
    pub setup_ms: f64,
    pub us_per_step_median: f64,
    pub us_per_step_p99: f64,
    pub us_per_step_max: f64,
    pub us_per_step_mean: f64,
    /// Wall time of the timed steps over their simulated duration `steps · dt`.
    pub realtime_ratio: f64,
    /// Monolithic Newmark (same model, no sub-steps), median µs per step.
    pub us_per_step_monolithic_median: f64,
    /// VmHWM of the process at the end [bytes].
    pub peak_rss_bytes: u64,
}

/// Peak resident set size (VmHWM) of this process, 0 where `/proc` is not available.
pub fn peak_rss_bytes() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1).and_then(|v| v.parse::<u64>().ok()))
        })
        .map_or(0, |kb| kb * 1024)
}

/// Quantile `q ∈ [0, 1]` of sorted samples (nearest rank).
fn quantile(sorted: &[f64], q: f64) -> f64 {
    let i = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1;
    sorted[i]
}

/// Ground acceleration at step `i`: a 1 Hz harmonic of 1 m/s².
fn ag(i: usize) -> f64 {
    (2.0 * std::f64::consts::PI * i as f64 * DT).sin()
}

/// The chain of the benchmarks and the comparison: `n` floors of 100 t, first period
/// `max(0.1 n, 0.1)` s, Rayleigh damping with 5 % at modes 1 and 2 (closed-form frequencies).
pub fn chain(n: usize) -> Result<(ShearBuilding, f64, f64)> {
    let b = ShearBuilding {
        stories: n,
        story_mass: 1.0e5,
        first_period: (0.1 * n as f64).max(0.1),
    };
    let (alpha, beta) = if n >= 2 {
        substep::model::rayleigh_coefficients(ZETA, b.omega(1), b.omega(2))?
    } else {
        (0.0, 2.0 * ZETA / b.omega(1))
    };
    Ok((b, alpha, beta))
}

/// The model and its coupling DOF (roof; for the frame the roof's left node, horizontal).
fn build(model: BenchModel, dofs: usize) -> Result<(SparseModel, usize, Option<usize>, usize)> {
    match model {
        BenchModel::Chain => {
            let (b, alpha, beta) = chain(dofs)?;
            let m = shear_building_sparse(&b)?.with_damping(&DampingSpec::Rayleigh { alpha, beta })?;
            Ok((m, dofs - 1, None, dofs))
        }
        BenchModel::Frame => {
            let f = Frame2d::with_about_dofs(dofs);
            let m = frame_2d(&f)?.with_damping(&DampingSpec::RayleighRatio {
                zeta: ZETA,
                modes: (1, 2),
            })?;
            let roof = f.dof(f.stories, 0, FrameDof::Ux).expect("roof node exists");
            Ok((m, roof, Some(f.bays), f.stories))
        }
    }
}

pub fn bench_model(model: BenchModel, dofs: usize, steps: usize, substeps: usize) -> Result<ModelBench> {
    if dofs < 3 {
        bail!(substep::Error::invalid("--dofs", "must be at least 3"));
    }
    let t_setup = Instant::now();
    let (m, roof, bays, stories) = build(model, dofs)?;
    let n = m.n_dofs();
    let coupling = vec![roof];
    let k_spec = 0.1 * m.stiffness.get(roof, roof);
    let specimens = vec![SpecimenSpec::LinearSdof {
        dof: roof,
        mass: None,
        stiffness: k_spec,
        damping: 0.0,
    }];
    let settings = SubstepSettings {
        dt: DT,
        beta: 0.25,
        gamma: 0.5,
        substeps,
        coupling_dofs: coupling.clone(),
        error_force: ErrorForceSpec::None,
    };
    let mi = m.effective_mass_vector();
    let mut load = -&mi * ag(0);
    let mut ctrl = SubstepController::new(&m, &settings, &load)?;
    let setup_ms = t_setup.elapsed().as_secs_f64() * 1e3;
    let dtau = DT / substeps as f64;
    let mut lab = VirtualLab::from_specs(
        &coupling,
        &specimens,
        &[ActuatorSpec::ideal()],
        &[SensorSpec::ideal()],
        &[SensorSpec::ideal()],
        dtau,
        1,
    )?;
    let (mut force, mut disp) = ([0.0], [0.0]);
    let mut samples = Vec::with_capacity(steps);
    let mut timed_wall = 0.0;
    for i in 0..WARMUP_STEPS + steps {
        let (a0, a1) = (ag(i), ag(i + 1));
        let t0 = Instant::now();
        load.copy_from(&mi);
        load.scale_mut(-a1);
        ctrl.begin_step(&load);
        for j in 1..=substeps {
            let command = ctrl.next_command();
            lab.substep(
                command,
                substep::substructure::substep_ground_acceleration(a0, a1, j, substeps),
                dtau,
                &mut force,
                &mut disp,
            )?;
            ctrl.feedback(&force);
        }
        ctrl.finish_step();
        let us = t0.elapsed().as_secs_f64() * 1e6;
        if i >= WARMUP_STEPS {
            samples.push(us);
            timed_wall += us * 1e-6;
        }
    }
    if !ctrl.state().is_finite() {
        bail!("the substructure benchmark diverged");
    }
    let solver = substep::integrate::NewmarkCore::new(&m, DT, 0.25, 0.5)?.solver();
    // Monolithic Newmark on the same model (shorter run; the comparison uses it).
    let mono_steps = steps.clamp(10, 2000);
    let mut integ = Scheme::Newmark { beta: 0.25, gamma: 0.5 }.build(&m, DT, &(-&mi * ag(0)))?;
    let mut mono = Vec::with_capacity(mono_steps);
    for i in 0..WARMUP_STEPS + mono_steps {
        let t0 = Instant::now();
        load.copy_from(&mi);
        load.scale_mut(-ag(i + 1));
        integ.step(&load);
        if i >= WARMUP_STEPS {
            mono.push(t0.elapsed().as_secs_f64() * 1e6);
        }
    }
    mono.sort_by(f64::total_cmp);
    let mean = samples.iter().sum::<f64>() / samples.len() as f64;
    samples.sort_by(f64::total_cmp);
    Ok(ModelBench {
        model,
        dofs: n,
        requested_dofs: dofs,
        bays,
        stories,
        steps,
        substeps,
        n_c: 1,
        dt: DT,
        nnz_k: m.stiffness.nnz(),
        half_bandwidth: m.stiffness.half_bandwidth(),
        solver,
        setup_ms,
        us_per_step_median: quantile(&samples, 0.5),
        us_per_step_p99: quantile(&samples, 0.99),
        us_per_step_max: *samples.last().expect("at least one step"),
        us_per_step_mean: mean,
        realtime_ratio: timed_wall / (steps as f64 * DT),
        us_per_step_monolithic_median: quantile(&mono, 0.5),
        peak_rss_bytes: peak_rss_bytes(),
    })
}

pub fn print_model_bench(r: &ModelBench) {
    println!(
        "substep bench: {:?} model, {} DOFs{}, k_sub = {}, n_c = 1 (spring specimen, ideal actuator), dt = {} s",
        r.model,
        r.dofs,
        r.bays
            .map_or(String::new(), |b| format!(" ({b} bays x {} stories)", r.stories)),
        r.substeps,
        r.dt
    );
    println!(
        "  K: {} stored entries, half-bandwidth {}; solver: {}",
        r.nnz_k, r.half_bandwidth, r.solver
    );
    println!(
        "  setup (assembly, damping, factorisation, gain columns): {:.1} ms",
        r.setup_ms
    );
    println!(
        "  full step over {} steps: median {:.1} µs, p99 {:.1} µs, max {:.1} µs; {:.4} x real time",
        r.steps, r.us_per_step_median, r.us_per_step_p99, r.us_per_step_max, r.realtime_ratio
    );
    println!(
        "  monolithic Newmark step: median {:.1} µs",
        r.us_per_step_monolithic_median
    );
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
pub fn sweep(model: BenchModel, sizes: &[usize], steps: usize, substeps: usize) -> Result<Sweep> {
    let exe = std::env::current_exe().context("cannot find the substep executable for --sweep")?;
    let mut runs = Vec::new();
    for &n in sizes {
        let name = match model {
            BenchModel::Chain => "chain",
            BenchModel::Frame => "frame",
        };
        let out = std::process::Command::new(&exe)
            .args(["bench", "--model", name, "--dofs", &n.to_string()])
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
        "substep bench --sweep: {:?} model, k_sub = {}, {} steps per size, each size in its own process",
        s.model, s.substeps, s.steps
    );
    println!(
        "  {:>7} {:>10} {:>10} {:>10} {:>10} {:>9}  solver",
        "DOFs", "median µs", "p99 µs", "max µs", "mono µs", "RSS MiB"
    );
    for r in &s.runs {
        println!(
            "  {:>7} {:>10.1} {:>10.1} {:>10.1} {:>10.1} {:>9.1}  {}",
            r.dofs,
            r.us_per_step_median,
            r.us_per_step_p99,
            r.us_per_step_max,
            r.us_per_step_monolithic_median,
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
