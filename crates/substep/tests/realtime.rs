//! The real-time runner: SPSC ring, overlapped predictor, real-time runs against the offline
//! `SubstructureTest`, deadline accounting and the late-step policy. Functional checks only; no
//! timing thresholds (those belong to the benchmark).

use nalgebra::{DMatrix, DVector, dmatrix};
use std::sync::Mutex;
use std::time::Duration;
use substep::error::{Error, Result};
use substep::integrate::Kinematics;
use substep::model::{StructuralModel, TmdSystem, sdof};
use substep::realtime::{
    LatePolicy, LatencyHistogram, OverlapPredictor, RealtimeOptions, RealtimeResult, RealtimeRunner, RtSetting,
    SpscRing, StepRecordOwned, StopHandle,
};
use substep::specimen::SpecimenSpec;
use substep::substructure::{
    ErrorForceSpec, ExperimentalSubstructure, LimitedSite, SafetyLimits, SubstepController, SubstepSettings,
    SubstructureTest,
};
use substep::transfer::{ActuatorSpec, SensorSpec, VirtualLab};

/// Real-time runs share two cores; run them one at a time within this binary.
static RT: Mutex<()> = Mutex::new(());

fn rt_lock() -> std::sync::MutexGuard<'static, ()> {
    RT.lock().unwrap_or_else(|e| e.into_inner())
}

// ------------------------------------------------------------------------------------------------
// SPSC ring

#[test]
fn spsc_ring_preserves_order_across_threads() {
    const N: u64 = 1_000_000;
    let mut ring = SpscRing::new(1024, || 0u64);
    let (mut tx, mut rx) = ring.split();
    std::thread::scope(|s| {
        s.spawn(move || {
            for i in 0..N {
                while !tx.try_push_with(|slot| *slot = i) {
                    std::hint::spin_loop();
                }
            }
        });
        let mut expected = 0u64;
        while expected < N {
            match rx.try_pop_with(|v| *v) {
                Some(v) => {
                    assert_eq!(v, expected, "item out of order");
                    expected += 1;
                }
                None => std::thread::yield_now(),
            }
        }
        assert!(rx.try_pop_with(|v| *v).is_none());
    });
    assert_eq!(ring.overflows(), 0);
    assert!(ring.is_empty());
}

#[test]
fn spsc_ring_counts_overflow_when_the_consumer_stalls() {
    // Without a consumer: the first `capacity` pushes land, the rest are dropped and counted.
    let mut ring = SpscRing::new(8, || 0usize);
    {
        let (mut tx, mut rx) = ring.split();
        let landed = (0..20).filter(|&i| tx.push_or_drop(|s| *s = i)).count();
        assert_eq!(landed, 8);
        let got: Vec<usize> = std::iter::from_fn(|| rx.try_pop_with(|v| *v)).collect();
        assert_eq!(got, (0..8).collect::<Vec<_>>());
        assert!(tx.push_or_drop(|s| *s = 99));
        assert_eq!(rx.try_pop_with(|v| *v), Some(99));
    }
    assert_eq!(ring.overflows(), 12);

    // Across threads, with a consumer that stalls at the start: what arrives is in order, and
    // arrived + dropped = pushed.
    const N: usize = 200_000;
    let mut ring = SpscRing::new(64, || 0usize);
    let (mut tx, mut rx) = ring.split();
    let received = std::thread::scope(|s| {
        let producer = s.spawn(move || {
            for i in 0..N {
                tx.push_or_drop(|slot| *slot = i);
            }
        });
        std::thread::sleep(Duration::from_millis(20));
        let mut received = Vec::new();
        loop {
            let done = producer.is_finished();
            while let Some(v) = rx.try_pop_with(|v| *v) {
                received.push(v);
            }
            if done {
                break;
            }
        }
        received
    });
    assert!(received.windows(2).all(|w| w[0] < w[1]), "order not preserved");
    assert!(ring.overflows() > 0, "a stalled consumer must cause overflows");
    assert_eq!(received.len() as u64 + ring.overflows(), N as u64);
}

#[test]
fn latency_histogram_percentiles_are_bin_upper_edges() {
    let mut h = LatencyHistogram::new(Duration::from_micros(1), 100);
    for us in [0.2, 0.5, 1.5, 2.5, 3.5, 4.5, 5.5, 6.5, 7.5, 250.0] {
        h.record(Duration::from_secs_f64(us * 1e-6));
    }
    assert_eq!(h.count(), 10);
    assert_eq!(h.above_range(), 1);
    assert_eq!(h.percentile(0.5), Duration::from_micros(4));
    assert_eq!(h.percentile(0.1), Duration::from_micros(1));
    assert_eq!(h.percentile(1.0), Duration::from_micros(250));
    assert_eq!(h.max(), Duration::from_micros(250));
    let bins: Vec<_> = h.bins().collect();
    assert_eq!(bins[0], (Duration::ZERO, Duration::from_micros(1), 2));
    assert_eq!(bins.last().unwrap().2, 1);
    assert_eq!(h.coarse(Duration::from_micros(4))[0].2, 5);
}

