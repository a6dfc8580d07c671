//! On-line identification: RLS, scalar RLS and the ARX helper on known systems.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use substep::ident::{Arx, Estimator, Rls, ScalarRls};

/// `y_j = 1.5 y_{j−1} − 0.7 y_{j−2} + 1.0 u_j + 0.5 u_{j−1} + e_j` (poles at radius √0.7).
const TRUE: [f64; 4] = [1.5, -0.7, 1.0, 0.5];
/// The system after the step change of the tracking test.
const CHANGED: [f64; 4] = [1.2, -0.5, 0.6, -0.3];

struct System {
    theta: [f64; 4],
    y1: f64,
    y2: f64,
    u1: f64,
}

impl System {
    fn new(theta: [f64; 4]) -> Self {
        Self {
            theta,
            y1: 0.0,
            y2: 0.0,
            u1: 0.0,
        }
    }
    fn step(&mut self, u: f64, e: f64) -> f64 {
        let t = &self.theta;
        let y = t[0] * self.y1 + t[1] * self.y2 + t[2] * u + t[3] * self.u1 + e;
        self.y2 = self.y1;
        self.y1 = y;
        self.u1 = u;
        y
    }
}

fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    StandardNormal.sample(rng)
}

fn max_err(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

fn rel_err(a: &[f64], b: &[f64]) -> f64 {
    let num: f64 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum();
    let den: f64 = b.iter().map(|y| y * y).sum();
    (num / den).sqrt()
}

#[test]
fn arx_recovers_second_order_system_noise_free() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut sys = System::new(TRUE);
    let mut arx = Arx::new(2, 1, 1.0, 1e8).unwrap();
    for _ in 0..500 {
        let u = gauss(&mut rng);
        let y = sys.step(u, 0.0);
        arx.push(u, y);
    }
    let err = max_err(arx.theta(), &TRUE);
    println!("noise-free: theta = {:?}, max error {err:.2e}", arx.theta());
    assert!(err < 1e-8, "max parameter error {err:.2e}");
    assert_eq!(arx.a().len(), 2);
    assert_eq!(arx.b().len(), 2);
    // The one-step prediction before the measurement is the system's next output.
    let u = 0.3;
    let predicted = arx.predict_next(u);
    let actual = sys.step(u, 0.0);
    assert!(
        (predicted - actual).abs() < 1e-7 * actual.abs().max(1.0),
        "{predicted} vs {actual}"
    );
}

#[test]
fn arx_recovers_second_order_system_with_noise() {
    // Equation-error noise (the ARX noise model), std 0.05 against an output std of ≈ 3.
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let mut sys = System::new(TRUE);
    let mut arx = Arx::new(2, 1, 1.0, 1e6).unwrap();
    for _ in 0..5000 {
        let u = gauss(&mut rng);
        let e = 0.05 * gauss(&mut rng);
        let y = sys.step(u, e);
        arx.push(u, y);
    }
    let err = max_err(arx.theta(), &TRUE);
    println!("noise 0.05: theta = {:?}, max error {err:.2e}", arx.theta());
    assert!(err < 1e-2, "max parameter error {err:.2e}");
}

/// Samples after the change until the relative parameter error stays below 1 %, and the
/// error 200 samples after the change.
fn tracking(lambda: f64) -> (usize, f64) {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut sys = System::new(TRUE);
    let mut arx = Arx::new(2, 1, lambda, 1e4).unwrap();
    for _ in 0..2000 {
        let u = gauss(&mut rng);
        arx.push(u, sys.step(u, 0.0));
    }
    assert!(max_err(arx.theta(), &TRUE) < 1e-8);
    sys.theta = CHANGED;
    let mut settled = None;
    let mut at_200 = f64::NAN;
    for t in 1..=5000 {
        let u = gauss(&mut rng);
        arx.push(u, sys.step(u, 0.0));
        let e = rel_err(arx.theta(), &CHANGED);
        if t == 200 {
            at_200 = e;
        }
        if e < 0.01 {
            settled.get_or_insert(t);
        } else {
            settled = None;
        }
    }
    (settled.expect("never settled"), at_200)
}

