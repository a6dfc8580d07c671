//! Bouc–Wen hysteretic law, with optional Baber–Wen degradation and Baber–Noori pinching: the
//! material [`BoucWenMaterial`] (the spring alone) and its parameters. The `bouc_wen` specimen
//! ([`crate::specimen::BoucWen`]) is this material plus a linear dashpot.
//!
//! # Model (normalised form, `z` in displacement units)
//!
//! Force of the material at the deformation `δ = u` (positive for positive deformation):
//!
//! ```text
//! F = α k u + (1 − α) k z
//! ```
//!
//! (the specimen exerts `f = −F − c u̇` on the structure, the sign of docs/theory.md §1.2: a
//! spring to ground pulls back), with the hysteretic displacement `z` [m] governed by
//!
//! ```text
//! ż = h(z) u̇ [A − ν (|z|/u_y)ⁿ (β sgn(u̇ z) + γ)] / η
//! ```
//!
//! `k` the initial stiffness (for `A = 1`), `α` the post-yield stiffness ratio, `u_y` the yield
//! displacement, `A`, `β`, `γ` dimensionless shape parameters (defaults `A = 1`, `β = γ = ½`),
//! `n ≥ 1` the sharpness of the transition. `z` is bounded by
//! `z_u = u_y (A / (ν (β + γ)))^{1/n}`; with the defaults `z_u = u_y` and the force approaches
//! the bilinear asymptotes `k u` and `α k u + (1 − α) k u_y`. Virgin loading (no degradation or
//! pinching) follows the backbone `dz/du = A − (β + γ)(z/u_y)ⁿ`, e.g.
//! `z = z_u (1 − exp(−(β + γ) u / u_y))` for `n = 1` and `z = u_y tanh(u / u_y)` for `n = 2`,
//! `A = 1`, `β + γ = 1`.
//!
//! Degradation (Baber–Wen): `A = A₀ − δ_A ε`, `ν = 1 + δ_ν ε`, `η = 1 + δ_η ε`, with the
//! normalised hysteretic energy `ε = ∫ z du / u_y²` (the dissipated energy of the hysteretic
//! spring is `E_h = (1 − α) k u_y² ε`). All `δ` default to 0 (off).
//!
//! Pinching (Baber–Noori): `h(z) = 1 − ζ₁ exp(−((z sgn(u̇) − q z_u) / (u_y ζ₂))²)`,
//! `ζ₁ = ζ_s (1 − exp(−p ε))`, `ζ₂ = (ψ + δ_ψ ε)(λ + ζ₁)`; `ζ₂` is normalised by `u_y` here.
//! Off by default.
//!
//! Tangent: `dF/du = α k + (1 − α) k G(z, ε; s)` at the trial state, with `G = dz/du` below and
//! `s` the direction of the move from the committed deformation to the trial one (for a trial
//! equal to the committed deformation, the direction of the last committed move; `+1` for the
//! virgin material). It is exact for the path: moving further from the committed state, or back
//! towards it, changes `z` at the rate `G`.
//!
//! # Integration
//!
//! Over a trial move (an interval of the specimen) the displacement moves linearly, so `u̇` has
//! one sign `s` and the model is rate independent in `z`: `dz/du = G(z, ε; s)`,
//! `dε/du = z / u_y²`. The displacement change is cut into equal sub-steps of at most
//! `0.05 u_ref / n` (`u_ref = z_u / A`, the travel to yield at the initial slope; `= u_y` with
//! the defaults), and at most `0.05 ψ λ u_y` (the narrowest pinching width) when pinching is
//! on. Each sub-step uses the implicit two-point Hermite (Obreschkoff) rule, 4th order and
//! A-stable,
//!
//! ```text
//! z₁ = z₀ + h/2 (G₀ + G₁) + h²/12 (G'₀ − G'₁),   G' = dG/du = G_z G + G_ε z / u_y²
//! ```
//!
//! (the trapezoidal rule plus its derivative correction; `ε` by the same rule), solved for `z₁`
//! by a safeguarded Newton iteration inside a bracket (bisection whenever a Newton step leaves
//! it). `G` is not smooth where `z = 0` (`G_z` jumps for `n = 1`, `|z|ⁿ` is singular for
//! non-integer `n`), so a sub-step in which `z` changes sign is split exactly there; for
//! non-integer `n` the part of the `|z|ⁿ` integral the rule misses next to `z = 0` is added in
//! closed form, and for non-integer `n < 4` the sub-steps are graded near `z = 0` (length factor
//! `(|z|/u_ref)^{(4−n)/4}`, at least 1/64). Without these the interval splitting would show at
//! the 1e-5 level.
//!
//! Robustness: a sub-step whose solve fails is halved (recursively); the last resort is a
//! backward-Euler step, whose bracket `[min(z₀, 0), max(z₀, z_u)]` (for `s > 0`) always holds a
//! root. Intervals that would need more than 4096 sub-steps (huge jumps) use 1024
//! backward-Euler sub-steps (L-stable, no overshoot, `|z| ≤ z_u` kept); a monotone travel beyond
//! `10⁶ u_ref` in one interval is integrated as `10⁶ u_ref` (z is saturated long before).
//! `set_trial` does not allocate and gives a finite force for finite input.
//!
//! Accuracy (tests/specimens.rs, tests/materials.rs): backbone to ~1e-12 of the closed forms,
//! forces independent of how a motion is split into intervals to ~1e-9, about 0.25 µs per
//! interval for typical real-time intervals (`|Δu| ≪ u_y`, integer `n`), about 1 µs with
//! pinching, degradation or non-integer `n`.

