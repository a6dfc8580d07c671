//! The monolithic model of a numerical substructure plus linear specimens, for either storage.

use super::spec::SpecimenScatter;
use super::{SpecimenSpec, assemble_monolithic};
use crate::error::Result;
use crate::model::{Model, SparseModel};
use crate::sparse::CscMatrix;
use nalgebra::DVector;

/// [`assemble_monolithic`] for a model of either storage: a dense model stays dense; a sparse
/// model is assembled sparse (same DOF numbering: internal specimen DOFs appended in specimen
/// order), without any `n × n` array.
pub fn assemble_monolithic_model(model: &Model, specimens: &[SpecimenSpec]) -> Result<Model> {
    match model {
        Model::Dense(m) => Ok(Model::Dense(assemble_monolithic(m, specimens)?)),
        Model::Sparse(m) => Ok(Model::Sparse(assemble_monolithic_sparse(m, specimens)?)),
    }
}

/// The sparse counterpart of [`assemble_monolithic`].
pub fn assemble_monolithic_sparse(model: &SparseModel, specimens: &[SpecimenSpec]) -> Result<SparseModel> {
    let n = model.n_dofs();
    let scatter = SpecimenScatter::new(n, specimens)?;
    let total = scatter.total;
    let mut iota = DVector::zeros(total);
    iota.rows_mut(0, n).copy_from(&model.influence);
    for &(i, v) in &scatter.influence {
        iota[i] = v;
    }
    let triplets = |pick: fn(&(usize, usize, f64, f64, f64)) -> f64| -> Vec<(usize, usize, f64)> {
        scatter.entries.iter().map(|e| (e.0, e.1, pick(e))).collect()
    };
    let (tm, tc, tk) = (triplets(|e| e.2), triplets(|e| e.3), triplets(|e| e.4));
    let add = |a: &CscMatrix, t: &[(usize, usize, f64)]| {
        CscMatrix::linear_combination(&[(1.0, &a.grown(total)), (1.0, &CscMatrix::from_triplets(total, t))])
    };
    SparseModel::new(
        add(&model.mass, &tm),
        add(&model.damping, &tc),
        add(&model.stiffness, &tk),
        Some(iota),
    )
}
