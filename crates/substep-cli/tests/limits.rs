//! Regression tests of issue 11 (limits before work, numerics, bounded reads) through the
//! binary: each hostile config is refused with one `error:` line naming the config, the key and
//! the limit, exit code 2, before anything is allocated or written (the command completes at
//! once and leaves no output directory). Completion is asserted with a generous deadline, not
//! timed.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("substep-limits-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Run `substep run CONFIG --out out` in `dir`; `(exit code, stderr)`. Killed (and the test
/// failed) if it does not finish within 60 s: a refusal must not wait for anything.
fn run(dir: &Path, config: &str) -> (i32, String) {
    run_args(dir, &["run", config, "--out", "out", "--quiet", "--no-plots"])
}

/// The binary with `args` in `dir`: exit code and stderr, failing the test if it does not end.
fn run_args(dir: &Path, args: &[&str]) -> (i32, String) {
    let config = args.join(" ");
    let mut child = Command::new(env!("CARGO_BIN_EXE_substep"))
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the substep binary runs");
    let started = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if started.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            panic!("substep {config} did not finish (hang or runaway work)");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut stderr).unwrap();
    (status.code().unwrap_or(-1), stderr)
}

/// Write `text` as `name` in a fresh dir, run it, and check the refusal: exit 2, one line
/// `error: NAME: ...` containing every fragment, and no output written.
fn refused(test: &str, text: &str, fragments: &[&str]) -> String {
    let dir = temp_dir(test);
    std::fs::write(dir.join("test.toml"), text).unwrap();
    refused_in(&dir, "test.toml", fragments)
}

fn refused_in(dir: &Path, config: &str, fragments: &[&str]) -> String {
    let (code, stderr) = run(dir, config);
    assert_eq!(code, 2, "exit code of a refused config; stderr: {stderr}");
    assert_eq!(stderr.lines().count(), 1, "one line: {stderr}");
    let line = stderr.trim_end();
    assert!(
        line.starts_with(&format!("error: {config}: ")),
        "names the config: {line}"
    );
    for f in fragments {
        assert!(line.contains(f), "'{f}' missing in: {line}");
    }
    assert!(!line.contains("panicked"), "{line}");
    assert!(!dir.join("out").exists(), "nothing is written for a refused config");
    line.to_string()
}

const HARMONIC: &str = r#"
[ground_motion]
generator = "harmonic"
amplitude = 1.0
frequency = 1.0
duration = 20.0

[integrator]
scheme = "average_acceleration"
dt = 0.01
"#;

fn shear(stories: &str, damping: &str) -> String {
    format!(
        "[structure.shear_building]\nstories = {stories}\nstory_mass = 1.0e5\nfirst_period = 2.0\n{damping}\n{HARMONIC}"
    )
}

/// A TMD substructure test (1000 kg primary, 50 kg TMD) with `actuator` and `extra` keys.
fn tmd(specimen: &str, actuator: &str, substructure: &str) -> String {
    format!(
        r#"[structure.sdof]
mass = 1000.0
stiffness = 39478.4
damping = 628.3
{HARMONIC}
[substructure]
coupling_dofs = [1]
{substructure}

[[substructure.specimen]]
kind = "linear_sdof"
dof = 1
{specimen}

[substructure.actuator]
{actuator}
"#
    )
}

const TMD_SPECIMEN: &str = "mass = 50.0\nstiffness = 1973.9\ndamping = 62.8";
const IDEAL: &str = "kind = \"ideal\"";
const SERVO: &str = "kind = \"second_order\"\nfrequency = 60.0\nzeta = 0.7\ndelay = 0.001";

