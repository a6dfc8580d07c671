//! Verification of the linear specimens (`LinearSpecimen`) against closed forms and an
//! independent RK4 integration of the specimen's equations of motion, written here from the
//! physical matrices (not from the library's state-space model).

use nalgebra::{DMatrix, DVector, dmatrix, dvector};
use substep::Error;
use substep::specimen::{LinearSpecimen, Motion, Specimen, SpecimenSpec};

/// The key an `InvalidInput` error names.
fn key(e: Error) -> String {
    match e {
        Error::InvalidInput { what, .. } => what,
        other => panic!("expected an InvalidInput error, got {other:?}"),
    }
}

fn err_key<T>(r: substep::Result<T>) -> String {
    match r {
        Ok(_) => panic!("expected an error"),
        Err(e) => key(e),
    }
}

/// Advance `sp` over one linear piece and commit; returns the force(s) at the end.
fn step(sp: &mut LinearSpecimen, d0: &[f64], d1: &[f64], ag: (f64, f64), dt: f64) -> Vec<f64> {
    let mut f = vec![0.0; d0.len()];
    sp.advance(
        &Motion {
            d_start: d0,
            d_end: d1,
            ag_start: ag.0,
            ag_end: ag.1,
            dt,
        },
        &mut f,
    );
    sp.commit();
    f
}

fn state(sp: &LinearSpecimen) -> Vec<f64> {
    let mut s = vec![0.0; sp.state_len()];
    sp.write_state(&mut s);
    s
}

/// Damped SDOF constants: `(ω, ω_d, ζ ω)` for `m ẍ + c ẋ + k x`.
fn sdof_constants(m: f64, k: f64, c: f64) -> (f64, f64, f64) {
    let w = (k / m).sqrt();
    let zw = c / (2.0 * m);
    (w, (w * w - zw * zw).sqrt(), zw)
}

/// Free vibration of `m ẍ + c ẋ + k x = 0` from `(x0, v0)`: `(x(t), ẋ(t))`.
fn free_vibration(m: f64, k: f64, c: f64, x0: f64, v0: f64, t: f64) -> (f64, f64) {
    let (_, wd, zw) = sdof_constants(m, k, c);
    let (a, b) = (x0, (v0 + zw * x0) / wd);
    let e = (-zw * t).exp();
    let (s, co) = (wd * t).sin_cos();
    let x = e * (a * co + b * s);
    let v = e * (-zw * (a * co + b * s) + wd * (-a * s + b * co));
    (x, v)
}

/// An independent model of a linear specimen over `[c; s]`: the internal equations
/// `M_ss ẍ + C_ss ẋ + K_ss x = −K_sc u − C_sc u̇ − M_ss ι_s a_g` integrated with classical RK4
/// for a support motion and ground acceleration linear over each piece; the force on the
/// structure `f = −(K_cc u + K_cs x + C_cc u̇ + C_cs ẋ)`.
struct Rk4Specimen {
    n_c: usize,
    m: DMatrix<f64>,
    c: DMatrix<f64>,
    k: DMatrix<f64>,
    iota: DVector<f64>,
    x: DVector<f64>,
    v: DVector<f64>,
}

impl Rk4Specimen {
    fn new(n_c: usize, m: &DMatrix<f64>, c: &DMatrix<f64>, k: &DMatrix<f64>, iota: &DVector<f64>) -> Self {
        let n_s = k.nrows() - n_c;
        Self {
            n_c,
            m: m.clone(),
            c: c.clone(),
            k: k.clone(),
            iota: iota.clone(),
            x: DVector::zeros(n_s),
            v: DVector::zeros(n_s),
        }
    }

    fn n_s(&self) -> usize {
        self.k.nrows() - self.n_c
    }

    fn blk(a: &DMatrix<f64>, r: usize, c: usize, nr: usize, nc: usize) -> DMatrix<f64> {
        a.view((r, c), (nr, nc)).into_owned()
    }