// ------------------------------------------------------------------------------------------------
// Overlapped predictor

fn three_dof() -> StructuralModel {
    let (k1, k2, k3) = (4.0e5, 3.0e5, 2.0e5);
    let m = DMatrix::from_diagonal(&DVector::from_vec(vec![2.0e3, 1.5e3, 1.0e3]));
    let k = dmatrix![k1 + k2, -k2, 0.0; -k2, k2 + k3, -k3; 0.0, -k3, k3];
    let c = &m * 0.1 + &k * 0.002;
    StructuralModel::new(m, c, k, None).unwrap()
}

fn settings(dt: f64, k: usize, coupling: Vec<usize>, error_force: ErrorForceSpec) -> SubstepSettings {
    SubstepSettings {
        dt,
        beta: 0.25,
        gamma: 0.5,
        substeps: k,
        coupling_dofs: coupling,
        error_force,
    }
}

/// Deterministic pseudo-random numbers in [−1, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

fn rel_diff(a: &DVector<f64>, b: &DVector<f64>) -> f64 {
    (a - b).amax() / b.amax().max(f64::MIN_POSITIVE)
}

#[test]
fn overlapped_predictor_equals_begin_step() {
    let model = three_dof();
    let pid = ErrorForceSpec::Pid {
        p: 0.8,
        i: 0.5,
        d: 0.002,
    };
    for k in [1usize, 2, 4] {
        let s = settings(0.02, k, vec![1, 2], pid);
        let loads: Vec<DVector<f64>> = (0..60)
            .map(|i| model.effective_mass_vector() * -(0.3 * i as f64).sin())
            .collect();
        let mut plain = SubstepController::new(&model, &s, &loads[0]).unwrap();
        let mut split = SubstepController::new(&model, &s, &loads[0]).unwrap();
        let mut overlap = OverlapPredictor::new(&mut split);
        plain.begin_step(&loads[1]);
        split.begin_step(&loads[1]);
        let k_spring = dmatrix![3.0e5, -1.0e5; -1.0e5, 2.0e5];
        let mut rng = Lcg(7);
        let mut worst = 0.0f64;
        for n in 0..loads.len() - 2 {
            // Numerical side, during the sub-steps.
            overlap.precompute(&mut split, &loads[n + 2]);
            // Sub-steps: a spring specimen with a noisy load cell, the same forces to both.
            let mut forces = vec![DVector::from_column_slice(plain.coupling_force())];
            for _ in 0..k {
                let d_plain = DVector::from_column_slice(plain.next_command());
                let d_split = DVector::from_column_slice(split.next_command());
                assert!(rel_diff(&d_split, &d_plain) <= 1e-12, "commands differ");
                let f = -(&k_spring * &d_plain) + DVector::from_fn(2, |_, _| 50.0 * rng.next());
                plain.feedback(f.as_slice());
                split.feedback(f.as_slice());
                forces.push(f);
            }
            plain.finish_step();
            split.finish_step();
            assert_eq!(plain.compensation_force(), split.compensation_force());
            plain.begin_step(&loads[n + 2]);
            let x = overlap.predictor(&split, forces[k - 1].as_slice()).clone();
            split.begin_step_with_predictor(&x);
            let d = rel_diff(split.predictor(), plain.predictor());
            if n == 0 {
                // Same state: the only difference is the split itself.
                assert!(d <= 1e-14, "k = {k}: first-step predictor differs by {d:e}");
            }
            worst = worst.max(d);
            assert!(rel_diff(&split.state().u, &plain.state().u) <= 1e-12);
            assert!(rel_diff(&split.state().a, &plain.state().a) <= 1e-12);
        }
        assert!(worst <= 1e-12, "k = {k}: predictor differs by {worst:e}");
    }
}

// ------------------------------------------------------------------------------------------------
// Real-time runs

fn sweep(dt: f64, duration: f64, f0: f64, f1: f64, amp: f64) -> Vec<f64> {
    let n = (duration / dt).round() as usize;
    (0..=n)
        .map(|i| {
            let t = i as f64 * dt;
            amp * (2.0 * std::f64::consts::PI * (f0 * t + (f1 - f0) * t * t / (2.0 * duration))).sin()
        })
        .collect()
}