#[test]
fn huge_shear_buildings_are_refused_before_allocating() {
    let rayleigh = "[structure.rayleigh]\nalpha = 0.1\nbeta = 0.001";
    for (stories, estimate) in [
        ("100000000", "111.8 GiB"),
        ("1000000000", "1.1 TiB"),
        ("18446744073709551615", "2.21e22 B"),
    ] {
        refused(
            &format!("stories-{stories}"),
            &shear(stories, rayleigh),
            &[
                "structure.shear_building.stories: a shear building of",
                &format!("needs about {estimate} of memory (estimate)"),
                "limits.max_memory = 4.0 GiB",
                "set [limits] max_memory",
            ],
        );
    }
}

#[test]
fn modal_damping_on_ten_million_stories_is_refused_first() {
    // The cheap contradiction comes before any estimate or assembly.
    refused(
        "modal-1e7",
        &shear("10000000", "[structure.modal]\nzeta = 0.05"),
        &[
            "structure: modal damping ([structure.modal]) needs dense matrices",
            "the model has 10000000 DOFs",
        ],
    );
}

#[test]
fn huge_frames_are_refused_before_allocating() {
    for (size, estimate) in [("1000", "11.2 GiB"), ("3000", "100.6 GiB")] {
        let text = format!(
            "[structure.frame]\nbays = {size}\nstories = {size}\n[structure.rayleigh]\nalpha = 0.1\nbeta = 0.001\n{HARMONIC}"
        );
        refused(
            &format!("frame-{size}"),
            &text,
            &[
                &format!("structure.frame: a frame of {size} bays and {size} stories"),
                &format!("needs about {estimate} of memory"),
                "limits.max_memory",
            ],
        );
    }
}

#[test]
fn matrix_market_size_lines_are_checked_before_allocating() {
    let dir = temp_dir("mtx");
    std::fs::write(
        dir.join("big.mtx"),
        "%%MatrixMarket matrix coordinate real general\n2000000000 2000000000 1\n1 1 1.0\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("arr.mtx"),
        "%%MatrixMarket matrix array real general\n50000 50000\n1\n2\n3\n4\n5\n6\n",
    )
    .unwrap();
    let model = |m: &str| format!("[structure]\nmass = \"{m}\"\nstiffness = \"{m}\"\n{HARMONIC}");
    std::fs::write(dir.join("big.toml"), model("big.mtx")).unwrap();
    refused_in(
        &dir,
        "big.toml",
        &[
            "structure.mass: big.mtx: line 2: matrix size 2000000000x2000000000 as a sparse model",
            "needs about 2.2 TiB of memory",
            "limits.max_memory",
        ],
    );
    // Sparse path: positions are walked, not listed, so 6 values of 2.5e9 are found cheaply.
    std::fs::write(dir.join("arr.toml"), model("arr.mtx")).unwrap();
    refused_in(
        &dir,
        "arr.toml",
        &["structure.mass: arr.mtx: a 50000x50000 array needs 2500000000 values but 6 were found"],
    );
    // Dense path (a specimen matrix): the size line alone is refused.
    let specimen = tmd("", IDEAL, "substeps = 2").replace(
        "kind = \"linear_sdof\"\ndof = 1\n",
        "kind = \"linear_mdof\"\ndofs = [1]\nstiffness = \"arr.mtx\"\n",
    );
    std::fs::write(dir.join("spec.toml"), specimen).unwrap();
    refused_in(
        &dir,
        "spec.toml",
        &[
            "substructure.specimen[1].stiffness: arr.mtx: line 2: matrix size 50000x50000 as a dense matrix",
            "needs about 21.0 GiB of memory",
        ],
    );
}

