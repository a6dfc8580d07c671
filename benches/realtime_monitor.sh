#!/usr/bin/env bash
# Does the live monitor cost a real-time run deadlines? Runs examples/realtime_1000.toml
# --realtime without and with --monitor, interleaved, PAIRS times (default 3; the order inside a
# pair alternates so that a drifting load favours neither). With the monitor a page client is
# attached for the whole run (curl reading the server-sent event stream), so frames really flow.
# Prints per run and as the median of each side the same statistics from realtime.json: missed
# deadlines, late steps, hold sub-steps, wake-up lateness p99 and max, records dropped, and for
# the monitored runs the event messages and frames the client received and the frames the
# monitor dropped.
# Usage: bash benches/realtime_monitor.sh   (from the repository root; about 15 s per run)
#        PAIRS=5 EXTRA="--fifo-priority 80 --lock-memory" bash benches/realtime_monitor.sh
set -euo pipefail
cargo build --release -q
bin=target/release/substep
config=${CONFIG:-examples/realtime_1000.toml}
pairs=${PAIRS:-3}
read -r -a extra <<< "${EXTRA:-}"
tmp=$(mktemp -d)
load_before=$(cut -d' ' -f1-3 /proc/loadavg)

without() {
    "$bin" run "$config" --realtime --quiet --no-plots --out "$tmp/without$1" "${extra[@]}" \
        > "$tmp/without$1.log" 2>&1 || echo "without $1: exit $?" >> "$tmp/notes"
}

with() {
    local log="$tmp/with$1.log" url="" client=""
    "$bin" run "$config" --realtime --quiet --no-plots --out "$tmp/with$1" "${extra[@]}" \
        --monitor 127.0.0.1:0 --monitor-linger 0 > "$log" 2>&1 &
    local run=$!
    # The monitor prints its address (also with --quiet) before the model is built.
    for _ in $(seq 200); do
        url=$(sed -n 's/^monitor: \(http:[^ ]*\) .*/\1/p' "$log")
        [ -n "$url" ] && break
        kill -0 "$run" 2> /dev/null || break
        sleep 0.05
    done
    if [ -n "$url" ]; then
        curl -sN --max-time 600 "${url}events" > "$tmp/events$1" 2> /dev/null &
        client=$!
    else
        echo "with $1: the monitor did not come up" >> "$tmp/notes"
    fi
    wait "$run" || echo "with $1: exit $?" >> "$tmp/notes"
    if [ -n "$client" ]; then
        # The server ends the stream when the run ends; do not wait for ever if it does not.
        for _ in $(seq 50); do kill -0 "$client" 2> /dev/null || break; sleep 0.1; done
        kill "$client" 2> /dev/null || true
        wait "$client" 2> /dev/null || true
    fi
}

for i in $(seq "$pairs"); do
    if [ $((i % 2)) -eq 1 ]; then without "$i"; with "$i"; else with "$i"; without "$i"; fi
done
load_after=$(cut -d' ' -f1-3 /proc/loadavg)
[ -f "$tmp/notes" ] && cat "$tmp/notes"
python3 - "$tmp" "$pairs" "$load_before" "$load_after" "$config" "${EXTRA:-}" <<'PY'
import json, os, statistics, sys
tmp, pairs, before, after, config, extra = sys.argv[1], int(sys.argv[2]), *sys.argv[3:7]

def report(side, i):
    p = f"{tmp}/{side}{i}/realtime.json"
    if not os.path.exists(p):
        return None
    r = json.load(open(p))
    row = {"missed": r["missed_deadlines"], "late": r["late_steps"], "holds": r["hold_substeps"],
           "p99": r["wake_up_latency"]["p99_us"], "max": r["wake_up_latency"]["max_us"],
           "dropped": r["records_dropped"], "steps": r["steps"]}
    ev = f"{tmp}/events{i}"
    if side == "with" and os.path.exists(ev):
        msgs, frames, fdrop = 0, 0, None
        for line in open(ev):
            if line.startswith("data: "):
                m = json.loads(line[6:])
                msgs += 1
                frames += len(m.get("frames", []))
                fdrop = m.get("status", {}).get("frames_dropped", fdrop)
        row.update(messages=msgs, frames=frames, frames_dropped=fdrop)
    return row

print(f"{config} --realtime {extra}".rstrip() + f", {pairs} pairs; load average before {before}, after {after}")
head = f"{'run':<10} {'steps':>6} {'missed':>7} {'late steps':>10} {'holds':>6} {'p99 [us]':>10} {'max [us]':>10} {'rec. dropped':>12}   page client"
print(head)
rows = {"without": [], "with": []}
for i in range(1, pairs + 1):
    for side in ("without", "with"):
        r = report(side, i)
        if r is None:
            print(f"{side} {i}: no realtime.json (see the notes above)")
            continue
        rows[side].append(r)
        client = ""
        if "messages" in r:
            client = f"{r['messages']} messages, {r['frames']} frames, {r['frames_dropped']} dropped by the monitor"
        print(f"{side + ' ' + str(i):<10} {r['steps']:>6} {r['missed']:>7} {r['late']:>10} {r['holds']:>6} "
              f"{r['p99']:>10.1f} {r['max']:>10.1f} {r['dropped']:>12}   {client}")
print()
print(f"{'median':<10} {'missed':>7} {'late steps':>10} {'p99 [us]':>10} {'max [us]':>10}")
for side in ("without", "with"):
    if rows[side]:
        med = lambda k: statistics.median(r[k] for r in rows[side])
        print(f"{side:<10} {med('missed'):>7} {med('late'):>10} {med('p99'):>10.1f} {med('max'):>10.1f}")
PY
rm -rf "$tmp"
