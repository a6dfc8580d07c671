//! Uniaxial materials (`substep::material`) through a cyclic deformation history, against
//! independent references: the Masing closed form of bilinear kinematic hardening, the Bouc–Wen
//! closed-form backbones and an RK4 integration of `dz/dδ`, finite differences for the tangents,
//! and OpenSees (`Steel01`, `ElasticPP`, `BoucWen` through openseespy) where it is installed.

use substep::material::{Bilinear, BoucWenMaterial, BoucWenParams, Elastic, Material, MaterialSpec, Pinching};
use substep::specimen::{BoucWen, Motion, Specimen};

const K: f64 = 1e6;
const FY: f64 = 1e4;
const UY: f64 = 0.01;
/// Reversal points of the cyclic history, in units of the yield deformation.
const REVERSALS: [f64; 6] = [0.0, 3.0, -2.0, 4.0, -5.0, 0.0];

/// The cyclic history through `REVERSALS · dy`: each leg cut into `max(1, round(per_dy |leg| /
/// dy))` equal steps (`per_dy = 0`: one jump per leg). Every sample after the start, with its leg;
/// the reversal points are hit exactly.
fn history(dy: f64, per_dy: f64) -> Vec<(f64, usize)> {
    let mut out = vec![];
    for (leg, w) in REVERSALS.windows(2).enumerate() {
        let (a, b) = (w[0] * dy, w[1] * dy);
        let m = ((per_dy * (w[1] - w[0]).abs()).round() as usize).max(1);
        out.extend((1..=m).map(|i| (if i == m { b } else { a + (b - a) * i as f64 / m as f64 }, leg)));
    }
    out
}

fn rel_max(pairs: impl Iterator<Item = (f64, f64)>) -> f64 {
    let (mut err, mut peak) = (0.0f64, 0.0f64);
    for (x, reference) in pairs {
        err = err.max((x - reference).abs());
        peak = peak.max(reference.abs());
    }
    err / peak
}

// ---------------------------------------------------------------------------------------------
// Bilinear (kinematic hardening) and elastic–perfectly plastic

/// Force and tangent of bilinear kinematic hardening (`k`, `F_y`, `b`) at `d` on leg `leg` of
/// the history, by the Masing rule, plus the distance from `d` to the leg's yield point. The
/// virgin leg is elastic over `δ_y = F_y / k` (force `F_y`); every later leg starts at a reversal
/// on a bound (each is longer than `2 δ_y`) and is elastic over `2 δ_y` (a force change of
/// `2 F_y`, i.e. `2 (1 − b) F_y` measured against the bounds `b k δ ± (1 − b) F_y`); after its
/// yield point the force grows with the slope `b k`.
fn masing(k: f64, fy: f64, b: f64, d: f64, leg: usize) -> (f64, f64, f64) {
    let dy = fy / k;
    let (mut start, mut f_start) = (0.0, 0.0);
    for (j, w) in REVERSALS.windows(2).enumerate() {
        let s = (w[1] - w[0]).signum();
        let travel = if j == 0 { 1.0 } else { 2.0 };
        assert!(
            j == 0 || (w[1] - w[0]).abs() > 2.0,
            "a leg must reach the opposite bound"
        );
        let (d_yield, f_yield) = (start + s * travel * dy, f_start + s * travel * fy);
        let at = |x: f64| {
            if s * (x - d_yield) <= 0.0 {
                (f_start + k * (x - start), k)
            } else {
                (f_yield + b * k * (x - d_yield), b * k)
            }
        };
        if j == leg {
            let (f, t) = at(d);
            return (f, t, (d - d_yield).abs());
        }
        (start, f_start) = (w[1] * dy, at(w[1] * dy).0);
    }
    unreachable!()
}

