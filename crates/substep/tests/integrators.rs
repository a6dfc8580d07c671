//! Forced-response verification of the integrators against independent implementations
//! written here (acceleration-form Newmark, the three-point recurrence of docs/theory.md §2.1, a
//! monolithic block solve of the HHT equations, a closed-form modal solution) and against
//! closed-form solutions.

mod common;

use common::{FAMILY, ground_loads, rel_error, rel_errors, shear_chain_modes, simulate, sine_sweep};
use nalgebra::{DMatrix, DVector, dvector};
use std::f64::consts::PI;
use substep::integrate::{Kinematics, Scheme};
use substep::model::{DampingSpec, ShearBuilding, StructuralModel, TmdSystem, sdof, shear_building, tmd_two_dof};

/// Newmark(β, γ) in acceleration form, solved with LU:
/// `(M + γΔt C + βΔt² K) a_{i+1} = f_{i+1} − C ṽ − K ũ`. Valid for β = 0 too.
fn newmark_acceleration_form(
    model: &StructuralModel,
    dt: f64,
    beta: f64,
    gamma: f64,
    loads: &[DVector<f64>],
) -> Vec<Kinematics> {
    let (m, c, k) = (&model.mass, &model.damping, &model.stiffness);
    let lhs = (m + c * (gamma * dt) + k * (beta * dt * dt)).lu();
    let n = model.n_dofs();
    let mut s = Kinematics {
        u: DVector::zeros(n),
        v: DVector::zeros(n),
        a: m.clone().lu().solve(&loads[0]).expect("M is regular"),
    };
    let mut out = vec![s.clone()];
    for f in &loads[1..] {
        let u_pred = &s.u + &s.v * dt + &s.a * ((0.5 - beta) * dt * dt);
        let v_pred = &s.v + &s.a * ((1.0 - gamma) * dt);
        let a = lhs.solve(&(f - c * &v_pred - k * &u_pred)).expect("regular");
        s = Kinematics {
            u: u_pred + &a * (beta * dt * dt),
            v: v_pred + &a * (gamma * dt),
            a,
        };
        out.push(s.clone());
    }
    out
}

/// The three-point recurrence of docs/theory.md §2.1 for displacements only, started from `u_0 = 0`
/// and the given `u_1`.
fn three_point_displacements(
    model: &StructuralModel,
    dt: f64,
    beta: f64,
    gamma: f64,
    loads: &[DVector<f64>],
    u1: &DVector<f64>,
) -> Vec<DVector<f64>> {
    let (m, c, k) = (&model.mass, &model.damping, &model.stiffness);
    let dt2 = dt * dt;
    let w = [beta, 0.5 - 2.0 * beta + gamma, 0.5 + beta - gamma];
    let lhs = (m + c * (gamma * dt) + k * (beta * dt2)).lu();
    let b = m * -2.0 + c * ((1.0 - 2.0 * gamma) * dt) + k * (w[1] * dt2);
    let cc = m - c * ((1.0 - gamma) * dt) + k * (w[2] * dt2);
    let mut u = vec![DVector::zeros(model.n_dofs()), u1.clone()];
    for i in 1..loads.len() - 1 {
        let rhs = (&loads[i + 1] * w[0] + &loads[i] * w[1] + &loads[i - 1] * w[2]) * dt2 - &b * &u[i] - &cc * &u[i - 1];
        u.push(lhs.solve(&rhs).expect("regular"));
    }
    u
}

