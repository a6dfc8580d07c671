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
    let args: Vec<String> = args.iter().map(|a| a.to_string()).collect();
    let (code, stderr, _, _) = run_measured(dir, &args);
    (code, stderr)
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
    // Every other command and file slot: every_command_refuses_special_files_and_huge_records_within_64_mb.
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
    // The record's numbers are counted before it is kept: 2001 rows are 4002 numbers.
    let config = "[structure.sdof]\nmass = 1.0\nstiffness = 100.0\n[ground_motion]\nfile = \"ag.csv\"\n\
                  [integrator]\ndt = 0.01\n[limits]\nmax_record_values = 4001\n";
    std::fs::write(dir.join("values.toml"), config).unwrap();
    refused_in(
        &dir,
        "values.toml",
        &["ground_motion.file: ag.csv: holds more than limits.max_record_values = 4001 numbers"],
    );
    std::fs::write(dir.join("values.toml"), config.replace("4001", "4002")).unwrap();
    let (code, stderr) = run(&dir, "values.toml");
    assert_eq!(code, 0, "4002 numbers within max_record_values = 4002: {stderr}");
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

/// `substep ARGS` in `dir`: (exit code, stderr, peak resident memory in bytes, wall time), from
/// `wait4` on the child. Killed (and the test failed) after 60 s: a hang guard, not a timing
/// goal.
// The child is reaped by wait4 (for its rusage), which clippy cannot see.
#[allow(clippy::zombie_processes)]
fn run_measured(dir: &Path, args: &[String]) -> (i32, String, u64, Duration) {
    let started = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_substep"))
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the substep binary runs");
    let pid = child.id() as libc::pid_t;
    let mut stderr = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = std::io::Read::read_to_string(&mut stderr, &mut text);
        text
    });
    let (mut status, mut usage) = (0, unsafe { std::mem::zeroed::<libc::rusage>() });
    loop {
        // SAFETY: plain wait4 on our own child; status and usage are valid out-pointers.
        let r = unsafe { libc::wait4(pid, &mut status, libc::WNOHANG, &mut usage) };
        assert!(r >= 0, "wait4 failed");
        if r == pid {
            break;
        }
        if started.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            panic!("substep {args:?} did not finish (hang or runaway work)");
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    let elapsed = started.elapsed();
    let code = if libc::WIFEXITED(status) {
        libc::WEXITSTATUS(status)
    } else {
        -1
    };
    // ru_maxrss is in KiB on Linux.
    (code, reader.join().unwrap(), usage.ru_maxrss as u64 * 1024, elapsed)
}

