//! substep's monolithic integration of a 3-storey shear building against OpenSees (openseespy,
//! `tests/opensees/shear_building.py`): the relative displacement of every floor at every step
//! must agree to 1e-6 of that floor's peak.
//!
//! Both tools read the same record file: the El Centro record of `crates/substep/data/rths`,
//! resampled here to `DT` by linear interpolation (as substep samples a record) and cut to
//! `DURATION`, so neither tool interpolates between samples; both scale it by the same factor.
//! OpenSees: `zeroLength` springs between 1-D nodes (node 0 fixed), lumped masses,
//! `UniformExcitation` with a `Path` series, Rayleigh damping `rayleigh(α, 0, β, 0)` (β on the
//! initial stiffness, `-doRayleigh 1` on the elements).
//!
//! * linear, `average_acceleration` vs `Newmark 0.5 0.25` + Newton;
//! * linear, `alpha_os` (α = −0.1) vs `AlphaOS 0.9` (and `AlphaOS_TP 0.9`, identical for linear
//!   models);
//! * nonlinear `[structure.storeys]` (bilinear = `Steel01`, elastic_plastic = `ElasticPP`), with
//!   Newton and with α-OS (α = −0.05): `alpha_os` vs `AlphaOS 0.95` and `alpha_os_tp` vs
//!   `AlphaOS_TP 0.95` (`Linear -initial`); the two forms differ by ~1e-3 of the peak here.
//!
//! Python is `$SUBSTEP_PYTHON` if set, else `python3`; without openseespy every test prints
//! `SKIPPED: openseespy is not installed ...` and passes.

use std::path::{Path, PathBuf};
use std::process::Command;

use nalgebra::{DMatrix, SymmetricEigen};

const MASSES: [f64; 3] = [2.0e5, 2.0e5, 1.5e5];
const STIFFNESS: [f64; 3] = [3.0e8, 2.5e8, 2.0e8];
const YIELD_FORCE: [f64; 3] = [6.0e5, 5.0e5, 3.5e5];
const HARDENING: f64 = 0.02;
/// Damping ratio at modes 1 and 2 (Rayleigh).
const ZETA: f64 = 0.02;
const DT: f64 = 0.01;
/// Length of the record used [s] (the strong motion of El Centro).
const DURATION: f64 = 10.0;
/// Scale of the record in the nonlinear cases: every storey yields (peak drift ≥ 2 × the yield
/// drift, the first storey about 30 ×; checked on the OpenSees response).
const NONLINEAR_SCALE: f64 = 2.0;
/// Allowed deviation, relative to the peak |u| of each floor.
const TOLERANCE: f64 = 1e-6;

fn python() -> String {
    std::env::var("SUBSTEP_PYTHON").unwrap_or_else(|_| "python3".into())
}

