//! Nonlinear virtual specimens (Bouc–Wen, friction, force replay) against independent
//! references: closed forms, an RK4 reference, and self-consistency under refinement.
//!
//! Over 800 lines on purpose: every file under `tests/` is its own test binary that links the
//! whole library, so related checks share one binary to keep the CI build short; the sections
//! below are independent and can be read one at a time.

use std::f64::consts::PI;
use substep::specimen::{
    BoucWen, BoucWenParams, Friction, FrictionModel, Motion, Pinching, Replay, Specimen, SpecimenSpec,
    assemble_monolithic,
};
use substep::substructure::ExperimentalSubstructure;
use substep::transfer::{ActuatorSpec, SensorSpec, VirtualLab};

const K: f64 = 1e6;
const UY: f64 = 0.01;

/// One interval `u0 → u1` over `dt`, committed; the force at the end.
fn step(sp: &mut dyn Specimen, u0: f64, u1: f64, dt: f64) -> f64 {
    let mut f = [0.0];
    sp.advance(
        &Motion {
            d_start: &[u0],
            d_end: &[u1],
            ag_start: 0.0,
            ag_end: 0.0,
            dt,
        },
        &mut f,
    );
    sp.commit();
    f[0]
}

/// Drive through the samples `u` (interval `dt`, starting from `u[0]`); forces at `u[1..]`.
fn drive(sp: &mut dyn Specimen, u: &[f64], dt: f64) -> Vec<f64> {
    u.windows(2).map(|w| step(sp, w[0], w[1], dt)).collect()
}

fn sine(amplitude: f64, freq: f64, dt: f64, duration: f64) -> Vec<f64> {
    let n = (duration / dt).round() as usize;
    (0..=n)
        .map(|i| amplitude * (2.0 * PI * freq * i as f64 * dt).sin())
        .collect()
}

/// Energy dissipated by the specimen, `−∮ f du` (f is the force on the structure), trapezoidal
/// over the samples `u[0..]` with forces `f[j]` at `u[j]`.
fn dissipated(u: &[f64], f: &[f64]) -> f64 {
    -u.windows(2)
        .zip(f.windows(2))
        .map(|(u, f)| 0.5 * (f[0] + f[1]) * (u[1] - u[0]))
        .sum::<f64>()
}

fn bw(params: BoucWenParams) -> BoucWen {
    BoucWen::new(&params).unwrap()
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m, x| m.max(x.abs()))
}

// ---------------------------------------------------------------------------------------------
// Bouc–Wen

#[test]
fn bouc_wen_small_amplitude_is_linear_elastic() {
    // Deviation from −k u is (1−α) u/(2 u_y) for n = 1 and (1−α) u²/(3 u_y²) for n = 2.
    for (n, amp) in [(1.0, 5e-7 * UY), (2.0, 1e-3 * UY), (3.0, 1e-3 * UY)] {
        let mut p = BoucWenParams::new(K, 0.1, UY);
        p.n = n;
        let mut s = bw(p);
        let u = sine(amp, 1.0, 1e-3, 2.0);
        let f = drive(&mut s, &u, 1e-3);
        let err = u[1..]
            .iter()
            .zip(&f)
            .map(|(u, f)| (f + K * u).abs())
            .fold(0.0, f64::max);
        let rel = err / (K * amp);
        println!(
            "n = {n}: amplitude {:.1e} u_y, max |f + k u| / (k u_max) = {rel:.3e}",
            amp / UY
        );
        assert!(rel < 1e-6, "n = {n}: {rel:e}");
    }
}

/// Virgin loading `z(u)`: `dz/du = A − (β+γ)(z/u_y)ⁿ`.
fn backbone_closed_form(p: &BoucWenParams, u: f64) -> f64 {
    let c = p.beta + p.gamma;
    if p.n == 1.0 {
        p.a * p.yield_displacement / c * (1.0 - (-c * u / p.yield_displacement).exp())
    } else if p.n == 2.0 {
        // dz/du = A − c z²/u_y²  ⇒  z = u_y √(A/c) tanh(√(A c) u / u_y)
        p.yield_displacement * (p.a / c).sqrt() * ((p.a * c).sqrt() * u / p.yield_displacement).tanh()
    } else {
        unreachable!()
    }
}

/// Independent reference for the backbone: classical RK4 with a tiny step.
fn backbone_rk4(p: &BoucWenParams, u_end: f64, steps: usize) -> f64 {
    let g = |z: f64| p.a - (p.beta + p.gamma) * (z.abs() / p.yield_displacement).powf(p.n);
    let h = u_end / steps as f64;
    let mut z = 0.0;
    for _ in 0..steps {
        let k1 = g(z);
        let k2 = g(z + 0.5 * h * k1);
        let k3 = g(z + 0.5 * h * k2);
        let k4 = g(z + h * k3);
        z += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
    }
    z
}

