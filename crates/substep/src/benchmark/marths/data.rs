//! The benchmark's data, shipped in `crates/substep/data/marths/` (MIT licence of the toolset,
//! see that folder's `LICENSE` and `README.md`): the 29-DOF frame (`K`, `M`), the three records,
//! the nominal plant's zeros, poles and gains, RoDeAC's initial parameters, and the 5-DOF
//! virtual frame of the feedback force (computed from the toolset's formulas).

use crate::benchmark::rths::GroundRecord;
use crate::error::{Error, Result};
use crate::transfer::lti::TransferFunction;
use crate::transfer::mimo::TransferMatrix;
use nalgebra::{Complex, DMatrix};
use std::f64::consts::PI;

const K_CSV: &str = include_str!("../../../data/marths/K.csv");
const M_CSV: &str = include_str!("../../../data/marths/M.csv");
const PHYSICAL5_K: &str = include_str!("../../../data/marths/physical5_K.csv");
const PHYSICAL5_C: &str = include_str!("../../../data/marths/physical5_C.csv");
const PHYSICAL5_M: &str = include_str!("../../../data/marths/physical5_M.csv");
const PHYSICAL5_CONDENSATION: &str = include_str!("../../../data/marths/physical5_condensation.csv");
const ELCENTRO: &str = include_str!("../../../data/marths/elcentro.csv");
const KOBE: &str = include_str!("../../../data/marths/kobe.csv");
const MORGAN: &str = include_str!("../../../data/marths/morgan.csv");
/// RoDeAC's `Initial_parameters.mat` as text (TOML).
pub const INITIAL_PARAMETERS_TOML: &str = include_str!("../../../data/marths/initial_parameters.toml");
/// The toolset's plant data (`ID_Control_plant_100Hz.mat`) as text (TOML), with the stored
/// state-space realisation the tests compare against.
pub const PLANT_TOML: &str = include_str!("../../../data/marths/plant.toml");

/// DOFs of the frame (29: SAP2000 equation numbers 1…29; 0-based here).
pub const N_DOF: usize = 29;
/// 0-based indices of the toolset's 1-based DOFs: floor 1, 2, 3 horizontal (27, 26, 13), the
/// controlled rotation (21, node 7), the uncontrolled interface rotation (29, node 6), the
/// rotations logged at storeys 2 and 3 (22, 3).
pub const DOF_X1: usize = 26;
pub const DOF_X2: usize = 25;
pub const DOF_X3: usize = 12;
pub const DOF_THETA: usize = 20;
pub const DOF_THETA29: usize = 28;
pub const DOF_R2: usize = 21;
pub const DOF_R3: usize = 2;

/// Rayleigh damping of the frame: 5 % at these two circular frequencies [rad/s] (hard-coded in
/// `build_reference.m`).
pub const RAYLEIGH_W: [f64; 2] = [13.493, 165.125];
pub const RAYLEIGH_ZETA: f64 = 0.05;

/// A matrix from CSV text (`#` comments skipped), `rows × cols`.
pub(crate) fn parse_matrix(name: &str, text: &str, rows: usize, cols: usize) -> Result<DMatrix<f64>> {
    let mut m = DMatrix::zeros(rows, cols);
    let mut r = 0;
    for line in text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
    {
        if r >= rows {
            return Err(Error::file(name, format!("more than {rows} rows")));
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != cols {
            return Err(Error::file(
                name,
                format!("row {}: {} columns, expected {cols}", r + 1, fields.len()),
            ));
        }
        for (c, f) in fields.iter().enumerate() {
            m[(r, c)] = f
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| Error::file(name, format!("row {}: `{f}` is not a finite number", r + 1)))?;
        }
        r += 1;
    }
    if r != rows {
        return Err(Error::file(name, format!("{r} rows, expected {rows}")));
    }
    Ok(m)
}

/// The reference frame: stiffness \[N/m, N, N·m/rad\], mass \[kg, kg·m²\], Rayleigh damping.
pub struct Frame {
    pub k: DMatrix<f64>,
    pub m: DMatrix<f64>,
    pub c: DMatrix<f64>,
    /// Ground-motion influence: 1 at the horizontal floor DOFs 13, 26, 27.
    pub influence: [f64; N_DOF],
}

/// Rayleigh coefficients `(α_M, α_K)` for damping `ζ` at `w` (the toolset's 2×2 solve).
pub fn rayleigh(w: [f64; 2], zeta: f64) -> (f64, f64) {
    // ζ = (α_M/ω + α_K ω)/2 at both frequencies.
    let det = 0.25 * (w[1] / w[0] - w[0] / w[1]);
    let a_m = 0.5 * zeta * (w[1] - w[0]) / det;
    let a_k = 0.5 * zeta * (1.0 / w[0] - 1.0 / w[1]) / det;
    (a_m, a_k)
}

