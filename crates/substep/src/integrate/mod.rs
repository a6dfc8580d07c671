//! Time integration of the (monolithic) numerical substructure behind one trait.
//!
//! Every scheme advances `M ü + C u̇ + K u = f*(t)` from `t_i` to `t_{i+1} = t_i + Δt` given the
//! total load `f*_{i+1}`; each keeps whatever history it needs (previous load, predictor).
//! Steps never allocate: all work vectors are created in the constructors.

mod exact;
mod hht;
mod kr_alpha;
mod newmark;
mod newton;

pub use exact::{ExactFoh, FohMap};
pub use hht::{AlphaOs, AlphaOsForm, Hht};
pub use kr_alpha::KrAlpha;
pub(crate) use kr_alpha::check_rho_inf;
pub use newmark::{ExplicitNewmark, Newmark, NewmarkConstants, NewmarkCore};
pub use newton::{NewmarkNewton, NewtonSettings};

use crate::error::{Error, Result, require_positive};
use crate::model::{ModelRef, Springs};
use crate::sparse::{FactorKind, SymmetricFactor};
use nalgebra::DVector;

/// Displacement, velocity and acceleration of all DOFs at one time level.
#[derive(Debug, Clone, PartialEq)]
pub struct Kinematics {
    pub u: DVector<f64>,
    pub v: DVector<f64>,
    pub a: DVector<f64>,
}

impl Kinematics {
    pub fn zeros(n: usize) -> Self {
        Self {
            u: DVector::zeros(n),
            v: DVector::zeros(n),
            a: DVector::zeros(n),
        }
    }
    /// Rest (`u₀ = v₀ = 0`) with the consistent initial acceleration `a₀ = M⁻¹ f*(0)`.
    pub fn at_rest<'a>(model: impl Into<ModelRef<'a>>, load0: &DVector<f64>) -> Result<Self> {
        let model = model.into();
        let mut k = Self::zeros(model.n_dofs());
        if load0.iter().all(|&f| f == 0.0) {
            // At rest without load: a = 0 whatever M is (also for massless DOFs).
            return Ok(k);
        }
        k.a.copy_from(load0);
        match model {
            ModelRef::Dense(model) => {
                let chol = model
                    .mass
                    .clone()
                    .cholesky()
                    .ok_or_else(|| Error::invalid("structure.mass", "is not positive definite"))?;
                chol.solve_mut(&mut k.a);
            }
            ModelRef::Sparse(model) if model.mass.is_diagonal() => {
                for (a, m) in k.a.iter_mut().zip(model.mass.diagonal()) {
                    *a /= m;
                }
            }
            ModelRef::Sparse(model) => {
                SymmetricFactor::new(&model.mass, FactorKind::Auto, "structure.mass")?
                    .solve_in_place(k.a.as_mut_slice());
            }
        }
        Ok(k)
    }
    pub fn is_finite(&self) -> bool {
        self.u
            .iter()
            .chain(self.v.iter())
            .chain(self.a.iter())
            .all(|x| x.is_finite())
    }
}

/// One time-integration scheme for a linear model.
pub trait Integrator: Send {
    /// Scheme name as used in configs.
    fn name(&self) -> &'static str;
    fn dt(&self) -> f64;
    fn state(&self) -> &Kinematics;
    /// Advance one step with the total load `f*_{i+1}` at the end of the step.
    fn step(&mut self, load_next: &DVector<f64>);
    /// Why the last step failed (a nonlinear solve that did not converge); the state is then
    /// that of the step before and further steps do nothing.
    fn failure(&self) -> Option<&str> {
        None
    }
    /// The hysteretic springs of a nonlinear model (committed state).
    fn springs(&self) -> Option<&crate::model::Springs> {
        None
    }
    /// Newton iterations of all steps so far and the most in one step (iterative schemes).
    fn newton_iterations(&self) -> Option<(usize, usize)> {
        None
    }
}

