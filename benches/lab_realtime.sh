#!/usr/bin/env bash
# Lab targets in real time (docs/realtime.md, "Lab targets at 1 kHz sub-steps"): the default
# example with k_sub = 10 (Δt = 10 ms, Δτ = 1 ms) for 20 s, `substep run --realtime` against
# `substep lab emulate` over each lab protocol and against `substep site serve` (SSTP, one round
# trip per sub-step), all on loopback, one after another. Prints one markdown row per variant:
# missed deadlines, the runner's sub-step completion latency (the same statistic for all) and the
# lab link's own round trip.
#
#   benches/lab_realtime.sh            # SUBSTEP=path/to/substep to use another binary
set -euo pipefail
cd "$(dirname "$0")/.."
S=${SUBSTEP:-target/release/substep}
W=$(mktemp -d)
trap 'rm -rf "$W"' EXIT
sed -e 's/^substeps = 4 .*/substeps = 10/' examples/default.toml > "$W/base.toml"
grep -q '^substeps = 10$' "$W/base.toml"
port_of() { head -1 "$1" | sed -E 's/.*127\.0\.0\.1:([0-9]+).*/\1/'; }
row() { # name dir
  python3 - "$1" "$2" <<'PY'
import json, sys
name, d = sys.argv[1], sys.argv[2]
r = json.load(open(f"{d}/realtime.json")); s = json.load(open(f"{d}/summary.json"))
c = r["completion_latency"]
lab = s.get("lab")
rtt = "–" if lab is None else "{:.0f} / {:.0f} / {:.0f}".format(lab["rtt_us"]["p50"], lab["rtt_us"]["p99"], lab["rtt_us"]["max"])
held = "–" if lab is None else str(lab["held"])
print(f"| {name} | {r['missed_deadlines']} of {r['substeps']} | {c['p50_us']:.0f} / {c['p99_us']:.0f} / {c['max_us']:.0f} | {rtt} | {held} | {'yes' if s['completed'] else 'no'} |")
PY
}
echo "| target | missed deadlines | sub-step completion p50 / p99 / max [µs] | lab round trip p50 / p99 / max [µs] | held | completed |"
echo "|---|---|---|---|---|---|"
for variant in "speedgoat udp" "speedgoat tcp" "generic_tcp tcp" "substep_udp udp"; do
  set -- $variant
  name="$1_$2"
  cp "$W/base.toml" "$W/$name.toml"
  printf '\n[substructure.lab]\nprotocol = "%s"\ntransport = "%s"\naddress = "127.0.0.1:9"\ntimeout = 0.0008\n' "$1" "$2" >> "$W/$name.toml"
  printf 'test = "%s.toml"\n' "$name" > "$W/$name.emu.toml"
  "$S" lab emulate "$W/$name.emu.toml" --bind 127.0.0.1:0 > "$W/$name.emu.log" 2>&1 &
  for _ in $(seq 50); do [ -s "$W/$name.emu.log" ] && break; sleep 0.1; done
  sed -i "s/127.0.0.1:9\"/127.0.0.1:$(port_of "$W/$name.emu.log")\"/" "$W/$name.toml"
  "$S" run "$W/$name.toml" --realtime --quiet --no-plots --out "$W/$name" || true
  wait
  row "$name ($1 over $2)" "$W/$name"
done
# SSTP per sub-step: the same specimen, actuator and sensors served by `substep site serve`.
{
  printf '[site]\nprotocol = "substep"\nlisten = "127.0.0.1:0"\n\n'
  sed -n '/^\[\[substructure.specimen\]\]/,/^\[substructure.error_force\]/p' examples/default.toml \
    | grep -v '^\[substructure.error_force\]' | sed 's/^\[\[substructure\./[[/; s/^\[substructure\./[/'
} > "$W/site.toml"
"$S" site serve "$W/site.toml" --once > "$W/site.log" 2>&1 &
for _ in $(seq 50); do [ -s "$W/site.log" ] && break; sleep 0.1; done
addr=$(head -1 "$W/site.log" | sed -E 's/.*tcp:\/\/(127\.0\.0\.1:[0-9]+).*/\1/')
cp "$W/base.toml" "$W/sstp.toml"
printf '\n[substructure.remote]\naddress = "%s"\nmode = "per_substep"\n' "$addr" >> "$W/sstp.toml"
# The virtual-lab keys move to the site.
python3 - "$W/sstp.toml" <<'PY'
import re, sys
p = sys.argv[1]; t = open(p).read()
t = re.sub(r"\n\[substructure\.(actuator|sensors)\][^\[]*", "\n", t)
open(p, "w").write(t)
PY
"$S" run "$W/sstp.toml" --realtime --quiet --no-plots --out "$W/sstp" || true
wait
row "SSTP per sub-step (substep site serve, tcp)" "$W/sstp"
