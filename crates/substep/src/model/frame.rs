//! Plane (2-D) moment frame: `bays × stories` of Euler–Bernoulli beam-column elements, three
//! DOFs per node (`ux`, `uy`, `θ`), fixed base, lumped masses, optional rigid floor diaphragm.
//!
//! DOF numbering (0-based here, 1-based in configs) goes floor by floor from the first floor
//! up, so the half-bandwidth is about one floor (`3 (bays + 1) + 2` without a diaphragm):
//! * without diaphragm, node `(level s ≥ 1, column line c)` has `ux, uy, θ` at
//!   `3 ((s − 1)(bays + 1) + c) + 0, 1, 2`;
//! * with a rigid diaphragm, floor `s` has one horizontal DOF shared by its nodes at
//!   `(s − 1)(1 + 2 (bays + 1))`, then `uy, θ` of each node in column-line order.
//!
//! Masses: the floor mass per bay is split equally between the bay's two end nodes (in `ux` and
//! `uy`); each member's own mass `ρ A L` is lumped half to each end, with the rotational
//! inertia `ρ A L · L² / 78` of HRZ lumping at each end, which keeps `M` positive definite.
//! The ground motion is horizontal: the influence vector is 1 on horizontal DOFs.

use super::{SparseModel, StructuralModel};
use crate::error::{Error, Result, require_positive};
use crate::sparse::CscMatrix;
use nalgebra::{DMatrix, DVector};

/// Cross-section properties of a member (strong axis in the frame plane).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Section {
    /// Area `A` \[m²\].
    pub area: f64,
    /// Second moment of area `I` \[m⁴\].
    pub inertia: f64,
}

impl Section {
    /// HEB 300 (European wide-flange column): `A` = 149.1 cm², `I_y` = 25 170 cm⁴.
    pub const HEB300: Section = Section {
        area: 149.1e-4,
        inertia: 25_170e-8,
    };
    /// IPE 400 (European I-beam): `A` = 84.46 cm², `I_y` = 23 130 cm⁴.
    pub const IPE400: Section = Section {
        area: 84.46e-4,
        inertia: 23_130e-8,
    };
}

/// One of the three DOFs of a frame node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameDof {
    /// Horizontal displacement.
    Ux,
    /// Vertical displacement.
    Uy,
    /// Rotation (counter-clockwise).
    Rz,
}

/// A regular plane moment frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame2d {
    /// Bays (0: a single column line, i.e. a cantilever column stack).
    pub bays: usize,
    /// Stories (≥ 1).
    pub stories: usize,
    /// Bay width \[m\].
    pub bay_width: f64,
    /// Story height \[m\].
    pub story_height: f64,
    /// Young's modulus of all members \[Pa\].
    pub elastic_modulus: f64,
    pub column: Section,
    pub beam: Section,
    /// Density of the members [kg/m³] (their own mass; must be > 0).
    pub density: f64,
    /// Floor mass per bay and floor \[kg\], lumped at the bay's two end nodes.
    pub floor_mass_per_bay: f64,
    /// Tie the horizontal DOFs of each floor into one (axially rigid floor).
    pub rigid_diaphragm: bool,
}

impl Default for Frame2d {
    /// Steel frame: 3 bays of 6 m, 10 stories of 3.5 m, `E` = 210 GPa, HEB 300 columns, IPE 400
    /// beams, steel density, 20 t of floor mass per bay, no diaphragm.
    fn default() -> Self {
        Self {
            bays: 3,
            stories: 10,
            bay_width: 6.0,
            story_height: 3.5,
            elastic_modulus: 210e9,
            column: Section::HEB300,
            beam: Section::IPE400,
            density: 7850.0,
            floor_mass_per_bay: 20_000.0,
            rigid_diaphragm: false,
        }
    }
}

