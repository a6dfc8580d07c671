//! One maRTHS run: the loop of the toolset's Simulink model at 1024 Hz, the evaluation J1–J10 of
//! `S5_Evaluation.m`, the realisability flag.

use super::data::{
    DOF_R2, DOF_R3, DOF_THETA, DOF_X1, DOF_X2, DOF_X3, Frame, InitialParameters, PARTITION_DOFS, Partition,
    PlantParameters, TOOLSET_DENSITY, VirtualFrame,
};
use super::mimo_arx::{MimoArx, MimoArxSpec};
use super::rodeac::{RlsAc, rodeac};
use super::structure::{FrameForce, NewmarkFrame, solve_ideal};
use crate::benchmark::rths::GroundRecord;
use crate::compensate::{ArxPhaseLagSpec, PhaseLagCompensator, Ramp};
use crate::error::{Error, Result};
use crate::model::StructuralModel;
use crate::substructure::{ErrorForceSpec, SubstepController, SubstepSettings};
use crate::transfer::kinematics::Coupler;
use crate::transfer::mimo::{MimoRk4, MimoStateSpace};
use nalgebra::DVector;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use std::sync::Arc;

/// The toolset's rate, 1024 Hz.
pub const SAMPLE_TIME: f64 = 1.0 / 1024.0;
/// σ of the displacement-sensor noise \[mm\]: Band-Limited White Noise of power 1.5e-7 at `h`.
pub const NOISE_STD_MM: f64 = 0.012393546707863733;
/// Command limit \[V\] (the realisability flag).
pub const COMMAND_LIMIT_V: f64 = 3.8;
/// Volts of a command: `(u/c)/g − o/g` per actuator (`S1_Input_Data.m`).
const V2D_GAIN: [f64; 2] = [7.4921, 7.3907];
const V2D_CONST: [f64; 2] = [0.0092, -0.0059];
const CORRECTION_GAIN: [f64; 2] = [1.053, 1.055];
/// A run stops as diverged when a frame displacement leaves this \[m\] (the specimen's stroke is
/// centimetres) or a value is not finite.
pub const DIVERGENCE_LIMIT: f64 = 1.0;
/// Lags searched by J1's correlation: ±this many samples (±250 ms).
pub const MAX_LAG: usize = 256;

/// The command in volts of actuator `a` for `u` \[mm\].
pub fn volts(a: usize, u_mm: f64) -> f64 {
    u_mm / CORRECTION_GAIN[a] / V2D_GAIN[a] - V2D_CONST[a] / V2D_GAIN[a]
}

/// What drives the actuators.
#[derive(Debug, Clone, PartialEq)]
pub enum ControllerKind {
    /// `u = x_t`.
    None,
    /// The toolset's RoDeAC.
    Rodeac,
    /// The project's ARX phase-lag compensator, per actuator after the kinematics.
    Arx(ArxPhaseLagSpec),
    /// The ARX identification over both actuators ([`MimoArx`]).
    ArxMimo(MimoArxSpec),
}

impl ControllerKind {
    pub fn parse(s: &str) -> Result<Self> {
        Ok(match s {
            "none" => Self::None,
            "rodeac" => Self::Rodeac,
            "arx" => Self::Arx(arx_default()),
            "arx_mimo" => Self::ArxMimo(MimoArxSpec::default()),
            _ => {
                return Err(Error::invalid(
                    "controller",
                    format!("unknown controller `{s}` (none, rodeac, arx, arx_mimo)"),
                ));
            }
        })
    }
    pub fn name(&self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Rodeac => "rodeac",
            Self::Arx(_) => "arx",
            Self::ArxMimo(_) => "arx_mimo",
        }
    }
}

/// The ARX compensator's setting on this benchmark (docs/benchmark.md): `k_lag` about the
/// actuators' lag at the frame's first frequency, velocities over 8 samples.
pub fn arx_default() -> ArxPhaseLagSpec {
    ArxPhaseLagSpec {
        lambda: 0.999,
        max_lead: Some(600.0),
        ..ArxPhaseLagSpec::new(16).with_span(8)
    }
}

/// What sits between the commands and the specimen.
#[derive(Debug, Clone, PartialEq)]
pub enum Transfer {
    /// A 2×2 plant (commands \[mm\] → strokes \[mm\], RK4 at `h`; a transfer-function matrix
    /// through [`crate::transfer::mimo::TransferMatrix::to_state_space`]) with sensor noise
    /// (`Some(seed)`) or without.
    Plant {
        plant: MimoStateSpace,
        noise_seed: Option<u64>,
    },
    /// Measured = target in the same sample, no noise: the coupled step solved implicitly.
    Ideal,
}

