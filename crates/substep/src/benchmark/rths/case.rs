//! The benchmark's reference structures (4 cases), the partition and the ground-motion record.

use crate::error::{Error, Result};
use nalgebra::{Matrix3, Vector3};

/// The common stiffness matrix [N/m].
pub const STIFFNESS: [[f64; 3]; 3] = [
    [26054883.8796, -23133938.8771, 5937035.46334],
    [-23133938.8771, 32560774.1864, -14419970.7772],
    [5937035.46334, -14419970.7772, 9267275.50622],
];

/// One reference structure: `M = m I`, classical modal damping ζ, `C` from the benchmark.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Case {
    pub number: u8,
    /// Floor mass \[kg\].
    pub mass: f64,
    /// Modal damping ratio (all modes).
    pub zeta: f64,
    /// Upper triangle of `C` [N s/m]: c11 c12 c13 c22 c23 c33.
    pub damping: [f64; 6],
}

const CASES: [Case; 4] = [
    Case {
        number: 1,
        mass: 1000.0,
        zeta: 0.05,
        damping: [
            14084.2757453,
            -7873.03146091,
            440.451498843,
            14943.6229379,
            -6348.67209631,
            7223.10131680,
        ],
    },
    Case {
        number: 2,
        mass: 1100.0,
        zeta: 0.04,
        damping: [
            11817.4226204,
            -6606.21542331,
            369.675562230,
            12538.5775697,
            -5327.04737379,
            6060.31980985,
        ],
    },
    Case {
        number: 3,
        mass: 1300.0,
        zeta: 0.03,
        damping: [
            9635.01436336,
            -5386.02577420,
            301.438640144,
            10223.0068118,
            -4343.08470212,
            4941.29882487,
        ],
    },
    Case {
        number: 4,
        mass: 1000.0,
        zeta: 0.03,
        damping: [
            8450.56544718,
            -4723.81887655,
            264.270899306,
            8966.17376274,
            -3809.20325778,
            4333.86079008,
        ],
    },
];

impl Case {
    /// Case 1..=4.
    pub fn new(number: u8) -> Result<Self> {
        CASES.iter().find(|c| c.number == number).copied().ok_or_else(|| {
            Error::invalid(
                "case",
                format!("unknown case {number} (the benchmark has cases 1, 2, 3, 4)"),
            )
        })
    }
    pub fn all() -> [Case; 4] {
        CASES
    }
    pub fn mass_matrix(&self) -> Matrix3<f64> {
        Matrix3::from_diagonal_element(self.mass)
    }
    pub fn damping_matrix(&self) -> Matrix3<f64> {
        let c = self.damping;
        Matrix3::new(c[0], c[1], c[2], c[1], c[3], c[4], c[2], c[4], c[5])
    }
    pub fn stiffness_matrix(&self) -> Matrix3<f64> {
        Matrix3::from_fn(|i, j| STIFFNESS[i][j])
    }
}

/// The experimental substructure: the first-storey column at DOF 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Specimen {
    pub m: f64,
    pub c: f64,
    pub k: f64,
}

impl Specimen {
    /// `m_e = 29.13 kg`, `k_e = 1.19e6 N/m`, `c_e = 2 ζ_e √(k_e m_e)`, `ζ_e = 0.0097`.
    pub fn benchmark() -> Self {
        Self {
            m: 29.13,
            c: 114.2208671,
            k: 1.19e6,
        }
    }
}

/// Numerical substructure `M_N, C_N, K_N` (the reference minus the specimen at DOF 1).
pub fn numerical_matrices(case: &Case, specimen: &Specimen) -> (Matrix3<f64>, Matrix3<f64>, Matrix3<f64>) {
    let mut m = case.mass_matrix();
    let mut c = case.damping_matrix();
    let mut k = case.stiffness_matrix();
    m[(0, 0)] -= specimen.m;
    c[(0, 0)] -= specimen.c;
    k[(0, 0)] -= specimen.k;
    (m, c, k)
}

/// `ι = [1, 1, 1]`.
pub fn influence() -> Vector3<f64> {
    Vector3::repeat(1.0)
}

/// Longest record the benchmark loop accepts \[s\] (bounds the memory of the histories).
pub const MAX_DURATION: f64 = 600.0;
/// Most rows a record file may have.
pub const MAX_ROWS: usize = 2_000_000;

