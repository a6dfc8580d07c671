//! One benchmark run: inputs, the loop (the benchmark's own, or with the numerical substructure
//! integrated by the sub-step algorithm), the exact reference and the evaluation criteria.

use super::case::{Case, GroundRecord, Specimen, influence, numerical_matrices};
use super::controller::ControllerSpec;
use crate::analysis::metrics::{nrms_error, peak_error, round_delay_ms, round_percent, tracking_delay};
use crate::error::{Error, Result};
use crate::integrate::FohMap;
use crate::linalg::{axpy_array, rk4_combine};
use crate::model::StructuralModel;
use crate::substructure::{ErrorForceSpec, SubstepController, SubstepSettings};
use crate::transfer::noise::{BENCHMARK_SEED, MinStdPolar, NoiseLevel};
use crate::transfer::servo::{Derivative, DifferenceForce, ServoActuator, ServoParams};
use nalgebra::{DMatrix, DVector, Matrix3, SMatrix, SVector};
use std::sync::Arc;

use super::controller::SAMPLE_TIME;

/// Displacement-sensor noise power `P_x` [m²·s] (σ_x = √(P_x/h) = 1.6e−5 m).
pub const NOISE_POWER_X: f64 = 6.25e-14;
/// Force-sensor noise power `P_f` [N²·s] (σ_f = √(P_f/h) ≈ 2.18 N).
pub const NOISE_POWER_F: f64 = 1.16e-3;
/// A run with `max |F| ≥` this \[N\] exceeds the actuator's capacity.
pub const FORCE_CAPACITY: f64 = 8900.0;
/// Lags of the J1 correlation (0..=49 samples: J1 saturates at 12.0 ms).
pub const MAX_LAG: usize = 49;
/// A displacement beyond this \[m\] (140× the stroke) stops the run as diverged.
pub const DIVERGENCE_LIMIT: f64 = 1.0;

/// A run whose tracking error J2 exceeds this [%] counts as unstable.
pub const UNSTABLE_TRACKING_PERCENT: f64 = 100.0;

/// How the numerical substructure is integrated.
#[derive(Debug, Clone, PartialEq)]
pub enum Algorithm {
    /// The benchmark's loop: continuous model, RK4 at h, one-sample force delay.
    Benchmark,
    /// The project's sub-step algorithm (Newmark at Δt, `k_sub` sub-steps, error-force
    /// compensation).
    Substep(SubstepSpec),
}

/// Settings of the sub-step algorithm in a benchmark run.
#[derive(Debug, Clone, PartialEq)]
pub struct SubstepSpec {
    /// Time step Δt \[s\]; a whole number of controller samples.
    pub dt: f64,
    pub k_sub: usize,
    pub beta: f64,
    pub gamma: f64,
    pub error_force: ErrorForceSpec,
}

impl Default for SubstepSpec {
    /// Δt = 1/1024 s (4 samples), `k_sub = 4`, average acceleration, P = 1 compensation.
    fn default() -> Self {
        Self {
            dt: 1.0 / 1024.0,
            k_sub: 4,
            beta: 0.25,
            gamma: 0.5,
            error_force: ErrorForceSpec::Pid { p: 1.0, i: 0.0, d: 0.0 },
        }
    }
}

impl SubstepSpec {
    /// Samples per step `Δt/h` (must be a whole number ≥ 1).
    pub fn samples_per_step(&self) -> Result<usize> {
        crate::error::require_positive("substep.dt", self.dt)?;
        let n = self.dt / SAMPLE_TIME;
        let r = n.round();
        if !(r >= 1.0 && (n - r).abs() < 1e-9 && r <= 4096.0 * 10.0) {
            return Err(Error::invalid(
                "substep.dt",
                format!(
                    "must be a whole number of controller samples (1/4096 s), got {} s = {n} samples",
                    self.dt
                ),
            ));
        }
        if self.k_sub == 0 || self.k_sub > 1000 {
            return Err(Error::invalid(
                "substep.k_sub",
                format!("must be in 1..=1000, got {}", self.k_sub),
            ));
        }
        self.error_force.validate()?;
        Ok(r as usize)
    }
}

