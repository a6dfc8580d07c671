//! What one client may ask of a site: every size the site allocates and every loop it runs on
//! a client's behalf is derived from the handshake, so the handshake is checked against these
//! limits before anything is built (site config keys, `docs/security.md`).

use super::protocol::{Hello, MAX_COUPLING, MAX_SUBSTEPS, Mode};

/// The site's own limits for a session (`[site]` keys of the same name).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SiteLimits {
    /// Largest number of coupling DOFs `n_c` (`max_coupling`).
    pub max_coupling: usize,
    /// Largest `k_sub` (`max_substeps`).
    pub max_substeps: usize,
    /// Shortest sub-step `Δτ` \[s\] (`min_dtau`), also for the `Δτ` of each `Substep` message.
    pub min_dtau: f64,
    /// Longest time step `Δt` \[s\] (`max_dt`); a `Substep`'s `Δτ` may not exceed the session's `Δt`.
    pub max_dt: f64,
    /// Largest estimated memory of one session \[bytes\] (`max_session_memory`, in MB there).
    pub max_session_bytes: usize,
    /// Largest estimated work of one request, in inner-step × actuator-history operations
    /// (`max_request_work`): bounds the CPU time of one `Step` or `Substep`.
    pub max_request_work: u64,
    /// Time over which the site ramps its actuators to rest when a session that moved them
    /// ends without the client's `Stop` \[s\] (`ramp_time`; at most [`MAX_SITE_RAMP_SUBSTEPS`]
    /// sub-steps).
    pub ramp_time: f64,
}

/// Most sub-steps of the site's own ramp to rest (a longer `ramp_time` takes longer sub-steps).
pub const MAX_SITE_RAMP_SUBSTEPS: usize = 10_000;

impl Default for SiteLimits {
    fn default() -> Self {
        Self {
            max_coupling: 64,
            max_substeps: 1000,
            min_dtau: 1e-6,
            max_dt: 10.0,
            max_session_bytes: 32 << 20,
            max_request_work: 20_000_000,
            ramp_time: 1.0,
        }
    }
}

/// What hosting one session costs the experimental substructure (estimated by its factory,
/// e.g. [`super::VirtualLabSpec::cost`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SessionCost {
    /// Memory of the hosted substructure \[bytes\].
    pub bytes: usize,
    /// Work of one sub-step (same unit as [`SiteLimits::max_request_work`]).
    pub work_per_substep: u64,
}

impl SiteLimits {
    /// Check the limits themselves (config values).
    pub fn validate(&self) -> std::result::Result<(), (&'static str, String)> {
        if self.max_coupling == 0 || self.max_coupling > MAX_COUPLING {
            return Err((
                "max_coupling",
                format!("is {}, must be 1..={MAX_COUPLING}", self.max_coupling),
            ));
        }
        if self.max_substeps == 0 || self.max_substeps > MAX_SUBSTEPS {
            return Err((
                "max_substeps",
                format!("is {}, must be 1..={MAX_SUBSTEPS}", self.max_substeps),
            ));
        }
        if !(self.ramp_time.is_finite() && self.ramp_time > 0.0 && self.ramp_time <= 600.0) {
            return Err((
                "ramp_time",
                format!("must be a number of seconds in (0, 600], got {}", self.ramp_time),
            ));
        }
        if !(self.min_dtau.is_finite() && self.min_dtau > 0.0) {
            return Err((
                "min_dtau",
                format!("must be a finite number > 0, got {}", self.min_dtau),
            ));
        }
        if !(self.max_dt.is_finite() && self.max_dt >= self.min_dtau) {
            return Err((
                "max_dt",
                format!("must be a finite number >= min_dtau, got {}", self.max_dt),
            ));
        }
        if self.max_session_bytes == 0 {
            return Err(("max_session_memory", "must be > 0".into()));
        }
        if self.max_request_work == 0 {
            return Err(("max_request_work", "must be > 0".into()));
        }
        Ok(())
    }

    /// Check a client's handshake against the limits that do not depend on what is hosted.
    /// The reason names the handshake field and the site key to change.
    pub fn check_hello(&self, hello: &Hello) -> std::result::Result<(), String> {
        if hello.n_coupling > self.max_coupling {
            return Err(format!(
                "n_c = {} exceeds this site's limit of {} coupling DOFs (site.max_coupling)",
                hello.n_coupling, self.max_coupling
            ));
        }
        if hello.substeps > self.max_substeps {
            return Err(format!(
                "k_sub = {} exceeds this site's limit of {} (site.max_substeps)",
                hello.substeps, self.max_substeps
            ));
        }
        if hello.dtau < self.min_dtau {
            return Err(format!(
                "the sub-step length dtau = {:e} s is below this site's limit of {:e} s (site.min_dtau)",
                hello.dtau, self.min_dtau
            ));
        }
        if hello.dt > self.max_dt {
            return Err(format!(
                "the time step dt = {} s exceeds this site's limit of {} s (site.max_dt)",
                hello.dt, self.max_dt
            ));
        }
        if hello.dtau > hello.dt {
            return Err(format!(
                "the sub-step length dtau = {:e} s is longer than the time step dt = {:e} s",
                hello.dtau, hello.dt
            ));
        }
        self.check_cost(hello, SessionCost::default())
    }

    /// Check a session's total estimated memory and per-request work: the server's own buffers
    /// for `hello` plus `cost` of the hosted substructure.
    pub fn check_cost(&self, hello: &Hello, cost: SessionCost) -> std::result::Result<(), String> {
        let (n, k) = (hello.n_coupling as u64, hello.substeps as u64);
        // Step replies (kept, cloned into the message, encoded), G_cc (handshake and ramp),
        // request buffers.
        let server_bytes = 4 * 24 * n * k + 16 * n * n + 64 * n + 4096;
        let bytes = server_bytes.saturating_add(cost.bytes as u64);
        if bytes > self.max_session_bytes as u64 {
            return Err(format!(
                "the session would need about {:.1} MB (n_c = {n}, k_sub = {k}), more than this site's limit of {:.1} MB (site.max_session_memory)",
                bytes as f64 / 1e6,
                self.max_session_bytes as f64 / 1e6
            ));
        }
        let per_substep = cost.work_per_substep.saturating_add(n * n + n);
        let work = match hello.mode {
            Mode::PerStep => per_substep.saturating_mul(k),
            Mode::PerSubstep => per_substep,
        };
        if work > self.max_request_work {
            return Err(format!(
                "one {} request would cost about {work:.2e} operations (n_c = {n}, k_sub = {k}, dtau = {:e} s), more than this site's limit of {:.2e} (site.max_request_work)",
                if hello.mode == Mode::PerStep { "Step" } else { "Substep" },
                hello.dtau,
                self.max_request_work as f64,
                work = work as f64
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_site_ramp_time_is_bounded() {
        assert!(SiteLimits::default().validate().is_ok());
        for bad in [0.0, -1.0, 601.0, f64::NAN, f64::INFINITY] {
            let limits = SiteLimits {
                ramp_time: bad,
                ..SiteLimits::default()
            };
            let (key, reason) = limits.validate().unwrap_err();
            assert_eq!(key, "ramp_time");
            assert!(
                reason.starts_with("must be a number of seconds in (0, 600]"),
                "{reason}"
            );
        }
    }
}
