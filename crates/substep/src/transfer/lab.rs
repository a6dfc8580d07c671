//! The virtual lab: actuators on the coupling DOFs, specimens attached to them, force and
//! displacement sensors. It is the simulated counterpart of a real test rig and implements
//! [`ExperimentalSubstructure`] like a remote site would.
//!
//! [`LabOptions`] add what a lab adds around the actuators: a D/A converter on each command
//! (quantise then saturate, before the actuator) and the force built from the measured motion
//! (`force = "from_motion"`): `f = −(k x + c D1 + m (D2 + a_g))` from backward differences of
//! the displacement `x` the actuator reached at the sub-step samples ([`DifferenceForce`]; the
//! benchmark's load cell, which differentiates the noise-free motion), then passed through the
//! force sensor (its noise, filter, A/D), instead of the specimen model's force.

use super::converter::Converter;
use super::servo::DifferenceForce;
use super::{Actuator, ActuatorSpec, Sensor, SensorSpec};
use crate::error::{Error, Result, require_positive};
use crate::specimen::{Motion, Specimen, SpecimenSpec};
use crate::substructure::ExperimentalSubstructure;

/// A specimen with the coupling-DOF indices (0-based positions in the coupling set) it is
/// attached to, in the specimen's own DOF order.
pub struct AttachedSpecimen {
    pub specimen: Box<dyn Specimen>,
    pub coupling_index: Vec<usize>,
}

/// How the lab measures force and converts commands (see the module docs).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LabOptions {
    /// D/A converter on every actuator command.
    pub command_converter: Option<Converter>,
    /// Build the force from the measured motion instead of taking the specimen model's force.
    pub force_from_motion: bool,
}

pub struct VirtualLab {
    actuators: Vec<Actuator>,
    command_converter: Option<Converter>,
    /// Per coupling DOF, with `force = "from_motion"`: the difference load cell and the mass
    /// (for its earthquake load `m a_g`).
    force_from_motion: Option<Vec<(DifferenceForce, f64)>>,
    command_da: Vec<f64>,
    specimens: Vec<AttachedSpecimen>,
    force_sensors: Vec<Sensor>,
    disp_sensors: Vec<Sensor>,
    inner_steps: usize,
    /// Command at the end of the previous sub-step (start of the command ramp).
    command_prev: Vec<f64>,
    /// Achieved displacements at the start / end of the current inner interval.
    achieved_start: Vec<f64>,
    achieved_end: Vec<f64>,
    command_inner: Vec<f64>,
    true_force: Vec<f64>,
    scratch_start: Vec<f64>,
    scratch_end: Vec<f64>,
    scratch_force: Vec<f64>,
}

impl VirtualLab {
    /// `actuators[i]`, `force_sensors[i]`, `disp_sensors[i]` belong to coupling DOF `i`.
    /// `dt_substep` is the nominal sub-step length; `inner_steps` the number of inner intervals
    /// per sub-step on which actuators and specimens are advanced (≥ 1).
    pub fn new(
        actuators: &[ActuatorSpec],
        specimens: Vec<AttachedSpecimen>,
        force_sensors: &[SensorSpec],
        disp_sensors: &[SensorSpec],
        dt_substep: f64,
        inner_steps: usize,
    ) -> Result<Self> {
        let n_c = actuators.len();
        Self::with_options(
            actuators,
            specimens,
            &vec![None; n_c],
            force_sensors,
            disp_sensors,
            dt_substep,
            inner_steps,
            &LabOptions::default(),
        )
    }

