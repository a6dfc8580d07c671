//! Every figure `substep run` writes, in every format: the files listed in summary.json exist,
//! PNGs have the expected size, SVGs parse as XML with the plotted series, PDFs are whole; the
//! engineering outputs are written with consistent columns; `[output.plots]` selects figures.

use std::path::{Path, PathBuf};
use std::process::Command;

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("substep-figures-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples")
}

fn run(args: &[&str]) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_substep")).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let dir = args[args.iter().position(|a| *a == "--out").unwrap() + 1];
    serde_json::from_str(&std::fs::read_to_string(Path::new(dir).join("summary.json")).unwrap()).unwrap()
}

fn outputs(summary: &serde_json::Value, ext: &str) -> Vec<PathBuf> {
    summary["outputs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| PathBuf::from(p.as_str().unwrap()))
        .filter(|p| p.extension().is_some_and(|e| e == ext))
        .collect()
}

fn png_size(bytes: &[u8]) -> (u32, u32) {
    assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n"));
    let be = |i: usize| u32::from_be_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
    (be(16), be(20))
}

const SUBSTRUCTURE_FIGURES: [&str; 12] = [
    "displacement",
    "acceleration",
    "coupling_force",
    "error_force",
    "hysteresis",
    "reference",
    "energy",
    "base_shear",
    "ground_motion",
    "response_spectrum",
    "compensation_force",
    "storeys",
];

#[test]
fn every_figure_is_written_in_every_format() {
    let formats: &[&str] = if cfg!(feature = "pdf") {
        &["png", "svg", "pdf"]
    } else {
        // Without the `pdf` feature PDF figures are refused up front, before any work and
        // before any file: one line, exit 2 (a run, the VST study, the RTHS benchmark).
        let dir = temp_dir("nopdf");
        let d = dir.join("out");
        for command in [
            &["run", "--quiet"][..],
            &["vst", "--quick", "--quiet"],
            &["benchmark", "rths"],
        ] {
            let out = Command::new(env!("CARGO_BIN_EXE_substep"))
                .args(command)
                .args(["--out", d.to_str().unwrap(), "--plot-format", "pdf"])
                .output()
                .unwrap();
            let e = String::from_utf8_lossy(&out.stderr).to_string();
            assert_eq!(out.status.code(), Some(2), "{command:?}: {e}");
            assert_eq!(e.lines().count(), 1, "{e}");
            assert!(
                e.starts_with("error: --plot-format: format `pdf`: this build of substep has no PDF figures"),
                "{e}"
            );
            assert!(e.contains("--features pdf"), "{e}");
            assert!(!d.exists(), "{command:?} wrote {} before refusing", d.display());
        }
        &["png", "svg"]
    };
    for &fmt in formats {
        let dir = temp_dir(fmt);
        let d = dir.to_str().unwrap();
        // The default example (1 DOF: no storey figure) and the 10-storey building.
        let s1 = run(&["run", "--out", d, "--quiet", "--plot-format", fmt]);
        let files = outputs(&s1, fmt);
        let names: Vec<String> = files
            .iter()
            .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
            .collect();
        for f in &SUBSTRUCTURE_FIGURES[..11] {
            assert!(names.iter().any(|n| n == f), "{fmt}: {f} missing from {names:?}");
        }
        let dir2 = temp_dir(&format!("{fmt}-sb"));
        let d2 = dir2.to_str().unwrap();
        let cfg = examples().join("shear_building_10.toml");
        let s2 = run(&[
            "run",
            cfg.to_str().unwrap(),
            "--out",
            d2,
            "--quiet",
            "--plot-format",
            fmt,
        ]);
        let files2 = outputs(&s2, fmt);
        assert!(
            files2.iter().any(|p| p.ends_with(format!("storeys.{fmt}"))),
            "{files2:?}"
        );
        for path in files.iter().chain(&files2) {
            let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            assert!(bytes.len() > 3000, "{}: {} bytes", path.display(), bytes.len());
            match fmt {
                "png" => {
                    let (w, h) = png_size(&bytes);
                    assert_eq!(w, 1100, "{}", path.display());
                    assert!((500..1400).contains(&h), "{}: height {h}", path.display());
                }
                "svg" => {
                    let text = String::from_utf8(bytes).unwrap();
                    assert!(
                        text.starts_with("<svg") && text.trim_end().ends_with("</svg>"),
                        "{}",
                        path.display()
                    );
                    // Every figure draws at least one data series and labelled axes.
                    assert!(text.matches("<polyline").count() >= 1, "{}", path.display());
                    assert!(text.matches("<text").count() >= 8, "{}", path.display());
                }
                _ => {
                    assert!(bytes.starts_with(b"%PDF-"), "{}", path.display());
                    assert!(String::from_utf8_lossy(&bytes[bytes.len() - 64..]).contains("%%EOF"));
                }
            }
        }
        std::fs::remove_dir_all(&dir).ok();
        std::fs::remove_dir_all(&dir2).ok();
    }
}

#[test]
fn engineering_outputs_and_figure_selection() {
    let dir = temp_dir("eng");
    let cfg_path = dir.join("sb.toml");
    let text = std::fs::read_to_string(examples().join("shear_building_10.toml")).unwrap();
    let text = text.split("[output]").next().unwrap().to_string()
        + "[output.plots]\nfigures = [\"energy\", \"storeys\"]\nwindow = [1.0, 3.0]\n";
    std::fs::write(&cfg_path, text).unwrap();
    let out = dir.join("out");
    let s = run(&[
        "run",
        cfg_path.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    let pngs = outputs(&s, "png");
    let names: Vec<_> = pngs
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, ["energy.png", "storeys.png"]);
    // response.csv: t, ag, 10 a_abs, 10 drifts, 10 shears, base shear, 6 energies.
    let csv = std::fs::read_to_string(out.join("response.csv")).unwrap();
    let head: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    assert_eq!(head.len(), 2 + 30 + 1 + 6);
    let row: Vec<f64> = csv
        .lines()
        .nth(500)
        .unwrap()
        .split(',')
        .map(|x| x.parse().unwrap())
        .collect();
    // Base shear equals the first-storey shear.
    let (shear1, base) = (row[22], row[32]);
    assert!(
        (shear1 - base).abs() <= 1e-9 * base.abs().max(1.0),
        "{shear1} vs {base}"
    );
    assert!(s["engineering"]["peak_drift_m"].as_array().unwrap().len() == 10);
    assert!(s["input_motion"]["pga_m_s2"].as_f64().unwrap() > 0.0);
    // Times are rounded: no float noise in history.csv.
    let hist = std::fs::read_to_string(out.join("history.csv")).unwrap();
    assert!(
        hist.lines().skip(1).all(|l| l.split(',').next().unwrap().len() <= 8),
        "float noise in t"
    );
    for f in ["ground_motion.csv", "fourier.csv", "spectrum.csv"] {
        assert!(
            std::fs::read_to_string(out.join(f)).unwrap().lines().count() > 50,
            "{f}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}
