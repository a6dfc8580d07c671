#!/usr/bin/env python3
"""Newmark (average acceleration) on the substep comparison chain in OpenSees (openseespy):
1-D model, `zeroLength` springs, lumped masses, Rayleigh damping, UniformExcitation with a
1 Hz sine (a Path series sampled at the step times), `algorithm Linear -factorOnce`, `analysis Transient`. Each linear-system solver
(BandSPD, ProfileSPD, UmfPack, SparseSYM, BandGeneral) is timed on `steps` steps after 20
warm-up steps (which include the one factorisation); the fastest is reported (one JSON line).
Needs `pip install openseespy` (and on Debian `apt-get install libblas3 liblapack3`)."""

import math
import time

from common import parse_args, report, skip

args = parse_args(__doc__)
try:
    import openseespy.opensees as ops
except Exception as e:  # pragma: no cover - import errors vary (missing BLAS, ...)
    skip(f"openseespy not available ({type(e).__name__}: {e}); pip install openseespy")

SYSTEMS = ["BandSPD", "ProfileSPD", "UmfPack", "SparseSYM", "BandGeneral"]
WARMUP = 20


def build(system):
    ops.wipe()
    ops.model("basic", "-ndm", 1, "-ndf", 1)
    ops.uniaxialMaterial("Elastic", 1, args.stiffness)
    ops.node(0, 0.0)
    ops.fix(0, 1)
    for i in range(1, args.dofs + 1):
        ops.node(i, 0.0)
        ops.mass(i, args.mass)
        ops.element("zeroLength", i, i - 1, i, "-mat", 1, "-dir", 1)
    # a_g(t) = sin(2 pi t) sampled at the step times (what substep applies at t_{i+1}).
    total = WARMUP + args.steps + 2
    values = [math.sin(2 * math.pi * i * args.dt) for i in range(total)]
    ops.timeSeries("Path", 1, "-dt", args.dt, "-values", *values)
    ops.pattern("UniformExcitation", 1, 1, "-accel", 1)
    ops.rayleigh(args.alpha, args.beta, 0.0, 0.0)
    ops.constraints("Plain")
    ops.numberer("RCM")
    if system == "SparseSYM":
        ops.system("SparseSYM")
    else:
        ops.system(system)
    ops.algorithm("Linear", "-factorOnce")
    ops.integrator("Newmark", 0.5, 0.25)
    ops.analysis("Transient")


results = {}
roof = {}
for system in SYSTEMS:
    try:
        build(system)
        if ops.analyze(WARMUP, args.dt) != 0:
            results[system] = None
            continue
        t0 = time.perf_counter()
        ok = ops.analyze(args.steps, args.dt)
        us = (time.perf_counter() - t0) * 1e6 / args.steps
        results[system] = us if ok == 0 else None
        roof[system] = ops.nodeDisp(args.dofs, 1)
    except Exception as e:  # a solver missing from this build
        results[system] = None
        roof[system] = f"{type(e).__name__}: {e}"
ops.wipe()
timed = {s: t for s, t in results.items() if t is not None}
if not timed:
    skip(f"no OpenSees solver ran: {roof}")
best = min(timed, key=timed.get)
report(
    tool="opensees",
    us_per_step=timed[best],
    best=f"system {best}",
    per_system_us=results,
    roof_u=roof,
    version=getattr(ops, "version", lambda: "?")(),
)
