//! The compensators side by side on the benchmark (`substep benchmark rths --compare`,
//! docs/benchmark.md "Comparison"): each controller with its one preset setting, every case,
//! with and without sensor noise, nominal and on perturbed plants, and the CPU time each
//! controller takes per sample.
//!
//! The CPU time is measured on the controller alone: the nominal run's desired and measured
//! displacements are replayed through a freshly built controller, so the plant, the numerical
//! substructure and the evaluation do not count. (A clock per sample inside the loop would cost
//! as much as the cheaper controllers.)

use super::{
    ControllerKind, ControllerSpec, RthsInput, RthsResult, SAMPLE_TIME, StudySetup, perturbed_stats, run, run_study,
};
use crate::error::Result;
use serde_json::{Value, json};
use std::time::Instant;

/// The controllers of the comparison, in table order (`inverse_fir` is refused on the
/// benchmark, docs/benchmark.md).
pub const COMPARED: &[ControllerKind] = &[
    ControllerKind::None,
    ControllerKind::Sample,
    ControllerKind::Polynomial,
    ControllerKind::Ats,
    ControllerKind::Amb,
    ControllerKind::Arx,
];

/// One controller on one case, with or without noise.
#[derive(Debug, Clone)]
pub struct ComparisonRow {
    pub kind: ControllerKind,
    pub noise: bool,
    pub case: u8,
    pub nominal: RthsResult,
    /// Perturbed plants run, stable among them, under the force capacity among them.
    pub perturbed: usize,
    pub stable: usize,
    pub under_capacity: usize,
    /// Largest J2 and J4 [%] and force \[N\] over the stable perturbed runs (NaN if none).
    pub worst_j2: f64,
    pub worst_j4: f64,
    pub worst_force: f64,
    /// CPU time of the controller per sample \[s\] (replayed on the nominal run's signals; NaN
    /// if the nominal run diverged before a full record).
    pub cpu_per_sample: f64,
}

impl ComparisonRow {
    /// One row as JSON (`substep benchmark rths --compare --json`, Python's
    /// `substep.benchmark.compare`): J in %, forces in N, CPU time in µs per sample; null where
    /// a value does not exist (a diverged run, no stable perturbed run).
    pub fn json(&self) -> Value {
        let finite = |x: f64| if x.is_finite() { json!(x) } else { Value::Null };
        let j = |i: usize| self.nominal.criteria.map_or(Value::Null, |c| json!(c.j[i]));
        json!({
            "controller": self.kind.name(),
            "noise": self.noise,
            "case": self.case,
            "J2": j(1),
            "J4": j(3),
            "max_force": finite(self.nominal.max_force),
            "stable": self.nominal.stable,
            "perturbed": self.perturbed,
            "perturbed_stable": self.stable,
            "under_capacity": self.under_capacity,
            "worst_J2": finite(self.worst_j2),
            "worst_J4": finite(self.worst_j4),
            "worst_force": finite(self.worst_force),
            "cpu_us_per_sample": finite(self.cpu_per_sample * 1e6),
        })
    }
}

impl StudySetup {
    /// The comparison of [`COMPARED`] on this setup's cases, record and perturbed plants (the
    /// setup's own controller is not used).
    pub fn compare(&self) -> Result<Vec<ComparisonRow>> {
        compare(
            &self.base,
            &self.cases,
            COMPARED,
            self.perturbed.unwrap_or(0),
            self.seed,
        )
    }

    /// The object of `--compare --json` for `rows` of [`Self::compare`].
    pub fn comparison_json(&self, rows: &[ComparisonRow]) -> Value {
        json!({
            "benchmark": "rths",
            "record": self.base.record.name,
            "intensity": self.base.intensity,
            "perturbed": self.perturbed.unwrap_or(0),
            "seed": self.seed,
            "comparison": rows.iter().map(ComparisonRow::json).collect::<Vec<_>>(),
        })
    }
}

/// Run the comparison of `kinds` on the cases of `base` (its controller is replaced by each
/// kind's preset; its noise setting by on/off), `perturbed` plants per case (0: none) from
/// `seed`. Rows in the order kind, noise (on first), case.
pub fn compare(
    base: &RthsInput,
    cases: &[super::Case],
    kinds: &[ControllerKind],
    perturbed: usize,
    seed: u64,
) -> Result<Vec<ComparisonRow>> {
    let mut rows = Vec::new();
    for &kind in kinds {
        for noise in [true, false] {
            let mut input = base.clone();
            input.controller = ControllerSpec::preset(kind);
            input.noise = noise;
            let study = run_study(&input, cases, &[None], (perturbed > 0).then_some(perturbed), seed)?;
            for row in study {
                let stats = perturbed_stats(&row.perturbed);
                let runs = &row.perturbed;
                let stable = runs.iter().filter(|(_, r)| r.stable).count();
                let under = runs.iter().filter(|(_, r)| !r.capacity_exceeded).count();
                let worst = |i: usize| stats.max[i];
                let worst_force = runs
                    .iter()
                    .filter(|(_, r)| r.stable)
                    .map(|(_, r)| r.max_force)
                    .fold(f64::NAN, f64::max);
                let mut replay = input.clone();
                replay.case = super::Case::new(row.case)?;
                let cpu_per_sample = controller_cpu_per_sample(&replay)?;
                rows.push(ComparisonRow {
                    kind,
                    noise,
                    case: row.case,
                    nominal: row.nominal,
                    perturbed: runs.len(),
                    stable,
                    under_capacity: under,
                    worst_j2: worst(1),
                    worst_j4: worst(3),
                    worst_force,
                    cpu_per_sample,
                });
            }
        }
    }
    Ok(rows)
}

/// CPU time per sample of `input`'s controller, replayed on its nominal run's signals (the
/// median of 5 replays).
fn controller_cpu_per_sample(input: &RthsInput) -> Result<f64> {
    let mut with_history = input.clone();
    with_history.keep_history = true;
    let result = run(&with_history)?;
    let Some(history) = result.history.filter(|_| result.diverged_at.is_none()) else {
        return Ok(f64::NAN);
    };
    let mut times = Vec::with_capacity(5);
    for _ in 0..5 {
        let mut controller = input.controller.build(SAMPLE_TIME)?;
        let started = Instant::now();
        let mut sink = 0.0;
        for (d, x) in history.desired.iter().zip(&history.measured) {
            sink += controller.command(*d, *x);
        }
        let elapsed = started.elapsed().as_secs_f64();
        std::hint::black_box(sink);
        times.push(elapsed / history.desired.len() as f64);
    }
    times.sort_by(f64::total_cmp);
    Ok(times[2])
}
