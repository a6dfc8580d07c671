//! The analysis model of docs/theory.md §9.3: numerical SDOF (`m`, `c`, `k`) with a TMD specimen
//! (`m_s`, `c_s`, `k_s`) on an actuator, in dimensionless form (`m = 1`, `ω = 1`, so
//! `Δt = Ω`, `T = 2π`).

use super::StepMap;
use super::converged::converged_parameters;
use crate::compensate::{
    ArxPhaseLagSpec, CompensatedSite, PhaseLagCompensator, PhaseLagDefinition, PhaseLagSpec, Polynomial, Ramp,
};
use crate::error::{Error, Result, require_non_negative, require_positive};
use crate::integrate::KrAlpha;
use crate::material::MaterialSpec;
use crate::model::{Hysteresis, SpringSpec, StructuralModel, TmdSystem, sdof, tmd_two_dof};
use crate::specimen::SpecimenSpec;
use crate::substructure::{
    ErrorForceSpec, ExperimentalSubstructure, ExplicitController, SubstepController, SubstepSettings, SubstructureTest,
};
use crate::transfer::{ActuatorSpec, Dynamics, SensorSpec, VirtualLab};
use nalgebra::DVector;
use std::f64::consts::PI;

/// One parameter point of the analysis model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnalysisCase {
    /// Mass ratio `η_m = m_s/m`.
    pub eta_m: f64,
    /// Frequency ratio `η_f = ω_s/ω`.
    pub eta_f: f64,
    /// Damping ratio of the numerical substructure.
    pub zeta: f64,
    /// Damping ratio of the specimen.
    pub zeta_s: f64,
    /// `Ω = ωΔt`.
    pub omega_dt: f64,
    pub k_sub: usize,
    /// Phase-lag ratio `η_p = τ/Δt` (pure delay of an otherwise ideal actuator).
    pub eta_p: f64,
    pub error_force: ErrorForceSpec,
    /// Phase-lag compensation with frozen parameters (a fixed linear filter), if any.
    pub phase_lag: Option<FrozenPhaseLag>,
    /// Instantaneous over initial stiffness `k_t/k₀` of the numerical substructure: with
    /// `≠ 1` its restoring force is `k₀ u + (k_t − k₀) ũ`, the operator splitting of a
    /// nonlinear model linearised at a yielded (`< 1`) or hardened (`> 1`) state
    /// (docs/theory.md §14.5); `K̂` and the gains keep `k₀`.
    pub stiffness_ratio: f64,
    /// The integrator that drives the test: the sub-step algorithm or CR / KR-α
    /// (docs/theory.md §2.9).
    pub scheme: AnalysisScheme,
}

/// Which algorithm the analysed test runs (docs/theory.md §2.9 for the explicit ones).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum AnalysisScheme {
    /// The sub-step algorithm with Newmark average acceleration.
    #[default]
    SubStep,
    /// The Chen–Ricles algorithm, `K₀` = the numerical substructure's stiffness.
    Cr,
    /// KR-α with `ρ∞`.
    KrAlpha { rho_inf: f64 },
}

impl AnalysisScheme {
    /// `substep`, `cr`, `kr_alpha` (ρ∞ 0.5) or `kr_alpha:RHO`.
    pub fn from_name(what: &str, s: &str) -> Result<Self> {
        match s {
            "substep" | "sub_step" => Ok(Self::SubStep),
            "cr" => Ok(Self::Cr),
            "kr_alpha" => Ok(Self::KrAlpha { rho_inf: 0.5 }),
            _ => match s.split_once(':') {
                Some(("kr_alpha", r)) => match r.trim().parse::<f64>() {
                    Ok(rho_inf) if (0.0..=1.0).contains(&rho_inf) => Ok(Self::KrAlpha { rho_inf }),
                    _ => Err(Error::invalid(
                        what,
                        format!("ρ∞ of kr_alpha:RHO must be a number in [0, 1], got '{r}'"),
                    )),
                },
                _ => Err(Error::invalid(
                    what,
                    format!("expected substep, cr, kr_alpha or kr_alpha:RHO, got '{s}'"),
                )),
            },
        }
    }
    /// For figure titles: `sub-step algorithm`, `CR`, `KR-α ρ∞ = 0.5`.
    pub fn label(self) -> String {
        match self {
            Self::SubStep => "sub-step algorithm".into(),
            Self::Cr => "CR".into(),
            Self::KrAlpha { rho_inf } => format!("KR-α ρ∞ = {rho_inf}"),
        }
    }
}

