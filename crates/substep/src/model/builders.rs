//! Model builders: SDOF, primary structure + TMD (2 DOF), uniform shear building (dense or
//! sparse storage). The moment frame is in `frame.rs`.

use super::StructuralModel;
use crate::error::{Error, Result, require_non_negative, require_positive};
use crate::sparse::CscMatrix;
use nalgebra::{DMatrix, DVector, dmatrix};
use std::f64::consts::PI;

/// Single-DOF oscillator.
pub fn sdof(mass: f64, damping: f64, stiffness: f64) -> Result<StructuralModel> {
    require_positive("structure.sdof.mass", mass)?;
    require_non_negative("structure.sdof.damping", damping)?;
    require_non_negative("structure.sdof.stiffness", stiffness)?;
    StructuralModel::new(dmatrix![mass], dmatrix![damping], dmatrix![stiffness], None)
}

/// Primary structure with a tuned mass damper (docs/theory.md §1.5; parameters: §9.3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TmdSystem {
    /// Primary mass `m` \[kg\].
    pub mass: f64,
    /// Primary natural frequency `f` \[Hz\].
    pub frequency: f64,
    /// Primary damping ratio `ζ`.
    pub zeta: f64,
    /// Mass ratio `η_m = m_s / m`.
    pub eta_m: f64,
    /// Frequency ratio `η_f = ω_s / ω`.
    pub eta_f: f64,
    /// TMD damping ratio `ζ_s`.
    pub zeta_s: f64,
}

impl TmdSystem {
    /// The dissertation's "typical TMD system" with a 1000 kg, 1 Hz primary structure.
    pub fn typical() -> Self {
        Self {
            mass: 1000.0,
            frequency: 1.0,
            zeta: 0.05,
            eta_m: 0.05,
            eta_f: 1.0,
            zeta_s: 0.10,
        }
    }
    /// "Coupled system with large mass ratio".
    pub fn large_mass_ratio() -> Self {
        Self {
            eta_m: 0.5,
            zeta_s: 0.05,
            ..Self::typical()
        }
    }
    pub fn omega(&self) -> f64 {
        2.0 * PI * self.frequency
    }
    /// Primary stiffness and damping `(k, c)`.
    pub fn primary(&self) -> (f64, f64) {
        let w = self.omega();
        (self.mass * w * w, 2.0 * self.zeta * self.mass * w)
    }
    /// TMD mass, stiffness, damping `(m_s, k_s, c_s)`.
    pub fn absorber(&self) -> (f64, f64, f64) {
        let ms = self.eta_m * self.mass;
        let ws = self.eta_f * self.omega();
        (ms, ms * ws * ws, 2.0 * self.zeta_s * ms * ws)
    }
    fn validate(&self) -> Result<()> {
        require_positive("tmd.mass", self.mass)?;
        require_positive("tmd.frequency", self.frequency)?;
        require_non_negative("tmd.zeta", self.zeta)?;
        require_positive("tmd.eta_m", self.eta_m)?;
        require_positive("tmd.eta_f", self.eta_f)?;
        require_non_negative("tmd.zeta_s", self.zeta_s)?;
        Ok(())
    }
}

/// Assembled 2-DOF model: DOF 1 the primary mass, DOF 2 the TMD.
pub fn tmd_two_dof(p: &TmdSystem) -> Result<StructuralModel> {
    p.validate()?;
    let (k, c) = p.primary();
    let (ms, ks, cs) = p.absorber();
    StructuralModel::new(
        dmatrix![p.mass, 0.0; 0.0, ms],
        dmatrix![c + cs, -cs; -cs, cs],
        dmatrix![k + ks, -ks; -ks, ks],
        None,
    )
}

/// Uniform shear building: `stories` floors of equal mass, equal story stiffness chosen so that
/// the first natural period equals `first_period`. DOF 1 is the first floor, DOF N the roof.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShearBuilding {
    pub stories: usize,
    /// Floor mass \[kg\].
    pub story_mass: f64,
    /// Target first natural period \[s\].
    pub first_period: f64,
}

impl ShearBuilding {
    /// Story stiffness [N/m] that gives the target first period. Uses the closed form
    /// `ω_j = 2 √(k/m) sin((2j−1)π / (2(2N+1)))` of the uniform shear beam.
    pub fn story_stiffness(&self) -> f64 {
        let w1 = 2.0 * PI / self.first_period;
        let s = (PI / (2.0 * (2 * self.stories + 1) as f64)).sin();
        self.story_mass * (w1 / (2.0 * s)).powi(2)
    }
    /// Circular frequency `ω_j` [rad/s] of mode `j ≥ 1` (closed form).
    pub fn omega(&self, j: usize) -> f64 {
        let theta = (2 * j - 1) as f64 * PI / (2.0 * (2 * self.stories + 1) as f64);
        2.0 * (self.story_stiffness() / self.story_mass).sqrt() * theta.sin()
    }
}

