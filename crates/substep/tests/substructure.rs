//! The sub-step algorithm against the assembled (monolithic) model and the exact solution.

use nalgebra::{DMatrix, DVector, dmatrix};
use substep::integrate::Scheme;
use substep::model::{StructuralModel, TmdSystem, sdof, tmd_two_dof};
use substep::specimen::{LinearSpecimen, SpecimenSpec, assemble_monolithic};
use substep::substructure::{
    ErrorForceSpec, ExperimentalSubstructure, SubstepController, SubstepObserver, SubstepSettings, SubstructureTest,
};
use substep::transfer::{ActuatorSpec, AttachedSpecimen, Dynamics, SensorSpec, VirtualLab};

fn sweep(dt: f64, duration: f64, f0: f64, f1: f64) -> Vec<f64> {
    let n = (duration / dt).round() as usize;
    (0..=n)
        .map(|i| {
            let t = i as f64 * dt;
            (2.0 * std::f64::consts::PI * (f0 * t + (f1 - f0) * t * t / (2.0 * duration))).sin()
        })
        .collect()
}

fn settings(dt: f64, k: usize, coupling: Vec<usize>, ef: ErrorForceSpec) -> SubstepSettings {
    SubstepSettings {
        dt,
        beta: 0.25,
        gamma: 0.5,
        substeps: k,
        coupling_dofs: coupling,
        error_force: ef,
    }
}

fn lab(
    specimens: Vec<AttachedSpecimen>,
    n_c: usize,
    dtau: f64,
    actuator: ActuatorSpec,
    inner: usize,
) -> Box<dyn ExperimentalSubstructure> {
    Box::new(
        VirtualLab::new(
            &vec![actuator; n_c],
            specimens,
            &vec![SensorSpec::ideal(); n_c],
            &vec![SensorSpec::ideal(); n_c],
            dtau,
            inner,
        )
        .unwrap(),
    )
}

/// Primary-structure displacement history of a TMD system as a substructure test
/// (numerical: the primary SDOF; specimen: the TMD; ideal actuator).
fn tmd_substructured(p: &TmdSystem, dt: f64, k: usize, ag: &[f64], ef: ErrorForceSpec) -> Vec<f64> {
    let (kp, cp) = p.primary();
    let (ms, ks, cs) = p.absorber();
    let model = sdof(p.mass, cp, kp).unwrap();
    let load0 = -model.effective_mass_vector() * ag[0];
    let ctrl = SubstepController::new(&model, &settings(dt, k, vec![0], ef), &load0).unwrap();
    let spec = LinearSpecimen::sdof(Some(ms), ks, cs).unwrap();
    let site = lab(
        vec![AttachedSpecimen {
            specimen: Box::new(spec),
            coupling_index: vec![0],
        }],
        1,
        dt / k as f64,
        ActuatorSpec::ideal(),
        1,
    );
    let mut test = SubstructureTest::new(&model, ctrl, site).unwrap();
    let mut out = vec![0.0];
    for i in 0..ag.len() - 1 {
        test.step(ag[i], ag[i + 1], &mut ()).unwrap();
        out.push(test.controller.state().u[0]);
    }
    out
}

fn monolithic(model: &StructuralModel, scheme: Scheme, dt: f64, ag: &[f64], dof: usize) -> Vec<f64> {
    let mi = model.effective_mass_vector();
    let mut integ = scheme.build(model, dt, &(-&mi * ag[0])).unwrap();
    let mut out = vec![0.0];
    for &a in &ag[1..] {
        integ.step(&(-&mi * a));
        out.push(integ.state().u[dof]);
    }
    out
}

fn rel_err(x: &[f64], r: &[f64]) -> f64 {
    let num = x.iter().zip(r).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    num / r.iter().map(|v| v.abs()).fold(0.0, f64::max)
}

