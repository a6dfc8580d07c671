//! Sparse structural models and the choice between dense and sparse storage.
//!
//! [`StructuralModel`] keeps `M`, `C`, `K` as dense `n × n` matrices (small models, the
//! analyses). [`SparseModel`] keeps them in CSC form for large numerical substructures; no
//! `n × n` array is ever formed on its path. [`Model`] holds either, and [`ModelRef`] borrows
//! either: the integrators and the sub-step controller take `impl Into<ModelRef>`, so
//! `&StructuralModel`, `&SparseModel` and `&Model` all work.

use super::lowest_frequencies;
use super::{DampingSpec, StructuralModel, rayleigh_coefficients};
use crate::error::{Error, Result, require_non_negative};
use crate::sparse::{CscMatrix, FactorKind, SymmetricFactor};
use nalgebra::DVector;
use std::borrow::Cow;

/// The largest model that dense-only features (modal analysis, modal damping, the exact
/// reference, the amplification-matrix analyses) convert from sparse storage. Above it they
/// refuse with a message instead of allocating `n × n` matrices.
pub const DENSE_MAX_DOFS: usize = 3000;

/// Automatic storage picks sparse above this many DOFs (when the matrices are sparse enough).
pub const AUTO_SPARSE_MIN_DOFS: usize = 300;
/// Automatic storage picks sparse below this density `nnz / n²` of `K + M + C`.
pub const AUTO_SPARSE_MAX_DENSITY: f64 = 0.05;

/// How the model matrices are stored (`[structure] storage`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Storage {
    /// Sparse when `n > 300` and the density of `K + M + C` is below 5 %, else dense.
    #[default]
    Auto,
    Dense,
    Sparse,
}

impl Storage {
    pub fn from_name(name: &str) -> Result<Self> {
        match name {
            "auto" => Ok(Storage::Auto),
            "dense" => Ok(Storage::Dense),
            "sparse" => Ok(Storage::Sparse),
            other => Err(Error::invalid(
                "structure.storage",
                format!("unknown storage '{other}' (expected auto, dense or sparse)"),
            )),
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            Storage::Auto => "auto",
            Storage::Dense => "dense",
            Storage::Sparse => "sparse",
        }
    }
    /// Whether a model of `n` DOFs with `nnz` stored entries (pattern of `K + M + C`) is stored
    /// sparse.
    pub fn is_sparse_for(self, n: usize, nnz: usize) -> bool {
        match self {
            Storage::Dense => false,
            Storage::Sparse => true,
            Storage::Auto => {
                n > AUTO_SPARSE_MIN_DOFS && (nnz as f64) < AUTO_SPARSE_MAX_DENSITY * (n as f64) * (n as f64)
            }
        }
    }
}

/// A linear structural model with sparse (CSC) `M`, `C`, `K`.
#[derive(Debug, Clone)]
pub struct SparseModel {
    pub mass: CscMatrix,
    pub damping: CscMatrix,
    pub stiffness: CscMatrix,
    /// Influence vector `ι` of the ground acceleration (`f_l = −M ι a_g`).
    pub influence: DVector<f64>,
}

impl SparseModel {
    /// Build and validate: square matrices of one size, finite and symmetric entries, positive
    /// definite mass. `influence = None` means all ones.
    pub fn new(
        mass: CscMatrix,
        damping: CscMatrix,
        stiffness: CscMatrix,
        influence: Option<DVector<f64>>,
    ) -> Result<Self> {
        let n = mass.n();
        if n == 0 {
            return Err(Error::invalid("structure.mass", "matrix is empty"));
        }
        for (name, m) in [
            ("structure.mass", &mass),
            ("structure.damping", &damping),
            ("structure.stiffness", &stiffness),
        ] {
            if m.n() != n {
                return Err(Error::invalid(
                    name,
                    format!(
                        "is {0}x{0} but the model has {n} DOFs (the mass matrix is {n}x{n})",
                        m.n()
                    ),
                ));
            }
            m.check_symmetric(name)?;
        }
        let influence = influence.unwrap_or_else(|| DVector::from_element(n, 1.0));
        if influence.len() != n {
            return Err(Error::invalid(
                "structure.influence",
                format!("has {} entries but the model has {n} DOFs", influence.len()),
            ));
        }
        if influence.iter().any(|x| !x.is_finite()) {
            return Err(Error::invalid("structure.influence", "contains a non-finite value"));
        }
        let mass_pd = if mass.is_diagonal() {
            mass.diagonal().iter().all(|&d| d > 0.0)
        } else {
            SymmetricFactor::new(&mass, FactorKind::Auto, "structure.mass").is_ok()
        };
        if !mass_pd {
            return Err(Error::invalid("structure.mass", "is not positive definite"));
        }
        Ok(Self {
            mass,
            damping,
            stiffness,
            influence,
        })
    }