/// What sits between the command and the specimen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Transfer {
    /// The servo-hydraulic plant with the specimen.
    Plant {
        params: ServoParams,
        derivative: Derivative,
    },
    /// `x = desired` exactly (no controller, no plant): the loop's own error.
    Ideal,
}

impl Transfer {
    pub fn nominal() -> Self {
        Transfer::Plant {
            params: ServoParams::benchmark(),
            derivative: Derivative::FiniteDifference,
        }
    }
}

/// Everything one run needs.
#[derive(Debug, Clone)]
pub struct RthsInput {
    pub case: Case,
    pub record: Arc<GroundRecord>,
    /// Scale of the record (`eq_intensity`, default 0.4).
    pub intensity: f64,
    pub controller: ControllerSpec,
    pub transfer: Transfer,
    /// The benchmark's sensor noise on.
    pub noise: bool,
    /// Start state of the noise generator (the benchmark's: [`BENCHMARK_SEED`]).
    pub noise_seed: u32,
    pub algorithm: Algorithm,
    /// Keep the time histories in the result (for plots).
    pub keep_history: bool,
}

impl RthsInput {
    /// The benchmark's nominal run of `case` with `controller`: El Centro at 0.4, noise on.
    pub fn nominal(case: Case, controller: ControllerSpec) -> Self {
        Self {
            case,
            record: Arc::new(GroundRecord::elcentro()),
            intensity: 0.4,
            controller,
            transfer: Transfer::nominal(),
            noise: true,
            noise_seed: BENCHMARK_SEED,
            algorithm: Algorithm::Benchmark,
            keep_history: false,
        }
    }

    /// Number of samples `⌊T/h⌋ + 1`.
    pub fn samples(&self) -> usize {
        (self.record.duration() / SAMPLE_TIME + 1e-9).floor() as usize + 1
    }
}

/// J1…J9 of a run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Criteria {
    /// J1 \[ms\], J2…J9 [%], rounded as the benchmark rounds.
    pub j: [f64; 9],
    /// The same unrounded (J1 = lag·h in ms, J2…J9 as 100 × ratio).
    pub raw: [f64; 9],
}

/// Time histories of a run (at the controller samples; the floors of the numerical
/// substructure every `floor_stride` samples).
#[derive(Debug, Clone, Default)]
pub struct RunHistory {
    pub h: f64,
    pub desired: Vec<f64>,
    /// The controller's output to the actuator (after the D/A) \[m\].
    pub command: Vec<f64>,
    pub measured: Vec<f64>,
    pub actuator_force: Vec<f64>,
    pub floor_stride: usize,
    pub floors: [Vec<f64>; 3],
    pub reference: [Vec<f64>; 3],
}

/// The outcome of a run.
#[derive(Debug, Clone)]
pub struct RthsResult {
    pub case: u8,
    /// `None` if the run diverged.
    pub criteria: Option<Criteria>,
    /// Largest |F| of the actuator \[N\] (ideal transfer: of the load-cell force).
    pub max_force: f64,
    pub stable: bool,
    pub capacity_exceeded: bool,
    /// Time at which the run diverged \[s\].
    pub diverged_at: Option<f64>,
    /// Why the phase-lag compensator's guard disabled it, if it did.
    pub guard_trip: Option<String>,
    pub history: Option<RunHistory>,
}

impl RthsResult {
    /// What a user must know about this run, one sentence each: no score (it diverged), the
    /// actuator force beyond the benchmark's capacity, the phase-lag guard disabling the
    /// compensator. Empty for a sound run.
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        if self.criteria.is_none() {
            w.push(match self.diverged_at {
                Some(t) => format!("case {}: no score: the run diverged at t = {t:.3} s", self.case),
                None => format!(
                    "case {}: no score: the run did not finish with finite responses",
                    self.case
                ),
            });
        }
        if self.capacity_exceeded {
            w.push(format!(
                "case {}: the actuator force reached {} N, beyond the benchmark's capacity of {FORCE_CAPACITY} N: \
                 a lab test would have overloaded the specimen",
                self.case,
                crate::format::sig(self.max_force, 4)
            ));
        }
        if let Some(g) = &self.guard_trip {
            w.push(format!(
                "case {}: the phase-lag compensator was disabled: {g}",
                self.case
            ));
        }
        w
    }
}

