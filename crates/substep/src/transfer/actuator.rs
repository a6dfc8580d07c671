//! Actuators: an optional pure delay followed by ideal, first-order, second-order, general
//! continuous LTI (transfer function or state space) or servo-hydraulic dynamics.
//!
//! The linear kinds are advanced by the exact first-order-hold map of their state space
//! ([`FohMap`]): the lab's command is linear over each inner interval, so FOH is exact for it
//! (no integration error at any inner rate, and the transfer-function kind reproduces the
//! first- and second-order kinds to rounding). The servo-hydraulic plant
//! ([`super::servo::ServoActuator`]) is advanced by RK4 with the linear command evaluated at the
//! stage times, as the benchmark integrates it, because its CSI velocity feedback can be the
//! benchmark's finite-difference block, which has no exact discretisation.

use super::lti::StateSpace;
use super::servo::{Derivative, ServoActuator, ServoParams};
use crate::error::{Error, Result, require_non_negative, require_positive};
use crate::integrate::FohMap;
use nalgebra::{DMatrix, DVector, dmatrix};

/// Dynamics from (delayed) command to achieved displacement.
#[derive(Debug, Clone, PartialEq)]
pub enum Dynamics {
    /// Achieved = command.
    Ideal,
    /// `τ ẏ + y = d`.
    FirstOrder { time_constant: f64 },
    /// `ÿ + 2ζ_a ω_a ẏ + ω_a² y = ω_a² d`, `ω_a = 2π f_a`.
    SecondOrder { frequency_hz: f64, zeta: f64 },
    /// A continuous SISO LTI system from command to displacement (from a transfer function or
    /// state space; see [`super::lti`]), which must be stable.
    Lti(StateSpace),
    /// The servo-hydraulic plant of [`super::servo`] with the specimen at the actuator's DOF in
    /// it; the specimen's mass, damping and stiffness come from the attached specimen.
    ServoHydraulic(ServoSpec),
}

/// The servo-valve / actuator part of the servo-hydraulic plant ([`ServoParams`] without the
/// specimen, whose `m_e`, `c_e`, `k_e` the lab takes from the attached specimen).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoSpec {
    pub g: f64,
    pub a1_beta0: f64,
    pub beta1: f64,
    pub beta2: f64,
    pub a2: f64,
    pub a3: f64,
    pub derivative: Derivative,
}

impl ServoSpec {
    /// The benchmark's nominal values (Silva et al. 2020).
    pub fn benchmark() -> Self {
        let p = ServoParams::benchmark();
        Self {
            g: p.g,
            a1_beta0: p.a1_beta0,
            beta1: p.beta1,
            beta2: p.beta2,
            a2: p.a2,
            a3: p.a3,
            derivative: Derivative::FiniteDifference,
        }
    }
    /// The block form of a servo described by its physical parameters (exact derivative: the
    /// physical velocity feedback).
    pub fn from_physical(h: &super::servo::HydraulicActuator) -> Self {
        let [g, a1_beta0, beta1, beta2, a2, a3] = h.servo_coefficients();
        Self {
            g,
            a1_beta0,
            beta1,
            beta2,
            a2,
            a3,
            derivative: Derivative::Exact,
        }
    }

    /// The plant with a specimen of mass `m`, damping `c`, stiffness `k` at the DOF.
    pub fn params(&self, [m, c, k]: [f64; 3]) -> ServoParams {
        ServoParams {
            g: self.g,
            a1_beta0: self.a1_beta0,
            beta1: self.beta1,
            beta2: self.beta2,
            a2: self.a2,
            a3: self.a3,
            m_e: m,
            c_e: c,
            k_e: k,
        }
    }
}

