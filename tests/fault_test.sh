#!/usr/bin/env bash
# Faults at random moments: a 3-worker cluster of real daemon processes
# renders a 240-frame job (15 views, each 16 times) while a chaos loop
# kills (SIGKILL, then starts again) or pauses (SIGSTOP, then SIGCONT) a
# random daemon of a random kind every few seconds: workers, the root (on
# its state directory) and the display. The job must complete, and every
# frame must be bit-identical to `transtick render --local 0`. Every daemon
# serves TLS with certificates from deploy/make-certs.sh, as deployed.
#
# Usage: fault_test.sh BUILD_DIR SOURCE_DIR. TRANSTICK_FAULT_SEED replays a
# run (the seed is printed); TRANSTICK_FAULTS sets how many faults (default
# 10); TRANSTICK_KEEP_TEST_DIR keeps the logs.
set -u
build=$1
T="$build/cli/transtick"
dir=$(mktemp -d)
pids=()
cleanup() {
  kill -CONT "${pids[@]}" 2>/dev/null
  kill -9 "${pids[@]}" 2>/dev/null
  if [[ -n ${TRANSTICK_KEEP_TEST_DIR:-} ]]; then echo "kept $dir"; else rm -rf "$dir"; fi
}
trap cleanup EXIT
fails=0
fail() { echo "FAIL: $*"; fails=$((fails + 1)); }
source "$(dirname "${BASH_SOURCE[0]}")/free_port.sh"

"$2/deploy/make-certs.sh" "$dir/certs" 2>/dev/null || { echo "FAIL: make-certs"; exit 1; }
tls() { echo --tls-ca "$dir/certs/ca.crt" --tls-cert "$dir/certs/$1.crt" --tls-key "$dir/certs/$1.key"; }
client=(--tls-ca "$dir/certs/ca.crt" --token-file "$dir/certs/client.token")

seed=${TRANSTICK_FAULT_SEED:-$(date +%N | sed 's/^0*//')}
seed=$((seed % 32768))
faults=${TRANSTICK_FAULTS:-10}
RANDOM=$seed
echo "fault_test: seed $seed (TRANSTICK_FAULT_SEED=$seed replays it), $faults faults"

# A 32x28x24 volume: a block with a hole through it, so views differ.
mkdir -p "$dir/data" "$dir/out"
python3 - "$dir/data/shape.nrrd" <<'PY'
import sys
nx, ny, nz = 32, 28, 24
body = bytearray()
for z in range(nz):
    for y in range(ny):
        for x in range(nx):
            inside = 6 < x < 26 and 5 < y < 23 and 4 < z < 20
            hole = (x - 16) ** 2 + (z - 12) ** 2 < 16
            body.append(200 if inside and not hole else 0)
