"""A (nonlinear) shear building under a ground-acceleration record in OpenSees (openseespy).

Usage: python shear_building.py SPEC.json OUT.csv

SPEC.json (SI units):
    masses      [kg], floor 1 first
    stiffness   [N/m], initial stiffness of each storey (storey 1 first)
    hysteresis  optional {"kind": "bilinear" | "elastic_plastic", "yield_force": [N, ...],
                "hardening": b}; bilinear: Steel01(Fy, E0 = k, b) (kinematic hardening, post-yield
                stiffness b k); elastic_plastic: ElasticPP(E = k, epsyP = Fy / k) (hardening must
                be absent or 0); absent: Elastic(k)
    rayleigh    optional {"alpha": a, "beta": b}: C = a M + b K_initial, i.e.
                rayleigh(a, 0.0, b, 0.0) (betaKinit) with -doRayleigh on the zeroLength elements
                (their default is no Rayleigh damping)
    dt          time step [s]; one analyze(1, dt) per step
    duration    optional [s]; default: the record's length
    record      two-column file t [s], a_g [m/s^2] (header lines, "#" comments, separators
                "," ";" space tab), sampled like substep does: linear interpolation at i dt,
                i = 0..floor(duration / dt + 1e-9), zero after the end of the record
    scale       factor on the record (Path -factor)
    integrator  "newmark" (average acceleration, Newton, NormDispIncr `tolerance`, default
                1e-12), "alpha_os" (AlphaOS `alpha`, Linear -initial) or "alpha_os_tp"
                (AlphaOS_TP `alpha`, Linear -initial), "kr_alpha" (KRAlphaExplicit `rho_inf`,
                Linear) or "kr_alpha_tp" (KRAlphaExplicit_TP `rho_inf`, Linear)
    rho_inf     the spectral radius at infinite frequency of the KR-alpha schemes
    alpha       OpenSees' alpha in [2/3, 1] (= 1 + Hilber's alpha) for the alpha-OS schemes
    tolerance   optional, NormDispIncr tolerance of "newmark" [m]

OUT.csv: header t,u1..un, then one row per step from t = 0: displacements relative to the
ground (UniformExcitation: M u'' + C u' + r(u) = -M iota a_g).
"""

import json
import math
import re
import sys

import openseespy.opensees as ops


def read_record(path):
    """(times, values) of a two-column text file; lines that do not parse are headers."""
    times, values = [], []
    with open(path) as f:
        for line in f:
            line = line.split("#", 1)[0].strip()
            if not line:
                continue
            parts = [p for p in re.split(r"[,;\s]+", line) if p]
            if len(parts) < 2:
                continue
            try:
                t, a = float(parts[0]), float(parts[1])
            except ValueError:
                continue  # header line
            times.append(t)
            values.append(a)
    if len(times) < 2:
        raise SystemExit(f"{path}: fewer than two samples")
    return times, values


def sample(times, values, dt, duration):
    """a_g(i dt) by linear interpolation, zero outside the record (substep's Record::value_at
    for a uniform record; also right for non-uniform times)."""
    if duration is None:
        duration = times[-1]
    n = int(math.floor(duration / dt + 1e-9)) + 1
    out, j = [], 0
    for i in range(n):
        t = i * dt
        if t < times[0] - 1e-9 * dt or t > times[-1] + 1e-9 * dt:
            out.append(0.0)
            continue
        t = min(max(t, times[0]), times[-1])
        while j + 2 < len(times) and times[j + 1] <= t:
            j += 1
        frac = (t - times[j]) / (times[j + 1] - times[j])
        frac = min(max(frac, 0.0), 1.0)
        out.append(values[j] + frac * (values[j + 1] - values[j]))
    return out


