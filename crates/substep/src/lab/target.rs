//! [`LabTarget`]: substep as the host of a lab's real-time target, one exchange per sub-step,
//! as an [`ExperimentalSubstructure`].
//!
//! Every exchange is bounded by `timeout`. A reply that does not come in time is a **hold**:
//! the last measured displacement and force stand for this sub-step (counted); after more than
//! `hold_limit` holds in a row the sub-step fails — the target is gone — and the test takes
//! its lost-site path (controlled stop, exit 1). Late, duplicated and unexpected replies are
//! discarded and counted ([`LabStats`]).

use super::channels::ChannelMap;
use super::frames::{self, OF_BYTES, action, status};
use super::link::{Link, LinkTransport, Received};
use crate::error::{Error, Result};
use crate::latency::LatencyHistogram;
use crate::substructure::ExperimentalSubstructure;
pub use crate::substructure::LabStats;
use std::net::SocketAddr;
use std::time::{Duration, Instant};

/// The lab-target protocol.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LabProtocol {
    /// OpenFresco's ECSpeedgoat (newTarget / switchPC / atTarget), UDP or TCP.
    Speedgoat,
    /// OpenFresco's ECGenericTCP (action codes 3, 6, 99), TCP.
    GenericTcp,
    /// substep's own lab I/O: sequence-numbered fixed frames over UDP.
    SubstepUdp,
}

impl LabProtocol {
    pub fn name(self) -> &'static str {
        match self {
            Self::Speedgoat => "speedgoat",
            Self::GenericTcp => "generic_tcp",
            Self::SubstepUdp => "substep_udp",
        }
    }
}

/// A lab target as configured (`[substructure.lab]`).
#[derive(Debug, Clone, PartialEq)]
pub struct LabTargetSpec {
    pub protocol: LabProtocol,
    pub transport: LinkTransport,
    pub address: SocketAddr,
    /// UDP: the host's own address (the port a target with a fixed destination sends to);
    /// `None`: any free port.
    pub local: Option<SocketAddr>,
    pub map: ChannelMap,
    /// Deadline of one exchange.
    pub timeout: Duration,
    /// Holds in a row tolerated before the target counts as gone.
    pub hold_limit: usize,
}

impl LabTargetSpec {
    /// The channels fit the protocol's frames: speedgoat `[newTarget, commands, time]` and
    /// `[switchPC, atTarget, signals]` in 256 words; generic_tcp `[code, commands, time]` and the
    /// signals in 256 words; substep_udp one UDP datagram (65 507 bytes) each way.
    pub fn check_frames(&self) -> Result<()> {
        let udp_words = 65_507 / 8;
        let (cmd_room, signal_room) = match self.protocol {
            LabProtocol::Speedgoat => (frames::OF_WORDS - 2, frames::OF_WORDS - 2),
            LabProtocol::GenericTcp => (frames::OF_WORDS - 2, frames::OF_WORDS),
            LabProtocol::SubstepUdp => (udp_words - 3, udp_words - 2),
        };
        let (n_cmd, m) = (self.map.commands.len(), self.map.n_signals);
        if n_cmd > cmd_room {
            return Err(Error::invalid(
                "substructure.lab.command",
                format!(
                    "{n_cmd} command channels do not fit a {} frame (at most {cmd_room})",
                    self.protocol.name()
                ),
            ));
        }
        if m > signal_room {
            return Err(Error::invalid(
                "substructure.lab.signals",
                format!(
                    "{m} measured signals do not fit a {} frame (at most {signal_room})",
                    self.protocol.name()
                ),
            ));
        }
        Ok(())
    }
}

impl LabStats {
    fn new(protocol: LabProtocol, transport: LinkTransport) -> Self {
        Self {
            protocol: protocol.name(),
            transport: transport.name(),
            exchanges: 0,
            held: 0,
            max_held_in_a_row: 0,
            late: 0,
            duplicated: 0,
            unexpected: 0,
            malformed: 0,
            stale: 0,
            resent: 0,
            // 1 µs bins up to 100 ms.
            rtt: LatencyHistogram::new(Duration::from_micros(1), 100_000),
            last_held: false,
            last_strays: 0,
        }
    }
}

/// How an exchange ended.
enum Exchange {
    Answered,
    /// No (usable) reply within the deadline.
    Missed,
}

