//! Structural model builders, damping models and modal analysis against closed forms, and the
//! error messages for bad input.

mod common;

use common::shear_chain_modes;
use nalgebra::{DMatrix, DVector, dmatrix, dvector};
use std::f64::consts::PI;
use substep::integrate::{AlphaOs, ExactFoh, ExplicitNewmark, Hht, Newmark, NewmarkConstants, NewmarkCore, Scheme};
use substep::model::{
    DampingSpec, ShearBuilding, StructuralModel, TmdSystem, modal_damping, modes, rayleigh_coefficients, sdof,
    shear_building, tmd_two_dof,
};

/// `max |a − b|`.
fn max_diff(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).amax()
}

#[test]
fn shear_building_matches_closed_form() {
    for (n, mass, period) in [(1usize, 2e4, 0.5), (5, 1e5, 1.0), (50, 1e5, 5.0), (200, 3e5, 20.0)] {
        let spec = ShearBuilding {
            stories: n,
            story_mass: mass,
            first_period: period,
        };
        let model = shear_building(&spec).unwrap();
        // Story stiffness from the target period, derived independently.
        let w1 = 2.0 * PI / period;
        let (k, omega, phi) = shear_chain_modes(n, mass, period);
        assert!((spec.story_stiffness() - k).abs() <= 1e-12 * k);
        let mut k_ref = DMatrix::zeros(n, n);
        for i in 0..n {
            k_ref[(i, i)] = if i + 1 < n { 2.0 * k } else { k };
            if i + 1 < n {
                k_ref[(i, i + 1)] = -k;
                k_ref[(i + 1, i)] = -k;
            }
        }
        assert!(max_diff(&model.stiffness, &k_ref) <= 1e-12 * k);
        assert_eq!(model.mass, DMatrix::from_diagonal_element(n, n, mass));
        assert_eq!(model.damping, DMatrix::zeros(n, n));
        assert_eq!(model.influence, DVector::from_element(n, 1.0));

        let md = model.modes().unwrap();
        let e1 = (md.omega[0] - w1).abs() / w1;
        assert!(e1 < 1e-10, "N={n}: ω1 {} vs target {w1} ({e1:.2e})", md.omega[0]);
        assert!((md.frequencies_hz()[0] - 1.0 / period).abs() < 1e-10 / period);
        let mut e_freq = 0.0f64;
        let mut e_shape = 0.0f64;
        for (j, w) in omega.iter().enumerate() {
            e_freq = e_freq.max((md.omega[j] - w).abs() / w);
            let (a, b) = (md.shapes.column(j), phi.column(j));
            let sign = a.dot(&b).signum();
            e_shape = e_shape.max((a - b * sign).amax() / b.amax());
        }
        println!("shear building N={n}: ω1 error {e1:.1e}, max ω_j error {e_freq:.1e}, max shape error {e_shape:.1e}");
        assert!(e_freq < 1e-10, "N={n}: frequencies {e_freq:.2e}");
        assert!(e_shape < 1e-9, "N={n}: mode shapes {e_shape:.2e}");
    }
}

/// A deterministic non-diagonal SPD mass and stiffness (exercises the Cholesky reduction).
fn coupled_model(n: usize) -> StructuralModel {
    let r = DMatrix::from_fn(n, n, |i, j| (((i * 7 + j * 3) % 11) as f64 - 5.0) / 10.0);
    let mass = &r * r.transpose() * 0.1 + DMatrix::from_fn(n, n, |i, j| if i == j { 2.0 + i as f64 } else { 0.0 });
    let s = DMatrix::from_fn(n, n, |i, j| (((i * 5 + j * 2) % 13) as f64 - 6.0) / 6.0);
    let stiffness = (&s * s.transpose() + DMatrix::identity(n, n)) * 1e4;
    StructuralModel::new(mass, DMatrix::zeros(n, n), stiffness, None).unwrap()
}