use super::Material;
use crate::error::{Error, Result, require_non_negative, require_positive};

/// Sub-step length in units of `u_ref / n`.
const SUBSTEP_RATIO: f64 = 0.05;
/// Maximum number of (uniform) sub-steps per interval before switching to backward Euler.
const MAX_SUBSTEPS: usize = 4096;
/// Number of backward-Euler sub-steps for such intervals.
const MAX_BACKWARD_EULER: usize = 1024;
/// Longest monotone travel integrated in one interval, in units of `u_ref`.
const MAX_TRAVEL: f64 = 1e6;
/// Recursion depth of the sub-step halving fallback.
const MAX_HALVINGS: u32 = 8;
const MAX_NEWTON: usize = 100;

/// Baber–Noori pinching parameters (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pinching {
    /// `ζ_s ∈ [0, 1)`: measure of the total slip (0 = no pinching).
    pub zeta_s: f64,
    /// `p ≥ 0`: rate at which pinching develops with the normalised energy `ε`.
    pub p: f64,
    /// `q ≥ 0`: fraction of `z_u` at which the pinching is centred.
    pub q: f64,
    /// `ψ > 0`: width of the pinched region (in units of `u_y`).
    pub psi: f64,
    /// `δ_ψ ≥ 0`: growth of the width with `ε`.
    pub delta_psi: f64,
    /// `λ > 0`: interaction of `ζ₁` and `ζ₂` (`ψ λ u_y` is the narrowest pinching width).
    pub lambda: f64,
}

impl Pinching {
    /// Pinching of strength `zeta_s` with shape `p = 1`, `q = 0.1`, `ψ = 0.2`, `δ_ψ = 0`,
    /// `λ = 0.5`.
    pub fn new(zeta_s: f64) -> Self {
        Self {
            zeta_s,
            p: 1.0,
            q: 0.1,
            psi: 0.2,
            delta_psi: 0.0,
            lambda: 0.5,
        }
    }
}

/// Parameters of the Bouc–Wen spring (see the module docs for the equations).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoucWenParams {
    /// Initial stiffness `k` [N/m] (`> 0`).
    pub stiffness: f64,
    /// Post-yield stiffness ratio `α ∈ [0, 1]`.
    pub alpha: f64,
    /// Yield displacement `u_y` \[m\] (`> 0`).
    pub yield_displacement: f64,
    /// `A > 0` (default 1).
    pub a: f64,
    /// `β ≥ 0` (default ½).
    pub beta: f64,
    /// `γ` with `β + γ > 0` (default ½).
    pub gamma: f64,
    /// Sharpness `n ∈ [1, 100]` (default 1).
    pub n: f64,
    /// Linear viscous damping `c` [N s/m] (default 0) of the `bouc_wen` specimen's dashpot; not
    /// part of the material.
    pub damping: f64,
    /// Degradation of `A` with `ε` (default 0).
    pub delta_a: f64,
    /// Strength degradation `δ_ν` (default 0).
    pub delta_nu: f64,
    /// Stiffness degradation `δ_η` (default 0).
    pub delta_eta: f64,
    /// Pinching (default off).
    pub pinching: Option<Pinching>,
}

