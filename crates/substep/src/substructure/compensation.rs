//! Error-force compensation (docs/theory.md §4): from the error force `e_{i+1} = f^{(k)} − f^{(k−1)}`
//! (per coupling DOF) compute the compensation force `f_u,i+1` that enters the next predictor.

use crate::error::{Error, Result};

#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum ErrorForceSpec {
    #[default]
    None,
    /// `f_u,i+1 = P e_{i+1} + I Δt Σ e + D (e_{i+1} − e_i)/Δt`.
    Pid { p: f64, i: f64, d: f64 },
    /// OpenHySL's variant: residual `r_{i+1} = e_{i+1} − f_u,i`, `f_u,i+1 = P r_{i+1}`
    /// (recursion `r_{i+1} + P r_i = e_{i+1}`, pole at `−P`). Only to reproduce OpenHySL runs.
    PidResidual { p: f64 },
    /// Estimation by on-line identification (docs/theory.md §4.4): an ARX model of order `order` (`n_u`,
    /// 2..=12) per coupling DOF, RLS with forgetting factor `lambda` and initial covariance `p0`
    /// (of the normalised regressor). The last sub-step's force is predicted, the last command
    /// solved consistently with it, and `f_u = e = f^{(k)} − f̂^{(k)}` (P = 1). See
    /// the module docs of `substructure::estimation` (private; summarised in docs/substructure.md).
    Arx { order: usize, lambda: f64, p0: f64 },
}

impl ErrorForceSpec {
    /// Defaults of the estimation: `n_u = 4`, `λ = 0.98`, `p0 = 100`.
    pub const ARX_DEFAULT: ErrorForceSpec = ErrorForceSpec::Arx {
        order: 4,
        lambda: 0.98,
        p0: 100.0,
    };

    /// `none`, `pid`, `pid_residual` or `arx` (the config's `kind`).
    pub fn kind(&self) -> &'static str {
        match self {
            ErrorForceSpec::None => "none",
            ErrorForceSpec::Pid { .. } => "pid",
            ErrorForceSpec::PidResidual { .. } => "pid_residual",
            ErrorForceSpec::Arx { .. } => "arx",
        }
    }
}

impl ErrorForceSpec {
    pub fn validate(&self) -> Result<()> {
        let check = |name: &str, v: f64| {
            if v.is_finite() {
                Ok(())
            } else {
                Err(Error::invalid(
                    format!("substructure.error_force.{name}"),
                    "must be finite",
                ))
            }
        };
        match *self {
            ErrorForceSpec::None => Ok(()),
            ErrorForceSpec::Pid { p, i, d } => {
                check("p", p)?;
                check("i", i)?;
                check("d", d)
            }
            ErrorForceSpec::PidResidual { p } => check("p", p),
            ErrorForceSpec::Arx { order, lambda, p0 } => {
                if !(2..=12).contains(&order) {
                    return Err(Error::invalid(
                        "substructure.error_force.order",
                        format!("must be in 2..=12, got {order}"),
                    ));
                }
                if !(lambda.is_finite() && lambda > 0.0 && lambda <= 1.0) {
                    return Err(Error::invalid(
                        "substructure.error_force.forgetting_factor",
                        format!("must be in (0, 1], got {lambda}"),
                    ));
                }
                if !(p0.is_finite() && p0 > 0.0) {
                    return Err(Error::invalid(
                        "substructure.error_force.p0",
                        format!("must be a finite number > 0, got {p0}"),
                    ));
                }
                Ok(())
            }
        }
    }
}

/// Compensation state for `n_c` coupling DOFs.
#[derive(Debug, Clone)]
pub struct ErrorForceCompensation {
    pub spec: ErrorForceSpec,
    /// `Σ e_l` (PID) — per coupling DOF.
    integral: Vec<f64>,
    /// `e_i` (PID derivative).
    previous: Vec<f64>,
}

impl ErrorForceCompensation {
    /// No compensation (`f_u = 0` always), for `n_c` coupling DOFs.
    pub fn none(n_c: usize) -> Self {
        Self {
            spec: ErrorForceSpec::None,
            integral: vec![0.0; n_c],
            previous: vec![0.0; n_c],
        }
    }

    pub fn new(spec: ErrorForceSpec, n_c: usize) -> Result<Self> {
        spec.validate()?;
        Ok(Self {
            spec,
            integral: vec![0.0; n_c],
            previous: vec![0.0; n_c],
        })
    }

    /// Given the error force `e` and the current compensation `f_u` (both per coupling DOF),
    /// overwrite `f_u` with the compensation for the next step.
    pub fn update(&mut self, e: &[f64], dt: f64, f_u: &mut [f64]) {
        match self.spec {
            ErrorForceSpec::None => f_u.iter_mut().for_each(|f| *f = 0.0),
            ErrorForceSpec::Pid { p, i, d } => {
                for k in 0..e.len() {
                    self.integral[k] += e[k];
                    f_u[k] = p * e[k] + i * dt * self.integral[k] + d * (e[k] - self.previous[k]) / dt;
                    self.previous[k] = e[k];
                }
            }
            ErrorForceSpec::PidResidual { p } => {
                for k in 0..e.len() {
                    f_u[k] = p * (e[k] - f_u[k]);
                }
            }
            // The estimation's error force is already the mismatch of the prediction: P = 1.
            ErrorForceSpec::Arx { .. } => f_u.copy_from_slice(e),
        }
    }

    /// State that carries over between steps and matters: `Σe` per DOF when `I ≠ 0`, `e_i`
    /// when `D ≠ 0`; nothing otherwise (the residual variant's only memory is `f_u`, which the
    /// controller already holds). Unused accumulators would add spurious eigenvalues 1 to the
    /// amplification matrix.
    pub fn state_len(&self) -> usize {
        let (with_i, with_d) = self.used_states();
        self.integral.len() * (with_i as usize + with_d as usize)
    }
    fn used_states(&self) -> (bool, bool) {
        match self.spec {
            ErrorForceSpec::Pid { i, d, .. } => (i != 0.0, d != 0.0),
            _ => (false, false),
        }
    }
    pub fn write_state(&self, out: &mut [f64]) {
        let (with_i, with_d) = self.used_states();
        let n = self.integral.len();
        let mut at = 0;
        if with_i {
            out[..n].copy_from_slice(&self.integral);
            at = n;
        }
        if with_d {
            out[at..at + n].copy_from_slice(&self.previous);
        }
    }
    pub fn read_state(&mut self, s: &[f64]) {
        let (with_i, with_d) = self.used_states();
        let n = self.integral.len();
        let mut at = 0;
        if with_i {
            self.integral.copy_from_slice(&s[..n]);
            at = n;
        }
        if with_d {
            self.previous.copy_from_slice(&s[at..at + n]);
        }
    }
}
