#!/usr/bin/env python3
"""Newmark (average acceleration) on the substep comparison chain in OpenSees (openseespy):
1-D model, `zeroLength` springs with `-doRayleigh 1` (without it OpenSees leaves the
stiffness-proportional damping out of the springs: a different model), lumped masses, Rayleigh
damping, UniformExcitation with a 1 Hz sine (a Path series sampled at the step times),
`algorithm Linear -factorOnce`, `analysis Transient`. Each linear-system solver (BandSPD,
ProfileSPD, UmfPack, SparseSYM, BandGeneral) runs the check steps and the timed batches (see
common.py); the fastest is reported (one JSON line) with its roof response.
Needs `pip install openseespy` (and on Debian `apt-get install libblas3 liblapack3`)."""

import math
import time

import time as _time

from common import parse_args, report, skip

args = parse_args(__doc__)
try:
    import openseespy.opensees as ops
except Exception as e:  # pragma: no cover - import errors vary (missing BLAS, ...)
    skip(f"openseespy not available ({type(e).__name__}: {e}); pip install openseespy")

SYSTEMS = ["BandSPD", "ProfileSPD", "UmfPack", "SparseSYM", "BandGeneral"]


def build(system):
    ops.wipe()
    ops.model("basic", "-ndm", 1, "-ndf", 1)
    ops.uniaxialMaterial("Elastic", 1, args.stiffness)
    ops.node(0, 0.0)
    ops.fix(0, 1)
    for i in range(1, args.dofs + 1):
        ops.node(i, 0.0)
        ops.mass(i, args.mass)
        ops.element("zeroLength", i, i - 1, i, "-mat", 1, "-dir", 1, "-doRayleigh", 1)
    # a_g(t) = sin(2 pi t) sampled at the step times (what substep applies at t_{i+1}).
    total = args.check_steps + args.batches * args.batch_steps + 2
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
batches = {}
for system in SYSTEMS:
    try:
        build(system)
        history = []
        ok = True
        for _ in range(args.check_steps):
            ok = ok and ops.analyze(1, args.dt) == 0
            history.append(ops.nodeDisp(args.dofs, 1))
        per = []
        for _ in range(args.batches):
            c0 = _time.process_time()
            ok = ok and ops.analyze(args.batch_steps, args.dt) == 0
            per.append((_time.process_time() - c0) * 1e6 / max(args.batch_steps, 1))
        if ok:
            roof[system], batches[system] = history, per
            results[system] = sorted(per)[len(per) // 2] if per else 0.0
        else:
            results[system] = None
    except Exception as e:  # a solver missing from this build
        results[system] = f"{type(e).__name__}: {e}"
ops.wipe()
timed = {s: t for s, t in results.items() if isinstance(t, float)}
if not timed:
    skip(f"no OpenSees solver ran: {results}")
best = min(timed, key=timed.get)
report(
    tool="opensees",
    roof_u=roof[best],
    cpu_us_per_batch=batches[best],
    best=f"system {best}",
    per_system_us=results,
    version=getattr(ops, "version", lambda: "?")(),
)