impl BoucWenParams {
    /// `k`, `α`, `u_y`, everything else at its default (`A = 1`, `β = γ = ½`, `n = 1`, no
    /// damping, degradation or pinching).
    pub fn new(stiffness: f64, alpha: f64, yield_displacement: f64) -> Self {
        Self {
            stiffness,
            alpha,
            yield_displacement,
            a: 1.0,
            beta: 0.5,
            gamma: 0.5,
            n: 1.0,
            damping: 0.0,
            delta_a: 0.0,
            delta_nu: 0.0,
            delta_eta: 0.0,
            pinching: None,
        }
    }

    /// Check every parameter; errors name the key (`specimen.<key>`).
    pub fn validate(&self) -> Result<()> {
        require_positive("specimen.stiffness", self.stiffness)?;
        if !(self.alpha.is_finite() && (0.0..=1.0).contains(&self.alpha)) {
            return Err(Error::invalid(
                "specimen.alpha",
                format!("must be in [0, 1], got {}", self.alpha),
            ));
        }
        require_positive("specimen.yield_displacement", self.yield_displacement)?;
        require_positive("specimen.a", self.a)?;
        require_non_negative("specimen.beta", self.beta)?;
        if !self.gamma.is_finite() {
            return Err(Error::invalid(
                "specimen.gamma",
                format!("must be finite, got {}", self.gamma),
            ));
        }
        if self.beta + self.gamma <= 0.0 {
            return Err(Error::invalid(
                "specimen.gamma",
                format!(
                    "beta + gamma must be > 0 (otherwise z is unbounded), got {}",
                    self.beta + self.gamma
                ),
            ));
        }
        if !(self.n.is_finite() && (1.0..=100.0).contains(&self.n)) {
            return Err(Error::invalid(
                "specimen.n",
                format!("must be in [1, 100], got {}", self.n),
            ));
        }
        require_non_negative("specimen.damping", self.damping)?;
        require_non_negative("specimen.delta_a", self.delta_a)?;
        require_non_negative("specimen.delta_nu", self.delta_nu)?;
        require_non_negative("specimen.delta_eta", self.delta_eta)?;
        if let Some(p) = &self.pinching {
            if !(p.zeta_s.is_finite() && (0.0..1.0).contains(&p.zeta_s)) {
                return Err(Error::invalid(
                    "specimen.pinching.zeta_s",
                    format!("must be in [0, 1), got {}", p.zeta_s),
                ));
            }
            require_non_negative("specimen.pinching.p", p.p)?;
            require_non_negative("specimen.pinching.q", p.q)?;
            require_positive("specimen.pinching.psi", p.psi)?;
            require_non_negative("specimen.pinching.delta_psi", p.delta_psi)?;
            require_positive("specimen.pinching.lambda", p.lambda)?;
        }
        Ok(())
    }

    /// Bound of `|z|` without degradation, `z_u = u_y (A / (β + γ))^{1/n}` \[m\].
    pub fn z_ultimate(&self) -> f64 {
        self.yield_displacement * (self.a / (self.beta + self.gamma)).powf(1.0 / self.n)
    }
}

/// `G = dz/du` and its derivatives at one point.
#[derive(Debug, Clone, Copy)]
struct Eval {
    g: f64,
    gz: f64,
    gzz: f64,
    ge: f64,
}

/// The Bouc–Wen spring as a [`Material`]: deformation `δ = u`, force
/// `F = α k δ + (1 − α) k z` (see the module docs). [`BoucWenParams::damping`] is not part of the
/// law (the `bouc_wen` specimen adds the dashpot).
#[derive(Debug, Clone)]
pub struct BoucWenMaterial {
    p: BoucWenParams,
    /// `z_u` without degradation.
    z0: f64,
    /// `u_ref = z_u / A`.
    u_ref: f64,
    /// Maximum sub-step length [m].
    h_max: f64,
    /// `n` as an integer exponent when it is one (faster powers).
    n_int: Option<i32>,
    /// Whether `G` depends on `ε` (degradation or pinching on).
    eps_dependent: bool,
    /// Committed deformation, `z`, `ε` and direction of the last move (`±1`).
    deformation: f64,
    z: f64,
    eps: f64,
    direction: f64,
    /// Trial deformation, `z`, `ε` and direction of the trial move.
    trial_deformation: f64,
    z_trial: f64,
    eps_trial: f64,
    trial_direction: f64,
}