/// A phase-lag compensator for the linear analysis: frozen, full from the first sub-step, on
/// the actuator of the analysis model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FrozenPhaseLag {
    /// Polynomial extrapolation of order `order` (1..=3) with the lead `η_p · k_sub` sub-steps
    /// (the actuator delay).
    Polynomial { order: usize },
    /// The ARX compensator by identification (`kind = "arx"` at its defaults for the delay
    /// `η_p · k_sub` sub-steps), frozen at the parameters it converges to in front of the
    /// actuator under the two modal frequencies of the assembled system
    /// ([`super::converged::converged_parameters`]).
    Arx,
}

/// Parameters that maps and series vary.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Parameter {
    ZetaS,
    Zeta,
    EtaF,
    EtaM,
    EtaP,
    /// `η_T = Δt/T = Ω/2π`.
    EtaT,
    Omega,
    /// `k_t/k₀` of the numerical substructure.
    StiffnessRatio,
}

impl Parameter {
    pub fn from_name(name: &str) -> Result<Self> {
        Ok(match name {
            "zeta_s" => Parameter::ZetaS,
            "zeta" => Parameter::Zeta,
            "eta_f" => Parameter::EtaF,
            "eta_m" => Parameter::EtaM,
            "eta_p" => Parameter::EtaP,
            "eta_t" | "eta_T" => Parameter::EtaT,
            "omega" | "Omega" => Parameter::Omega,
            "stiffness_ratio" => Parameter::StiffnessRatio,
            other => {
                return Err(Error::invalid(
                    "parameter",
                    format!(
                        "unknown parameter '{other}' (expected zeta_s, zeta, eta_f, eta_m, eta_p, eta_T, Omega or \
                         stiffness_ratio)"
                    ),
                ));
            }
        })
    }
    pub fn name(self) -> &'static str {
        match self {
            Parameter::ZetaS => "zeta_s",
            Parameter::Zeta => "zeta",
            Parameter::EtaF => "eta_f",
            Parameter::EtaM => "eta_m",
            Parameter::EtaP => "eta_p",
            Parameter::EtaT => "eta_T",
            Parameter::Omega => "Omega",
            Parameter::StiffnessRatio => "stiffness_ratio",
        }
    }
    /// The symbol for figures and tables (`η_m`, `ζ_s`, `Ω`, …).
    pub fn symbol(self) -> &'static str {
        match self {
            Parameter::ZetaS => "ζ_s",
            Parameter::Zeta => "ζ",
            Parameter::EtaF => "η_f",
            Parameter::EtaM => "η_m",
            Parameter::EtaP => "η_p",
            Parameter::EtaT => "η_T",
            Parameter::Omega => "Ω",
            Parameter::StiffnessRatio => "k_t/k₀",
        }
    }
}

impl AnalysisCase {
    /// "Typical TMD system": `η_m = 5 %`, `ζ = 5 %`, `ζ_s = 10 %`, `η_f = 1`.
    pub fn typical_tmd() -> Self {
        Self {
            eta_m: 0.05,
            eta_f: 1.0,
            zeta: 0.05,
            zeta_s: 0.10,
            omega_dt: 0.1,
            k_sub: 1,
            eta_p: 0.0,
            error_force: ErrorForceSpec::None,
            phase_lag: None,
            stiffness_ratio: 1.0,
            scheme: AnalysisScheme::SubStep,
        }
    }
    /// "Coupled system with large mass ratio": `η_m = 50 %`, `ζ = ζ_s = 5 %`, `η_f = 1`.
    pub fn large_mass_ratio() -> Self {
        Self {
            eta_m: 0.5,
            zeta_s: 0.05,
            ..Self::typical_tmd()
        }
    }

