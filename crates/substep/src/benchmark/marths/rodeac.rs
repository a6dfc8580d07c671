//! RoDeAC, the robust decentralised adaptive controller of the public maRTHS toolset (Quiroz,
//! Gálmez & Fermandois 2024), reproduced from its Simulink blocks ("MIMO CONTROLLER", one
//! "RLS-AC" per actuator, no cross terms). Per actuator and sample `k` (signals in mm):
//!
//! ```text
//! T_k  = [x_t(k), x_t(k−1), x_t(k−2), x_t(k−3)]          tapped target
//! φ_k  = [x̃_m(k), …, x̃_m(k−3)],   x̃_m = B(z) x_m        measured, 4th-order 20 Hz Butterworth
//! ũ_c  = B(z) u_c                                       the command, filtered alike
//! g_k  = P φ / (λ + φᵀ P φ),   e_k = ũ_c(k) − θᵀ φ
//! θ_k  = θ + g e,   P_k = (P − g φᵀ P)/λ,   λ = 1
//! u_c(k) = θ_kᵀ T_k                                     the command sent
//! ```
//!
//! i.e. an RLS identification of the inverse plant (filtered measured → filtered command) whose
//! weights act on the target. The new `θ_k` is used in the same sample, and `ũ_c(k)` depends on
//! `u_c(k)` through the filter's direct term `b₀`: Simulink solves this algebraic loop
//! iteratively; it is linear, so here it is solved exactly,
//! `u_c = (θᵀT + (Tᵀg)(s − θᵀφ)) / (1 − b₀ Tᵀg)` with `s` the filter output without the
//! current input. The Butterworth coefficients are MATLAB's `butter(4, 20/512)` (bilinear, with
//! prewarping), as computed by SciPy's identical design; the initial `θ`, `P` are the toolset's
//! `Initial_parameters.mat`. No allocation per sample.

use super::data::InitialParameters;

/// `butter(4, 20/(1024/2))`: numerator `b`, denominator `a` (`a₀ = 1`).
pub const BUTTER_B: [f64; 5] = [
    1.213433306582026e-05,
    4.853733226328104e-05,
    7.280599839492156e-05,
    4.853733226328104e-05,
    1.213433306582026e-05,
];
pub const BUTTER_A: [f64; 5] = [
    1.0,
    -3.6794182542904585,
    5.088644606369255,
    -3.134517189896432,
    0.7254849871466889,
];

/// A direct-form-II filter `B(z)/A(z)` of order 4 from rest.
#[derive(Debug, Clone, Default)]
pub struct Butterworth {
    w: [f64; 4],
}

impl Butterworth {
    /// The output's part that does not depend on the current input:
    /// `y = b₀ u + rest`, `rest = b₀ (−Σ aᵢ w_{k−i}) + Σ bᵢ w_{k−i}`.
    pub fn rest(&self) -> f64 {
        let feedback: f64 = (1..5).map(|i| -BUTTER_A[i] * self.w[i - 1]).sum();
        BUTTER_B[0] * feedback + (1..5).map(|i| BUTTER_B[i] * self.w[i - 1]).sum::<f64>()
    }
    /// Filter one sample.
    pub fn step(&mut self, u: f64) -> f64 {
        let w0 = u - (1..5).map(|i| BUTTER_A[i] * self.w[i - 1]).sum::<f64>();
        let y = BUTTER_B[0] * w0 + (1..5).map(|i| BUTTER_B[i] * self.w[i - 1]).sum::<f64>();
        self.w = [w0, self.w[0], self.w[1], self.w[2]];
        y
    }
}

/// One actuator's RLS-AC block.
#[derive(Debug, Clone)]
pub struct RlsAc {
    pub theta: [f64; 4],
    pub p: [[f64; 4]; 4],
    lambda: f64,
    target: [f64; 4],
    phi: [f64; 4],
    measured_filter: Butterworth,
    command_filter: Butterworth,
}

