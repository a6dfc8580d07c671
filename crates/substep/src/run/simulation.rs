//! Running a [`TestDefinition`]: [`Simulation`] advances the test one step at a time (monolithic
//! integration, or controller + virtual lab for a substructure test) and [`Reference`] integrates
//! the assembled monolithic model alongside, when every specimen is linear.
//!
//! Both are built once (all allocation happens in the constructors) and then stepped; the
//! caller records whatever it needs between steps.

use crate::error::{Error, Result};
use crate::integrate::{Integrator, Kinematics, Scheme};
use crate::io::config::{EXACT_REFERENCE_MAX_DOFS, TestDefinition};
use crate::material::MaterialSpec;
use crate::model::Model;
use crate::model::SpringSpec;
use crate::site::{Mode, RemoteStepTest};
use crate::specimen::{FrictionModel, SpecimenSpec, assemble_monolithic_model};
use crate::substructure::{
    CouplingController, ExperimentalSubstructure, ExplicitController, StepRecord, SubstepObserver, SubstructureTest,
};
use nalgebra::{DMatrix, DVector};

enum Engine {
    Monolithic {
        integrator: Box<dyn Integrator>,
        mass_influence: DVector<f64>,
        load: DVector<f64>,
        /// A constant load held from the static preload on (gravity).
        static_load: Option<DVector<f64>>,
    },
    Substructured(Box<SubstructureTest>),
    /// A CR / KR-α substructure test (docs/theory.md §2.9).
    Explicit(Box<SubstructureTest<ExplicitController>>),
    /// A remote site in per-step mode (the site runs the sub-steps).
    RemoteStep(Box<RemoteStepTest>),
}

/// A test in progress.
pub struct Simulation {
    engine: Engine,
    accel: Vec<f64>,
    dt: f64,
    step: usize,
}

impl Simulation {
    /// Build the integrator, or the controller and the virtual lab, at rest at `t = 0`. Input
    /// errors (e.g. an effective stiffness that is not positive definite) name the config.
    pub fn new(def: &TestDefinition) -> Result<Self> {
        Self::build(def).map_err(|e| in_config(e, &def.source))
    }

    fn build(def: &TestDefinition) -> Result<Self> {
        let model = &def.model;
        if def.ground_motion.accel.len() < 2 {
            return Err(Error::invalid("ground_motion", "needs at least two samples (one step)"));
        }
        let accel = def.ground_motion.accel.clone();
        let dt = def.integrator.dt;
        let mass_influence = model.effective_mass_vector();
        let load0 = -&mass_influence * accel[0];
        let springs = match &def.hysteresis {
            Some(h) => Some(h.build(model.n_dofs())?),
            None => None,
        };
        let engine = match &def.substructure {
            None if def.static_load.is_some() => {
                let static_load = def.static_load.clone().expect("checked");
                let Scheme::Newmark { beta, gamma } = def.integrator.scheme else {
                    return Err(Error::invalid(
                        "structure.frame.gravity",
                        "needs an implicit Newmark scheme (Newton–Raphson)",
                    ));
                };
                let springs = match springs {
                    Some(s) => s,
                    None => crate::model::Hysteresis::default().build(model.n_dofs())?,
                };
                let mut newton = crate::integrate::NewmarkNewton::new(
                    model,
                    springs,
                    dt,
                    beta,
                    gamma,
                    def.integrator.newton,
                    &load0,
                )?;
                newton.preload(model, &static_load)?;
                Engine::Monolithic {
                    integrator: Box::new(newton),
                    load: load0,
                    mass_influence,
                    static_load: Some(static_load),
                }
            }
            None => Engine::Monolithic {
                integrator: match springs {
                    Some(springs) => {
                        def.integrator
                            .scheme
                            .build_nonlinear(model, springs, dt, def.integrator.newton, &load0)?
                    }
                    None => def.integrator.scheme.build(model, dt, &load0)?,
                },
                load: load0,
                mass_influence,
                static_load: None,
            },
            Some(s) if s.remote.as_ref().is_some_and(|r| r.mode == Mode::PerStep) => {
                // The site ramps from the predictors and G_cc it is sent; the springs' deviation
                // force is inside the predictor (operator splitting), so a nonlinear numerical
                // substructure needs nothing more from it. The client checks every command.
                let mut test = s.build_remote_step_test(model, dt, &load0)?;
                if let Some(springs) = springs {
                    test.controller.set_springs(springs);
                }
                Engine::RemoteStep(Box::new(test))
            }
            Some(s) if s.explicit.is_some() => {
                let dense = model.dense("a cr or kr_alpha substructure test")?;
                Engine::Explicit(Box::new(s.build_explicit_test(&dense, dt, springs, &load0)?))
            }
            Some(s) => {
                let mut test = s.build_test(model, dt, &load0)?;
                if let Some(springs) = springs {
                    test.controller.set_springs(springs);
                }
                Engine::Substructured(Box::new(test))
            }
        };
        Ok(Self {
            engine,
            accel,
            dt,
            step: 0,
        })
    }

