//! Two processes on loopback: `substep site serve` hosting the specimen and `substep run` with
//! `[substructure.remote]` give the same history as the local run, bit for bit; a site killed
//! mid-test and a limit violation end in a controlled stop with intact records.

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("substep-remote-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_substep"))
}

fn run(dir: &Path, cfg: &str, out: &str) -> Output {
    run_with(dir, cfg, out, &[])
}

fn run_with(dir: &Path, cfg: &str, out: &str, env: &[(&str, &str)]) -> Output {
    let mut cmd = bin();
    cmd.env_remove("SUBSTEP_SITE_SECRET");
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.args(["run", cfg, "--out", out, "--quiet", "--no-plots"])
        .current_dir(dir)
        .output()
        .unwrap()
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

const STRUCTURE: &str = r#"
[structure]
mass = [[2000.0, 0.0], [0.0, 1000.0]]
stiffness = [[1.2e5, -5.0e4], [-5.0e4, 5.0e4]]
damping = [[800.0, -300.0], [-300.0, 300.0]]

[ground_motion]
generator = "sine_sweep"
amplitude = 1.0
f0 = 0.3
f1 = 3.0
duration = DURATION

[integrator]
scheme = "average_acceleration"
dt = 0.01
"#;

const SPECIMENS: &str = r#"
[[PREFIXspecimen]]
kind = "linear_sdof"
dof = 2
mass = 60.0
stiffness = 3000.0
damping = 40.0

[[PREFIXspecimen]]
kind = "linear_sdof"
dof = 1
stiffness = 8000.0
damping = 100.0

[PREFIXactuator]
kind = "second_order"
frequency = 40.0
zeta = 0.7
delay = 0.0015

[PREFIXsensors]
force_noise = 2.0
displacement_noise = 1e-6
seed = 11
"#;

fn client_config(duration: f64, remote: Option<(&str, &str)>, extra: &str) -> String {
    let mut s = STRUCTURE.replace("DURATION", &duration.to_string());
    s.push_str("\n[substructure]\ncoupling_dofs = [1, 2]\nsubsteps = 4\n");
    s.push_str(&SPECIMENS.replace("PREFIX", "substructure."));
    s.push_str("\n[substructure.error_force]\nkind = \"pid\"\np = 1.0\n");
    if let Some((addr, mode)) = remote {
        s.push_str(&format!(
            "\n[substructure.remote]\naddress = \"{addr}\"\nmode = \"{mode}\"\ntimeout = 1.0\n"
        ));
    }
    s.push_str(extra);
    s
}

/// Start `substep site serve --once` on a free port; returns the child and its address.
fn serve(dir: &Path) -> (Child, String) {
    serve_with(dir, "", &[])
}

/// As [`serve`] with extra `[site]` keys and environment variables.
fn serve_with(dir: &Path, site_keys: &str, env: &[(&str, &str)]) -> (Child, String) {
    let site = format!(
        "[site]\nprotocol = \"substep\"\nlisten = \"127.0.0.1:0\"\n{site_keys}\n{}",
        SPECIMENS.replace("PREFIX", "")
    );
    std::fs::write(dir.join("site.toml"), site).unwrap();
    let mut cmd = bin();
    cmd.env_remove("SUBSTEP_SITE_SECRET");
    for (k, v) in env {
        cmd.env(k, v);
    }
    let mut child = cmd
        .args(["site", "serve", "site.toml", "--once"])
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.as_mut().unwrap())
        .read_line(&mut line)
        .unwrap();
    let addr = line.trim().rsplit("tcp://").next().unwrap().to_string();
    assert!(line.contains("listening on tcp://127.0.0.1:"), "{line}");
    (child, addr)
}

