//! `substep bench --compare`: monolithic Newmark (average acceleration, linear) on one model
//! in substep and in other tools, measured in one run with one statistic. The model (chain,
//! 2-D or 3-D frame; `--compare-model`) is exported as MatrixMarket files for the tools that
//! read matrices (SciPy `splu` with COLAMD and with MMD, CHOLMOD); OpenSees builds the chain
//! itself from its parameters. Every tool first runs `CHECK_STEPS` steps and reports the roof
//! displacement after each: a tool whose response differs from substep's (relative
//! `AGREEMENT_TOLERANCE`) is refused and not timed. Then `--rounds` rounds, interleaved over the
//! tools, each of `BATCHES` batches of `--steps / BATCHES` steps timed in CPU time: per round the
//! median over its batches, per tool the median (and min–max) over the rounds. The scripts live
//! in `benches/compare/*.py`; a script that cannot run is reported as skipped.

use super::compare::{check_agreement, max_rel_difference};
use super::models::{BenchModel, DT, ModelBenchOptions, bench_model, build, chain, monolithic_run};
use super::stats::{Spread, median};
use crate::{Error, Result};
use serde::Serialize;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// Steps of the agreement check.
pub const CHECK_STEPS: usize = 50;
/// Relative difference of the roof response above which a tool computes a different model.
pub const AGREEMENT_TOLERANCE: f64 = 1e-9;
/// Timed batches per round.
pub const BATCHES: usize = 5;

#[derive(Debug, Serialize)]
pub struct ToolResult {
    pub tool: String,
    /// `agreed`, `refused` or `skipped`.
    pub status: String,
    /// Why refused or skipped.
    pub reason: Option<String>,
    /// Relative difference of the roof response from substep's over the check steps.
    pub agreement: Option<f64>,
    /// CPU µs per step: median, min, max over the rounds.
    pub cpu_us_per_step: Option<Spread>,
    /// Their median over substep's monolithic median, and over substep's full substructure step.
    pub ratio_to_monolithic: Option<f64>,
    pub ratio_to_substructure_step: Option<f64>,
    pub detail: Value,
}

