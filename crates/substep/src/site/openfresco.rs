//! The OpenFresco / OpenSees `genericClient` protocol (docs/theory.md §10.2; use: `docs/openfresco.md`).
//!
//! * [`OpenFrescoServer`] serves as a SimAppSiteServer for OpenSees' `genericClient` element (or
//!   any OpenFresco generic client): the client sends 11 `i32` sizes, then every message in
//!   both directions is `data_size` `f64` (little-endian), slot 0 of a request being the action
//!   code. The hosted thing is an [`ElementSite`]: [`LinearElement`] (`p = K u + C v`) or
//!   [`SubstructureElement`], which runs any [`ExperimentalSubstructure`] (e.g. a
//!   [`VirtualLab`] with a specimen from [`SpecimenSpec`]) on the element DOFs.
//! * [`OpenFrescoSite`] is a client of such a server (as OpenFresco's generic TCP experimental
//!   control would be) and implements [`ExperimentalSubstructure`], so `substep` can drive an
//!   OpenFresco-style site.
//!
//! Sign convention: on this protocol the force is the element's **resisting force** `p`
//! (OpenSees' sign: a spring `k` to ground gives `p = k u`). `substep`'s coupling force is the
//! force **on** the numerical substructure, `f_c = −p`; [`SubstructureElement`] and
//! [`OpenFrescoSite`] convert.

use super::server::{Flow, ServeOptions, ServeReport, ServerHandle, serve_tcp_sessions};
use super::transport::{LinkError, quick_ack, read_full, write_all};
use crate::error::{Error, Result};
use crate::specimen::SpecimenSpec;
use crate::substructure::ExperimentalSubstructure;
use crate::transfer::{ActuatorSpec, SensorSpec, VirtualLab};
use nalgebra::DMatrix;
use std::net::{SocketAddr, TcpListener, TcpStream, ToSocketAddrs};
use std::time::{Duration, Instant};

/// Action codes (slot 0 of a request).
pub mod action {
    pub const OPEN: i32 = 1;
    pub const SETUP: i32 = 2;
    pub const SET_TRIAL_RESPONSE: i32 = 3;
    pub const EXECUTE: i32 = 4;
    pub const COMMIT_STATE: i32 = 5;
    pub const GET_DAQ_RESPONSE: i32 = 6;
    pub const GET_DISP: i32 = 7;
    pub const GET_VEL: i32 = 8;
    pub const GET_ACCEL: i32 = 9;
    pub const GET_FORCE: i32 = 10;
    pub const GET_TIME: i32 = 11;
    pub const GET_INITIAL_STIFF: i32 = 12;
    pub const GET_TANGENT_STIFF: i32 = 13;
    pub const GET_DAMP: i32 = 14;
    pub const GET_MASS: i32 = 15;
    pub const SHUTDOWN: i32 = 98;
    pub const DISCONNECT: i32 = 99;
}

/// Number of `i32` in the sizes message.
pub const SIZES_LEN: usize = 11;
/// Largest `data_size` accepted [f64 per message].
pub const MAX_DATA_SIZE: usize = 1 << 20;
/// Largest number of element DOFs accepted.
pub const MAX_DOFS: usize = 1024;

/// Block order of the control and DAQ vectors.
pub const DISP: usize = 0;
pub const VEL: usize = 1;
pub const ACCEL: usize = 2;
pub const FORCE: usize = 3;
pub const TIME: usize = 4;

const SIZE_NAMES: [&str; SIZES_LEN] = [
    "ctrl_disp",
    "ctrl_vel",
    "ctrl_accel",
    "ctrl_force",
    "ctrl_time",
    "daq_disp",
    "daq_vel",
    "daq_accel",
    "daq_force",
    "daq_time",
    "data_size",
];

fn oerr(what: impl AsRef<str>, reason: impl Into<String>) -> Error {
    Error::invalid(format!("openfresco: {}", what.as_ref()), reason)
}

/// The sizes message: control and DAQ block sizes (disp, vel, accel, force, time) and the
/// number of `f64` in every later message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sizes {
    pub ctrl: [usize; 5],
    pub daq: [usize; 5],
    pub data_size: usize,
}