#[test]
fn bouc_wen_backbone_matches_closed_form() {
    let mut cases = vec![];
    cases.push(BoucWenParams::new(K, 0.05, UY)); // n = 1: z = u_y (1 − e^{−u/u_y})
    let mut p = BoucWenParams::new(K, 0.1, UY);
    p.n = 2.0; // z = u_y tanh(u/u_y)
    cases.push(p);
    let mut p = BoucWenParams::new(K, 0.2, UY);
    (p.a, p.beta, p.gamma) = (1.5, 0.3, 0.2); // n = 1, z_u = 3 u_y
    cases.push(p);
    let mut p = BoucWenParams::new(K, 0.0, UY);
    (p.a, p.beta, p.gamma, p.n) = (0.8, 0.9, -0.2, 2.0);
    cases.push(p);
    // Slow ramp to 6 u_y in 3000 intervals of 10 ms.
    let dt = 0.01;
    let u: Vec<f64> = (0..=3000).map(|i| 6.0 * UY * i as f64 / 3000.0).collect();
    for p in cases {
        let mut s = bw(p);
        let f = drive(&mut s, &u, dt);
        let mut worst: f64 = 0.0;
        for (ui, fi) in u[1..].iter().zip(&f) {
            let z = backbone_closed_form(&p, *ui);
            let exact = -(p.alpha * K * ui + (1.0 - p.alpha) * K * z);
            worst = worst.max(((fi - exact) / exact).abs());
        }
        println!(
            "backbone A = {}, beta = {}, gamma = {}, n = {}: max relative force error {worst:.3e}",
            p.a, p.beta, p.gamma, p.n
        );
        assert!(worst < 1e-4, "{worst:e}");
        assert!(worst < 1e-8, "the 4th-order rule should do much better: {worst:e}");
    }
    // Non-integer and larger n against RK4.
    for n in [1.5, 3.0, 8.0] {
        let mut p = BoucWenParams::new(K, 0.1, UY);
        p.n = n;
        let mut s = bw(p);
        let f = drive(&mut s, &u, dt);
        let mut worst: f64 = 0.0;
        for j in (0..f.len()).step_by(150) {
            let ui = u[j + 1];
            let z = backbone_rk4(&p, ui, 200_000);
            let exact = -(p.alpha * K * ui + (1.0 - p.alpha) * K * z);
            worst = worst.max(((f[j] - exact) / exact).abs());
        }
        println!("backbone n = {n} vs RK4: max relative force error {worst:.3e}");
        assert!(worst < 1e-6, "n = {n}: {worst:e}");
    }
}

/// Energy of the last of three cycles at 1 Hz, amplitude `amp`.
fn bouc_wen_cycle_energy(p: &BoucWenParams, amp: f64, dt: f64) -> (f64, f64) {
    let mut s = bw(*p);
    let u = sine(amp, 1.0, dt, 3.0);
    let f = drive(&mut s, &u, dt);
    let per = (1.0 / dt).round() as usize;
    let n = u.len() - 1;
    let mut e_start = 0.0;
    let mut us = vec![u[n - per]];
    let mut fs = vec![0.0];
    // Force at u[n − per] is f[n − per − 1].
    fs[0] = f[n - per - 1];
    for j in n - per..n {
        us.push(u[j + 1]);
        fs.push(f[j]);
    }
    // Hysteretic energy over the same cycle from the specimen's own ε (exact integral of z du).
    let mut s2 = bw(*p);
    drive(&mut s2, &u[..=n - per], dt);
    e_start += s2.hysteretic_energy();
    (dissipated(&us, &fs), s.hysteretic_energy() - e_start)
}

#[test]
fn bouc_wen_cyclic_loop_area_positive_and_converges() {
    let mut p = BoucWenParams::new(K, 0.1, UY);
    p.n = 1.0;
    let mut prev: Option<f64> = None;
    for dt in [2e-3, 1e-3, 5e-4, 2.5e-4] {
        let (e, e_h) = bouc_wen_cycle_energy(&p, 4.0 * UY, dt);
        println!("dt = {dt:.1e}: −∮ f du = {e:.6} J, (1−α) k u_y² Δε = {e_h:.6} J");
        assert!(e > 0.0);
        assert!(
            ((e - e_h) / e_h).abs() < 2e-3,
            "loop area vs hysteretic energy: {e} vs {e_h}"
        );
        if let Some(ep) = prev {
            let change = ((e - ep) / ep).abs();
            println!("   change on halving dt: {:.4} %", 100.0 * change);
            assert!(change < 5e-3);
        }
        prev = Some(e);
    }
    // The loop is bounded by the bilinear envelope: less than the elastic–perfectly-plastic
    // area 4 (1−α) k u_y (U − u_y), more than a fair fraction of it.
    let (e, _) = bouc_wen_cycle_energy(&p, 4.0 * UY, 5e-4);
    let epp = 4.0 * (1.0 - p.alpha) * K * UY * (4.0 * UY - UY);
    println!("loop area / EPP parallelogram = {:.4}", e / epp);
    assert!(e < epp && e > 0.7 * epp);
}