    pub fn dt(&self) -> f64 {
        self.dt
    }
    /// Steps done so far.
    pub fn steps_done(&self) -> usize {
        self.step
    }
    /// Steps of the whole run.
    pub fn steps_total(&self) -> usize {
        self.accel.len() - 1
    }
    /// Time of the current state \[s\].
    pub fn time(&self) -> f64 {
        self.step as f64 * self.dt
    }
    /// Ground acceleration at step `i` [m/s²].
    pub fn ground_acceleration(&self, i: usize) -> f64 {
        self.accel[i]
    }

    /// Current displacement, velocity and acceleration of the numerical DOFs (relative).
    pub fn state(&self) -> &Kinematics {
        match &self.engine {
            Engine::Monolithic { integrator, .. } => integrator.state(),
            Engine::Substructured(test) => test.controller.state(),
            Engine::Explicit(test) => test.controller.state(),
            Engine::RemoteStep(test) => test.controller.state(),
        }
    }

    /// The hysteretic springs of a nonlinear numerical substructure, in their committed state
    /// (`None` for a linear model).
    pub fn springs(&self) -> Option<&crate::model::Springs> {
        match &self.engine {
            Engine::Monolithic { integrator, .. } => integrator.springs(),
            Engine::Substructured(test) => test.controller.springs(),
            Engine::Explicit(test) => test.controller.springs(),
            Engine::RemoteStep(_) => None,
        }
    }