#[test]
fn modes_are_mass_normalised_and_diagonalise_stiffness() {
    let models = [
        ("coupled 12-DOF", coupled_model(12)),
        (
            "shear building 30",
            shear_building(&ShearBuilding {
                stories: 30,
                story_mass: 1e5,
                first_period: 2.0,
            })
            .unwrap(),
        ),
        ("TMD", tmd_two_dof(&TmdSystem::large_mass_ratio()).unwrap()),
    ];
    for (name, model) in models {
        let md = model.modes().unwrap();
        let n = model.n_dofs();
        let phi = &md.shapes;
        let ortho = max_diff(&(phi.transpose() * &model.mass * phi), &DMatrix::identity(n, n));
        let w2 = DVector::from_iterator(n, md.omega.iter().map(|w| w * w));
        let kk = phi.transpose() * &model.stiffness * phi;
        let stiff = max_diff(&kk, &DMatrix::from_diagonal(&w2)) / w2.max();
        // Each mode solves K φ = ω² M φ.
        let resid = (&model.stiffness * phi - &model.mass * phi * DMatrix::from_diagonal(&w2)).amax()
            / (model.stiffness.amax() * phi.amax());
        println!("{name}: ΦᵀMΦ − I {ortho:.1e}, ΦᵀKΦ − diag(ω²) {stiff:.1e}, residual {resid:.1e}");
        assert!(ortho < 1e-10, "{name}: ΦᵀMΦ − I = {ortho:.2e}");
        assert!(stiff < 1e-10, "{name}: ΦᵀKΦ − diag(ω²) = {stiff:.2e}");
        assert!(resid < 1e-10, "{name}: K φ − ω² M φ = {resid:.2e}");
        assert!(
            md.omega.as_slice().windows(2).all(|w| w[0] <= w[1]),
            "{name}: not sorted"
        );
        // Deterministic sign: the largest-magnitude component of each shape is positive.
        for j in 0..n {
            let col = phi.column(j);
            assert!(col[col.iamax()] > 0.0, "{name}: mode {j} sign");
        }
    }
}

/// Undamped 2-DOF TMD frequencies: `m m_s λ² − (m k_s + m_s (k + k_s)) λ + k k_s = 0`.
#[test]
fn tmd_frequencies_match_closed_form() {
    for p in [TmdSystem::typical(), TmdSystem::large_mass_ratio()] {
        let (k, _) = p.primary();
        let (ms, ks, _) = p.absorber();
        let m = p.mass;
        let (a, b, c) = (m * ms, -(m * ks + ms * (k + ks)), k * ks);
        let disc = (b * b - 4.0 * a * c).sqrt();
        let lambda = [(-b - disc) / (2.0 * a), (-b + disc) / (2.0 * a)];
        let md = tmd_two_dof(&p).unwrap().modes().unwrap();
        for (j, l) in lambda.iter().enumerate() {
            let e = (md.omega[j] - l.sqrt()).abs() / l.sqrt();
            assert!(e < 1e-12, "{p:?} mode {j}: {} vs {}", md.omega[j], l.sqrt());
        }
    }
}

#[test]
fn modal_damping_is_diagonal_in_modal_coordinates() {
    let model = shear_building(&ShearBuilding {
        stories: 10,
        story_mass: 2e5,
        first_period: 1.5,
    })
    .unwrap();
    let md = model.modes().unwrap();
    let n = model.n_dofs();
    let per_mode: Vec<f64> = (1..=n).map(|j| 0.01 * j as f64).collect();
    for zeta in [vec![0.05], per_mode] {
        let c = model
            .clone()
            .with_damping(&DampingSpec::Modal { zeta: zeta.clone() })
            .unwrap()
            .damping;
        let z = |j: usize| if zeta.len() == 1 { zeta[0] } else { zeta[j] };
        let target = DVector::from_fn(n, |j, _| 2.0 * z(j) * md.omega[j]);
        let cc = md.shapes.transpose() * &c * &md.shapes;
        let e = max_diff(&cc, &DMatrix::from_diagonal(&target)) / target.max();
        println!("modal damping ({} ratios): ΦᵀCΦ − diag(2ζω) {e:.1e}", zeta.len());
        assert!(e < 1e-10, "ΦᵀCΦ − diag(2ζω) = {e:.2e}");
        assert!(max_diff(&c, &c.transpose()) == 0.0, "C not symmetric");
        // The free function gives the same matrix.
        let z_all: Vec<f64> = (0..n).map(z).collect();
        let c2 = modal_damping(&model.mass, &model.stiffness, &z_all).unwrap();
        assert!(max_diff(&c, &c2) <= 1e-12 * c.amax());
    }
}

