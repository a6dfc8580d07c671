//! The large-model benchmark: one full substructure step (predictor solve, `k_sub` sub-steps
//! with a spring specimen behind an ideal actuator, closing the step) on a chain, a 2-D or a
//! 3-D frame, timed step by step; and the monolithic Newmark loop the comparisons use.

use super::stats::{peak_rss_bytes, quantile, reset_peak_rss, thread_cpu_seconds};
use crate::error::{Error, Result};
use crate::integrate::{Integrator, Newmark};
use crate::model::{
    DampingSpec, Frame2d, Frame3d, FrameDof, ShearBuilding, SparseModel, frame_2d, frame_3d, rayleigh_coefficients,
    shear_building_sparse,
};
use crate::specimen::SpecimenSpec;
use crate::substructure::{
    ErrorForceSpec, ExperimentalSubstructure, SubstepController, SubstepSettings, substep_ground_acceleration,
};
use crate::transfer::{ActuatorSpec, SensorSpec, VirtualLab};
use nalgebra::DVector;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Time step of every benchmark \[s\].
pub const DT: f64 = 0.01;
/// Rayleigh damping ratio at modes 1 and 2.
pub const ZETA: f64 = 0.05;
const WARMUP_STEPS: usize = 20;

/// Ground acceleration at step `i`: a 1 Hz harmonic of 1 m/s².
pub fn ag(i: usize) -> f64 {
    (2.0 * std::f64::consts::PI * i as f64 * DT).sin()
}

/// Which model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BenchModel {
    /// Uniform shear building (tridiagonal K, diagonal M).
    Chain,
    /// 2-D steel moment frame, twice as many stories as bays.
    Frame,
    /// 3-D steel moment frame ([`Frame3d::with_about_dofs`]).
    Frame3d,
}

impl BenchModel {
    pub fn name(self) -> &'static str {
        match self {
            BenchModel::Chain => "chain",
            BenchModel::Frame => "frame",
            BenchModel::Frame3d => "frame3d",
        }
    }
    pub fn from_name(s: &str) -> Result<Self> {
        match s {
            "chain" => Ok(BenchModel::Chain),
            "frame" => Ok(BenchModel::Frame),
            "frame3d" => Ok(BenchModel::Frame3d),
            other => Err(Error::invalid(
                "--model",
                format!("unknown model '{other}' (expected chain, frame or frame3d)"),
            )),
        }
    }
}

/// The chain of the benchmarks and the comparison: `n` floors of 100 t, first period
/// `max(0.1 n, 0.1)` s, Rayleigh damping with 5 % at modes 1 and 2 (closed-form frequencies).
pub fn chain(n: usize) -> Result<(ShearBuilding, f64, f64)> {
    let b = ShearBuilding {
        stories: n,
        story_mass: 1.0e5,
        first_period: (0.1 * n as f64).max(0.1),
    };
    let (alpha, beta) = if n >= 2 {
        rayleigh_coefficients(ZETA, b.omega(1), b.omega(2))?
    } else {
        (0.0, 2.0 * ZETA / b.omega(1))
    };
    Ok((b, alpha, beta))
}

/// A benchmark model with its coupling DOF (the roof; for frames the first roof node, in `x`).
#[derive(Debug, Clone)]
pub struct BuiltModel {
    pub model: SparseModel,
    pub roof: usize,
    /// `"129 bays x 256 stories"` and the like.
    pub layout: String,
    /// Bays of a frame (0 for the chain).
    pub bays: usize,
    pub stories: usize,
    /// Rayleigh `(α, β)` of the damping `C = α M + β K`.
    pub rayleigh: (f64, f64),
}