/// Ratio of the peak primary displacement in the last tenth of a free vibration to that in the
/// first tenth (> 1: growing, i.e. unstable).
fn growth(p: &TmdSystem, dt: f64, k: usize, ef: ErrorForceSpec, steps: usize) -> f64 {
    let (kp, cp) = p.primary();
    let (ms, ks, cs) = p.absorber();
    let model = sdof(p.mass, cp, kp).unwrap();
    let load0 = -model.effective_mass_vector() * 0.0;
    let ctrl = SubstepController::new(&model, &settings(dt, k, vec![0], ef), &load0).unwrap();
    let spec = LinearSpecimen::sdof(Some(ms), ks, cs).unwrap();
    let site = lab(
        vec![AttachedSpecimen {
            specimen: Box::new(spec),
            coupling_index: vec![0],
        }],
        1,
        dt / k as f64,
        ActuatorSpec::ideal(),
        1,
    );
    let mut test = SubstructureTest::new(&model, ctrl, site).unwrap();
    let mut first: f64 = 0.0;
    let mut last: f64 = 0.0;
    for i in 0..steps {
        // one pulse of ground acceleration, then free vibration
        let ag_next = if i == 0 { 1.0 } else { 0.0 };
        let ag_now = if i == 1 { 1.0 } else { 0.0 };
        if test.step(ag_now, ag_next, &mut ()).is_err() {
            return f64::INFINITY;
        }
        let u = test.controller.state().u[0].abs();
        if i < steps / 10 {
            first = first.max(u)
        } else if i >= steps * 9 / 10 {
            last = last.max(u)
        }
    }
    last / first
}

const PID_P1: ErrorForceSpec = ErrorForceSpec::Pid { p: 1.0, i: 0.0, d: 0.0 };

#[allow(clippy::too_many_arguments)]
fn spring_substructured(
    kp: f64,
    cp: f64,
    m: f64,
    ks: f64,
    dt: f64,
    k: usize,
    ef: ErrorForceSpec,
    ag: &[f64],
) -> Vec<f64> {
    let model = sdof(m, cp, kp).unwrap();
    let load0 = -model.effective_mass_vector() * ag[0];
    let ctrl = SubstepController::new(&model, &settings(dt, k, vec![0], ef), &load0).unwrap();
    let spec = LinearSpecimen::sdof(None, ks, 0.0).unwrap();
    let site = lab(
        vec![AttachedSpecimen {
            specimen: Box::new(spec),
            coupling_index: vec![0],
        }],
        1,
        dt / k as f64,
        ActuatorSpec::ideal(),
        1,
    );
    let mut test = SubstructureTest::new(&model, ctrl, site).unwrap();
    let mut out = vec![0.0];
    for i in 0..ag.len() - 1 {
        test.step(ag[i], ag[i + 1], &mut ()).unwrap();
        out.push(test.controller.state().u[0]);
    }
    out
}

/// A stiffness specimen makes the converged sub-stepping a fixed point of the implicit Newmark
/// equations of the assembled model: the error must fall as k_sub grows, to < 1e-4 at 50.
#[test]
fn spring_specimen_converges_to_monolithic_newmark() {
    let p = TmdSystem::typical();
    let (kp, cp) = p.primary();
    let (_, ks, _) = p.absorber();
    let dt = 0.01;
    let ag = sweep(dt, 20.0, 0.2, 3.0);
    let assembled = StructuralModel::new(dmatrix![p.mass], dmatrix![cp], dmatrix![kp + ks], None).unwrap();
    let reference = monolithic(&assembled, Scheme::Newmark { beta: 0.25, gamma: 0.5 }, dt, &ag, 0);
    for ef in [ErrorForceSpec::None, PID_P1] {
        let errors: Vec<f64> = [1, 2, 4, 10, 50]
            .iter()
            .map(|&k| rel_err(&spring_substructured(kp, cp, p.mass, ks, dt, k, ef, &ag), &reference))
            .collect();
        println!("{ef:?}: {errors:?}");
        assert!(
            errors.windows(2).all(|w| w[1] < w[0]),
            "{ef:?}: not monotonic {errors:?}"
        );
        // the one-sub-step lag of the force is first order in the sub-step length
        assert!(errors[4] < errors[0] / 25.0, "{ef:?}: {errors:?}");
        if ef == PID_P1 {
            assert!(errors[4] < 1e-4, "k_sub = 50 with P = 1: {:.3e}", errors[4]);
        }
    }
}

