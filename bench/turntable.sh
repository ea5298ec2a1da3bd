#!/usr/bin/env bash
# A turntable through the cluster, as a user runs it: a display, a root and
# W worker daemons on loopback (each with a tracer thread per core), one
# warm-up job that loads the dataset's slabs, then ROUNDS rounds of a
# FRAMES-frame turntable job and a one-frame job on the loaded dataset.
# Prints, per round and as medians: the turntable's steady frames per
# second (frames / the submit command's wall time), its median frame time
# at the root, the workers' summed tracer CPU per frame, and for the
# one-frame job the time outside its frame (client start, submit, queue,
# slab checks, image and statistics back) and the time from the root
# accepting it to its frame's start (since_submit_ms); and where the
# cores went in the turntable: each process's CPU a frame (the workers,
# the display, the root and the client writing PNGs, from /proc and the
# client's rusage) and the cores' time left idle. Each round then
# renders the turntable's views in-process (render_bench, one thread per
# core, one timed frame each after a warm-up), so the cluster's rate is set
# against the in-process rate of the same frames measured minutes apart,
# not days.
#
# Usage: bench/turntable.sh [BUILD_DIR] [WORKERS] [FRAMES] [ROUNDS] [SURFACE] [BALANCE]
#   defaults: build 2 30 3 smooth off; SURFACE smooth|voxel; BALANCE
#   off|test-rays|previous-frame. Frames are 400x400 of cthead.nrrd from
#   TRANSTICK_DATA_DIR (default ../shared/data), elevation 15, shadows on.
set -euo pipefail
src=$(cd "$(dirname "$0")/.." && pwd)
build=${1:-$src/build}
workers=${2:-2}
frames=${3:-30}
rounds=${4:-3}
surface=${5:-smooth}
balance=${6:-off}
data=${TRANSTICK_DATA_DIR:-$src/../shared/data}
[[ -f $data/cthead.nrrd ]] || { echo "turntable: no cthead.nrrd in $data" >&2; exit 1; }
[[ $surface == smooth || $surface == voxel ]] || { echo "turntable: SURFACE is smooth or voxel" >&2; exit 2; }
dir=$(mktemp -d /tmp/transtick-turntable.XXXXXX)
pids=()
stop() { kill "${pids[@]}" 2>/dev/null || true; wait "${pids[@]}" 2>/dev/null || true; pids=(); }
trap 'stop; rm -rf "$dir"' EXIT
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }

python3 - "$dir" "$frames" "$src/examples/cthead_materials.json" "$surface" "$balance" <<'EOF'
import json, sys
d, frames, materials, surface, balance = sys.argv[1], int(sys.argv[2]), json.load(open(sys.argv[3])), sys.argv[4], sys.argv[5]
materials["surface"] = surface.upper()
def job(name, views):
    return {"name": name, "balance": balance,
            "datasets": [{"volume": "cthead.nrrd", "materials": materials, "views": views}]}
def view(az, out):
    return {"azimuth": az, "elevation": 15, "width": 400, "height": 400, "shadows": True,
            "output": out}
turn = [view(360.0 * i / frames, f"turn{i:03d}.png") for i in range(frames)]
json.dump(job("turntable", turn), open(f"{d}/turntable.json", "w"))
json.dump(materials, open(f"{d}/materials.json", "w"))
open(f"{d}/azimuths", "w").write(",".join(f"{360.0 * i / frames:g}" for i in range(frames)))
json.dump(job("one frame", [view(30, "one.png")]), open(f"{d}/one.json", "w"))
EOF

rport=$(free_port) dport=$(free_port)
"$build/services/display/transtick-display" --listen 127.0.0.1:$dport >"$dir/display.log" 2>&1 &
pids+=($!)
"$build/services/root/transtick-root" --listen 127.0.0.1:$rport --data-dir "$data" \
  --display 127.0.0.1:$dport >"$dir/root.log" 2>&1 &
pids+=($!)
for ((w = 0; w < workers; ++w)); do
  "$build/services/worker/transtick-worker" --root 127.0.0.1:$rport --listen 127.0.0.1:0 \
    >"$dir/worker$w.log" 2>&1 &
  pids+=($!)
done
for _ in $(seq 100); do
  "$build/cli/transtick" status --root 127.0.0.1:$rport 2>/dev/null | grep -q "^$workers workers" && break
  sleep 0.1
