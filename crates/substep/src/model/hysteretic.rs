//! Hysteretic springs: the nonlinear part of a numerical model (docs/theory.md §14.2).
//!
//! A nonlinear model keeps its **initial** stiffness `K₀` in the linear matrices (`M`, `C`,
//! `K = K₀`) and adds springs whose force departs from their initial slope. Spring `e` acts on
//! the deformation `δ_e = u_to − u_from` (`u_from = 0` for a spring to the ground: the first
//! storey, a specimen) with a uniaxial [`Material`] of initial tangent `k_e`, so the restoring
//! force is
//!
//! ```text
//! r(u) = K₀ u + Σ_e a_e (F_e(δ_e) − k_e δ_e),   δ_e = a_eᵀ u,   a_e = e_to − e_from,
//! K_t(u) = K₀ + Σ_e a_e a_eᵀ (k_t,e − k_e).
//! ```
//!
//! `d(u) = r(u) − K₀ u` is the **deviation force**: zero while every spring is on its initial
//! slope, so a model whose springs never yield integrates exactly like the linear one.
//! A storey spring of a shear building, a rotational hinge between a node and a member end
//! and a specimen's spring to the ground are all of this form. Units: N and m (N·m and rad
//! for rotations).

use crate::error::{Error, Result};
use crate::material::{Material, MaterialSpec};
use nalgebra::DMatrix;

/// One hysteretic spring as configured.
#[derive(Debug, Clone, PartialEq)]
pub struct SpringSpec {
    /// DOF at the spring's other end (0-based), `None` for the ground.
    pub from: Option<usize>,
    /// DOF the spring's deformation is measured at (0-based).
    pub to: usize,
    /// Initial stiffness `k_e` (its part of `K₀`) \[N/m\].
    pub stiffness: f64,
    pub law: MaterialSpec,
    /// Config item named in errors (e.g. `structure.storeys.hysteresis` storey 2).
    pub what: String,
}

/// The hysteretic springs of a model, as configured (cheap to clone; [`Hysteresis::build`]
/// makes the stateful [`Springs`]).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Hysteresis {
    pub springs: Vec<SpringSpec>,
    /// Members with P-Δ (geometric nonlinearity, OpenSees' `PDelta` transformation).
    pub p_delta: Vec<PDeltaSpec>,
}

/// An elastic member under P-Δ as OpenSees' `PDelta` coordinate transformation has it: with the
/// local displacements `ul = R u` (axial `ul0, ul3`, transverse `ul1, ul4` of ends `a`, `b`),
/// the axial force `q0 = (EA/L)(ul3 − ul0)` (tension positive) adds the transverse end forces
/// `±q0 (ul1 − ul4)/L` and the tangent `(q0/L)[[1, −1], [−1, 1]]` on `ul1, ul4` (no `∂q0/∂u`
/// term, as OpenSees). The member's elastic stiffness is in `K₀`; this is the deviation.
#[derive(Debug, Clone, PartialEq)]
pub struct PDeltaSpec {
    /// `(ux, uy)` DOFs of end `a` and of end `b` (`None`: fixed).
    pub a: [Option<usize>; 2],
    pub b: [Option<usize>; 2],
    /// Direction cosines of `a → b`.
    pub cos: f64,
    pub sin: f64,
    /// `EA/L` \[N/m\] and `L` \[m\].
    pub axial_stiffness: f64,
    pub length: f64,
}

impl PDeltaSpec {
    fn value(&self, u: &[f64], end: [Option<usize>; 2]) -> (f64, f64) {
        let x = end[0].map_or(0.0, |d| u[d]);
        let y = end[1].map_or(0.0, |d| u[d]);
        (self.cos * x + self.sin * y, -self.sin * x + self.cos * y)
    }
    /// `(q0, ul1 − ul4)` at `u`.
    fn state(&self, u: &[f64]) -> (f64, f64) {
        let (axial_a, transverse_a) = self.value(u, self.a);
        let (axial_b, transverse_b) = self.value(u, self.b);
        (self.axial_stiffness * (axial_b - axial_a), transverse_a - transverse_b)
    }
    /// Global `(dof, transverse direction component)` of the ends' translations.
    fn transverse(&self) -> [(Option<usize>, f64); 4] {
        [
            (self.a[0], -self.sin),
            (self.a[1], self.cos),
            (self.b[0], self.sin),
            (self.b[1], -self.cos),
        ]
    }
}