    /// [`Self::new`] with `plants[i]`, the `[m, c, k]` of the specimen at coupling DOF `i` (for
    /// actuators whose plant contains the specimen, and for `force_from_motion`), and options.
    #[allow(clippy::too_many_arguments)]
    pub fn with_options(
        actuators: &[ActuatorSpec],
        specimens: Vec<AttachedSpecimen>,
        plants: &[Option<[f64; 3]>],
        force_sensors: &[SensorSpec],
        disp_sensors: &[SensorSpec],
        dt_substep: f64,
        inner_steps: usize,
        options: &LabOptions,
    ) -> Result<Self> {
        let n_c = actuators.len();
        if plants.len() != n_c {
            return Err(Error::invalid(
                "lab",
                format!("need one plant entry per coupling DOF ({n_c})"),
            ));
        }
        require_positive("sub-step length", dt_substep)?;
        if inner_steps == 0 {
            return Err(Error::invalid("substructure.inner_steps", "must be at least 1"));
        }
        if force_sensors.len() != n_c || disp_sensors.len() != n_c {
            return Err(Error::invalid(
                "sensors",
                format!("need one force and one displacement sensor per coupling DOF ({n_c})"),
            ));
        }
        let mut attached_count = vec![0usize; n_c];
        let mut max_dofs = 0;
        for (k, s) in specimens.iter().enumerate() {
            if s.coupling_index.len() != s.specimen.n_dofs() {
                return Err(Error::invalid(
                    format!("substructure.specimen[{}]", k + 1),
                    format!(
                        "is attached to {} DOFs but the {} specimen has {}",
                        s.coupling_index.len(),
                        s.specimen.kind(),
                        s.specimen.n_dofs()
                    ),
                ));
            }
            for &i in &s.coupling_index {
                if i >= n_c {
                    return Err(Error::invalid(
                        format!("substructure.specimen[{}].dof", k + 1),
                        "is not one of substructure.coupling_dofs",
                    ));
                }
                attached_count[i] += 1;
            }
            max_dofs = max_dofs.max(s.coupling_index.len());
        }
        let dt_inner = dt_substep / inner_steps as f64;
        let actuators = actuators
            .iter()
            .zip(plants)
            .map(|(a, p)| a.build_with_plant(dt_inner, *p))
            .collect::<Result<Vec<_>>>()?;
        let force_from_motion = if options.force_from_motion {
            let mut cells = Vec::with_capacity(n_c);
            for (i, p) in plants.iter().enumerate() {
                let [m, c, k] = p.ok_or_else(|| {
                    Error::invalid(
                        "substructure.force",
                        format!(
                            "from_motion needs one lumped_sdof (or massless linear_sdof) specimen alone at coupling DOF #{}",
                            i + 1
                        ),
                    )
                })?;
                cells.push((DifferenceForce::new(m, c, k, dt_substep), m));
            }
            Some(cells)
        } else {
            None
        };
        let force_sensors = force_sensors
            .iter()
            .map(|s| s.build("sensors.force"))
            .collect::<Result<Vec<_>>>()?;
        let disp_sensors = disp_sensors
            .iter()
            .map(|s| s.build("sensors.displacement"))
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            actuators,
            command_converter: options.command_converter,
            force_from_motion,
            command_da: vec![0.0; n_c],
            specimens,
            force_sensors,
            disp_sensors,
            inner_steps,
            command_prev: vec![0.0; n_c],
            achieved_start: vec![0.0; n_c],
            achieved_end: vec![0.0; n_c],
            command_inner: vec![0.0; n_c],
            true_force: vec![0.0; n_c],
            scratch_start: vec![0.0; max_dofs],
            scratch_end: vec![0.0; max_dofs],
            scratch_force: vec![0.0; max_dofs],
        })
    }

    /// Build from specimen descriptions attached to model DOFs; `coupling_dofs` (0-based model
    /// DOFs) fixes the order of actuators and sensors.
    pub fn from_specs(
        coupling_dofs: &[usize],
        specimens: &[SpecimenSpec],
        actuators: &[ActuatorSpec],
        force_sensors: &[SensorSpec],
        disp_sensors: &[SensorSpec],
        dt_substep: f64,
        inner_steps: usize,
    ) -> Result<Self> {
        Self::from_specs_with(
            coupling_dofs,
            specimens,
            actuators,
            force_sensors,
            disp_sensors,
            dt_substep,
            inner_steps,
            &LabOptions::default(),
        )
    }

    /// [`Self::from_specs`] with options; the `[m, c, k]` of a coupling DOF is that of its
    /// specimen when exactly one specimen with [`SpecimenSpec::lumped_mck`] is attached there.
    #[allow(clippy::too_many_arguments)]
    pub fn from_specs_with(
        coupling_dofs: &[usize],
        specimens: &[SpecimenSpec],
        actuators: &[ActuatorSpec],
        force_sensors: &[SensorSpec],
        disp_sensors: &[SensorSpec],
        dt_substep: f64,
        inner_steps: usize,
        options: &LabOptions,
    ) -> Result<Self> {
        let n_c = coupling_dofs.len();
        let mut plants: Vec<Option<[f64; 3]>> = vec![None; n_c];
        let mut count = vec![0usize; n_c];
        for spec in specimens {
            for dof in spec.dofs() {
                if let Some(i) = coupling_dofs.iter().position(|&c| c == dof) {
                    count[i] += 1;
                    plants[i] = spec.lumped_mck();
                }
            }
        }
        for (p, &c) in plants.iter_mut().zip(&count) {
            if c != 1 {
                *p = None;
            }
        }
        let mut attached = Vec::with_capacity(specimens.len());
        for (k, spec) in specimens.iter().enumerate() {
            let mut coupling_index = Vec::new();
            for dof in spec.dofs() {
                let i = coupling_dofs.iter().position(|&c| c == dof).ok_or_else(|| {
                    Error::invalid(
                        format!("substructure.specimen[{}].dof", k + 1),
                        format!("DOF {} is not one of substructure.coupling_dofs", dof + 1),
                    )
                })?;
                coupling_index.push(i);
            }
            // `specimen.mass` → `substructure.specimen[k].mass`; a bare `specimen` (e.g. unstable
            // internal dynamics) → `substructure.specimen[k]`.
            let prefix = |what: String| match what.strip_prefix("specimen") {
                Some(rest) if rest.is_empty() || rest.starts_with('.') => {
                    format!("substructure.specimen[{}]{rest}", k + 1)
                }
                _ => format!("substructure.specimen[{}].{what}", k + 1),
            };
            let specimen = spec.build().map_err(|e| match e {
                Error::InvalidInput { what, reason } => Error::invalid(prefix(what), reason),
                Error::Numerical { what, reason } => Error::numerical(prefix(what), reason),
                other => other,
            })?;
            attached.push(AttachedSpecimen {
                specimen,
                coupling_index,
            });
        }
        Self::with_options(
            actuators,
            attached,
            &plants,
            force_sensors,
            disp_sensors,
            dt_substep,
            inner_steps,
            options,
        )
    }

    pub fn actuators(&self) -> &[Actuator] {
        &self.actuators
    }

    /// Force on the structure before noise and quantisation, at the end of the last sub-step.
    pub fn true_force(&self) -> &[f64] {
        &self.true_force
    }
    /// Displacement achieved by each actuator at the end of the last sub-step.
    pub fn achieved(&self) -> &[f64] {
        &self.achieved_start
    }
    pub fn specimens(&self) -> &[AttachedSpecimen] {
        &self.specimens
    }
}

