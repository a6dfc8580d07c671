//! Experiment: the damping product C w of a frame, both-triangle CSC vs SymmetricProduct, interleaved.
use std::time::Instant;
use substep::model::{Frame2d, frame_2d};
use substep::sparse::{CscMatrix, SymmetricProduct};

fn main() {
    let dofs: usize = std::env::args().nth(1).map_or(100_000, |s| s.parse().unwrap());
    let m = frame_2d(&Frame2d::with_about_dofs(dofs)).unwrap();
    let n = m.n_dofs();
    let c = CscMatrix::linear_combination(&[(0.002, &m.stiffness), (0.1, &m.mass)]);
    let p = SymmetricProduct::new(&c).unwrap();
    let x: Vec<f64> = (0..n).map(|i| ((i as f64) * 0.37).sin()).collect();
    let mut y1 = vec![0.0; n];
    let mut y2 = vec![0.0; n];
    let (mut t1, mut t2) = (Vec::new(), Vec::new());
    for _ in 0..200 {
        y1.fill(1.0);
        let t = Instant::now();
        c.sym_mul_add(1.0, &x, 1.0, &mut y1);
        t1.push(t.elapsed().as_secs_f64() * 1e6);
        y2.fill(1.0);
        let t = Instant::now();
        p.mul_add(&x, &mut y2);
        t2.push(t.elapsed().as_secs_f64() * 1e6);
    }
    let d = y1.iter().zip(&y2).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    t1.sort_by(f64::total_cmp);
    t2.sort_by(f64::total_cmp);
    println!(
        "n {n} nnz {} bytes csc {} sym {}; median csc {:.0} us, sym {:.0} us; max diff {d:e}",
        c.nnz(),
        c.heap_bytes(),
        p.bytes(),
        t1[100],
        t2[100]
    );
}
