//! `[structure.reduction]` (Craig–Bampton with static correction, docs/config.md "Model
//! reduction"): on three frames the reduced test's coupling and roof displacements are compared
//! with the same test on the full model (the definition with the reduction table removed, run
//! by the same engine); the printed estimate bounds the measured error, enough modes bring it
//! under 1e-3, and bad reduction settings are refused before the test starts.

use std::path::Path;
use std::sync::atomic::AtomicBool;
use substep::io::TestDefinition;
use substep::run::{HistoryTable, RunSummary, execute};

/// A 3-D frame (2 × 2 bays, 4 storeys, 216 DOFs), a 2-D frame (3 bays, 8 storeys, 96 DOFs), a
/// 20-storey shear building: (structure tables, roof DOF 1-based).
fn frames() -> Vec<(&'static str, String, usize)> {
    vec![
        (
            "3-D frame",
            "[structure.frame]\ndimensions = 3\nbays = 2\nbays_y = 2\nstories = 4\n".into(),
            3 * 54 + 1,
        ),
        ("2-D frame", "[structure.frame]\nbays = 3\nstories = 8\n".into(), 85),
        (
            "shear building",
            "[structure.shear_building]\nstories = 20\nstory_mass = 2.0e5\nfirst_period = 1.5\n".into(),
            20,
        ),
    ]
}

/// The reduction methods: fixed-interface modes, load-dependent Ritz vectors.
const METHODS: [&str; 2] = ["craig_bampton", "ritz"];

fn definition(structure: &str, reduction: Option<(&str, usize, usize)>) -> TestDefinition {
    let reduction = reduction.map_or_else(String::new, |(method, modes, roof)| {
        format!("[structure.reduction]\nmethod = \"{method}\"\nmodes = {modes}\nkeep = [{roof}]\n")
    });
    let text = format!(
        r#"{structure}
[structure.rayleigh]
zeta = 0.02
modes = [1, 3]

{reduction}
[ground_motion]
file = "{records}/elcentro.csv"

[integrator]
scheme = "average_acceleration"
dt = 0.01
duration = 8.0

[substructure]
coupling_dofs = [1]
substeps = 10

[[substructure.specimen]]
kind = "linear_sdof"
dof = 1
stiffness = 2.0e6
damping = 2.0e5
"#,
        records = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/records")
    );
    TestDefinition::from_toml(&text, "reduction.toml", Path::new(".")).unwrap()
}

fn run(def: &TestDefinition) -> (RunSummary, HistoryTable) {
    let mut table = HistoryTable::default();
    let s = execute(def, &mut table, &AtomicBool::new(false)).unwrap();
    assert!(s.completed, "{:?}", s.reason);
    (s, table)
}

/// Peak |reduced − full| relative to the full run's peak, for the coupling DOF and the roof.
fn measured(reduced: &HistoryTable, full: &HistoryTable, roof: usize) -> [f64; 2] {
    let err = |red: &str, ful: &str| {
        let (a, b) = (reduced.history.column(red).unwrap(), full.history.column(ful).unwrap());
        let peak = b.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        a.iter().zip(b).fold(0.0_f64, |m, (x, y)| m.max((x - y).abs())) / peak
    };
    // The reduced model's first DOFs are the kept ones in order: DOF 1, then the roof.
    [err("u1", "u1"), err("u2", &format!("u{roof}"))]
}