/// The exact FOH reference of the full 3-DOF model under `ag` sampled at `h`: floor
/// displacements `[x_r1, x_r2, x_r3]`.
pub fn reference(case: &Case, ag: &[f64], h: f64) -> Result<[Vec<f64>; 3]> {
    let m = case.mass_matrix();
    let minv = m.try_inverse().expect("diagonal positive mass");
    let (k, c) = (case.stiffness_matrix(), case.damping_matrix());
    let mut a = DMatrix::zeros(6, 6);
    for i in 0..3 {
        a[(i, i + 3)] = 1.0;
    }
    let mk = -(minv * k);
    let mc = -(minv * c);
    for i in 0..3 {
        for j in 0..3 {
            a[(3 + i, j)] = mk[(i, j)];
            a[(3 + i, 3 + j)] = mc[(i, j)];
        }
    }
    // M q̈ = … − M ι a_g  →  input column −ι.
    let mut b = DMatrix::zeros(6, 1);
    for i in 0..3 {
        b[(3 + i, 0)] = -influence()[i];
    }
    let map = FohMap::new(&a, &b, h)?;
    let phi = SMatrix::<f64, 6, 6>::from_fn(|i, j| map.phi[(i, j)]);
    let g0 = SVector::<f64, 6>::from_fn(|i, _| map.gamma0[(i, 0)]);
    let g1 = SVector::<f64, 6>::from_fn(|i, _| map.gamma1[(i, 0)]);
    let mut z = SVector::<f64, 6>::zeros();
    let mut out = [
        Vec::with_capacity(ag.len()),
        Vec::with_capacity(ag.len()),
        Vec::with_capacity(ag.len()),
    ];
    for k in 0..ag.len() {
        for i in 0..3 {
            out[i].push(z[i]);
        }
        if k + 1 < ag.len() {
            z = phi * z + g0 * ag[k] + g1 * (ag[k + 1] - ag[k]);
        }
    }
    Ok(out)
}

/// The numerical substructure as the benchmark integrates it: `z = [q; q̇]`,
/// `M_N q̈ + C_N q̇ + K_N q = −M ι a_g − e₁ f_in`, RK4 with `f_in` held.
struct Numerical {
    mk: Matrix3<f64>,
    mc: Matrix3<f64>,
    load: [f64; 3],
    fvec: f64,
    z: [f64; 6],
}

impl Numerical {
    fn new(case: &Case, specimen: &Specimen) -> Self {
        let (mn, cn, kn) = numerical_matrices(case, specimen);
        let minv = Matrix3::from_diagonal(&mn.diagonal().map(|v| 1.0 / v));
        let mfull = case.mass_matrix() * influence();
        Self {
            mk: minv * kn,
            mc: minv * cn,
            load: [
                -mfull[0] * minv[(0, 0)],
                -mfull[1] * minv[(1, 1)],
                -mfull[2] * minv[(2, 2)],
            ],
            fvec: -minv[(0, 0)],
            z: [0.0; 6],
        }
    }
    #[inline]
    fn rhs(&self, z: &[f64; 6], ag: f64, f: f64) -> [f64; 6] {
        let mut out = [z[3], z[4], z[5], 0.0, 0.0, 0.0];
        for i in 0..3 {
            let mut acc = self.load[i] * ag;
            for j in 0..3 {
                acc -= self.mk[(i, j)] * z[j] + self.mc[(i, j)] * z[3 + j];
            }
            out[3 + i] = acc;
        }
        out[3] += self.fvec * f;
        out
    }
    #[inline]
    fn step(&mut self, ag: [f64; 3], f: f64, h: f64) {
        let z0 = self.z;
        let k1 = self.rhs(&z0, ag[0], f);
        let k2 = self.rhs(&axpy_array(&z0, 0.5 * h, &k1), ag[1], f);
        let k3 = self.rhs(&axpy_array(&z0, 0.5 * h, &k2), ag[1], f);
        let k4 = self.rhs(&axpy_array(&z0, h, &k3), ag[2], f);
        self.z = rk4_combine(&z0, h, [&k1, &k2, &k3, &k4]);
    }
}

