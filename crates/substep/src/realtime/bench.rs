//! The overlap benchmark: a large shear building with a spring specimen on the roof, run in
//! real time and offline, compared step by step.

use super::{RealtimeOptions, RealtimeReport, RealtimeRunner};
use crate::error::{Error, Result};
use crate::model::{DampingSpec, ShearBuilding, StructuralModel, shear_building};
use crate::specimen::SpecimenSpec;
use crate::substructure::{ErrorForceSpec, SubstepController, SubstepSettings, SubstructureTest};
use crate::transfer::{ActuatorSpec, SensorSpec, VirtualLab};
use nalgebra::DVector;
use std::fmt;
use std::time::{Duration, Instant};

/// Result of [`bench_overlap`].
#[derive(Debug, Clone)]
pub struct BenchOverlap {
    pub n_dofs: usize,
    pub k_sub: usize,
    pub dt: f64,
    pub steps: usize,
    /// Model, damping, factorisation and `H` (the real-time run's set-up, done twice).
    pub setup_time: Duration,
    /// The real-time run.
    pub report: RealtimeReport,
    /// Offline `SubstructureTest::step` per step (predictor, `k` sub-steps, close): mean, max.
    /// This sequential work has to fit between two sub-steps without the overlap.
    pub offline_step_mean: Duration,
    pub offline_step_max: Duration,
    /// `max |x_rt − x_offline| / max |x_offline|` over all steps and DOFs for `u`, `v`, `a`.
    pub max_rel_diff: [f64; 3],
}

impl fmt::Display for BenchOverlap {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "overlap benchmark: {} DOFs, dt = {} ms, k_sub = {}, {} steps (set-up {:.2} s)",
            self.n_dofs,
            self.dt * 1e3,
            self.k_sub,
            self.steps,
            self.setup_time.as_secs_f64()
        )?;
        write!(f, "{}", self.report)?;
        writeln!(
            f,
            "offline step (sequential, not overlapped): mean {:.1} µs, max {:.1} µs; sub-step length {:.1} µs",
            self.offline_step_mean.as_secs_f64() * 1e6,
            self.offline_step_max.as_secs_f64() * 1e6,
            self.dt / self.k_sub as f64 * 1e6
        )?;
        writeln!(
            f,
            "real-time vs offline, max relative difference: u {:.2e}, v {:.2e}, a {:.2e}",
            self.max_rel_diff[0], self.max_rel_diff[1], self.max_rel_diff[2]
        )
    }
}

fn build(n_dofs: usize, k_sub: usize, dt: f64) -> Result<(StructuralModel, SubstructureTest)> {
    let building = ShearBuilding {
        stories: n_dofs,
        story_mass: 1.0e4,
        first_period: 2.0,
    };
    let model = shear_building(&building)?.with_damping(&DampingSpec::Modal { zeta: vec![0.05] })?;
    let roof = n_dofs - 1;
    let settings = SubstepSettings {
        dt,
        beta: 0.25,
        gamma: 0.5,
        substeps: k_sub,
        coupling_dofs: vec![roof],
        error_force: ErrorForceSpec::Pid { p: 1.0, i: 0.0, d: 0.0 },
    };
    let controller = SubstepController::new(&model, &settings, &DVector::zeros(n_dofs))?;
    // A spring of 0.3 times the roof's effective stiffness `1/G_cc`: a substantial specimen
    // for which the sub-step iteration converges (its gain is `G_cc k_s = 0.3`).
    let spring = SpecimenSpec::LinearSdof {
        dof: roof,
        mass: None,
        stiffness: 0.3 / controller.gain_cc()[(0, 0)],
        damping: 0.0,
    };
    let lab = VirtualLab::from_specs(
        &[roof],
        &[spring],
        &[ActuatorSpec::ideal()],
        &[SensorSpec::ideal()],
        &[SensorSpec::ideal()],
        dt / k_sub as f64,
        1,
    )?;
    let test = SubstructureTest::new(&model, controller, Box::new(lab))?;
    Ok((model, test))
}

/// Run an `n_dofs`-story shear building (10 t floors, first period 2 s, 5 % modal damping;
/// spring specimen of `0.3/G_cc` on the roof DOF, ideal actuator, PID `P = 1`) for `steps` steps of a 0.2–5 Hz sine sweep in real time at
/// `Δt = 10 ms` with `k_sub` sub-steps, and the same test offline; report latencies and the
/// difference between the two. Takes `steps · 10 ms` of wall time plus set-up (about a
/// second for 1000 DOFs, mostly the modal damping).
pub fn bench_overlap(n_dofs: usize, k_sub: usize, steps: usize) -> Result<BenchOverlap> {
    bench_overlap_with(n_dofs, k_sub, steps, RealtimeOptions::default())
}

/// [`bench_overlap`] with explicit options (e.g. `fifo_priority`, `lock_memory`); records are
/// always taken for all DOFs at every step (they are compared with the offline run).
pub fn bench_overlap_with(
    n_dofs: usize,
    k_sub: usize,
    steps: usize,
    mut options: RealtimeOptions,
) -> Result<BenchOverlap> {
    if n_dofs == 0 || k_sub == 0 || steps == 0 {
        return Err(Error::invalid("bench", "n_dofs, k_sub and steps must be at least 1"));
    }
    let dt = 0.01;
    let duration = steps as f64 * dt;
    let ag: Vec<f64> = (0..=steps)
        .map(|i| {
            let t = i as f64 * dt;
            (2.0 * std::f64::consts::PI * (0.2 * t + 4.8 * t * t / (2.0 * duration))).sin()
        })
        .collect();

    // Offline reference.
    let setup = Instant::now();
    let (_, mut offline) = build(n_dofs, k_sub, dt)?;
    let mut setup_time = setup.elapsed();
    let mut reference = Vec::with_capacity(steps + 1);
    reference.push(offline.controller.state().clone());
    let (mut step_sum, mut step_max) = (Duration::ZERO, Duration::ZERO);
    for i in 0..steps {
        let t = Instant::now();
        offline.step(ag[i], ag[i + 1], &mut ())?;
        let e = t.elapsed();
        step_sum += e;
        step_max = step_max.max(e);
        reference.push(offline.controller.state().clone());
    }
    drop(offline);

    let setup = Instant::now();
    let (model, test) = build(n_dofs, k_sub, dt)?;
    options.record_every = 1;
    options.record_dofs = None;
    let runner = RealtimeRunner::new(&model, test, ag, options)?;
    setup_time += setup.elapsed();
    let mut diff = [0.0f64; 3];
    let mut scale = [0.0f64; 3];
    let sink = |r: &super::StepRecordOwned| {
        let s = &reference[r.step];
        for (q, (x, y)) in [(&r.u, &s.u), (&r.v, &s.v), (&r.a, &s.a)].into_iter().enumerate() {
            for (a, b) in x.iter().zip(y.iter()) {
                diff[q] = diff[q].max((a - b).abs());
                scale[q] = scale[q].max(b.abs());
            }
        }
    };
    let (report, _) = runner.run(sink).map_err(|f| f.error)?;
    let max_rel_diff = [0, 1, 2].map(|q| if scale[q] > 0.0 { diff[q] / scale[q] } else { diff[q] });
    Ok(BenchOverlap {
        n_dofs,
        k_sub,
        dt,
        steps,
        setup_time,
        report,
        offline_step_mean: step_sum / steps as u32,
        offline_step_max: step_max,
        max_rel_diff,
    })
}