#[test]
fn the_estimate_bounds_the_measured_error_on_three_frames() {
    for ((name, structure, roof), method) in frames().into_iter().flat_map(|f| METHODS.map(|m| (f.clone(), m))) {
        let (_, full) = run(&definition(&structure, None));
        let n_interior = definition(&structure, None).model.n_dofs() - 2;
        let mut last = f64::INFINITY;
        // Ritz vectors need a few more than modes before their error falls steadily.
        let counts = if method == "ritz" { [4, 8, 16] } else { [2, 4, 8] };
        for modes in counts.into_iter().filter(|&m| m <= n_interior) {
            let def = definition(&structure, Some((method, modes, roof)));
            let (s, reduced) = run(&def);
            let r = s.reduction.as_ref().unwrap();
            assert_eq!(r.kept_dofs, [1, roof]);
            assert_eq!(r.method, method);
            let m = measured(&reduced, &full, roof);
            let worst = m[0].max(m[1]);
            println!(
                "{name}, {method}, {modes} modes: estimate {:.3e}, measured {:.3e} (coupling {:.3e}, roof {:.3e}), enriched to {} modes",
                r.error_estimate, worst, m[0], m[1], r.estimate_modes
            );
            assert!(
                r.error_estimate >= worst,
                "{name}, {method}, {modes} modes: estimate {} < measured {worst}",
                r.error_estimate
            );
            // Not a bound by a mile: within 20x of the error.
            assert!(
                r.error_estimate <= 20.0 * worst.max(1e-6),
                "{name}, {method}, {modes} modes: estimate {} vs {worst}",
                r.error_estimate
            );
            // The library's own check against the full model measures the same error.
            let c = r.check.as_ref().unwrap();
            assert!(
                (c.max_error - worst).abs() <= 1e-9 * worst.max(1e-12),
                "check {} vs {worst}",
                c.max_error
            );
            assert!(worst < last, "{name}, {method}: more modes must not be worse");
            last = worst;
        }
    }
}

#[test]
fn enough_modes_bring_coupling_and_roof_within_1e_3_of_the_full_run() {
    // (method, modes or Ritz vectors) per frame.
    let counts = [
        [("craig_bampton", 80), ("ritz", 16)],
        [("craig_bampton", 24), ("ritz", 14)],
        [("craig_bampton", 14), ("ritz", 12)],
    ];
    for ((name, structure, roof), (method, modes)) in frames()
        .into_iter()
        .zip(counts)
        .flat_map(|(f, c)| c.map(|c| (f.clone(), c)))
    {
        let (_, full) = run(&definition(&structure, None));
        let def = definition(&structure, Some((method, modes, roof)));
        let (s, reduced) = run(&def);
        let m = measured(&reduced, &full, roof);
        println!(
            "{name}, {method}, {modes} modes: coupling {:.2e}, roof {:.2e}",
            m[0], m[1]
        );
        assert!(m[0] <= 1e-3 && m[1] <= 1e-3, "{name}, {method}: {m:?}");
        let r = s.reduction.unwrap();
        assert!(r.error_estimate >= m[0].max(m[1]));
        assert!(r.reduced_dofs < def.reduction.as_ref().unwrap().reduction.n_full / 2 || name == "shear building");
    }
}

fn refused(structure: &str, reduction: &str) -> String {
    let text = format!(
        "{structure}\n[structure.reduction]\n{reduction}\n[ground_motion]\ngenerator = \"harmonic\"\namplitude = 1.0\nfrequency = 1.0\n\
         [integrator]\nscheme = \"average_acceleration\"\ndt = 0.01\nduration = 1.0\n\
         [substructure]\ncoupling_dofs = [1]\nsubsteps = 4\n[[substructure.specimen]]\nkind = \"linear_sdof\"\ndof = 1\nstiffness = 1.0e6\n"
    );
    match TestDefinition::from_toml(&text, "bad.toml", Path::new(".")) {
        Ok(_) => panic!("accepted: {reduction}"),
        Err(e) => {
            let m = e.to_string();
            assert!(!m.contains('\n'), "one line: {m}");
            m
        }
    }
}

