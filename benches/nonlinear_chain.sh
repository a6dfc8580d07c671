#!/usr/bin/env bash
# A yielding shear chain of ~10^4 DOFs (bilinear storey springs at every storey, docs/theory.md
# §14), one run each, side by side (docs/performance.md, "Nonlinear numerical substructures"):
#   * substep, full substructure step (k_sub = 10, spring specimen at the roof, ideal actuator)
#     with the operator splitting: median and p99 per step;
#   * the same linear chain (no springs), full step;
#   * substep, monolithic Newmark + Newton on the yielding chain;
#   * OpenSees (openseespy), Newmark + Newton on the same yielding chain (Steel01 springs).
# Usage: benches/nonlinear_chain.sh [DOFS] [STEPS]    (needs a release build and, for OpenSees,
# a Python with openseespy: $SUBSTEP_PYTHON or python3)
set -euo pipefail
cd "$(dirname "$0")/.."
dofs=${1:-10000}
steps=${2:-500}
bin=target/release/substep
py=${SUBSTEP_PYTHON:-python3}
lin=$($bin bench --model chain --dofs "$dofs" --steps "$steps" --json)
nl=$($bin bench --model chain --dofs "$dofs" --steps "$steps" --yielding --json)
os=$($py benches/compare/opensees_yielding_chain.py --dofs "$dofs" --steps 200)
"$py" - "$lin" "$nl" "$os" <<'PY'
import json, sys
lin, nl, os_ = (json.loads(a) for a in sys.argv[1:4])
print(f"yielding chain, {nl['dofs']} DOFs ({nl['springs_yielded']} storeys past yield at the end), dt = {nl['dt']} s, k_sub = {nl['substeps']}")
print(f"| run | median µs/step | p99 µs/step |")
print(f"|---|---|---|")
print(f"| substep full step, yielding (operator splitting) | {nl['us_per_step_median']:.1f} | {nl['us_per_step_p99']:.1f} |")
print(f"| substep full step, linear chain | {lin['us_per_step_median']:.1f} | {lin['us_per_step_p99']:.1f} |")
print(f"| substep monolithic Newmark + Newton ({nl['newton_iterations_per_step']:.2f} it/step) | {nl['us_per_step_monolithic_median']:.1f} | – |")
if "skipped" in os_:
    print(f"| OpenSees Newmark + Newton | skipped: {os_['skipped']} | |")
else:
    print(f"| OpenSees Newmark + Newton, Steel01, BandSPD ({os_['iterations_per_step']:.2f} it/step) | {os_['us_per_step_median']:.1f} | {os_['us_per_step_p99']:.1f} |")
    print(f"OpenSees Newton / substep full step (yielding): {os_['us_per_step_median'] / nl['us_per_step_median']:.1f}x (median)")
    print(f"OpenSees Newton / substep Newton: {os_['us_per_step_median'] / nl['us_per_step_monolithic_median']:.1f}x (median)")
print(f"yielding / linear full step: {nl['us_per_step_median'] / lin['us_per_step_median']:.2f}x (median)")
PY