/// HHT-α (docs/theory.md §2.4) as one monolithic linear system per step in the unknowns
/// `[u_{i+1}; v_{i+1}; a_{i+1}]` (3n × 3n, LU): the two Newmark relations and the HHT
/// equilibrium `M a' + (1+α)(C v' + K u') − α(C v + K u) = (1+α) f' − α f`.
fn hht_block_reference(model: &StructuralModel, dt: f64, alpha: f64, loads: &[DVector<f64>]) -> Vec<Kinematics> {
    let (m, c, k) = (&model.mass, &model.damping, &model.stiffness);
    let n = model.n_dofs();
    let gamma = 0.5 - alpha;
    let beta = (1.0 - alpha).powi(2) / 4.0;
    let eye = DMatrix::<f64>::identity(n, n);
    let mut big = DMatrix::zeros(3 * n, 3 * n);
    big.view_mut((0, 0), (n, n)).copy_from(&eye);
    big.view_mut((0, 2 * n), (n, n)).copy_from(&(&eye * (-beta * dt * dt)));
    big.view_mut((n, n), (n, n)).copy_from(&eye);
    big.view_mut((n, 2 * n), (n, n)).copy_from(&(&eye * (-gamma * dt)));
    big.view_mut((2 * n, 0), (n, n)).copy_from(&(k * (1.0 + alpha)));
    big.view_mut((2 * n, n), (n, n)).copy_from(&(c * (1.0 + alpha)));
    big.view_mut((2 * n, 2 * n), (n, n)).copy_from(m);
    let lu = big.lu();
    let mut s = Kinematics {
        u: DVector::zeros(n),
        v: DVector::zeros(n),
        a: m.clone().lu().solve(&loads[0]).expect("M is regular"),
    };
    let mut out = vec![s.clone()];
    for i in 0..loads.len() - 1 {
        let mut rhs = DVector::zeros(3 * n);
        rhs.rows_mut(0, n)
            .copy_from(&(&s.u + &s.v * dt + &s.a * ((0.5 - beta) * dt * dt)));
        rhs.rows_mut(n, n).copy_from(&(&s.v + &s.a * ((1.0 - gamma) * dt)));
        rhs.rows_mut(2 * n, n)
            .copy_from(&(&loads[i + 1] * (1.0 + alpha) - &loads[i] * alpha + (c * &s.v + k * &s.u) * alpha));
        let x = lu.solve(&rhs).expect("regular");
        s = Kinematics {
            u: x.rows(0, n).into_owned(),
            v: x.rows(n, n).into_owned(),
            a: x.rows(2 * n, n).into_owned(),
        };
        out.push(s.clone());
    }
    out
}

/// Typical TMD system under a 1 m/s² sine sweep plus a constant `offset` [m/s²] (a non-zero
/// offset makes `f_0 ≠ 0`, which exercises the consistent initial acceleration).
fn tmd_sweep(f0: f64, f1: f64, duration: f64, dt: f64, offset: f64) -> (StructuralModel, Vec<DVector<f64>>) {
    let model = tmd_two_dof(&TmdSystem::typical()).unwrap();
    let ag: Vec<f64> = sine_sweep(f0, f1, duration, dt, 1.0)
        .iter()
        .map(|a| a + offset)
        .collect();
    let loads = ground_loads(&model, &ag);
    (model, loads)
}

/// Acceptance 1(a): average acceleration on the non-classically damped 2-DOF TMD model,
/// 0.1–5 Hz sweep over 20 s, Δt = 0.01 s, against the acceleration form and the three-point
/// recurrence.
#[test]
fn average_acceleration_matches_independent_forms_on_tmd() {
    let dt = 0.01;
    let (model, loads) = tmd_sweep(0.1, 5.0, 20.0, dt, 0.0);
    assert_eq!(loads.len(), 2001);
    let sim = simulate(Scheme::Newmark { beta: 0.25, gamma: 0.5 }, &model, dt, &loads);
    let reference = newmark_acceleration_form(&model, dt, 0.25, 0.5, &loads);
    let [eu, ev, ea] = rel_errors(&sim, &reference);
    println!("TMD average acceleration vs acceleration form: u {eu:.2e}, v {ev:.2e}, a {ea:.2e}");
    for (what, e) in [("u", eu), ("v", ev), ("a", ea)] {
        assert!(e < 1e-10, "{what}: relative error {e:.3e}");
    }
    let u3 = three_point_displacements(&model, dt, 0.25, 0.5, &loads, &reference[1].u);
    let e3 = rel_error(sim.iter().map(|s| &s.u), &u3);
    println!("TMD average acceleration vs three-point recurrence: u {e3:.2e}");
    assert!(e3 < 1e-10, "three-point: relative error {e3:.3e}");
    // The response is substantial (not a trivially small reference).
    let peak = sim.iter().map(|s| s.u.amax()).fold(0.0, f64::max);
    assert!(peak > 1e-3, "peak displacement {peak}");
}