    /// Coupling data of the last step (substructured runs only).
    pub fn coupling(&self) -> Option<StepRecord<'_>> {
        match &self.engine {
            Engine::Monolithic { .. } => None,
            Engine::Substructured(test) => Some(test.record()),
            Engine::Explicit(test) => Some(test.record()),
            Engine::RemoteStep(test) => Some(test.record()),
        }
    }

    /// The experimental side of a local or per-sub-step test (virtual lab, lab target, site),
    /// whichever algorithm drives it.
    pub fn site(&self) -> Option<&dyn ExperimentalSubstructure> {
        match &self.engine {
            Engine::Monolithic { .. } | Engine::RemoteStep(_) => None,
            Engine::Substructured(test) => Some(test.site.as_ref()),
            Engine::Explicit(test) => Some(test.site.as_ref()),
        }
    }

    /// The coupling DOFs (0-based) of a substructured run.
    pub fn coupling_dofs(&self) -> Option<&[usize]> {
        match &self.engine {
            Engine::Monolithic { .. } => None,
            Engine::Substructured(test) => Some(test.controller.coupling_dofs()),
            Engine::Explicit(test) => Some(test.controller.coupling_dofs()),
            Engine::RemoteStep(test) => Some(test.controller.coupling_dofs()),
        }
    }

    /// The substructure test of the sub-step algorithm (controller and experimental side), if
    /// there is one.
    pub fn substructure_test(&self) -> Option<&SubstructureTest> {
        match &self.engine {
            Engine::Monolithic { .. } | Engine::RemoteStep(_) | Engine::Explicit(_) => None,
            Engine::Substructured(test) => Some(test),
        }
    }

    /// Ask for the controlled stop (operator, stability indicator): the next step's first
    /// sub-step ramps the actuators to the safe position (the safety limits' ramp) and the step
    /// fails with [`Error::Stopped`] and `reason`. `false` if this run cannot ramp (no
    /// `[substructure.limits]` on a local or per-sub-step test, or a per-step remote site).
    pub fn request_stop(&mut self, reason: &str) -> bool {
        match &mut self.engine {
            Engine::Substructured(test) => test.site.request_stop(reason),
            Engine::Explicit(test) => test.site.request_stop(reason),
            _ => false,
        }
    }

    /// Advance one step; `observer` sees every sub-step of a substructured run. A non-finite
    /// state gives [`Error::Diverged`]; stepping past the end is an error.
    pub fn step(&mut self, observer: &mut impl SubstepObserver) -> Result<()> {
        let i = self.step;
        if i + 1 >= self.accel.len() {
            return Err(Error::invalid("simulation", "the run is already complete"));
        }
        let (ag_i, ag_next) = (self.accel[i], self.accel[i + 1]);
        match &mut self.engine {
            Engine::Monolithic {
                integrator,
                mass_influence,
                load,
                static_load,
            } => {
                load.copy_from(mass_influence);
                load.scale_mut(-ag_next);
                if let Some(s) = static_load {
                    *load += &*s;
                }
                integrator.step(load);
                if let Some(reason) = integrator.failure() {
                    return Err(Error::Diverged {
                        step: i + 1,
                        time: (i + 1) as f64 * self.dt,
                        reason: reason.to_string(),
                    });
                }
                if !integrator.state().is_finite() {
                    return Err(Error::Diverged {
                        step: i + 1,
                        time: (i + 1) as f64 * self.dt,
                        reason: "the response is no longer finite (NaN or overflow)".into(),
                    });
                }
            }
            Engine::Substructured(test) => test.step(ag_i, ag_next, observer)?,
            Engine::Explicit(test) => test.step(ag_i, ag_next, observer)?,
            Engine::RemoteStep(test) => test.step(ag_i, ag_next, observer)?,
        }
        self.step = i + 1;
        Ok(())
    }
}

/// `CONFIG: what: reason` for input and numerical errors of a defined test, so that every
/// refusal names the config it came from (run-time stops and file errors already say where).
fn in_config(e: Error, source: &str) -> Error {
    match e {
        Error::InvalidInput { what, reason } if !what.starts_with(source) => {
            Error::invalid(format!("{source}: {what}"), reason)
        }
        Error::Numerical { what, reason } if !what.starts_with(source) => {
            Error::numerical(format!("{source}: {what}"), reason)
        }
        other => other,
    }
}

/// One linear specimen inside the assembled model: global DOFs (attached, then internal), its
/// stiffness and damping rows of the attached DOFs, and the coupling index of each attached DOF.
struct SpecimenRows {
    global: Vec<usize>,
    coupling_index: Vec<usize>,
    k_rows: DMatrix<f64>,
    c_rows: DMatrix<f64>,
}

/// The monolithic reference of a substructure test with linear specimens: numerical model plus
/// specimens assembled ([`assemble_monolithic`](crate::specimen::assemble_monolithic)) and integrated exactly (first-order hold) if it
/// has at most [`EXACT_REFERENCE_MAX_DOFS`] DOFs, else with the run's Newmark scheme.
pub struct Reference {
    integrator: Box<dyn Integrator>,
    scheme: &'static str,
    n_numerical: usize,
    n_assembled: usize,
    mass_influence: DVector<f64>,
    load: DVector<f64>,
    specimens: Vec<SpecimenRows>,
    /// Hysteretic specimens: their springs start at this index of the integrator's springs,
    /// one per entry of `hysteretic` = (coupling index, DOF, damping).
    first_specimen_spring: usize,
    hysteretic: Vec<(usize, usize, f64)>,
    force: Vec<f64>,
}