/// The host side of a lab target (see the module docs).
pub struct LabTarget {
    spec: LabTargetSpec,
    name: String,
    link: Link,
    n_c: usize,
    sequence: u64,
    /// Bit `k` set: the reply to `sequence − k` was taken (substep_udp).
    answered: u64,
    in_a_row: u64,
    /// generic_tcp: replies still owed by the target for held sub-steps (a TCP stream delivers
    /// them late but in order).
    owed: u64,
    tx: Vec<u8>,
    rx: Vec<u8>,
    command_signals: Vec<f64>,
    control: Vec<f64>,
    measured_signals: Vec<f64>,
    displacement: Vec<f64>,
    force: Vec<f64>,
    stats: LabStats,
    gone: Option<String>,
}

impl LabTarget {
    /// Connect to the target (TCP: and send generic_tcp's sizes) for `n_c` coupling DOFs.
    pub fn connect(spec: &LabTargetSpec, n_c: usize) -> Result<Self> {
        spec.map.validate(n_c, "substructure.lab")?;
        spec.check_frames()?;
        let name = format!(
            "lab target {} ({} over {})",
            spec.address,
            spec.protocol.name(),
            spec.transport.name()
        );
        let mut link = Link::connect(
            spec.transport,
            spec.address,
            spec.local,
            spec.timeout.max(Duration::from_secs(1)),
            spec.timeout,
        )
        .map_err(|e| Error::invalid(&name, format!("cannot connect: {e}")))?;
        let n_cmd = spec.map.commands.len();
        let m = spec.map.n_signals;
        if spec.protocol == LabProtocol::GenericTcp {
            let n_disp = count(&spec.map, super::channels::Quantity::Displacement);
            let sizes = frames::GenericSizes::substep(n_cmd, n_disp, m - n_disp);
            link.send(&sizes.encode())
                .map_err(|e| Error::invalid(&name, format!("cannot send the sizes: {e}")))?;
        }
        let (tx, rx) = match spec.protocol {
            LabProtocol::SubstepUdp => (8 * (3 + n_cmd), 8 * (2 + m)),
            _ => (OF_BYTES, OF_BYTES),
        };
        Ok(Self {
            spec: spec.clone(),
            name,
            link,
            n_c,
            sequence: 0,
            answered: 0,
            in_a_row: 0,
            owed: 0,
            tx: vec![0; tx],
            // One word more than a reply, so that an oversized datagram shows as one.
            rx: vec![0; rx + 8],
            command_signals: vec![0.0; n_cmd],
            control: vec![0.0; n_cmd + 1],
            measured_signals: vec![0.0; m],
            displacement: vec![0.0; n_c],
            force: vec![0.0; n_c],
            stats: LabStats::new(spec.protocol, spec.transport),
            gone: None,
        })
    }

    pub fn stats(&self) -> &LabStats {
        &self.stats
    }

    fn fail(&mut self, reason: String) -> Error {
        self.gone = Some(reason.clone());
        Error::invalid(&self.name, reason)
    }

    fn send(&mut self, what: &str) -> Result<()> {
        let tx = std::mem::take(&mut self.tx);
        let r = self.link.send(&tx);
        self.tx = tx;
        r.map_err(|e| self.fail(format!("cannot send {what}: {e}")))
    }

    /// Receive one frame of `len` bytes before `deadline`: `Ok(true)` got it (in `rx`),
    /// `Ok(false)` the deadline passed; wrong-sized UDP datagrams are counted and skipped.
    fn receive(&mut self, len: usize, deadline: Instant) -> Result<bool> {
        loop {
            let got = {
                let buf = match self.link {
                    Link::Tcp(_) => &mut self.rx[..len],
                    Link::Udp(_) => &mut self.rx[..],
                };
                self.link.recv(buf, deadline)
            };
            match got {
                Ok(Received::Frame(n)) if n == len => return Ok(true),
                Ok(Received::Frame(_)) => self.stats.malformed += 1,
                Ok(Received::TimedOut) => return Ok(false),
                Ok(Received::Closed) => return Err(self.fail("the target closed the connection".into())),
                Err(e) => return Err(self.fail(format!("receive failed: {e}"))),
            }
        }
    }

