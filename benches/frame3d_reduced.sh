#!/usr/bin/env bash
# A 3-D frame of 101 388 DOFs with a damper specimen in real time by verified reduction
# (examples/frame3d_reduced.toml; docs/performance.md, "3-D frame of 10^5 DOFs in real time";
# issue 42). Two runs of the same file, one after another:
#   1. reduced (40 load-dependent Ritz vectors), offline, with the library's check: the same
#      file with [structure.reduction] removed runs offline through the same engine (the full
#      model, 1 200 steps of 10 sub-steps) and the summary gives the peak error of the coupling
#      DOF and the roof relative to the full run's peak (goal: <= 1e-3), beside the estimate;
#   2. reduced, `--realtime` (dt = 10 ms, k_sub = 10: wall-clock sub-steps of 1 ms): missed
#      deadlines (goal: < 1 %) and the numerical step's time; its history must equal run 1's
#      (the virtual specimen is deterministic), so run 1's check measures it too; then again
#      with --fifo-priority 80 --lock-memory (root or CAP_SYS_NICE / CAP_IPC_LOCK).
# (`substep run` of the file without the table writes a history.csv of about 7 GB, one column
# per DOF: the check measures the same run without writing it.)
#
#   benches/frame3d_reduced.sh            # SUBSTEP=path/to/substep to use another binary
set -euo pipefail
cd "$(dirname "$0")/.."
S=${SUBSTEP:-target/release/substep}
W=$(mktemp -d)
trap 'rm -rf "$W"' EXIT
cp examples/frame3d_reduced.toml "$W/reduced.toml"
mkdir -p "$W/records"
cp examples/records/elcentro.csv "$W/records/"
run() { # name config flags...
  local name=$1 cfg=$2
  shift 2
  local t0=$SECONDS
  set +e
  /usr/bin/time -f "%M" -o "$W/$name.rss" "$S" run "$cfg" --out "$W/$name" --no-plots "$@" > "$W/$name.log" 2>&1
  echo $? > "$W/$name.rc"
  set -e
  echo $(( SECONDS - t0 )) > "$W/$name.wall"
}
run offline "$W/reduced.toml"
run realtime "$W/reduced.toml" --realtime
run realtime_fifo "$W/reduced.toml" --realtime --fifo-priority 80 --lock-memory
python3 - "$W" <<'PY'
import csv, json, sys
w = sys.argv[1]
csv.field_size_limit(1 << 30)
def summary(name):
    return json.load(open(f"{w}/{name}/summary.json"))
def columns(name, wanted):
    with open(f"{w}/{name}/history.csv", newline="") as f:
        rows = csv.reader(f)
        header = next(rows)
        idx = [header.index(c) for c in wanted]
        out = [[] for _ in wanted]
        for row in rows:
            for k, i in enumerate(idx):
                out[k].append(float(row[i]))
    return out
for name in ["offline", "realtime", "realtime_fifo"]:
    rc = open(f"{w}/{name}.rc").read().strip()
    if rc != "0":
        print(f"{name}: FAILED (exit {rc}): {open(f'{w}/{name}.log').read().strip().splitlines()[-1]}")
        sys.exit(1)
off, rt = summary("offline"), summary("realtime")
red = off["reduction"]
check = red["check"]
r = json.load(open(f"{w}/realtime/realtime.json"))
rf = json.load(open(f"{w}/realtime_fifo/realtime.json"))
slots = r["substeps"] + r["hold_substeps"]
slots_f = rf["substeps"] + rf["hold_substeps"]
# The real-time history equals the offline one: the check's error is the real-time run's.
a, b = columns("realtime", ["u1", "u2"]), columns("offline", ["u1", "u2"])
same = max(max(abs(x - y) for x, y in zip(p, q)) / max(abs(y) for y in q) for p, q in zip(a, b))
errs = [d["error"] for d in check["dofs"]]
steps = off["steps"] if "steps" in off else len(b[0]) - 1
def stat(k):
    x = r[k]
    return f"{x['p50_us']:.0f} / {x['p99_us']:.0f} / {x['max_us']:.0f}"
print("| quantity | value |")
print("|---|---|")
print(f"| model | {red['full_dofs']} DOFs, reduced to {red['reduced_dofs']} ({red['modes']} Ritz vectors, up to {red['highest_kept_hz']:.2f} Hz) in {red['seconds']:.1f} s |")
print(f"| error estimate / measured against the full run (offline) | {red['error_estimate']:.2e} / {check['max_error']:.2e} |")
print(f"| coupling DOF / roof: peak error over the full run's peak | {errs[0]:.2e} / {errs[1]:.2e} |")
print(f"| real-time run: missed deadlines | {r['missed_deadlines']} of {slots} ({100 * r['missed_deadlines'] / slots:.2f} %) |")
print(f"| real-time run: numerical step p50 / p99 / max [µs] | {stat('numerical_step')} |")
print(f"| real-time run, SCHED_FIFO {rf['fifo']} + mlockall {rf['memory_lock']}: missed deadlines | {rf['missed_deadlines']} of {slots_f} ({100 * rf['missed_deadlines'] / slots_f:.2f} %) |")
print(f"| real-time vs offline reduced history (peak difference over peak) | {same:.1e} |")
print(f"| time per step [ms]: reduced (offline) / full (the check's run) | {off['us_per_step'] / 1e3:.4f} / {check['full_run_seconds'] * 1e3 / steps:.1f} (ratio {check['full_run_seconds'] * 1e6 / steps / off['us_per_step']:.0f}) |")
print(f"| wall time [s]: reduced offline with check / real time | {open(f'{w}/offline.wall').read().strip()} / {open(f'{w}/realtime.wall').read().strip()} |")
print(f"| peak resident memory [MB]: offline with check / real time | {int(open(f'{w}/offline.rss').read().split()[-1]) / 1024:.0f} / {int(open(f'{w}/realtime.rss').read().split()[-1]) / 1024:.0f} |")
errs.append(same)
ok = r["missed_deadlines"] < 0.01 * slots and max(errs) <= 1e-3
print("verdict:", "PASS" if ok else "FAIL", "(missed < 1 %, coupling and roof within 1e-3 of the full run, real time = offline)")
sys.exit(0 if ok else 1)
PY