#[test]
fn delay_lines_and_inner_steps_are_sized_before_allocating() {
    let servo = |delay: &str| SERVO.replace("delay = 0.001", &format!("delay = {delay}"));
    refused(
        "delay-1e9",
        &tmd(TMD_SPECIMEN, &servo("1e9"), "substeps = 4"),
        &[
            "substructure.actuator.delay: a delay of 1000000000 s sampled every 2.500e-4 s",
            "8.000e12 samples per actuator",
            "needs about 232.8 TiB of memory",
            "limits.max_memory",
        ],
    );
    // Sub-steps and inner steps shrink the sampling interval of a (short) delay line.
    refused(
        "substeps-1e9-delay",
        &tmd(TMD_SPECIMEN, SERVO, "substeps = 1000000000"),
        &[
            "substructure.actuator.delay",
            "sampled every 1.000e-12 s",
            "limits.max_memory",
        ],
    );
    refused(
        "inner-1e9-delay",
        &tmd(TMD_SPECIMEN, SERVO, "substeps = 4\ninner_steps = 1000000000"),
        &[
            "substructure.actuator.delay",
            "sampled every 2.500e-12 s",
            "limits.max_memory",
        ],
    );
}

#[test]
fn steps_times_substeps_times_inner_steps_are_estimated_before_running() {
    refused(
        "substeps-1e9",
        &tmd(TMD_SPECIMEN, IDEAL, "substeps = 1000000000"),
        &[
            "substructure.substeps: 2000 steps of a 1-DOF model with 1000000000 sub-steps of 1 inner steps",
            "of computation (estimate), more than limits.max_run_time = 60.0 min",
            "set [limits] max_run_time",
        ],
    );
    refused(
        "inner-1e9",
        &tmd(TMD_SPECIMEN, IDEAL, "substeps = 4\ninner_steps = 1000000000"),
        &["substructure.inner_steps: 2000 steps", "limits.max_run_time"],
    );
    // Affordable in time, but substeps.csv would fill the disk: refused up front.
    refused(
        "substeps-output",
        &tmd(TMD_SPECIMEN, IDEAL, "substeps = 100000"),
        &[
            "substructure.substeps: 2000 steps of a 1-DOF model with 100000 sub-steps",
            "writes about 26.8 GiB of history.csv and substeps.csv (estimate)",
            "limits.max_output_bytes = 4.0 GiB",
        ],
    );
    refused(
        "steps",
        &tmd(TMD_SPECIMEN, IDEAL, "substeps = 4").replace("duration = 20.0", "duration = 1e7"),
        &[
            "integrator.dt: a 10000000 s excitation at dt = 0.01 s",
            "limits.max_memory",
        ],
    );
}

#[test]
fn extreme_finite_specimens_are_refused_not_hung_or_panicking() {
    let specimen = |k: &str, m: &str, c: &str| format!("mass = {m}\nstiffness = {k}\ndamping = {c}");
    // Was: panic in the matrix exponential (1e60), endless balancing (1e90), unnamed
    // "matrix exponential is not finite" (1e30).
    for k in ["1e30", "1e60", "1e80", "1e90"] {
        refused(
            &format!("k-{k}"),
            &tmd(&specimen(k, "50.0", "62.8"), IDEAL, "substeps = 4"),
            &[
                "substructure.specimen[1].stiffness: stiffness",
                "against a mass of 1.000e3 kg at DOF 1 at dt = 0.01 s",
                "outside what f64 can integrate",
            ],
        );
    }
    for (m, c) in [("1e-300", "62.8"), ("50.0", "1e308")] {
        refused(
            &format!("m-{m}-c-{c}"),
            &tmd(&specimen("1973.9", m, c), IDEAL, "substeps = 4"),
            &[
                "substructure.specimen[1]: its internal dynamics",
                "outside what f64 can integrate",
            ],
        );
    }
}

