//! The on-line stability indicator: both views (energy, model) fed step by step, with the
//! thresholds of `[substructure.limits]` (docs/theory.md §15).

use super::energy::EnergyIndicator;
use super::model_view::{Identification, ModelView};
use crate::error::Result;
use crate::io::SubstructureDefinition;
use crate::model::Model;
pub use crate::substructure::{StabilityAction, StabilitySettings};
use serde::Serialize;

/// Which view raised an alarm.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IndicatorView {
    Energy,
    Model,
}

impl IndicatorView {
    pub fn name(self) -> &'static str {
        match self {
            IndicatorView::Energy => "energy",
            IndicatorView::Model => "model",
        }
    }
}

/// The first crossing of a threshold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Alarm {
    pub step: usize,
    pub time: f64,
    pub view: IndicatorView,
    /// `η` (energy view) or `1 − ρ` (model view).
    pub value: f64,
    pub threshold: f64,
}

impl Alarm {
    pub fn message(&self) -> String {
        match self.view {
            IndicatorView::Energy => format!(
                "stability indicator (energy): the transfer system cancels {:.0} % of the dissipation (threshold {:.0} %) at t = {:.3} s (step {})",
                100.0 * self.value,
                100.0 * self.threshold,
                self.time,
                self.step
            ),
            IndicatorView::Model => format!(
                "stability indicator (model): margin 1 − ρ = {:.3e} is below {:.3e} for the identified specimen and lag at t = {:.3} s (step {})",
                self.value, self.threshold, self.time, self.step
            ),
        }
    }
}

/// Both views of the indicator for one test. Feed it the state after every step with
/// [`Self::push`]; only the model-view refresh (every `refresh` steps, and only when the
/// identified values changed) builds and probes a small linear test (it allocates: keep it off
/// real-time threads).
pub struct StabilityMonitor {
    settings: StabilitySettings,
    dt: f64,
    coupling: Vec<usize>,
    energy: EnergyIndicator,
    ident: Identification,
    view: Option<ModelView>,
    view_note: Option<String>,
    damping: DampingWork,
    steps: usize,
    rho: f64,
    last_probe: Vec<f64>,
    over_energy: usize,
    over_model: usize,
    alarm: Option<Alarm>,
    /// Worst values so far (NaN until known).
    max_eta: f64,
    min_margin: f64,
    /// A threshold is crossed (for `persistence` evaluations) at the last refresh point.
    alarm_active: bool,
    /// Episodes of [`Self::alarm_active`] (the first one raised [`Self::alarm`]).
    alarm_count: usize,
}

/// The damping work of the numerical substructure `E_D = Σ Δuᵀ C v̄` (trapezoidal, as
/// [`crate::analysis::energy`]), on dense or sparse `C`; allocation-free per step.
struct DampingWork {
    c: DampingMatrix,
    u: Vec<f64>,
    v: Vec<f64>,
    cv: Vec<f64>,
    work: f64,
    started: bool,
}

enum DampingMatrix {
    Dense(nalgebra::DMatrix<f64>),
    Sparse(crate::sparse::CscMatrix),
}

impl DampingWork {
    fn new(model: &Model) -> Self {
        let n = model.n_dofs();
        let c = match (model.as_dense(), model.as_sparse()) {
            (Some(d), _) => DampingMatrix::Dense(d.damping.clone()),
            (None, Some(s)) => DampingMatrix::Sparse(s.damping.clone()),
            (None, None) => DampingMatrix::Dense(nalgebra::DMatrix::zeros(n, n)),
        };
        Self {
            c,
            u: vec![0.0; n],
            v: vec![0.0; n],
            cv: vec![0.0; n],
            work: 0.0,
            started: false,
        }
    }

    fn push(&mut self, u: &[f64], v: &[f64]) -> f64 {
        if u.len() != self.u.len() || v.len() != self.v.len() {
            return self.work;
        }
        if self.started {
            for (m, &x) in self.v.iter_mut().zip(v) {
                *m = 0.5 * (*m + x);
            }
            match &self.c {
                DampingMatrix::Dense(c) => {
                    let vm = nalgebra::DVectorView::from_slice(&self.v, self.v.len());
                    let mut out = nalgebra::DVectorViewMut::from_slice(&mut self.cv, self.u.len());
                    out.gemv(1.0, c, &vm, 0.0);
                }
                DampingMatrix::Sparse(c) => c.sym_mul_add(1.0, &self.v, 0.0, &mut self.cv),
            }
            self.work += self
                .cv
                .iter()
                .zip(u.iter().zip(&self.u))
                .map(|(f, (a, b))| f * (a - b))
                .sum::<f64>();
        }
        self.u.copy_from_slice(u);
        self.v.copy_from_slice(v);
        self.started = true;
        self.work
    }
}

