//! The damper grid: phase-lag compensation by identification on tests nobody tuned it for
//! (docs/vst.md, "The damper grid"; docs/theory.md §6.4).
//!
//! A 3-storey shear building (3 × 200 t, storey stiffness 200 MN/m, Rayleigh damping 2 % at
//! modes 1 and 2) with a viscous damper `c` between the ground and floor 1 as the specimen,
//! behind an actuator with a pure delay (optionally after second-order dynamics), `Δt = 10 ms`,
//! P = 1 error-force compensation, the first 30 s of El Centro (the RTHS benchmark's record,
//! unscaled). Every setting of dampers × delays × `k_sub` runs twice — without phase-lag
//! compensation and with `[substructure.phase_lag] kind = "arx"` at its defaults — and is
//! compared with the exact solution of the assembled structure (the run's `reference`):
//! [`damper_grid`] returns one [`GridRow`] per setting. Each run is a config exactly as a user
//! writes it ([`config_text`]); the record replaces the config's placeholder motion.

use crate::Result;
use crate::benchmark::rths::GroundRecord;
use crate::io::TestDefinition;
use crate::run::exceeds;
use rayon::prelude::*;
use std::path::Path;

/// Time step of every run \[s\].
pub const GRID_DT: f64 = 0.01;
/// Length of every run \[s\].
pub const GRID_DURATION: f64 = 30.0;

/// The actuator in front of the delay.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GridActuator {
    /// `kind = "ideal"` with the delay (the specimen follows the delayed command linearly).
    PureDelay,
    /// `kind = "second_order"`, `frequency` \[Hz\], `zeta`, with the delay.
    SecondOrder { frequency: f64, zeta: f64 },
}

impl GridActuator {
    pub fn name(&self) -> String {
        match self {
            GridActuator::PureDelay => "pure delay".into(),
            GridActuator::SecondOrder { frequency, zeta } => {
                format!("second order {frequency} Hz, ζ = {zeta}, + delay")
            }
        }
    }
}

/// What the grid spans.
#[derive(Debug, Clone, PartialEq)]
pub struct GridSettings {
    /// Damper coefficients \[N·s/m\].
    pub dampers: Vec<f64>,
    /// Actuator delays \[s\].
    pub delays: Vec<f64>,
    pub k_subs: Vec<usize>,
    pub actuator: GridActuator,
}

impl GridSettings {
    /// Dampers 1, 2.5 and 5 MN·s/m (5×), delays of half a step to two steps (5, 10, 15, 20 ms),
    /// `k_sub` 1, 2, 3, 5, 10: 60 settings.
    pub fn full(actuator: GridActuator) -> Self {
        Self {
            dampers: vec![1.0e6, 2.5e6, 5.0e6],
            delays: vec![0.005, 0.010, 0.015, 0.020],
            k_subs: vec![1, 2, 3, 5, 10],
            actuator,
        }
    }
}

/// One setting: the error of both runs against the exact reference (largest displacement
/// error over the run and the floors, relative to the peak; NaN without a reference), the same
/// against the assembled structure integrated with the test's own Newmark scheme (the summary's
/// [`crate::run::SameIntegratorSummary`]), and how each ended.
#[derive(Debug, Clone, PartialEq)]
pub struct GridRow {
    pub damper: f64,
    pub delay: f64,
    pub k_sub: usize,
    pub error_none: f64,
    pub error_arx: f64,
    /// The errors against the same-integrator reference (NaN for a run that ended early).
    pub integrator_error_none: f64,
    pub integrator_error_arx: f64,
    /// That Newmark solution against the exact one: the time step's own error, the error of a
    /// test whose actuator followed its commands perfectly.
    pub time_step_error: f64,
    /// `completed` of each run's summary (false: diverged or stopped).
    pub completed_none: bool,
    pub completed_arx: bool,
    pub diverged_none: bool,
    pub diverged_arx: bool,
    /// The ARX compensator's supervisor backed off (its warning is in the summary).
    pub backed_off: bool,
}

