#!/usr/bin/env bash
# Parallel speed-up of a parameter study: the 200-run Monte-Carlo study of
# examples/studies/monte_carlo.toml on 1 and on 2 threads (substep study --threads N), each
# repeated REPEATS times (default 5), alternating; prints the fastest wall time of each, the
# CPU time, the speed-up, the load average, and checks that both give the same study.csv.
# Usage: bash benches/study_scaling.sh   (from the repository root; about a minute)
set -euo pipefail
cargo build --release -q
bin=target/release/substep
tmp=$(mktemp -d)
repeats=${REPEATS:-5}
load_before=$(cut -d' ' -f1-3 /proc/loadavg)
for _ in $(seq "$repeats"); do
    for t in 1 2; do
        /usr/bin/time -f "$t %e %U" -a -o "$tmp/times" \
            "$bin" study examples/studies/monte_carlo.toml --out "$tmp/t$t" --threads "$t" --quiet --no-plots
    done
done
load_after=$(cut -d' ' -f1-3 /proc/loadavg)
cmp -s "$tmp/t1/study.csv" "$tmp/t2/study.csv" && same=yes || same=NO
python3 - "$tmp/times" "$load_before" "$load_after" "$same" <<'PY'
import sys
times, before, after, same = sys.argv[1:5]
rows = [l.split() for l in open(times) if l.strip()]
best = {t: min(float(w) for tt, w, _ in rows if tt == t) for t in ("1", "2")}
cpu = {t: min(float(u) for tt, _, u in rows if tt == t) for t in ("1", "2")}
print(f"200-run Monte Carlo: 1 thread {best['1']:.2f} s (CPU {cpu['1']:.2f} s), "
      f"2 threads {best['2']:.2f} s (CPU {cpu['2']:.2f} s): speed-up {best['1'] / best['2']:.2f}x; "
      f"same study.csv: {same}; load average before {before}, after {after}")
PY
rm -rf "$tmp"
