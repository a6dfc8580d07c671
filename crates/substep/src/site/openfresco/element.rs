//! What the OpenFresco server hosts: the [`ElementSite`] trait, [`LinearElement`],
//! [`SubstructureElement`] and their description [`ElementSpec`].

use super::*;

/// What the OpenFresco server hosts: an element with `n` DOFs in the client's DOF order.
pub trait ElementSite: Send {
    /// Short description for the log (e.g. `linear_element`).
    fn kind(&self) -> String;
    fn n_dofs(&self) -> usize;
    /// Action 3: impose a trial response. Blocks the client does not send are `None`.
    fn set_trial(&mut self, disp: &[f64], vel: Option<&[f64]>, accel: Option<&[f64]>, time: Option<f64>) -> Result<()>;
    /// Action 5: the trial state is accepted.
    fn commit(&mut self) -> Result<()>;
    /// The measured (DAQ) response at the trial state.
    fn disp(&self) -> &[f64];
    fn vel(&self) -> &[f64];
    fn accel(&self) -> &[f64];
    /// The element's resisting force `p` (OpenSees' sign).
    fn force(&self) -> &[f64];
    fn time(&self) -> f64;
    /// `n × n` matrices, column-major, into `out` (`n²` entries).
    fn initial_stiffness(&self, out: &mut [f64]);
    fn tangent_stiffness(&self, out: &mut [f64]);
    fn damping(&self, out: &mut [f64]);
    fn mass(&self, out: &mut [f64]);
}
pub(super) fn check_matrix(name: &str, m: &DMatrix<f64>, n: usize) -> Result<()> {
    if m.nrows() != n || m.ncols() != n {
        return Err(Error::invalid(
            name,
            format!("must be {n}x{n}, got {}x{}", m.nrows(), m.ncols()),
        ));
    }
    if m.iter().any(|x| !x.is_finite()) {
        return Err(Error::invalid(name, "contains a non-finite value"));
    }
    Ok(())
}

/// Kinematic state shared by the element implementations.
#[derive(Debug, Clone)]
pub(super) struct Trial {
    disp: Vec<f64>,
    vel: Vec<f64>,
    accel: Vec<f64>,
    force: Vec<f64>,
    time: f64,
}

impl Trial {
    fn zeros(n: usize) -> Self {
        Trial {
            disp: vec![0.0; n],
            vel: vec![0.0; n],
            accel: vec![0.0; n],
            force: vec![0.0; n],
            time: 0.0,
        }
    }
}

/// `kind = "linear_element"`: `p = K u + C v` on the element DOFs (`u`, `v` the trial
/// displacement and velocity the client sends; without a velocity block, `v` is the backward
/// difference from the committed state).
///
/// With `damping_to_client = false` (default) the damping force is part of `p` (what a load
/// cell measures) and action 14 returns a zero matrix. OpenSees' `genericClient` adds
/// `C_reported v` to `p` itself and uses `C_reported` in its tangent, so with
/// `damping_to_client = true` the server returns `p = K u` and reports `C` for action 14: that
/// reproduces a native OpenSees element with the same `K`, `C` exactly (also with
/// `algorithm Linear`). The optional mass is only reported (action 15), never in `p`.
pub struct LinearElement {
    n: usize,
    stiffness: DMatrix<f64>,
    damping: DMatrix<f64>,
    mass: DMatrix<f64>,
    damping_to_client: bool,
    trial: Trial,
    committed: Trial,
}

impl LinearElement {
    pub fn new(
        stiffness: DMatrix<f64>,
        damping: Option<DMatrix<f64>>,
        mass: Option<DMatrix<f64>>,
        damping_to_client: bool,
    ) -> Result<Self> {
        let n = stiffness.nrows();
        if n == 0 || n > MAX_DOFS {
            return Err(Error::invalid(
                "element.stiffness",
                format!("must be n x n with 1 <= n <= {MAX_DOFS}"),
            ));
        }
        check_matrix("element.stiffness", &stiffness, n)?;
        let damping = damping.unwrap_or_else(|| DMatrix::zeros(n, n));
        check_matrix("element.damping", &damping, n)?;
        let mass = mass.unwrap_or_else(|| DMatrix::zeros(n, n));
        check_matrix("element.mass", &mass, n)?;
        Ok(Self {
            n,
            stiffness,
            damping,
            mass,
            damping_to_client,
            trial: Trial::zeros(n),
            committed: Trial::zeros(n),
        })
    }

    fn copy_matrix(m: &DMatrix<f64>, out: &mut [f64]) {
        out.copy_from_slice(m.as_slice());
    }
}