    /// The same model with sparse storage.
    pub fn from_dense(model: &StructuralModel) -> Self {
        Self {
            mass: CscMatrix::from_dense(&model.mass),
            damping: CscMatrix::from_dense(&model.damping),
            stiffness: CscMatrix::from_dense(&model.stiffness),
            influence: model.influence.clone(),
        }
    }

    /// The same model with dense storage; refused above [`DENSE_MAX_DOFS`] (`purpose` says what
    /// needed it).
    pub fn to_dense(&self, purpose: &str) -> Result<StructuralModel> {
        let n = self.n_dofs();
        if n > DENSE_MAX_DOFS {
            return Err(Error::invalid(
                "structure",
                format!(
                    "{purpose} needs dense n x n matrices, but the model has {n} DOFs in sparse storage \
                     (dense-only features are limited to {DENSE_MAX_DOFS} DOFs)"
                ),
            ));
        }
        Ok(StructuralModel {
            mass: self.mass.to_dense(),
            damping: self.damping.to_dense(),
            stiffness: self.stiffness.to_dense(),
            influence: self.influence.clone(),
        })
    }

    pub fn n_dofs(&self) -> usize {
        self.mass.n()
    }

    /// Stored entries of the pattern of `K + M + C` (the effective stiffness).
    pub fn pattern_nnz(&self) -> usize {
        CscMatrix::linear_combination(&[(1.0, &self.stiffness), (1.0, &self.mass), (1.0, &self.damping)]).nnz()
    }

    /// `M ι`.
    pub fn effective_mass_vector(&self) -> DVector<f64> {
        let mut out = DVector::zeros(self.n_dofs());
        self.mass
            .sym_mul_add(1.0, self.influence.as_slice(), 0.0, out.as_mut_slice());
        out
    }

    /// Replace the damping matrix: an explicit matrix, Rayleigh `α M + β K`, or Rayleigh with
    /// ratio `ζ` at two modes (the two frequencies by shift-invert Lanczos). Modal damping gives a
    /// dense `n × n` matrix and is refused here.
    pub fn with_damping(mut self, spec: &DampingSpec) -> Result<Self> {
        let n = self.n_dofs();
        self.damping = match spec {
            DampingSpec::Matrix(c) => {
                if c.nrows() != n || c.ncols() != n {
                    return Err(Error::invalid(
                        "structure.damping",
                        format!("is {}x{} but the model has {n} DOFs", c.nrows(), c.ncols()),
                    ));
                }
                CscMatrix::from_dense(c)
            }
            DampingSpec::Rayleigh { alpha, beta } => {
                require_non_negative("structure.rayleigh.alpha", *alpha)?;
                require_non_negative("structure.rayleigh.beta", *beta)?;
                CscMatrix::linear_combination(&[(*alpha, &self.mass), (*beta, &self.stiffness)])
            }
            DampingSpec::RayleighRatio { zeta, modes: (i, j) } => {
                require_non_negative("structure.rayleigh.zeta", *zeta)?;
                for (key, k) in [("first", *i), ("second", *j)] {
                    if k == 0 || k > n {
                        return Err(Error::invalid(
                            "structure.rayleigh.modes",
                            format!("{key} mode number {k} is outside 1..={n}"),
                        ));
                    }
                }
                if i == j {
                    return Err(Error::invalid("structure.rayleigh.modes", "the two modes must differ"));
                }
                let w = lowest_frequencies(&self.mass, &self.stiffness, (*i).max(*j))?;
                let (alpha, beta) = rayleigh_coefficients(*zeta, w[i - 1], w[j - 1])?;
                CscMatrix::linear_combination(&[(alpha, &self.mass), (beta, &self.stiffness)])
            }
            DampingSpec::Modal { .. } => {
                return Err(Error::invalid(
                    "structure.modal",
                    format!(
                        "modal damping makes a dense n x n damping matrix and is available with dense \
                         storage only (storage = \"dense\", up to {DENSE_MAX_DOFS} DOFs); with sparse \
                         storage use [structure.rayleigh]"
                    ),
                ));
            }
        };
        self.damping.check_symmetric("structure.damping")?;
        Ok(self)
    }
}

/// A model with either storage.
#[derive(Debug, Clone)]
pub enum Model {
    Dense(StructuralModel),
    Sparse(SparseModel),
}

