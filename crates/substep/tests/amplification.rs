//! Free-vibration behaviour of the integrators on an SDOF: amplification factors against the
//! characteristic polynomial of docs/theory.md §2.7, the HHT amplification matrix and characteristic
//! cubic derived by hand, and the stability limits.
//!
//! All runs use an SDOF with `m = 1`, `Δt = 0.01 s`, `ω = Ω/Δt`, `c = 2ζω`, started at rest
//! and kicked by a unit load at step 1 only (`f_0 = 0`, `f_1 = 1`, `f_i = 0` after). The
//! three-point recurrence then has zero load for `i ≥ 3`, HHT's equilibrium for `i ≥ 2`.

mod common;

use common::FAMILY;
use nalgebra::{Complex, DMatrix, DVector, Matrix3, Vector3, dvector};
use substep::integrate::{Kinematics, Scheme};
use substep::model::sdof;

const DT: f64 = 0.01;

/// States `0..=n` of the kicked SDOF.
fn kicked(scheme: Scheme, omega_dt: f64, zeta: f64, n: usize) -> Vec<Kinematics> {
    let w = omega_dt / DT;
    let model = sdof(1.0, 2.0 * zeta * w, w * w).unwrap();
    let mut integrator = scheme.build(&model, DT, &dvector![0.0]).unwrap();
    let mut out = vec![integrator.state().clone()];
    for i in 1..=n {
        integrator.step(&dvector![if i == 1 { 1.0 } else { 0.0 }]);
        out.push(integrator.state().clone());
    }
    out
}

fn displacements(states: &[Kinematics]) -> Vec<f64> {
    states.iter().map(|s| s.u[0]).collect()
}

/// Coefficients `[a, b, c]` of `a ρ² + b ρ + c` of docs/theory.md §2.7 with `m = 1`, `Δt c = 2ζΩ`,
/// `Δt² k = Ω²`.
fn char_poly(beta: f64, gamma: f64, omega_dt: f64, zeta: f64) -> [f64; 3] {
    let (dc, dk) = (2.0 * zeta * omega_dt, omega_dt * omega_dt);
    [
        1.0 + gamma * dc + beta * dk,
        -2.0 + (1.0 - 2.0 * gamma) * dc + (0.5 - 2.0 * beta + gamma) * dk,
        1.0 - (1.0 - gamma) * dc + (0.5 + beta - gamma) * dk,
    ]
}

fn quadratic_roots(a: f64, b: f64, c: f64) -> [Complex<f64>; 2] {
    let disc = Complex::new(b * b - 4.0 * a * c, 0.0).sqrt();
    [(-b + disc) / (2.0 * a), (-b - disc) / (2.0 * a)]
}

/// Least-squares `(T, D)` in `u_{i+1} = T u_i − D u_{i−1}` over `i ∈ from..to` (rows scaled
/// to unit size so that decaying sequences weigh evenly).
fn identify_recurrence(u: &[f64], from: usize, to: usize) -> (f64, f64) {
    let rows = to - from;
    let mut a = DMatrix::zeros(rows, 2);
    let mut b = DVector::zeros(rows);
    for (r, i) in (from..to).enumerate() {
        let s = 1.0 / u[i - 1].abs().max(u[i].abs()).max(u[i + 1].abs());
        a[(r, 0)] = u[i] * s;
        a[(r, 1)] = -u[i - 1] * s;
        b[r] = u[i + 1] * s;
    }
    let x = a.svd(true, true).solve(&b, 0.0).unwrap();
    (x[0], x[1])
}

/// `(|ρ|, ξ̄, T̄/T − 1)` of a complex root (docs/theory.md §2.7).
fn damping_and_elongation(rho: Complex<f64>, omega_dt: f64) -> (f64, f64, f64) {
    let (r, th) = (rho.norm(), rho.arg().abs());
    (r, -r.ln() / th, omega_dt / th - 1.0)
}

fn omega_grid(max: f64) -> Vec<f64> {
    (1..)
        .map(|i| 0.05 * i as f64)
        .take_while(|w| *w <= max + 1e-9)
        .collect()
}

