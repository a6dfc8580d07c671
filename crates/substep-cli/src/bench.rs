//! `substep bench`: µs per step of Newmark (average acceleration) on uniform shear buildings with
//! 5 % modal damping, and of the sub-step algorithm (full step and one sub-step) with spring
//! specimens on 1 and 4 coupling DOFs behind ideal actuators. Each figure is the median over
//! the repetitions.
//!
//! With `--model chain|frame --dofs N`, the large-model benchmark of `bench_models.rs` (sparse
//! storage, per-step median/p99, peak RSS); `--sweep` runs it over sizes 10²…10⁵; `--compare`
//! times the 5000-DOF chain against OpenSees and SciPy (`bench_compare.rs`).

use anyhow::{Result, bail};
use nalgebra::DVector;
use serde::Serialize;
use std::time::{Duration, Instant};
use substep::integrate::Scheme;
use substep::model::{DampingSpec, ShearBuilding, StructuralModel, shear_building};
use substep::specimen::SpecimenSpec;
use substep::substructure::{ErrorForceSpec, ExperimentalSubstructure, SubstepController, SubstepSettings};
use substep::transfer::{ActuatorSpec, SensorSpec, VirtualLab};

use crate::bench_models::{self, BenchModel};

const DT: f64 = 0.01;
const ZETA: f64 = 0.05;

#[derive(Debug, Clone, clap::Args)]
pub struct BenchArgs {
    /// Stories of the shear buildings (repeat the option or give a list: 100,1000); the
    /// substructure benchmark uses the largest
    #[arg(long, value_delimiter = ',', num_args = 1.., default_values_t = [100, 1000])]
    pub stories: Vec<usize>,
    /// Steps per repetition
    #[arg(long, default_value_t = 200)]
    pub steps: usize,
    /// Repetitions (the median is reported; at least 5)
    #[arg(long, default_value_t = 5)]
    pub repeats: usize,
    /// Print one JSON object instead of the table
    #[arg(long)]
    pub json: bool,
    /// Large-model benchmark on a sparse model: chain (shear building), frame (2-D) or frame3d
    #[arg(long, value_parser = bench_models::parse_model)]
    pub model: Option<BenchModel>,
    /// Sweep the sparse factor on two cores (a worker thread takes half of the elimination tree)
    #[arg(long)]
    pub two_cores: bool,
    /// With --model chain: yielding storeys; with --model frame: hinges at every member end (both
    /// bilinear, docs/theory.md §14): the full step with the operator splitting, and Newmark +
    /// Newton as the monolithic step
    #[arg(long, requires = "model")]
    pub yielding: bool,
    /// DOFs of the --model benchmark (the frame takes the nearest size its layout allows)
    #[arg(long)]
    pub dofs: Option<usize>,
    /// Sub-steps per step k_sub
    #[arg(long, default_value_t = 10)]
    pub substeps: usize,
    /// With --model: run 100 … 100 000 DOFs (or the --dofs list), each in its own process, and
    /// report the largest model within 1 ms and 10 ms per step
    #[arg(long, requires = "model")]
    pub sweep: bool,
    /// Sizes for --sweep (comma-separated)
    #[arg(long, value_delimiter = ',', requires = "sweep")]
    pub sizes: Option<Vec<usize>>,
    /// Time monolithic Newmark on one model against OpenSees (chain), SciPy splu (COLAMD, MMD)
    /// and CHOLMOD on the exported matrices, after checking that they compute the same
    /// response (benches/compare/*.py; tools that are missing are skipped)
    #[arg(long, conflicts_with = "model")]
    pub compare: bool,
    /// Model of --compare: chain, frame or frame3d
    #[arg(long, default_value = "chain", value_parser = bench_models::parse_model, requires = "compare")]
    pub compare_model: BenchModel,
    /// DOFs of the --compare model
    #[arg(long, default_value_t = 5000, requires = "compare")]
    pub compare_dofs: usize,
    /// Timing rounds of --compare, interleaved over the tools (the median is reported)
    #[arg(long, default_value_t = 3, requires = "compare")]
    pub rounds: usize,
}

#[derive(Debug, Serialize)]
struct MonolithicResult {
    stories: usize,
    us_per_step: f64,
}