/// The typical TMD system (numerical: primary SDOF; specimen: TMD, ideal actuator).
#[test]
fn tmd_substructure_converges_and_matches_exact() {
    let p = TmdSystem::typical();
    let dt = 0.01;
    let ag = sweep(dt, 20.0, 0.2, 3.0);
    let assembled = tmd_two_dof(&p).unwrap();
    let newmark = monolithic(&assembled, Scheme::Newmark { beta: 0.25, gamma: 0.5 }, dt, &ag, 0);
    let exact = monolithic(&assembled, Scheme::Exact, dt, &ag, 0);
    let newmark_vs_exact = rel_err(&newmark, &exact);
    let mut vs_newmark = Vec::new();
    for k in [1, 2, 4, 10, 50] {
        let sub = tmd_substructured(&p, dt, k, &ag, ErrorForceSpec::None);
        vs_newmark.push(rel_err(&sub, &newmark));
        if k == 4 {
            let e = rel_err(&sub, &exact);
            assert!(e < 0.02, "k_sub = 4 vs exact: {e:.3e}");
            let e_pid = rel_err(&tmd_substructured(&p, dt, k, &ag, PID_P1), &exact);
            assert!(e_pid < e, "P = 1 should improve k_sub = 4: {e_pid:.3e} vs {e:.3e}");
        }
    }
    println!("vs newmark {vs_newmark:?}, newmark vs exact {newmark_vs_exact:.3e}");
    assert!(vs_newmark.windows(2).all(|w| w[1] < w[0]), "{vs_newmark:?}");
    // What remains at k_sub = 50 is the different discretisation of the specimen (integrated
    // exactly along the actuator path, its dashpot seeing the chord velocity), of the order of
    // Newmark's own error against the exact solution.
    assert!(vs_newmark[4] < newmark_vs_exact, "{vs_newmark:?}");
}

/// With k_sub = 1 the scheme is Newmark with the coupling force of the previous step.
#[test]
fn one_substep_is_explicit_coupling() {
    let (m, c, kp, ks, cs, dt) = (1000.0, 300.0, 4e4, 1.5e4, 150.0, 0.02);
    let ag = sweep(dt, 10.0, 0.5, 2.0);
    let model = sdof(m, c, kp).unwrap();
    let ctrl = SubstepController::new(
        &model,
        &settings(dt, 1, vec![0], ErrorForceSpec::None),
        &DVector::zeros(1),
    )
    .unwrap();
    let spec = LinearSpecimen::sdof(None, ks, cs).unwrap();
    let site = lab(
        vec![AttachedSpecimen {
            specimen: Box::new(spec),
            coupling_index: vec![0],
        }],
        1,
        dt,
        ActuatorSpec::ideal(),
        1,
    );
    let mut test = SubstructureTest::new(&model, ctrl, site).unwrap();
    // Independent scalar implementation: trapezoidal Newmark in acceleration form with the
    // load f_l,i+1 + f_c,i, and f_c,i+1 = −k_s u_{i+1} − c_s (u_{i+1} − u_i)/Δt.
    let (beta, gamma) = (0.25, 0.5);
    let (mut u, mut v, mut a, mut fc) = (0.0, 0.0, -ag[0], 0.0);
    let mut u_peak: f64 = 0.0;
    for i in 0..ag.len() - 1 {
        let up = u + dt * v + dt * dt * (0.5 - beta) * a;
        let vp = v + (1.0 - gamma) * dt * a;
        let a1 = (-m * ag[i + 1] + fc - c * vp - kp * up) / (m + gamma * dt * c + beta * dt * dt * kp);
        let u1 = up + beta * dt * dt * a1;
        fc = -ks * u1 - cs * (u1 - u) / dt;
        (u, v, a) = (u1, vp + gamma * dt * a1, a1);
        test.step(ag[i], ag[i + 1], &mut ()).unwrap();
        let s = test.controller.state();
        u_peak = u_peak.max(u.abs());
        assert!((s.u[0] - u).abs() < 1e-10 * u_peak, "step {i}: u {} vs {u}", s.u[0]);
        assert!(
            (s.v[0] - v).abs() < 1e-10 * u_peak / dt,
            "step {i}: v {} vs {v}",
            s.v[0]
        );
        assert!((test.controller.coupling_force()[0] - fc).abs() < 1e-10 * u_peak * ks);
    }
}

/// Records f^(k−1) (the force of the second-to-last sub-step) of every step.
#[derive(Default)]
struct SecondToLast {
    k: usize,
    forces: Vec<Vec<f64>>,
    previous: Vec<f64>,
}

impl SubstepObserver for SecondToLast {
    fn substep(&mut self, _step: usize, j: usize, _command: &[f64], force: &[f64], _displacement: &[f64]) {
        if j == self.k {
            self.forces.push(self.previous.clone());
        }
        self.previous = force.to_vec();
    }
}

