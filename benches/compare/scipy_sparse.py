#!/usr/bin/env python3
"""Newmark (average acceleration) with SciPy on the matrices substep exported (--mtx DIR): the
effective stiffness K + a0 M + a1 C is factorised once, by `scipy.sparse.linalg.splu` (SuperLU)
with COLAMD (`--solver splu_colamd`, SciPy's default) or with minimum degree on A^T + A in
symmetric mode (`--solver splu_mmd`: permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0,
SymmetricMode), or by CHOLMOD (`--solver cholmod`, scikit-sparse, where installed). Each step
forms the effective load with two sparse products (CSR) and solves. See common.py."""

import os
import time

from common import ag, parse_args, report, skip

args = parse_args(__doc__)
try:
    import numpy as np
    import scipy
    import scipy.io
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla
except ImportError as e:  # pragma: no cover
    skip(f"numpy/scipy not available ({e}); pip install numpy scipy")
solver = args.solver or "splu_colamd"
if solver == "cholmod":
    try:
        from sksparse.cholmod import cholesky
    except Exception as e:  # pragma: no cover - needs libsuitesparse-dev + scikit-sparse
        skip(f"CHOLMOD not available ({type(e).__name__}: {e}); pip install scikit-sparse")
elif solver not in ("splu_colamd", "splu_mmd"):
    skip(f"unknown solver {solver}")
if args.mtx is None or args.roof is None:
    skip("needs --mtx DIR and --roof")


def load(name):
    return scipy.io.mmread(os.path.join(args.mtx, name))


t0 = time.process_time()
M = sp.csr_matrix(load("M.mtx"))
C = sp.csr_matrix(load("C.mtx"))
K = sp.csr_matrix(load("K.mtx"))
iota = np.asarray(load("influence.mtx")).ravel()
n, dt = K.shape[0], args.dt
b_, g_ = 0.25, 0.5
a0, a1, a2 = 1 / (b_ * dt * dt), g_ / (b_ * dt), 1 / (b_ * dt)
a3, a4, a5 = 1 / (2 * b_) - 1, g_ / b_ - 1, dt * (g_ / b_ - 2) / 2
a6, a7 = (1 - g_) * dt, g_ * dt
Khat = sp.csc_matrix(K + a0 * M + a1 * C)
if solver == "splu_colamd":
    lu = spla.splu(Khat, permc_spec="COLAMD")
    solve = lu.solve
    factor_nnz = lu.L.nnz + lu.U.nnz
elif solver == "splu_mmd":
    lu = spla.splu(Khat, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options=dict(SymmetricMode=True))
    solve = lu.solve
    factor_nnz = lu.L.nnz + lu.U.nnz
else:
    f = cholesky(Khat)
    solve = f
    factor_nnz = f.L().nnz
setup_s = time.process_time() - t0
mi = M @ iota
u, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
step_no = 0


def step():
    global u, v, a, step_no
    step_no += 1
    rhs = M @ (a0 * u + a2 * v + a3 * a) + C @ (a1 * u + a4 * v + a5 * a) - mi * ag(step_no, dt)
    un = solve(rhs)
    an = a0 * (un - u) - a2 * v - a3 * a
    v = v + a6 * a + a7 * an
    u, a = un, an


roof_u = []
for _ in range(args.check_steps):
    step()
    roof_u.append(float(u[args.roof]))
batches = []
for _ in range(args.batches):
    c0 = time.process_time()
    for _ in range(args.batch_steps):
        step()
    batches.append((time.process_time() - c0) * 1e6 / max(args.batch_steps, 1))
if not np.all(np.isfinite(u)):
    skip("the SciPy loop diverged")
report(
    tool=f"scipy_{solver}",
    roof_u=roof_u,
    cpu_us_per_batch=batches,
    setup_s=setup_s,
    factor_nnz=int(factor_nnz),
    numpy=np.__version__,
    scipy=scipy.__version__,
)