impl From<StructuralModel> for Model {
    fn from(m: StructuralModel) -> Self {
        Model::Dense(m)
    }
}
impl From<SparseModel> for Model {
    fn from(m: SparseModel) -> Self {
        Model::Sparse(m)
    }
}

impl Model {
    pub fn n_dofs(&self) -> usize {
        self.as_ref().n_dofs()
    }
    /// `dense` or `sparse`.
    pub fn storage_name(&self) -> &'static str {
        self.as_ref().storage_name()
    }
    pub fn as_ref(&self) -> ModelRef<'_> {
        self.into()
    }
    pub fn is_sparse(&self) -> bool {
        matches!(self, Model::Sparse(_))
    }
    /// `M ι`.
    pub fn effective_mass_vector(&self) -> DVector<f64> {
        self.as_ref().effective_mass_vector()
    }
    pub fn influence(&self) -> &DVector<f64> {
        match self {
            Model::Dense(m) => &m.influence,
            Model::Sparse(m) => &m.influence,
        }
    }
    /// The dense model, if stored dense.
    pub fn as_dense(&self) -> Option<&StructuralModel> {
        match self {
            Model::Dense(m) => Some(m),
            Model::Sparse(_) => None,
        }
    }
    /// The sparse model, if stored sparse.
    pub fn as_sparse(&self) -> Option<&SparseModel> {
        match self {
            Model::Dense(_) => None,
            Model::Sparse(m) => Some(m),
        }
    }
    /// The dense model for a dense-only feature (`purpose` names it in the error): borrowed if
    /// stored dense, converted if sparse with at most [`DENSE_MAX_DOFS`] DOFs, refused above.
    pub fn dense(&self, purpose: &str) -> Result<Cow<'_, StructuralModel>> {
        match self {
            Model::Dense(m) => Ok(Cow::Borrowed(m)),
            Model::Sparse(m) => m.to_dense(purpose).map(Cow::Owned),
        }
    }
    /// Convert to the storage `storage` chooses for this model.
    pub fn with_storage(self, storage: Storage) -> Result<Self> {
        let n = self.n_dofs();
        match self {
            Model::Dense(m) => {
                let nnz = (0..n * n)
                    .filter(|&k| m.mass[k] != 0.0 || m.damping[k] != 0.0 || m.stiffness[k] != 0.0)
                    .count();
                if storage.is_sparse_for(n, nnz) {
                    Ok(Model::Sparse(SparseModel::from_dense(&m)))
                } else {
                    Ok(Model::Dense(m))
                }
            }
            Model::Sparse(m) => {
                if storage.is_sparse_for(n, m.pattern_nnz()) {
                    Ok(Model::Sparse(m))
                } else {
                    Ok(Model::Dense(m.to_dense("dense storage")?))
                }
            }
        }
    }
    /// Replace the damping (see [`StructuralModel::with_damping`], [`SparseModel::with_damping`]).
    pub fn with_damping(self, spec: &DampingSpec) -> Result<Self> {
        Ok(match self {
            Model::Dense(m) => Model::Dense(m.with_damping(spec)?),
            Model::Sparse(m) => Model::Sparse(m.with_damping(spec)?),
        })
    }
}

/// A borrowed model of either storage.
#[derive(Debug, Clone, Copy)]
pub enum ModelRef<'a> {
    Dense(&'a StructuralModel),
    Sparse(&'a SparseModel),
}

impl<'a> From<&'a StructuralModel> for ModelRef<'a> {
    fn from(m: &'a StructuralModel) -> Self {
        ModelRef::Dense(m)
    }
}
impl<'a> From<&'a SparseModel> for ModelRef<'a> {
    fn from(m: &'a SparseModel) -> Self {
        ModelRef::Sparse(m)
    }
}
impl<'a> From<&'a Model> for ModelRef<'a> {
    fn from(m: &'a Model) -> Self {
        match m {
            Model::Dense(d) => ModelRef::Dense(d),
            Model::Sparse(s) => ModelRef::Sparse(s),
        }
    }
}

impl ModelRef<'_> {
    pub fn n_dofs(&self) -> usize {
        match self {
            ModelRef::Dense(m) => m.n_dofs(),
            ModelRef::Sparse(m) => m.n_dofs(),
        }
    }
    pub fn storage_name(&self) -> &'static str {
        match self {
            ModelRef::Dense(_) => "dense",
            ModelRef::Sparse(_) => "sparse",
        }
    }
    /// `M ι`.
    pub fn effective_mass_vector(&self) -> DVector<f64> {
        match self {
            ModelRef::Dense(m) => m.effective_mass_vector(),
            ModelRef::Sparse(m) => m.effective_mass_vector(),
        }
    }
}