#[test]
fn rayleigh_damping_hits_the_two_chosen_modes() {
    let model = shear_building(&ShearBuilding {
        stories: 8,
        story_mass: 1e5,
        first_period: 1.0,
    })
    .unwrap();
    let md = model.modes().unwrap();
    let zeta = 0.05;
    let c = model
        .clone()
        .with_damping(&DampingSpec::RayleighRatio { zeta, modes: (1, 3) })
        .unwrap()
        .damping;
    let cc = md.shapes.transpose() * &c * &md.shapes;
    let ratio: Vec<f64> = (0..8).map(|j| cc[(j, j)] / (2.0 * md.omega[j])).collect();
    println!("Rayleigh (modes 1, 3): ζ_j = {ratio:.4?}");
    assert!(
        (ratio[0] - zeta).abs() < 1e-12 && (ratio[2] - zeta).abs() < 1e-12,
        "{ratio:?}"
    );
    assert!(
        ratio[1] < zeta - 1e-3,
        "between the two modes the ratio is lower: {ratio:?}"
    );
    assert!(
        ratio[3..].iter().all(|&r| r > zeta + 1e-3),
        "above mode 3 it is higher: {ratio:?}"
    );
    // Rayleigh damping is classical: ΦᵀCΦ is diagonal.
    let off = (0..8).flat_map(|i| (0..8).filter(move |&j| j != i).map(move |j| (i, j)));
    let off_max = off.map(|(i, j)| cc[(i, j)].abs()).fold(0.0, f64::max);
    assert!(off_max < 1e-10 * cc.amax(), "off-diagonal {off_max}");
    // Closed-form coefficients: ζ(ω) = α/(2ω) + βω/2 at both frequencies.
    let (w1, w3) = (md.omega[0], md.omega[2]);
    let (alpha, beta) = rayleigh_coefficients(zeta, w1, w3).unwrap();
    for w in [w1, w3] {
        assert!((alpha / (2.0 * w) + beta * w / 2.0 - zeta).abs() < 1e-14);
    }
    assert!(max_diff(&c, &(&model.mass * alpha + &model.stiffness * beta)) <= 1e-12 * c.amax());
    // Explicit Rayleigh coefficients and an explicit matrix are taken as given.
    let c = model
        .clone()
        .with_damping(&DampingSpec::Rayleigh { alpha: 0.3, beta: 2e-3 })
        .unwrap()
        .damping;
    assert_eq!(c, &model.mass * 0.3 + &model.stiffness * 2e-3);
    let explicit = DMatrix::from_diagonal_element(8, 8, 7.0);
    let c = model
        .with_damping(&DampingSpec::Matrix(explicit.clone()))
        .unwrap()
        .damping;
    assert_eq!(c, explicit);
}

