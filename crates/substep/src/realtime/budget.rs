//! The real-time budget, measured before a test starts: can this numerical substructure keep up
//! with the wall clock on this machine?
//!
//! The runner gives the numerical thread a whole step `Δt` for the step's work (closing the
//! step, the next predictor, `W` of the step after; the overlap of the module docs), and a
//! nonlinear substructure's springs one sub-step `Δτ = Δt/k_sub` (the one-sub-step pipeline,
//! docs/realtime.md). [`probe`] runs a few steps of a throwaway controller of the same model
//! with zero coupling forces and measures both; [`BudgetProbe::check`] refuses a test whose
//! median cost is over its budget, which would miss deadlines on every step and never be the
//! test it defines. The median, not the maximum: a probe of a few steps on a busy machine sees
//! scheduler stalls that the run's deadline report then counts honestly.

use super::OverlapPredictor;
use crate::error::{Error, Result};
use crate::substructure::{CouplingController, SubstepController};
use nalgebra::DVector;
use std::time::{Duration, Instant};

/// Steps a probe runs at most (fewer when a step is slow: see [`probe`]).
pub const PROBE_STEPS: usize = 20;

/// What [`probe`] measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BudgetProbe {
    /// Steps measured.
    pub steps: usize,
    /// Median wall time of one step's numerical work.
    pub step: Duration,
    /// Median wall time of the springs' share (state closed, springs at the next predictor,
    /// their coupling rows): `None` for a linear substructure.
    pub springs: Option<Duration>,
    /// The step `Δt` and the sub-step count of the test.
    pub dt: f64,
    pub k_sub: usize,
}

/// Run up to [`PROBE_STEPS`] steps of `controller` (a throwaway copy of the test's: its state
/// and springs are changed) under the loads `−M ι a_g` of the first samples of `ground_accel`,
/// with zero coupling forces, and time them. Stops early once the probe has taken more than a
/// second (a model that slow fails the check anyway).
pub fn probe(mut controller: SubstepController, mass_influence: &DVector<f64>, ground_accel: &[f64]) -> BudgetProbe {
    if !controller.is_nonlinear() {
        return probe_steps(controller, mass_influence, ground_accel);
    }
    let k = controller.substeps();
    let n_c = controller.n_coupling();
    let zeros = vec![0.0; n_c];
    let mut command = vec![0.0; n_c];
    let mut load = DVector::zeros(mass_influence.len());
    // The springs' coupling rows come from the runner's own code (its known part W is zero here:
    // only the time counts).
    let mut overlap = OverlapPredictor::new(&mut controller);
    let mut step_times = Vec::with_capacity(PROBE_STEPS);
    let mut springs_times = Vec::with_capacity(PROBE_STEPS);
    let started = Instant::now();
    for i in 0..PROBE_STEPS {
        let ag = ground_accel.get(i + 1).copied().unwrap_or(0.0);
        let t0 = Instant::now();
        load.copy_from(mass_influence);
        load.scale_mut(-ag);
        controller.begin_step(&load);
        for _ in 1..k {
            controller.next_command();
            controller.feedback(&zeros);
        }
        command.copy_from_slice(controller.next_command());
        let t1 = Instant::now();
        // What the pipeline does within the last sub-step.
        controller.close_kinematics_with(&zeros, &command, true);
        std::hint::black_box(overlap.deviation_coupling(&controller));
        springs_times.push(t1.elapsed());
        controller.close_with_last_force(&zeros);
        step_times.push(t0.elapsed());
        if started.elapsed() > Duration::from_secs(1) {
            break;
        }
    }
    BudgetProbe {
        steps: step_times.len(),
        step: median(&mut step_times),
        springs: Some(median(&mut springs_times)),
        dt: controller.dt(),
        k_sub: k,
    }
}

