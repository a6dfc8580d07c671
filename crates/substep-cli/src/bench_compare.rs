//! `substep bench --compare`: per-step time of monolithic Newmark (average acceleration,
//! linear) on the same chain (default 5000 DOFs) in substep, in OpenSees (openseespy, fastest of
//! several linear-system solvers) and in a NumPy/SciPy loop around `cho_solve_banded`, measured
//! in one run, with the ratios. The Python side lives in `benches/compare/*.py`; a script that
//! cannot run (no python3, no openseespy, no scipy) is reported as skipped.

use crate::bench::BenchArgs;
use crate::bench_models::{self, BenchModel, DT, chain};
use anyhow::Result;
use serde::Serialize;
use serde_json::Value;
use std::path::PathBuf;

#[derive(Debug, Serialize)]
struct ToolResult {
    tool: String,
    /// Median µs per step, or `None` if skipped.
    us_per_step: Option<f64>,
    /// Their time over substep's monolithic step.
    ratio: Option<f64>,
    detail: Value,
}

#[derive(Debug, Serialize)]
struct Comparison {
    dofs: usize,
    steps: usize,
    dt: f64,
    story_mass: f64,
    story_stiffness: f64,
    rayleigh_alpha: f64,
    rayleigh_beta: f64,
    substep_us_per_step: f64,
    substep_solver: String,
    /// Full substructure step (k_sub sub-steps, n_c = 1) on the same chain, for reference.
    substep_substructure_us_per_step: f64,
    tools: Vec<ToolResult>,
}

fn scripts_dir() -> PathBuf {
    if let Ok(d) = std::env::var("SUBSTEP_COMPARE_DIR") {
        return PathBuf::from(d);
    }
    let local = PathBuf::from("benches/compare");
    if local.is_dir() {
        return local;
    }
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../benches/compare"))
}

pub fn compare(args: &BenchArgs) -> Result<()> {
    let n = args.compare_dofs;
    let steps = args.steps.max(100);
    let (b, alpha, beta) = chain(n)?;
    // substep: monolithic Newmark and the full substructure step on the same chain, per-step
    // medians after a warm-up (see bench_models::bench_model).
    let sub = bench_models::bench_model(BenchModel::Chain, n, steps, args.substeps)?;
    let ours = sub.us_per_step_monolithic_median;
    let solver = sub.solver.clone();

    let python = std::env::var("SUBSTEP_PYTHON").unwrap_or_else(|_| "python3".into());
    let dir = scripts_dir();
    let mut tools = Vec::new();
    for (tool, script) in [("opensees", "opensees_chain.py"), ("scipy_banded", "scipy_banded.py")] {
        let path = dir.join(script);
        let out = std::process::Command::new(&python)
            .arg(&path)
            .args([
                "--dofs",
                &n.to_string(),
                "--steps",
                &steps.to_string(),
                "--dt",
                &DT.to_string(),
            ])
            .args([
                "--mass",
                &b.story_mass.to_string(),
                "--stiffness",
                &b.story_stiffness().to_string(),
            ])
            .args(["--alpha", &alpha.to_string(), "--beta", &beta.to_string()])
            .output();
        let (us, detail) = match out {
            Err(e) => (None, Value::String(format!("skipped: cannot run {python}: {e}"))),
            Ok(o) => {
                let text = String::from_utf8_lossy(&o.stdout);
                let json = text.lines().rev().find_map(|l| serde_json::from_str::<Value>(l).ok());
                match json {
                    Some(v) if v.get("us_per_step").and_then(Value::as_f64).is_some() => (v["us_per_step"].as_f64(), v),
                    Some(v) => (None, v),
                    None => (
                        None,
                        Value::String(format!(
                            "skipped: {} exited with {} and printed no result: {}",
                            path.display(),
                            o.status,
                            String::from_utf8_lossy(&o.stderr).lines().last().unwrap_or("")
                        )),
                    ),
                }
            }
        };
        tools.push(ToolResult {
            tool: tool.into(),
            ratio: us.map(|u| u / ours),
            us_per_step: us,
            detail,
        });
    }
    let c = Comparison {
        dofs: n,
        steps,
        dt: DT,
        story_mass: b.story_mass,
        story_stiffness: b.story_stiffness(),
        rayleigh_alpha: alpha,
        rayleigh_beta: beta,
        substep_us_per_step: ours,
        substep_solver: solver,
        substep_substructure_us_per_step: sub.us_per_step_median,
        tools,
    };
    if args.json {
        println!("{}", serde_json::to_string(&c).expect("comparison serialises"));
        return Ok(());
    }
    println!(
        "substep bench --compare: {n}-DOF chain, Newmark average acceleration, Rayleigh 5 %, dt = {DT} s, {steps} steps"
    );
    println!("  substep (monolithic step, {}): {ours:.1} µs", c.substep_solver);
    println!(
        "  substep (full substructure step, k_sub = {}, n_c = 1): {:.1} µs",
        args.substeps, c.substep_substructure_us_per_step
    );
    for t in &c.tools {
        match (t.us_per_step, t.ratio) {
            (Some(us), Some(r)) => {
                let best = t.detail.get("best").and_then(Value::as_str).unwrap_or("");
                println!("  {:<13} {us:>10.1} µs per step   {r:>7.1} x substep  {best}", t.tool);
            }
            _ => println!("  {:<13} {}", t.tool, t.detail),
        }
    }
    Ok(())
}