    /// Acceleration of the internal DOFs.
    fn accel(&self, x: &DVector<f64>, v: &DVector<f64>, u: &DVector<f64>, ud: &DVector<f64>, ag: f64) -> DVector<f64> {
        let (nc, ns) = (self.n_c, self.n_s());
        let mss = Self::blk(&self.m, nc, nc, ns, ns);
        let rhs = -(Self::blk(&self.k, nc, nc, ns, ns) * x)
            - Self::blk(&self.c, nc, nc, ns, ns) * v
            - Self::blk(&self.k, nc, 0, ns, nc) * u
            - Self::blk(&self.c, nc, 0, ns, nc) * ud
            - &mss * self.iota.rows(nc, ns) * ag;
        mss.lu().solve(&rhs).expect("regular internal mass")
    }

    /// Advance over one linear piece with `sub` RK4 steps; returns the force at the end.
    fn step(&mut self, d0: &[f64], d1: &[f64], ag: (f64, f64), dt: f64, sub: usize) -> DVector<f64> {
        let (u0, u1) = (DVector::from_column_slice(d0), DVector::from_column_slice(d1));
        let ud = (&u1 - &u0) / dt;
        let h = dt / sub as f64;
        let at = |t: f64| (&u0 + &ud * t, ag.0 + (ag.1 - ag.0) * t / dt);
        for i in 0..sub {
            let t = i as f64 * h;
            let (x, v) = (self.x.clone(), self.v.clone());
            let (ua, aga) = at(t);
            let (ub, agb) = at(t + 0.5 * h);
            let (uc, agc) = at(t + h);
            let k1x = v.clone();
            let k1v = self.accel(&x, &v, &ua, &ud, aga);
            let (x2, v2) = (&x + &k1x * (0.5 * h), &v + &k1v * (0.5 * h));
            let k2x = v2.clone();
            let k2v = self.accel(&x2, &v2, &ub, &ud, agb);
            let (x3, v3) = (&x + &k2x * (0.5 * h), &v + &k2v * (0.5 * h));
            let k3x = v3.clone();
            let k3v = self.accel(&x3, &v3, &ub, &ud, agb);
            let (x4, v4) = (&x + &k3x * h, &v + &k3v * h);
            let k4x = v4.clone();
            let k4v = self.accel(&x4, &v4, &uc, &ud, agc);
            self.x = &x + (k1x + k2x * 2.0 + k3x * 2.0 + k4x) * (h / 6.0);
            self.v = &v + (k1v + k2v * 2.0 + k3v * 2.0 + k4v) * (h / 6.0);
        }
        let (nc, ns) = (self.n_c, self.n_s());
        -(Self::blk(&self.k, 0, 0, nc, nc) * &u1
            + Self::blk(&self.k, 0, nc, nc, ns) * &self.x
            + Self::blk(&self.c, 0, 0, nc, nc) * &ud
            + Self::blk(&self.c, 0, nc, nc, ns) * &self.v)
    }
}

/// A deterministic, irregular piecewise-linear history (sum of incommensurate sines).
fn wiggle(t: f64, phase: f64) -> f64 {
    (7.3 * t + phase).sin() + 0.4 * (23.1 * t + 2.0 * phase).sin() + 0.15 * (61.0 * t - phase).cos()
}

#[test]
fn tmd_free_vibration_from_state_matches_closed_form() {
    // Support at rest, initial condition set through the state: f = k x + c ẋ.
    let (m, k, c) = (2.0, 800.0, 4.0);
    let (x0, v0) = (0.01, -0.3);
    let mut sp = LinearSpecimen::sdof(Some(m), k, c).unwrap();
    assert_eq!(sp.state_len(), 2);
    sp.read_state(&[x0, v0]);
    let h = 0.01;
    let (mut err, mut scale, mut err_state) = (0.0f64, 0.0f64, 0.0f64);
    for i in 1..=300 {
        let f = step(&mut sp, &[0.0], &[0.0], (0.0, 0.0), h)[0];
        let (x, v) = free_vibration(m, k, c, x0, v0, i as f64 * h);
        let f_ref = k * x + c * v;
        err = err.max((f - f_ref).abs());
        scale = scale.max(f_ref.abs());
        let s = state(&sp);
        err_state = err_state
            .max((s[0] - x).abs() / x0.abs())
            .max((s[1] - v).abs() / v0.abs());
    }
    eprintln!(
        "tmd free vibration: force rel err {:.2e}, state rel err {err_state:.2e}",
        err / scale
    );
    assert!(err / scale < 1e-12, "force rel err {}", err / scale);
    assert!(err_state < 1e-12);
}