/// An actuator as configured: dynamics plus a pure delay \[s\].
#[derive(Debug, Clone, PartialEq)]
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

    /// The lag \[s\] of the command at low frequency: the pure delay plus the group delay of the
    /// dynamics at `ω → 0` (`τ` of a first-order actuator, `2ζ/ω_a` of a second-order one,
    /// `−G′(0)/G(0)` of an LTI model); the default lead of phase-lag compensation. A servo-hydraulic
    /// plant (whose specimen is part of it) and a non-finite or negative result count the
    /// delay only.
    pub fn low_frequency_lag(&self) -> f64 {
        let dynamics = match &self.dynamics {
            Dynamics::Ideal | Dynamics::ServoHydraulic(_) => 0.0,
            Dynamics::FirstOrder { time_constant } => *time_constant,
            Dynamics::SecondOrder { frequency_hz, zeta } => 2.0 * zeta / (2.0 * std::f64::consts::PI * frequency_hz),
            Dynamics::Lti(ss) => {
                // G(s) = C (sI − A)⁻¹ B + D: G(0) = D − C A⁻¹ B, G′(0) = −C A⁻² B.
                match ss.a.clone().lu().solve(&ss.b) {
                    Some(x) => {
                        let g0 = ss.d - ss.c.dot(&x);
                        let dg0 = ss.a.clone().lu().solve(&x).map_or(f64::NAN, |y| -ss.c.dot(&y));
                        -dg0 / g0
                    }
                    None => 0.0,
                }
            }
        };
        self.delay
            + if dynamics.is_finite() && dynamics > 0.0 {
                dynamics
            } else {
                0.0
            }
    }

    /// The first four coefficients of the power series of the actuator's inverse at `s = 0`,
    /// `1/G(s) = g₀ + g₁ s + g₂ s² + g₃ s³ + …` \[sⁱ\]: the delay's `e^{sτ}` times the inverse of
    /// the dynamics (the model of adaptive model-based compensation). A servo-hydraulic plant
    /// (whose specimen is part of it) and an LTI model whose series does not exist count the
    /// delay only.
    pub fn inverse_series(&self) -> [f64; 4] {
        let t = self.delay;
        let delay = [1.0, t, t * t / 2.0, t * t * t / 6.0];
        let dynamics = match &self.dynamics {
            Dynamics::Ideal | Dynamics::ServoHydraulic(_) => None,
            Dynamics::FirstOrder { time_constant } => Some([1.0, *time_constant, 0.0, 0.0]),
            Dynamics::SecondOrder { frequency_hz, zeta } => {
                let w = 2.0 * std::f64::consts::PI * frequency_hz;
                Some([1.0, 2.0 * zeta / w, 1.0 / (w * w), 0.0])
            }
            Dynamics::Lti(ss) => lti_inverse_series(ss),
        };
        let Some(dyn_inv) = dynamics.filter(|g| g.iter().all(|v| v.is_finite())) else {
            return delay;
        };
        let mut out = [0.0; 4];
        for (k, o) in out.iter_mut().enumerate() {
            *o = (0..=k).map(|i| delay[i] * dyn_inv[k - i]).sum();
        }
        out
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
            Dynamics::Lti(ref ss) => {
                if ss.order() == 0 {
                    return Err(Error::invalid(
                        "actuator",
                        "a static gain is no actuator dynamics (the transfer function or state space has no state)",
                    ));
                }
                let ev = crate::linalg::eigenvalues(&ss.a)
                    .ok_or_else(|| Error::numerical("actuator", "eigenvalues of A could not be computed"))?;
                if let Some(z) = ev.iter().find(|z| z.re >= 0.0) {
                    return Err(Error::invalid(
                        "actuator",
                        format!(
                            "the actuator dynamics are not asymptotically stable (pole {:.6} {:+.6}i, need Re < 0)",
                            z.re, z.im
                        ),
                    ));
                }
            }
            Dynamics::ServoHydraulic(ref s) => {
                let all = [
                    ("g", s.g),
                    ("a1_beta0", s.a1_beta0),
                    ("beta1", s.beta1),
                    ("beta2", s.beta2),
                    ("a2", s.a2),
                    ("a3", s.a3),
                ];
                for (name, v) in all {
                    if !v.is_finite() {
                        return Err(Error::invalid(
                            format!("actuator.{name}"),
                            format!("must be finite, got {v}"),
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    /// Whether the dynamics need the attached specimen's `[m, c, k]` ([`Self::build_with_plant`]).
    pub fn needs_plant(&self) -> bool {
        matches!(self.dynamics, Dynamics::ServoHydraulic(_))
    }

    /// [`Self::build`] for dynamics whose plant contains the specimen: `plant = [m, c, k]` of
    /// the specimen at the actuator's DOF (ignored by the other kinds).
    pub fn build_with_plant(&self, dt_inner: f64, plant: Option<[f64; 3]>) -> Result<Actuator> {
        let Dynamics::ServoHydraulic(servo) = self.dynamics else {
            return self.build(dt_inner);
        };
        self.validate()?;
        require_positive("sub-step length", dt_inner)?;
        let plant = plant.ok_or_else(|| {
            Error::invalid(
                "actuator.kind",
                "servo_hydraulic needs the specimen at its DOF (a lumped_sdof specimen: its mass, damping and stiffness are part of the plant)",
            )
        })?;
        let params = servo.params(plant);
        params.validate().map_err(|e| match e {
            Error::InvalidInput { what, reason } => Error::invalid(what.replace("plant.m_e", "specimen.mass"), reason),
            other => other,
        })?;
        params.check_runnable(dt_inner)?;
        let servo_act = ServoActuator::new(params, servo.derivative, dt_inner).map_err(|e| match e {
            Error::InvalidInput { what, reason } => Error::invalid(
                what.replace("plant.m_e", "specimen.mass")
                    .replace("plant.", "actuator."),
                reason,
            ),
            other => other,
        })?;
        let mut a = self.build_linear(dt_inner, DMatrix::zeros(0, 0), DMatrix::zeros(0, 1))?;
        a.servo = Some(Box::new(servo_act));
        Ok(a)
    }

    /// Build an actuator for commands updated every `dt_inner` seconds.
    pub fn build(&self, dt_inner: f64) -> Result<Actuator> {
        self.validate()?;
        require_positive("sub-step length", dt_inner)?;
        let (a, b) = match &self.dynamics {
            Dynamics::Ideal => (DMatrix::zeros(0, 0), DMatrix::zeros(0, 1)),
            Dynamics::FirstOrder { time_constant: t } => (dmatrix![-1.0 / t], dmatrix![1.0 / t]),
            Dynamics::SecondOrder { frequency_hz, zeta } => {
                let w = 2.0 * std::f64::consts::PI * frequency_hz;
                (dmatrix![0.0, 1.0; -w * w, -2.0 * zeta * w], dmatrix![0.0; w * w])
            }
            Dynamics::Lti(ss) => {
                let n = ss.order();
                let mut a = self.build_linear(
                    dt_inner,
                    ss.a.clone(),
                    DMatrix::from_column_slice(n, 1, ss.b.as_slice()),
                )?;
                a.output = Some((ss.c.clone(), ss.d));
                return Ok(a);
            }
            Dynamics::ServoHydraulic(_) => return self.build_with_plant(dt_inner, None),
        };
        self.build_linear(dt_inner, a, b)
    }

    // NaN-safe checks: `!(x > 0.0)` also refuses NaN, which `x <= 0.0` would let through.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    fn build_linear(&self, dt_inner: f64, a: DMatrix<f64>, b: DMatrix<f64>) -> Result<Actuator> {
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
            spec: self.clone(),
            delay,
            a,
            b,
            output: None,
            servo: None,
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

    /// The signal at time `t`: linear between the two samples around it, the oldest sample
    /// before the history. The sample times fall from the newest (`k = 0`) to the oldest
    /// (`k = cap − 1`), so the first older sample at or before `t` is found by bisection:
    /// O(log n) per call, where a scan would cost O(delay / Δτ) — quadratic over a run with a
    /// long delay.
    fn value_at(&self, t: f64) -> f64 {
        let cap = self.times.len();
        let at = |k: usize| (self.head + cap - k) % cap;
        // first k in 1..cap with times[at(k)] <= t; cap when there is none
        let (mut lo, mut hi) = (1usize, cap);
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            if self.times[at(mid)] <= t {
                hi = mid;
            } else {
                lo = mid + 1;
            }
        }
        if lo == cap {
            return self.values[at(cap - 1)];
        }
        let (older, newer) = (at(lo), at(lo - 1));
        let (t0, t1) = (self.times[older], self.times[newer]);
        let r = if t1 > t0 { (t - t0) / (t1 - t0) } else { 1.0 };
        self.values[older] + r * (self.values[newer] - self.values[older])
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
    /// `(C, D)` of an LTI actuator (`position = C·z + D·delayed`); `None`: `position = z[0]`.
    output: Option<(DVector<f64>, f64)>,
    servo: Option<Box<ServoActuator>>,
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

    /// Achieved displacement at the end of the last interval \[m\].
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
        if let Some(servo) = &mut self.servo {
            servo.set_step(dt);
            servo.step_linear(delayed_start, self.delayed);
            self.position = servo.displacement();
            return self.position;
        }
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
                self.output_now()
            }
        };
        self.position
    }

    fn output_now(&self) -> f64 {
        match &self.output {
            None => self.z[0],
            Some((c, d)) => c.dot(&self.z) + d * self.delayed,
        }
    }

    /// The servo-hydraulic plant, for that kind.
    pub fn servo(&self) -> Option<&ServoActuator> {
        self.servo.as_deref()
    }

    /// State: `[delayed command, dynamics state…, delay history…]`.
    /// The servo-hydraulic kind stores its plant state in place of the dynamics state.
    pub fn state_len(&self) -> usize {
        1 + self.dynamics_len() + self.delay.as_ref().map_or(0, DelayLine::state_len)
    }
    fn dynamics_len(&self) -> usize {
        match &self.servo {
            Some(_) => ServoActuator::STATE_LEN,
            None => self.z.len(),
        }
    }
    pub fn write_state(&self, out: &mut [f64]) {
        out[0] = self.delayed;
        let nz = self.dynamics_len();
        match &self.servo {
            Some(s) => s.write_state(&mut out[1..1 + nz]),
            None => out[1..1 + nz].copy_from_slice(self.z.as_slice()),
        }
        if let Some(d) = &self.delay {
            d.write_state(&mut out[1 + nz..]);
        }
    }
    pub fn read_state(&mut self, s: &[f64]) {
        self.delayed = s[0];
        let nz = self.dynamics_len();
        if let Some(servo) = &mut self.servo {
            servo.read_state(&s[1..1 + nz]);
            self.position = servo.displacement();
        } else {
            self.z.copy_from_slice(&s[1..1 + nz]);
            self.position = if nz > 0 { self.output_now() } else { self.delayed };
        }
        if let Some(d) = &mut self.delay {
            d.read_state(&s[1 + nz..]);
        }
    }
}

/// `1/G(s)` to third order for `G(s) = D + C (sI − A)⁻¹ B = Σ Gₖ sᵏ`, `G₀ = D − C A⁻¹ B`,
/// `Gₖ = −C A⁻⁽ᵏ⁺¹⁾ B`; `None` if `A` is singular or `G(0) = 0`.
fn lti_inverse_series(ss: &StateSpace) -> Option<[f64; 4]> {
    let lu = ss.a.clone().lu();
    let mut x = ss.b.clone();
    let mut g = [0.0; 4];
    for (k, gk) in g.iter_mut().enumerate() {
        x = lu.solve(&x)?;
        *gk = -ss.c.dot(&x) + if k == 0 { ss.d } else { 0.0 };
    }
    if g[0] == 0.0 {
        return None;
    }
    let mut q = [0.0; 4];
    for k in 0..4 {
        let r = if k == 0 { 1.0 } else { 0.0 } - (1..=k).map(|i| g[i] * q[k - i]).sum::<f64>();
        q[k] = r / g[0];
    }
    Some(q)
}

#[cfg(test)]
mod tests {
    use super::DelayLine;

    /// The scan the bisection replaced: newest to oldest, the first sample at or before `t`.
    fn scan(line: &DelayLine, t: f64) -> f64 {
        let cap = line.times.len();
        let mut newer = line.head;
        for _ in 1..cap {
            let older = (newer + cap - 1) % cap;
            if line.times[older] <= t {
                let (t0, t1) = (line.times[older], line.times[newer]);
                let r = if t1 > t0 { (t - t0) / (t1 - t0) } else { 1.0 };
                return line.values[older] + r * (line.values[newer] - line.values[older]);
            }
            newer = older;
        }
        line.values[newer]
    }

    /// The bisection gives the scan's values bit for bit: irregular spacing (re-spaced
    /// sub-steps, down to half), the history wrapping many times, times before the history,
    /// between samples and on them.
    #[test]
    fn bisection_equals_the_scan() {
        let mut line = DelayLine::new(0.0137, 0.001);
        let mut state = 12345u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for k in 0..5000 {
            let dt = 0.001 * (0.5 + 0.5 * next());
            let value = (k as f64 * 0.01).sin() + next();
            let delayed = line.push(value, dt);
            assert_eq!(
                delayed.to_bits(),
                scan(&line, line.now - line.delay).to_bits(),
                "push {k}"
            );
            for t in [
                line.now - 1.0,
                line.now - 0.02,
                line.now - 0.005 * next(),
                line.now,
                line.times[line.head],
            ] {
                assert_eq!(
                    line.value_at(t).to_bits(),
                    scan(&line, t).to_bits(),
                    "push {k}, t = {t}"
                );
            }
        }
    }
}
