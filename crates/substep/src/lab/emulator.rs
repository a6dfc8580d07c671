//! A lab-target emulator: serves one of the protocols and runs a virtual actuator + specimen
//! (any [`ExperimentalSubstructure`], usually the test's [`crate::transfer::VirtualLab`])
//! behind it, one sub-step per command, so that a test can be rehearsed against exactly the
//! packets the real target will see — and can inject faults into its replies.
//!
//! The target works out which sub-step a command is from the sequence number (substep_udp) or
//! the time it carries (speedgoat, generic_tcp): `c = round(t/Δτ)`; the ground acceleration of
//! that sub-step comes from the test's record as the host interpolates it
//! ([`crate::substructure::substep_ground_acceleration`]), so specimens with mass see the same
//! excitation as in the virtual lab.

use super::channels::ChannelMap;
use super::frames::{self, OF_BYTES, action, status};
use super::link::LinkTransport;
use super::target::LabProtocol;
use crate::error::{Error, Result};
use crate::substructure::{ExperimentalSubstructure, substep_ground_acceleration};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Faults the emulator injects into its replies (probabilities per reply; times in the test's
/// time, i.e. sub-step count × Δτ).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Faults {
    /// Share of replies not sent.
    pub loss: f64,
    /// Share of replies sent twice.
    pub duplicate: f64,
    /// Share of replies held back and sent after the next one.
    pub reorder: f64,
    /// `(at, duration)` \[s\]: once the test time reaches `at`, the target stalls for `duration`
    /// of wall-clock time before it answers.
    pub stall: Option<(f64, f64)>,
    /// From this test time on the target is dead: it answers nothing and closes its socket.
    pub die_at: Option<f64>,
    pub seed: u64,
}

impl Faults {
    pub fn none() -> Self {
        Self {
            loss: 0.0,
            duplicate: 0.0,
            reorder: 0.0,
            stall: None,
            die_at: None,
            seed: 1,
        }
    }

    pub fn validate(&self, what: &str) -> Result<()> {
        for (key, p) in [
            ("loss", self.loss),
            ("duplicate", self.duplicate),
            ("reorder", self.reorder),
        ] {
            if !(0.0..=1.0).contains(&p) {
                return Err(Error::invalid(
                    format!("{what}.{key}"),
                    format!("must be a share from 0 to 1, got {p}"),
                ));
            }
        }
        if let Some((at, d)) = self.stall
            && !(at.is_finite() && at >= 0.0 && d.is_finite() && (0.0..=60.0).contains(&d))
        {
            return Err(Error::invalid(
                format!("{what}.stall"),
                format!("needs [at >= 0 s, duration 0 to 60 s], got [{at}, {d}]"),
            ));
        }
        if let Some(t) = self.die_at
            && !(t.is_finite() && t >= 0.0)
        {
            return Err(Error::invalid(
                format!("{what}.die_at"),
                format!("must be a time >= 0 s, got {t}"),
            ));
        }
        Ok(())
    }
}

/// What the emulator serves.
#[derive(Debug, Clone, PartialEq)]
pub struct EmulatorSpec {
    pub protocol: LabProtocol,
    pub transport: LinkTransport,
    pub bind: SocketAddr,
    pub map: ChannelMap,
    /// The test's time step and sub-steps per step (Δτ = dt / k_sub).
    pub dt: f64,
    pub k_sub: usize,
    /// The ground acceleration at every step \[m/s²\].
    pub accel: Vec<f64>,
    pub faults: Faults,
    /// A session ends when the host sends nothing for this long.
    pub idle: Duration,
}

/// What a session did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EmulatorReport {
    pub substeps: u64,
    pub frames_in: u64,
    pub replies: u64,
    pub dropped: u64,
    pub duplicated: u64,
    pub reordered: u64,
    pub stalls: u64,
    /// Why the session ended.
    pub ended: String,
}

enum Socket {
    Udp(UdpSocket),
    Tcp(TcpListener),
}