impl ExperimentalSubstructure for VirtualLab {
    fn n_coupling(&self) -> usize {
        self.actuators.len()
    }

    fn substep(
        &mut self,
        command: &[f64],
        ag: (f64, f64),
        dtau: f64,
        force: &mut [f64],
        displacement: &mut [f64],
    ) -> Result<()> {
        let h = dtau / self.inner_steps as f64;
        let command = match &self.command_converter {
            Some(c) => {
                for (o, &u) in self.command_da.iter_mut().zip(command) {
                    *o = c.da(u);
                }
                &self.command_da[..]
            }
            None => command,
        };
        for s in 0..self.inner_steps {
            let r0 = s as f64 / self.inner_steps as f64;
            let r1 = (s + 1) as f64 / self.inner_steps as f64;
            for (i, actuator) in self.actuators.iter_mut().enumerate() {
                self.command_inner[i] = self.command_prev[i] + r1 * (command[i] - self.command_prev[i]);
                self.achieved_end[i] = actuator.advance(self.command_inner[i], h);
            }
            let ag_start = ag.0 + r0 * (ag.1 - ag.0);
            let ag_end = ag.0 + r1 * (ag.1 - ag.0);
            self.true_force.iter_mut().for_each(|f| *f = 0.0);
            for att in &mut self.specimens {
                let m = att.coupling_index.len();
                for (k, &i) in att.coupling_index.iter().enumerate() {
                    self.scratch_start[k] = self.achieved_start[i];
                    self.scratch_end[k] = self.achieved_end[i];
                }
                let motion = Motion {
                    d_start: &self.scratch_start[..m],
                    d_end: &self.scratch_end[..m],
                    ag_start,
                    ag_end,
                    dt: h,
                };
                att.specimen.advance(&motion, &mut self.scratch_force[..m]);
                att.specimen.commit();
                for (k, &i) in att.coupling_index.iter().enumerate() {
                    self.true_force[i] += self.scratch_force[k];
                }
            }
            std::mem::swap(&mut self.achieved_start, &mut self.achieved_end);
        }
        self.command_prev.copy_from_slice(command);
        for i in 0..self.actuators.len() {
            let f = match &mut self.force_from_motion {
                Some(cells) => {
                    let (cell, m) = &mut cells[i];
                    -(cell.force(self.achieved_start[i]) + *m * ag.1)
                }
                None => self.true_force[i],
            };
            force[i] = self.force_sensors[i].measure(f, dtau);
            displacement[i] = self.disp_sensors[i].measure(self.achieved_start[i], dtau);
        }
        Ok(())
    }

