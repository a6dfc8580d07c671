//! Nonlinear numerical substructures (`[structure.storeys]` with hysteretic storeys): the
//! substructure test against its Newmark + Newton reference over a grid of intensities,
//! dampers and compensations; the Newton solution's energy balance; bad input. (OpenSees
//! comparisons: `crates/substep-cli/tests/opensees_nonlinear.rs`; the laws:
//! `tests/materials.rs`; the splitting's stability: `tests/analysis.rs`.)

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use substep::io::TestDefinition;
use substep::run::{HistoryTable, RunSummary, execute};

fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/rths")
}

/// The 3-storey building of the issue: floor masses, initial storey stiffness, bilinear storeys
/// (2 % hardening), Rayleigh 2 % at modes 1 and 2, El Centro (first 20 s) scaled by `scale`.
fn building(scale: f64, dt: f64, hysteresis: &str) -> String {
    format!(
        r#"
[structure.storeys]
masses    = [2.0e5, 2.0e5, 1.5e5]
stiffness = [3.0e8, 2.5e8, 2.0e8]
{hysteresis}
[structure.rayleigh]
zeta = 0.02
modes = [1, 2]
[ground_motion]
file = "elcentro.csv"
scale = {scale}
[integrator]
scheme = "average_acceleration"
dt = {dt}
duration = 20
"#
    )
}

const BILINEAR: &str = r#"[structure.storeys.hysteresis]
kind = "bilinear"
yield_force = [6.0e5, 5.0e5, 3.5e5]
hardening = 0.02
"#;

/// A linear spring + dashpot specimen at floor 1 behind an ideal actuator, k_sub = 10.
fn substructure(damping: f64, p: f64) -> String {
    let mut s = format!(
        r#"
[substructure]
coupling_dofs = [1]
substeps = 10
[[substructure.specimen]]
kind = "linear_sdof"
dof = 1
stiffness = 5.0e7
damping = {damping}
"#
    );
    if p > 0.0 {
        s += &format!("[substructure.error_force]\nkind = \"pid\"\np = {p}\n");
    }
    s
}

fn run(text: &str) -> (RunSummary, HistoryTable) {
    let def = TestDefinition::from_toml(text, "nonlinear.toml", &data_dir()).unwrap();
    let mut table = HistoryTable::default();
    let s = execute(&def, &mut table, &AtomicBool::new(false)).unwrap();
    (s, table)
}

fn refused(text: &str) -> String {
    match TestDefinition::from_toml(text, "bad.toml", &data_dir()) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => e.to_string(),
    }
}

/// Largest inter-storey drift over yield drift of the reference (storey 1 yields at 2 mm).
fn ductility(table: &HistoryTable) -> f64 {
    let h = &table.history;
    let u: Vec<&[f64]> = (1..=3).map(|k| h.column(&format!("uref{k}")).unwrap()).collect();
    let yield_drift = [6.0e5 / 3.0e8, 5.0e5 / 2.5e8, 3.5e5 / 2.0e8];
    (0..3)
        .map(|s| {
            let peak = (0..u[0].len())
                .map(|i| (u[s][i] - if s == 0 { 0.0 } else { u[s - 1][i] }).abs())
                .fold(0.0, f64::max);
            peak / yield_drift[s]
        })
        .fold(0.0, f64::max)
}