    fn exchange_substep_udp(&mut self, time: f64, dtau: f64, deadline: Instant, start: Instant) -> Result<Exchange> {
        let seq = self.sequence;
        frames::lab_command(seq as f64, time, dtau, &self.command_signals, &mut self.tx);
        self.send("the command")?;
        let len = 8 * (2 + self.spec.map.n_signals);
        let resend_at = start + (deadline - start) / 2;
        let mut resent = false;
        loop {
            let wait = if resent { deadline } else { resend_at.min(deadline) };
            if !self.receive(len, wait)? {
                if !resent && Instant::now() < deadline {
                    // Half the budget gone: the command or its reply may be lost; the target
                    // answers a repeated sequence number again without applying it twice.
                    resent = true;
                    self.stats.resent += 1;
                    self.send("the command again")?;
                    continue;
                }
                return Ok(Exchange::Missed);
            }
            let s = frames::word(&self.rx, 0);
            if s == seq as f64 {
                let st = frames::word(&self.rx, 1);
                if st.is_finite() && (st as u32) & status::INTERLOCK != 0 {
                    return Err(self.fail(format!(
                        "the target reports that its interlock tripped (status {st}) at sub-step {seq}"
                    )));
                }
                frames::words(&self.rx, 2, &mut self.measured_signals);
                return Ok(Exchange::Answered);
            }
            // Another sub-step's reply: late (its sub-step was held), a duplicate, or unexpected.
            let age = seq as f64 - s;
            if !(age.is_finite() && age == age.trunc()) || age <= 0.0 {
                self.stats.unexpected += 1;
            } else if age < 64.0 && self.answered & (1u64 << (age as u32)) != 0 {
                self.stats.duplicated += 1;
            } else {
                self.stats.late += 1;
            }
        }
    }

    /// One ECSpeedgoat cycle: newTarget = 1 (×2) → switchPC = 1 → newTarget = 0 (×2) →
    /// switchPC = 0 → atTarget = 1 with the DAQ words.
    fn exchange_speedgoat(&mut self, deadline: Instant) -> Result<Exchange> {
        let mut buf = std::mem::take(&mut self.rx);
        self.stats.stale += self.link.drain(&mut buf) as u64;
        self.rx = buf;
        for (new_target, want) in [(1.0, 1.0), (0.0, 0.0)] {
            self.speedgoat_send(new_target)?;
            loop {
                if !self.receive(OF_BYTES, deadline)? {
                    // Leave the target with newTarget = 0 so that the next command is new.
                    if new_target == 1.0 {
                        self.speedgoat_send(0.0)?;
                    }
                    return Ok(Exchange::Missed);
                }
                if frames::word(&self.rx, 0) == want {
                    break;
                }
            }
        }
        // acquire(): atTarget = 0, then read until a frame says 1 — at least one new frame, as
        // the C++ does (ECSpeedgoat.cpp 800–803).
        loop {
            if !self.receive(OF_BYTES, deadline)? {
                return Ok(Exchange::Missed);
            }
            if frames::word(&self.rx, 1) == 1.0 {
                frames::words(&self.rx, 2, &mut self.measured_signals);
                return Ok(Exchange::Answered);
            }
        }
    }

    /// The send buffer as one OpenFresco frame (speedgoat and generic_tcp size it so).
    fn of_frame(tx: &mut [u8]) -> &mut [u8; OF_BYTES] {
        tx.try_into()
            .expect("the send buffer of speedgoat and generic_tcp is one frame")
    }

    fn speedgoat_send(&mut self, new_target: f64) -> Result<()> {
        frames::speedgoat_command(new_target, &self.control, Self::of_frame(&mut self.tx))
            .map_err(|e| self.fail(e.to_string()))?;
        // Every host frame twice, as ECSpeedgoat sends them.
        self.send("the command")?;
        self.send("the command")
    }

    /// One ECGenericTCP exchange: 3 (trial: the commands, then the time) and 6 (DAQ).
    fn exchange_generic(&mut self, deadline: Instant) -> Result<Exchange> {
        for (code, what) in [
            (action::SET_TRIAL_RESPONSE, "action 3"),
            (action::GET_DAQ_RESPONSE, "action 6"),
        ] {
            frames::generic_frame(code, &self.control, Self::of_frame(&mut self.tx))
                .map_err(|e| self.fail(e.to_string()))?;
            self.send(what)?;
        }
        // Replies owed for held sub-steps come first (the stream keeps their order): read and
        // discard them, then this sub-step's.
        let mut owed = self.owed + 1;
        while owed > 0 {
            if !self.receive(OF_BYTES, deadline)? {
                self.owed = owed;
                return Ok(Exchange::Missed);
            }
            owed -= 1;
            if owed > 0 {
                self.stats.late += 1;
            }
        }
        self.owed = 0;
        frames::words(&self.rx, 0, &mut self.measured_signals);
        Ok(Exchange::Answered)
    }

