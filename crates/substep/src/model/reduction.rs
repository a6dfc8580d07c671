//! Craig–Bampton reduction of a large linear numerical substructure (`[structure.reduction]`,
//! theory §12).
//!
//! The DOFs split into the kept set `B` (the coupling DOFs and any DOF the user wants to see,
//! e.g. the roof) and the interior `I`. The displacement is approximated in the basis
//!
//! ```text
//!        ⎡ I            0     0 ⎤ ⎡ u_B ⎤
//!   u ≈  ⎣ −K_II⁻¹ K_IB  Φ_I   r ⎦ ⎢  η  ⎥ = T q,
//!                                  ⎣  ρ  ⎦
//! ```
//!
//! * the constraint modes `Ψ = −K_II⁻¹ K_IB`: the static shape of a unit motion of one kept DOF
//!   with the others held; they keep `u_B` physical, so the sub-step controller, the specimens,
//!   the actuators and the lab see the reduced model's first `|B|` DOFs as the structure's own;
//! * `N` fixed-interface modes `K_II φ = ω² M_II φ` (mass-normalised, lowest first), found by
//!   shift-invert block Lanczos on the sparse factor of `K_II` ([`ModeSolver`]), whose factor
//!   also gives `Ψ` and `r`;
//! * the static correction `r = K_II⁻¹ (M ι)_I`: the interior's static response to the ground
//!   load with `B` held, so the static response to the earthquake load is exact whatever `N`
//!   (as it is for loads at `B` through `Ψ`); stored `M`-orthogonal to the test's `N` modes,
//!   dropped when they span it.
//!
//! `method = "ritz"` replaces `Φ_I` and `r` by `N` **load-dependent Ritz vectors** (Wilson, Yuan
//! & Dickens 1982) of the same fixed-interface problem: the `M_II`-orthonormal block Krylov basis
//! of `K_II⁻¹ M_II` started from the static responses to the loads the interior feels,
//! `K_II⁻¹ [(M ι)_I, M_IB + M_II Ψ]` (the ground load and the inertia of each constraint mode),
//! built by the same Lanczos iteration ([`ModeSolver::krylov_basis`]). Its first vector is `r`,
//! so the static response stays exact; the rest follow the load's dynamic response instead of
//! every mode in a frequency band. A 3-D frame has many modes the ground motion hardly excites
//! (axial modes of the column lines, local floor modes); on a 6 030-DOF frame with rigid floors
//! 24 Ritz vectors give a coupling error of 2·10⁻⁵ where 100 fixed-interface modes give 8·10⁻³.
//! The estimate's basis is the first `2N` vectors (the bases are nested).
//!
//! The reduced matrices are `M_r = Tᵀ M T`, `C_r = Tᵀ C T`, `K_r = Tᵀ K T` (Rayleigh damping
//! `a M + b K` stays `a M_r + b K_r`), the load `Tᵀ M ι a_g` is kept exactly by the influence
//! `ι_r = M_r⁻¹ Tᵀ M ι`. Craig–Bampton: more modes than asked are computed (every mode up to twice the first
//! dropped frequency, at most the interior's massive DOFs): the nested basis with all of them
//! gives the error estimate of the truncation (`run::reduction`).

use super::{ModeSolver, Model, StructuralModel, sparse_modes};
use crate::error::{Error, Result};
use crate::sparse::CscMatrix;
use nalgebra::{DMatrix, DVector};

/// How many fixed-interface modes a reduction keeps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ModeCount {
    /// Exactly this many.
    Modes(usize),
    /// Every mode up to this frequency \[Hz\] (at least one).
    FrequencyMax(f64),
}

/// The estimate's basis reaches this multiple of the first dropped frequency.
pub const ENRICHMENT: f64 = 2.0;

/// The static correction is kept when its part outside the test's modes exceeds this fraction.
pub const RESIDUAL_TOLERANCE: f64 = 1e-6;