#[test]
fn bouc_wen_result_independent_of_interval_splitting() {
    // The same piecewise-linear motion, once as N intervals, once with each interval split at
    // its midpoint.
    let mut variants = vec![];
    let mut p = BoucWenParams::new(K, 0.1, UY);
    p.damping = 2e3;
    variants.push(("n = 1, damping", p));
    let mut p = BoucWenParams::new(K, 0.05, UY);
    p.n = 2.0;
    variants.push(("n = 2", p));
    let mut p = BoucWenParams::new(K, 0.1, UY);
    p.n = 1.5;
    (p.beta, p.gamma) = (0.25, 0.75);
    variants.push(("n = 1.5, beta < gamma", p));
    let mut p = BoucWenParams::new(K, 0.1, UY);
    (p.delta_a, p.delta_nu, p.delta_eta) = (0.01, 0.05, 0.05);
    p.pinching = Some(Pinching::new(0.6));
    variants.push(("n = 1, degradation + pinching", p));
    // Irregular amplitude so interval lengths do not line up with the sub-step grid.
    let dt = 1.0 / 137.0;
    let u: Vec<f64> = (0..=(3.0 / dt) as usize)
        .map(|i| {
            let t = i as f64 * dt;
            UY * (3.3 * (2.0 * PI * t).sin() + 0.7 * (2.0 * PI * 2.3 * t).sin())
        })
        .collect();
    for (name, p) in variants {
        let mut a = bw(p);
        let mut b = bw(p);
        let fa = drive(&mut a, &u, dt);
        let fb: Vec<f64> = u
            .windows(2)
            .map(|w| {
                let mid = 0.5 * (w[0] + w[1]);
                step(&mut b, w[0], mid, 0.5 * dt);
                step(&mut b, mid, w[1], 0.5 * dt)
            })
            .collect();
        let scale = max_abs(&fa);
        let diff = fa.iter().zip(&fb).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max) / scale;
        let pointwise = fa
            .iter()
            .zip(&fb)
            .filter(|(x, _)| x.abs() > 0.01 * scale)
            .map(|(x, y)| ((x - y) / x).abs())
            .fold(0.0, f64::max);
        println!("{name}: max |f_h − f_h/2| / max|f| = {diff:.3e}, pointwise (|f| > 1 %) {pointwise:.3e}");
        assert!(diff < 1e-6 && pointwise < 1e-6, "{name}: {diff:e} {pointwise:e}");
    }
}