#[derive(Debug, Serialize)]
pub struct Comparison {
    pub model: String,
    pub dofs: usize,
    pub layout: String,
    pub dt: f64,
    pub rayleigh_alpha: f64,
    pub rayleigh_beta: f64,
    pub check_steps: usize,
    pub rounds: usize,
    pub batches: usize,
    pub batch_steps: usize,
    pub substep_solver: String,
    pub substep_second_core: bool,
    pub substep_solve_bytes: usize,
    /// substep monolithic step, CPU µs: median, min, max over the rounds.
    pub substep_cpu_us_per_step: Spread,
    /// Full substructure step (k_sub sub-steps, n_c = 1) on the same model: median CPU µs and
    /// wall p99 µs over `--steps` steps.
    pub substep_substructure_cpu_us_per_step: f64,
    pub substep_substructure_p99_us: f64,
    pub tools: Vec<ToolResult>,
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

/// The Pythons to try for a peer: `SUBSTEP_PYTHON` alone when set; else the project's `.venv`
/// (see docs/performance.md) when there is one, then `python3` — so a peer whose packages are
/// installed system-wide (SciPy from Debian, openseespy with `pip install --user`) is found
/// even when the `.venv` lacks them.
fn pythons() -> Vec<String> {
    if let Ok(p) = std::env::var("SUBSTEP_PYTHON") {
        return vec![p];
    }
    let mut found: Vec<String> = [
        ".venv/bin/python",
        concat!(env!("CARGO_MANIFEST_DIR"), "/../../.venv/bin/python"),
    ]
    .iter()
    .filter(|v| Path::new(v).is_file())
    .take(1)
    .map(|v| v.to_string())
    .collect();
    found.push("python3".into());
    found
}

/// [`run_peer`] with each of `pythons` until one runs the peer (not a skip); the Python that
/// did, or every skip reason joined.
fn run_peer_any(
    pythons: &[String],
    dir: &Path,
    p: &Peer,
    extra: &[String],
) -> std::result::Result<(String, Value), String> {
    let mut reasons = Vec::new();
    for python in pythons {
        match run_peer(python, dir, p, extra) {
            Ok(v) => return Ok((python.clone(), v)),
            Err(reason) => reasons.push(format!("{python}: {reason}")),
        }
    }
    Err(reasons.join("; "))
}

/// A peer: a display name, its script and the arguments that describe the model.
struct Peer {
    tool: &'static str,
    script: &'static str,
    args: Vec<String>,
}

/// Run a peer script; `Ok(json)` with `roof_u` and `cpu_us_per_batch`, or `Err(reason)` for a skip.
fn run_peer(python: &str, dir: &Path, p: &Peer, extra: &[String]) -> std::result::Result<Value, String> {
    let path = dir.join(p.script);
    if !path.is_file() {
        return Err(format!("skipped: {} not found", path.display()));
    }
    let out = std::process::Command::new(python)
        .arg(&path)
        .args(&p.args)
        .args(extra)
        .output()
        .map_err(|e| format!("skipped: cannot run {python}: {e}"))?;
    let text = String::from_utf8_lossy(&out.stdout);
    match text.lines().rev().find_map(|l| serde_json::from_str::<Value>(l).ok()) {
        Some(v) if v.get("skipped").is_some() => Err(format!("skipped: {}", v["skipped"].as_str().unwrap_or("?"))),
        Some(v) if v.get("roof_u").is_some() && v.get("cpu_us_per_batch").is_some() => Ok(v),
        _ => Err(format!(
            "skipped: {} exited with {} and printed no result: {}",
            path.display(),
            out.status,
            String::from_utf8_lossy(&out.stderr).lines().last().unwrap_or("")
        )),
    }
}

fn floats(v: &Value, key: &str) -> Vec<f64> {
    v.get(key)
        .and_then(Value::as_array)
        .map(|a| a.iter().map(|x| x.as_f64().unwrap_or(f64::NAN)).collect())
        .unwrap_or_default()
}

/// The settings of `substep bench --compare` (`--compare-model`, `--compare-dofs`, `--steps`,
/// `--rounds`, `--substeps`, `--two-cores`).
#[derive(Debug, Clone)]
pub struct CompareOptions {
    pub model: BenchModel,
    pub dofs: usize,
    pub steps: usize,
    pub rounds: usize,
    pub substeps: usize,
    pub two_cores: bool,
}

/// Time monolithic Newmark on the model of `args` in substep and in every peer that agrees with
/// it; `log` gets one line per checked tool and per finished round.
pub fn compare(args: &CompareOptions, log: &mut dyn FnMut(&str)) -> Result<Comparison> {
    let steps = args.steps;
    if steps < BATCHES || !steps.is_multiple_of(BATCHES) {
        return Err(Error::invalid(
            "--steps",
            format!("with --compare must be a multiple of {BATCHES} (the timed batches per round), got {steps}"),
        ));
    }
    if args.rounds == 0 {
        return Err(Error::invalid("--rounds", "must be at least 1"));
    }
    let batch_steps = steps / BATCHES;
    let model = args.model;
    let built = build(model, args.dofs)?;
    let (m, roof) = (&built.model, built.roof);
    let (alpha, beta) = built.rayleigh;
    let n = m.n_dofs();

    // The exported model, for the tools that read matrices.
    let export_dir = std::env::temp_dir().join(format!("substep-compare-{}", std::process::id()));
    crate::io::export_model(m, &[roof], &export_dir, "substep bench --compare")?;
    let mtx = vec![
        "--mtx".to_string(),
        export_dir.display().to_string(),
        "--roof".into(),
        roof.to_string(),
        "--dt".into(),
        DT.to_string(),
    ];
    let mut peers = Vec::new();
    if model == BenchModel::Chain {
        let (b, _, _) = chain(n)?;
        let chain_args = vec![
            "--dofs".to_string(),
            n.to_string(),
            "--mass".into(),
            b.story_mass.to_string(),
            "--stiffness".into(),
            b.story_stiffness().to_string(),
            "--alpha".into(),
            alpha.to_string(),
            "--beta".into(),
            beta.to_string(),
            "--dt".into(),
            DT.to_string(),
        ];
        peers.push(Peer {
            tool: "opensees",
            script: "opensees_chain.py",
            args: chain_args.clone(),
        });
        peers.push(Peer {
            tool: "scipy_banded",
            script: "scipy_banded.py",
            args: chain_args,
        });
    }
    for (tool, solver) in [
        ("scipy_splu_colamd", "splu_colamd"),
        ("scipy_splu_mmd", "splu_mmd"),
        ("cholmod", "cholmod"),
    ] {
        let mut a = mtx.clone();
        a.extend(["--solver".to_string(), solver.to_string()]);
        peers.push(Peer {
            tool,
            script: "scipy_sparse.py",
            args: a,
        });
    }

    // Agreement first: the same response after the same steps, or no timing.
    let (ours_roof, _) = monolithic_run(m, roof, args.two_cores, CHECK_STEPS, 0, 0)?;
    let candidates = pythons();
    let dir = scripts_dir();
    let check = [
        "--check-steps".to_string(),
        CHECK_STEPS.to_string(),
        "--batches".into(),
        "0".into(),
    ];
    let mut tools: Vec<ToolResult> = Vec::new();
    // The Python that ran each peer's check runs its timed rounds.
    let mut peer_python: Vec<String> = Vec::new();
    for p in &peers {
        let outcome = run_peer_any(&candidates, &dir, p, &check);
        peer_python.push(outcome.as_ref().map(|(python, _)| python.clone()).unwrap_or_default());
        let r = match outcome.map(|(_, v)| v) {
            Err(reason) => ToolResult {
                tool: p.tool.into(),
                status: "skipped".into(),
                reason: Some(reason),
                agreement: None,
                cpu_us_per_step: None,
                ratio_to_monolithic: None,
                ratio_to_substructure_step: None,
                detail: Value::Null,
            },
            Ok(v) => {
                let theirs = floats(&v, "roof_u");
                match check_agreement(p.tool, &ours_roof, &theirs, AGREEMENT_TOLERANCE) {
                    Ok(d) => ToolResult {
                        tool: p.tool.into(),
                        status: "agreed".into(),
                        reason: None,
                        agreement: Some(d),
                        cpu_us_per_step: None,
                        ratio_to_monolithic: None,
                        ratio_to_substructure_step: None,
                        detail: v,
                    },
                    Err(e) => ToolResult {
                        tool: p.tool.into(),
                        status: "refused".into(),
                        reason: Some(e.to_string()),
                        agreement: Some(max_rel_difference(&ours_roof, &theirs)),
                        cpu_us_per_step: None,
                        ratio_to_monolithic: None,
                        ratio_to_substructure_step: None,
                        detail: Value::Null,
                    },
                }
            }
        };
        log(&format!(
            "  {:<18} {}{}",
            r.tool,
            r.status,
            r.agreement
                .map_or(String::new(), |d| format!(" (roof response within {d:.1e})"))
        ));
        tools.push(r);
    }

    // Timing: rounds interleaved over substep and the tools that agreed.
    let timed = [
        "--check-steps".to_string(),
        "0".into(),
        "--batches".into(),
        BATCHES.to_string(),
        "--batch-steps".into(),
        batch_steps.to_string(),
    ];
    let mut ours_rounds = Vec::new();
    let mut theirs_rounds: Vec<Vec<f64>> = vec![Vec::new(); peers.len()];
    for round in 0..args.rounds {
        let (_, batches) = monolithic_run(m, roof, args.two_cores, 0, BATCHES, batch_steps)?;
        ours_rounds.push(median(&batches));
        for (k, p) in peers.iter().enumerate() {
            if tools[k].status != "agreed" {
                continue;
            }
            match run_peer(&peer_python[k], &dir, p, &timed) {
                Ok(v) => {
                    theirs_rounds[k].push(median(&floats(&v, "cpu_us_per_batch")));
                    tools[k].detail = v;
                }
                Err(reason) => {
                    tools[k].status = "skipped".into();
                    tools[k].reason = Some(format!("round {}: {reason}", round + 1));
                }
            }
        }
        log(&format!("  round {}/{} done", round + 1, args.rounds));
    }
    let ours = Spread::of(&ours_rounds);
    let sub = bench_model(&ModelBenchOptions {
        model,
        dofs: args.dofs,
        steps,
        substeps: args.substeps,
        second_core: args.two_cores,
        yielding: false,
    })?;
    for (k, t) in tools.iter_mut().enumerate() {
        if t.status == "agreed" && !theirs_rounds[k].is_empty() {
            let s = Spread::of(&theirs_rounds[k]);
            t.ratio_to_monolithic = Some(s.median / ours.median);
            t.ratio_to_substructure_step = Some(s.median / sub.cpu_us_per_step_median);
            t.cpu_us_per_step = Some(s);
        }
        // The timing rounds' detail holds what the tools report about themselves; the
        // response histories are not needed again.
        if let Some(o) = t.detail.as_object_mut() {
            o.remove("roof_u");
        }
    }
    let _ = std::fs::remove_dir_all(&export_dir);
    let c = Comparison {
        model: model.name().into(),
        dofs: n,
        layout: built.layout.clone(),
        dt: DT,
        rayleigh_alpha: alpha,
        rayleigh_beta: beta,
        check_steps: CHECK_STEPS,
        rounds: args.rounds,
        batches: BATCHES,
        batch_steps,
        substep_solver: sub.solver.clone(),
        substep_second_core: sub.second_core,
        substep_solve_bytes: sub.solve_bytes,
        substep_cpu_us_per_step: ours,
        substep_substructure_cpu_us_per_step: sub.cpu_us_per_step_median,
        substep_substructure_p99_us: sub.us_per_step_p99,
        tools,
    };
    Ok(c)
}
