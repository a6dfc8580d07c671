//! Specimens as described in a test definition (what a config file or a Python script gives),
//! attached to DOFs of the numerical model.

use super::{BoucWen, BoucWenParams, Friction, FrictionModel, LinearSpecimen, LumpedSdof, Replay, Specimen};
use crate::error::{Error, Result};
use crate::model::StructuralModel;
use nalgebra::{DMatrix, DVector, dmatrix};

#[derive(Debug, Clone, PartialEq)]
pub enum SpecimenSpec {
    /// TMD (mass on spring and dashpot) on model DOF `dof` (0-based); `mass = None` is a spring
    /// and dashpot to ground.
    LinearSdof {
        dof: usize,
        mass: Option<f64>,
        stiffness: f64,
        damping: f64,
    },
    /// Linear MDOF specimen: matrices over `[attached DOFs; internal DOFs]`, the first
    /// `dofs.len()` attached to model DOFs `dofs` (0-based).
    LinearMdof {
        dofs: Vec<usize>,
        mass: DMatrix<f64>,
        damping: DMatrix<f64>,
        stiffness: DMatrix<f64>,
        influence: Option<DVector<f64>>,
    },
    /// Bouc–Wen hysteretic spring to ground on model DOF `dof` (0-based); see
    /// [`BoucWenParams`] for the parameters and their defaults.
    BoucWen { dof: usize, params: BoucWenParams },
    /// Friction damper on model DOF `dof` (0-based): slip force `slip_force` \[N\], the friction
    /// law `model` (configs default to `stick_slip`), linear viscous part `damping` [N s/m].
    Friction {
        dof: usize,
        slip_force: f64,
        model: FrictionModel,
        damping: f64,
    },
    /// Replay of a measured force record on model DOF `dof` (0-based): samples `values` \[N\] of
    /// the force on the structure at `t = j dt` \[s\], independent of the motion.
    Replay { dof: usize, dt: f64, values: Vec<f64> },
    /// Mass, dashpot and spring at model DOF `dof` (0-based) itself ([`LumpedSdof`]).
    LumpedSdof {
        dof: usize,
        mass: f64,
        damping: f64,
        stiffness: f64,
    },
}

/// Matrices of a linear specimen over `[attached; internal]` DOFs.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearMatrices {
    pub dofs: Vec<usize>,
    pub mass: DMatrix<f64>,
    pub damping: DMatrix<f64>,
    pub stiffness: DMatrix<f64>,
    pub influence: DVector<f64>,
}

impl SpecimenSpec {
    pub fn kind(&self) -> &'static str {
        match self {
            SpecimenSpec::LinearSdof { .. } => "linear_sdof",
            SpecimenSpec::LinearMdof { .. } => "linear_mdof",
            SpecimenSpec::BoucWen { .. } => "bouc_wen",
            SpecimenSpec::Friction { .. } => "friction",
            SpecimenSpec::Replay { .. } => "replay",
            SpecimenSpec::LumpedSdof { .. } => "lumped_sdof",
        }
    }

    /// Model DOFs (0-based) the specimen is attached to, in the specimen's order.
    pub fn dofs(&self) -> Vec<usize> {
        match self {
            SpecimenSpec::LinearSdof { dof, .. } => vec![*dof],
            SpecimenSpec::LinearMdof { dofs, .. } => dofs.clone(),
            SpecimenSpec::BoucWen { dof, .. }
            | SpecimenSpec::Friction { dof, .. }
            | SpecimenSpec::Replay { dof, .. }
            | SpecimenSpec::LumpedSdof { dof, .. } => {
                vec![*dof]
            }
        }
    }

    pub fn build(&self) -> Result<Box<dyn Specimen>> {
        Ok(match self {
            SpecimenSpec::LinearSdof {
                mass,
                stiffness,
                damping,
                ..
            } => Box::new(LinearSpecimen::sdof(*mass, *stiffness, *damping)?),
            SpecimenSpec::LinearMdof {
                dofs,
                mass,
                damping,
                stiffness,
                influence,
            } => Box::new(LinearSpecimen::from_matrices(
                dofs.len(),
                mass.clone(),
                damping.clone(),
                stiffness.clone(),
                influence.clone(),
            )?),
            SpecimenSpec::BoucWen { params, .. } => Box::new(BoucWen::new(params)?),
            SpecimenSpec::Friction {
                slip_force,
                model,
                damping,
                ..
            } => Box::new(Friction::new(*slip_force, *model, *damping)?),
            SpecimenSpec::Replay { dt, values, .. } => Box::new(Replay::new(*dt, values.as_slice())?),
            SpecimenSpec::LumpedSdof {
                mass,
                damping,
                stiffness,
                ..
            } => Box::new(LumpedSdof::new(*mass, *damping, *stiffness)?),
        })
    }

    /// The matrices of a linear specimen (for the monolithic reference); `None` if nonlinear.
    pub fn linear_matrices(&self) -> Option<LinearMatrices> {
        match self {
            SpecimenSpec::LinearSdof {
                dof,
                mass: None,
                stiffness,
                damping,
            } => Some(LinearMatrices {
                dofs: vec![*dof],
                mass: dmatrix![0.0],
                damping: dmatrix![*damping],
                stiffness: dmatrix![*stiffness],
                influence: DVector::from_element(1, 1.0),
            }),
            SpecimenSpec::LinearSdof {
                dof,
                mass: Some(m),
                stiffness: k,
                damping: c,
            } => Some(LinearMatrices {
                dofs: vec![*dof],
                mass: dmatrix![0.0, 0.0; 0.0, *m],
                damping: dmatrix![*c, -*c; -*c, *c],
                stiffness: dmatrix![*k, -*k; -*k, *k],
                influence: DVector::from_element(2, 1.0),
            }),
            SpecimenSpec::LinearMdof {
                dofs,
                mass,
                damping,
                stiffness,
                influence,
            } => Some(LinearMatrices {
                dofs: dofs.clone(),
                mass: mass.clone(),
                damping: damping.clone(),
                stiffness: stiffness.clone(),
                influence: influence
                    .clone()
                    .unwrap_or_else(|| DVector::from_element(stiffness.nrows(), 1.0)),
            }),
            SpecimenSpec::LumpedSdof {
                dof,
                mass,
                damping,
                stiffness,
            } => Some(LinearMatrices {
                dofs: vec![*dof],
                mass: dmatrix![*mass],
                damping: dmatrix![*damping],
                stiffness: dmatrix![*stiffness],
                influence: DVector::from_element(1, 1.0),
            }),
            SpecimenSpec::BoucWen { .. } | SpecimenSpec::Friction { .. } | SpecimenSpec::Replay { .. } => None,
        }
    }

    /// `[m, c, k]` at the attached DOF of a specimen whose force is `−(m ẍ + c ẋ + k x)` of
    /// that DOF's motion alone (a lumped SDOF, or a spring and dashpot to ground with `m = 0`);
    /// `None` for the others. The servo-hydraulic plant and the lab's `force = "from_motion"`
    /// use it.
    pub fn lumped_mck(&self) -> Option<[f64; 3]> {
        match *self {
            SpecimenSpec::LumpedSdof {
                mass,
                damping,
                stiffness,
                ..
            } => Some([mass, damping, stiffness]),
            SpecimenSpec::LinearSdof {
                mass: None,
                stiffness,
                damping,
                ..
            } => Some([0.0, damping, stiffness]),
            _ => None,
        }
    }
}

