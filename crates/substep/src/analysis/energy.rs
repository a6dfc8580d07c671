//! Energy balance of a run in relative coordinates.
//!
//! The numerical substructure obeys `M ü + C u̇ + K u = −M ι a_g + f_c`, with `f_c` the force of
//! the experimental substructure on the structure, spread onto all DOFs (zero where there is no
//! coupling DOF). Its energy terms at step `i` are
//!
//! * kinetic `E_K = ½ vᵀ M v`, strain `E_S = ½ uᵀ K u` (state functions; for a nonlinear model
//!   `K = K₀` and the work of the hysteretic deviation force `Σ Δuᵀ d̄` is added, so `E_S` is the
//!   work of the restoring force `r = K₀ u + d`: stored plus dissipated by yielding),
//! * damping `E_D = Σ Δuᵀ C v̄`, input `E_I = −Σ Δuᵀ M ι ā_g`, coupling `E_C = Σ Δuᵀ f̄_c`
//!   (work integrals),
//!
//! where `Δu = u_{i+1} − u_i` and the bar is the mean of the two ends of a step (`v̄ = (v_i +
//! v_{i+1})/2`). Integrating the work "in displacement" with the trapezoidal rule is what makes
//! the balance exact for the average-acceleration Newmark scheme: with `Δu = Δt v̄` and
//! `Δv = Δt ā`, the mean of the equations of motion at `i` and `i+1`, multiplied by `Δuᵀ`, is
//! term by term `ΔE_K + ΔE_D + ΔE_S = ΔE_I + ΔE_C`. Any other scheme, a sub-step controller
//! that does not converge or a noisy load cell leaves a residual
//!
//! `E_err = E_K + E_S + E_D − E_I − E_C`,
//!
//! reported at each step relative to the largest energy that entered the system so far, and
//! as the run's largest `|E_err|` relative to the largest energy that entered over the run
//! (`max |E_I| + max |E_C|`), so that the number does not blow up at the start of a record. A positive coupling work means the specimen fed energy into the structure; the energy
//! the specimen absorbed is `−E_C`.
//!
//! [`EnergyBalance::push`] allocates nothing (dense matrix-vector products into preallocated
//! vectors) so it may run inside a test loop.

use crate::error::{Error, Result};
use crate::model::StructuralModel;
use nalgebra::DVector;

/// The energy terms at one step \[J\].
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct EnergyTerms {
    pub input: f64,
    pub kinetic: f64,
    pub damping: f64,
    pub strain: f64,
    pub coupling: f64,
}

impl EnergyTerms {
    /// `E_K + E_S + E_D − E_I − E_C` \[J\].
    pub fn residual(&self) -> f64 {
        self.kinetic + self.strain + self.damping - self.input - self.coupling
    }
}

/// Running energy balance of a linear numerical substructure (see the module docs).
#[derive(Debug, Clone)]
pub struct EnergyBalance {
    model: StructuralModel,
    m_iota: DVector<f64>,
    terms: EnergyTerms,
    /// `E_K + E_S` of the first state (energy the system starts with).
    initial: f64,
    /// Previous `u`, `v`, `a_g`, `f_c`.
    u: DVector<f64>,
    v: DVector<f64>,
    ag: f64,
    fc: DVector<f64>,
    work: DVector<f64>,
    product: DVector<f64>,
    max_in: f64,
    /// The largest `|E_err|` so far \[J\].
    max_abs_error: f64,
    started: bool,
    /// Work of the springs' deviation force so far, and the last deviation force.
    hysteretic: f64,
    deviation: DVector<f64>,
}

impl EnergyBalance {
    pub fn new(model: &StructuralModel) -> Self {
        let n = model.n_dofs();
        Self {
            m_iota: model.effective_mass_vector(),
            model: model.clone(),
            terms: EnergyTerms::default(),
            initial: 0.0,
            u: DVector::zeros(n),
            v: DVector::zeros(n),
            ag: 0.0,
            fc: DVector::zeros(n),
            work: DVector::zeros(n),
            product: DVector::zeros(n),
            max_in: 0.0,
            max_abs_error: 0.0,
            started: false,
            hysteretic: 0.0,
            deviation: DVector::zeros(n),
        }
    }