#[test]
fn tmd_ramp_support_matches_closed_form() {
    // u_c = s t from rest: y = x_s − u_c obeys m ÿ + c ẏ + k y = 0 with y(0) = 0, ẏ(0) = −s,
    // and f = k y + c ẏ. The dashpot sees the support velocity through the rate term.
    let (m, k, c) = (0.5, 200.0, 1.5);
    let s = 0.02;
    for h in [1e-3f64, 0.0137, 0.05] {
        let mut sp = LinearSpecimen::sdof(Some(m), k, c).unwrap();
        let (mut err, mut scale) = (0.0f64, 0.0f64);
        let n = (1.0 / h).round() as usize;
        for i in 1..=n {
            let (t0, t1) = ((i - 1) as f64 * h, i as f64 * h);
            let f = step(&mut sp, &[s * t0], &[s * t1], (0.0, 0.0), h)[0];
            let (y, yd) = free_vibration(m, k, c, 0.0, -s, t1);
            let f_ref = k * y + c * yd;
            err = err.max((f - f_ref).abs());
            scale = scale.max(f_ref.abs());
        }
        eprintln!("tmd ramp support h = {h}: rel err {:.2e}", err / scale);
        assert!(err / scale < 1e-12, "h = {h}: rel err {}", err / scale);
    }
}

#[test]
fn tmd_constant_ground_acceleration_matches_step_response() {
    // Support fixed, a_g = a0 from t = 0: x = x_st (1 − e^{−ζωt}(cos ω_d t + ζω/ω_d sin ω_d t)),
    // ẋ = x_st ω²/ω_d e^{−ζωt} sin ω_d t, x_st = −m a0 / k; f = k x + c ẋ.
    let (m, k, c) = (3.0, 1200.0, 6.0);
    let a0 = 1.7;
    let (w, wd, zw) = sdof_constants(m, k, c);
    let x_st = -m * a0 / k;
    let h = 0.004;
    let mut sp = LinearSpecimen::sdof(Some(m), k, c).unwrap();
    let (mut err, mut scale) = (0.0f64, 0.0f64);
    for i in 1..=500 {
        let t = i as f64 * h;
        let f = step(&mut sp, &[0.0], &[0.0], (a0, a0), h)[0];
        let e = (-zw * t).exp();
        let x = x_st * (1.0 - e * ((wd * t).cos() + zw / wd * (wd * t).sin()));
        let v = x_st * w * w / wd * e * (wd * t).sin();
        let f_ref = k * x + c * v;
        err = err.max((f - f_ref).abs());
        scale = scale.max(f_ref.abs());
    }
    eprintln!("tmd constant a_g: rel err {:.2e}", err / scale);
    assert!(err / scale < 1e-12, "rel err {}", err / scale);
}

#[test]
fn tmd_general_motion_matches_rk4() {
    let (m, k, c) = (1.2, 450.0, 2.2);
    let mut sp = LinearSpecimen::sdof(Some(m), k, c).unwrap();
    let mass = dmatrix![0.0, 0.0; 0.0, m];
    let damp = dmatrix![c, -c; -c, c];
    let stiff = dmatrix![k, -k; -k, k];
    let mut rk = Rk4Specimen::new(1, &mass, &damp, &stiff, &dvector![1.0, 1.0]);
    let h = 0.01;
    let (mut err, mut scale, mut err_state) = (0.0f64, 0.0f64, 0.0f64);
    for i in 1..=200 {
        let (t0, t1) = ((i - 1) as f64 * h, i as f64 * h);
        let d = [0.01 * wiggle(t0, 0.3), 0.01 * wiggle(t1, 0.3)];
        let ag = (2.0 * wiggle(t0, 1.1), 2.0 * wiggle(t1, 1.1));
        let f = step(&mut sp, &d[..1], &d[1..], ag, h)[0];
        let f_ref = rk.step(&d[..1], &d[1..], ag, h, 100)[0];
        err = err.max((f - f_ref).abs());
        scale = scale.max(f_ref.abs());
        let s = state(&sp);
        err_state = err_state.max((s[0] - rk.x[0]).abs()).max((s[1] - rk.v[0]).abs() * h);
    }
    eprintln!(
        "tmd general motion vs RK4: force rel err {:.2e}, state err {err_state:.2e}",
        err / scale
    );
    assert!(err / scale < 1e-8, "rel err {}", err / scale);
    assert!(err_state < 1e-10);
}