#[test]
fn remote_runs_equal_the_local_run_bit_for_bit() {
    let dir = temp_dir("equal");
    std::fs::write(dir.join("local.toml"), client_config(3.0, None, "")).unwrap();
    let local = run(&dir, "local.toml", "local");
    assert!(local.status.success(), "{}", text(&local.stderr));
    let local_history = std::fs::read_to_string(dir.join("local/history.csv")).unwrap();
    let local_substeps = std::fs::read_to_string(dir.join("local/substeps.csv")).unwrap();
    assert_eq!(local_history.lines().count(), 302);
    for mode in ["per_step", "per_substep"] {
        let (mut site, addr) = serve(&dir);
        let cfg = format!("remote_{mode}.toml");
        std::fs::write(dir.join(&cfg), client_config(3.0, Some((&addr, mode)), "")).unwrap();
        let out = run(&dir, &cfg, mode);
        assert!(out.status.success(), "{mode}: {}", text(&out.stderr));
        let history = std::fs::read_to_string(dir.join(mode).join("history.csv")).unwrap();
        let substeps = std::fs::read_to_string(dir.join(mode).join("substeps.csv")).unwrap();
        // the local run also records the noise-free error force (fei), which a remote site
        // cannot report: compare every other column
        let without_fei = |h: &str| -> Vec<String> {
            let header: Vec<&str> = h.lines().next().unwrap().split(',').collect();
            let keep: Vec<usize> = (0..header.len()).filter(|&i| !header[i].starts_with("fei")).collect();
            h.lines()
                .map(|l| {
                    let f: Vec<&str> = l.split(',').collect();
                    keep.iter().map(|&i| f[i]).collect::<Vec<_>>().join(",")
                })
                .collect()
        };
        assert!(history.contains("fc1") && !history.contains("fei"));
        assert!(
            without_fei(&history) == without_fei(&local_history),
            "{mode}: history differs from the local run"
        );
        assert!(substeps == local_substeps, "{mode}: substeps differ from the local run");
        let status = site.wait().unwrap();
        assert!(status.success(), "site exit {status:?}");
    }
}

#[test]
fn killing_the_site_stops_the_test_with_intact_records() {
    let dir = temp_dir("kill");
    let (mut site, addr) = serve(&dir);
    std::fs::write(
        dir.join("remote.toml"),
        client_config(600.0, Some((&addr, "per_substep")), ""),
    )
    .unwrap();
    let client = bin()
        .args(["run", "remote.toml", "--out", "out", "--quiet", "--no-plots"])
        .current_dir(&dir)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(700));
    site.kill().unwrap();
    site.wait().unwrap();
    let out = client.wait_with_output().unwrap();
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.starts_with("error: stopped at step ") && err.contains("experimental side failed"),
        "{err}"
    );
    assert!(err.contains(&addr), "the message names the site: {err}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/summary.json")).unwrap()).unwrap();
    assert_eq!(summary["completed"], false);
    let stopped = summary["stopped_at_step"].as_u64().unwrap() as usize;
    assert!(stopped > 10, "the test ran a while before the kill: {stopped}");
    let history = std::fs::read_to_string(dir.join("out/history.csv")).unwrap();
    // header + steps 0 ..= stopped - 1, every row complete and finite
    let rows: Vec<&str> = history.lines().skip(1).collect();
    assert_eq!(rows.len(), stopped);
    let head: Vec<&str> = history.lines().next().unwrap().split(',').collect();
    let width = head.len();
    // The stability indicator's columns (eta, margin, k_id1, …) are NaN until known.
    let indicator = head.iter().position(|h| *h == "eta").unwrap_or(width);
    assert!(rows.iter().all(|r| {
        let v: Vec<f64> = r.split(',').map(|v| v.parse().unwrap()).collect();
        v.len() == width && v[..indicator].iter().all(|x| x.is_finite())
    }));
}

