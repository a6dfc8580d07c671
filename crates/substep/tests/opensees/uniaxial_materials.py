#!/usr/bin/env python3
"""OpenSees uniaxial materials through given strain histories, for crates/substep/tests/materials.rs.

stdin: JSON {"runs": [{"material": ["Steel01", Fy, E0, b], "strains": [...]}, ...]}: each run
defines `uniaxialMaterial(material[0], 1, *material[1:])` in a wiped model and applies the
strains one by one with `testUniaxialMaterial` / `setStrain` (trial and commit), starting from
the virgin state. stdout: one line `RESULT <json>` with, per run, {"stress": [...],
"tangent": [...]} after each strain (OpenSees may print other lines).

`--check` only imports openseespy (exit status 0 when it works).
"""

import ctypes
import importlib.util
import json
import os
import sys


def import_opensees():
    try:
        import openseespy.opensees as ops

        return ops
    except Exception:
        pass
    # The Linux wheel (openseespylinux) ships libblas.so.3 next to its liblapack.so.3, but only
    # the extension's own RUNPATH points there, so on a system without a BLAS the loader does not
    # find it for liblapack: load it first, then import again.
    spec = importlib.util.find_spec("openseespylinux")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError("openseespy is not installed")
    blas = os.path.join(list(spec.submodule_search_locations)[0], "lib", "libblas.so.3")
    if not os.path.exists(blas):
        raise ImportError("openseespy does not import")
    ctypes.CDLL(blas, mode=ctypes.RTLD_GLOBAL)
    for name in [m for m in sys.modules if m.startswith("openseespy")]:
        del sys.modules[name]
    import openseespy.opensees as ops

    return ops


def main():
    ops = import_opensees()
    if "--check" in sys.argv[1:]:
        return
    runs = json.load(sys.stdin)["runs"]
    out = []
    for run in runs:
        ops.wipe()
        material = run["material"]
        ops.uniaxialMaterial(material[0], 1, *material[1:])
        ops.testUniaxialMaterial(1)
        stress, tangent = [], []
        for e in run["strains"]:
            ops.setStrain(e)
            stress.append(ops.getStress())
            tangent.append(ops.getTangent())
        out.append({"stress": stress, "tangent": tangent})
    ops.wipe()
    print("RESULT " + json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
