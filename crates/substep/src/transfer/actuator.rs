//! Actuators: an optional pure delay followed by ideal, first-order or second-order
//! (servo-hydraulic) dynamics.

use crate::error::{Error, Result, require_non_negative, require_positive};
use crate::integrate::FohMap;
use nalgebra::{DMatrix, DVector, dmatrix};

/// Dynamics from (delayed) command to achieved displacement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Dynamics {
    /// Achieved = command.
    Ideal,
    /// `τ ẏ + y = d`.
    FirstOrder { time_constant: f64 },
    /// `ÿ + 2ζ_a ω_a ẏ + ω_a² y = ω_a² d`, `ω_a = 2π f_a`.
    SecondOrder { frequency_hz: f64, zeta: f64 },
}

/// An actuator as configured: dynamics plus a pure delay [s].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActuatorSpec {
    pub dynamics: Dynamics,
    pub delay: f64,
}

impl ActuatorSpec {
    pub fn ideal() -> Self {
        Self {
            dynamics: Dynamics::Ideal,
            delay: 0.0,
        }
    }

    pub fn validate(&self) -> Result<()> {
        require_non_negative("actuator.delay", self.delay)?;
        match self.dynamics {
            Dynamics::Ideal => {}
            Dynamics::FirstOrder { time_constant } => {
                require_positive("actuator.time_constant", time_constant)?;
            }
            Dynamics::SecondOrder { frequency_hz, zeta } => {
                require_positive("actuator.frequency", frequency_hz)?;
                if !(zeta.is_finite() && zeta > 0.0) {
                    return Err(Error::invalid(
                        "actuator.zeta",
                        format!("must be > 0 (an undamped or negatively damped actuator is unstable), got {zeta}"),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Build an actuator for commands updated every `dt_inner` seconds.
    pub fn build(&self, dt_inner: f64) -> Result<Actuator> {
        self.validate()?;
        require_positive("sub-step length", dt_inner)?;
        let (a, b) = match self.dynamics {
            Dynamics::Ideal => (DMatrix::zeros(0, 0), DMatrix::zeros(0, 1)),
            Dynamics::FirstOrder { time_constant: t } => (dmatrix![-1.0 / t], dmatrix![1.0 / t]),
            Dynamics::SecondOrder { frequency_hz, zeta } => {
                let w = 2.0 * std::f64::consts::PI * frequency_hz;
                (dmatrix![0.0, 1.0; -w * w, -2.0 * zeta * w], dmatrix![0.0; w * w])
            }
        };
        let n = a.nrows();
        if self.delay > 0.0 {
            // A backstop for callers that did not size the line first (configs are checked
            // against `[limits] max_memory`, sites against their own limits).
            let samples = DelayLine::samples(self.delay, dt_inner);
            if !(samples <= DELAY_MAX_SAMPLES as f64) {
                return Err(Error::invalid(
                    "actuator.delay",
                    format!(
                        "a delay of {} s at a sub-step of {dt_inner:e} s needs {samples:.3e} samples of history, \
                         more than {DELAY_MAX_SAMPLES}",
                        self.delay
                    ),
                ));
            }
        }
        let delay = (self.delay > 0.0).then(|| DelayLine::new(self.delay, dt_inner));
        Ok(Actuator {
            spec: *self,
            delay,
            a,
            b,
            map: None,
            z: DVector::zeros(n),
            z_next: DVector::zeros(n),
            w0: DVector::zeros(1),
            w1: DVector::zeros(1),
            dw: DVector::zeros(1),
            delayed: 0.0,
            position: 0.0,
        })
    }
}

/// A pure delay of a piecewise-linear signal, with linear interpolation between samples
/// (fractional delays). Samples are time-stamped, so a change of the sample spacing is fine as
/// long as the history covers the delay; older requests return the oldest sample. The history
/// starts full (the signal was 0 since t = −∞), so its state has a fixed layout from the start.
#[derive(Debug, Clone)]
pub struct DelayLine {
    delay: f64,
    times: Vec<f64>,
    values: Vec<f64>,
    /// Index of the newest sample.
    head: usize,
    now: f64,
}

/// Most samples a [`DelayLine`] built by [`ActuatorSpec::build`] may hold (2³⁰: 16 GiB of
/// times and values); see [`DelayLine::samples`].
pub const DELAY_MAX_SAMPLES: usize = 1 << 30;

impl DelayLine {
    /// Samples of the history a line for `delay` at spacing `dt_nominal` holds (as `f64`, to
    /// be checked before [`DelayLine::new`] allocates them; infinite or NaN for absurd input).
    pub fn samples(delay: f64, dt_nominal: f64) -> f64 {
        2.0 * ((delay / dt_nominal).ceil() + 2.0)
    }

    pub fn new(delay: f64, dt_nominal: f64) -> Self {
        // Twice the needed length tolerates sub-steps re-spaced down to half their length.
        let cap = 2 * ((delay / dt_nominal).ceil() as usize + 2);
        let times = (0..cap).map(|k| (k as f64 - (cap - 1) as f64) * dt_nominal).collect();
        Self {
            delay,
            times,
            values: vec![0.0; cap],
            head: cap - 1,
            now: 0.0,
        }
    }

    /// Append the signal value at the end of an interval of length `dt`; return the delayed
    /// value at that time.
    pub fn push(&mut self, value: f64, dt: f64) -> f64 {
        self.now += dt;
        self.head = (self.head + 1) % self.times.len();
        self.times[self.head] = self.now;
        self.values[self.head] = value;
        self.value_at(self.now - self.delay)
    }

    fn value_at(&self, t: f64) -> f64 {
        let cap = self.times.len();
        let mut newer = self.head;
        for _ in 1..cap {
            let older = (newer + cap - 1) % cap;
            if self.times[older] <= t {
                let (t0, t1) = (self.times[older], self.times[newer]);
                let r = if t1 > t0 { (t - t0) / (t1 - t0) } else { 1.0 };
                return self.values[older] + r * (self.values[newer] - self.values[older]);
            }
            newer = older;
        }
        self.values[newer]
    }

    /// Values of the history, newest first, as a fixed-length state (for the linear analysis).
    pub fn state_len(&self) -> usize {
        self.values.len()
    }
    pub fn write_state(&self, out: &mut [f64]) {
        let cap = self.values.len();
        for (k, o) in out.iter_mut().enumerate() {
            *o = self.values[(self.head + cap - k) % cap];
        }
    }
    /// Set the history values (newest first) keeping the current time grid.
    pub fn read_state(&mut self, state: &[f64]) {
        let cap = self.values.len();
        for (k, &v) in state.iter().enumerate() {
            self.values[(self.head + cap - k) % cap] = v;
        }
    }
}

/// One actuator with its state; see [`ActuatorSpec`].
#[derive(Debug, Clone)]
pub struct Actuator {
    spec: ActuatorSpec,
    delay: Option<DelayLine>,
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    map: Option<(f64, FohMap)>,
    z: DVector<f64>,
    z_next: DVector<f64>,
    w0: DVector<f64>,
    w1: DVector<f64>,
    dw: DVector<f64>,
    /// Delayed command at the end of the last interval.
    delayed: f64,
    /// Achieved displacement at the end of the last interval.
    position: f64,
}

impl Actuator {
    pub fn spec(&self) -> &ActuatorSpec {
        &self.spec
    }

    /// Achieved displacement at the end of the last interval [m].
    pub fn position(&self) -> f64 {
        self.position
    }

    /// Advance over `dt` while the command moves linearly to `command_end`; return the achieved
    /// displacement at the end.
    pub fn advance(&mut self, command_end: f64, dt: f64) -> f64 {
        let delayed_start = self.delayed;
        self.delayed = match &mut self.delay {
            Some(line) => line.push(command_end, dt),
            None => command_end,
        };
        self.position = match self.spec.dynamics {
            Dynamics::Ideal => self.delayed,
            _ => {
                let stale = self.map.as_ref().is_none_or(|(h, _)| (h - dt).abs() > 1e-12 * dt);
                if stale {
                    // Allocates once per run (or per re-spacing of the real-time runner).
                    let map = FohMap::new(&self.a, &self.b, dt)
                        .unwrap_or_else(|_| FohMap::not_a_number(self.a.nrows(), self.b.ncols()));
                    self.map = Some((dt, map));
                }
                let map = &self.map.as_ref().expect("map set above").1;
                self.w0[0] = delayed_start;
                self.w1[0] = self.delayed;
                map.apply(&self.z, &self.w0, &self.w1, &mut self.dw, &mut self.z_next);
                std::mem::swap(&mut self.z, &mut self.z_next);
                self.z[0]
            }
        };
        self.position
    }

    /// State: `[delayed command, dynamics state…, delay history…]`.
    pub fn state_len(&self) -> usize {
        1 + self.z.len() + self.delay.as_ref().map_or(0, DelayLine::state_len)
    }
    pub fn write_state(&self, out: &mut [f64]) {
        out[0] = self.delayed;
        let nz = self.z.len();
        out[1..1 + nz].copy_from_slice(self.z.as_slice());
        if let Some(d) = &self.delay {
            d.write_state(&mut out[1 + nz..]);
        }
    }
    pub fn read_state(&mut self, s: &[f64]) {
        self.delayed = s[0];
        let nz = self.z.len();
        self.z.copy_from_slice(&s[1..1 + nz]);
        self.position = if nz > 0 { self.z[0] } else { self.delayed };
        if let Some(d) = &mut self.delay {
            d.read_state(&s[1 + nz..]);
        }
    }
}