#[test]
fn a_limit_violation_stops_the_test() {
    let dir = temp_dir("limit");
    let limits = "\n[substructure.limits]\ndisplacement = 0.01\nforce = 1e6\nramp_time = 0.2\n";
    std::fs::write(dir.join("local.toml"), client_config(20.0, None, limits)).unwrap();
    let out = run(&dir, "local.toml", "out");
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("safety stop: measured displacement") && err.contains("exceeds the limit 1e-2 m"),
        "{err}"
    );
    assert!(err.contains("actuators ramped to 0 over 0.2 s"), "{err}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/summary.json")).unwrap()).unwrap();
    assert_eq!(summary["completed"], false);
    let stopped = summary["stopped_at_step"].as_u64().unwrap() as usize;
    let history = std::fs::read_to_string(dir.join("out/history.csv")).unwrap();
    assert_eq!(history.lines().count(), 1 + stopped);
    // the limit was respected by every recorded measured displacement (columns dm1, dm2)
    let header: Vec<&str> = history.lines().next().unwrap().split(',').collect();
    let dm: Vec<usize> = header
        .iter()
        .enumerate()
        .filter(|(_, h)| h.starts_with("dm"))
        .map(|(i, _)| i)
        .collect();
    for row in history.lines().skip(1) {
        let f: Vec<f64> = row.split(',').map(|v| v.parse().unwrap()).collect();
        assert!(dm.iter().all(|&i| f[i].abs() <= 0.01));
    }
    // substeps.csv: the tripping sub-step, then the ramp to 0: 0.2 s in 2.5 ms sub-steps = 80
    // rows marked ramp = 1..=80, linear from the last command to exactly 0, time running on
    let offline = ramp_rows(&dir.join("out/substeps.csv"), stopped);
    assert_eq!(offline.len(), 1 + 80);
    assert_eq!(summary["ramp_substeps"], 80);
    check_ramp(&offline, stopped);

    // the same stop in real time: exit 1, the same step (not 0) in the message and the summary,
    // and the same ramp in substeps.csv (the run equals the offline one up to round-off)
    let out = bin()
        .args([
            "run",
            "local.toml",
            "--out",
            "rt",
            "--quiet",
            "--no-plots",
            "--realtime",
        ])
        .current_dir(&dir)
        .output()
        .unwrap();
    let rt_err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{rt_err}");
    assert!(
        rt_err.starts_with(&format!("error: stopped at step {stopped} ")),
        "offline stopped at {stopped}: {rt_err}"
    );
    let rt_summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("rt/summary.json")).unwrap()).unwrap();
    assert_eq!(rt_summary["completed"], false);
    assert_eq!(rt_summary["stopped_at_step"].as_u64(), Some(stopped as u64));
    assert_eq!(rt_summary["steps_done"].as_u64(), Some(stopped as u64 - 1));
    assert_eq!(rt_summary["ramp_substeps"], 80);
    let rt = ramp_rows(&dir.join("rt/substeps.csv"), stopped);
    check_ramp(&rt, stopped);
    for (a, b) in offline.iter().zip(&rt) {
        assert_eq!(a[..3], b[..3], "step, sub-step, time");
        for (x, y) in a[3..].iter().zip(&b[3..]) {
            assert!((x - y).abs() <= 1e-9 * (1.0 + x.abs()), "{a:?} vs {b:?}");
        }
    }
}

/// The rows of `substeps.csv` of step `step` from the tripping sub-step on (all columns).
fn ramp_rows(path: &Path, step: usize) -> Vec<Vec<f64>> {
    let csv = std::fs::read_to_string(path).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    assert_eq!(*header.last().unwrap(), "ramp", "{header:?}");
    let rows: Vec<Vec<f64>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .filter(|r: &Vec<f64>| r[0] == step as f64)
        .collect();
    let first_ramp = rows.iter().position(|r| *r.last().unwrap() > 0.0).unwrap();
    rows[first_ramp - 1..].to_vec()
}

/// Row 0 is the tripping sub-step (ramp = 0, a |dm| beyond 0.01 m), then ramp rows 1..: the
/// commands `cmd1, cmd2` fall linearly to 0 and the sub-step numbers and times run on.
fn check_ramp(rows: &[Vec<f64>], step: usize) {
    let (tripped, ramp) = (&rows[0], &rows[1..]);
    assert_eq!(*tripped.last().unwrap(), 0.0);
    assert!(tripped[7].abs() > 0.01 || tripped[8].abs() > 0.01, "{tripped:?}");
    let n = ramp.len() as f64;
    for (s, r) in ramp.iter().enumerate() {
        assert_eq!(r[0], step as f64);
        assert_eq!(r[1], tripped[1] + (s + 1) as f64);
        assert_eq!(*r.last().unwrap(), (s + 1) as f64);
        assert!((r[2] - (tripped[2] + (s + 1) as f64 * 0.0025)).abs() < 1e-12, "t {r:?}");
        for c in [3, 4] {
            let expected = tripped[c] * (1.0 - (s + 1) as f64 / n);
            assert!((r[c] - expected).abs() <= 1e-15, "ramp {s}: {} vs {expected}", r[c]);
        }
    }
    assert_eq!(ramp.last().unwrap()[3..5], [0.0, 0.0]);
}

