#!/usr/bin/env bash
# A plane steel moment frame of ~10^4 DOFs with rotational hinges at every member end (bilinear,
# docs/theory.md §14; `substep bench --model frame --yielding`), one run each, side by side
# (docs/performance.md, "Nonlinear numerical substructures"):
#   * substep, full substructure step (k_sub = 10, spring specimen at the roof, ideal actuator)
#     with the operator splitting: median and p99 per step;
#   * substep, the linear frame of the same number of DOFs, full step;
#   * substep, monolithic Newmark + Newton on the hinged frame;
#   * OpenSees (openseespy), Newmark + Newton on the same hinged frame
#     (crates/substep-cli/tests/opensees/hinged_frame.py, timing mode).
# Usage: benches/nonlinear_frame.sh [DOFS] [STEPS]   (needs a release build and, for OpenSees,
# a Python with openseespy: $SUBSTEP_PYTHON or python3)
set -euo pipefail
cd "$(dirname "$0")/.."
dofs=${1:-10000}
steps=${2:-500}
bin=target/release/substep
py=${SUBSTEP_PYTHON:-python3}
nl=$($bin bench --model frame --dofs "$dofs" --steps "$steps" --yielding --json)
n=$("$py" -c "import json,sys; print(json.loads(sys.argv[1])['dofs'])" "$nl")
lin=$($bin bench --model frame --dofs "$n" --steps "$steps" --json)
spec=$(mktemp)
"$py" - "$nl" > "$spec" <<'PY'
import json, sys
r = json.loads(sys.argv[1])
print(json.dumps({
    "bays": r["bays"], "stories": r["stories"], "bay_width": 6.0, "story_height": 3.5,
    "elastic_modulus": 210e9,
    "column": {"area": 149.1e-4, "inertia": 25_170e-8},
    "beam": {"area": 84.46e-4, "inertia": 23_130e-8},
    "density": 7850.0, "floor_mass_per_bay": 20_000.0,
    "hinges": {"at": "both", "kind": "bilinear", "yield_rotation": 2.0e-6, "hardening": 0.02,
               "stiffness_factor": 10.0},
    "rayleigh": {"alpha": r["rayleigh"][0], "beta": r["rayleigh"][1]},
    "dt": r["dt"], "scale": 1.0, "timing": {"warmup": 5, "steps": 30},
}))
PY
os=$("$py" crates/substep-cli/tests/opensees/hinged_frame.py "$spec" /dev/null 2>/dev/null | tail -1)
rm -f "$spec"
"$py" - "$lin" "$nl" "$os" <<'PY'
import json, sys
lin, nl, os_ = (json.loads(a) for a in sys.argv[1:4])
print(f"hinged frame {nl['layout']}: {nl['dofs']} DOFs, dt = {nl['dt']} s, k_sub = {nl['substeps']}; {nl['springs_yielded']} hinges past yield at the end")
print("| run | median µs/step | p99 µs/step |")
print("|---|---|---|")
print(f"| substep full step, hinged frame (operator splitting) | {nl['us_per_step_median']:.1f} | {nl['us_per_step_p99']:.1f} |")
print(f"| substep full step, linear frame {lin['layout']} ({lin['dofs']} DOFs) | {lin['us_per_step_median']:.1f} | {lin['us_per_step_p99']:.1f} |")
print(f"| substep monolithic Newmark + Newton ({nl['newton_iterations_per_step']:.2f} it/step) | {nl['us_per_step_monolithic_median']:.1f} | – |")
if "skipped" in os_:
    print(f"| OpenSees Newmark + Newton | skipped: {os_['skipped']} | |")
else:
    print(f"| OpenSees Newmark + Newton, UmfPack, {os_['dofs']} DOFs ({os_['iterations_per_step']:.2f} it/step) | {os_['us_per_step_median']:.1f} | {os_['us_per_step_p99']:.1f} |")
    print(f"OpenSees Newton / substep full step (hinged): {os_['us_per_step_median'] / nl['us_per_step_median']:.1f}x (median)")
    print(f"OpenSees Newton / substep Newton: {os_['us_per_step_median'] / nl['us_per_step_monolithic_median']:.2f}x (median)")
print(f"hinged / linear full step: {nl['us_per_step_median'] / lin['us_per_step_median']:.2f}x (median)")
PY