impl StabilityMonitor {
    /// For the test `sub` on `model` with time step `dt`.
    pub fn new(sub: &SubstructureDefinition, model: &Model, dt: f64, settings: StabilitySettings) -> Result<Self> {
        settings.validate()?;
        let n_c = sub.coupling_dofs.len();
        let window = ((settings.window / dt).round() as usize).max(2);
        let (view, view_note) = match model.as_dense().map(|m| ModelView::new(sub, m, dt)) {
            Some(Ok(v)) => (Some(v), None),
            Some(Err(e)) => (None, Some(e.to_string())),
            None => (
                None,
                Some(format!(
                    "the model view needs a dense model of at most {} DOFs",
                    super::model_view::MODEL_VIEW_MAX_DOFS
                )),
            ),
        };
        Ok(Self {
            dt,
            coupling: sub.coupling_dofs.clone(),
            energy: EnergyIndicator::new(n_c, window),
            ident: Identification::new(n_c, dt, window),
            view,
            view_note,
            damping: DampingWork::new(model),
            steps: 0,
            rho: f64::NAN,
            last_probe: vec![f64::NAN; 3 * n_c],
            over_energy: 0,
            over_model: 0,
            alarm: None,
            max_eta: f64::NAN,
            min_margin: f64::NAN,
            alarm_active: false,
            alarm_count: 0,
            settings,
        })
    }

    pub fn settings(&self) -> &StabilitySettings {
        &self.settings
    }

    /// The state after step `step`: `u`, `v` of every numerical DOF, ground acceleration `ag`,
    /// and per coupling DOF the force on the numerical substructure, the command and the
    /// measured displacement. Returns the alarm if this step raised it (the first one only).
    #[allow(clippy::too_many_arguments)]
    pub fn push(
        &mut self,
        step: usize,
        u: &[f64],
        v: &[f64],
        ag: f64,
        force: &[f64],
        command: &[f64],
        measured: &[f64],
    ) -> Option<Alarm> {
        let _ = ag;
        let damping = self.damping.push(u, v);
        self.ident.push(force, command, measured);
        let stored: f64 = self
            .ident
            .stiffness()
            .iter()
            .zip(measured)
            .map(|(&k, &x)| if k > 0.0 { 0.5 * k * x * x } else { 0.0 })
            .sum();
        self.energy.push(force, command, measured, damping, stored);
        self.steps += 1;
        let eta = self.energy.eta();
        self.max_eta = nan_max(self.max_eta, eta);
        if !self.steps.is_multiple_of(self.settings.refresh) {
            return None;
        }
        // Both views are judged at the refresh points: `persistence` refreshes in a row.
        self.refresh_model();
        let margin = self.margin();
        self.min_margin = -nan_max(-self.min_margin, -margin);
        self.over_energy = if eta > self.settings.energy_threshold {
            self.over_energy + 1
        } else {
            0
        };
        let alarm = if self.over_energy >= self.settings.persistence {
            Some((IndicatorView::Energy, eta, self.settings.energy_threshold))
        } else if self.over_model >= self.settings.persistence {
            Some((IndicatorView::Model, margin, self.settings.margin_threshold))
        } else {
            None
        };
        if alarm.is_some() && !self.alarm_active {
            self.alarm_count += 1;
        }
        self.alarm_active = alarm.is_some();
        if self.alarm.is_some() {
            return None;
        }
        self.alarm = alarm.map(|(view, value, threshold)| Alarm {
            step,
            time: step as f64 * self.dt,
            view,
            value,
            threshold,
        });
        self.alarm
    }

    fn refresh_model(&mut self) {
        let Some(view) = &self.view else { return };
        let n_c = self.coupling.len();
        let (k, c, t) = (self.ident.stiffness(), self.ident.damping(), self.ident.lag());
        if k.iter().chain(c).chain(t).any(|x| !x.is_finite()) {
            return;
        }
        // Probing allocates and costs one step per state: skip it while the identified
        // values stay within 0.5 % (lag: 0.5 % of a sub-step) of the last probed ones.
        let close = (0..n_c).all(|i| {
            let near = |a: f64, b: f64, scale: f64| (a - b).abs() <= 5e-3 * scale;
            near(k[i], self.last_probe[i], k[i].abs())
                && near(c[i], self.last_probe[n_c + i], c[i].abs())
                && near(t[i], self.last_probe[2 * n_c + i], self.dt)
        });
        if !close {
            self.rho = view.spectral_radius(k, c, t).unwrap_or(f64::NAN);
            self.last_probe[..n_c].copy_from_slice(k);
            self.last_probe[n_c..2 * n_c].copy_from_slice(c);
            self.last_probe[2 * n_c..].copy_from_slice(t);
        }
        self.over_model = if self.margin() < self.settings.margin_threshold {
            self.over_model + 1
        } else {
            0
        };
    }