/// Acceptance 2: for each three-point scheme, the simulated free vibration obeys the
/// recurrence whose coefficients are those of the characteristic polynomial of docs/theory.md §2.7,
/// and the identified roots give the closed-form |ρ|, ξ̄ and period elongation.
#[test]
fn three_point_schemes_match_characteristic_polynomial() {
    for (name, beta, gamma) in FAMILY {
        let max_omega = if beta < 0.25 { 1.9 } else { 3.0 };
        let (mut e_coef, mut e_root, mut n_complex) = (0.0f64, 0.0f64, 0);
        for zeta in [0.0, 0.05] {
            for w in omega_grid(max_omega) {
                let u = displacements(&kicked(Scheme::Newmark { beta, gamma }, w, zeta, 40));
                let (t, d) = identify_recurrence(&u, 3, 40);
                let [a, b, c] = char_poly(beta, gamma, w, zeta);
                let (t_ref, d_ref) = (-b / a, c / a);
                let e = (t - t_ref).abs().max((d - d_ref).abs());
                assert!(e < 1e-11, "{name} Ω={w} ζ={zeta}: T {t} vs {t_ref}, D {d} vs {d_ref}");
                e_coef = e_coef.max(e);

                let id = quadratic_roots(1.0, -t, d);
                let cf = quadratic_roots(a, b, c);
                let disc = t_ref * t_ref - 4.0 * d_ref;
                if disc < -1e-6 {
                    // Complex pair: compare |ρ|, numerical damping and period elongation.
                    n_complex += 1;
                    let (r1, xi1, el1) = damping_and_elongation(id[0], w);
                    let (r2, xi2, el2) = damping_and_elongation(cf[0], w);
                    let e = (r1 - r2).abs().max((xi1 - xi2).abs()).max((el1 - el2).abs());
                    assert!(
                        e < 1e-9,
                        "{name} Ω={w} ζ={zeta}: |ρ| {r1} vs {r2}, ξ {xi1} vs {xi2}, elong {el1} vs {el2}"
                    );
                    e_root = e_root.max(e);
                } else if disc > 1e-6 {
                    // Two real roots.
                    let mut x = [id[0].re, id[1].re];
                    let mut y = [cf[0].re, cf[1].re];
                    x.sort_by(f64::total_cmp);
                    y.sort_by(f64::total_cmp);
                    let e = (x[0] - y[0]).abs().max((x[1] - y[1]).abs());
                    assert!(e < 1e-9, "{name} Ω={w} ζ={zeta}: real roots {x:?} vs {y:?}");
                    e_root = e_root.max(e);
                }

                if gamma == 0.5 && zeta == 0.0 {
                    // No numerical damping: |ρ| = 1 and cos(arg ρ) = (1 − (½−β)Ω²)/(1 + βΩ²).
                    assert!((d - 1.0).abs() < 1e-12, "{name} Ω={w}: |ρ|² = {d}");
                    let cos_ref = (1.0 - (0.5 - beta) * w * w) / (1.0 + beta * w * w);
                    assert!((id[0].arg().cos() - cos_ref).abs() < 1e-10, "{name} Ω={w}: phase");
                }
                if beta == 0.25 && gamma == 0.5 && zeta == 0.0 {
                    // Trapezoidal rule: arg ρ = 2 atan(Ω/2).
                    let th = id[0].arg().abs();
                    assert!((th - 2.0 * (w / 2.0).atan()).abs() < 1e-10, "Ω={w}: arg ρ {th}");
                }
            }
        }
        println!(
            "{name}: max |Δ(T, D)| {e_coef:.1e}, max root-metric error {e_root:.1e} \
             ({n_complex} complex cases)"
        );
    }
}

/// Members with γ > ½ dissipate (|ρ| < 1, ξ̄ > 0 at Ω = 1, undamped SDOF); members with
/// γ = ½ do not (|ρ| = 1, ξ̄ = 0).
#[test]
fn numerical_damping_sign_follows_gamma() {
    for (name, beta, gamma) in FAMILY {
        let w = 1.0;
        let u = displacements(&kicked(Scheme::Newmark { beta, gamma }, w, 0.0, 40));
        let (t, d) = identify_recurrence(&u, 3, 40);
        let rho = quadratic_roots(1.0, -t, d)[0];
        let (r, xi, _) = damping_and_elongation(rho, w);
        if gamma > 0.5 {
            assert!(r < 1.0 - 1e-3 && xi > 1e-3, "{name}: |ρ| = {r}, ξ̄ = {xi}");
        } else {
            assert!(
                (r - 1.0).abs() < 1e-12 && xi.abs() < 1e-11,
                "{name}: |ρ| = {r}, ξ̄ = {xi}"
            );
        }
    }
}