/// A bound emulator (see the module docs).
pub struct Emulator {
    spec: EmulatorSpec,
    lab: Box<dyn ExperimentalSubstructure>,
    socket: Socket,
    local: SocketAddr,
}

/// The session's state beside the socket.
struct Session {
    executed: u64,
    command: Vec<f64>,
    measured: Vec<f64>,
    force: Vec<f64>,
    displacement: Vec<f64>,
    rng: ChaCha8Rng,
    held_back: Option<Vec<u8>>,
    stalled: bool,
    report: EmulatorReport,
}

enum Peer<'a> {
    Udp(&'a UdpSocket, SocketAddr),
    Tcp(&'a mut TcpStream),
}

impl Peer<'_> {
    fn send(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        match self {
            Peer::Udp(s, to) => s.send_to(bytes, *to).map(|_| ()),
            Peer::Tcp(s) => s.write_all(bytes),
        }
    }
}

impl Emulator {
    /// Bind the socket of `spec` with `lab` behind it (its coupling DOFs are the map's).
    pub fn bind(spec: EmulatorSpec, lab: Box<dyn ExperimentalSubstructure>) -> Result<Self> {
        let name = format!("lab emulator at {}", spec.bind);
        spec.map.validate(lab.n_coupling(), "lab")?;
        spec.faults.validate("faults")?;
        if !(spec.dt.is_finite() && spec.dt > 0.0) || spec.k_sub == 0 || spec.accel.is_empty() {
            return Err(Error::invalid(&name, "needs dt > 0, k_sub >= 1 and a ground motion"));
        }
        match (spec.protocol, spec.transport) {
            (LabProtocol::SubstepUdp, LinkTransport::Tcp) | (LabProtocol::GenericTcp, LinkTransport::Udp) => {
                return Err(Error::invalid(
                    &name,
                    format!(
                        "{} runs over {}",
                        spec.protocol.name(),
                        if spec.protocol == LabProtocol::SubstepUdp {
                            "udp"
                        } else {
                            "tcp"
                        }
                    ),
                ));
            }
            _ => {}
        }
        let (socket, local) = match spec.transport {
            LinkTransport::Udp => {
                let s = UdpSocket::bind(spec.bind).map_err(|e| Error::invalid(&name, format!("cannot bind: {e}")))?;
                let local = s.local_addr().map_err(|e| Error::invalid(&name, e.to_string()))?;
                (Socket::Udp(s), local)
            }
            LinkTransport::Tcp => {
                let s = TcpListener::bind(spec.bind).map_err(|e| Error::invalid(&name, format!("cannot bind: {e}")))?;
                let local = s.local_addr().map_err(|e| Error::invalid(&name, e.to_string()))?;
                (Socket::Tcp(s), local)
            }
        };
        Ok(Self {
            spec,
            lab,
            socket,
            local,
        })
    }

    pub fn local_addr(&self) -> SocketAddr {
        self.local
    }

    /// Serve one host session (until it shuts the target down, closes, goes idle, the target
    /// dies by `die_at`, or `stop` is raised).
    pub fn serve(mut self, stop: &AtomicBool) -> Result<EmulatorReport> {
        let n_c = self.lab.n_coupling();
        let mut session = Session {
            executed: 0,
            command: vec![0.0; n_c],
            measured: vec![0.0; self.spec.map.n_signals],
            force: vec![0.0; n_c],
            displacement: vec![0.0; n_c],
            rng: ChaCha8Rng::seed_from_u64(self.spec.faults.seed),
            held_back: None,
            stalled: false,
            report: EmulatorReport::default(),
        };
        let socket = std::mem::replace(
            &mut self.socket,
            Socket::Udp(UdpSocket::bind("127.0.0.1:0").map_err(|e| Error::invalid("lab emulator", e.to_string()))?),
        );
        let ended = match socket {
            Socket::Udp(s) => self.serve_udp(&s, &mut session, stop)?,
            Socket::Tcp(l) => self.serve_tcp(&l, &mut session, stop)?,
        };
        session.report.ended = ended;
        Ok(session.report)
    }

