//! Space (3-D) moment frame: a regular grid of `bays_x × bays_y` bays in plan and `stories`
//! storeys of 3-D Euler–Bernoulli beam-columns (axial, torsion, bending about both axes), six
//! DOFs per node (`ux, uy, uz, θx, θy, θz`; `z` up), fixed base, lumped masses, optional rigid
//! floor diaphragms (theory §11.5).
//!
//! DOF numbering (0-based here) goes floor by floor from the first floor up; within a floor the
//! nodes go in plan order `k = iy (bays_x + 1) + ix` (node at `x = ix · bay_x`, `y = iy · bay_y`):
//! * without diaphragms, node `k` of floor `s ≥ 1` has its six DOFs at
//!   `(s − 1) · 6 N + 6 k + 0..6` (`N = (bays_x + 1)(bays_y + 1)` nodes per floor);
//! * with rigid diaphragms, floor `s` starts with its three in-plane DOFs `U_x, U_y, Θ_z` (at the
//!   plan centre), then `uz, θx, θy` of each node: `(s − 1)(3 + 3 N) + 3 + 3 k + 0..3`. A node's
//!   in-plane motion is `ux = U_x − (y − y_c) Θ_z`, `uy = U_y + (x − x_c) Θ_z`, `θz = Θ_z`.
//!
//! Columns bend about their strong axis for motion in `x`; beams bend about their strong axis
//! in the vertical plane. Masses: the floor mass per panel (`bay_x × bay_y`) goes a quarter to
//! each corner node (in `ux, uy, uz`); each member's own mass `ρ A L` is lumped half to each
//! end, with `ρ A L · L² / 78` on each rotation (HRZ, keeps `M` positive definite). The ground
//! motion is along `x`: the influence vector is 1 on `ux` (or `U_x`).

use super::SparseModel;
use crate::error::{Error, Result, require_non_negative, require_positive};
use crate::sparse::CscMatrix;
use nalgebra::DVector;

/// Cross-section of a 3-D member.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Section3d {
    /// Area `A` \[m²\].
    pub area: f64,
    /// Second moment about the strong axis \[m⁴\].
    pub i_strong: f64,
    /// Second moment about the weak axis \[m⁴\].
    pub i_weak: f64,
    /// Torsion constant `J` \[m⁴\].
    pub torsion: f64,
}

impl Section3d {
    /// HEB 300: `A` = 149.1 cm², `I_y` = 25 170 cm⁴, `I_z` = 8 563 cm⁴, `I_t` = 185 cm⁴.
    pub const HEB300: Section3d = Section3d {
        area: 149.1e-4,
        i_strong: 25_170e-8,
        i_weak: 8_563e-8,
        torsion: 185e-8,
    };
    /// IPE 400: `A` = 84.46 cm², `I_y` = 23 130 cm⁴, `I_z` = 1 318 cm⁴, `I_t` = 51.08 cm⁴.
    pub const IPE400: Section3d = Section3d {
        area: 84.46e-4,
        i_strong: 23_130e-8,
        i_weak: 1_318e-8,
        torsion: 51.08e-8,
    };
}

/// One of the six DOFs of a space-frame node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Frame3dDof {
    Ux,
    Uy,
    Uz,
    Rx,
    Ry,
    Rz,
}

/// A regular space moment frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame3d {
    pub bays_x: usize,
    pub bays_y: usize,
    pub stories: usize,
    /// Bay widths in `x` and `y` \[m\].
    pub bay_x: f64,
    pub bay_y: f64,
    pub story_height: f64,
    /// Young's and shear modulus of all members \[Pa\].
    pub elastic_modulus: f64,
    pub shear_modulus: f64,
    pub column: Section3d,
    pub beam: Section3d,
    /// Density of the members \[kg/m³\] (> 0).
    pub density: f64,
    /// Floor mass per panel `bay_x × bay_y` and floor \[kg\].
    pub floor_mass_per_panel: f64,
    /// Tie the in-plane motion of each floor to three DOFs (rigid slab).
    pub rigid_diaphragm: bool,
}

impl Default for Frame3d {
    /// Steel frame: 3 × 3 bays of 6 m, 10 storeys of 3.5 m, `E` = 210 GPa, `G` = 81 GPa, HEB 300
    /// columns, IPE 400 beams, 20 t per panel and floor, no diaphragms.
    fn default() -> Self {
        Self {
            bays_x: 3,
            bays_y: 3,
            stories: 10,
            bay_x: 6.0,
            bay_y: 6.0,
            story_height: 3.5,
            elastic_modulus: 210e9,
            shear_modulus: 81e9,
            column: Section3d::HEB300,
            beam: Section3d::IPE400,
            density: 7850.0,
            floor_mass_per_panel: 20_000.0,
            rigid_diaphragm: false,
        }
    }
}

