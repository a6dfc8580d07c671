//! `substep bench`: µs per step of Newmark (average acceleration) on uniform shear buildings with
//! 5 % modal damping, and of the sub-step algorithm (full step and one sub-step) with spring
//! specimens on 1 and 4 coupling DOFs behind ideal actuators. Each figure is the median over
//! the repetitions.
//!
//! With `--model chain|frame --dofs N`, the large-model benchmark of `bench_models.rs` (sparse
//! storage, per-step median/p99, peak RSS); `--sweep` runs it over sizes 10²…10⁵; `--compare`
//! times the 5000-DOF chain against OpenSees and SciPy (`bench_compare.rs`).

use anyhow::Result;
use substep::bench::{STEP_BENCH_DT as DT, STEP_BENCH_ZETA as ZETA};

use crate::bench_models::{self, BenchModel};

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
    let result = substep::bench::bench_steps(&substep::bench::StepBenchOptions {
        stories: args.stories.clone(),
        steps: args.steps,
        repeats: args.repeats,
        substeps: args.substeps,
    })?;
    let largest = result.substructure.stories;
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