/// Every member of the three-point family (including the explicit β = 0 path) against the
/// acceleration form (u, v, a) and the three-point recurrence (u).
#[test]
fn newmark_family_matches_independent_forms_on_tmd() {
    let dt = 0.01;
    let (model, loads) = tmd_sweep(0.1, 5.0, 10.0, dt, 0.3);
    for (name, beta, gamma) in FAMILY {
        let sim = simulate(Scheme::Newmark { beta, gamma }, &model, dt, &loads);
        let reference = newmark_acceleration_form(&model, dt, beta, gamma, &loads);
        let [eu, ev, ea] = rel_errors(&sim, &reference);
        let u3 = three_point_displacements(&model, dt, beta, gamma, &loads, &reference[1].u);
        let e3 = rel_error(sim.iter().map(|s| &s.u), &u3);
        println!("{name}: u {eu:.2e}, v {ev:.2e}, a {ea:.2e}, three-point u {e3:.2e}");
        for (what, e) in [("u", eu), ("v", ev), ("a", ea), ("three-point u", e3)] {
            assert!(e < 1e-10, "{name} {what}: relative error {e:.3e}");
        }
    }
}

/// Acceptance 1(b): average acceleration on a 1000-story shear building with 5 % modal
/// damping against the closed-form modal solution: mode shapes
/// `φ_j(r) = 2 sin(r θ_j) / √(m (2N+1))`, `θ_j = (2j−1)π/(2N+1)`, frequencies
/// `ω_j = 2 √(k/m) sin(θ_j/2)`, each mode integrated as a scalar SDOF by average acceleration.
#[test]
fn average_acceleration_matches_modal_solution_on_1000_story_building() {
    let (n, mass, period) = (1000usize, 1e5, 20.0);
    let dt = 0.01;
    let zeta = 0.05;
    let steps = 200;
    let model = shear_building(&ShearBuilding {
        stories: n,
        story_mass: mass,
        first_period: period,
    })
    .unwrap()
    .with_damping(&DampingSpec::Modal { zeta: vec![zeta] })
    .unwrap();
    let ag = sine_sweep(0.5, 5.0, steps as f64 * dt, dt, 1.0);
    let loads = ground_loads(&model, &ag);
    let sim = simulate(Scheme::Newmark { beta: 0.25, gamma: 0.5 }, &model, dt, &loads);

    // Closed-form modes of the uniform fixed-free shear chain.
    let (k_story, omega, phi) = shear_chain_modes(n, mass, period);
    assert!((k_story - model.stiffness[(n - 1, n - 1)]).abs() < 1e-12 * k_story);
    // Modal participation per unit ground acceleration: p_j = φ_jᵀ (−M ι) = −m Σ_r φ_j(r).
    let gamma_j: Vec<f64> = (0..n).map(|j| -mass * phi.column(j).sum()).collect();

    // Scalar average-acceleration Newmark per mode (acceleration form).
    let (mut q, mut qd) = (vec![0.0; n], vec![0.0; n]);
    let mut qdd: Vec<f64> = gamma_j.iter().map(|g| g * ag[0]).collect();
    let mut reference = Vec::with_capacity(steps + 1);
    let to_dofs = |q: &[f64], qd: &[f64], qdd: &[f64]| Kinematics {
        u: &phi * DVector::from_column_slice(q),
        v: &phi * DVector::from_column_slice(qd),
        a: &phi * DVector::from_column_slice(qdd),
    };
    reference.push(to_dofs(&q, &qd, &qdd));
    for &a_next in &ag[1..] {
        for j in 0..n {
            let (w, c) = (omega[j], 2.0 * zeta * omega[j]);
            let u_pred = q[j] + dt * qd[j] + 0.25 * dt * dt * qdd[j];
            let v_pred = qd[j] + 0.5 * dt * qdd[j];
            let acc =
                (gamma_j[j] * a_next - c * v_pred - w * w * u_pred) / (1.0 + 0.5 * dt * c + 0.25 * dt * dt * w * w);
            q[j] = u_pred + 0.25 * dt * dt * acc;
            qd[j] = v_pred + 0.5 * dt * acc;
            qdd[j] = acc;
        }
        reference.push(to_dofs(&q, &qd, &qdd));
    }
    // The two references (dense acceleration form with the library's C, closed-form modal
    // solution) must agree with each other first.
    let dense = newmark_acceleration_form(&model, dt, 0.25, 0.5, &loads);
    let [du, dv, da] = rel_errors(&dense, &reference);
    println!("1000-story: acceleration form vs modal solution: u {du:.2e}, v {dv:.2e}, a {da:.2e}");
    for (what, e) in [("u", du), ("v", dv), ("a", da)] {
        assert!(e < 1e-10, "references disagree in {what}: {e:.3e}");
    }
    let [eu, ev, ea] = rel_errors(&sim, &reference);
    println!("1000-story: library Newmark vs modal solution: u {eu:.2e}, v {ev:.2e}, a {ea:.2e}");
    assert!(eu < 1e-10, "u: relative error {eu:.3e}");
    // Velocity and acceleration are looser: the effective-stiffness form (docs/theory.md §2.2) pushes
    // the whole displacement through the dense 1000×1000 solve and then differences it,
    // `a_{i+1} = a0 (u_{i+1} − u_i) − …` with a0 = 4/Δt² = 4e4, so its round-off is about
    // ten times that of the acceleration form (measured 1.3e-10 / 1.5e-10 here).
    assert!(ev < 1e-9, "v: relative error {ev:.3e}");
    assert!(ea < 1e-9, "a: relative error {ea:.3e}");
    let peak = sim.iter().map(|s| s.u.amax()).fold(0.0, f64::max);
    assert!(peak > 1e-3, "peak displacement {peak}");
}

