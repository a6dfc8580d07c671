//! One client session ([`Hosted`]: the hosted substructure and the per-step machinery) and the
//! checks of a handshake (limits, authentication), shared by TCP and UDP.

use crate::error::Result;
use crate::site::auth::{MAC_LEN, NONCE_LEN, Role, Secret, SessionKeys};
use crate::site::limits::{MAX_SITE_RAMP_SUBSTEPS, SiteLimits};
use crate::site::protocol::{HEADER_LEN, Header, Hello, MAX_DATAGRAM, Message, Mode, Session, StepReply};
use crate::site::{CommandRamp, substep_ground_acceleration};
use crate::substructure::ExperimentalSubstructure;

/// One client session: the hosted substructure and the per-step machinery.
pub(super) struct Hosted {
    pub(super) hello: Hello,
    pub(super) site: Box<dyn ExperimentalSubstructure>,
    pub(super) ramp: CommandRamp,
    pub(super) force: Vec<f64>,
    pub(super) disp: Vec<f64>,
    pub(super) command: Vec<f64>,
    pub(super) reply: StepReply,
    pub(super) min_dtau: f64,
    pub(super) substeps: u64,
    pub(super) steps: u64,
    /// The site's ramp to rest (`SiteLimits::ramp_time`) and the last sub-step length used.
    ramp_time: f64,
    last_dtau: f64,
    /// The client ended the session with `Stop` (its own controlled end).
    client_stopped: bool,
}

pub(super) enum Outcome {
    Reply(Message),
    /// Reply, then end the session with the given log reason.
    Close(Message, String),
}

impl Outcome {
    pub(super) fn error(reason: String) -> Self {
        Outcome::Close(Message::Error { reason: reason.clone() }, reason)
    }
}

impl Hosted {
    /// Build the session for an accepted (and, with a secret, authenticated) handshake that
    /// passed [`SiteLimits::check_hello`].
    pub(super) fn open(
        hello: Hello,
        factory: &mut impl FnMut(&Hello) -> Result<Box<dyn ExperimentalSubstructure>>,
        limits: &SiteLimits,
        udp: bool,
    ) -> std::result::Result<Self, String> {
        let s = hello.session();
        if udp && HEADER_LEN + s.max_payload() > MAX_DATAGRAM {
            return Err(format!(
                "n_c = {} with k_sub = {} needs messages larger than one UDP datagram ({MAX_DATAGRAM} bytes); use TCP",
                hello.n_coupling, hello.substeps
            ));
        }
        let site = factory(&hello).map_err(|e| format!("cannot build the site: {e}"))?;
        if site.n_coupling() != hello.n_coupling {
            return Err(format!(
                "the site has {} coupling DOFs, the client asked for {}",
                site.n_coupling(),
                hello.n_coupling
            ));
        }
        let n = hello.n_coupling;
        Ok(Self {
            ramp: CommandRamp::new(n, hello.substeps, &hello.gain_cc),
            reply: StepReply::zeros(&s),
            site,
            force: vec![0.0; n],
            disp: vec![0.0; n],
            command: vec![0.0; n],
            min_dtau: limits.min_dtau,
            ramp_time: limits.ramp_time,
            last_dtau: hello.dtau,
            client_stopped: false,
            hello,
            substeps: 0,
            steps: 0,
        })
    }

    pub(super) fn limits(&self) -> Session {
        self.hello.session()
    }

    pub(super) fn describe(&self) -> String {
        format!(
            "n_c = {}, k_sub = {}, dt = {} s, {}",
            self.hello.n_coupling,
            self.hello.substeps,
            self.hello.dt,
            self.hello.mode.name()
        )
    }