// ---------------------------------------------------------------------------------------
// HHT

fn hht_constants(alpha: f64) -> (f64, f64) {
    (0.5 - alpha, (1.0 - alpha).powi(2) / 4.0)
}

/// Amplification matrix of HHT-α for the SDOF in the scaled state `[ω u, v, a/ω]`, built by
/// hand from `L x_{i+1} = R x_i`:
/// `u' − βΔt² a' = u + Δt v + (½−β)Δt² a`, `v' − γΔt a' = v + (1−γ)Δt a`,
/// `(1+α)k u' + (1+α)c v' + m a' = αk u + αc v` (zero load).
fn hht_amplification(alpha: f64, omega_dt: f64, zeta: f64) -> Matrix3<f64> {
    let (gamma, beta) = hht_constants(alpha);
    let w = omega_dt / DT;
    let (k, c, dt) = (w * w, 2.0 * zeta * w, DT);
    #[rustfmt::skip]
    let l = Matrix3::new(
        1.0, 0.0, -beta * dt * dt,
        0.0, 1.0, -gamma * dt,
        (1.0 + alpha) * k, (1.0 + alpha) * c, 1.0,
    );
    #[rustfmt::skip]
    let r = Matrix3::new(
        1.0, dt, (0.5 - beta) * dt * dt,
        0.0, 1.0, (1.0 - gamma) * dt,
        alpha * k, alpha * c, 0.0,
    );
    let s = Matrix3::from_diagonal(&Vector3::new(w, 1.0, 1.0 / w));
    let s_inv = Matrix3::from_diagonal(&Vector3::new(1.0 / w, 1.0, w));
    s * l.try_inverse().unwrap() * r * s_inv
}

fn poly_mul(p: &[f64], q: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; p.len() + q.len() - 1];
    for (i, a) in p.iter().enumerate() {
        for (j, b) in q.iter().enumerate() {
            out[i + j] += a * b;
        }
    }
    out
}

/// Characteristic cubic of HHT-α for the SDOF (ascending powers, normalised to be monic),
/// derived by expanding `det(λ L − R)`:
/// `χ(λ) = λ(λ−1)² + c̄ (λ−1)(γλ + 1−γ)((1+α)λ − α)
///        + k̄ ((1+α)λ − α)(βλ² + (½−2β+γ)λ + (½+β−γ))`,  `c̄ = 2ζΩ`, `k̄ = Ω²`.
/// (With α = 0 the factor λ splits off and the rest is the quadratic of docs/theory.md §2.7.)
fn hht_cubic(alpha: f64, omega_dt: f64, zeta: f64) -> [f64; 4] {
    let (gamma, beta) = hht_constants(alpha);
    let (cb, kb) = (2.0 * zeta * omega_dt, omega_dt * omega_dt);
    let p = [-alpha, 1.0 + alpha];
    let t1 = [0.0, 1.0, -2.0, 1.0];
    let t2 = poly_mul(&poly_mul(&[-1.0, 1.0], &[1.0 - gamma, gamma]), &p);
    let t3 = poly_mul(&p, &[0.5 + beta - gamma, 0.5 - 2.0 * beta + gamma, beta]);
    let mut chi = [0.0; 4];
    for i in 0..4 {
        chi[i] = t1[i] + cb * t2[i] + kb * t3[i];
    }
    let lead = chi[3];
    chi.map(|x| x / lead)
}

/// Roots of a monic cubic (ascending coefficients) by Durand–Kerner iteration.
fn cubic_roots(p: &[f64; 4]) -> [Complex<f64>; 3] {
    let eval = |z: Complex<f64>| ((z + p[2]) * z + p[1]) * z + p[0];
    let seed = Complex::new(0.4, 0.9);
    let mut z = [Complex::new(1.0, 0.0), seed, seed * seed];
    for _ in 0..5000 {
        for k in 0..3 {
            let mut den = Complex::new(1.0, 0.0);
            for j in 0..3 {
                if j != k {
                    den *= z[k] - z[j];
                }
            }
            z[k] -= eval(z[k]) / den;
        }
    }
    z
}

fn spectral_radius(roots: &[Complex<f64>]) -> f64 {
    roots.iter().map(|z| z.norm()).fold(0.0, f64::max)
}

