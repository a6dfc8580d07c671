//! Issue 27: `[substructure.lab]` against `substep lab emulate` on loopback — every protocol
//! equals the virtual lab, injected faults give the documented behaviour without a hang, and
//! bad input is one line with exit code 2.

#[path = "../../substep/tests/common/frame3d_scaled.rs"]
mod frame3d_scaled;

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

const DEFAULT: &str = include_str!("../../../examples/default.toml");

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("substep-lab-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_substep"))
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// The default example, 4 s (400 steps of 10 ms, 4 sub-steps each), with `lab` appended.
fn config(lab: &str) -> String {
    format!("{}\n{lab}\n", DEFAULT.replace("duration = 20.0", "duration = 4.0"))
}

fn lab_table(protocol: &str, transport: &str, port: u16, extra: &str) -> String {
    format!(
        "[substructure.lab]\nprotocol = \"{protocol}\"\ntransport = \"{transport}\"\naddress = \"127.0.0.1:{port}\"\n{extra}"
    )
}

/// Start `substep lab emulate` for the test `test` (its `[substructure.lab]` gives the
/// protocol) with `faults`; returns the child and its port.
fn emulate(dir: &Path, name: &str, faults: &str) -> (Child, u16) {
    std::fs::write(
        dir.join(format!("{name}.emu.toml")),
        format!("test = \"{name}.toml\"\nidle = 20.0\n{faults}\n"),
    )
    .unwrap();
    let mut child = bin()
        .args(["lab", "emulate", &format!("{name}.emu.toml"), "--bind", "127.0.0.1:0"])
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.as_mut().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert!(line.starts_with("lab emulator: "), "{line}");
    let port = line
        .split("127.0.0.1:")
        .nth(1)
        .unwrap()
        .split(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    (child, port)
}

/// Run `cfg` to its end or kill it after 60 s (a hang fails the test instead of blocking it).
fn run(dir: &Path, cfg: &str, out: &str) -> Output {
    run_with(dir, cfg, out, &[])
}

/// As [`run`] with more options (e.g. `--realtime`).
fn run_with(dir: &Path, cfg: &str, out: &str, more: &[&str]) -> Output {
    let mut child = bin()
        .args(["run", cfg, "--out", out, "--quiet", "--no-plots"])
        .args(more)
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            panic!("{cfg}: substep run hung");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

/// A lab test against a fresh emulator: write the test with `port` filled in after the
/// emulator bound, run it, wait for the emulator. `(run output, summary.json)`.
fn lab_run(
    dir: &Path,
    name: &str,
    protocol: &str,
    transport: &str,
    extra: &str,
    faults: &str,
) -> (Output, serde_json::Value) {
    // The emulator reads the test for the protocol and channels; the address is its own.
    std::fs::write(
        dir.join(format!("{name}.toml")),
        config(&lab_table(protocol, transport, 9, extra)),
    )
    .unwrap();
    let (mut emulator, port) = emulate(dir, name, faults);
    std::fs::write(
        dir.join(format!("{name}.toml")),
        config(&lab_table(protocol, transport, port, extra)),
    )
    .unwrap();
    let out = run(dir, &format!("{name}.toml"), name);
    let start = Instant::now();
    while emulator.try_wait().unwrap().is_none() {
        if start.elapsed() > Duration::from_secs(30) {
            let _ = emulator.kill();
            panic!("{name}: the emulator did not end its session");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    // The emulator's report ("session ended: …; N sub-steps, …") for the tests that read it.
    let rest = emulator.wait_with_output().unwrap();
    std::fs::write(dir.join(format!("{name}.emu.out")), &rest.stdout).unwrap();
    let summary = std::fs::read_to_string(dir.join(name).join("summary.json")).unwrap();
    (out, serde_json::from_str(&summary).unwrap())
}

fn table(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let t = std::fs::read_to_string(path).unwrap();
    let mut lines = t.lines();
    let head = lines.next().unwrap().split(',').map(str::to_owned).collect();
    let rows = lines
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    (head, rows)
}

/// Largest difference of each column of `reference` relative to its peak, against the column
/// of the same name in `other`, which must have every column but `fei` (the virtual lab's
/// noise-free force, which a lab target cannot report).
fn worst_relative(reference: &Path, other: &Path) -> f64 {
    let (h1, a) = table(reference);
    let (h2, b) = table(other);
    assert_eq!(a.len(), b.len(), "{}", other.display());
    h1.iter()
        .enumerate()
        .filter(|(_, name)| !name.starts_with("fei"))
        .map(|(j, name)| {
            let k = h2
                .iter()
                .position(|n| n == name)
                .unwrap_or_else(|| panic!("{name} missing"));
            let peak = a.iter().map(|r| r[j].abs()).fold(0.0, f64::max).max(1e-300);
            a.iter().zip(&b).map(|(x, y)| (x[j] - y[k]).abs()).fold(0.0, f64::max) / peak
        })
        .fold(0.0, f64::max)
}

#[test]
fn every_protocol_against_the_emulator_equals_the_virtual_lab() {
    let dir = temp_dir("equal");
    std::fs::write(dir.join("local.toml"), config("")).unwrap();
    let local = run(&dir, "local.toml", "local");
    assert!(local.status.success(), "{}", text(&local.stderr));
    for (protocol, transport) in [
        ("speedgoat", "udp"),
        ("speedgoat", "tcp"),
        ("generic_tcp", "tcp"),
        ("substep_udp", "udp"),
    ] {
        let name = format!("{protocol}_{transport}");
        let (out, s) = lab_run(&dir, &name, protocol, transport, "timeout = 2.0\n", "");
        assert!(out.status.success(), "{name}: {}", text(&out.stderr));
        assert_eq!(s["completed"], true, "{name}");
        for file in ["history.csv", "substeps.csv"] {
            let worst = worst_relative(&dir.join("local").join(file), &dir.join(&name).join(file));
            assert!(worst <= 1e-9, "{name} {file}: {worst:e} of the peak");
        }
        // Per sub-step: nothing held, no strays.
        let (head, rows) = table(&dir.join(&name).join("substeps.csv"));
        let held = head.iter().position(|c| c == "held").unwrap();
        assert!(rows.iter().all(|r| r[held] == 0.0 && r[held + 1] == 0.0), "{name}");
        let l = &s["lab"];
        assert_eq!(
            (l["protocol"].as_str(), l["transport"].as_str()),
            (Some(protocol), Some(transport))
        );
        assert_eq!(l["exchanges"], 1600, "{name}: one exchange per sub-step");
        assert_eq!(l["held"], 0, "{name}");
        assert!(l["rtt_us"]["p50"].as_f64().unwrap() > 0.0, "{name}: {l}");
    }
}

#[test]
fn injected_faults_give_the_documented_behaviour() {
    let dir = temp_dir("faults");
    std::fs::write(dir.join("local.toml"), config("")).unwrap();
    assert!(run(&dir, "local.toml", "local").status.success());
    let udp = |name: &str, extra: &str, faults: &str| lab_run(&dir, name, "substep_udp", "udp", extra, faults);
    // Lost, duplicated and reordered replies with a generous budget: the resend at half the
    // budget recovers every lost reply, the stray copies are discarded and counted, and the
    // test equals the virtual lab.
    for (name, faults, counted) in [
        ("loss", "[faults]\nloss = 0.01\n", "resent"),
        ("duplicates", "[faults]\nduplicate = 0.05\n", "duplicated"),
        ("reordering", "[faults]\nreorder = 0.05\n", "duplicated"),
    ] {
        let (out, s) = udp(name, "timeout = 0.2\n", faults);
        assert!(out.status.success(), "{name}: {}", text(&out.stderr));
        assert_eq!(s["lab"]["held"], 0, "{name}: {}", s["lab"]);
        assert!(s["lab"][counted].as_u64().unwrap() > 0, "{name}: {}", s["lab"]);
        let worst = worst_relative(&dir.join("local/history.csv"), &dir.join(name).join("history.csv"));
        assert!(worst <= 1e-9, "{name}: {worst:e}");
    }
    // A 50 ms stall against 5 ms budgets: with 3 holds allowed the target counts as gone (exit
    // 1, controlled stop, records kept); with 40 allowed the test rides through it, holding
    // the last measurement, and says so.
    let (out, s) = udp(
        "stall_stop",
        "timeout = 0.005\nhold_limit = 3\n",
        "[faults]\nstall = [1.0, 0.05]\n",
    );
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    assert!(
        text(&out.stderr).contains("the target is gone"),
        "{}",
        text(&out.stderr)
    );
    assert_eq!(s["completed"], false);
    assert_eq!(s["lab"]["max_held_in_a_row"], 4);
    assert!(table(&dir.join("stall_stop/history.csv")).1.len() > 90);
    let (out, s) = udp(
        "stall_ride",
        "timeout = 0.005\nhold_limit = 40\n",
        "[faults]\nstall = [1.0, 0.05]\n",
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let held = s["lab"]["held"].as_u64().unwrap();
    assert!((5..=11).contains(&held), "{}", s["lab"]);
    assert!(
        s["warnings"].to_string().contains("held the last measurement"),
        "{}",
        s["warnings"]
    );
    let (head, rows) = table(&dir.join("stall_ride/substeps.csv"));
    let col = head.iter().position(|c| c == "held").unwrap();
    let marked = rows.iter().filter(|r| r[col] == 1.0).count() as u64;
    assert_eq!(marked, held, "substeps.csv marks the held sub-steps");
    // A killed target: over UDP silence (holds, then gone); over TCP a closed connection.
    let (out, s) = udp("dead_udp", "timeout = 0.01\n", "[faults]\ndie_at = 2.0\n");
    assert_eq!(out.status.code(), Some(1));
    assert!(
        text(&out.stderr).contains("the target is gone"),
        "{}",
        text(&out.stderr)
    );
    assert_eq!(s["stopped_at_step"], 201);
    let (out, s) = lab_run(
        &dir,
        "dead_tcp",
        "speedgoat",
        "tcp",
        "timeout = 0.5\n",
        "[faults]\ndie_at = 2.0\n",
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(
        text(&out.stderr).contains("closed the connection"),
        "{}",
        text(&out.stderr)
    );
    assert_eq!(s["completed"], false);
}

#[test]
fn bad_lab_input_is_one_line_with_exit_code_2() {
    let dir = temp_dir("bad");
    for (extra, message) in [
        (
            "[substructure.lab]\nprotocol = \"ethercat\"\naddress = \"127.0.0.1:5000\"",
            "substructure.lab.protocol: unknown protocol 'ethercat'",
        ),
        (
            "[substructure.lab]\nprotocol = \"substep_udp\"\naddress = \"127.0.0.1:5000\"\nsignals = 2\n\
             [[substructure.lab.measured]]\nsignal = 9\nquantity = \"force\"\ndof = 1",
            "substructure.lab.measured[1].signal: signal 9 is out of range",
        ),
        (
            "[substructure.lab]\nprotocol = \"speedgoat\"\naddress = \"127.0.0.1:5000\"\n\
             [[substructure.lab.command]]\ndof = 1\ngain = 0.0",
            "substructure.lab.command[1].gain: must be a finite number other than 0",
        ),
        (
            "[substructure.lab]\nprotocol = \"speedgoat\"\naddress = \"192.0.2.7:5000\"",
            "substructure.lab.address: 192.0.2.7:5000 is not a loopback address",
        ),
        (
            "[substructure.lab]\nprotocol = \"generic_tcp\"\ntransport = \"udp\"\naddress = \"127.0.0.1:5000\"",
            "substructure.lab.transport: generic_tcp runs over tcp",
        ),
        (
            "[substructure.lab]\nprotocol = \"speedgoat\"\naddress = \"127.0.0.1:5000\"\nsignals = 300",
            "substructure.lab.signals: 300 measured signals do not fit a speedgoat frame (at most 254)",
        ),
        (
            "[substructure.lab]\nprotocol = \"speedgoat\"\naddress = \"127.0.0.1:5000\"\n\
             [[substructure.lab.command]]\ndof = 7",
            "substructure.lab.command[1].dof: DOF 7 is not a coupling DOF",
        ),
    ] {
        std::fs::write(dir.join("bad.toml"), config(extra)).unwrap();
        let out = run(&dir, "bad.toml", "out");
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{extra}: {err}");
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(err.starts_with("error: ") && err.contains(message), "{message}: {err}");
    }
    // The emulator: a target file whose test has no [substructure.lab].
    std::fs::write(dir.join("plain.toml"), config("")).unwrap();
    std::fs::write(dir.join("e.toml"), "test = \"plain.toml\"\n").unwrap();
    let out = bin()
        .args(["lab", "emulate", "e.toml"])
        .current_dir(&dir)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("the test has no [substructure.lab]"),
        "{}",
        text(&out.stderr)
    );
}

/// Safety stays on the host: the same displacement limit stops the lab test at the same step as
/// the virtual one, and the ramp to the safe position goes to the target sub-step by sub-step,
/// the same commands in `substeps.csv`.
#[test]
fn safety_limits_stop_a_lab_test_as_they_stop_the_virtual_one() {
    let dir = temp_dir("limits");
    let limits = "[substructure.limits]\ndisplacement = 0.05\nramp_time = 0.2\n";
    std::fs::write(dir.join("local.toml"), config(limits)).unwrap();
    let local = run(&dir, "local.toml", "local");
    assert_eq!(local.status.code(), Some(1), "{}", text(&local.stderr));
    assert!(text(&local.stderr).contains("safety stop: measured displacement"));
    let (out, s) = lab_run(
        &dir,
        "lab",
        "substep_udp",
        "udp",
        &format!("timeout = 2.0\n{limits}"),
        "",
    );
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    let local_summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("local/summary.json")).unwrap()).unwrap();
    assert_eq!(s["stopped_at_step"], local_summary["stopped_at_step"]);
    assert_eq!(s["ramp_substeps"], 80);
    assert_eq!(s["lab"]["held"], 0);
    let (h1, a) = table(&dir.join("local/substeps.csv"));
    let (h2, b) = table(&dir.join("lab/substeps.csv"));
    let ramp = |h: &[String]| h.iter().position(|c| c == "ramp").unwrap();
    let (r1, r2) = (ramp(&h1), ramp(&h2));
    let ramp_rows =
        |rows: &[Vec<f64>], r: usize| rows.iter().filter(|x| x[r] > 0.0).map(|x| x[3]).collect::<Vec<f64>>();
    let (ca, cb) = (ramp_rows(&a, r1), ramp_rows(&b, r2));
    assert_eq!(ca.len(), 80);
    assert_eq!(ca, cb, "the ramp commands");
    assert_eq!(*cb.last().unwrap(), 0.0);
    // The target executed every sub-step the host recorded, the ramp's included.
    let emulated = std::fs::read_to_string(dir.join("lab.emu.out")).unwrap();
    assert!(
        emulated.contains(&format!("; {} sub-steps,", b.len())),
        "{emulated} vs {} rows",
        b.len()
    );
}

/// `--realtime` against a lab target that dies: exit 1 with the target named, and the link's
/// counts are in `summary.json` although the run failed.
#[test]
fn a_realtime_run_whose_target_dies_reports_the_link() {
    let dir = temp_dir("realtime");
    let name = "rt";
    let extra = "timeout = 0.005\n";
    std::fs::write(dir.join("rt.toml"), config(&lab_table("substep_udp", "udp", 9, extra))).unwrap();
    let (mut emulator, port) = emulate(&dir, name, "[faults]\ndie_at = 0.5\n");
    std::fs::write(
        dir.join("rt.toml"),
        config(&lab_table("substep_udp", "udp", port, extra)),
    )
    .unwrap();
    let out = run_with(&dir, "rt.toml", "rt", &["--realtime"]);
    let _ = emulator.kill();
    let _ = emulator.wait();
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    assert!(
        text(&out.stderr).contains("the target is gone"),
        "{}",
        text(&out.stderr)
    );
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("rt/summary.json")).unwrap()).unwrap();
    assert_eq!(s["completed"], false);
    let lab = &s["lab"];
    assert_eq!(lab["protocol"], "substep_udp", "{s}");
    assert_eq!(lab["max_held_in_a_row"], 4, "{lab}");
    // 0.5 s of 2.5 ms sub-steps answered, then 4 held: about 204 exchanges.
    let n = lab["exchanges"].as_u64().unwrap();
    assert!((200..=210).contains(&n), "{lab}");
}

/// Issue 38: a yielding numerical substructure (examples/yielding_building.toml, cut to 7 s, where it yields: yielding_examples_in_real_time_equal_the_offline_run)
/// with a lab target: every protocol against the emulator equals the virtual-lab run, offline
/// and with `--realtime --late-policy wait` (the one-sub-step springs pipeline).
#[test]
fn a_yielding_structure_with_a_lab_target_equals_the_virtual_lab() {
    let s = lab_runs_equal_the_virtual_lab(
        "yielding_building",
        &[
            ("speedgoat", "udp", false),
            ("speedgoat", "tcp", false),
            ("generic_tcp", "tcp", false),
            ("substep_udp", "udp", false),
            ("substep_udp", "udp", true),
        ],
    );
    assert_eq!(s["scheme"], "average_acceleration");
}

/// A CR test (issue 38, docs/theory.md §2.9: the explicit scheme commands the coupling DOF
/// itself) against the emulator equals its virtual-lab run, offline and in real time, as the
/// sub-step algorithm's does.
#[test]
fn a_cr_test_with_a_lab_target_equals_the_virtual_lab() {
    let s = lab_runs_equal_the_virtual_lab(
        "yielding_building_cr",
        &[
            ("speedgoat", "udp", false),
            ("generic_tcp", "tcp", false),
            ("substep_udp", "udp", true),
        ],
    );
    assert_eq!(s["scheme"], "cr");
}

/// A reduced numerical substructure (issue 42: `[structure.reduction]`, here the space frame of
/// examples/frame3d_reduced.toml scaled down to 2 × 2 bays and 4 storeys, 120 DOFs reduced to
/// 2 + 12 Ritz vectors) against the emulator, offline and in real time, equals its virtual-lab
/// run: the lab sees the reduced model's coupling DOF as the structure's own.
#[test]
fn a_reduced_structure_with_a_lab_target_equals_the_virtual_lab() {
    let examples = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples");
    let text = std::fs::read_to_string(format!("{examples}/frame3d_reduced.toml")).unwrap();
    let base = frame3d_scaled::scaled_frame3d(&text)
        .replace("\"records/", &format!("\"{examples}/records/"))
        .replace("duration = 12.0\n", "duration = 7.0\n");
    assert!(
        base.contains("duration = 7.0\n"),
        "frame3d_reduced.toml changed: adapt this test"
    );
    let s = lab_runs_equal(
        "reduced",
        &base,
        7000,
        &[("speedgoat", "udp", false), ("substep_udp", "udp", true)],
    );
    assert_eq!(s["reduction"]["method"], "ritz");
    assert_eq!(s["reduction"]["reduced_dofs"], 14);
}

/// `examples/<example>.toml` shortened to 7 s, run locally (virtual lab), then against the
/// emulator once per `(protocol, transport, realtime)` (real time with `--late-policy wait`):
/// each run completes with one exchange per sub-step and its history (and, offline,
/// substeps.csv) within 1e-9 of the local run's peaks. Returns the local run's summary.
fn lab_runs_equal_the_virtual_lab(example: &str, cases: &[(&str, &str, bool)]) -> serde_json::Value {
    let examples = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples");
    let base = std::fs::read_to_string(format!("{examples}/{example}.toml"))
        .unwrap()
        .replace("\"records/", &format!("\"{examples}/records/"))
        .replace("duration = 20.0", "duration = 7.0");
    assert!(
        base.contains("duration = 7.0"),
        "{example}.toml changed: adapt this test"
    );
    lab_runs_equal(example, &base, 14000, cases)
}

/// [`lab_runs_equal_the_virtual_lab`] for the test definition `base` (`exchanges`: steps ×
/// sub-steps).
fn lab_runs_equal(tag: &str, base: &str, exchanges: u64, cases: &[(&str, &str, bool)]) -> serde_json::Value {
    let (example, dir) = (tag, temp_dir(tag));
    let write =
        |name: &str, lab: &str| std::fs::write(dir.join(format!("{name}.toml")), format!("{base}\n{lab}\n")).unwrap();
    let summary = |name: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(dir.join(name).join("summary.json")).unwrap()).unwrap()
    };
    write("local", "");
    let local = run(&dir, "local.toml", "local");
    assert!(local.status.success(), "{}", text(&local.stderr));
    for &(protocol, transport, realtime) in cases {
        let name = format!("{protocol}_{transport}{}", if realtime { "_rt" } else { "" });
        write(&name, &lab_table(protocol, transport, 9, "timeout = 2.0\n"));
        let (mut emulator, port) = emulate(&dir, &name, "");
        write(&name, &lab_table(protocol, transport, port, "timeout = 2.0\n"));
        let more: &[&str] = if realtime {
            &["--realtime", "--late-policy", "wait", "--max-missed", "1"]
        } else {
            &[]
        };
        let out = run_with(&dir, &format!("{name}.toml"), &name, more);
        let _ = emulator.wait();
        assert!(out.status.success(), "{example} {name}: {}", text(&out.stderr));
        let s = summary(&name);
        assert_eq!(s["completed"], true, "{example} {name}");
        assert_eq!(
            s["lab"]["exchanges"], exchanges,
            "{example} {name}: one exchange per sub-step"
        );
        let files: &[&str] = if realtime {
            &["history.csv"]
        } else {
            &["history.csv", "substeps.csv"]
        };
        for &file in files {
            let worst = worst_relative_common(&dir.join("local").join(file), &dir.join(&name).join(file));
            assert!(worst <= 1e-9, "{example} {name} {file}: {worst:e} of the peak");
        }
    }
    summary("local")
}

/// As [`worst_relative`] over the columns both files have (a real-time history has no
/// phase-lag columns); at least five of them.
fn worst_relative_common(reference: &Path, other: &Path) -> f64 {
    let (h1, a) = table(reference);
    let (h2, b) = table(other);
    assert_eq!(a.len(), b.len(), "{}", other.display());
    let mut compared = 0;
    let worst = h1
        .iter()
        .enumerate()
        .filter(|(_, name)| !name.starts_with("fei"))
        .filter_map(|(j, name)| Some((j, h2.iter().position(|n| n == name)?)))
        .map(|(j, k)| {
            compared += 1;
            let peak = a.iter().map(|r| r[j].abs()).fold(0.0, f64::max).max(1e-300);
            a.iter().zip(&b).map(|(x, y)| (x[j] - y[k]).abs()).fold(0.0, f64::max) / peak
        })
        .fold(0.0, f64::max);
    assert!(compared >= 5, "{}: {compared} columns in common", other.display());
    worst
}
