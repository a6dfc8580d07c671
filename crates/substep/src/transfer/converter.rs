//! A/D and D/A converters: saturation at `±range` and quantisation to steps of `q`,
//! `y = q · round(u / q)` with rounding half away from zero (`f64::round`). The A/D saturates
//! then quantises; the D/A quantises then saturates (the RTHS benchmark's order).

use crate::error::{Result, require_positive};

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Converter {
    range: f64,
    q: f64,
}

impl Converter {
    /// `range > 0` [signal units], step `q > 0`.
    pub fn new(range: f64, q: f64) -> Result<Self> {
        require_positive("converter.range", range)?;
        require_positive("converter.quantum", q)?;
        Ok(Self { range, q })
    }
    /// Range [signal units].
    pub fn range(&self) -> f64 {
        self.range
    }
    /// Step [signal units].
    pub fn quantum(&self) -> f64 {
        self.q
    }
    /// The benchmark's converters: ±3.8 (m), `q = 2⁻¹⁸`.
    pub fn benchmark() -> Self {
        Self {
            range: 3.8,
            q: 1.0 / 262_144.0,
        }
    }
    #[inline]
    pub fn quantise(&self, u: f64) -> f64 {
        self.q * (u / self.q).round()
    }
    #[inline]
    pub fn saturate(&self, u: f64) -> f64 {
        u.clamp(-self.range, self.range)
    }
    /// Saturate, then quantise.
    #[inline]
    pub fn ad(&self, u: f64) -> f64 {
        self.quantise(self.saturate(u))
    }
    /// Quantise, then saturate.
    #[inline]
    pub fn da(&self, u: f64) -> f64 {
        self.saturate(self.quantise(u))
    }
}