impl ElementSite for LinearElement {
    fn kind(&self) -> String {
        "linear_element".into()
    }
    fn n_dofs(&self) -> usize {
        self.n
    }
    fn set_trial(&mut self, disp: &[f64], vel: Option<&[f64]>, accel: Option<&[f64]>, time: Option<f64>) -> Result<()> {
        let n = self.n;
        self.trial.disp.copy_from_slice(disp);
        self.trial.time = time.unwrap_or(self.committed.time);
        match vel {
            Some(v) => self.trial.vel.copy_from_slice(v),
            None => {
                let dt = self.trial.time - self.committed.time;
                for ((v, d), d0) in self.trial.vel.iter_mut().zip(disp).zip(&self.committed.disp) {
                    *v = if dt > 0.0 { (d - d0) / dt } else { 0.0 };
                }
            }
        }
        match accel {
            Some(a) => self.trial.accel.copy_from_slice(a),
            None => self.trial.accel.iter_mut().for_each(|a| *a = 0.0),
        }
        for i in 0..n {
            let mut p = 0.0;
            for j in 0..n {
                p += self.stiffness[(i, j)] * self.trial.disp[j];
            }
            if !self.damping_to_client {
                for j in 0..n {
                    p += self.damping[(i, j)] * self.trial.vel[j];
                }
            }
            self.trial.force[i] = p;
        }
        Ok(())
    }
    fn commit(&mut self) -> Result<()> {
        self.committed.clone_from(&self.trial);
        Ok(())
    }
    fn disp(&self) -> &[f64] {
        &self.trial.disp
    }
    fn vel(&self) -> &[f64] {
        &self.trial.vel
    }
    fn accel(&self) -> &[f64] {
        &self.trial.accel
    }
    fn force(&self) -> &[f64] {
        &self.trial.force
    }
    fn time(&self) -> f64 {
        self.trial.time
    }
    fn initial_stiffness(&self, out: &mut [f64]) {
        Self::copy_matrix(&self.stiffness, out);
    }
    fn tangent_stiffness(&self, out: &mut [f64]) {
        Self::copy_matrix(&self.stiffness, out);
    }
    fn damping(&self, out: &mut [f64]) {
        if self.damping_to_client {
            Self::copy_matrix(&self.damping, out);
        } else {
            out.iter_mut().for_each(|x| *x = 0.0);
        }
    }
    fn mass(&self, out: &mut [f64]) {
        Self::copy_matrix(&self.mass, out);
    }
}

/// Any [`ExperimentalSubstructure`] on the element DOFs (coupling DOF `i` = element DOF `i`).
///
/// A trial (action 3) restores the committed state of the substructure (`read_state`) and
/// runs one sub-step from the committed to the trial displacement over the time increment
/// `Δt = t_trial − t_committed` (the client's time block; without one, `default_dt`), with zero
/// ground acceleration. Repeated trials within a step (Newton iterations) therefore start from
/// the same state; commit (action 5) saves it (`write_state`). A trial with no time increment
/// and no motion returns the committed force; a motion without a time increment uses the last
/// positive increment (or `default_dt`). The DAQ force is `p = −f_c` (the substructure reports
/// the force on the structure). Actions 12/13 return `stiffness` (for a linear specimen the
/// attached-DOF block of its stiffness), 14 and 15 zero: damping and inertia of the specimen
/// are in the measured force.
pub struct SubstructureElement {
    site: Box<dyn ExperimentalSubstructure>,
    kind: String,
    n: usize,
    stiffness: DMatrix<f64>,
    default_dt: f64,
    last_dt: Option<f64>,
    state: Vec<f64>,
    measured: Vec<f64>,
    measured_committed: Vec<f64>,
    raw_force: Vec<f64>,
    trial: Trial,
    committed: Trial,
}

impl SubstructureElement {
    pub fn new(
        site: Box<dyn ExperimentalSubstructure>,
        kind: impl Into<String>,
        stiffness: DMatrix<f64>,
        default_dt: f64,
    ) -> Result<Self> {
        let n = site.n_coupling();
        check_matrix("element.stiffness", &stiffness, n)?;
        crate::error::require_positive("element.default_dt", default_dt)?;
        let mut state = vec![0.0; site.state_len()];
        site.write_state(&mut state);
        Ok(Self {
            site,
            kind: kind.into(),
            n,
            stiffness,
            default_dt,
            last_dt: None,
            state,
            measured: vec![0.0; n],
            measured_committed: vec![0.0; n],
            raw_force: vec![0.0; n],
            trial: Trial::zeros(n),
            committed: Trial::zeros(n),
        })
    }