    /// One sub-step with `self.command`.
    pub(super) fn run_substep(&mut self, ag: (f64, f64), dtau: f64) -> std::result::Result<(), String> {
        self.site
            .substep(&self.command, ag, dtau, &mut self.force, &mut self.disp)
            .map_err(|e| format!("the site failed at sub-step {}: {e}", self.substeps + 1))?;
        self.substeps += 1;
        self.last_dtau = dtau;
        // Never a non-finite value on the wire: refuse instead.
        if let Some(i) = self.force.iter().position(|f| !f.is_finite()) {
            return Err(format!(
                "the site measured a non-finite force on coupling DOF {} (command {:e} m)",
                i + 1,
                self.command[i]
            ));
        }
        if let Some(i) = self.disp.iter().position(|f| !f.is_finite()) {
            return Err(format!(
                "the site measured a non-finite displacement on coupling DOF {} (command {:e} m)",
                i + 1,
                self.command[i]
            ));
        }
        Ok(())
    }

    pub(super) fn handle(&mut self, msg: Message) -> Outcome {
        let mode = self.hello.mode;
        match msg {
            Message::Substep { command, ag, dtau } if mode == Mode::PerSubstep => {
                // The sub-step length sizes nothing here, but bounds the work of the specimen
                // and actuator models (and keeps their matrix exponentials in range).
                if !(dtau >= self.min_dtau && dtau <= self.hello.dt) {
                    return Outcome::error(format!(
                        "site protocol: Substep.dtau = {dtau:e} s is outside {:e} s (site.min_dtau) ..= {:e} s (the session's dt)",
                        self.min_dtau, self.hello.dt
                    ));
                }
                self.command.copy_from_slice(&command);
                match self.run_substep(ag, dtau) {
                    Ok(()) => Outcome::Reply(Message::Measured {
                        force: self.force.clone(),
                        displacement: self.disp.clone(),
                    }),
                    Err(reason) => Outcome::error(reason),
                }
            }
            Message::Step(req) if mode == Mode::PerStep => {
                let (n, k) = (self.hello.n_coupling, self.hello.substeps);
                let dtau = self.hello.dtau;
                self.ramp
                    .begin(&req.predictor_c_prev, &req.predictor_c, &req.force_prev);
                for j in 1..=k {
                    self.command.copy_from_slice(self.ramp.next_command());
                    if let Some(i) = self.command.iter().position(|c| !c.is_finite()) {
                        return Outcome::error(format!(
                            "sub-step {j}: the command on coupling DOF {} is not finite (the Step request's values are too large)",
                            i + 1
                        ));
                    }
                    let ag = substep_ground_acceleration(req.ag.0, req.ag.1, j, k);
                    if let Err(reason) = self.run_substep(ag, dtau) {
                        return Outcome::error(reason);
                    }
                    self.ramp.feedback(&self.force);
                    let row = (j - 1) * n..j * n;
                    self.reply.commands[row.clone()].copy_from_slice(&self.command);
                    self.reply.forces[row.clone()].copy_from_slice(&self.force);
                    self.reply.displacements[row].copy_from_slice(&self.disp);
                }
                self.steps += 1;
                Outcome::Reply(Message::StepResult(self.reply.clone()))
            }
            Message::Substep { .. } | Message::Step(_) => {
                Outcome::error(format!("{} message in a {} session", msg.kind().name(), mode.name()))
            }
            Message::Heartbeat => Outcome::Reply(Message::Heartbeat),
            Message::Stop { reason } => {
                self.client_stopped = true;
                Outcome::Close(
                    Message::Stop {
                        reason: "stop acknowledged".into(),
                    },
                    format!("client stopped ({reason})"),
                )
            }
            Message::Error { reason } => Outcome::Close(
                Message::Stop {
                    reason: "error acknowledged".into(),
                },
                format!("client reported an error: {reason}"),
            ),
            Message::Hello(_) => Outcome::error("handshake repeated within a session".to_string()),
            other => Outcome::error(format!("unexpected {} message from a client", other.kind().name())),
        }
    }

