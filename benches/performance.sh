#!/usr/bin/env bash
# Regenerate docs/performance.json: chain and frame sweeps (k_sub = 10, each size in its own
# process; the frame on one and on two cores), the 3-D frame at 10^4 DOFs, and the comparisons
# with OpenSees, SciPy splu (COLAMD, MMD) and CHOLMOD (each skipped if not installed) on the
# 5000-DOF chain and the 10^4- and 10^5-DOF frames. Peers: python3 -m venv .venv &&
# .venv/bin/pip install scipy openseespy (OpenSees needs apt-get install libblas3 liblapack3;
# CHOLMOD: apt-get install libsuitesparse-dev && .venv/bin/pip install scikit-sparse==0.4.16 --
# 0.5 needs SuiteSparse 7, Debian 12 ships 5.12).
# Usage: bash benches/performance.sh   (from the repository root; takes about twenty minutes)
#        BASELINE=path/to/older/substep bash benches/performance.sh   also sweeps the chain with an
#        older build right after this one's (the no-regression check of the chain figures).
# Then benches/performance_tables.py writes the tables of docs/performance.md from the JSON.
set -euo pipefail
cargo build --release -q
bin=target/release/substep
tmp=$(mktemp -d)
load_before=$(cut -d' ' -f1-3 /proc/loadavg)
$bin bench --model chain --sweep --steps 2000 --json > "$tmp/chain.json"
if [ -n "${BASELINE:-}" ]; then
    "$BASELINE" bench --model chain --sweep --steps 2000 --json > "$tmp/chain_base.json"
fi
$bin bench --model frame --sweep --steps 1000 --json > "$tmp/frame.json"
$bin bench --model frame --sweep --sizes 10000,30000,100000 --steps 1000 --two-cores --json > "$tmp/frame2.json"
$bin bench --model frame3d --dofs 10000 --steps 1000 --json > "$tmp/frame3d.json"
$bin bench --model frame3d --dofs 100000 --steps 50 --json > "$tmp/frame3d_1e5.json"
$bin bench --model frame3d --dofs 100000 --steps 50 --two-cores --json > "$tmp/frame3d_1e5_2.json"
$bin bench --compare --steps 1000 --json > "$tmp/compare.json"
$bin bench --compare --compare-model frame --compare-dofs 10000 --steps 200 --json > "$tmp/compare_frame_1e4.json"
$bin bench --compare --compare-model frame --compare-dofs 10000 --steps 200 --two-cores --json > "$tmp/compare_frame_1e4_2.json"
$bin bench --compare --compare-model frame --compare-dofs 100000 --steps 50 --json > "$tmp/compare_frame_1e5.json"
$bin bench --compare --compare-model frame --compare-dofs 100000 --steps 50 --two-cores --json > "$tmp/compare_frame_1e5_2.json"
$bin bench --compare --compare-model frame3d --compare-dofs 10000 --steps 100 --json > "$tmp/compare_frame3d_1e4.json"
load_after=$(cut -d' ' -f1-3 /proc/loadavg)
python3 - "$tmp" "$load_before" "$load_after" > docs/performance.json <<'PY'
import json, os, platform, sys
tmp, before, after = sys.argv[1:4]
cpu = next((l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name")), "?")
out = {
    "machine": {"cpu": cpu, "cores": os.cpu_count(), "kernel": platform.release(),
                "load_average_before": before, "load_average_after": after},
    "command": "bash benches/performance.sh",
    "date": __import__("datetime").datetime.now(__import__("datetime").timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
    "chain_sweep": json.load(open(f"{tmp}/chain.json")),
    "frame_sweep": json.load(open(f"{tmp}/frame.json")),
    "frame_sweep_two_cores": json.load(open(f"{tmp}/frame2.json")),
    "frame3d_1e4": json.load(open(f"{tmp}/frame3d.json")),
    "frame3d_1e5": json.load(open(f"{tmp}/frame3d_1e5.json")),
    "frame3d_1e5_two_cores": json.load(open(f"{tmp}/frame3d_1e5_2.json")),
    "compare_5000_dof_chain": json.load(open(f"{tmp}/compare.json")),
    "compare_frame_1e4": json.load(open(f"{tmp}/compare_frame_1e4.json")),
    "compare_frame_1e4_two_cores": json.load(open(f"{tmp}/compare_frame_1e4_2.json")),
    "compare_frame_1e5": json.load(open(f"{tmp}/compare_frame_1e5.json")),
    "compare_frame_1e5_two_cores": json.load(open(f"{tmp}/compare_frame_1e5_2.json")),
    "compare_frame3d_1e4": json.load(open(f"{tmp}/compare_frame3d_1e4.json")),
}
if os.path.exists(f"{tmp}/chain_base.json"):
    out["chain_sweep_baseline"] = json.load(open(f"{tmp}/chain_base.json"))
print(json.dumps(out, indent=1))
PY
rm -rf "$tmp"
echo "wrote docs/performance.json" >&2
python3 benches/performance_tables.py docs/performance.json docs/performance.md