#[test]
fn bilinear_and_elastic_plastic_follow_the_masing_closed_form() {
    let dy = FY / K;
    for b in [0.0, 0.02, 0.1] {
        let spec = MaterialSpec::Bilinear {
            yield_force: FY,
            hardening: b,
        };
        for per_dy in [50.0, 1.0, 0.0] {
            let mut m = spec.build(K, "t").unwrap();
            let (mut pairs, mut ties) = (vec![], 0);
            for (d, leg) in history(dy, per_dy) {
                m.set_trial(d);
                m.commit();
                let (f, t, to_yield) = masing(K, FY, b, d, leg);
                pairs.push((m.force(), f));
                // at a yield point itself both slopes are right
                if to_yield > 1e-9 * dy {
                    assert_eq!(m.tangent(), t, "b = {b}, δ = {d}");
                } else {
                    ties += 1;
                }
            }
            let rel = rel_max(pairs.into_iter());
            println!(
                "{} b = {b}, {per_dy} samples/δ_y: max |F − F_Masing| / F_peak = {rel:.2e} ({ties} samples at a yield point)",
                m.kind()
            );
            assert!(rel <= 1e-12, "b = {b}, {per_dy}: {rel:e}");
        }
    }
    // elastic: F = k δ exactly
    let mut m = Elastic::new(K).unwrap();
    for (d, _) in history(dy, 7.0) {
        m.set_trial(d);
        m.commit();
        assert!(m.force() == K * d && m.tangent() == K);
    }
}

// ---------------------------------------------------------------------------------------------
// Bouc–Wen

/// The laws under test: defaults (n = 1); n = 2 with other shape parameters and degradation;
/// non-integer n with pinching and degradation.
fn bouc_wen_cases() -> Vec<(&'static str, BoucWenParams)> {
    let base = BoucWenParams::new(K, 0.1, UY);
    let mut shaped = base;
    (shaped.n, shaped.a, shaped.beta, shaped.gamma) = (2.0, 1.2, 0.7, 0.3);
    (shaped.delta_a, shaped.delta_nu, shaped.delta_eta) = (0.02, 0.1, 0.08);
    let mut pinched = base;
    pinched.n = 1.5;
    pinched.delta_nu = 0.05;
    let mut pin = Pinching::new(0.7);
    (pin.p, pin.q, pin.psi, pin.delta_psi, pin.lambda) = (0.5, 0.2, 0.3, 0.01, 0.4);
    pinched.pinching = Some(pin);
    vec![
        ("n = 1", base),
        ("n = 2, degradation", shaped),
        ("n = 1.5, pinching", pinched),
    ]
}

/// `(dz/dδ, dε/dδ)` written out from the documented law, moving in the direction `s`.
fn bouc_wen_rhs(p: &BoucWenParams, z: f64, eps: f64, s: f64) -> (f64, f64) {
    let uy = p.yield_displacement;
    let e = eps.max(0.0);
    let a = (p.a - p.delta_a * e).max(0.0);
    let (nu, eta) = (1.0 + p.delta_nu * e, 1.0 + p.delta_eta * e);
    let sgn = if s * z >= 0.0 { 1.0 } else { -1.0 };
    let core = a - nu * (z.abs() / uy).powf(p.n) * (p.beta * sgn + p.gamma);
    let h = p.pinching.map_or(1.0, |pin| {
        let zeta1 = pin.zeta_s * (1.0 - (-pin.p * e).exp());
        let zeta2 = (pin.psi + pin.delta_psi * e) * (pin.lambda + zeta1);
        let zu = uy * (a / (nu * (p.beta + p.gamma))).powf(1.0 / p.n);
        1.0 - zeta1 * (-((s * z - pin.q * zu) / (uy * zeta2)).powi(2)).exp()
    });
    (h * core / eta, z / (uy * uy))
}

/// Classical RK4 of `(z, ε)` over `δ0 → δ1` with steps of at most `h_max`.
fn rk4(p: &BoucWenParams, (mut z, mut e): (f64, f64), d0: f64, d1: f64, h_max: f64) -> (f64, f64) {
    let (s, m) = ((d1 - d0).signum(), ((d1 - d0).abs() / h_max).ceil().max(1.0));
    let h = (d1 - d0) / m;
    for _ in 0..m as usize {
        let (k1, l1) = bouc_wen_rhs(p, z, e, s);
        let (k2, l2) = bouc_wen_rhs(p, z + 0.5 * h * k1, e + 0.5 * h * l1, s);
        let (k3, l3) = bouc_wen_rhs(p, z + 0.5 * h * k2, e + 0.5 * h * l2, s);
        let (k4, l4) = bouc_wen_rhs(p, z + h * k3, e + h * l3, s);
        z += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
        e += h / 6.0 * (l1 + 2.0 * l2 + 2.0 * l3 + l4);
    }
    (z, e)
}