#[test]
fn arx_tracks_a_step_change_at_the_rate_set_by_lambda() {
    let (t95, e95) = tracking(0.95);
    let (t99, e99) = tracking(0.99);
    println!("lambda 0.95: < 1 % after {t95} samples, error at 200: {e95:.2e}");
    println!("lambda 0.99: < 1 % after {t99} samples, error at 200: {e99:.2e}");
    assert!(t95 <= 200, "lambda 0.95 settled after {t95} samples");
    assert!(e95 < 0.01);
    assert!(
        e99 > 0.01,
        "lambda 0.99 should still be off after 200 samples: {e99:.2e}"
    );
    assert!(
        t99 > 2 * t95,
        "lambda 0.99 ({t99}) should be much slower than 0.95 ({t95})"
    );
    assert!(t99 < 2000);
}

#[test]
fn rls_survives_long_poor_excitation() {
    // Identify, then 1e5 samples without input (the output decays to exactly zero), then 1e5
    // samples of a constant input (rank-one excitation): with λ = 0.98 the unexcited directions
    // of P would grow as 0.98^−t ≈ 10^877 without the covariance bound.
    let lambda = 0.98;
    let p0 = 1e3;
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let mut sys = System::new(TRUE);
    let mut arx = Arx::new(2, 1, lambda, p0).unwrap();
    let n = 4.0;
    for _ in 0..1000 {
        let u = gauss(&mut rng);
        arx.push(u, sys.step(u, 0.0));
    }
    let mut max_trace: f64 = 0.0;
    for phase in [0.0, 1.0] {
        for _ in 0..100_000 {
            let e = arx.push(phase, sys.step(phase, 0.0));
            assert!(e.is_finite());
            assert!(arx.theta().iter().all(|t| t.is_finite()), "theta {:?}", arx.theta());
            let tr = arx.rls().covariance_trace();
            assert!(tr.is_finite());
            max_trace = max_trace.max(tr);
        }
    }
    println!(
        "after poor excitation: trace P max {max_trace:.3e} (bound {:.3e}), theta {:?}",
        p0 * n,
        arx.theta()
    );
    assert!(max_trace <= p0 * n * (1.0 + 1e-12));
    // Excitation returns: the estimate recovers.
    for _ in 0..1000 {
        let u = gauss(&mut rng);
        arx.push(u, sys.step(u, 0.0));
    }
    let err = max_err(arx.theta(), &TRUE);
    assert!(err < 1e-6, "after the excitation returns: max error {err:.2e}");
}

#[test]
fn rls_skips_unusable_data_and_never_produces_nan() {
    let mut rls = Rls::new(3, 0.98, 100.0).unwrap().with_theta(&[1.0, 2.0, 3.0]);
    assert_eq!(rls.predict(&[1.0, 1.0, 1.0]), 6.0);
    // All-zero regressor: skipped.
    for _ in 0..100_000 {
        rls.update(&[0.0; 3], 5.0);
    }
    assert_eq!(rls.theta(), &[1.0, 2.0, 3.0]);
    assert_eq!(rls.covariance_trace(), 300.0);
    // Non-finite inputs: skipped, the returned error is finite.
    assert_eq!(rls.update(&[f64::NAN, 1.0, 0.0], 1.0), 0.0);
    assert_eq!(rls.update(&[1.0, 1.0, 0.0], f64::INFINITY), 0.0);
    assert_eq!(rls.update(&[1.0, f64::INFINITY, 0.0], 1.0), 0.0);
    assert_eq!(rls.theta(), &[1.0, 2.0, 3.0]);
    // Huge but finite values: θ stays finite.
    rls.update(&[1e200, 1e200, 1e200], 1e300);
    rls.update(&[1e-300, 0.0, 0.0], -1e300);
    assert!(rls.theta().iter().all(|t| t.is_finite()), "{:?}", rls.theta());
    assert!(rls.covariance_trace().is_finite());
    // Dead zone: small errors do not update.
    let mut dz = Rls::new(2, 1.0, 10.0).unwrap().with_dead_zone(0.1).unwrap();
    dz.update(&[1.0, 0.0], 0.05);
    assert_eq!(dz.theta(), &[0.0, 0.0]);
    dz.update(&[1.0, 0.0], 1.0);
    assert!(dz.theta()[0] > 0.9);
    // Reset.
    rls.reset_covariance();
    assert_eq!(rls.covariance_trace(), 300.0);
}

