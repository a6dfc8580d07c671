//! The virtual substructure test (VST) study of the dissertation's chapter 9, as a library
//! driver: every compensation method on one set-up against the exact reference.
//!
//! A 3-storey shear frame (3 × 1000 kg, first mode 1 Hz, 2 % modal damping) is the numerical
//! substructure; a TMD-like linear specimen (150 kg, tuned to 0.95 Hz, 10 % damping) on the top
//! floor is the experimental substructure, behind a servo-hydraulic actuator (second order,
//! 40 Hz, ζ = 0.7, plus a pure delay, 10 ms by default) with 1 % force noise (standard deviation
//! 1 % of the peak coupling force of the exact reference). Ground motion: a sine sweep.
//! `Δt = 0.01 s`, `k_sub = 4` (`Δτ = 2.5 ms`).
//!
//! Every method runs on the same set-up and noise sequence and is compared with the exact
//! solution of the assembled model (`assemble_monolithic` + `Scheme::Exact`, through
//! [`crate::run::Reference`]). [`run_study`] returns the numbers ([`Study`]: per-step series and
//! error statistics per method, [`acceptance`] the verdicts); [`report`] turns them into the
//! files of `substep vst` (`vst.md`, `vst.csv`, the figures; the damper grid's
//! `damper_grid.md`, `.csv`; docs/vst.md).
//!
//! ```
//! use substep::study::vst::{VstSettings, run_study};
//! // A 1.5 s sweep keeps the example fast; `VstSettings::quick` is the 12 s study.
//! let settings = VstSettings { duration: 1.5, settle: 0.5, ..VstSettings::quick(0.010) };
//! let study = run_study(&settings).unwrap();
//! let none = study.run("none");
//! assert!(none.completed);
//! // The identified phase-lag compensation tracks better than no compensation.
//! assert!(study.run("pl_arx").tracking_rms < none.tracking_rms);
//! assert!(study.sigma > 0.0 && study.ref_peak_u > 0.0);
//! ```

pub mod grid;
pub mod report;
mod run;

pub use run::{RunResult, Series, Study, acceptance, run_study};

use crate::Result;
use crate::compensate::{ArxPhaseLagSpec, InverseFirSpec, PhaseLagDefinition, PhaseLagSpec, Ramp};
use crate::excitation::sine_sweep;
use crate::integrate::Scheme;
use crate::io::config::{GroundMotion, IntegratorDefinition, OutputSettings, SubstructureDefinition, TestDefinition};
use crate::model::{DampingSpec, ShearBuilding, StructuralModel, shear_building};
use crate::specimen::SpecimenSpec;
use crate::substructure::ErrorForceSpec;
use crate::transfer::{ActuatorSpec, Dynamics, SensorSpec};

/// The set-up of the study.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VstSettings {
    /// Length of the sine sweep \[s\].
    pub duration: f64,
    /// Sweep range \[Hz\] and amplitude \[m/s²\].
    pub f0: f64,
    pub f1: f64,
    pub amplitude: f64,
    /// Pure delay of the actuator \[s\].
    pub delay: f64,
    /// Force noise as a fraction of the reference's peak coupling force.
    pub noise_ratio: f64,
    pub dt: f64,
    pub k_sub: usize,
    /// Phase-lag ramp-in \[steps\] (from t = 0).
    pub ramp_steps: usize,
    /// Statistics of tracking and error force from this time on \[s\] (after ramp-in and warm-up).
    pub settle: f64,
}

impl VstSettings {
    pub fn full(delay: f64) -> Self {
        Self {
            duration: 60.0,
            f0: 0.3,
            f1: 5.0,
            amplitude: 1.0,
            delay,
            noise_ratio: 0.01,
            dt: 0.01,
            k_sub: 4,
            ramp_steps: 100,
            settle: 2.0,
        }
    }
    pub fn quick(delay: f64) -> Self {
        Self {
            duration: 12.0,
            ..Self::full(delay)
        }
    }
    /// The sub-step `Δτ = Δt/k_sub` \[s\].
    pub fn dtau(&self) -> f64 {
        self.dt / self.k_sub as f64
    }
    /// The actuator delay in sub-steps.
    fn delay_substeps(&self) -> f64 {
        self.delay / self.dtau()
    }
}

/// Actuator: second order 40 Hz, ζ = 0.7, plus the delay.
pub const ACTUATOR_HZ: f64 = 40.0;
pub const ACTUATOR_ZETA: f64 = 0.7;
/// Specimen: 150 kg TMD tuned to 0.95 Hz with 10 % damping.
pub const TMD_MASS: f64 = 150.0;
pub const TMD_HZ: f64 = 0.95;
pub const TMD_ZETA: f64 = 0.10;
/// Order of the error-force estimation in the main runs.
const MAIN_ORDER: usize = 4;
/// The orders of the n_u series.
pub const ORDERS: [usize; 6] = [2, 3, 4, 5, 8, 12];
/// Top floor (0-based), the coupling DOF.
pub(crate) const TOP: usize = 2;

/// Which compensation a run uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Method {
    pub key: &'static str,
    pub name: &'static str,
    pub error_force: ErrorForceSpec,
    pub phase_lag: Option<PhaseLagSpec>,
    /// Part of the n_u series (second table) rather than the main comparison.
    pub series: bool,
}

fn arx_ef(order: usize) -> ErrorForceSpec {
    ErrorForceSpec::Arx {
        order,
        lambda: 0.98,
        p0: 100.0,
    }
}

