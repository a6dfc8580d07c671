//! [`OpenFrescoSite`]: a client of an OpenFresco-style site server, usable as an
//! [`ExperimentalSubstructure`].

use super::*;

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
    pub fn connect(addr: impl ToSocketAddrs, n_dofs: usize, options: &crate::site::ClientOptions) -> Result<Self> {
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