/// Every root of `a` lies within `tol` of some root of `b`, and vice versa.
fn same_roots(a: &[Complex<f64>], b: &[Complex<f64>], tol: f64) -> bool {
    let near = |x: &Complex<f64>, set: &[Complex<f64>]| set.iter().any(|y| (x - y).norm() < tol);
    a.iter().all(|x| near(x, b)) && b.iter().all(|y| near(y, a))
}

/// The state map of the HHT and α-OS integrators is the hand-built amplification matrix,
/// and its eigenvalues are the roots of the hand-derived characteristic cubic.
#[test]
fn hht_state_map_is_hand_built_amplification_matrix() {
    let mut worst = 0.0f64;
    for alpha in [-0.1, -0.3] {
        for zeta in [0.0, 0.05] {
            for w in [0.05, 0.5, 1.0, 3.0, 10.0] {
                let a_hat = hht_amplification(alpha, w, zeta);
                let omega = w / DT;
                let scaled = |s: &Kinematics| Vector3::new(omega * s.u[0], s.v[0], s.a[0] / omega);
                for scheme in [Scheme::Hht { alpha }, Scheme::AlphaOs { alpha }] {
                    let states = kicked(scheme, w, zeta, 30);
                    for i in 2..30 {
                        let (x, y) = (scaled(&states[i]), scaled(&states[i + 1]));
                        let e = (y - a_hat * x).amax() / x.amax();
                        assert!(e < 1e-12, "{scheme:?} Ω={w} ζ={zeta} step {i}: {e:.3e}");
                        worst = worst.max(e);
                    }
                }
                let eig = nalgebra::Schur::try_new(a_hat, f64::EPSILON, 1000)
                    .expect("Schur converges")
                    .complex_eigenvalues();
                let cubic = cubic_roots(&hht_cubic(alpha, w, zeta));
                assert!(
                    same_roots(eig.as_slice(), &cubic, 1e-9),
                    "α={alpha} Ω={w} ζ={zeta}: eig {eig:?} vs cubic {cubic:?}"
                );
            }
        }
    }
    println!("HHT/α-OS state map vs hand-built amplification matrix: max rel error {worst:.1e}");
}

/// With α = 0 the HHT cubic is λ·(quadratic of docs/theory.md §2.7 for average acceleration).
#[test]
fn hht_cubic_reduces_to_newmark_quadratic() {
    for w in [0.1, 1.0, 5.0] {
        let roots = cubic_roots(&hht_cubic(0.0, w, 0.05));
        let [a, b, c] = char_poly(0.25, 0.5, w, 0.05);
        let mut expected = quadratic_roots(a, b, c).to_vec();
        expected.push(Complex::new(0.0, 0.0));
        assert!(same_roots(&roots, &expected, 1e-12), "Ω={w}: {roots:?} vs {expected:?}");
    }
}

/// HHT spectral radius: ≤ 1 over Ω ∈ (0, 100]; < 1 (dissipative) away from Ω → 0; and
/// as Ω → ∞ the principal pair tends to the double root `−(1+α)/(1−α)` and the spurious
/// root to `α/(1+α)`, so `ρ∞ = (1+α)/(1−α)` (derived: with `u/a → 0` the Newmark relations
/// give `βρ² + (½−2β+γ)ρ + (½+β−γ) = 0`, which for HHT's β, γ is
/// `((1−α)ρ + (1+α))² = 0`; the other factor of χ/k̄ is `(1+α)ρ − α`).
#[test]
fn hht_spectral_radius_bounded_and_limit() {
    for alpha in [-0.1, -0.3, -1.0 / 3.0] {
        let (mut rho_max, mut rho_prev) = (0.0f64, 1.0f64);
        for i in 0..=500 {
            let w = 10f64.powf(-3.0 + 5.0 * i as f64 / 500.0); // 1e-3 … 1e2
            let rho = spectral_radius(&cubic_roots(&hht_cubic(alpha, w, 0.0)));
            assert!(rho <= 1.0 + 1e-12, "α={alpha} Ω={w}: ρ = {rho}");
            // Numerical damping sets in like Ω⁴ (1 − ρ ≈ 1e-6 at Ω = 0.1 for α = −0.1) and
            // grows monotonically with Ω.
            if w >= 0.1 {
                assert!(rho < 1.0 - 1e-7, "α={alpha} Ω={w}: not dissipative, ρ = {rho}");
            }
            assert!(
                rho <= rho_prev + 1e-13,
                "α={alpha} Ω={w}: ρ = {rho} rises from {rho_prev}"
            );
            rho_prev = rho;
            rho_max = rho_max.max(rho);
        }
        let limit = (1.0 + alpha) / (1.0 - alpha);
        let roots = cubic_roots(&hht_cubic(alpha, 1e6, 0.0));
        let rho_inf = spectral_radius(&roots);
        println!("HHT α={alpha:.4}: max ρ on (0, 100] {rho_max:.12}, ρ(Ω=1e6) {rho_inf:.8}, closed form {limit:.8}");
        // At α = −⅓ all three limit roots coincide at −½, so the O(1/Ω²) coefficient
        // perturbation moves them by its cube root.
        let tol = if alpha > -0.33 { 1e-4 } else { 1e-3 };
        assert!((rho_inf - limit).abs() < tol, "α={alpha}: ρ∞ {rho_inf} vs {limit}");
        let expected = [
            Complex::new(-limit, 0.0),
            Complex::new(-limit, 0.0),
            Complex::new(alpha / (1.0 + alpha), 0.0),
        ];
        assert!(same_roots(&roots, &expected, tol), "α={alpha}: roots {roots:?}");
        // And at a large but finite Ω the simulated state map agrees with the matrix.
        let a_hat = hht_amplification(alpha, 100.0, 0.0);
        let eig = nalgebra::Schur::try_new(a_hat, f64::EPSILON, 1000)
            .unwrap()
            .complex_eigenvalues();
        let rho100 = spectral_radius(eig.as_slice());
        assert!(rho100 < 1.0 && rho100 > limit - 0.05, "α={alpha}: ρ(100) = {rho100}");
    }
}

