//! `[[substructure.specimen]]` (docs/config.md, section `[[substructure.specimen]]`): the specimen
//! kinds. To add one: a variant of `RawSpecimen` (its keys are the variant's fields) and one arm
//! of `RawSpecimen::to_spec`.

use super::common::{MatrixInput, dof_index, matrix_with, one, rekey};
use crate::error::{Error, Result, require_non_negative, require_positive};
use crate::excitation::{self};
use crate::limits::Limits;
use crate::specimen::{BoucWenParams, FrictionModel, Pinching, SpecimenSpec};
use nalgebra::{DMatrix, DVector};
use serde::Deserialize;
use std::path::Path;

/// One `[[substructure.specimen]]`; `kind` selects the variant.
#[derive(Debug, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub(crate) enum RawSpecimen {
    LinearSdof {
        dof: usize,
        mass: Option<f64>,
        stiffness: f64,
        #[serde(default)]
        damping: f64,
    },
    LinearMdof {
        dofs: Vec<usize>,
        mass: Option<MatrixInput>,
        stiffness: MatrixInput,
        damping: Option<MatrixInput>,
        influence: Option<Vec<f64>>,
    },
    /// Bouc–Wen hysteretic spring; optional keys default as in `BoucWenParams::new`.
    BoucWen {
        dof: usize,
        stiffness: f64,
        alpha: f64,
        yield_displacement: f64,
        a: Option<f64>,
        beta: Option<f64>,
        gamma: Option<f64>,
        n: Option<f64>,
        #[serde(default)]
        damping: f64,
        #[serde(default)]
        delta_a: f64,
        #[serde(default)]
        delta_nu: f64,
        #[serde(default)]
        delta_eta: f64,
        /// Baber–Noori pinching strength `ζ_s` (shape parameters at their defaults).
        pinching: Option<f64>,
    },
    /// Friction damper: `model = "stick_slip"` (default, needs `stiffness`) or `"smooth"` (`v_ref`).
    Friction {
        dof: usize,
        slip_force: f64,
        model: Option<String>,
        stiffness: Option<f64>,
        v_ref: Option<f64>,
        #[serde(default)]
        damping: f64,
    },
    /// Replay of a measured force record [N]: `file` (two columns t, f) or `values` + `dt`.
    Replay {
        dof: usize,
        file: Option<String>,
        values: Option<Vec<f64>>,
        dt: Option<f64>,
        #[serde(default = "one")]
        scale: f64,
    },
    /// Mass, dashpot and spring at the coupling DOF itself.
    LumpedSdof {
        dof: usize,
        mass: f64,
        #[serde(default)]
        damping: f64,
        #[serde(default)]
        stiffness: f64,
    },
}

impl RawSpecimen {
    /// The library's description; `n` is the number of model DOFs, `what` the key prefix.
    pub(crate) fn to_spec(&self, n: usize, what: &str, base: &Path) -> Result<SpecimenSpec> {
        self.to_spec_with(n, what, base, &Limits::default())
    }