#[derive(Debug, Serialize)]
struct SubstructureCase {
    n_c: usize,
    us_per_step: f64,
    us_per_substep: f64,
}

#[derive(Debug, Serialize)]
struct SubstructureResult {
    stories: usize,
    substeps: usize,
    cases: Vec<SubstructureCase>,
}

#[derive(Debug, Serialize)]
struct BenchResult {
    scheme: &'static str,
    dt: f64,
    steps: usize,
    repeats: usize,
    monolithic: Vec<MonolithicResult>,
    substructure: SubstructureResult,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

fn building(stories: usize) -> Result<StructuralModel> {
    let b = ShearBuilding {
        stories,
        story_mass: 1.0e5,
        first_period: (0.1 * stories as f64).max(0.1),
    };
    Ok(shear_building(&b)?.with_damping(&DampingSpec::Modal { zeta: vec![ZETA] })?)
}

/// Ground acceleration at step `i`: a 1 Hz harmonic of 1 m/s².
fn ag(i: usize) -> f64 {
    (2.0 * std::f64::consts::PI * i as f64 * DT).sin()
}

fn bench_monolithic(model: &StructuralModel, steps: usize, repeats: usize) -> Result<f64> {
    let mi = model.effective_mass_vector();
    let mut load = DVector::zeros(model.n_dofs());
    let mut integ = Scheme::Newmark { beta: 0.25, gamma: 0.5 }.build(model, DT, &(-&mi * ag(0)))?;
    let mut i = 0;
    let mut samples = Vec::with_capacity(repeats);
    for _ in 0..repeats {
        let t0 = Instant::now();
        for _ in 0..steps {
            i += 1;
            load.copy_from(&mi);
            load.scale_mut(-ag(i));
            integ.step(&load);
        }
        samples.push(t0.elapsed().as_secs_f64() * 1e6 / steps as f64);
    }
    if !integ.state().is_finite() {
        bail!("the monolithic benchmark diverged");
    }
    Ok(median(samples))
}

/// `(µs per full step, µs per sub-step)` with `n_c` spring specimens on the top floors.
fn bench_substructure(
    model: &StructuralModel,
    n_c: usize,
    substeps: usize,
    steps: usize,
    repeats: usize,
) -> Result<(f64, f64)> {
    let n = model.n_dofs();
    let coupling: Vec<usize> = (0..n_c).map(|k| n - 1 - k).collect();
    let k_story = model.stiffness[(n - 1, n - 1)];
    let specimens: Vec<SpecimenSpec> = coupling
        .iter()
        .map(|&dof| SpecimenSpec::LinearSdof {
            dof,
            mass: None,
            stiffness: 0.1 * k_story,
            damping: 0.0,
        })
        .collect();
    let settings = SubstepSettings {
        dt: DT,
        beta: 0.25,
        gamma: 0.5,
        substeps,
        coupling_dofs: coupling.clone(),
        error_force: ErrorForceSpec::None,
    };
    let mi = model.effective_mass_vector();
    let mut load = -&mi * ag(0);
    let mut ctrl = SubstepController::new(model, &settings, &load)?;
    let dtau = DT / substeps as f64;
    let mut lab = VirtualLab::from_specs(
        &coupling,
        &specimens,
        &vec![ActuatorSpec::ideal(); n_c],
        &vec![SensorSpec::ideal(); n_c],
        &vec![SensorSpec::ideal(); n_c],
        dtau,
        1,
    )?;
    let (mut force, mut disp) = (vec![0.0; n_c], vec![0.0; n_c]);
    let mut i = 0;
    let (mut per_step, mut per_substep) = (Vec::new(), Vec::new());
    for _ in 0..repeats {
        let (mut total, mut inner) = (Duration::ZERO, Duration::ZERO);
        for _ in 0..steps {
            let (a0, a1) = (ag(i), ag(i + 1));
            i += 1;
            let t0 = Instant::now();
            load.copy_from(&mi);
            load.scale_mut(-a1);
            ctrl.begin_step(&load);
            let t1 = Instant::now();
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
            inner += t1.elapsed();
            ctrl.finish_step();
            total += t0.elapsed();
        }
        per_step.push(total.as_secs_f64() * 1e6 / steps as f64);
        per_substep.push(inner.as_secs_f64() * 1e6 / (steps * substeps) as f64);
    }
    if !ctrl.state().is_finite() {
        bail!("the substructure benchmark diverged");
    }
    Ok((median(per_step), median(per_substep)))
}

pub fn bench(args: &BenchArgs) -> Result<()> {
    if args.substeps == 0 {
        return Err(substep::Error::invalid("--substeps", "must be at least 1").into());
    }
    if args.steps == 0 {
        return Err(substep::Error::invalid("--steps", "must be at least 1").into());
    }
    if args.compare {
        return crate::bench_compare::compare(args);
    }
    if let Some(model) = args.model {
        if args.sweep {
            let sizes = args.sizes.clone().unwrap_or_else(|| bench_models::SWEEP_DOFS.to_vec());
            let s = bench_models::sweep(model, &sizes, args.steps, args.substeps, args.two_cores)?;
            if args.json {
                println!("{}", serde_json::to_string(&s).expect("sweep serialises"));
            } else {
                bench_models::print_sweep(&s);
            }
            return Ok(());
        }
        let dofs = args
            .dofs
            .ok_or_else(|| substep::Error::invalid("--dofs", "is required with --model (or use --sweep)"))?;
        let r = bench_models::bench_model(&bench_models::ModelBenchOptions {
            model,
            dofs,
            steps: args.steps,
            substeps: args.substeps,
            second_core: args.two_cores,
            yielding: args.yielding,
        })?;
        if args.json {
            println!("{}", serde_json::to_string(&r).expect("bench result serialises"));
        } else {
            bench_models::print_model_bench(&r);
        }
        return Ok(());
    }
    if args.dofs.is_some() {
        return Err(substep::Error::invalid("--dofs", "needs --model chain|frame").into());
    }
    if args.stories.contains(&0) {
        return Err(substep::Error::invalid("--stories", "must be at least 1").into());
    }
    if args.steps == 0 {
        return Err(substep::Error::invalid("--steps", "must be at least 1").into());
    }
    if args.repeats < 5 {
        return Err(substep::Error::invalid("--repeats", format!("must be at least 5, got {}", args.repeats)).into());
    }
    let mut stories = args.stories.clone();
    stories.sort_unstable();
    stories.dedup();
    let largest = *stories.last().expect("default list is not empty");

    let mut monolithic = Vec::new();
    let mut largest_model = None;
    for &n in &stories {
        let model = building(n)?;
        let us = bench_monolithic(&model, args.steps, args.repeats)?;
        monolithic.push(MonolithicResult {
            stories: n,
            us_per_step: us,
        });
        if n == largest {
            largest_model = Some(model);
        }
    }
    let model = largest_model.expect("largest model was built");
    let mut cases = Vec::new();
    for n_c in [1, 4] {
        if n_c <= largest {
            let (step, sub) = bench_substructure(&model, n_c, args.substeps, args.steps, args.repeats)?;
            cases.push(SubstructureCase {
                n_c,
                us_per_step: step,
                us_per_substep: sub,
            });
        }
    }
    let result = BenchResult {
        scheme: "newmark average acceleration (beta = 1/4, gamma = 1/2)",
        dt: DT,
        steps: args.steps,
        repeats: args.repeats,
        monolithic,
        substructure: SubstructureResult {
            stories: largest,
            substeps: args.substeps,
            cases,
        },
    };
    if args.json {
        println!("{}", serde_json::to_string(&result).expect("bench result serialises"));
        return Ok(());
    }
    println!(
        "substep bench: Newmark average acceleration, uniform shear building, {} % modal damping, dt = {DT} s",
        100.0 * ZETA
    );
    println!("  median over {} repetitions of {} steps", args.repeats, args.steps);
    println!("  monolithic");
    println!("    {:>8}  {:>12}", "stories", "µs/step");
    for m in &result.monolithic {
        println!("    {:>8}  {:>12.2}", m.stories, m.us_per_step);
    }
    println!(
        "  substructure: {} stories, k_sub = {}, spring specimens on the top floors, ideal actuators",
        largest, args.substeps
    );
    println!("    {:>8}  {:>12}  {:>14}", "n_c", "µs/step", "µs/sub-step");
    for c in &result.substructure.cases {
        println!("    {:>8}  {:>12.2}  {:>14.3}", c.n_c, c.us_per_step, c.us_per_substep);
    }
    Ok(())
}