/// The substructure test of a yielding building against its own converged Newmark + Newton
/// reference: within 3 % of each floor's peak at Δt = 5 ms over intensities from ductility ~2 to
/// ~35, two dampers and with and without P = 1 error-force compensation. (At Δt = 10 ms the same
/// grid gives 2.4–6.2 %: the splitting's force error is O(Δt²), docs/theory.md §14.4.)
#[test]
fn a_yielding_building_test_is_within_3_percent_of_its_nonlinear_reference() {
    let mut worst: f64 = 0.0;
    let mut ductilities = Vec::new();
    for scale in [0.25, 0.5, 1.0, 2.0] {
        for damping in [2.0e5, 1.0e6] {
            for p in [0.0, 1.0] {
                let text = building(scale, 0.005, BILINEAR) + &substructure(damping, p);
                let (s, table) = run(&text);
                assert!(s.completed, "{:?}", s.failure);
                let r = s.reference.as_ref().expect("a nonlinear test has a reference");
                assert_eq!(r.scheme, "newmark_newton");
                let e = r.max_displacement_error;
                println!("scale {scale}, c {damping:e}, P {p}: max error {:.3} %", 100.0 * e);
                assert!(e < 0.03, "scale {scale}, c {damping}, P {p}: {e}");
                worst = worst.max(e);
                if damping == 2.0e5 && p == 0.0 {
                    ductilities.push(ductility(&table));
                }
            }
        }
    }
    println!("worst {:.3} %, ductility per scale {ductilities:.1?}", 100.0 * worst);
    // the grid spans moderate to very large yielding
    assert!(ductilities[0] > 1.5 && ductilities[3] > 20.0, "{ductilities:?}");
}

/// The same test with storeys that never yield has the linear error, so the splitting's share
/// is what the grid above measures: and the nonlinear reference then equals the linear one.
#[test]
fn storeys_that_never_yield_give_the_linear_test() {
    let strong = r#"[structure.storeys.hysteresis]
kind = "bilinear"
yield_force = 1.0e12
hardening = 0.02
"#;
    let (nl, nl_table) = run(&(building(1.0, 0.01, strong) + &substructure(2.0e5, 0.0)));
    let (lin, lin_table) = run(&(building(1.0, 0.01, "") + &substructure(2.0e5, 0.0)));
    for k in 1..=3 {
        let a = nl_table.history.column(&format!("u{k}")).unwrap();
        let b = lin_table.history.column(&format!("u{k}")).unwrap();
        let d = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
        let peak = b.iter().map(|x| x.abs()).fold(0.0, f64::max);
        // d(ũ) = k δ − k δ is round-off only
        assert!(
            d <= 1e-12 * peak,
            "floor {k}: the test differs by {d} m (peak {peak} m)"
        );
    }
    // the references: Newmark + Newton vs the exact solution of the linear model
    assert_eq!(nl.reference.as_ref().unwrap().scheme, "newmark_newton");
    assert_eq!(lin.reference.as_ref().unwrap().scheme, "exact");
}

/// Newmark + Newton of the monolithic yielding building: the energy balance (input = kinetic +
/// damping + the restoring force's work) closes to round-off, as it must for the trapezoidal
/// rule with converged iterations (docs/theory.md §14.3), while the storeys dissipate most of the
/// input by yielding.
#[test]
fn the_newton_solution_balances_its_energy() {
    let bouc_wen = "[structure.storeys.hysteresis]\nkind = \"bouc_wen\"\nyield_force = [6.0e5, 5.0e5, 3.5e5]\n\
                    hardening = 0.02\nn = 2\n";
    for hysteresis in [BILINEAR, bouc_wen] {
        let (s, _) = run(&building(2.0, 0.01, hysteresis));
        assert!(s.completed, "{:?}", s.failure);
        let e = s.engineering.as_ref().unwrap();
        let energy = &e.energy;
        println!("{energy:?}, relative error {:e}", e.energy_error_relative_max);
        assert!(e.energy_error_relative_max < 1e-9, "{}", e.energy_error_relative_max);
        // the springs' work (stored + dissipated by yielding) takes most of the input
        assert!(energy.strain > 0.5 * energy.input, "{energy:?}");
    }
}

