//! A servo-hydraulic actuator in block form with the specimen in its plant and the natural
//! velocity feedback of the specimen (control–structure interaction, CSI), as in the RTHS
//! benchmark (Silva et al. 2020).
//!
//! ```text
//! e = g·u − x                                   (inner displacement loop, gain g)
//! p = a₁β₀ / (s² + β₁ s + β₂) · e               (servo-valve)
//! w = p − a₂ D(x)                               (CSI: the specimen's velocity fed back)
//! F = w / (s + a₃)                              (actuator force)
//! x = F / (m_e s² + c_e s + k_e)                (specimen)
//! ```
//!
//! Five states `[p, ṗ, F, x, ẋ]`, input `u` held over the step, integrated by classical RK4 at
//! the step `h` (the benchmark's integrator; see [`crate::transfer::lti`]). `D(x)` is either
//! the exact derivative `ẋ` ([`Derivative::Exact`]) or the benchmark's finite-difference
//! "derivative block" ([`Derivative::FiniteDifference`]): at the start of step `k`,
//! `D = (x_k − x_{k−1})/h` (0 at `k = 0`); at an RK4 stage `t_k + τ`, `D = (x(t_k + τ) − x_k)/τ`.
//!
//! With the exact derivative the plant is
//! `G_p(s) = g a₁β₀ / ((s² + β₁ s + β₂)((s + a₃)(m_e s² + c_e s + k_e) + a₂ s) + a₁β₀)`
//! ([`ServoParams::closed_form`]).
//!
//! [`DifferenceForce`] is the load cell as the benchmark builds it from the measured motion:
//! `f_k = k_e x_k + c_e D1_k + m_e D2_k`, `D1_k = (x_k − x_{k−1})/h`, `D2_k = (D1_k − D1_{k−1})/h`
//! (both 0 at `k = 0`).

use super::lti::{TransferFunction, poly_add, poly_mul};
use crate::error::{Error, Result};
use crate::linalg::{axpy_array, rk4_combine};

/// Parameters of the servo-hydraulic plant (SI: m, N, s, kg).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoParams {
    /// Inner-loop gain `g` on the command.
    pub g: f64,
    /// Servo-valve gain `a₁β₀`.
    pub a1_beta0: f64,
    pub beta1: f64,
    pub beta2: f64,
    /// Velocity-feedback (CSI) coefficient `a₂`.
    pub a2: f64,
    pub a3: f64,
    /// Specimen mass, damping, stiffness.
    pub m_e: f64,
    pub c_e: f64,
    pub k_e: f64,
}

impl ServoParams {
    /// The benchmark's nominal plant.
    pub fn benchmark() -> Self {
        Self {
            g: 1.0261,
            a1_beta0: 2.1283e13,
            beta1: 425.0,
            beta2: 9.9976e4,
            a2: 4.2297e6,
            a3: 3.3,
            m_e: 29.13,
            c_e: 114.2208671,
            k_e: 1.19e6,
        }
    }

    pub fn validate(&self) -> Result<()> {
        let all = [
            ("g", self.g),
            ("a1_beta0", self.a1_beta0),
            ("beta1", self.beta1),
            ("beta2", self.beta2),
            ("a2", self.a2),
            ("a3", self.a3),
            ("m_e", self.m_e),
            ("c_e", self.c_e),
            ("k_e", self.k_e),
        ];
        for (name, v) in all {
            if !v.is_finite() {
                return Err(Error::invalid(
                    format!("plant.{name}"),
                    format!("must be finite, got {v}"),
                ));
            }
        }
        crate::error::require_positive("plant.m_e", self.m_e)?;
        Ok(())
    }

    /// `G_p(s) = x/u` with the exact derivative (module docs).
    pub fn closed_form(&self) -> Result<TransferFunction> {
        let servo_den = [1.0, self.beta1, self.beta2];
        let act_spec = poly_mul(&[1.0, self.a3], &[self.m_e, self.c_e, self.k_e]);
        let inner = poly_add(&act_spec, &[self.a2, 0.0]);
        let den = poly_add(&poly_mul(&servo_den, &inner), &[self.a1_beta0]);
        TransferFunction::new("plant", &[self.g * self.a1_beta0], &den)
    }
}