#[test]
fn bouc_wen_extreme_inputs_stay_finite_and_bounded() {
    let mut variants = vec![];
    variants.push(BoucWenParams::new(K, 0.1, UY));
    for n in [1.5, 2.0, 20.0, 100.0] {
        let mut p = BoucWenParams::new(K, 0.1, UY);
        p.n = n;
        variants.push(p);
    }
    let mut p = BoucWenParams::new(K, 0.1, UY);
    (p.delta_a, p.delta_nu, p.delta_eta, p.damping) = (0.5, 1.0, 1.0, 1e4);
    p.pinching = Some(Pinching::new(0.9));
    variants.push(p);
    let mut p = BoucWenParams::new(K, 0.0, UY);
    (p.beta, p.gamma) = (0.0, 1.0);
    variants.push(p);
    let jumps = [
        0.0,
        1e3,
        -1e3,
        1e-300,
        5e6,
        -7e9,
        1e15,
        1e15,
        0.0,
        0.37,
        -0.37,
        1e-20,
        3.0 * UY,
        -2.5 * UY,
    ];
    for p in variants {
        let mut s = bw(p);
        let t0 = std::time::Instant::now();
        for w in jumps.windows(2) {
            for dt in [1e-3, 1e-12] {
                let f = step(&mut s, w[0], w[1], dt);
                assert!(f.is_finite(), "non-finite force {f} for {p:?} on {w:?}");
                let mut st = [0.0; 2];
                s.write_state(&mut st);
                assert!(st.iter().all(|x| x.is_finite()), "{st:?}");
                assert!(st[0].abs() <= p.z_ultimate() * (1.0 + 1e-9), "|z| > z_u: {st:?}");
            }
        }
        println!(
            "n = {}: {} huge jumps in {:?}",
            p.n,
            2 * (jumps.len() - 1),
            t0.elapsed()
        );
    }
    // Non-finite input or a zero-length interval must not panic or poison the state.
    let specs = [
        SpecimenSpec::BoucWen {
            dof: 0,
            params: BoucWenParams::new(K, 0.1, UY),
        },
        SpecimenSpec::Friction {
            dof: 0,
            slip_force: 1e3,
            model: FrictionModel::StickSlip { stiffness: K },
            damping: 10.0,
        },
        SpecimenSpec::Friction {
            dof: 0,
            slip_force: 1e3,
            model: FrictionModel::Smooth { v_ref: 1e-3 },
            damping: 10.0,
        },
        replay_spec(0),
    ];
    for spec in &specs {
        let mut s = spec.build().unwrap();
        step(s.as_mut(), 0.0, 2.0 * UY, 1e-3);
        for (u0, u1, dt) in [
            (2.0 * UY, f64::NAN, 1e-3),
            (f64::INFINITY, 0.0, 1e-3),
            (2.0 * UY, UY, 0.0),
            (UY, -UY, f64::NAN),
        ] {
            step(s.as_mut(), u0, u1, dt);
            let mut st = vec![0.0; s.state_len()];
            s.write_state(&mut st);
            assert!(st.iter().all(|x| x.is_finite()), "{}: {st:?}", spec.kind());
        }
        let f = step(s.as_mut(), -UY, 0.5 * UY, 1e-3);
        assert!(f.is_finite(), "{}: {f}", spec.kind());
    }
    // After a huge monotone jump z is saturated: force = −(α k u + (1−α) k z_u).
    let p = BoucWenParams::new(K, 0.1, UY);
    let mut s = bw(p);
    let f = step(&mut s, 0.0, 1e3, 1.0);
    let exact = -(0.1 * K * 1e3 + 0.9 * K * UY);
    assert!(((f - exact) / exact).abs() < 1e-12, "{f} vs {exact}");
    assert!((s.z() - UY).abs() < 1e-12 * UY);
}

#[test]
fn bouc_wen_trial_state_and_checkpoints() {
    let mut p = BoucWenParams::new(K, 0.1, UY);
    p.delta_nu = 0.1;
    let mut s = bw(p);
    let u = sine(2.5 * UY, 1.0, 1e-3, 0.6);
    drive(&mut s, &u, 1e-3);
    let mut saved = [0.0; 2];
    s.write_state(&mut saved);
    let m = Motion {
        d_start: &[u[u.len() - 1]],
        d_end: &[u[u.len() - 1] - 0.3 * UY],
        ag_start: 0.0,
        ag_end: 0.0,
        dt: 1e-3,
    };
    let (mut f1, mut f2) = ([0.0], [0.0]);
    s.advance(&m, &mut f1);
    s.advance(&m, &mut f2); // no commit in between: same start state
    assert_eq!(f1, f2);
    s.commit();
    s.read_state(&saved);
    s.advance(&m, &mut f2);
    assert_eq!(f1, f2);
    let mut fresh = bw(p);
    fresh.read_state(&saved);
    fresh.advance(&m, &mut f2);
    assert_eq!(f1, f2);
}

#[test]
fn bouc_wen_viscous_part_is_minus_c_v() {
    let p0 = BoucWenParams::new(K, 0.1, UY);
    let mut p1 = p0;
    p1.damping = 3e3;
    let (mut a, mut b) = (bw(p0), bw(p1));
    let dt = 2e-3;
    let u = sine(3.0 * UY, 0.7, dt, 2.0);
    let (fa, fb) = (drive(&mut a, &u, dt), drive(&mut b, &u, dt));
    for (j, w) in u.windows(2).enumerate() {
        let v = (w[1] - w[0]) / dt;
        assert!((fb[j] - (fa[j] - 3e3 * v)).abs() <= 1e-9 * fa[j].abs().max(1.0));
    }
}