    pub fn with(mut self, p: Parameter, value: f64) -> Self {
        match p {
            Parameter::ZetaS => self.zeta_s = value,
            Parameter::Zeta => self.zeta = value,
            Parameter::EtaF => self.eta_f = value,
            Parameter::EtaM => self.eta_m = value,
            Parameter::EtaP => self.eta_p = value,
            Parameter::EtaT => self.omega_dt = 2.0 * PI * value,
            Parameter::Omega => self.omega_dt = value,
            Parameter::StiffnessRatio => self.stiffness_ratio = value,
        }
        self
    }

    pub fn get(&self, p: Parameter) -> f64 {
        match p {
            Parameter::ZetaS => self.zeta_s,
            Parameter::Zeta => self.zeta,
            Parameter::EtaF => self.eta_f,
            Parameter::EtaM => self.eta_m,
            Parameter::EtaP => self.eta_p,
            Parameter::EtaT => self.omega_dt / (2.0 * PI),
            Parameter::Omega => self.omega_dt,
            Parameter::StiffnessRatio => self.stiffness_ratio,
        }
    }

    pub fn validate(&self) -> Result<()> {
        require_positive("eta_m", self.eta_m)?;
        require_positive("eta_f", self.eta_f)?;
        require_non_negative("zeta", self.zeta)?;
        require_non_negative("zeta_s", self.zeta_s)?;
        require_positive("Omega", self.omega_dt)?;
        require_non_negative("eta_p", self.eta_p)?;
        require_non_negative("stiffness_ratio", self.stiffness_ratio)?;
        if self.k_sub == 0 {
            return Err(Error::invalid("k_sub", "must be at least 1"));
        }
        if self.scheme != AnalysisScheme::SubStep && self.error_force != ErrorForceSpec::None {
            return Err(Error::invalid(
                "error_force",
                "error-force compensation belongs to the sub-step algorithm, not to cr or kr_alpha",
            ));
        }
        self.error_force.validate()
    }

    fn system(&self) -> TmdSystem {
        TmdSystem {
            mass: 1.0,
            frequency: 1.0 / (2.0 * PI),
            zeta: self.zeta,
            eta_m: self.eta_m,
            eta_f: self.eta_f,
            zeta_s: self.zeta_s,
        }
    }

    /// `Δt` of the dimensionless model (`ω = 1`).
    pub fn dt(&self) -> f64 {
        self.omega_dt
    }

    /// The assembled 2-DOF model (DOF 1 primary, DOF 2 TMD), the exact reference.
    pub fn assembled_model(&self) -> Result<StructuralModel> {
        tmd_two_dof(&self.system())
    }

    /// The substructure test of this case: numerical SDOF, TMD specimen on a delayed ideal
    /// actuator, Newmark average acceleration, noise-free sensors; with `phase_lag`, the lab is
    /// wrapped in a frozen [`CompensatedSite`].
    pub fn build_test(&self) -> Result<SubstructureTest> {
        self.validate()?;
        let sys = self.system();
        let (k, c) = sys.primary();
        let model = sdof(1.0, c, k)?;
        let settings = SubstepSettings {
            dt: self.dt(),
            beta: 0.25,
            gamma: 0.5,
            substeps: self.k_sub,
            coupling_dofs: vec![0],
            error_force: self.error_force,
        };
        let mut controller = SubstepController::new(&model, &settings, &DVector::zeros(1))?;
        if let Some(springs) = self.springs(k)? {
            controller.set_springs(springs);
        }
        SubstructureTest::new(&model, controller, self.site()?)
    }

    /// The same case driven by CR or KR-α ([`Self::scheme`]; docs/theory.md §2.9): `K₀` is the
    /// numerical substructure's stiffness, the specimen is measured.
    pub fn build_explicit_test(&self) -> Result<SubstructureTest<ExplicitController>> {
        self.validate()?;
        let sys = self.system();
        let (k, c) = sys.primary();
        let model = sdof(1.0, c, k)?;
        let springs = self.springs(k)?;
        let zero = DVector::zeros(1);
        let scheme = match self.scheme {
            AnalysisScheme::Cr => KrAlpha::cr(&model, self.dt(), springs, &zero)?,
            AnalysisScheme::KrAlpha { rho_inf } => KrAlpha::with_rho_inf(&model, self.dt(), rho_inf, springs, &zero)?,
            AnalysisScheme::SubStep => {
                return Err(Error::invalid("scheme", "the sub-step algorithm's test is build_test"));
            }
        };
        let controller = ExplicitController::new(scheme, &[0], self.k_sub)?;
        SubstructureTest::new(&model, controller, self.site()?)
    }

