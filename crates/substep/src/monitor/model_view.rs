//! The model view of the stability indicator (docs/theory.md §15.2): the specimen's stiffness
//! and damping and the transfer system's lag identified on-line from the step data, and the
//! spectral radius of the sub-step algorithm's amplification matrix for those values.

use crate::analysis::StepMap;
use crate::error::{Error, Result};
use crate::io::SubstructureDefinition;
use crate::model::StructuralModel;
use crate::specimen::SpecimenSpec;
use crate::substructure::ErrorForceSpec;
use crate::transfer::{ActuatorSpec, Dynamics};

/// Exponentially weighted least squares with forgetting `λ`: the RLS of [`crate::ident`]
/// started with an infinite covariance (no prior, so the result does not depend on the units
/// of the regressors), kept as the normal equations of at most two parameters.
#[derive(Debug, Clone, Copy, Default)]
struct Ewls2 {
    s11: f64,
    s12: f64,
    s22: f64,
    b1: f64,
    b2: f64,
}

impl Ewls2 {
    fn update(&mut self, lambda: f64, p1: f64, p2: f64, y: f64) {
        self.s11 = lambda * self.s11 + p1 * p1;
        self.s12 = lambda * self.s12 + p1 * p2;
        self.s22 = lambda * self.s22 + p2 * p2;
        self.b1 = lambda * self.b1 + p1 * y;
        self.b2 = lambda * self.b2 + p2 * y;
    }
    /// `(θ1, θ2)` of `y ≈ θ1 p1 + θ2 p2`; `None` while the data do not determine both (no or
    /// collinear excitation).
    fn solve2(&self) -> Option<(f64, f64)> {
        let det = self.s11 * self.s22 - self.s12 * self.s12;
        if det.is_nan() || det <= 1e-9 * self.s11 * self.s22 {
            return None;
        }
        Some((
            (self.s22 * self.b1 - self.s12 * self.b2) / det,
            (self.s11 * self.b2 - self.s12 * self.b1) / det,
        ))
    }
    /// `θ1` of `y ≈ θ1 p1` (uses `s11`, `b1` only).
    fn solve1(&self) -> Option<f64> {
        (self.s11 > 0.0).then(|| self.b1 / self.s11)
    }
}

/// On-line identification per coupling DOF, from one sample per step: the restoring force
/// `r = k x + c ẋ` of the specimen and the lag `τ` of the measured displacement behind the
/// command, `d − x ≈ τ ḋ` (first order in `τ`). Velocities are central differences, so the
/// sample of step `i` is used when step `i + 1` arrives. [`Self::push`] does not allocate.
#[derive(Debug, Clone)]
pub struct Identification {
    dt: f64,
    lambda: f64,
    /// Samples `i − 1`, `i` per DOF: restoring force, command, measured displacement.
    hist: Vec<[[f64; 3]; 2]>,
    samples: usize,
    kc: Vec<Ewls2>,
    lag: Vec<Ewls2>,
    k: Vec<f64>,
    c: Vec<f64>,
    tau: Vec<f64>,
}

impl Identification {
    /// `n_c` DOFs, step `dt` \[s\], memory of about `memory` steps (`λ = 1 − 1/memory`).
    pub fn new(n_c: usize, dt: f64, memory: usize) -> Self {
        Self {
            dt,
            lambda: 1.0 - 1.0 / memory.max(2) as f64,
            hist: vec![[[0.0; 3]; 2]; n_c],
            samples: 0,
            kc: vec![Ewls2::default(); n_c],
            lag: vec![Ewls2::default(); n_c],
            k: vec![f64::NAN; n_c],
            c: vec![f64::NAN; n_c],
            tau: vec![f64::NAN; n_c],
        }
    }

    /// The sample at the end of a step: `force` on the numerical substructure (the
    /// specimen's restoring force is `−force`), `command`, `measured` displacement.
    pub fn push(&mut self, force: &[f64], command: &[f64], measured: &[f64]) {
        let h2 = 2.0 * self.dt;
        for k in 0..self.hist.len() {
            let now = [-force[k], command[k], measured[k]];
            let [prev, mid] = self.hist[k];
            if self.samples >= 2 && now.iter().chain(&prev).chain(&mid).all(|v| v.is_finite()) {
                let xdot = (now[2] - prev[2]) / h2;
                let ddot = (now[1] - prev[1]) / h2;
                self.kc[k].update(self.lambda, mid[2], xdot, mid[0]);
                self.lag[k].update(self.lambda, ddot, 0.0, mid[1] - mid[2]);
                if let Some((kk, cc)) = self.kc[k].solve2() {
                    self.k[k] = kk;
                    self.c[k] = cc;
                }
                if let Some(t) = self.lag[k].solve1() {
                    self.tau[k] = t;
                }
            }
            self.hist[k] = [mid, now];
        }
        self.samples += 1;
    }