#[test]
fn bouc_wen_degradation_and_pinching_reduce_the_loop() {
    let dt = 1e-3;
    let u = sine(4.0 * UY, 1.0, dt, 4.0);
    let per = 1000;
    let cycle_energy = |p: BoucWenParams| -> Vec<f64> {
        let mut s = bw(p);
        let f = drive(&mut s, &u, dt);
        (0..4)
            .map(|c| {
                let j0 = c * per;
                let us = &u[j0 + 1..=j0 + per];
                dissipated(us, &f[j0..j0 + per])
            })
            .collect()
    };
    let base = BoucWenParams::new(K, 0.1, UY);
    let mut degr = base;
    (degr.delta_nu, degr.delta_eta) = (0.05, 0.05);
    let mut pinch = base;
    pinch.pinching = Some(Pinching::new(0.8));
    let (eb, ed, ep) = (cycle_energy(base), cycle_energy(degr), cycle_energy(pinch));
    println!("cycle energies [J]: plain {eb:.2?}, degrading {ed:.2?}, pinched {ep:.2?}");
    // Plain: steady after the first cycle; degrading: every cycle smaller than the last.
    assert!(((eb[3] - eb[2]) / eb[2]).abs() < 1e-6);
    assert!(ed[1] < ed[0] && ed[2] < ed[1] && ed[3] < ed[2]);
    assert!(ed[3] < 0.95 * eb[3]);
    assert!(ep[3] < 0.95 * eb[3] && ep[3] > 0.0);
}

/// `dz/du` and `dε/du` written out from the documented equations, for the RK4 reference.
fn bouc_wen_rhs(p: &BoucWenParams, z: f64, eps: f64, s: f64) -> (f64, f64) {
    let uy = p.yield_displacement;
    let e = eps.max(0.0);
    let a = (p.a - p.delta_a * e).max(0.0);
    let nu = 1.0 + p.delta_nu * e;
    let eta = 1.0 + p.delta_eta * e;
    let sgn = if s * z >= 0.0 { 1.0 } else { -1.0 };
    let core = a - nu * (z.abs() / uy).powf(p.n) * (p.beta * sgn + p.gamma);
    let h = match &p.pinching {
        Some(pin) => {
            let zeta1 = pin.zeta_s * (1.0 - (-pin.p * e).exp());
            let zeta2 = (pin.psi + pin.delta_psi * e) * (pin.lambda + zeta1);
            let zu = uy * (a / (nu * (p.beta + p.gamma))).powf(1.0 / p.n);
            1.0 - zeta1 * (-((s * z - pin.q * zu) / (uy * zeta2)).powi(2)).exp()
        }
        None => 1.0,
    };
    (h * core / eta, z / (uy * uy))
}

#[test]
fn bouc_wen_degradation_and_pinching_match_rk4_reference() {
    let mut variants = vec![];
    for n in [1.0, 2.0] {
        let mut p = BoucWenParams::new(K, 0.1, UY);
        p.n = n;
        (p.delta_a, p.delta_nu, p.delta_eta) = (0.02, 0.1, 0.08);
        variants.push(("degradation", p));
        let mut p = BoucWenParams::new(K, 0.1, UY);
        p.n = n;
        let mut pin = Pinching::new(0.7);
        (pin.p, pin.q, pin.psi, pin.delta_psi, pin.lambda) = (0.5, 0.2, 0.3, 0.01, 0.4);
        p.pinching = Some(pin);
        p.delta_nu = 0.05;
        variants.push(("pinching + degradation", p));
    }
    let dt = 1.0 / 400.0;
    let u = sine(3.0 * UY, 1.0, dt, 2.0);
    for (name, p) in variants {
        let mut s = bw(p);
        let f = drive(&mut s, &u, dt);
        let (mut z, mut eps) = (0.0, 0.0);
        let mut worst: f64 = 0.0;
        let mut peak: f64 = 0.0;
        for (j, w) in u.windows(2).enumerate() {
            let du = w[1] - w[0];
            let sd = du.signum();
            let m = 2000;
            let h = du / m as f64;
            for _ in 0..m {
                let (k1z, k1e) = bouc_wen_rhs(&p, z, eps, sd);
                let (k2z, k2e) = bouc_wen_rhs(&p, z + 0.5 * h * k1z, eps + 0.5 * h * k1e, sd);
                let (k3z, k3e) = bouc_wen_rhs(&p, z + 0.5 * h * k2z, eps + 0.5 * h * k2e, sd);
                let (k4z, k4e) = bouc_wen_rhs(&p, z + h * k3z, eps + h * k3e, sd);
                z += h / 6.0 * (k1z + 2.0 * k2z + 2.0 * k3z + k4z);
                eps += h / 6.0 * (k1e + 2.0 * k2e + 2.0 * k3e + k4e);
            }
            let exact = -(p.alpha * K * w[1] + (1.0 - p.alpha) * K * z);
            worst = worst.max((f[j] - exact).abs());
            peak = peak.max(exact.abs());
        }
        let mut st = [0.0; 2];
        s.write_state(&mut st);
        println!(
            "{name}, n = {}: max |f − f_RK4| / max|f| = {:.3e}; ε = {:.6} (RK4 {:.6})",
            p.n,
            worst / peak,
            st[1],
            eps
        );
        assert!(worst / peak < 1e-6, "{name}: {:e}", worst / peak);
        assert!((st[1] - eps).abs() < 1e-6 * eps);
    }
}