    fn true_force(&self) -> Option<&[f64]> {
        Some(&self.true_force)
    }
    fn true_displacement(&self) -> Option<&[f64]> {
        Some(&self.achieved_start)
    }

    fn is_linear(&self) -> Result<()> {
        for (k, s) in self.specimens.iter().enumerate() {
            if !s.specimen.is_linear() {
                return Err(Error::invalid(
                    format!("substructure.specimen[{}]", k + 1),
                    format!(
                        "the {} specimen is nonlinear; the linear analysis needs linear specimens",
                        s.specimen.kind()
                    ),
                ));
            }
        }
        if self
            .force_sensors
            .iter()
            .chain(&self.disp_sensors)
            .any(|s| !s.is_linear())
        {
            return Err(Error::invalid(
                "sensors",
                "noise and quantisation must be off for the linear analysis",
            ));
        }
        if self.command_converter.is_some() {
            return Err(Error::invalid(
                "substructure.actuator.da_quantum",
                "the D/A converter quantises; the linear analysis needs it off",
            ));
        }
        if self.force_from_motion.is_some() {
            return Err(Error::invalid(
                "substructure.force",
                "the linear analysis does not cover the difference load cell (from_motion); use force = \"model\"",
            ));
        }
        Ok(())
    }

    fn state_len(&self) -> usize {
        let n_c = self.actuators.len();
        3 * n_c
            + self.actuators.iter().map(Actuator::state_len).sum::<usize>()
            + self.specimens.iter().map(|s| s.specimen.state_len()).sum::<usize>()
    }

    fn write_state(&self, out: &mut [f64]) {
        let n_c = self.actuators.len();
        out[0..n_c].copy_from_slice(&self.command_prev);
        out[n_c..2 * n_c].copy_from_slice(&self.achieved_start);
        for (i, f) in self.force_sensors.iter().enumerate() {
            out[2 * n_c + i] = f.filter_state();
        }
        let mut at = 3 * n_c;
        for a in &self.actuators {
            let l = a.state_len();
            a.write_state(&mut out[at..at + l]);
            at += l;
        }
        for s in &self.specimens {
            let l = s.specimen.state_len();
            s.specimen.write_state(&mut out[at..at + l]);
            at += l;
        }
    }

    fn read_state(&mut self, s: &[f64]) {
        let n_c = self.actuators.len();
        self.command_prev.copy_from_slice(&s[0..n_c]);
        self.achieved_start.copy_from_slice(&s[n_c..2 * n_c]);
        for (i, f) in self.force_sensors.iter_mut().enumerate() {
            f.set_filter_state(s[2 * n_c + i]);
        }
        let mut at = 3 * n_c;
        for a in &mut self.actuators {
            let l = a.state_len();
            a.read_state(&s[at..at + l]);
            at += l;
        }
        for sp in &mut self.specimens {
            let l = sp.specimen.state_len();
            sp.specimen.read_state(&s[at..at + l]);
            at += l;
        }
    }
}