// ---------------------------------------------------------------------------------------
// Stability

/// `max |u_i|` over `range`.
fn peak(u: &[f64], range: std::ops::Range<usize>) -> f64 {
    u[range].iter().fold(0.0, |m, x| m.max(x.abs()))
}

/// Acceptance 3: central difference is unstable beyond Ω = 2 and bounded below; the same for
/// Fox–Goodwin (Ω_cr = √6) and linear acceleration (Ω_cr = √12). For γ = ½ the limit is
/// `Ω_cr = 1/√(¼ − β)`.
#[test]
fn conditionally_stable_schemes_have_their_stability_limit() {
    for (name, beta, omega_cr) in [
        ("central difference", 0.0f64, 2.0),
        ("Fox-Goodwin", 1.0 / 12.0, 6f64.sqrt()),
        ("linear acceleration", 1.0 / 6.0, 12f64.sqrt()),
    ] {
        assert!((omega_cr - 1.0 / (0.25 - beta).sqrt()).abs() < 1e-12);
        let scheme = Scheme::Newmark { beta, gamma: 0.5 };
        let over = if beta == 0.0 { 2.05 } else { 1.02 * omega_cr };
        let under = if beta == 0.0 { 1.95 } else { 0.98 * omega_cr };

        let u = displacements(&kicked(scheme, over, 0.0, 500));
        let growth = u[500].abs() / peak(&u, 1..6);
        // Per-step growth equals the larger |root| of the characteristic polynomial.
        let [a, b, c] = char_poly(beta, 0.5, over, 0.0);
        let rho = spectral_radius(&quadratic_roots(a, b, c));
        let (t, d) = identify_recurrence(&u, 3, 20);
        let rho_id = spectral_radius(&quadratic_roots(1.0, -t, d));
        println!("{name} Ω={over:.4}: growth over 500 steps {growth:.2e}, ρ {rho:.6} (identified {rho_id:.6})");
        assert!(growth > 1e3, "{name} Ω={over}: growth {growth}");
        assert!(
            rho > 1.0 && (rho - rho_id).abs() < 1e-9 * rho,
            "{name}: ρ {rho} vs {rho_id}"
        );

        let u = displacements(&kicked(scheme, under, 0.0, 5000));
        let (early, late) = (peak(&u, 1..200), peak(&u, 200..5001));
        println!("{name} Ω={under:.4}: peak steps 1..200 {early:.3e}, steps 200..5000 {late:.3e}");
        assert!(late <= 1.01 * early, "{name} Ω={under}: grows ({early} → {late})");
        let (_, d) = identify_recurrence(&u, 3, 200);
        assert!((d - 1.0).abs() < 1e-12, "{name} Ω={under}: |ρ|² = {d}");
    }
}

