//! The `substep` binary end to end: the default job, outputs, bad input, divergence, bench.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A fresh, empty directory for one test.
fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("substep-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn substep(cwd: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_substep"))
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("the substep binary runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn lines(path: &Path) -> Vec<String> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(String::from)
        .collect()
}

fn is_png(path: &Path) -> bool {
    std::fs::read(path).is_ok_and(|b| b.starts_with(b"\x89PNG\r\n\x1a\n") && b.len() > 10_000)
}

#[test]
fn default_job_runs_the_embedded_example() {
    let dir = temp_dir("default");
    let out = substep(&dir, &[]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", text(&out.stderr));
    assert!(stdout.contains("running the embedded default example"), "{stdout}");
    assert!(stdout.contains("max error vs exact solution: "), "{stdout}");
    let res = dir.join("results");
    let summary = json(&res.join("summary.json"));
    assert_eq!(summary["completed"], true);
    assert_eq!(summary["config"], "embedded default");
    assert_eq!(summary["steps"], 2000);
    assert_eq!(summary["substructure"]["substeps"], 4);
    assert_eq!(summary["reference"]["scheme"], "exact");
    let err = summary["reference"]["max_displacement_error"].as_f64().unwrap();
    assert!(err > 0.0 && err < 0.05, "{err}");
    // The time step's share: Newmark of the assembled system against the exact solution is
    // far smaller here (Δt = 10 ms for a 1 Hz structure) than the test's error against it.
    let split = &summary["reference"]["same_integrator"];
    let (time_step, rest) = (
        split["integration_error"].as_f64().unwrap(),
        split["max_displacement_error"].as_f64().unwrap(),
    );
    assert!(time_step > 0.0 && time_step < 0.2 * err && rest > 0.5 * err, "{split}");
    assert!(stdout.contains("the time step alone: "), "{stdout}");
    assert!(summary["us_per_step"].as_f64().unwrap() > 0.0);

    let history = lines(&res.join("history.csv"));
    assert_eq!(
        history[0],
        "t,u1,v1,a1,fc1,fe1,fu1,dm1,fei1,uref1,eta,margin,k_id1,c_id1,lag_id1"
    );
    assert_eq!(history.len(), 1 + 2001, "one row per step from t = 0");
    assert!(history[2].starts_with("0.01,"));
    let substeps = lines(&res.join("substeps.csv"));
    assert_eq!(substeps[0], "step,substep,t,cmd1,fm1,dm1");
    assert_eq!(substeps.len(), 1 + 2000 * 4);
    for png in [
        "displacement",
        "acceleration",
        "coupling_force",
        "error_force",
        "hysteresis",
        "reference",
    ] {
        assert!(is_png(&res.join(format!("{png}.png"))), "{png}.png");
    }
}

#[test]
fn monolithic_example_with_out_dir_and_without_plots() {
    let dir = temp_dir("monolithic");
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/monolithic_tmd.toml");
    let out = substep(
        &dir,
        &[
            "run",
            config.to_str().unwrap(),
            "--out",
            "here",
            "--no-plots",
            "--quiet",
        ],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(out.stdout.is_empty(), "--quiet prints nothing");
    let res = dir.join("here");
    assert_eq!(lines(&res.join("history.csv"))[0], "t,u1,u2,v1,v2,a1,a2");
    assert!(!res.join("substeps.csv").exists());
    assert!(!res.join("displacement.png").exists());
    let summary = json(&res.join("summary.json"));
    assert_eq!(summary["completed"], true);
    assert_eq!(summary["n_dofs"], 2);
    assert!(summary.get("reference").is_none());
    assert_eq!(summary["peaks"].as_array().unwrap().len(), 2);
}

const BASE: &str = r#"
[structure]
mass = [[1000.0, 0.0, 0.0], [0.0, 1000.0, 0.0], [0.0, 0.0, 1000.0]]
stiffness = [[2e6, -1e6, 0.0], [-1e6, 2e6, -1e6], [0.0, -1e6, 1e6]]

[ground_motion]
generator = "harmonic"
amplitude = 1.0
frequency = 2.0
duration = 1.0

[integrator]
scheme = "newmark"
dt = 0.01

[substructure]
coupling_dofs = [3]
substeps = 4

[[substructure.specimen]]
kind = "linear_sdof"
dof = 3
mass = 50.0
stiffness = 2000.0
damping = 60.0

[substructure.actuator]
kind = "second_order"
frequency = 50.0
zeta = 0.7
"#;

/// Write `config` as `cfg.toml` into a fresh directory, run it, and check the bad-input
/// contract: exit code 2, one stderr line `error: ...` containing `expected`, no panic, no
/// summary.json.
fn assert_bad_input(name: &str, config: &str, files: &[(&str, &str)], expected: &str) {
    let dir = temp_dir(name);
    std::fs::write(dir.join("cfg.toml"), config).unwrap();
    for (file, content) in files {
        std::fs::write(dir.join(file), content).unwrap();
    }
    let out = substep(&dir, &["run", "cfg.toml", "--out", "out"]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{name}: {stderr}");
    assert!(stderr.starts_with("error: "), "{name}: {stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "{name}: {stderr}");
    assert!(stderr.contains(expected), "{name}: expected '{expected}' in: {stderr}");
    assert!(!stderr.contains("panicked"), "{name}: {stderr}");
    assert!(!dir.join("out/summary.json").exists(), "{name}");
}

fn edit(from: &str, to: &str) -> String {
    assert!(BASE.contains(from), "{from}");
    BASE.replacen(from, to, 1)
}

#[test]
fn base_config_of_the_bad_input_tests_is_valid() {
    let dir = temp_dir("base");
    std::fs::write(dir.join("cfg.toml"), BASE).unwrap();
    let out = substep(&dir, &["run", "cfg.toml", "--out", "out", "--quiet", "--no-plots"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(json(&dir.join("out/summary.json"))["completed"], true);
}

#[test]
fn bad_input_gives_one_line_and_exit_code_2() {
    let record = "t,ag\n0,0\n0.01,0.5\n0.02,nan\n0.03,0\n";
    let cases: Vec<(&str, String, &str)> = vec![
        (
            "malformed",
            edit("substeps = 4", "substeps = [4"),
            "error: cfg.toml: line ",
        ),
        (
            "unknown_key",
            edit("substeps = 4", "substeps = 4\nsub_steps = 4"),
            "cfg.toml: line 19: unknown field `sub_steps`",
        ),
        (
            "matrix_size",
            edit(
                "stiffness = [[2e6, -1e6, 0.0], [-1e6, 2e6, -1e6], [0.0, -1e6, 1e6]]",
                "stiffness = [[2e6, -1e6], [-1e6, 2e6]]",
            ),
            "structure.stiffness: is 2x2 but the model has 3 DOFs",
        ),
        (
            "non_symmetric",
            edit("[-1e6, 2e6, -1e6], [0.0", "[-1e6, 2e6, -1e6], [3.0"),
            "structure.stiffness: is not symmetric",
        ),
        (
            "mass_not_spd",
            edit("[0.0, 0.0, 1000.0]]", "[0.0, 0.0, 0.0]]"),
            "cfg.toml: structure.mass: is not positive definite",
        ),
        (
            "missing_matrix_file",
            edit(
                "mass = [[1000.0, 0.0, 0.0], [0.0, 1000.0, 0.0], [0.0, 0.0, 1000.0]]",
                "mass = \"matrices/M.mtx\"",
            ),
            "matrices/M.mtx: cannot read file",
        ),
        (
            "missing_record",
            edit(
                "generator = \"harmonic\"\namplitude = 1.0\nfrequency = 2.0\nduration = 1.0",
                "file = \"no_such_record.csv\"",
            ),
            "no_such_record.csv: cannot read file",
        ),
        (
            "dt_zero",
            edit("dt = 0.01", "dt = 0.0"),
            "cfg.toml: integrator.dt: must be a finite number > 0, got 0",
        ),
        (
            "dt_negative",
            edit("dt = 0.01", "dt = -1e-3"),
            "integrator.dt: must be a finite number > 0",
        ),
        (
            "substeps_zero",
            edit("substeps = 4", "substeps = 0"),
            "cfg.toml: substructure.substeps: must be at least 1",
        ),
        (
            "coupling_out_of_range",
            edit("coupling_dofs = [3]", "coupling_dofs = [7]"),
            "substructure.coupling_dofs: DOF 7 is out of range (the model has DOFs 1..=3)",
        ),
        (
            "coupling_repeated",
            edit("coupling_dofs = [3]", "coupling_dofs = [3, 3]"),
            "substructure.coupling_dofs: DOF 3 is listed twice",
        ),
        (
            "specimen_not_on_coupling_dof",
            edit("dof = 3", "dof = 2"),
            "substructure.specimen[1].dof: DOF 2 is not one of substructure.coupling_dofs",
        ),
        (
            "negative_specimen_mass",
            edit("mass = 50.0", "mass = -50.0"),
            "substructure.specimen[1].mass: must be a finite number > 0, got -50",
        ),
        (
            "negative_specimen_damping",
            edit("damping = 60.0", "damping = -1.0"),
            "substructure.specimen[1].damping: must be a finite number >= 0, got -1",
        ),
        (
            "unstable_actuator",
            edit("zeta = 0.7", "zeta = 0.0"),
            "substructure.actuator.zeta: must be > 0",
        ),
        (
            "unknown_scheme",
            edit("scheme = \"newmark\"", "scheme = \"runge_kutta\""),
            "integrator.scheme: unknown scheme 'runge_kutta'",
        ),
        (
            "unknown_specimen_kind",
            edit("kind = \"linear_sdof\"", "kind = \"magic\""),
            "unknown variant `magic`, expected one of `linear_sdof`, `linear_mdof`, `bouc_wen`, `friction`, `replay`, `lumped_sdof`",
        ),
        (
            "unknown_actuator_kind",
            edit("kind = \"second_order\"", "kind = \"pneumatic\""),
            "unknown variant `pneumatic`",
        ),
        (
            "explicit_scheme_with_substructure",
            edit("scheme = \"newmark\"", "scheme = \"central_difference\""),
            "integrator.scheme: the substructure algorithm needs an implicit Newmark scheme",
        ),
    ];
    for (name, config, expected) in &cases {
        assert_bad_input(name, config, &[], expected);
    }
    assert_bad_input(
        "nan_in_record",
        &edit(
            "generator = \"harmonic\"\namplitude = 1.0\nfrequency = 2.0\nduration = 1.0",
            "file = \"ag.csv\"",
        ),
        &[("ag.csv", record)],
        "ag.csv: line 4: value is not finite (NaN)",
    );
}

#[test]
fn missing_config_file_is_bad_input() {
    let dir = temp_dir("missing-config");
    let out = substep(&dir, &["run", "nowhere/test.toml"]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr.starts_with("error: nowhere/test.toml: cannot read file"),
        "{stderr}"
    );
    assert!(!dir.join("results").exists());
}

#[test]
fn diverging_run_keeps_its_rows_and_exits_1() {
    let dir = temp_dir("diverge");
    // Central difference beyond its stability limit: omega dt = 3.14 > 2.
    let config = "[structure.sdof]\nmass = 1.0\nstiffness = 3947.8417604357433\n\
                  [ground_motion]\ngenerator = \"harmonic\"\namplitude = 1.0\nfrequency = 1.0\nduration = 30.0\n\
                  [integrator]\nscheme = \"central_difference\"\ndt = 0.05\n";
    std::fs::write(dir.join("cfg.toml"), config).unwrap();
    // A summary left over from an earlier run must not survive.
    std::fs::create_dir_all(dir.join("out")).unwrap();
    std::fs::write(dir.join("out/summary.json"), "{\"completed\": true}").unwrap();
    let out = substep(&dir, &["run", "cfg.toml", "--out", "out"]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.starts_with("error: diverged at step "), "{stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1);
    assert!(text(&out.stdout).contains("STOPPED after "));
    let summary = json(&dir.join("out/summary.json"));
    assert_eq!(summary["completed"], false);
    let stopped = summary["stopped_at_step"].as_u64().unwrap() as usize;
    assert!(stopped > 5 && stopped < 600, "{stopped}");
    // It grows past the runaway bound (1 km) before it overflows.
    assert!(
        summary["reason"].as_str().unwrap().contains("runaway response"),
        "{}",
        summary["reason"]
    );
    assert_eq!(summary["diverged"], true);
    assert_eq!(summary["steps_done"].as_u64().unwrap() as usize, stopped - 1);
    // Header plus the rows of steps 0 ..= stopped - 1, all finite.
    let history = lines(&dir.join("out/history.csv"));
    assert_eq!(history.len(), 1 + stopped);
    assert!(history[1..].iter().all(|l| !l.contains("NaN") && !l.contains("inf")));
}

#[test]
fn bench_prints_json() {
    let dir = temp_dir("bench");
    let out = substep(&dir, &["bench", "--steps", "5", "--stories", "10", "--json"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["monolithic"][0]["stories"], 10);
    assert!(v["monolithic"][0]["us_per_step"].as_f64().unwrap() > 0.0);
    let cases = v["substructure"]["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 2);
    assert_eq!(v["substructure"]["substeps"], 10);
}

/// The names of the files in `dir`, sorted.
fn file_names(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn a_run_removes_the_outputs_of_an_earlier_run_and_nothing_else() {
    let dir = temp_dir("stale");
    std::fs::write(dir.join("sub.toml"), BASE).unwrap();
    let out = substep(&dir, &["run", "sub.toml", "--out", "out", "--quiet"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let first = file_names(&dir.join("out"));
    for f in ["substeps.csv", "displacement.png", "hysteresis.png", "summary.json"] {
        assert!(first.iter().any(|n| n == f), "{f} in {first:?}");
    }
    assert!(
        !first.iter().any(|n| n.starts_with('.')),
        "no temporary file left: {first:?}"
    );
    std::fs::write(dir.join("out/notes.txt"), "mine").unwrap();
    std::fs::write(dir.join("out/my_plot.png"), "mine too").unwrap();

    // A diverging monolithic run without plots: nothing of the first run may remain (its
    // summary said `completed: true`), the user's files stay untouched.
    let config = "[structure.sdof]\nmass = 1.0\nstiffness = 3947.8417604357433\n\
                  [ground_motion]\ngenerator = \"harmonic\"\namplitude = 1.0\nfrequency = 1.0\nduration = 30.0\n\
                  [integrator]\nscheme = \"central_difference\"\ndt = 0.05\n";
    std::fs::write(dir.join("diverge.toml"), config).unwrap();
    let out = substep(&dir, &["run", "diverge.toml", "--out", "out", "--no-plots"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    assert_eq!(
        file_names(&dir.join("out")),
        [
            "fourier.csv",
            "ground_motion.csv",
            "history.csv",
            "my_plot.png",
            "notes.txt",
            "response.csv",
            "spectrum.csv",
            "summary.json"
        ]
    );
    assert_eq!(json(&dir.join("out/summary.json"))["completed"], false);
    assert_eq!(std::fs::read_to_string(dir.join("out/notes.txt")).unwrap(), "mine");
    assert_eq!(
        std::fs::read_to_string(dir.join("out/my_plot.png")).unwrap(),
        "mine too"
    );

    // The same for a real-time run after an offline one with plots.
    let out = substep(&dir, &["run", "sub.toml", "--out", "out", "--quiet"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    // (the files are checked here, not the pace: a loaded test machine may miss deadlines)
    let out = substep(
        &dir,
        &[
            "run",
            "sub.toml",
            "--out",
            "out",
            "--quiet",
            "--realtime",
            "--max-missed",
            "1",
        ],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(
        file_names(&dir.join("out")),
        [
            "history.csv",
            "my_plot.png",
            "notes.txt",
            "realtime.json",
            "realtime.txt",
            "summary.json"
        ]
    );
    assert_eq!(json(&dir.join("out/summary.json"))["mode"], "realtime");

    // A config refused as bad input writes and removes nothing.
    std::fs::write(dir.join("bad.toml"), edit("substeps = 4", "substeps = 0")).unwrap();
    let out = substep(&dir, &["run", "bad.toml", "--out", "out"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert_eq!(json(&dir.join("out/summary.json"))["mode"], "realtime");
}

#[test]
fn an_output_dir_that_cannot_be_used_is_bad_input() {
    let dir = temp_dir("outdir");
    std::fs::write(dir.join("cfg.toml"), BASE).unwrap();
    std::fs::write(dir.join("taken"), "a file, not a directory").unwrap();
    for realtime in [false, true] {
        let mut args = vec!["run", "cfg.toml", "--out", "taken/out", "--quiet"];
        if realtime {
            args.push("--realtime");
        }
        let out = substep(&dir, &args);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "realtime {realtime}: {stderr}");
        assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
        assert!(
            stderr.starts_with("error: taken/out: cannot create the output directory: Not a directory"),
            "{stderr}"
        );
    }
    // a name substep writes is taken by a directory: refused before anything is written
    std::fs::create_dir_all(dir.join("out/summary.json")).unwrap();
    let out = substep(&dir, &["run", "cfg.toml", "--out", "out", "--quiet"]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.starts_with("error: out/summary.json: is a directory, but substep writes a file of that name here"),
        "{stderr}"
    );
    assert_eq!(file_names(&dir.join("out")), ["summary.json"]);
}

#[test]
fn a_run_killed_at_any_moment_leaves_no_broken_summary() {
    let dir = temp_dir("killed");
    std::fs::write(dir.join("cfg.toml"), edit("duration = 1.0", "duration = 20.0")).unwrap();
    for k in 0..12u64 {
        let mut child = Command::new(env!("CARGO_BIN_EXE_substep"))
            .args(["run", "cfg.toml", "--out", "out", "--quiet"])
            .current_dir(&dir)
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(20 + 20 * k));
        let _ = child.kill();
        let status = child.wait().unwrap();
        let summary = dir.join("out/summary.json");
        if !summary.exists() {
            continue; // killed before the directory was prepared
        }
        // the old summary or the new one, whole: it parses, and it says whether it completed
        let text = std::fs::read_to_string(&summary).unwrap();
        let value: serde_json::Value =
            serde_json::from_str(&text).unwrap_or_else(|e| panic!("kill {k}: summary.json is broken ({e}): {text}"));
        let completed = value["completed"].as_bool().expect("completed is a bool");
        eprintln!("kill {k}: completed {completed}, status {status}");
        assert!(completed || !status.success(), "kill {k}");
        if completed {
            assert_eq!(lines(&dir.join("out/history.csv")).len(), 1 + 2001, "kill {k}");
        }
        // only temporary files of substep's own outputs may be left behind; the next run removes them
        for name in file_names(&dir.join("out")) {
            if let Some(tmp) = name.strip_prefix('.') {
                assert!(tmp.contains(".tmp."), "kill {k}: unexpected {name}");
            }
        }
    }
    let out = substep(&dir, &["run", "cfg.toml", "--out", "out", "--quiet", "--no-plots"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let names = file_names(&dir.join("out"));
    assert_eq!(
        names,
        [
            "fourier.csv",
            "ground_motion.csv",
            "history.csv",
            "response.csv",
            "spectrum.csv",
            "substeps.csv",
            "summary.json"
        ]
    );
}

/// Nonlinear models (docs/theory.md §14): bad input gives one line and exit 2; a Newton
/// iteration that does not converge gives exit 1, names the step and the residual, and keeps
/// the rows before.
#[test]
fn nonlinear_bad_input_exits_2_and_a_failed_newton_exits_1() {
    let storeys = |hysteresis: &str, integrator: &str| {
        format!(
            "[structure.storeys]\nmasses = [2.0e5, 2.0e5]\nstiffness = [3.0e8, 2.5e8]\n\
             [structure.storeys.hysteresis]\n{hysteresis}\n\
             [ground_motion]\ngenerator = \"harmonic\"\namplitude = 3.0\nfrequency = 2.0\nduration = 2.0\n\
             [integrator]\ndt = 0.01\n{integrator}\n"
        )
    };
    let bilinear = "kind = \"bilinear\"\nyield_force = 1.0e5\nhardening = 0.02";
    for (name, config, expected) in [
        (
            "nl-yield",
            storeys("kind = \"bilinear\"\nyield_force = 0.0\nhardening = 0.02", ""),
            "structure.storeys.hysteresis.yield_force: storey 1: must be a finite force > 0 N",
        ),
        (
            "nl-hardening",
            storeys("kind = \"bilinear\"\nyield_force = 1.0e5\nhardening = 1.0", ""),
            "structure.storeys.hysteresis.hardening: must lie in [0, 1)",
        ),
        (
            "nl-tolerance",
            storeys(bilinear, "tolerance = 0.0"),
            "integrator.tolerance: must lie in (0, 1)",
        ),
        (
            "nl-scheme",
            storeys(bilinear, "scheme = \"hht\""),
            "\"hht\" cannot integrate a nonlinear model",
        ),
        (
            "nl-hinge",
            "[structure.frame]\nbays = 0\n[structure.frame.hinges]\nat = \"beams\"\nkind = \"elastic\"\n\
             [ground_motion]\ngenerator = \"harmonic\"\namplitude = 1.0\nfrequency = 1.0\nduration = 1.0\n\
             [integrator]\ndt = 0.01\n"
                .to_string(),
            "structure.frame.hinges.at: \"beams\" asks for beam hinges, but the frame has no beams (bays = 0)",
        ),
    ] {
        assert_bad_input(name, &config, &[], expected);
    }
    let dir = temp_dir("nl-newton");
    std::fs::write(dir.join("cfg.toml"), storeys(bilinear, "max_iterations = 1")).unwrap();
    let out = substep(&dir, &["run", "cfg.toml", "--out", "out"]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.starts_with("error: diverged at step "), "{stderr}");
    assert!(
        stderr.contains("Newton–Raphson did not converge in 1 iterations"),
        "{stderr}"
    );
    assert!(stderr.contains("largest residual force"), "{stderr}");
    let summary = json(&dir.join("out/summary.json"));
    assert_eq!(summary["completed"], false);
    assert_eq!(summary["diverged"], true);
    let done = summary["steps_done"].as_u64().unwrap() as usize;
    assert_eq!(lines(&dir.join("out/history.csv")).len(), 1 + done + 1);
}
