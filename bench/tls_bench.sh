#!/usr/bin/env bash
# What TLS costs the cluster (docs/security.md): real daemons on loopback, a
# display, a root and W workers, serving plaintext or TLS with certificates
# from deploy/make-certs.sh, render the same turntable job. The runs are
# interleaved (plain, tls, plain, tls, ...) so that both see the same
# machine. For each run: the median frame time, rays passed between workers
# per frame and the rate of one ring link (rays sent over a link in a
# frame / the frame's time), and the bytes on the wire; then the ratios.
#
# Usage: bench/tls_bench.sh [BUILD_DIR] [REPEATS] [FRAMES] [WORKERS]
#   defaults: build 3 24 2; TRANSTICK_DATA_DIR (default ../shared/data) holds
#   cthead.nrrd. Frames are 256x256 with shadows, balanced with test rays.
set -euo pipefail
src=$(cd "$(dirname "$0")/.." && pwd)
build=${1:-$src/build}
repeats=${2:-3}
frames=${3:-24}
workers=${4:-2}
data=${TRANSTICK_DATA_DIR:-$src/../shared/data}
[[ -f $data/cthead.nrrd ]] || { echo "tls_bench: no cthead.nrrd in $data" >&2; exit 1; }
dir=$(mktemp -d /tmp/transtick-tls-bench.XXXXXX)
pids=()
stop() { kill "${pids[@]}" 2>/dev/null || true; wait "${pids[@]}" 2>/dev/null || true; pids=(); }
trap 'stop; rm -rf "$dir"' EXIT
"$src/deploy/make-certs.sh" "$dir/certs" 2>/dev/null
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }

python3 - "$dir/job.json" "$frames" "$src/examples/cthead_materials.json" <<'EOF'
import json, sys
out, frames, materials = sys.argv[1], int(sys.argv[2]), json.load(open(sys.argv[3]))
views = [{"azimuth": 360.0 * i / frames, "elevation": 15, "width": 256, "height": 256,
          "shadows": True} for i in range(frames)]
json.dump({"name": "tls-bench", "balance": "test-rays",
           "datasets": [{"volume": "cthead.nrrd", "materials": materials, "views": views}]},
          open(out, "w"))
EOF

run() {  # run MODE N: one cluster, one job; stats in $dir/MODE-N.json
  local mode=$1 n=$2 c=$dir/certs rport dport tls=() client=()
  rport=$(free_port) dport=$(free_port)
  tlsf() { [[ $mode == tls ]] && echo "--tls-ca $c/ca.crt --tls-cert $c/$1.crt --tls-key $c/$1.key"; true; }
  if [[ $mode == tls ]]; then
    tls=(--tokens "$c/tokens")
    client=(--tls-ca "$c/ca.crt" --token-file "$c/client.token")
  fi
  # shellcheck disable=SC2046  # the TLS flags are words
  "$build/services/display/transtick-display" --listen 127.0.0.1:$dport $(tlsf display) \
    >"$dir/display.log" 2>&1 &
  pids+=($!)
  # shellcheck disable=SC2046
  "$build/services/root/transtick-root" --listen 127.0.0.1:$rport --data-dir "$data" \
    --display 127.0.0.1:$dport $(tlsf root) "${tls[@]}" >"$dir/root.log" 2>&1 &
  pids+=($!)
  for ((w = 0; w < workers; ++w)); do
    # shellcheck disable=SC2046
    "$build/services/worker/transtick-worker" --root 127.0.0.1:$rport --listen 127.0.0.1:0 \
      --threads 1 $(tlsf worker) >"$dir/worker$w.log" 2>&1 &
    pids+=($!)
  done
  for _ in $(seq 100); do
    "$build/cli/transtick" status --root 127.0.0.1:$rport "${client[@]}" 2>/dev/null |
      grep -q "^$workers workers" && break
    sleep 0.1
  done
  "$build/cli/transtick" submit "$dir/job.json" --root 127.0.0.1:$rport "${client[@]}" \
    --out-dir "$dir/out" --stats "$dir/$mode-$n.json" >/dev/null 2>&1
  stop
}

for ((i = 0; i < repeats; ++i)); do
  run plain "$i"
  run tls "$i"
done

python3 - "$dir" "$repeats" "$workers" <<'EOF'
import json, statistics, sys
d, repeats, workers = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
def figures(path):
    stats = json.load(open(path))[1:]  # the first frame balances and loads the slabs
    ms = statistics.median(s["frame_ms"] for s in stats)
    sent = [sum(int(w.get("rays_sent", 0)) for w in s["workers"]) for s in stats]
    bytes_ = [sum(int(w.get("bytes_sent", 0)) for w in s["workers"]) for s in stats]
    links = max(1, 2 * (workers - 1))  # each cut carries rays both ways
    rate = statistics.median(r / links / (s["frame_ms"] / 1e3) for r, s in zip(sent, stats))
    return ms, statistics.median(sent), statistics.median(bytes_) / 1e6, rate
rows = {m: [figures(f"{d}/{m}-{i}.json") for i in range(repeats)] for m in ("plain", "tls")}
print(f"tls_bench: {workers} workers, 1 ring, cthead 256x256, shadows, {repeats} interleaved runs each")
print(f"{'run':>4} {'mode':>6} {'frame ms':>9} {'rays passed':>12} {'MB passed':>10} {'rays/s per link':>16}")
for i in range(repeats):
    for m in ("plain", "tls"):
        ms, sent, mb, rate = rows[m][i]
        print(f"{i:>4} {m:>6} {ms:>9.1f} {sent:>12.0f} {mb:>10.2f} {rate:>16.0f}")
med = {m: [statistics.median(r[k] for r in rows[m]) for k in range(4)] for m in rows}
print(f"median frame: plain {med['plain'][0]:.1f} ms, tls {med['tls'][0]:.1f} ms, "
      f"ratio tls/plain {med['tls'][0] / med['plain'][0]:.3f}")
print(f"rays/s per link: plain {med['plain'][3]:.0f}, tls {med['tls'][3]:.0f}, "
      f"ratio tls/plain {med['tls'][3] / med['plain'][3]:.3f}")
EOF