/// The "typical TMD system" of docs/theory.md §1.5 with a 1000 kg, 1 Hz primary structure:
/// m = 1000 kg, k = 39478.4176 N/m, c = 628.3185 N·s/m; m_s = 50 kg, k_s = 1973.9209 N/m,
/// c_s = 62.8319 N·s/m.
#[test]
fn tmd_builder_gives_the_contract_matrices() {
    let p = TmdSystem::typical();
    let model = tmd_two_dof(&p).unwrap();
    let (m, k, c) = (1000.0, 39478.4176, 628.3185);
    let (ms, ks, cs) = (50.0, 1973.9209, 62.8319);
    let mm = dmatrix![m, 0.0; 0.0, ms];
    let kk = dmatrix![k + ks, -ks; -ks, ks];
    let cc = dmatrix![c + cs, -cs; -cs, cs];
    assert_eq!(model.mass, mm);
    assert!(max_diff(&model.stiffness, &kk) < 1e-4, "{}", model.stiffness);
    assert!(max_diff(&model.damping, &cc) < 1e-4, "{}", model.damping);
    assert_eq!(model.influence, dvector![1.0, 1.0]);
    // Exact values from the definitions (ω = 2π f, k = m ω², c = 2ζ m ω; η_m, η_f, ζ_s).
    let w = 2.0 * PI;
    let exact_k = dmatrix![m * w * w + ms * w * w, -ms * w * w; -ms * w * w, ms * w * w];
    let exact_c = dmatrix![
        2.0 * 0.05 * m * w + 2.0 * 0.1 * ms * w, -2.0 * 0.1 * ms * w;
        -2.0 * 0.1 * ms * w, 2.0 * 0.1 * ms * w
    ];
    assert!(max_diff(&model.stiffness, &exact_k) <= 1e-12 * exact_k.amax());
    assert!(max_diff(&model.damping, &exact_c) <= 1e-12 * exact_c.amax());
    // Large mass ratio: η_m = 0.5, ζ = ζ_s = 0.05.
    let model = tmd_two_dof(&TmdSystem::large_mass_ratio()).unwrap();
    let (ms, ks, cs) = (500.0, 500.0 * w * w, 2.0 * 0.05 * 500.0 * w);
    assert_eq!(model.mass, dmatrix![m, 0.0; 0.0, ms]);
    assert!(max_diff(&model.stiffness, &dmatrix![m * w * w + ks, -ks; -ks, ks]) <= 1e-12 * 6e4);
    assert!(max_diff(&model.damping, &dmatrix![2.0 * 0.05 * m * w + cs, -cs; -cs, cs]) <= 1e-12 * 1e3);
    // A detuned absorber: ω_s = η_f ω.
    let p = TmdSystem {
        eta_f: 0.9,
        ..TmdSystem::typical()
    };
    let (ms, ks, cs) = p.absorber();
    assert!((ks - ms * (0.9 * w).powi(2)).abs() < 1e-12 * ks);
    assert!((cs - 2.0 * 0.1 * ms * 0.9 * w).abs() < 1e-12 * cs);
    let model = tmd_two_dof(&p).unwrap();
    assert!((model.damping[(1, 1)] - cs).abs() < 1e-12 * cs);
    assert!((model.stiffness[(1, 1)] - ks).abs() < 1e-12 * ks);
    // SDOF builder.
    let s = sdof(2.0, 0.5, 80.0).unwrap();
    assert_eq!(
        (s.mass[(0, 0)], s.damping[(0, 0)], s.stiffness[(0, 0)]),
        (2.0, 0.5, 80.0)
    );
}

/// The error message of a failed call (the `Display` form the CLI prints).
fn message<T>(r: substep::Result<T>) -> String {
    match r {
        Ok(_) => panic!("expected an error"),
        Err(e) => e.to_string(),
    }
}

fn expect_key<T>(r: substep::Result<T>, key: &str, case: &str) {
    let msg = message(r);
    assert!(msg.contains(key), "{case}: message {msg:?} does not name {key:?}");
}

