//! The sub-step algorithm against the assembled (monolithic) model and the exact solution.

use nalgebra::{DVector, dmatrix};
use substep::integrate::Scheme;
use substep::model::{StructuralModel, TmdSystem, sdof, tmd_two_dof};
use substep::specimen::LinearSpecimen;
use substep::substructure::{
    ErrorForceSpec, ExperimentalSubstructure, SubstepController, SubstepSettings, SubstructureTest,
};
use substep::transfer::{ActuatorSpec, AttachedSpecimen, SensorSpec, VirtualLab};

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

/// Primary-structure displacement history of the typical TMD system as a substructure test.
fn tmd_substructured(p: &TmdSystem, dt: f64, k: usize, ag: &[f64]) -> Vec<f64> {
    tmd_substructured_ef(p, dt, k, ag, ErrorForceSpec::Pid { p: 1.0, i: 0.0, d: 0.0 })
}

fn tmd_substructured_ef(p: &TmdSystem, dt: f64, k: usize, ag: &[f64], ef: ErrorForceSpec) -> Vec<f64> {
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

#[test]
fn tmd_converges_with_substeps() {
    let p = TmdSystem::typical();
    for dt in [0.01, 0.002, 0.001] {
        let ag = sweep(dt, 20.0, 0.2, 3.0);
        let assembled = tmd_two_dof(&p).unwrap();
        let newmark = monolithic(&assembled, Scheme::Newmark { beta: 0.25, gamma: 0.5 }, dt, &ag, 0);
        let exact = monolithic(&assembled, Scheme::Exact, dt, &ag, 0);
        for k in [1, 2, 4, 10, 50] {
            let sub = tmd_substructured(&p, dt, k, &ag);
            println!(
                "k = {k}: vs newmark {:.3e}, vs exact {:.3e}",
                rel_err(&sub, &newmark),
                rel_err(&sub, &exact)
            );
        }
        println!("dt {dt} newmark vs exact {:.3e}", rel_err(&newmark, &exact));
    }
}

#[test]
fn explore_spring() {
    let p = TmdSystem::typical();
    let dt = 0.01;
    let ag = sweep(dt, 20.0, 0.2, 3.0);
    let (kp, cp) = p.primary();
    let ks = 0.3 * kp;
    let assembled = StructuralModel::new(dmatrix![p.mass], dmatrix![cp], dmatrix![kp + ks], None).unwrap();
    let newmark = monolithic(&assembled, Scheme::Newmark { beta: 0.25, gamma: 0.5 }, dt, &ag, 0);
    for ef in [ErrorForceSpec::None, ErrorForceSpec::Pid { p: 1.0, i: 0.0, d: 0.0 }] {
        for k in [1, 2, 4, 10, 50] {
            let model = sdof(p.mass, cp, kp).unwrap();
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
            println!("{ef:?} k = {k}: vs newmark {:.3e}", rel_err(&out, &newmark));
        }
    }
    let _ = DVector::<f64>::zeros(1);
}
