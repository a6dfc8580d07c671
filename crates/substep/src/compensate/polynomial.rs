//! Polynomial extrapolation of the target (Horiuchi et al. 1999).

use super::{Guard, GuardTrip, History, PhaseLagCompensator};
use crate::error::{Error, Result};

/// Weights `w_0 … w_p` of the Lagrange polynomial through the samples at `x_i = −i`
/// (`d_j, d_{j−1}, …, d_{j−p}`) evaluated at `x = lead`:
/// `d̂_{j+lead} = Σ_i w_i d_{j−i}`, `w_i = Π_{m≠i} (lead − x_m)/(x_i − x_m)`.
/// `lead = 1`, `p = 3` gives `[4, −6, 4, −1]`.
pub fn lagrange_extrapolation_weights(order: usize, lead: f64) -> Vec<f64> {
    (0..=order)
        .map(|i| {
            let xi = -(i as f64);
            (0..=order)
                .filter(|&m| m != i)
                .map(|m| {
                    let xm = -(m as f64);
                    (lead - xm) / (xi - xm)
                })
                .product()
        })
        .collect()
}

/// `Δu_j = d̂_{j+lead} − d_j` with the order-`p` Lagrange extrapolation through the targets
/// `d_j, d_{j−s}, …, d_{j−p s}` (node spacing `s`, 1 by default: the last `p + 1` targets); `lead`
/// is the actuator delay in sub-steps (may be fractional). Nodes further apart extrapolate less
/// far in units of their spacing, so the noise on the target is amplified less (the benchmark's
/// own polynomial example places them 49 samples apart). Uses the targets only,
/// so it is a fixed linear filter (not adaptive); measured displacements are ignored. The guard's
/// bound is checked unless the compensator is frozen (for the linear analysis).
#[derive(Debug, Clone)]
pub struct Polynomial {
    order: usize,
    lead: f64,
    spacing: usize,
    weights: Vec<f64>,
    /// `d_{j−1} … d_{j−p s}` (zero before the start).
    past: History,
    guard: Guard,
}

impl Polynomial {
    /// `order ∈ 1..=3`, `lead ≥ 0` sub-steps.
    pub fn new(order: usize, lead: f64) -> Result<Self> {
        if !(1..=3).contains(&order) {
            return Err(Error::invalid(
                "phase_lag.order",
                format!("polynomial extrapolation supports orders 1 to 3, got {order}"),
            ));
        }
        if !(lead.is_finite() && lead >= 0.0) {
            return Err(Error::invalid(
                "phase_lag.lead",
                format!("must be a finite number of sub-steps >= 0, got {lead}"),
            ));
        }
        Ok(Self {
            order,
            lead,
            spacing: 1,
            weights: lagrange_extrapolation_weights(order, lead),
            past: History::new(order),
            guard: Guard::default(),
        })
    }
    /// Nodes `spacing` sub-steps apart (1 to 4096).
    pub fn with_spacing(mut self, spacing: usize) -> Result<Self> {
        if !(1..=4096).contains(&spacing) {
            return Err(Error::invalid(
                "phase_lag.spacing",
                format!("must be 1 to 4096 sub-steps, got {spacing}"),
            ));
        }
        self.spacing = spacing;
        self.weights = lagrange_extrapolation_weights(self.order, self.lead / spacing as f64);
        self.past = History::new(self.order * spacing);
        Ok(self)
    }
    pub fn spacing(&self) -> usize {
        self.spacing
    }
    pub fn with_guard(mut self, guard: Guard) -> Self {
        self.guard = guard;
        self
    }
    pub fn order(&self) -> usize {
        self.order
    }
    pub fn lead(&self) -> f64 {
        self.lead
    }
    /// `[w_0 … w_p]` for `d_j … d_{j−p}`.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }
}

impl PhaseLagCompensator for Polynomial {
    fn correction(&mut self, target: f64, measured_prev: f64, h: f64) -> f64 {
        if !self.guard.admit(target, measured_prev) {
            return 0.0;
        }
        // d̂ − d_j = Σ_{i≥1} w_i (d_{j−i} − d_j) since Σ w_i = 1: exactly 0 for a constant target.
        let mut du = 0.0;
        for i in 1..=self.order {
            du += self.weights[i] * (self.past.get(i * self.spacing - 1) - target);
        }
        self.past.push(target);
        self.guard.output(du, h)
    }
    fn kind(&self) -> &'static str {
        "polynomial"
    }
    fn is_adaptive(&self) -> bool {
        false
    }
    fn set_frozen(&mut self, frozen: bool) {
        self.guard.set_frozen(frozen);
    }
    fn trip(&self) -> Option<GuardTrip> {
        self.guard.trip()
    }
    fn state_len(&self) -> usize {
        self.order * self.spacing
    }
    fn write_state(&self, out: &mut [f64]) {
        self.past.write(out);
    }
    fn read_state(&mut self, s: &[f64]) {
        self.past.read(s);
    }
}
