//! Experiment: sparse solve of a frame's effective stiffness, orderings and solves compared.
//! `cargo run --release -p substep --example frame_solve -- 100000`
use std::time::Instant;
use substep::model::{Frame2d, Frame3d, frame_2d, frame_3d};
use substep::sparse::{CscMatrix, FactorKind, SparseOrdering, SymmetricFactor};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let dofs: usize = std::env::args().nth(1).map_or(10_000, |s| s.parse().unwrap());
    let reps: usize = std::env::args().nth(2).map_or(30, |s| s.parse().unwrap());
    let three = std::env::var("THREE").is_ok();
    let (m, label) = if three {
        let f = Frame3d {
            rigid_diaphragm: std::env::var("DIAPHRAGM").is_ok(),
            ..Frame3d::with_about_dofs(dofs)
        };
        (
            frame_3d(&f).unwrap(),
            format!("3-D {} x {} bays x {} stories", f.bays_x, f.bays_y, f.stories),
        )
    } else {
        let f = Frame2d::with_about_dofs(dofs);
        (
            frame_2d(&f).unwrap(),
            format!("2-D {} bays x {} stories", f.bays, f.stories),
        )
    };
    let n = m.n_dofs();
    let dt = 0.01;
    let (a0, a1) = (4.0 / (dt * dt), 2.0 / dt);
    let (alpha, beta) = (0.1, 0.002);
    let k_hat = CscMatrix::linear_combination(&[(1.0 + a1 * beta, &m.stiffness), (a0 + a1 * alpha, &m.mass)]);
    println!("frame {label}, n = {n}, nnz(K_hat) = {}", k_hat.nnz());
    let rhs: Vec<f64> = (0..n).map(|i| ((i as f64) * 0.37).sin()).collect();
    let mut reference: Option<Vec<f64>> = None;
    for ord in [SparseOrdering::Amd, SparseOrdering::NestedDissection] {
        let t = Instant::now();
        let mut fac = SymmetricFactor::with_ordering(&k_hat, FactorKind::Sparse, ord, "K").unwrap();
        if std::env::var("TWO").is_ok() {
            assert!(fac.enable_second_core(), "no split");
        }
        let setup = t.elapsed().as_secs_f64() * 1e3;
        let mut x = rhs.clone();
        let mut times = Vec::new();
        let mut cpu = Vec::new();
        for _ in 0..reps {
            x.copy_from_slice(&rhs);
            let t = Instant::now();
            let c = thread_cpu();
            fac.solve_in_place(&mut x);
            cpu.push((thread_cpu() - c) * 1e6);
            times.push(t.elapsed().as_secs_f64() * 1e6);
        }
        println!(
            "  thread CPU median {:.1} µs min {:.1}",
            median(cpu.clone()),
            cpu.iter().cloned().fold(f64::INFINITY, f64::min)
        );
        let mut r = vec![0.0; n];
        k_hat.sym_mul_add(1.0, &x, 0.0, &mut r);
        let res = r.iter().zip(&rhs).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        let diff = reference.as_ref().map_or(0.0, |y| {
            y.iter().zip(&x).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max)
                / y.iter().fold(0.0f64, |m, v| m.max(v.abs()))
        });
        if reference.is_none() {
            reference = Some(x.clone());
        }
        println!(
            "{:<28} setup {setup:8.1} ms  factor {:>10} values  {:>7.1} MB/solve  solve median {:9.1} µs  min {:9.1}  residual {res:.2e} diff {diff:.2e}  [{}]",
            ord.name(),
            fac.factor_len(),
            fac.bytes_per_solve() as f64 / 1e6,
            median(times.clone()),
            times.iter().cloned().fold(f64::INFINITY, f64::min),
            fac.describe()
        );
    }
    // faer's own solve on its AMD factor, for reference.
    faer_baseline(&k_hat, &rhs, reps);
    // Streaming read bandwidth.
    let big = vec![1.0f64; 64 << 20];
    let mut bw = Vec::new();
    for _ in 0..5 {
        let t = Instant::now();
        let mut acc = [0.0f64; 8];
        for c in big.chunks_exact(8) {
            for k in 0..8 {
                acc[k] += c[k];
            }
        }
        let s: f64 = acc.iter().sum();
        let e = t.elapsed().as_secs_f64();
        assert!(s > 0.0);
        bw.push(big.len() as f64 * 8.0 / e / 1e9);
    }
    println!("read bandwidth {:.1} GB/s (median of 5, 512 MiB)", median(bw));
}

fn faer_baseline(a: &CscMatrix, rhs: &[f64], reps: usize) {
    use faer::dyn_stack::{MemBuffer, MemStack};
    use faer::sparse::linalg::cholesky::{
        CholeskySymbolicParams, LltRef, SymmetricOrdering, factorize_symbolic_cholesky,
    };
    use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
    use faer::{Conj, MatMut, Par, Side};
    let n = a.n();
    let (cp, ri, vals) = a.lower_triangle();
    let sym = SymbolicSparseColMatRef::new_checked(n, n, &cp, None, &ri);
    let s = factorize_symbolic_cholesky(
        sym,
        Side::Lower,
        SymmetricOrdering::Amd,
        CholeskySymbolicParams::default(),
    )
    .unwrap();
    let mut l = vec![0.0; s.len_val()];
    let mut buf = MemBuffer::new(s.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()));
    s.factorize_numeric_llt::<f64>(
        &mut l,
        SparseColMatRef::new(sym, &vals),
        Side::Lower,
        Default::default(),
        Par::Seq,
        MemStack::new(&mut buf),
        Default::default(),
    )
    .unwrap();
    let mut sb = MemBuffer::new(s.solve_in_place_scratch::<f64>(1, Par::Seq));
    let mut x = rhs.to_vec();
    let mut times = Vec::new();
    for _ in 0..reps {
        x.copy_from_slice(rhs);
        let t = Instant::now();
        LltRef::<usize, f64>::new(&s, &l).solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(&mut x, n, 1),
            Par::Seq,
            MemStack::new(&mut sb),
        );
        times.push(t.elapsed().as_secs_f64() * 1e6);
    }
    println!(
        "faer AMD + faer solve: {} values, solve median {:9.1} µs",
        l.len(),
        median(times)
    );
}

fn thread_cpu() -> f64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}