impl Reference {
    /// `None` for monolithic runs and when a specimen has no model to integrate (replayed
    /// forces, rate-dependent friction). Hysteretic specimens (Bouc–Wen, stick–slip friction)
    /// and a nonlinear numerical model give a Newmark + Newton reference. Errors name the config.
    pub fn new(def: &TestDefinition) -> Result<Option<Self>> {
        Self::build(def, false).map_err(|e| in_config(e, &def.source))
    }

    /// The same assembled model integrated with the test's own Newmark scheme (its `β`, `γ`
    /// and `Δt`) whatever its size: the monolithic solution the test would give with an ideal
    /// actuator and converged sub-stepping if the specimen were part of the model. Its distance
    /// from the test is the error the substructuring and the transfer system add, without the
    /// time integration's own error, which the exact reference includes. A cr / kr_alpha test
    /// (`SubstructureDefinition::explicit`) gets its own explicit scheme instead, also on a
    /// nonlinear structure.
    pub fn same_integrator(def: &TestDefinition) -> Result<Option<Self>> {
        Self::build(def, true).map_err(|e| in_config(e, &def.source))
    }

    /// Why a substructure test has no reference (`None`: it has one, or it is monolithic).
    pub fn unavailable(def: &TestDefinition) -> Option<String> {
        let s = def.substructure.as_ref()?;
        if s.specimens.is_empty() {
            return Some("the remote site does not describe its specimens".into());
        }
        s.specimens.iter().find_map(|spec| match spec {
            SpecimenSpec::Replay { .. } => {
                Some("a replayed specimen force has no model to integrate (replay specimen)".into())
            }
            SpecimenSpec::Friction {
                model: FrictionModel::Smooth { .. },
                ..
            } => Some("rate-dependent (smooth) friction has no reference model; stick_slip friction has one".into()),
            _ => None,
        })
    }