    fn serve_udp(&mut self, s: &UdpSocket, ses: &mut Session, stop: &AtomicBool) -> Result<String> {
        let io = |e: std::io::Error| Error::invalid("lab emulator", e.to_string());
        s.set_read_timeout(Some(Duration::from_millis(10))).map_err(io)?;
        let mut buf = vec![0u8; OF_BYTES + 8];
        let mut last = Instant::now();
        let mut last_reply: Vec<u8> = Vec::new();
        let mut sg = SpeedgoatState::default();
        loop {
            if stop.load(Ordering::Relaxed) {
                return Ok("stopped".into());
            }
            let (n, from) = match s.recv_from(&mut buf) {
                Ok(x) => x,
                Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {
                    if last.elapsed() > self.spec.idle {
                        return Ok("the host went silent".into());
                    }
                    continue;
                }
                Err(e) => return Err(io(e)),
            };
            last = Instant::now();
            ses.report.frames_in += 1;
            let frame = &buf[..n];
            let mut peer = Peer::Udp(s, from);
            let outcome = match self.spec.protocol {
                LabProtocol::SubstepUdp => self.substep_udp_frame(frame, ses, &mut last_reply, &mut peer)?,
                LabProtocol::Speedgoat => self.speedgoat_frame(frame, ses, &mut sg, &mut peer)?,
                LabProtocol::GenericTcp => unreachable!("checked at bind"),
            };
            if let Some(ended) = outcome {
                return Ok(ended);
            }
        }
    }