fn bw(p: &BoucWenParams) -> BoucWenMaterial {
    BoucWenMaterial::new(p).unwrap()
}

#[test]
fn bouc_wen_virgin_loading_matches_closed_forms() {
    // A = 1, β = γ = ½: n = 1: z = u_y (1 − e^{−δ/u_y}), dz/dδ = e^{−δ/u_y};
    // n = 2: z = u_y tanh(δ/u_y), dz/dδ = 1 − tanh²; odd in δ
    for n in [1.0, 2.0] {
        let mut p = BoucWenParams::new(K, 0.1, UY);
        p.n = n;
        let exact = |d: f64| {
            let x = d.abs() / UY;
            let (z, g) = if n == 1.0 {
                (1.0 - (-x).exp(), (-x).exp())
            } else {
                (x.tanh(), 1.0 - x.tanh().powi(2))
            };
            let z = d.signum() * UY * z;
            (
                p.alpha * K * d + (1.0 - p.alpha) * K * z,
                p.alpha * K + (1.0 - p.alpha) * K * g,
            )
        };
        let (mut f_err, mut t_err) = (0.0f64, 0.0f64);
        for s in [1.0, -1.0] {
            // committed steps of 0.01 u_y to 6 u_y, and single jumps from the virgin state
            let mut m = bw(&p);
            let mut check = |m: &dyn Material, d: f64| {
                let (f, t) = exact(d);
                f_err = f_err.max(((m.force() - f) / f).abs());
                t_err = t_err.max(((m.tangent() - t) / K).abs());
            };
            for i in 1..=600 {
                let d = s * i as f64 * 0.01 * UY;
                m.set_trial(d);
                m.commit();
                check(&m, d);
            }
            for x in [0.003, 0.5, 2.0, 6.0, 40.0] {
                let mut m = bw(&p);
                m.set_trial(s * x * UY);
                check(&m, s * x * UY);
            }
        }
        println!(
            "virgin loading, n = {n}: max |F − F_exact| / |F| = {f_err:.2e}, max |dF/dδ − exact| / k = {t_err:.2e}"
        );
        assert!(f_err <= 1e-8 && t_err <= 1e-8, "n = {n}: {f_err:e} {t_err:e}");
    }
}

#[test]
fn bouc_wen_cyclic_history_matches_rk4() {
    for (name, p) in bouc_wen_cases() {
        // 0.02 u_y steps, and one jump per leg (3 to 9 u_y)
        for per_dy in [50.0, 0.0] {
            let mut m = bw(&p);
            let (mut d0, mut state) = (0.0, (0.0, 0.0));
            let (mut forces, mut energies) = (vec![], vec![]);
            for (d, _) in history(UY, per_dy) {
                m.set_trial(d);
                m.commit();
                state = rk4(&p, state, d0, d, 2e-5 * UY);
                d0 = d;
                forces.push((m.force(), p.alpha * K * d + (1.0 - p.alpha) * K * state.0));
                energies.push((m.normalised_energy(), state.1));
            }
            let (rf, re) = (rel_max(forces.into_iter()), rel_max(energies.into_iter()));
            println!(
                "Bouc–Wen {name}, {per_dy} samples/u_y: max |F − F_RK4| / F_peak = {rf:.2e}, ε: {re:.2e} (ε_end = {:.3})",
                m.normalised_energy()
            );
            assert!(rf <= 1e-6 && re <= 1e-6, "{name} {per_dy}: {rf:e} {re:e}");
        }
    }
}

