#!/usr/bin/env bash
# The multi-axial RTHS benchmark's CPU time (docs/performance.md, "maRTHS"), one invocation:
#   * one 41 s run (El Centro × 0.4, RoDeAC, sensor noise): the process's user + system CPU time,
#     the median of 10 runs (the reference structure, the loop and J1–J10 included);
#   * --trials 20 (21 runs): wall and CPU time, and CPU/wall = the cores used;
#   * side by side, the same noise-free run in the independent NumPy implementation of the
#     toolset's loop (crates/substep/tests/marths/reference.py; the toolset itself needs
#     MATLAB/Simulink, which this machine does not have).
# Usage: benches/marths.sh   (needs a release build; Python with numpy and scipy:
# $SUBSTEP_PYTHON or python3)
set -euo pipefail
cd "$(dirname "$0")/.."
bin=target/release/substep
py=${SUBSTEP_PYTHON:-python3}
cpu() { # user+sys seconds and wall seconds of one command
  local t0 t1; t0=$(date +%s.%N)
  local r; r=$( { /usr/bin/env time -f "%U %S" "$@" >/dev/null; } 2>&1 | tail -1)
  t1=$(date +%s.%N)
  echo "$r $(echo "$t1 - $t0" | bc)"
}
single=()
for _ in $(seq 10); do
  read -r u s w < <(cpu "$bin" benchmark marths)
  single+=("$(echo "$u + $s" | bc)")
done
median=$(printf '%s\n' "${single[@]}" | sort -g | awk '{a[NR]=$1} END {print (NR%2 ? a[(NR+1)/2] : (a[NR/2]+a[NR/2+1])/2)}')
read -r u s w < <(cpu "$bin" benchmark marths --trials 20)
trials_cpu=$(echo "$u + $s" | bc)
read -r nu ns nw < <(cpu "$bin" benchmark marths --no-noise)
t0=$(date +%s.%N)
echo '[{"record": "elcentro", "intensity": 0.4, "transfer": "plant", "controller": "rodeac"}]' \
  | "$py" crates/substep/tests/marths/reference.py >/dev/null 2>&1
t1=$(date +%s.%N)
numpy=$(echo "$t1 - $t0" | bc)
f() { printf '%.3f' "$1"; }
echo "| run | CPU [s] | wall [s] |"
echo "|---|---|---|"
echo "| substep, one run (median of 10) | $(f "$median") | – |"
echo "| substep, --trials 20 (21 runs) | $(f "$trials_cpu") | $(f "$w") |"
echo "| substep, one run without noise | $(f "$(echo "$nu + $ns" | bc)") | $(f "$nw") |"
echo "| NumPy re-implementation, the same run | – | $(f "$numpy") |"
echo "cores used by --trials 20: $(f "$(echo "scale=3; $trials_cpu / $w" | bc)")"
echo "NumPy / substep (wall, one run without noise): $(f "$(echo "scale=3; $numpy / $nw" | bc)")x"