/// The typical TMD system as a substructure test: numerical primary SDOF, TMD specimen on an
/// ideal actuator.
fn tmd_test(dt: f64, k: usize, ef: ErrorForceSpec) -> (StructuralModel, SubstructureTest) {
    let p = TmdSystem::typical();
    let (kp, cp) = p.primary();
    let (ms, ks, cs) = p.absorber();
    let model = sdof(p.mass, cp, kp).unwrap();
    let ctrl = SubstepController::new(&model, &settings(dt, k, vec![0], ef), &DVector::zeros(1)).unwrap();
    let lab = VirtualLab::from_specs(
        &[0],
        &[SpecimenSpec::LinearSdof {
            dof: 0,
            mass: Some(ms),
            stiffness: ks,
            damping: cs,
        }],
        &[ActuatorSpec::ideal()],
        &[SensorSpec::ideal()],
        &[SensorSpec::ideal()],
        dt / k as f64,
        1,
    )
    .unwrap();
    let test = SubstructureTest::new(&model, ctrl, Box::new(lab)).unwrap();
    (model, test)
}

/// 3-DOF model, TMDs on DOFs 2 and 3 (two coupling DOFs).
fn three_dof_test(dt: f64, k: usize, ef: ErrorForceSpec) -> (StructuralModel, SubstructureTest) {
    let model = three_dof();
    let ctrl = SubstepController::new(&model, &settings(dt, k, vec![1, 2], ef), &DVector::zeros(3)).unwrap();
    let tmd = |dof, m: f64| SpecimenSpec::LinearSdof {
        dof,
        mass: Some(m),
        stiffness: m * 40.0 * 40.0,
        damping: 2.0 * 0.08 * m * 40.0,
    };
    let lab = VirtualLab::from_specs(
        &[1, 2],
        &[tmd(1, 80.0), tmd(2, 60.0)],
        &vec![ActuatorSpec::ideal(); 2],
        &[SensorSpec::ideal(); 2],
        &[SensorSpec::ideal(); 2],
        dt / k as f64,
        1,
    )
    .unwrap();
    let test = SubstructureTest::new(&model, ctrl, Box::new(lab)).unwrap();
    (model, test)
}

fn offline(mut test: SubstructureTest, ag: &[f64]) -> Vec<Kinematics> {
    let mut out = vec![test.controller.state().clone()];
    for i in 0..ag.len() - 1 {
        test.step(ag[i], ag[i + 1], &mut ()).unwrap();
        out.push(test.controller.state().clone());
    }
    out
}

fn realtime(
    model: &StructuralModel,
    test: SubstructureTest,
    ag: &[f64],
    options: RealtimeOptions,
) -> (RealtimeResult, Vec<StepRecordOwned>) {
    let runner = RealtimeRunner::new(model, test, ag.to_vec(), options).unwrap();
    let mut records = Vec::new();
    let result = runner.run(|r: &StepRecordOwned| records.push(r.clone()));
    (result, records)
}

/// Max relative difference of recorded `u`, `v`, `a` against the offline states over `steps`.
fn compare(records: &[StepRecordOwned], reference: &[Kinematics], steps: std::ops::Range<usize>) -> [f64; 3] {
    let mut diff = [0.0f64; 3];
    let mut scale = [0.0f64; 3];
    for r in records.iter().filter(|r| steps.contains(&r.step)) {
        let s = &reference[r.step];
        for (q, (x, y)) in [(&r.u, &s.u), (&r.v, &s.v), (&r.a, &s.a)].into_iter().enumerate() {
            for (&d, a) in r.dofs.iter().zip(x) {
                diff[q] = diff[q].max((a - y[d]).abs());
                scale[q] = scale[q].max(y[d].abs());
            }
        }
    }
    [0, 1, 2].map(|q| diff[q] / scale[q])
}

fn exact_options() -> RealtimeOptions {
    RealtimeOptions {
        late_policy: LatePolicy::Wait,
        ..RealtimeOptions::default()
    }
}

