//! The step and sub-step paths allocate nothing: over the shipped examples (virtual labs with
//! actuator dynamics, delays, sensor noise, PID and estimated error forces, ARX phase-lag
//! compensation, hysteretic specimens and structures with Newton iterations, sparse models),
//! stepping a warmed-up simulation makes no allocation (its own test binary, for the counting
//! allocator).

use std::path::Path;
use substep::io::TestDefinition;
use substep::run::Simulation;
use substep::substructure::SubstepObserver;

#[path = "common/counting_alloc.rs"]
mod counting_alloc;
use counting_alloc::allocations;

struct Quiet;
impl SubstepObserver for Quiet {}

/// Allocations while stepping `def` for up to 200 steps after 20 warm-up steps.
fn allocations_while_stepping(def: &TestDefinition) -> (usize, usize) {
    let mut sim = Simulation::new(def).unwrap();
    let warm_up = 20;
    let steps = 200.min(sim.steps_total() - warm_up);
    for _ in 0..warm_up {
        sim.step(&mut Quiet).unwrap();
    }
    let before = allocations();
    for _ in 0..steps {
        sim.step(&mut Quiet).unwrap();
    }
    (allocations() - before, steps)
}

#[test]
fn stepping_and_the_run_loop_allocate_nothing() {
    // The counter counts (else every check below would pass).
    let before = allocations();
    let v = std::hint::black_box(vec![1u8; 64]);
    assert!(allocations() > before && v.len() == 64);

    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    let default = std::fs::read_to_string(examples.join("default.toml")).unwrap();
    let pid =
        "kind = \"pid\"                       # feed the last sub-step's force change into the next step\np = 1.0";
    assert!(default.contains(pid));
    let variants = [
        (
            "default with ARX phase-lag compensation",
            default.clone() + "\n[substructure.phase_lag]\nkind = \"arx\"\n",
        ),
        (
            "default with the estimated error force",
            default.replace(pid, "kind = \"arx\""),
        ),
        (
            "default with polynomial phase-lag compensation",
            default.clone() + "\n[substructure.phase_lag]\nkind = \"polynomial\"\n",
        ),
    ];
    for (name, text) in &variants {
        let def = TestDefinition::from_toml(text, name, &examples).unwrap();
        let (n, steps) = allocations_while_stepping(&def);
        println!("{name}: {n} allocations in {steps} steps");
        assert_eq!(n, 0, "{name}: {n} allocations in {steps} steps");
    }
    for name in [
        "default.toml",
        "tmd_substructure.toml",
        "two_specimens.toml",
        "servo_hydraulic.toml",
        "yielding_building.toml",
        "hinged_frame.toml",
        "shear_building_10.toml",
        "monolithic_tmd.toml",
    ] {
        let def = TestDefinition::from_file(examples.join(name)).unwrap();
        let (n, steps) = allocations_while_stepping(&def);
        println!("{name}: {n} allocations in {steps} steps");
        assert_eq!(n, 0, "{name}: {n} allocations in {steps} steps");
    }
    the_run_loop_allocates_nothing_per_step();
}

/// The run loop around the steps — the exact and same-integrator references, the summary's
/// statistics and tracking metrics — allocates nothing per step either: a whole run makes as
/// many allocations over 4 s as over 2 s. Not counted: the stability indicator (on by
/// default), whose model view re-computes the spectral radius of the test's step map (an
/// analysis that builds its matrices) whenever the identified specimen values move by more
/// than 0.5 %; it runs between steps, and in a real-time run on the writer thread, never on
/// the real-time one (docs/monitor.md).
/// (Called from the one test of this binary: the counter is the process's, and the test
/// harness allocates when a test ends.)
fn the_run_loop_allocates_nothing_per_step() {
    struct Rows;
    impl SubstepObserver for Rows {}
    impl substep::run::RunObserver for Rows {
        fn step(&mut self, _row: &substep::run::StepRow<'_>) -> std::ops::ControlFlow<()> {
            std::ops::ControlFlow::Continue(())
        }
    }
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    let default = std::fs::read_to_string(examples.join("default.toml")).unwrap();
    for extra in ["", "\n[substructure.phase_lag]\nkind = \"arx\"\n"] {
        let count = |seconds: f64| {
            let text = default.replace("duration = 20.0", &format!("duration = {seconds}")) + extra;
            let mut def = TestDefinition::from_toml(&text, "default", &examples).unwrap();
            def.substructure.as_mut().unwrap().stability_off = true;
            let before = allocations();
            let s = substep::run::execute(&def, &mut Rows, &std::sync::atomic::AtomicBool::new(false)).unwrap();
            assert!(s.completed && s.reference.as_ref().unwrap().same_integrator.is_some());
            allocations() - before
        };
        let (short, long) = (count(2.0), count(4.0));
        println!("run loop{extra:?}: {short} allocations over 2 s, {long} over 4 s");
        assert_eq!(short, long, "{extra:?}");
    }
}