    /// After the session ended: if it moved the actuators and did not end with the client's
    /// `Stop` (a lost client, a message that failed authentication, a protocol or site error),
    /// ramp the commands linearly to 0 over `ramp_time` (no ground motion), so that the
    /// specimen is not left where an interrupted test put it; the client cannot do it when its
    /// link is what failed. What was done, for the log (empty if nothing).
    pub(super) fn ramp_to_rest(&mut self) -> String {
        if self.client_stopped || self.substeps == 0 || self.command.iter().all(|c| *c == 0.0) {
            return String::new();
        }
        let dtau = self.last_dtau.max(self.ramp_time / MAX_SITE_RAMP_SUBSTEPS as f64);
        let n = ((self.ramp_time / dtau).ceil() as usize).clamp(1, MAX_SITE_RAMP_SUBSTEPS);
        let start = self.command.clone();
        let largest = start.iter().fold(0.0f64, |m, c| m.max(c.abs()));
        for s in 1..=n {
            let left = 1.0 - s as f64 / n as f64;
            for (c, c0) in self.command.iter_mut().zip(&start) {
                *c = c0 * left;
            }
            if let Err(e) = self.run_substep((0.0, 0.0), dtau) {
                return format!("; the site's ramp to rest failed at {s}/{n}: {e}");
            }
        }
        format!(
            "; the site ramped its actuators to rest from |command| ≤ {largest:.3e} m over {n} sub-steps ({} s)",
            self.ramp_time
        )
    }

    pub(super) fn summary(&self) -> String {
        format!("{} sub-steps, {} steps", self.substeps, self.steps)
    }
}

/// Why a handshake did not lead to a session.
pub(super) struct Refusal {
    /// Sequence number of the `Reject` (with `log` as its reason) to send, if any.
    pub(super) reply: Option<u32>,
    pub(super) log: String,
}

impl Refusal {
    pub(super) fn reject(reason: String, seq: u32) -> Self {
        Refusal {
            reply: Some(seq),
            log: reason,
        }
    }
}

/// Check a decoded Hello (sequence number, limits).
pub(super) fn admit_hello(header: &Header, msg: Message, limits: &SiteLimits) -> std::result::Result<Hello, Refusal> {
    match msg {
        Message::Hello(hello) if header.seq == 0 => {
            limits.check_hello(&hello).map_err(|r| Refusal::reject(r, 0))?;
            Ok(hello)
        }
        other => Err(Refusal::reject(
            format!(
                "expected Hello with sequence number 0, got {} #{}",
                other.kind().name(),
                header.seq
            ),
            header.seq,
        )),
    }
}

/// With a secret, what an accepted `Auth` gives: the site's proof for `Accept` and the session
/// keys.
pub(super) type Proof = ([u8; MAC_LEN], SessionKeys);

/// Check the client's `Auth` against the challenge; on success the site's proof for `Accept`
/// and the session keys.
pub(super) fn check_auth(
    secret: &Secret,
    site_nonce: &[u8; NONCE_LEN],
    hello_payload: &[u8],
    header: &Header,
    msg: Message,
) -> std::result::Result<Proof, Refusal> {
    match msg {
        Message::Auth { nonce, mac } if header.seq == 1 => {
            if secret.verify(Role::Client, site_nonce, &nonce, hello_payload, &mac) {
                Ok((
                    secret.mac(Role::Site, site_nonce, &nonce, hello_payload),
                    secret.session_keys(Role::Site, site_nonce, &nonce, hello_payload),
                ))
            } else {
                Err(Refusal::reject(
                    "authentication failed: wrong proof (a different secret, or a replayed handshake)".into(),
                    1,
                ))
            }
        }
        other => Err(Refusal::reject(
            format!(
                "authentication required: expected Auth #1 after the Challenge, got {} #{} (configure the site's secret on the client)",
                other.kind().name(),
                header.seq
            ),
            header.seq,
        )),
    }
}