impl BoucWenMaterial {
    /// The virgin material (`δ = z = ε = 0`); errors name the key as `specimen.<key>`
    /// ([`MaterialSpec::build`](super::MaterialSpec::build) renames them).
    pub fn new(params: &BoucWenParams) -> Result<Self> {
        params.validate()?;
        let z0 = params.z_ultimate();
        let u_ref = z0 / params.a;
        let n_int = if params.n.fract() == 0.0 {
            Some(params.n as i32)
        } else {
            None
        };
        let pinching = params.pinching.filter(|p| p.zeta_s > 0.0);
        // The sub-step also resolves the narrowest pinching width `ζ₂ ≥ ψ λ` (in units of u_y).
        let mut h_max = SUBSTEP_RATIO * u_ref / params.n;
        if let Some(pin) = &pinching {
            h_max = h_max.min(SUBSTEP_RATIO * pin.psi * pin.lambda * params.yield_displacement);
        }
        let eps_dependent =
            params.delta_a > 0.0 || params.delta_nu > 0.0 || params.delta_eta > 0.0 || pinching.is_some();
        Ok(Self {
            p: *params,
            z0,
            u_ref,
            h_max,
            n_int,
            eps_dependent,
            deformation: 0.0,
            z: 0.0,
            eps: 0.0,
            direction: 1.0,
            trial_deformation: 0.0,
            z_trial: 0.0,
            eps_trial: 0.0,
            trial_direction: 1.0,
        })
    }

    pub fn params(&self) -> &BoucWenParams {
        &self.p
    }

    /// Committed hysteretic displacement `z` \[m\].
    pub fn z(&self) -> f64 {
        self.z
    }

    /// Hysteretic displacement `z` of the trial state \[m\].
    pub fn trial_z(&self) -> f64 {
        self.z_trial
    }

    /// Committed normalised hysteretic energy `ε = ∫ z du / u_y²`.
    pub fn normalised_energy(&self) -> f64 {
        self.eps
    }

    /// Committed hysteretic energy `E_h = (1 − α) k u_y² ε` \[J\].
    pub fn hysteretic_energy(&self) -> f64 {
        (1.0 - self.p.alpha) * self.p.stiffness * self.p.yield_displacement.powi(2) * self.eps
    }

    /// Trial move along the straight path from `start` to `end`, beginning at the committed
    /// `(z, ε)`: the committed deformation is taken to be `start` (the `bouc_wen` specimen passes
    /// its interval's end points). [`Material::set_trial`] is `set_trial_path(δ_n, δ)`.
    pub fn set_trial_path(&mut self, start: f64, end: f64) {
        let du = end - start;
        let (z, eps) = self.integrate(self.z, self.eps, du);
        self.z_trial = z;
        self.eps_trial = eps;
        self.trial_deformation = end;
        self.trial_direction = if du > 0.0 {
            1.0
        } else if du < 0.0 {
            -1.0
        } else {
            self.direction
        };
    }

    /// `x^e` for `x ≥ 0`, with `0^e = 0` for `e ≠ 0` (the derivative terms that would be
    /// infinite at `z = 0` for `1 < n < 2` only enter the Newton Jacobian).
    #[inline]
    fn pow(&self, x: f64, e_off: i32) -> f64 {
        if x == 0.0 {
            return if self.p.n - e_off as f64 == 0.0 { 1.0 } else { 0.0 };
        }
        match self.n_int {
            Some(ni) => x.powi(ni - e_off),
            None => x.powf(self.p.n - e_off as f64),
        }
    }