/// Where a node DOF goes: up to three global DOFs with coefficients (a diaphragm node's `ux`
/// is `U_x − (y − y_c) Θ_z`).
type DofMap = [(usize, f64); 3];
const NONE: (usize, f64) = (usize::MAX, 0.0);

impl Frame3d {
    /// A building of about `dofs` DOFs (no diaphragm): twice as many bays in `x` as in `y`, and
    /// storeys to make up the size.
    pub fn with_about_dofs(dofs: usize) -> Self {
        // 6 (2b + 1)(b + 1) s with s ≈ 6 b.
        let b = ((dofs as f64 / 72.0).cbrt().round() as usize).max(1);
        let per_floor = 6 * (2 * b + 1) * (b + 1);
        Self {
            bays_x: 2 * b,
            bays_y: b,
            stories: (dofs / per_floor).max(1),
            ..Self::default()
        }
    }

    fn nodes_per_floor(&self) -> usize {
        (self.bays_x + 1) * (self.bays_y + 1)
    }

    fn floor_block(&self) -> usize {
        if self.rigid_diaphragm {
            3 + 3 * self.nodes_per_floor()
        } else {
            6 * self.nodes_per_floor()
        }
    }

    pub fn n_dofs(&self) -> usize {
        self.stories * self.floor_block()
    }

    /// A DOF of node (`level`, `ix`, `iy`) that is a global DOF of its own: all six without
    /// diaphragms; `uz, θx, θy` with them (the in-plane ones are [`Frame3d::diaphragm_dof`]).
    /// `None` at the base, outside the frame, or for a tied DOF.
    pub fn dof(&self, level: usize, ix: usize, iy: usize, which: Frame3dDof) -> Option<usize> {
        if level == 0 || level > self.stories || ix > self.bays_x || iy > self.bays_y {
            return None;
        }
        let k = iy * (self.bays_x + 1) + ix;
        let base = (level - 1) * self.floor_block();
        let w = which as usize;
        if self.rigid_diaphragm {
            match which {
                Frame3dDof::Uz | Frame3dDof::Rx | Frame3dDof::Ry => Some(base + 3 + 3 * k + (w - 2)),
                _ => None,
            }
        } else {
            Some(base + 6 * k + w)
        }
    }

    /// The diaphragm DOF of floor `level`: `Ux`, `Uy` or `Rz` (`None` without diaphragms).
    pub fn diaphragm_dof(&self, level: usize, which: Frame3dDof) -> Option<usize> {
        if !self.rigid_diaphragm || level == 0 || level > self.stories {
            return None;
        }
        let base = (level - 1) * self.floor_block();
        match which {
            Frame3dDof::Ux => Some(base),
            Frame3dDof::Uy => Some(base + 1),
            Frame3dDof::Rz => Some(base + 2),
            _ => None,
        }
    }

    /// The horizontal `x` DOF of the roof's first node (or the roof diaphragm).
    pub fn roof_x_dof(&self) -> usize {
        self.diaphragm_dof(self.stories, Frame3dDof::Ux)
            .or_else(|| self.dof(self.stories, 0, 0, Frame3dDof::Ux))
            .expect("the frame has a roof")
    }

    fn node_map(&self, level: usize, ix: usize, iy: usize) -> [DofMap; 6] {
        let mut m = [[NONE; 3]; 6];
        if level == 0 {
            return m;
        }
        use Frame3dDof::*;
        for (w, d) in [Ux, Uy, Uz, Rx, Ry, Rz].into_iter().enumerate() {
            if let Some(g) = self.dof(level, ix, iy, d) {
                m[w][0] = (g, 1.0);
            }
        }
        if self.rigid_diaphragm {
            let (ux, uy, rz) = (
                self.diaphragm_dof(level, Ux).expect("floor"),
                self.diaphragm_dof(level, Uy).expect("floor"),
                self.diaphragm_dof(level, Rz).expect("floor"),
            );
            let x = ix as f64 * self.bay_x - 0.5 * self.bays_x as f64 * self.bay_x;
            let y = iy as f64 * self.bay_y - 0.5 * self.bays_y as f64 * self.bay_y;
            m[0] = [(ux, 1.0), (rz, -y), NONE];
            m[1] = [(uy, 1.0), (rz, x), NONE];
            m[5] = [(rz, 1.0), NONE, NONE];
        }
        m
    }

