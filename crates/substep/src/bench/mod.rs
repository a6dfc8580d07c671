//! Benchmark drivers: the models, the timed step loops, the statistics and the agreement check
//! of the comparisons with other tools. The CLI (`substep bench`) parses arguments and prints;
//! everything measured is here.
//!
//! ```
//! use substep::bench::{BenchModel, ModelBenchOptions, bench_model};
//! let r = bench_model(&ModelBenchOptions {
//!     model: BenchModel::Frame,
//!     dofs: 300,
//!     steps: 5,
//!     substeps: 4,
//!     second_core: false,
//!     yielding: false,
//! })
//! .unwrap();
//! assert_eq!(r.steps, 5);
//! assert!(r.solver.starts_with("supernodal") || r.solver.starts_with("banded"));
//! ```

mod compare;
mod models;
mod peers;
mod stats;
mod steps;

pub use compare::{check_agreement, max_rel_difference};
pub use models::{
    BenchModel, BuiltModel, DT, ModelBench, ModelBenchOptions, YIELD_DRIFT, YIELD_ROTATION, ZETA, ag,
    bench_frame_hinges, bench_model, build, build_hinged_frame, chain, monolithic_run, yielding_springs,
};
pub use peers::{AGREEMENT_TOLERANCE, BATCHES, CHECK_STEPS, CompareOptions, Comparison, ToolResult, compare};
pub use stats::{Spread, median, peak_rss_bytes, quantile, read_bandwidth_gbs, reset_peak_rss, thread_cpu_seconds};
pub use steps::{
    MonolithicResult, STEP_BENCH_DT, STEP_BENCH_ZETA, StepBench, StepBenchOptions, SubstructureCase,
    SubstructureResult, bench_steps,
};
