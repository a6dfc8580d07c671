//! `substep study` end to end: study.csv with one row per run in run order, equal to
//! `substep run` of the same variant; figures; a failing run keeps the others; bad study files
//! are bad input (exit code 2); `--format mat|mat73` give MATLAB level-5 / v7.3 files in every build.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("substep-study-{}-{name}", std::process::id()));
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

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// The example base test, shortened to 1 s.
fn write_base(dir: &Path) {
    let base = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../examples/studies/tmd_base.toml"
    ))
    .unwrap()
    .replace("duration = 5.0", "duration = 1.0");
    assert!(base.contains("duration = 1.0"));
    std::fs::write(dir.join("base.toml"), base).unwrap();
}

#[test]
fn study_csv_rows_match_single_runs_and_survive_a_failing_run() {
    let dir = temp_dir("grid");
    write_base(&dir);
    std::fs::write(
        dir.join("s.toml"),
        "base = \"base.toml\"\nmetrics = [\"max_displacement_error\", \"reference.max_force_error\"]\n\
         [grid]\n\"substructure.substeps\" = [2, 0, 4]\n",
    )
    .unwrap();
    let out = substep(&dir, &["study", "s.toml", "--out", "o"]);
    // A study with a failed run exits 1 and says how many, in one line; study.csv has every row.
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    let stderr = text(&out.stderr);
    assert!(stderr.starts_with("error: 1 of 3 runs did not complete"), "{stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    let stdout = text(&out.stdout);
    assert!(stdout.contains("1 of 3 runs did not complete"), "{stdout}");
    let csv = std::fs::read_to_string(dir.join("o/study.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv.lines().map(|l| l.splitn(6, ',').collect()).collect();
    assert_eq!(
        rows[0],
        [
            "run",
            "substructure.substeps",
            "completed",
            "max_displacement_error",
            "reference.max_force_error",
            "error"
        ]
    );
    assert_eq!(rows.len(), 4);
    assert_eq!(rows[2][..3], ["1", "0", "false"]);
    assert!(
        rows[2][5].starts_with("run 1 [substructure.substeps = 0]: "),
        "{}",
        rows[2][5]
    );
    assert!(rows[2][5].contains("substructure.substeps"), "{}", rows[2][5]);
    assert!(dir.join("o/study_max_displacement_error.png").is_file());
    // Row 2 (k_sub = 4) equals `substep run` of the base (which has k_sub = 4).
    let run = substep(&dir, &["run", "base.toml", "--out", "r", "--quiet", "--no-plots"]);
    assert!(run.status.success(), "{}", text(&run.stderr));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("r/summary.json")).unwrap()).unwrap();
    let max_u = summary["reference"]["dofs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d["peak_error"].as_f64().unwrap())
        .fold(f64::NEG_INFINITY, f64::max);
    assert_eq!(rows[3][..3], ["2", "4", "true"]);
    assert_eq!(rows[3][3].parse::<f64>().unwrap(), max_u);
    assert_eq!(
        rows[3][4].parse::<f64>().unwrap(),
        summary["reference"]["max_force_error"].as_f64().unwrap()
    );
}

#[test]
fn bad_study_files_are_bad_input() {
    let dir = temp_dir("bad");
    write_base(&dir);
    let case = |body: &str| {
        std::fs::write(dir.join("s.toml"), body).unwrap();
        let out = substep(&dir, &["study", "s.toml", "--out", "o", "--quiet"]);
        assert_eq!(out.status.code(), Some(2), "{body}");
        let e = text(&out.stderr);
        assert_eq!(e.lines().count(), 1, "{e}");
        e
    };
    assert!(case("base = \"base.toml\"\nmetric = []\n").contains("s.toml: line 2: unknown field `metric`"));
    assert!(case("metrics = []\n").contains("s.toml: base: missing"));
    assert!(case("base = \"nope.toml\"\n").contains("nope.toml: cannot read"));
    assert!(
        case("base = \"base.toml\"\n[samples]\nn = 3\n[samples.params]\n\"substructure.actuator.delay\" = { dist = \"uniform\", low = 0.2, high = 0.1 }\n")
            .contains("samples.params.substructure.actuator.delay: uniform needs finite low < high")
    );
}

#[test]
fn container_formats_need_the_feature_or_work() {
    let dir = temp_dir("format");
    write_base(&dir);
    let run = |format: &str| {
        substep(
            &dir,
            &[
                "run",
                "base.toml",
                "--out",
                "o",
                "--quiet",
                "--no-plots",
                "--format",
                format,
            ],
        )
    };
    // MATLAB level 5: every build.
    let out = run("mat");
    assert!(out.status.success(), "{}", text(&out.stderr));
    let head = std::fs::read(dir.join("o/results.mat")).unwrap();
    assert!(head.starts_with(b"MATLAB 5.0 MAT-file"));
    assert_eq!(&head[124..128], b"\x00\x01IM");
    assert_eq!(
        &head[128..132],
        &14u32.to_le_bytes(),
        "an miMATRIX element follows the header"
    );
    // MATLAB v7.3 (pure-Rust HDF5 writer, every build).
    let out = run("mat73");
    assert!(out.status.success(), "{}", text(&out.stderr));
    let head = std::fs::read(dir.join("o/results.mat")).unwrap();
    assert!(head.starts_with(b"MATLAB 7.3 MAT-file"));
    assert_eq!(&head[124..128], b"\x00\x02IM");
    // the HDF5 signature right after the 512-byte user block
    assert_eq!(&head[512..520], b"\x89HDF\r\n\x1a\n");
    let out = substep(&dir, &["run", "base.toml", "--out", "o", "--quiet", "--format", "xlsx"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("unknown output format `xlsx`"));
    // and in the config
    let base = std::fs::read_to_string(dir.join("base.toml")).unwrap();
    std::fs::write(dir.join("f.toml"), base + "\n[output]\nformat = \"parquet\"\n").unwrap();
    let out = substep(&dir, &["run", "f.toml", "--out", "o", "--quiet"]);
    assert_eq!(out.status.code(), Some(2));
    let e = text(&out.stderr);
    assert!(
        e.contains("f.toml: output.format: unknown output format `parquet`"),
        "{e}"
    );
}

/// A study's run that diverges (here: the sub-step iteration with a 5 MN·s/m damper at
/// k_sub = 10) has `completed = false` and says why in `error`; the stable one does not.
#[test]
fn a_diverging_run_is_not_completed_in_study_csv() {
    let dir = temp_dir("diverging");
    std::fs::write(
        dir.join("base.toml"),
        r#"[structure]
mass = [[2.0e5, 0.0, 0.0], [0.0, 2.0e5, 0.0], [0.0, 0.0, 2.0e5]]
stiffness = [[4.0e8, -2.0e8, 0.0], [-2.0e8, 4.0e8, -2.0e8], [0.0, -2.0e8, 2.0e8]]
[structure.rayleigh]
zeta = 0.02
[ground_motion]
generator = "sine_sweep"
amplitude = 2.0
f0 = 0.5
f1 = 5.0
duration = 8.0
[integrator]
scheme = "average_acceleration"
dt = 0.01
[substructure]
coupling_dofs = [1]
substeps = 10
[[substructure.specimen]]
kind = "linear_sdof"
dof = 1
stiffness = 0.0
damping = 2.5e6
[substructure.actuator]
kind = "ideal"
delay = 0.01
[substructure.error_force]
kind = "pid"
p = 1.0
"#,
    )
    .unwrap();
    std::fs::write(
        dir.join("s.toml"),
        "base = \"base.toml\"\nmetrics = [\"max_displacement_error\"]\n[grid]\n\"substructure.specimen.0.damping\" = [2.5e6, 5.0e6]\n",
    )
    .unwrap();
    let out = substep(&dir, &["study", "s.toml", "--out", "o", "--no-plots"]);
    let stdout = text(&out.stdout);
    assert!(
        stdout.contains("1 of 2 runs did not complete"),
        "{stdout}{}",
        text(&out.stderr)
    );
    let csv = std::fs::read_to_string(dir.join("o/study.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv.lines().map(|l| l.splitn(5, ',').collect()).collect();
    assert_eq!(rows[1][2], "true");
    assert!(rows[1][3].parse::<f64>().unwrap() < 1.0);
    assert_eq!(rows[2][2], "false");
    // Its metrics are NaN, as docs/config.md says (not the 10⁵ % of a runaway response).
    assert_eq!(rows[2][3], "NaN");
    assert!(rows[2][4].contains("runaway response"), "{}", rows[2][4]);
}

/// Issue "Hardening, round 2": `--threads 10⁶` is refused in one line (exit 2), before anything
/// is spawned.
#[test]
fn an_absurd_thread_count_is_refused() {
    let dir = temp_dir("threads");
    write_base(&dir);
    std::fs::write(
        dir.join("s.toml"),
        "base = \"base.toml\"\n[grid]\n\"substructure.substeps\" = [2, 4]\n",
    )
    .unwrap();
    let out = substep(&dir, &["study", "s.toml", "--out", "o", "--threads", "1000000"]);
    assert_eq!(out.status.code(), Some(2));
    let err = text(&out.stderr);
    assert!(err.starts_with("error: threads: at most 256"), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
}