/// Build `model` of about `dofs` DOFs (the frames take the nearest size their layout allows),
/// damped with Rayleigh 5 % at modes 1 and 2.
pub fn build(model: BenchModel, dofs: usize) -> Result<BuiltModel> {
    if dofs < 3 {
        return Err(Error::invalid("--dofs", "must be at least 3"));
    }
    let ratio = |m: SparseModel| -> Result<(SparseModel, (f64, f64))> {
        let w = crate::model::lowest_frequencies(&m.mass, &m.stiffness, 2)?;
        let (alpha, beta) = rayleigh_coefficients(ZETA, w[0], w[1])?;
        Ok((m.with_damping(&DampingSpec::Rayleigh { alpha, beta })?, (alpha, beta)))
    };
    match model {
        BenchModel::Chain => {
            let (b, alpha, beta) = chain(dofs)?;
            let m = shear_building_sparse(&b)?.with_damping(&DampingSpec::Rayleigh { alpha, beta })?;
            Ok(BuiltModel {
                model: m,
                roof: dofs - 1,
                layout: format!("{dofs} stories"),
                bays: 0,
                stories: dofs,
                rayleigh: (alpha, beta),
            })
        }
        BenchModel::Frame => {
            let f = Frame2d::with_about_dofs(dofs);
            let (m, rayleigh) = ratio(frame_2d(&f)?)?;
            Ok(BuiltModel {
                model: m,
                roof: f.dof(f.stories, 0, FrameDof::Ux).expect("roof node exists"),
                layout: format!("{} bays x {} stories", f.bays, f.stories),
                bays: f.bays,
                stories: f.stories,
                rayleigh,
            })
        }
        BenchModel::Frame3d => {
            let f = Frame3d::with_about_dofs(dofs);
            let (m, rayleigh) = ratio(frame_3d(&f)?)?;
            Ok(BuiltModel {
                model: m,
                roof: f.roof_x_dof(),
                layout: format!("{} x {} bays x {} stories", f.bays_x, f.bays_y, f.stories),
                bays: f.bays_x,
                stories: f.stories,
                rayleigh,
            })
        }
    }
}

/// Yield rotation of the hinged frame's hinges \[rad\] (the yield moment is this times the
/// hinge's initial stiffness): the benchmark's 1 m/s² harmonic yields part of them (the count
/// is reported).
pub const YIELD_ROTATION: f64 = 2.0e-6;

/// The hinges of the yielding frame benchmark: at every member end, bilinear (2 % hardening),
/// initial stiffness 10 · 6EI/L, yield at [`YIELD_ROTATION`].
pub fn bench_frame_hinges(f: &Frame2d) -> crate::model::FrameHinges {
    let law = |sec: crate::model::Section, len: f64| crate::material::MaterialSpec::Bilinear {
        yield_force: 10.0 * 6.0 * f.elastic_modulus * sec.inertia / len * YIELD_ROTATION,
        hardening: 0.02,
    };
    crate::model::FrameHinges {
        at: crate::model::HingeLocation::Both,
        stiffness_factor: 10.0,
        beam_law: law(f.beam, f.bay_width),
        column_law: law(f.column, f.story_height),
    }
}

/// The plane frame with hinges at every member end whose DOFs (nodes and hinges) come to about
/// `dofs` (a node carries 3 DOFs and about 4 hinge rotations: the nodes get 3/7 of them),
/// Rayleigh 5 % at modes 1 and 2 of the initial stiffness.
pub fn build_hinged_frame(dofs: usize) -> Result<(BuiltModel, crate::model::Hysteresis)> {
    if dofs < 3 {
        return Err(Error::invalid("--dofs", "must be at least 3"));
    }
    let f = Frame2d::with_about_dofs((3 * dofs / 7).max(3));
    let (m, springs) = crate::model::frame_2d_hinged(&f, &bench_frame_hinges(&f))?;
    let w = crate::model::lowest_frequencies(&m.mass, &m.stiffness, 2)?;
    let (alpha, beta) = rayleigh_coefficients(ZETA, w[0], w[1])?;
    let n_hinges = springs.springs.len();
    Ok((
        BuiltModel {
            model: m.with_damping(&DampingSpec::Rayleigh { alpha, beta })?,
            roof: f.dof(f.stories, 0, FrameDof::Ux).expect("roof node exists"),
            layout: format!("{} bays x {} stories, {n_hinges} hinges", f.bays, f.stories),
            bays: f.bays,
            stories: f.stories,
            rayleigh: (alpha, beta),
        },
        springs,
    ))
}