    fn build(def: &TestDefinition, same_integrator: bool) -> Result<Option<Self>> {
        let Some(s) = &def.substructure else {
            return Ok(None);
        };
        if s.specimens.is_empty() {
            // a remote site without specimen descriptions: nothing to assemble
            return Ok(None);
        }
        let mut parts = Vec::with_capacity(s.specimens.len());
        let mut linear_specimens = Vec::with_capacity(s.specimens.len());
        // Hysteretic specimens become springs to the ground (with their dashpot) of the
        // assembled model: (DOF, damping, spring).
        let mut hysteretic: Vec<(usize, f64, SpringSpec)> = Vec::new();
        for spec in &s.specimens {
            if let Some(m) = spec.linear_matrices() {
                parts.push(m);
                linear_specimens.push(spec.clone());
                continue;
            }
            let (dof, damping, law, stiffness) = match spec {
                SpecimenSpec::BoucWen { dof, params } => {
                    let mut p = *params;
                    p.damping = 0.0;
                    (
                        *dof,
                        params.damping,
                        MaterialSpec::BoucWen(Box::new(p)),
                        params.stiffness,
                    )
                }
                SpecimenSpec::Friction {
                    dof,
                    slip_force,
                    model: FrictionModel::StickSlip { stiffness },
                    damping,
                } => (
                    *dof,
                    *damping,
                    MaterialSpec::Bilinear {
                        yield_force: *slip_force,
                        hardening: 0.0,
                    },
                    *stiffness,
                ),
                // rate-dependent friction, replayed forces: no model to integrate
                _ => return Ok(None),
            };
            hysteretic.push((
                dof,
                damping,
                SpringSpec {
                    from: None,
                    to: dof,
                    stiffness,
                    law,
                    what: format!("substructure.specimen ({} at DOF {})", spec.kind(), dof + 1),
                },
            ));
        }
        let mut assembled = assemble_monolithic_model(&def.model, &linear_specimens)?;
        for (dof, damping, spring) in &hysteretic {
            assembled = add_to_diagonal(assembled, *dof, spring.stiffness, *damping)?;
        }
        let n = def.model.n_dofs();
        let n_assembled = assembled.n_dofs();
        // The numerical model's springs keep their DOFs (numerical DOFs come first in the
        // assembled model), the specimens' follow.
        let mut springs = def.hysteresis.clone().unwrap_or_default();
        let first_specimen_spring = springs.springs.len();
        springs.springs.extend(hysteretic.iter().map(|h| h.2.clone()));
        let hysteretic_coupling = hysteretic
            .iter()
            .map(|(dof, damping, _)| {
                let ci = s.coupling_dofs.iter().position(|c| c == dof).ok_or_else(|| {
                    Error::invalid(
                        "substructure.specimen",
                        format!("DOF {} is not one of substructure.coupling_dofs", dof + 1),
                    )
                })?;
                Ok((ci, *dof, *damping))
            })
            .collect::<Result<Vec<_>>>()?;
        let nonlinear = !springs.springs.is_empty();
        let exact = n_assembled <= EXACT_REFERENCE_MAX_DOFS && !same_integrator;
        if exact && assembled.is_sparse() {
            assembled = Model::Dense(assembled.dense("the exact reference")?.into_owned());
        }
        let (scheme, name) = if let (true, Some(explicit)) = (same_integrator, s.explicit) {
            // a cr / kr_alpha test: the assembled model with the same explicit scheme
            (explicit, if explicit == Scheme::Cr { "cr" } else { "kr_alpha" })
        } else if nonlinear {
            // Nonlinear: Newmark with the test's β, γ and Δt, Newton–Raphson to convergence.
            (
                Scheme::Newmark {
                    beta: s.beta,
                    gamma: s.gamma,
                },
                "newmark_newton",
            )
        } else if exact {
            (Scheme::Exact, "exact")
        } else {
            (
                Scheme::Newmark {
                    beta: s.beta,
                    gamma: s.gamma,
                },
                "newmark",
            )
        };
        let mass_influence = assembled.effective_mass_vector();
        let load = -&mass_influence * def.ground_motion.accel.first().copied().unwrap_or(0.0);
        let explicit_split = same_integrator && s.explicit.is_some();
        let integrator = if explicit_split {
            // The test's K₀ is the numerical substructure's stiffness: the specimens' stiffness
            // enters only through the measured force, so the monolithic counterpart keeps it out
            // of the integration-parameter matrices too.
            let dense = assembled.dense("the same-integrator reference of a cr / kr_alpha test")?;
            let mut k0 = DMatrix::zeros(n_assembled, n_assembled);
            k0.view_mut((0, 0), (n, n))
                .copy_from(&def.model.dense("the numerical substructure")?.stiffness);
            let rho_inf = match scheme {
                Scheme::KrAlpha { rho_inf } => Some(rho_inf),
                _ => None,
            };
            let springs = if nonlinear {
                Some(springs.build(n_assembled)?)
            } else {
                None
            };
            Box::new(crate::integrate::KrAlpha::with_parameter_stiffness(
                &dense,
                &k0,
                def.integrator.dt,
                rho_inf,
                springs,
                &load,
            )?)
        } else if nonlinear {
            scheme.build_nonlinear(
                &assembled,
                springs.build(n_assembled)?,
                def.integrator.dt,
                def.integrator.newton,
                &load,
            )?
        } else {
            scheme.build(&assembled, def.integrator.dt, &load)?
        };
        // Same DOF numbering as assemble_monolithic: internal DOFs appended in specimen order.
        let mut next = n;
        let specimens = parts
            .iter()
            .map(|p| {
                let n_a = p.dofs.len();
                let n_p = p.stiffness.nrows();
                let global: Vec<usize> = p.dofs.iter().copied().chain(next..next + n_p - n_a).collect();
                next += n_p - n_a;
                let coupling_index = p
                    .dofs
                    .iter()
                    .map(|d| {
                        s.coupling_dofs.iter().position(|c| c == d).ok_or_else(|| {
                            Error::invalid(
                                "substructure.specimen",
                                format!("DOF {} is not one of substructure.coupling_dofs", d + 1),
                            )
                        })
                    })
                    .collect::<Result<_>>()?;
                Ok(SpecimenRows {
                    global,
                    coupling_index,
                    k_rows: p.stiffness.rows(0, n_a).into_owned(),
                    c_rows: p.damping.rows(0, n_a).into_owned(),
                })
            })
            .collect::<Result<_>>()?;
        Ok(Some(Self {
            integrator,
            scheme: name,
            n_numerical: n,
            n_assembled,
            mass_influence,
            load,
            specimens,
            first_specimen_spring,
            hysteretic: hysteretic_coupling,
            force: vec![0.0; s.coupling_dofs.len()],
        }))
    }