#[test]
fn split_of_linear_piece_does_not_change_result() {
    // One interval of 2h equals two of h with the midpoint on the line (motion and a_g).
    let mass = dmatrix![0.0, 0.0, 0.0; 0.0, 0.0, 0.0; 0.0, 0.0, 1.5];
    let damp = dmatrix![3.0, -0.5, -2.0; -0.5, 1.0, -0.5; -2.0, -0.5, 2.5];
    let stiff = dmatrix![900.0, -100.0, -600.0; -100.0, 400.0, -300.0; -600.0, -300.0, 900.0];
    let sdof = || LinearSpecimen::sdof(Some(0.8), 300.0, 1.1).unwrap();
    let mdof = || LinearSpecimen::from_matrices(2, mass.clone(), damp.clone(), stiff.clone(), None).unwrap();
    let h = 0.007;
    for (name, mut one, mut two) in [("linear_sdof", sdof(), sdof()), ("linear_mdof", mdof(), mdof())] {
        let n_c = one.n_dofs();
        let mut d_prev = vec![0.0; n_c];
        let mut ag_prev = 0.0;
        let (mut err, mut scale) = (0.0f64, 0.0f64);
        let (mut s_err, mut s_scale) = (vec![0.0f64; one.state_len()], vec![0.0f64; one.state_len()]);
        for i in 1..=60 {
            let t = i as f64 * 2.0 * h;
            let d_end: Vec<f64> = (0..n_c).map(|j| 0.01 * wiggle(t, j as f64)).collect();
            let ag_end = wiggle(t, 2.5);
            let d_mid: Vec<f64> = d_prev.iter().zip(&d_end).map(|(a, b)| 0.5 * (a + b)).collect();
            let ag_mid = 0.5 * (ag_prev + ag_end);
            let f1 = step(&mut one, &d_prev, &d_end, (ag_prev, ag_end), 2.0 * h);
            step(&mut two, &d_prev, &d_mid, (ag_prev, ag_mid), h);
            let f2 = step(&mut two, &d_mid, &d_end, (ag_mid, ag_end), h);
            for (a, b) in f1.iter().zip(&f2) {
                err = err.max((a - b).abs());
                scale = scale.max(a.abs());
            }
            for (j, (a, b)) in state(&one).iter().zip(state(&two)).enumerate() {
                s_err[j] = s_err[j].max((a - b).abs());
                s_scale[j] = s_scale[j].max(a.abs());
            }
            d_prev = d_end;
            ag_prev = ag_end;
        }
        let s_rel = s_err.iter().zip(&s_scale).map(|(e, s)| e / s).fold(0.0, f64::max);
        eprintln!(
            "{name}: one piece of 2h vs two of h: force rel diff {:.2e}, state rel diff {s_rel:.2e}",
            err / scale
        );
        assert!(err / scale < 1e-12, "{name}: rel diff {}", err / scale);
        assert!(s_rel < 1e-12, "{name}: state rel diff {s_rel}");
    }
}

#[test]
fn spring_dashpot_force_is_exact() {
    let (k, c) = (1500.0, 37.0);
    let mut sp = LinearSpecimen::sdof(None, k, c).unwrap();
    assert_eq!(sp.state_len(), 0);
    let mut d0 = 0.0;
    for i in 1..=50 {
        let dt = 0.001 * (1.0 + 0.37 * (i % 5) as f64);
        let d1 = 0.02 * wiggle(i as f64 * 0.013, 0.0);
        // The ground acceleration must not matter (no mass).
        let f = step(&mut sp, &[d0], &[d1], (3.0 * i as f64, -2.0), dt)[0];
        assert_eq!(f, -k * d1 - c * (d1 - d0) / dt, "interval {i}");
        d0 = d1;
    }
    // The same through the general constructor (no internal DOFs).
    let mut g = LinearSpecimen::from_matrices(1, dmatrix![0.0], dmatrix![c], dmatrix![k], None).unwrap();
    let f = step(&mut g, &[0.003], &[-0.002], (0.0, 0.0), 0.004)[0];
    assert_eq!(f, -k * -0.002 - c * (-0.002 - 0.003) / 0.004);
}