/// What to run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelBenchOptions {
    pub model: BenchModel,
    pub dofs: usize,
    pub steps: usize,
    pub substeps: usize,
    /// Sweep the sparse factor on two cores (opt-in, see
    /// [`SubstepController::enable_second_core`]).
    pub second_core: bool,
    /// Bilinear storey springs on the chain ([`yielding_springs`]) or hinges at every member
    /// end of the frame ([`build_hinged_frame`]); the full step then runs the operator
    /// splitting and the monolithic step Newmark + Newton.
    pub yielding: bool,
}

/// Yield drift of the yielding chain's storeys \[m\]: the benchmark's 1 m/s² harmonic makes the
/// lower storeys of the tall chains yield (the count is reported).
pub const YIELD_DRIFT: f64 = 2.0e-6;

/// Bilinear storey springs (2 % hardening, yield at [`YIELD_DRIFT`]) on the chain `b`.
pub fn yielding_springs(b: &ShearBuilding) -> crate::model::Hysteresis {
    let n = b.stories;
    let k = vec![b.story_stiffness(); n];
    let laws = vec![
        crate::material::MaterialSpec::Bilinear {
            yield_force: b.story_stiffness() * YIELD_DRIFT,
            hardening: 0.02,
        };
        n
    ];
    crate::model::storey_springs(&k, &laws, "bench.yielding")
}

/// The result of one model benchmark.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ModelBench {
    pub model: BenchModel,
    /// DOFs of the numerical model (the frames' is the nearest to the request their layout allows).
    pub dofs: usize,
    pub requested_dofs: usize,
    pub layout: String,
    pub stories: usize,
    pub steps: usize,
    pub substeps: usize,
    pub n_c: usize,
    pub dt: f64,
    /// Stored entries of K and the half-bandwidth of K (natural DOF order).
    pub nnz_k: usize,
    pub half_bandwidth: usize,
    /// The factorisation of the effective stiffness.
    pub solver: String,
    /// Whether the sparse solve ran on two cores.
    pub second_core: bool,
    /// Bytes of the factor one solve reads (forward and backward sweep).
    pub solve_bytes: usize,
    /// Model assembly + damping + factorisation + gain columns \[ms\].
    pub setup_ms: f64,
    pub us_per_step_median: f64,
    pub us_per_step_p99: f64,
    pub us_per_step_max: f64,
    pub us_per_step_mean: f64,
    /// CPU time of the stepping thread per step, median \[µs\].
    pub cpu_us_per_step_median: f64,
    /// Wall time of the timed steps over their simulated duration `steps · dt`.
    pub realtime_ratio: f64,
    /// Monolithic Newmark (same model, no sub-steps), median µs per step.
    pub us_per_step_monolithic_median: f64,
    /// Streaming read bandwidth of one core, measured after the run \[GB/s\]
    /// ([`super::read_bandwidth_gbs`]).
    pub read_bandwidth_gbs: f64,
    /// The physical floor of one solve: `solve_bytes` over that bandwidth \[µs\].
    pub solve_floor_us: f64,
    /// Peak RSS while the model is held and the substructure test is built and run (the peak
    /// is reset after the model is built; the monolithic run comes after) \[bytes\].
    pub peak_rss_bytes: u64,
    /// Yielding storeys (`--yielding`): springs past their yield drift at the end of the run,
    /// and the Newton iterations per monolithic step.
    #[serde(default)]
    pub yielding: bool,
    #[serde(default)]
    pub springs_yielded: usize,
    #[serde(default)]
    pub newton_iterations_per_step: f64,
    /// Rayleigh `(α, β)` of the model (`C = α M + β K`, initial stiffness).
    #[serde(default)]
    pub rayleigh: (f64, f64),
    /// Bays of a frame model (0 for the chain).
    #[serde(default)]
    pub bays: usize,
}

