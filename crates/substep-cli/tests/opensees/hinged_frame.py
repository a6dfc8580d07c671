#!/usr/bin/env python3
"""A plane moment frame with rotational hinges in OpenSees (openseespy), built as substep's
`[structure.frame]` + `[structure.frame.hinges]` builds it (crates/substep/src/model/frame.rs):

* nodes on a `bays × stories` grid, fixed base, 3 DOFs (ux, uy, θ) per node;
* members: `elasticBeamColumn` (Euler–Bernoulli, `Linear` transformation), columns then beams
  of each storey; a hinged member end connects to its own node at the same place, tied to the
  grid node in ux, uy (`equalDOF`, `Transformation` constraints; at the fixed base the hinge node
  is fixed in ux, uy) through a `zeroLength` rotational spring (`-dir 3`, `-doRayleigh 1`) with
  `Steel01(My, k_h, b)` (or `ElasticPP`, `Elastic`), `k_h = factor · 6 E I / L`;
* lumped masses: floor mass per bay half to each end node (ux, uy); each member `ρ A L` half to
  each end (ux, uy) and `ρ A L · L²/78` of rotational inertia per end — half to the hinge and half
  to the grid node where the end is hinged (all of it to the hinge at the fixed base);
* Rayleigh `rayleigh α 0 β 0` (initial stiffness), `UniformExcitation` in x with a `Path` series,
  Newmark (½, ¼) with Newton (`NormDispIncr`), one `analyze(1, dt)` per step; with
  `"integrator": "kr_alpha"` / `"kr_alpha_tp"` and `"rho_inf"` instead `KRAlphaExplicit` /
  `KRAlphaExplicit_TP` with the `Linear` algorithm on a `FullGeneral` system.

argv[1]: a JSON spec; argv[2]: the output CSV, one row per step: `t` and every grid node's ux,
uy, θ in substep's DOF order (floor by floor, column lines in order).

Timing mode (benches/nonlinear_frame.sh): with `"timing": {"warmup": W, "steps": S}` in the spec
the excitation is a_g = sin(2πt) (substep bench's) instead of `record`, and one JSON line is
printed instead of the CSV: {"tool": "opensees", "us_per_step_median", "us_per_step_p99",
"iterations_per_step", "dofs"}. A spec can give the yield moments as yield rotations
(`"yield_rotation"`: M_y = k_h · θ_y)."""

import json
import math
import statistics
import sys
import time

spec = json.load(open(sys.argv[1]))
out_path = sys.argv[2]
try:
    import openseespy.opensees as ops
except Exception as e:  # pragma: no cover
    print(f"SKIPPED: openseespy is not installed ({e})")
    sys.exit(3)

bays, stories = spec["bays"], spec["stories"]
w, h, E = spec["bay_width"], spec["story_height"], spec["elastic_modulus"]
col, beam = spec["column"], spec["beam"]
rho, floor_mass = spec["density"], spec["floor_mass_per_bay"]
hinges = spec.get("hinges")
dt, scale = spec["dt"], spec["scale"]

ops.wipe()
ops.model("basic", "-ndm", 2, "-ndf", 3)


def tag(s, c):
    return 1 + s * (bays + 1) + c


for s in range(stories + 1):
    for c in range(bays + 1):
        ops.node(tag(s, c), c * w, s * h)
        if s == 0:
            ops.fix(tag(s, c), 1, 1, 1)
ops.geomTransf("Linear", 1)
# P-Δ of the columns (substep's [structure.frame] p_delta): OpenSees' PDelta transformation
ops.geomTransf("PDelta" if spec.get("p_delta") else "Linear", 2)
mass = {}


def add_mass(node, mx=0.0, my=0.0, mr=0.0):
    m = mass.setdefault(node, [0.0, 0.0, 0.0])
    m[0] += mx
    m[1] += my
    m[2] += mr


next_node, next_elem, next_mat = 100000, 1, 1
laws = {}


def law(is_beam, k):
    """The material tag of a hinge law with initial stiffness k."""
    global next_mat
    key = (is_beam, k)
    if key in laws:
        return laws[key]
    kind = hinges["kind"]
    if "yield_rotation" in hinges:
        my = k * hinges["yield_rotation"]
    else:
        my = hinges["beam_yield_moment"] if is_beam else hinges["column_yield_moment"]
    if kind == "bilinear":
        ops.uniaxialMaterial("Steel01", next_mat, my, k, hinges["hardening"])
    elif kind == "elastic_plastic":
        ops.uniaxialMaterial("ElasticPP", next_mat, k, my / k)
    else:
        ops.uniaxialMaterial("Elastic", next_mat, k)
    laws[key] = next_mat
    next_mat += 1
    return laws[key]


def hinged(is_beam):
    if not hinges:
        return False
    return hinges["at"] == "both" or (hinges["at"] == "beams") == is_beam