def build(spec, ag):
    masses, stiffness = spec["masses"], spec["stiffness"]
    n = len(masses)
    if len(stiffness) != n:
        raise SystemExit("masses and stiffness must have the same length")
    hyst = spec.get("hysteresis")

    ops.wipe()
    ops.model("basic", "-ndm", 1, "-ndf", 1)
    for i in range(n + 1):
        ops.node(i, 0.0)
    ops.fix(0, 1)
    for i, m in enumerate(masses, start=1):
        ops.mass(i, m)
    for s, k in enumerate(stiffness, start=1):
        if hyst is None:
            ops.uniaxialMaterial("Elastic", s, k)
        else:
            fy = hyst["yield_force"][s - 1]
            b = hyst.get("hardening", 0.0) or 0.0
            if hyst["kind"] == "bilinear":
                ops.uniaxialMaterial("Steel01", s, fy, k, b)
            elif hyst["kind"] == "elastic_plastic":
                if b != 0.0:
                    raise SystemExit("elastic_plastic takes no hardening")
                ops.uniaxialMaterial("ElasticPP", s, k, fy / k)
            else:
                raise SystemExit(f"unknown hysteresis kind {hyst['kind']!r}")
        ops.element("zeroLength", s, s - 1, s, "-mat", s, "-dir", 1, "-doRayleigh", 1)

    ray = spec.get("rayleigh")
    if ray:
        # alphaM, betaK (current), betaKinit, betaKcomm: C = alpha M + beta K_initial
        ops.rayleigh(ray.get("alpha", 0.0), 0.0, ray.get("beta", 0.0), 0.0)

    dt = spec["dt"]
    ops.timeSeries("Path", 1, "-dt", dt, "-values", *ag, "-factor", spec.get("scale", 1.0))
    ops.pattern("UniformExcitation", 1, 1, "-accel", 1)

    # Start at rest with the consistent acceleration a_0 = -iota a_g(0) (substep's start;
    # OpenSees would otherwise start with a_0 = 0).
    a0 = -spec.get("scale", 1.0) * ag[0]
    if a0 != 0.0:
        for i in range(1, n + 1):
            ops.setNodeAccel(i, 1, a0, "-commit")

    ops.constraints("Plain")
    ops.numberer("Plain")
    ops.system("FullGeneral")
    scheme = spec["integrator"]
    if scheme == "newmark":
        ops.test("NormDispIncr", spec.get("tolerance", 1e-12), 100)
        ops.algorithm("Newton")
        ops.integrator("Newmark", 0.5, 0.25)
    elif scheme in ("alpha_os", "alpha_os_tp"):
        # alpha-OS: one linear solve per step with the initial stiffness
        ops.algorithm("Linear", "-initial")
        name = "AlphaOS" if scheme == "alpha_os" else "AlphaOS_TP"
        ops.integrator(name, spec["alpha"])
    elif scheme in ("kr_alpha", "kr_alpha_tp"):
        # KR-alpha (KRAlphaExplicit: forces at u_{n+alpha_f}) or its two-point form
        # (KRAlphaExplicit_TP; with rho_inf = 1 the Chen-Ricles algorithm): one linear solve
        # with the effective mass per step (FullGeneral: the effective mass is dense)
        ops.algorithm("Linear")
        name = "KRAlphaExplicit" if scheme == "kr_alpha" else "KRAlphaExplicit_TP"
        ops.integrator(name, spec["rho_inf"])
    else:
        raise SystemExit(f"unknown integrator {scheme!r}")
    ops.analysis("Transient")
    return n


def main():
    if len(sys.argv) != 3:
        raise SystemExit(__doc__)
    with open(sys.argv[1]) as f:
        spec = json.load(f)
    times, values = read_record(spec["record"])
    dt = spec["dt"]
    ag = sample(times, values, dt, spec.get("duration"))
    n = build(spec, ag)
    rows = [[0.0] + [ops.nodeDisp(i, 1) for i in range(1, n + 1)]]
    for step in range(1, len(ag)):
        if ops.analyze(1, dt) != 0:
            raise SystemExit(f"OpenSees failed at step {step} (t = {step * dt})")
        rows.append([step * dt] + [ops.nodeDisp(i, 1) for i in range(1, n + 1)])
    ops.wipe()
    with open(sys.argv[2], "w") as f:
        f.write("t," + ",".join(f"u{i}" for i in range(1, n + 1)) + "\n")
        for r in rows:
            f.write(",".join(repr(x) for x in r) + "\n")


if __name__ == "__main__":
    main()
