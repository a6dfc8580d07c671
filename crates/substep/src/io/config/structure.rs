//! `[structure]` (docs/config.md, section `[structure]` and its sub-tables): the numerical model —
//! explicit matrices, shear building, 2-D frame, SDOF, TMD, damping, storage — and the checks
//! that keep the exact reference in range.

use super::common::{MatrixInput, OneOrMany, forbid, matrix_with, prefixed, sparse_matrix};
use super::substructure::SubstructureDefinition;
use crate::error::{Error, Result};
use crate::integrate::Scheme;
use crate::limits::{self, Limits, RunShape};
use crate::material::{BoucWenParams, MaterialSpec, check_hardening};
use crate::model::{
    DENSE_MAX_DOFS, DampingSpec, Frame2d, Frame3d, FrameHinges, HingeLocation, Hysteresis, Model, Section, Section3d,
    ShearBuilding, SparseModel, Storage, StructuralModel, TmdSystem, frame_2d, frame_2d_hinged, frame_3d,
    frame_gravity, frame_p_delta, sdof, shear_building_sparse, storey_building, storey_springs, tmd_two_dof,
};
use crate::sparse::CscMatrix;
use crate::transfer::Dynamics;
use nalgebra::{DMatrix, DVector};
use serde::Deserialize;
use std::path::Path;

/// The largest assembled model integrated with the exact scheme as a reference; larger models
/// use Newmark with the run's β, γ and time step (on sparse storage if the model is sparse).
/// Defined with the test definition because the definition's checks depend on it.
pub const EXACT_REFERENCE_MAX_DOFS: usize = 200;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawStructure {
    pub(crate) mass: Option<MatrixInput>,
    pub(crate) stiffness: Option<MatrixInput>,
    pub(crate) damping: Option<MatrixInput>,
    pub(crate) influence: Option<Vec<f64>>,
    pub(crate) rayleigh: Option<RawRayleigh>,
    pub(crate) modal: Option<RawModal>,
    pub(crate) shear_building: Option<RawShearBuilding>,
    pub(crate) storeys: Option<RawStoreys>,
    pub(crate) sdof: Option<RawSdof>,
    pub(crate) tmd: Option<RawTmd>,
    pub(crate) frame: Option<RawFrame>,
    pub(crate) storage: Option<String>,
    pub(crate) reduction: Option<super::reduction::RawReduction>,
}

/// `[structure.frame]`; every key has the default of [`Frame2d::default`].
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub(crate) struct RawFrame {
    pub(crate) bays: usize,
    pub(crate) stories: usize,
    pub(crate) bay_width: f64,
    pub(crate) story_height: f64,
    pub(crate) elastic_modulus: f64,
    pub(crate) column_area: f64,
    pub(crate) column_inertia: f64,
    pub(crate) beam_area: f64,
    pub(crate) beam_inertia: f64,
    pub(crate) density: f64,
    pub(crate) floor_mass_per_bay: f64,
    pub(crate) rigid_diaphragm: bool,
    /// 2 (plane frame, [`Frame2d`]) or 3 (space frame, [`Frame3d`]).
    pub(crate) dimensions: usize,
    // Space frames only (refused with `dimensions = 2`); defaults of [`Frame3d::default`].
    pub(crate) bays_y: Option<usize>,
    pub(crate) bay_width_y: Option<f64>,
    pub(crate) shear_modulus: Option<f64>,
    pub(crate) column_inertia_weak: Option<f64>,
    pub(crate) column_torsion: Option<f64>,
    pub(crate) beam_inertia_weak: Option<f64>,
    pub(crate) beam_torsion: Option<f64>,
    /// `[structure.frame.hinges]`: concentrated plasticity (plane frames).
    pub(crate) hinges: Option<RawFrameHinges>,
    /// P-Δ of the columns (OpenSees' `PDelta` transformation; plane frames).
    pub(crate) p_delta: bool,
    /// Gravity on the lumped masses, applied statically before the excitation (plane frames).
    pub(crate) gravity: bool,
}

/// `[structure.frame.hinges]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawFrameHinges {
    pub(crate) at: String,
    pub(crate) kind: String,
    pub(crate) beam_yield_moment: Option<f64>,
    pub(crate) column_yield_moment: Option<f64>,
    pub(crate) hardening: Option<f64>,
    pub(crate) stiffness_factor: Option<f64>,
}

const HINGES: &str = "structure.frame.hinges";