#[test]
fn bad_nonlinear_input_is_refused_with_one_clear_line() {
    let with = |hysteresis: &str, integrator_extra: &str| {
        building(1.0, 0.01, hysteresis).replace("dt = 0.01\n", &format!("dt = 0.01\n{integrator_extra}"))
    };
    let cases: Vec<(String, &str)> = vec![
        (
            with(&BILINEAR.replace("[6.0e5, 5.0e5, 3.5e5]", "[6.0e5, 0.0, 3.5e5]"), ""),
            "structure.storeys.hysteresis.yield_force: storey 2: must be a finite force > 0 N, got 0",
        ),
        (
            with(&BILINEAR.replace("[6.0e5, 5.0e5, 3.5e5]", "-1.0"), ""),
            "storey 1: must be a finite force > 0 N, got -1",
        ),
        (
            with(&BILINEAR.replace("[6.0e5, 5.0e5, 3.5e5]", "[6.0e5, 5.0e5]"), ""),
            "yield_force: has 2 entries but the building has 3 storeys",
        ),
        (
            with(&BILINEAR.replace("hardening = 0.02", "hardening = 1.0"), ""),
            "structure.storeys.hysteresis.hardening: must lie in [0, 1)",
        ),
        (
            with(&BILINEAR.replace("hardening = 0.02", "hardening = -0.1"), ""),
            "must lie in [0, 1)",
        ),
        (
            with(&BILINEAR.replace("bilinear", "trilinear"), ""),
            "unknown hysteresis 'trilinear' (expected elastic, bilinear, bouc_wen or elastic_plastic)",
        ),
        (
            with(BILINEAR, "tolerance = 0.0\n"),
            "integrator.tolerance: must lie in (0, 1)",
        ),
        (
            with(BILINEAR, "tolerance = -1e-9\n"),
            "integrator.tolerance: must lie in (0, 1)",
        ),
        (
            with(BILINEAR, "max_iterations = 0\n"),
            "integrator.max_iterations: must lie in 1..=1000",
        ),
        (
            with(BILINEAR, "").replace("\"average_acceleration\"", "\"hht\""),
            "\"hht\" cannot integrate a nonlinear model",
        ),
        (
            with(BILINEAR, "").replace("\"average_acceleration\"", "\"exact\""),
            "\"exact\" cannot integrate a nonlinear model",
        ),
        (
            with(BILINEAR, "").replace("\"average_acceleration\"", "\"central_difference\""),
            "\"central_difference\" cannot integrate a nonlinear model",
        ),
        (
            with(BILINEAR, "").replace("stiffness = [3.0e8, 2.5e8, 2.0e8]", "stiffness = [3.0e8, 2.5e8]"),
            "structure.storeys.stiffness: has 2 entries but masses has 3 (one per storey)",
        ),
    ];
    for (text, expected) in cases {
        let e = refused(&text);
        assert!(e.contains(expected), "expected '{expected}' in: {e}");
        assert!(e.starts_with("bad.toml: "), "{e}");
        assert!(!e.contains('\n'), "one line: {e}");
    }
}

/// A Newton iteration that cannot converge stops the run at the step, naming the residual; the
/// steps before are recorded.
#[test]
fn a_newton_iteration_that_does_not_converge_stops_the_run_at_its_step() {
    let text = building(2.0, 0.01, BILINEAR).replace("dt = 0.01\n", "dt = 0.01\nmax_iterations = 1\n");
    let def = TestDefinition::from_toml(&text, "nonlinear.toml", &data_dir()).unwrap();
    let mut table = HistoryTable::default();
    let s = execute(&def, &mut table, &AtomicBool::new(false)).unwrap();
    assert!(!s.completed);
    let failure = s.failure.unwrap().to_string();
    println!("{failure}");
    assert!(
        failure.contains("Newton–Raphson did not converge in 1 iterations"),
        "{failure}"
    );
    assert!(failure.contains("residual force"), "{failure}");
    assert!(failure.contains(&format!("step {}", s.steps_done + 1)), "{failure}");
    assert_eq!(table.history.rows(), s.steps_done + 1);
}

/// The linear building with a hysteretic specimen at floor 1 (k_sub = 10, ideal actuator).
fn hysteretic_specimen(specimen: &str, dt: f64) -> String {
    building(1.0, dt, "")
        + &format!(
            r#"
[substructure]
coupling_dofs = [1]
substeps = 10
[[substructure.specimen]]
dof = 1
damping = 2.0e5
{specimen}
"#
        )
}