#[test]
fn rls_update_matches_the_textbook_formulas() {
    // One step by hand: P = 2 I, φ = [1, 2], y = 3, λ = 0.5.
    let mut rls = Rls::new(2, 0.5, 2.0).unwrap().with_covariance_bound(1e9).unwrap();
    let e = rls.update(&[1.0, 2.0], 3.0);
    assert_eq!(e, 3.0);
    // Pφ = [2, 4], φᵀPφ = 10, K = [2, 4]/10.5, θ = 3K.
    let k = [2.0 / 10.5, 4.0 / 10.5];
    assert!((rls.theta()[0] - 3.0 * k[0]).abs() < 1e-15);
    assert!((rls.theta()[1] - 3.0 * k[1]).abs() < 1e-15);
    // P = (2I − [2,4][2,4]ᵀ/10.5)/0.5.
    let p = rls.covariance();
    let expect = [
        (2.0 - 4.0 / 10.5) / 0.5,
        (-8.0 / 10.5) / 0.5,
        (-8.0 / 10.5) / 0.5,
        (2.0 - 16.0 / 10.5) / 0.5,
    ];
    for (a, b) in p.iter().zip(expect) {
        assert!((a - b).abs() < 1e-14, "{p:?} vs {expect:?}");
    }
}

fn converge<E: Estimator>(mut est: E, samples: usize) -> f64 {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut sys = System::new(TRUE);
    let (mut y1, mut y2, mut u1) = (0.0, 0.0, 0.0);
    for _ in 0..samples {
        let u = gauss(&mut rng);
        let y = sys.step(u, 0.0);
        est.update(&[y1, y2, u, u1], y);
        (y2, y1, u1) = (y1, y, u);
    }
    max_err(est.theta(), &TRUE)
}

#[test]
fn scalar_rls_converges_on_the_same_system() {
    let full = converge(Rls::new(4, 0.98, 1e3).unwrap(), 2000);
    let scalar = converge(ScalarRls::new(4, 0.98, 1e3).unwrap(), 2000);
    let scalar_long = converge(ScalarRls::new(4, 0.98, 1e3).unwrap(), 20_000);
    println!("max parameter error: full RLS {full:.2e} (2000), scalar {scalar:.2e} (2000), {scalar_long:.2e} (20000)");
    assert!(full < 1e-10);
    assert!(scalar < 1e-2);
    assert!(scalar_long < 1e-8);
    assert!(full < scalar, "the full covariance should converge faster");
}

#[test]
fn constructors_reject_bad_parameters_with_named_errors() {
    let msg = |r: substep::Result<Rls>| r.expect_err("should fail").to_string();
    assert!(msg(Rls::new(0, 0.99, 1.0)).starts_with("order"));
    for lambda in [0.0, -0.5, 1.01, f64::NAN] {
        assert!(
            msg(Rls::new(2, lambda, 1.0)).starts_with("forgetting_factor"),
            "{lambda}"
        );
    }
    for p0 in [0.0, -1.0, f64::INFINITY] {
        assert!(msg(Rls::new(2, 0.99, p0)).starts_with("p0"), "{p0}");
    }
    assert!(
        ScalarRls::new(2, 1.5, 1.0)
            .unwrap_err()
            .to_string()
            .starts_with("forgetting_factor")
    );
    assert!(Arx::new(2, 1, 0.99, -1.0).unwrap_err().to_string().starts_with("p0"));
    assert!(Rls::new(2, 0.99, 1.0).unwrap().with_covariance_bound(0.0).is_err());
    assert!(Rls::new(2, 0.99, 1.0).unwrap().with_dead_zone(-1.0).is_err());
}
