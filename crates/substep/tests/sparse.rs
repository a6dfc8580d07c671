//! Sparse models: the frame builder against closed forms, sparse vs dense assembly, and the
//! sparse integration paths (monolithic Newmark and the sub-step controller) against the dense
//! ones on the same models, plus the guards that keep dense-only features off large models.

use nalgebra::{DMatrix, DVector};
use std::f64::consts::PI;
use substep::integrate::{Kinematics, Scheme};
use substep::model::{
    DENSE_MAX_DOFS, DampingSpec, Frame2d, FrameDof, Model, ModelRef, Section, ShearBuilding, SparseModel,
    StructuralModel, frame_2d, frame_2d_dense, shear_building, shear_building_sparse,
};
use substep::sparse::{CscMatrix, FactorKind, SymmetricFactor};
use substep::specimen::SpecimenSpec;
use substep::substructure::{ErrorForceSpec, SubstepController, SubstepSettings, SubstructureTest};
use substep::transfer::{ActuatorSpec, SensorSpec, VirtualLab};

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

/// Flexibility entry `(K⁻¹)_{dd}`: the displacement at DOF `d` under a unit force there.
fn flexibility(k: &DMatrix<f64>, d: usize) -> f64 {
    let mut e = DVector::zeros(k.nrows());
    e[d] = 1.0;
    k.clone().cholesky().expect("K is SPD").solve(&e)[d]
}

#[test]
fn cantilever_column_tip_stiffness() {
    let f = Frame2d {
        bays: 0,
        stories: 1,
        story_height: 3.7,
        ..Frame2d::default()
    };
    let k = frame_2d(&f).unwrap().stiffness.to_dense();
    assert_eq!(k.nrows(), 3);
    let (e, a, i, l) = (f.elastic_modulus, f.column.area, f.column.inertia, f.story_height);
    let ux = f.dof(1, 0, FrameDof::Ux).unwrap();
    let uy = f.dof(1, 0, FrameDof::Uy).unwrap();
    // Lateral: a tip force with free rotation, 3EI/L³; axial: EA/L.
    assert!(rel(1.0 / flexibility(&k, ux), 3.0 * e * i / l.powi(3)) < 1e-10);
    assert!(rel(1.0 / flexibility(&k, uy), e * a / l) < 1e-10);
    assert!(rel(k[(uy, uy)], e * a / l) < 1e-12);
}

/// Lateral stiffness of a fixed-base portal frame with axially rigid members (slope-deflection):
/// `k = 12 k_c (k_c + 6 k_b) / (h² (2 k_c + 3 k_b))` with `k_c = E I_c / h`, `k_b = E I_b / L`.
fn portal_closed_form(e: f64, ic: f64, ib: f64, h: f64, l: f64) -> f64 {
    let (kc, kb) = (e * ic / h, e * ib / l);
    12.0 * kc * (kc + 6.0 * kb) / (h * h * (2.0 * kc + 3.0 * kb))
}

#[test]
fn documented_frame_dof_numbering() {
    // docs/config.md: the default frame's roof horizontal DOF is 109 (1-based), 82 with a
    // rigid diaphragm.
    let f = Frame2d::default();
    assert_eq!(f.dof(10, 0, FrameDof::Ux), Some(108));
    assert_eq!(f.dof(2, 1, FrameDof::Rz), Some(3 * (4 + 1) + 2));
    assert_eq!(f.dof(0, 0, FrameDof::Ux), None);
    let d = Frame2d {
        rigid_diaphragm: true,
        ..f
    };
    assert_eq!(d.dof(10, 0, FrameDof::Ux), Some(81));
    assert_eq!(d.dof(10, 3, FrameDof::Ux), Some(81));
    assert_eq!(d.n_dofs(), 90);
}