fn dot(a: &[f64; 4], b: &[f64; 4]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

impl RlsAc {
    pub fn new(theta: [f64; 4], p: [[f64; 4]; 4], lambda: f64) -> Self {
        Self {
            theta,
            p,
            lambda,
            target: [0.0; 4],
            phi: [0.0; 4],
            measured_filter: Butterworth::default(),
            command_filter: Butterworth::default(),
        }
    }

    /// The RLS update with regressor `phi` and filtered command `u_filtered` (the toolset's
    /// `fcn(xm, u, forgfact, damb_a, P_corr_a)`), returning the gain `g`.
    pub fn update(&mut self, phi: &[f64; 4], u_filtered: f64) -> [f64; 4] {
        let g = self.gain(phi);
        let error = u_filtered - dot(&self.theta, phi);
        self.apply(phi, &g, error);
        g
    }

    fn gain(&self, phi: &[f64; 4]) -> [f64; 4] {
        let pphi: [f64; 4] = std::array::from_fn(|i| dot(&self.p[i], phi));
        let denom = self.lambda + dot(phi, &pphi);
        pphi.map(|v| v / denom)
    }

    fn apply(&mut self, phi: &[f64; 4], g: &[f64; 4], error: f64) {
        // φᵀP (row), P symmetric in exact arithmetic but kept as the toolset computes it.
        let phit_p: [f64; 4] = std::array::from_fn(|j| (0..4).map(|i| phi[i] * self.p[i][j]).sum());
        for ((row, gi), theta) in self.p.iter_mut().zip(g).zip(&mut self.theta) {
            for (p, pj) in row.iter_mut().zip(&phit_p) {
                *p = (*p - gi * pj) / self.lambda;
            }
            *theta += gi * error;
        }
    }

    /// The command `u_c(k)` \[mm\] for the target `x_t(k)` and the measurement `x_m(k)` \[mm\].
    pub fn command(&mut self, target: f64, measured: f64) -> f64 {
        self.target = [target, self.target[0], self.target[1], self.target[2]];
        let xf = self.measured_filter.step(measured);
        self.phi = [xf, self.phi[0], self.phi[1], self.phi[2]];
        let phi = self.phi;
        let g = self.gain(&phi);
        let s = self.command_filter.rest();
        let tg = dot(&self.target, &g);
        let predicted = dot(&self.theta, &phi);
        let u = (dot(&self.theta, &self.target) + tg * (s - predicted)) / (1.0 - BUTTER_B[0] * tg);
        let u_filtered = self.command_filter.step(u);
        self.apply(&phi, &g, u_filtered - predicted);
        u
    }
}

/// Both actuators' blocks from the toolset's initial parameters.
pub fn rodeac(init: &InitialParameters) -> [RlsAc; 2] {
    [0, 1].map(|a| RlsAc::new(init.theta[a], init.p[a], init.forgetting))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_filter_is_a_unit_gain_20_hz_low_pass() {
        let dc = BUTTER_B.iter().sum::<f64>() / BUTTER_A.iter().sum::<f64>();
        assert!((dc - 1.0).abs() < 1e-9, "{dc}");
        let z = nalgebra::Complex::from_polar(1.0, 2.0 * std::f64::consts::PI * 20.0 / 1024.0);
        let eval = |c: &[f64; 5]| {
            c.iter()
                .enumerate()
                .fold(nalgebra::Complex::new(0.0, 0.0), |acc, (i, v)| {
                    acc + *v * z.powi(-(i as i32))
                })
        };
        let mag = (eval(&BUTTER_B) / eval(&BUTTER_A)).norm();
        assert!((mag - 0.5f64.sqrt()).abs() < 1e-9, "{mag}");
        // The step response settles at 1.
        let mut f = Butterworth::default();
        let mut y = 0.0;
        for _ in 0..4096 {
            let r = f.rest();
            y = f.step(1.0);
            assert!((y - (BUTTER_B[0] + r)).abs() < 1e-15);
        }
        assert!((y - 1.0).abs() < 1e-12);
    }

    #[test]
    fn the_command_solves_the_algebraic_loop_exactly() {
        // u = θ_kᵀ T with θ_k from the filtered u itself.
        let init = InitialParameters::toolset();
        let mut c = rodeac(&init)[0].clone();
        for k in 0..600 {
            let t = k as f64 / 1024.0;
            let target = 3.0 * (2.0 * std::f64::consts::PI * 2.3 * t).sin();
            let measured = 0.86 * 3.0 * (2.0 * std::f64::consts::PI * 2.3 * (t - 0.02)).sin();
            let u = c.command(target, measured);
            assert!(
                (u - dot(&c.theta, &c.target)).abs() <= 1e-9 * u.abs().max(1.0),
                "{k}: {u}"
            );
        }
    }
}