/// DOFs `[c1, c2, s1, s2]`: springs/dashpots c1–s1, s1–s2, s2–c2, s1–ground; masses on s1, s2.
fn mdof_matrices() -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
    let chain = |a: f64, b: f64, c: f64, g: f64| {
        let mut k = DMatrix::zeros(4, 4);
        for (i, j, v) in [(0, 2, a), (2, 3, b), (3, 1, c)] {
            k[(i, i)] += v;
            k[(j, j)] += v;
            k[(i, j)] -= v;
            k[(j, i)] -= v;
        }
        k[(2, 2)] += g;
        k
    };
    let mut m = DMatrix::zeros(4, 4);
    m[(2, 2)] = 1.5;
    m[(3, 3)] = 0.7;
    m[(2, 3)] = 0.1;
    m[(3, 2)] = 0.1;
    (m, chain(2.0, 0.8, 1.6, 0.3), chain(900.0, 500.0, 700.0, 200.0))
}

#[test]
fn mdof_specimen_with_internal_mass_matches_rk4() {
    let (m, c, k) = mdof_matrices();
    for iota in [None, Some(dvector![0.0, 0.0, 1.0, 0.6])] {
        let mut sp = LinearSpecimen::from_matrices(2, m.clone(), c.clone(), k.clone(), iota.clone()).unwrap();
        assert_eq!(sp.n_dofs(), 2);
        assert_eq!(sp.state_len(), 4);
        let mut rk = Rk4Specimen::new(
            2,
            &m,
            &c,
            &k,
            &iota.clone().unwrap_or_else(|| DVector::from_element(4, 1.0)),
        );
        let h = 0.005;
        let mut d_prev = [0.0, 0.0];
        let (mut err, mut scale, mut err_state) = (0.0f64, 0.0f64, 0.0f64);
        for i in 1..=300 {
            let t = i as f64 * h;
            let d = [0.01 * wiggle(t, 0.2), -0.006 * wiggle(t, 1.9)];
            let ag = (1.5 * wiggle(t - h, 0.7), 1.5 * wiggle(t, 0.7));
            let f = step(&mut sp, &d_prev, &d, ag, h);
            let f_ref = rk.step(&d_prev, &d, ag, h, 50);
            for j in 0..2 {
                err = err.max((f[j] - f_ref[j]).abs());
                scale = scale.max(f_ref[j].abs());
            }
            let s = state(&sp);
            for j in 0..2 {
                err_state = err_state
                    .max((s[j] - rk.x[j]).abs())
                    .max((s[2 + j] - rk.v[j]).abs() * h);
            }
            d_prev = d;
        }
        eprintln!(
            "mdof (influence {:?}) vs RK4: force rel err {:.2e}, state err {err_state:.2e}",
            iota.as_ref().map(|v| v.as_slice().to_vec()),
            err / scale
        );
        assert!(err / scale < 1e-8, "rel err {}", err / scale);
        assert!(err_state < 1e-10, "state err {err_state}");
    }
}

#[test]
fn mdof_sdof_equivalence() {
    // A TMD given as matrices is the sdof TMD.
    let (m, k, c) = (0.9, 350.0, 1.3);
    let mut a = LinearSpecimen::sdof(Some(m), k, c).unwrap();
    let mut b = LinearSpecimen::from_matrices(
        1,
        dmatrix![0.0, 0.0; 0.0, m],
        dmatrix![c, -c; -c, c],
        dmatrix![k, -k; -k, k],
        None,
    )
    .unwrap();
    let mut d0 = 0.0;
    for i in 1..=100 {
        let t = i as f64 * 0.01;
        let d1 = 0.01 * wiggle(t, 0.0);
        let ag = (wiggle(t - 0.01, 3.0), wiggle(t, 3.0));
        let fa = step(&mut a, &[d0], &[d1], ag, 0.01)[0];
        let fb = step(&mut b, &[d0], &[d1], ag, 0.01)[0];
        assert_eq!(fa, fb);
        d0 = d1;
    }
}