/// The experimental side at one sample: plant (or ideal transfer), load cell, noise.
struct Lab {
    plant: Option<ServoActuator>,
    load_cell: DifferenceForce,
    noise: Option<MinStdPolar>,
    sigma_x: f64,
    sigma_f: f64,
}

impl Lab {
    fn new(input: &RthsInput) -> Result<Self> {
        let (plant, spec) = match input.transfer {
            Transfer::Plant { params, derivative } => (
                Some(ServoActuator::new(params, derivative, SAMPLE_TIME)?),
                Specimen {
                    m: params.m_e,
                    c: params.c_e,
                    k: params.k_e,
                },
            ),
            Transfer::Ideal => (None, Specimen::benchmark()),
        };
        let sigma_x = NoiseLevel::Power {
            p: NOISE_POWER_X,
            sample_time: SAMPLE_TIME,
        }
        .sigma("noise.displacement")?;
        let sigma_f = NoiseLevel::Power {
            p: NOISE_POWER_F,
            sample_time: SAMPLE_TIME,
        }
        .sigma("noise.force")?;
        Ok(Self {
            plant,
            load_cell: DifferenceForce::new(spec.m, spec.c, spec.k, SAMPLE_TIME),
            noise: if input.noise {
                Some(MinStdPolar::new(input.noise_seed)?)
            } else {
                None
            },
            sigma_x,
            sigma_f,
        })
    }

    /// Step 1 of the benchmark's step: `(x, x_m, f_m, |F|)` at `t_k`; `desired` is used by the
    /// ideal transfer.
    #[inline]
    fn outputs(&mut self, desired: f64) -> (f64, f64, f64, f64) {
        let x = match &self.plant {
            Some(p) => p.displacement(),
            None => desired,
        };
        let f = self.load_cell.force(x);
        let n = self.noise.as_mut().map_or(0.0, |g| g.normal());
        let big_f = match &self.plant {
            Some(p) => p.force().abs(),
            None => f.abs(),
        };
        (x, x + self.sigma_x * n, f + self.sigma_f * n, big_f)
    }

    #[inline]
    fn advance(&mut self, u: f64) {
        if let Some(p) = &mut self.plant {
            p.step(u);
        }
    }
}