/// docs/theory.md §3.7: the equilibrium residual with the last measured force equals Sᵀ(f^(k) − f^(k−1)).
#[test]
fn error_force_identity_holds_every_step() {
    // 2-DOF numerical model, TMD on DOF 2, k_sub = 4, first-order actuator, PID compensation.
    let model = StructuralModel::new(
        dmatrix![2000.0, 0.0; 0.0, 1000.0],
        dmatrix![800.0, -300.0; -300.0, 300.0],
        dmatrix![1.2e5, -5e4; -5e4, 5e4],
        None,
    )
    .unwrap();
    let k = 4;
    let dt = 0.01;
    let ef = ErrorForceSpec::Pid {
        p: 1.0,
        i: 0.3,
        d: 0.001,
    };
    let ctrl = SubstepController::new(&model, &settings(dt, k, vec![1], ef), &DVector::zeros(2)).unwrap();
    let spec = LinearSpecimen::sdof(Some(60.0), 3000.0, 40.0).unwrap();
    let act = ActuatorSpec {
        dynamics: Dynamics::FirstOrder { time_constant: 0.002 },
        delay: 0.0,
    };
    let site = lab(
        vec![AttachedSpecimen {
            specimen: Box::new(spec),
            coupling_index: vec![0],
        }],
        1,
        dt / k as f64,
        act,
        10,
    );
    let mut test = SubstructureTest::new(&model, ctrl, site).unwrap();
    let ag = sweep(dt, 5.0, 0.5, 4.0);
    let mut obs = SecondToLast {
        k,
        ..Default::default()
    };
    let mi = model.effective_mass_vector();
    let mut checked = 0;
    for i in 0..ag.len() - 1 {
        let f_u = test.controller.compensation_force().to_vec();
        test.step(ag[i], ag[i + 1], &mut obs).unwrap();
        let residual = test.controller.equilibrium_residual(&(-&mi * ag[i + 1]), &f_u);
        let fk = test.controller.coupling_force()[0];
        let fk1 = obs.forces.last().unwrap()[0];
        let expected = [0.0, fk - fk1];
        let scale = 1e-9 * (1.0 + fk.abs() + (&mi * ag[i + 1]).amax());
        for d in 0..2 {
            assert!(
                (residual[d] - expected[d]).abs() < scale,
                "step {i} dof {d}: {} vs {}",
                residual[d],
                expected[d]
            );
        }
        assert!((test.controller.error_force()[0] - (fk - fk1)).abs() < 1e-12 * (1.0 + fk.abs()));
        checked += 1;
    }
    assert!(checked > 400);
}

/// A parameter point found by a time-domain scan (coupled system with large mass ratio, undamped
/// primary, ζ_s = 10 %, Ω = 0.628, k_sub = 1): unstable without compensation, stable with P = 1.
#[test]
fn pid_stabilises_an_unstable_case() {
    let p = TmdSystem {
        zeta: 0.0,
        zeta_s: 0.1,
        frequency: 10.0,
        ..TmdSystem::large_mass_ratio()
    };
    let dt = 0.01;
    let without = growth(&p, dt, 1, ErrorForceSpec::None, 2000);
    let with = growth(&p, dt, 1, PID_P1, 2000);
    println!("growth without {without:.3e}, with P = 1 {with:.3e}");
    assert!(without > 1e6, "expected growth without compensation, got {without:.3e}");
    assert!(with < 1e-3, "expected decay with P = 1, got {with:.3e}");
}

fn chain_model() -> StructuralModel {
    StructuralModel::new(
        dmatrix![2000.0, 0.0; 0.0, 1500.0],
        dmatrix![900.0, -300.0; -300.0, 300.0],
        dmatrix![2.0e5, -8e4; -8e4, 8e4],
        None,
    )
    .unwrap()
}