/// How the numerical substructure is integrated.
#[derive(Debug, Clone, PartialEq)]
pub enum Algorithm {
    /// The toolset's loop: one Newmark step per sample with the force measured in that sample.
    Benchmark,
    /// The project's sub-step algorithm (docs/benchmark.md, "maRTHS with the sub-step
    /// algorithm").
    Substep(SubstepSpec),
}

/// The sub-step algorithm on this benchmark: Newmark (average acceleration) at
/// `Δt = samples_per_step · h`, `k_sub` sub-steps, error-force compensation; the coupling DOFs
/// `x₂₇, θ₂₁, θ₂₉` (the last receives the virtual frame's moment but is not commanded).
#[derive(Debug, Clone, PartialEq)]
pub struct SubstepSpec {
    pub samples_per_step: usize,
    pub k_sub: usize,
    pub error_force: ErrorForceSpec,
}

impl Default for SubstepSpec {
    /// Δt = 2 samples (1/512 s), `k_sub = 2` (Δτ = one sample), P = 1.
    fn default() -> Self {
        Self {
            samples_per_step: 2,
            k_sub: 2,
            error_force: ErrorForceSpec::Pid { p: 1.0, i: 0.0, d: 0.0 },
        }
    }
}

impl SubstepSpec {
    fn validate(&self) -> Result<()> {
        if !(1..=1024).contains(&self.samples_per_step) {
            return Err(Error::invalid(
                "substep.samples_per_step",
                format!("must be in 1..=1024, got {}", self.samples_per_step),
            ));
        }
        if !(1..=1000).contains(&self.k_sub) {
            return Err(Error::invalid(
                "substep.k_sub",
                format!("must be in 1..=1000, got {}", self.k_sub),
            ));
        }
        self.error_force.validate()
    }
}

/// Everything one run needs.
#[derive(Debug, Clone)]
pub struct MarthsInput {
    pub record: Arc<GroundRecord>,
    pub intensity: f64,
    pub transfer: Transfer,
    pub controller: ControllerKind,
    /// The coupler (default: the benchmark's, with the inverse as the toolset codes it).
    pub coupler: Coupler,
    /// Density of the partition removed from the frame \[kg/m³\] (default: the toolset's
    /// 785e3, which removes 902.5 kg from `x₂₇`; steel is 7850).
    pub partition_density: f64,
    pub algorithm: Algorithm,
    pub keep_history: bool,
}

impl MarthsInput {
    pub fn new(record: Arc<GroundRecord>) -> Self {
        Self {
            record,
            intensity: 0.4,
            transfer: Transfer::Plant {
                plant: PlantParameters::nominal()
                    .transfer_matrix()
                    .expect("the nominal plant is valid")
                    .to_state_space(),
                noise_seed: Some(123),
            },
            controller: ControllerKind::Rodeac,
            coupler: Coupler::marths()
                .toolset_inverse()
                .expect("the benchmark's coupler is symmetric"),
            partition_density: TOOLSET_DENSITY,
            algorithm: Algorithm::Benchmark,
            keep_history: false,
        }
    }
    /// Samples `0 ..= floor(t_end/h)`.
    pub fn samples(&self) -> usize {
        (self.record.duration() / SAMPLE_TIME).floor() as usize + 1
    }
    fn validate(&self) -> Result<()> {
        if !(self.intensity.is_finite() && self.intensity > 0.0 && self.intensity <= 10.0) {
            return Err(Error::invalid(
                "intensity",
                format!("must be in (0, 10] (a scale of the record), got {}", self.intensity),
            ));
        }
        if !(self.partition_density.is_finite()
            && self.partition_density > 0.0
            && self.partition_density <= TOOLSET_DENSITY)
        {
            return Err(Error::invalid(
                "partition_density",
                format!(
                    "must be in (0, {TOOLSET_DENSITY}] kg/m³, got {}",
                    self.partition_density
                ),
            ));
        }
        if let Transfer::Plant { plant, .. } = &self.transfer
            && (plant.outputs() != 2 || plant.inputs() != 2)
        {
            return Err(Error::invalid(
                "plant",
                format!(
                    "must be 2×2 (two actuators, two commands), got {}×{}",
                    plant.outputs(),
                    plant.inputs()
                ),
            ));
        }
        if let Algorithm::Substep(spec) = &self.algorithm {
            spec.validate()?;
            if self.transfer == Transfer::Ideal {
                return Err(Error::invalid(
                    "transfer",
                    "the ideal transfer system solves the toolset's step implicitly: not with the sub-step algorithm",
                ));
            }
        }
        Ok(())
    }
}

