//! Numerical substructure: linear structural models `M ü + C u̇ + K u = f_l(t) + Sᵀ f_c(t)`.
//!
//! Units are SI: mass in kg, stiffness in N/m, damping in N·s/m, displacements in m.
//! DOFs are numbered from 0 inside the library; the user-facing config and CSV files use
//! 1-based numbers.

mod builders;
mod damping;
mod frame;
mod frame3d;
mod hysteretic;
mod modal;
mod reduction;
mod sparse;
mod sparse_modes;

pub use builders::{
    ShearBuilding, TmdSystem, sdof, shear_building, shear_building_sparse, storey_building, storey_springs, tmd_two_dof,
};
pub use damping::{DampingSpec, modal_damping, rayleigh_coefficients};
pub use frame::{
    Frame2d, FrameDof, FrameHinges, HingeLocation, Section, frame_2d, frame_2d_dense, frame_2d_hinged, frame_gravity,
    frame_p_delta,
};
pub use frame3d::{Frame3d, Frame3dDof, Section3d, frame_3d};
pub use hysteretic::{Hysteresis, PDeltaSpec, SpringSpec, Springs};
pub use modal::{Modes, modes};
pub use reduction::{
    ENRICHMENT as REDUCTION_ENRICHMENT, MAX_MODES, ModeCount, Reduction, ReductionMethod, ReductionSpec,
};
pub use sparse::{
    AUTO_SPARSE_MAX_DENSITY, AUTO_SPARSE_MIN_DOFS, DENSE_MAX_DOFS, Model, ModelRef, SparseModel, Storage,
};
pub use sparse_modes::{ModeSolver, SparseModes, lowest_frequencies, lowest_modes};

use crate::error::{Error, Result};
use nalgebra::{DMatrix, DVector};

/// A linear structural model (the numerical substructure).
#[derive(Debug, Clone)]
pub struct StructuralModel {
    pub mass: DMatrix<f64>,
    pub damping: DMatrix<f64>,
    pub stiffness: DMatrix<f64>,
    /// Influence vector `ι` of the ground acceleration (`f_l = −M ι a_g`).
    pub influence: DVector<f64>,
}

impl StructuralModel {
    /// Build and validate a model: square matrices of one size, finite and symmetric entries,
    /// positive definite mass. `influence = None` means all ones (shear model).
    pub fn new(
        mass: DMatrix<f64>,
        damping: DMatrix<f64>,
        stiffness: DMatrix<f64>,
        influence: Option<DVector<f64>>,
    ) -> Result<Self> {
        let model = Self::checked(mass, damping, stiffness, influence)?;
        if model.mass.clone().cholesky().is_none() {
            return Err(Error::invalid("structure.mass", "is not positive definite"));
        }
        Ok(model)
    }

    /// Like [`Self::new`], for a finite-element model whose mass matrix is singular (massless
    /// rotational DOFs): the mass need only have a non-negative diagonal, and `K + M` be positive
    /// definite (so the Newmark effective stiffness is regular and the massless DOFs follow
    /// statically). Such a model starts at rest with zero load.
    pub fn with_massless_dofs(
        mass: DMatrix<f64>,
        damping: DMatrix<f64>,
        stiffness: DMatrix<f64>,
        influence: Option<DVector<f64>>,
    ) -> Result<Self> {
        let model = Self::checked(mass, damping, stiffness, influence)?;
        if model.mass.diagonal().iter().any(|&d| d < 0.0) {
            return Err(Error::invalid("structure.mass", "has a negative diagonal entry"));
        }
        if (&model.stiffness + &model.mass).cholesky().is_none() {
            return Err(Error::invalid(
                "structure",
                "K + M is not positive definite: a DOF has neither mass nor stiffness",
            ));
        }
        Ok(model)
    }

    /// The checks both constructors share: square matrices of one size, finite and symmetric
    /// entries, an influence vector of the model's size.
    fn checked(
        mass: DMatrix<f64>,
        damping: DMatrix<f64>,
        stiffness: DMatrix<f64>,
        influence: Option<DVector<f64>>,
    ) -> Result<Self> {
        let n = mass.nrows();
        if n == 0 {
            return Err(Error::invalid("structure.mass", "matrix is empty"));
        }
        for (name, m) in [
            ("structure.mass", &mass),
            ("structure.damping", &damping),
            ("structure.stiffness", &stiffness),
        ] {
            check_square_symmetric(name, m, n)?;
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
        Ok(Self {
            mass,
            damping,
            stiffness,
            influence,
        })
    }

    pub fn n_dofs(&self) -> usize {
        self.mass.nrows()
    }

    /// `M ι`, the load vector per unit ground acceleration (with opposite sign).
    pub fn effective_mass_vector(&self) -> DVector<f64> {
        &self.mass * &self.influence
    }

    /// Replace the damping matrix by one built from `spec` (Rayleigh, modal or explicit).
    pub fn with_damping(mut self, spec: &DampingSpec) -> Result<Self> {
        self.damping = spec.build(&self.mass, &self.stiffness)?;
        check_square_symmetric("structure.damping", &self.damping, self.n_dofs())?;
        Ok(self)
    }

    /// Natural frequencies and mass-normalised mode shapes.
    pub fn modes(&self) -> Result<Modes> {
        modes(&self.mass, &self.stiffness)
    }
}

fn check_square_symmetric(name: &str, m: &DMatrix<f64>, n: usize) -> Result<()> {
    if m.nrows() != n || m.ncols() != n {
        return Err(Error::invalid(
            name,
            format!(
                "is {}x{} but the model has {n} DOFs (the mass matrix is {n}x{n})",
                m.nrows(),
                m.ncols()
            ),
        ));
    }
    if let Some(pos) = m.iter().position(|x| !x.is_finite()) {
        return Err(Error::invalid(
            name,
            format!("entry ({}, {}) is not finite", pos % n + 1, pos / n + 1),
        ));
    }
    let scale = m.amax().max(f64::MIN_POSITIVE);
    for j in 0..n {
        for i in (j + 1)..n {
            if (m[(i, j)] - m[(j, i)]).abs() > 1e-9 * scale {
                return Err(Error::invalid(
                    name,
                    format!(
                        "is not symmetric: entry ({}, {}) = {} but ({}, {}) = {}",
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
    Ok(())
}