/// Run one benchmark run.
pub fn run(input: &RthsInput) -> Result<RthsResult> {
    crate::error::require_non_negative("intensity", input.intensity)?;
    if !input.intensity.is_finite() {
        return Err(Error::invalid("intensity", "must be finite"));
    }
    let h = SAMPLE_TIME;
    let n = input.samples();
    // a_g at t_k and t_k + h/2.
    let mut ag = Vec::with_capacity(2 * n + 1);
    input
        .record
        .sample_sorted((0..=2 * n).map(|i| i as f64 * 0.5 * h), input.intensity, &mut ag);
    let ag_k: Vec<f64> = (0..n).map(|k| ag[2 * k]).collect();
    let reference = reference(&input.case, &ag_k, h)?;

    let mut controller = input.controller.build(h)?;
    let mut lab = Lab::new(input)?;
    let mut desired = vec![0.0; n];
    let mut measured = vec![0.0; n];
    let mut force_hist = if input.keep_history { vec![0.0; n] } else { Vec::new() };
    let mut command_hist = if input.keep_history { vec![0.0; n] } else { Vec::new() };
    let mut max_force = 0.0f64;
    let mut diverged_at = None;

    let (floors, stride) = match &input.algorithm {
        Algorithm::Benchmark => {
            let mut num = Numerical::new(&input.case, &Specimen::benchmark());
            let mut floors = [vec![0.0; n], vec![0.0; n], vec![0.0; n]];
            let mut f_delay = 0.0;
            for k in 0..n {
                let q = [num.z[0], num.z[1], num.z[2]];
                let (x, x_m, f_m, big_f) = lab.outputs(q[0]);
                if !(q.iter().all(|v| v.is_finite() && v.abs() <= DIVERGENCE_LIMIT)
                    && x.is_finite()
                    && x.abs() <= DIVERGENCE_LIMIT)
                {
                    diverged_at = Some(k as f64 * h);
                    break;
                }
                max_force = max_force.max(big_f);
                for i in 0..3 {
                    floors[i][k] = q[i];
                }
                desired[k] = q[0];
                measured[k] = x_m;
                if input.keep_history {
                    force_hist[k] = big_f;
                }
                let u = controller.command(q[0], x_m);
                if input.keep_history {
                    command_hist[k] = u;
                }
                let f_in = f_delay;
                f_delay = f_m;
                lab.advance(u);
                num.step([ag[2 * k], ag[2 * k + 1], ag[2 * k + 2]], f_in, h);
            }
            (floors, 1)
        }
        Algorithm::Substep(spec) => {
            let per_step = spec.samples_per_step()?;
            let r = run_substep(
                input,
                spec,
                per_step,
                &ag_k,
                &mut controller,
                &mut lab,
                &mut desired,
                &mut measured,
                &mut force_hist,
                &mut command_hist,
                &mut max_force,
            )?;
            diverged_at = r.1;
            (r.0, per_step)
        }
    };

    let criteria = if diverged_at.is_none() {
        let sub = |v: &[f64]| -> Vec<f64> { v.iter().step_by(stride).copied().collect() };
        let (mut r2, mut r3) = (sub(&reference[1]), sub(&reference[2]));
        r2.truncate(floors[1].len());
        r3.truncate(floors[2].len());
        let delay = tracking_delay(&desired, &measured, h, MAX_LAG)?;
        let ratios = [
            nrms_error(&measured, &desired)?,
            peak_error(&measured, &desired)?,
            nrms_error(&measured, &reference[0])?,
            peak_error(&measured, &reference[0])?,
            nrms_error(&floors[1], &r2)?,
            nrms_error(&floors[2], &r3)?,
            peak_error(&floors[1], &r2)?,
            peak_error(&floors[2], &r3)?,
        ];
        let mut j = [round_delay_ms(delay); 9];
        let mut raw = [delay * 1000.0; 9];
        for (i, r) in ratios.iter().enumerate() {
            j[i + 1] = round_percent(*r);
            raw[i + 1] = 100.0 * r;
        }
        Some(Criteria { j, raw })
    } else {
        None
    };
    // A loop that did not blow up but tracks worse than not moving at all (J2 > 100 %) is
    // unstable too (e.g. a compensator oscillating at its bound).
    let stable = criteria.is_some_and(|c| c.raw[1] <= UNSTABLE_TRACKING_PERCENT);
    Ok(RthsResult {
        case: input.case.number,
        criteria,
        max_force,
        stable,
        capacity_exceeded: max_force >= FORCE_CAPACITY,
        diverged_at,
        guard_trip: controller.guard_trip(),
        history: input.keep_history.then_some(RunHistory {
            h,
            desired,
            command: command_hist,
            measured,
            actuator_force: force_hist,
            floor_stride: stride,
            floors,
            reference,
        }),
    })
}