    fn validate(&self) -> Result<()> {
        let p = "structure.frame.";
        if self.stories == 0 {
            return Err(Error::invalid(format!("{p}stories"), "must be at least 1"));
        }
        let fits = (self.bays_x.checked_add(1))
            .and_then(|a| a.checked_mul(self.bays_y.checked_add(1)?))
            .and_then(|nodes| nodes.checked_mul(6))
            .and_then(|b| b.checked_mul(self.stories))
            .and_then(|n| n.checked_mul(144 * 3));
        if fits.is_none() {
            return Err(Error::invalid(
                format!("{p}stories"),
                format!(
                    "{} x {} bays x {} stories cannot be indexed",
                    self.bays_x, self.bays_y, self.stories
                ),
            ));
        }
        for (k, v) in [
            ("bay_width", self.bay_x),
            ("bay_width_y", self.bay_y),
            ("story_height", self.story_height),
            ("elastic_modulus", self.elastic_modulus),
            ("shear_modulus", self.shear_modulus),
            ("column_area", self.column.area),
            ("column_inertia", self.column.i_strong),
            ("column_inertia_weak", self.column.i_weak),
            ("column_torsion", self.column.torsion),
            ("beam_area", self.beam.area),
            ("beam_inertia", self.beam.i_strong),
            ("beam_inertia_weak", self.beam.i_weak),
            ("beam_torsion", self.beam.torsion),
            ("density", self.density),
        ] {
            require_positive(&format!("{p}{k}"), v)?;
        }
        require_non_negative(&format!("{p}floor_mass_per_bay"), self.floor_mass_per_panel)?;
        Ok(())
    }

    /// Walk all members and lumped masses; `stiff(i, j, v)` and `mass(i, j, v)` receive the
    /// contributions to the global matrices (to be summed).
    fn assemble(&self, mut stiff: impl FnMut(usize, usize, f64), mut mass: impl FnMut(usize, usize, f64)) {
        let (wx, wy, h) = (self.bay_x, self.bay_y, self.story_height);
        // Scatter a 12 × 12 (or 6 × 6 lumped) block through the node maps.
        fn scatter(maps: &[[DofMap; 6]], k: &dyn Fn(usize, usize) -> f64, out: &mut dyn FnMut(usize, usize, f64)) {
            let n = 6 * maps.len();
            for r in 0..n {
                for c in 0..n {
                    let v = k(r, c);
                    if v == 0.0 {
                        continue;
                    }
                    for &(gi, ci) in &maps[r / 6][r % 6] {
                        if gi == usize::MAX {
                            continue;
                        }
                        for &(gj, cj) in &maps[c / 6][c % 6] {
                            if gj != usize::MAX {
                                out(gi, gj, ci * cj * v);
                            }
                        }
                    }
                }
            }
        }
        let mut member = |a: (usize, usize, usize), b: (usize, usize, usize), sec: Section3d, dir: usize| {
            let len = [wx, wy, h][dir];
            let ke = space_member_stiffness(self.elastic_modulus, self.shear_modulus, sec, len, dir);
            let maps = [self.node_map(a.0, a.1, a.2), self.node_map(b.0, b.1, b.2)];
            scatter(&maps, &|r, c| ke[r][c], &mut stiff);
            let m_e = self.density * sec.area * len;
            for end in maps {
                let lumped = |r: usize, c: usize| {
                    if r != c {
                        0.0
                    } else if r < 3 {
                        0.5 * m_e
                    } else {
                        m_e * len * len / 78.0
                    }
                };
                scatter(&[end], &lumped, &mut mass);
            }
        };
        for s in 1..=self.stories {
            for iy in 0..=self.bays_y {
                for ix in 0..=self.bays_x {
                    member((s - 1, ix, iy), (s, ix, iy), self.column, 2);
                    if ix < self.bays_x {
                        member((s, ix, iy), (s, ix + 1, iy), self.beam, 0);
                    }
                    if iy < self.bays_y {
                        member((s, ix, iy), (s, ix, iy + 1), self.beam, 1);
                    }
                }
            }
        }
        let quarter = 0.25 * self.floor_mass_per_panel;
        for s in 1..=self.stories {
            for iy in 0..=self.bays_y {
                for ix in 0..=self.bays_x {
                    // Panels around the node: (ix − 1 or ix) × (iy − 1 or iy) that exist.
                    let px = (ix > 0) as usize + (ix < self.bays_x) as usize;
                    let py = (iy > 0) as usize + (iy < self.bays_y) as usize;
                    let m = quarter * (px * py) as f64;
                    if m > 0.0 {
                        let map = self.node_map(s, ix, iy);
                        scatter(&[map], &|r, c| if r == c && r < 3 { m } else { 0.0 }, &mut mass);
                    }
                }
            }
        }
    }