#[test]
fn devices_and_fifos_are_refused_without_reading() {
    let dir = temp_dir("special");
    let record = |file: &str| {
        format!(
            "[structure.sdof]\nmass = 1.0\nstiffness = 100.0\n[ground_motion]\nfile = \"{file}\"\n[integrator]\ndt = 0.01\nduration = 1.0\n"
        )
    };
    let status = Command::new("mkfifo")
        .arg(dir.join("fifo"))
        .status()
        .expect("mkfifo runs");
    assert!(status.success());
    for (name, file) in [("zero", "/dev/zero"), ("urandom", "/dev/urandom"), ("fifo", "fifo")] {
        std::fs::write(dir.join(format!("{name}.toml")), record(file)).unwrap();
        refused_in(
            &dir,
            &format!("{name}.toml"),
            &[&format!("ground_motion.file: {file}: is not a regular file")],
        );
    }
    let matrices = "[structure]\nmass = \"/dev/urandom\"\nstiffness = \"fifo\"\n";
    std::fs::write(dir.join("mtx.toml"), format!("{matrices}{HARMONIC}")).unwrap();
    refused_in(
        &dir,
        "mtx.toml",
        &["structure.mass: /dev/urandom: is not a regular file"],
    );
    // The config itself.
    let (code, stderr) = run(&dir, "fifo");
    assert_eq!(code, 2, "{stderr}");
    assert_eq!(
        stderr.trim_end(),
        "error: fifo: is not a regular file (a device, FIFO or socket is never read as input)"
    );
    // The benchmark's settings and record, a study file: the same bounded reader.
    for file in ["/dev/zero", "fifo"] {
        for args in [
            vec![
                "benchmark",
                "rths",
                "--case",
                "1",
                "--config",
                file,
                "--no-plots",
                "--out",
                "out",
            ],
            vec![
                "benchmark",
                "rths",
                "--case",
                "1",
                "--record",
                file,
                "--no-plots",
                "--out",
                "out",
            ],
            vec!["study", file, "--out", "out", "--quiet"],
        ] {
            let (code, stderr) = run_args(&dir, &args);
            assert_eq!(code, 2, "{args:?}: {stderr}");
            assert_eq!(
                stderr.trim_end(),
                format!("error: {file}: is not a regular file (a device, FIFO or socket is never read as input)"),
                "{args:?}"
            );
        }
    }
    // A site file, too.
    for file in ["/dev/zero", "fifo"] {
        let (code, stderr) = run_args(&dir, &["site", "serve", file, "--once"]);
        assert_eq!(code, 2, "{stderr}");
        assert_eq!(
            stderr.trim_end(),
            format!("error: {file}: is not a regular file (a device, FIFO or socket is never read as input)")
        );
    }
}

#[test]
fn limits_are_keys_that_can_be_tightened_and_checked() {
    let dir = temp_dir("file-limit");
    let rows: String = (0..2001).map(|i| format!("{},{}\n", i as f64 * 0.01, 0.0)).collect();
    let size = format!("is {:.1} KiB", rows.len() as f64 / 1024.0);
    std::fs::write(dir.join("ag.csv"), rows).unwrap();
    let config = "[structure.sdof]\nmass = 1.0\nstiffness = 100.0\n[ground_motion]\nfile = \"ag.csv\"\n\
                  [integrator]\ndt = 0.01\n[limits]\nmax_file_bytes = 1000\n";
    std::fs::write(dir.join("small.toml"), config).unwrap();
    refused_in(
        &dir,
        "small.toml",
        &[&format!(
            "ground_motion.file: ag.csv: {size}, more than limits.max_file_bytes = 1000 B"
        )],
    );
    refused(
        "run-time",
        &format!(
            "{}\n[limits]\nmax_run_time = 1e-6\n",
            tmd(TMD_SPECIMEN, SERVO, "substeps = 4")
        ),
        &["more than limits.max_run_time = 0.00 s"],
    );
    refused(
        "bad-limit",
        &format!(
            "{}\n[limits]\nmax_memory = -1\n",
            tmd(TMD_SPECIMEN, SERVO, "substeps = 4")
        ),
        &["limits.max_memory: must be a finite number > 0, got -1"],
    );
    // Within the default limits the same kind of run goes through.
    let dir = temp_dir("within");
    std::fs::write(dir.join("ok.toml"), tmd(TMD_SPECIMEN, SERVO, "substeps = 4")).unwrap();
    let (code, stderr) = run(&dir, "ok.toml");
    assert_eq!(code, 0, "{stderr}");
}