/// A basis with more modes than the test's drops the static correction when they span all but
/// this fraction of it.
pub const RESIDUAL_DROP: f64 = 1e-3;

/// The largest number of fixed-interface modes a reduction computes.
pub const MAX_MODES: usize = 1000;

/// How the interior is represented.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReductionMethod {
    /// The lowest fixed-interface modes and the static correction of the ground load.
    CraigBampton,
    /// Load-dependent Ritz vectors of the fixed-interface problem: a block Krylov basis
    /// started from the static responses to the ground load and to the constraint modes'
    /// inertia (module docs).
    Ritz,
}

impl ReductionMethod {
    pub fn name(self) -> &'static str {
        match self {
            Self::CraigBampton => "craig_bampton",
            Self::Ritz => "ritz",
        }
    }
}

/// What to reduce to: the method, the modes (Ritz vectors) and the kept DOFs (0-based,
/// strictly increasing).
#[derive(Debug, Clone, PartialEq)]
pub struct ReductionSpec {
    pub method: ReductionMethod,
    pub modes: ModeCount,
    pub kept: Vec<usize>,
}

/// A computed Craig–Bampton basis: the reduced matrices of the largest nested basis (kept DOFs,
/// then [`computed_modes`](Self::computed_modes) modes, then the static correction), from which
/// [`model`](Self::model) takes the one with fewer modes.
#[derive(Debug, Clone)]
pub struct Reduction {
    /// DOFs of the full model.
    pub n_full: usize,
    /// The kept DOFs of the full model (0-based, ascending); DOF `k` of the reduced model is
    /// `kept[k]` for `k < kept.len()`.
    pub kept: Vec<usize>,
    pub method: ReductionMethod,
    /// The number of modes (Ritz vectors) the reduced model of the test keeps (`N`).
    pub modes: usize,
    /// Modes (Ritz vectors) computed, `≥ modes` (the extra ones serve the error estimate).
    computed: usize,
    /// Craig–Bampton: natural frequencies \[Hz\] of the computed fixed-interface modes (Ritz:
    /// empty).
    pub frequencies_hz: Vec<f64>,
    /// The highest frequency \[Hz\] the test's basis and the estimate's basis resolve (the
    /// highest kept mode; for Ritz vectors the largest Ritz value).
    pub basis_top_hz: [f64; 2],
    /// The test's basis ends with the static correction of the ground load (its `N` modes do
    /// not span it).
    pub residual: bool,
    /// For `p = N … computed_modes()` modes: the `M`-norm of the static correction's part that
    /// modes `N+1 … p` leave unspanned (1 at `p = N`); a larger basis drops it when that is
    /// below [`RESIDUAL_DROP`] (it would make the mass matrix near-singular).
    residual_span: Vec<f64>,
    /// The estimate's basis stopped short of [`ENRICHMENT`] times the first dropped frequency
    /// (the cap on modes), so the estimate is a guess.
    pub enrichment_cut_short: bool,
    mass: DMatrix<f64>,
    damping: DMatrix<f64>,
    stiffness: DMatrix<f64>,
    /// `Tᵀ M ι`.
    load: DVector<f64>,
}

