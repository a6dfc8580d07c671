//! The yielding buildings, specimens and record shared by the real-time grid
//! (`realtime_nonlinear.rs`) and the CR / KR-α tests (`explicit_substructure.rs`): two
//! buildings with three record scales from elastic to ductility > 5, a spring–dashpot and a
//! Bouc–Wen damper at floor 1, El Centro's strong motion.

use std::path::Path;

/// El Centro of the RTHS benchmark from its first non-zero sample (5 s in the file), so the
/// wall clock is spent on motion.
pub fn write_record(dir: &Path) {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/data/rths/elcentro.csv")).unwrap();
    let mut out = String::from("t,a_g\n");
    let mut t0 = None;
    for line in text.lines().filter(|l| !l.starts_with('#') && !l.starts_with('t')) {
        let mut f = line.split(',');
        let (t, a): (f64, f64) = (f.next().unwrap().parse().unwrap(), f.next().unwrap().parse().unwrap());
        if t0.is_none() && a != 0.0 {
            t0 = Some(t - 0.02);
        }
        if let Some(t0) = t0 {
            out += &format!("{},{a}\n", t - t0);
        }
    }
    std::fs::write(dir.join("elcentro_strong.csv"), out).unwrap();
}

pub struct Structure {
    pub name: &'static str,
    pub storeys: &'static str,
    /// Yield drift of each storey [m].
    pub yield_drift: &'static [f64],
    /// Record scales: elastic, moderate, ductility > 5.
    pub scales: [f64; 3],
}

pub const STRUCTURES: [Structure; 2] = [
    Structure {
        name: "3-storey bilinear",
        storeys: r#"[structure.storeys]
masses    = [2.0e5, 2.0e5, 1.5e5]
stiffness = [3.0e8, 2.5e8, 2.0e8]
[structure.storeys.hysteresis]
kind = "bilinear"
yield_force = [6.0e5, 5.0e5, 3.5e5]
hardening = 0.02
"#,
        yield_drift: &[6.0e5 / 3.0e8, 5.0e5 / 2.5e8, 3.5e5 / 2.0e8],
        scales: [0.1, 0.5, 2.0],
    },
    Structure {
        name: "5-storey Bouc-Wen",
        storeys: r#"[structure.storeys]
masses    = [1.2e5, 1.2e5, 1.1e5, 1.0e5, 0.8e5]
stiffness = [2.0e8, 1.8e8, 1.6e8, 1.3e8, 1.0e8]
[structure.storeys.hysteresis]
kind = "bouc_wen"
yield_force = [5.0e5, 4.5e5, 4.0e5, 3.2e5, 2.5e5]
hardening = 0.05
"#,
        yield_drift: &[
            5.0e5 / 2.0e8,
            4.5e5 / 1.8e8,
            4.0e5 / 1.6e8,
            3.2e5 / 1.3e8,
            2.5e5 / 1.0e8,
        ],
        scales: [0.1, 0.5, 2.0],
    },
];

/// The specimens at floor 1: a linear spring–dashpot and a hysteretic (Bouc–Wen) damper.
pub const SPECIMENS: [(&str, &str); 2] = [
    (
        "spring-dashpot",
        "kind = \"linear_sdof\"\nstiffness = 5.0e7\ndamping = 2.0e5",
    ),
    (
        "Bouc-Wen damper",
        "kind = \"bouc_wen\"\nstiffness = 1.0e8\nalpha = 0.05\nyield_displacement = 0.002\ndamping = 2.0e5",
    ),
];