/// The methods of the study.
pub fn methods(s: &VstSettings) -> Vec<Method> {
    let lead = s.delay_substeps();
    let total_lag = (s.delay + 2.0 * ACTUATOR_ZETA / (2.0 * std::f64::consts::PI * ACTUATOR_HZ)) / s.dtau();
    // What `[substructure.phase_lag] kind = "arx"` gives for this actuator.
    let arx_pl = PhaseLagSpec::Arx(ArxPhaseLagSpec::for_substeps(total_lag, s.k_sub));
    let pid = ErrorForceSpec::Pid { p: 1.0, i: 0.0, d: 0.0 };
    let poly = |order, lead| PhaseLagSpec::Polynomial {
        order,
        lead,
        spacing: 1,
        guard_factor: 10.0,
    };
    let m = |key, name, error_force, phase_lag| Method {
        key,
        name,
        error_force,
        phase_lag,
        series: false,
    };
    let mut v = vec![
        m("none", "(a) no compensation", ErrorForceSpec::None, None),
        m(
            "ef_arx",
            "(b) error force: estimation (ARX, n_u = 4)",
            arx_ef(MAIN_ORDER),
            None,
        ),
        m(
            "pl_arx",
            "(c) phase lag: identification (ARX)",
            ErrorForceSpec::None,
            Some(arx_pl),
        ),
        m("both", "(d) both: (b) + (c)", arx_ef(MAIN_ORDER), Some(arx_pl)),
        m("pid", "error force: PID P = 1", pid, None),
        m(
            "poly_delay",
            "phase lag: polynomial p = 3, lead = delay",
            ErrorForceSpec::None,
            Some(poly(3, lead)),
        ),
        m(
            "poly_lag",
            "phase lag: polynomial p = 2, lead = delay + 2ζ/ω_a",
            ErrorForceSpec::None,
            Some(poly(2, total_lag)),
        ),
        m(
            "inverse_fir",
            "phase lag: inverse FIR",
            ErrorForceSpec::None,
            Some(PhaseLagSpec::InverseFir(InverseFirSpec::new(lead))),
        ),
        m("pid_pl_arx", "PID P = 1 + (c)", pid, Some(arx_pl)),
    ];
    const SERIES_KEYS: [&str; 6] = ["ef_arx_2", "ef_arx_3", "ef_arx_4", "ef_arx_5", "ef_arx_8", "ef_arx_12"];
    const SERIES_NAMES: [&str; 6] = [
        "estimation n_u = 2",
        "estimation n_u = 3",
        "estimation n_u = 4",
        "estimation n_u = 5",
        "estimation n_u = 8",
        "estimation n_u = 12",
    ];
    for (k, &n) in ORDERS.iter().enumerate() {
        v.push(Method {
            key: SERIES_KEYS[k],
            name: SERIES_NAMES[k],
            error_force: arx_ef(n),
            phase_lag: None,
            series: true,
        });
    }
    v
}

/// The numerical substructure: 3 floors × 1000 kg, first period 1 s, 2 % modal damping.
fn structure() -> Result<StructuralModel> {
    let b = ShearBuilding {
        stories: 3,
        story_mass: 1000.0,
        first_period: 1.0,
    };
    shear_building(&b)?.with_damping(&DampingSpec::Modal { zeta: vec![0.02] })
}

fn specimen() -> SpecimenSpec {
    let w = 2.0 * std::f64::consts::PI * TMD_HZ;
    SpecimenSpec::LinearSdof {
        dof: TOP,
        mass: Some(TMD_MASS),
        stiffness: TMD_MASS * w * w,
        damping: 2.0 * TMD_ZETA * TMD_MASS * w,
    }
}

/// The test definition of one run (force noise `sigma` \[N\]).
pub(crate) fn definition(s: &VstSettings, sigma: f64, method: &Method) -> Result<TestDefinition> {
    let record = sine_sweep(s.amplitude, s.f0, s.f1, s.duration, s.dt)?;
    let steps = record.accel.len() - 1;
    let (beta, gamma) = (0.25, 0.5);
    let substructure = SubstructureDefinition {
        coupling_dofs: vec![TOP],
        substeps: s.k_sub,
        inner_steps: 10,
        specimens: vec![specimen()],
        actuator: ActuatorSpec {
            dynamics: Dynamics::SecondOrder {
                frequency_hz: ACTUATOR_HZ,
                zeta: ACTUATOR_ZETA,
            },
            delay: s.delay,
        },
        force_sensors: vec![SensorSpec {
            noise_std: sigma,
            seed: 11,
            ..SensorSpec::ideal()
        }],
        displacement_sensors: vec![SensorSpec::ideal()],
        error_force: method.error_force,
        beta,
        gamma,
        explicit: None,
        phase_lag: method.phase_lag.map(|spec| PhaseLagDefinition {
            spec,
            ramp: Ramp::new(0, s.ramp_steps * s.k_sub),
        }),
        remote: None,
        lab_target: None,
        limits: None,
        stability_off: false,
        lab: Default::default(),
        controller: None,
        controller_feedforward: None,
        delay_ramp: None,
    };
    Ok(TestDefinition {
        source: format!("vst: {}", method.name),
        model: structure()?.into(),
        hysteresis: None,
        static_load: None,
        ground_motion: GroundMotion {
            accel: record.accel,
            description: format!(
                "linear sine sweep {}–{} Hz, {} m/s², {} s",
                s.f0, s.f1, s.amplitude, s.duration
            ),
        },
        integrator: IntegratorDefinition {
            name: "average_acceleration".into(),
            scheme: Scheme::Newmark { beta, gamma },
            dt: s.dt,
            steps,
            newton: Default::default(),
        },
        substructure: Some(substructure),
        output: OutputSettings {
            dir: None,
            plots: false,
            plot_options: Default::default(),
            format: Default::default(),
        },
        monitor: Default::default(),
        realtime: Default::default(),
        reduction: None,
    })
}