impl ServoParams {
    /// The plant's state matrix with the exact derivative, states `[p, ṗ, F, x, ẋ]` (the
    /// command `u` is the input and does not enter it).
    pub fn state_matrix(&self) -> nalgebra::DMatrix<f64> {
        let p = self;
        nalgebra::dmatrix![
            0.0, 1.0, 0.0, 0.0, 0.0;
            -p.beta2, -p.beta1, 0.0, -p.a1_beta0, 0.0;
            1.0, 0.0, -p.a3, 0.0, -p.a2;
            0.0, 0.0, 0.0, 0.0, 1.0;
            0.0, 0.0, 1.0 / p.m_e, -p.k_e / p.m_e, -p.c_e / p.m_e
        ]
    }

    /// The closed-loop poles of the servo loop with the specimen (exact derivative) \[1/s\].
    pub fn poles(&self) -> Result<Vec<nalgebra::Complex<f64>>> {
        crate::linalg::eigenvalues(&self.state_matrix())
            .ok_or_else(|| Error::numerical("actuator", "the poles of the servo loop could not be computed"))
    }

    /// Refuse a plant that cannot be run: a servo loop that is unstable with this specimen
    /// (a pole with `Re ≥ 0`), or one that RK4 at the inner step `h` cannot integrate (a pole
    /// `λ` with `|R(λh)| > 1`, `R(z) = 1 + z + z²/2 + z³/6 + z⁴/24`); the message names the pole
    /// and what to change. Errors name `actuator`.
    pub fn check_runnable(&self, h: f64) -> Result<()> {
        let poles = self.poles()?;
        let pole = |z: &nalgebra::Complex<f64>| {
            format!(
                "{} {} {}i 1/s",
                crate::format::sig(z.re, 4),
                if z.im < 0.0 { '-' } else { '+' },
                crate::format::sig(z.im.abs(), 4)
            )
        };
        let specimen = format!(
            "m = {} kg, c = {} N·s/m, k = {} N/m",
            crate::format::sig(self.m_e, 4),
            crate::format::sig(self.c_e, 4),
            crate::format::sig(self.k_e, 4)
        );
        if let Some(z) = poles.iter().find(|z| z.re >= 0.0) {
            return Err(Error::invalid(
                "actuator",
                format!(
                    "the servo loop with the specimen at its DOF ({specimen}) is unstable: closed-loop pole \
                     {} has Re >= 0; lower the loop gain (kp or valve_flow of a hydraulic actuator, \
                     a1_beta0 of servo_hydraulic) or raise the valve's damping",
                    pole(z)
                ),
            ));
        }
        let rk4 = |z: nalgebra::Complex<f64>| (1.0 + z + z * z / 2.0 + z * z * z / 6.0 + z * z * z * z / 24.0).norm();
        if let Some(z) = poles.iter().find(|&&z| rk4(z * h) > 1.0) {
            // the smallest subdivision of h that makes every pole stable
            let factor = (1..=1 << 20)
                .map(|n: u32| n as f64)
                .find(|&n| poles.iter().all(|&p| rk4(p * (h / n)) <= 1.0))
                .unwrap_or(f64::INFINITY);
            return Err(Error::invalid(
                "actuator",
                format!(
                    "the servo plant's pole {} (with the specimen: {specimen}) is too fast for RK4 \
                     at the inner step {} s; divide the inner step by at least {factor} (substructure.inner_steps)",
                    pole(z),
                    crate::format::sig(h, 4)
                ),
            ));
        }
        Ok(())
    }
}