#[test]
fn killing_the_site_of_a_realtime_run_is_a_stop_not_bad_input() {
    let dir = temp_dir("kill-rt");
    let (mut site, addr) = serve(&dir);
    std::fs::write(
        dir.join("remote.toml"),
        client_config(600.0, Some((&addr, "per_substep")), ""),
    )
    .unwrap();
    let client = bin()
        .args([
            "run",
            "remote.toml",
            "--out",
            "out",
            "--quiet",
            "--no-plots",
            "--realtime",
        ])
        .current_dir(&dir)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(700));
    site.kill().unwrap();
    site.wait().unwrap();
    let out = client.wait_with_output().unwrap();
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.starts_with("error: stopped at step ") && err.contains("experimental side failed") && err.contains(&addr),
        "{err}"
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/summary.json")).unwrap()).unwrap();
    assert_eq!(summary["completed"], false);
    let stopped = summary["stopped_at_step"].as_u64().unwrap();
    assert!(stopped > 10, "the test ran a while before the kill: {stopped}");
    assert!(err.starts_with(&format!("error: stopped at step {stopped} ")), "{err}");
    assert_eq!(summary["steps_done"].as_u64(), Some(stopped - 1));
}

#[test]
fn bad_remote_and_limit_keys_are_named() {
    let dir = temp_dir("bad");
    let cases = [
        (
            "\n[substructure.remote]\naddress = \"127.0.0.1:1\"\nmode = \"sometimes\"\n",
            "substructure.remote.mode",
        ),
        (
            "\n[substructure.remote]\naddress = \"127.0.0.1:1\"\nprotocol = \"corba\"\n",
            "substructure.remote.protocol",
        ),
        (
            "\n[substructure.limits]\ndisplacement = [0.1, 0.1, 0.1]\n",
            "substructure.limits.displacement",
        ),
        ("\n[substructure.limits]\nforce = -1.0\n", "substructure.limits.force"),
        // a ramp that would never end
        (
            "\n[substructure.limits]\nforce = 1e6\nramp_time = 1e6\n",
            "substructure.limits.ramp_time: 1000000 s is longer than the maximum of 60 s",
        ),
    ];
    for (extra, key) in cases {
        std::fs::write(dir.join("c.toml"), client_config(1.0, None, extra)).unwrap();
        let out = run(&dir, "c.toml", "out");
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains(key), "{key}: {err}");
    }
    // nobody listens on port 1: a clear connection error, exit 2 before anything is written
    std::fs::write(
        dir.join("c.toml"),
        client_config(1.0, Some(("127.0.0.1:1", "per_substep")), ""),
    )
    .unwrap();
    let out = run(&dir, "c.toml", "nothing");
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("127.0.0.1:1"), "{err}");
    assert!(!dir.join("nothing/summary.json").exists());
    // the same in real time
    let out = bin()
        .args(["run", "c.toml", "--out", "nothing", "--quiet", "--realtime"])
        .current_dir(&dir)
        .output()
        .unwrap();
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert_eq!(
        err.trim_end(),
        "error: site tcp://127.0.0.1:1: cannot connect: Connection refused (os error 111)"
    );
    assert!(!dir.join("nothing").exists());
    // a bad site file
    std::fs::write(dir.join("site.toml"), "[site]\nprotocol = \"carrier_pigeon\"\nlisten = \"127.0.0.1:0\"\n[[specimen]]\nkind = \"linear_sdof\"\ndof = 1\nstiffness = 1.0\n").unwrap();
    let out = bin()
        .args(["site", "serve", "site.toml", "--once"])
        .current_dir(&dir)
        .output()
        .unwrap();
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("site.protocol") && err.contains("carrier_pigeon"), "{err}");
}

/// History rows without the `fei` columns (which only a local run can record).
fn without_fei(h: &str) -> Vec<String> {
    let header: Vec<&str> = h.lines().next().unwrap().split(',').collect();
    let keep: Vec<usize> = (0..header.len()).filter(|&i| !header[i].starts_with("fei")).collect();
    h.lines()
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            keep.iter().map(|&i| f[i]).collect::<Vec<_>>().join(",")
        })
        .collect()
}

