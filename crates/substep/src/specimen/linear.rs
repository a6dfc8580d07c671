//! Linear specimens: a linear MDOF system attached to coupling DOFs, integrated exactly for a
//! piecewise-linear support motion (first-order hold). Covers the TMD (mass on a spring and
//! dashpot attached to one coupling DOF) and the spring + dashpot to ground (`m_s → ∞`).
//!
//! The specimen's DOFs are ordered `[c; s]`: `c` the attached (prescribed) coupling DOFs, `s`
//! its internal DOFs. Internal equations, relative to the ground:
//! `M_ss ẍ_s + C_ss ẋ_s + K_ss x_s = −K_sc u_c − C_sc u̇_c − M_ss ι_s a_g`, and the force on the
//! structure is `f_c = −(K_cc u_c + K_cs x_s + C_cc u̇_c + C_cs ẋ_s)`. Mass on the coupling DOFs
//! (`M_cc`, `M_cs`) is not allowed: it belongs to the numerical model.

use super::{Motion, Specimen};
use crate::error::{Error, Result, require_non_negative, require_positive};
use crate::integrate::FohMap;
use nalgebra::{DMatrix, DVector, dmatrix};

pub struct LinearSpecimen {
    kind: &'static str,
    n_c: usize,
    n_s: usize,
    k_cc: DMatrix<f64>,
    k_cs: DMatrix<f64>,
    c_cc: DMatrix<f64>,
    c_cs: DMatrix<f64>,
    /// State-space model of the internal DOFs, `z = [x_s; ẋ_s]`, inputs `w = [u_c; a_g]`.
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    d: DMatrix<f64>,
    /// Discrete map for the last interval length (recomputed only when `dt` changes).
    map: Option<(f64, FohMap)>,
    z: DVector<f64>,
    z_trial: DVector<f64>,
    w_start: DVector<f64>,
    w_end: DVector<f64>,
    dw: DVector<f64>,
}

impl LinearSpecimen {
    /// TMD on one coupling DOF: mass `m_s`, stiffness `k_s`, damping `c_s`. `mass = None`
    /// (`m_s → ∞`) gives a spring and dashpot to ground, `f_c = −k_s u_c − c_s u̇_c`.
    pub fn sdof(mass: Option<f64>, stiffness: f64, damping: f64) -> Result<Self> {
        require_non_negative("specimen.stiffness", stiffness)?;
        require_non_negative("specimen.damping", damping)?;
        match mass {
            None => Self::build(
                "linear_sdof",
                1,
                dmatrix![0.0],
                dmatrix![damping],
                dmatrix![stiffness],
                DVector::zeros(1),
            ),
            Some(m) => {
                require_positive("specimen.mass", m)?;
                Self::build(
                    "linear_sdof",
                    1,
                    dmatrix![0.0, 0.0; 0.0, m],
                    dmatrix![damping, -damping; -damping, damping],
                    dmatrix![stiffness, -stiffness; -stiffness, stiffness],
                    DVector::from_element(2, 1.0),
                )
            }
        }
    }

    /// General linear specimen from matrices over `[c; s]` (the first `n_coupling` DOFs are
    /// attached). `influence` is `ι` for all DOFs (only the internal part is used).
    pub fn from_matrices(
        n_coupling: usize,
        mass: DMatrix<f64>,
        damping: DMatrix<f64>,
        stiffness: DMatrix<f64>,
        influence: Option<DVector<f64>>,
    ) -> Result<Self> {
        let n = stiffness.nrows();
        let influence = influence.unwrap_or_else(|| DVector::from_element(n, 1.0));
        Self::build("linear_mdof", n_coupling, mass, damping, stiffness, influence)
    }