#[test]
fn portal_frame_lateral_stiffness() {
    for (ib_scale, diaphragm) in [(1.0, false), (0.1, true), (10.0, true)] {
        let f = Frame2d {
            bays: 1,
            stories: 1,
            bay_width: 6.0,
            story_height: 3.5,
            column: Section {
                area: 1e4, // axially rigid columns
                inertia: Section::HEB300.inertia,
            },
            beam: Section {
                area: 1e4,
                inertia: ib_scale * Section::IPE400.inertia,
            },
            rigid_diaphragm: diaphragm,
            ..Frame2d::default()
        };
        let k = frame_2d(&f).unwrap().stiffness.to_dense();
        // Equal lateral forces on both joints (or the floor DOF): F_total / Δ.
        let mut load = DVector::zeros(k.nrows());
        for c in 0..=1 {
            load[f.dof(1, c, FrameDof::Ux).unwrap()] += 0.5;
        }
        let u = k.clone().cholesky().unwrap().solve(&load);
        let stiffness = 1.0 / u[f.dof(1, 0, FrameDof::Ux).unwrap()];
        let want = portal_closed_form(f.elastic_modulus, f.column.inertia, f.beam.inertia, 3.5, 6.0);
        assert!(rel(stiffness, want) < 1e-7, "ib x{ib_scale}: {stiffness} vs {want}");
    }
}

#[test]
fn frame_matrices_are_symmetric_positive_definite_and_assemblies_agree() {
    for f in [
        Frame2d::default(),
        Frame2d {
            bays: 4,
            stories: 6,
            rigid_diaphragm: true,
            ..Frame2d::default()
        },
    ] {
        let s = frame_2d(&f).unwrap();
        let d = frame_2d_dense(&f).unwrap();
        assert_eq!(s.n_dofs(), f.n_dofs());
        for (sp, de) in [(&s.mass, &d.mass), (&s.stiffness, &d.stiffness)] {
            let sd = sp.to_dense();
            assert!(
                (&sd - de).amax() <= 1e-12 * de.amax(),
                "sparse and dense assembly differ"
            );
            assert!((&sd - sd.transpose()).amax() <= 1e-12 * sd.amax(), "not symmetric");
            assert!(sd.clone().cholesky().is_some(), "not positive definite");
        }
        assert_eq!(s.influence, d.influence);
        assert!(s.mass.is_diagonal());
        // Total horizontal mass = floor masses + member masses.
        let total: f64 = s.effective_mass_vector().dot(&s.influence);
        let members = f.density
            * f.stories as f64
            * ((f.bays + 1) as f64 * f.column.area * f.story_height + f.bays as f64 * f.beam.area * f.bay_width);
        // The base halves of the first-story columns sit on the fixed base.
        let base = f.density * (f.bays + 1) as f64 * f.column.area * f.story_height * 0.5;
        let floors = f.floor_mass_per_bay * (f.bays * f.stories) as f64;
        assert!(rel(total, floors + members - base) < 1e-12);
        // Bandwidth of one to two floors of DOFs.
        assert!(s.stiffness.half_bandwidth() < 2 * f.n_dofs() / f.stories);
    }
}

fn rayleigh_5pct() -> DampingSpec {
    DampingSpec::RayleighRatio {
        zeta: 0.05,
        modes: (1, 3),
    }
}

/// Both storages of a chain (`n` stories) and a frame (`bays × stories`), damped alike.
fn models() -> Vec<(&'static str, StructuralModel, SparseModel)> {
    let b = ShearBuilding {
        stories: 240,
        story_mass: 1e5,
        first_period: 3.0,
    };
    let chain_d = shear_building(&b).unwrap().with_damping(&rayleigh_5pct()).unwrap();
    let chain_s = shear_building_sparse(&b)
        .unwrap()
        .with_damping(&rayleigh_5pct())
        .unwrap();
    let f = Frame2d {
        bays: 3,
        stories: 30,
        ..Frame2d::default()
    };
    let frame_d = frame_2d_dense(&f).unwrap().with_damping(&rayleigh_5pct()).unwrap();
    let frame_s = frame_2d(&f).unwrap().with_damping(&rayleigh_5pct()).unwrap();
    assert_eq!(frame_s.n_dofs(), 360);
    vec![("chain", chain_d, chain_s), ("frame", frame_d, frame_s)]
}

