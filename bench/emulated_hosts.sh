#!/usr/bin/env bash
# Emulated hosts: the root, the display and every worker each in a network
# namespace of its own, joined through a bridge by veth links with a rate
# limit (tc tbf) and a latency (bench/delay_relay, since this kernel has no
# netem). For each point of a sweep over link latency, bandwidth, workers
# and rings it runs a warm-up job (the slabs go out over the links) and a
# turntable job, checks every frame bit for bit against the in-process
# render (`transtick render --local 0`), and prints the frame time, rays and
# bytes per ring link, hops per ray and the frame's tail after its last
# deposit (bench/emulated_hosts.py). Needs root (it makes namespaces);
# exits 77 when it cannot make one. How to read the output: bench/README.md,
# "Emulated hosts".
#
# Usage: bench/emulated_hosts.sh [--build DIR] [--full] [--point W:R:LAT_MS:GBIT]...
#          [--rounds N] [--frames N] [--size WxH] [--volume FILE] [--materials FILE]
#          [--threads N] [--frames-tracing auto|1|2] [--batch-rays N] [--linger-us US] [--json FILE]
#          [--timeout S] [--keep]
#   Default points: a subset of the sweep (below), 3 rounds (about 6 minutes
#   on 2 cores). --full: every point of latency 0.05/0.5/5 ms x 1/10 Gbit/s x
#   2/4/8 workers x 1/2/4 rings (rings at most the workers), 48 points, 1
#   round unless --rounds (about 9 minutes a round). --point replaces the set;
#   give it several times; LAT_MS 0 is no delay and GBIT 0 no rate limit;
#   R auto: the root's --rings auto, told the link (--link-latency-ms,
#   --link-gbits), picks the rings; the row shows them as aR.
#   Each round runs every point once, so a slow drift in the machine's load
#   spreads over all points; the summary takes the median over rounds.
#   Defaults: 10 frames of cthead.nrrd (from TRANSTICK_DATA_DIR, default
#   ../shared/data) at 400x400, elevation 15, shadows, one tracer thread per
#   worker, the worker's own batch and linger, 300 s per job at most, and
#   the root's --frames-tracing 2: the emulated hosts share one boot id, so
#   the root's auto would take them for one machine (docs/design.md,
#   "Overlapped frames").
#   --json FILE: one JSON object per point (tests/emulated_hosts_test.sh).
set -uo pipefail
src=$(cd "$(dirname "$0")/.." && pwd)
build=$src/build
data=${TRANSTICK_DATA_DIR:-$src/../shared/data}
volume=$data/cthead.nrrd
materials=$src/examples/cthead_materials.json
frames=10 size=400x400 threads=1 rounds="" json="" timeout_s=300 keep=0 full=0 frames_tracing=2
worker_extra=()
points=()
while (($#)); do
  case $1 in
    --build) build=$2; shift ;;
    --full) full=1 ;;
    --point) points+=("$2"); shift ;;
    --frames) frames=$2; shift ;;
    --rounds) rounds=$2; shift ;;
    --size) size=$2; shift ;;
    --volume) volume=$2; shift ;;
    --materials) materials=$2; shift ;;
    --threads) threads=$2; shift ;;
    --frames-tracing) frames_tracing=$2; shift ;;
    --batch-rays) worker_extra+=(--batch-rays "$2"); shift ;;
    --linger-us) worker_extra+=(--linger-us "$2"); shift ;;
    --json) json=$2; shift ;;
    --timeout) timeout_s=$2; shift ;;
    --keep) keep=1 ;;
    *) echo "emulated_hosts: unknown argument $1 (usage at the top of $0)" >&2; exit 2 ;;
  esac
  shift
done
[[ $size =~ ^([0-9]+)x([0-9]+)$ ]] || { echo "emulated_hosts: --size is WxH" >&2; exit 2; }
width=${BASH_REMATCH[1]} height=${BASH_REMATCH[2]}
[[ -f $volume ]] || { echo "emulated_hosts: no volume $volume (set TRANSTICK_DATA_DIR)" >&2; exit 2; }
[[ -f $materials ]] || { echo "emulated_hosts: no materials $materials" >&2; exit 2; }
volume=$(cd "$(dirname "$volume")" && pwd)/$(basename "$volume")
materials=$(cd "$(dirname "$materials")" && pwd)/$(basename "$materials")
T=$build/cli/transtick
relay=$build/bench/delay_relay
for b in "$T" "$relay" "$build/services/root/transtick-root" "$build/services/worker/transtick-worker" \
  "$build/services/display/transtick-display"; do
  [[ -x $b ]] || { echo "emulated_hosts: $b is not built" >&2; exit 2; }