    fn shutdown(&mut self) {
        let mut tx = [0u8; OF_BYTES];
        let _ = match self.spec.protocol {
            LabProtocol::Speedgoat => frames::speedgoat_command(-1.0, &self.control, &mut tx).map(|()| {
                let _ = self.link.send(&tx);
                let _ = self.link.send(&tx);
            }),
            LabProtocol::GenericTcp => frames::generic_frame(action::DIE, &self.control, &mut tx).map(|()| {
                let _ = self.link.send(&tx);
            }),
            LabProtocol::SubstepUdp => {
                let mut f = vec![0u8; self.tx.len()];
                frames::lab_command(-1.0, 0.0, 0.0, &self.command_signals, &mut f);
                let _ = self.link.send(&f);
                Ok(())
            }
        };
    }
}

fn count(map: &ChannelMap, q: super::channels::Quantity) -> usize {
    map.measured.iter().filter(|m| m.quantity == q).count()
}

impl Drop for LabTarget {
    fn drop(&mut self) {
        self.shutdown();
    }
}

impl ExperimentalSubstructure for LabTarget {
    fn n_coupling(&self) -> usize {
        self.n_c
    }

    fn substep(
        &mut self,
        command: &[f64],
        _ag: (f64, f64),
        dtau: f64,
        force: &mut [f64],
        displacement: &mut [f64],
    ) -> Result<()> {
        if let Some(why) = &self.gone {
            let reason = format!("the link is unusable after an earlier failure: {why}");
            return Err(Error::invalid(&self.name, reason));
        }
        if let Some(i) = command.iter().position(|c| !c.is_finite()) {
            return Err(Error::numerical(
                format!("command to {}", self.name),
                format!("coupling DOF {} is not finite ({})", i + 1, command[i]),
            ));
        }
        self.spec.map.encode_commands(command, &mut self.command_signals);
        self.sequence += 1;
        self.answered <<= 1;
        // The time from the sub-step count, not a running sum: the target can recover the count.
        let time = self.sequence as f64 * dtau;
        let n_cmd = self.command_signals.len();
        self.control[..n_cmd].copy_from_slice(&self.command_signals);
        self.control[n_cmd] = time;
        let start = Instant::now();
        let deadline = start + self.spec.timeout;
        self.stats.exchanges += 1;
        let strays_before = self.stats.strays();
        let outcome = match self.spec.protocol {
            LabProtocol::SubstepUdp => self.exchange_substep_udp(time, dtau, deadline, start)?,
            LabProtocol::Speedgoat => self.exchange_speedgoat(deadline)?,
            LabProtocol::GenericTcp => self.exchange_generic(deadline)?,
        };
        self.stats.last_held = matches!(outcome, Exchange::Missed);
        self.stats.last_strays = self.stats.strays() - strays_before;
        match outcome {
            Exchange::Answered => {
                self.stats.rtt.record(start.elapsed());
                self.answered |= 1;
                self.in_a_row = 0;
                if let Some(k) = self.measured_signals.iter().position(|v| !v.is_finite()) {
                    return Err(self.fail(format!(
                        "measured signal {} is not finite ({}) at sub-step {}",
                        k + 1,
                        self.measured_signals[k],
                        self.sequence
                    )));
                }
                self.spec
                    .map
                    .decode_measured(&self.measured_signals, &mut self.displacement, &mut self.force);
            }
            Exchange::Missed => {
                self.stats.held += 1;
                self.in_a_row += 1;
                self.stats.max_held_in_a_row = self.stats.max_held_in_a_row.max(self.in_a_row);
                if self.in_a_row > self.spec.hold_limit as u64 {
                    return Err(self.fail(format!(
                        "no reply for {} sub-steps in a row (timeout {:.3} ms each, {} held allowed): the target is gone",
                        self.in_a_row,
                        self.spec.timeout.as_secs_f64() * 1e3,
                        self.spec.hold_limit
                    )));
                }
            }
        }
        displacement.copy_from_slice(&self.displacement);
        force.copy_from_slice(&self.force);
        Ok(())
    }

    fn is_linear(&self) -> Result<()> {
        Err(Error::invalid(
            &self.name,
            "a lab target's linearity is unknown; the amplification-matrix analysis needs a local model",
        ))
    }
    fn state_len(&self) -> usize {
        0
    }
    fn write_state(&self, _out: &mut [f64]) {}
    fn read_state(&mut self, _state: &[f64]) {}
    fn lab_stats(&self) -> Option<&LabStats> {
        Some(&self.stats)
    }
}
