#!/usr/bin/env bash
# Memory over many jobs: a root, a display and two workers as separate
# processes serve N jobs (default 200) submitted one after another, each
# three views of a real head; prints every daemon's RSS after the first job
# (warm), right after the last, and idle (3 s later, when the daemons have
# handed their free heap back: services/common/heap.h), the growth from the
# first to idle, and the size of the root's state directory. The root keeps
# no image after it is delivered, so its RSS should stay flat.
# Usage: bench/soak.sh [BUILD_DIR] [JOBS] [SIZE]
set -euo pipefail
src=$(cd "$(dirname "$0")/.." && pwd)
build=${1:-$src/build}
jobs=${2:-200}
size=${3:-256}
data=${TRANSTICK_DATA_DIR:-$src/../shared/data}
[[ -f $data/cthead.nrrd ]] || { echo "soak: $data/cthead.nrrd not found" >&2; exit 2; }
dir=$(mktemp -d)
pids=()
cleanup() { kill "${pids[@]}" 2>/dev/null || true; wait 2>/dev/null || true; rm -rf "$dir"; }
trap cleanup EXIT
T=$build/cli/transtick
port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
rss() { awk '/VmRSS/ {print $2}' "/proc/$1/status"; }

dport=$(port); rport=$(port)
"$build/services/display/transtick-display" --listen 127.0.0.1:$dport >"$dir/display.log" 2>&1 &
pids+=($!); dpid=$!
"$build/services/root/transtick-root" --listen 127.0.0.1:$rport --data-dir "$data" \
  --state-dir "$dir/state" --display 127.0.0.1:$dport >"$dir/root.log" 2>&1 &
pids+=($!); rpid=$!
wpids=()
for i in 1 2; do
  "$build/services/worker/transtick-worker" --root 127.0.0.1:$rport --listen 127.0.0.1:0 \
    >"$dir/worker$i.log" 2>&1 &
  pids+=($!); wpids+=($!)
done
for _ in $(seq 100); do
  "$T" status --root 127.0.0.1:$rport 2>/dev/null | grep -q '^2 workers' && break
  sleep 0.1
done
sed "s/\"width\": 400, \"height\": 400/\"width\": $size, \"height\": $size/g" \
  "$src/examples/cthead_job.json" >"$dir/job.json"
cp "$src/examples/cthead_materials.json" "$dir/"
submit() {
  "$T" submit "$dir/job.json" --root 127.0.0.1:$rport --out-dir "$dir/out" >"$dir/submit.log" 2>&1 ||
    { cat "$dir/submit.log" >&2; tail -20 "$dir/root.log" >&2; return 1; }
}
submit
sleep 3
declare -A before busy
for p in $rpid $dpid "${wpids[@]}"; do before[$p]=$(rss "$p"); done
start=$(date +%s.%N)
for i in $(seq 2 "$jobs"); do
  submit || { echo "soak: job $i failed" >&2; exit 1; }
done
end=$(date +%s.%N)
printf 'soak: %d jobs of 3 %sx%s frames in %.1f s\n' "$jobs" "$size" "$size" "$(echo "$end - $start" | bc)"
for p in $rpid $dpid "${wpids[@]}"; do busy[$p]=$(rss "$p"); done
sleep 3
printf '%-10s %12s %12s %12s %12s\n' daemon "RSS after 1" "after $jobs" idle growth
mb() { printf '%9.1f MB' "$(echo "$1 / 1024" | bc -l)"; }
show() {
  local name=$1 pid=$2 after
  after=$(rss "$pid")
  printf '%-10s %s %s %s %+9.1f MB\n' "$name" "$(mb "${before[$pid]}")" "$(mb "${busy[$pid]}")" \
    "$(mb "$after")" "$(echo "($after - ${before[$pid]}) / 1024" | bc -l)"
}
show root "$rpid"
show display "$dpid"
for i in "${!wpids[@]}"; do show "worker$((i + 1))" "${wpids[$i]}"; done
printf 'root state directory (jobs.db, WAL, history of the last 32 jobs): %s\n' \
  "$(du -sh "$dir/state" | cut -f1)"
