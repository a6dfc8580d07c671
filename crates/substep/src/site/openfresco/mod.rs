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
//!
//! Files: this one (sizes, constants, wire helpers), `element.rs` (what is hosted), `server.rs`,
//! `client.rs`.

use super::server::{Flow, ServeOptions, ServeReport, ServerHandle, serve_tcp_sessions};
use super::transport::{LinkError, quick_ack, read_full, write_all};
use crate::error::{Error, Result};
use crate::specimen::SpecimenSpec;
use crate::substructure::ExperimentalSubstructure;
use crate::transfer::{ActuatorSpec, SensorSpec, VirtualLab};
use nalgebra::DMatrix;
use std::net::{SocketAddr, TcpListener, TcpStream, ToSocketAddrs};
use std::time::{Duration, Instant};

mod client;
mod element;
mod server;

pub use client::OpenFrescoSite;
pub use element::{ElementSite, ElementSpec, LinearElement, SubstructureElement};
pub use server::OpenFrescoServer;

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
