#!/usr/bin/env bash
# Regenerate docs/performance.json: chain and frame sweeps (k_sub = 10, each size in its own
# process) and the 5000-DOF comparison with OpenSees and SciPy (skipped if not installed).
# Usage: bash benches/performance.sh   (from the repository root; takes a few minutes)
set -euo pipefail
cargo build --release -q
bin=target/release/substep
tmp=$(mktemp -d)
load_before=$(cut -d' ' -f1-3 /proc/loadavg)
$bin bench --model chain --sweep --steps 2000 --json > "$tmp/chain.json"
$bin bench --model frame --sweep --steps 1000 --json > "$tmp/frame.json"
$bin bench --compare --steps 1000 --json > "$tmp/compare.json"
load_after=$(cut -d' ' -f1-3 /proc/loadavg)
python3 - "$tmp" "$load_before" "$load_after" > docs/performance.json <<'PY'
import json, os, platform, sys
tmp, before, after = sys.argv[1:4]
cpu = next((l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name")), "?")
out = {
    "machine": {"cpu": cpu, "cores": os.cpu_count(), "kernel": platform.release(),
                "load_average_before": before, "load_average_after": after},
    "command": "bash benches/performance.sh",
    "chain_sweep": json.load(open(f"{tmp}/chain.json")),
    "frame_sweep": json.load(open(f"{tmp}/frame.json")),
    "compare_5000_dof_chain": json.load(open(f"{tmp}/compare.json")),
}
print(json.dumps(out, indent=1))
PY
rm -rf "$tmp"
echo "wrote docs/performance.json" >&2