/// HHT-α (including Hilber's limit α = −⅓) against the monolithic block solve; this also pins
/// the load term `−α f_i` (using `f_{i+1}` twice changes each step by `α Δt ḟ`, far above
/// round-off).
#[test]
fn hht_matches_block_reference_on_tmd() {
    let dt = 0.01;
    let (model, loads) = tmd_sweep(0.1, 5.0, 20.0, dt, 0.3);
    for alpha in [0.0, -0.05, -0.1, -0.3, -1.0 / 3.0] {
        let sim = simulate(Scheme::Hht { alpha }, &model, dt, &loads);
        let reference = hht_block_reference(&model, dt, alpha, &loads);
        let [eu, ev, ea] = rel_errors(&sim, &reference);
        println!("HHT alpha = {alpha:.4}: u {eu:.2e}, v {ev:.2e}, a {ea:.2e}");
        for (what, e) in [("u", eu), ("v", ev), ("a", ea)] {
            assert!(e < 1e-10, "alpha {alpha} {what}: relative error {e:.3e}");
        }
    }
}

/// The same on an SDOF with a load that jumps (step load at step 10): with `f_{i+1}` in place
/// of `f_i` the step across the jump is wrong by `α ΔF`.
#[test]
fn hht_uses_previous_load_for_step_load() {
    let model = sdof(2.0, 0.3, 50.0).unwrap();
    let dt = 0.05;
    let loads: Vec<DVector<f64>> = (0..200).map(|i| dvector![if i >= 10 { 7.0 } else { 0.0 }]).collect();
    for alpha in [-0.1, -0.3] {
        let sim = simulate(Scheme::Hht { alpha }, &model, dt, &loads);
        let reference = hht_block_reference(&model, dt, alpha, &loads);
        let [eu, ev, ea] = rel_errors(&sim, &reference);
        for (what, e) in [("u", eu), ("v", ev), ("a", ea)] {
            assert!(e < 1e-12, "alpha {alpha} {what}: relative error {e:.3e}");
        }
    }
}

/// HHT with α = 0 is Newmark average acceleration.
#[test]
fn hht_alpha_zero_is_average_acceleration() {
    let dt = 0.01;
    let (model, loads) = tmd_sweep(0.1, 5.0, 10.0, dt, 0.3);
    let hht = simulate(Scheme::Hht { alpha: 0.0 }, &model, dt, &loads);
    let nm = simulate(Scheme::Newmark { beta: 0.25, gamma: 0.5 }, &model, dt, &loads);
    let [eu, ev, ea] = rel_errors(&hht, &nm);
    println!("HHT(0) vs average acceleration: u {eu:.2e}, v {ev:.2e}, a {ea:.2e}");
    for (what, e) in [("u", eu), ("v", ev), ("a", ea)] {
        assert!(e < 1e-11, "{what}: relative error {e:.3e}");
    }
}