/// A ground-acceleration record `t [s], a_g [m/s²]`, linearly interpolated.
#[derive(Debug, Clone, PartialEq)]
pub struct GroundRecord {
    pub name: String,
    t: Vec<f64>,
    a: Vec<f64>,
}

/// The El Centro record shipped with the benchmark (unscaled).
pub const ELCENTRO_CSV: &str = include_str!("../../../data/rths/elcentro.csv");

impl GroundRecord {
    /// The embedded El Centro record.
    pub fn elcentro() -> Self {
        Self::parse_csv("elcentro", ELCENTRO_CSV).expect("the embedded record is valid")
    }

    /// Parse a two-column `t,a_g` CSV (m/s²): `#` comments and blank lines skipped, an optional
    /// header line (the first non-comment line, if it is not numeric), `t` starting at 0 and
    /// strictly increasing, every value finite, at least 2 rows. `name` names the file in errors.
    pub fn parse_csv(name: &str, text: &str) -> Result<Self> {
        let (mut t, mut a) = (Vec::new(), Vec::new());
        let mut first = true;
        for (i, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let fields: Vec<&str> = line.split(',').map(str::trim).collect();
            let numeric = fields.iter().all(|f| f.parse::<f64>().is_ok());
            if first && !numeric {
                first = false;
                if fields.len() != 2 {
                    return Err(Error::file(
                        name,
                        format!(
                            "line {}: header has {} columns, expected 2 (t, a_g)",
                            i + 1,
                            fields.len()
                        ),
                    ));
                }
                continue;
            }
            first = false;
            if fields.len() != 2 {
                return Err(Error::file(
                    name,
                    format!(
                        "line {}: expected 2 columns (t [s], a_g [m/s²]), found {}",
                        i + 1,
                        fields.len()
                    ),
                ));
            }
            let parse = |f: &str, what: &str| -> Result<f64> {
                match f.parse::<f64>() {
                    Ok(v) if v.is_finite() => Ok(v),
                    _ => Err(Error::file(
                        name,
                        format!("line {}: {what} `{f}` is not a finite number", i + 1),
                    )),
                }
            };
            let ti = parse(fields[0], "time")?;
            let ai = parse(fields[1], "acceleration")?;
            if let Some(&prev) = t.last() {
                if ti <= prev {
                    return Err(Error::file(
                        name,
                        format!("line {}: time {ti} does not increase (previous {prev})", i + 1),
                    ));
                }
            } else if ti != 0.0 {
                return Err(Error::file(
                    name,
                    format!("line {}: the record must start at t = 0, got {ti}", i + 1),
                ));
            }
            if ti > MAX_DURATION {
                return Err(Error::file(
                    name,
                    format!(
                        "line {}: time {ti} s exceeds the {MAX_DURATION} s limit of the benchmark loop",
                        i + 1
                    ),
                ));
            }
            if t.len() >= MAX_ROWS {
                return Err(Error::file(name, format!("more than {MAX_ROWS} rows")));
            }
            t.push(ti);
            a.push(ai);
        }
        if t.len() < 2 {
            return Err(Error::file(
                name,
                format!("needs at least 2 samples, found {}", t.len()),
            ));
        }
        Ok(Self {
            name: name.to_string(),
            t,
            a,
        })
    }

    /// Last time \[s\].
    pub fn duration(&self) -> f64 {
        self.t[self.t.len() - 1]
    }
    /// Largest |a_g| [m/s²].
    pub fn peak(&self) -> f64 {
        self.a.iter().fold(0.0, |m, v| m.max(v.abs()))
    }

    /// `a_g` at the sorted times `times` (linear interpolation, held beyond the last sample),
    /// scaled by `scale`, written to `out`.
    pub fn sample_sorted(&self, times: impl Iterator<Item = f64>, scale: f64, out: &mut Vec<f64>) {
        let mut i = 0;
        for t in times {
            while i + 2 < self.t.len() && self.t[i + 1] <= t {
                i += 1;
            }
            let (t0, t1) = (self.t[i], self.t[i + 1]);
            let v = if t >= t1 {
                self.a[i + 1]
            } else {
                let r = (t - t0) / (t1 - t0);
                self.a[i] + r * (self.a[i + 1] - self.a[i])
            };
            out.push(scale * v);
        }
    }
}