    /// Names of the indicator's history columns for `n_c` coupling DOFs: `eta, margin,
    /// k_id1.., c_id1.., lag_id1..` (the order of [`history_values`](Self::history_values)).
    pub fn history_columns(n_c: usize) -> impl Iterator<Item = String> {
        ["eta".to_string(), "margin".to_string()].into_iter().chain(
            ["k_id", "c_id", "lag_id"]
                .into_iter()
                .flat_map(move |p| (1..=n_c).map(move |k| format!("{p}{k}"))),
        )
    }

    /// This step's values of [`history_columns`](Self::history_columns) (NaN until known).
    pub fn history_values(&self) -> impl Iterator<Item = f64> + '_ {
        let id = self.identification();
        [self.eta(), self.margin()]
            .into_iter()
            .chain(id.stiffness().iter().chain(id.damping()).chain(id.lag()).copied())
    }

    /// Energy ratio `η` of the last window (NaN until known).
    pub fn eta(&self) -> f64 {
        self.energy.eta()
    }
    pub fn energy(&self) -> &EnergyIndicator {
        &self.energy
    }
    /// Spectral radius of the model view (NaN until known or without a model view).
    pub fn rho(&self) -> f64 {
        self.rho
    }
    /// `1 − ρ`.
    pub fn margin(&self) -> f64 {
        1.0 - self.rho
    }
    pub fn identification(&self) -> &Identification {
        &self.ident
    }
    /// Why there is no model view, if there is none.
    pub fn model_view_note(&self) -> Option<&str> {
        self.view_note.as_deref()
    }
    pub fn alarm(&self) -> Option<&Alarm> {
        self.alarm.as_ref()
    }
    /// Largest `η` so far (NaN while unknown).
    pub fn max_eta(&self) -> f64 {
        self.max_eta
    }
    /// Smallest margin `1 − ρ` so far (NaN while unknown).
    pub fn min_margin(&self) -> f64 {
        self.min_margin
    }
    /// Alarm episodes so far: runs of refresh points at which a threshold stays crossed
    /// (`persistence` evaluations in a row) count once each.
    pub fn alarm_count(&self) -> usize {
        self.alarm_count
    }

    /// `summary.json`'s `stability` block of the run so far.
    pub fn summary(&self) -> StabilitySummary {
        let s = &self.settings;
        let id = &self.ident;
        StabilitySummary {
            action: s.action.name(),
            energy_threshold: s.energy_threshold,
            margin_threshold: s.margin_threshold,
            window_s: s.window,
            max_eta: self.max_eta,
            min_margin: self.min_margin,
            final_eta: self.eta(),
            final_margin: self.margin(),
            first_alarm_s: self.alarm.map(|a| a.time),
            alarm_count: self.alarm_count,
            added_energy_j: self.energy.total_added(),
            identified: IdentifiedSummary {
                stiffness: id.stiffness().to_vec(),
                damping: id.damping().to_vec(),
                lag_s: id.lag().to_vec(),
            },
            model_view: self
                .view_note
                .as_ref()
                .map_or_else(|| "on".to_string(), |n| format!("off: {n}")),
            alarm: self.alarm.map(|a| AlarmSummary {
                view: a.view.name(),
                step: a.step,
                time: a.time,
                value: a.value,
                threshold: a.threshold,
                message: a.message(),
            }),
        }
    }
}

/// `summary.json`'s `stability` block. Numbers that are not known (NaN) are written `null`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StabilitySummary {
    /// `warn` or `stop`.
    pub action: &'static str,
    pub energy_threshold: f64,
    pub margin_threshold: f64,
    pub window_s: f64,
    /// Worst values over the run: largest `η`, smallest `1 − ρ`.
    pub max_eta: f64,
    pub min_margin: f64,
    /// The values at the end of the run.
    pub final_eta: f64,
    pub final_margin: f64,
    /// Time of the first alarm \[s\] (`null`: none).
    pub first_alarm_s: Option<f64>,
    /// Alarm episodes ([`StabilityMonitor::alarm_count`]).
    pub alarm_count: usize,
    /// Energy the transfer system added at the interface over the run \[J\].
    pub added_energy_j: f64,
    /// The identified values at the end of the run, per coupling DOF.
    pub identified: IdentifiedSummary,
    /// `on`, or `off: ` and why the model view does not run.
    pub model_view: String,
    /// The first alarm.
    pub alarm: Option<AlarmSummary>,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct IdentifiedSummary {
    /// Stiffness \[N/m\], damping \[N s/m\] and lag \[s\] per coupling DOF.
    pub stiffness: Vec<f64>,
    pub damping: Vec<f64>,
    pub lag_s: Vec<f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AlarmSummary {
    /// `energy` or `model`.
    pub view: &'static str,
    pub step: usize,
    pub time: f64,
    pub value: f64,
    pub threshold: f64,
    pub message: String,
}

/// The larger of two values, ignoring NaN.
fn nan_max(a: f64, b: f64) -> f64 {
    if a.is_nan() {
        b
    } else if b.is_nan() {
        a
    } else {
        a.max(b)
    }
}
