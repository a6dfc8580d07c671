//! The byte layouts of the lab-target protocols (docs/lab.md): pure functions from values to
//! frames and back, no I/O. All numbers are little-endian IEEE-754 (`f64`) or two's-complement
//! (`i32`), as OpenFresco sends them from x86 hosts.

use crate::error::{Error, Result};

/// Words per OpenFresco frame (`OF_Network_dataSize`).
pub const OF_WORDS: usize = 256;
/// Bytes per OpenFresco frame.
pub const OF_BYTES: usize = 8 * OF_WORDS;

/// OpenFresco's remote-test action codes (`FrescoGlobals.h`) used here.
pub mod action {
    pub const SET_TRIAL_RESPONSE: f64 = 3.0;
    pub const GET_DAQ_RESPONSE: f64 = 6.0;
    pub const DIE: f64 = 99.0;
}

/// `values` into `out` as little-endian `f64`, the rest of `out` zeroed. `out.len()` must be
/// `8 ×` the frame's words and at least `8 × values.len()`.
pub fn put_f64s(values: &[f64], out: &mut [u8]) {
    debug_assert!(out.len() >= 8 * values.len());
    out.fill(0);
    for (x, c) in values.iter().zip(out.chunks_exact_mut(8)) {
        c.copy_from_slice(&x.to_le_bytes());
    }
}

/// Word `k` of a frame of little-endian `f64`.
pub fn word(frame: &[u8], k: usize) -> f64 {
    f64::from_le_bytes(frame[8 * k..8 * k + 8].try_into().expect("8 bytes"))
}

/// Words `from..from + out.len()` of a frame into `out`.
pub fn words(frame: &[u8], from: usize, out: &mut [f64]) {
    for (i, o) in out.iter_mut().enumerate() {
        *o = word(frame, from + i);
    }
}

fn check_fits(what: &str, n: usize, room: usize) -> Result<()> {
    if n > room {
        return Err(Error::invalid(
            what,
            format!("{n} signals do not fit a frame of {OF_WORDS} words (at most {room})"),
        ));
    }
    Ok(())
}

/// ECSpeedgoat, host → target: `[newTarget, ctrl_1 … ctrl_n, 0 …]` (2048 bytes).
pub fn speedgoat_command(new_target: f64, control: &[f64], out: &mut [u8; OF_BYTES]) -> Result<()> {
    check_fits("speedgoat control signals", control.len(), OF_WORDS - 1)?;
    out.fill(0);
    out[..8].copy_from_slice(&new_target.to_le_bytes());
    for (x, c) in control.iter().zip(out[8..].chunks_exact_mut(8)) {
        c.copy_from_slice(&x.to_le_bytes());
    }
    Ok(())
}

/// ECSpeedgoat, target → host: `[switchPC, atTarget, daq_1 … daq_m, …]`; returns
/// `(switchPC, atTarget)` and fills `daq`.
pub fn speedgoat_reply(frame: &[u8; OF_BYTES], daq: &mut [f64]) -> (f64, f64) {
    words(frame, 2, daq);
    (word(frame, 0), word(frame, 1))
}

/// ECSpeedgoat, target → host (what a target, or the emulator, sends).
pub fn speedgoat_target_frame(switch_pc: f64, at_target: f64, daq: &[f64], out: &mut [u8; OF_BYTES]) -> Result<()> {
    check_fits("speedgoat daq signals", daq.len(), OF_WORDS - 2)?;
    out.fill(0);
    out[..8].copy_from_slice(&switch_pc.to_le_bytes());
    out[8..16].copy_from_slice(&at_target.to_le_bytes());
    for (x, c) in daq.iter().zip(out[16..].chunks_exact_mut(8)) {
        c.copy_from_slice(&x.to_le_bytes());
    }
    Ok(())
}

/// ECGenericTCP's set-up message: 11 `i32` — control sizes (displacement, velocity,
/// acceleration, force, time), DAQ sizes (the same five), data size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GenericSizes {
    pub ctrl: [i32; 5],
    pub daq: [i32; 5],
    pub data_size: i32,
}