// ---------------------------------------------------------------------------------------------
// Friction

#[test]
fn friction_stick_slip_loop_energy_matches_closed_form() {
    let (k, fs, amp) = (1e7, 1e4, 0.02); // slip displacement F_s/k = 1 mm
    let mut s = Friction::new(fs, FrictionModel::StickSlip { stiffness: k }, 0.0).unwrap();
    let per = 20_000;
    let dt = 1.0 / per as f64;
    let u = sine(amp, 1.0, dt, 3.0);
    let f = drive(&mut s, &u, dt);
    let exact = 4.0 * fs * (amp - fs / k);
    for c in 1..3 {
        let j0 = c * per;
        let mut us = vec![u[j0]];
        us.extend_from_slice(&u[j0 + 1..=j0 + per]);
        let mut fv = vec![f[j0 - 1]];
        fv.extend_from_slice(&f[j0..j0 + per]);
        let e = dissipated(&us, &fv);
        println!(
            "cycle {}: −∮ f du = {e:.9} J, closed form {exact:.9} J, rel {:.2e}",
            c + 1,
            (e - exact) / exact
        );
        assert!(((e - exact) / exact).abs() < 1e-6);
    }
    assert!(f.iter().all(|x| x.abs() <= fs * (1.0 + 1e-12)));
    assert!((max_abs(&f) - fs).abs() < 1e-9 * fs);
    // Small motion (< F_s/k) stays elastic and never slips.
    let mut s = Friction::new(fs, FrictionModel::StickSlip { stiffness: k }, 0.0).unwrap();
    let u = sine(0.9 * fs / k, 3.0, 1e-3, 1.0);
    let f = drive(&mut s, &u, 1e-3);
    for (ui, fi) in u[1..].iter().zip(&f) {
        assert!((fi + k * ui).abs() <= 1e-9 * fs);
    }
    assert_eq!(s.slip(), 0.0);
}

#[test]
fn friction_stick_slip_is_rate_independent_and_exact_per_interval() {
    // One big interval vs many small ones along a monotone path: identical end state.
    let (k, fs) = (2e6, 500.0);
    let mut a = Friction::new(fs, FrictionModel::StickSlip { stiffness: k }, 0.0).unwrap();
    let mut b = Friction::new(fs, FrictionModel::StickSlip { stiffness: k }, 0.0).unwrap();
    let fa = step(&mut a, 0.0, 0.01, 0.1);
    let mut fb = 0.0;
    for i in 0..100 {
        fb = step(&mut b, i as f64 * 1e-4, (i + 1) as f64 * 1e-4, 1e-3);
    }
    assert!((fa - fb).abs() < 1e-9 && (fa + fs).abs() < 1e-9);
    assert!((a.slip() - b.slip()).abs() < 1e-15 && (a.slip() - (0.01 - fs / k)).abs() < 1e-15);
    // Unloading by 2 F_s/k brings the force to +F_s exactly at the corner.
    let f = step(&mut a, 0.01, 0.01 - 2.0 * fs / k, 0.1);
    assert!((f - fs).abs() < 1e-9);
}

#[test]
fn friction_smooth_model_is_exact_for_constant_velocity() {
    let (fs, v_ref, c) = (800.0, 0.004, 150.0);
    for &v in &[0.01, -0.003, 1e-6, 0.0, 5.0] {
        let mut s = Friction::new(fs, FrictionModel::Smooth { v_ref }, c).unwrap();
        let dt = 1e-3;
        let mut u = 0.123;
        for _ in 0..50 {
            let f = step(&mut s, u, u + v * dt, dt);
            u += v * dt;
            let exact = -fs * (v / v_ref).tanh() - c * v;
            assert!(
                (f - exact).abs() <= 1e-9 * exact.abs().max(1e-9),
                "v = {v}: {f} vs {exact}"
            );
        }
    }
    let s = Friction::new(fs, FrictionModel::Smooth { v_ref }, 0.0).unwrap();
    assert_eq!(s.state_len(), 0);
}

// ---------------------------------------------------------------------------------------------
// Replay

fn replay_spec(dof: usize) -> SpecimenSpec {
    SpecimenSpec::Replay {
        dof,
        dt: 0.01,
        values: vec![0.0, 10.0, -5.0, 20.0],
    }
}