#[test]
fn non_physical_parameters_are_rejected_with_their_key() {
    // SDOF.
    assert_eq!(err_key(LinearSpecimen::sdof(Some(-1.0), 100.0, 1.0)), "specimen.mass");
    assert_eq!(err_key(LinearSpecimen::sdof(Some(0.0), 100.0, 1.0)), "specimen.mass");
    assert_eq!(
        err_key(LinearSpecimen::sdof(Some(f64::NAN), 100.0, 1.0)),
        "specimen.mass"
    );
    assert_eq!(
        err_key(LinearSpecimen::sdof(Some(1.0), -100.0, 1.0)),
        "specimen.stiffness"
    );
    assert_eq!(err_key(LinearSpecimen::sdof(None, -100.0, 1.0)), "specimen.stiffness");
    assert_eq!(
        err_key(LinearSpecimen::sdof(Some(1.0), 100.0, -1.0)),
        "specimen.damping"
    );
    assert_eq!(
        err_key(LinearSpecimen::sdof(None, 100.0, f64::INFINITY)),
        "specimen.damping"
    );
    assert!(
        LinearSpecimen::sdof(Some(1.0), 0.0, 0.0).is_ok(),
        "a free mass is stable (marginally)"
    );
    assert!(LinearSpecimen::sdof(None, 0.0, 0.0).is_ok());

    // MDOF.
    let (m, c, k) = mdof_matrices();
    let build = |m: DMatrix<f64>, c: DMatrix<f64>, k: DMatrix<f64>| LinearSpecimen::from_matrices(2, m, c, k, None);
    assert!(build(m.clone(), c.clone(), k.clone()).is_ok());
    let mut m_coupling = m.clone();
    m_coupling[(0, 0)] = 0.1;
    assert_eq!(err_key(build(m_coupling, c.clone(), k.clone())), "specimen.mass");
    let mut m_cs = m.clone();
    m_cs[(1, 3)] = 0.05;
    assert_eq!(err_key(build(m_cs, c.clone(), k.clone())), "specimen.mass");
    let mut m_neg = m.clone();
    m_neg[(3, 3)] = -0.7;
    assert_eq!(err_key(build(m_neg, c.clone(), k.clone())), "specimen.mass");
    // Negative internal stiffness or damping: unstable internal dynamics.
    let mut k_neg = k.clone();
    k_neg[(2, 2)] = -50.0;
    assert_eq!(err_key(build(m.clone(), c.clone(), k_neg)), "specimen");
    let mut c_neg = c.clone();
    c_neg[(3, 3)] = -5.0;
    assert_eq!(err_key(build(m.clone(), c_neg, k.clone())), "specimen");
    // Shapes, finiteness, attachment.
    assert_eq!(
        err_key(build(m.clone(), c.clone(), DMatrix::zeros(3, 3))),
        "specimen.mass"
    );
    assert_eq!(
        err_key(build(m.clone(), DMatrix::zeros(4, 3), k.clone())),
        "specimen.damping"
    );
    let mut k_nan = k.clone();
    k_nan[(0, 1)] = f64::NAN;
    assert_eq!(err_key(build(m.clone(), c.clone(), k_nan)), "specimen.stiffness");
    assert_eq!(
        err_key(LinearSpecimen::from_matrices(0, m.clone(), c.clone(), k.clone(), None)),
        "specimen.dofs"
    );
    assert_eq!(
        err_key(LinearSpecimen::from_matrices(5, m.clone(), c.clone(), k.clone(), None)),
        "specimen.dofs"
    );
    assert_eq!(
        err_key(LinearSpecimen::from_matrices(2, m, c, k, Some(dvector![1.0, 1.0]))),
        "specimen.influence"
    );

    // Through the test-definition type: same keys.
    let spec = SpecimenSpec::LinearSdof {
        dof: 0,
        mass: Some(-2.0),
        stiffness: 1.0,
        damping: 0.0,
    };
    assert_eq!(err_key(spec.build()), "specimen.mass");
}
