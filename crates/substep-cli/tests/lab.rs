//! `substep run` with lab-grade transfer systems (issue 10, items 1–3): the servo-hydraulic
//! example with the benchmark's sample controller runs stably and tracks like the benchmark's
//! published figures say that transfer system does, and bad transfer inputs exit 2 with one line.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("substep-lab-{}-{name}", std::process::id()));
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

fn example() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/servo_hydraulic.toml")
}

fn summary(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("out/summary.json")).unwrap()).unwrap()
}

#[test]
fn servo_hydraulic_example_is_stable_and_tracks() {
    let dir = temp_dir("servo");
    let ex = example();
    let out = substep(
        &dir,
        &["run", ex.to_str().unwrap(), "--out", "out", "--quiet", "--no-plots"],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let s = summary(&dir);
    assert_eq!(s["completed"], true);
    assert_eq!(s["substructure"]["actuator"]["kind"], "servo_hydraulic");
    assert_eq!(s["substructure"]["force"], "from_motion");
    assert_eq!(s["substructure"]["sensors"]["generator"], "benchmark");
    let t = &s["tracking"][0];
    let delay = t["delay_s"].as_f64().unwrap();
    let nrms = t["nrms_error"].as_f64().unwrap();
    let peak = t["peak_error"].as_f64().unwrap();
    // The benchmark's sample controller on this plant and specimen (published table, case 1):
    // J1 = 4.6 ms tracking delay, J2 = 10.4 % NRMS and J3 = 11.5 % peak tracking error. Our
    // excitation (a sweep, not El Centro) and timing (the command ramps over the sub-step
    // instead of being held) differ, so the figures agree to about a sample and a few percent.
    assert!((delay - 4.6e-3).abs() < 0.5e-3, "tracking delay {delay} s");
    assert!((nrms - 0.104).abs() < 0.03, "NRMS tracking error {nrms}");
    assert!((peak - 0.115).abs() < 0.03, "peak tracking error {peak}");
    // Stable: bounded and close to the exact solution to the level the benchmark reports for
    // this controller (J4 ≈ 36 %, J6 ≈ 32 % peak errors for case 1).
    let r = &s["reference"];
    let e = r["max_displacement_error"].as_f64().unwrap();
    assert!(e < 0.3, "max displacement error {e}");
    // Without the controller the same test is unstable (as the benchmark's uncompensated loop):
    // the controller is what makes it work.
    let text = std::fs::read_to_string(&ex).unwrap();
    let cut = text.index_of("[substructure.controller]");
    let end = text[cut..].find("[substructure.sensors]").unwrap() + cut;
    let without = format!("{}{}", &text[..cut], &text[end..]);
    std::fs::write(dir.join("nc.toml"), without).unwrap();
    let out = substep(&dir, &["run", "nc.toml", "--out", "out2", "--quiet", "--no-plots"]);
    let s2: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out2/summary.json")).unwrap()).unwrap();
    let e2 = s2["reference"]["max_displacement_error"]
        .as_f64()
        .unwrap_or(f64::INFINITY);
    assert!(!out.status.success() || e2 > 1.0, "without the controller: error {e2}");
}

trait IndexOf {
    fn index_of(&self, pat: &str) -> usize;
}
impl IndexOf for String {
    fn index_of(&self, pat: &str) -> usize {
        self.find(pat).unwrap_or_else(|| panic!("{pat} not in the example"))
    }
}

/// Exit 2, one line naming the key, no summary.
fn assert_bad(name: &str, config: &str, expected: &str) {
    let dir = temp_dir(name);
    std::fs::write(dir.join("cfg.toml"), config).unwrap();
    let out = substep(&dir, &["run", "cfg.toml", "--out", "out", "--no-plots"]);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(2), "{name}: {stderr}");
    assert!(stderr.starts_with("error: "), "{name}: {stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "{name}: {stderr}");
    assert!(stderr.contains(expected), "{name}: expected '{expected}' in: {stderr}");
    assert!(!dir.join("out/summary.json").exists(), "{name}");
}

#[test]
fn bad_transfer_inputs_exit_2_with_one_line() {
    let text = std::fs::read_to_string(example()).unwrap();
    let edit = |from: &str, to: &str| {
        assert!(text.contains(from), "{from}");
        text.replacen(from, to, 1)
    };
    for (name, config, expected) in [
        (
            "zero_den",
            edit("den = [1.0, 0.0]\n", "den = [0.0, 0.0]\n"),
            "cfg.toml: substructure.controller.den: is zero",
        ),
        (
            "improper",
            edit("num = [2.0, 95.0]", "num = [1.0, 2.0, 95.0]"),
            "cfg.toml: substructure.controller: improper transfer function",
        ),
        (
            "unstable",
            edit("den = [1.0, 0.0]\n", "den = [1.0, -50.0]\n"),
            "cfg.toml: substructure.controller: discretised controller is unstable",
        ),
        (
            "unstable_ff",
            edit(
                "feedforward_den = [1.0, 8570.397339444286]",
                "feedforward_den = [1.0, -8570.397339444286]",
            ),
            "cfg.toml: substructure.controller.feedforward: discretised controller is unstable",
        ),
        (
            "servo_without_lumped_specimen",
            edit("kind = \"lumped_sdof\"", "kind = \"linear_sdof\"").replace("mass = 29.13 ", "# mass = 29.13 "),
            "cfg.toml: substructure.actuator.kind: a servo_hydraulic or hydraulic actuator needs exactly one lumped_sdof specimen at coupling DOF 1",
        ),
        (
            "csi",
            edit(
                "kind = \"servo_hydraulic\"",
                "kind = \"servo_hydraulic\"\ncsi_derivative = \"central\"",
            ),
            "cfg.toml: substructure.actuator.csi_derivative: unknown 'central'",
        ),
        (
            "force",
            edit("force = \"from_motion\"", "force = \"loadcell\""),
            "cfg.toml: substructure.force: unknown 'loadcell'",
        ),
        (
            "generator",
            edit("generator = \"benchmark\"", "generator = \"mt19937\""),
            "cfg.toml: substructure.sensors.generator: unknown generator 'mt19937'",
        ),
        (
            "negative_power",
            edit("force_noise_power = 1.16e-3", "force_noise_power = -1.0"),
            "cfg.toml: substructure.sensors.force_noise_power: must be",
        ),
        (
            "quantum",
            edit("command_quantum = 3.814697265625e-6", "command_quantum = 0.0"),
            "cfg.toml: substructure.sensors.command_quantum: must be",
        ),
        (
            "specimen_mass",
            edit("mass = 29.13 ", "mass = 0.0 "),
            "cfg.toml: substructure.specimen[1].mass: must be",
        ),
    ] {
        assert_bad(name, &config, expected);
    }
}