    fn influence(&self) -> DVector<f64> {
        let mut iota = DVector::zeros(self.n_dofs());
        for s in 1..=self.stories {
            if let Some(d) = self.diaphragm_dof(s, Frame3dDof::Ux) {
                iota[d] = 1.0;
                continue;
            }
            for iy in 0..=self.bays_y {
                for ix in 0..=self.bays_x {
                    if let Some(d) = self.dof(s, ix, iy, Frame3dDof::Ux) {
                        iota[d] = 1.0;
                    }
                }
            }
        }
        iota
    }
}

/// Global stiffness of a 3-D Euler–Bernoulli member of length `len` along global axis `dir`
/// (0 = x, 1 = y, 2 = z); DOF order `u, v, w, θx, θy, θz` at each end. Local axes: columns
/// (along z) have local `y` = global `x` (strong-axis bending for motion in `x`), beams have
/// local `z` = global `z` (strong-axis bending in the vertical plane).
pub(crate) fn space_member_stiffness(e: f64, g: f64, sec: Section3d, len: f64, dir: usize) -> [[f64; 12]; 12] {
    // Bending in the local x-y plane uses I_z, in the local x-z plane I_y.
    let (iz, iy) = if dir == 2 {
        (sec.i_strong, sec.i_weak)
    } else {
        (sec.i_weak, sec.i_strong)
    };
    let (l, l2, l3) = (len, len * len, len * len * len);
    let mut k = [[0.0; 12]; 12];
    let mut set = |i: usize, j: usize, v: f64| {
        k[i][j] = v;
        k[j][i] = v;
    };
    let ea = e * sec.area / l;
    set(0, 0, ea);
    set(6, 6, ea);
    set(0, 6, -ea);
    let gj = g * sec.torsion / l;
    set(3, 3, gj);
    set(9, 9, gj);
    set(3, 9, -gj);
    // v, θz (I_z)
    let (a, b, c, d) = (
        12.0 * e * iz / l3,
        6.0 * e * iz / l2,
        4.0 * e * iz / l,
        2.0 * e * iz / l,
    );
    set(1, 1, a);
    set(7, 7, a);
    set(1, 7, -a);
    set(1, 5, b);
    set(1, 11, b);
    set(5, 7, -b);
    set(7, 11, -b);
    set(5, 5, c);
    set(11, 11, c);
    set(5, 11, d);
    // w, θy (I_y)
    let (a, b, c, d) = (
        12.0 * e * iy / l3,
        6.0 * e * iy / l2,
        4.0 * e * iy / l,
        2.0 * e * iy / l,
    );
    set(2, 2, a);
    set(8, 8, a);
    set(2, 8, -a);
    set(2, 4, -b);
    set(2, 10, -b);
    set(4, 8, b);
    set(8, 10, b);
    set(4, 4, c);
    set(10, 10, c);
    set(4, 10, d);
    // Rows of R: the local axes in global coordinates.
    let r: [[f64; 3]; 3] = match dir {
        0 => [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        1 => [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
        _ => [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
    };
    // K = Tᵀ k T, T = diag(R, R, R, R).
    let t = |i: usize, j: usize| if i / 3 == j / 3 { r[i % 3][j % 3] } else { 0.0 };
    let kt: [[f64; 12]; 12] =
        std::array::from_fn(|i| std::array::from_fn(|j| (0..12).map(|m| k[i][m] * t(m, j)).sum()));
    std::array::from_fn(|i| std::array::from_fn(|j| (0..12).map(|m| t(m, i) * kt[m][j]).sum()))
}

/// The undamped space frame in sparse storage; add damping with [`SparseModel::with_damping`].
pub fn frame_3d(f: &Frame3d) -> Result<SparseModel> {
    f.validate()?;
    let n = f.n_dofs();
    let mut kt = Vec::new();
    let mut mt = Vec::new();
    f.assemble(|i, j, v| kt.push((i, j, v)), |i, j, v| mt.push((i, j, v)));
    SparseModel::new(
        CscMatrix::from_triplets(n, &mt),
        CscMatrix::zeros(n),
        CscMatrix::from_triplets(n, &kt),
        Some(f.influence()),
    )
}
