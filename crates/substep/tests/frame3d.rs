//! The space-frame builder against closed forms (cantilever column, total mass) and against
//! the plane frame (a space frame one bay deep in `y = 0` responds in its plane like the 2-D
//! frame), with and without rigid diaphragms.

use nalgebra::{DMatrix, DVector};
use substep::model::{Frame2d, Frame3d, Frame3dDof, FrameDof, Section, Section3d, frame_2d, frame_3d};

/// `(K⁻¹)_{dd}`.
fn flexibility(k: &DMatrix<f64>, d: usize) -> f64 {
    let mut e = DVector::zeros(k.nrows());
    e[d] = 1.0;
    k.clone().cholesky().expect("K is SPD").solve(&e)[d]
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

#[test]
fn cantilever_column_flexibilities() {
    let f = Frame3d {
        bays_x: 0,
        bays_y: 0,
        stories: 1,
        story_height: 3.7,
        ..Frame3d::default()
    };
    let m = frame_3d(&f).unwrap();
    assert_eq!(m.n_dofs(), 6);
    let k = m.stiffness.to_dense();
    let (e, g, s, l) = (f.elastic_modulus, f.shear_modulus, f.column, f.story_height);
    let d = |w| f.dof(1, 0, 0, w).unwrap();
    assert!(rel(flexibility(&k, d(Frame3dDof::Ux)), l.powi(3) / (3.0 * e * s.i_strong)) < 1e-10);
    assert!(rel(flexibility(&k, d(Frame3dDof::Uy)), l.powi(3) / (3.0 * e * s.i_weak)) < 1e-10);
    assert!(rel(flexibility(&k, d(Frame3dDof::Uz)), l / (e * s.area)) < 1e-10);
    assert!(rel(flexibility(&k, d(Frame3dDof::Rz)), l / (g * s.torsion)) < 1e-10);
    // Tip rotation under a tip moment about y (bending in x-z): L / (E I_strong).
    assert!(rel(flexibility(&k, d(Frame3dDof::Ry)), l / (e * s.i_strong)) < 1e-10);
    assert!(rel(flexibility(&k, d(Frame3dDof::Rx)), l / (e * s.i_weak)) < 1e-10);
}

#[test]
fn one_bay_deep_plane_matches_the_2d_frame_in_plane() {
    for diaphragm in [false, true] {
        let f3 = Frame3d {
            bays_x: 3,
            bays_y: 0,
            stories: 4,
            rigid_diaphragm: diaphragm,
            ..Frame3d::default()
        };
        let f2 = Frame2d {
            bays: 3,
            stories: 4,
            bay_width: f3.bay_x,
            story_height: f3.story_height,
            column: Section {
                area: f3.column.area,
                inertia: f3.column.i_strong,
            },
            beam: Section {
                area: f3.beam.area,
                inertia: f3.beam.i_strong,
            },
            rigid_diaphragm: diaphragm,
            ..Frame2d::default()
        };
        let k3 = frame_3d(&f3).unwrap().stiffness.to_dense();
        let k2 = frame_2d(&f2).unwrap().stiffness.to_dense();
        for s in 1..=4 {
            let d3 = if diaphragm {
                f3.diaphragm_dof(s, Frame3dDof::Ux).unwrap()
            } else {
                f3.dof(s, 0, 0, Frame3dDof::Ux).unwrap()
            };
            let d2 = f2.dof(s, 0, FrameDof::Ux).unwrap();
            let (a, b) = (flexibility(&k3, d3), flexibility(&k2, d2));
            assert!(rel(a, b) < 1e-9, "diaphragm {diaphragm}, storey {s}: {a} vs {b}");
            // Vertical, in plane: uz (3-D) is uy (2-D).
            let (a, b) = (
                flexibility(&k3, f3.dof(s, 1, 0, Frame3dDof::Uz).unwrap()),
                flexibility(&k2, f2.dof(s, 1, FrameDof::Uy).unwrap()),
            );
            assert!(
                rel(a, b) < 1e-9,
                "diaphragm {diaphragm}, storey {s}, vertical: {a} vs {b}"
            );
        }
    }
}

#[test]
fn symmetric_plan_has_equal_flexibility_in_x_and_y() {
    let round = Section3d {
        area: 149.1e-4,
        i_strong: 25_170e-8,
        i_weak: 25_170e-8,
        torsion: 185e-8,
    };
    let f = Frame3d {
        bays_x: 2,
        bays_y: 2,
        stories: 3,
        column: round,
        rigid_diaphragm: true,
        ..Frame3d::default()
    };
    let k = frame_3d(&f).unwrap().stiffness.to_dense();
    let ux = flexibility(&k, f.diaphragm_dof(3, Frame3dDof::Ux).unwrap());
    let uy = flexibility(&k, f.diaphragm_dof(3, Frame3dDof::Uy).unwrap());
    assert!(rel(ux, uy) < 1e-10, "{ux} vs {uy}");
    // The rigid slab stiffens: without diaphragms the corner node moves more.
    let free = Frame3d {
        rigid_diaphragm: false,
        ..f
    };
    let kf = frame_3d(&free).unwrap().stiffness.to_dense();
    assert!(flexibility(&kf, free.dof(3, 0, 0, Frame3dDof::Ux).unwrap()) > ux);
}

#[test]
fn translational_mass_is_floors_plus_members() {
    for diaphragm in [false, true] {
        let f = Frame3d {
            bays_x: 3,
            bays_y: 2,
            stories: 5,
            rigid_diaphragm: diaphragm,
            ..Frame3d::default()
        };
        let m = frame_3d(&f).unwrap();
        let iota = m.influence.clone();
        let mut mi = vec![0.0; m.n_dofs()];
        m.mass.sym_mul_add(1.0, iota.as_slice(), 0.0, &mut mi);
        let total: f64 = mi.iter().zip(iota.iter()).map(|(a, b)| a * b).sum();
        let (bx, by, s) = (3.0, 2.0, 5.0);
        let floors = s * bx * by * f.floor_mass_per_panel;
        let columns = s * (bx + 1.0) * (by + 1.0) * f.density * f.column.area * f.story_height;
        let beams = s * f.density * f.beam.area * ((by + 1.0) * bx * f.bay_x + (bx + 1.0) * by * f.bay_y);
        // Columns at the base lose the half lumped at the fixed base node.
        let want = floors + beams + columns - 0.5 * columns / s;
        assert!(rel(total, want) < 1e-12, "diaphragm {diaphragm}: {total} vs {want}");
        assert_eq!(m.n_dofs(), if diaphragm { 5 * (3 + 3 * 12) } else { 5 * 6 * 12 });
    }
}

mod config {
    use super::*;
    use std::path::Path;
    use substep::io::TestDefinition;

    const MOTION: &str =
        "[ground_motion]\ngenerator = \"harmonic\"\namplitude = 1.0\nfrequency = 2.0\nduration = 0.1\n";

    fn cfg(frame: &str) -> String {
        format!(
            "[structure]\nstorage = \"sparse\"\n[structure.frame]\n{frame}\n[structure.rayleigh]\nalpha = 0.1\nbeta = 0.002\n\
             {MOTION}[integrator]\nscheme = \"newmark\"\ndt = 0.01\n"
        )
    }

    fn parse(text: &str) -> substep::Result<TestDefinition> {
        TestDefinition::from_toml(text, "cfg.toml", Path::new("."))
    }

    #[test]
    fn dimensions_3_builds_the_space_frame_of_the_keys() {
        let d = parse(&cfg(
            "dimensions = 3\nbays = 2\nbays_y = 1\nstories = 3\nrigid_diaphragm = true\nbay_width_y = 5.0",
        ))
        .unwrap();
        let f = Frame3d {
            bays_x: 2,
            bays_y: 1,
            stories: 3,
            bay_y: 5.0,
            rigid_diaphragm: true,
            ..Frame3d::default()
        };
        let want = frame_3d(&f).unwrap();
        let got = d.model.as_sparse().expect("sparse storage");
        assert_eq!(got.stiffness, want.stiffness);
        assert_eq!(got.mass, want.mass);
        assert_eq!(got.influence, want.influence);
        // Rayleigh C = 0.1 M + 0.002 K on the space frame's matrices.
        assert!((got.damping.get(0, 0) - (0.1 * want.mass.get(0, 0) + 0.002 * want.stiffness.get(0, 0))).abs() < 1e-6);
        let mut sim = substep::run::Simulation::new(&d).unwrap();
        for _ in 0..sim.steps_total() {
            sim.step(&mut ()).unwrap();
        }
        assert!(sim.state().u.amax() > 0.0);
    }

    #[test]
    fn space_keys_need_dimensions_3_and_dimensions_is_2_or_3() {
        let e = parse(&cfg("bays_y = 2")).unwrap_err().to_string();
        assert!(
            e.contains("structure.frame.bays_y: is a space-frame key: it needs dimensions = 3"),
            "{e}"
        );
        let e = parse(&cfg("dimensions = 4")).unwrap_err().to_string();
        assert!(
            e.contains("structure.frame.dimensions: must be 2 (plane frame) or 3 (space frame), got 4"),
            "{e}"
        );
    }
}
