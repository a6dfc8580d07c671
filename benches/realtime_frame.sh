#!/usr/bin/env bash
# A yielding 10^4-DOF plane frame in real time (docs/performance.md, "Yielding 10^4-DOF frame in
# real time"; issue 38): `substep run --realtime` with 1 ms sub-steps (dt = 10 ms, k_sub = 10) for
# 10 s of El Centro x 3, one run after another in one invocation:
#   * the hinged frame: 27 bays x 51 storeys, bilinear rotational hinges at both ends of every
#     member (5610 hinges, 9894 DOFs), the springs through the one-sub-step pipeline;
#   * the same frame with elastic hinges (same DOFs and solve, no yielding): the peak coupling
#     force differs by > 10 %, so the hinges do yield;
#   * the linear frame of about the same size without hinges: 41 bays x 79 storeys, 9954 DOFs;
# each with the default scheduling and with SCHED_FIFO + mlockall (--fifo-priority 80
# --lock-memory: root or CAP_SYS_NICE / CAP_IPC_LOCK; the row says when it was not permitted).
# One markdown row per run: missed deadlines, wake-up lateness, numerical-thread time per step and
# the springs' pipeline (p50 / p99 / max), the peak coupling force, the verdict.
#
#   benches/realtime_frame.sh            # SUBSTEP=path/to/substep to use another binary
set -euo pipefail
cd "$(dirname "$0")/.."
S=${SUBSTEP:-target/release/substep}
W=$(mktemp -d)
trap 'rm -rf "$W"' EXIT
frame() { # bays stories hinge-kind|none
  local hinges=""
  if [[ $3 != none ]]; then
    hinges=$(printf '[structure.frame.hinges]\nat = "both"\nkind = "%s"\nbeam_yield_moment = 5.0e4\ncolumn_yield_moment = 8.0e4\nhardening = 0.02\n' "$3")
    [[ $3 == elastic ]] && hinges=$(printf '[structure.frame.hinges]\nat = "both"\nkind = "elastic"\n')
  fi
  cat <<EOF
[structure.frame]
bays = $1
stories = $2

$hinges

[structure.rayleigh]
zeta = 0.02
modes = [1, 2]

[ground_motion]
file = "$PWD/examples/records/elcentro.csv"
scale = 3.0

[integrator]
scheme = "average_acceleration"
dt = 0.01
duration = 10.0

[substructure]
coupling_dofs = [1]
substeps = 10

[[substructure.specimen]]
kind = "linear_sdof"
dof = 1
stiffness = 5.0e7
damping = 1.0e5

[substructure.actuator]
kind = "ideal"

[output]
dir = "$W/out"
plots = false
EOF
}
frame 27 51 bilinear > "$W/hinged.toml"
frame 27 51 elastic > "$W/elastic_hinges.toml"
frame 41 79 none > "$W/linear.toml"
echo "| frame | scheduling | missed deadlines | wake-up lateness p50 / p99 / max [µs] | numerical step p50 / p99 / max [µs] | springs pipeline p50 / p99 / max [µs] | peak coupling force [N] | verdict |"
echo "|---|---|---|---|---|---|---|---|"
for name in hinged elastic_hinges linear; do
  for sched in default fifo; do
    flags=()
    [[ $sched == fifo ]] && flags=(--fifo-priority 80 --lock-memory)
    rm -rf "$W/out"
    set +e
    "$S" run "$W/$name.toml" --realtime "${flags[@]}" > "$W/log" 2>&1
    rc=$?
    set -e
    python3 - "$name" "$sched" "$W/out" "$W/log" "$rc" <<'PY'
import json, re, sys
name, sched, out, log, rc = sys.argv[1:6]
text = open(log).read()
try:
    r = json.load(open(f"{out}/realtime.json"))
except OSError:
    print(f"| {name} | {sched} | run failed before the test (exit {rc}): {text.strip().splitlines()[-1]} | | | | | |")
    sys.exit(0)
dofs = re.search(r"(\d+) DOFs", text)
def h(k):
    x = r[k]
    return "–" if x["count"] == 0 else f"{x['p50_us']:.0f} / {x['p99_us']:.0f} / {x['max_us']:.0f}"
slots = r["substeps"] + r["hold_substeps"]
peak = re.search(r"peak coupling force \|f_c\| = ([0-9.eE+-]+) N", text)
fifo = "" if sched == "default" else f" (SCHED_FIFO {r['fifo']}, mlockall {r['memory_lock']})"
verdict = "real time" if rc == "0" else f"NOT real time (exit {rc})"
label = f"{name}" + (f", {dofs.group(1)} DOFs" if dofs else "")
print(f"| {label} | {sched}{fifo} | {r['missed_deadlines']} of {slots} ({100 * r['missed_deadlines'] / slots:.2f} %) "
      f"| {h('wake_up_latency')} | {h('numerical_step')} | {h('springs_pipeline')} "
      f"| {peak.group(1) if peak else '–'} | {verdict} |")
PY
  done
done