    /// [`RawSpecimen::to_spec`] with files read within `limits`.
    pub(crate) fn to_spec_with(&self, n: usize, what: &str, base: &Path, limits: &Limits) -> Result<SpecimenSpec> {
        match self {
            RawSpecimen::BoucWen {
                dof,
                stiffness,
                alpha,
                yield_displacement,
                a,
                beta,
                gamma,
                n: sharpness,
                damping,
                delta_a,
                delta_nu,
                delta_eta,
                pinching,
            } => {
                let mut p = BoucWenParams::new(*stiffness, *alpha, *yield_displacement);
                p.a = a.unwrap_or(p.a);
                p.beta = beta.unwrap_or(p.beta);
                p.gamma = gamma.unwrap_or(p.gamma);
                p.n = sharpness.unwrap_or(p.n);
                p.damping = *damping;
                p.delta_a = *delta_a;
                p.delta_nu = *delta_nu;
                p.delta_eta = *delta_eta;
                p.pinching = pinching.map(Pinching::new);
                let spec = SpecimenSpec::BoucWen {
                    dof: dof_index(&format!("{what}.dof"), *dof, n)?,
                    params: p,
                };
                spec.build().map_err(|e| rekey(e, what))?;
                Ok(spec)
            }
            RawSpecimen::Friction {
                dof,
                slip_force,
                model,
                stiffness,
                v_ref,
                damping,
            } => {
                let model = match model.as_deref().unwrap_or("stick_slip") {
                    "stick_slip" => FrictionModel::StickSlip {
                        stiffness: stiffness.ok_or_else(|| {
                            Error::invalid(
                                format!("{what}.stiffness"),
                                "is required for model = \"stick_slip\" (pre-slip stiffness, N/m)",
                            )
                        })?,
                    },
                    "smooth" => FrictionModel::Smooth {
                        v_ref: v_ref.ok_or_else(|| {
                            Error::invalid(
                                format!("{what}.v_ref"),
                                "is required for model = \"smooth\" (reference velocity, m/s)",
                            )
                        })?,
                    },
                    other => {
                        return Err(Error::invalid(
                            format!("{what}.model"),
                            format!("unknown friction model '{other}' (expected stick_slip or smooth)"),
                        ));
                    }
                };
                let spec = SpecimenSpec::Friction {
                    dof: dof_index(&format!("{what}.dof"), *dof, n)?,
                    slip_force: *slip_force,
                    model,
                    damping: *damping,
                };
                spec.build().map_err(|e| rekey(e, what))?;
                Ok(spec)
            }
            RawSpecimen::Replay {
                dof,
                file,
                values,
                dt,
                scale,
            } => {
                let (dt, values) = match (file, values) {
                    (Some(f), None) => {
                        let path = base.join(f);
                        let rec = excitation::read_record_with(&path, *dt, limits)
                            .map_err(|e| Error::invalid(format!("{what}.file"), e.to_string()))?;
                        (rec.dt, rec.accel)
                    }
                    (None, Some(v)) => {
                        let dt = dt.ok_or_else(|| Error::invalid(format!("{what}.dt"), "is required with values"))?;
                        (dt, v.clone())
                    }
                    _ => {
                        return Err(Error::invalid(
                            what.to_string(),
                            "give either file or values (with dt) for a replay",
                        ));
                    }
                };
                if !scale.is_finite() {
                    return Err(Error::invalid(format!("{what}.scale"), "must be finite"));
                }
                let spec = SpecimenSpec::Replay {
                    dof: dof_index(&format!("{what}.dof"), *dof, n)?,
                    dt,
                    values: values.iter().map(|v| v * scale).collect(),
                };
                spec.build().map_err(|e| rekey(e, what))?;
                Ok(spec)
            }
            RawSpecimen::LumpedSdof {
                dof,
                mass,
                damping,
                stiffness,
            } => {
                require_positive(&format!("{what}.mass"), *mass)?;
                require_non_negative(&format!("{what}.stiffness"), *stiffness)?;
                require_non_negative(&format!("{what}.damping"), *damping)?;
                Ok(SpecimenSpec::LumpedSdof {
                    dof: dof_index(&format!("{what}.dof"), *dof, n)?,
                    mass: *mass,
                    damping: *damping,
                    stiffness: *stiffness,
                })
            }
            RawSpecimen::LinearSdof {
                dof,
                mass,
                stiffness,
                damping,
            } => {
                if let Some(m) = mass {
                    require_positive(&format!("{what}.mass"), *m)?;
                }
                require_non_negative(&format!("{what}.stiffness"), *stiffness)?;
                require_non_negative(&format!("{what}.damping"), *damping)?;
                Ok(SpecimenSpec::LinearSdof {
                    dof: dof_index(&format!("{what}.dof"), *dof, n)?,
                    mass: *mass,
                    stiffness: *stiffness,
                    damping: *damping,
                })
            }
            RawSpecimen::LinearMdof {
                dofs,
                mass,
                stiffness,
                damping,
                influence,
            } => {
                let key = format!("{what}.dofs");
                if dofs.is_empty() {
                    return Err(Error::invalid(key, "must list at least one DOF"));
                }
                let mut idx = Vec::with_capacity(dofs.len());
                for &d in dofs {
                    let i = dof_index(&key, d, n)?;
                    if idx.contains(&i) {
                        return Err(Error::invalid(key, format!("DOF {d} is listed twice")));
                    }
                    idx.push(i);
                }
                let k = matrix_with(stiffness, &format!("{what}.stiffness"), base, limits)?;
                let size = k.nrows();
                let m = match mass {
                    Some(m) => matrix_with(m, &format!("{what}.mass"), base, limits)?,
                    None => DMatrix::zeros(size, size),
                };
                let c = match damping {
                    Some(c) => matrix_with(c, &format!("{what}.damping"), base, limits)?,
                    None => DMatrix::zeros(size, size),
                };
                for (key, mat) in [("stiffness", &k), ("mass", &m), ("damping", &c)] {
                    if mat.nrows() != mat.ncols() || mat.nrows() < dofs.len() || mat.nrows() != size {
                        return Err(Error::invalid(
                            format!("{what}.{key}"),
                            format!(
                                "is {}x{}; it must be square over the {} attached DOFs followed by the internal \
                                 DOFs, and all specimen matrices must have one size (stiffness is {size}x{size})",
                                mat.nrows(),
                                mat.ncols(),
                                dofs.len()
                            ),
                        ));
                    }
                }
                if let Some(inf) = influence
                    && inf.len() != size
                {
                    return Err(Error::invalid(
                        format!("{what}.influence"),
                        format!("has {} entries, the specimen has {size} DOFs", inf.len()),
                    ));
                }
                Ok(SpecimenSpec::LinearMdof {
                    dofs: idx,
                    mass: m,
                    damping: c,
                    stiffness: k,
                    influence: influence.clone().map(DVector::from_vec),
                })
            }
        }
    }
}
