//! The monolithic model of a numerical substructure plus linear specimens, for either storage.

use super::{SpecimenSpec, assemble_monolithic};
use crate::error::{Error, Result};
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
    let mut parts = Vec::with_capacity(specimens.len());
    for (k, s) in specimens.iter().enumerate() {
        let m = s.linear_matrices().ok_or_else(|| {
            Error::invalid(
                format!("substructure.specimen[{}]", k + 1),
                format!("the {} specimen is not linear", s.kind()),
            )
        })?;
        parts.push(m);
    }
    let total = n + parts.iter().map(|p| p.stiffness.nrows() - p.dofs.len()).sum::<usize>();
    let mut iota = DVector::zeros(total);
    iota.rows_mut(0, n).copy_from(&model.influence);
    let (mut tm, mut tc, mut tk) = (Vec::new(), Vec::new(), Vec::new());
    let mut next = n;
    for p in &parts {
        let n_a = p.dofs.len();
        let n_p = p.stiffness.nrows();
        let global: Vec<usize> = p.dofs.iter().copied().chain(next..next + n_p - n_a).collect();
        for (li, &gi) in global.iter().enumerate() {
            if li >= n_a {
                iota[gi] = p.influence[li];
            }
            for (lj, &gj) in global.iter().enumerate() {
                tm.push((gi, gj, p.mass[(li, lj)]));
                tc.push((gi, gj, p.damping[(li, lj)]));
                tk.push((gi, gj, p.stiffness[(li, lj)]));
            }
        }
        next += n_p - n_a;
    }
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