    /// `G(z, ε; s)` and derivatives. `s = ±1` is the direction of motion; at `z = 0`, `sgn z`
    /// is taken as `side`.
    fn eval(&self, z: f64, eps: f64, s: f64, side: f64) -> Eval {
        let p = &self.p;
        let uy = p.yield_displacement;
        let (e, active) = if eps > 0.0 { (eps, 1.0) } else { (0.0, 0.0) };
        let mut a_e = p.a - p.delta_a * e;
        let mut da = -p.delta_a * active;
        if a_e <= 0.0 {
            a_e = 0.0;
            da = 0.0;
        }
        let nu = 1.0 + p.delta_nu * e;
        let dnu = p.delta_nu * active;
        let eta = 1.0 + p.delta_eta * e;
        let deta = p.delta_eta * active;

        let sgn_z = if z > 0.0 {
            1.0
        } else if z < 0.0 {
            -1.0
        } else {
            side
        };
        let coef = p.beta * sgn_z * s + p.gamma;
        let x = z.abs() / uy;
        let (xn, xn1, xn2) = if coef == 0.0 {
            (0.0, 0.0, 0.0)
        } else {
            (self.pow(x, 0), self.pow(x, 1), self.pow(x, 2))
        };
        let n = p.n;
        let core = a_e - nu * xn * coef;
        let core_z = -nu * coef * n * xn1 * sgn_z / uy;
        let core_zz = -nu * coef * n * (n - 1.0) * xn2 / (uy * uy);
        let core_e = da - dnu * xn * coef;

        let (mut hp, mut hp_z, mut hp_zz, mut hp_e) = (1.0, 0.0, 0.0, 0.0);
        if let Some(pin) = &p.pinching
            && pin.zeta_s > 0.0
        {
            let ex = (-pin.p * e).exp();
            let zeta1 = pin.zeta_s * (1.0 - ex);
            let zeta1_e = pin.zeta_s * pin.p * ex * active;
            let psi_e = pin.psi + pin.delta_psi * e;
            let zeta2 = psi_e * (pin.lambda + zeta1);
            if zeta2 > 0.0 {
                let zu = uy * (a_e / (nu * (p.beta + p.gamma))).powf(1.0 / n);
                let zu_e = if a_e > 0.0 { zu / n * (da / a_e - dnu / nu) } else { 0.0 };
                let zeta2_e = pin.delta_psi * active * (pin.lambda + zeta1) + psi_e * zeta1_e;
                let w = (s * z - pin.q * zu) / (uy * zeta2);
                let g = (-w * w).exp();
                hp = 1.0 - zeta1 * g;
                hp_z = 2.0 * zeta1 * g * w * s / (uy * zeta2);
                hp_zz = 2.0 * zeta1 * g * (1.0 - 2.0 * w * w) / (uy * zeta2).powi(2);
                let w_e = -pin.q * zu_e / (uy * zeta2) - w * zeta2_e / zeta2;
                hp_e = -zeta1_e * g + 2.0 * zeta1 * g * w * w_e;
            }
        }
        let g = hp * core / eta;
        Eval {
            g,
            gz: (hp_z * core + hp * core_z) / eta,
            gzz: (hp_zz * core + 2.0 * hp_z * core_z + hp * core_zz) / eta,
            ge: (hp_e * core + hp * core_e) / eta - g * deta / eta,
        }
    }

    /// `dG/du` along the solution.
    #[inline]
    fn total_derivative(&self, ev: &Eval, z: f64) -> f64 {
        let uy = self.p.yield_displacement;
        ev.gz * ev.g + ev.ge * z / (uy * uy)
    }

    /// For non-integer `n`, `G` has a term `∝ |z|ⁿ` that is not smooth where `z = 0`; the
    /// Hermite rule misses part of its integral over a sub-step with one end at `z = 0`. This is
    /// the missing part, `−s K |h|ⁿ⁺¹ (1/(n+1) − 1/2 + n/12)`, with `|z| ≈ G(0) |u|` and
    /// `K = h ν (β sg + γ) G(0)ⁿ / (η u_yⁿ)`; `sg = ±1` selects the side of `z = 0`.
    fn singular_correction(&self, eps: f64, h: f64, s: f64, sg: f64) -> f64 {
        if self.n_int.is_some() {
            return 0.0;
        }
        let p = &self.p;
        let e = eps.max(0.0);
        let nu = 1.0 + p.delta_nu * e;
        let eta = 1.0 + p.delta_eta * e;
        let e0 = self.eval(0.0, eps, s, s);
        let a = e0.g; // = h(0) A / η
        if a <= 0.0 {
            return 0.0;
        }
        let hp0 = a * eta / (p.a - p.delta_a * e).max(f64::MIN_POSITIVE);
        let n = p.n;
        let k = hp0 * nu * (p.beta * sg + p.gamma) * (a / p.yield_displacement).powf(n) / eta;
        -s * k * h.abs().powf(n + 1.0) * (1.0 / (n + 1.0) - 0.5 + n / 12.0)
    }