#[test]
fn bad_reduction_settings_are_refused_in_one_line() {
    let frame = "[structure.frame]\nbays = 1\nstories = 2\n"; // 12 DOFs
    let cases = [
        (
            "modes = 12",
            "structure.reduction.modes: 12 modes asked, but the model has 11",
        ),
        ("modes = 0", "structure.reduction.modes: must be at least 1"),
        ("", "structure.reduction: give modes"),
        (
            "modes = 2\nfrequency_max = 10.0",
            "structure.reduction.frequency_max: cannot be combined",
        ),
        (
            "frequency_max = -1.0",
            "structure.reduction.frequency_max: must be a positive frequency",
        ),
        (
            "modes = 2\nkeep = [13]",
            "structure.reduction.keep: DOF 13 is out of range",
        ),
        (
            "modes = 2\nmethod = \"guyan\"",
            "structure.reduction.method: unknown method 'guyan'",
        ),
        (
            "method = \"ritz\"\nfrequency_max = 10.0",
            "structure.reduction.frequency_max: method ritz takes modes",
        ),
        (
            "method = \"ritz\"\nmodes = 12",
            "structure.reduction.modes: 12 modes asked, but the model has 11",
        ),
        (
            "modes = 2\nkeep = [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12]",
            "structure.reduction: keeps all 12 DOFs",
        ),
    ];
    for (reduction, expected) in cases {
        let m = refused(frame, reduction);
        assert!(m.contains(expected), "{reduction}: {m}");
    }
    // A structure that is not held once the kept DOFs are (a singular K_II) cannot be solved.
    let matrices =
        |masses: &str, stiffness: &str| format!("[structure]\nmass = [[{masses}]]\nstiffness = {stiffness}\n");
    let m = refused(
        &matrices(
            "1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0",
            "[[2.0, -1.0, 0.0], [-1.0, 1.0, 0.0], [0.0, 0.0, 0.0]]",
        ),
        "modes = 1",
    );
    assert!(
        m.contains("structure.reduction (the structure with its kept DOFs held): is not positive definite"),
        "{m}"
    );
    // A yielding structure is not reduced (its springs act on the full model's drifts).
    let m = refused(
        "[structure.storeys]\nmasses = [1.0e5, 1.0e5, 1.0e5]\nstiffness = [1.0e8, 1.0e8, 1.0e8]\n\
         [structure.storeys.hysteresis]\nkind = \"bilinear\"\nyield_force = 1.0e5\nhardening = 0.02\n",
        "modes = 1",
    );
    assert!(m.contains("structure.reduction: reduces linear structures only"), "{m}");
}

/// A reduced model's DOFs past the kept ones are mass-normalised coordinates (`√kg · m`), not
/// metres: a heavy building's exceed the 1 000 m runaway bound while it moves centimetres, and
/// the run must not call that a divergence (it did: "runaway response on DOF 3").
#[test]
fn modal_coordinates_of_a_heavy_building_are_not_a_runaway() {
    let structure = "[structure.shear_building]\nstories = 20\nstory_mass = 2.0e9\nfirst_period = 1.5\n";
    let (_, full) = run(&definition(structure, None));
    let (s, reduced) = run(&definition(structure, Some(("ritz", 8, 20))));
    let coordinate = reduced.history.column("u3").unwrap();
    let largest = coordinate.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
    assert!(largest > 1.0e3, "the case must exercise the bound: {largest}");
    let roof = full.history.column("u20").unwrap();
    let peak = roof.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
    assert!(peak < 1.0, "the building moves {peak} m");
    let m = measured(&reduced, &full, 20);
    assert!(m[0].max(m[1]) < 1e-2, "{m:?}");
    assert!(s.completed);
}

/// With nearly every direction in the basis the reduced and the full run differ by their own
/// arithmetic (1e-13 here), which the estimate cannot predict: no warning below
/// `CHECK_FLOOR`.
#[test]
fn no_warning_at_the_arithmetic_floor() {
    let (_, structure, roof) = frames().remove(0);
    let (s, _) = run(&definition(&structure, Some(("ritz", 96, roof))));
    let r = s.reduction.as_ref().unwrap();
    let measured = r.check.as_ref().unwrap().max_error;
    assert!(measured < substep::run::reduction::CHECK_FLOOR, "{measured}");
    assert!(
        !s.warnings.iter().any(|w| w.contains("exceeds its estimate")),
        "{:?} (estimate {}, measured {measured})",
        s.warnings,
        r.error_estimate
    );
}