    /// Identified stiffness \[N/m\], damping \[N·s/m\] and lag \[s\] per DOF (NaN until known).
    pub fn stiffness(&self) -> &[f64] {
        &self.k
    }
    pub fn damping(&self) -> &[f64] {
        &self.c
    }
    pub fn lag(&self) -> &[f64] {
        &self.tau
    }
}

/// Builds the linear test "numerical substructure + identified specimen + identified lag" and
/// returns its spectral radius `ρ` (the amplification-matrix analysis of [`crate::analysis`]).
#[derive(Debug, Clone)]
pub struct ModelView {
    base: SubstructureDefinition,
    model: StructuralModel,
    dt: f64,
    /// Longest lag analysed \[s\] (a larger identified lag is clamped to it).
    max_lag: f64,
}

/// Largest model the view analyses: probing costs one step per state, per refresh.
pub const MODEL_VIEW_MAX_DOFS: usize = 60;

impl ModelView {
    /// The view of `sub` on the dense `model` at time step `dt`; refused (with the reason) for
    /// models larger than [`MODEL_VIEW_MAX_DOFS`].
    pub fn new(sub: &SubstructureDefinition, model: &StructuralModel, dt: f64) -> Result<Self> {
        if model.n_dofs() > MODEL_VIEW_MAX_DOFS {
            return Err(Error::invalid(
                "stability model view",
                format!(
                    "the numerical model has {} DOFs; the view probes models up to {MODEL_VIEW_MAX_DOFS} DOFs",
                    model.n_dofs()
                ),
            ));
        }
        if matches!(sub.error_force, ErrorForceSpec::Arx { .. }) {
            // Probing needs a linear step map; the estimation identifies its model on line.
            return Err(Error::invalid(
                "stability model view",
                "error-force estimation (error_force.kind = \"arx\") is adaptive; the view analyses linear algorithms only (the energy view runs)",
            ));
        }
        let mut base = sub.clone();
        // The identified lag is the whole path from the command the observer sees to the
        // measured displacement: tracking controller and phase-lag compensation included.
        base.controller = None;
        base.controller_feedforward = None;
        base.phase_lag = None;
        base.remote = None;
        base.limits = None;
        Ok(Self {
            base,
            model: model.clone(),
            dt,
            max_lag: 10.0 * dt,
        })
    }

    /// `ρ` of the algorithm with, at each coupling DOF, a spring-dashpot specimen `k[i]`,
    /// `c[i]` (negative values clamped to 0) behind an ideal actuator with the pure delay
    /// `max τ` (clamped to `[0, 10 Δt]`).
    pub fn spectral_radius(&self, k: &[f64], c: &[f64], tau: &[f64]) -> Result<f64> {
        let n_c = self.base.coupling_dofs.len();
        if k.len() != n_c || c.len() != n_c || tau.len() != n_c {
            return Err(Error::invalid(
                "stability model view",
                "one k, c and τ per coupling DOF",
            ));
        }
        if k.iter().chain(c).chain(tau).any(|v| !v.is_finite()) {
            return Err(Error::numerical(
                "stability model view",
                "the identified values are not known yet",
            ));
        }
        let mut sub = self.base.clone();
        sub.specimens = self
            .base
            .coupling_dofs
            .iter()
            .enumerate()
            .map(|(i, &dof)| SpecimenSpec::LinearSdof {
                dof,
                mass: None,
                stiffness: k[i].max(0.0),
                damping: c[i].max(0.0),
            })
            .collect();
        let lag = tau.iter().fold(0.0f64, |a, &t| a.max(t)).clamp(0.0, self.max_lag);
        sub.actuator = ActuatorSpec {
            dynamics: Dynamics::Ideal,
            delay: lag,
        };
        let mut test = sub.build_frozen_test(&self.model, self.dt)?;
        Ok(StepMap::probe(&mut test)?.spectral_radius())
    }
}
