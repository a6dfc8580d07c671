#!/usr/bin/env python3
"""The yielding chain of `substep bench --model chain --yielding` in OpenSees (openseespy):
`--dofs` floors of 100 t on `zeroLength` springs with `Steel01` (yield at 2e-6 m of drift,
2 % hardening, `-doRayleigh 1`), Rayleigh 5 % at modes 1 and 2 on the initial stiffness
(`rayleigh α 0 β 0`), first period 0.1·dofs s (the closed forms substep uses), under
a_g = sin(2πt); Newmark average acceleration with Newton–Raphson (`NormDispIncr`, relative to
the displacement scale as substep's tolerance 1e-10), `BandSPD` (the chain is tridiagonal).
Runs `--warmup` steps, then times `--steps` steps one by one (CPU time of the process) and
prints one JSON line: {"tool": "opensees", "us_per_step_median", "us_per_step_p99",
"iterations_per_step", "roof_u"}, or {"skipped": reason}.
Needs `pip install openseespy` (and on Debian `apt-get install libblas3 liblapack3`)."""

import argparse
import json
import math
import statistics
import sys
import time

p = argparse.ArgumentParser(description=__doc__)
p.add_argument("--dofs", type=int, default=10000)
p.add_argument("--steps", type=int, default=200)
p.add_argument("--warmup", type=int, default=20)
p.add_argument("--dt", type=float, default=0.01)
args = p.parse_args()
try:
    import openseespy.opensees as ops
except Exception as e:  # pragma: no cover - import errors vary (missing BLAS, ...)
    print(json.dumps({"skipped": f"openseespy not available ({type(e).__name__}: {e})"}))
    sys.exit(0)

n, m, zeta, dt = args.dofs, 1.0e5, 0.05, args.dt
first_period = max(0.1 * n, 0.1)
w1 = 2 * math.pi / first_period
k = m * (w1 / (2 * math.sin(math.pi / (2 * (2 * n + 1))))) ** 2
omega = lambda j: 2 * math.sqrt(k / m) * math.sin((2 * j - 1) * math.pi / (2 * (2 * n + 1)))
o1, o2 = omega(1), omega(2)
alpha, beta = 2 * zeta * o1 * o2 / (o1 + o2), 2 * zeta / (o1 + o2)
yield_drift = 2.0e-6

ops.wipe()
ops.model("basic", "-ndm", 1, "-ndf", 1)
ops.uniaxialMaterial("Steel01", 1, k * yield_drift, k, 0.02)
ops.node(0, 0.0)
ops.fix(0, 1)
for i in range(1, n + 1):
    ops.node(i, 0.0)
    ops.mass(i, m)
    ops.element("zeroLength", i, i - 1, i, "-mat", 1, "-dir", 1, "-doRayleigh", 1)
total = args.warmup + args.steps + 2
ops.timeSeries("Path", 1, "-dt", dt, "-values", *[math.sin(2 * math.pi * i * dt) for i in range(total)])
ops.pattern("UniformExcitation", 1, 1, "-accel", 1)
ops.rayleigh(alpha, 0.0, beta, 0.0)
ops.constraints("Plain")
ops.numberer("Plain")
ops.system("BandSPD")
# substep converges when |du|_inf <= 1e-10 max|u|; the roof moves ~1e-3 m here
ops.test("NormDispIncr", 1e-13, 50)
ops.algorithm("Newton")
ops.integrator("Newmark", 0.5, 0.25)
ops.analysis("Transient")

times, iterations = [], []
for i in range(args.warmup + args.steps):
    c0 = time.process_time()
    if ops.analyze(1, dt) != 0:
        print(json.dumps({"skipped": f"OpenSees did not converge at step {i + 1}"}))
        sys.exit(0)
    c1 = time.process_time()
    if i >= args.warmup:
        times.append((c1 - c0) * 1e6)
        iterations.append(ops.testIter())
times.sort()
print(json.dumps({
    "tool": "opensees",
    "dofs": n,
    "us_per_step_median": statistics.median(times),
    "us_per_step_p99": times[min(len(times) - 1, int(0.99 * len(times)))],
    "iterations_per_step": sum(iterations) / len(iterations),
    "roof_u": ops.nodeDisp(n, 1),
}))