impl Frame {
    pub fn reference() -> Self {
        let k = parse_matrix("marths/K.csv", K_CSV, N_DOF, N_DOF).expect("the shipped K is valid");
        let m = parse_matrix("marths/M.csv", M_CSV, N_DOF, N_DOF).expect("the shipped M is valid");
        let (a_m, a_k) = rayleigh(RAYLEIGH_W, RAYLEIGH_ZETA);
        let c = &m * a_m + &k * a_k;
        let mut influence = [0.0; N_DOF];
        for i in [DOF_X1, DOF_X2, DOF_X3] {
            influence[i] = 1.0;
        }
        Self { k, m, c, influence }
    }
}

/// The ideal physical partition of `build_physical_ideal.m` at the DOFs `[x_27, θ_29, θ_21]`:
/// half a beam and a column of the first storey, Euler–Bernoulli, with the density **as coded**
/// (785e3 kg/m³, 100 × steel; docs/benchmark.md).
pub struct Partition {
    pub k: [[f64; 3]; 3],
    pub m: [f64; 3],
    pub c: [[f64; 3]; 3],
}

/// DOFs of the partition, in its order.
pub const PARTITION_DOFS: [usize; 3] = [DOF_X1, DOF_THETA29, DOF_THETA];

/// The partition's density as `build_physical_ideal.m` codes it \[kg/m³\] (100 × steel).
pub const TOOLSET_DENSITY: f64 = 785e3;
/// Steel \[kg/m³\] (what the virtual frame uses).
pub const STEEL_DENSITY: f64 = 7.85e3;

impl Partition {
    /// As the toolset codes it ([`TOOLSET_DENSITY`]).
    pub fn toolset() -> Self {
        Self::with_density(TOOLSET_DENSITY)
    }

    /// The same members with density `rho` \[kg/m³\].
    pub fn with_density(rho: f64) -> Self {
        let inch: f64 = 25.4 / 1000.0;
        let (lb, lc): (f64, f64) = (0.762, 0.635);
        let (ic, ib) = (2.520 * inch.powi(4), 0.6132 * inch.powi(4));
        let (ac, ab) = (1.670 * inch * inch, 0.947 * inch * inch);
        let e = 200e9;
        let (mass_b, mass_c) = (rho * ab * lb, rho * ac * lc);
        let m1 = mass_b + mass_c;
        let m2 = (mass_b / 2.0) * lb * lb / 12.0 + (mass_c / 2.0) * lc * lc / 12.0;
        let m = [m1, m2, m2];
        let k11 = 2.0 * (3.0 * ic * e / lc.powi(3));
        let k12 = -3.0 * e * ic / (lc * lc);
        let k22 = 3.0 * e * ic / lc + 4.0 * e * ib / lb;
        let k23 = -2.0 * e * ib / lb;
        let k = [[k11, k12, k12], [k12, k22, k23], [k12, k23, k22]];
        // Rayleigh 5 % at the first and third eigenfrequencies of (KP, MP).
        let kd = DMatrix::from_fn(3, 3, |i, j| k[i][j] / (m[i] * m[j]).sqrt());
        let mut w: Vec<f64> = kd.symmetric_eigenvalues().iter().map(|l| l.sqrt()).collect();
        w.sort_by(f64::total_cmp);
        let (a_m, a_k) = rayleigh([w[0], w[2]], 0.05);
        let c = std::array::from_fn(|i| std::array::from_fn(|j| a_k * k[i][j] + if i == j { a_m * m[i] } else { 0.0 }));
        Self { k, m, c }
    }
}

/// The virtual physical frame of the feedback force (`physicalFrame_feedbackForce.m`): 5 DOFs
/// `[X_1, @_1, @_2, @_3, @_4]`, its `K`, modal `C` (5 %), lumped `M`, and the static condensation
/// `[@_2, @_3, @_4] = G [x, θ]`. Values computed from the toolset's formulas (data README).
pub struct VirtualFrame {
    pub k: DMatrix<f64>,
    pub c: DMatrix<f64>,
    pub m: DMatrix<f64>,
    pub condensation: DMatrix<f64>,
}

impl VirtualFrame {
    pub fn toolset() -> Self {
        let p = |name, text, r, c| parse_matrix(name, text, r, c).expect("the shipped virtual frame is valid");
        Self {
            k: p("marths/physical5_K.csv", PHYSICAL5_K, 5, 5),
            c: p("marths/physical5_C.csv", PHYSICAL5_C, 5, 5),
            m: p("marths/physical5_M.csv", PHYSICAL5_M, 5, 5),
            condensation: p("marths/physical5_condensation.csv", PHYSICAL5_CONDENSATION, 3, 2),
        }
    }
}

/// The shipped records (unscaled, m/s²).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Record {
    ElCentro,
    Kobe,
    Morgan,
}

impl Record {
    pub fn all() -> [Record; 3] {
        [Record::ElCentro, Record::Kobe, Record::Morgan]
    }
    pub fn name(self) -> &'static str {
        match self {
            Record::ElCentro => "elcentro",
            Record::Kobe => "kobe",
            Record::Morgan => "morgan",
        }
    }
    pub fn load(self) -> GroundRecord {
        let text = match self {
            Record::ElCentro => ELCENTRO,
            Record::Kobe => KOBE,
            Record::Morgan => MORGAN,
        };
        GroundRecord::parse_csv(self.name(), text).expect("the shipped records are valid")
    }
}