/// Acceptance 3: average acceleration is unconditionally stable: at Ω = 10, 100 (and 1000)
/// the undamped response keeps `|ρ| = 1` to 1e-12, the discrete energy `½v² + ½ω²u²` is
/// conserved (the trapezoidal rule is a Cayley transform) and `|u| ≤ √(2E)/ω`.
#[test]
fn average_acceleration_is_unconditionally_stable() {
    let scheme = Scheme::Newmark { beta: 0.25, gamma: 0.5 };
    for w in [10.0, 100.0, 1000.0] {
        let n = 2000;
        let states = kicked(scheme, w, 0.0, n);
        let u = displacements(&states);
        let (_, d) = identify_recurrence(&u, 3, 100);
        let omega = w / DT;
        let energy = |s: &Kinematics| 0.5 * s.v[0] * s.v[0] + 0.5 * omega * omega * s.u[0] * s.u[0];
        let e0 = energy(&states[2]);
        let drift = states[2..]
            .iter()
            .map(|s| (energy(s) / e0 - 1.0).abs())
            .fold(0.0, f64::max);
        let bound = (2.0 * e0).sqrt() / omega;
        let late = peak(&u, 2..n + 1);
        println!(
            "average acceleration Ω={w}: |ρ|²−1 = {:.1e}, energy drift {drift:.1e}",
            d - 1.0
        );
        assert!((d - 1.0).abs() < 1e-12, "Ω={w}: |ρ|² = {d}");
        assert!(drift < 1e-12, "Ω={w}: energy drift {drift:.3e}");
        assert!(late <= bound * (1.0 + 1e-12), "Ω={w}: |u| {late} > bound {bound}");
        // With damping it decays.
        let u = displacements(&kicked(scheme, w, 0.05, 100));
        let (_, d) = identify_recurrence(&u, 3, 100);
        let [a, _, c] = char_poly(0.25, 0.5, w, 0.05);
        assert!(
            d < 1.0 && (d - c / a).abs() < 1e-11,
            "Ω={w} ζ=0.05: |ρ|² = {d} vs {}",
            c / a
        );
    }
}

/// KR-α's constants `(α_m, α_f, β, γ)` for `ρ∞` (docs/theory.md §2.8).
fn kr_constants(rho: f64) -> (f64, f64, f64, f64) {
    (
        (2.0 - rho) / (1.0 + rho),
        1.0 / (1.0 + rho),
        1.0 / (1.0 + rho).powi(2),
        0.5 * (3.0 - rho) / (1.0 + rho),
    )
}

/// Amplification matrix of KR-α for the SDOF (`m = 1`) in the scaled state `[ω u, v, a/ω]`,
/// built by hand from the scalar form of docs/theory.md §2.8: `A = 1 + γΔt c + βΔt² k`,
/// `α₁ = 1/A`, `α₃ = ((1−α_m) + (1−α_f)(γΔt c + βΔt² k))/A`,
/// `u' = u + Δt v + (½+γ)Δt² α₁ a`, `v' = v + Δt α₁ a`,
/// `(1−α₃) a' = −k((1−α_f) u + α_f u') − c((1−α_f) v + α_f v') − α₃ a` (zero load).
fn kr_amplification(rho: f64, omega_dt: f64, zeta: f64) -> Matrix3<f64> {
    let (am, af, beta, gamma) = kr_constants(rho);
    let w = omega_dt / DT;
    let (k, c, dt) = (w * w, 2.0 * zeta * w, DT);
    let a = 1.0 + gamma * dt * c + beta * dt * dt * k;
    let (a1, a3) = (
        1.0 / a,
        ((1.0 - am) + (1.0 - af) * (gamma * dt * c + beta * dt * dt * k)) / a,
    );
    // rows u', v' from the state; then a' from u', v' and the state
    let (uu, uv, ua) = (1.0, dt, (0.5 + gamma) * dt * dt * a1);
    let (vu, vv, va) = (0.0, 1.0, dt * a1);
    let au = (-k * ((1.0 - af) + af * uu) - c * af * vu) / (1.0 - a3);
    let av = (-k * af * uv - c * ((1.0 - af) + af * vv)) / (1.0 - a3);
    let aa = (-k * af * ua - c * af * va - a3) / (1.0 - a3);
    #[rustfmt::skip]
    let m = Matrix3::new(
        uu, uv, ua,
        vu, vv, va,
        au, av, aa,
    );
    let s = Matrix3::from_diagonal(&Vector3::new(w, 1.0, 1.0 / w));
    let s_inv = Matrix3::from_diagonal(&Vector3::new(1.0 / w, 1.0, w));
    s * m * s_inv
}