impl Frame2d {
    /// Bays and stories of about `dofs` DOFs in total (no diaphragm), twice as many stories
    /// as bays (a tall building; at least one bay).
    pub fn with_about_dofs(dofs: usize) -> Self {
        // 3 (b + 1) s DOFs with s = 2 b.
        let b = (((dofs as f64) / 6.0).sqrt().round() as usize).max(1);
        let s = (dofs / (3 * (b + 1))).max(1);
        Self {
            bays: b,
            stories: s,
            ..Self::default()
        }
    }

    fn lines(&self) -> usize {
        self.bays + 1
    }
    fn floor_block(&self) -> usize {
        if self.rigid_diaphragm {
            1 + 2 * self.lines()
        } else {
            3 * self.lines()
        }
    }

    pub fn n_dofs(&self) -> usize {
        self.stories * self.floor_block()
    }

    /// The DOF of node (`level`, column line `line`); `None` at the fixed base (`level = 0`) or
    /// outside the frame.
    pub fn dof(&self, level: usize, line: usize, which: FrameDof) -> Option<usize> {
        if level == 0 || level > self.stories || line > self.bays {
            return None;
        }
        let base = (level - 1) * self.floor_block();
        Some(if self.rigid_diaphragm {
            match which {
                FrameDof::Ux => base,
                FrameDof::Uy => base + 1 + 2 * line,
                FrameDof::Rz => base + 2 + 2 * line,
            }
        } else {
            base + 3 * line
                + match which {
                    FrameDof::Ux => 0,
                    FrameDof::Uy => 1,
                    FrameDof::Rz => 2,
                }
        })
    }

    fn validate(&self) -> Result<()> {
        let p = "structure.frame.";
        if self.stories == 0 {
            return Err(Error::invalid(format!("{p}stories"), "must be at least 1"));
        }
        // DOF numbers and the 36 stiffness triplets per member must be indexable (configs are
        // held far below this by `[limits]`).
        let dofs = (self.bays.checked_add(1))
            .and_then(|l| l.checked_mul(3))
            .and_then(|b| b.checked_mul(self.stories))
            .and_then(|n| n.checked_mul(72));
        if dofs.is_none() {
            return Err(Error::invalid(
                format!("{p}stories"),
                format!("{} bays x {} stories cannot be indexed", self.bays, self.stories),
            ));
        }
        require_positive(&format!("{p}bay_width"), self.bay_width)?;
        require_positive(&format!("{p}story_height"), self.story_height)?;
        require_positive(&format!("{p}elastic_modulus"), self.elastic_modulus)?;
        require_positive(&format!("{p}column_area"), self.column.area)?;
        require_positive(&format!("{p}column_inertia"), self.column.inertia)?;
        require_positive(&format!("{p}beam_area"), self.beam.area)?;
        require_positive(&format!("{p}beam_inertia"), self.beam.inertia)?;
        require_positive(&format!("{p}density"), self.density)?;
        crate::error::require_non_negative(&format!("{p}floor_mass_per_bay"), self.floor_mass_per_bay)?;
        Ok(())
    }

    /// Walk all members and lumped masses; `stiff(i, j, v)` and `mass(i, v)` receive the
    /// contributions to the global matrices (to be summed).
    fn assemble(&self, stiff: impl FnMut(usize, usize, f64), mass: impl FnMut(usize, f64)) {
        self.assemble_with(None, stiff, mass, |_| {});
    }