fn ground(steps: usize, dt: f64) -> Vec<f64> {
    (0..=steps)
        .map(|i| {
            let t = i as f64 * dt;
            2.0 * (2.0 * PI * 1.3 * t).sin() + 0.7 * (2.0 * PI * 4.1 * t).sin()
        })
        .collect()
}

fn max_rel_diff(x: &[DVector<f64>], r: &[DVector<f64>]) -> f64 {
    let scale = r.iter().map(|v| v.amax()).fold(0.0, f64::max);
    assert!(scale > 0.0);
    x.iter().zip(r).map(|(a, b)| (a - b).amax()).fold(0.0, f64::max) / scale
}

#[test]
fn rayleigh_ratio_damping_agrees_between_storages() {
    for (name, d, s) in models() {
        let c = s.damping.to_dense();
        assert!((&c - &d.damping).amax() <= 1e-9 * d.damping.amax(), "{name}");
    }
}

#[test]
fn monolithic_newmark_sparse_matches_dense() {
    let dt = 0.01;
    let ag = ground(300, dt);
    for (name, dense, sparse) in models() {
        let run = |m: ModelRef| -> Vec<DVector<f64>> {
            let mi = m.effective_mass_vector();
            let mut integ = Scheme::Newmark { beta: 0.25, gamma: 0.5 }
                .build(m, dt, &(-&mi * ag[0]))
                .unwrap();
            let mut out = vec![];
            for &a in &ag[1..] {
                integ.step(&(-&mi * a));
                out.push(integ.state().u.clone());
            }
            out
        };
        let (ud, us) = (run((&dense).into()), run((&sparse).into()));
        let err = max_rel_diff(&us, &ud);
        assert!(err < 1e-10, "{name}: sparse vs dense {err:e}");
    }
}

/// Coupling DOFs and spring specimens (10 % of a story stiffness) on the top of the model.
fn substructured(model: ModelRef, coupling: &[usize], k_spec: f64, ag: &[f64], dt: f64) -> Vec<DVector<f64>> {
    substructured_with(model, coupling, k_spec, ag, dt, false)
}

fn substructured_with(
    model: ModelRef,
    coupling: &[usize],
    k_spec: f64,
    ag: &[f64],
    dt: f64,
    second_core: bool,
) -> Vec<DVector<f64>> {
    let k_sub = 10;
    let settings = SubstepSettings {
        dt,
        beta: 0.25,
        gamma: 0.5,
        substeps: k_sub,
        coupling_dofs: coupling.to_vec(),
        error_force: ErrorForceSpec::None,
    };
    let specimens: Vec<SpecimenSpec> = coupling
        .iter()
        .map(|&dof| SpecimenSpec::LinearSdof {
            dof,
            mass: Some(500.0),
            stiffness: k_spec,
            damping: 0.0,
        })
        .collect();
    let n_c = coupling.len();
    let lab = VirtualLab::from_specs(
        coupling,
        &specimens,
        &vec![ActuatorSpec::ideal(); n_c],
        &vec![SensorSpec::ideal(); n_c],
        &vec![SensorSpec::ideal(); n_c],
        dt / k_sub as f64,
        1,
    )
    .unwrap();
    let load0 = -model.effective_mass_vector() * ag[0];
    let mut ctrl = SubstepController::new(model, &settings, &load0).unwrap();
    if second_core {
        assert!(ctrl.enable_second_core(), "{}", ctrl.solver());
    }
    let mut test = SubstructureTest::new(model, ctrl, Box::new(lab)).unwrap();
    let mut out = vec![];
    for i in 0..ag.len() - 1 {
        test.step(ag[i], ag[i + 1], &mut ()).unwrap();
        out.push(test.controller.state().u.clone());
    }
    out
}