#[test]
fn bouc_wen_tangent_matches_finite_differences() {
    fn force_at(m: &mut BoucWenMaterial, x: f64) -> f64 {
        m.set_trial(x);
        m.force()
    }
    let h = 1e-6 * UY;
    let path = history(UY, 4.0);
    for (name, p) in bouc_wen_cases() {
        let mut m = bw(&p);
        assert!((m.initial_tangent() / (K * (p.alpha + (1.0 - p.alpha) * p.a)) - 1.0).abs() < 1e-15);
        m.set_trial(0.0);
        assert_eq!(m.tangent(), m.initial_tangent(), "{name}: virgin tangent");
        let (mut worst, mut worst_zero) = (0.0f64, 0.0f64);
        let mut last = 0.0;
        for (i, &(d, _)) in path.iter().enumerate() {
            m.set_trial(d);
            m.commit();
            let s = (d - last).signum();
            last = d;
            if i % 3 != 0 {
                continue;
            }
            // trial moves both ways from the committed state (lengths off the sub-step grid)
            for dd in [0.123, -0.377, 1.234, -2.71] {
                let x = d + dd * UY;
                let fd = (force_at(&mut m, x + h) - force_at(&mut m, x - h)) / (2.0 * h);
                m.set_trial(x);
                worst = worst.max((m.tangent() - fd).abs() / K);
            }
            // zero move: the one-sided derivative in the direction of the last committed move
            let g = 1e-5 * UY * s;
            let fd = (-3.0 * force_at(&mut m, d) + 4.0 * force_at(&mut m, d + g) - force_at(&mut m, d + 2.0 * g))
                / (2.0 * g);
            m.set_trial(d);
            worst_zero = worst_zero.max((m.tangent() - fd).abs() / K);
        }
        println!(
            "Bouc–Wen {name}: max |dF/dδ − central FD| / k = {worst:.2e}, zero move vs one-sided FD: {worst_zero:.2e}"
        );
        assert!(worst <= 1e-6 && worst_zero <= 1e-6, "{name}: {worst:e} {worst_zero:e}");
    }
}

// ---------------------------------------------------------------------------------------------
// Every law: trial / commit / revert and checkpoints

/// Trial moves that are reverted or overwritten leave no trace; `revert` is the zero move
/// `set_trial(δ_n)`; the state vector restores the material bit for bit.
fn check_trial_semantics(law: &dyn Material, dy: f64) {
    let path: Vec<f64> = history(dy, 3.0).into_iter().map(|(d, _)| d).collect();
    let mut reference = law.fresh();
    let mut expected = vec![];
    let mut checkpoint = None;
    for (i, &d) in path.iter().enumerate() {
        if i == path.len() / 2 {
            let mut s = vec![f64::NAN; reference.state_len()];
            reference.write_state(&mut s);
            checkpoint = Some(s);
        }
        reference.set_trial(d);
        expected.push((reference.force(), reference.tangent()));
        reference.commit();
    }
    let mut m = law.fresh();
    let mut committed = 0.0;
    for (i, &d) in path.iter().enumerate() {
        m.set_trial(d + 2.5 * dy);
        m.set_trial(d - 1.5 * dy);
        m.revert();
        let reverted = (m.force(), m.tangent());
        m.set_trial(committed);
        assert_eq!(
            reverted,
            (m.force(), m.tangent()),
            "{}: revert ≠ zero move at {i}",
            law.kind()
        );
        m.set_trial(-d);
        m.set_trial(d);
        assert_eq!((m.force(), m.tangent()), expected[i], "{}: sample {i}", law.kind());
        m.commit();
        committed = d;
    }
    let s = checkpoint.unwrap();
    let mut restored = law.fresh();
    restored.read_state(&s);
    let mut again = vec![f64::NAN; s.len()];
    restored.write_state(&mut again);
    assert_eq!(
        s.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
        again.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
    );
    for (i, &d) in path.iter().enumerate().skip(path.len() / 2) {
        restored.set_trial(d);
        assert_eq!(
            (restored.force(), restored.tangent()),
            expected[i],
            "{}: restored, sample {i}",
            law.kind()
        );
        restored.commit();
    }
}

#[test]
fn every_law_keeps_trial_and_committed_states_apart() {
    check_trial_semantics(&Elastic::new(K).unwrap(), FY / K);
    check_trial_semantics(&Bilinear::new(K, FY, 0.05).unwrap(), FY / K);
    check_trial_semantics(&Bilinear::new(K, FY, 0.0).unwrap(), FY / K);
    for (_, p) in bouc_wen_cases() {
        check_trial_semantics(&bw(&p), UY);
    }
}