impl GridRow {
    /// `error_arx / error_none`.
    pub fn ratio(&self) -> f64 {
        self.error_arx / self.error_none
    }
    /// `integrator_error_arx / integrator_error_none`.
    pub fn integrator_ratio(&self) -> f64 {
        self.integrator_error_arx / self.integrator_error_none
    }
    /// The uncompensated test is stable (completed, error ≤ 100 %).
    pub fn stable_without(&self) -> bool {
        self.completed_none && !self.diverged_none
    }
    /// The delay is at least one time step.
    pub fn delay_of_a_step_or_more(&self) -> bool {
        self.delay >= GRID_DT - 1e-12
    }
}

/// The config of one run (`phase_lag`: with `kind = "arx"` at its defaults).
pub fn config_text(damper: f64, delay: f64, k_sub: usize, actuator: GridActuator, phase_lag: bool) -> String {
    let actuator = match actuator {
        GridActuator::PureDelay => format!("kind = \"ideal\"\ndelay = {delay}"),
        GridActuator::SecondOrder { frequency, zeta } => {
            format!("kind = \"second_order\"\nfrequency = {frequency}\nzeta = {zeta}\ndelay = {delay}")
        }
    };
    let phase_lag = if phase_lag {
        "\n[substructure.phase_lag]\nkind = \"arx\"\n"
    } else {
        ""
    };
    format!(
        r#"[structure]
mass = [[2.0e5, 0.0, 0.0], [0.0, 2.0e5, 0.0], [0.0, 0.0, 2.0e5]]
stiffness = [[4.0e8, -2.0e8, 0.0], [-2.0e8, 4.0e8, -2.0e8], [0.0, -2.0e8, 2.0e8]]
[structure.rayleigh]
zeta = 0.02

[ground_motion]        # replaced by El Centro (the RTHS benchmark's record)
generator = "harmonic"
amplitude = 1.0
frequency = 1.0
duration = {GRID_DURATION}

[integrator]
scheme = "average_acceleration"
dt = {GRID_DT}

[substructure]
coupling_dofs = [1]
substeps = {k_sub}

[[substructure.specimen]]
kind = "linear_sdof"
dof = 1
stiffness = 0.0
damping = {damper}

[substructure.actuator]
{actuator}

[substructure.error_force]
kind = "pid"
p = 1.0
{phase_lag}"#
    )
}

/// The test definition of one run, with the first [`GRID_DURATION`] s of El Centro.
pub fn definition(
    damper: f64,
    delay: f64,
    k_sub: usize,
    actuator: GridActuator,
    phase_lag: bool,
) -> Result<TestDefinition> {
    let text = config_text(damper, delay, k_sub, actuator, phase_lag);
    let mut def = TestDefinition::from_toml(&text, "damper grid", Path::new("."))?;
    let mut accel = Vec::with_capacity(def.integrator.steps + 1);
    GroundRecord::elcentro().sample_sorted((0..=def.integrator.steps).map(|i| i as f64 * GRID_DT), 1.0, &mut accel);
    def.ground_motion.accel = accel;
    def.ground_motion.description = "El Centro 1940 (RTHS benchmark record, unscaled), 30 s".into();
    // The stability indicator (on by default, warn only) does not change a run's numbers; off,
    // the grid runs ten times faster at k_sub = 10 (its model view probes the test's map).
    if let Some(sub) = &mut def.substructure {
        sub.stability_off = true;
    }
    Ok(def)
}

/// What one run gives.
struct RunResult {
    /// Against the exact reference and against the same-integrator one.
    error: f64,
    integrator_error: f64,
    time_step_error: f64,
    completed: bool,
    diverged: bool,
    backed_off: bool,
}