/// The integration schemes offered by name.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Scheme {
    /// Newmark(β, γ); `β = 0` selects the explicit form.
    Newmark { beta: f64, gamma: f64 },
    /// Hilber–Hughes–Taylor with Hilber's `α ∈ [−⅓, 0]`.
    Hht { alpha: f64 },
    /// Operator splitting α-OS, OpenSees' `AlphaOS` form (restoring force at the predictor,
    /// the linear part implicit with the initial stiffness).
    AlphaOs { alpha: f64 },
    /// α-OS in OpenSees' `AlphaOS_TP` form (differs from `AlphaOs` for nonlinear models only).
    AlphaOsTp { alpha: f64 },
    /// The Chen–Ricles algorithm (explicit, model-based; docs/theory.md §2.8).
    Cr,
    /// KR-α (Kolay–Ricles) with the spectral radius `ρ∞ ∈ [0, 1]` at infinite frequency, OpenSees'
    /// `KRAlphaExplicit` form (docs/theory.md §2.8).
    KrAlpha { rho_inf: f64 },
    /// Exact first-order-hold discretisation (reference).
    Exact,
}

impl Scheme {
    /// Resolve a scheme name of the config (`newmark` uses the given β, γ; `hht` and the α-OS
    /// schemes Hilber's `alpha`; `kr_alpha` `rho_inf`).
    pub fn from_name(name: &str, beta: f64, gamma: f64, alpha: f64, rho_inf: f64) -> Result<Self> {
        let nm = |beta, gamma| Ok(Scheme::Newmark { beta, gamma });
        match name {
            "newmark" => nm(beta, gamma),
            "central_difference" | "cdm" => nm(0.0, 0.5),
            "fox_goodwin" => nm(1.0 / 12.0, 0.5),
            "linear_acceleration" => nm(1.0 / 6.0, 0.5),
            "average_acceleration" | "trapezoidal" => nm(0.25, 0.5),
            "galerkin" => nm(0.8, 1.5),
            "backward_difference" => nm(1.0, 1.5),
            "hht" => Ok(Scheme::Hht { alpha }),
            "alpha_os" => Ok(Scheme::AlphaOs { alpha }),
            "alpha_os_tp" => Ok(Scheme::AlphaOsTp { alpha }),
            "cr" | "chen_ricles" => Ok(Scheme::Cr),
            "kr_alpha" => Ok(Scheme::KrAlpha { rho_inf }),
            "exact" => Ok(Scheme::Exact),
            other => Err(Error::invalid(
                "integrator.scheme",
                format!(
                    "unknown scheme '{other}' (expected one of newmark, central_difference, fox_goodwin, \
                     linear_acceleration, average_acceleration, galerkin, backward_difference, hht, alpha_os, alpha_os_tp, cr, kr_alpha, exact)"
                ),
            )),
        }
    }

    /// Build the integrator for `model`, time step `dt` and initial load `f*(0)`; starts at rest.
    /// A sparse model supports the implicit Newmark schemes only.
    pub fn build<'a>(
        &self,
        model: impl Into<ModelRef<'a>>,
        dt: f64,
        load0: &DVector<f64>,
    ) -> Result<Box<dyn Integrator>> {
        require_positive("integrator.dt", dt)?;
        let model = match model.into() {
            ModelRef::Dense(m) => m,
            ModelRef::Sparse(m) => {
                return match *self {
                    Scheme::Newmark { beta, gamma } if beta > 0.0 => {
                        Ok(Box::new(Newmark::new(m, dt, beta, gamma, load0)?))
                    }
                    _ => Err(Error::invalid(
                        "integrator.scheme",
                        format!(
                            "{} needs dense matrices, but the model has {} DOFs in sparse storage: use an \
                             implicit Newmark scheme (e.g. average_acceleration) or structure.storage = \"dense\"",
                            self.name(),
                            m.n_dofs()
                        ),
                    )),
                };
            }
        };
        Ok(match *self {
            Scheme::Newmark { beta: 0.0, gamma } => Box::new(ExplicitNewmark::new(model, dt, gamma, load0)?),
            Scheme::Newmark { beta, gamma } => Box::new(Newmark::new(model, dt, beta, gamma, load0)?),
            Scheme::Hht { alpha } => Box::new(Hht::new(model, dt, alpha, load0)?),
            Scheme::AlphaOs { .. } | Scheme::AlphaOsTp { .. } => {
                let (alpha, form) = self.alpha_os_form().expect("an alpha-OS scheme");
                Box::new(AlphaOs::with_springs(model, dt, alpha, form, None, load0)?)
            }
            Scheme::Cr => Box::new(KrAlpha::cr(model, dt, None, load0)?),
            Scheme::KrAlpha { rho_inf } => Box::new(KrAlpha::with_rho_inf(model, dt, rho_inf, None, load0)?),
            Scheme::Exact => Box::new(ExactFoh::new(model, dt, load0)?),
        })
    }
}