/// J1–J10 in the toolset's order: J1–J4 per actuator \[ms, %, %, ms\], J5–J7 and J9 per frame
/// component `(x, θ)` [%], J8 and J10 `(x, θ)` of storeys 2 and 3 [%].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Criteria {
    pub j1: [f64; 2],
    pub j2: [f64; 2],
    pub j3: [f64; 2],
    pub j4: [f64; 2],
    pub j5: [f64; 2],
    pub j6: [f64; 2],
    pub j7: [f64; 2],
    pub j8: [f64; 4],
    pub j9: [f64; 2],
    pub j10: [f64; 4],
}

impl Criteria {
    /// `("J1", values) … ("J10", values)`.
    pub fn lists(&self) -> [(&'static str, Vec<f64>); 10] {
        [
            ("J1", self.j1.to_vec()),
            ("J2", self.j2.to_vec()),
            ("J3", self.j3.to_vec()),
            ("J4", self.j4.to_vec()),
            ("J5", self.j5.to_vec()),
            ("J6", self.j6.to_vec()),
            ("J7", self.j7.to_vec()),
            ("J8", self.j8.to_vec()),
            ("J9", self.j9.to_vec()),
            ("J10", self.j10.to_vec()),
        ]
    }
    /// Every value through `f` (rounding, averaging helpers).
    pub fn map(&self, f: impl Fn(f64) -> f64) -> Self {
        Self {
            j1: self.j1.map(&f),
            j2: self.j2.map(&f),
            j3: self.j3.map(&f),
            j4: self.j4.map(&f),
            j5: self.j5.map(&f),
            j6: self.j6.map(&f),
            j7: self.j7.map(&f),
            j8: self.j8.map(&f),
            j9: self.j9.map(&f),
            j10: self.j10.map(&f),
        }
    }
    /// The mean of several (the toolset's average over uncertain trials).
    pub fn mean(all: &[Criteria]) -> Option<Self> {
        let n = all.len() as f64;
        let first = *all.first()?;
        let mut m = first.map(|_| 0.0);
        for c in all {
            let add = |a: &mut [f64], b: &[f64]| a.iter_mut().zip(b).for_each(|(x, y)| *x += y / n);
            add(&mut m.j1, &c.j1);
            add(&mut m.j2, &c.j2);
            add(&mut m.j3, &c.j3);
            add(&mut m.j4, &c.j4);
            add(&mut m.j5, &c.j5);
            add(&mut m.j6, &c.j6);
            add(&mut m.j7, &c.j7);
            add(&mut m.j8, &c.j8);
            add(&mut m.j9, &c.j9);
            add(&mut m.j10, &c.j10);
        }
        Some(m)
    }
}

/// MATLAB's `round(x, 1)` (half away from zero).
pub fn round1(x: f64) -> f64 {
    (x * 10.0).round() / 10.0
}

/// The logged signals of a run, per sample (the toolset's `To Workspace` blocks).
#[derive(Debug, Clone, Default)]
pub struct History {
    pub target: [Vec<f64>; 2],
    pub measured: [Vec<f64>; 2],
    pub command: [Vec<f64>; 2],
    /// Frame `(x [mm], θ [rad])` from the measured strokes, of the numerical substructure and of
    /// the reference.
    pub frame_measured: [Vec<f64>; 2],
    pub frame_numerical: [Vec<f64>; 2],
    pub frame_reference: [Vec<f64>; 2],
    /// Storeys 2 and 3, `[x₂, θ₂, x₃, θ₃]` [m, rad], numerical and reference.
    pub storeys_numerical: [Vec<f64>; 4],
    pub storeys_reference: [Vec<f64>; 4],
}

impl History {
    fn with_capacity(n: usize) -> Self {
        let v = || Vec::with_capacity(n);
        Self {
            target: [v(), v()],
            measured: [v(), v()],
            command: [v(), v()],
            frame_measured: [v(), v()],
            frame_numerical: [v(), v()],
            frame_reference: [v(), v()],
            storeys_numerical: [v(), v(), v(), v()],
            storeys_reference: [v(), v(), v(), v()],
        }
    }
    pub fn len(&self) -> usize {
        self.target[0].len()
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The reference structure's logged signals (independent of the plant and controller).
#[derive(Debug, Clone)]
pub struct Reference {
    pub frame: [Vec<f64>; 2],
    pub storeys: [Vec<f64>; 4],
}

/// The full frame integrated like the toolset's reference block, for `input`'s record and
/// intensity.
pub fn reference(input: &MarthsInput) -> Result<Reference> {
    let frame = Frame::reference();
    let mut s = NewmarkFrame::new(&frame.k, &frame.m, &frame.c, &frame.influence, SAMPLE_TIME)?;
    let n = input.samples();
    let mut ag = Vec::with_capacity(n);
    input
        .record
        .sample_sorted((0..n).map(|k| k as f64 * SAMPLE_TIME), input.intensity, &mut ag);
    let v = || Vec::with_capacity(n);
    let mut r = Reference {
        frame: [v(), v()],
        storeys: [v(), v(), v(), v()],
    };
    for &a in &ag {
        s.step(a, [0.0; 3]);
        r.frame[0].push(1000.0 * s.u[DOF_X1]);
        r.frame[1].push(-s.u[DOF_THETA]);
        for (k, d) in [DOF_X2, DOF_R2, DOF_X3, DOF_R3].into_iter().enumerate() {
            r.storeys[k].push(s.u[d]);
        }
    }
    Ok(r)
}

/// The numerical substructure of `build_numerical.m`: the frame less the ideal partition (mass
/// only at `x₂₇`), the partition's members of density `density` \[kg/m³\] (the toolset's
/// [`TOOLSET_DENSITY`]).
pub fn numerical_matrices(density: f64) -> Frame {
    let mut f = Frame::reference();
    let p = Partition::with_density(density);
    for (i, &di) in PARTITION_DOFS.iter().enumerate() {
        for (j, &dj) in PARTITION_DOFS.iter().enumerate() {
            f.k[(di, dj)] -= p.k[i][j];
            f.c[(di, dj)] -= p.c[i][j];
        }
    }
    f.m[(DOF_X1, DOF_X1)] -= p.m[0];
    f
}

/// Outcome of one run.
#[derive(Debug, Clone)]
pub struct MarthsResult {
    /// `None` if the run diverged.
    pub criteria: Option<Criteria>,
    pub diverged: bool,
    /// Sample at which a diverged run stopped, and why.
    pub stopped_at: Option<usize>,
    pub stop_reason: Option<String>,
    /// Peak command per actuator \[V\].
    pub peak_volts: [f64; 2],
    /// The toolset's flag: both actuators above [`COMMAND_LIMIT_V`].
    pub realizable: bool,
    /// An ARX compensator's guard or supervisor backed off (the test went on uncompensated on
    /// that actuator).
    pub backed_off: bool,
    /// RoDeAC's weights `[θ₁, θ₂]` at the start and after every second (empty for the other
    /// controllers).
    pub rodeac_weights: Vec<[[f64; 4]; 2]>,
    pub history: Option<History>,
}

enum Drive {
    None,
    Rodeac(Box<[RlsAc; 2]>),
    Arx(Vec<Box<dyn PhaseLagCompensator>>, Ramp),
    Mimo(Box<MimoArx>, Ramp),
}

/// The lab side of one sample: the plant (or nothing: ideal), sensors, the coupler, the virtual
/// frame's force and the controller.
struct Lab {
    plant: Option<MimoRk4>,
    noise: Option<ChaCha8Rng>,
    coupler: Coupler,
    feedback: FrameForce,
    drive: Drive,
    command: [f64; 2],
    peak_volts: [f64; 2],
    weights: Vec<[[f64; 4]; 2]>,
}

impl Lab {
    fn new(input: &MarthsInput) -> Result<Self> {
        let h = SAMPLE_TIME;
        let (plant, noise) = match &input.transfer {
            Transfer::Plant { plant, noise_seed } => (Some(plant.rk4(h)?), noise_seed.map(ChaCha8Rng::seed_from_u64)),
            Transfer::Ideal => (None, None),
        };
        let drive = match &input.controller {
            ControllerKind::None => Drive::None,
            ControllerKind::Rodeac => Drive::Rodeac(Box::new(rodeac(&InitialParameters::toolset()))),
            ControllerKind::Arx(spec) => {
                let c = (0..2)
                    .map(|_| spec.build().map(|c| Box::new(c) as Box<dyn PhaseLagCompensator>))
                    .collect::<Result<Vec<_>>>()?;
                Drive::Arx(c, Ramp::new(0, 1024))
            }
            ControllerKind::ArxMimo(spec) => Drive::Mimo(Box::new(MimoArx::new(*spec)?), Ramp::new(0, 1024)),
        };
        Ok(Self {
            plant,
            noise,
            coupler: input.coupler.clone(),
            feedback: FrameForce::new(&VirtualFrame::toolset(), h),
            drive,
            command: [0.0; 2],
            peak_volts: [0.0; 2],
            weights: Vec::with_capacity(input.samples() / 1024 + 2),
        })
    }

    /// The measured strokes \[mm\] of this sample (plant output plus noise), the frame motion
    /// `(x, θ)` from them and the virtual frame's force.
    fn measure(&mut self) -> Result<([f64; 2], [f64; 2], [f64; 3])> {
        let mut measured = [0.0; 2];
        if let Some(p) = &self.plant {
            p.output(&self.command, &mut measured);
        }
        if let Some(rng) = &mut self.noise {
            // The toolset gives both sensor blocks the same seed: one draw for both.
            let e: f64 = rng.sample(StandardNormal);
            measured.iter_mut().for_each(|m| *m += NOISE_STD_MM * e);
        }
        let q = self.coupler.dofs([measured[0] / 1000.0, measured[1] / 1000.0])?;
        let f = self.feedback.force(q);
        Ok((measured, q, f))
    }

    /// The controller's commands for the target strokes, then the plant's step.
    fn drive(&mut self, k: usize, target: [f64; 2], measured: [f64; 2]) {
        match &mut self.drive {
            Drive::None => self.command = target,
            Drive::Rodeac(c) => {
                if k.is_multiple_of(1024) && self.weights.len() < self.weights.capacity() {
                    self.weights.push([c[0].theta, c[1].theta]);
                }
                for i in 0..2 {
                    self.command[i] = c[i].command(target[i], measured[i]);
                }
            }
            Drive::Arx(c, ramp) => {
                let r = ramp.value(k);
                for i in 0..2 {
                    self.command[i] = target[i] + c[i].correction(target[i], measured[i], r);
                }
            }
            Drive::Mimo(c, ramp) => {
                let du = c.corrections(target, measured, ramp.value(k));
                self.command = [target[0] + du[0], target[1] + du[1]];
            }
        }
        for i in 0..2 {
            self.peak_volts[i] = self.peak_volts[i].max(volts(i, self.command[i]).abs());
        }
        if let Some(p) = &mut self.plant {
            p.step(&self.command, &mut [0.0; 2]);
        }
    }

    fn backed_off(&self) -> bool {
        match &self.drive {
            Drive::Arx(c, _) => c.iter().any(|c| c.trip().is_some()),
            _ => false,
        }
    }

    /// A command beyond 1000 × the divergence limit in mm (or not finite).
    fn runaway(&self) -> bool {
        !self.command.iter().all(|c| c.abs() < 1e3 * DIVERGENCE_LIMIT)
    }
}

fn runaway(k: usize) -> String {
    format!(
        "the response ran away at t = {:.4} s (a displacement beyond ±{DIVERGENCE_LIMIT} m or a command beyond ±{} mm)",
        k as f64 * SAMPLE_TIME,
        1e3 * DIVERGENCE_LIMIT
    )
}

/// Measured strokes no coupler position gives: the test has left the coupler's range.
fn left_the_coupler(k: usize, e: &Error) -> String {
    format!(
        "the measured strokes left the coupler's range at t = {:.4} s ({e})",
        k as f64 * SAMPLE_TIME
    )
}

/// `Some(x)` if `x` is finite and inside ±[`DIVERGENCE_LIMIT`].
fn within(x: f64) -> Option<f64> {
    (x.abs() < DIVERGENCE_LIMIT).then_some(x)
}

fn record_sample(
    hist: &mut History,
    target: [f64; 2],
    measured: [f64; 2],
    command: [f64; 2],
    q: [f64; 2],
    numerical: [f64; 2],
) {
    for i in 0..2 {
        hist.target[i].push(target[i]);
        hist.measured[i].push(measured[i]);
        hist.command[i].push(command[i]);
    }
    hist.frame_measured[0].push(1000.0 * q[0]);
    hist.frame_measured[1].push(q[1]);
    hist.frame_numerical[0].push(1000.0 * numerical[0]);
    hist.frame_numerical[1].push(numerical[1]);
}

/// Run `input` against `reference` (from [`reference()`] with the same record and intensity).
pub fn run(input: &MarthsInput, reference: &Reference) -> Result<MarthsResult> {
    input.validate()?;
    let n = input.samples();
    if reference.frame[0].len() != n {
        return Err(Error::invalid(
            "marths.reference",
            format!("has {} samples, the run {n}", reference.frame[0].len()),
        ));
    }
    let h = SAMPLE_TIME;
    let mut ag = Vec::with_capacity(n);
    input
        .record
        .sample_sorted((0..n).map(|k| k as f64 * h), input.intensity, &mut ag);
    check_coupler(&input.coupler, reference)?;
    let mut lab = Lab::new(input)?;
    let mut hist = History::with_capacity(n);
    let (stopped_at, storey_reference) = match &input.algorithm {
        Algorithm::Benchmark => (run_benchmark(input.partition_density, &ag, &mut lab, &mut hist)?, None),
        Algorithm::Substep(spec) => {
            let stopped = run_substep(input.partition_density, spec, &ag, &mut lab, &mut hist)?;
            // The storeys exist at the step ends: the reference there.
            let every = spec.samples_per_step;
            let steps = hist.storeys_numerical[0].len();
            let r: [Vec<f64>; 4] =
                std::array::from_fn(|i| (0..steps).map(|j| reference.storeys[i][j * every]).collect());
            (stopped, Some(r))
        }
    };
    let (stopped_at, stop_reason) = match stopped_at {
        Some((k, why)) => (Some(k), Some(why)),
        None => (None, None),
    };
    let diverged = stopped_at.is_some();
    let criteria = if diverged {
        None
    } else {
        let r = Reference {
            frame: reference.frame.clone(),
            storeys: storey_reference.clone().unwrap_or_else(|| reference.storeys.clone()),
        };
        Some(evaluate(&hist, &r)?)
    };
    let peak_volts = lab.peak_volts;
    Ok(MarthsResult {
        criteria,
        diverged,
        stopped_at,
        stop_reason,
        peak_volts,
        realizable: !(peak_volts[0] > COMMAND_LIMIT_V && peak_volts[1] > COMMAND_LIMIT_V),
        backed_off: lab.backed_off(),
        rodeac_weights: std::mem::take(&mut lab.weights),
        history: input.keep_history.then(|| {
            let mut h = hist;
            h.frame_reference = reference.frame.clone();
            h.storeys_reference = storey_reference.unwrap_or_else(|| reference.storeys.clone());
            h
        }),
    })
}

/// The coupler must move the node through the reference's motion and back: every corner of
/// `±x_peak × ±θ_peak` (and 2× beyond, for the tracking errors of a test) must map to strokes
/// whose inverse returns it.
fn check_coupler(coupler: &Coupler, reference: &Reference) -> Result<()> {
    let peak = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let (xp, tp) = (
        2.0 * peak(&reference.frame[0]) / 1000.0,
        2.0 * peak(&reference.frame[1]),
    );
    // The actuators must control θ over the whole range: the Jacobian keeps its sign.
    let det = |theta: f64| {
        let j = coupler.jacobian([0.0, theta]);
        j[0][0] * j[1][1] - j[0][1] * j[1][0]
    };
    let d0 = det(0.0);
    for i in 0..=40 {
        let theta = tp * (i as f64 / 20.0 - 1.0);
        let d = det(theta);
        if d * d0 <= 0.0 || d.abs() < 1e-3 * d0.abs() {
            return Err(Error::invalid(
                "coupler",
                format!(
                    "cannot reach the target: the actuators lose control of the rotation at θ = {theta:.4e} rad \
                     (singular kinematics within twice the reference's peak rotation, {tp:.4e} rad)"
                ),
            ));
        }
    }
    for sx in [-1.0, 0.0, 1.0] {
        for st in [-1.0, 0.0, 1.0] {
            let q = [sx * xp, st * tp];
            let back = coupler.dofs(coupler.strokes(q)).map_err(|e| {
                Error::invalid(
                    "coupler",
                    format!(
                        "cannot reach the target x = {:.4e} m, θ = {:.4e} rad (twice the reference's peak): {e}",
                        q[0], q[1]
                    ),
                )
            })?;
            // 1e-3: the toolset's inverse is off by O(θ³) (2e-5 of the peak here), a wrong branch by far more.
            if (back[0] - q[0]).abs() > 1e-3 * xp.max(1e-6) || (back[1] - q[1]).abs() > 1e-3 * tp.max(1e-6) {
                return Err(Error::invalid(
                    "coupler",
                    format!(
                        "cannot reach the target x = {:.4e} m, θ = {:.4e} rad: its inverse returns x = {:.4e} m, θ = {:.4e} rad",
                        q[0], q[1], back[0], back[1]
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// The toolset's loop (module docs); returns the sample a diverging run stopped at.
fn run_benchmark(density: f64, ag: &[f64], lab: &mut Lab, hist: &mut History) -> Result<Option<(usize, String)>> {
    let numerical = numerical_matrices(density);
    let mut structure = NewmarkFrame::new(
        &numerical.k,
        &numerical.m,
        &numerical.c,
        &numerical.influence,
        SAMPLE_TIME,
    )?;
    for (k, &a) in ag.iter().enumerate() {
        let (measured, q, target) = if lab.plant.is_some() {
            let (measured, q, f) = match lab.measure() {
                Ok(m) => m,
                Err(e) => return Ok(Some((k, left_the_coupler(k, &e)))),
            };
            structure.step(a, f);
            let target = [structure.u[DOF_X1], -structure.u[DOF_THETA]];
            (measured, q, target)
        } else {
            structure.predict(a);
            let q = solve_ideal(&mut structure, &lab.feedback)?;
            let f = lab.feedback.force(q);
            structure.correct(f);
            structure.commit();
            let s = lab.coupler.strokes(q);
            ([1000.0 * s[0], 1000.0 * s[1]], q, q)
        };
        let s = lab.coupler.strokes(target);
        let target_mm = [1000.0 * s[0], 1000.0 * s[1]];
        lab.drive(k, target_mm, measured);
        record_sample(hist, target_mm, measured, lab.command, q, target);
        for (j, d) in [DOF_X2, DOF_R2, DOF_X3, DOF_R3].into_iter().enumerate() {
            hist.storeys_numerical[j].push(structure.u[d]);
        }
        if within(structure.u[DOF_X1]).is_none() || lab.runaway() {
            return Ok(Some((k, runaway(k))));
        }
    }
    Ok(None)
}

/// The numerical substructure by the sub-step algorithm, mapped onto the samples as in the RTHS
/// benchmark (docs/benchmark.md): the command signal is linear between the sub-step commands
/// and sampled at `t_k` as the target; the force fed back at the end of sub-step `s` is the
/// latest sample at or before `s Δτ`; a sub-step is computed when the target first needs it.
fn run_substep(
    density: f64,
    spec: &SubstepSpec,
    ag: &[f64],
    lab: &mut Lab,
    hist: &mut History,
) -> Result<Option<(usize, String)>> {
    let n = ag.len();
    let numerical = numerical_matrices(density);
    let influence = DVector::from_column_slice(&numerical.influence);
    let mass_iota = &numerical.m * &influence;
    let model = StructuralModel::with_massless_dofs(
        numerical.m.clone(),
        numerical.c.clone(),
        numerical.k.clone(),
        Some(influence),
    )?;
    let (per_step, k_sub) = (spec.samples_per_step, spec.k_sub);
    let settings = SubstepSettings {
        dt: per_step as f64 * SAMPLE_TIME,
        beta: 0.25,
        gamma: 0.5,
        substeps: k_sub,
        coupling_dofs: vec![DOF_X1, DOF_THETA, super::data::DOF_THETA29],
        error_force: spec.error_force,
    };
    let load_at = |k: usize, out: &mut DVector<f64>| {
        let a = ag[k.min(n - 1)];
        for (o, m) in out.iter_mut().zip(mass_iota.iter()) {
            *o = -m * a;
        }
    };
    let mut load = DVector::zeros(super::data::N_DOF);
    load_at(0, &mut load);
    let mut sc = SubstepController::new(&model, &settings, &load)?;
    let mut forces = vec![[0.0; 3]; n];
    let mut issued = 0usize;
    let (mut d_prev, mut d_cur) = ([0.0; 2], [0.0; 2]);
    let boundary = |s: usize| s as f64 * per_step as f64 / k_sub as f64;
    for k in 0..n {
        while boundary(issued) < k as f64 {
            let s = issued;
            if s > 0 {
                let f = forces[(s * per_step) / k_sub];
                // The force on the numerical substructure (the toolset subtracts F).
                sc.feedback(&[-f[0], -f[1], -f[2]]);
                if s.is_multiple_of(k_sub) {
                    sc.finish_step();
                    let u = &sc.state().u;
                    for (j, d) in [DOF_X2, DOF_R2, DOF_X3, DOF_R3].into_iter().enumerate() {
                        hist.storeys_numerical[j].push(u[d]);
                    }
                    if !u.iter().all(|v| v.is_finite() && v.abs() <= DIVERGENCE_LIMIT) {
                        return Ok(Some((k, runaway(k))));
                    }
                }
            } else {
                for j in 0..4 {
                    hist.storeys_numerical[j].push(0.0);
                }
            }
            if s.is_multiple_of(k_sub) {
                load_at((s / k_sub + 1) * per_step, &mut load);
                sc.begin_step(&load);
            }
            d_prev = d_cur;
            let c = sc.next_command();
            d_cur = [c[0], -c[1]];
            issued += 1;
        }
        let q_target = if issued == 0 {
            [0.0; 2]
        } else {
            let (b0, b1) = (boundary(issued - 1), boundary(issued));
            let r = (k as f64 - b0) / (b1 - b0);
            [
                d_prev[0] + r * (d_cur[0] - d_prev[0]),
                d_prev[1] + r * (d_cur[1] - d_prev[1]),
            ]
        };
        let s = lab.coupler.strokes(q_target);
        let target_mm = [1000.0 * s[0], 1000.0 * s[1]];
        let (measured, q, f) = match lab.measure() {
            Ok(m) => m,
            Err(e) => return Ok(Some((k, left_the_coupler(k, &e)))),
        };
        forces[k] = f;
        lab.drive(k, target_mm, measured);
        record_sample(hist, target_mm, measured, lab.command, q, q_target);
        if within(q_target[0]).is_none() || lab.runaway() {
            return Ok(Some((k, runaway(k))));
        }
    }
    // Steps whose end lies beyond the last sample are not complete.
    let complete = (n - 1) / per_step + 1;
    for v in hist.storeys_numerical.iter_mut() {
        v.truncate(complete);
    }
    Ok(None)
}

/// MATLAB's `finddelay(x, y)` over lags `±max_lag`: the lag `d` maximising
/// `|Σ x(n) y(n + d)|` (positive when `y` lags `x`); ties go to the smallest `|d|`, positive
/// first. 0 if either signal is all zero.
pub fn find_delay(x: &[f64], y: &[f64], max_lag: usize) -> isize {
    let n = x.len().min(y.len());
    if x[..n].iter().all(|v| *v == 0.0) || y[..n].iter().all(|v| *v == 0.0) {
        return 0;
    }
    let corr = |d: isize| -> f64 {
        let (xs, ys) = if d >= 0 {
            let d = d as usize;
            (&x[..n.saturating_sub(d)], &y[d.min(n)..n])
        } else {
            let d = (-d) as usize;
            (&x[d.min(n)..n], &y[..n.saturating_sub(d)])
        };
        xs.iter().zip(ys).map(|(a, b)| a * b).sum::<f64>().abs()
    };
    let mut best = (0isize, corr(0));
    let max_lag = max_lag.min(n.saturating_sub(1)) as isize;
    for m in 1..=max_lag {
        for d in [m, -m] {
            let c = corr(d);
            if c > best.1 {
                best = (d, c);
            }
        }
    }
    best.0
}

fn nrms(x: &[f64], r: &[f64]) -> f64 {
    100.0 * crate::analysis::metrics::nrms_error(x, r).unwrap_or(f64::NAN)
}
fn peak(x: &[f64], r: &[f64]) -> f64 {
    100.0 * crate::analysis::metrics::peak_error(x, r).unwrap_or(f64::NAN)
}

/// J1–J10 of a complete history against the reference, as `S5_Evaluation.m` codes them.
pub fn evaluate(h: &History, reference: &Reference) -> Result<Criteria> {
    let delay = |a: usize| find_delay(&h.target[a], &h.measured[a], MAX_LAG) as f64 * SAMPLE_TIME * 1000.0;
    let j1 = [delay(0), delay(1)];
    let per = |f: &dyn Fn(&[f64], &[f64]) -> f64, x: &[Vec<f64>], r: &[Vec<f64>]| -> [f64; 2] {
        [f(&x[0], &r[0]), f(&x[1], &r[1])]
    };
    let per4 = |f: &dyn Fn(&[f64], &[f64]) -> f64| -> [f64; 4] {
        std::array::from_fn(|i| f(&h.storeys_numerical[i], &reference.storeys[i]))
    };
    Ok(Criteria {
        j1,
        j2: per(&nrms, &h.measured, &h.target),
        j3: per(&peak, &h.measured, &h.target),
        j4: j1,
        j5: per(&nrms, &h.frame_measured, &h.frame_numerical),
        j6: per(&peak, &h.frame_measured, &h.frame_numerical),
        j7: per(&nrms, &h.frame_measured, &reference.frame),
        j8: per4(&nrms),
        j9: per(&peak, &h.frame_measured, &reference.frame),
        j10: per4(&peak),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn find_delay_finds_a_shift_either_way() {
        let x: Vec<f64> = (0..500)
            .map(|k| (k as f64 * 0.05).sin() * (k as f64 * 0.013).cos())
            .collect();
        let mut y = vec![0.0; 500];
        y[7..].copy_from_slice(&x[..493]);
        assert_eq!(find_delay(&x, &y, 50), 7);
        assert_eq!(find_delay(&y, &x, 50), -7);
        assert_eq!(find_delay(&x, &x, 50), 0);
        assert_eq!(find_delay(&x, &vec![0.0; 500], 50), 0);
    }
}