#[test]
fn authenticated_remote_runs_equal_the_local_run_bit_for_bit() {
    let dir = temp_dir("auth");
    std::fs::write(dir.join("local.toml"), client_config(1.0, None, "")).unwrap();
    let local = run(&dir, "local.toml", "local");
    assert!(local.status.success(), "{}", text(&local.stderr));
    let local_history = std::fs::read_to_string(dir.join("local/history.csv")).unwrap();
    let local_substeps = std::fs::read_to_string(dir.join("local/substeps.csv")).unwrap();
    // the site reads its secret from a file, the client from the environment (per_step) or
    // from its own secret_file (per_substep)
    std::fs::write(dir.join("site.key"), "3f9a1c07e2b84d6a95c3e1f0a7b2d4c6\n").unwrap();
    for (mode, client_key, env) in [
        (
            "per_step",
            "",
            vec![("SUBSTEP_SITE_SECRET", "3f9a1c07e2b84d6a95c3e1f0a7b2d4c6")],
        ),
        ("per_substep", "secret_file = \"site.key\"\n", vec![]),
    ] {
        let (mut site, addr) = serve_with(&dir, "secret_file = \"site.key\"", &[]);
        let cfg = format!("auth_{mode}.toml");
        let config = client_config(1.0, Some((&addr, mode)), "")
            .replace("timeout = 1.0\n", &format!("timeout = 1.0\n{client_key}"));
        std::fs::write(dir.join(&cfg), config).unwrap();
        let out = run_with(&dir, &cfg, mode, &env);
        assert!(out.status.success(), "{mode}: {}", text(&out.stderr));
        let history = std::fs::read_to_string(dir.join(mode).join("history.csv")).unwrap();
        let substeps = std::fs::read_to_string(dir.join(mode).join("substeps.csv")).unwrap();
        assert!(
            without_fei(&history) == without_fei(&local_history),
            "{mode}: history differs"
        );
        assert!(substeps == local_substeps, "{mode}: substeps differ from the local run");
        let status = site.wait().unwrap();
        assert!(status.success(), "site exit {status:?}");
    }
    // without the secret, or with another one: refused before anything runs, exit 2 or 1,
    // no results written, and the site's log says why
    for (extra, env, expect) in [
        ("", vec![], "requires authentication"),
        (
            "",
            vec![("SUBSTEP_SITE_SECRET", "not-the-secret-0000000000")],
            "authentication failed",
        ),
    ] {
        let (mut site, addr) = serve_with(&dir, "secret_file = \"site.key\"", &[]);
        std::fs::write(
            dir.join("bad.toml"),
            client_config(1.0, Some((&addr, "per_substep")), extra),
        )
        .unwrap();
        let out = run_with(&dir, "bad.toml", "refused", &env);
        let err = text(&out.stderr);
        assert_ne!(out.status.code(), Some(0), "{err}");
        assert!(
            err.starts_with("error: ") && err.contains(expect) && err.contains(&addr),
            "{err}"
        );
        assert!(
            !dir.join("refused/history.csv").exists()
                || std::fs::read_to_string(dir.join("refused/history.csv"))
                    .unwrap()
                    .lines()
                    .count()
                    <= 1
        );
        let _ = site.kill();
        let _ = site.wait();
    }
}

#[test]
fn remote_durations_and_secrets_are_checked() {
    let dir = temp_dir("keys");
    for (extra, key, reason) in [
        ("timeout = 1e20\n", "substructure.remote.timeout", "at most 1e6 s"),
        ("timeout = 1e19\n", "substructure.remote.timeout", "at most 1e6 s"),
        (
            "secret_file = \"nope.key\"\n",
            "substructure.remote.secret_file",
            "cannot read",
        ),
    ] {
        let cfg = format!("\n[substructure.remote]\naddress = \"127.0.0.1:1\"\n{extra}");
        std::fs::write(dir.join("c.toml"), client_config(1.0, None, &cfg)).unwrap();
        let out = run(&dir, "c.toml", "out");
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains(key) && err.contains(reason), "{key}: {err}");
    }
    std::fs::write(dir.join("short.key"), "tiny\n").unwrap();
    let cfg = "\n[substructure.remote]\naddress = \"127.0.0.1:1\"\nsecret_file = \"short.key\"\n";
    std::fs::write(dir.join("c.toml"), client_config(1.0, None, cfg)).unwrap();
    let out = run(&dir, "c.toml", "out");
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("at least 16"), "{err}");
    // and the site's own keys
    for (keys, key) in [
        ("idle_timeout = 1e20", "site.idle_timeout"),
        ("idle_timeout = 1e19", "site.idle_timeout"),
        ("secret_file = \"short.key\"", "site.secret_file"),
    ] {
        let site = format!(
            "[site]\nprotocol = \"substep\"\n{keys}\n[[specimen]]\nkind = \"linear_sdof\"\ndof = 1\nstiffness = 1.0\n"
        );
        std::fs::write(dir.join("site.toml"), site).unwrap();
        let out = bin()
            .args(["site", "serve", "site.toml", "--once"])
            .current_dir(&dir)
            .output()
            .unwrap();
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.starts_with("error: ") && err.contains(key), "{key}: {err}");
    }
}

