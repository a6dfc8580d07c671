#!/usr/bin/env bash
# A 3-D frame of 101 388 DOFs with a damper specimen in real time by verified reduction
# (examples/frame3d_reduced.toml; docs/performance.md, "3-D frame of 10^5 DOFs in real time";
# issue 42). Three runs of the same file, one after another:
#   1. reduced (40 load-dependent Ritz vectors), offline, with the library's check against the
#      full model (the estimate and the measured error of the summary);
#   2. reduced, `--realtime` (dt = 10 ms, k_sub = 10: wall-clock sub-steps of 1 ms): missed
#      deadlines and the numerical step's time;
#   3. the same file with [structure.reduction] removed: the full model, offline (its
#      history.csv of about 7 GB needs [limits] max_output_bytes, added here).
# The real-time run's coupling DOF and roof are then compared with the full run's, relative to
# the full run's peak (goal: <= 1e-3), and the run times side by side.
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
python3 - "$W" <<'PY'
import re, sys
w = sys.argv[1]
text = open(f"{w}/reduced.toml").read()
full = re.sub(r"\[structure\.reduction\]\n(?:[^\[\n][^\n]*\n|\n)*", "", text)
assert "[structure.reduction]" not in full and "keep =" not in full
full += "\n[limits]\nmax_output_bytes = 3.0e10\n"
open(f"{w}/full.toml", "w").write(full)
PY
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
run full "$W/full.toml"
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
for name in ["offline", "realtime", "full"]:
    rc = open(f"{w}/{name}.rc").read().strip()
    if rc != "0":
        print(f"{name}: FAILED (exit {rc}): {open(f'{w}/{name}.log').read().strip().splitlines()[-1]}")
        sys.exit(1)
off, rt, full = summary("offline"), summary("realtime"), summary("full")
red = off["reduction"]
r = json.load(open(f"{w}/realtime/realtime.json"))
slots = r["substeps"] + r["hold_substeps"]
reduced_cols = columns("realtime", ["u1", "u2"])
full_cols = columns("full", ["u1", "u99898"])
errs = []
for a, b in zip(reduced_cols, full_cols):
    peak = max(abs(x) for x in b)
    errs.append(max(abs(x - y) for x, y in zip(a, b)) / peak)
def stat(k):
    x = r[k]
    return f"{x['p50_us']:.0f} / {x['p99_us']:.0f} / {x['max_us']:.0f}"
print(f"| quantity | value |")
print(f"|---|---|")
print(f"| full model | {red['full_dofs']} DOFs; reduced: {red['reduced_dofs']} DOFs ({red['modes']} Ritz vectors up to {red['highest_kept_hz']:.2f} Hz), computed in {red['seconds']:.1f} s |")
print(f"| error estimate / measured by the check (offline) | {red['error_estimate']:.2e} / {red['check']['max_error']:.2e} |")
print(f"| real-time run: missed deadlines | {r['missed_deadlines']} of {slots} ({100 * r['missed_deadlines'] / slots:.2f} %) |")
print(f"| real-time run: numerical step p50 / p99 / max [µs] | {stat('numerical_step')} |")
print(f"| real-time vs full run (offline): coupling DOF / roof, peak error over the full run's peak | {errs[0]:.2e} / {errs[1]:.2e} |")
print(f"| µs per step: reduced (offline) / full | {off['us_per_step']:.1f} / {full['us_per_step']:.0f} (ratio {full['us_per_step'] / off['us_per_step']:.0f}) |")
print(f"| wall time of the whole run [s]: reduced offline / real time / full | {open(f'{w}/offline.wall').read().strip()} / {open(f'{w}/realtime.wall').read().strip()} / {open(f'{w}/full.wall').read().strip()} |")
print(f"| peak resident memory [MB]: reduced real time / full | {int(open(f'{w}/realtime.rss').read().split()[-1]) / 1024:.0f} / {int(open(f'{w}/full.rss').read().split()[-1]) / 1024:.0f} |")
ok = r["missed_deadlines"] < 0.01 * slots and max(errs) <= 1e-3
print("verdict:", "PASS" if ok else "FAIL", "(missed < 1 %, coupling and roof within 1e-3 of the full run)")
sys.exit(0 if ok else 1)
PY