/// The loop with the sub-step algorithm (see the module docs of [`super`] for the mapping of
/// sub-steps onto controller samples). Returns the floors on the step grid and the divergence time.
#[allow(clippy::too_many_arguments)]
fn run_substep(
    input: &RthsInput,
    spec: &SubstepSpec,
    per_step: usize,
    ag: &[f64],
    controller: &mut super::controller::Controller,
    lab: &mut Lab,
    desired: &mut [f64],
    measured: &mut [f64],
    force_hist: &mut [f64],
    command_hist: &mut [f64],
    max_force: &mut f64,
) -> Result<([Vec<f64>; 3], Option<f64>)> {
    let h = SAMPLE_TIME;
    let n = desired.len();
    let case = &input.case;
    let (mn, cn, kn) = numerical_matrices(case, &Specimen::benchmark());
    let to_d = |m: Matrix3<f64>| DMatrix::from_fn(3, 3, |i, j| m[(i, j)]);
    let model = StructuralModel::new(to_d(mn), to_d(cn), to_d(kn), None)?;
    let settings = SubstepSettings {
        dt: spec.dt,
        beta: spec.beta,
        gamma: spec.gamma,
        substeps: spec.k_sub,
        coupling_dofs: vec![0],
        error_force: spec.error_force,
    };
    let mass_iota = case.mass_matrix() * influence();
    let load_at = |k: usize, out: &mut DVector<f64>| {
        let a = ag[k.min(ag.len() - 1)];
        for i in 0..3 {
            out[i] = -mass_iota[i] * a;
        }
    };
    let mut load = DVector::zeros(3);
    load_at(0, &mut load);
    let mut sc = SubstepController::new(&model, &settings, &load)?;
    let k_sub = spec.k_sub;
    let n_steps = (n - 1) / per_step + 1;
    let mut floors = [vec![0.0; n_steps], vec![0.0; n_steps], vec![0.0; n_steps]];
    let mut f_meas = vec![0.0; n];
    // Sub-steps issued so far; command signal between (s·Δτ, d_prev) and ((s+1)·Δτ, d_cur) for
    // the last issued sub-step s.
    let mut issued: usize = 0;
    let (mut d_prev, mut d_cur) = (0.0f64, 0.0f64);
    let mut steps_done = 0usize;
    // Time of sub-step boundary s in samples: s·per_step/k_sub.
    let boundary = |s: usize| s as f64 * per_step as f64 / k_sub as f64;
    for k in 0..n {
        // The command signal at t_k needs every sub-step s with s·Δτ < t_k issued.
        while boundary(issued) < k as f64 {
            let s = issued;
            if s > 0 {
                // Force at the end of sub-step s − 1: the latest sample at or before s·Δτ.
                let m = (s * per_step) / k_sub;
                sc.feedback(&[-f_meas[m]]);
                if s.is_multiple_of(k_sub) {
                    sc.finish_step();
                    steps_done += 1;
                    let u = &sc.state().u;
                    for i in 0..3 {
                        floors[i][steps_done] = u[i];
                    }
                    if !u.iter().all(|v| v.is_finite() && v.abs() <= DIVERGENCE_LIMIT) {
                        return Ok((floors, Some(k as f64 * h)));
                    }
                }
            }
            if s.is_multiple_of(k_sub) {
                load_at((s / k_sub + 1) * per_step, &mut load);
                sc.begin_step(&load);
            }
            d_prev = d_cur;
            d_cur = sc.next_command()[0];
            issued += 1;
        }
        // Linear command signal at t_k.
        let y_n = if issued == 0 {
            0.0
        } else {
            let (b0, b1) = (boundary(issued - 1), boundary(issued));
            d_prev + (k as f64 - b0) / (b1 - b0) * (d_cur - d_prev)
        };
        let (x, x_m, f_m, big_f) = lab.outputs(y_n);
        if !(x.is_finite() && x.abs() <= DIVERGENCE_LIMIT && y_n.is_finite()) {
            return Ok((floors, Some(k as f64 * h)));
        }
        *max_force = max_force.max(big_f);
        f_meas[k] = f_m;
        desired[k] = y_n;
        measured[k] = x_m;
        if !force_hist.is_empty() {
            force_hist[k] = big_f;
        }
        let u = controller.command(y_n, x_m);
        if !command_hist.is_empty() {
            command_hist[k] = u;
        }
        lab.advance(u);
    }
    // Steps whose end lies beyond the last sample are not completed; keep the grid consistent.
    let done = steps_done + 1;
    for f in floors.iter_mut() {
        f.truncate(done.min(n_steps));
    }
    Ok((floors, None))
}