done

[[ -n $rounds ]] || rounds=$((full ? 1 : 3))
[[ $rounds =~ ^[1-9][0-9]*$ ]] || { echo "emulated_hosts: --rounds is a count" >&2; exit 2; }
if ((${#points[@]} == 0)); then
  if ((full)); then
    for lat in 0.05 0.5 5; do for gbit in 1 10; do for w in 2 4 8; do for r in 1 2 4; do
      ((r <= w)) && points+=("$w:$r:$lat:$gbit")
    done; done; done; done
  else
    # 4 workers on links with neither a delay nor a rate limit (this
    # machine's floor); latency at 4 workers; bandwidth at two latencies;
    # workers and rings at 0.5 ms and 10 Gbit/s, and the root's own choice
    # there (--rings auto) beside them.
    points=(4:1:0:0 4:1:0.05:10 4:1:0.5:10 4:1:5:10 4:1:0.5:1 4:1:5:1
            2:1:0.5:10 8:1:0.5:10 4:2:0.5:10 8:2:0.5:10 8:4:0.5:10 4:auto:0.5:10)
  fi
fi
for p in "${points[@]}"; do
  [[ $p =~ ^[0-9]+:([0-9]+|auto):[0-9.]+:[0-9.]+$ ]] ||
    { echo "emulated_hosts: --point $p is not W:R:LAT_MS:GBIT (R a number or auto)" >&2; exit 2; }
done

# --- namespaces --------------------------------------------------------
# Every name carries this run's id, so a cleanup removes only its own.
run=tteh$$
dir=$(mktemp -d "${TMPDIR:-/tmp}/transtick-emulated.XXXXXX")
pids=()
cleanup() {
  local ns
  kill "${pids[@]}" 2>/dev/null
  for ns in $(ip netns list 2>/dev/null | awk -v r="$run-" 'index($1, r) == 1 {print $1}'); do
    # Anything still running in one of our namespaces was started here.
    kill -9 $(ip netns pids "$ns" 2>/dev/null) 2>/dev/null
    ip netns del "$ns" 2>/dev/null
  done
  wait 2>/dev/null
  pids=()
}
finish() {
  cleanup
  if ((keep)); then echo "emulated_hosts: kept $dir"; else rm -rf "$dir"; fi
}
trap finish EXIT
trap 'exit 130' INT
trap 'exit 143' TERM
trap 'exit 129' HUP

if [[ $(id -u) != 0 ]]; then
  echo "emulated_hosts: SKIP: making network namespaces needs root (uid $(id -u))"
  exit 77
fi
if ! ip netns add "$run-probe" 2>"$dir/probe.err"; then
  echo "emulated_hosts: SKIP: 'ip netns add' fails here: $(cat "$dir/probe.err")"
  exit 77
fi
ip netns del "$run-probe"

nsx() { ip netns exec "$@"; }
# ip_of HOST: the address of host 1 (the root), 2 (the display) or 10 + i
# (worker i), in a /24 that exists only inside this run's namespaces.
ip_of() { echo "10.77.0.$1"; }

# make_net HOSTS GBIT: a hub namespace with a bridge, and HOSTS namespaces
# ($run-h1 ...) each with eth0 linked to it. Both ends of each link are
# limited to GBIT by tbf (none for 0): what a host sends, and what it receives.
make_net() {
  local hosts=$1 gbit=$2 i ns burst
  # A burst of 1 ms at the rate, and at least two 64 KB GSO packets.
  burst=$(python3 -c "print(max(131072, int($gbit * 1e9 / 8 * 1e-3)))")
  ip netns add "$run-hub" || return 1
  nsx "$run-hub" ip link set lo up
  ip -n "$run-hub" link add br0 type bridge || return 1
  ip -n "$run-hub" link set br0 up
  for i in $hosts; do
    ns=$run-h$i
    ip netns add "$ns" || return 1
    ip -n "$run-hub" link add "p$i" type veth peer name eth0 netns "$ns" || return 1
    ip -n "$run-hub" link set "p$i" master br0 up
    ip -n "$ns" link set lo up
    ip -n "$ns" addr add "$(ip_of "$i")/24" dev eth0
    ip -n "$ns" link set eth0 up
    [[ $gbit == 0 ]] && continue  # no rate limit
    tc -n "$ns" qdisc add dev eth0 root tbf rate "${gbit}gbit" burst "$burst" latency 10ms || return 1
    tc -n "$run-hub" qdisc add dev "p$i" root tbf rate "${gbit}gbit" burst "$burst" latency 10ms ||
      return 1
  done
}

# wait_for SECONDS CMD...: polls CMD every 0.1 s.
wait_for() {
  local n=$(($1 * 10)); shift
  for ((; n > 0; --n)); do "$@" >/dev/null 2>&1 && return 0; sleep 0.1; done
  return 1
}

# --- jobs and references ----------------------------------------------
python3 - "$dir" "$frames" "$materials" "$width" "$height" "$(basename "$volume")" <<'EOF'
import json, sys
d, frames, materials, vol = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[6]
w, h = int(sys.argv[4]), int(sys.argv[5])
def view(az, out):
    return {"azimuth": az, "elevation": 15, "width": w, "height": h, "shadows": True, "output": out}
def job(name, views):
    return {"name": name, "datasets": [{"volume": vol, "materials_file": materials, "views": views}]}
turn = [view(360 * i // frames, f"turn{i:03d}.png") for i in range(frames)]
json.dump(job("turntable", turn), open(f"{d}/turntable.json", "w"))
json.dump(job("warm-up", [view(30, "warm.png")]), open(f"{d}/warm.json", "w"))
open(f"{d}/azimuths", "w").write("".join(f"{360 * i // frames}\n" for i in range(frames)))
EOF
echo "emulated_hosts: in-process references of the $frames views ($(basename "$volume") ${width}x$height)"
i=0
while read -r az; do
  "$T" render --local 0 --volume "$volume" --materials "$materials" --azimuth "$az" --elevation 15 \
    --size "${width}x$height" --shadows on --quiet --out "$dir/ref$(printf %03d $i).png" \
    >"$dir/ref.log" 2>&1 ||
    { echo "emulated_hosts: reference render failed: $(cat "$dir/ref.log")" >&2; exit 1; }
  i=$((i + 1))
done <"$dir/azimuths"

# --- one point ----------------------------------------------------------
# run_point W R LAT_MS GBIT: prints the point's row; appends its JSON.
failures=0
run_point() {
  local w=$1 r=$2 lat=$3 gbit=$4 delay_us hosts i pdir root_ns disp_ns
  delay_us=$(python3 -c "print(round($lat * 1000))")
  pdir=$dir/point-$w-$r-$lat-$gbit-$round
  mkdir -p "$pdir/out"
  hosts="1 2"
  for ((i = 0; i < w; ++i)); do hosts+=" $((10 + i))"; done
  if ! make_net "$hosts" "$gbit" 2>"$pdir/net.err"; then
    echo "emulated_hosts: cannot make the network: $(cat "$pdir/net.err")" >&2
    return 1
  fi
  root_ns=$run-h1 disp_ns=$run-h2
  # Every daemon listens on its namespace's loopback (plaintext is allowed
  # there); its relay listens on the namespace's link address, delays each
  # direction by the link's latency, and is the address the others dial.
  start_relay() {  # NS INDEX PORT
    nsx "$1" "$relay" --listen "$(ip_of "$2"):$3" --to "127.0.0.1:$(($3 - 1000))" \
      --delay-us "$delay_us" --stats "$pdir/relay-$2.stats" >"$pdir/relay-$2.log" 2>&1 &
    pids+=($!)
  }
  start_relay "$disp_ns" 2 8002
  nsx "$disp_ns" "$build/services/display/transtick-display" --listen 127.0.0.1:7002 \
    --metrics 127.0.0.1:7102 >"$pdir/display.log" 2>&1 &
  pids+=($!)
  start_relay "$root_ns" 1 8000
  nsx "$root_ns" "$build/services/root/transtick-root" --listen 127.0.0.1:7000 \
    --data-dir "$(dirname "$volume")" --display "$(ip_of 2):8002" --rings "$r" \
    --link-latency-ms "$lat" --link-gbits "$(python3 -c "print($gbit or 100)")" \
    --frames-tracing "$frames_tracing" --metrics 127.0.0.1:7100 >"$pdir/root.log" 2>&1 &
  pids+=($!)
  for ((i = 0; i < w; ++i)); do
    local ns=$run-h$((10 + i))
    start_relay "$ns" $((10 + i)) 8001
    nsx "$ns" "$build/services/worker/transtick-worker" --root "$(ip_of 1):8000" \
      --listen 127.0.0.1:7001 --advertise "$(ip_of $((10 + i))):8001" --threads "$threads" \
      --metrics 127.0.0.1:7101 "${worker_extra[@]}" >"$pdir/worker$i.log" 2>&1 &
    pids+=($!)
  done
  registered() { nsx "$root_ns" "$T" status --root 127.0.0.1:7000 | grep -q "^$w workers"; }
  if ! wait_for 30 registered; then
    echo "emulated_hosts: $w workers did not register in 30 s: $(tail -2 "$pdir/root.log")" >&2
    cleanup
    return 1
  fi
  wait_for 10 nsx "$disp_ns" "$T" health --addr 127.0.0.1:7002 ||
    { echo "emulated_hosts: the display does not answer" >&2; cleanup; return 1; }
  submit() {  # JOB STATS
    # In the background and waited for, so that a signal is handled at once
    # (timeout runs in a process group of its own, which a terminal's ^C
    # does not reach).
    timeout "$timeout_s" ip netns exec "$root_ns" "$T" submit "$dir/$1" --root 127.0.0.1:7000 \
      --out-dir "$pdir/out" --stats "$pdir/$2" >"$pdir/submit.log" 2>&1 &
    wait $!
  }
  scrape() {  # PREFIX: the display's metrics and every relay's counts, now
    nsx "$disp_ns" curl -sf http://127.0.0.1:7102/metrics >"$pdir/$1-display.prom"
    for f in "$pdir"/relay-*.stats; do cp "$f" "$pdir/$1-$(basename "$f")"; done
  }
  local ok=1
  submit warm.json warm.json ||
    { echo "emulated_hosts: warm-up job: $(tail -3 "$pdir/submit.log")" >&2; ok=0; }
  if ((ok)); then
    sleep 0.3  # the relays' counts settle (they are written every 100 ms)
    scrape before
    local s e
    s=$(date +%s.%N)
    submit turntable.json turn.json ||
      { echo "emulated_hosts: turntable job: $(tail -3 "$pdir/submit.log")" >&2; ok=0; }
    e=$(date +%s.%N)
    echo "$s $e" >"$pdir/wall"
    sleep 0.3
    scrape after
  fi
  cleanup
  ((ok)) || return 1
  local same=0
  for ((i = 0; i < frames; ++i)); do
    cmp -s "$pdir/out/turn$(printf %03d $i).png" "$dir/ref$(printf %03d $i).png" &&
      same=$((same + 1))
  done
  python3 "$src/bench/emulated_hosts.py" point "$pdir" "$w" "$r" "$lat" "$gbit" "$frames" "$same" \
    "$round" "$dir/rows.jsonl"
}

echo "emulated_hosts: $(nproc) cores; ${#points[@]} points, $rounds round(s), $frames frames of" \
  "${width}x$height each, $threads tracer thread(s) per worker${worker_extra[*]:+, ${worker_extra[*]}}"
python3 "$src/bench/emulated_hosts.py" header
for ((round = 0; round < rounds; ++round)); do
  for p in "${points[@]}"; do
    IFS=: read -r w r lat gbit <<<"$p"
    run_point "$w" "$r" "$lat" "$gbit" || { failures=$((failures + 1)); echo "$p: FAILED"; }
  done
done
python3 "$src/bench/emulated_hosts.py" summary "$dir/rows.jsonl" "$json" || failures=$((failures + 1))
((failures == 0)) || { echo "emulated_hosts: $failures point(s) failed"; exit 1; }