#[test]
fn realtime_run_equals_offline_run_tmd_sweep() {
    let _g = rt_lock();
    let (dt, k) = (0.01, 10);
    let ag = sweep(dt, 1.0, 0.5, 3.0, 2.0);
    let pid = ErrorForceSpec::Pid { p: 1.0, i: 0.0, d: 0.0 };
    let reference = offline(tmd_test(dt, k, pid).1, &ag);
    let (model, test) = tmd_test(dt, k, pid);
    let (result, records) = realtime(&model, test, &ag, exact_options());
    let (report, test) = result.expect("real-time run");
    println!("{report}");
    assert_eq!(report.steps, 100);
    assert_eq!(report.substeps, 100 * k);
    assert_eq!(report.k_sub, k);
    assert_eq!(
        report.histogram.count() as usize,
        report.substeps + report.hold_substeps
    );
    assert_eq!(
        report.completion.count() as usize,
        report.substeps + report.hold_substeps
    );
    assert_eq!(report.numerical.count(), 100);
    assert_eq!(report.hold_substeps, 0, "the Wait policy sends no hold sub-steps");
    assert_eq!(report.records_written, 101);
    assert_eq!(report.records_dropped, 0);
    assert_eq!(report.memory_lock, RtSetting::NotRequested);
    assert_eq!(records.len(), 101);
    assert!(
        records
            .iter()
            .enumerate()
            .all(|(i, r)| r.step == i && r.time == i as f64 * dt)
    );
    let err = compare(&records, &reference, 0..101);
    assert!(err.iter().all(|&e| e <= 1e-12), "real-time vs offline: {err:?}");
    // The returned test holds the final state.
    assert!(rel_diff(&test.controller.state().u, &reference[100].u) <= 1e-12);
    // Records carry the step's forces: the error force is f^(k) − f^(k−1) ≠ 0 during a sweep.
    assert!(records[50].error_force[0] != 0.0);
    assert_eq!(records[50].coupling_force.len(), 1);
}

#[test]
fn realtime_run_equals_offline_run_two_coupling_dofs_and_k1() {
    let _g = rt_lock();
    let pid = ErrorForceSpec::Pid {
        p: 0.7,
        i: 0.3,
        d: 0.001,
    };
    for (dt, k) in [(0.005, 3), (0.005, 1)] {
        let ag = sweep(dt, 0.3, 1.0, 8.0, 3.0);
        let steps = ag.len() - 1;
        let reference = offline(three_dof_test(dt, k, pid).1, &ag);
        let (model, test) = three_dof_test(dt, k, pid);
        let options = RealtimeOptions {
            record_dofs: Some(vec![2, 0]),
            record_every: 2,
            ..exact_options()
        };
        let (result, records) = realtime(&model, test, &ag, options);
        let (report, _) = result.expect("real-time run");
        assert_eq!(report.substeps, steps * k);
        assert_eq!(records.len(), steps / 2 + 1);
        assert!(
            records
                .iter()
                .all(|r| r.step % 2 == 0 && r.dofs == [2, 0] && r.u.len() == 2)
        );
        let err = compare(&records, &reference, 0..steps + 1);
        assert!(err.iter().all(|&e| e <= 1e-12), "k = {k}: {err:?}");
    }
}

/// Forwards to a virtual lab, but sleeps `delay` on the listed (0-based) sub-step calls, or
/// fails / returns NaN on one of them.
struct Faulty {
    inner: Box<dyn ExperimentalSubstructure>,
    calls: usize,
    slow: Vec<usize>,
    delay: Duration,
    fail_at: Option<usize>,
    nan_at: Option<usize>,
}

impl Faulty {
    fn wrap(test: SubstructureTest, model: &StructuralModel, f: impl FnOnce(&mut Faulty)) -> SubstructureTest {
        let SubstructureTest { controller, site, .. } = test;
        let mut faulty = Faulty {
            inner: site,
            calls: 0,
            slow: Vec::new(),
            delay: Duration::ZERO,
            fail_at: None,
            nan_at: None,
        };
        f(&mut faulty);
        SubstructureTest::new(model, controller, Box::new(faulty)).unwrap()
    }
}

impl ExperimentalSubstructure for Faulty {
    fn n_coupling(&self) -> usize {
        self.inner.n_coupling()
    }
    fn substep(
        &mut self,
        command: &[f64],
        ag: (f64, f64),
        dtau: f64,
        force: &mut [f64],
        displacement: &mut [f64],
    ) -> Result<()> {
        let call = self.calls;
        self.calls += 1;
        if self.slow.contains(&call) {
            std::thread::sleep(self.delay);
        }
        if self.fail_at == Some(call) {
            return Err(Error::invalid("site", "connection lost"));
        }
        self.inner.substep(command, ag, dtau, force, displacement)?;
        if self.nan_at == Some(call) {
            force[0] = f64::NAN;
        }
        Ok(())
    }
    fn is_linear(&self) -> Result<()> {
        self.inner.is_linear()
    }
    fn state_len(&self) -> usize {
        self.inner.state_len()
    }
    fn write_state(&self, out: &mut [f64]) {
        self.inner.write_state(out)
    }
    fn read_state(&mut self, state: &[f64]) {
        self.inner.read_state(state)
    }
}