/// Run the benchmark of `o`.
pub fn bench_model(o: &ModelBenchOptions) -> Result<ModelBench> {
    if o.substeps == 0 {
        return Err(Error::invalid("--substeps", "must be at least 1"));
    }
    if o.steps == 0 {
        return Err(Error::invalid("--steps", "must be at least 1"));
    }
    let t_setup = Instant::now();
    let (built, springs_of_frame) = match (o.yielding, o.model) {
        (true, BenchModel::Frame) => {
            let (b, h) = build_hinged_frame(o.dofs)?;
            (b, Some(h))
        }
        _ => (build(o.model, o.dofs)?, None),
    };
    reset_peak_rss();
    let (m, roof) = (&built.model, built.roof);
    let n = m.n_dofs();
    let coupling = vec![roof];
    let specimens = vec![SpecimenSpec::LinearSdof {
        dof: roof,
        mass: None,
        stiffness: 0.1 * m.stiffness.get(roof, roof),
        damping: 0.0,
    }];
    let settings = SubstepSettings {
        dt: DT,
        beta: 0.25,
        gamma: 0.5,
        substeps: o.substeps,
        coupling_dofs: coupling.clone(),
        error_force: ErrorForceSpec::None,
    };
    let mi = m.effective_mass_vector();
    let mut load = -&mi * ag(0);
    let mut ctrl = SubstepController::new(m, &settings, &load)?;
    let springs = match (o.yielding, o.model) {
        (false, _) => None,
        (true, BenchModel::Chain) => Some(yielding_springs(&chain(o.dofs)?.0)),
        (true, BenchModel::Frame) => springs_of_frame,
        (true, BenchModel::Frame3d) => {
            return Err(Error::invalid(
                "--yielding",
                "needs --model chain or frame (space frames have no hinges)",
            ));
        }
    };
    if let Some(h) = &springs {
        ctrl.set_springs(h.build(n)?);
    }
    let second_core = o.second_core && ctrl.enable_second_core();
    let setup_ms = t_setup.elapsed().as_secs_f64() * 1e3;
    let dtau = DT / o.substeps as f64;
    let mut lab = VirtualLab::from_specs(
        &coupling,
        &specimens,
        &[ActuatorSpec::ideal()],
        &[SensorSpec::ideal()],
        &[SensorSpec::ideal()],
        dtau,
        1,
    )?;
    let (mut force, mut disp) = ([0.0], [0.0]);
    let mut samples = Vec::with_capacity(o.steps);
    let mut cpu = Vec::with_capacity(o.steps);
    let mut timed_wall = 0.0;
    for i in 0..WARMUP_STEPS + o.steps {
        let (a0, a1) = (ag(i), ag(i + 1));
        let c0 = thread_cpu_seconds();
        let t0 = Instant::now();
        load.copy_from(&mi);
        load.scale_mut(-a1);
        ctrl.begin_step(&load);
        for j in 1..=o.substeps {
            let command = ctrl.next_command();
            lab.substep(
                command,
                substep_ground_acceleration(a0, a1, j, o.substeps),
                dtau,
                &mut force,
                &mut disp,
            )?;
            ctrl.feedback(&force);
        }
        ctrl.finish_step();
        let us = t0.elapsed().as_secs_f64() * 1e6;
        let c = (thread_cpu_seconds() - c0) * 1e6;
        if i >= WARMUP_STEPS {
            samples.push(us);
            cpu.push(c);
            timed_wall += us * 1e-6;
        }
    }
    if !ctrl.state().is_finite() {
        return Err(Error::numerical("benchmark", "the substructure benchmark diverged"));
    }
    let peak = peak_rss_bytes();
    let (solver, solve_bytes) = (ctrl.solver(), ctrl.solve_bytes());
    let springs_yielded = ctrl.springs().map_or(0, |s| {
        s.states().filter(|(d, _)| d.abs() > YIELD_DRIFT * (1.0 + 1e-9)).count()
    });
    drop(ctrl);
    // Monolithic Newmark (+ Newton for yielding storeys) on the same model (shorter run), after
    // the test is gone.
    let mono_steps = o.steps.clamp(10, 2000);
    let mut integ: Box<dyn Integrator> = match &springs {
        Some(h) => Box::new(crate::integrate::NewmarkNewton::new(
            m,
            h.build(n)?,
            DT,
            0.25,
            0.5,
            crate::integrate::NewtonSettings::default(),
            &(-&mi * ag(0)),
        )?),
        None => {
            let mut integ = Newmark::new(m, DT, 0.25, 0.5, &(-&mi * ag(0)))?;
            if o.second_core {
                integ.enable_second_core();
            }
            Box::new(integ)
        }
    };
    let mut mono = Vec::with_capacity(mono_steps);
    for i in 0..WARMUP_STEPS + mono_steps {
        let t0 = Instant::now();
        load.copy_from(&mi);
        load.scale_mut(-ag(i + 1));
        integ.step(&load);
        if i >= WARMUP_STEPS {
            mono.push(t0.elapsed().as_secs_f64() * 1e6);
        }
    }
    if let Some(reason) = integ.failure() {
        return Err(Error::numerical("benchmark (monolithic Newton)", reason.to_string()));
    }
    let newton_iterations_per_step = integ
        .newton_iterations()
        .map_or(0.0, |(total, _)| total as f64 / (WARMUP_STEPS + mono_steps) as f64);
    mono.sort_by(f64::total_cmp);
    cpu.sort_by(f64::total_cmp);
    let bandwidth = super::read_bandwidth_gbs();
    let mean = samples.iter().sum::<f64>() / samples.len() as f64;
    samples.sort_by(f64::total_cmp);
    Ok(ModelBench {
        model: o.model,
        dofs: n,
        requested_dofs: o.dofs,
        layout: built.layout,
        stories: built.stories,
        steps: o.steps,
        substeps: o.substeps,
        n_c: 1,
        dt: DT,
        nnz_k: m.stiffness.nnz(),
        half_bandwidth: m.stiffness.half_bandwidth(),
        solver,
        second_core,
        solve_bytes,
        setup_ms,
        us_per_step_median: quantile(&samples, 0.5),
        us_per_step_p99: quantile(&samples, 0.99),
        us_per_step_max: *samples.last().expect("at least one step"),
        us_per_step_mean: mean,
        cpu_us_per_step_median: quantile(&cpu, 0.5),
        realtime_ratio: timed_wall / (o.steps as f64 * DT),
        us_per_step_monolithic_median: quantile(&mono, 0.5),
        read_bandwidth_gbs: bandwidth,
        solve_floor_us: solve_bytes as f64 / (bandwidth * 1e3),
        peak_rss_bytes: peak,
        yielding: springs.is_some(),
        springs_yielded,
        newton_iterations_per_step,
        rayleigh: built.rayleigh,
        bays: built.bays,
    })
}