    /// A specimen on the element DOFs (in the specimen's DOF order) behind ideal actuators and
    /// sensors, e.g. `linear_sdof` with `mass = None` (a spring and dashpot to ground) on a
    /// 1-DOF element.
    pub fn from_specimen(spec: &SpecimenSpec, default_dt: f64) -> Result<Self> {
        let dofs = spec.dofs();
        let n = dofs.len();
        let lab = VirtualLab::from_specs(
            &dofs,
            std::slice::from_ref(spec),
            &vec![ActuatorSpec::ideal(); n],
            &vec![SensorSpec::ideal(); n],
            &vec![SensorSpec::ideal(); n],
            default_dt,
            1,
        )?;
        let stiffness = spec
            .linear_matrices()
            .map(|m| m.stiffness.view((0, 0), (n, n)).into_owned())
            .unwrap_or_else(|| DMatrix::zeros(n, n));
        Self::new(Box::new(lab), spec.kind(), stiffness, default_dt)
    }
}

impl ElementSite for SubstructureElement {
    fn kind(&self) -> String {
        self.kind.clone()
    }
    fn n_dofs(&self) -> usize {
        self.n
    }
    fn set_trial(&mut self, disp: &[f64], vel: Option<&[f64]>, accel: Option<&[f64]>, time: Option<f64>) -> Result<()> {
        let (t, mut dt) = match time {
            Some(t) => (t, t - self.committed.time),
            None => (self.committed.time + self.default_dt, self.default_dt),
        };
        self.trial.disp.copy_from_slice(disp);
        self.trial.time = t;
        if let Some(v) = vel {
            self.trial.vel.copy_from_slice(v);
        }
        if let Some(a) = accel {
            self.trial.accel.copy_from_slice(a);
        }
        self.site.read_state(&self.state);
        if dt.is_nan() || dt <= 0.0 {
            let moved = disp
                .iter()
                .zip(&self.committed.disp)
                .any(|(a, b)| a.to_bits() != b.to_bits());
            if !moved {
                self.trial.force.copy_from_slice(&self.committed.force);
                self.measured.copy_from_slice(&self.measured_committed);
                return Ok(());
            }
            dt = self.last_dt.unwrap_or(self.default_dt);
        }
        self.site
            .substep(disp, (0.0, 0.0), dt, &mut self.raw_force, &mut self.measured)?;
        self.last_dt = Some(dt);
        for i in 0..self.n {
            self.trial.force[i] = -self.raw_force[i];
        }
        Ok(())
    }
    fn commit(&mut self) -> Result<()> {
        self.site.write_state(&mut self.state);
        self.committed.clone_from(&self.trial);
        self.measured_committed.copy_from_slice(&self.measured);
        Ok(())
    }
    fn disp(&self) -> &[f64] {
        &self.measured
    }
    fn vel(&self) -> &[f64] {
        &self.trial.vel
    }
    fn accel(&self) -> &[f64] {
        &self.trial.accel
    }
    fn force(&self) -> &[f64] {
        &self.trial.force
    }
    fn time(&self) -> f64 {
        self.trial.time
    }
    fn initial_stiffness(&self, out: &mut [f64]) {
        out.copy_from_slice(self.stiffness.as_slice());
    }
    fn tangent_stiffness(&self, out: &mut [f64]) {
        out.copy_from_slice(self.stiffness.as_slice());
    }
    fn damping(&self, out: &mut [f64]) {
        out.iter_mut().for_each(|x| *x = 0.0);
    }
    fn mass(&self, out: &mut [f64]) {
        out.iter_mut().for_each(|x| *x = 0.0);
    }
}

/// An element description (what a config file gives).
#[derive(Debug, Clone, PartialEq)]
pub enum ElementSpec {
    /// `kind = "linear_element"`, see [`LinearElement`].
    LinearElement {
        stiffness: DMatrix<f64>,
        damping: Option<DMatrix<f64>>,
        mass: Option<DMatrix<f64>>,
        damping_to_client: bool,
    },
    /// One of the specimens (`linear_sdof`, `linear_mdof`), see
    /// [`SubstructureElement::from_specimen`].
    Specimen { spec: SpecimenSpec, default_dt: f64 },
}

impl ElementSpec {
    pub fn kind(&self) -> &'static str {
        match self {
            ElementSpec::LinearElement { .. } => "linear_element",
            ElementSpec::Specimen { spec, .. } => spec.kind(),
        }
    }
    pub fn n_dofs(&self) -> usize {
        match self {
            ElementSpec::LinearElement { stiffness, .. } => stiffness.nrows(),
            ElementSpec::Specimen { spec, .. } => spec.dofs().len(),
        }
    }
    pub fn build(&self) -> Result<Box<dyn ElementSite>> {
        Ok(match self {
            ElementSpec::LinearElement {
                stiffness,
                damping,
                mass,
                damping_to_client,
            } => Box::new(LinearElement::new(
                stiffness.clone(),
                damping.clone(),
                mass.clone(),
                *damping_to_client,
            )?),
            ElementSpec::Specimen { spec, default_dt } => {
                Box::new(SubstructureElement::from_specimen(spec, *default_dt)?)
            }
        })
    }
}