#[test]
fn bad_model_input_names_the_key() {
    let eye = DMatrix::<f64>::identity(2, 2);
    let k = dmatrix![2.0, -1.0; -1.0, 1.0];
    let new = |m: DMatrix<f64>, c: DMatrix<f64>, k: DMatrix<f64>| StructuralModel::new(m, c, k, None);
    expect_key(
        new(eye.clone(), eye.clone(), dmatrix![2.0, -1.0; -1.1, 1.0]),
        "structure.stiffness",
        "non-symmetric K",
    );
    assert!(message(new(eye.clone(), eye.clone(), dmatrix![2.0, -1.0; -1.1, 1.0])).contains("symmetric"));
    expect_key(
        new(eye.clone(), dmatrix![1.0, 2.0; 3.0, 1.0], k.clone()),
        "structure.damping",
        "non-symmetric C",
    );
    expect_key(
        new(eye.clone(), DMatrix::identity(3, 3), k.clone()),
        "structure.damping",
        "wrong size C",
    );
    expect_key(
        new(eye.clone(), eye.clone(), DMatrix::zeros(2, 3)),
        "structure.stiffness",
        "non-square K",
    );
    expect_key(
        new(dmatrix![1.0, 0.0; 0.0, -1.0], eye.clone(), k.clone()),
        "structure.mass",
        "non-SPD mass",
    );
    assert!(message(new(dmatrix![1.0, 2.0; 2.0, 1.0], eye.clone(), k.clone())).contains("positive definite"));
    expect_key(
        new(DMatrix::zeros(0, 0), DMatrix::zeros(0, 0), DMatrix::zeros(0, 0)),
        "structure.mass",
        "empty",
    );
    expect_key(
        new(eye.clone(), eye.clone(), dmatrix![f64::NAN, 0.0; 0.0, 1.0]),
        "structure.stiffness",
        "NaN in K",
    );
    expect_key(
        StructuralModel::new(eye.clone(), eye.clone(), k.clone(), Some(dvector![1.0, 1.0, 1.0])),
        "structure.influence",
        "influence length",
    );
    // Stiffness that is not positive semi-definite is caught by the modal analysis.
    expect_key(
        modes(&eye, &dmatrix![-1.0, 0.0; 0.0, 1.0]),
        "structure.stiffness",
        "indefinite K",
    );

    // Damping specifications.
    let model = shear_building(&ShearBuilding {
        stories: 3,
        story_mass: 1.0,
        first_period: 1.0,
    })
    .unwrap();
    let with = |spec: DampingSpec| model.clone().with_damping(&spec);
    expect_key(
        with(DampingSpec::Modal { zeta: vec![0.05, 0.05] }),
        "structure.modal.zeta",
        "zeta count",
    );
    expect_key(
        with(DampingSpec::Modal { zeta: vec![-0.05] }),
        "structure.modal.zeta",
        "negative zeta",
    );
    expect_key(
        with(DampingSpec::RayleighRatio {
            zeta: 0.05,
            modes: (0, 2),
        }),
        "structure.rayleigh.modes",
        "mode 0",
    );
    expect_key(
        with(DampingSpec::RayleighRatio {
            zeta: 0.05,
            modes: (1, 4),
        }),
        "structure.rayleigh.modes",
        "mode 4 of 3",
    );
    expect_key(
        with(DampingSpec::RayleighRatio {
            zeta: 0.05,
            modes: (2, 2),
        }),
        "structure.rayleigh.modes",
        "same mode",
    );
    expect_key(
        with(DampingSpec::RayleighRatio {
            zeta: -0.05,
            modes: (1, 2),
        }),
        "structure.rayleigh.zeta",
        "negative zeta",
    );
    expect_key(
        with(DampingSpec::Rayleigh { alpha: -1.0, beta: 0.0 }),
        "structure.rayleigh.alpha",
        "negative alpha",
    );
    expect_key(
        with(DampingSpec::Rayleigh {
            alpha: 0.0,
            beta: f64::NAN,
        }),
        "structure.rayleigh.beta",
        "NaN beta",
    );
    expect_key(
        with(DampingSpec::Matrix(DMatrix::identity(2, 2))),
        "structure.damping",
        "explicit C of wrong size",
    );
    expect_key(
        rayleigh_coefficients(0.05, 3.0, 3.0),
        "structure.rayleigh.modes",
        "equal frequencies",
    );
    // The free function needs one ratio per mode (it used to panic in the matrix product).
    expect_key(
        modal_damping(&model.mass, &model.stiffness, &[0.05]),
        "structure.modal.zeta",
        "modal_damping count",
    );

    // Builders.
    let sb = |stories, story_mass, first_period| {
        shear_building(&ShearBuilding {
            stories,
            story_mass,
            first_period,
        })
    };
    expect_key(sb(0, 1.0, 1.0), "structure.shear_building.stories", "0 stories");
    expect_key(sb(3, 0.0, 1.0), "structure.shear_building.story_mass", "zero mass");
    expect_key(
        sb(3, 1.0, -1.0),
        "structure.shear_building.first_period",
        "negative period",
    );
    let typical = TmdSystem::typical();
    expect_key(
        tmd_two_dof(&TmdSystem { eta_m: 0.0, ..typical }),
        "tmd.eta_m",
        "eta_m = 0",
    );
    expect_key(
        tmd_two_dof(&TmdSystem {
            frequency: f64::NAN,
            ..typical
        }),
        "tmd.frequency",
        "NaN frequency",
    );
    expect_key(
        tmd_two_dof(&TmdSystem {
            zeta_s: -0.1,
            ..typical
        }),
        "tmd.zeta_s",
        "negative zeta_s",
    );
    expect_key(sdof(0.0, 0.0, 1.0), "mass", "sdof mass 0");
    expect_key(sdof(1.0, -1.0, 1.0), "damping", "sdof negative damping");
}