    // NaN-safe checks: `!(x > 0.0)` also refuses NaN, which `x <= 0.0` would let through.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    fn build(
        kind: &'static str,
        n_c: usize,
        mass: DMatrix<f64>,
        damping: DMatrix<f64>,
        stiffness: DMatrix<f64>,
        influence: DVector<f64>,
    ) -> Result<Self> {
        let n = stiffness.nrows();
        for (name, m) in [
            ("specimen.mass", &mass),
            ("specimen.damping", &damping),
            ("specimen.stiffness", &stiffness),
        ] {
            if m.nrows() != n || m.ncols() != n {
                return Err(Error::invalid(
                    name,
                    format!("must be {n}x{n}, got {}x{}", m.nrows(), m.ncols()),
                ));
            }
            if m.iter().any(|x| !x.is_finite()) {
                return Err(Error::invalid(name, "contains a non-finite value"));
            }
            // The monolithic reference assembles these into symmetric model matrices.
            let scale = m.amax().max(f64::MIN_POSITIVE);
            for j in 0..n {
                for i in (j + 1)..n {
                    if (m[(i, j)] - m[(j, i)]).abs() > 1e-9 * scale {
                        return Err(Error::invalid(
                            name,
                            format!(
                                "is not symmetric: entry ({}, {}) = {:e} but ({}, {}) = {:e}",
                                i + 1,
                                j + 1,
                                m[(i, j)],
                                j + 1,
                                i + 1,
                                m[(j, i)]
                            ),
                        ));
                    }
                }
            }
        }
        if n_c == 0 || n_c > n {
            return Err(Error::invalid(
                "specimen.dofs",
                format!("{n_c} attached DOFs for a {n}-DOF specimen"),
            ));
        }
        if influence.len() != n {
            return Err(Error::invalid("specimen.influence", format!("must have {n} entries")));
        }
        let n_s = n - n_c;
        if mass.view((0, 0), (n_c, n)).iter().any(|&x| x != 0.0) {
            return Err(Error::invalid(
                "specimen.mass",
                "has mass on an attached (coupling) DOF; put that mass into the numerical model",
            ));
        }
        let part = |m: &DMatrix<f64>, r: usize, c: usize, nr: usize, nc: usize| m.view((r, c), (nr, nc)).into_owned();
        let m_ss = part(&mass, n_c, n_c, n_s, n_s);
        let (mut a, mut b, mut d) = (
            DMatrix::zeros(2 * n_s, 2 * n_s),
            DMatrix::zeros(2 * n_s, n_c + 1),
            DMatrix::zeros(2 * n_s, n_c + 1),
        );
        if n_s > 0 {
            let minv = m_ss
                .clone()
                .cholesky()
                .ok_or_else(|| Error::invalid("specimen.mass", "internal mass matrix is not positive definite"))?
                .inverse();
            a.view_mut((0, n_s), (n_s, n_s)).fill_with_identity();
            a.view_mut((n_s, 0), (n_s, n_s))
                .copy_from(&(-&minv * part(&stiffness, n_c, n_c, n_s, n_s)));
            a.view_mut((n_s, n_s), (n_s, n_s))
                .copy_from(&(-&minv * part(&damping, n_c, n_c, n_s, n_s)));
            b.view_mut((n_s, 0), (n_s, n_c))
                .copy_from(&(-&minv * part(&stiffness, n_c, 0, n_s, n_c)));
            let iota_s = influence.rows(n_c, n_s).into_owned();
            b.view_mut((n_s, n_c), (n_s, 1)).copy_from(&(-&minv * (&m_ss * iota_s)));
            d.view_mut((n_s, 0), (n_s, n_c))
                .copy_from(&(-&minv * part(&damping, n_c, 0, n_s, n_c)));
            // Eigenvalues and exponentials of entries near the f64 range are meaningless.
            let a_norm = crate::linalg::one_norm(&a);
            if !(a_norm <= 1e100) {
                return Err(Error::invalid(
                    "specimen",
                    format!(
                        "its internal dynamics (M⁻¹K, M⁻¹C of the internal DOFs) reach {a_norm:.3e}, outside what \
                         f64 can integrate (at most 1e100): check the units of mass, stiffness and damping"
                    ),
                ));
            }
            // An unstable specimen model is almost certainly a typo in its matrices.
            let eig = crate::linalg::eigenvalues(&a)
                .ok_or_else(|| Error::numerical("specimen", "eigenvalues of the internal dynamics did not converge"))?;
            if eig.iter().any(|l| l.re > 1e-9 * a.amax().max(1.0)) {
                return Err(Error::invalid(
                    "specimen",
                    "internal dynamics are unstable (negative stiffness or damping?)",
                ));
            }
        }
        Ok(Self {
            kind,
            n_c,
            n_s,
            k_cc: part(&stiffness, 0, 0, n_c, n_c),
            k_cs: part(&stiffness, 0, n_c, n_c, n_s),
            c_cc: part(&damping, 0, 0, n_c, n_c),
            c_cs: part(&damping, 0, n_c, n_c, n_s),
            a,
            b,
            d,
            map: None,
            z: DVector::zeros(2 * n_s),
            z_trial: DVector::zeros(2 * n_s),
            w_start: DVector::zeros(n_c + 1),
            w_end: DVector::zeros(n_c + 1),
            dw: DVector::zeros(n_c + 1),
        })
    }

    fn map_for(&mut self, dt: f64) -> &FohMap {
        let stale = match &self.map {
            Some((h, _)) => (h - dt).abs() > 1e-12 * dt,
            None => true,
        };
        if stale {
            // Allocates; happens once per run (or when the real-time runner re-spaces sub-steps).
            let map = FohMap::with_rate(&self.a, &self.b, &self.d, dt)
                .unwrap_or_else(|_| FohMap::not_a_number(self.a.nrows(), self.b.ncols()));
            self.map = Some((dt, map));
        }
        &self.map.as_ref().expect("map was just set").1
    }
}

impl Specimen for LinearSpecimen {
    fn kind(&self) -> &'static str {
        self.kind
    }
    fn n_dofs(&self) -> usize {
        self.n_c
    }
    fn advance(&mut self, m: &Motion, force: &mut [f64]) {
        let n_c = self.n_c;
        for i in 0..n_c {
            self.w_start[i] = m.d_start[i];
            self.w_end[i] = m.d_end[i];
        }
        self.w_start[n_c] = m.ag_start;
        self.w_end[n_c] = m.ag_end;
        if self.n_s > 0 {
            self.map_for(m.dt);
            let map = &self.map.as_ref().expect("map set above").1;
            map.apply(&self.z, &self.w_start, &self.w_end, &mut self.dw, &mut self.z_trial);
        }
        let n_s = self.n_s;
        for (i, f) in force.iter_mut().enumerate().take(n_c) {
            let mut acc = 0.0;
            for j in 0..n_c {
                acc += self.k_cc[(i, j)] * m.d_end[j] + self.c_cc[(i, j)] * (m.d_end[j] - m.d_start[j]) / m.dt;
            }
            for j in 0..n_s {
                acc += self.k_cs[(i, j)] * self.z_trial[j] + self.c_cs[(i, j)] * self.z_trial[n_s + j];
            }
            *f = -acc;
        }
    }
    fn commit(&mut self) {
        self.z.copy_from(&self.z_trial);
    }
    fn is_linear(&self) -> bool {
        true
    }
    fn state_len(&self) -> usize {
        2 * self.n_s
    }
    fn write_state(&self, out: &mut [f64]) {
        out.copy_from_slice(self.z.as_slice());
    }
    fn read_state(&mut self, state: &[f64]) {
        self.z.copy_from_slice(state);
        self.z_trial.copy_from_slice(state);
    }
}