/// The specimens' contribution to the monolithic model of a numerical substructure with `n`
/// DOFs: internal specimen DOFs are appended after the model's DOFs, in specimen order.
pub(crate) struct SpecimenScatter {
    /// DOFs of the assembled model.
    pub total: usize,
    /// `(global DOF, ι)` of the appended internal DOFs.
    pub influence: Vec<(usize, f64)>,
    /// `(row, column, m, c, k)` to add to the assembled matrices.
    pub entries: Vec<(usize, usize, f64, f64, f64)>,
}

impl SpecimenScatter {
    /// Errors name the first nonlinear specimen.
    pub fn new(n: usize, specimens: &[SpecimenSpec]) -> Result<Self> {
        let mut out = Self {
            total: n,
            influence: Vec::new(),
            entries: Vec::new(),
        };
        for (k, s) in specimens.iter().enumerate() {
            let p = s.linear_matrices().ok_or_else(|| {
                Error::invalid(
                    format!("substructure.specimen[{}]", k + 1),
                    format!("the {} specimen is not linear", s.kind()),
                )
            })?;
            let (n_a, n_p) = (p.dofs.len(), p.stiffness.nrows());
            let next = out.total;
            let global: Vec<usize> = p.dofs.iter().copied().chain(next..next + n_p - n_a).collect();
            for (li, &gi) in global.iter().enumerate() {
                if li >= n_a {
                    out.influence.push((gi, p.influence[li]));
                }
                for (lj, &gj) in global.iter().enumerate() {
                    out.entries
                        .push((gi, gj, p.mass[(li, lj)], p.damping[(li, lj)], p.stiffness[(li, lj)]));
                }
            }
            out.total += n_p - n_a;
        }
        Ok(out)
    }
}

/// The monolithic model of the numerical substructure plus all (linear) specimens: internal
/// specimen DOFs are appended after the model's DOFs, in specimen order. Errors name the first
/// nonlinear specimen.
pub fn assemble_monolithic(model: &StructuralModel, specimens: &[SpecimenSpec]) -> Result<StructuralModel> {
    let n = model.n_dofs();
    let scatter = SpecimenScatter::new(n, specimens)?;
    let total = scatter.total;
    let grow = |a: &DMatrix<f64>| {
        let mut b = DMatrix::zeros(total, total);
        b.view_mut((0, 0), (n, n)).copy_from(a);
        b
    };
    let (mut mm, mut cc, mut kk) = (grow(&model.mass), grow(&model.damping), grow(&model.stiffness));
    let mut iota = DVector::zeros(total);
    iota.rows_mut(0, n).copy_from(&model.influence);
    for &(i, v) in &scatter.influence {
        iota[i] = v;
    }
    for &(i, j, m, c, k) in &scatter.entries {
        mm[(i, j)] += m;
        cc[(i, j)] += c;
        kk[(i, j)] += k;
    }
    StructuralModel::new(mm, cc, kk, Some(iota))
}