/// A servo-hydraulic actuator described by its physical parameters (SI), as a lab knows it:
/// the servo-controller's proportional gain, the servo-valve's rated flow and dynamics, the
/// piston area, the oil column's stiffness and the leakage. It maps onto the block form of the
/// module docs with the exact derivative (docs/config.md, `kind = "hydraulic"`):
///
/// ```text
/// i = k_p (g u − x)                                   valve command (1 = fully open)
/// q = Q_r ω_v² / (s² + 2ζ_v ω_v s + ω_v²) · i         valve flow [m³/s]
/// q = A ẋ + (A / k_oil) Ḟ + (C_l / A) F               continuity (P = F/A, k_oil = 4 β_e A² / V)
/// m_e ẍ + c_e ẋ + k_e x = F                           piston + specimen
/// ```
///
/// so `a₁β₀ = k_oil Q_r k_p ω_v² / A`, `β₁ = 2ζ_v ω_v`, `β₂ = ω_v²`, `a₂ = k_oil`,
/// `a₃ = k_oil C_l / A²` ([`Self::servo_coefficients`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HydraulicActuator {
    /// Piston area `A` \[m²\].
    pub piston_area: f64,
    /// Oil column stiffness `k_oil` \[N/m\] (`4 β_e A² / V`, [`Self::oil_stiffness`]).
    pub oil_stiffness: f64,
    /// Leakage coefficient `C_l` across the piston \[m³/(s·Pa)\].
    pub leakage: f64,
    /// Rated flow `Q_r` of the servo-valve at full opening \[m³/s\].
    pub valve_flow: f64,
    /// Servo-valve natural frequency `f_v` \[Hz\] and damping ratio `ζ_v`.
    pub valve_frequency_hz: f64,
    pub valve_damping: f64,
    /// Proportional gain `k_p` of the servo-controller \[1/m\]: valve opening per metre of
    /// displacement error.
    pub kp: f64,
    /// Gain `g` on the command.
    pub command_gain: f64,
}

impl HydraulicActuator {
    /// `4 β_e A² / V`: the stiffness of the two oil columns of a symmetric actuator with its
    /// piston centred (bulk modulus `β_e` \[Pa\], total oil volume `V` \[m³\]).
    pub fn oil_stiffness(bulk_modulus: f64, piston_area: f64, oil_volume: f64) -> f64 {
        4.0 * bulk_modulus * piston_area * piston_area / oil_volume
    }

    /// Every parameter finite and positive (leakage: non-negative); errors name
    /// `actuator.KEY` with the config's key names.
    pub fn validate(&self) -> Result<()> {
        for (key, v) in [
            ("piston_area", self.piston_area),
            ("oil_stiffness", self.oil_stiffness),
            ("valve_flow", self.valve_flow),
            ("valve_frequency", self.valve_frequency_hz),
            ("valve_damping", self.valve_damping),
            ("kp", self.kp),
            ("command_gain", self.command_gain),
        ] {
            crate::error::require_positive(&format!("actuator.{key}"), v)?;
        }
        crate::error::require_non_negative("actuator.leakage", self.leakage)?;
        Ok(())
    }

    /// `(g, a₁β₀, β₁, β₂, a₂, a₃)` of the block form (struct docs).
    pub fn servo_coefficients(&self) -> [f64; 6] {
        let w = 2.0 * std::f64::consts::PI * self.valve_frequency_hz;
        let k = self.oil_stiffness;
        let a = self.piston_area;
        [
            self.command_gain,
            k * self.valve_flow * self.kp * w * w / a,
            2.0 * self.valve_damping * w,
            w * w,
            k,
            k * self.leakage / (a * a),
        ]
    }
}

/// How the CSI feedback differentiates the specimen displacement.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Derivative {
    /// The benchmark's finite-difference derivative block (module docs).
    #[default]
    FiniteDifference,
    /// `ẋ` from the state.
    Exact,
}

/// The plant, integrated by RK4 at `h` with the command held.
#[derive(Debug, Clone)]
pub struct ServoActuator {
    p: ServoParams,
    derivative: Derivative,
    h: f64,
    /// `[p, ṗ, F, x, ẋ]`.
    s: [f64; 5],
    x_prev: f64,
    steps: u64,
}

impl ServoActuator {
    pub fn new(params: ServoParams, derivative: Derivative, h: f64) -> Result<Self> {
        params.validate()?;
        crate::error::require_positive("plant.h", h)?;
        Ok(Self {
            p: params,
            derivative,
            h,
            s: [0.0; 5],
            x_prev: 0.0,
            steps: 0,
        })
    }

    pub fn params(&self) -> &ServoParams {
        &self.p
    }
    /// Specimen displacement `x` \[m\].
    #[inline]
    pub fn displacement(&self) -> f64 {
        self.s[3]
    }
    /// Actuator force `F` \[N\].
    #[inline]
    pub fn force(&self) -> f64 {
        self.s[2]
    }
    pub fn state(&self) -> &[f64; 5] {
        &self.s
    }