#[test]
fn slow_experimental_side_counts_missed_deadlines_and_catches_up() {
    let _g = rt_lock();
    let (dt, k) = (0.01, 10);
    let ag = sweep(dt, 1.0, 0.5, 3.0, 2.0);
    let reference = offline(tmd_test(dt, k, ErrorForceSpec::None).1, &ag);
    let (model, test) = tmd_test(dt, k, ErrorForceSpec::None);
    // Three sub-steps take 2.5 Δτ each (one of them the last sub-step of a step).
    let test = Faulty::wrap(test, &model, |f| {
        f.slow = vec![15, 249, 700];
        f.delay = Duration::from_micros(2500);
    });
    let (result, records) = realtime(&model, test, &ag, exact_options());
    let (report, _) = result.expect("the run completes");
    println!("{report}");
    assert_eq!(report.steps, 100);
    assert_eq!(report.substeps, 1000);
    assert!(report.missed >= 3, "missed = {}", report.missed);
    assert!(report.completion.max() >= Duration::from_micros(2500));
    // Catch-up keeps the algorithm unchanged: results still equal the offline run.
    let err = compare(&records, &reference, 0..101);
    assert!(err.iter().all(|&e| e <= 1e-12), "{err:?}");
}

#[test]
fn late_predictor_holds_then_respaces_the_step() {
    let _g = rt_lock();
    let (dt, k) = (0.01, 10);
    let ag = sweep(dt, 1.0, 0.5, 3.0, 2.0);
    let reference = offline(tmd_test(dt, k, ErrorForceSpec::None).1, &ag);
    let (model, test) = tmd_test(dt, k, ErrorForceSpec::None);
    // The predictor of step 30 (t_30 → t_31) comes at least 2 ms late.
    let options = RealtimeOptions {
        numerical_delay: vec![(30, Duration::from_millis(13))],
        ..RealtimeOptions::default()
    };
    let (result, records) = realtime(&model, test, &ag, options);
    let (report, _) = result.expect("the run completes");
    println!("{report}");
    assert_eq!(report.steps, 100);
    assert_eq!(report.substeps, 1000, "hold sub-steps are not algorithm sub-steps");
    assert!(report.late_steps >= 1);
    assert!(report.hold_substeps >= 1);
    assert_eq!(
        report.histogram.count() as usize,
        report.substeps + report.hold_substeps
    );
    assert!(records[31].holds > 0, "the record of step 31 marks the held step");
    assert_eq!(records.iter().map(|r| r.holds).sum::<usize>(), report.hold_substeps);
    // Up to the first late step (step 31 unless the machine delayed another) the run is the
    // offline run; afterwards the specimen has seen the hold sub-steps, and the response stays
    // finite and close.
    let first_held = records.iter().find(|r| r.holds > 0).unwrap().step;
    let before = compare(&records, &reference, 0..first_held);
    assert!(before.iter().all(|&e| e <= 1e-12), "{before:?}");
    let after = compare(&records, &reference, 31..101);
    println!("after the held step: {after:?}");
    assert!(after.iter().all(|&e| e.is_finite() && e > 0.0 && e < 0.2), "{after:?}");
}

#[test]
fn late_predictor_with_wait_policy_re_bases_and_stays_exact() {
    let _g = rt_lock();
    let (dt, k) = (0.01, 10);
    let ag = sweep(dt, 0.5, 0.5, 3.0, 2.0);
    let reference = offline(tmd_test(dt, k, ErrorForceSpec::None).1, &ag);
    let (model, test) = tmd_test(dt, k, ErrorForceSpec::None);
    let options = RealtimeOptions {
        numerical_delay: vec![(20, Duration::from_millis(15))],
        ..exact_options()
    };
    let (result, records) = realtime(&model, test, &ag, options);
    let (report, _) = result.expect("the run completes");
    assert!(report.late_steps >= 1);
    assert!(report.rebased >= 1);
    assert_eq!(report.hold_substeps, 0);
    let err = compare(&records, &reference, 0..51);
    assert!(err.iter().all(|&e| e <= 1e-12), "{err:?}");
}

