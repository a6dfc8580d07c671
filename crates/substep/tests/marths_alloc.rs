//! The maRTHS loop allocates nothing per sample: the number of allocations of a whole run does
//! not depend on the number of samples (its own test binary, for the counting allocator).

use std::sync::Arc;
use substep::benchmark::marths::*;
use substep::benchmark::rths::GroundRecord;

#[path = "common/counting_alloc.rs"]
mod counting_alloc;
use counting_alloc::allocations as allocations_so_far;

fn allocations(seconds: f64, controller: &str, algorithm: Algorithm) -> usize {
    let rows: String = (0..=(seconds * 100.0) as usize)
        .map(|i| {
            let t = i as f64 * 0.01;
            format!("{t},{}\n", (2.0 * std::f64::consts::PI * 2.0 * t).sin())
        })
        .collect();
    let mut input = MarthsInput::new(Arc::new(GroundRecord::parse_csv("sine", &rows).unwrap()));
    input.controller = ControllerKind::parse(controller).unwrap();
    input.algorithm = algorithm;
    let reference = reference(&input).unwrap();
    let before = allocations_so_far();
    let r = run(&input, &reference).unwrap();
    let n = allocations_so_far() - before;
    assert!(!r.diverged);
    n
}

#[test]
fn allocations_do_not_grow_with_the_run_length() {
    for (controller, algorithm) in [
        ("rodeac", Algorithm::Benchmark),
        ("arx", Algorithm::Benchmark),
        ("arx_mimo", Algorithm::Benchmark),
        ("rodeac", Algorithm::Substep(SubstepSpec::default())),
    ] {
        let short = allocations(2.0, controller, algorithm.clone());
        let long = allocations(4.0, controller, algorithm.clone());
        assert_eq!(short, long, "{controller} {algorithm:?}: {short} vs {long} allocations");
    }
}
