//! `substep analyze` end to end: the CSV contracts, the verification verdict, the planner and
//! bad input.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use substep::analysis::AnalysisCase;

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("substep-analyze-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn substep(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_substep"))
        .args(args)
        .output()
        .expect("the substep binary runs")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn read_lines(p: &Path) -> Vec<String> {
    std::fs::read_to_string(p).unwrap().lines().map(String::from).collect()
}

fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples")
}

#[test]
fn stability_writes_the_contract_csv_limits_and_maps() {
    let dir = temp_dir("stability");
    let out = substep(&[
        "analyze",
        "stability",
        "--eta-m",
        "0.5",
        "--zeta",
        "0.05",
        "--zeta-s",
        "0.05",
        "--eta-f",
        "1.0",
        "--k-sub",
        "1,2",
        "--omega",
        "0.1:1.5:15",
        "--vary",
        "zeta_s=0:0.2:5",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let lines = read_lines(&dir.join("stability.csv"));
    assert_eq!(lines[0], "k_sub,Omega,zeta_s,rho");
    assert_eq!(lines.len(), 1 + 2 * 15 * 5);
    // every row is the library's spectral radius at that point
    for line in lines[1..].iter().step_by(17) {
        let f: Vec<f64> = line.split(',').map(|v| v.parse().unwrap()).collect();
        let case = AnalysisCase {
            eta_m: 0.5,
            zeta_s: f[2],
            omega_dt: f[1],
            k_sub: f[0] as usize,
            ..AnalysisCase::typical_tmd()
        };
        let rho = case.spectral_radius().unwrap();
        assert!((rho - f[3]).abs() < 1e-12, "{line}: {rho}");
    }
    let limits = read_lines(&dir.join("stability_limit.csv"));
    assert_eq!(limits[0], "k_sub,zeta_s,Omega_cr");
    assert_eq!(limits.len(), 1 + 2 * 5);
    // an undamped TMD with k_sub = 1 on the large mass ratio system has a finite limit
    let undamped = limits.iter().find(|l| l.starts_with("1,0.05,")).unwrap();
    let w: f64 = undamped.split(',').nth(2).unwrap().parse().unwrap();
    assert!(w > 0.1 && w < 1.5, "{undamped}");
    for k in [1, 2] {
        let png = std::fs::read(dir.join(format!("stability_k{k}.png"))).unwrap();
        assert!(png.starts_with(b"\x89PNG"));
    }
}

#[test]
fn accuracy_writes_one_row_per_peak() {
    let dir = temp_dir("accuracy");
    let out = substep(&[
        "analyze",
        "accuracy",
        "--k-sub",
        "1,2",
        "--eta-t",
        "0.01,0.05",
        "--out",
        dir.to_str().unwrap(),
        "--no-plots",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let lines = read_lines(&dir.join("accuracy.csv"));
    assert_eq!(
        lines[0],
        "k_sub,eta_T,eta_p,peak,freq_ratio,h,freq_ratio_exact,h_exact,amplitude_error,period_error"
    );
    assert_eq!(lines.len(), 1 + 2 * 2 * 2);
    for l in &lines[1..] {
        let f: Vec<f64> = l.split(',').map(|v| v.parse().unwrap()).collect();
        assert!((f[8] - (f[5] / f[7] - 1.0)).abs() < 1e-12, "{l}");
        assert!((f[9] - (f[6] / f[4] - 1.0)).abs() < 1e-12, "{l}");
        // errors shrink with η_T: at 1 % they are small
        if f[1] == 0.01 {
            assert!(f[8].abs() < 0.1 && f[9].abs() < 0.01, "{l}");
        }
    }
}

#[test]
fn verify_agrees_with_the_time_domain() {
    let dir = temp_dir("verify");
    let out = substep(&["analyze", "verify", "--out", dir.to_str().unwrap(), "--quiet"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let md = std::fs::read_to_string(dir.join("verify.md")).unwrap();
    assert!(md.contains("All checks agree: **yes**"), "{md}");
    assert!(!md.contains("| NO |"));
    let csv = read_lines(&dir.join("verify.csv"));
    assert!(csv.len() > 20);
    // A CSV reader sees every row with the header's nine fields: the case names that hold a
    // comma ("typical, ζ_s = 2 %") are quoted.
    let mut reader = csv::Reader::from_path(dir.join("verify.csv")).unwrap();
    let rows: Vec<csv::StringRecord> = reader.records().map(|r| r.unwrap()).collect();
    assert_eq!(rows.len(), csv.len() - 1);
    assert!(rows.iter().all(|r| r.len() == 9));
    assert!(
        rows.iter()
            .any(|r| &r[1] == "typical, ζ_s = 2 %" && r[0].starts_with("boundary_"))
    );
    assert!(rows.iter().all(|r| &r[8] == "true"));
}

#[test]
fn plan_recommends_a_stable_setting() {
    let dir = temp_dir("plan");
    let cfg = examples().join("tmd_substructure.toml");
    let out = substep(&[
        "analyze",
        "plan",
        cfg.to_str().unwrap(),
        "--k-sub",
        "1,4",
        "--out",
        dir.to_str().unwrap(),
    ]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(stdout.contains("recommendation: dt = "), "{stdout}");
    let lines = read_lines(&dir.join("plan.csv"));
    assert_eq!(
        lines[0],
        "dt,k_sub,delay,rho,margin,class,error,error_dt,error_substep,error_delay,dominant,us_per_step,budget_share,peak,freq_hz,freq_hz_exact,amplitude_error,period_error"
    );
    assert_eq!(lines.len(), 1 + 3 * 2 * 2);
    assert!(
        stdout.contains("dominant error: ") && stdout.contains("remedy: "),
        "{stdout}"
    );
}

#[test]
fn plan_analyses_phase_lag_compensation_frozen_and_changes_its_advice() {
    let dir = temp_dir("plan-phase-lag");
    let base = std::fs::read_to_string(examples().join("tmd_substructure.toml")).unwrap();
    let base = base.replace("dir = \"results/tmd_substructure\"", "").replace(
        "file = \"ag_sweep.csv\"",
        "generator = \"harmonic\"\namplitude = 1.0\nfrequency = 1.0\nduration = 1.0",
    );
    let with = dir.join("with.toml");
    std::fs::write(
        &with,
        format!("{base}\n[substructure.phase_lag]\nkind = \"polynomial\"\norder = 2\n").replace(
            "[substructure.actuator]\nkind = \"ideal\"",
            "[substructure.actuator]\nkind = \"ideal\"\ndelay = 0.01",
        ),
    )
    .unwrap();
    let without = dir.join("without.toml");
    std::fs::write(
        &without,
        base.replace(
            "[substructure.actuator]\nkind = \"ideal\"",
            "[substructure.actuator]\nkind = \"ideal\"\ndelay = 0.01",
        ),
    )
    .unwrap();
    let run = |cfg: &std::path::Path| {
        let out = substep(&[
            "analyze",
            "plan",
            cfg.to_str().unwrap(),
            "--k-sub",
            "4",
            "--dt",
            "0.01",
            "--out",
            dir.to_str().unwrap(),
        ]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        text(&out.stdout)
    };
    let a = run(&without);
    let b = run(&with);
    assert!(
        a.contains("dominant error: actuator delay/lag") && a.contains("remedy: phase-lag compensation"),
        "{a}"
    );
    assert!(b.contains("phase-lag compensation (polynomial) analysed frozen"), "{b}");
    assert!(!b.contains("remedy: phase-lag compensation,"), "{b}");
}

#[test]
fn plan_refuses_a_nonlinear_specimen() {
    let dir = temp_dir("plan-nonlinear");
    let cfg = dir.join("bw.toml");
    std::fs::write(
        &cfg,
        r#"
[structure.sdof]
mass = 1000.0
stiffness = 4.0e4
damping = 100.0
[ground_motion]
generator = "harmonic"
amplitude = 1.0
frequency = 1.0
duration = 1.0
[integrator]
dt = 0.01
[substructure]
coupling_dofs = [1]
substeps = 2
[[substructure.specimen]]
kind = "bouc_wen"
dof = 1
stiffness = 1.0e4
alpha = 0.1
yield_displacement = 0.01
"#,
    )
    .unwrap();
    let out = substep(&["analyze", "plan", cfg.to_str().unwrap(), "--out", dir.to_str().unwrap()]);
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("substructure.specimen[1]") && err.contains("bouc_wen"),
        "{err}"
    );
}

#[test]
fn bad_grids_are_refused_with_a_reason() {
    let cases: [(&[&str], &str); 6] = [
        (&["analyze", "stability", "--omega", "1:0.5:10"], "inverted"),
        (&["analyze", "stability", "--omega", "0.1:1:0"], "empty"),
        (
            &["analyze", "stability", "--vary", "foo=0:1:3"],
            "unknown parameter 'foo'",
        ),
        (
            &[
                "analyze",
                "stability",
                "--omega",
                "0.1:3:5000",
                "--vary",
                "zeta_s=0:1:5000",
            ],
            "too many",
        ),
        (&["analyze", "stability", "--k-sub", "0"], "--k-sub"),
        (&["analyze", "accuracy", "--eta-t", "0.7"], "--eta-t"),
    ];
    for (args, needle) in cases {
        let out = substep(args);
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.starts_with("error: ") && err.contains(needle), "{args:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{err}");
    }
}

/// `--scheme cr | kr_alpha[:RHO]`: the map of the explicit schemes (docs/theory.md §2.9), each
/// row the library's spectral radius of that case; a bad scheme is refused in one line.
#[test]
fn stability_maps_the_explicit_schemes_too() {
    use substep::analysis::AnalysisScheme;
    for (arg, scheme) in [
        ("cr", AnalysisScheme::Cr),
        ("kr_alpha:0.3", AnalysisScheme::KrAlpha { rho_inf: 0.3 }),
    ] {
        let dir = temp_dir(&format!("scheme-{}", arg.replace(':', "-")));
        let out = substep(&[
            "analyze",
            "stability",
            "--case",
            "large_mass_ratio",
            "--scheme",
            arg,
            "--eta-p",
            "1",
            "--k-sub",
            "1,3",
            "--omega",
            "0.1:3:12",
            "--vary",
            "zeta_s=0:0.2:3",
            "--no-plots",
            "--out",
            dir.to_str().unwrap(),
        ]);
        assert!(out.status.success(), "{arg}: {}", text(&out.stderr));
        let lines = read_lines(&dir.join("stability.csv"));
        assert_eq!(lines.len(), 1 + 2 * 12 * 3, "{arg}");
        let mut unstable = 0;
        for line in &lines[1..] {
            let f: Vec<f64> = line.split(',').map(|v| v.parse().unwrap()).collect();
            let case = AnalysisCase {
                scheme,
                eta_p: 1.0,
                zeta_s: f[2],
                omega_dt: f[1],
                k_sub: f[0] as usize,
                ..AnalysisCase::large_mass_ratio()
            };
            let rho = case.spectral_radius().unwrap();
            assert!((rho - f[3]).abs() < 1e-12, "{arg} {line}: {rho}");
            unstable += usize::from(rho > 1.0 + 1e-9);
        }
        assert!(unstable > 0, "{arg}: the delayed large mass ratio is stable everywhere");
    }
    let out = substep(&["analyze", "stability", "--scheme", "central_difference", "--no-plots"]);
    assert_eq!(out.status.code(), Some(2));
    let e = text(&out.stderr);
    assert!(
        e.contains("--scheme") && e.contains("kr_alpha") && e.trim().lines().count() == 1,
        "{e}"
    );
}
