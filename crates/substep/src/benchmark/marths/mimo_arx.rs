//! The ARX phase-lag compensation over both actuators at once (a MIMO identification), to answer
//! whether one model over both channels beats the decentralised compensators on the coupled
//! plant (docs/benchmark.md, "maRTHS"). Per actuator `i` and sample `j`, with `L = k_lag`,
//! `S = span` and the smoothed target velocities `v_c` of both channels (`c = 1, 2`, as in
//! [`crate::compensate::ArxPhaseLag`]: two low-pass stages of `S/2`, differences over `S`):
//!
//! ```text
//! Δu_i(j) = Σ_c Σ_l θ_i,cl v_c(j − l S)  [+ Σ_c θ_i,c d_c(j)]      (cross: both channels; static: the targets)
//! ```
//!
//! identified like the single-channel compensator's delayed pairing: every `L` samples the
//! regressor of `L` samples ago is fitted by RLS to the correction that would have cancelled the
//! tracking error seen now, `h Δu_i(j−1−L) + (d_i(j−1) − y_i(j))`. `cross = false` keeps each
//! actuator's own channel (decentralised); `static_term` adds the targets themselves, which a
//! velocity regressor lacks: the plant's static gains (0.864, 0.926, and 0.13–0.14 across) are
//! not 1. Regressor blocks are normalised by their running maxima (velocities, targets), which
//! keeps `p0` meaningful and cancels in `Δu`. No allocation per sample.

use crate::error::{Error, Result};
use crate::ident::Rls;

/// Settings of [`MimoArx`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MimoArxSpec {
    pub k_lag: usize,
    pub span: usize,
    pub n_u: usize,
    pub lambda: f64,
    pub p0: f64,
    /// Both channels in each actuator's regressor.
    pub cross: bool,
    /// The targets themselves in the regressor.
    pub static_term: bool,
}

impl Default for MimoArxSpec {
    /// `k_lag = 8`, `span = 8`, `n_u = 5`, `λ = 0.999`, `p0 = 100`, both channels and the static
    /// term (the best J2 of actuator 1 with noise on El Centro over k_lag ∈ {8, 16, 32},
    /// span ∈ {8, 16}; docs/benchmark.md).
    fn default() -> Self {
        Self {
            k_lag: 8,
            span: 8,
            n_u: 5,
            lambda: 0.999,
            p0: 100.0,
            cross: true,
            static_term: true,
        }
    }
}

/// Samples before the first update (the ramp-in: the running maxima that normalise the regressor
/// are still growing).
const WARM_UP: usize = 1024;

/// Longest history kept \[samples\].
const MAX_HISTORY: usize = 1 << 14;

/// A ring of the newest samples, age 0 = the newest.
#[derive(Debug, Clone)]
struct Ring {
    data: Vec<f64>,
    head: usize,
}

impl Ring {
    fn new(n: usize) -> Self {
        Self {
            data: vec![0.0; n.max(1)],
            head: 0,
        }
    }
    fn push(&mut self, v: f64) {
        self.head = (self.head + 1) % self.data.len();
        self.data[self.head] = v;
    }
    fn get(&self, age: usize) -> f64 {
        let n = self.data.len();
        self.data[(self.head + n - age % n) % n]
    }
}

/// One channel's signals.
#[derive(Debug, Clone)]
struct Channel {
    stage: [f64; 2],
    smoothed: Ring,
    velocity: Ring,
    target: Ring,
    applied: Ring,
}

/// The MIMO (or decentralised) ARX compensator of the module docs.
#[derive(Debug, Clone)]
pub struct MimoArx {
    spec: MimoArxSpec,
    alpha: f64,
    rls: [Rls; 2],
    ch: [Channel; 2],
    phi: Vec<f64>,
    /// Per actuator: the weights in use, blended over each interval from `from` to the estimate.
    theta: [Vec<f64>; 2],
    from: [Vec<f64>; 2],
    scale_v: f64,
    scale_d: f64,
    count: usize,
}