#[test]
fn bouc_wen_specimen_is_the_material_plus_a_dashpot() {
    for (_, mut p) in bouc_wen_cases() {
        p.damping = 3e3;
        let (mut spec, mut mat) = (BoucWen::new(&p).unwrap(), bw(&p));
        let (dt, mut u0) = (1e-3, 0.0);
        for (u1, _) in history(UY, 10.0) {
            let mut f = [0.0];
            spec.advance(
                &Motion {
                    d_start: &[u0],
                    d_end: &[u1],
                    ag_start: 0.0,
                    ag_end: 0.0,
                    dt,
                },
                &mut f,
            );
            spec.commit();
            mat.set_trial(u1);
            mat.commit();
            assert_eq!(f[0].to_bits(), (-mat.force() - p.damping * ((u1 - u0) / dt)).to_bits());
            u0 = u1;
        }
    }
    // the config-level spec: the element's stiffness, errors named after the config item
    let mut p = BoucWenParams::new(1.0, 0.1, UY);
    p.a = 0.8;
    let spec = MaterialSpec::BoucWen(Box::new(p));
    let m = spec.build(K, "storey").unwrap();
    assert_eq!((spec.kind(), m.kind()), ("bouc_wen", "bouc_wen"));
    assert!((m.initial_tangent() / (K * (0.1 + 0.9 * 0.8)) - 1.0).abs() < 1e-15);
    p.alpha = 1.5;
    let e = MaterialSpec::BoucWen(Box::new(p))
        .build(K, "storey")
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("storey.alpha"), "{e}");
    p.alpha = 0.1;
    p.damping = 1.0;
    let e = MaterialSpec::BoucWen(Box::new(p))
        .build(K, "storey")
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("storey.damping"), "{e}");
}

// ---------------------------------------------------------------------------------------------
// OpenSees

fn python() -> String {
    std::env::var("SUBSTEP_PYTHON").unwrap_or_else(|_| "python3".into())
}

const SCRIPT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/opensees/uniaxial_materials.py");