const BOUC_WEN: &str = "kind = \"bouc_wen\"\nstiffness = 1.0e8\nalpha = 0.05\nyield_displacement = 0.002";
const FRICTION: &str = "kind = \"friction\"\nslip_force = 1.5e5\nstiffness = 1.0e8";

/// Bouc–Wen and stick–slip friction specimens have a Newmark + Newton reference now: the test
/// reports its error against it, the error is small (ideal actuator, 10 sub-steps) and shrinks
/// with Δt as the algorithm's error does, and the specimen yields (it is a nonlinear test).
#[test]
fn hysteretic_specimen_tests_report_their_error_against_a_nonlinear_reference() {
    for (name, specimen) in [("bouc_wen", BOUC_WEN), ("friction", FRICTION)] {
        let mut errors = Vec::new();
        for dt in [0.01, 0.005] {
            let (s, table) = run(&hysteretic_specimen(specimen, dt));
            assert!(s.completed, "{name}: {:?}", s.failure);
            let r = s.reference.as_ref().unwrap_or_else(|| panic!("{name}: no reference"));
            assert_eq!(r.scheme, "newmark_newton");
            assert!(r.max_force_error.is_finite() && r.max_force_error > 0.0);
            errors.push(r.max_displacement_error);
            // the specimen yields: its peak force is near the yield force (not k · peak u)
            let u1 = table.history.column("u1").unwrap();
            let fc = table.history.column("fc1").unwrap();
            let peak_u = u1.iter().map(|x| x.abs()).fold(0.0, f64::max);
            let peak_f = fc.iter().map(|x| x.abs()).fold(0.0, f64::max);
            assert!(
                peak_f < 0.5 * 1.0e8 * peak_u,
                "{name}: peak force {peak_f} N, k u {}",
                1.0e8 * peak_u
            );
        }
        println!(
            "{name}: max displacement error {:.3} % (dt 10 ms), {:.3} % (5 ms)",
            100.0 * errors[0],
            100.0 * errors[1]
        );
        assert!(errors[1] < 0.01, "{name}: {errors:?}");
        assert!(
            errors[1] < errors[0],
            "{name}: the error must shrink with dt: {errors:?}"
        );
    }
}

/// Replayed forces and rate-dependent friction have no model to integrate: no reference, and
/// the reason is named.
#[test]
fn specimens_without_a_model_have_no_reference_and_say_why() {
    let smooth = "kind = \"friction\"\nslip_force = 1.5e5\nmodel = \"smooth\"\nv_ref = 0.01";
    let def = TestDefinition::from_toml(&hysteretic_specimen(smooth, 0.01), "smooth.toml", &data_dir()).unwrap();
    assert!(substep::run::Reference::new(&def).unwrap().is_none());
    let why = substep::run::Reference::unavailable(&def).unwrap();
    assert!(why.contains("smooth"), "{why}");
    let def = TestDefinition::from_toml(&hysteretic_specimen(BOUC_WEN, 0.01), "bw.toml", &data_dir()).unwrap();
    assert!(substep::run::Reference::unavailable(&def).is_none());
}

/// Newton on sparse storage (the path of large models: the tangent assembled as CSC and
/// factorised by the sparse Cholesky) gives the dense result; so does the splitting in the
/// sub-step controller.
#[test]
fn sparse_and_dense_storage_give_the_same_nonlinear_run() {
    let with = |storage: &str, sub: &str| {
        run(&(building(2.0, 0.01, BILINEAR) + &format!("[structure]\nstorage = \"{storage}\"\n") + sub))
    };
    let sub = substructure(2.0e5, 0.0);
    for (name, extra) in [("monolithic Newton", ""), ("substructure test", sub.as_str())] {
        let (a, b) = (with("dense", extra), with("sparse", extra));
        for col in ["u1", "u2", "u3"] {
            let x = a.1.history.column(col).unwrap();
            let y = b.1.history.column(col).unwrap();
            let peak = x.iter().map(|v| v.abs()).fold(0.0, f64::max);
            let d = x.iter().zip(y).map(|(p, q)| (p - q).abs()).fold(0.0, f64::max);
            assert!(
                d <= 1e-9 * peak,
                "{name}, {col}: dense and sparse differ by {d} m (peak {peak} m)"
            );
        }
    }
}

