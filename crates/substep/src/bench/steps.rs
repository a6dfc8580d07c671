//! `substep bench` without `--model`: µs per step of Newmark (average acceleration, β = 1/4,
//! γ = 1/2) on uniform shear buildings with 5 % modal damping (Δt = 0.01 s, a 1 Hz harmonic
//! ground acceleration of 1 m/s²), and of the sub-step algorithm (full step and one sub-step)
//! with spring specimens on 1 and 4 coupling DOFs behind ideal actuators. Each figure is the
//! median over the repetitions.

use crate::integrate::Scheme;
use crate::model::{DampingSpec, ShearBuilding, StructuralModel, shear_building};
use crate::specimen::SpecimenSpec;
use crate::substructure::{ErrorForceSpec, ExperimentalSubstructure, SubstepController, SubstepSettings};
use crate::transfer::{ActuatorSpec, SensorSpec, VirtualLab};
use crate::{Error, Result};
use nalgebra::DVector;
use serde::Serialize;
use std::time::{Duration, Instant};

/// Time step of the step benchmark \[s\].
pub const STEP_BENCH_DT: f64 = 0.01;
const DT: f64 = STEP_BENCH_DT;
/// Modal damping ratio of the buildings.
pub const STEP_BENCH_ZETA: f64 = 0.05;
const ZETA: f64 = STEP_BENCH_ZETA;

/// The settings of one step benchmark (`--stories`, `--steps`, `--repeats`, `--substeps`).
#[derive(Debug, Clone)]
pub struct StepBenchOptions {
    pub stories: Vec<usize>,
    pub steps: usize,
    pub repeats: usize,
    pub substeps: usize,
}

/// Time the buildings of `o` (every size monolithic, the largest also substructured).
pub fn bench_steps(o: &StepBenchOptions) -> Result<StepBench> {
    if o.stories.is_empty() || o.stories.contains(&0) {
        return Err(Error::invalid("--stories", "must be at least 1"));
    }
    if o.steps == 0 {
        return Err(Error::invalid("--steps", "must be at least 1"));
    }
    if o.substeps == 0 {
        return Err(Error::invalid("--substeps", "must be at least 1"));
    }
    if o.repeats < 5 {
        return Err(Error::invalid(
            "--repeats",
            format!("must be at least 5, got {}", o.repeats),
        ));
    }
    let mut stories = o.stories.clone();
    stories.sort_unstable();
    stories.dedup();
    let largest = *stories.last().expect("default list is not empty");

    let mut monolithic = Vec::new();
    let mut largest_model = None;
    for &n in &stories {
        let model = building(n)?;
        let us = bench_monolithic(&model, o.steps, o.repeats)?;
        monolithic.push(MonolithicResult {
            stories: n,
            us_per_step: us,
        });
        if n == largest {
            largest_model = Some(model);
        }
    }
    let model = largest_model.expect("largest model was built");
    let mut cases = Vec::new();
    for n_c in [1, 4] {
        if n_c <= largest {
            let (step, sub) = bench_substructure(&model, n_c, o.substeps, o.steps, o.repeats)?;
            cases.push(SubstructureCase {
                n_c,
                us_per_step: step,
                us_per_substep: sub,
            });
        }
    }
    Ok(StepBench {
        scheme: "newmark average acceleration (beta = 1/4, gamma = 1/2)",
        dt: DT,
        steps: o.steps,
        repeats: o.repeats,
        monolithic,
        substructure: SubstructureResult {
            stories: largest,
            substeps: o.substeps,
            cases,
        },
    })
}

#[derive(Debug, Serialize)]
pub struct MonolithicResult {
    pub stories: usize,
    pub us_per_step: f64,
}

#[derive(Debug, Serialize)]
pub struct SubstructureCase {
    pub n_c: usize,
    pub us_per_step: f64,
    pub us_per_substep: f64,
}

#[derive(Debug, Serialize)]
pub struct SubstructureResult {
    pub stories: usize,
    pub substeps: usize,
    pub cases: Vec<SubstructureCase>,
}

#[derive(Debug, Serialize)]
/// What `substep bench` measures (its `--json` object).
pub struct StepBench {
    pub scheme: &'static str,
    pub dt: f64,
    pub steps: usize,
    pub repeats: usize,
    pub monolithic: Vec<MonolithicResult>,
    pub substructure: SubstructureResult,
}