fn openseespy_available() -> bool {
    Command::new(python())
        .args(["-c", "import openseespy.opensees"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false)
}

macro_rules! require_openseespy {
    () => {
        if !openseespy_available() {
            println!(
                "SKIPPED: openseespy is not installed (pip install openseespy, or set SUBSTEP_PYTHON to a Python \
                 that has it); the OpenSees comparison did not run"
            );
            return;
        }
    };
}

/// A fresh, empty directory for one test.
fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("substep-opensees-nl-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The El Centro record sampled at `i·DT`, `i = 0..=DURATION/DT`, by linear interpolation,
/// written to `dir/record.csv` (`t,a_g`).
fn write_record(dir: &Path) -> PathBuf {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../substep/data/rths/elcentro.csv");
    let text = std::fs::read_to_string(&src).unwrap();
    let (mut ts, mut vs) = (Vec::new(), Vec::new());
    for line in text.lines() {
        let mut cols = line.split(',').map(str::trim);
        if let (Some(Ok(t)), Some(Ok(a))) = (cols.next().map(str::parse::<f64>), cols.next().map(str::parse::<f64>)) {
            ts.push(t);
            vs.push(a);
        }
    }
    assert!(ts.len() > 100 && ts[0] == 0.0, "{}: unexpected format", src.display());
    let n = (DURATION / DT + 1e-9).floor() as usize + 1;
    let mut out = String::from("t,a_g\n");
    let mut j = 0;
    for i in 0..n {
        let t = i as f64 * DT;
        assert!(t <= *ts.last().unwrap(), "the record is shorter than DURATION");
        while j + 2 < ts.len() && ts[j + 1] <= t {
            j += 1;
        }
        let frac = ((t - ts[j]) / (ts[j + 1] - ts[j])).clamp(0.0, 1.0);
        let a = vs[j] + frac * (vs[j + 1] - vs[j]);
        out.push_str(&format!("{t:?},{a:?}\n"));
    }
    let path = dir.join("record.csv");
    std::fs::write(&path, out).unwrap();
    path
}

/// Initial stiffness matrix of the shear chain.
fn stiffness_matrix() -> DMatrix<f64> {
    let n = STIFFNESS.len();
    DMatrix::from_fn(n, n, |i, j| {
        let k = |s: usize| STIFFNESS.get(s).copied().unwrap_or(0.0);
        if i == j {
            k(i) + k(i + 1)
        } else if j == i + 1 {
            -k(j)
        } else if i == j + 1 {
            -k(i)
        } else {
            0.0
        }
    })
}

/// Rayleigh `(α, β)` with damping ratio `ZETA` at modes 1 and 2 of the initial stiffness:
/// `α = 2ζ ω1 ω2 / (ω1 + ω2)`, `β = 2ζ / (ω1 + ω2)`.
fn rayleigh() -> (f64, f64) {
    let k = stiffness_matrix();
    let n = MASSES.len();
    // M^{-1/2} K M^{-1/2} (M diagonal)
    let a = DMatrix::from_fn(n, n, |i, j| k[(i, j)] / (MASSES[i] * MASSES[j]).sqrt());
    let mut w: Vec<f64> = SymmetricEigen::new(a).eigenvalues.iter().map(|l| l.sqrt()).collect();
    w.sort_by(f64::total_cmp);
    let (w1, w2) = (w[0], w[1]);
    (2.0 * ZETA * w1 * w2 / (w1 + w2), 2.0 * ZETA / (w1 + w2))
}

fn toml_array(v: &[f64]) -> String {
    let items: Vec<String> = v.iter().map(|x| format!("{x:?}")).collect();
    format!("[{}]", items.join(", "))
}

fn toml_matrix(m: &DMatrix<f64>) -> String {
    let rows: Vec<String> = m
        .row_iter()
        .map(|r| toml_array(&r.iter().copied().collect::<Vec<_>>()))
        .collect();
    format!("[{}]", rows.join(", "))
}

/// `[ground_motion]`, `[output]` and `[structure.rayleigh]`, shared by all configs.
fn common_toml(scale: f64) -> String {
    let (alpha, beta) = rayleigh();
    format!(
        "[structure.rayleigh]\nalpha = {alpha:?}\nbeta = {beta:?}\n\n\
         [ground_motion]\nfile = \"record.csv\"\nscale = {scale:?}\n\n\
         [output]\ndir = \"out\"\nplots = false\n"
    )
}

/// The linear model as explicit matrices.
fn linear_toml(integrator: &str) -> String {
    let n = MASSES.len();
    let mass = DMatrix::from_fn(n, n, |i, j| if i == j { MASSES[i] } else { 0.0 });
    format!(
        "[structure]\nmass = {}\nstiffness = {}\n\n{}\n{integrator}",
        toml_matrix(&mass),
        toml_matrix(&stiffness_matrix()),
        common_toml(1.0)
    )
}

/// The nonlinear model in the `[structure.storeys]` form.
fn storeys_toml(kind: &str, integrator: &str) -> String {
    let hardening = if kind == "bilinear" {
        format!("hardening = {HARDENING:?}\n")
    } else {
        String::new()
    };
    format!(
        "[structure.storeys]\nmasses = {}\nstiffness = {}\n\n[structure.storeys.hysteresis]\nkind = \"{kind}\"\n\
         yield_force = {}\n{hardening}\n{}\n{integrator}",
        toml_array(&MASSES),
        toml_array(&STIFFNESS),
        toml_array(&YIELD_FORCE),
        common_toml(NONLINEAR_SCALE)
    )
}

/// The columns `t, u1..un` of a CSV file with a header.
fn read_displacements(path: &Path, n: usize) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let wanted: Vec<String> = std::iter::once("t".to_string())
        .chain((1..=n).map(|i| format!("u{i}")))
        .collect();
    let idx: Vec<usize> = wanted
        .iter()
        .map(|w| {
            header
                .iter()
                .position(|h| h == w)
                .unwrap_or_else(|| panic!("{}: no column {w}", path.display()))
        })
        .collect();
    let mut cols = vec![Vec::new(); idx.len()];
    for line in lines {
        let fields: Vec<&str> = line.split(',').collect();
        for (c, &i) in cols.iter_mut().zip(&idx) {
            c.push(fields[i].parse::<f64>().unwrap());
        }
    }
    cols
}

/// Runs substep on `config`: `t` and the first `n` displacements of `history.csv`;
/// `Err(stderr)` if it refuses or fails.
fn run_substep_dofs(dir: &Path, config: &str, n: usize) -> Result<Vec<Vec<f64>>, String> {
    std::fs::write(dir.join("test.toml"), config).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_substep"))
        .args(["run", "test.toml", "--quiet", "--no-plots"])
        .current_dir(dir)
        .output()
        .expect("the substep binary runs");
    if !out.status.success() {
        return Err(format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    Ok(read_displacements(&dir.join("out/history.csv"), n))
}

/// [`run_substep_dofs`] for the shear building.
fn run_substep(dir: &Path, config: &str) -> Result<Vec<Vec<f64>>, String> {
    run_substep_dofs(dir, config, MASSES.len())
}

/// Runs `tests/opensees/shear_building.py` with `integrator` ("newmark", "alpha_os",
/// "alpha_os_tp", "kr_alpha", "kr_alpha_tp"), OpenSees' parameter `alpha` (AlphaOS' α, or
/// KRAlphaExplicit's ρ∞), the hysteresis `kind` (None: linear) and `scale`.
fn run_opensees(dir: &Path, integrator: &str, alpha: f64, kind: Option<&str>, scale: f64) -> Vec<Vec<f64>> {
    let (ray_alpha, ray_beta) = rayleigh();
    let mut spec = serde_json::json!({
        "masses": MASSES,
        "stiffness": STIFFNESS,
        "rayleigh": {"alpha": ray_alpha, "beta": ray_beta},
        "dt": DT,
        "duration": DURATION,
        "record": dir.join("record.csv"),
        "scale": scale,
        "integrator": integrator,
        "alpha": alpha,
        "rho_inf": alpha,
        "tolerance": 1e-12,
    });
    if let Some(kind) = kind {
        let mut h = serde_json::json!({"kind": kind, "yield_force": YIELD_FORCE});
        if kind == "bilinear" {
            h["hardening"] = HARDENING.into();
        }
        spec["hysteresis"] = h;
    }
    let name = format!("opensees_{integrator}");
    let spec_path = dir.join(format!("{name}.json"));
    let out_path = dir.join(format!("{name}.csv"));
    std::fs::write(&spec_path, serde_json::to_string_pretty(&spec).unwrap()).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/opensees/shear_building.py");
    let out = Command::new(python())
        .arg(&script)
        .arg(&spec_path)
        .arg(&out_path)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "OpenSees ({integrator}) failed:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    read_displacements(&out_path, MASSES.len())
}

/// `max_t |u_a − u_b| / max_t |u_b|` per floor (same time grid required).
fn deviations(a: &[Vec<f64>], b: &[Vec<f64>]) -> Vec<f64> {
    assert_eq!(a[0].len(), b[0].len(), "different numbers of steps");
    for (ta, tb) in a[0].iter().zip(&b[0]) {
        assert!((ta - tb).abs() < 1e-9, "time grids differ: {ta} vs {tb}");
    }
    (1..a.len())
        .map(|j| {
            let peak = b[j].iter().fold(0.0_f64, |m, x| m.max(x.abs()));
            let dev = a[j].iter().zip(&b[j]).fold(0.0_f64, |m, (x, y)| m.max((x - y).abs()));
            dev / peak
        })
        .collect()
}

/// `[a, b, c]` with each number as `{:.3e}`.
fn exp(v: &[f64]) -> String {
    let items: Vec<String> = v.iter().map(|x| format!("{x:.3e}")).collect();
    format!("[{}]", items.join(", "))
}

fn peaks(u: &[Vec<f64>]) -> Vec<f64> {
    u[1..]
        .iter()
        .map(|c| c.iter().fold(0.0_f64, |m, x| m.max(x.abs())))
        .collect()
}

/// Prints the deviations of `case` and asserts them (within [`TOLERANCE`]).
fn check(case: &str, substep: &[Vec<f64>], opensees: &[Vec<f64>]) {
    check_within(case, substep, opensees, TOLERANCE);
}

/// [`check`] with another tolerance (the explicit schemes, which do not iterate).
fn check_within(case: &str, substep: &[Vec<f64>], opensees: &[Vec<f64>], tolerance: f64) {
    let dev = deviations(substep, opensees);
    eprintln!(
        "{case}: max|u_substep - u_opensees| / peak|u| per floor = {} (peaks {} m)",
        exp(&dev),
        exp(&peaks(opensees))
    );
    assert!(
        dev.iter().all(|d| *d <= tolerance),
        "{case}: deviation {} exceeds {tolerance:e} of the peak",
        exp(&dev)
    );
}

#[test]
fn linear_average_acceleration_matches_opensees_newmark() {
    require_openseespy!();
    let dir = temp_dir("linear-newmark");
    write_record(&dir);
    let config = linear_toml(&format!(
        "[integrator]\nscheme = \"average_acceleration\"\ndt = {DT:?}\nduration = {DURATION:?}\n"
    ));
    let sub = run_substep(&dir, &config).unwrap_or_else(|e| panic!("substep failed:\n{e}\nconfig:\n{config}"));
    let os = run_opensees(&dir, "newmark", 1.0, None, 1.0);
    assert_eq!(sub[0].len(), (DURATION / DT).round() as usize + 1);
    check(
        "linear, average_acceleration vs OpenSees Newmark(1/2, 1/4) + Newton",
        &sub,
        &os,
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn linear_alpha_os_matches_opensees_alphaos() {
    require_openseespy!();
    let dir = temp_dir("linear-alpha-os");
    write_record(&dir);
    let config = linear_toml(&format!(
        "[integrator]\nscheme = \"alpha_os\"\nalpha = -0.1\ndt = {DT:?}\nduration = {DURATION:?}\n"
    ));
    let sub = run_substep(&dir, &config).unwrap_or_else(|e| panic!("substep failed:\n{e}\nconfig:\n{config}"));
    let os = run_opensees(&dir, "alpha_os", 0.9, None, 1.0);
    check("linear, alpha_os -0.1 vs OpenSees AlphaOS 0.9", &sub, &os);
    // For a linear model OpenSees' trapezoidal variant is the same scheme.
    let tp = run_opensees(&dir, "alpha_os_tp", 0.9, None, 1.0);
    check("linear, alpha_os -0.1 vs OpenSees AlphaOS_TP 0.9", &sub, &tp);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Asserts that every storey of the response `u` (OpenSees') yields clearly: peak drift more than
/// twice the yield drift.
fn require_yielding(kind: &str, u: &[Vec<f64>]) {
    let ductility: Vec<f64> = (0..MASSES.len())
        .map(|s| {
            let below = |i: usize| if s == 0 { 0.0 } else { u[s][i] };
            let peak = (0..u[0].len()).fold(0.0_f64, |m, i| m.max((u[s + 1][i] - below(i)).abs()));
            peak / (YIELD_FORCE[s] / STIFFNESS[s])
        })
        .collect();
    eprintln!("{kind}, scale {NONLINEAR_SCALE}: OpenSees peak drift / yield drift per storey = {ductility:.2?}");
    assert!(
        ductility.iter().all(|&d| d > 2.0),
        "storeys do not yield clearly: {ductility:?}"
    );
}

/// One nonlinear case: `kind` with substep's `scheme` (and `alpha`) against OpenSees.
fn nonlinear_case(kind: &str, scheme: &str) {
    require_openseespy!();
    let dir = temp_dir(&format!("{kind}-{scheme}"));
    write_record(&dir);
    let integrator = match scheme {
        "average_acceleration" => {
            format!(
                "[integrator]\nscheme = \"average_acceleration\"\ndt = {DT:?}\nduration = {DURATION:?}\ntolerance = 1e-12\n"
            )
        }
        "alpha_os" | "alpha_os_tp" => {
            format!("[integrator]\nscheme = \"{scheme}\"\nalpha = -0.05\ndt = {DT:?}\nduration = {DURATION:?}\n")
        }
        _ => unreachable!(),
    };
    let config = storeys_toml(kind, &integrator);
    let sub = run_substep(&dir, &config).unwrap_or_else(|e| panic!("substep failed:\n{e}\nconfig:\n{config}"));
    let (os_name, os) = match scheme {
        "average_acceleration" => (
            "Newmark(1/2, 1/4) + Newton",
            run_opensees(&dir, "newmark", 1.0, Some(kind), NONLINEAR_SCALE),
        ),
        "alpha_os" => (
            "AlphaOS 0.95",
            run_opensees(&dir, "alpha_os", 0.95, Some(kind), NONLINEAR_SCALE),
        ),
        _ => (
            "AlphaOS_TP 0.95",
            run_opensees(&dir, "alpha_os_tp", 0.95, Some(kind), NONLINEAR_SCALE),
        ),
    };
    // The test itself: every storey must yield clearly in the reference response.
    require_yielding(kind, &os);

    check(&format!("{kind}, {scheme} vs OpenSees {os_name}"), &sub, &os);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bilinear_average_acceleration_matches_opensees_newmark_steel01() {
    nonlinear_case("bilinear", "average_acceleration");
}

#[test]
fn bilinear_alpha_os_matches_opensees_alphaos_steel01() {
    nonlinear_case("bilinear", "alpha_os");
}

#[test]
fn elastic_plastic_average_acceleration_matches_opensees_newmark_elasticpp() {
    nonlinear_case("elastic_plastic", "average_acceleration");
}

#[test]
fn elastic_plastic_alpha_os_matches_opensees_alphaos_elasticpp() {
    nonlinear_case("elastic_plastic", "alpha_os");
}

#[test]
fn alpha_os_tp_matches_opensees_alphaos_tp() {
    nonlinear_case("bilinear", "alpha_os_tp");
    nonlinear_case("elastic_plastic", "alpha_os_tp");
}

/// The 2-bay, 3-storey hinged frame of the frame tests: `kind` of its hinges (`elastic`,
/// `bilinear`, `elastic_plastic`), with or without gravity and P-Δ of the columns.
fn hinged_frame_config(kind: &str, p_delta: bool, scale: f64) -> String {
    let law = match kind {
        "bilinear" => "kind = \"bilinear\"\nhardening = 0.02\n",
        "elastic_plastic" => "kind = \"elastic_plastic\"\n",
        _ => "kind = \"elastic\"\n",
    };
    let moments = if kind == "elastic" {
        ""
    } else {
        "beam_yield_moment = 4.6e5\ncolumn_yield_moment = 6.6e5\n"
    };
    let gravity = if p_delta {
        "p_delta = true\ngravity = true\n"
    } else {
        ""
    };
    format!(
        "[structure.frame]\nbays = 2\nstories = 3\n{gravity}\n[structure.frame.hinges]\nat = \"both\"\n\
         {law}{moments}stiffness_factor = 10.0\n\n[structure.rayleigh]\nalpha = 0.2\nbeta = 0.001\n\n\
         [ground_motion]\nfile = \"record.csv\"\nscale = {scale:?}\n\n[integrator]\n\
         scheme = \"average_acceleration\"\ndt = {DT:?}\nduration = {DURATION:?}\ntolerance = 1e-12\n\n\
         [output]\ndir = \"out\"\nplots = false\n"
    )
}

/// DOFs of the frame grid (3 per node, 3 column lines, 3 storeys).
const FRAME_DOFS: usize = 27;

/// Runs substep on a frame config in `dir`: the grid DOFs' columns.
fn run_frame(dir: &Path, config: &str) -> Vec<Vec<f64>> {
    run_substep_dofs(dir, config, FRAME_DOFS).unwrap_or_else(|e| panic!("substep failed: {e}\n{config}"))
}

/// Runs `tests/opensees/hinged_frame.py` on the frame of [`hinged_frame_config`].
/// An explicit OpenSees integrator for the frame: `KRAlphaExplicit` (`"kr_alpha"`) or
/// `KRAlphaExplicit_TP` (`"kr_alpha_tp"`) with `rho_inf`; `mass_damping: false` drops the
/// mass-proportional Rayleigh term (`C = β K₀` only).
struct ExplicitFrame<'a> {
    integrator: &'a str,
    rho_inf: f64,
    mass_damping: bool,
}

/// `explicit`: OpenSees' explicit integrator, `None` for Newmark + Newton.
fn run_opensees_frame(
    dir: &Path,
    record: &Path,
    kind: &str,
    p_delta: bool,
    scale: f64,
    explicit: Option<ExplicitFrame>,
) -> Vec<Vec<f64>> {
    let (integrator, rho_inf, ray_alpha) = match &explicit {
        None => ("newmark", 1.0, 0.2),
        Some(e) => (e.integrator, e.rho_inf, if e.mass_damping { 0.2 } else { 0.0 }),
    };
    let spec = serde_json::json!({
        "integrator": integrator, "rho_inf": rho_inf,
        "bays": 2, "stories": 3, "bay_width": 6.0, "story_height": 3.5,
        "elastic_modulus": 210e9,
        "column": {"area": 149.1e-4, "inertia": 25_170e-8},
        "beam": {"area": 84.46e-4, "inertia": 23_130e-8},
        "density": 7850.0, "floor_mass_per_bay": 20_000.0,
        "hinges": {"at": "both", "kind": kind, "beam_yield_moment": 4.6e5, "column_yield_moment": 6.6e5,
                   "hardening": 0.02, "stiffness_factor": 10.0},
        "rayleigh": {"alpha": ray_alpha, "beta": 0.001},
        "p_delta": p_delta, "gravity": p_delta,
        "dt": DT, "scale": scale, "record": record,
    });
    let spec_path = dir.join("frame.json");
    std::fs::write(&spec_path, spec.to_string()).unwrap();
    let out_path = dir.join("opensees_frame.csv");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/opensees/hinged_frame.py");
    let o = Command::new(python())
        .arg(&script)
        .arg(&spec_path)
        .arg(&out_path)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "OpenSees failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    read_displacements(&out_path, FRAME_DOFS)
}

/// Largest deviation of `a` from `b` per DOF kind (ux, uy, θ) relative to the peak of that kind
/// over the nodes (the middle column's uy is zero by symmetry without gravity).
fn frame_deviations(a: &[Vec<f64>], b: &[Vec<f64>]) -> Vec<f64> {
    (0..3)
        .map(|k| {
            let cols: Vec<usize> = (0..FRAME_DOFS).filter(|d| d % 3 == k).map(|d| d + 1).collect();
            let peak = cols
                .iter()
                .flat_map(|&c| b[c].iter())
                .fold(0.0_f64, |m, x| m.max(x.abs()));
            let dev = cols
                .iter()
                .flat_map(|&c| a[c].iter().zip(&b[c]))
                .fold(0.0_f64, |m, (x, y)| m.max((x - y).abs()));
            dev / peak
        })
        .collect()
}

/// A plane frame with rotational hinges at every member end (`[structure.frame.hinges]`,
/// bilinear and elastic–perfectly plastic), Newmark + Newton, against OpenSees
/// (`tests/opensees/hinged_frame.py`: `elasticBeamColumn` + `zeroLength` hinges with `Steel01` /
/// `ElasticPP`, `equalDOF`, the same lumped masses and Rayleigh on the initial stiffness):
/// every grid DOF (ux, uy, θ of 9 nodes) within 1e-6 of the peak of its kind; the hinges yield
/// (the response differs from the same frame with elastic hinges by more than 5 %).
#[test]
fn hinged_frame_newton_matches_opensees() {
    require_openseespy!();
    let dir = temp_dir("hinged-frame");
    let record = write_record(&dir);
    let scale = 3.0;
    let elastic = run_frame(&dir, &hinged_frame_config("elastic", false, scale));
    for kind in ["bilinear", "elastic_plastic"] {
        let sub = run_frame(&dir, &hinged_frame_config(kind, false, scale));
        let os = run_opensees_frame(&dir, &record, kind, false, scale, None);
        let change = frame_deviations(&sub, &elastic)[0];
        eprintln!("{kind} hinges: largest ux change against elastic hinges {change:.3e} of the peak");
        assert!(change > 0.05, "the hinges hardly yield: {change}");
        let dev = frame_deviations(&sub, &os);
        eprintln!(
            "hinged frame, {kind} hinges, Newton vs OpenSees: max deviation (ux, uy, θ) / peak of its kind = {}",
            exp(&dev)
        );
        assert!(dev.iter().all(|d| *d <= TOLERANCE), "{kind}: {}", exp(&dev));
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The hinged frame under gravity (a static Newton state first, as OpenSees' static analysis and
/// `loadConst`) with P-Δ of the columns (OpenSees' `PDelta` transformation: the axial force
/// follows the response), Newmark + Newton against OpenSees: within 1e-6 of the peak of each
/// DOF kind, gravity state included; P-Δ changes the response (against gravity without P-Δ).
#[test]
fn hinged_frame_with_gravity_and_p_delta_matches_opensees() {
    require_openseespy!();
    let dir = temp_dir("hinged-frame-pdelta");
    let record = write_record(&dir);
    let scale = 3.0;
    let sub = run_frame(&dir, &hinged_frame_config("bilinear", true, scale));
    let os = run_opensees_frame(&dir, &record, "bilinear", true, scale, None);
    let dev = frame_deviations(&sub, &os);
    eprintln!(
        "hinged frame with gravity and P-Delta, Newton vs OpenSees: max deviation (ux, uy, θ) / peak of its kind = {}",
        exp(&dev)
    );
    assert!(dev.iter().all(|d| *d <= TOLERANCE), "{}", exp(&dev));
    // the gravity state is there (the first row) and P-Δ matters
    assert!(sub[2][0] < -1e-5, "floor 1 uy at t = 0: {}", sub[2][0]);
    let without = run_frame(
        &dir,
        &hinged_frame_config("bilinear", true, scale).replace("p_delta = true\n", ""),
    );
    let effect = frame_deviations(&sub, &without)[0];
    eprintln!("P-Delta changes ux by {effect:.3e} of the peak");
    assert!(effect > 1e-3, "P-Delta has no effect: {effect}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Allowed deviation of the explicit model-based schemes (CR, KR-α) from OpenSees, relative to
/// the peak: they do not iterate, so only round-off separates the two implementations.
const EXPLICIT_TOLERANCE: f64 = 1e-9;

/// `[integrator]` of substep's `cr` or `kr_alpha` (with `rho_inf`).
fn explicit_integrator(scheme: &str, rho_inf: f64) -> String {
    let rho = if scheme == "kr_alpha" {
        format!("rho_inf = {rho_inf:?}\n")
    } else {
        String::new()
    };
    format!("[integrator]\nscheme = \"{scheme}\"\n{rho}dt = {DT:?}\nduration = {DURATION:?}\n")
}

/// The linear shear building: `kr_alpha` (ρ∞ = 0, 0.5, 1) against OpenSees `KRAlphaExplicit ρ∞`,
/// and `cr` against `KRAlphaExplicit_TP 1.0` and `KRAlphaExplicit 1.0` (both are CR for a linear
/// model): every floor within 1e-9 of its peak.
#[test]
fn linear_kr_alpha_and_cr_match_opensees_kralphaexplicit() {
    require_openseespy!();
    let dir = temp_dir("linear-kr-alpha");
    write_record(&dir);
    for rho in [0.0, 0.5, 1.0] {
        let sub = run_substep(&dir, &linear_toml(&explicit_integrator("kr_alpha", rho))).unwrap();
        let os = run_opensees(&dir, "kr_alpha", rho, None, 1.0);
        check_within(
            &format!("linear, kr_alpha rho_inf = {rho} vs OpenSees KRAlphaExplicit {rho}"),
            &sub,
            &os,
            EXPLICIT_TOLERANCE,
        );
    }
    let cr = run_substep(&dir, &linear_toml(&explicit_integrator("cr", 1.0))).unwrap();
    let tp = run_opensees(&dir, "kr_alpha_tp", 1.0, None, 1.0);
    check_within(
        "linear, cr vs OpenSees KRAlphaExplicit_TP 1.0",
        &cr,
        &tp,
        EXPLICIT_TOLERANCE,
    );
    let one_point = run_opensees(&dir, "kr_alpha", 1.0, None, 1.0);
    check_within(
        "linear, cr vs OpenSees KRAlphaExplicit 1.0",
        &cr,
        &one_point,
        EXPLICIT_TOLERANCE,
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The yielding shear building (`Steel01` and `ElasticPP` storeys, every storey past twice its
/// yield drift): `kr_alpha` ρ∞ = 0.5 against `KRAlphaExplicit 0.5` (springs at `u_{n+α_f}`), `cr`
/// against `KRAlphaExplicit_TP 1.0` (forces at `t_{n+1}`): within 1e-9 of the peak. The two
/// forms are different schemes on a yielding model (they differ by more than 1e-4 here).
#[test]
fn yielding_storeys_kr_alpha_and_cr_match_opensees() {
    require_openseespy!();
    for kind in ["bilinear", "elastic_plastic"] {
        let dir = temp_dir(&format!("{kind}-kr-alpha"));
        write_record(&dir);
        let kr = run_substep(&dir, &storeys_toml(kind, &explicit_integrator("kr_alpha", 0.5))).unwrap();
        let os = run_opensees(&dir, "kr_alpha", 0.5, Some(kind), NONLINEAR_SCALE);
        require_yielding(kind, &os);
        check_within(
            &format!("{kind}, kr_alpha 0.5 vs OpenSees KRAlphaExplicit 0.5"),
            &kr,
            &os,
            EXPLICIT_TOLERANCE,
        );
        let cr = run_substep(&dir, &storeys_toml(kind, &explicit_integrator("cr", 1.0))).unwrap();
        let tp = run_opensees(&dir, "kr_alpha_tp", 1.0, Some(kind), NONLINEAR_SCALE);
        check_within(
            &format!("{kind}, cr vs OpenSees KRAlphaExplicit_TP 1.0"),
            &cr,
            &tp,
            EXPLICIT_TOLERANCE,
        );
        let one_point = run_opensees(&dir, "kr_alpha", 1.0, Some(kind), NONLINEAR_SCALE);
        let forms = deviations(&cr, &one_point);
        eprintln!(
            "{kind}: cr vs KRAlphaExplicit 1.0 (forces at the mid-step) differ by {}",
            exp(&forms)
        );
        assert!(
            forms.iter().any(|d| *d > 1e-4),
            "{kind}: the forms do not differ: {}",
            exp(&forms)
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}

/// The 2 × 3 hinged frame (hinges at every member end; `FullGeneral`, the same lumped masses and
/// Rayleigh on the initial stiffness), every grid DOF within 1e-9 of the peak of its kind
/// (ux, uy, θ):
/// * yielding (bilinear) hinges: `kr_alpha` ρ∞ = 0.5 against `KRAlphaExplicit 0.5`;
/// * yielding hinges, stiffness-proportional damping only: `cr` against `KRAlphaExplicit_TP 1.0`;
/// * elastic hinges, full Rayleigh: `cr` against `KRAlphaExplicit 1.0` (CR for a linear model).
///
/// Why not `cr` against `KRAlphaExplicit_TP 1.0` with the mass-proportional term: on this frame
/// OpenSees' two forms disagree with each other by 2e-5 of the peak even with elastic hinges,
/// where both are CR, as soon as `C` has a mass-proportional part. Without it they agree to
/// 1.4e-12, and so does substep's `cr` with each. The shear building (no `equalDOF` hinge nodes)
/// shows no such difference (`yielding_storeys_kr_alpha_and_cr_match_opensees`).
#[test]
fn hinged_frame_kr_alpha_and_cr_match_opensees() {
    require_openseespy!();
    let dir = temp_dir("hinged-frame-kr-alpha");
    let record = write_record(&dir);
    let scale = 3.0;
    let explicit = |kind: &str, scheme: &str, rho: f64| {
        let newton = hinged_frame_config(kind, false, scale);
        let block = explicit_integrator(scheme, rho);
        let start = newton.find("[integrator]").unwrap();
        let end = start + newton[start..].find("\n\n").unwrap() + 1;
        format!("{}{block}{}", &newton[..start], &newton[end..])
    };
    let elastic = run_frame(&dir, &hinged_frame_config("elastic", false, scale));
    let cases = [
        ("bilinear", "kr_alpha", "kr_alpha", 0.5, true),
        ("bilinear", "cr", "kr_alpha_tp", 1.0, false),
        ("elastic", "cr", "kr_alpha", 1.0, true),
    ];
    for (kind, scheme, os_name, rho, mass_damping) in cases {
        let mut config = explicit(kind, scheme, rho);
        if !mass_damping {
            config = config.replace(
                "[structure.rayleigh]\nalpha = 0.2\n",
                "[structure.rayleigh]\nalpha = 0.0\n",
            );
            assert!(config.contains("alpha = 0.0\n"), "{config}");
        }
        let sub = run_frame(&dir, &config);
        let os = run_opensees_frame(
            &dir,
            &record,
            kind,
            false,
            scale,
            Some(ExplicitFrame {
                integrator: os_name,
                rho_inf: rho,
                mass_damping,
            }),
        );
        let change = frame_deviations(&sub, &elastic)[0];
        if kind == "bilinear" {
            assert!(change > 0.05, "{scheme}: the hinges hardly yield: {change}");
        }
        let dev = frame_deviations(&sub, &os);
        eprintln!(
            "hinged frame, {kind} hinges, {scheme} vs OpenSees {os_name} {rho} (mass damping: {mass_damping}): \
             max deviation (ux, uy, θ) / peak of its kind = {} (against the elastic-hinge Newton run: {change:.3})",
            exp(&dev)
        );
        assert!(dev.iter().all(|d| *d <= EXPLICIT_TOLERANCE), "{scheme}: {}", exp(&dev));
    }
    let _ = std::fs::remove_dir_all(&dir);
}
