#!/usr/bin/env python3
"""Newmark (average acceleration) on the substep comparison chain with NumPy/SciPy: the
effective stiffness is factorised once (`scipy.linalg.cholesky_banded`), each step forms the
effective load with vector operations on the band and solves with `cho_solve_banded`.
Check steps and timed batches as in common.py (one JSON line)."""

import time

from common import ag, parse_args, report, skip

args = parse_args(__doc__)
try:
    import numpy as np
    from scipy.linalg import cho_solve_banded, cholesky_banded
except ImportError as e:  # pragma: no cover
    skip(f"numpy/scipy not available ({e}); pip install numpy scipy")

n, dt, m, k = args.dofs, args.dt, args.mass, args.stiffness
alpha, beta = args.alpha, args.beta
b_, g_ = 0.25, 0.5
a0, a1, a2 = 1 / (b_ * dt * dt), g_ / (b_ * dt), 1 / (b_ * dt)
a3, a4, a5 = 1 / (2 * b_) - 1, g_ / b_ - 1, dt * (g_ / b_ - 2) / 2
a6, a7 = (1 - g_) * dt, g_ * dt

kd = np.full(n, 2 * k)
kd[-1] = k
ko = np.full(n - 1, -k)  # K[i, i+1]
mv = np.full(n, m)
# K_hat = K + a0 M + a1 C, C = alpha M + beta K  -> upper banded form (u = 1)
c_k = 1 + a1 * beta
ab = np.zeros((2, n))
ab[0, 1:] = c_k * ko
ab[1, :] = c_k * kd + (a0 + a1 * alpha) * mv
cb = cholesky_banded(ab, lower=False, check_finite=False)


def kmul(x, out):
    np.multiply(kd, x, out=out)
    out[:-1] += ko * x[1:]
    out[1:] += ko * x[:-1]
    return out


u, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
a[:] = -1.0 * np.sin(0.0)  # consistent a0 = M^-1 f(0) = -a_g(0) for a lumped shear chain
wm, wc, kw, rhs = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n)


def step(i):
    global u, v, a, wm, wc, kw, rhs
    g = ag(i + 1, dt)
    # F_hat = M (a0 u + a2 v + a3 a) + C (a1 u + a4 v + a5 a), C = alpha M + beta K
    np.multiply(a1, u, out=wc)
    wc += a4 * v
    wc += a5 * a
    np.multiply(a0, u, out=wm)
    wm += a2 * v
    wm += a3 * a
    wm += alpha * wc
    np.multiply(mv, wm, out=rhs)
    rhs += beta * kmul(wc, kw)
    rhs -= mv * g
    un = cho_solve_banded((cb, False), rhs, check_finite=False)
    an = a0 * (un - u) - a2 * v - a3 * a
    vn = v + a6 * a + a7 * an
    u, v, a = un, vn, an


roof = args.roof if args.roof is not None else n - 1
roof_u = []
i = 0
for _ in range(args.check_steps):
    step(i)
    i += 1
    roof_u.append(float(u[roof]))
batches = []
for _ in range(args.batches):
    c0 = time.process_time()
    for _ in range(args.batch_steps):
        step(i)
        i += 1
    batches.append((time.process_time() - c0) * 1e6 / max(args.batch_steps, 1))
if not np.all(np.isfinite(u)):
    skip("the SciPy loop diverged")
report(
    tool="scipy_banded",
    roof_u=roof_u,
    cpu_us_per_batch=batches,
    best="cho_solve_banded",
    numpy=np.__version__,
    scipy=__import__("scipy").__version__,
)