#[test]
fn substructured_run_sparse_matches_dense() {
    let dt = 0.01;
    let ag = ground(200, dt);
    for (name, dense, sparse) in models() {
        let n = dense.n_dofs();
        let coupling = if name == "chain" {
            vec![n - 1, n / 2]
        } else {
            vec![n - 3, n - 2]
        };
        let k_spec = 0.1 * dense.stiffness[(n - 1, n - 1)];
        let ud = substructured((&dense).into(), &coupling, k_spec, &ag, dt);
        let us = substructured((&sparse).into(), &coupling, k_spec, &ag, dt);
        let err = max_rel_diff(&us, &ud);
        assert!(err < 1e-10, "{name}: sparse vs dense {err:e}");
        // The gain columns agree too.
        let settings = SubstepSettings {
            dt,
            beta: 0.25,
            gamma: 0.5,
            substeps: 4,
            coupling_dofs: coupling.clone(),
            error_force: ErrorForceSpec::None,
        };
        let z = DVector::zeros(n);
        let gd = SubstepController::new(&dense, &settings, &z)
            .unwrap()
            .gain_columns()
            .clone();
        let gs = SubstepController::new(&sparse, &settings, &z)
            .unwrap()
            .gain_columns()
            .clone();
        assert!((&gs - &gd).amax() <= 1e-12 * gd.amax(), "{name}: gain columns");
    }
}

#[test]
fn banded_and_amd_factors_agree_on_a_frame() {
    let f = Frame2d {
        bays: 6,
        stories: 12,
        ..Frame2d::default()
    };
    let m = frame_2d(&f).unwrap();
    let k_eff = CscMatrix::linear_combination(&[(1.0, &m.stiffness), (4e4, &m.mass)]);
    let rhs: Vec<f64> = (0..m.n_dofs()).map(|i| ((i * 7919) % 101) as f64 - 50.0).collect();
    let mut sols = vec![];
    for kind in [FactorKind::Banded, FactorKind::Sparse] {
        let mut fac = SymmetricFactor::new(&k_eff, kind, "K_hat").unwrap();
        let mut x = rhs.clone();
        fac.solve_in_place(&mut x);
        // Residual check.
        let mut r = vec![0.0; x.len()];
        k_eff.sym_mul_add(1.0, &x, 0.0, &mut r);
        let res = r.iter().zip(&rhs).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(
            res < 1e-9 * rhs.iter().fold(0.0f64, |m, v| m.max(v.abs())),
            "{kind:?}: {res}"
        );
        sols.push(x);
    }
    let d = sols[0]
        .iter()
        .zip(&sols[1])
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(d <= 1e-10 * sols[0].iter().fold(0.0f64, |m, v| m.max(v.abs())));
}

#[test]
fn consistent_initial_acceleration_with_sparse_mass() {
    let f = Frame2d {
        bays: 2,
        stories: 3,
        ..Frame2d::default()
    };
    let (s, d) = (frame_2d(&f).unwrap(), frame_2d_dense(&f).unwrap());
    let load: DVector<f64> = DVector::from_fn(s.n_dofs(), |i, _| (i as f64).cos());
    let (ks, kd) = (
        Kinematics::at_rest(&s, &load).unwrap(),
        Kinematics::at_rest(&d, &load).unwrap(),
    );
    assert!((&ks.a - &kd.a).amax() <= 1e-12 * kd.a.amax());
}

#[test]
fn dense_only_features_refuse_large_sparse_models() {
    let big = shear_building_sparse(&ShearBuilding {
        stories: DENSE_MAX_DOFS + 1,
        story_mass: 1e5,
        first_period: 10.0,
    })
    .unwrap();
    let model = Model::Sparse(big.clone());
    let e = model.dense("the exact reference").unwrap_err().to_string();
    assert!(e.contains("the exact reference needs dense n x n matrices"), "{e}");
    assert!(
        e.contains(&format!("{} DOFs in sparse storage", DENSE_MAX_DOFS + 1)),
        "{e}"
    );
    let e = big
        .clone()
        .with_damping(&DampingSpec::Modal { zeta: vec![0.05] })
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("structure.modal: modal damping makes a dense n x n damping matrix"),
        "{e}"
    );
    let z = DVector::zeros(big.n_dofs());
    for scheme in [
        Scheme::Exact,
        Scheme::Hht { alpha: -0.1 },
        Scheme::Newmark { beta: 0.0, gamma: 0.5 },
    ] {
        let e = scheme.build(&big, 0.01, &z).err().expect("refused").to_string();
        assert!(e.starts_with("integrator.scheme: "), "{e}");
        assert!(e.contains("sparse storage"), "{e}");
    }
    // Newmark works, and a small sparse model converts for the dense-only features.
    assert!(Scheme::Newmark { beta: 0.25, gamma: 0.5 }.build(&big, 0.01, &z).is_ok());
    let small = Model::Sparse(
        shear_building_sparse(&ShearBuilding {
            stories: 5,
            story_mass: 1.0,
            first_period: 1.0,
        })
        .unwrap(),
    );
    assert_eq!(small.dense("modes").unwrap().n_dofs(), 5);
}

