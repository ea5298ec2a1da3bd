#!/usr/bin/env bash
# bench/emulated_hosts.sh in its short form: the root, the display and two
# workers in network namespaces of their own, on 1 Gbit/s links with 5 ms of
# latency each way, render a 3-frame turntable of a generated volume. Checks:
# every frame is bit-identical to the in-process render; rays cross the
# ring's one link and each one sent arrives; the link's bytes on the wire
# hold at least every ray record and the workers' batch bytes, plus a
# little framing; hops per ray lie in (0, 1] (a ray crosses a cut at most
# once); no frame is shorter than the round trips it must make; and an
# interrupted run leaves no namespace and no process behind. Skips (77)
# where namespaces cannot be made (not root, or no `ip netns`).
set -u
build=$1
src=$2
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
fails=0
fail() { echo "FAIL: $*"; fails=$((fails + 1)); }

# A 40x40x40 volume: a half-opaque box across the middle plane along Y
# (where two workers' slabs meet), so that primary and shadow rays cross it.
mkdir -p "$dir/data" "$dir/tmp"
python3 - "$dir/data/box.nrrd" <<'EOF'
import sys
n = 40
with open(sys.argv[1], "wb") as f:
    f.write(f"NRRD0004\ntype: uint8\ndimension: 3\nsizes: {n} {n} {n}\nencoding: raw\n\n".encode())
    f.write(bytes(200 if 8 < x < 30 and 6 < y < 34 and 10 < z < 28 else 0
                  for z in range(n) for y in range(n) for x in range(n)))
EOF
cat >"$dir/m.json" <<'JSON'
{"materials":[{"name":"box","min":100,"max":256,"color":[0.8,0.7,0.6],"opacity":0.5}]}
JSON

latency_ms=5
TMPDIR=$dir/tmp "$src/bench/emulated_hosts.sh" --build "$build" --point "2:1:$latency_ms:1" --rounds 1 \
  --frames 3 --size 64x48 --volume "$dir/data/box.nrrd" --materials "$dir/m.json" \
  --json "$dir/points.json" --timeout 60 >"$dir/bench.log" 2>&1
rc=$?
cat "$dir/bench.log"
if [[ $rc == 77 ]]; then
  echo "emulated_hosts_test: skipped: $(grep SKIP "$dir/bench.log")"
  exit 77
fi
[[ $rc == 0 ]] || fail "the bench exited $rc"
[[ -s $dir/points.json ]] || { fail "no results"; exit 1; }

python3 - "$dir/points.json" "$latency_ms" <<'EOF' || fail "invariants (above)"
import json, sys
p = json.loads(open(sys.argv[1]).read().splitlines()[0])
lat = float(sys.argv[2])
RAY = 106
PACKED_MAX = 113
bad = []
def check(ok, what):
    if not ok:
        bad.append(what)
check(p["frames"] == 3 and p["frames_identical"] == 3,
      f"frames {p['frames']}, bit-identical {p['frames_identical']} of 3")
check(len(p["links"]) == 1, f"{len(p['links'])} links for 2 workers in 1 ring")
link = p["links"][0] if p["links"] else {"rays": 0, "rays_received": -1, "wire_bytes": 0}
check(link["rays"] > 0, "no ray crossed the link")
check(link["rays"] == link["rays_received"], f"{link['rays']} rays sent, {link['rays_received']} received")
check(link["rays"] == p["rays_forwarded"], "the one link does not carry every forwarded ray")
# The workers' batch bytes: packed rays (docs/formats.md), each at least
# its 2-byte mask and at most 113 bytes, plus a few bytes of protobuf
# framing per batch (frame id, length) and each stream's first message;
# and fewer than the rays' records, since neighbouring rays share fields.
check(p["ray_bytes_sent"] >= 2 * p["rays_sent"], "fewer batch bytes than a mask per ray")
check(p["ray_bytes_sent"] <= PACKED_MAX * p["rays_sent"] * 1.01 + 64 * p["frames"] * 2,
      f"batch bytes {p['ray_bytes_sent']} for {p['rays_sent']} rays")