    /// [`Self::assemble`] with rotational hinges at the member ends `hinges` asks for: a hinged
    /// end gets its own rotation DOF (numbered after the nodes' DOFs, in member order: columns
    /// then beams of each storey, end `a` before end `b`), the member's rotational inertia at
    /// that end is split half to it and half to the node (all of it where the node is fixed),
    /// and `spring` receives the hinge between the node's rotation (`None` at the fixed base)
    /// and the end's.
    fn assemble_with(
        &self,
        hinges: Option<&FrameHinges>,
        mut stiff: impl FnMut(usize, usize, f64),
        mut mass: impl FnMut(usize, f64),
        mut spring: impl FnMut(HingeSpring),
    ) {
        let (w, h) = (self.bay_width, self.story_height);
        let node_dofs =
            |level: usize, line: usize| [FrameDof::Ux, FrameDof::Uy, FrameDof::Rz].map(|d| self.dof(level, line, d));
        let mut next_hinge = self.n_dofs();
        let mut member = |a: (usize, usize), b: (usize, usize), sec: Section, dx: f64, dy: f64, is_beam: bool| {
            let len = (dx * dx + dy * dy).sqrt();
            let ke = beam_column_stiffness(self.elastic_modulus, sec, len, dx / len, dy / len);
            let hinged = hinges.is_some_and(|h| h.at.hinges(is_beam));
            let mut ends = [node_dofs(a.0, a.1), node_dofs(b.0, b.1)];
            let node_rz = [ends[0][2], ends[1][2]];
            if hinged {
                let h = hinges.expect("hinged");
                for end in &mut ends {
                    let node = end[2];
                    end[2] = Some(next_hinge);
                    spring(HingeSpring {
                        node,
                        hinge: next_hinge,
                        stiffness: h.stiffness_factor * 6.0 * self.elastic_modulus * sec.inertia / len,
                        is_beam,
                    });
                    next_hinge += 1;
                }
            }
            let dofs: Vec<Option<usize>> = ends[0].into_iter().chain(ends[1]).collect();
            for (r, gr) in dofs.iter().enumerate() {
                for (c, gc) in dofs.iter().enumerate() {
                    if let (Some(i), Some(j)) = (gr, gc) {
                        stiff(*i, *j, ke[r][c]);
                    }
                }
            }
            let m_e = self.density * sec.area * len;
            for (end, node_rz) in ends.iter().zip(node_rz) {
                let [ux, uy, rz] = *end;
                for d in [ux, uy].into_iter().flatten() {
                    mass(d, 0.5 * m_e);
                }
                let inertia = m_e * len * len / 78.0;
                match (hinged, rz, node_rz) {
                    (true, Some(hinge), Some(node)) => {
                        mass(hinge, 0.5 * inertia);
                        mass(node, 0.5 * inertia);
                    }
                    (_, Some(d), _) => mass(d, inertia),
                    (_, None, _) => {}
                }
            }
        };
        for s in 1..=self.stories {
            for c in 0..=self.bays {
                member((s - 1, c), (s, c), self.column, 0.0, h, false);
            }
            for b in 0..self.bays {
                member((s, b), (s, b + 1), self.beam, w, 0.0, true);
            }
        }
        for s in 1..=self.stories {
            for b in 0..self.bays {
                for c in [b, b + 1] {
                    let [ux, uy, _] = node_dofs(s, c);
                    for d in [ux, uy].into_iter().flatten() {
                        mass(d, 0.5 * self.floor_mass_per_bay);
                    }
                }
            }
        }
    }

    /// Influence vector: 1 on horizontal DOFs.
    fn influence(&self) -> DVector<f64> {
        self.influence_of(self.n_dofs())
    }

    /// Influence vector of a model of `n ≥ n_dofs()` DOFs (hinge rotations: 0).
    fn influence_of(&self, n: usize) -> DVector<f64> {
        let mut iota = DVector::zeros(n);
        for s in 1..=self.stories {
            for c in 0..=self.bays {
                if let Some(d) = self.dof(s, c, FrameDof::Ux) {
                    iota[d] = 1.0;
                }
            }
        }
        iota
    }
}

/// Which member ends get rotational hinges.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HingeLocation {
    Beams,
    Columns,
    Both,
}

impl HingeLocation {
    pub fn from_name(name: &str) -> Result<Self> {
        match name {
            "beams" => Ok(HingeLocation::Beams),
            "columns" => Ok(HingeLocation::Columns),
            "both" => Ok(HingeLocation::Both),
            other => Err(Error::invalid(
                "structure.frame.hinges.at",
                format!("unknown location '{other}' (expected beams, columns or both)"),
            )),
        }
    }
    fn hinges(self, is_beam: bool) -> bool {
        match self {
            HingeLocation::Beams => is_beam,
            HingeLocation::Columns => !is_beam,
            HingeLocation::Both => true,
        }
    }
}

