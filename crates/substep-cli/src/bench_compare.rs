//! `substep bench --compare`: the comparison of [`substep::bench::compare`] (monolithic Newmark
//! in substep and in other tools on one model, agreement first, then interleaved timing rounds),
//! printed as a table or as JSON.

use crate::bench::BenchArgs;
use anyhow::Result;
use substep::bench::{BATCHES, CompareOptions, DT};

pub fn compare(args: &BenchArgs) -> Result<()> {
    let options = CompareOptions {
        model: args.compare_model,
        dofs: args.compare_dofs,
        steps: args.steps,
        rounds: args.rounds,
        substeps: args.substeps,
        two_cores: args.two_cores,
    };
    let json = args.json;
    let c = substep::bench::compare(&options, &mut |line| {
        if !json {
            eprintln!("{line}");
        }
    })?;
    let (n, batch_steps, ours) = (c.dofs, c.batch_steps, c.substep_cpu_us_per_step);
    if args.json {
        println!("{}", serde_json::to_string(&c).expect("comparison serialises"));
        return Ok(());
    }
    println!(
        "substep bench --compare: {} model, {n} DOFs ({}), Newmark average acceleration, Rayleigh 5 %, dt = {DT} s",
        c.model, c.layout
    );
    println!(
        "  CPU µs per step, median (min-max) over {} rounds of {BATCHES} batches of {batch_steps} steps, interleaved",
        args.rounds
    );
    println!(
        "  {:<34} {:>10.1} ({:.1}-{:.1})",
        format!(
            "substep monolithic{}",
            if c.substep_second_core { ", two cores" } else { "" }
        ),
        ours.median,
        ours.min,
        ours.max
    );
    println!(
        "  {:<34} {:>10.1} (p99 wall {:.1})   solver: {}",
        format!("substep substructure step, k_sub = {}", args.substeps),
        c.substep_substructure_cpu_us_per_step,
        c.substep_substructure_p99_us,
        c.substep_solver
    );
    for t in &c.tools {
        match (&t.cpu_us_per_step, t.ratio_to_monolithic, t.ratio_to_substructure_step) {
            (Some(s), Some(r), Some(rs)) => println!(
                "  {:<34} {:>10.1} ({:.1}-{:.1})   {r:.2} x substep monolithic, {rs:.2} x substep substructure step",
                t.tool, s.median, s.min, s.max
            ),
            _ => println!(
                "  {:<34} {}",
                t.tool,
                t.reason.clone().unwrap_or_else(|| t.status.clone())
            ),
        }
    }
    Ok(())
}