impl Hysteresis {
    /// Springs in their virgin state, for a model of `n` DOFs.
    pub fn build(&self, n: usize) -> Result<Springs> {
        let mut springs = Vec::with_capacity(self.springs.len());
        for s in &self.springs {
            for d in s.from.iter().chain(std::iter::once(&s.to)) {
                if *d >= n {
                    return Err(Error::invalid(
                        s.what.as_str(),
                        format!("DOF {} is out of range (the model has DOFs 1..={n})", d + 1),
                    ));
                }
            }
            if s.from == Some(s.to) {
                return Err(Error::invalid(s.what.as_str(), "connects a DOF to itself"));
            }
            let material = s.law.build(s.stiffness, &s.what)?;
            springs.push(Spring {
                from: s.from,
                to: s.to,
                stiffness: s.stiffness,
                material,
                trial_deformation: 0.0,
                committed_deformation: 0.0,
            });
        }
        for p in &self.p_delta {
            for d in p.a.iter().chain(&p.b).flatten() {
                if *d >= n {
                    return Err(Error::invalid(
                        "structure.frame.p_delta",
                        format!("DOF {} is out of range (the model has DOFs 1..={n})", d + 1),
                    ));
                }
            }
        }
        Ok(Springs {
            springs,
            p_delta: self.p_delta.iter().map(|p| (p.clone(), 0.0, 0.0)).collect(),
        })
    }

    /// Whether every spring is elastic (then the model is linear).
    pub fn is_linear(&self) -> bool {
        self.p_delta.is_empty()
            && self
                .springs
                .iter()
                .all(|s| matches!(s.law, MaterialSpec::Elastic | MaterialSpec::Scaled { .. }))
    }
}

struct Spring {
    from: Option<usize>,
    to: usize,
    stiffness: f64,
    material: Box<dyn Material>,
    trial_deformation: f64,
    committed_deformation: f64,
}

impl Spring {
    fn deformation_of_trial(&self) -> f64 {
        self.trial_deformation
    }
    fn deformation(&self, u: &[f64]) -> f64 {
        u[self.to] - self.from.map_or(0.0, |f| u[f])
    }
    fn add(&self, value: f64, out: &mut [f64]) {
        out[self.to] += value;
        if let Some(f) = self.from {
            out[f] -= value;
        }
    }
}

/// The springs with their material states (and the P-Δ members with their trial `q0` and
/// `ul1 − ul4`). Trial and commit never allocate.
pub struct Springs {
    springs: Vec<Spring>,
    p_delta: Vec<(PDeltaSpec, f64, f64)>,
}