/// Whether an `SSTP` frame is a message of the session (not `Hello` = 1 or `Auth` = 12).
fn is_session_message(frame: &[u8]) -> bool {
    frame.len() >= 16 && !matches!(u16::from_le_bytes([frame[6], frame[7]]), 1 | 12)
}

/// A proxy in front of the site at `site` that passes the handshake and flips one bit (the
/// lowest of the first payload byte: the first command's last mantissa bit) of every later
/// client → site message; replies pass unchanged. Runs for at most 30 s.
fn tampering_proxy(site: &str, udp: bool) -> String {
    use std::io::Write;
    use std::net::{SocketAddr, TcpListener, TcpStream, UdpSocket};
    use std::time::{Duration, Instant};
    let site: SocketAddr = site.parse().unwrap();
    if udp {
        let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
        socket.set_read_timeout(Some(Duration::from_millis(20))).unwrap();
        let addr = socket.local_addr().unwrap().to_string();
        std::thread::spawn(move || {
            let start = Instant::now();
            let (mut buf, mut client) = (vec![0u8; 70_000], None);
            while start.elapsed() < Duration::from_secs(30) {
                let Ok((n, from)) = socket.recv_from(&mut buf) else {
                    continue;
                };
                if from == site {
                    if let Some(c) = client {
                        let _ = socket.send_to(&buf[..n], c);
                    }
                } else {
                    client = Some(from);
                    if is_session_message(&buf[..n]) {
                        buf[16] ^= 1;
                    }
                    let _ = socket.send_to(&buf[..n], site);
                }
            }
        });
        return addr;
    }
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    std::thread::spawn(move || {
        let Ok((mut client, _)) = listener.accept() else {
            return;
        };
        let mut upstream = TcpStream::connect(site).unwrap();
        let (mut from_site, mut to_client) = (upstream.try_clone().unwrap(), client.try_clone().unwrap());
        std::thread::spawn(move || {
            let _ = std::io::copy(&mut from_site, &mut to_client);
            let _ = to_client.shutdown(std::net::Shutdown::Both);
        });
        client.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
        loop {
            let mut frame = vec![0u8; 16];
            if client.read_exact(&mut frame).is_err() {
                break;
            }
            let len = u32::from_le_bytes(frame[12..16].try_into().unwrap()) as usize;
            frame.resize(16 + len, 0);
            if client.read_exact(&mut frame[16..]).is_err() {
                break;
            }
            if is_session_message(&frame) && frame.len() > 16 {
                frame[16] ^= 1;
            }
            if upstream.write_all(&frame).is_err() {
                break;
            }
        }
        let _ = upstream.shutdown(std::net::Shutdown::Both);
    });
    addr
}