impl Reduction {
    /// Reduce `model` (linear, `K` positive definite with the kept DOFs held) by `spec`.
    /// `max_bytes` bounds the dense basis (`n × (|B| + 2N + 1)` values), checked before it is
    /// allocated. Errors name `structure.reduction.*`.
    pub fn compute(model: &Model, spec: &ReductionSpec, max_bytes: f64) -> Result<Self> {
        let n = model.n_dofs();
        let kept = &spec.kept;
        if let Some(w) = kept.windows(2).find(|w| w[0] >= w[1]) {
            return Err(Error::invalid(
                "structure.reduction.keep",
                format!("DOF {} is given twice", w[1] + 1),
            ));
        }
        if let Some(&d) = kept.iter().find(|&&d| d >= n) {
            return Err(Error::invalid(
                "structure.reduction.keep",
                format!("DOF {} is out of range (the model has DOFs 1..={n})", d + 1),
            ));
        }
        let (mass, damping, stiffness) = match model {
            Model::Sparse(m) => (m.mass.clone(), m.damping.clone(), m.stiffness.clone()),
            Model::Dense(m) => (
                CscMatrix::from_dense(&m.mass),
                CscMatrix::from_dense(&m.damping),
                CscMatrix::from_dense(&m.stiffness),
            ),
        };
        let mass_diagonal = mass.diagonal();
        if let Some(&d) = kept.iter().find(|&&d| mass_diagonal[d] <= 0.0) {
            return Err(Error::invalid(
                "structure.reduction",
                format!(
                    "kept DOF {} has no mass: the reduced model cannot represent a massless coupling or \
                     kept DOF (keep translational DOFs with mass)",
                    d + 1
                ),
            ));
        }
        let mut is_kept = vec![false; n];
        for &d in kept {
            is_kept[d] = true;
        }
        let interior: Vec<usize> = (0..n).filter(|&i| !is_kept[i]).collect();
        let n_i = interior.len();
        if n_i == 0 {
            return Err(Error::invalid(
                "structure.reduction",
                format!("keeps all {n} DOFs: there is nothing to reduce"),
            ));
        }
        let k_ii = stiffness.principal(&interior);
        let m_ii = mass.principal(&interior);
        // DOFs of the interior that carry mass bound the number of finite frequencies.
        let massive = if m_ii.is_diagonal() {
            m_ii.diagonal().iter().filter(|&&d| d > 0.0).count()
        } else {
            n_i
        };
        match spec.modes {
            ModeCount::Modes(0) => {
                return Err(Error::invalid("structure.reduction.modes", "must be at least 1"));
            }
            ModeCount::Modes(m) if m > massive || m > MAX_MODES => {
                return Err(Error::invalid(
                    "structure.reduction.modes",
                    format!(
                        "{m} modes asked, but the model has {} (its {n} DOFs less the {} kept, {} of them \
                         with mass; at most {MAX_MODES} here)",
                        massive.min(MAX_MODES),
                        kept.len(),
                        massive
                    ),
                ));
            }
            ModeCount::Modes(_) => {}
            ModeCount::FrequencyMax(f) if !(f.is_finite() && f > 0.0) => {
                return Err(Error::invalid(
                    "structure.reduction.frequency_max",
                    format!("must be a positive frequency in Hz, got {f}"),
                ));
            }
            ModeCount::FrequencyMax(_) => {} // the count is found below
        }
        let cap = massive.min(MAX_MODES);
        if let (ReductionMethod::Ritz, ModeCount::FrequencyMax(_)) = (spec.method, spec.modes) {
            return Err(Error::invalid(
                "structure.reduction.frequency_max",
                "method ritz takes modes (the number of Ritz vectors), not a frequency",
            ));
        }
        // Memory of the largest basis: the Lanczos vectors, then T and A T side by side.
        let check_basis = |modes: usize| -> Result<()> {
            let vectors = sparse_modes::max_vectors(modes).min(n_i) + 2 * (kept.len() + modes + 1);
            let bytes = 8.0 * n as f64 * vectors as f64;
            if bytes > max_bytes {
                return Err(Error::invalid(
                    "structure.reduction",
                    format!(
                        "a basis of {modes} modes for {n} DOFs needs {:.3} GB, more than [limits] max_memory \
                         ({:.3} GB): ask for fewer modes",
                        bytes / 1e9,
                        max_bytes / 1e9
                    ),
                ));
            }
            Ok(())
        };
        let what = "structure.reduction (the structure with its kept DOFs held)";
        let eigen_error = |count: usize| {
            move |e: Error| match e {
                Error::Numerical { reason, .. } => Error::invalid(
                    "structure.reduction",
                    format!("the eigen-solve for {count} fixed-interface modes failed: {reason}"),
                ),
                other => other,
            }
        };
        let mut solver = ModeSolver::new(&m_ii, &k_ii, what)?;
        let mut interior_index = vec![usize::MAX; n];
        for (k, &i) in interior.iter().enumerate() {
            interior_index[i] = k;
        }
        // Column `b` of a full matrix restricted to the interior rows.
        let interior_column = |a: &CscMatrix, b: usize| {
            let mut column = vec![0.0; n_i];
            let (rows, vals) = a.col(b);
            for (&r, &v) in rows.iter().zip(vals) {
                if interior_index[r] != usize::MAX {
                    column[interior_index[r]] = v;
                }
            }
            column
        };
        // Constraint modes Ψ = −K_II⁻¹ K_IB.
        let nb = kept.len();
        let mut psi = DMatrix::<f64>::zeros(n_i, nb);
        for (c, &b) in kept.iter().enumerate() {
            let mut rhs = interior_column(&stiffness, b);
            rhs.iter_mut().for_each(|x| *x = -*x);
            solver.factor_mut().solve_in_place(&mut rhs);
            psi.column_mut(c).copy_from_slice(&rhs);
        }
        let ground = model.effective_mass_vector();
        let ground_interior: Vec<f64> = interior.iter().map(|&i| ground[i]).collect();

        // The interior basis (n_i × m): the test's first `modes` columns, then the estimate's.
        let (modes, basis, frequencies_hz, enrichment_cut_short) = match spec.method {
            ReductionMethod::CraigBampton => {
                let mut solve = |count: usize| -> Result<super::SparseModes> {
                    check_basis(count)?;
                    solver.lowest(count).map_err(eigen_error(count))
                };
                // The modes of the test and as many again for the error estimate.
                let (modes, mut found) = match spec.modes {
                    ModeCount::Modes(m) => (m, solve((2 * m).min(cap))?),
                    ModeCount::FrequencyMax(f) => {
                        let omega_max = 2.0 * std::f64::consts::PI * f;
                        let mut count = 8.min(cap);
                        loop {
                            let found = solve(count)?;
                            let below = found.omega.iter().filter(|&&w| w <= omega_max).count().max(1);
                            if count == MAX_MODES && below == count {
                                return Err(Error::invalid(
                                    "structure.reduction.frequency_max",
                                    format!("{f} Hz takes more than {MAX_MODES} modes: lower it or give modes"),
                                ));
                            }
                            if 2 * below <= count || count == cap {
                                break (below, found);
                            }
                            count = (2 * count).max(2 * below).min(cap);
                        }
                    }
                };
                // Enrich the estimate's basis up to twice the first dropped frequency.
                let mut count = found.omega.len();
                while count < cap
                    && found.omega.len() > modes
                    && found.omega[count - 1] < ENRICHMENT * found.omega[modes]
                {
                    count = (2 * count).min(cap);
                    found = solve(count)?;
                }
                let m = found.omega.len();
                let cut_short = m > modes && m < massive && found.omega[m - 1] < ENRICHMENT * found.omega[modes];
                let hz = found.omega.iter().map(|w| w / (2.0 * std::f64::consts::PI)).collect();
                (modes, found.shapes, hz, cut_short)
            }
            ReductionMethod::Ritz => {
                let ModeCount::Modes(modes) = spec.modes else {
                    unreachable!("refused above")
                };
                let count = (2 * modes).min(cap);
                check_basis(count)?;
                // The loads on the interior with the kept DOFs held: the ground load and the
                // inertia of each constraint mode, (M_IB + M_II Ψ) ü_B.
                let mut loads = vec![ground_interior.clone()];
                let mut inertia = vec![0.0; n_i];
                for (c, &b) in kept.iter().enumerate() {
                    let mut load = interior_column(&mass, b);
                    m_ii.sym_mul_add(1.0, psi.column(c).as_slice(), 0.0, &mut inertia);
                    load.iter_mut().zip(&inertia).for_each(|(l, i)| *l += i);
                    loads.push(load);
                }
                solver.start_with(&loads);
                let basis = solver.krylov_basis(count).map_err(eigen_error(count))?;
                (modes, basis, Vec::new(), false)
            }
        };
        let m = basis.ncols();

        // The basis T, n × (|B| + m + 1).
        let cols = nb + m + 1;
        let mut t = DMatrix::<f64>::zeros(n, cols);
        for (c, &b) in kept.iter().enumerate() {
            for (k, &i) in interior.iter().enumerate() {
                t[(i, c)] = psi[(k, c)];
            }
            t[(b, c)] = 1.0;
        }
        for j in 0..m {
            for (k, &i) in interior.iter().enumerate() {
                t[(i, nb + j)] = basis[(k, j)];
            }
        }
        // The test's static correction is what of r = K_II⁻¹ (M ι)_I its own N modes do not
        // span (the modes past N serve the estimate only), M-orthogonalised against those N.
        // Ritz vectors start with r: none needed.
        let mut residual_span = Vec::new();
        let residual = spec.method == ReductionMethod::CraigBampton && {
            let mut rhs = ground_interior;
            solver.factor_mut().solve_in_place(&mut rhs);
            let mut r = DVector::from_vec(rhs);
            let mut mv = vec![0.0; n_i];
            let mut m_dot = |a: &DVector<f64>, b: &DVector<f64>| {
                m_ii.sym_mul_add(1.0, b.as_slice(), 0.0, &mut mv);
                a.iter().zip(&mv).map(|(x, y)| x * y).sum::<f64>()
            };
            let norm = m_dot(&r, &r).max(0.0).sqrt();
            for _ in 0..2 {
                for j in 0..modes {
                    let phi = basis.column(j).into_owned();
                    let c = m_dot(&phi, &r);
                    r.axpy(-c, &phi, 1.0);
                }
            }
            let left = m_dot(&r, &r).max(0.0).sqrt();
            if norm > 0.0 && left > RESIDUAL_TOLERANCE * norm {
                r /= left;
                // How much of it the estimate's extra modes leave unspanned, mode by mode.
                let mut unspanned = 1.0_f64;
                residual_span.push(unspanned);
                for j in modes..m {
                    let phi = basis.column(j).into_owned();
                    let c = m_dot(&phi, &r);
                    unspanned = (unspanned * unspanned - c * c).max(0.0).sqrt();
                    residual_span.push(unspanned);
                }
                for (k, &i) in interior.iter().enumerate() {
                    t[(i, nb + m)] = r[k];
                }
                true
            } else {
                false
            }
        };
        drop(solver);
        let t = if residual {
            t
        } else {
            t.columns(0, cols - 1).into_owned()
        };
        let project = |a: &CscMatrix| -> DMatrix<f64> {
            let mut at = DMatrix::<f64>::zeros(n, t.ncols());
            for j in 0..t.ncols() {
                a.sym_mul_add(1.0, t.column(j).as_slice(), 0.0, at.column_mut(j).as_mut_slice());
            }
            let p = t.transpose() * at;
            (&p + p.transpose()) * 0.5
        };
        let stiffness = project(&stiffness);
        // The highest frequency each basis resolves: its largest Ritz value (the interior
        // block of K_r, whose vectors are M-orthonormal).
        let top_hz = |p: usize| -> f64 {
            if spec.method == ReductionMethod::CraigBampton {
                return frequencies_hz.get(p.max(1) - 1).copied().unwrap_or(f64::NAN);
            }
            let block = stiffness.view((nb, nb), (p, p)).into_owned();
            let top = block.symmetric_eigenvalues().max();
            top.max(0.0).sqrt() / (2.0 * std::f64::consts::PI)
        };
        let basis_top_hz = [top_hz(modes), top_hz(m)];
        Ok(Self {
            n_full: n,
            kept: kept.clone(),
            method: spec.method,
            modes,
            computed: m,
            frequencies_hz,
            basis_top_hz,
            residual,
            residual_span,
            enrichment_cut_short,
            mass: project(&mass),
            damping: project(&damping),
            stiffness,
            load: t.transpose() * ground,
        })
    }