/// Concentrated plasticity of a plane frame: a rotational spring at both ends of the members
/// `at` selects (docs/theory.md §14.2), between the node's rotation and the member end's.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameHinges {
    pub at: HingeLocation,
    /// Initial hinge stiffness as a multiple of the member's `6 E I / L` (the member end is not
    /// stiffened; default 10, Ibarra and Krawinkler's `n`).
    pub stiffness_factor: f64,
    /// The law of the beams' and of the columns' hinges (moment \[N·m\] over rotation \[rad\]).
    pub beam_law: crate::material::MaterialSpec,
    pub column_law: crate::material::MaterialSpec,
}

/// One hinge found by the frame assembly.
#[derive(Debug, Clone, Copy)]
struct HingeSpring {
    node: Option<usize>,
    hinge: usize,
    stiffness: f64,
    is_beam: bool,
}

/// The frame with hinges: the undamped model (sparse; the hinges' initial stiffness in `K`) and
/// its springs. DOFs `0..f.n_dofs()` are the nodes' as in [`frame_2d`]; the hinge rotations
/// follow.
pub fn frame_2d_hinged(f: &Frame2d, hinges: &FrameHinges) -> Result<(SparseModel, super::Hysteresis)> {
    f.validate()?;
    crate::error::require_positive("structure.frame.hinges.stiffness_factor", hinges.stiffness_factor)?;
    let mut kt = Vec::with_capacity(40 * (2 * f.lines() * f.stories));
    let mut md = vec![0.0; f.n_dofs()];
    let mut found = Vec::new();
    f.assemble_with(
        Some(hinges),
        |i, j, v| kt.push((i, j, v)),
        |i, v| {
            if i >= md.len() {
                md.resize(i + 1, 0.0);
            }
            md[i] += v
        },
        |h| found.push(h),
    );
    let n = f.n_dofs() + found.len();
    md.resize(n, 0.0);
    let mut springs = Vec::with_capacity(found.len());
    for h in &found {
        kt.push((h.hinge, h.hinge, h.stiffness));
        if let Some(node) = h.node {
            kt.extend([
                (node, node, h.stiffness),
                (node, h.hinge, -h.stiffness),
                (h.hinge, node, -h.stiffness),
            ]);
        }
        springs.push(super::SpringSpec {
            from: h.node,
            to: h.hinge,
            stiffness: h.stiffness,
            law: if h.is_beam {
                hinges.beam_law.clone()
            } else {
                hinges.column_law.clone()
            },
            what: format!(
                "structure.frame.hinges ({} hinge at DOF {})",
                if h.is_beam { "beam" } else { "column" },
                h.hinge + 1
            ),
        });
    }
    let model = SparseModel::new(
        CscMatrix::from_diagonal(&md),
        CscMatrix::zeros(n),
        CscMatrix::from_triplets(n, &kt),
        Some(f.influence_of(n)),
    )?;
    Ok((
        model,
        super::Hysteresis {
            springs,
            p_delta: Vec::new(),
        },
    ))
}

/// The columns of `f` under P-Δ ([`super::PDeltaSpec`], OpenSees' `PDelta` transformation):
/// their end translations are the nodes' (hinges change only rotations).
pub fn frame_p_delta(f: &Frame2d) -> Vec<super::PDeltaSpec> {
    let mut out = Vec::with_capacity(f.stories * f.lines());
    for s in 1..=f.stories {
        for c in 0..=f.bays {
            let end = |level| [f.dof(level, c, FrameDof::Ux), f.dof(level, c, FrameDof::Uy)];
            out.push(super::PDeltaSpec {
                a: end(s - 1),
                b: end(s),
                cos: 0.0,
                sin: 1.0,
                axial_stiffness: f.elastic_modulus * f.column.area / f.story_height,
                length: f.story_height,
            });
        }
    }
    out
}