impl MimoArx {
    pub fn new(spec: MimoArxSpec) -> Result<Self> {
        if spec.k_lag == 0 || spec.span == 0 || !(1..=12).contains(&spec.n_u) {
            return Err(Error::invalid(
                "controller.arx_mimo",
                format!(
                    "needs k_lag ≥ 1, span ≥ 1, n_u in 1..=12; got {}, {}, {}",
                    spec.k_lag, spec.span, spec.n_u
                ),
            ));
        }
        let len = spec.k_lag + spec.n_u * spec.span + 2;
        if len > MAX_HISTORY {
            return Err(Error::invalid(
                "controller.arx_mimo",
                format!("k_lag + n_u·span exceeds {MAX_HISTORY} samples"),
            ));
        }
        let channels = if spec.cross { 2 } else { 1 };
        let n = channels * (spec.n_u + usize::from(spec.static_term));
        let rls = [
            Rls::new(n, spec.lambda, spec.p0)?.with_covariance_bound(spec.p0)?,
            Rls::new(n, spec.lambda, spec.p0)?.with_covariance_bound(spec.p0)?,
        ];
        let channel = || Channel {
            stage: [0.0; 2],
            smoothed: Ring::new(spec.span + 1),
            velocity: Ring::new(len),
            target: Ring::new(len),
            applied: Ring::new(len),
        };
        let smoothing = spec.span as f64 / 2.0;
        Ok(Self {
            spec,
            alpha: 1.0 - (-1.0 / smoothing).exp(),
            rls,
            ch: [channel(), channel()],
            phi: vec![0.0; n],
            theta: [vec![0.0; n], vec![0.0; n]],
            from: [vec![0.0; n], vec![0.0; n]],
            scale_v: 0.0,
            scale_d: 0.0,
            count: 0,
        })
    }

    /// The regressor of actuator `i` at `age` (0: the sample just pushed), normalised.
    fn regressor(&mut self, i: usize, age: usize) {
        let s = &self.spec;
        let (sv, sd) = (self.scale_v.max(f64::MIN_POSITIVE), self.scale_d.max(f64::MIN_POSITIVE));
        let mut at = 0;
        for c in 0..2 {
            if !s.cross && c != i {
                continue;
            }
            for l in 0..s.n_u {
                self.phi[at] = self.ch[c].velocity.get(age + l * s.span) / sv;
                at += 1;
            }
            if s.static_term {
                self.phi[at] = self.ch[c].target.get(age) / sd;
                at += 1;
            }
        }
    }

    /// Corrections `Δu` \[mm\] for the targets `d` and the measurements `y` of this sample (the
    /// response to the previous commands), `h` the ramp.
    pub fn corrections(&mut self, d: [f64; 2], y: [f64; 2], h: f64) -> [f64; 2] {
        let (l, s) = (self.spec.k_lag, self.spec.span);
        // The tracking error of the previous target, before this sample's push.
        let lag = [self.ch[0].target.get(0) - y[0], self.ch[1].target.get(0) - y[1]];
        for (c, &dc) in self.ch.iter_mut().zip(&d) {
            c.stage[0] += self.alpha * (dc - c.stage[0]);
            c.stage[1] += self.alpha * (c.stage[0] - c.stage[1]);
            let v = c.stage[1] - c.smoothed.get(s - 1);
            c.smoothed.push(c.stage[1]);
            c.velocity.push(v);
            c.target.push(dc);
            self.scale_v = self.scale_v.max(v.abs());
            self.scale_d = self.scale_d.max(dc.abs());
        }
        // As the single-channel compensator: velocities and errors on one scale.
        self.scale_v = self.scale_v.max(lag[0].abs()).max(lag[1].abs());
        let sv = self.scale_v.max(f64::MIN_POSITIVE);
        if self.count > l.max(WARM_UP) && self.count.is_multiple_of(l) && self.scale_v > 0.0 {
            for (i, lag_i) in lag.iter().enumerate() {
                // The regressor of the correction sent at j − 1 − L (age L + 1 after the push).
                self.regressor(i, l + 1);
                let want = (self.ch[i].applied.get(l) + lag_i) / sv;
                let e = want - self.rls[i].predict(&self.phi);
                self.rls[i].update_with_error(&self.phi, e);
                self.from[i].copy_from_slice(&self.theta[i]);
            }
        }
        // Blend to the estimate over the interval: no jumps in the command.
        let r = ((self.count % l) + 1) as f64 / l as f64;
        let mut du = [0.0; 2];
        for (i, out) in du.iter_mut().enumerate() {
            for ((t, f), e) in self.theta[i].iter_mut().zip(&self.from[i]).zip(self.rls[i].theta()) {
                *t = f + r * (e - f);
            }
            self.regressor(i, 0);
            *out = sv * self.phi.iter().zip(&self.theta[i]).map(|(p, t)| p * t).sum::<f64>();
        }
        for (c, u) in self.ch.iter_mut().zip(&du) {
            c.applied.push(h * u);
        }
        self.count += 1;
        [h * du[0], h * du[1]]
    }
}