impl RawFrameHinges {
    fn build(&self, frame: &Frame2d) -> Result<FrameHinges> {
        let at = HingeLocation::from_name(&self.at)?;
        if frame.bays == 0 && at != HingeLocation::Columns {
            return Err(Error::invalid(
                format!("{HINGES}.at"),
                format!(
                    "\"{}\" asks for beam hinges, but the frame has no beams (bays = 0)",
                    self.at
                ),
            ));
        }
        let (beams, columns) = match at {
            HingeLocation::Beams => (true, false),
            HingeLocation::Columns => (false, true),
            HingeLocation::Both => (true, true),
        };
        let law = |used: bool, key: &str, moment: Option<f64>| -> Result<MaterialSpec> {
            if !used {
                if moment.is_some() {
                    return Err(Error::invalid(
                        format!("{HINGES}.{key}"),
                        format!("is not used with at = \"{}\"", self.at),
                    ));
                }
                return Ok(MaterialSpec::Elastic);
            }
            if self.kind == "elastic" {
                return Ok(MaterialSpec::Elastic);
            }
            let m = moment.ok_or_else(|| {
                Error::invalid(
                    format!("{HINGES}.{key}"),
                    format!("missing (kind = \"{}\" at = \"{}\" needs it) [N·m]", self.kind, self.at),
                )
            })?;
            if !(m.is_finite() && m > 0.0) {
                return Err(Error::invalid(
                    format!("{HINGES}.{key}"),
                    format!("must be a finite moment > 0 N·m, got {m}"),
                ));
            }
            let hardening = match self.kind.as_str() {
                "bilinear" => {
                    let b = self.hardening.ok_or_else(|| {
                        Error::invalid(
                            format!("{HINGES}.hardening"),
                            "missing (kind = \"bilinear\" needs the post-yield over initial stiffness ratio)",
                        )
                    })?;
                    check_hardening(&format!("{HINGES}.hardening"), b)?;
                    b
                }
                "elastic_plastic" => 0.0,
                other => {
                    return Err(Error::invalid(
                        format!("{HINGES}.kind"),
                        format!("unknown hinge law '{other}' (expected elastic, bilinear or elastic_plastic)"),
                    ));
                }
            };
            Ok(MaterialSpec::Bilinear {
                yield_force: m,
                hardening,
            })
        };
        Ok(FrameHinges {
            at,
            stiffness_factor: self.stiffness_factor.unwrap_or(10.0),
            beam_law: law(beams, "beam_yield_moment", self.beam_yield_moment)?,
            column_law: law(columns, "column_yield_moment", self.column_yield_moment)?,
        })
    }
}

impl Default for RawFrame {
    fn default() -> Self {
        let f = Frame2d::default();
        Self {
            bays: f.bays,
            stories: f.stories,
            bay_width: f.bay_width,
            story_height: f.story_height,
            elastic_modulus: f.elastic_modulus,
            column_area: f.column.area,
            column_inertia: f.column.inertia,
            beam_area: f.beam.area,
            beam_inertia: f.beam.inertia,
            density: f.density,
            floor_mass_per_bay: f.floor_mass_per_bay,
            rigid_diaphragm: f.rigid_diaphragm,
            dimensions: 2,
            bays_y: None,
            bay_width_y: None,
            shear_modulus: None,
            column_inertia_weak: None,
            column_torsion: None,
            beam_inertia_weak: None,
            beam_torsion: None,
            hinges: None,
            p_delta: false,
            gravity: false,
        }
    }
}

/// The frame a `[structure.frame]` describes.
pub(crate) enum FrameKind {
    Plane(Frame2d),
    Space(Frame3d),
}

impl RawFrame {
    /// Check `dimensions` and that space-frame keys come with `dimensions = 3`.
    pub(crate) fn kind(&self) -> Result<FrameKind> {
        let space_keys = [
            ("bays_y", self.bays_y.is_some()),
            ("bay_width_y", self.bay_width_y.is_some()),
            ("shear_modulus", self.shear_modulus.is_some()),
            ("column_inertia_weak", self.column_inertia_weak.is_some()),
            ("column_torsion", self.column_torsion.is_some()),
            ("beam_inertia_weak", self.beam_inertia_weak.is_some()),
            ("beam_torsion", self.beam_torsion.is_some()),
        ];
        match self.dimensions {
            2 => {
                if let Some((k, _)) = space_keys.iter().find(|(_, set)| *set) {
                    return Err(Error::invalid(
                        format!("structure.frame.{k}"),
                        "is a space-frame key: it needs dimensions = 3",
                    ));
                }
                Ok(FrameKind::Plane(self.to_frame()))
            }
            3 => {
                let d = Frame3d::default();
                Ok(FrameKind::Space(Frame3d {
                    bays_x: self.bays,
                    bays_y: self.bays_y.unwrap_or(d.bays_y),
                    stories: self.stories,
                    bay_x: self.bay_width,
                    bay_y: self.bay_width_y.unwrap_or(self.bay_width),
                    story_height: self.story_height,
                    elastic_modulus: self.elastic_modulus,
                    shear_modulus: self.shear_modulus.unwrap_or(d.shear_modulus),
                    column: Section3d {
                        area: self.column_area,
                        i_strong: self.column_inertia,
                        i_weak: self.column_inertia_weak.unwrap_or(d.column.i_weak),
                        torsion: self.column_torsion.unwrap_or(d.column.torsion),
                    },
                    beam: Section3d {
                        area: self.beam_area,
                        i_strong: self.beam_inertia,
                        i_weak: self.beam_inertia_weak.unwrap_or(d.beam.i_weak),
                        torsion: self.beam_torsion.unwrap_or(d.beam.torsion),
                    },
                    density: self.density,
                    floor_mass_per_panel: self.floor_mass_per_bay,
                    rigid_diaphragm: self.rigid_diaphragm,
                }))
            }
            other => Err(Error::invalid(
                "structure.frame.dimensions",
                format!("must be 2 (plane frame) or 3 (space frame), got {other}"),
            )),
        }
    }