#[test]
fn replay_values_at_samples_and_between() {
    let mut s = replay_spec(0).build().unwrap();
    assert_eq!(s.kind(), "replay");
    // Half-sample intervals; the motion is arbitrary and ignored.
    let expected = [5.0, 10.0, 2.5, -5.0, 7.5, 20.0, 0.0, 0.0];
    for (j, e) in expected.iter().enumerate() {
        let f = step(s.as_mut(), 1e3 * j as f64, -7.0 * j as f64, 0.005);
        assert!((f - e).abs() < 1e-12, "t = {}: {f} vs {e}", 0.005 * (j + 1) as f64);
    }
    // Whole samples, accumulated time 0.01 + 0.01 + 0.01 > 0.03 by round-off: still the last
    // sample, then zero.
    let mut s = replay_spec(0).build().unwrap();
    let f: Vec<f64> = (0..5).map(|_| step(s.as_mut(), 0.0, 0.0, 0.01)).collect();
    assert_eq!(f, vec![10.0, -5.0, 20.0, 0.0, 0.0]);
    // Irregular intervals: interpolation at arbitrary times.
    let r = Replay::new(0.01, vec![0.0, 10.0, -5.0, 20.0]).unwrap();
    for (t, e) in [
        (0.0, 0.0),
        (0.0025, 2.5),
        (0.013, 5.5),
        (0.029, 17.5),
        (0.03, 20.0),
        (0.0301, 0.0),
    ] {
        assert!((r.value_at(t) - e).abs() < 1e-9, "{t}: {} vs {e}", r.value_at(t));
    }
}

#[test]
fn replay_instances_are_independent_and_state_is_time() {
    let spec = replay_spec(2);
    let (mut a, mut b) = (spec.build().unwrap(), spec.build().unwrap());
    for _ in 0..3 {
        step(a.as_mut(), 0.0, 0.0, 0.005);
    }
    let fb = step(b.as_mut(), 0.0, 0.0, 0.005);
    let fa = step(a.as_mut(), 0.0, 0.0, 0.005);
    assert_eq!((fa, fb), (-5.0, 5.0));
    // Uncommitted advances do not move the clock.
    let mut f = [0.0];
    let m = Motion {
        d_start: &[0.0],
        d_end: &[0.0],
        ag_start: 0.0,
        ag_end: 0.0,
        dt: 0.005,
    };
    b.advance(&m, &mut f);
    b.advance(&m, &mut f);
    assert_eq!(f[0], 10.0);
    let mut st = [0.0];
    a.write_state(&mut st);
    assert!((st[0] - 0.02).abs() < 1e-15);
    b.read_state(&[0.02]);
    b.advance(&m, &mut f);
    assert!((f[0] - 7.5).abs() < 1e-12);
}

// ---------------------------------------------------------------------------------------------
// Descriptions