/// Issue 25: a proxy that passes the authenticated handshake and then changes every command
/// (the attack multiplied them by 1000; one flipped bit is enough) cannot move the site: the
/// site refuses the first changed message and says why, and the run stops with exit 1 through
/// the controlled stop (the ramp-down to the safe position is attempted; the site has ended the
/// session, so it reports that the ramp could not be sent) with "message authentication failed"
/// on both sides, over TCP and UDP.
#[test]
fn a_tampering_proxy_stops_an_authenticated_run_with_exit_1_on_both_sides() {
    let dir = temp_dir("tamper");
    std::fs::write(dir.join("site.key"), "3f9a1c07e2b84d6a95c3e1f0a7b2d4c6\n").unwrap();
    let limits = "\n[substructure.limits]\ndisplacement = 0.05\nforce = 1e6\nramp_time = 0.2\n";
    for transport in ["tcp", "udp"] {
        // the site: `site serve --once` over `transport`, with the secret
        let site_toml = format!(
            "[site]\nprotocol = \"substep\"\ntransport = \"{transport}\"\nlisten = \"127.0.0.1:0\"\nsecret_file = \"site.key\"\nidle_timeout = 1.0\n{}",
            SPECIMENS.replace("PREFIX", "")
        );
        std::fs::write(dir.join("site.toml"), site_toml).unwrap();
        let mut site = bin()
            .env_remove("SUBSTEP_SITE_SECRET")
            .args(["site", "serve", "site.toml", "--once"])
            .current_dir(&dir)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut site_out = BufReader::new(site.stdout.take().unwrap());
        let mut line = String::new();
        site_out.read_line(&mut line).unwrap();
        let marker = format!("listening on {transport}://");
        assert!(line.contains(&marker), "{line}");
        let site_addr = line.trim().rsplit(&marker).next().unwrap().to_string();
        let proxy = tampering_proxy(&site_addr, transport == "udp");
        let config = client_config(2.0, Some((&proxy, "per_substep")), limits).replace(
            "timeout = 1.0\n",
            &format!("timeout = 0.3\ntransport = \"{transport}\"\nsecret_file = \"site.key\"\n"),
        );
        std::fs::write(dir.join("tamper.toml"), config).unwrap();
        let out = run(&dir, "tamper.toml", transport);
        let err = text(&out.stderr);
        println!("{transport} client: {err}");
        assert_eq!(out.status.code(), Some(1), "{transport}: {err}");
        assert!(
            err.starts_with("error: stopped at step 1 (t = 0.010000 s): experimental side failed: "),
            "{transport}: {err}"
        );
        assert!(
            err.contains(&format!("site {transport}://{proxy}")),
            "names the site: {err}"
        );
        let reason = match transport {
            "tcp" => {
                "the site reported an error (reply to Substep #2): message authentication failed: Substep #2: the tag does not match"
            }
            _ => "message authentication failed: the site dropped Substep #2 as unauthenticated (4 of 4 attempts",
        };
        assert!(err.contains(reason), "{transport}: {err}");
        // the controlled stop: the ramp to the safe position was attempted on the dead link
        assert!(
            err.contains("; the ramp to the safe position failed at 1/80: ")
                && err.contains("connection unusable after an earlier failure"),
            "{transport}: {err}"
        );
        let summary: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join(transport).join("summary.json")).unwrap()).unwrap();
        assert_eq!(summary["completed"], false);
        assert_eq!(summary["stopped_at_step"], 1);
        // the site: ended (TCP) or dropped (UDP) with the reason and the peer, then exits
        // after the session (UDP: after its idle timeout)
        let status = site.wait().unwrap();
        let mut log = String::new();
        site_out.read_to_string(&mut log).unwrap();
        println!("{transport} site: {line}{log}");
        assert!(status.success(), "{transport}: site exit {status:?}");
        let expected = match transport {
            "tcp" => {
                "session ended after 0 sub-steps, 0 steps: message authentication failed: Substep #2: the tag does not match"
            }
            _ => {
                "message authentication failed: Substep #2: the tag does not match (the message was changed on the way, forged, or sealed with another key); the datagram was dropped, not executed"
            }
        };
        assert!(
            log.lines()
                .any(|l| l.starts_with("site: 127.0.0.1:") && l.contains(expected)),
            "{transport}: {log}"
        );
        assert!(log.contains("authenticated)"), "{log}");
    }
}

/// Issue 38: a yielding numerical substructure (two storeys with bilinear hysteresis) with a
/// remote site, per step and per sub-step, equals the local virtual-lab run bit for bit (the
/// per-step site ramps from the predictors it is sent; the springs are inside them). The
/// storeys yield: the same run with elastic storeys differs by more than 1 % of the peak.
#[test]
fn a_yielding_structure_with_a_remote_site_equals_the_local_run() {
    let dir = temp_dir("yielding");
    let config = |yield_force: &str, remote: Option<(&str, &str)>| {
        let linear = client_config(3.0, remote, "");
        let start = linear.find("[ground_motion]").unwrap();
        format!(
            "[structure.storeys]\nmasses = [2000.0, 1000.0]\nstiffness = [7.0e4, 5.0e4]\n\
             [structure.storeys.hysteresis]\nkind = \"bilinear\"\nyield_force = {yield_force}\nhardening = 0.05\n\
             [structure.rayleigh]\nzeta = 0.02\nmodes = [1, 2]\n\n{}",
            &linear[start..]
        )
    };
    let yielding = "[900.0, 500.0]";
    std::fs::write(dir.join("local.toml"), config(yielding, None)).unwrap();
    std::fs::write(dir.join("elastic.toml"), config("[9.0e5, 5.0e5]", None)).unwrap();
    for name in ["local", "elastic"] {
        let out = run(&dir, &format!("{name}.toml"), name);
        assert!(out.status.success(), "{name}: {}", text(&out.stderr));
    }
    let local_history = std::fs::read_to_string(dir.join("local/history.csv")).unwrap();
    let u1 = |h: &str| -> Vec<f64> {
        h.lines()
            .skip(1)
            .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
            .collect()
    };
    let elastic = u1(&std::fs::read_to_string(dir.join("elastic/history.csv")).unwrap());
    let yielded = u1(&local_history);
    let peak = yielded.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let diff = yielded
        .iter()
        .zip(&elastic)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    assert!(diff > 0.01 * peak, "the storeys do not yield: {diff} of a peak {peak}");
    remote_runs_equal_local(&dir, "yielding", |remote| config(yielding, remote));
}

