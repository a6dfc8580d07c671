//! The benchmark loop allocates nothing per sample: the number of allocations of a whole run
//! does not depend on the number of samples (its own test binary, for the counting allocator).

use std::sync::Arc;
use substep::benchmark::rths::*;

#[path = "common/counting_alloc.rs"]
mod counting_alloc;
use counting_alloc::allocations as allocations_so_far;

fn allocations(seconds: f64, kind: ControllerKind, algorithm: Algorithm) -> usize {
    let rows: String = (0..=(seconds * 100.0) as usize)
        .map(|i| {
            let t = i as f64 * 0.01;
            format!("{t},{}\n", (2.0 * std::f64::consts::PI * 2.0 * t).sin())
        })
        .collect();
    let record = GroundRecord::parse_csv("sine", &rows).unwrap();
    let mut input = RthsInput::nominal(Case::new(1).unwrap(), ControllerSpec::preset(kind));
    input.record = Arc::new(record);
    input.intensity = 1.0;
    input.algorithm = algorithm;
    let before = allocations_so_far();
    let r = run(&input).unwrap();
    let n = allocations_so_far() - before;
    assert!(r.stable);
    n
}

#[test]
fn allocations_do_not_grow_with_the_run_length() {
    for (kind, algorithm) in [
        (ControllerKind::Sample, Algorithm::Benchmark),
        (ControllerKind::Arx, Algorithm::Benchmark),
        (ControllerKind::Sample, Algorithm::Substep(SubstepSpec::default())),
    ] {
        let short = allocations(2.0, kind, algorithm.clone());
        let long = allocations(4.0, kind, algorithm.clone());
        assert_eq!(short, long, "{kind:?} {algorithm:?}: {short} vs {long} allocations");
    }
}
