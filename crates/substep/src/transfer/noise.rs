//! Sensor noise as labs specify it, and the RTHS benchmark's exact noise generator.
//!
//! A noise level is given either as a standard deviation `σ` or as the "power" `P` of
//! band-limited white noise held at sample time `T_s` (Simulink's block), whose samples have
//! `σ² = P / T_s`.
//!
//! [`MinStdPolar`] reproduces the benchmark's sequence: uniforms by the Park–Miller "minimal
//! standard" recurrence `s ← 16807 s mod (2³¹ − 1)` (Schrage's method, `q = 127773`,
//! `r = 2836`), `u = s · 4.6566128752457969e−10`, and normals by the Marsaglia polar method
//! (`v₁, v₂ = 2u − 1` until `0 < ρ = v₁² + v₂² ≤ 1`, return `v₁ √(−2 ln ρ / ρ)`; the second
//! normal of the pair is discarded). The benchmark starts it from [`BENCHMARK_SEED`]. One
//! generator can drive several channels with the same sequence ([`SharedNoise`]).

use crate::error::{Error, Result};

/// The benchmark's internal start state of the generator.
pub const BENCHMARK_SEED: u32 = 1_144_108_930;

const M: i64 = 2_147_483_647;
const A: i64 = 16_807;
const Q: i64 = 127_773;
const R: i64 = 2_836;

/// Noise level of one channel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum NoiseLevel {
    /// Standard deviation σ (signal units).
    Sigma(f64),
    /// Band-limited white noise of power `p` at sample time `sample_time`: `σ = √(p / T_s)`.
    Power { p: f64, sample_time: f64 },
}

impl NoiseLevel {
    /// σ, validated (`what` names the parameter).
    pub fn sigma(&self, what: &str) -> Result<f64> {
        match *self {
            NoiseLevel::Sigma(s) => crate::error::require_non_negative(what, s),
            NoiseLevel::Power { p, sample_time } => {
                crate::error::require_non_negative(&format!("{what}.power"), p)?;
                crate::error::require_positive(&format!("{what}.sample_time"), sample_time)?;
                Ok((p / sample_time).sqrt())
            }
        }
    }
}

/// Park–Miller minimal standard uniforms + Marsaglia polar normals (module docs).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MinStdPolar {
    state: i64,
}

impl MinStdPolar {
    /// Start from `seed ∈ 1 ..= 2³¹ − 2` (0 and `2³¹ − 1` are fixed points of the recurrence).
    pub fn new(seed: u32) -> Result<Self> {
        if seed == 0 || seed as i64 >= M {
            return Err(Error::invalid(
                "noise.seed",
                format!("must be in 1..={}, got {seed}", M - 1),
            ));
        }
        Ok(Self { state: seed as i64 })
    }

    /// The benchmark's generator.
    pub fn benchmark() -> Self {
        Self {
            state: BENCHMARK_SEED as i64,
        }
    }

    /// Next uniform in (0, 1).
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        let hi = self.state / Q;
        let lo = self.state % Q;
        let mut t = A * lo - R * hi;
        if t <= 0 {
            t += M;
        }
        self.state = t;
        t as f64 * 4.656_612_875_245_797e-10
    }

    /// Next standard normal.
    #[inline]
    pub fn normal(&mut self) -> f64 {
        // Terminates with probability 1; accepted fraction π/4 per pair.
        loop {
            let v1 = 2.0 * self.uniform() - 1.0;
            let v2 = 2.0 * self.uniform() - 1.0;
            let rho = v1 * v1 + v2 * v2;
            if rho <= 1.0 && rho > 0.0 {
                return v1 * (-2.0 * rho.ln() / rho).sqrt();
            }
        }
    }
}

/// One generator, several channels with the same standard-normal sequence scaled by their σ.
#[derive(Debug, Clone)]
pub struct SharedNoise {
    generator: MinStdPolar,
    sigma: Vec<f64>,
}

impl SharedNoise {
    pub fn new(generator: MinStdPolar, sigma: Vec<f64>) -> Self {
        Self { generator, sigma }
    }
    /// Draw one normal and write `σ_c · n` to every channel (`out.len()` = channels).
    pub fn sample(&mut self, out: &mut [f64]) {
        let n = self.generator.normal();
        for (o, s) in out.iter_mut().zip(&self.sigma) {
            *o = s * n;
        }
    }
}