impl Sizes {
    /// What OpenSees' `genericClient` with `n` element DOFs sends:
    /// `[n, n, n, 0, 1, 0, 0, 0, n, 0, max(data_size, 3n + 2, n²)]` (its default `data_size`
    /// is 256).
    pub fn generic_client(n: usize, data_size: usize) -> Self {
        Self {
            ctrl: [n, n, n, 0, 1],
            daq: [0, 0, 0, n, 0],
            data_size: data_size.max(3 * n + 2).max(n * n),
        }
    }

    /// What [`OpenFrescoSite`] sends: control displacement and time, DAQ displacement and force.
    pub fn substep_client(n: usize) -> Self {
        Self {
            ctrl: [n, 0, 0, 0, 1],
            daq: [n, 0, 0, n, 0],
            data_size: 256usize.max(n + 2).max(2 * n).max(n * n),
        }
    }

    /// Number of element DOFs (the control displacement size).
    pub fn n_dofs(&self) -> usize {
        self.ctrl[DISP]
    }

    fn values(&self) -> [usize; SIZES_LEN] {
        let mut v = [0; SIZES_LEN];
        v[..5].copy_from_slice(&self.ctrl);
        v[5..10].copy_from_slice(&self.daq);
        v[10] = self.data_size;
        v
    }

    pub fn encode(&self) -> [u8; 4 * SIZES_LEN] {
        let mut out = [0u8; 4 * SIZES_LEN];
        for (i, v) in self.values().iter().enumerate() {
            out[4 * i..4 * i + 4].copy_from_slice(&(*v as i32).to_le_bytes());
        }
        out
    }

    /// Decode and validate the 44-byte sizes message.
    pub fn decode(bytes: &[u8]) -> Result<Self> {
        if bytes.len() != 4 * SIZES_LEN {
            return Err(oerr(
                "sizes",
                format!("{} bytes, expected {}", bytes.len(), 4 * SIZES_LEN),
            ));
        }
        let mut v = [0usize; SIZES_LEN];
        for i in 0..SIZES_LEN {
            let x = i32::from_le_bytes([bytes[4 * i], bytes[4 * i + 1], bytes[4 * i + 2], bytes[4 * i + 3]]);
            if x < 0 {
                return Err(oerr(
                    format!("sizes.{}", SIZE_NAMES[i]),
                    format!("is {x}, must be >= 0"),
                ));
            }
            v[i] = x as usize;
        }
        let mut s = Sizes {
            ctrl: [0; 5],
            daq: [0; 5],
            data_size: v[10],
        };
        s.ctrl.copy_from_slice(&v[..5]);
        s.daq.copy_from_slice(&v[5..10]);
        s.validate()?;
        Ok(s)
    }

    /// Check the sizes: `n = ctrl_disp` in `1..=MAX_DOFS`; every other block 0 or `n` (time 0
    /// or 1); `data_size` large enough for a request, a DAQ reply and an `n × n` matrix.
    pub fn validate(&self) -> Result<()> {
        let n = self.n_dofs();
        if n == 0 || n > MAX_DOFS {
            return Err(oerr("sizes.ctrl_disp", format!("is {n}, must be 1..={MAX_DOFS}")));
        }
        let v = self.values();
        for (i, &x) in v.iter().enumerate().take(10) {
            let ok = if i % 5 == TIME { x <= 1 } else { x == 0 || x == n };
            if !ok {
                let allowed = if i % 5 == TIME {
                    "0 or 1".to_string()
                } else {
                    format!("0 or {n} (ctrl_disp)")
                };
                return Err(oerr(
                    format!("sizes.{}", SIZE_NAMES[i]),
                    format!("is {x}, must be {allowed}"),
                ));
            }
        }
        let need = (1 + self.ctrl.iter().sum::<usize>())
            .max(self.daq.iter().sum::<usize>())
            .max(n * n);
        if self.data_size < need || self.data_size > MAX_DATA_SIZE {
            return Err(oerr(
                "sizes.data_size",
                format!("is {}, must be in {need}..={MAX_DATA_SIZE}", self.data_size),
            ));
        }
        Ok(())
    }
}

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