    /// `exact`, `newmark` or, for a nonlinear model, `newmark_newton`.
    pub fn scheme(&self) -> &'static str {
        self.scheme
    }
    /// DOFs of the assembled model.
    pub fn n_dofs(&self) -> usize {
        self.n_assembled
    }

    /// Advance to the next step, ground acceleration `ag_next` at its end. A nonlinear
    /// reference whose Newton iteration fails is an error naming the reference.
    pub fn step(&mut self, ag_next: f64) -> Result<()> {
        self.load.copy_from(&self.mass_influence);
        self.load.scale_mut(-ag_next);
        self.integrator.step(&self.load);
        if let Some(reason) = self.integrator.failure() {
            return Err(Error::numerical("the monolithic reference", reason.to_string()));
        }
        let s = self.integrator.state();
        self.force.iter_mut().for_each(|f| *f = 0.0);
        for p in &self.specimens {
            for (li, &ci) in p.coupling_index.iter().enumerate() {
                let mut acc = 0.0;
                for (lj, &g) in p.global.iter().enumerate() {
                    acc += p.k_rows[(li, lj)] * s.u[g] + p.c_rows[(li, lj)] * s.v[g];
                }
                self.force[ci] -= acc;
            }
        }
        if let Some(springs) = self.integrator.springs() {
            for ((ci, dof, damping), (_, spring_force)) in self
                .hysteretic
                .iter()
                .zip(springs.states().skip(self.first_specimen_spring))
            {
                self.force[*ci] -= spring_force + damping * s.v[*dof];
            }
        }
        Ok(())
    }

    /// Displacements of the numerical DOFs \[m\].
    pub fn u(&self) -> &[f64] {
        &self.integrator.state().u.as_slice()[..self.n_numerical]
    }
    /// Force of the specimens on the structure at each coupling DOF \[N\].
    pub fn coupling_force(&self) -> &[f64] {
        &self.force
    }
}

/// `model` with `stiffness` and `damping` added on the diagonal at `dof` (a spring and dashpot to
/// the ground).
fn add_to_diagonal(model: Model, dof: usize, stiffness: f64, damping: f64) -> Result<Model> {
    Ok(match model {
        Model::Dense(mut m) => {
            m.stiffness[(dof, dof)] += stiffness;
            m.damping[(dof, dof)] += damping;
            Model::Dense(m)
        }
        Model::Sparse(m) => {
            let n = m.n_dofs();
            let k = crate::sparse::CscMatrix::from_triplets(n, &[(dof, dof, stiffness)]);
            let c = crate::sparse::CscMatrix::from_triplets(n, &[(dof, dof, damping)]);
            let stiffness = crate::sparse::CscMatrix::linear_combination(&[(1.0, &m.stiffness), (1.0, &k)]);
            let damping = crate::sparse::CscMatrix::linear_combination(&[(1.0, &m.damping), (1.0, &c)]);
            Model::Sparse(crate::model::SparseModel::new(
                m.mass,
                damping,
                stiffness,
                Some(m.influence),
            )?)
        }
    })
}