/// `[structure.frame.hinges]`: bad input is refused in one line naming the key.
#[test]
fn bad_hinge_input_is_refused_with_one_clear_line() {
    let frame = |frame_keys: &str, hinges: &str| {
        format!(
            "[structure.frame]\n{frame_keys}\n[structure.frame.hinges]\n{hinges}\n[ground_motion]\n\
             file = \"elcentro.csv\"\n[integrator]\nscheme = \"average_acceleration\"\ndt = 0.01\nduration = 1\n"
        )
    };
    let cases = [
        (
            frame(
                "bays = 0\nstories = 3",
                "at = \"beams\"\nkind = \"bilinear\"\nbeam_yield_moment = 1e5\nhardening = 0.02",
            ),
            "structure.frame.hinges.at: \"beams\" asks for beam hinges, but the frame has no beams (bays = 0)",
        ),
        (
            frame("", "at = \"walls\"\nkind = \"bilinear\""),
            "structure.frame.hinges.at: unknown location 'walls' (expected beams, columns or both)",
        ),
        (
            frame(
                "",
                "at = \"beams\"\nkind = \"bilinear\"\nbeam_yield_moment = -1.0\nhardening = 0.02",
            ),
            "structure.frame.hinges.beam_yield_moment: must be a finite moment > 0 N·m, got -1",
        ),
        (
            frame(
                "",
                "at = \"both\"\nkind = \"bilinear\"\nbeam_yield_moment = 1e5\nhardening = 0.02",
            ),
            "structure.frame.hinges.column_yield_moment: missing",
        ),
        (
            frame(
                "",
                "at = \"beams\"\nkind = \"bilinear\"\nbeam_yield_moment = 1e5\ncolumn_yield_moment = 1e5\nhardening = 0.02",
            ),
            "structure.frame.hinges.column_yield_moment: is not used with at = \"beams\"",
        ),
        (
            frame(
                "",
                "at = \"beams\"\nkind = \"bilinear\"\nbeam_yield_moment = 1e5\nhardening = 1.5",
            ),
            "structure.frame.hinges.hardening: must lie in [0, 1)",
        ),
        (
            frame(
                "",
                "at = \"beams\"\nkind = \"bilinear\"\nbeam_yield_moment = 1e5\nhardening = 0.02\nstiffness_factor = 0.0",
            ),
            "structure.frame.hinges.stiffness_factor: must be a finite number > 0",
        ),
        (
            frame("dimensions = 3", "at = \"beams\"\nkind = \"elastic\""),
            "structure.frame.hinges: hinges are built for plane frames (dimensions = 2) only",
        ),
        (
            frame("gravity = true", "at = \"beams\"\nkind = \"elastic\"")
                .replace("\"average_acceleration\"", "\"alpha_os\""),
            "structure.frame.gravity: needs an implicit Newmark scheme",
        ),
        (
            frame("gravity = true", "at = \"beams\"\nkind = \"elastic\"")
                + "[substructure]\ncoupling_dofs = [1]\nsubsteps = 4\n[[substructure.specimen]]\nkind = \"linear_sdof\"\ndof = 1\nstiffness = 1e6\n",
            "structure.frame.gravity: is for monolithic runs: the sub-step algorithm starts at rest",
        ),
    ];
    for (text, expected) in cases {
        let e = refused(&text);
        assert!(e.contains(expected), "expected '{expected}' in: {e}");
        assert!(!e.contains('\n'), "one line: {e}");
    }
}