    /// DOFs and the nodes per floor of the frame (the run-size estimate).
    pub(crate) fn size(&self) -> (f64, f64) {
        let lines = self.bays as f64 + 1.0;
        if self.dimensions == 3 {
            let nodes = lines * (self.bays_y.unwrap_or(Frame3d::default().bays_y) as f64 + 1.0);
            let per_floor = if self.rigid_diaphragm {
                3.0 + 3.0 * nodes
            } else {
                6.0 * nodes
            };
            (self.stories as f64 * per_floor, per_floor / 3.0)
        } else {
            let per_floor = if self.rigid_diaphragm {
                1.0 + 2.0 * lines
            } else {
                3.0 * lines
            };
            (self.stories as f64 * per_floor, lines)
        }
    }

    pub(crate) fn to_frame(&self) -> Frame2d {
        Frame2d {
            bays: self.bays,
            stories: self.stories,
            bay_width: self.bay_width,
            story_height: self.story_height,
            elastic_modulus: self.elastic_modulus,
            column: Section {
                area: self.column_area,
                inertia: self.column_inertia,
            },
            beam: Section {
                area: self.beam_area,
                inertia: self.beam_inertia,
            },
            density: self.density,
            floor_mass_per_bay: self.floor_mass_per_bay,
            rigid_diaphragm: self.rigid_diaphragm,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawRayleigh {
    pub(crate) alpha: Option<f64>,
    pub(crate) beta: Option<f64>,
    pub(crate) zeta: Option<f64>,
    pub(crate) modes: Option<Vec<usize>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawModal {
    pub(crate) zeta: OneOrMany,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawShearBuilding {
    pub(crate) stories: usize,
    pub(crate) story_mass: f64,
    pub(crate) first_period: f64,
}

/// `[structure.storeys]`: a shear building storey by storey, optionally with hysteretic storeys.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawStoreys {
    pub(crate) masses: Vec<f64>,
    pub(crate) stiffness: Vec<f64>,
    pub(crate) hysteresis: Option<RawHysteresis>,
}

/// `[structure.storeys.hysteresis]`: the law of every storey spring.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawHysteresis {
    pub(crate) kind: String,
    pub(crate) yield_force: Option<OneOrMany>,
    pub(crate) hardening: Option<f64>,
    /// Bouc–Wen shape: sharpness `n`, `beta`, `gamma` (defaults of the `bouc_wen` specimen).
    pub(crate) n: Option<f64>,
    pub(crate) beta: Option<f64>,
    pub(crate) gamma: Option<f64>,
}

const STOREYS: &str = "structure.storeys";
const HYSTERESIS: &str = "structure.storeys.hysteresis";

impl RawStoreys {
    /// The law of each storey (`elastic` without `[structure.storeys.hysteresis]`).
    fn laws(&self) -> Result<Vec<MaterialSpec>> {
        let n = self.masses.len();
        let Some(h) = &self.hysteresis else {
            return Ok(vec![MaterialSpec::Elastic; n]);
        };
        let yield_forces = |h: &RawHysteresis| -> Result<Vec<f64>> {
            let f = h.yield_force.as_ref().ok_or_else(|| {
                Error::invalid(
                    format!("{HYSTERESIS}.yield_force"),
                    format!(
                        "missing (kind = \"{}\" needs a yield force per storey, or one for all)",
                        h.kind
                    ),
                )
            })?;
            let f = match f.0.len() {
                1 => vec![f.0[0]; n],
                m if m == n => f.0.clone(),
                m => {
                    return Err(Error::invalid(
                        format!("{HYSTERESIS}.yield_force"),
                        format!(
                            "has {m} entries but the building has {n} storeys (give one per storey, or one number)"
                        ),
                    ));
                }
            };
            for (i, &y) in f.iter().enumerate() {
                if !(y.is_finite() && y > 0.0) {
                    return Err(Error::invalid(
                        format!("{HYSTERESIS}.yield_force"),
                        format!("storey {}: must be a finite force > 0 N, got {y}", i + 1),
                    ));
                }
            }
            Ok(f)
        };
        match h.kind.as_str() {
            "elastic" => {
                forbid(
                    &format!("{HYSTERESIS}."),
                    &[
                        ("yield_force", h.yield_force.is_some()),
                        ("hardening", h.hardening.is_some()),
                    ],
                    "not used with kind = \"elastic\"",
                )?;
                Ok(vec![MaterialSpec::Elastic; n])
            }
            "bilinear" => {
                let hardening = h.hardening.ok_or_else(|| {
                    Error::invalid(
                        format!("{HYSTERESIS}.hardening"),
                        "missing (kind = \"bilinear\" needs the post-yield over initial stiffness ratio; use kind = \"elastic_plastic\" for 0)",
                    )
                })?;
                check_hardening(&format!("{HYSTERESIS}.hardening"), hardening)?;
                Ok(yield_forces(h)?
                    .into_iter()
                    .map(|yield_force| MaterialSpec::Bilinear { yield_force, hardening })
                    .collect())
            }
            "elastic_plastic" => {
                forbid(
                    &format!("{HYSTERESIS}."),
                    &[("hardening", h.hardening.is_some())],
                    "not used with kind = \"elastic_plastic\" (its hardening is 0; use kind = \"bilinear\")",
                )?;
                Ok(yield_forces(h)?
                    .into_iter()
                    .map(|yield_force| MaterialSpec::Bilinear {
                        yield_force,
                        hardening: 0.0,
                    })
                    .collect())
            }
            "bouc_wen" => {
                let hardening = h.hardening.unwrap_or(0.0);
                check_hardening(&format!("{HYSTERESIS}.hardening"), hardening)?;
                yield_forces(h)?
                    .into_iter()
                    .zip(&self.stiffness)
                    .enumerate()
                    .map(|(i, (yield_force, &k))| {
                        // z is bounded by u_y: the force approaches α k u + (1 − α) F_y
                        let mut p = BoucWenParams::new(k, hardening, yield_force / k);
                        p.n = h.n.unwrap_or(p.n);
                        p.beta = h.beta.unwrap_or(p.beta);
                        p.gamma = h.gamma.unwrap_or(p.gamma);
                        p.validate().map_err(|e| match e {
                            Error::InvalidInput { what, reason } => Error::invalid(
                                format!(
                                    "{HYSTERESIS}.{} (storey {})",
                                    what.trim_start_matches("specimen."),
                                    i + 1
                                ),
                                reason,
                            ),
                            other => other,
                        })?;
                        Ok(MaterialSpec::BoucWen(Box::new(p)))
                    })
                    .collect()
            }
            other => Err(Error::invalid(
                format!("{HYSTERESIS}.kind"),
                format!("unknown hysteresis '{other}' (expected elastic, bilinear, bouc_wen or elastic_plastic)"),
            )),
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSdof {
    pub(crate) mass: f64,
    pub(crate) stiffness: f64,
    #[serde(default)]
    pub(crate) damping: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub(crate) struct RawTmd {
    pub(crate) mass: f64,
    pub(crate) frequency: f64,
    pub(crate) zeta: f64,
    pub(crate) eta_m: f64,
    pub(crate) eta_f: f64,
    pub(crate) zeta_s: f64,
}

impl Default for RawTmd {
    fn default() -> Self {
        let t = TmdSystem::typical();
        Self {
            mass: t.mass,
            frequency: t.frequency,
            zeta: t.zeta,
            eta_m: t.eta_m,
            eta_f: t.eta_f,
            zeta_s: t.zeta_s,
        }
    }
}

impl RawStructure {
    /// The hysteretic springs of a nonlinear model (`None`: the model is linear).
    pub(crate) fn hysteresis(&self) -> Result<Option<Hysteresis>> {
        if let Some(f) = &self.frame
            && (f.hinges.is_some() || f.p_delta)
            && let FrameKind::Plane(p) = f.kind()?
        {
            let mut h = match &f.hinges {
                Some(h) => frame_2d_hinged(&p, &h.build(&p)?)?.1,
                None => Hysteresis::default(),
            };
            if f.p_delta {
                h.p_delta = frame_p_delta(&p);
            }
            return Ok((!h.is_linear()).then_some(h));
        }
        let Some(b) = &self.storeys else {
            return Ok(None);
        };
        let laws = b.laws()?;
        if laws.iter().all(|l| *l == MaterialSpec::Elastic) {
            return Ok(None);
        }
        Ok(Some(storey_springs(&b.stiffness, &laws, HYSTERESIS)))
    }

    /// The static load applied before the excitation (`[structure.frame] gravity`), for a model
    /// of `n` DOFs with the lumped masses of `model`.
    pub(crate) fn static_load(&self, model: &Model) -> Result<Option<DVector<f64>>> {
        let Some(f) = &self.frame else { return Ok(None) };
        if !f.gravity {
            return Ok(None);
        }
        let FrameKind::Plane(p) = f.kind()? else {
            return Ok(None);
        };
        let mass: Vec<f64> = match model {
            Model::Dense(m) => m.mass.diagonal().iter().copied().collect(),
            Model::Sparse(m) => m.mass.diagonal(),
        };
        Ok(Some(frame_gravity(&p, &mass, model.n_dofs())))
    }

    /// The model in the storage `[structure] storage` asks for; `sparse_capable` is false when
    /// the integrator needs dense matrices (then `auto` keeps models dense).
    pub(crate) fn build(&self, base: &Path, sparse_capable: bool, limits: &Limits) -> Result<Model> {
        let matrices = self.mass.is_some() || self.stiffness.is_some();
        let forms = [
            ("mass + stiffness", matrices),
            ("[structure.shear_building]", self.shear_building.is_some()),
            ("[structure.storeys]", self.storeys.is_some()),
            ("[structure.sdof]", self.sdof.is_some()),
            ("[structure.tmd]", self.tmd.is_some()),
            ("[structure.frame]", self.frame.is_some()),
        ];
        let given: Vec<&str> = forms.iter().filter(|f| f.1).map(|f| f.0).collect();
        match given.len() {
            0 => {
                return Err(Error::invalid(
                    "structure",
                    "no model given: set mass and stiffness, or one of [structure.shear_building], \
                     [structure.storeys], [structure.frame], [structure.sdof], [structure.tmd]",
                ));
            }
            1 => {}
            _ => {
                return Err(Error::invalid(
                    "structure",
                    format!("give only one model form, found {}", given.join(" and ")),
                ));
            }
        }
        let storage = match &self.storage {
            Some(s) => Storage::from_name(s)?,
            None => Storage::Auto,
        };
        let damping_options = [
            ("damping", self.damping.is_some()),
            ("rayleigh", self.rayleigh.is_some()),
            ("modal", self.modal.is_some()),
        ];
        let damping_given: Vec<&str> = damping_options.iter().filter(|f| f.1).map(|f| f.0).collect();
        if damping_given.len() > 1 {
            return Err(Error::invalid(
                format!("structure.{}", damping_given[1]),
                format!("cannot be combined with structure.{}", damping_given[0]),
            ));
        }
        let influence = self.influence.clone().map(DVector::from_vec);

        let model: Model = if let Some(s) = &self.sdof {
            forbid(
                "structure.",
                &damping_options,
                "not allowed with [structure.sdof] (give its damping there)",
            )?;
            let m = sdof(s.mass, s.damping, s.stiffness).map_err(|e| prefixed(e, "structure.sdof."))?;
            StructuralModel::new(m.mass, m.damping, m.stiffness, influence)?.into()
        } else if let Some(t) = &self.tmd {
            forbid(
                "structure.",
                &damping_options,
                "not allowed with [structure.tmd] (it sets damping by zeta and zeta_s)",
            )?;
            let p = TmdSystem {
                mass: t.mass,
                frequency: t.frequency,
                zeta: t.zeta,
                eta_m: t.eta_m,
                eta_f: t.eta_f,
                zeta_s: t.zeta_s,
            };
            let m = tmd_two_dof(&p).map_err(|e| prefixed(e, "structure."))?;
            StructuralModel::new(m.mass, m.damping, m.stiffness, influence)?.into()
        } else if let Some(b) = &self.shear_building {
            let m = shear_building_sparse(&ShearBuilding {
                stories: b.stories,
                story_mass: b.story_mass,
                first_period: b.first_period,
            })?;
            let damping = match &self.damping {
                Some(c) => sparse_matrix(c, "structure.damping", base, limits)?,
                None => m.damping,
            };
            SparseModel::new(m.mass, damping, m.stiffness, influence)?.into()
        } else if let Some(b) = &self.storeys {
            let m = storey_building(&b.masses, &b.stiffness, STOREYS)?;
            let damping = match &self.damping {
                Some(c) => sparse_matrix(c, "structure.damping", base, limits)?,
                None => m.damping,
            };
            SparseModel::new(m.mass, damping, m.stiffness, influence)?.into()
        } else if let Some(f) = &self.frame {
            let m = match (f.kind()?, &f.hinges) {
                (FrameKind::Plane(p), None) => frame_2d(&p)?,
                (FrameKind::Plane(p), Some(h)) => frame_2d_hinged(&p, &h.build(&p)?)?.0,
                (FrameKind::Space(_), Some(_)) => {
                    return Err(Error::invalid(
                        HINGES,
                        "hinges are built for plane frames (dimensions = 2) only",
                    ));
                }
                (FrameKind::Space(_), None) if f.p_delta || f.gravity => {
                    return Err(Error::invalid(
                        if f.p_delta {
                            "structure.frame.p_delta"
                        } else {
                            "structure.frame.gravity"
                        },
                        "is built for plane frames (dimensions = 2) only",
                    ));
                }
                (FrameKind::Space(s), None) => frame_3d(&s)?,
            };
            let damping = match &self.damping {
                Some(c) => sparse_matrix(c, "structure.damping", base, limits)?,
                None => m.damping,
            };
            SparseModel::new(m.mass, damping, m.stiffness, influence.or(Some(m.influence)))?.into()
        } else {
            let (mass, stiffness) = match (&self.mass, &self.stiffness) {
                (Some(m), Some(k)) => (m, k),
                (Some(_), None) => {
                    return Err(Error::invalid(
                        "structure.stiffness",
                        "missing (structure.mass is given)",
                    ));
                }
                _ => {
                    return Err(Error::invalid(
                        "structure.mass",
                        "missing (structure.stiffness is given)",
                    ));
                }
            };
            let inputs = [Some(mass), Some(stiffness), self.damping.as_ref()];
            if inputs.iter().flatten().any(|m| matches!(m, MatrixInput::File(_))) {
                // MatrixMarket files are read sparse (they may be large).
                let mass = sparse_matrix(mass, "structure.mass", base, limits)?;
                let stiffness = sparse_matrix(stiffness, "structure.stiffness", base, limits)?;
                let damping = match &self.damping {
                    Some(c) => sparse_matrix(c, "structure.damping", base, limits)?,
                    None => CscMatrix::zeros(mass.n()),
                };
                SparseModel::new(mass, damping, stiffness, influence)?.into()
            } else {
                let mass = matrix_with(mass, "structure.mass", base, limits)?;
                let stiffness = matrix_with(stiffness, "structure.stiffness", base, limits)?;
                let damping = match &self.damping {
                    Some(c) => matrix_with(c, "structure.damping", base, limits)?,
                    None => DMatrix::zeros(mass.nrows(), mass.ncols()),
                };
                StructuralModel::new(mass, damping, stiffness, influence)?.into()
            }
        };

        let spec = if let Some(r) = &self.rayleigh {
            Some(r.spec()?)
        } else {
            self.modal
                .as_ref()
                .map(|m| DampingSpec::Modal { zeta: m.zeta.0.clone() })
        };
        let model = resolve_storage(model, storage, sparse_capable, self.modal.is_some())?;
        match spec {
            Some(spec) => model.with_damping(&spec),
            None => Ok(model),
        }
    }
}

/// Put `model` in the storage asked for. `auto` picks sparse for large sparse models, but dense
/// when the integrator or modal damping needs dense matrices (up to [`DENSE_MAX_DOFS`]).
pub(crate) fn resolve_storage(model: Model, storage: Storage, sparse_capable: bool, modal: bool) -> Result<Model> {
    let n = model.n_dofs();
    check_storage(n, storage, sparse_capable, modal)?;
    match storage {
        Storage::Auto if modal || !sparse_capable => model.with_storage(Storage::Dense),
        storage => model.with_storage(storage),
    }
}

/// Whether storage `storage` can hold an `n`-DOF model for this scheme and damping (cheap: it
/// runs before the model is built).
pub(crate) fn check_storage(n: usize, storage: Storage, sparse_capable: bool, modal: bool) -> Result<()> {
    let needs_dense = if modal {
        Some("modal damping ([structure.modal])")
    } else if !sparse_capable {
        Some("the integrator scheme")
    } else {
        None
    };
    match (storage, needs_dense) {
        (Storage::Sparse, Some(why)) => Err(Error::invalid(
            "structure.storage",
            format!(
                "\"sparse\" cannot be used with {why}, which needs dense matrices: use \
                 [structure.rayleigh] and an implicit Newmark scheme, or storage = \"dense\""
            ),
        )),
        (Storage::Auto, Some(why)) if n > DENSE_MAX_DOFS => Err(Error::invalid(
            "structure",
            format!(
                "{why} needs dense matrices, but the model has {n} DOFs (dense storage is limited to \
                 {DENSE_MAX_DOFS} DOFs here): use [structure.rayleigh] and an implicit Newmark scheme"
            ),
        )),
        _ => Ok(()),
    }
}

/// Size of the numerical model, known before it is built (or from the built model).
#[derive(Debug, Clone, Copy)]
pub(crate) struct ModelShape {
    pub(crate) n: f64,
    pub(crate) bytes: f64,
    pub(crate) step_seconds: f64,
}

impl ModelShape {
    pub(crate) fn of(model: &Model) -> Self {
        let n = model.n_dofs() as f64;
        match model {
            Model::Dense(_) => Self::dense(n),
            Model::Sparse(m) => {
                let nnz = (m.mass.nnz() + m.damping.nnz() + m.stiffness.nnz()) as f64;
                Self {
                    n,
                    bytes: n * limits::CHAIN_BYTES_PER_DOF + nnz * limits::MTX_BYTES_PER_ENTRY,
                    step_seconds: RunShape::sparse_step_seconds(nnz),
                }
            }
        }
    }
    pub(crate) fn dense(n: f64) -> Self {
        Self {
            n,
            bytes: limits::dense_model_bytes(n),
            step_seconds: RunShape::dense_step_seconds(n),
        }
    }
}

impl RawStructure {
    /// The model's size from the config alone, refused when over `limits` or when its storage
    /// contradicts the scheme or the damping; `None` for MatrixMarket files (their size line is
    /// checked as they are read).
    pub(crate) fn shape(&self, sparse_capable: bool, limits: &Limits) -> Result<Option<ModelShape>> {
        let storage = match &self.storage {
            Some(s) => Storage::from_name(s)?,
            None => Storage::Auto,
        };
        let (n, sparse, key, asked) = if let Some(b) = &self.shear_building {
            let n = b.stories as f64;
            let sparse = ModelShape {
                n,
                bytes: n * limits::CHAIN_BYTES_PER_DOF,
                step_seconds: RunShape::chain_step_seconds(n),
            };
            let asked = format!("a shear building of {} stories", b.stories);
            (n, sparse, "structure.shear_building.stories", asked)
        } else if let Some(b) = &self.storeys {
            let n = b.masses.len() as f64;
            let sparse = ModelShape {
                n,
                bytes: n * limits::CHAIN_BYTES_PER_DOF,
                step_seconds: RunShape::chain_step_seconds(n),
            };
            (
                n,
                sparse,
                "structure.storeys.masses",
                format!("a shear building of {n} storeys"),
            )
        } else if let Some(f) = &self.frame {
            let (n, lines) = f.size();
            let sparse = ModelShape {
                n,
                bytes: n * limits::FRAME_BYTES_PER_DOF,
                step_seconds: RunShape::frame_step_seconds(n, lines),
            };
            let asked = format!(
                "a frame of {} bays and {} stories ({} DOFs)",
                f.bays,
                f.stories,
                limits::number(n)
            );
            (n, sparse, "structure.frame", asked)
        } else {
            let n = if self.sdof.is_some() {
                1
            } else if self.tmd.is_some() {
                2
            } else if let Some(MatrixInput::Rows(rows)) = &self.mass {
                rows.len()
            } else {
                return Ok(None);
            };
            return Ok(Some(ModelShape::dense(n as f64)));
        };
        let modal = self.modal.is_some();
        check_storage(n.min(usize::MAX as f64) as usize, storage, sparse_capable, modal)?;
        let shape = if modal || !sparse_capable || storage == Storage::Dense {
            ModelShape::dense(n)
        } else {
            sparse
        };
        limits.check_memory(key, &asked, shape.bytes)?;
        Ok(Some(shape))
    }
}

/// Largest rate `max(|K_ii|, |C_ii|) / M_ii · Δt` (the diagonal of `A·Δt` of `ż = A z`) that an
/// exact integration accepts: the matrix exponential is computed up to `‖A·Δt‖₁ =`
/// [`crate::linalg::EXPM_MAX_NORM`], and the off-diagonal terms add to the diagonal's.
pub(crate) const EXACT_MAX_RATE: f64 = 1e11;

impl RawStructure {
    /// Config key of the model's stiffness or damping (`what` = "stiffness" / "damping").
    pub(crate) fn key(&self, what: &str) -> String {
        if self.sdof.is_some() {
            format!("structure.sdof.{what}")
        } else if self.tmd.is_some() {
            "structure.tmd".into()
        } else if self.shear_building.is_some() {
            "structure.shear_building".into()
        } else if self.storeys.is_some() {
            STOREYS.into()
        } else if self.frame.is_some() {
            "structure.frame".into()
        } else if what == "damping" && self.rayleigh.is_some() {
            "structure.rayleigh".into()
        } else if what == "damping" && self.modal.is_some() {
            "structure.modal".into()
        } else {
            format!("structure.{what}")
        }
    }
}

/// Refuse what the matrix exponentials cannot integrate in f64 (e.g. a stiffness of 1e60 N/m
/// on 50 kg, or a mass of 1e-300 kg): every DOF of the exact scheme or of the exact reference at
/// `dt`, specimen internal DOFs and actuator dynamics at the inner step, with the key of the
/// term that dominates.
// NaN-safe checks: `!(x > 0.0)` also refuses NaN, which `x <= 0.0` would let through.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
pub(crate) fn check_exact_range(
    raw: &RawStructure,
    model: &Model,
    sub: Option<&SubstructureDefinition>,
    scheme: Scheme,
    dt: f64,
) -> Result<()> {
    struct Dof {
        m: f64,
        k: f64,
        c: f64,
        /// Specimen (index) whose stiffness / damping dominates, `None` for the structure.
        k_owner: Option<usize>,
        c_owner: Option<usize>,
        /// Integrated at the inner step only (a specimen's internal DOF).
        internal: bool,
    }
    let n = model.n_dofs();
    let diagonals = match model {
        Model::Dense(m) => (m.mass.diagonal(), m.stiffness.diagonal(), m.damping.diagonal()),
        Model::Sparse(m) => (
            DVector::from_vec(m.mass.diagonal()),
            DVector::from_vec(m.stiffness.diagonal()),
            DVector::from_vec(m.damping.diagonal()),
        ),
    };
    let mut dofs: Vec<Dof> = (0..n)
        .map(|i| Dof {
            m: diagonals.0[i],
            k: diagonals.1[i],
            c: diagonals.2[i],
            k_owner: None,
            c_owner: None,
            internal: false,
        })
        .collect();
    let mut all_linear = true;
    let mut dt_inner = dt;
    if let Some(s) = sub {
        dt_inner = dt / s.substeps as f64 / s.inner_steps as f64;
        for (idx, spec) in s.specimens.iter().enumerate() {
            let Some(lm) = spec.linear_matrices() else {
                all_linear = false;
                continue;
            };
            for (a, row) in (0..lm.stiffness.nrows()).map(|a| (a, lm.dofs.get(a).copied())) {
                let (k, c, m) = (lm.stiffness[(a, a)], lm.damping[(a, a)], lm.mass[(a, a)]);
                match row {
                    Some(g) if g < n => {
                        let d = &mut dofs[g];
                        if k.abs() > d.k.abs() {
                            d.k_owner = Some(idx);
                        }
                        if c.abs() > d.c.abs() {
                            d.c_owner = Some(idx);
                        }
                        d.k += k;
                        d.c += c;
                        d.m += m;
                    }
                    _ => dofs.push(Dof {
                        m,
                        k,
                        c,
                        k_owner: Some(idx),
                        c_owner: Some(idx),
                        internal: true,
                    }),
                }
            }
        }
        let (key, rate) = match &s.actuator.dynamics {
            // Continuous LTI and servo-hydraulic actuators are checked for stability and
            // integrability where the lab builds them (transfer/lti.rs, transfer/servo.rs).
            Dynamics::Ideal | Dynamics::Lti(_) | Dynamics::ServoHydraulic(_) => ("", 0.0),
            Dynamics::FirstOrder { time_constant } => ("time_constant", dt_inner / time_constant),
            Dynamics::SecondOrder { frequency_hz, zeta } => {
                let w = 2.0 * std::f64::consts::PI * frequency_hz;
                ("frequency", (w * w).max(2.0 * zeta * w) * dt_inner)
            }
        };
        if !(rate <= EXACT_MAX_RATE) {
            return Err(Error::invalid(
                format!("substructure.actuator.{key}"),
                format!(
                    "gives a rate of {rate:.3e} per inner step of {dt_inner:.3e} s (at most {EXACT_MAX_RATE:.0e}): \
                     outside what f64 can integrate; check the units"
                ),
            ));
        }
    }
    let exact = scheme == Scheme::Exact
        || sub.is_some_and(|s| !s.specimens.is_empty() && all_linear && dofs.len() <= EXACT_REFERENCE_MAX_DOFS);
    for (i, d) in dofs.iter().enumerate() {
        let h = if d.internal { dt_inner } else { dt };
        if !(d.internal || exact) || d.m <= 0.0 {
            continue; // no exponential at this DOF; a mass that is not positive is refused elsewhere
        }
        let (rate_k, rate_c) = (d.k.abs() / d.m * h, d.c.abs() / d.m * h);
        if rate_k <= EXACT_MAX_RATE && rate_c <= EXACT_MAX_RATE {
            continue;
        }
        let (what, value, owner) = if !(rate_c > rate_k) {
            ("stiffness", d.k, d.k_owner)
        } else {
            ("damping", d.c, d.c_owner)
        };
        let key = match owner {
            Some(idx) => format!("substructure.specimen[{}].{what}", idx + 1),
            None => raw.key(what),
        };
        let place = if d.internal {
            format!("an internal specimen DOF at the inner step {h:.3e} s")
        } else {
            format!("DOF {} at dt = {h} s", i + 1)
        };
        return Err(Error::invalid(
            key,
            format!(
                "{what} {value:.3e} against a mass of {:.3e} kg at {place} gives a rate {what}/mass·dt = \
                 {:.3e}, more than {EXACT_MAX_RATE:.0e}: outside what f64 can integrate exactly (matrix \
                 exponential); check the units of mass, {what} and dt",
                d.m,
                rate_k.max(rate_c)
            ),
        ));
    }
    Ok(())
}

impl RawRayleigh {
    pub(crate) fn spec(&self) -> Result<DampingSpec> {
        match (self.alpha, self.beta, self.zeta) {
            (None, None, Some(zeta)) => {
                let modes = match self.modes.as_deref() {
                    None => (1, 2),
                    Some([i, j]) => (*i, *j),
                    Some(other) => {
                        return Err(Error::invalid(
                            "structure.rayleigh.modes",
                            format!("must list two mode numbers, got {}", other.len()),
                        ));
                    }
                };
                Ok(DampingSpec::RayleighRatio { zeta, modes })
            }
            (alpha, beta, None) if alpha.is_some() || beta.is_some() => {
                if self.modes.is_some() {
                    return Err(Error::invalid(
                        "structure.rayleigh.modes",
                        "only used with zeta (not with alpha, beta)",
                    ));
                }
                Ok(DampingSpec::Rayleigh {
                    alpha: alpha.unwrap_or(0.0),
                    beta: beta.unwrap_or(0.0),
                })
            }
            (_, _, Some(_)) => Err(Error::invalid(
                "structure.rayleigh",
                "give either alpha and beta, or zeta (with modes), not both",
            )),
            _ => Err(Error::invalid(
                "structure.rayleigh",
                "give alpha and beta, or zeta (with modes = [i, j], default [1, 2])",
            )),
        }
    }
}