fn err_of(spec: SpecimenSpec) -> String {
    match spec.build() {
        Ok(_) => panic!("{spec:?} should not build"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn specimen_spec_variants_build_and_name_keys() {
    let bouc = |f: &dyn Fn(&mut BoucWenParams)| {
        let mut p = BoucWenParams::new(K, 0.1, UY);
        f(&mut p);
        SpecimenSpec::BoucWen { dof: 1, params: p }
    };
    let fric = |fs: f64, model| SpecimenSpec::Friction {
        dof: 0,
        slip_force: fs,
        model,
        damping: 0.0,
    };
    let ss = FrictionModel::StickSlip { stiffness: 1e6 };
    let ok = [
        bouc(&|_| {}),
        fric(100.0, ss),
        fric(100.0, FrictionModel::Smooth { v_ref: 0.01 }),
        replay_spec(3),
    ];
    for (spec, (kind, dof)) in ok
        .iter()
        .zip([("bouc_wen", 1), ("friction", 0), ("friction", 0), ("replay", 3)])
    {
        assert_eq!(spec.kind(), kind);
        assert_eq!(spec.dofs(), vec![dof]);
        assert!(spec.linear_matrices().is_none());
        let s = spec.build().unwrap();
        assert_eq!((s.kind(), s.n_dofs(), s.is_linear()), (kind, 1, false));
    }
    let cases: Vec<(SpecimenSpec, &str)> = vec![
        (fric(-1.0, ss), "specimen.slip_force"),
        (fric(f64::NAN, ss), "specimen.slip_force"),
        (
            fric(1.0, FrictionModel::StickSlip { stiffness: 0.0 }),
            "specimen.stiffness",
        ),
        (fric(1.0, FrictionModel::Smooth { v_ref: -0.1 }), "specimen.v_ref"),
        (
            SpecimenSpec::Friction {
                dof: 0,
                slip_force: 1.0,
                model: ss,
                damping: -2.0,
            },
            "specimen.damping",
        ),
        (bouc(&|p| p.alpha = 1.5), "specimen.alpha"),
        (bouc(&|p| p.alpha = -0.1), "specimen.alpha"),
        (bouc(&|p| p.stiffness = -1.0), "specimen.stiffness"),
        (bouc(&|p| p.yield_displacement = 0.0), "specimen.yield_displacement"),
        (bouc(&|p| p.a = 0.0), "specimen.a"),
        (bouc(&|p| p.beta = -0.5), "specimen.beta"),
        (bouc(&|p| p.gamma = -0.5), "specimen.gamma"),
        (bouc(&|p| p.n = 0.5), "specimen.n"),
        (bouc(&|p| p.damping = -1.0), "specimen.damping"),
        (bouc(&|p| p.delta_nu = -1.0), "specimen.delta_nu"),
        (bouc(&|p| p.delta_eta = f64::INFINITY), "specimen.delta_eta"),
        (bouc(&|p| p.delta_a = -1.0), "specimen.delta_a"),
        (
            bouc(&|p| p.pinching = Some(Pinching::new(1.0))),
            "specimen.pinching.zeta_s",
        ),
        (
            bouc(&|p| {
                let mut pin = Pinching::new(0.5);
                pin.psi = 0.0;
                p.pinching = Some(pin);
            }),
            "specimen.pinching.psi",
        ),
        (
            SpecimenSpec::Replay {
                dof: 0,
                dt: 0.0,
                values: vec![1.0],
            },
            "specimen.dt",
        ),
        (
            SpecimenSpec::Replay {
                dof: 0,
                dt: 0.01,
                values: vec![],
            },
            "specimen.values",
        ),
        (
            SpecimenSpec::Replay {
                dof: 0,
                dt: 0.01,
                values: vec![1.0, f64::NAN],
            },
            "specimen.values",
        ),
    ];
    for (spec, key) in cases {
        let msg = err_of(spec);
        assert!(msg.starts_with(&format!("{key}:")), "expected {key}, got {msg}");
    }
    // Through the virtual lab the key is re-rooted at the specimen's position.
    let err = VirtualLab::from_specs(
        &[0],
        &[fric(-5.0, ss)],
        &[ActuatorSpec::ideal()],
        &[SensorSpec::ideal()],
        &[SensorSpec::ideal()],
        1e-3,
        1,
    )
    .err()
    .unwrap()
    .to_string();
    assert!(err.starts_with("substructure.specimen[1].slip_force:"), "{err}");
    // Nonlinear specimens have no monolithic model.
    let model = substep::model::sdof(1.0, 0.0, 1e3).unwrap();
    let err = assemble_monolithic(&model, &[bouc(&|_| {})]).unwrap_err().to_string();
    assert!(err.contains("bouc_wen"), "{err}");
}

#[test]
fn nonlinear_specimens_run_in_the_virtual_lab() {
    let specs = [
        SpecimenSpec::BoucWen {
            dof: 0,
            params: BoucWenParams::new(K, 0.1, UY),
        },
        SpecimenSpec::Friction {
            dof: 0,
            slip_force: 2e3,
            model: FrictionModel::StickSlip { stiffness: 1e6 },
            damping: 0.0,
        },
        replay_spec(0),
    ];
    let mut lab = VirtualLab::from_specs(
        &[0],
        &specs,
        &[ActuatorSpec::ideal()],
        &[SensorSpec::ideal()],
        &[SensorSpec::ideal()],
        1e-3,
        4,
    )
    .unwrap();
    assert!(lab.is_linear().is_err());
    let (mut f, mut d) = ([0.0], [0.0]);
    // Ramp the command to 2 u_y over 20 sub-steps, with a separate reference for each specimen.
    let mut refs: Vec<Box<dyn Specimen>> = specs.iter().map(|s| s.build().unwrap()).collect();
    let mut prev = 0.0;
    for i in 1..=20 {
        let cmd = 2.0 * UY * i as f64 / 20.0;
        lab.substep(&[cmd], (0.0, 0.0), 1e-3, &mut f, &mut d).unwrap();
        let mut expect = 0.0;
        for r in refs.iter_mut() {
            for q in 0..4 {
                let a = prev + (cmd - prev) * q as f64 / 4.0;
                let b = prev + (cmd - prev) * (q + 1) as f64 / 4.0;
                let fq = step(r.as_mut(), a, b, 0.25e-3);
                if q == 3 {
                    expect += fq;
                }
            }
        }
        prev = cmd;
        assert!((f[0] - expect).abs() <= 1e-9 * expect.abs(), "{} vs {expect}", f[0]);
    }
    let n = lab.state_len();
    let mut st = vec![0.0; n];
    lab.write_state(&mut st);
    assert!(st.iter().all(|x| x.is_finite()));
}