/// As [`probe`] for any controller whose whole step runs on the numerical thread within `Δt`
/// (a linear sub-step test, or a CR / KR-α test, whose springs are evaluated at `u_α` during
/// the step: no springs' budget): up to [`PROBE_STEPS`] steps with zero coupling forces, timed.
pub fn probe_steps<C: CouplingController>(
    mut controller: C,
    mass_influence: &DVector<f64>,
    ground_accel: &[f64],
) -> BudgetProbe {
    let k = controller.substeps();
    let zeros = vec![0.0; controller.n_coupling()];
    let mut load = DVector::zeros(mass_influence.len());
    let mut step_times = Vec::with_capacity(PROBE_STEPS);
    let started = Instant::now();
    for i in 0..PROBE_STEPS {
        let ag = ground_accel.get(i + 1).copied().unwrap_or(0.0);
        let t0 = Instant::now();
        load.copy_from(mass_influence);
        load.scale_mut(-ag);
        controller.begin_step(&load);
        for _ in 0..k {
            controller.next_command();
            controller.feedback(&zeros);
        }
        controller.finish_step();
        step_times.push(t0.elapsed());
        if started.elapsed() > Duration::from_secs(1) {
            break;
        }
    }
    BudgetProbe {
        steps: step_times.len(),
        step: median(&mut step_times),
        springs: None,
        dt: controller.dt(),
        k_sub: k,
    }
}

fn median(x: &mut [Duration]) -> Duration {
    x.sort_unstable();
    x.get(x.len() / 2).copied().unwrap_or_default()
}

impl BudgetProbe {
    /// The sub-step `Δτ`.
    pub fn dtau(&self) -> Duration {
        Duration::from_secs_f64(self.dt / self.k_sub as f64)
    }

    /// Refuse (`what`: the option that asked for real time) a test whose median step work is
    /// over `Δt`, or whose springs' share is over one sub-step; the message gives the measured
    /// and the allowed times and what to change.
    pub fn check(&self, what: &str) -> Result<()> {
        let dt = Duration::from_secs_f64(self.dt);
        if self.step > dt {
            return Err(Error::invalid(
                what,
                format!(
                    "the numerical substructure cannot keep up: one step's work takes {} (median of {} steps \
                     measured before the test) but the step is Δt = {}; use a larger integrator.dt, a smaller \
                     model, or run without --realtime",
                    show(self.step),
                    self.steps,
                    show(dt)
                ),
            ));
        }
        if let Some(springs) = self.springs.filter(|&s| s > self.dtau()) {
            return Err(Error::invalid(
                what,
                format!(
                    "the springs of the nonlinear numerical substructure cannot keep up: their share of the \
                     next predictor takes {} (median of {} steps measured before the test) but must fit one \
                     sub-step, Δτ = Δt/k_sub = {}; use fewer substructure.substeps, a larger integrator.dt, or \
                     run without --realtime",
                    show(springs),
                    self.steps,
                    show(self.dtau())
                ),
            ));
        }
        Ok(())
    }
}

/// `1.23 ms`, `45.6 µs`.
fn show(d: Duration) -> String {
    let s = d.as_secs_f64();
    if s >= 1e-3 {
        format!("{:.2} ms", s * 1e3)
    } else {
        format!("{:.1} µs", s * 1e6)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn probe_of(step_us: u64, springs_us: Option<u64>) -> BudgetProbe {
        BudgetProbe {
            steps: 20,
            step: Duration::from_micros(step_us),
            springs: springs_us.map(Duration::from_micros),
            dt: 0.005,
            k_sub: 10,
        }
    }

    #[test]
    fn check_compares_the_medians_with_the_step_and_the_sub_step() {
        assert!(probe_of(4_999, Some(499)).check("--realtime").is_ok());
        assert!(probe_of(4_999, None).check("--realtime").is_ok());
        let e = probe_of(5_001, None).check("--realtime").unwrap_err().to_string();
        assert!(
            e.starts_with("--realtime: the numerical substructure cannot keep up: one step's work takes 5.00 ms"),
            "{e}"
        );
        assert!(e.contains("Δt = 5.00 ms"), "{e}");
        let e = probe_of(100, Some(501)).check("--realtime").unwrap_err().to_string();
        assert!(e.contains("their share of the next predictor takes 501.0 µs"), "{e}");
        assert!(e.contains("Δτ = Δt/k_sub = 500.0 µs"), "{e}");
    }
}