/// α-OS with a linear restoring force `K ũ` is algebraically HHT (docs/theory.md §2.5).
#[test]
fn alpha_os_equals_hht_for_linear_model() {
    let dt = 0.01;
    let (model, loads) = tmd_sweep(0.1, 5.0, 20.0, dt, 0.3);
    for alpha in [0.0, -0.1, -0.3] {
        let os = simulate(Scheme::AlphaOs { alpha }, &model, dt, &loads);
        let hht = simulate(Scheme::Hht { alpha }, &model, dt, &loads);
        let [eu, ev, ea] = rel_errors(&os, &hht);
        println!("alpha-OS vs HHT, alpha = {alpha}: u {eu:.2e}, v {ev:.2e}, a {ea:.2e}");
        for (what, e) in [("u", eu), ("v", ev), ("a", ea)] {
            assert!(e < 1e-12, "alpha {alpha} {what}: relative error {e:.3e}");
        }
    }
}

/// Acceptance 4: average acceleration at Δt = 0.01 s is within 1 % of the exact FOH solution
/// in the peak displacement of each DOF of the typical TMD system (0.2–3 Hz sweep, 60 s,
/// 1 m/s²).
#[test]
fn average_acceleration_peaks_within_one_percent_of_exact() {
    let dt = 0.01;
    let (model, loads) = tmd_sweep(0.2, 3.0, 60.0, dt, 0.0);
    let nm = simulate(Scheme::Newmark { beta: 0.25, gamma: 0.5 }, &model, dt, &loads);
    let ex = simulate(Scheme::Exact, &model, dt, &loads);
    for dof in 0..2 {
        let peak = |h: &[Kinematics]| h.iter().map(|s| s.u[dof].abs()).fold(0.0, f64::max);
        let (p_nm, p_ex) = (peak(&nm), peak(&ex));
        let rel = (p_nm - p_ex).abs() / p_ex;
        println!(
            "DOF {}: peak Newmark {p_nm:.6e} m, exact {p_ex:.6e} m, rel diff {rel:.2e}",
            dof + 1
        );
        assert!(p_ex > 1e-3, "exact peak too small: {p_ex}");
        assert!(rel < 0.01, "DOF {}: peak differs by {rel:.3e}", dof + 1);
    }
    let e = rel_error(nm.iter().map(|s| &s.u), ex.iter().map(|s| &s.u));
    println!("Newmark vs exact, whole displacement history: {e:.2e}");
}

/// Response of `m ü + c u̇ + k u = t` (unit-slope ramp from rest), displacement and velocity:
/// `u = (1/k)[t − 2ζ/ω + e^{−ζωt}(2ζ/ω cos ω_d t + (2ζ²−1)/ω_d sin ω_d t)]`,
/// `u̇ = (1/k)[1 − e^{−ζωt}(cos ω_d t + ζω/ω_d sin ω_d t)]`; zero for `t ≤ 0`.
fn ramp_response(k: f64, w: f64, zeta: f64, t: f64) -> (f64, f64) {
    if t <= 0.0 {
        return (0.0, 0.0);
    }
    let wd = w * (1.0 - zeta * zeta).sqrt();
    let e = (-zeta * w * t).exp();
    let (s, c) = (wd * t).sin_cos();
    let u = (t - 2.0 * zeta / w + e * (2.0 * zeta / w * c + (2.0 * zeta * zeta - 1.0) / wd * s)) / k;
    let v = (1.0 - e * (c + zeta * w / wd * s)) / k;
    (u, v)
}