/// Gravity on the nodes of `f` in a model of `n ≥ f.n_dofs()` DOFs with the diagonal mass
/// `mass`: `−g m` on every vertical DOF, `m` the mass lumped there \[N\] (`g` = 9.80665 m/s²).
pub fn frame_gravity(f: &Frame2d, mass: &[f64], n: usize) -> DVector<f64> {
    let mut load = DVector::zeros(n);
    for s in 1..=f.stories {
        for c in 0..=f.bays {
            if let Some(d) = f.dof(s, c, FrameDof::Uy) {
                load[d] = -9.80665 * mass[d];
            }
        }
    }
    load
}

/// Global stiffness of a 2-D Euler–Bernoulli beam-column from end `a` to end `b` with direction
/// cosines `(c, s)`; DOF order `ux_a, uy_a, θ_a, ux_b, uy_b, θ_b`.
pub(crate) fn beam_column_stiffness(e: f64, sec: Section, len: f64, c: f64, s: f64) -> [[f64; 6]; 6] {
    let ea = e * sec.area / len;
    let ei = e * sec.inertia;
    let (k1, k2, k3, k4) = (
        12.0 * ei / len.powi(3),
        6.0 * ei / len.powi(2),
        4.0 * ei / len,
        2.0 * ei / len,
    );
    let kl = [
        [ea, 0.0, 0.0, -ea, 0.0, 0.0],
        [0.0, k1, k2, 0.0, -k1, k2],
        [0.0, k2, k3, 0.0, -k2, k4],
        [-ea, 0.0, 0.0, ea, 0.0, 0.0],
        [0.0, -k1, -k2, 0.0, k1, -k2],
        [0.0, k2, k4, 0.0, -k2, k3],
    ];
    // T = diag(R, R), R = [c s 0; −s c 0; 0 0 1]; K = Tᵀ k T.
    let mut t = [[0.0; 6]; 6];
    for o in [0, 3] {
        t[o][o] = c;
        t[o][o + 1] = s;
        t[o + 1][o] = -s;
        t[o + 1][o + 1] = c;
        t[o + 2][o + 2] = 1.0;
    }
    let mut kt = [[0.0; 6]; 6];
    for i in 0..6 {
        for j in 0..6 {
            kt[i][j] = (0..6).map(|k| kl[i][k] * t[k][j]).sum();
        }
    }
    let mut kg = [[0.0; 6]; 6];
    for i in 0..6 {
        for j in 0..6 {
            kg[i][j] = (0..6).map(|k| t[k][i] * kt[k][j]).sum();
        }
    }
    kg
}

/// The undamped frame in sparse storage; add damping with [`SparseModel::with_damping`].
pub fn frame_2d(f: &Frame2d) -> Result<SparseModel> {
    f.validate()?;
    let n = f.n_dofs();
    let mut kt = Vec::with_capacity(36 * (2 * f.lines() * f.stories));
    let mut md = vec![0.0; n];
    f.assemble(|i, j, v| kt.push((i, j, v)), |i, v| md[i] += v);
    SparseModel::new(
        CscMatrix::from_diagonal(&md),
        CscMatrix::zeros(n),
        CscMatrix::from_triplets(n, &kt),
        Some(f.influence()),
    )
}

/// The undamped frame assembled straight into dense matrices (small frames, and the check
/// that both assemblies agree).
pub fn frame_2d_dense(f: &Frame2d) -> Result<StructuralModel> {
    f.validate()?;
    let n = f.n_dofs();
    if n > super::DENSE_MAX_DOFS {
        return Err(Error::invalid(
            "structure.frame",
            format!(
                "{n} DOFs are too many for dense storage (at most {})",
                super::DENSE_MAX_DOFS
            ),
        ));
    }
    let mut kk = DMatrix::zeros(n, n);
    let mut mm = DMatrix::zeros(n, n);
    f.assemble(|i, j, v| kk[(i, j)] += v, |i, v| mm[(i, i)] += v);
    StructuralModel::new(mm, DMatrix::zeros(n, n), kk, Some(f.influence()))
}