with open(sys.argv[1], "wb") as f:
    f.write(b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: %d %d %d\nencoding: raw\n\n" % (nx, ny, nz))
    f.write(body)
PY
echo '{"materials":[{"name":"shape","min":100,"max":256,"color":[0.8,0.7,0.6]}]}' >"$dir/m.json"
frames=240 views=15
{
  printf '{"name":"chaos","datasets":[{"volume":"shape.nrrd","materials_file":"m.json","views":['
  for i in $(seq 0 $((frames - 1))); do
    ((i > 0)) && printf ','
    v=$((i % views))
    printf '{"azimuth":%d,"elevation":%d,"width":240,"height":200,"output":"f%d.png"}' \
      $((v * 24)) $((v % 7 * 5 - 15)) "$i"
  done
  printf ']}]}\n'
} >"$dir/job.json"
for v in $(seq 0 $((views - 1))); do
  "$T" render --local 0 --volume "$dir/data/shape.nrrd" --materials "$dir/m.json" \
    --azimuth $((v * 24)) --elevation $((v % 7 * 5 - 15)) --size 240x200 \
    --out "$dir/ref$v.png" 2>/dev/null || fail "reference render $v"
done

dport=$(port)
rport=$(port)
n_display=0 n_root=0 n_worker=0
start_display() {
  n_display=$((n_display + 1))
  # shellcheck disable=SC2046  # the TLS flags are words
  "$build/services/display/transtick-display" --listen 127.0.0.1:$dport $(tls display) \
    >"$dir/display$n_display.log" 2>&1 &
  dpid=$!
  pids+=($dpid)
}
start_root() {
  n_root=$((n_root + 1))
  # shellcheck disable=SC2046
  "$build/services/root/transtick-root" --listen 127.0.0.1:$rport --data-dir "$dir/data" \
    --state-dir "$dir/state" --display 127.0.0.1:$dport $(tls root) --tokens "$dir/certs/tokens" \
    >"$dir/root$n_root.log" 2>&1 &
  rpid=$!
  pids+=($rpid)
}
wpids=()
start_worker() {
  n_worker=$((n_worker + 1))
  # shellcheck disable=SC2046
  "$build/services/worker/transtick-worker" --root 127.0.0.1:$rport --listen 127.0.0.1:0 \
    --threads 1 $(tls worker) >"$dir/worker$n_worker.log" 2>&1 &
  pids+=($!)
  wpids[$1]=$!
}
start_display
start_root
for w in 0 1 2; do start_worker $w; done
for _ in $(seq 100); do
  "$T" status --root 127.0.0.1:$rport "${client[@]}" 2>/dev/null | grep -q '^3 workers' && break
  sleep 0.1
done
"$T" status --root 127.0.0.1:$rport "${client[@]}" | grep -q '^3 workers' || fail "3 workers did not register"

begin=$(date +%s)
timeout 400 "$T" submit "$dir/job.json" --root 127.0.0.1:$rport "${client[@]}" --out-dir "$dir/out" \
  >"$dir/submit.log" 2>&1 &
spid=$!

# The chaos: a fault every 1.5-4 s while the job runs. A pause lasts 0.5-7 s
# (past 5 s a worker is dropped by the root and comes back on its own).
# The first three faults hit each kind once, in a random order.
first=(3 4 $((RANDOM % 3)))
for i in 2 1; do
  j=$((RANDOM % (i + 1)))
  t=${first[$i]} first[$i]=${first[$j]} first[$j]=$t
done
log=()
for n in $(seq "$faults"); do
  sleep "$((RANDOM % 25 + 15))e-1"
  kill -0 "$spid" 2>/dev/null || break
  kind=$((RANDOM % 5))  # 0-2 a worker, 3 the root, 4 the display
  ((n <= 3)) && kind=${first[$((n - 1))]}
  pause=$((RANDOM % 2))
  case $kind in
    3) pid=$rpid what=root ;;
    4) pid=$dpid what=display ;;
    *) pid=${wpids[$kind]} what="worker $kind" ;;
  esac
  if ((pause)); then
    tenths=$((RANDOM % 66 + 5))
    log+=("$(date +%s.%N | cut -c1-14): pause $what ${tenths}00 ms")
    kill -STOP "$pid"
    sleep "${tenths}e-1"
    kill -CONT "$pid"
  else
    log+=("$(date +%s.%N | cut -c1-14): kill $what")
    kill -9 "$pid"
    wait "$pid" 2>/dev/null
    case $kind in
      3) start_root ;;
      4) start_display ;;
      *) start_worker "$kind" ;;
    esac
  fi
done
printf '  %s\n' "${log[@]}"
if wait "$spid"; then
  echo "fault_test: the $frames-frame job done $(($(date +%s) - begin)) s after submission, through ${#log[@]} faults"
else
  fail "the job did not complete through the faults: $(tail -c 600 "$dir/submit.log" | tr '\r' '\n' | tail -4)"
fi
bad=0
for i in $(seq 0 $((frames - 1))); do
  cmp -s "$dir/out/f$i.png" "$dir/ref$((i % views)).png" || bad=$((bad + 1))
done
((bad == 0)) || fail "$bad of $frames frames differ from the in-process render"
rendered=$(cat "$dir"/root*.log | grep -c "frame .* (job-1 ")
echo "fault_test: $n_root root(s), $n_display display(s), $n_worker worker processes; $rendered frame renders for $frames frames"
echo "fault_test: $((fails == 0 ? 1 : 0)) passed, $fails failed checks (seed $seed)"
[[ $fails == 0 ]]