fn check_matrix(name: &str, m: &DMatrix<f64>, n: usize) -> Result<()> {
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
struct Trial {
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

/// The OpenFresco-compatible site server (one client at a time).
pub struct OpenFrescoServer;

impl OpenFrescoServer {
    /// Serve `genericClient`-style clients on `listener` until a `once` session ends, a client
    /// sends action 98 (shutdown) or the stop flag is raised. The factory builds the element
    /// from the client's sizes; a client whose `n` differs from the element's is dropped.
    pub fn serve(
        listener: TcpListener,
        mut factory: impl FnMut(&Sizes) -> Result<Box<dyn ElementSite>>,
        options: &ServeOptions,
    ) -> Result<ServeReport> {
        let local = listener
            .local_addr()
            .map_err(|e| Error::invalid("openfresco server", e.to_string()))?;
        // The protocol has no way to say "busy": a second client is disconnected at once.
        serve_tcp_sessions(listener, options, "openfresco", drop, |stream, peer, report| {
            let (opened, shutdown) = serve_connection(stream, peer, &mut factory, options, report);
            if shutdown {
                options.log(&format!("openfresco: tcp://{local} shut down by {peer} (action 98)"));
            }
            Flow { opened, shutdown }
        })
    }

    /// [`OpenFrescoServer::serve`] in a new thread.
    pub fn spawn(
        listener: TcpListener,
        factory: impl FnMut(&Sizes) -> Result<Box<dyn ElementSite>> + Send + 'static,
        options: &ServeOptions,
    ) -> Result<ServerHandle> {
        let addr = listener
            .local_addr()
            .map_err(|e| Error::invalid("openfresco server", e.to_string()))?;
        ServerHandle::start(addr, options, move |o| Self::serve(listener, factory, &o))
    }
}

fn f64s_from_le(bytes: &[u8], out: &mut [f64]) {
    for (x, c) in out.iter_mut().zip(bytes.chunks_exact(8)) {
        *x = f64::from_le_bytes(c.try_into().expect("chunks of 8"));
    }
}

fn f64s_to_le(values: &[f64], out: &mut [u8]) {
    for (x, c) in values.iter().zip(out.chunks_exact_mut(8)) {
        c.copy_from_slice(&x.to_le_bytes());
    }
}

/// Read an action code from slot 0.
fn action_code(x: f64) -> Option<i32> {
    if x.is_finite() && x.fract() == 0.0 && x.abs() <= i32::MAX as f64 {
        Some(x as i32)
    } else {
        None
    }
}

/// Serve one connection; returns (a session was opened, the client asked for shutdown).
fn serve_connection(
    mut stream: TcpStream,
    peer: SocketAddr,
    factory: &mut impl FnMut(&Sizes) -> Result<Box<dyn ElementSite>>,
    options: &ServeOptions,
    report: &mut ServeReport,
) -> (bool, bool) {
    let io = options.io_timeout;
    let stop = options.stop.as_deref();
    let _ = stream.set_nonblocking(false);
    let _ = stream.set_nodelay(true);
    let mut raw = [0u8; 4 * SIZES_LEN];
    if let Err(e) = read_full(
        &mut stream,
        &mut raw,
        ServeOptions::deadline(Some(options.handshake_timeout)),
        stop,
    ) {
        options.log(&format!("openfresco: {peer} rejected: no sizes message: {e}"));
        report.rejected += 1;
        return (false, false);
    }
    let sizes = match Sizes::decode(&raw) {
        Ok(s) => s,
        Err(e) => {
            options.log(&format!("openfresco: {peer} rejected: {e}"));
            report.rejected += 1;
            return (false, false);
        }
    };
    let mut site = match factory(&sizes) {
        Ok(s) if s.n_dofs() == sizes.n_dofs() => s,
        Ok(s) => {
            options.log(&format!(
                "openfresco: {peer} rejected: the client has {} element DOFs, the hosted {} has {}",
                sizes.n_dofs(),
                s.kind(),
                s.n_dofs()
            ));
            report.rejected += 1;
            return (false, false);
        }
        Err(e) => {
            options.log(&format!("openfresco: {peer} rejected: cannot build the element: {e}"));
            report.rejected += 1;
            return (false, false);
        }
    };
    report.sessions += 1;
    options.log(&format!(
        "openfresco: {peer} connected ({} DOFs, data_size {}, hosting {})",
        sizes.n_dofs(),
        sizes.data_size,
        site.kind()
    ));
    let n = sizes.n_dofs();
    let ds = sizes.data_size;
    let mut rx = vec![0u8; 8 * ds];
    let mut tx = vec![0u8; 8 * ds];
    let mut msg = vec![0.0; ds];
    let mut reply = vec![0.0; ds];
    let (mut trials, mut commits) = (0u64, 0u64);
    let mut shutdown = false;
    let end = loop {
        // The first 8 bytes (the action) may take as long as the client likes (or the idle
        // timeout); the rest of the message must follow within the I/O timeout.
        let idle = ServeOptions::deadline(options.idle_timeout);
        quick_ack(&stream);
        let got = read_full(&mut stream, &mut rx[..8], idle, stop).and_then(|_| {
            read_full(&mut stream, &mut rx[8..], ServeOptions::deadline(Some(io)), stop).map_err(|e| match e {
                LinkError::Closed { got } => LinkError::Closed { got: got + 8 },
                LinkError::TimedOut { got } => LinkError::TimedOut { got: got + 8 },
                e => e,
            })
        });
        match got {
            Ok(()) => {}
            Err(LinkError::Closed { got: 0 }) => break "client disconnected without action 99".to_string(),
            Err(LinkError::Stopped) => break "server stopped; connection dropped".to_string(),
            Err(e) => {
                report.errors += 1;
                break format!("reading a message: {e}");
            }
        }
        f64s_from_le(&rx, &mut msg);
        let Some(code) = action_code(msg[0]) else {
            report.errors += 1;
            break format!("slot 0 = {} is not an action code", msg[0]);
        };
        let reply_len = match code {
            action::OPEN | action::SETUP | action::EXECUTE => None,
            action::SET_TRIAL_RESPONSE => {
                let mut at = 1;
                let mut blocks: [Option<&[f64]>; 5] = [None; 5];
                for (b, block) in blocks.iter_mut().enumerate() {
                    let len = sizes.ctrl[b];
                    if len > 0 {
                        *block = Some(&msg[at..at + len]);
                        at += len;
                    }
                }
                if let Some(i) = msg[1..at].iter().position(|x| !x.is_finite()) {
                    report.errors += 1;
                    break format!(
                        "setTrialResponse: control value {} is not finite ({})",
                        i + 1,
                        msg[1 + i]
                    );
                }
                let time = blocks[TIME].map(|t| t[0]);
                // The time increment sizes the specimen's integration step (its matrix
                // exponential): bounded like a substep client's dt.
                if let Some(t) = time
                    && t - site.time() > options.limits.max_dt
                {
                    report.errors += 1;
                    break format!(
                        "setTrialResponse: trial time {t:e} s is {:e} s after the previous one, more than site.max_dt = {} s",
                        t - site.time(),
                        options.limits.max_dt
                    );
                }
                let disp = blocks[DISP].expect("ctrl_disp >= 1 (validated)");
                if let Err(e) = site.set_trial(disp, blocks[VEL], blocks[ACCEL], time) {
                    report.errors += 1;
                    break format!("setTrialResponse failed: {e}");
                }
                if let Some(i) = site.force().iter().position(|f| !f.is_finite()) {
                    report.errors += 1;
                    break format!(
                        "setTrialResponse: the trial displacement {:e} m gives a non-finite force on element DOF {}; connection closed",
                        disp[i.min(disp.len() - 1)],
                        i + 1
                    );
                }
                trials += 1;
                None
            }
            action::COMMIT_STATE => {
                if let Err(e) = site.commit() {
                    report.errors += 1;
                    break format!("commitState failed: {e}");
                }
                commits += 1;
                None
            }
            action::GET_DAQ_RESPONSE => {
                let mut at = 0;
                for b in 0..5 {
                    let len = sizes.daq[b];
                    if len > 0 {
                        match b {
                            DISP => reply[at..at + len].copy_from_slice(site.disp()),
                            VEL => reply[at..at + len].copy_from_slice(site.vel()),
                            ACCEL => reply[at..at + len].copy_from_slice(site.accel()),
                            FORCE => reply[at..at + len].copy_from_slice(site.force()),
                            _ => reply[at] = site.time(),
                        }
                        at += len;
                    }
                }
                Some(at)
            }
            action::GET_DISP => {
                reply[..n].copy_from_slice(site.disp());
                Some(n)
            }
            action::GET_VEL => {
                reply[..n].copy_from_slice(site.vel());
                Some(n)
            }
            action::GET_ACCEL => {
                reply[..n].copy_from_slice(site.accel());
                Some(n)
            }
            action::GET_FORCE => {
                reply[..n].copy_from_slice(site.force());
                Some(n)
            }
            action::GET_TIME => {
                reply[0] = site.time();
                Some(1)
            }
            action::GET_INITIAL_STIFF => {
                site.initial_stiffness(&mut reply[..n * n]);
                Some(n * n)
            }
            action::GET_TANGENT_STIFF => {
                site.tangent_stiffness(&mut reply[..n * n]);
                Some(n * n)
            }
            action::GET_DAMP => {
                site.damping(&mut reply[..n * n]);
                Some(n * n)
            }
            action::GET_MASS => {
                site.mass(&mut reply[..n * n]);
                Some(n * n)
            }
            action::SHUTDOWN => {
                shutdown = true;
                break "client asked for shutdown (action 98)".to_string();
            }
            action::DISCONNECT => break "client disconnected (action 99)".to_string(),
            other => {
                report.errors += 1;
                break format!("unknown action code {other}");
            }
        };
        if let Some(len) = reply_len {
            // Never a non-finite value on the wire. The protocol has no error reply, so the
            // connection is closed instead (the client sees a failed receive, not a NaN force).
            if let Some(i) = reply[..len].iter().position(|x| !x.is_finite()) {
                report.errors += 1;
                break format!(
                    "the reply to action {code} has a non-finite value in slot {i} ({}); connection closed instead of sending it",
                    reply[i]
                );
            }
            reply[len..].iter_mut().for_each(|x| *x = 0.0);
            f64s_to_le(&reply, &mut tx);
            if let Err(e) = write_all(&mut stream, &tx, io) {
                report.errors += 1;
                break format!("cannot send the reply to action {code}: {e}");
            }
        }
    };
    report.substeps += trials;
    report.steps += commits;
    options.log(&format!(
        "openfresco: {peer} session ended after {trials} trials, {commits} commits: {end}"
    ));
    (true, shutdown)
}

/// A client of an OpenFresco-style site server (the role of OpenFresco's generic TCP
/// experimental control), usable as an [`ExperimentalSubstructure`].
///
/// Sizes sent: control displacement + time, DAQ displacement + force
/// ([`Sizes::substep_client`]). Each sub-step is `3` (trial displacement = the command, time
/// advanced by `Δτ`), `6` (DAQ: measured displacement and resisting force), `5` (commit). The
/// coupling force is `f_c = −p`. The protocol carries no ground acceleration: specimens whose
/// force depends on it need the `SSTP` protocol.
pub struct OpenFrescoSite {
    stream: TcpStream,
    peer: SocketAddr,
    sizes: Sizes,
    time: f64,
    timeout: Duration,
    tx_values: Vec<f64>,
    tx: Vec<u8>,
    rx: Vec<u8>,
    rx_values: Vec<f64>,
    broken: Option<String>,
}

impl OpenFrescoSite {
    /// Connect to the server at `addr` and send the sizes for `n_dofs` element DOFs.
    pub fn connect(addr: impl ToSocketAddrs, n_dofs: usize, options: &super::ClientOptions) -> Result<Self> {
        let peer = addr
            .to_socket_addrs()
            .map_err(|e| Error::invalid("openfresco site address", format!("cannot resolve: {e}")))?
            .next()
            .ok_or_else(|| Error::invalid("openfresco site address", "resolves to no address"))?;
        let name = format!("openfresco site {peer}");
        let sizes = Sizes::substep_client(n_dofs);
        sizes.validate()?;
        let mut stream = TcpStream::connect_timeout(&peer, options.connect_timeout.max(Duration::from_millis(1)))
            .map_err(|e| Error::invalid(&name, format!("cannot connect: {e}")))?;
        stream
            .set_nodelay(true)
            .map_err(|e| Error::invalid(&name, format!("cannot set TCP_NODELAY: {e}")))?;
        write_all(&mut stream, &sizes.encode(), options.timeout)
            .map_err(|e| Error::invalid(&name, format!("cannot send the sizes: {e}")))?;
        let ds = sizes.data_size;
        Ok(Self {
            stream,
            peer,
            sizes,
            time: 0.0,
            timeout: options.timeout,
            tx_values: vec![0.0; ds],
            tx: vec![0u8; 8 * ds],
            rx: vec![0u8; 8 * ds],
            rx_values: vec![0.0; ds],
            broken: None,
        })
    }

    pub fn peer(&self) -> SocketAddr {
        self.peer
    }
    pub fn sizes(&self) -> &Sizes {
        &self.sizes
    }

    fn err(&mut self, reason: String) -> Error {
        self.broken = Some(reason.clone());
        Error::invalid(format!("openfresco site {}", self.peer), reason)
    }

    /// Send `values` (action code first), zero-padded to `data_size`.
    fn send(&mut self, values: &[f64]) -> Result<()> {
        self.send_with(|tx| tx[..values.len()].copy_from_slice(values))
    }

    /// Send the message that `fill` writes into the zeroed send buffer (action code first):
    /// the per-sub-step trial goes out without a temporary vector.
    fn send_with(&mut self, fill: impl FnOnce(&mut [f64])) -> Result<()> {
        if let Some(b) = &self.broken {
            let reason = format!("connection unusable after an earlier failure: {b}");
            return Err(Error::invalid(format!("openfresco site {}", self.peer), reason));
        }
        self.tx_values.iter_mut().for_each(|x| *x = 0.0);
        fill(&mut self.tx_values);
        f64s_to_le(&self.tx_values, &mut self.tx);
        let code = self.tx_values[0];
        write_all(&mut self.stream, &self.tx, self.timeout).map_err(|e| {
            let reason = match e {
                LinkError::Closed { .. } => format!("the site closed the connection (sending action {code})"),
                e => format!("cannot send action {code}: {e}"),
            };
            self.err(reason)
        })
    }

    fn receive(&mut self, code: i32) -> Result<()> {
        let deadline = Instant::now().checked_add(self.timeout);
        match read_full(&mut self.stream, &mut self.rx, deadline, None) {
            Ok(()) => {
                f64s_from_le(&self.rx, &mut self.rx_values);
                Ok(())
            }
            Err(e) => {
                let reason = match e {
                    LinkError::TimedOut { got: 0 } => format!(
                        "no reply to action {code} within {:.3} s (timeout)",
                        self.timeout.as_secs_f64()
                    ),
                    LinkError::Closed { got: 0 } => {
                        format!("the site closed the connection (no reply to action {code}); the site is gone")
                    }
                    e => format!("reply to action {code}: {e}"),
                };
                Err(self.err(reason))
            }
        }
    }
}

impl Drop for OpenFrescoSite {
    fn drop(&mut self) {
        if self.broken.is_none() {
            let _ = self.send(&[action::DISCONNECT as f64]);
        }
    }
}

impl ExperimentalSubstructure for OpenFrescoSite {
    fn n_coupling(&self) -> usize {
        self.sizes.n_dofs()
    }

    fn substep(
        &mut self,
        command: &[f64],
        _ag: (f64, f64),
        dtau: f64,
        force: &mut [f64],
        displacement: &mut [f64],
    ) -> Result<()> {
        let n = self.sizes.n_dofs();
        if let Some(i) = command.iter().position(|c| !c.is_finite()) {
            return Err(Error::numerical(
                format!("command to openfresco site {}", self.peer),
                format!("coupling DOF {} is not finite ({})", i + 1, command[i]),
            ));
        }
        self.time += dtau;
        let time = self.time;
        self.send_with(|tx| {
            tx[0] = action::SET_TRIAL_RESPONSE as f64;
            tx[1..=n].copy_from_slice(command);
            tx[n + 1] = time;
        })?;
        self.send(&[action::GET_DAQ_RESPONSE as f64])?;
        self.receive(action::GET_DAQ_RESPONSE)?;
        // DAQ blocks in order: displacement (n), force (n).
        if let Some(i) = self.rx_values[..2 * n].iter().position(|x| !x.is_finite()) {
            let (block, k) = if i < n { ("displacement", i) } else { ("force", i - n) };
            let reason = format!(
                "bad reply to action 6: daq {block}[{k}] is not finite ({})",
                self.rx_values[i]
            );
            return Err(self.err(reason));
        }
        displacement.copy_from_slice(&self.rx_values[..n]);
        for (f, p) in force.iter_mut().zip(&self.rx_values[n..2 * n]) {
            *f = -p;
        }
        self.send(&[action::COMMIT_STATE as f64])
    }

    fn is_linear(&self) -> Result<()> {
        Err(Error::invalid(
            format!("openfresco site {}", self.peer),
            "a remote site's linearity is unknown; the amplification-matrix analysis needs a local model",
        ))
    }
    fn state_len(&self) -> usize {
        0
    }
    fn write_state(&self, _out: &mut [f64]) {}
    fn read_state(&mut self, _state: &[f64]) {}
}