/// Run a substructure test of `chain_model` with specimens from descriptions; returns the
/// numerical displacement histories (one Vec per DOF).
fn run_specs(
    specs: &[SpecimenSpec],
    coupling: Vec<usize>,
    dt: f64,
    k: usize,
    ef: ErrorForceSpec,
    ag: &[f64],
) -> Vec<Vec<f64>> {
    let model = chain_model();
    let n_c = coupling.len();
    let ctrl = SubstepController::new(&model, &settings(dt, k, coupling.clone(), ef), &DVector::zeros(2)).unwrap();
    let site = VirtualLab::from_specs(
        &coupling,
        specs,
        &vec![ActuatorSpec::ideal(); n_c],
        &vec![SensorSpec::ideal(); n_c],
        &vec![SensorSpec::ideal(); n_c],
        dt / k as f64,
        1,
    )
    .unwrap();
    let mut test = SubstructureTest::new(&model, ctrl, Box::new(site)).unwrap();
    let mut out = vec![vec![0.0]; 2];
    for i in 0..ag.len() - 1 {
        test.step(ag[i], ag[i + 1], &mut ()).unwrap();
        for (d, o) in out.iter_mut().enumerate() {
            o.push(test.controller.state().u[d]);
        }
    }
    out
}

/// Two specimens on different DOFs plus a two-DOF specimen coupling both, stiffness only:
/// converges to Newmark of the assembled model like the single spring.
#[test]
fn several_specimens_converge_to_monolithic_newmark() {
    let specs = vec![
        SpecimenSpec::LinearSdof {
            dof: 0,
            mass: None,
            stiffness: 2e4,
            damping: 0.0,
        },
        SpecimenSpec::LinearSdof {
            dof: 1,
            mass: None,
            stiffness: 1e4,
            damping: 0.0,
        },
        SpecimenSpec::LinearMdof {
            dofs: vec![0, 1],
            mass: DMatrix::zeros(2, 2),
            damping: DMatrix::zeros(2, 2),
            stiffness: dmatrix![1.5e4, -1.5e4; -1.5e4, 1.5e4],
            influence: None,
        },
    ];
    let dt = 0.01;
    let ag = sweep(dt, 10.0, 0.2, 4.0);
    let assembled = assemble_monolithic(&chain_model(), &specs).unwrap();
    assert_eq!(assembled.n_dofs(), 2);
    let reference: Vec<Vec<f64>> = (0..2)
        .map(|d| monolithic(&assembled, Scheme::Newmark { beta: 0.25, gamma: 0.5 }, dt, &ag, d))
        .collect();
    let errors: Vec<f64> = [1, 4, 10, 50]
        .iter()
        .map(|&k| {
            let sub = run_specs(&specs, vec![0, 1], dt, k, PID_P1, &ag);
            (0..2).map(|d| rel_err(&sub[d], &reference[d])).fold(0.0, f64::max)
        })
        .collect();
    println!("k_sub = 1, 4, 10, 50: {errors:?}");
    assert!(errors.windows(2).all(|w| w[1] < w[0]), "{errors:?}");
    // first order in the sub-step length: 50 sub-steps cut the error ~50 times
    assert!(errors[3] < errors[0] / 40.0 && errors[3] < 5e-4, "{errors:?}");
}

/// A two-DOF specimen with an internal mass between both coupling DOFs, and a TMD: the
/// substructure test matches the exact solution of the assembled 4-DOF model.
#[test]
fn mdof_specimen_with_internal_mass_matches_exact() {
    let (ka, kb, m3) = (2e4, 3e4, 120.0);
    let specs = vec![
        SpecimenSpec::LinearMdof {
            dofs: vec![0, 1],
            mass: DMatrix::from_diagonal(&DVector::from_vec(vec![0.0, 0.0, m3])),
            damping: dmatrix![60.0, 0.0, -60.0; 0.0, 40.0, -40.0; -60.0, -40.0, 100.0],
            stiffness: dmatrix![ka, 0.0, -ka; 0.0, kb, -kb; -ka, -kb, ka + kb],
            influence: None,
        },
        SpecimenSpec::LinearSdof {
            dof: 1,
            mass: Some(75.0),
            stiffness: 5e3,
            damping: 80.0,
        },
    ];
    let dt = 0.005;
    let ag = sweep(dt, 10.0, 0.2, 4.0);
    let assembled = assemble_monolithic(&chain_model(), &specs).unwrap();
    assert_eq!(assembled.n_dofs(), 4);
    let sub = run_specs(&specs, vec![0, 1], dt, 10, PID_P1, &ag);
    for (d, sub_d) in sub.iter().enumerate() {
        let exact = monolithic(&assembled, Scheme::Exact, dt, &ag, d);
        let err = rel_err(sub_d, &exact);
        println!("dof {}: {err:.3e}", d + 1);
        assert!(err < 5e-3, "dof {}: {err:.3e}", d + 1);
    }
}