#[test]
fn site_failure_stops_the_run_and_flushes_the_records() {
    let _g = rt_lock();
    let (dt, k) = (0.01, 10);
    let ag = sweep(dt, 1.0, 0.5, 3.0, 2.0);
    let (model, test) = tmd_test(dt, k, ErrorForceSpec::None);
    // Call 245 is sub-step 6 of step 24 (0-based): 24 steps complete.
    let test = Faulty::wrap(test, &model, |f| f.fail_at = Some(245));
    let (result, records) = realtime(&model, test, &ag, exact_options());
    let failure = result.err().expect("the run fails");
    assert!(failure.to_string().contains("connection lost"), "{failure}");
    // A controlled stop at the step the offline driver reports (not "bad input", not step 0).
    let msg = failure.error.to_string();
    assert!(
        matches!(failure.error, Error::Stopped { step: 25, .. })
            && msg.starts_with("stopped at step 25 (t = 0.250000 s): experimental side failed: "),
        "{msg}"
    );
    assert_eq!(failure.stopped_at, Some((25, 6)));
    assert!(failure.stop_log.is_none(), "no safety limits: nothing was ramped");
    assert_eq!(failure.report.steps, 24);
    assert_eq!(failure.report.substeps, 245);
    assert_eq!(records.len(), 25, "initial state + 24 steps");
    assert_eq!(failure.report.records_written, 25);
}

#[test]
fn non_finite_force_is_reported_as_divergence() {
    let _g = rt_lock();
    let (dt, k) = (0.01, 5);
    let ag = sweep(dt, 0.5, 0.5, 3.0, 2.0);
    let (model, test) = tmd_test(dt, k, ErrorForceSpec::None);
    // Call 62 is sub-step 3 of step 12: the NaN reaches f^(k) of step 12 → diverged at step 13.
    let test = Faulty::wrap(test, &model, |f| f.nan_at = Some(62));
    let (result, records) = realtime(&model, test, &ag, exact_options());
    let failure = result.err().expect("the run fails");
    match failure.error {
        Error::Diverged { step, .. } => assert_eq!(step, 13),
        other => panic!("expected a divergence, got {other}"),
    }
    assert_eq!(records.len(), 13, "initial state + 12 steps");
}

#[test]
fn memory_lock_and_fifo_requests_are_reported_not_fatal() {
    let _g = rt_lock();
    let (dt, k) = (0.01, 10);
    let ag = sweep(dt, 0.2, 0.5, 3.0, 2.0);
    let (model, test) = tmd_test(dt, k, ErrorForceSpec::None);
    let options = RealtimeOptions {
        lock_memory: true,
        fifo_priority: Some(20),
        numerical_fifo_priority: Some(10),
        ..exact_options()
    };
    let (result, _) = realtime(&model, test, &ag, options);
    let (report, _) = result.expect("the run completes with or without the privileges");
    println!("mlockall: {}, SCHED_FIFO: {}", report.memory_lock, report.fifo);
    assert_ne!(report.memory_lock, RtSetting::NotRequested);
    assert_ne!(report.fifo, RtSetting::NotRequested);
    assert_ne!(report.numerical_fifo, RtSetting::NotRequested);
    assert_eq!(report.substeps, 20 * k);
}

#[test]
fn runner_rejects_bad_input() {
    let (model, test) = tmd_test(0.01, 2, ErrorForceSpec::None);
    let err = RealtimeRunner::new(&model, test, vec![0.0], RealtimeOptions::default())
        .err()
        .unwrap();
    assert!(err.to_string().contains("ground_accel"), "{err}");
    let (model, test) = tmd_test(0.01, 2, ErrorForceSpec::None);
    let options = RealtimeOptions {
        record_dofs: Some(vec![1]),
        ..RealtimeOptions::default()
    };
    let err = RealtimeRunner::new(&model, test, vec![0.0; 3], options).err().unwrap();
    assert!(err.to_string().contains("record_dofs"), "{err}");
    let (_, test) = tmd_test(0.01, 2, ErrorForceSpec::None);
    let other = sdof(1.0, 0.0, 1.0).unwrap();
    let err = RealtimeRunner::new(&other, test, vec![0.0; 3], RealtimeOptions::default())
        .err()
        .unwrap();
    assert!(err.to_string().contains("realtime.model"), "{err}");
}

