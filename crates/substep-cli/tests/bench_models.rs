//! `substep bench --model chain|frame`: the JSON contract, the sweep and the comparison's
//! skip path (timing goals live in docs/performance.md, never in tests).

use std::process::{Command, Output};

fn substep(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_substep"))
        .args(args)
        .output()
        .expect("the substep binary runs")
}

fn json_of(out: &Output) -> serde_json::Value {
    assert!(out.status.success(), "stderr: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("one JSON object")
}

#[test]
fn model_bench_prints_the_contract_fields() {
    for (model, dofs) in [("chain", 500usize), ("frame", 400)] {
        let n = dofs.to_string();
        let v = json_of(&substep(&[
            "bench",
            "--model",
            model,
            "--dofs",
            &n,
            "--steps",
            "5",
            "--substeps",
            "3",
            "--json",
        ]));
        for key in [
            "dofs",
            "steps",
            "substeps",
            "us_per_step_median",
            "us_per_step_p99",
            "peak_rss_bytes",
        ] {
            assert!(v.get(key).is_some(), "{model}: missing {key} in {v}");
        }
        assert_eq!(v["steps"], 5);
        assert_eq!(v["substeps"], 3);
        assert!(v["us_per_step_p99"].as_f64().unwrap() >= v["us_per_step_median"].as_f64().unwrap());
        assert!(v["peak_rss_bytes"].as_u64().unwrap() > 0);
        let d = v["dofs"].as_u64().unwrap() as usize;
        if model == "chain" {
            assert_eq!(d, dofs);
            assert!(v["solver"].as_str().unwrap().starts_with("banded"), "{v}");
        } else {
            assert!(d.abs_diff(dofs) < dofs / 2, "frame of about {dofs} DOFs: {d}");
        }
    }
}

#[test]
fn sweep_reports_each_size_and_the_budgets() {
    let v = json_of(&substep(&[
        "bench", "--model", "chain", "--sweep", "--sizes", "100,300", "--steps", "5", "--json",
    ]));
    let runs = v["runs"].as_array().unwrap();
    assert_eq!(
        runs.iter().map(|r| r["dofs"].as_u64().unwrap()).collect::<Vec<_>>(),
        vec![100, 300]
    );
    assert!(v.get("largest_dofs_within_1ms").is_some() && v.get("largest_dofs_within_10ms").is_some());
}

#[test]
fn bad_model_options_are_refused() {
    let out = substep(&["bench", "--model", "chain", "--steps", "5"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--dofs: is required with --model"));
    let out = substep(&["bench", "--dofs", "100"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--dofs: needs --model chain|frame"));
}

#[test]
fn compare_skips_missing_tools_cleanly() {
    // A Python that does not exist: every tool is reported as skipped, the run still succeeds.
    let out = Command::new(env!("CARGO_BIN_EXE_substep"))
        .args([
            "bench",
            "--compare",
            "--compare-dofs",
            "200",
            "--steps",
            "10",
            "--rounds",
            "1",
            "--json",
        ])
        .env("SUBSTEP_PYTHON", "/nonexistent/python3")
        .output()
        .unwrap();
    let v = json_of(&out);
    assert_eq!(v["dofs"], 200);
    assert_eq!(v["batch_steps"], 2);
    for t in v["tools"].as_array().unwrap() {
        assert_eq!(t["status"], "skipped", "{t}");
        assert!(t["cpu_us_per_step"].is_null(), "{t}");
        // each Python tried is named with its reason (SUBSTEP_PYTHON: the only one)
        assert!(
            t["reason"]
                .as_str()
                .unwrap()
                .starts_with("/nonexistent/python3: skipped: cannot run"),
            "{t}"
        );
    }
    // --steps is honoured, not rounded up: it must split into the timed batches.
    let out = substep(&["bench", "--compare", "--compare-dofs", "200", "--steps", "12"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("--steps: with --compare must be a multiple of 5"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A stand-in for the OpenSees script: Newmark on the chain in plain Python (tridiagonal
/// solve), with the springs scaled by `CHAIN_STIFFNESS_SCALE` (1: our model; else a
/// deliberately different one).
const CHAIN_PEER: &str = r#"
import json, math, os, sys
a = dict(zip(sys.argv[1::2], sys.argv[2::2]))
n, m, k = int(a["--dofs"]), float(a["--mass"]), float(a["--stiffness"]) * float(os.environ["CHAIN_STIFFNESS_SCALE"])
al, be, dt = float(a["--alpha"]), float(a["--beta"]), float(a["--dt"])
check = int(a["--check-steps"])
a0, a1, a2, a3, a4, a5 = 4/dt**2, 2/dt, 4/dt, 1.0, 1.0, 0.0
a6, a7 = dt/2, dt/2
kd = [2*k]*(n-1) + [k]
def kmul(x):
    return [kd[i]*x[i] - (k*x[i-1] if i > 0 else 0) - (k*x[i+1] if i < n-1 else 0) for i in range(n)]
# K_hat = (1 + a1 be) K + (a0 + a1 al) m I, tridiagonal: Thomas factors.
c, d = 1 + a1*be, a0 + a1*al
diag = [c*kd[i] + d*m for i in range(n)]
off = -c*k
cp, dp = [0.0]*n, [0.0]*n
u, v, ac = [0.0]*n, [0.0]*n, [0.0]*n
roof = []
for s in range(1, check + 1):
    g = math.sin(2*math.pi*s*dt)
    wc = [a1*u[i] + a4*v[i] + a5*ac[i] for i in range(n)]
    kw = kmul(wc)
    rhs = [m*(a0*u[i] + a2*v[i] + a3*ac[i]) + al*m*wc[i] + be*kw[i] - m*g for i in range(n)]
    # Thomas algorithm
    b0 = diag[0]
    cp[0] = off / b0
    dp[0] = rhs[0] / b0
    for i in range(1, n):
        den = diag[i] - off*cp[i-1]
        cp[i] = off / den
        dp[i] = (rhs[i] - off*dp[i-1]) / den
    un = [0.0]*n
    un[n-1] = dp[n-1]
    for i in range(n-2, -1, -1):
        un[i] = dp[i] - cp[i]*un[i+1]
    an = [a0*(un[i]-u[i]) - a2*v[i] - a3*ac[i] for i in range(n)]
    v = [v[i] + a6*ac[i] + a7*an[i] for i in range(n)]
    u, ac = un, an
    roof.append(u[n-1])
print(json.dumps({"tool": "chain_peer", "roof_u": roof, "cpu_us_per_batch": [1.0]}))
"#;

#[test]
fn compare_refuses_a_tool_whose_model_differs() {
    let dir = std::env::temp_dir().join(format!("substep-peer-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("opensees_chain.py"), CHAIN_PEER).unwrap();
    let run = |scale: &str| {
        let out = Command::new(env!("CARGO_BIN_EXE_substep"))
            .args([
                "bench",
                "--compare",
                "--compare-dofs",
                "30",
                "--steps",
                "5",
                "--rounds",
                "1",
                "--json",
            ])
            .env("SUBSTEP_COMPARE_DIR", &dir)
            .env("CHAIN_STIFFNESS_SCALE", scale)
            .output()
            .unwrap();
        let v = json_of(&out);
        v["tools"]
            .as_array()
            .unwrap()
            .iter()
            .find(|t| t["tool"] == "opensees")
            .cloned()
            .unwrap()
    };
    // The same chain: the response agrees to rounding and the tool is timed.
    let same = run("1.0");
    if same["status"] == "skipped" {
        // No python3 on this machine: nothing to compare with.
        assert!(same["reason"].as_str().unwrap().contains("cannot run"), "{same}");
        return;
    }
    assert_eq!(same["status"], "agreed", "{same}");
    assert!(same["agreement"].as_f64().unwrap() < 1e-9, "{same}");
    assert!(same["cpu_us_per_step"]["median"].as_f64().is_some(), "{same}");
    // Springs 2 % stiffer: a different model, refused and not timed (50 steps of a 3 s chain
    // move its roof by a few mm, so the difference is small but far above rounding).
    let other = run("1.02");
    assert_eq!(other["status"], "refused", "{other}");
    assert!(other["cpu_us_per_step"].is_null());
    let reason = other["reason"].as_str().unwrap();
    assert!(
        reason.starts_with("opensees: its response differs from substep's by"),
        "{reason}"
    );
    assert!(other["agreement"].as_f64().unwrap() > 1e-7, "{other}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn model_export_writes_what_the_config_builds() {
    use substep::io::{TestDefinition, read_matrix_market, read_matrix_market_sparse};
    let dir = std::env::temp_dir().join(format!("substep-export-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = dir.join("frame.toml");
    std::fs::write(
        &cfg,
        "[structure]\nstorage = \"sparse\"\n[structure.frame]\nbays = 4\nstories = 6\n\
         [structure.rayleigh]\nalpha = 0.1\nbeta = 0.002\n\
         [ground_motion]\ngenerator = \"harmonic\"\namplitude = 1.0\nfrequency = 2.0\nduration = 0.05\n\
         [integrator]\nscheme = \"newmark\"\ndt = 0.01\n\
         [substructure]\ncoupling_dofs = [76]\nsubsteps = 4\n\
         [[substructure.specimen]]\nkind = \"linear_sdof\"\ndof = 76\nstiffness = 1e6\n",
    )
    .unwrap();
    let out_dir = dir.join("mtx");
    let out = substep(&[
        "model",
        "export",
        cfg.to_str().unwrap(),
        "--mtx",
        out_dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let def = TestDefinition::from_file(&cfg).unwrap();
    let m = def.model.as_sparse().unwrap();
    // Bit for bit (17 significant digits; the reader drops the stored zeros, so compare dense).
    for (name, want) in [("K.mtx", &m.stiffness), ("M.mtx", &m.mass), ("C.mtx", &m.damping)] {
        let got = read_matrix_market_sparse(out_dir.join(name)).unwrap();
        assert_eq!(got.to_dense(), want.to_dense(), "{name}");
    }
    let iota = read_matrix_market(out_dir.join("influence.mtx")).unwrap();
    assert_eq!(iota.as_slice(), m.influence.as_slice());
    assert_eq!(std::fs::read_to_string(out_dir.join("coupling.txt")).unwrap(), "76\n");
    // A config that does not exist: exit code 2 with the file named.
    let out = substep(&[
        "model",
        "export",
        "/nonexistent/x.toml",
        "--mtx",
        out_dir.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/x.toml"));
    std::fs::remove_dir_all(&dir).unwrap();
}