    /// One Hermite–Obreschkoff sub-step of signed length `h` from `(z, ε)`.
    fn hermite_step(&self, z: f64, eps: f64, h: f64, s: f64) -> Option<(f64, f64)> {
        let uy2 = self.p.yield_displacement.powi(2);
        let e0 = self.eval(z, eps, s, s);
        let (g0, d0) = (e0.g, self.total_derivative(&e0, z));
        let corr = if z == 0.0 {
            self.singular_correction(eps, h, s, 1.0)
        } else {
            0.0
        };
        let res = |x: f64| {
            // ε at the end by its own Hermite rule, `G₁` inside it from the trapezoidal ε
            // (an O(h⁵) approximation); one evaluation when G does not depend on ε.
            let eps_trap = eps + 0.5 * h * (z + x) / uy2;
            let mut ev = self.eval(x, eps_trap, s, s);
            if self.eps_dependent {
                ev = self.eval(x, eps_trap + h * h / 12.0 * (g0 - ev.g) / uy2, s, s);
            }
            let d1 = self.total_derivative(&ev, x);
            let r = x - z - 0.5 * h * (g0 + ev.g) - h * h / 12.0 * (d0 - d1) - corr;
            let j = 1.0 - 0.5 * h * ev.gz + h * h / 12.0 * (ev.gzz * ev.g + ev.gz * ev.gz);
            (r, j)
        };
        let zp = z + h * g0 + 0.5 * h * h * d0 + corr;
        let mut w = (0.25 * (h * g0).abs()).max((h * h * d0).abs()).max(1e-10 * self.u_ref);
        let mut bracket = None;
        for _ in 0..16 {
            let (lo, hi) = (zp - w, zp + w);
            let (r_lo, r_hi) = (res(lo).0, res(hi).0);
            if !(r_lo.is_finite() && r_hi.is_finite()) {
                return None;
            }
            if r_lo * r_hi <= 0.0 {
                bracket = Some((lo, hi, r_lo, r_hi));
                break;
            }
            w *= 4.0;
        }
        let (lo, hi, r_lo, r_hi) = bracket?;
        let z1 = safeguarded_newton(res, lo, hi, r_lo, r_hi, zp, self.tol(zp))?;
        let eps_trap = eps + 0.5 * h * (z + z1) / uy2;
        let g1 = self.eval(z1, eps_trap, s, s).g;
        let eps1 = eps_trap + h * h / 12.0 * (g0 - g1) / uy2;
        (z1.is_finite() && eps1.is_finite()).then_some((z1, eps1))
    }

    /// A Hermite sub-step, split where `z` changes sign (`G_z` jumps there for `n = 1`, and
    /// `G` is not smooth there for non-integer `n`): the first part ends exactly at `z = 0`
    /// (its length from the rule itself), the second starts there.
    fn step(&self, z: f64, eps: f64, h: f64, s: f64) -> Option<(f64, f64)> {
        let (z1, eps1) = self.hermite_step(z, eps, h, s)?;
        if z == 0.0 || z1 == 0.0 || (z1 > 0.0) == (z > 0.0) {
            return Some((z1, eps1));
        }
        let uy2 = self.p.yield_displacement.powi(2);
        let side = z.signum();
        let sg_near = side * s;
        let en = self.eval(z, eps, s, s);
        let (gn, dn) = (en.g, self.total_derivative(&en, z));
        // Solve  0 = z + h₁/2 (G_n + G_c) + h₁²/12 (G'_n − G'_c) + correction  for h₁, with G
        // at the crossing on the near side and ε there.
        let mut h1 = -z / gn;
        let mut eps_c = eps;
        for _ in 0..4 {
            let ez = self.eval(0.0, eps_c, s, side);
            let (gc, dc) = (ez.g, self.total_derivative(&ez, 0.0));
            let corr = self.singular_correction(eps_c, h1, s, sg_near);
            let phi = z + 0.5 * h1 * (gn + gc) + h1 * h1 / 12.0 * (dn - dc) + corr;
            let dphi = 0.5 * (gn + gc) + h1 / 6.0 * (dn - dc) + (self.p.n + 1.0) * corr / h1;
            let next = h1 - phi / dphi;
            if !next.is_finite() {
                break;
            }
            h1 = next;
            eps_c = eps + 0.5 * h1 * z / uy2 + h1 * h1 / 12.0 * (gn - gc) / uy2;
        }
        let frac = h1 / h;
        if !(frac.is_finite() && frac > 0.0) {
            return Some((z1, eps1));
        }
        if frac >= 1.0 {
            return Some((0.0, eps_c));
        }
        Some(self.hermite_step(0.0, eps_c, h - h1, s).unwrap_or((z1, eps1)))
    }