check(p["ray_bytes_sent"] < RAY * p["rays_sent"],
      f"packed rays took {p['ray_bytes_sent']} bytes, no fewer than their records")
# On the wire, HTTP/2 and gRPC add their headers, frames and pings: more
# than the batches, and not by much.
check(link["wire_bytes"] >= p["ray_bytes_sent"],
      f"wire bytes {link['wire_bytes']} < batch bytes {p['ray_bytes_sent']}")
check(link["wire_bytes"] <= p["ray_bytes_sent"] * 1.05 + 8192 * p["frames"],
      f"wire bytes {link['wire_bytes']} for batch bytes {p['ray_bytes_sent']}")
check(0 < p["hops_per_ray"] <= 1, f"hops per ray {p['hops_per_ray']}")
# Every pixel of every frame ends in a deposit at least; packed for the
# display, they take fewer bytes than their 20-byte records.
check(p["deposits"] >= p["pixels"] * p["frames"], f"{p['deposits']} deposits")
check(0 < p["deposit_bytes"] < 20 * p["deposits"],
      f"{p['deposit_bytes']} packed bytes for {p['deposits']} deposits")
# Each frame waits for: PrepareFrame and RunFrame (a round trip each), the
# deposits (one way), the display's "complete" (one way) and EndFrame (a
# round trip): 8 one-way latencies at least.
check(p["frame_ms_min"] >= 8 * lat, f"a frame of {p['frame_ms_min']} ms with {lat} ms links")
check(0 < p["assembly_ms_mean"] < p["frame_ms_mean"], f"assembly {p['assembly_ms_mean']} ms")
# The tail holds the display's "complete" and EndFrame's round trip.
check(p["tail_ms"] >= 3 * lat, f"tail {p['tail_ms']} ms")
for b in bad:
    print("invariant:", b)
sys.exit(1 if bad else 0)
EOF

# Stopped (SIGTERM) while its daemons run: the bench's trap removes its
# namespaces and stops every process it started. (SIGTERM, not SIGINT: a
# script's background job starts with SIGINT ignored, and bash cannot trap
# a signal ignored on entry; a terminal's ^C reaches it in the foreground.)
TMPDIR=$dir/tmp "$src/bench/emulated_hosts.sh" --build "$build" --point 2:1:5:1 --frames 40 \
  --size 64x48 --volume "$dir/data/box.nrrd" --materials "$dir/m.json" >"$dir/int.log" 2>&1 &
bench=$!
for _ in $(seq 200); do
  ip netns list | grep -q "^tteh$bench-h11" && break
  sleep 0.05
done
ip netns list | grep -q "^tteh$bench-h11" || fail "the bench made no namespaces: $(cat "$dir/int.log")"
sleep 1
# The namespaces' identities: a process left in one after its name is gone
# still shows it in /proc/PID/ns/net.
for f in /run/netns/tteh$bench-*; do echo "net:[$(stat -L -c %i "$f")]"; done >"$dir/netns"
kill -TERM $bench
for _ in $(seq 100); do kill -0 $bench 2>/dev/null || break; sleep 0.1; done
kill -0 $bench 2>/dev/null && fail "the bench still runs 10 s after SIGTERM"
wait $bench
rc=$?
[[ $rc == 143 ]] || fail "stopped bench exited $rc: $(tail -3 "$dir/int.log")"
left=$(ip netns list | grep -c "^tteh$bench-")
((left == 0)) || fail "$left namespaces left after SIGTERM: $(ip netns list | grep "^tteh$bench-")"
stray=()
for p in /proc/[0-9]*; do
  grep -qxF "$(readlink "$p/ns/net" 2>/dev/null)" "$dir/netns" && stray+=("${p#/proc/}")
done
((${#stray[@]} == 0)) || { fail "processes left in its namespaces: ${stray[*]}"; kill -9 "${stray[@]}"; }

echo "emulated_hosts_test: $((fails == 0 ? 1 : 0)) passed, $fails failed checks"
[[ $fails == 0 ]]