    /// The operator splitting's spring of a `stiffness_ratio ≠ 1` (initial stiffness `k`).
    fn springs(&self, k: f64) -> Result<Option<crate::model::Springs>> {
        if self.stiffness_ratio == 1.0 {
            return Ok(None);
        }
        let springs = Hysteresis {
            springs: vec![SpringSpec {
                from: None,
                to: 0,
                stiffness: k,
                law: MaterialSpec::Scaled {
                    ratio: self.stiffness_ratio,
                },
                what: "stiffness_ratio".into(),
            }],
            p_delta: Vec::new(),
        };
        Ok(Some(springs.build(1)?))
    }

    /// The experimental side: TMD specimen on a delayed ideal actuator, noise-free sensors, and
    /// the frozen phase-lag compensation if any.
    fn site(&self) -> Result<Box<dyn ExperimentalSubstructure>> {
        let sys = self.system();
        let (ms, ks, cs) = sys.absorber();
        let actuator = ActuatorSpec {
            dynamics: Dynamics::Ideal,
            delay: self.eta_p * self.dt(),
        };
        let specimen = SpecimenSpec::LinearSdof {
            dof: 0,
            mass: Some(ms),
            stiffness: ks,
            damping: cs,
        };
        let lab = VirtualLab::from_specs(
            &[0],
            &[specimen],
            std::slice::from_ref(&actuator),
            &[SensorSpec::ideal()],
            &[SensorSpec::ideal()],
            self.dt() / self.k_sub as f64,
            1,
        )?;
        let site: Box<dyn ExperimentalSubstructure> = match self.phase_lag {
            None => Box::new(lab),
            Some(FrozenPhaseLag::Polynomial { order }) => {
                let lead = self.eta_p * self.k_sub as f64;
                let comp: Box<dyn PhaseLagCompensator> = Box::new(Polynomial::new(order, lead)?);
                let mut site = CompensatedSite::new(Box::new(lab), vec![comp], Ramp::full())?;
                site.set_frozen(true);
                Box::new(site)
            }
            Some(FrozenPhaseLag::Arx) => {
                let def = PhaseLagDefinition {
                    spec: PhaseLagSpec::Arx(ArxPhaseLagSpec::for_substeps(
                        self.eta_p * self.k_sub as f64,
                        self.k_sub,
                    )),
                    ramp: Ramp::full(),
                };
                let modes = self.assembled_model()?.modes()?;
                let freqs: Vec<f64> = modes.omega.iter().map(|w| w / (2.0 * PI)).collect();
                let dtau = self.dt() / self.k_sub as f64;
                let theta = converged_parameters(&def, &actuator, dtau, 1, &freqs)?;
                let mut site = def.wrap(Box::new(lab))?;
                if let Some(t) = &theta {
                    site.set_parameters(t);
                }
                site.set_frozen(true);
                Box::new(site)
            }
        };
        Ok(site)
    }

    pub fn step_map(&self) -> Result<StepMap> {
        match self.scheme {
            AnalysisScheme::SubStep => StepMap::probe(&mut self.build_test()?),
            _ => StepMap::probe(&mut self.build_explicit_test()?),
        }
    }

    /// `ρ` of the step map. Probes only `A` (the load vectors `B0`, `B1` do not enter `ρ`), so
    /// it equals `self.step_map()?.spectral_radius()` exactly at two probing steps less.
    pub fn spectral_radius(&self) -> Result<f64> {
        let a = match self.scheme {
            AnalysisScheme::SubStep => StepMap::probe_transition(&mut self.build_test()?)?,
            _ => StepMap::probe_transition(&mut self.build_explicit_test()?)?,
        };
        Ok(super::amplification::spectral_radius_of(&a))
    }
}