fn median_of(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

fn building(stories: usize) -> Result<StructuralModel> {
    let b = ShearBuilding {
        stories,
        story_mass: 1.0e5,
        first_period: (0.1 * stories as f64).max(0.1),
    };
    shear_building(&b)?.with_damping(&DampingSpec::Modal { zeta: vec![ZETA] })
}

/// Ground acceleration at step `i`: a 1 Hz harmonic of 1 m/s².
fn ag(i: usize) -> f64 {
    (2.0 * std::f64::consts::PI * i as f64 * DT).sin()
}

fn bench_monolithic(model: &StructuralModel, steps: usize, repeats: usize) -> Result<f64> {
    let mi = model.effective_mass_vector();
    let mut load = DVector::zeros(model.n_dofs());
    let mut integ = Scheme::Newmark { beta: 0.25, gamma: 0.5 }.build(model, DT, &(-&mi * ag(0)))?;
    let mut i = 0;
    let mut samples = Vec::with_capacity(repeats);
    for _ in 0..repeats {
        let t0 = Instant::now();
        for _ in 0..steps {
            i += 1;
            load.copy_from(&mi);
            load.scale_mut(-ag(i));
            integ.step(&load);
        }
        samples.push(t0.elapsed().as_secs_f64() * 1e6 / steps as f64);
    }
    if !integ.state().is_finite() {
        return Err(Error::numerical("substep bench", "the monolithic benchmark diverged"));
    }
    Ok(median_of(samples))
}

/// `(µs per full step, µs per sub-step)` with `n_c` spring specimens on the top floors.
fn bench_substructure(
    model: &StructuralModel,
    n_c: usize,
    substeps: usize,
    steps: usize,
    repeats: usize,
) -> Result<(f64, f64)> {
    let n = model.n_dofs();
    let coupling: Vec<usize> = (0..n_c).map(|k| n - 1 - k).collect();
    let k_story = model.stiffness[(n - 1, n - 1)];
    let specimens: Vec<SpecimenSpec> = coupling
        .iter()
        .map(|&dof| SpecimenSpec::LinearSdof {
            dof,
            mass: None,
            stiffness: 0.1 * k_story,
            damping: 0.0,
        })
        .collect();
    let settings = SubstepSettings {
        dt: DT,
        beta: 0.25,
        gamma: 0.5,
        substeps,
        coupling_dofs: coupling.clone(),
        error_force: ErrorForceSpec::None,
    };
    let mi = model.effective_mass_vector();
    let mut load = -&mi * ag(0);
    let mut ctrl = SubstepController::new(model, &settings, &load)?;
    let dtau = DT / substeps as f64;
    let mut lab = VirtualLab::from_specs(
        &coupling,
        &specimens,
        &vec![ActuatorSpec::ideal(); n_c],
        &vec![SensorSpec::ideal(); n_c],
        &vec![SensorSpec::ideal(); n_c],
        dtau,
        1,
    )?;
    let (mut force, mut disp) = (vec![0.0; n_c], vec![0.0; n_c]);
    let mut i = 0;
    let (mut per_step, mut per_substep) = (Vec::new(), Vec::new());
    for _ in 0..repeats {
        let (mut total, mut inner) = (Duration::ZERO, Duration::ZERO);
        for _ in 0..steps {
            let (a0, a1) = (ag(i), ag(i + 1));
            i += 1;
            let t0 = Instant::now();
            load.copy_from(&mi);
            load.scale_mut(-a1);
            ctrl.begin_step(&load);
            let t1 = Instant::now();
            for j in 1..=substeps {
                let command = ctrl.next_command();
                lab.substep(
                    command,
                    crate::substructure::substep_ground_acceleration(a0, a1, j, substeps),
                    dtau,
                    &mut force,
                    &mut disp,
                )?;
                ctrl.feedback(&force);
            }
            inner += t1.elapsed();
            ctrl.finish_step();
            total += t0.elapsed();
        }
        per_step.push(total.as_secs_f64() * 1e6 / steps as f64);
        per_substep.push(inner.as_secs_f64() * 1e6 / (steps * substeps) as f64);
    }
    if !ctrl.state().is_finite() {
        return Err(Error::numerical("substep bench", "the substructure benchmark diverged"));
    }
    Ok((median_of(per_step), median_of(per_substep)))
}