/// Zeros, poles and gains of the 2×2 plant as `fcn_build_uncert_plant.m` writes them (Hz, then
/// × 2π), so the nominal plant and its perturbations come from one description.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlantParameters {
    /// Frame pole pair `(−50 ± 63 j)·2π` (the one with negative imaginary part).
    pub frame_pole: Complex<f64>,
    /// H11, H21: zeros and the two real poles.
    pub h1_zeros: [f64; 2],
    pub h1_poles: [f64; 2],
    /// H12 and H22: their zeros; both: the two real poles.
    pub h12_zero: f64,
    pub h22_zero: f64,
    pub h2_poles: [f64; 2],
    /// Gains `[H11, H12, H21, H22]`.
    pub gains: [f64; 4],
}

impl PlantParameters {
    pub fn nominal() -> Self {
        let w = 2.0 * PI;
        Self {
            frame_pole: Complex::new(-50.0 * w, -63.0 * w),
            h1_zeros: [-120.0 * w, -90.0 * w],
            h1_poles: [-2.65 * w, -40.0 * w],
            h12_zero: -3.0 * w,
            h22_zero: -5.0 * w,
            h2_poles: [-3.5 * w, -18.5 * w],
            gains: [2165.2, 4.5394e6, 349.95, 1.9238e7],
        }
    }

    /// The plant `[[H11, H12], [H21, H22]]` (commands \[mm\] → actuator displacements \[mm\]).
    pub fn transfer_matrix(&self) -> Result<TransferMatrix> {
        let re = |v: f64| Complex::new(v, 0.0);
        let frame = [self.frame_pole, self.frame_pole.conj()];
        let p1 = [frame[0], frame[1], re(self.h1_poles[0]), re(self.h1_poles[1])];
        let p2 = [frame[0], frame[1], re(self.h2_poles[0]), re(self.h2_poles[1])];
        let z1 = [re(self.h1_zeros[0]), re(self.h1_zeros[1])];
        let g = self.gains;
        let entries = vec![
            TransferFunction::from_zpk("plant.H11", &z1, &p1, g[0])?,
            TransferFunction::from_zpk("plant.H12", &[re(self.h12_zero)], &p2, g[1])?,
            TransferFunction::from_zpk("plant.H21", &z1, &p1, g[2])?,
            TransferFunction::from_zpk("plant.H22", &[re(self.h22_zero)], &p2, g[3])?,
        ];
        TransferMatrix::new("plant", 2, 2, entries)
    }
}

/// The toolset's stored realisation of the nominal plant (`plantFRAME_SS` in
/// [`PLANT_TOML`]: 8 states, `D = 0`), for comparisons with [`PlantParameters::transfer_matrix`].
pub fn stored_plant() -> crate::transfer::mimo::MimoStateSpace {
    #[derive(serde::Deserialize)]
    struct Ss {
        a: Vec<Vec<f64>>,
        b: Vec<Vec<f64>>,
        c: Vec<Vec<f64>>,
    }
    #[derive(serde::Deserialize)]
    struct Nominal {
        ss: Ss,
    }
    #[derive(serde::Deserialize)]
    struct File {
        nominal: Nominal,
    }
    let f: File = toml::from_str(PLANT_TOML).expect("the shipped plant is valid");
    let m = |v: &Vec<Vec<f64>>| DMatrix::from_fn(v.len(), v[0].len(), |i, j| v[i][j]);
    let (a, b, c) = (m(&f.nominal.ss.a), m(&f.nominal.ss.b), m(&f.nominal.ss.c));
    let d = DMatrix::zeros(c.nrows(), b.ncols());
    crate::transfer::mimo::MimoStateSpace::new("marths/plant.toml", a, b, c, d).expect("the shipped plant is valid")
}

/// RoDeAC's initial FIR weights (newest tap first) and RLS covariances per actuator.
#[derive(Debug, Clone, PartialEq)]
pub struct InitialParameters {
    pub theta: [[f64; 4]; 2],
    pub p: [[[f64; 4]; 4]; 2],
    pub forgetting: f64,
}

impl InitialParameters {
    pub fn toolset() -> Self {
        #[derive(serde::Deserialize)]
        struct Raw {
            forgfact: f64,
            theta0_1: [f64; 4],
            theta0_2: [f64; 4],
            #[serde(rename = "P0_1")]
            p0_1: [[f64; 4]; 4],
            #[serde(rename = "P0_2")]
            p0_2: [[f64; 4]; 4],
        }
        let raw: Raw = toml::from_str(INITIAL_PARAMETERS_TOML).expect("the shipped initial parameters are valid");
        Self {
            theta: [raw.theta0_1, raw.theta0_2],
            p: [raw.p0_1, raw.p0_2],
            forgetting: raw.forgfact,
        }
    }
}
