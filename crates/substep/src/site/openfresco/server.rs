//! [`OpenFrescoServer`]: the SimAppSiteServer side of the protocol, one connection at a time.

use super::*;

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
/// Serve one connection; returns (a session was opened, the client asked for shutdown).
pub(super) fn serve_connection(
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