/// Undamped shear building; add damping with [`StructuralModel::with_damping`].
pub fn shear_building(b: &ShearBuilding) -> Result<StructuralModel> {
    b.validate()?;
    let n = b.stories;
    let k = b.story_stiffness();
    let mut kk = DMatrix::zeros(n, n);
    for i in 0..n {
        kk[(i, i)] = if i + 1 < n { 2.0 * k } else { k };
        if i + 1 < n {
            kk[(i, i + 1)] = -k;
            kk[(i + 1, i)] = -k;
        }
    }
    let mm = DMatrix::from_diagonal(&DVector::from_element(n, b.story_mass));
    StructuralModel::new(mm, DMatrix::zeros(n, n), kk, None)
}

/// The same undamped shear building in sparse storage (diagonal `M`, tridiagonal `K`); add
/// damping with [`SparseModel::with_damping`](super::SparseModel::with_damping).
pub fn shear_building_sparse(b: &ShearBuilding) -> Result<super::SparseModel> {
    b.validate()?;
    let n = b.stories;
    let k = b.story_stiffness();
    let mut t = Vec::with_capacity(3 * n);
    for i in 0..n {
        t.push((i, i, if i + 1 < n { 2.0 * k } else { k }));
        if i + 1 < n {
            t.push((i, i + 1, -k));
            t.push((i + 1, i, -k));
        }
    }
    super::SparseModel::new(
        CscMatrix::from_diagonal(&vec![b.story_mass; n]),
        CscMatrix::zeros(n),
        CscMatrix::from_triplets(n, &t),
        None,
    )
}

impl ShearBuilding {
    fn validate(&self) -> Result<()> {
        if self.stories == 0 {
            return Err(crate::error::Error::invalid(
                "structure.shear_building.stories",
                "must be at least 1",
            ));
        }
        // The builders index 3 n triplets; configs are held far below this by `[limits]`.
        if self.stories > usize::MAX / 8 {
            return Err(crate::error::Error::invalid(
                "structure.shear_building.stories",
                format!("{} stories cannot be indexed", self.stories),
            ));
        }
        require_positive("structure.shear_building.story_mass", self.story_mass)?;
        require_positive("structure.shear_building.first_period", self.first_period)?;
        Ok(())
    }
}

/// A shear building given storey by storey: floor masses `masses` \[kg\] and storey stiffnesses
/// `stiffness` \[N/m\], first floor first; diagonal `M`, tridiagonal `K` (the initial stiffness of
/// hysteretic storeys, see [`storey_springs`]), no damping (add it with
/// [`SparseModel::with_damping`](super::SparseModel::with_damping)). DOF `i` is floor `i + 1`.
pub fn storey_building(masses: &[f64], stiffness: &[f64], what: &str) -> Result<super::SparseModel> {
    let n = masses.len();
    if n == 0 {
        return Err(Error::invalid(format!("{what}.masses"), "must list at least one floor"));
    }
    if stiffness.len() != n {
        return Err(Error::invalid(
            format!("{what}.stiffness"),
            format!("has {} entries but masses has {n} (one per storey)", stiffness.len()),
        ));
    }
    for (i, (&m, &k)) in masses.iter().zip(stiffness).enumerate() {
        crate::error::require_positive(&format!("{what}.masses[{}]", i + 1), m)?;
        crate::error::require_positive(&format!("{what}.stiffness[{}]", i + 1), k)?;
    }
    let mut t = Vec::with_capacity(3 * n);
    for i in 0..n {
        let above = stiffness.get(i + 1).copied().unwrap_or(0.0);
        t.push((i, i, stiffness[i] + above));
        if i + 1 < n {
            t.push((i, i + 1, -above));
            t.push((i + 1, i, -above));
        }
    }
    super::SparseModel::new(
        CscMatrix::from_diagonal(masses),
        CscMatrix::zeros(n),
        CscMatrix::from_triplets(n, &t),
        None,
    )
}

/// One hysteretic spring per storey of a [`storey_building`]: storey `i` (1-based) acts on
/// the drift `u_i − u_{i−1}` (`u_0 = 0`, the ground) with initial stiffness `stiffness[i−1]`
/// and the law `laws[i−1]`.
pub fn storey_springs(stiffness: &[f64], laws: &[crate::material::MaterialSpec], what: &str) -> super::Hysteresis {
    super::Hysteresis {
        springs: stiffness
            .iter()
            .zip(laws)
            .enumerate()
            .map(|(i, (&k, law))| super::SpringSpec {
                from: i.checked_sub(1),
                to: i,
                stiffness: k,
                law: law.clone(),
                what: format!("{what} (storey {})", i + 1),
            })
            .collect(),
        p_delta: Vec::new(),
    }
}