    /// Add the state of the next step: displacement `u`, velocity `v`, ground acceleration
    /// `ag` and the coupling force `fc` on every DOF (zeros for a monolithic run). The first
    /// call sets the initial state; its `E_K + E_S` counts as energy put in
    /// ([`Self::initial`]), so a free vibration from a displaced state balances too.
    // Several arrays of one length walked together: the index form reads like the formula.
    #[allow(clippy::needless_range_loop)]
    pub fn push(&mut self, u: &[f64], v: &[f64], ag: f64, fc: &[f64]) -> Result<()> {
        self.push_nonlinear(u, v, ag, fc, None)
    }

    /// [`push`](Self::push) for a nonlinear model: `deviation` is the springs' deviation force
    /// `d` of this state (docs/theory.md §14.2), whose work joins the strain term.
    #[allow(clippy::needless_range_loop)]
    pub fn push_nonlinear(
        &mut self,
        u: &[f64],
        v: &[f64],
        ag: f64,
        fc: &[f64],
        deviation: Option<&[f64]>,
    ) -> Result<()> {
        let n = self.u.len();
        if deviation.is_some_and(|d| d.len() != n) {
            return Err(Error::invalid(
                "energy balance",
                format!("expected {n} deviation forces"),
            ));
        }
        if u.len() != n || v.len() != n || fc.len() != n {
            return Err(Error::invalid(
                "energy balance",
                format!("expected {n} values of u, v and f_c per step"),
            ));
        }
        if self.started {
            // Δu into `work`.
            for k in 0..n {
                self.work[k] = u[k] - self.u[k];
            }
            // Damping: Δuᵀ C (v_i + v_{i+1}) / 2.
            for k in 0..n {
                self.v[k] = 0.5 * (self.v[k] + v[k]);
            }
            self.product.gemv(1.0, &self.model.damping, &self.v, 0.0);
            self.terms.damping += self.work.dot(&self.product);
            self.terms.input -= 0.5 * (self.ag + ag) * self.work.dot(&self.m_iota);
            let mut w = 0.0;
            for k in 0..n {
                w += self.work[k] * 0.5 * (self.fc[k] + fc[k]);
            }
            self.terms.coupling += w;
            if let Some(d) = deviation {
                let mut h = 0.0;
                for k in 0..n {
                    h += self.work[k] * 0.5 * (self.deviation[k] + d[k]);
                }
                self.hysteretic += h;
            }
        }
        if let Some(d) = deviation {
            self.deviation.copy_from_slice(d);
        }
        self.u.copy_from_slice(u);
        self.v.copy_from_slice(v);
        self.ag = ag;
        self.fc.copy_from_slice(fc);
        self.product.gemv(1.0, &self.model.mass, &self.v, 0.0);
        self.terms.kinetic = 0.5 * self.v.dot(&self.product);
        self.product.gemv(1.0, &self.model.stiffness, &self.u, 0.0);
        self.terms.strain = 0.5 * self.u.dot(&self.product) + self.hysteretic;
        if !self.started {
            self.initial = self.terms.kinetic + self.terms.strain;
            self.started = true;
        }
        self.max_in = self
            .max_in
            .max(self.initial + self.terms.input.abs() + self.terms.coupling.abs());
        self.max_abs_error = self.max_abs_error.max(self.error().abs());
        Ok(())
    }

    /// The energy terms at the last step.
    pub fn terms(&self) -> EnergyTerms {
        self.terms
    }

    /// `E_K + E_S` of the first state \[J\].
    pub fn initial(&self) -> f64 {
        self.initial
    }

    /// `E_err = E_K + E_S + E_D − E_I − E_C − E_0` \[J\] at the last step (`E_0`: [`Self::initial`]).
    pub fn error(&self) -> f64 {
        self.terms.residual() - self.initial
    }

    /// [`Self::error`] over the largest energy that entered so far (`E_0 + |E_I| + |E_C|`);
    /// 0 while nothing has entered.
    pub fn relative_error(&self) -> f64 {
        if self.max_in > 0.0 {
            self.error() / self.max_in
        } else {
            0.0
        }
    }

    /// The largest `|E_err|` over the run so far relative to the largest energy that entered
    /// over the run (`E_0 + max |E_I| + max |E_C|`; 0 while nothing has entered). Dividing by the
    /// run's largest input, not the input up to that step, keeps a few mJ of residual in the
    /// first steps of a record from reading as a large error (explicit schemes, whose velocity
    /// is not the trapezoidal mean of the displacement increments, have such a start).
    pub fn max_relative_error(&self) -> f64 {
        if self.max_in > 0.0 {
            self.max_abs_error / self.max_in
        } else {
            0.0
        }
    }
}