/// Run `config(Some((site address, mode)))` against a fresh site per mode (`per_step`,
/// `per_substep`): its history (but `fei`) and `substeps.csv` equal those of the local run in
/// `dir/local`. Returns the remote runs' summaries.
fn remote_runs_equal_local(
    dir: &Path,
    tag: &str,
    config: impl Fn(Option<(&str, &str)>) -> String,
) -> Vec<serde_json::Value> {
    let local_history = std::fs::read_to_string(dir.join("local/history.csv")).unwrap();
    let local_substeps = std::fs::read_to_string(dir.join("local/substeps.csv")).unwrap();
    let mut summaries = Vec::new();
    for mode in ["per_step", "per_substep"] {
        let (mut site, addr) = serve(dir);
        let cfg = format!("{tag}_{mode}.toml");
        std::fs::write(dir.join(&cfg), config(Some((&addr, mode)))).unwrap();
        let out = run(dir, &cfg, mode);
        assert!(out.status.success(), "{tag} {mode}: {}", text(&out.stderr));
        let history = std::fs::read_to_string(dir.join(mode).join("history.csv")).unwrap();
        let substeps = std::fs::read_to_string(dir.join(mode).join("substeps.csv")).unwrap();
        assert!(
            without_fei(&history) == without_fei(&local_history),
            "{tag} {mode}: history differs"
        );
        assert!(
            substeps == local_substeps,
            "{tag} {mode}: substeps differ from the local run"
        );
        assert!(site.wait().unwrap().success());
        let summary = std::fs::read_to_string(dir.join(mode).join("summary.json")).unwrap();
        summaries.push(serde_json::from_str(&summary).unwrap());
    }
    summaries
}

/// A reduced numerical substructure (issue 42, `[structure.reduction]`: a 12-storey shear
/// building reduced to its two coupling DOFs and 4 Ritz vectors) with a remote site equals
/// the local run, per step and per sub-step; the remote run says why it has no check against
/// the full model (the site is never driven twice).
#[test]
fn a_reduced_structure_with_a_remote_site_equals_the_local_run() {
    let dir = temp_dir("reduced");
    let config = |remote: Option<(&str, &str)>| {
        let linear = client_config(3.0, remote, "");
        let start = linear.find("[ground_motion]").unwrap();
        format!(
            "[structure.shear_building]\nstories = 12\nstory_mass = 2000.0\nfirst_period = 0.8\n\
             [structure.rayleigh]\nzeta = 0.02\nmodes = [1, 2]\n\
             [structure.reduction]\nmethod = \"ritz\"\nmodes = 4\n\n{}",
            &linear[start..]
        )
    };
    std::fs::write(dir.join("local.toml"), config(None)).unwrap();
    let out = run(&dir, "local.toml", "local");
    assert!(out.status.success(), "local: {}", text(&out.stderr));
    let summary = |name: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(dir.join(name).join("summary.json")).unwrap()).unwrap()
    };
    let local = summary("local");
    assert_eq!(local["reduction"]["reduced_dofs"], 6);
    assert!(local["reduction"]["check"]["max_error"].as_f64().unwrap() < 0.05);
    for s in remote_runs_equal_local(&dir, "reduced", config) {
        assert!(s["reduction"]["check"].is_null());
        assert!(
            s["reduction"]["no_check"].as_str().unwrap().contains("remote site"),
            "{}",
            s["reduction"]["no_check"]
        );
    }
}