impl GenericSizes {
    /// substep's: control `n_cmd` displacements and the time; DAQ `n_disp` displacements and
    /// `n_force` forces; 256 words.
    pub fn substep(n_cmd: usize, n_disp: usize, n_force: usize) -> Self {
        Self {
            ctrl: [n_cmd as i32, 0, 0, 0, 1],
            daq: [n_disp as i32, 0, 0, n_force as i32, 0],
            data_size: OF_WORDS as i32,
        }
    }
    pub fn encode(&self) -> [u8; 44] {
        let mut out = [0u8; 44];
        let all = self
            .ctrl
            .iter()
            .chain(&self.daq)
            .chain(std::iter::once(&self.data_size));
        for (v, c) in all.zip(out.chunks_exact_mut(4)) {
            c.copy_from_slice(&v.to_le_bytes());
        }
        out
    }
    /// Decode and check (sizes ≥ 0, data size 256, the control and DAQ vectors fit a frame).
    pub fn decode(bytes: &[u8; 44]) -> Result<Self> {
        let v: Vec<i32> = bytes
            .chunks_exact(4)
            .map(|c| i32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect();
        let s = Self {
            ctrl: [v[0], v[1], v[2], v[3], v[4]],
            daq: [v[5], v[6], v[7], v[8], v[9]],
            data_size: v[10],
        };
        if s.ctrl.iter().chain(&s.daq).any(|&n| n < 0) || s.data_size != OF_WORDS as i32 {
            return Err(Error::invalid(
                "generic_tcp sizes",
                format!("need sizes >= 0 and a data size of {OF_WORDS}, got {s:?}"),
            ));
        }
        let total = |a: &[i32; 5]| a.iter().map(|&n| n as usize).sum::<usize>();
        if total(&s.ctrl) + 1 > OF_WORDS || total(&s.daq) > OF_WORDS {
            return Err(Error::invalid("generic_tcp sizes", format!("{s:?} do not fit a frame")));
        }
        Ok(s)
    }
}

/// ECGenericTCP, host → target: `[code, ctrl…]`. ECGenericTCP keeps one send buffer whose
/// words from 1 on are the control vector, and only sets word 0 to the action code: 3 (set
/// trial response), 6 (get DAQ response) and 99 (die) all carry the last control vector.
pub fn generic_frame(code: f64, control: &[f64], out: &mut [u8; OF_BYTES]) -> Result<()> {
    check_fits("generic_tcp control signals", control.len(), OF_WORDS - 1)?;
    speedgoat_command(code, control, out)
}

/// substep lab I/O (`substep_udp`), host → target: `[sequence, time, Δτ, cmd_1 … cmd_n]`,
/// `8 (3 + n)` bytes. Sequence −1 asks the target to hold and ramp down on its own.
pub fn lab_command(sequence: f64, time: f64, dtau: f64, commands: &[f64], out: &mut [u8]) {
    debug_assert_eq!(out.len(), 8 * (3 + commands.len()));
    out[..8].copy_from_slice(&sequence.to_le_bytes());
    out[8..16].copy_from_slice(&time.to_le_bytes());
    out[16..24].copy_from_slice(&dtau.to_le_bytes());
    for (x, c) in commands.iter().zip(out[24..].chunks_exact_mut(8)) {
        c.copy_from_slice(&x.to_le_bytes());
    }
}

/// substep lab I/O, target → host: `[sequence echoed, status, meas_1 … meas_m]`,
/// `8 (2 + m)` bytes.
pub fn lab_reply(sequence: f64, status: f64, measured: &[f64], out: &mut [u8]) {
    debug_assert_eq!(out.len(), 8 * (2 + measured.len()));
    out[..8].copy_from_slice(&sequence.to_le_bytes());
    out[8..16].copy_from_slice(&status.to_le_bytes());
    for (x, c) in measured.iter().zip(out[16..].chunks_exact_mut(8)) {
        c.copy_from_slice(&x.to_le_bytes());
    }
}

/// Status bits of a substep lab I/O reply.
pub mod status {
    /// The command was applied (the actuator is at its target for this sub-step).
    pub const APPLIED: u32 = 1;
    /// The target's own interlock has tripped.
    pub const INTERLOCK: u32 = 2;
    /// The target is holding its last setpoint (it heard nothing in time).
    pub const HOLDING: u32 = 4;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layouts() {
        let mut f = [0u8; OF_BYTES];
        speedgoat_command(1.0, &[0.25, -2.0], &mut f).unwrap();
        assert_eq!(&f[..8], &1.0f64.to_le_bytes());
        assert_eq!(&f[8..16], &0.25f64.to_le_bytes());
        assert_eq!(&f[16..24], &(-2.0f64).to_le_bytes());
        assert!(f[24..].iter().all(|&b| b == 0));
        assert!(speedgoat_command(1.0, &[0.0; 256], &mut f).is_err());
        let s = GenericSizes::substep(2, 2, 2);
        let e = s.encode();
        assert_eq!(&e[..4], &2i32.to_le_bytes());
        assert_eq!(&e[16..20], &1i32.to_le_bytes());
        assert_eq!(&e[40..44], &256i32.to_le_bytes());
        assert_eq!(GenericSizes::decode(&e).unwrap(), s);
        let mut bad = e;
        bad[40..44].copy_from_slice(&100i32.to_le_bytes());
        assert!(GenericSizes::decode(&bad).is_err());
        let mut l = [0u8; 32];
        lab_command(1.0, 0.01, 0.001, &[0.5], &mut l);
        assert_eq!(&l[..8], &[0, 0, 0, 0, 0, 0, 0xF0, 0x3F]);
    }
}