fn run_one(def: &TestDefinition) -> Result<RunResult> {
    let s = crate::run::execute(
        def,
        &mut super::super::SummaryOnly,
        &std::sync::atomic::AtomicBool::new(false),
    )?;
    let error = s.reference.as_ref().map_or(f64::NAN, |r| r.max_displacement_error);
    let same = s.reference.as_ref().and_then(|r| r.same_integrator.as_ref());
    let (integrator_error, time_step_error) = match (same, s.completed) {
        (Some(x), true) => (x.max_displacement_error, x.integration_error),
        _ => (f64::NAN, f64::NAN),
    };
    Ok(RunResult {
        error,
        integrator_error,
        time_step_error,
        completed: s.completed,
        diverged: s.diverged,
        backed_off: s.warnings.iter().any(|w| w.contains("backed off")),
    })
}

/// Run every setting of `settings` (in parallel; rows in the order dampers × delays × `k_sub`).
pub fn damper_grid(settings: &GridSettings) -> Result<Vec<GridRow>> {
    let mut points = Vec::new();
    for &c in &settings.dampers {
        for &d in &settings.delays {
            for &k in &settings.k_subs {
                points.push((c, d, k));
            }
        }
    }
    points
        .par_iter()
        .map(|&(damper, delay, k_sub)| {
            let none = run_one(&definition(damper, delay, k_sub, settings.actuator, false)?)?;
            let arx = run_one(&definition(damper, delay, k_sub, settings.actuator, true)?)?;
            Ok(GridRow {
                damper,
                delay,
                k_sub,
                error_none: none.error,
                error_arx: arx.error,
                integrator_error_none: none.integrator_error,
                integrator_error_arx: arx.integrator_error,
                time_step_error: none.time_step_error,
                completed_none: none.completed,
                completed_arx: arx.completed,
                diverged_none: none.diverged,
                diverged_arx: arx.diverged,
                backed_off: arx.backed_off,
            })
        })
        .collect()
}

/// The counts of the acceptance lines (docs/vst.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GridCounts {
    pub settings: usize,
    /// Settings whose uncompensated test is stable.
    pub stable_without: usize,
    /// Among those: the compensated test diverged.
    pub diverged_with: usize,
    /// Among those: compensated error > 1.2 × uncompensated.
    pub worse: usize,
    /// Delays ≥ one step, uncompensated stable: how many, and how many at ≤ 0.7 ×.
    pub step_delays: usize,
    pub step_delays_better: usize,
    /// The same two lines against the same-integrator reference: compensated > 1.2 ×
    /// uncompensated (among the settings stable without), and at ≤ 0.7 × among the step delays.
    pub worse_vs_integrator: usize,
    pub step_delays_better_vs_integrator: usize,
    /// The supervisor backed off.
    pub backed_off: usize,
}

pub fn counts(rows: &[GridRow]) -> GridCounts {
    let stable: Vec<&GridRow> = rows.iter().filter(|r| r.stable_without()).collect();
    let step: Vec<&&GridRow> = stable.iter().filter(|r| r.delay_of_a_step_or_more()).collect();
    GridCounts {
        settings: rows.len(),
        stable_without: stable.len(),
        diverged_with: stable.iter().filter(|r| r.diverged_arx || !r.completed_arx).count(),
        worse: stable
            .iter()
            .filter(|r| exceeds(r.error_arx, 1.2 * r.error_none))
            .count(),
        step_delays: step.len(),
        step_delays_better: step.iter().filter(|r| r.error_arx <= 0.7 * r.error_none).count(),
        worse_vs_integrator: stable
            .iter()
            .filter(|r| exceeds(r.integrator_error_arx, 1.2 * r.integrator_error_none))
            .count(),
        step_delays_better_vs_integrator: step
            .iter()
            .filter(|r| r.integrator_error_arx <= 0.7 * r.integrator_error_none)
            .count(),
        backed_off: rows.iter().filter(|r| r.backed_off).count(),
    }
}
