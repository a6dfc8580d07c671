#!/usr/bin/env bash
# Throughput of the stability maps (docs/performance.md, "Stability maps"): the default map of
# `substep analyze stability` (typical TMD system, 200 Ω × 200 ζ_s × k_sub 1..5 = 200 000 grid
# points) on one core (RAYON_NUM_THREADS=1) and on all cores, each REPEATS times (default 3),
# alternating; prints the median points/s per core of both (the rate the CLI prints), the load
# average, and with REFERENCE=path/to/an/older/substep the same for that build, measured in the
# same loop, and the speed-up.
#
# Checks, exit status 1 if one fails:
#   * the one-core rate is at least MIN_RATE points/s (default 2e5);
#   * every ρ of the map equals the stored reference to 1e-12 (relative; absolute below 1e-3;
#     NaN where NaN). The reference, written by the build before issue 42's speed-up, is in
#     benches/reference/: stability_limit.csv whole, and of stability.csv (12 MB, 1.6 MB
#     compressed) every 37th row (5 406 points; 37 is prime to the 200-point axes, so the sample
#     covers every k_sub, ζ_s and Ω). With REFERENCE, the whole stability.csv is also compared
#     with that build's.
#
#   benches/stability_maps.sh     # SUBSTEP=path/to/substep to time another binary
set -euo pipefail
cd "$(dirname "$0")/.."
S=${SUBSTEP:-target/release/substep}
REF=${REFERENCE:-}
REPEATS=${REPEATS:-3}
MIN_RATE=${MIN_RATE:-200000}
CORES=$(nproc)
[ -x "$S" ] || { echo "no binary $S (cargo build --release -p substep-cli)" >&2; exit 2; }
W=$(mktemp -d)
trap 'rm -rf "$W"' EXIT
load_before=$(cut -d' ' -f1-3 /proc/loadavg)
run() { # tag binary threads
  local out
  out=$(RAYON_NUM_THREADS=$3 "$2" analyze stability --out "$W/$1" --no-plots)
  # "stability map: N points in S s (P points/s) -> ..."
  sed -n 's/^stability map: .*(\([0-9.]*\) points\/s).*/\1/p' <<<"$out" >> "$W/$1.rates"
}
for _ in $(seq "$REPEATS"); do
  run new1 "$S" 1
  [ -n "$REF" ] && run ref1 "$REF" 1
  run newN "$S" "$CORES"
  [ -n "$REF" ] && run refN "$REF" "$CORES"
done
load_after=$(cut -d' ' -f1-3 /proc/loadavg)
python3 - "$W" "$CORES" "$MIN_RATE" "$load_before" "$load_after" "$REF" <<'PY'
import csv, gzip, io, math, os, statistics, sys
w, cores, min_rate, before, after, ref = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), *sys.argv[4:7]

def median(tag):
    rates = [float(x) for x in open(f"{w}/{tag}.rates").read().split()]
    return statistics.median(rates), rates

def rows(path):
    text = gzip.open(path, "rt").read() if path.endswith(".gz") else open(path).read()
    return list(csv.reader(io.StringIO(text)))

def worst_difference(a, b, what):
    """Largest difference of the numeric cells, relative (absolute for |reference| < 1e-3);
    inf if a NaN or a text cell ("none") differs."""
    if a[0] != b[0] or len(a) != len(b):
        sys.exit(f"{what}: header or row count differ")
    worst = 0.0
    for ra, rb in zip(a[1:], b[1:]):
        for x, y in zip(ra, rb):
            try:
                x, y = float(x), float(y)
            except ValueError:  # "none": a row without a stability limit
                if x != y:
                    return math.inf
                continue
            if math.isnan(x) or math.isnan(y):
                if not (math.isnan(x) and math.isnan(y)):
                    return math.inf
                continue
            worst = max(worst, abs(x - y) / (abs(x) if abs(x) >= 1e-3 else 1.0))
    return worst

ok = True
print(f"default stability map, 200 000 points, median of {len(median('new1')[1])} runs, {cores} cores")
for tag, name in (("new", "this build"), ("ref", "reference build")):
    if tag == "ref" and not ref:
        continue
    one, r1 = median(f"{tag}1")
    all_, rn = median(f"{tag}N")
    print(f"  {name:16} 1 core: {one:9.0f} points/s   {cores} cores: {all_:9.0f} points/s = "
          f"{all_ / cores:9.0f} per core   (runs: {', '.join(f'{x:.0f}' for x in r1)} | "
          f"{', '.join(f'{x:.0f}' for x in rn)})")
if ref:
    print(f"  speed-up: 1 core {median('new1')[0] / median('ref1')[0]:.2f}x, "
          f"{cores} cores {median('newN')[0] / median('refN')[0]:.2f}x")
print(f"  load average before {before}, after {after}")

new = rows(f"{w}/new1/stability.csv")
sample = rows("benches/reference/stability_maps_default_sample.csv.gz")
picked = [new[0]] + [r for i, r in enumerate(new[1:]) if i % 37 == 0]
checks = [("stability.csv, every 37th point, against the stored reference", worst_difference(sample, picked, "sample")),
          ("stability_limit.csv against the stored reference",
           worst_difference(rows("benches/reference/stability_maps_default_limit.csv.gz"),
                            rows(f"{w}/new1/stability_limit.csv"), "limit")),
          (f"stability.csv, {cores} cores against 1 core",
           worst_difference(new, rows(f"{w}/newN/stability.csv"), "threads"))]
if ref:
    checks.append(("stability.csv, every point, against the reference build",
                   worst_difference(rows(f"{w}/ref1/stability.csv"), new, "reference build")))
for what, d in checks:
    good = d <= 1e-12
    ok &= good
    print(f"  {what}: worst difference {d:.1e} {'ok' if good else 'FAIL (> 1e-12)'}")
rate = median("new1")[0]
if rate < min_rate:
    ok = False
    print(f"  FAIL: one-core rate {rate:.0f} points/s is below {min_rate:.0f}")
sys.exit(0 if ok else 1)
PY