/// Issue 25: every command that reads a file refuses `/dev/zero`, a FIFO and a record of 10⁸
/// rows in every place a file goes — the config itself, a ground-motion record, a `.mtx`
/// matrix, a study file, its base and the base's record, the benchmark's settings and record,
/// a site file — with exit 2 and one line naming the file, and within 64 MB of peak memory
/// (wait4's ru_maxrss of the process). The times are printed (`--nocapture`), not asserted.
#[test]
fn every_command_refuses_special_files_and_huge_records_within_64_mb() {
    let dir = temp_dir("table");
    assert!(Command::new("mkfifo").arg(dir.join("fifo")).status().unwrap().success());
    // The smallest honest 10⁸-row record: one value per line (200 MB).
    {
        let mut f = std::io::BufWriter::new(std::fs::File::create(dir.join("rows.txt")).unwrap());
        let chunk = "0\n".repeat(1_000_000);
        for _ in 0..100 {
            std::io::Write::write_all(&mut f, chunk.as_bytes()).unwrap();
        }
    }
    let sdof_with_record = |file: &str| {
        format!(
            "[structure.sdof]\nmass = 1.0\nstiffness = 100.0\n[ground_motion]\nfile = \"{file}\"\ndt = 0.01\n[integrator]\ndt = 0.01\nduration = 1.0\n"
        )
    };
    let tmd_with_record = |file: &str| {
        tmd(TMD_SPECIMEN, SERVO, "substeps = 2").replace(
            HARMONIC,
            &format!("[ground_motion]\nfile = \"{file}\"\ndt = 0.01\n[integrator]\nscheme = \"average_acceleration\"\ndt = 0.01\nduration = 1.0\n"),
        )
    };
    let matrix = |file: &str| format!("[structure]\nmass = \"{file}\"\nstiffness = [[1.0]]\n{HARMONIC}");
    let mut table = Vec::new();
    for (kind, file) in [
        ("/dev/zero", "/dev/zero"),
        ("FIFO", "fifo"),
        ("10^8-row record", "rows.txt"),
    ] {
        let key = kind.replace(['/', '^'], "_");
        let write = |name: &str, text: String| {
            let name = format!("{key}-{name}");
            std::fs::write(dir.join(&name), text).unwrap();
            name
        };
        let record_cfg = write("record.toml", sdof_with_record(file));
        let matrix_cfg = write("matrix.toml", matrix(file));
        let plan_cfg = write("plan.toml", tmd_with_record(file));
        let base_cfg = write("base.toml", sdof_with_record(file));
        let study_base = write(
            "study_base.toml",
            format!("base = \"{file}\"\n[grid]\n\"structure.sdof.mass\" = [1.0]\n"),
        );
        let study_record = write(
            "study_record.toml",
            format!("base = \"{base_cfg}\"\n[grid]\n\"structure.sdof.mass\" = [1.0]\n"),
        );
        let cases: Vec<(&str, Vec<String>)> = vec![
            ("run CONFIG", vec!["run".into(), file.into()]),
            ("run: ground_motion.file", vec!["run".into(), record_cfg.clone()]),
            ("run: structure.mass (.mtx)", vec!["run".into(), matrix_cfg.clone()]),
            (
                "analyze plan CONFIG",
                vec!["analyze".into(), "plan".into(), file.into()],
            ),
            (
                "analyze plan: ground_motion.file",
                vec!["analyze".into(), "plan".into(), plan_cfg],
            ),
            (
                "model export CONFIG",
                vec!["model".into(), "export".into(), file.into(), "--mtx".into(), "m".into()],
            ),
            (
                "model export: structure.mass",
                vec!["model".into(), "export".into(), matrix_cfg, "--mtx".into(), "m".into()],
            ),
            (
                "model export: ground_motion.file",
                vec!["model".into(), "export".into(), record_cfg, "--mtx".into(), "m".into()],
            ),
            ("study FILE", vec!["study".into(), file.into()]),
            ("study: base", vec!["study".into(), study_base]),
            ("study: the base's record", vec!["study".into(), study_record]),
            (
                "benchmark rths --config",
                vec!["benchmark".into(), "rths".into(), "--config".into(), file.into()],
            ),
            (
                "benchmark rths --record",
                vec!["benchmark".into(), "rths".into(), "--record".into(), file.into()],
            ),
            (
                "site serve FILE",
                vec!["site".into(), "serve".into(), file.into(), "--once".into()],
            ),
        ];
        for (what, mut args) in cases {
            if args[0] == "run" || args[0] == "study" || args[0] == "benchmark" {
                args.extend(["--out".into(), "out".into()]);
            }
            if args[0] == "run" || args[0] == "benchmark" {
                args.push("--no-plots".into());
            }
            let (code, stderr, peak, took) = run_measured(&dir, &args);
            let line = stderr.trim_end();
            assert_eq!(code, 2, "{what} with {kind}: exit code; stderr: {stderr}");
            assert_eq!(stderr.lines().count(), 1, "{what} with {kind}: one line: {stderr}");
            assert!(
                line.starts_with("error: ") && line.contains(&format!("{file}: ")),
                "{what} with {kind}: names the file: {line}"
            );
            let reason_ok = [
                "is not a regular file",
                "a configuration file may have",
                "holds more than limits.max_record_values",
                "not a MatrixMarket file",
            ]
            .iter()
            .any(|r| line.contains(r));
            assert!(reason_ok, "{what} with {kind}: says why: {line}");
            assert!(
                peak < 64 << 20,
                "{what} with {kind}: peak memory {:.1} MB",
                peak as f64 / 1e6
            );
            assert!(!dir.join("out").exists(), "{what} with {kind}: nothing written");
            table.push(format!(
                "| {what} | {kind} | {:.3} | {:.1} |",
                took.as_secs_f64(),
                peak as f64 / 1e6
            ));
        }
    }
    println!("| command and file | input | wall [s] | peak memory [MB] |\n|---|---|---|---|");
    for row in table {
        println!("{row}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
