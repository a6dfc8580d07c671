#!/usr/bin/env bash
# The explicit schemes for yielding structures side by side (docs/theory.md §2.8, "Accuracy and
# cost"): the 3-storey bilinear building of examples/yielding_building.toml without its specimen,
# El Centro x 1.5 for 20 s, monolithic, at dt = 5 ms and 10 ms, integrated by
#   average_acceleration + Newton (tolerance 1e-12: the reference), alpha_os (alpha = -0.05),
#   cr, kr_alpha (rho_inf = 1, 0.5, 0),
# and, for each, the largest floor deviation from the Newton solution of the same dt (relative
# to that floor's peak), the same against Newton at dt / 10 (the converged response), and the
# computation time per step that `substep run` reports. One markdown row per scheme and dt.
#
#   benches/explicit_schemes.sh            # SUBSTEP=path/to/substep to use another binary
set -euo pipefail
cd "$(dirname "$0")/.."
S=${SUBSTEP:-target/release/substep}
W=$(mktemp -d)
trap 'rm -rf "$W"' EXIT
# the structure and the record of the example, up to its [integrator]
sed -n '1,/^\[integrator\]/p' examples/yielding_building.toml | sed '$d' \
  | sed "s|^file = \"records/|file = \"$PWD/examples/records/|" > "$W/structure.toml"
run() { # name dt scheme-lines
  { cat "$W/structure.toml"; printf '[integrator]\n%b\ndt = %s\nduration = 20.0\n[output]\ndir = "%s"\nplots = false\n' "$3" "$2" "$W/$1"; } > "$W/$1.toml"
  "$S" run "$W/$1.toml" --no-plots > "$W/$1.log" 2>&1
}
newton='scheme = "average_acceleration"\ntolerance = 1e-12'
echo "| dt [ms] | scheme | max floor deviation from Newton, same dt | from Newton at dt/10 | µs per step |"
echo "|---|---|---|---|---|"
for dt in 0.005 0.01; do
  fine=$(python3 -c "print($dt / 10)")
  run "ref_$dt" "$dt" "$newton"
  run "fine_$dt" "$fine" "$newton"
  for s in "newton|$newton" "alpha_os|scheme = \"alpha_os\"\nalpha = -0.05" "cr|scheme = \"cr\"" \
           "kr_alpha_1|scheme = \"kr_alpha\"\nrho_inf = 1.0" "kr_alpha_0.5|scheme = \"kr_alpha\"\nrho_inf = 0.5" \
           "kr_alpha_0|scheme = \"kr_alpha\"\nrho_inf = 0.0"; do
    name=${s%%|*}
    run "${name}_$dt" "$dt" "${s#*|}"
    python3 - "$W" "$name" "$dt" <<'PY'
import csv, re, sys
w, name, dt = sys.argv[1], sys.argv[2], sys.argv[3]
def floors(path, every=1):
    rows = list(csv.DictReader(open(path)))
    cols = [c for c in rows[0] if re.fullmatch(r"u\d+", c)]
    return [[float(r[c]) for r in rows[::every]] for c in cols]
def worst(a, b):
    return max(max(abs(x - y) for x, y in zip(fa, fb)) / max(abs(y) for y in fb) for fa, fb in zip(a, b))
u = floors(f"{w}/{name}_{dt}/history.csv")
same = worst(u, floors(f"{w}/ref_{dt}/history.csv"))
conv = worst(u, floors(f"{w}/fine_{dt}/history.csv", 10))
cost = re.search(r"\(([0-9.]+) µs per step of computation\)", open(f"{w}/{name}_{dt}.log").read())
label = {"newton": "average_acceleration + Newton", "alpha_os": "alpha_os α = −0.05", "cr": "cr"}.get(
    name, name.replace("kr_alpha_", "kr_alpha ρ∞ = "))
print(f"| {float(dt) * 1e3:g} | {label} | {same:.2e} | {conv:.2e} | {cost.group(1) if cost else '–'} |")
PY
  done
done