    fn serve_tcp(&mut self, l: &TcpListener, ses: &mut Session, stop: &AtomicBool) -> Result<String> {
        let io = |e: std::io::Error| Error::invalid("lab emulator", e.to_string());
        l.set_nonblocking(true).map_err(io)?;
        let started = Instant::now();
        let mut stream = loop {
            if stop.load(Ordering::Relaxed) {
                return Ok("stopped".into());
            }
            match l.accept() {
                Ok((s, _)) => break s,
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                    if started.elapsed() > self.spec.idle {
                        return Ok("no host connected".into());
                    }
                    std::thread::sleep(Duration::from_millis(2));
                }
                Err(e) => return Err(io(e)),
            }
        };
        stream.set_nonblocking(false).map_err(io)?;
        stream.set_nodelay(true).map_err(io)?;
        if self.spec.protocol == LabProtocol::GenericTcp {
            let mut sizes = [0u8; 44];
            if !read_frame(&mut stream, &mut sizes, stop, self.spec.idle).map_err(io)? {
                return Ok("the host sent no sizes".into());
            }
            let got = frames::GenericSizes::decode(&sizes)?;
            let n_disp = self
                .spec
                .map
                .measured
                .iter()
                .filter(|m| m.quantity == super::channels::Quantity::Displacement)
                .count();
            let want =
                frames::GenericSizes::substep(self.spec.map.commands.len(), n_disp, self.spec.map.n_signals - n_disp);
            if got != want {
                return Err(Error::invalid(
                    "lab emulator",
                    format!("the host's sizes {got:?} are not this target's {want:?}"),
                ));
            }
        }
        let mut buf = [0u8; OF_BYTES];
        let mut sg = SpeedgoatState::default();
        loop {
            if !read_frame(&mut stream, &mut buf, stop, self.spec.idle).map_err(io)? {
                return Ok("the host closed the connection or went silent".into());
            }
            ses.report.frames_in += 1;
            let mut peer = Peer::Tcp(&mut stream);
            let outcome = match self.spec.protocol {
                LabProtocol::Speedgoat => self.speedgoat_frame(&buf, ses, &mut sg, &mut peer)?,
                LabProtocol::GenericTcp => self.generic_frame(&buf, ses, &mut peer)?,
                LabProtocol::SubstepUdp => unreachable!("checked at bind"),
            };
            if let Some(ended) = outcome {
                return Ok(ended);
            }
        }
    }

    /// Execute sub-step `counter` (1-based, over the whole test) with the command signals; a
    /// counter already executed changes nothing.
    fn apply(&mut self, counter: u64, signals: &[f64], ses: &mut Session) -> Result<()> {
        if counter <= ses.executed {
            return Ok(());
        }
        self.spec.map.decode_commands(signals, &mut ses.command);
        let k = self.spec.k_sub as u64;
        let i = ((counter - 1) / k) as usize;
        let j = ((counter - 1) % k) as usize + 1;
        let last = *self.spec.accel.last().expect("checked at bind");
        let a = |n: usize| self.spec.accel.get(n).copied().unwrap_or(last);
        let ag = substep_ground_acceleration(a(i), a(i + 1), j, self.spec.k_sub);
        let dtau = self.spec.dt / self.spec.k_sub as f64;
        self.lab
            .substep(&ses.command, ag, dtau, &mut ses.force, &mut ses.displacement)?;
        self.spec
            .map
            .encode_measured(&ses.displacement, &ses.force, &mut ses.measured);
        ses.executed = counter;
        ses.report.substeps += 1;
        Ok(())
    }

    fn counter_from_time(&self, t: f64) -> u64 {
        let dtau = self.spec.dt / self.spec.k_sub as f64;
        (t / dtau).round().max(0.0) as u64
    }

    /// Whether the target is dead at test time `t` (then it answers nothing).
    fn dead(&self, counter: u64) -> bool {
        let dtau = self.spec.dt / self.spec.k_sub as f64;
        self.spec.faults.die_at.is_some_and(|t| counter as f64 * dtau >= t)
    }

    /// Send `reply` through the fault layer.
    fn reply(&self, reply: &[u8], counter: u64, ses: &mut Session, peer: &mut Peer) -> Result<()> {
        let io = |e: std::io::Error| Error::invalid("lab emulator", format!("cannot reply: {e}"));
        let f = &self.spec.faults;
        let dtau = self.spec.dt / self.spec.k_sub as f64;
        if let Some((at, d)) = f.stall
            && !ses.stalled
            && counter as f64 * dtau >= at
        {
            ses.stalled = true;
            ses.report.stalls += 1;
            std::thread::sleep(Duration::from_secs_f64(d));
        }
        if f.loss > 0.0 && ses.rng.random::<f64>() < f.loss {
            ses.report.dropped += 1;
            return Ok(());
        }
        if f.reorder > 0.0 && ses.held_back.is_none() && ses.rng.random::<f64>() < f.reorder {
            ses.held_back = Some(reply.to_vec());
            ses.report.reordered += 1;
            return Ok(());
        }
        peer.send(reply).map_err(io)?;
        ses.report.replies += 1;
        if let Some(old) = ses.held_back.take() {
            peer.send(&old).map_err(io)?;
            ses.report.replies += 1;
        }
        if f.duplicate > 0.0 && ses.rng.random::<f64>() < f.duplicate {
            peer.send(reply).map_err(io)?;
            ses.report.duplicated += 1;
        }
        Ok(())
    }

    fn substep_udp_frame(
        &mut self,
        frame: &[u8],
        ses: &mut Session,
        last_reply: &mut Vec<u8>,
        peer: &mut Peer,
    ) -> Result<Option<String>> {
        let n_cmd = self.spec.map.commands.len();
        if frame.len() != 8 * (3 + n_cmd) {
            return Ok(None);
        }
        let seq = frames::word(frame, 0);
        if seq == -1.0 {
            return Ok(Some("the host stopped the test (sequence −1)".into()));
        }
        if !(seq.is_finite() && seq >= 1.0 && seq == seq.trunc()) {
            return Ok(None);
        }
        let counter = seq as u64;
        if self.dead(counter) {
            return Ok(Some("died (die_at)".into()));
        }
        if counter < ses.executed {
            return Ok(None);
        }
        if counter == ses.executed {
            // The host repeated a command: answer again, do not apply it twice.
            let r = last_reply.clone();
            if !r.is_empty() {
                self.reply(&r, counter, ses, peer)?;
            }
            return Ok(None);
        }
        let mut signals = vec![0.0; n_cmd];
        frames::words(frame, 3, &mut signals);
        self.apply(counter, &signals, ses)?;
        last_reply.resize(8 * (2 + ses.measured.len()), 0);
        frames::lab_reply(seq, status::APPLIED as f64, &ses.measured, last_reply);
        let r = last_reply.clone();
        self.reply(&r, counter, ses, peer)?;
        Ok(None)
    }

    fn speedgoat_frame(
        &mut self,
        frame: &[u8],
        ses: &mut Session,
        sg: &mut SpeedgoatState,
        peer: &mut Peer,
    ) -> Result<Option<String>> {
        if frame.len() != OF_BYTES {
            return Ok(None);
        }
        let n_cmd = self.spec.map.commands.len();
        let new_target = frames::word(frame, 0);
        if new_target == -1.0 {
            return Ok(Some("the host shut the target down (newTarget −1)".into()));
        }
        let counter = self.counter_from_time(frames::word(frame, 1 + n_cmd));
        if self.dead(counter.max(ses.executed)) {
            return Ok(Some("died (die_at)".into()));
        }
        if new_target == 1.0 && sg.switch_pc == 0.0 {
            let mut signals = vec![0.0; n_cmd];
            frames::words(frame, 1, &mut signals);
            self.apply(counter, &signals, ses)?;
            sg.switch_pc = 1.0;
            sg.at_target = 0.0;
        } else if new_target == 0.0 && sg.switch_pc == 1.0 {
            sg.switch_pc = 0.0;
            sg.at_target = 1.0;
        }
        let mut out = [0u8; OF_BYTES];
        frames::speedgoat_target_frame(sg.switch_pc, sg.at_target, &ses.measured, &mut out)?;
        self.reply(&out, ses.executed, ses, peer)?;
        Ok(None)
    }

    fn generic_frame(&mut self, frame: &[u8], ses: &mut Session, peer: &mut Peer) -> Result<Option<String>> {
        let n_cmd = self.spec.map.commands.len();
        let code = frames::word(frame, 0);
        if code == action::DIE {
            return Ok(Some("the host ended the session (action 99)".into()));
        }
        if code == action::SET_TRIAL_RESPONSE {
            let counter = self.counter_from_time(frames::word(frame, 1 + n_cmd));
            if self.dead(counter) {
                return Ok(Some("died (die_at)".into()));
            }
            let mut signals = vec![0.0; n_cmd];
            frames::words(frame, 1, &mut signals);
            self.apply(counter, &signals, ses)?;
        } else if code == action::GET_DAQ_RESPONSE {
            let mut out = [0u8; OF_BYTES];
            frames::put_f64s(&ses.measured, &mut out);
            self.reply(&out, ses.executed, ses, peer)?;
        }
        Ok(None)
    }
}

#[derive(Default)]
struct SpeedgoatState {
    switch_pc: f64,
    at_target: f64,
}

/// Read one whole frame; `false` when the peer closed or sent nothing for `idle`.
fn read_frame(s: &mut TcpStream, buf: &mut [u8], stop: &AtomicBool, idle: Duration) -> std::io::Result<bool> {
    s.set_read_timeout(Some(Duration::from_millis(10)))?;
    let mut got = 0;
    let mut last = Instant::now();
    while got < buf.len() {
        if stop.load(Ordering::Relaxed) || last.elapsed() > idle {
            return Ok(false);
        }
        match s.read(&mut buf[got..]) {
            Ok(0) => return Ok(false),
            Ok(n) => {
                got += n;
                last = Instant::now();
            }
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut | std::io::ErrorKind::Interrupted
                ) => {}
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => return Ok(false),
            Err(e) => return Err(e),
        }
    }
    Ok(true)
}