    /// Modes (or Ritz vectors) computed (`≥` [`Self::modes`]).
    pub fn computed_modes(&self) -> usize {
        self.computed
    }

    /// DOFs of the reduced model with `modes` modes.
    pub fn size(&self, modes: usize) -> usize {
        self.kept.len() + modes + usize::from(self.has_residual(modes))
    }

    /// The basis with `modes` modes ends with the static correction.
    fn has_residual(&self, modes: usize) -> bool {
        self.residual
            && modes >= self.modes
            && self
                .residual_span
                .get(modes - self.modes)
                .is_some_and(|&left| left > RESIDUAL_DROP)
    }

    /// The reduced model with the first `modes ≤ computed_modes()` modes (the test's is
    /// `model(self.modes)`).
    pub fn model(&self, modes: usize) -> Result<StructuralModel> {
        assert!(
            modes <= self.computed_modes(),
            "reduction: {modes} modes of {}",
            self.computed_modes()
        );
        let nb = self.kept.len();
        let mut index: Vec<usize> = (0..nb + modes).collect();
        if self.has_residual(modes) {
            index.push(nb + self.computed_modes());
        }
        let pick = |a: &DMatrix<f64>| DMatrix::from_fn(index.len(), index.len(), |i, j| a[(index[i], index[j])]);
        let mass = pick(&self.mass);
        let load = DVector::from_iterator(index.len(), index.iter().map(|&i| self.load[i]));
        let influence = mass.clone().cholesky().map(|c| c.solve(&load)).ok_or_else(|| {
            Error::invalid(
                "structure.reduction",
                "the reduced mass matrix is not positive definite (a kept DOF without mass?)",
            )
        })?;
        StructuralModel::new(mass, pick(&self.damping), pick(&self.stiffness), Some(influence))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{ShearBuilding, shear_building_sparse};

    #[test]
    fn keeping_all_modes_reproduces_the_full_frequencies() {
        // With every interior mode in the basis the reduction is a change of basis: the reduced
        // model's frequencies are the full model's.
        let full = shear_building_sparse(&ShearBuilding {
            stories: 8,
            story_mass: 2.0e5,
            first_period: 0.8,
        })
        .unwrap();
        let model: Model = full.clone().into();
        let spec = ReductionSpec {
            method: ReductionMethod::CraigBampton,
            modes: ModeCount::Modes(6),
            kept: vec![2, 7],
        };
        let r = Reduction::compute(&model, &spec, 1e9).unwrap();
        assert_eq!(r.computed_modes(), 6);
        let reduced = r.model(6).unwrap();
        let exact = model.dense("test").unwrap().modes().unwrap().omega;
        let got = reduced.modes().unwrap().omega;
        assert_eq!(got.len(), 8);
        for (a, b) in got.iter().zip(exact.iter()) {
            assert!((a - b).abs() < 1e-8 * b, "{a} vs {b}");
        }
        // The kept DOFs stay physical: a static load there gives the full model's deflection.
        let k = model.dense("test").unwrap().stiffness.clone();
        let mut f = DVector::zeros(8);
        f[7] = 1.0e5;
        let u_full = k.cholesky().unwrap().solve(&f);
        let mut f_r = DVector::zeros(reduced.n_dofs());
        f_r[1] = 1.0e5;
        let u_r = reduced.stiffness.clone().cholesky().unwrap().solve(&f_r);
        assert!((u_r[0] - u_full[2]).abs() < 1e-12 * u_full[7].abs());
        assert!((u_r[1] - u_full[7]).abs() < 1e-12 * u_full[7].abs());
    }
}