impl Springs {
    /// Springs and P-Δ members (each has one tangent quantity, see
    /// [`Springs::tangents_unchanged`]).
    pub fn len(&self) -> usize {
        self.springs.len() + self.p_delta.len()
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Whether every spring is linear and there is no P-Δ (then a step is a linear map of the
    /// state).
    pub fn is_linear(&self) -> bool {
        self.p_delta.is_empty() && self.springs.iter().all(|s| s.material.kind() == "elastic")
    }

    /// Trial state at the displacements `u` (from the committed state).
    pub fn set_trial(&mut self, u: &[f64]) {
        for s in &mut self.springs {
            let d = s.deformation(u);
            s.trial_deformation = d;
            s.material.set_trial(d);
        }
        for (p, q0, ul14) in &mut self.p_delta {
            (*q0, *ul14) = p.state(u);
        }
    }

    /// `out += scale · d(u)` of the trial state, `d` the deviation force.
    pub fn add_deviation(&self, scale: f64, out: &mut [f64]) {
        for s in &self.springs {
            let d = s.material.force() - s.stiffness * s.deformation_of_trial();
            s.add(scale * d, out);
        }
        for (p, q0, ul14) in &self.p_delta {
            // local transverse forces +P at a, −P at b; the direction signs are in `transverse`
            let force = scale * q0 * ul14 / p.length;
            for (dof, t) in p.transverse() {
                if let Some(d) = dof {
                    out[d] += force * t;
                }
            }
        }
    }

    /// `k += Σ a aᵀ (k_t − k₀)` of the trial state (a dense tangent).
    pub fn add_tangent_deviation(&self, k: &mut DMatrix<f64>) {
        for s in &self.springs {
            let dk = s.material.tangent() - s.stiffness;
            if dk == 0.0 {
                continue;
            }
            k[(s.to, s.to)] += dk;
            if let Some(f) = s.from {
                k[(f, f)] += dk;
                k[(f, s.to)] -= dk;
                k[(s.to, f)] -= dk;
            }
        }
        for (p, q0, _) in &self.p_delta {
            let g = q0 / p.length;
            for (di, ti) in p.transverse() {
                for (dj, tj) in p.transverse() {
                    if let (Some(i), Some(j)) = (di, dj) {
                        k[(i, j)] += g * ti * tj;
                    }
                }
            }
        }
    }

    /// The entries of `Σ a aᵀ (k_t − k₀)` of the trial state as `(row, column, value)`.
    pub fn tangent_deviation_triplets(&self, out: &mut Vec<(usize, usize, f64)>) {
        out.clear();
        for s in &self.springs {
            let dk = s.material.tangent() - s.stiffness;
            if dk == 0.0 {
                continue;
            }
            out.push((s.to, s.to, dk));
            if let Some(f) = s.from {
                out.extend([(f, f, dk), (f, s.to, -dk), (s.to, f, -dk)]);
            }
        }
        for (p, q0, _) in &self.p_delta {
            let g = q0 / p.length;
            for (di, ti) in p.transverse() {
                for (dj, tj) in p.transverse() {
                    if let (Some(i), Some(j)) = (di, dj) {
                        out.push((i, j, g * ti * tj));
                    }
                }
            }
        }
    }

    /// Whether the trial tangents equal those in `tangents` (then a factorised tangent can be
    /// reused); writes the current ones into it.
    pub fn tangents_unchanged(&self, tangents: &mut [f64]) -> bool {
        let mut same = true;
        let quantities = self
            .springs
            .iter()
            .map(|s| s.material.tangent())
            .chain(self.p_delta.iter().map(|p| p.1));
        for (now, t) in quantities.zip(tangents.iter_mut()) {
            if now != *t {
                same = false;
                *t = now;
            }
        }
        same
    }

    /// Deformation and force of each spring's trial state.
    pub fn states(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.springs
            .iter()
            .map(|s| (s.deformation_of_trial(), s.material.force()))
    }

    pub fn commit(&mut self) {
        for s in &mut self.springs {
            s.material.commit();
            s.committed_deformation = s.trial_deformation;
        }
    }
    pub fn revert(&mut self) {
        for s in &mut self.springs {
            s.material.revert();
            s.trial_deformation = s.committed_deformation;
        }
    }

    pub fn state_len(&self) -> usize {
        self.springs.iter().map(|s| 1 + s.material.state_len()).sum()
    }
    /// Committed states (the deformation of each spring, then its material's state).
    pub fn write_state(&self, out: &mut [f64]) {
        let mut at = 0;
        for s in &self.springs {
            out[at] = s.committed_deformation;
            let m = s.material.state_len();
            s.material.write_state(&mut out[at + 1..at + 1 + m]);
            at += 1 + m;
        }
    }
    pub fn read_state(&mut self, state: &[f64]) {
        let mut at = 0;
        for s in &mut self.springs {
            s.committed_deformation = state[at];
            s.trial_deformation = state[at];
            let m = s.material.state_len();
            s.material.read_state(&state[at + 1..at + 1 + m]);
            at += 1 + m;
        }
    }
}