fn eigenvalues(m: Matrix3<f64>) -> Vec<Complex<f64>> {
    nalgebra::Schur::try_new(m, f64::EPSILON, 1000)
        .expect("Schur converges")
        .complex_eigenvalues()
        .as_slice()
        .to_vec()
}

/// KR-α (docs/theory.md §2.8): the integrator's state map is the hand-built scalar
/// amplification matrix (to 1e-12); the spectral radius is at most 1 on `Ω ≤ 1000` with and
/// without damping (unconditional stability for linear systems) and tends to the ρ∞ it was
/// built with as `Ω → ∞` (Kolay & Ricles' defining property), for ρ∞ = 0 … 1.
#[test]
fn kr_alpha_state_map_and_spectral_radius() {
    let mut worst = 0.0f64;
    for rho in [0.0, 0.25, 0.5, 0.75, 1.0] {
        for zeta in [0.0, 0.05] {
            for w in [0.05, 0.5, 1.0, 3.0, 10.0, 100.0] {
                let a_hat = kr_amplification(rho, w, zeta);
                let omega = w / DT;
                let scaled = |s: &Kinematics| Vector3::new(omega * s.u[0], s.v[0], s.a[0] / omega);
                let states = kicked(Scheme::KrAlpha { rho_inf: rho }, w, zeta, 30);
                for i in 2..30 {
                    let (x, y) = (scaled(&states[i]), scaled(&states[i + 1]));
                    if x.amax() < 1e-200 {
                        break;
                    }
                    let e = (y - a_hat * x).amax() / x.amax();
                    assert!(e < 1e-12, "kr_alpha ρ∞={rho} Ω={w} ζ={zeta} step {i}: {e:.3e}");
                    worst = worst.max(e);
                }
            }
            let mut largest = 0.0f64;
            for w in omega_grid(1000.0).into_iter().step_by(7) {
                largest = largest.max(spectral_radius(&eigenvalues(kr_amplification(rho, w, zeta))));
            }
            // 1e-6: with ρ∞ = 1 the spurious root is −1 and the principal pair approaches it at
            // large Ω, a near-multiple root whose computed modulus is only good to ~ε^(1/2).
            assert!(
                largest <= 1.0 + 1e-6,
                "ρ∞={rho} ζ={zeta}: spectral radius {largest} > 1"
            );
            let at_infinity = spectral_radius(&eigenvalues(kr_amplification(rho, 1e6, zeta)));
            println!(
                "kr_alpha ρ∞={rho} ζ={zeta}: max spectral radius on Ω ≤ 1000 {largest:.12}, at Ω = 1e6 {at_infinity:.6}"
            );
            assert!(
                (at_infinity - rho).abs() < 2e-3,
                "ρ∞={rho} ζ={zeta}: ρ(Ω=1e6) = {at_infinity}"
            );
        }
    }
    println!("kr_alpha state map vs hand-built amplification matrix: max rel error {worst:.1e}");
}

/// CR (docs/theory.md §2.8) has the characteristic roots of average acceleration on a linear
/// SDOF (Chen & Ricles): the recurrence identified from its free vibration has the roots of the
/// trapezoidal quadratic of §2.7 to 1e-9, with and without damping, so `|ρ| = 1` undamped.
#[test]
fn cr_has_the_roots_of_average_acceleration() {
    for zeta in [0.0, 0.05] {
        for w in [0.05, 0.5, 1.0, 3.0, 10.0, 100.0] {
            let u = displacements(&kicked(Scheme::Cr, w, zeta, 60));
            let (t, d) = identify_recurrence(&u, 3, 40);
            let cr = quadratic_roots(1.0, -t, d);
            let [a, b, c] = char_poly(0.25, 0.5, w, zeta);
            let trapezoidal = quadratic_roots(a, b, c);
            assert!(
                same_roots(&cr, &trapezoidal, 1e-9),
                "Ω={w} ζ={zeta}: cr {cr:?} vs average acceleration {trapezoidal:?}"
            );
            if zeta == 0.0 {
                assert!(
                    (spectral_radius(&cr) - 1.0).abs() < 1e-9,
                    "Ω={w}: |ρ| = {}",
                    spectral_radius(&cr)
                );
            }
        }
    }
}
