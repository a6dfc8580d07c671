//! Nested-dissection ordering of a symmetric sparse matrix by METIS (`METIS_NodeND`, vendored
//! C source built by the `metis-sys` crate; no system library).
//!
//! A building frame is a graph of about `√n`-node floors stacked on each other; AMD orders
//! it greedily, nested dissection cuts it recursively along small separators, so the dense
//! blocks of `L` are the separators and the factor is smaller (theory §11.4).

use super::CscMatrix;
use crate::error::{Error, Result};

/// `(fwd, inv)`: permuted row `i` is row `fwd[i]` of `a`; `inv` is the inverse.
/// Deterministic (METIS' fixed default seed).
pub(crate) fn nested_dissection(a: &CscMatrix) -> Result<(Vec<usize>, Vec<usize>)> {
    let n = a.n();
    let off_diag = a.nnz() - (0..n).filter(|&j| a.col(j).0.binary_search(&j).is_ok()).count();
    if n > i32::MAX as usize || off_diag > i32::MAX as usize {
        return Err(Error::invalid(
            "structure",
            format!("{n} DOFs with {off_diag} couplings are too many for the METIS ordering"),
        ));
    }
    if n <= 1 || off_diag == 0 {
        return Ok(((0..n).collect(), (0..n).collect()));
    }
    let mut xadj: Vec<i32> = Vec::with_capacity(n + 1);
    let mut adjncy: Vec<i32> = Vec::with_capacity(off_diag);
    xadj.push(0);
    for j in 0..n {
        adjncy.extend(a.col(j).0.iter().filter(|&&i| i != j).map(|&i| i as i32));
        xadj.push(adjncy.len() as i32);
    }
    let mut nv = n as i32;
    let mut perm = vec![0i32; n];
    let mut iperm = vec![0i32; n];
    let mut options = [0i32; metis_sys::METIS_NOPTIONS as usize];
    // SAFETY: the arrays have the sizes METIS_NodeND expects (n + 1, xadj[n], n, n, NOPTIONS),
    // the graph is symmetric without self loops (a symmetric matrix's pattern), and METIS
    // neither keeps nor frees them.
    let status = unsafe {
        metis_sys::METIS_SetDefaultOptions(options.as_mut_ptr());
        metis_sys::METIS_NodeND(
            &mut nv,
            xadj.as_mut_ptr(),
            adjncy.as_mut_ptr(),
            std::ptr::null_mut(),
            options.as_mut_ptr(),
            perm.as_mut_ptr(),
            iperm.as_mut_ptr(),
        )
    };
    if status != metis_sys::rstatus_et_METIS_OK {
        return Err(Error::numerical(
            "nested-dissection ordering",
            format!("METIS_NodeND failed (status {status})"),
        ));
    }
    let fwd: Vec<usize> = perm.iter().map(|&p| p as usize).collect();
    let inv: Vec<usize> = iperm.iter().map(|&p| p as usize).collect();
    // METIS returns a permutation; check it before faer trusts it.
    if fwd.iter().any(|&p| p >= n) || fwd.iter().enumerate().any(|(i, &p)| inv[p] != i) {
        return Err(Error::numerical(
            "nested-dissection ordering",
            "METIS returned no permutation",
        ));
    }
    Ok((fwd, inv))
}