done
submit() {  # submit JOB STATS: prints the wall time and the client's CPU, in seconds
  python3 - "$build/cli/transtick" submit "$dir/$1" --root 127.0.0.1:$rport --out-dir "$dir/out" \
    --stats "$dir/$2" 2>"$dir/submit.log" <<'EOF2' || { cat "$dir/submit.log" >&2; exit 1; }
import os, subprocess, sys, time
t = time.monotonic()
p = subprocess.Popen(sys.argv[1:], stdout=subprocess.DEVNULL)
_, status, ru = os.wait4(p.pid, 0)
wall = time.monotonic() - t
if os.waitstatus_to_exitcode(status) != 0:
    sys.exit(f"turntable: {' '.join(sys.argv[1:3])} failed")
print(wall, ru.ru_utime + ru.ru_stime)
EOF2
}
# The CPU seconds the daemons have used: display, root, then each worker.
daemons_cpu() {
  local p tick
  tick=$(getconf CLK_TCK)
  for p in "${pids[@]}"; do
    awk -v t="$tick" '{printf "%.3f ", ($14 + $15) / t}' "/proc/$p/stat"
  done
  echo
}
submit one.json warm.json >/dev/null  # loads the slabs
for ((i = 0; i < rounds; ++i)); do
  daemons_cpu >"$dir/cpu-$i.before"
  submit turntable.json "turn-$i.json" >"$dir/turn-$i.wall"
  daemons_cpu >"$dir/cpu-$i.after"
  submit one.json "one-$i.json" >"$dir/one-$i.wall"
  # The same views in-process: the sum of their frame times (medians of one).
  "$build/bench/render_bench" --volume "$data/cthead.nrrd" --materials "$dir/materials.json" \
    --size 400x400 --elevation 15 --azimuth "$(cat "$dir/azimuths")" --shadows on --threads 0 \
    --repeat 1 >"$dir/local-$i.log" 2>&1 || { cat "$dir/local-$i.log" >&2; exit 1; }
  awk '/^(frontal|az)/ {sum += $3; n++} END {if (n == 0) exit 1; print sum}' "$dir/local-$i.log" \
    >"$dir/local-$i.ms" || { echo "turntable: render_bench printed no frames" >&2; exit 1; }
done

python3 - "$dir" "$rounds" "$frames" "$workers" "$surface" "$balance" "$(nproc)" <<'EOF'
import json, statistics, sys
d, rounds, frames, workers, surface, balance = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), sys.argv[5], sys.argv[6]
cores = int(sys.argv[7])
print(f"turntable: {workers} worker daemons, cthead 400x400, {surface} surfaces, shadows, "
      f"balance {balance}, {frames} frames a job, {rounds} rounds")
print(f"{'round':>5} {'frames/s':>9} {'frame ms':>9} {'tracer CPU ms':>14} {'1-frame job ms':>15} "
      f"{'its frame ms':>13} {'outside':>8} {'to start':>9} {'in-process f/s':>15} {'ratio':>6}")
rows, cpus = [], []
for i in range(rounds):
    wall, client = (float(v) for v in open(f"{d}/turn-{i}.wall").read().split())
    st = json.load(open(f"{d}/turn-{i}.json"))
    fms = statistics.median(s["frame_ms"] for s in st)
    cpu = statistics.median(sum(w["cpu_ms"] for w in s["workers"]) for s in st)
    one_wall = float(open(f"{d}/one-{i}.wall").read().split()[0]) * 1e3
    first = json.load(open(f"{d}/one-{i}.json"))[0]
    one, start = first["frame_ms"], first.get("since_submit_ms", 0)
    local = frames / (float(open(f"{d}/local-{i}.ms").read()) / 1e3)
    rows.append((frames / wall, fms, cpu, one_wall, one, one_wall - one, start, local,
                 local / (frames / wall)))
    print(f"{i:>5} {rows[-1][0]:>9.1f} {fms:>9.1f} {cpu:>14.1f} {one_wall:>15.0f} {one:>13.1f} "
          f"{one_wall - one:>8.0f} {start:>9.1f} {local:>15.1f} {rows[-1][8]:>6.2f}")
    # Each process's CPU a frame over the job (ms): the workers (and their
    # tracer threads' mean, from the statistics), the display, the root,
    # the client, and what the cores left idle.
    before = [float(v) for v in open(f"{d}/cpu-{i}.before").read().split()]
    after = [float(v) for v in open(f"{d}/cpu-{i}.after").read().split()]
    used = [(a - b) * 1e3 / frames for a, b in zip(after, before)]
    tracers = statistics.mean(sum(w["cpu_ms"] for w in s["workers"]) for s in st)
    client_ms = client * 1e3 / frames
    cpus.append((sum(used[2:]), tracers, used[0], used[1], client_ms,
                 cores * wall * 1e3 / frames - sum(used) - client_ms))
med = [statistics.median(r[k] for r in rows) for k in range(9)]
print(f"median: {med[0]:.1f} frames/s steady, frame {med[1]:.1f} ms, tracer CPU {med[2]:.1f} ms a frame; "
      f"a one-frame job on the loaded dataset takes {med[3]:.0f} ms, {med[5]:.0f} ms of it outside the frame, "
      f"and its frame starts {med[6]:.1f} ms after the root accepts it")
print(f"in-process, the same {frames} views one after another: {med[7]:.1f} frames/s; "
      f"a cluster frame takes {med[8]:.2f}x an in-process one (the round's ratio, median)")
c = [statistics.median(r[k] for r in cpus) for k in range(6)]
print(f"where the {cores} cores went, ms of CPU a turntable frame (medians over rounds): "
      f"workers {c[0]:.1f} (their tracer threads {c[1]:.1f}), display {c[2]:.1f}, root {c[3]:.1f}, "
      f"client {c[4]:.1f} (writing the PNGs), idle {c[5]:.1f}; an in-process frame is "
      f"{cores * 1e3 / med[7]:.1f} ms of the cores")
EOF