    #[inline]
    fn rhs(&self, s: &[f64; 5], u: f64, dx: f64) -> [f64; 5] {
        let p = &self.p;
        let e = p.g * u - s[3];
        [
            s[1],
            p.a1_beta0 * e - p.beta1 * s[1] - p.beta2 * s[0],
            -p.a3 * s[2] + s[0] - p.a2 * dx,
            s[4],
            (s[2] - p.c_e * s[4] - p.k_e * s[3]) / p.m_e,
        ]
    }

    #[inline]
    fn dx(&self, st: &[f64; 5], x0: f64, tau: f64) -> f64 {
        match self.derivative {
            Derivative::Exact => st[4],
            Derivative::FiniteDifference => (st[3] - x0) / tau,
        }
    }

    /// Advance one step `h` with the command `u` held.
    #[inline]
    pub fn step(&mut self, u: f64) {
        self.step_inputs(u, u, u);
    }

    /// Advance one step `h` while the command moves linearly from `u_start` to `u_end` (the
    /// virtual lab's command): RK4 with the command at its stage times.
    #[inline]
    pub fn step_linear(&mut self, u_start: f64, u_end: f64) {
        self.step_inputs(u_start, 0.5 * (u_start + u_end), u_end);
    }

    /// Change the step (the real-time runner may re-space sub-steps); the state is kept.
    #[inline]
    pub fn set_step(&mut self, h: f64) {
        self.h = h;
    }

    /// Length of [`Self::write_state`]: `[p, ṗ, F, x, ẋ, x_prev, started]`.
    pub const STATE_LEN: usize = 7;
    pub fn write_state(&self, out: &mut [f64]) {
        out[..5].copy_from_slice(&self.s);
        out[5] = self.x_prev;
        out[6] = if self.steps > 0 { 1.0 } else { 0.0 };
    }
    pub fn read_state(&mut self, st: &[f64]) {
        self.s.copy_from_slice(&st[..5]);
        self.x_prev = st[5];
        self.steps = u64::from(st[6] != 0.0);
    }

    #[inline]
    fn step_inputs(&mut self, u: f64, u_mid: f64, u_end: f64) {
        let h = self.h;
        let s0 = self.s;
        let x0 = s0[3];
        let d1 = match self.derivative {
            Derivative::Exact => s0[4],
            Derivative::FiniteDifference if self.steps == 0 => 0.0,
            Derivative::FiniteDifference => (x0 - self.x_prev) / h,
        };
        let k1 = self.rhs(&s0, u, d1);
        let s2 = axpy_array(&s0, 0.5 * h, &k1);
        let k2 = self.rhs(&s2, u_mid, self.dx(&s2, x0, 0.5 * h));
        let s3 = axpy_array(&s0, 0.5 * h, &k2);
        let k3 = self.rhs(&s3, u_mid, self.dx(&s3, x0, 0.5 * h));
        let s4 = axpy_array(&s0, h, &k3);
        let k4 = self.rhs(&s4, u_end, self.dx(&s4, x0, h));
        self.s = rk4_combine(&s0, h, [&k1, &k2, &k3, &k4]);
        self.x_prev = x0;
        self.steps += 1;
    }
}

/// The load-cell force from backward differences of the measured displacement (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DifferenceForce {
    m: f64,
    c: f64,
    k: f64,
    h: f64,
    x_prev: f64,
    d1_prev: f64,
    started: bool,
}

impl DifferenceForce {
    pub fn new(m: f64, c: f64, k: f64, h: f64) -> Self {
        Self {
            m,
            c,
            k,
            h,
            x_prev: 0.0,
            d1_prev: 0.0,
            started: false,
        }
    }
    /// The force at the sample with displacement `x`; stores the difference states.
    #[inline]
    pub fn force(&mut self, x: f64) -> f64 {
        let (d1, d2) = if self.started {
            let d1 = (x - self.x_prev) / self.h;
            (d1, (d1 - self.d1_prev) / self.h)
        } else {
            (0.0, 0.0)
        };
        self.started = true;
        self.x_prev = x;
        self.d1_prev = d1;
        self.k * x + self.c * d1 + self.m * d2
    }
}