impl Scheme {
    /// Hilber's α and the form of an α-OS scheme.
    pub fn alpha_os_form(&self) -> Option<(f64, AlphaOsForm)> {
        match *self {
            Scheme::AlphaOs { alpha } => Some((alpha, AlphaOsForm::OnePoint)),
            Scheme::AlphaOsTp { alpha } => Some((alpha, AlphaOsForm::TwoPoint)),
            _ => None,
        }
    }

    /// Build the integrator for a nonlinear model: `model` holds the initial stiffness `K₀`,
    /// `springs` the hysteretic part (docs/theory.md §9). The implicit Newmark schemes iterate
    /// with Newton–Raphson; α-OS evaluates the springs at its predictor, CR and KR-α at their
    /// explicit displacement (no iterations).
    pub fn build_nonlinear<'a>(
        &self,
        model: impl Into<ModelRef<'a>>,
        springs: Springs,
        dt: f64,
        newton: NewtonSettings,
        load0: &DVector<f64>,
    ) -> Result<Box<dyn Integrator>> {
        require_positive("integrator.dt", dt)?;
        let model = model.into();
        match (*self, model) {
            (Scheme::Newmark { beta, gamma }, _) if beta > 0.0 => Ok(Box::new(NewmarkNewton::new(
                model, springs, dt, beta, gamma, newton, load0,
            )?)),
            (Scheme::AlphaOs { .. } | Scheme::AlphaOsTp { .. }, model) => {
                let (alpha, form) = self.alpha_os_form().expect("an alpha-OS scheme");
                let dense = match model {
                    ModelRef::Dense(m) => std::borrow::Cow::Borrowed(m),
                    ModelRef::Sparse(m) => std::borrow::Cow::Owned(m.to_dense("alpha_os on a nonlinear model")?),
                };
                Ok(Box::new(AlphaOs::with_springs(
                    &dense,
                    dt,
                    alpha,
                    form,
                    Some(springs),
                    load0,
                )?))
            }
            (Scheme::Cr | Scheme::KrAlpha { .. }, model) => {
                let dense = match model {
                    ModelRef::Dense(m) => std::borrow::Cow::Borrowed(m),
                    ModelRef::Sparse(m) => std::borrow::Cow::Owned(m.to_dense("cr / kr_alpha (dense α matrices)")?),
                };
                Ok(Box::new(match *self {
                    Scheme::KrAlpha { rho_inf } => KrAlpha::with_rho_inf(&dense, dt, rho_inf, Some(springs), load0)?,
                    _ => KrAlpha::cr(&dense, dt, Some(springs), load0)?,
                }))
            }
            _ => Err(Error::invalid(
                "integrator.scheme",
                format!(
                    "{} cannot integrate a nonlinear model: use an implicit Newmark scheme (e.g. \
                     average_acceleration, solved by Newton–Raphson), alpha_os, cr or kr_alpha",
                    self.name()
                ),
            )),
        }
    }

    /// A short name for messages.
    pub fn name(&self) -> &'static str {
        match self {
            Scheme::Newmark { beta, .. } if *beta == 0.0 => "explicit Newmark (central difference)",
            Scheme::Newmark { .. } => "newmark",
            Scheme::Hht { .. } => "hht",
            Scheme::AlphaOs { .. } => "alpha_os",
            Scheme::AlphaOsTp { .. } => "alpha_os_tp",
            Scheme::Cr => "cr",
            Scheme::KrAlpha { .. } => "kr_alpha",
            Scheme::Exact => "the exact scheme",
        }
    }
}

/// Check Hilber's α.
pub(crate) fn check_hilber_alpha(alpha: f64) -> Result<()> {
    if !(alpha.is_finite() && (-1.0 / 3.0 - 1e-12..=0.0).contains(&alpha)) {
        return Err(Error::invalid(
            "integrator.alpha",
            format!("Hilber's alpha must lie in [-1/3, 0], got {alpha} (OpenSees' alpha = 1 + this)"),
        ));
    }
    Ok(())
}