fn openseespy_available() -> bool {
    std::process::Command::new(python())
        .args([SCRIPT, "--check"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false)
}

/// Stress and tangent of OpenSees for each `(uniaxialMaterial arguments without the tag,
/// strains)` run, through tests/opensees/uniaxial_materials.py.
fn opensees(runs: &[(serde_json::Value, Vec<f64>)]) -> Vec<(Vec<f64>, Vec<f64>)> {
    use std::io::Write;
    let input = serde_json::json!({
        "runs": runs.iter().map(|(m, s)| serde_json::json!({"material": m, "strains": s})).collect::<Vec<_>>()
    });
    let mut child = std::process::Command::new(python())
        .arg(SCRIPT)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(input.to_string().as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let line = stdout
        .lines()
        .find_map(|l| l.strip_prefix("RESULT "))
        .expect("no RESULT line");
    let v: serde_json::Value = serde_json::from_str(line).unwrap();
    let floats = |x: &serde_json::Value| x.as_array().unwrap().iter().map(|y| y.as_f64().unwrap()).collect();
    v.as_array()
        .unwrap()
        .iter()
        .map(|r| (floats(&r["stress"]), floats(&r["tangent"])))
        .collect()
}

#[test]
fn bilinear_and_bouc_wen_match_opensees() {
    if !openseespy_available() {
        println!(
            "SKIPPED: openseespy is not installed (pip install openseespy; set SUBSTEP_PYTHON to its Python); the OpenSees material comparison did not run"
        );
        return;
    }
    use serde_json::json;
    let dy = FY / K;
    // Steel01 (a1 = a3 = 0 by default: no isotropic hardening) and ElasticPP against Bilinear,
    // finely sampled and with one jump per δ_y
    let mut cases: Vec<(f64, f64, serde_json::Value)> = vec![];
    for b in [0.1, 0.02, 0.0] {
        for per_dy in [50.0, 1.0] {
            cases.push((b, per_dy, json!(["Steel01", FY, K, b])));
        }
    }
    for per_dy in [50.0, 1.0] {
        cases.push((0.0, per_dy, json!(["ElasticPP", K, dy])));
    }
    // Bouc–Wen without degradation, and with it. OpenSees' z is dimensionless with u_y = 1
    // (`dz/dε = A − |z|ⁿ (γ + β sgn(dε z))`), its energy `e = (1 − α) k_o ∫ z dε`: ours with
    // strain `δ / u_y`, `k_o = k u_y`, `δ_OS = δ / ((1 − α) k u_y)` (A, ν, η). It integrates
    // with one backward-Euler step per strain increment (first order): two step sizes,
    // Richardson-extrapolated.
    let bw_cases = {
        let base = BoucWenParams::new(K, 0.1, UY);
        let mut shaped = base;
        (shaped.n, shaped.beta, shaped.gamma) = (2.0, 0.7, 0.3);
        let mut degrading = shaped;
        (degrading.delta_a, degrading.delta_nu, degrading.delta_eta) = (0.02, 0.1, 0.08);
        [
            ("n = 1", base),
            ("n = 2, β = 0.7, γ = 0.3", shaped),
            ("n = 2, degradation", degrading),
        ]
    };
    let per_uy = 1000.0;
    let mut runs: Vec<(serde_json::Value, Vec<f64>)> = cases
        .iter()
        .map(|(_, per_dy, m)| (m.clone(), history(dy, *per_dy).into_iter().map(|x| x.0).collect()))
        .collect();
    for (_, p) in &bw_cases {
        let e = (1.0 - p.alpha) * p.stiffness * UY;
        let m = json!([
            "BoucWen",
            p.alpha,
            p.stiffness * UY,
            p.n,
            p.gamma,
            p.beta,
            p.a,
            p.delta_a / e,
            p.delta_nu / e,
            p.delta_eta / e,
            1e-14,
            200
        ]);
        for per in [per_uy, 2.0 * per_uy] {
            runs.push((m.clone(), history(1.0, per).into_iter().map(|x| x.0).collect()));
        }
    }
    let results = opensees(&runs);
    for ((b, per_dy, m), (stress, tangent)) in cases.iter().zip(&results) {
        let mut ours = Bilinear::new(K, FY, *b).unwrap();
        let (mut pairs, mut tangent_mismatch) = (vec![], vec![]);
        for ((d, leg), (s, t)) in history(dy, *per_dy).into_iter().zip(stress.iter().zip(tangent)) {
            ours.set_trial(d);
            ours.commit();
            pairs.push((ours.force(), *s));
            if ours.tangent() != *t {
                tangent_mismatch.push((d / dy, masing(K, FY, *b, d, leg).2 / dy, ours.tangent(), *t));
            }
        }
        let rel = rel_max(pairs.into_iter());
        println!(
            "{} vs Bilinear b = {b}, {per_dy} samples/δ_y: max |ΔF| / F_peak = {rel:.2e}; tangents differ at (δ/δ_y, distance to the yield point / δ_y, ours, OpenSees) {tangent_mismatch:?}",
            m[0]
        );
        assert!(rel <= 1e-10, "{m}: {rel:e}");
        // tangents agree except exactly at a yield point (both slopes are right there)
        assert!(tangent_mismatch.iter().all(|x| x.1 < 1e-9), "{m}: {tangent_mismatch:?}");
    }
    for (i, (name, p)) in bw_cases.iter().enumerate() {
        let (coarse, fine) = (&results[cases.len() + 2 * i].0, &results[cases.len() + 2 * i + 1].0);
        let mut ours = bw(p);
        let (mut raw, mut extrapolated) = (vec![], vec![]);
        for (j, (x, _)) in history(1.0, per_uy).into_iter().enumerate() {
            ours.set_trial(x * UY);
            ours.commit();
            raw.push((ours.force(), fine[2 * j + 1]));
            extrapolated.push((ours.force(), 2.0 * fine[2 * j + 1] - coarse[j]));
        }
        let (r1, r2) = (rel_max(raw.into_iter()), rel_max(extrapolated.into_iter()));
        println!(
            "OpenSees BoucWen {name}: max |ΔF| / F_peak = {r1:.2e} (steps of {:.1e} u_y), {r2:.2e} Richardson-extrapolated",
            0.5 / per_uy
        );
        assert!(r2 <= 1e-6, "{name}: {r1:e} {r2:e}");
    }
}