    /// One backward-Euler sub-step (robust fallback).
    fn backward_euler_step(&self, z: f64, eps: f64, h: f64, s: f64) -> Option<(f64, f64)> {
        let uy2 = self.p.yield_displacement.powi(2);
        let res = |x: f64| {
            let ev = self.eval(x, eps + h * x / uy2, s, s);
            (x - z - h * ev.g, 1.0 - h * (ev.gz + ev.ge * h / uy2))
        };
        let (lo, hi) = if s > 0.0 {
            (z.min(0.0), z.max(self.z0))
        } else {
            (z.min(-self.z0), z.max(0.0))
        };
        let (r_lo, r_hi) = (res(lo).0, res(hi).0);
        if !(r_lo.is_finite() && r_hi.is_finite()) || r_lo * r_hi > 0.0 {
            return None;
        }
        let g0 = self.eval(z, eps, s, s).g;
        let z1 = safeguarded_newton(res, lo, hi, r_lo, r_hi, z + h * g0, self.tol(z))?;
        let eps1 = eps + h * z1 / uy2;
        (z1.is_finite() && eps1.is_finite()).then_some((z1, eps1))
    }

    fn step_robust(&self, z: f64, eps: f64, h: f64, s: f64, depth: u32) -> (f64, f64) {
        if let Some(r) = self.step(z, eps, h, s) {
            return r;
        }
        if depth < MAX_HALVINGS {
            let (za, ea) = self.step_robust(z, eps, 0.5 * h, s, depth + 1);
            return self.step_robust(za, ea, 0.5 * h, s, depth + 1);
        }
        self.backward_euler_step(z, eps, h, s).unwrap_or((z, eps))
    }

    fn tol(&self, x: f64) -> f64 {
        4e-15 * (x.abs() + self.u_ref)
    }

    /// Sub-step length factor near `z = 0` for non-integer `n < 4`, where `z(u)` has a
    /// singular derivative of order `n + 1`: `(|z| / u_ref)^{(4−n)/4}` keeps the local error per
    /// unit travel of the 4th-order rule uniform; floored at 1/64 (the step from `z = 0` itself
    /// carries the singular correction).
    fn grade(&self, z: f64, exponent: f64) -> f64 {
        (z.abs() / self.u_ref).powf(exponent).clamp(1.0 / 64.0, 1.0)
    }

    /// Integrate `(z, ε)` over a displacement change `du` (the interval's rule).
    fn integrate(&self, mut z: f64, mut eps: f64, du: f64) -> (f64, f64) {
        if !du.is_finite() || du == 0.0 {
            return (z, eps);
        }
        let s = du.signum();
        let travel = du.abs().min(MAX_TRAVEL * self.u_ref);
        let wanted = (travel / self.h_max).ceil();
        if wanted > MAX_SUBSTEPS as f64 {
            let h = s * travel / MAX_BACKWARD_EULER as f64;
            for _ in 0..MAX_BACKWARD_EULER {
                (z, eps) = self.backward_euler_step(z, eps, h, s).unwrap_or((z, eps));
            }
            return (z, eps);
        }
        let count = wanted.max(1.0) as usize;
        let h = travel / count as f64;
        let grading = match self.n_int {
            None if self.p.n < 4.0 => Some((4.0 - self.p.n) / 4.0),
            _ => None,
        };
        let Some(exponent) = grading else {
            for _ in 0..count {
                (z, eps) = self.step_robust(z, eps, s * h, s, 0);
            }
            return (z, eps);
        };
        let mut left = travel;
        let mut steps = 0;
        while left > 0.0 {
            let factor = if steps < 2 * MAX_SUBSTEPS {
                self.grade(z, exponent)
            } else {
                1.0
            };
            let mut d = (h * factor).min(left);
            if left - d <= 1e-9 * h {
                d = left;
            }
            (z, eps) = self.step_robust(z, eps, s * d, s, 0);
            left -= d;
            steps += 1;
        }
        (z, eps)
    }
}