#[test]
fn bad_integrator_input_names_the_key() {
    let model = sdof(1.0, 0.1, 100.0).unwrap();
    let f0 = dvector![0.0];
    let schemes = [
        Scheme::Newmark { beta: 0.25, gamma: 0.5 },
        Scheme::Newmark { beta: 0.0, gamma: 0.5 },
        Scheme::Hht { alpha: -0.1 },
        Scheme::AlphaOs { alpha: -0.1 },
        Scheme::Exact,
    ];
    for scheme in schemes {
        for dt in [0.0, -0.01, f64::NAN, f64::INFINITY] {
            expect_key(
                scheme.build(&model, dt, &f0),
                "integrator.dt",
                &format!("{scheme:?} dt={dt}"),
            );
        }
    }
    // The constructors check dt themselves too.
    expect_key(
        Newmark::new(&model, 0.0, 0.25, 0.5, &f0),
        "integrator.dt",
        "Newmark::new",
    );
    expect_key(
        ExplicitNewmark::new(&model, -1.0, 0.5, &f0),
        "integrator.dt",
        "ExplicitNewmark::new",
    );
    expect_key(Hht::new(&model, 0.0, -0.1, &f0), "integrator.dt", "Hht::new");
    expect_key(AlphaOs::new(&model, 0.0, -0.1, &f0), "integrator.dt", "AlphaOs::new");
    expect_key(ExactFoh::new(&model, 0.0, &f0), "integrator.dt", "ExactFoh::new");
    expect_key(
        NewmarkCore::new(&model, 0.0, 0.25, 0.5),
        "integrator.dt",
        "NewmarkCore::new",
    );
    expect_key(
        NewmarkConstants::new(0.25, 0.5, 0.0),
        "integrator.dt",
        "NewmarkConstants::new",
    );

    // Hilber's α outside [−⅓, 0].
    for alpha in [0.1, -0.34, -1.0, f64::NAN] {
        for scheme in [Scheme::Hht { alpha }, Scheme::AlphaOs { alpha }] {
            expect_key(
                scheme.build(&model, 0.01, &f0),
                "integrator.alpha",
                &format!("{scheme:?}"),
            );
        }
    }
    // KR-α's ρ∞ outside [0, 1]; CR and KR-α on a model with a massless DOF (they solve M a = …).
    for rho_inf in [-0.1, 1.1, f64::NAN] {
        expect_key(
            Scheme::KrAlpha { rho_inf }.build(&model, 0.01, &f0),
            "integrator.rho_inf",
            &format!("kr_alpha {rho_inf}"),
        );
    }
    // (StructuralModel::new refuses such a mass; a library caller can still build one by hand.)
    let massless = StructuralModel {
        mass: dmatrix![1.0, 0.0; 0.0, 0.0],
        damping: DMatrix::zeros(2, 2),
        stiffness: dmatrix![2.0, -1.0; -1.0, 1.0],
        influence: dvector![1.0, 1.0],
    };
    for scheme in [Scheme::Cr, Scheme::KrAlpha { rho_inf: 0.5 }] {
        let msg = message(scheme.build(&massless, 0.01, &DVector::zeros(2)));
        assert!(
            msg.contains("integrator.scheme") && msg.contains("mass"),
            "{scheme:?}: {msg}"
        );
    }
    assert!(Scheme::Hht { alpha: -1.0 / 3.0 }.build(&model, 0.01, &f0).is_ok());
    assert!(Scheme::Hht { alpha: 0.0 }.build(&model, 0.01, &f0).is_ok());
    // Newmark parameters.
    expect_key(
        Scheme::Newmark { beta: -0.1, gamma: 0.5 }.build(&model, 0.01, &f0),
        "integrator.beta",
        "beta < 0",
    );
    expect_key(
        Scheme::Newmark {
            beta: 0.25,
            gamma: -0.5,
        }
        .build(&model, 0.01, &f0),
        "integrator.gamma",
        "gamma < 0",
    );
    expect_key(
        Scheme::Newmark { beta: 0.0, gamma: -0.5 }.build(&model, 0.01, &f0),
        "integrator.gamma",
        "explicit gamma < 0",
    );

    // Scheme names.
    let msg = message(Scheme::from_name("runge_kutta", 0.25, 0.5, 0.0, 0.5));
    assert!(
        msg.contains("integrator.scheme") && msg.contains("runge_kutta"),
        "{msg}"
    );
    for (name, expected) in [
        ("newmark", Scheme::Newmark { beta: 0.3, gamma: 0.6 }),
        ("central_difference", Scheme::Newmark { beta: 0.0, gamma: 0.5 }),
        ("cdm", Scheme::Newmark { beta: 0.0, gamma: 0.5 }),
        (
            "fox_goodwin",
            Scheme::Newmark {
                beta: 1.0 / 12.0,
                gamma: 0.5,
            },
        ),
        (
            "linear_acceleration",
            Scheme::Newmark {
                beta: 1.0 / 6.0,
                gamma: 0.5,
            },
        ),
        ("average_acceleration", Scheme::Newmark { beta: 0.25, gamma: 0.5 }),
        ("trapezoidal", Scheme::Newmark { beta: 0.25, gamma: 0.5 }),
        ("galerkin", Scheme::Newmark { beta: 0.8, gamma: 1.5 }),
        ("backward_difference", Scheme::Newmark { beta: 1.0, gamma: 1.5 }),
        ("hht", Scheme::Hht { alpha: -0.2 }),
        ("alpha_os", Scheme::AlphaOs { alpha: -0.2 }),
        ("cr", Scheme::Cr),
        ("chen_ricles", Scheme::Cr),
        ("kr_alpha", Scheme::KrAlpha { rho_inf: 0.5 }),
        ("exact", Scheme::Exact),
    ] {
        assert_eq!(
            Scheme::from_name(name, 0.3, 0.6, -0.2, 0.5).unwrap(),
            expected,
            "{name}"
        );
    }
}