/// ExactFoh against closed forms: undamped ramp `f = F0 t` (`u = F0/k (t − sin ωt/ω)`) and a
/// damped triangular pulse (superposition of ramps; exercises the load kinks).
#[test]
fn exact_foh_matches_closed_form_ramp_and_pulse() {
    let (m, dt, n_steps) = (2.0, 0.01, 1000usize);
    let w = 2.0 * PI * 1.3;
    let k = m * w * w;
    let f0 = 3.0;

    // Undamped ramp.
    let model = sdof(m, 0.0, k).unwrap();
    let loads: Vec<DVector<f64>> = (0..=n_steps).map(|i| dvector![f0 * i as f64 * dt]).collect();
    let sim = simulate(Scheme::Exact, &model, dt, &loads);
    let u_ref: Vec<DVector<f64>> = (0..=n_steps)
        .map(|i| {
            let t = i as f64 * dt;
            dvector![f0 / k * (t - (w * t).sin() / w)]
        })
        .collect();
    let v_ref: Vec<DVector<f64>> = (0..=n_steps)
        .map(|i| dvector![f0 / k * (1.0 - (w * i as f64 * dt).cos())])
        .collect();
    let eu = rel_error(sim.iter().map(|s| &s.u), &u_ref);
    let ev = rel_error(sim.iter().map(|s| &s.v), &v_ref);
    // Cross-check the closed form used below against this one (ζ = 0).
    for i in [1, 37, 500, 1000] {
        let t = i as f64 * dt;
        let (u, v) = ramp_response(k, w, 0.0, t);
        assert!((u * f0 - u_ref[i][0]).abs() < 1e-15 && (v * f0 - v_ref[i][0]).abs() < 1e-14);
    }
    println!("exact FOH, undamped ramp: u {eu:.2e}, v {ev:.2e}");
    assert!(eu < 1e-10 && ev < 1e-10, "ramp: u {eu:.3e}, v {ev:.3e}");

    // Damped triangular pulse: f = F0 [r(t) − 2 r(t − t1) + r(t − 2 t1)], r(t) = max(t, 0).
    let zeta = 0.05;
    let model = sdof(m, 2.0 * zeta * m * w, k).unwrap();
    let t1 = 0.5;
    let r = |t: f64| t.max(0.0);
    let loads: Vec<DVector<f64>> = (0..=n_steps)
        .map(|i| {
            let t = i as f64 * dt;
            dvector![f0 * (r(t) - 2.0 * r(t - t1) + r(t - 2.0 * t1))]
        })
        .collect();
    let sim = simulate(Scheme::Exact, &model, dt, &loads);
    let (mut u_ref, mut v_ref) = (Vec::new(), Vec::new());
    for i in 0..=n_steps {
        let t = i as f64 * dt;
        let (ua, va) = ramp_response(k, w, zeta, t);
        let (ub, vb) = ramp_response(k, w, zeta, t - t1);
        let (uc, vc) = ramp_response(k, w, zeta, t - 2.0 * t1);
        u_ref.push(dvector![f0 * (ua - 2.0 * ub + uc)]);
        v_ref.push(dvector![f0 * (va - 2.0 * vb + vc)]);
    }
    let eu = rel_error(sim.iter().map(|s| &s.u), &u_ref);
    let ev = rel_error(sim.iter().map(|s| &s.v), &v_ref);
    println!("exact FOH, damped triangular pulse: u {eu:.2e}, v {ev:.2e}");
    assert!(eu < 1e-10 && ev < 1e-10, "pulse: u {eu:.3e}, v {ev:.3e}");
    // Acceleration from equilibrium a = (f − c v − k u)/m with the closed-form u, v.
    let c = 2.0 * zeta * m * w;
    let a_ref: Vec<DVector<f64>> = (0..=n_steps)
        .map(|i| (&loads[i] - &v_ref[i] * c - &u_ref[i] * k) / m)
        .collect();
    let ea = rel_error(sim.iter().map(|s| &s.a), &a_ref);
    assert!(ea < 1e-10, "pulse: a {ea:.3e}");

    // Constant load from t = 0 (f_0 ≠ 0, so a_0 = F0/m): u = F0/k (1 − cos ωt), undamped.
    let model = sdof(m, 0.0, k).unwrap();
    let loads = vec![dvector![f0]; n_steps + 1];
    let sim = simulate(Scheme::Exact, &model, dt, &loads);
    let t = |i: usize| i as f64 * dt;
    let u_ref: Vec<DVector<f64>> = (0..=n_steps)
        .map(|i| dvector![f0 / k * (1.0 - (w * t(i)).cos())])
        .collect();
    let v_ref: Vec<DVector<f64>> = (0..=n_steps).map(|i| dvector![f0 / k * w * (w * t(i)).sin()]).collect();
    let a_ref: Vec<DVector<f64>> = (0..=n_steps).map(|i| dvector![f0 / m * (w * t(i)).cos()]).collect();
    let [eu, ev, ea] = [
        rel_error(sim.iter().map(|s| &s.u), &u_ref),
        rel_error(sim.iter().map(|s| &s.v), &v_ref),
        rel_error(sim.iter().map(|s| &s.a), &a_ref),
    ];
    println!("exact FOH, constant load from t = 0: u {eu:.2e}, v {ev:.2e}, a {ea:.2e}");
    assert!(
        eu < 1e-10 && ev < 1e-10 && ea < 1e-10,
        "step: u {eu:.3e}, v {ev:.3e}, a {ea:.3e}"
    );
}