/// Monolithic Newmark (average acceleration) from rest under `a_g = sin 2πt`: the roof
/// displacement after each of `check_steps` steps, then the CPU time per step \[µs\] of each of
/// `batches` batches of `batch_steps` further steps. The load of step `i + 1` is
/// `−M ι a_g(t_{i+1})`, exactly as the comparison scripts apply it.
pub fn monolithic_run(
    model: &SparseModel,
    roof: usize,
    second_core: bool,
    check_steps: usize,
    batches: usize,
    batch_steps: usize,
) -> Result<(Vec<f64>, Vec<f64>)> {
    let mi = model.effective_mass_vector();
    let mut integ = Newmark::new(model, DT, 0.25, 0.5, &(-&mi * ag(0)))?;
    if second_core {
        integ.enable_second_core();
    }
    let mut load = DVector::zeros(model.n_dofs());
    let mut i = 0;
    let mut step = |integ: &mut Newmark, i: &mut usize| {
        *i += 1;
        load.copy_from(&mi);
        load.scale_mut(-ag(*i));
        integ.step(&load);
    };
    let mut roof_u = Vec::with_capacity(check_steps);
    for _ in 0..check_steps {
        step(&mut integ, &mut i);
        roof_u.push(integ.state().u[roof]);
    }
    let mut per_batch = Vec::with_capacity(batches);
    for _ in 0..batches {
        let c0 = thread_cpu_seconds();
        for _ in 0..batch_steps {
            step(&mut integ, &mut i);
        }
        per_batch.push((thread_cpu_seconds() - c0) * 1e6 / batch_steps.max(1) as f64);
    }
    if !integ.state().is_finite() {
        return Err(Error::numerical("benchmark", "the monolithic run diverged"));
    }
    Ok((roof_u, per_batch))
}