/// Library callers (not only configs, which `[limits]` checks first) get an error, not a
/// capacity-overflow panic, for sizes that cannot be indexed.
#[test]
fn builders_refuse_sizes_that_cannot_be_indexed() {
    let b = ShearBuilding {
        stories: usize::MAX,
        story_mass: 1.0,
        first_period: 1.0,
    };
    assert!(message(substep::model::shear_building_sparse(&b)).contains("structure.shear_building.stories"));
    let f = substep::model::Frame2d {
        bays: usize::MAX / 2,
        stories: 10,
        ..Default::default()
    };
    assert!(message(substep::model::frame_2d(&f)).contains("cannot be indexed"));
}

/// The exponential of a matrix far too stiff for its time step is an error, not a panic (was:
/// `Option::unwrap()` on `None` inside nalgebra at a stiffness of 1e60 N/m), and moderate
/// norms keep nalgebra's result bit for bit.
#[test]
fn matrix_exponential_refuses_instead_of_panicking() {
    let model = substep::model::sdof(50.0, 62.8, 1e60).unwrap();
    let e = message(ExactFoh::new(&model, 0.01, &DVector::zeros(1)));
    assert!(
        e.starts_with("exact integrator: cannot be computed for ‖A·dt‖₁ = 2.000e56"),
        "{e}"
    );
    let a = dmatrix![0.0, 1.0; -400.0, -2.0];
    assert_eq!(substep::linalg::expm(&a).unwrap(), a.exp());
    // Pre-scaled beyond norm 1000: a stiff undamped oscillator keeps |Φ| bounded (rotation).
    let w = 3.0e4_f64;
    let phi = substep::linalg::expm(&dmatrix![0.0, 1.0; -w * w, 0.0]).unwrap();
    let exact = [w.cos(), w.sin() / w, -w * w.sin(), w.cos()];
    for (got, want) in phi.iter().zip([exact[0], exact[2], exact[1], exact[3]]) {
        assert!((got - want).abs() <= 1e-6 * want.abs().max(1.0), "{got} vs {want}");
    }
    assert!(substep::linalg::expm(&dmatrix![f64::NAN]).is_none());
}

/// Balancing and eigenvalues terminate on entries near the f64 range (nalgebra's balancing
/// looped forever on a specimen of stiffness 1e90 or mass 1e-300).
#[test]
fn eigenvalues_terminate_on_extreme_matrices() {
    for a in [
        dmatrix![0.0, 1.0; -2e303, -1.0],
        dmatrix![0.0, 1.0; -1e90, -1e-300],
        dmatrix![1e300, 1e-300; 1e-300, 1e300],
    ] {
        let _ = substep::linalg::eigenvalues(&a);
    }
    let ev = substep::linalg::eigenvalues(&dmatrix![0.0, 1.0; -4.0, 0.0]).unwrap();
    assert!(
        ev.iter()
            .all(|z| (z.im.abs() - 2.0).abs() < 1e-12 && z.re.abs() < 1e-12)
    );
}