/// Newton's method kept inside the bracket `[lo, hi]` (`r(lo)`, `r(hi)` of opposite signs),
/// bisecting whenever a Newton step would leave it or the derivative is unusable.
fn safeguarded_newton(
    f: impl Fn(f64) -> (f64, f64),
    lo: f64,
    hi: f64,
    r_lo: f64,
    r_hi: f64,
    x0: f64,
    tol: f64,
) -> Option<f64> {
    if r_lo == 0.0 {
        return Some(lo);
    }
    if r_hi == 0.0 {
        return Some(hi);
    }
    // Orient: f(neg) < 0 < f(pos).
    let (mut neg, mut pos) = if r_lo < 0.0 { (lo, hi) } else { (hi, lo) };
    let inside = |x: f64, a: f64, b: f64| x > a.min(b) && x < a.max(b);
    let mut x = if inside(x0, neg, pos) { x0 } else { 0.5 * (neg + pos) };
    for _ in 0..MAX_NEWTON {
        let (r, j) = f(x);
        if !r.is_finite() {
            return None;
        }
        if r == 0.0 {
            return Some(x);
        }
        if r < 0.0 {
            neg = x;
        } else {
            pos = x;
        }
        let dx = r / j;
        if dx.abs() <= tol {
            return Some(x - dx);
        }
        let mut next = x - dx;
        if !(next.is_finite() && inside(next, neg, pos)) {
            next = 0.5 * (neg + pos);
        }
        if (pos - neg).abs() <= tol {
            return Some(next);
        }
        x = next;
    }
    Some(0.5 * (neg + pos))
}

impl Material for BoucWenMaterial {
    fn kind(&self) -> &'static str {
        "bouc_wen"
    }
    fn set_trial(&mut self, deformation: f64) {
        self.set_trial_path(self.deformation, deformation);
    }
    fn force(&self) -> f64 {
        let p = &self.p;
        p.alpha * p.stiffness * self.trial_deformation + (1.0 - p.alpha) * p.stiffness * self.z_trial
    }
    /// `α k + (1 − α) k G(z, ε; s)` at the trial state, `s` the direction of the trial move
    /// (of the last committed move when the trial deformation is the committed one).
    fn tangent(&self) -> f64 {
        let p = &self.p;
        let s = self.trial_direction;
        let g = self.eval(self.z_trial, self.eps_trial, s, s).g;
        p.alpha * p.stiffness + (1.0 - p.alpha) * p.stiffness * g
    }
    /// `k (α + (1 − α) A)`, evaluated as `α k + (1 − α) k A` (the trial tangent of the virgin
    /// state, bit for bit).
    fn initial_tangent(&self) -> f64 {
        let p = &self.p;
        p.alpha * p.stiffness + (1.0 - p.alpha) * p.stiffness * p.a
    }
    fn commit(&mut self) {
        self.deformation = self.trial_deformation;
        self.z = self.z_trial;
        self.eps = self.eps_trial;
        self.direction = self.trial_direction;
    }
    fn revert(&mut self) {
        self.trial_deformation = self.deformation;
        self.z_trial = self.z;
        self.eps_trial = self.eps;
        self.trial_direction = self.direction;
    }
    fn fresh(&self) -> Box<dyn Material> {
        Box::new(Self::new(&self.p).expect("validated"))
    }
    /// `[δ, z, ε, s]` (committed deformation, hysteretic displacement, normalised energy,
    /// direction of the last move).
    fn state_len(&self) -> usize {
        4
    }
    fn write_state(&self, out: &mut [f64]) {
        out[0] = self.deformation;
        out[1] = self.z;
        out[2] = self.eps;
        out[3] = self.direction;
    }
    fn read_state(&mut self, state: &[f64]) {
        self.deformation = state[0];
        self.z = state[1];
        self.eps = state[2];
        self.direction = if state[3] < 0.0 { -1.0 } else { 1.0 };
        self.revert();
    }
}