def member(a, b, sec, is_beam):
    global next_node, next_elem
    length = w if is_beam else h
    ends = [tag(*a), tag(*b)]
    me = rho * sec["area"] * length
    inertia = me * length * length / 78.0
    hinge_ends = list(ends)
    if hinged(is_beam):
        k = hinges["stiffness_factor"] * 6.0 * E * sec["inertia"] / length
        for i, (s, c) in enumerate([a, b]):
            node = ends[i]
            hn = next_node
            next_node += 1
            ops.node(hn, c * w, s * h)
            if s == 0:
                ops.fix(hn, 1, 1, 0)
            else:
                ops.equalDOF(node, hn, 1, 2)
            ops.element("zeroLength", next_elem, node, hn, "-mat", law(is_beam, k), "-dir", 3, "-doRayleigh", 1)
            next_elem += 1
            hinge_ends[i] = hn
            add_mass(node, me / 2, me / 2)
            if s == 0:
                add_mass(hn, 0.0, 0.0, inertia)
            else:
                add_mass(hn, 0.0, 0.0, inertia / 2)
                add_mass(node, 0.0, 0.0, inertia / 2)
    else:
        for i, (s, c) in enumerate([a, b]):
            add_mass(ends[i], me / 2, me / 2, inertia)
    transf = 1 if is_beam else 2
    ops.element("elasticBeamColumn", next_elem, hinge_ends[0], hinge_ends[1], sec["area"], E, sec["inertia"], transf)
    next_elem += 1


for s in range(1, stories + 1):
    for c in range(bays + 1):
        member((s - 1, c), (s, c), col, False)
    for bb in range(bays):
        member((s, bb), (s, bb + 1), beam, True)
for s in range(1, stories + 1):
    for bb in range(bays):
        for c in (bb, bb + 1):
            add_mass(tag(s, c), floor_mass / 2, floor_mass / 2)
for node, m in mass.items():
    if node > tag(0, bays):  # the fixed base carries no mass (substep has no DOF there)
        ops.mass(node, *m)

if spec.get("gravity"):
    # gravity on the lumped masses, a static analysis (Newton), then held (loadConst)
    ops.timeSeries("Linear", 2)
    ops.pattern("Plain", 2, 2)
    for node, m in mass.items():
        if node > tag(0, bays) and node < 100000:
            ops.load(node, 0.0, -9.80665 * m[1], 0.0)
    ops.constraints("Transformation")
    ops.numberer("RCM")
    ops.system("UmfPack")
    ops.test("NormDispIncr", 1e-13, 50)
    ops.algorithm("Newton")
    ops.integrator("LoadControl", 1.0)
    ops.analysis("Static")
    if ops.analyze(1) != 0:
        print("OpenSees: no static state under gravity", file=sys.stderr)
        sys.exit(1)
    ops.loadConst("-time", 0.0)
    ops.wipeAnalysis()

timing = spec.get("timing")
if timing:
    total = timing["warmup"] + timing["steps"] + 2
    values = [math.sin(2 * math.pi * i * dt) for i in range(total)]
else:
    record = [line.split(",") for line in open(spec["record"]).read().split("\n")[1:] if line.strip()]
    values = [float(r[1]) for r in record]
ops.timeSeries("Path", 1, "-dt", dt, "-values", *values, "-factor", scale)
ops.pattern("UniformExcitation", 1, 1, "-accel", 1)
ops.rayleigh(spec["rayleigh"]["alpha"], 0.0, spec["rayleigh"]["beta"], 0.0)
ops.constraints("Transformation")
ops.numberer("RCM")
scheme = spec.get("integrator", "newmark")
if scheme == "newmark":
    ops.system("UmfPack")
    ops.test("NormDispIncr", 1e-13, 50)
    ops.algorithm("Newton")
    ops.integrator("Newmark", 0.5, 0.25)
elif scheme in ("kr_alpha", "kr_alpha_tp"):
    # KRAlphaExplicit(_TP) adds its dense effective mass to the system: FullGeneral, or a sparse
    # system would drop the entries outside the stiffness pattern
    ops.system("FullGeneral")
    ops.algorithm("Linear")
    ops.integrator("KRAlphaExplicit" if scheme == "kr_alpha" else "KRAlphaExplicit_TP", spec["rho_inf"])
else:
    raise SystemExit(f"unknown integrator {scheme!r}")
ops.analysis("Transient")

if timing:
    times, iterations = [], []
    for i in range(timing["warmup"] + timing["steps"]):
        c0 = time.process_time()
        if ops.analyze(1, dt) != 0:
            print(json.dumps({"skipped": f"OpenSees did not converge at step {i + 1}"}))
            sys.exit(0)
        c1 = time.process_time()
        if i >= timing["warmup"]:
            times.append((c1 - c0) * 1e6)
            iterations.append(ops.testIter())
    times.sort()
    print(json.dumps({
        "tool": "opensees",
        "dofs": 3 * stories * (bays + 1) + (next_node - 100000),
        "us_per_step_median": statistics.median(times),
        "us_per_step_p99": times[min(len(times) - 1, int(0.99 * len(times)))],
        "iterations_per_step": sum(iterations) / len(iterations),
    }))
    sys.exit(0)

grid = [tag(s, c) for s in range(1, stories + 1) for c in range(bays + 1)]
steps = len(values) - 1
with open(out_path, "w") as f:
    f.write("t," + ",".join(f"u{i + 1}" for i in range(3 * len(grid))) + "\n")
    row0 = []
    for n in grid:
        row0.extend(ops.nodeDisp(n)[:3])
    f.write("0.0," + ",".join(repr(x) for x in row0) + "\n")
    for i in range(steps):
        if ops.analyze(1, dt) != 0:
            print(f"OpenSees did not converge at step {i + 1}", file=sys.stderr)
            sys.exit(1)
        row = []
        for n in grid:
            row.extend(ops.nodeDisp(n)[:3])
        f.write(f"{(i + 1) * dt!r}," + ",".join(repr(x) for x in row) + "\n")