// ---------------------------------------------------------------------------------------------
// Config: [structure] storage and [structure.frame].

mod config {
    use std::path::Path;
    use substep::io::TestDefinition;
    use substep::run::{Reference, Simulation};

    const MOTION: &str =
        "[ground_motion]\ngenerator = \"harmonic\"\namplitude = 1.0\nfrequency = 2.0\nduration = 0.05\n";

    fn parse(text: &str) -> substep::Result<TestDefinition> {
        TestDefinition::from_toml(text, "cfg.toml", Path::new("."))
    }

    fn frame_cfg(extra: &str, scheme: &str) -> String {
        format!(
            "[structure]\n{extra}\n[structure.frame]\nbays = 3\nstories = 30\n[structure.rayleigh]\nzeta = 0.05\n\
             {MOTION}[integrator]\nscheme = \"{scheme}\"\ndt = 0.01\n"
        )
    }

    #[test]
    fn storage_auto_dense_sparse() {
        let d = parse(&frame_cfg("", "newmark")).unwrap();
        assert_eq!((d.model.n_dofs(), d.model.storage_name()), (360, "sparse"));
        let d = parse(&frame_cfg("storage = \"dense\"", "newmark")).unwrap();
        assert_eq!(d.model.storage_name(), "dense");
        // Dense-only schemes keep auto storage dense; explicit sparse is refused.
        let d = parse(&frame_cfg("", "hht")).unwrap();
        assert_eq!(d.model.storage_name(), "dense");
        let e = parse(&frame_cfg("storage = \"sparse\"", "exact"))
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("cfg.toml: structure.storage: \"sparse\" cannot be used with the integrator scheme"),
            "{e}"
        );
        let e = parse(&frame_cfg("storage = \"banded\"", "newmark"))
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "cfg.toml: structure.storage: unknown storage 'banded' (expected auto, dense or sparse)"
        );
        // A small shear building stays dense under auto, a large one goes sparse.
        let chain = |stories: usize, extra: &str| {
            format!(
                "[structure]\n{extra}\n[structure.shear_building]\nstories = {stories}\nstory_mass = 1e5\n\
                 first_period = 2.0\n{MOTION}[integrator]\ndt = 0.01\n"
            )
        };
        assert_eq!(parse(&chain(50, "")).unwrap().model.storage_name(), "dense");
        assert_eq!(parse(&chain(400, "")).unwrap().model.storage_name(), "sparse");
        assert_eq!(
            parse(&chain(50, "storage = \"sparse\"")).unwrap().model.storage_name(),
            "sparse"
        );
        // Modal damping needs dense matrices.
        let modal = "[structure.modal]\nzeta = 0.05\n";
        let e = parse(&chain(400, &format!("storage = \"sparse\"\n{modal}")))
            .unwrap_err()
            .to_string();
        assert!(e.contains("cannot be used with modal damping"), "{e}");
        assert_eq!(parse(&chain(400, modal)).unwrap().model.storage_name(), "dense");
        let e = parse(&chain(5000, modal)).unwrap_err().to_string();
        assert!(e.starts_with("cfg.toml: structure: modal damping ([structure.modal]) needs dense matrices, but the model has 5000 DOFs"), "{e}");
    }

    #[test]
    fn frame_keys_and_sparse_substructured_run_with_reference() {
        let text = format!(
            "{}[substructure]\ncoupling_dofs = [262]\nsubsteps = 4\n[[substructure.specimen]]\nkind = \"linear_sdof\"\n\
             dof = 262\nstiffness = 1e6\n",
            frame_cfg("", "newmark").replace(
                "stories = 30\n",
                "stories = 30\nrigid_diaphragm = true\nbay_width = 5.0\n"
            )
        );
        let d = parse(&text).unwrap();
        assert_eq!(d.model.n_dofs(), 30 * 9);
        assert_eq!(d.model.storage_name(), "dense", "270 DOFs stay dense under auto");
        let d = parse(&text.replace("[structure]\n", "[structure]\nstorage = \"sparse\"\n")).unwrap();
        assert!(d.model.is_sparse());
        let mut sim = Simulation::new(&d).unwrap();
        let mut reference = Reference::new(&d).unwrap().expect("linear specimen");
        assert_eq!(reference.scheme(), "newmark");
        for i in 0..sim.steps_total() {
            sim.step(&mut ()).unwrap();
            reference.step(d.ground_motion.accel[i + 1]).unwrap();
        }
        let (u, r) = (&sim.state().u, reference.u());
        let scale = r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let diff = u.iter().zip(r).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(
            scale > 0.0 && diff < 0.05 * scale,
            "substructured vs reference: {diff} / {scale}"
        );
        let e = parse(&text.replace("bays = 3", "bays = 3\ncolumns = 2"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown field `columns`"), "{e}");
    }

    #[test]
    fn matrix_market_files_are_read_sparse() {
        let dir = std::env::temp_dir().join(format!("substep-sparse-mtx-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let n = 500;
        let mut m = format!("%%MatrixMarket matrix coordinate real symmetric\n{n} {n} {n}\n");
        let mut k = format!(
            "%%MatrixMarket matrix coordinate real symmetric\n{n} {n} {}\n",
            2 * n - 1
        );
        for i in 1..=n {
            m.push_str(&format!("{i} {i} 1000\n"));
            k.push_str(&format!("{i} {i} {}\n", if i < n { 2e6 } else { 1e6 }));
            if i < n {
                k.push_str(&format!("{} {i} -1e6\n", i + 1));
            }
        }
        std::fs::write(dir.join("M.mtx"), m).unwrap();
        std::fs::write(dir.join("K.mtx"), k).unwrap();
        let text = format!(
            "[structure]\nmass = \"M.mtx\"\nstiffness = \"K.mtx\"\n[structure.rayleigh]\nalpha = 0.1\nbeta = 0.001\n\
             {MOTION}[integrator]\ndt = 0.01\n"
        );
        let d = TestDefinition::from_toml(&text, "cfg.toml", &dir).unwrap();
        assert_eq!((d.model.n_dofs(), d.model.storage_name()), (n, "sparse"));
        let s = d.model.as_sparse().unwrap();
        assert_eq!(s.stiffness.nnz(), 3 * n - 2);
        assert!((s.damping.get(0, 0) - (0.1 * 1000.0 + 0.001 * 2e6)).abs() < 1e-9);
        let mut sim = Simulation::new(&d).unwrap();
        sim.step(&mut ()).unwrap();
        std::fs::remove_dir_all(&dir).ok();
    }
}

/// `K̂ = K + a0 M + a1 C` of a frame (Rayleigh `C = 0.1 M + 0.002 K`, `dt = 0.01 s`).
fn frame_k_hat(f: &Frame2d) -> CscMatrix {
    let m = frame_2d(f).unwrap();
    let (a0, a1) = (4.0 / 1e-4, 2.0 / 0.01);
    CscMatrix::linear_combination(&[(1.0 + a1 * 0.002, &m.stiffness), (a0 + a1 * 0.1, &m.mass)])
}

#[test]
fn supernodal_solves_match_dense_cholesky_for_both_orderings() {
    use substep::sparse::SparseOrdering;
    // A frame (3-DOF nodes, supernodes of many widths) and a frame with a rigid diaphragm
    // (one DOF shared by a floor: wide, dense rows), plus two unconnected frames in one matrix
    // (a forest: the elimination tree has two roots).
    let a = Frame2d {
        bays: 9,
        stories: 17,
        ..Frame2d::default()
    };
    let b = Frame2d {
        bays: 5,
        stories: 11,
        rigid_diaphragm: true,
        ..Frame2d::default()
    };
    let (ka, kb) = (frame_k_hat(&a), frame_k_hat(&b));
    // Two copies of the frame: balanced roots, so the two-core split is at the virtual root
    // (no top separator).
    let na = ka.n();
    let mut t = Vec::new();
    for (off, k) in [(0, &ka), (na, &ka)] {
        for j in 0..k.n() {
            let (rows, vals) = k.col(j);
            t.extend(rows.iter().zip(vals).map(|(&i, &v)| (i + off, j + off, v)));
        }
    }
    let forest = CscMatrix::from_triplets(2 * na, &t);
    for (name, k) in [("frame", &ka), ("diaphragm frame", &kb), ("two frames", &forest)] {
        let dense = k.to_dense().cholesky().expect("K_hat is SPD");
        let rhs: Vec<f64> = (0..k.n()).map(|i| ((i * 7919) % 101) as f64 - 50.0).collect();
        let want = dense.solve(&DVector::from_row_slice(&rhs));
        for ord in [
            SparseOrdering::Amd,
            SparseOrdering::NestedDissection,
            SparseOrdering::Auto,
        ] {
            let mut fac = SymmetricFactor::with_ordering(k, FactorKind::Sparse, ord, "K_hat").unwrap();
            assert!(fac.describe().starts_with("supernodal"), "{}", fac.describe());
            let mut x = rhs.clone();
            fac.solve_in_place(&mut x);
            // Solving twice with the same factor gives the same bits (no state left behind).
            let mut y = rhs.clone();
            fac.solve_in_place(&mut y);
            assert_eq!(x, y, "{name} {ord:?}: rerun differs");
            let err = (DVector::from_row_slice(&x) - &want).amax() / want.amax();
            assert!(err < 1e-10, "{name} {ord:?}: {err}");
            assert!(fac.bytes_per_solve() >= 16 * fac.factor_len() / 2, "{name}: bytes");
            // The same factor swept on two cores: the halves of the tree below the top
            // separator (nested dissection always has them here).
            if fac.enable_second_core() {
                assert!(fac.uses_second_core());
                let mut z = rhs.clone();
                fac.solve_in_place(&mut z);
                let err2 = (DVector::from_row_slice(&z) - &want).amax() / want.amax();
                assert!(err2 < 1e-10, "{name} {ord:?} two cores: {err2}");
                for _ in 0..3 {
                    let mut z2 = rhs.clone();
                    fac.solve_in_place(&mut z2);
                    assert_eq!(z, z2, "{name} {ord:?}: two-core rerun differs");
                }
            } else {
                assert_ne!(ord, SparseOrdering::NestedDissection, "{name}: no split");
            }
        }
    }
}

#[test]
fn substructured_frame_on_two_cores_matches_one() {
    // A 10-bay, 20-storey frame, spring specimen on the roof: the sub-step controller with the
    // predictor solve on one core and on two gives the same response (to rounding).
    let f = Frame2d {
        bays: 10,
        stories: 20,
        ..Frame2d::default()
    };
    let m = frame_2d(&f)
        .unwrap()
        .with_damping(&DampingSpec::Rayleigh {
            alpha: 0.2,
            beta: 0.002,
        })
        .unwrap();
    let roof = f.dof(f.stories, 0, FrameDof::Ux).unwrap();
    let ag = ground(200, 0.01);
    let one = substructured(ModelRef::Sparse(&m), &[roof], 1e6, &ag, 0.01);
    let two = substructured_with(ModelRef::Sparse(&m), &[roof], 1e6, &ag, 0.01, true);
    let d = max_rel_diff(&two, &one);
    assert!(d < 1e-10, "{d}");
    assert!(one.last().unwrap().amax() > 0.0);
}
