//! The energy view of the stability indicator (docs/theory.md §15.1): how much energy the
//! transfer system adds at the interface, against how much the hybrid system dissipates.
//!
//! Per step `i → i+1` and coupling DOF, with `r = −f` the specimen's restoring force (the
//! measured force on the specimen), `d` the command and `x` the measured displacement, both
//! works integrated with the trapezoidal rule:
//!
//! ```text
//! ΔW_m = r̄ (x_{i+1} − x_i)      work the specimen actually received (measured motion)
//! ΔW_n = r̄ (d_{i+1} − d_i)      work the numerical side believes it did (its own motion)
//! ΔE_a = ΔW_m − ΔW_n            energy the transfer system added (tracking error × force)
//! ΔD   = ΔE_D + ΔW_m − ΔS       dissipation: numerical damping + what the specimen absorbed
//! ```
//!
//! `S` is an estimate of the energy stored in the specimen (the caller's, e.g. `½ k̂ x²` with
//! the identified stiffness): without it a window that does not span whole cycles counts the
//! change of stored energy as dissipation, which can even be negative.
//!
//! Over a sliding window of `W` steps the indicator is `η = Σ ΔE_a / Σ ΔD`: the fraction of the
//! system's dissipation that the transfer system cancels. `η ≥ 1` means the hybrid system is
//! no longer damped (its free response grows); the alarm threshold sits below that.

/// Running energy indicator; every buffer is sized at construction, [`Self::push`] does not
/// allocate.
#[derive(Debug, Clone)]
pub struct EnergyIndicator {
    n_c: usize,
    /// Last sample per DOF: restoring force, command, measured displacement.
    r: Vec<f64>,
    d: Vec<f64>,
    x: Vec<f64>,
    damping_energy: f64,
    stored: f64,
    started: bool,
    /// Per-step increments of the last `window` steps (ring).
    added: Vec<f64>,
    dissipated: Vec<f64>,
    head: usize,
    filled: usize,
    sum_added: f64,
    sum_dissipated: f64,
    /// Largest windowed dissipation seen: the scale below which a window counts as quiet.
    max_dissipated: f64,
    steps: usize,
    total_added: f64,
    total_measured: f64,
    total_numerical: f64,
    eta: f64,
}

/// A window whose dissipation is below this share of the largest one seen is "quiet": the
/// ratio of two noise-sized numbers says nothing, and `η` is unknown (NaN) there.
const QUIET: f64 = 0.05;

impl EnergyIndicator {
    /// `n_c` coupling DOFs, a sliding window of `window ≥ 1` steps.
    pub fn new(n_c: usize, window: usize) -> Self {
        let window = window.max(1);
        Self {
            n_c,
            r: vec![0.0; n_c],
            d: vec![0.0; n_c],
            x: vec![0.0; n_c],
            damping_energy: 0.0,
            stored: 0.0,
            started: false,
            added: vec![0.0; window],
            dissipated: vec![0.0; window],
            head: 0,
            filled: 0,
            sum_added: 0.0,
            sum_dissipated: 0.0,
            max_dissipated: 0.0,
            steps: 0,
            total_added: 0.0,
            total_measured: 0.0,
            total_numerical: 0.0,
            eta: f64::NAN,
        }
    }

    pub fn n_coupling(&self) -> usize {
        self.n_c
    }

    /// Add the state at the end of a step: `force` on the numerical substructure (N, the
    /// sign convention of the records: the specimen's restoring force is `−force`), `command`
    /// and `measured` displacement (m) per coupling DOF, and the cumulative damping energy of
    /// the numerical substructure `E_D` and the energy stored in the specimen `S` (J; 0 if
    /// unknown). The first call sets the start; `η` is known after two windows (the first
    /// holds the start-up transient).
    pub fn push(&mut self, force: &[f64], command: &[f64], measured: &[f64], damping_energy: f64, stored: f64) {
        if !self.started {
            for k in 0..self.n_c {
                self.r[k] = -force[k];
                self.d[k] = command[k];
                self.x[k] = measured[k];
            }
            self.damping_energy = damping_energy;
            self.stored = stored;
            self.started = true;
            return;
        }
        let (mut dwm, mut dwn) = (0.0, 0.0);
        for k in 0..self.n_c {
            let r = -force[k];
            let mean = 0.5 * (self.r[k] + r);
            dwm += mean * (measured[k] - self.x[k]);
            dwn += mean * (command[k] - self.d[k]);
            self.r[k] = r;
            self.d[k] = command[k];
            self.x[k] = measured[k];
        }
        let de = damping_energy - self.damping_energy;
        self.damping_energy = damping_energy;
        let added = dwm - dwn;
        let dissipated = de + dwm - (stored - self.stored);
        self.stored = stored;
        self.steps += 1;
        self.total_added += added;
        self.total_measured += dwm;
        self.total_numerical += dwn;
        if !(added.is_finite() && dissipated.is_finite()) {
            self.eta = f64::NAN;
            return;
        }
        let w = self.added.len();
        if self.filled == w {
            self.sum_added -= self.added[self.head];
            self.sum_dissipated -= self.dissipated[self.head];
        } else {
            self.filled += 1;
        }
        self.added[self.head] = added;
        self.dissipated[self.head] = dissipated;
        self.sum_added += added;
        self.sum_dissipated += dissipated;
        self.head = (self.head + 1) % w;
        if self.head == 0 {
            // Re-sum once per window: the running sums cannot drift by round-off.
            self.sum_added = self.added.iter().sum();
            self.sum_dissipated = self.dissipated.iter().sum();
        }
        if self.steps < 2 * w {
            return;
        }
        self.max_dissipated = self.max_dissipated.max(self.sum_dissipated);
        if self.sum_dissipated > QUIET * self.max_dissipated && self.sum_dissipated > 0.0 {
            self.eta = self.sum_added / self.sum_dissipated;
        } else {
            // A window in which the specimen gave back more stored energy than the estimate
            // `S` accounts for (a mass-carrying specimen passing resonance) has no meaningful
            // ratio: unknown, not alarming.
            self.eta = f64::NAN;
        }
    }

    /// `η` over the last window; NaN until the first window is full (and while every window
    /// so far was quiet).
    pub fn eta(&self) -> f64 {
        self.eta
    }
    /// Energy added by the transfer system over the last window \[J\].
    pub fn window_added(&self) -> f64 {
        self.sum_added
    }
    /// Dissipation over the last window \[J\].
    pub fn window_dissipated(&self) -> f64 {
        self.sum_dissipated
    }
    /// Energy added by the transfer system since the start \[J\].
    pub fn total_added(&self) -> f64 {
        self.total_added
    }
    /// Work received by the specimen (measured motion) since the start \[J\].
    pub fn total_measured_work(&self) -> f64 {
        self.total_measured
    }
    /// Work the numerical side did on the interface (its own motion) since the start \[J\].
    pub fn total_numerical_work(&self) -> f64 {
        self.total_numerical
    }
}