/// The acceptance benchmark (1000 DOFs, Δt = 10 ms, k_sub = 10); run by hand:
/// `cargo test --release -p substep --test realtime -- --ignored --nocapture bench_overlap_1000`.
#[test]
#[ignore]
fn bench_overlap_1000() {
    let _g = rt_lock();
    let steps = std::env::var("SUBSTEP_BENCH_STEPS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1000);
    let fifo = std::env::var("SUBSTEP_BENCH_FIFO").ok().and_then(|s| s.parse().ok());
    let options = RealtimeOptions {
        fifo_priority: fifo,
        numerical_fifo_priority: fifo.map(|p: i32| p - 10),
        lock_memory: fifo.is_some(),
        histogram_bin: Duration::from_nanos(100),
        histogram_bins: 100_000,
        ..RealtimeOptions::default()
    };
    let b = substep::realtime::bench_overlap_with(1000, 10, steps, options).unwrap();
    println!("{b}");
    // u and v agree to 1e-12; the acceleration of this stiff model is more sensitive to
    // round-off (a 1-ulp change of the load moves it by ~3e-11 relative; docs/realtime.md).
    if b.report.hold_substeps == 0 {
        assert!(b.max_rel_diff[0] <= 1e-12 && b.max_rel_diff[1] <= 1e-12 && b.max_rel_diff[2] <= 1e-9);
    }
}

// ------------------------------------------------------------------------------------------------
// Controlled stop from outside

/// Asks for the stop through the runner's handle during sub-step call `at` (0-based), i.e. from
/// the real-time thread at a known point of the schedule.
struct StopTrigger {
    inner: Box<dyn ExperimentalSubstructure>,
    calls: usize,
    at: usize,
    handle: StopHandle,
}

impl ExperimentalSubstructure for StopTrigger {
    fn n_coupling(&self) -> usize {
        self.inner.n_coupling()
    }
    fn substep(
        &mut self,
        command: &[f64],
        ag: (f64, f64),
        dtau: f64,
        force: &mut [f64],
        displacement: &mut [f64],
    ) -> Result<()> {
        if self.calls == self.at {
            self.handle.request("operator stop (test)");
        }
        self.calls += 1;
        self.inner.substep(command, ag, dtau, force, displacement)
    }
    fn is_linear(&self) -> Result<()> {
        self.inner.is_linear()
    }
    fn state_len(&self) -> usize {
        self.inner.state_len()
    }
    fn write_state(&self, out: &mut [f64]) {
        self.inner.write_state(out)
    }
    fn read_state(&mut self, state: &[f64]) {
        self.inner.read_state(state)
    }
}

/// Collects the ramp sub-steps an offline stop replays.
#[derive(Default)]
struct Ramp(Vec<(usize, usize, f64)>);
impl substep::substructure::SubstepObserver for Ramp {
    fn ramp(&mut self, step: usize, j: usize, _s: usize, command: &[f64], _f: &[f64], _d: &[f64]) {
        self.0.push((step, j, command[0]));
    }
}

/// The TMD test behind a ramp-only `LimitedSite` (ramp 50 ms = 50 sub-steps of 1 ms); the stop
/// is asked for during the last sub-step of step `stop_after` (1-based step count).
fn limited_tmd(dt: f64, k: usize, stop_after: usize, handle: StopHandle) -> (StructuralModel, SubstructureTest) {
    let (model, test) = tmd_test(dt, k, ErrorForceSpec::Pid { p: 1.0, i: 0.0, d: 0.0 });
    let SubstructureTest { controller, site, .. } = test;
    let trigger = StopTrigger {
        inner: site,
        calls: 0,
        at: stop_after * k - 1,
        handle,
    };
    let limits = SafetyLimits {
        ramp_time: 0.05,
        ..SafetyLimits::default()
    };
    let site = LimitedSite::new(Box::new(trigger), limits).unwrap();
    let test = SubstructureTest::new(&model, controller, Box::new(site)).unwrap();
    (model, test)
}

#[test]
fn external_stop_ramps_to_the_safe_position_at_the_next_step() {
    let _g = rt_lock();
    let (dt, k, stop_after) = (0.01, 10, 30);
    let ag = sweep(dt, 1.0, 0.5, 3.0, 2.0);

    // Reference: the offline driver, stopped between steps 30 and 31 as the monitor does.
    let (_, mut offline_test) = limited_tmd(dt, k, usize::MAX / k, StopHandle::new());
    let mut reference = vec![offline_test.controller.state().clone()];
    for i in 0..stop_after {
        offline_test.step(ag[i], ag[i + 1], &mut ()).unwrap();
        reference.push(offline_test.controller.state().clone());
    }
    let last_command = offline_test.controller.command()[0];
    assert!(last_command.abs() > 1e-6, "the test must be away from 0 when stopped");
    assert!(offline_test.site.request_stop("operator stop (test)"));
    let mut offline_ramp = Ramp::default();
    let offline_err = offline_test
        .step(ag[stop_after], ag[stop_after + 1], &mut offline_ramp)
        .unwrap_err();

    let handle = StopHandle::new();
    let (model, test) = limited_tmd(dt, k, stop_after, handle.clone());
    let runner = RealtimeRunner::new(&model, test, ag.clone(), exact_options())
        .unwrap()
        .with_stop_handle(handle.clone());
    let mut records = Vec::new();
    let failure = runner
        .run(|r: &StepRecordOwned| records.push(r.clone()))
        .err()
        .expect("the run stops");
    assert_eq!(handle.requested(), Some("operator stop (test)"));

    // The stop comes at the next step boundary: step 31 is not executed, 30 are complete.
    assert!(
        matches!(failure.error, Error::Stopped { step: 31, .. }),
        "{}",
        failure.error
    );
    assert_eq!(failure.error.to_string(), offline_err.to_string());
    assert!(
        failure
            .error
            .to_string()
            .contains("operator stop (test); actuators ramped to 0 over 0.05 s"),
        "{}",
        failure.error
    );
    assert_eq!(failure.stopped_at, Some((31, 1)));
    assert_eq!(failure.report.steps, stop_after);
    assert_eq!(failure.report.substeps, stop_after * k);
    // Records up to the stop are flushed and equal the offline run.
    assert_eq!(records.len(), stop_after + 1, "initial state + 30 steps");
    assert_eq!(records.last().unwrap().step, stop_after);
    let err = compare(&records, &reference, 0..stop_after + 1);
    assert!(err.iter().all(|&e| e <= 1e-12), "{err:?}");

    // The ramp: 50 sub-steps from the last command of step 30 linearly to exactly 0, numbered
    // after it in step 31, the same rows as the offline stop.
    let log = failure.stop_log.expect("the ramp is logged");
    assert!(
        log.tripped().is_none(),
        "no sub-step was measured: the ramp starts the step"
    );
    assert_eq!(log.ramp_len(), 50);
    let d_k = records.last().unwrap().command[0];
    assert!((d_k - last_command).abs() <= 1e-12 * last_command.abs());
    for (s, (c, _, _)) in log.ramp().enumerate() {
        let expected = (1.0 - (s + 1) as f64 / 50.0) * d_k;
        assert!(
            (c[0] - expected).abs() <= 1e-12 * d_k.abs(),
            "ramp {s}: {} vs {expected}",
            c[0]
        );
    }
    assert_eq!(
        log.ramp().last().unwrap().0[0],
        0.0,
        "the ramp ends at the safe position"
    );
    let mut rt_ramp = Ramp::default();
    let (step, j) = failure.stopped_at.unwrap();
    log.replay(step, j, &mut rt_ramp);
    assert_eq!(rt_ramp.0.len(), offline_ramp.0.len());
    for (a, b) in rt_ramp.0.iter().zip(&offline_ramp.0) {
        assert_eq!((a.0, a.1), (b.0, b.1));
        assert!((a.2 - b.2).abs() <= 1e-12 * d_k.abs(), "{a:?} vs {b:?}");
    }
    assert_eq!(rt_ramp.0[0].0, 31);
    assert_eq!(rt_ramp.0[0].1, 1);
    // Paced on the real-time thread: step 31 starts 0.30 s after the first deadline and its 49
    // ramp sub-steps after the first start 1 ms apart, so the run lasts at least that (a sleep
    // never ends early; a lower bound, not a timing goal).
    assert!(
        failure.report.wall_time >= Duration::from_millis(300 + 49),
        "{:?}",
        failure.report.wall_time
    );
}

#[test]
fn external_stop_without_a_ramp_stops_before_the_first_step() {
    let _g = rt_lock();
    let (dt, k) = (0.01, 4);
    let ag = sweep(dt, 0.2, 0.5, 3.0, 2.0);
    let (model, test) = tmd_test(dt, k, ErrorForceSpec::None);
    let handle = StopHandle::new();
    assert!(handle.request("stability stop"));
    assert!(!handle.request("operator stop"), "the first reason is kept");
    let (result, records) = {
        let runner = RealtimeRunner::new(&model, test, ag, exact_options())
            .unwrap()
            .with_stop_handle(handle);
        let mut records = Vec::new();
        let r = runner.run(|r: &StepRecordOwned| records.push(r.clone()));
        (r, records)
    };
    let failure = result.err().expect("the run stops");
    assert_eq!(
        failure.error.to_string(),
        "stopped at step 1 (t = 0.010000 s): stability stop (between steps: this run has no ramp to the safe position)"
    );
    assert!(failure.stop_log.is_none());
    assert_eq!((failure.report.steps, failure.report.substeps), (0, 0));
    assert_eq!(records.len(), 1, "the initial state");
}
