#!/usr/bin/env bash
# The daemons as separate processes: a job submitted from a job file
# renders the same image as --local 0 (balanced with test rays, so planes
# move between the worker processes), a malformed job file gets a clear
# error, a worker killed with SIGKILL is dropped and the next job still
# renders (the survivors re-cut their slabs without the dead one's planes),
# a worker killed in the middle of a job does not stall it, nor does a worker
# paused with SIGSTOP, a restarted root gets its workers back by itself and
# resumes its jobs from its state directory, a
# job survives the display's restart, no two daemons share a port, a job
# chooses its rings (auto, a number, a refused setting), and every
# daemon stops cleanly on SIGTERM.
set -u
build=$1
src=$2
dir=$(mktemp -d)
pids=()
cleanup() { kill -9 "${pids[@]}" 2>/dev/null; if [[ -n ${TRANSTICK_KEEP_TEST_DIR:-} ]]; then echo "kept $dir"; else rm -rf "$dir"; fi; }
trap cleanup EXIT
fails=0
fail() { echo "FAIL: $*"; fails=$((fails + 1)); }
T=$build/cli/transtick
source "$(dirname "${BASH_SOURCE[0]}")/free_port.sh"

# A 24x20x16 float volume with a bright block in the middle.
mkdir -p "$dir/data"
{
  printf 'NRRD0004\ntype: uint8\ndimension: 3\nsizes: 24 20 16\nencoding: raw\n\n'
  for z in $(seq 0 15); do for y in $(seq 0 19); do for x in $(seq 0 23); do
    if ((x > 5 && x < 18 && y > 4 && y < 15 && z > 3 && z < 12)); then printf '\310'; else printf '\000'; fi
  done; done; done
} >"$dir/data/box.nrrd"
cat >"$dir/m.json" <<'JSON'
{"materials":[{"name":"box","min":100,"max":256,"color":[0.8,0.7,0.6]}]}
JSON
cat >"$dir/job.json" <<JSON
{"name":"t","balance":"test-rays","datasets":[{"volume":"box.nrrd","materials_file":"m.json",
  "views":[{"azimuth":35,"elevation":20,"width":48,"height":40,"output":"a.png"}]}]}
JSON

dport=$(port); rport=$(port)
"$build/services/display/transtick-display" --listen 127.0.0.1:$dport \
  --metrics 127.0.0.1:$(port) >"$dir/display.log" 2>&1 &
pids+=($!); dpid=$!
"$build/services/root/transtick-root" --listen 127.0.0.1:$rport --data-dir "$dir/data" \
  --state-dir "$dir/state" --display 127.0.0.1:$dport >"$dir/root.log" 2>&1 &
pids+=($!); rpid=$!
wpids=()
for i in 1 2 3; do
  "$build/services/worker/transtick-worker" --root 127.0.0.1:$rport --listen 127.0.0.1:0 \
    --threads 1 >"$dir/worker$i.log" 2>&1 &
  pids+=($!); wpids+=($!)
done
for _ in $(seq 100); do
  "$T" status --root 127.0.0.1:$rport 2>/dev/null | grep -q '^3 workers' && break
  sleep 0.1
done
"$T" status --root 127.0.0.1:$rport | grep -q '^3 workers' || fail "3 workers did not register"
# The display started first, but on a loaded machine it may still be coming
# up after the workers registered (the command no longer takes 0.4 s to
# start, which used to hide this).
for _ in $(seq 100); do "$T" health --addr 127.0.0.1:$dport >/dev/null 2>&1 && break; sleep 0.1; done
"$T" health --addr 127.0.0.1:$dport >/dev/null || fail "display not SERVING"
# One line per daemon, from the decoded HealthCheckResponse.
"$T" health --addr 127.0.0.1:$rport,127.0.0.1:$dport >"$dir/health.log" 2>&1 &&
  grep -qx "127.0.0.1:$rport: SERVING" "$dir/health.log" &&
  grep -qx "127.0.0.1:$dport: SERVING" "$dir/health.log" || fail "health: $(cat "$dir/health.log")"

# A port is one daemon's: a second daemon on a taken port fails to start,
# and the workers listening on port 0 were given ports no other daemon holds.
timeout 10 "$build/services/display/transtick-display" --listen 127.0.0.1:$rport \
  --metrics off >"$dir/dup.log" 2>&1 && fail "a display started on the root's port"
grep -q "cannot listen on 127.0.0.1:$rport" "$dir/dup.log" ||
  fail "second daemon on a taken port: $(cat "$dir/dup.log")"
"$T" status --root 127.0.0.1:$rport >"$dir/status.log"
# What the root offers to open, with its size.
"$T" volumes --root 127.0.0.1:$rport >"$dir/volumes.log" 2>&1 &&
  grep -qE "^box.nrrd +[0-9]+ (B|KiB)$" "$dir/volumes.log" ||
  fail "volumes: $(cat "$dir/volumes.log")"
sed -n 's/.* at 127.0.0.1:\([0-9]*\),.*/\1/p' "$dir/status.log" >"$dir/ports"
# Each worker offers its host's memory (no --memory-mb, no cgroup limit
# here unless the machine has one), shown with it.
[[ $(grep -c " MB" "$dir/status.log") == 3 ]] || fail "status shows no worker memory: $(cat "$dir/status.log")"
# And where it runs: the CPUs it may use, of this machine's.
[[ $(grep -c "of its machine's $(getconf _NPROCESSORS_ONLN) CPUs" "$dir/status.log") == 3 ]] ||
  fail "status shows no worker CPUs: $(cat "$dir/status.log")"
[[ $( (cat "$dir/ports"; echo $rport; echo $dport) | sort -u | wc -l) == 5 ]] ||
  fail "daemons share ports: workers on $(tr '\n' ' ' <"$dir/ports"), root $rport, display $dport"

"$T" submit "$dir/job.json" --root 127.0.0.1:$rport --out-dir "$dir/out" >"$dir/submit.log" 2>&1 ||
  fail "submit: $(cat "$dir/submit.log")"
"$T" render --local 0 --volume "$dir/data/box.nrrd" --materials "$dir/m.json" --azimuth 35 \
  --elevation 20 --size 48x40 --out "$dir/ref.png" 2>/dev/null
cmp -s "$dir/out/a.png" "$dir/ref.png" || fail "cluster image differs from --local 0"

# The submitting client dies; `transtick watch` takes the job up and saves
# its image, the same bits.

"$T" submit "$dir/job.json" --root 127.0.0.1:$rport --out-dir "$dir/out2" >"$dir/lost.log" 2>&1 &
lost=$!
for _ in $(seq 100); do grep -q '^job-[0-9]*: 1 frame' "$dir/lost.log" && break; sleep 0.05; done
kill -9 "$lost" 2>/dev/null; wait "$lost" 2>/dev/null
job_id=$(grep -o '^job-[0-9]*' "$dir/lost.log" | head -1)
rm -f "$dir/out2/a.png"
"$T" watch "$job_id" --root 127.0.0.1:$rport --out-dir "$dir/out2" >"$dir/watch.log" 2>&1 ||
  fail "watch $job_id: $(cat "$dir/watch.log")"
cmp -s "$dir/out2/a.png" "$dir/ref.png" || fail "image saved by watch differs: $(cat "$dir/watch.log")"
"$T" watch job-999 --root 127.0.0.1:$rport >"$dir/watch2.log" 2>&1
[[ $? == 1 ]] && grep -q "does not know job-999" "$dir/watch2.log" ||
  fail "watch of an unknown job: $(cat "$dir/watch2.log")"

printf '{"datasets":[{"volume":' >"$dir/bad.json"
"$T" submit "$dir/bad.json" --root 127.0.0.1:$rport >"$dir/bad.log" 2>&1
[[ $? == 2 ]] && grep -q "bad.json" "$dir/bad.log" || fail "malformed job file: $(cat "$dir/bad.log")"

# Rings chosen per job: "auto" (the cluster model; the root logs why), a
# number, and a refused setting naming the field. The image is the same bits.
for rings in '"auto"' 3; do
  sed "s/\"name\":\"t\",/\"name\":\"t\",\"rings\":$rings,/" "$dir/job.json" >"$dir/rings.json"
  rm -f "$dir/out/a.png"
  "$T" submit "$dir/rings.json" --root 127.0.0.1:$rport --out-dir "$dir/out" >"$dir/rings.log" 2>&1 ||
    fail "submit with rings $rings: $(cat "$dir/rings.log")"
  cmp -s "$dir/out/a.png" "$dir/ref.png" || fail "image with rings $rings differs"
done
grep -q "rings auto: .* ring(s) of 3 workers" "$dir/root.log" || fail "no rings auto line in the root's log"
# The three workers share this machine (one boot id): its CPUs are divided.
grep -q "3 worker(s) on 1 host(s) and 1 machine(s)" "$dir/root.log" ||
  fail "the root did not see the workers share a machine: $(grep 'rings auto' "$dir/root.log")"
sed 's/"name":"t",/"name":"t","rings":"many",/' "$dir/job.json" >"$dir/rings.json"
"$T" submit "$dir/rings.json" --root 127.0.0.1:$rport >"$dir/rings.log" 2>&1 &&
  fail "a job with rings \"many\" was accepted"
grep -q "rings: 'many' is neither auto nor a number" "$dir/rings.log" ||
  fail "rings \"many\": $(cat "$dir/rings.log")"

# A worker dies: the root drops it and the next job renders on the others.
kill -9 "${wpids[1]}"
rm -f "$dir/out/a.png"
"$T" submit "$dir/job.json" --root 127.0.0.1:$rport --out-dir "$dir/out" >"$dir/submit2.log" 2>&1 ||
  fail "submit after a worker died: $(cat "$dir/submit2.log")"
cmp -s "$dir/out/a.png" "$dir/ref.png" || fail "image after a worker died differs"

# A worker dies in the middle of a frame: the display sees its deposit
# stream break and aborts the frame at once (not after the root's 600 s
# frame timeout), the root retries it on the survivors, and the job
# completes with the right image.
"$build/services/worker/transtick-worker" --root 127.0.0.1:$rport --listen 127.0.0.1:0 \
  --threads 1 >"$dir/worker4.log" 2>&1 &
pids+=($!); w4=$!
for _ in $(seq 100); do
  "$T" status --root 127.0.0.1:$rport 2>/dev/null | grep -q '^3 workers' && break
  sleep 0.1
done
"$T" status --root 127.0.0.1:$rport | grep -q '^3 workers' || fail "a fourth worker did not register"
{
  printf '{"name":"long","datasets":[{"volume":"box.nrrd","materials_file":"m.json","views":['
  for i in $(seq 80); do
    ((i > 1)) && printf ','
    printf '{"azimuth":35,"elevation":20,"width":320,"height":320,"output":"long.png"}'
  done
  printf ']}]}\n'
} >"$dir/long.json"
"$T" render --local 0 --volume "$dir/data/box.nrrd" --materials "$dir/m.json" --azimuth 35 \
  --elevation 20 --size 320x320 --out "$dir/long_ref.png" 2>/dev/null
start=$(date +%s)
timeout 120 "$T" submit "$dir/long.json" --root 127.0.0.1:$rport --out-dir "$dir/out" \
  >"$dir/submit3.log" 2>&1 &
spid=$!
sleep 1
kill -9 "$w4"
if wait "$spid"; then
  cmp -s "$dir/out/long.png" "$dir/long_ref.png" || fail "image after a worker died mid-job differs"
  grep -q "aborted: a worker's deposit stream broke" "$dir/display.log" ||
    echo "note: the kill fell between frames (no frame was aborted)"
else
  fail "job with a worker killed mid-frame did not complete in 120 s: $(tail -3 "$dir/submit3.log")"
fi
echo "mid-job kill: job done $(($(date +%s) - start)) s after submission"

# A worker paused with SIGSTOP in the middle of a job: it stops renewing its
# registration, the root drops it within seconds (not the 600 s frame
# timeout), retries the frame on the others, and the job completes with the
# right image.
"$build/services/worker/transtick-worker" --root 127.0.0.1:$rport --listen 127.0.0.1:0 \
  --threads 1 >"$dir/worker5.log" 2>&1 &
pids+=($!); w5=$!
for _ in $(seq 100); do
  "$T" status --root 127.0.0.1:$rport 2>/dev/null | grep -q '^3 workers' && break
  sleep 0.1
done
"$T" status --root 127.0.0.1:$rport | grep -q '^3 workers' || fail "a fifth worker did not register"
rm -f "$dir/out/long.png"
start=$(date +%s.%N)
timeout 120 "$T" submit "$dir/long.json" --root 127.0.0.1:$rport --out-dir "$dir/out" \
  --stats "$dir/stats4.json" >"$dir/submit4.log" 2>&1 &
spid=$!
sleep 1
kill -STOP "$w5"
if wait "$spid"; then
  cmp -s "$dir/out/long.png" "$dir/long_ref.png" || fail "image after a worker paused mid-job differs"
  # The frame the pause caught was rendered again, and its statistics say so.
  python3 - "$dir/stats4.json" <<'PY' || fail "no frame's statistics show the retry after the pause"
import json, sys
stats = json.load(open(sys.argv[1]))
assert len(stats) == 80 and all(s["attempts"] >= 1 for s in stats)
retried = [i for i, s in enumerate(stats) if s["attempts"] > 1]
assert retried, "every frame reports 1 attempt"
print("paused worker: frames rendered again:", retried)
PY
else
  fail "job with a worker paused mid-frame did not complete in 120 s: $(tail -3 "$dir/submit4.log")"
fi
printf 'paused worker: 80-frame job done %.1f s after submission\n' "$(echo "$(date +%s.%N) - $start" | bc)"
kill -9 "$w5"

# The root paused with SIGSTOP for 7 s in the middle of a job (a debugger, a
# stalled virtual machine): the workers' heartbeats went unheard meanwhile,
# which is not their silence. No worker is dropped, no frame is rendered
# again, and the job completes with the right image.
for _ in $(seq 100); do
  "$T" status --root 127.0.0.1:$rport 2>/dev/null | grep -q '^2 workers' && break
  sleep 0.1
done
dropped=$(grep -c "dropping worker" "$dir/root.log")
rm -f "$dir/out/long.png"
timeout 120 "$T" submit "$dir/long.json" --root 127.0.0.1:$rport --out-dir "$dir/out" \
  --stats "$dir/stats5.json" >"$dir/submit5.log" 2>&1 &
spid=$!
sleep 1
kill -STOP "$rpid"
sleep 7
kill -CONT "$rpid"
if wait "$spid"; then
  cmp -s "$dir/out/long.png" "$dir/long_ref.png" || fail "image after the root was paused differs"
  grep -q "the root did not run for" "$dir/root.log" || fail "the root did not notice its pause"
  [[ $(grep -c "dropping worker" "$dir/root.log") == "$dropped" ]] ||
    fail "the paused root dropped a worker: $(grep "dropping worker" "$dir/root.log" | tail -1)"
  python3 - "$dir/stats5.json" <<'PY' || fail "a frame was rendered again after the root's pause"
import json, sys
stats = json.load(open(sys.argv[1]))
assert len(stats) == 80, len(stats)
again = [i for i, s in enumerate(stats) if s["attempts"] != 1]
assert not again, f"frames rendered again: {again}"
PY
else
  fail "job with the root paused for 7 s did not complete in 120 s: $(tail -3 "$dir/submit5.log")"
fi
echo "paused root: $(grep -o 'the root did not run for [0-9]* ms' "$dir/root.log" | tail -1)"

# The root killed (SIGKILL) in the middle of a job, with a second job queued
# behind it, and started again on the same state directory: the workers
# register again by themselves (their heartbeat), both clients watch again,
# the running job resumes from its first undelivered frame (frames already
# delivered are not rendered again), the queued job runs, and every image is
# right.
{
  printf '{"name":"turn","datasets":[{"volume":"box.nrrd","materials_file":"m.json","views":['
  for i in $(seq 0 39); do
    ((i > 0)) && printf ','
    printf '{"azimuth":%d,"elevation":20,"width":320,"height":320,"output":"turn%d.png"}' $((i * 9)) "$i"
  done
  printf ']}]}\n'
} >"$dir/turn.json"
for i in $(seq 0 39); do
  "$T" render --local 0 --volume "$dir/data/box.nrrd" --materials "$dir/m.json" --azimuth $((i * 9)) \
    --elevation 20 --size 320x320 --out "$dir/turn_ref$i.png" 2>/dev/null
done
rm -f "$dir/out/a.png"
timeout 180 "$T" submit "$dir/turn.json" --root 127.0.0.1:$rport --out-dir "$dir/out" \
  >"$dir/submit5.log" 2>&1 &
spid=$!
for _ in $(seq 1200); do
  grep -q "queued: 'turn'" "$dir/root.log" && break
  sleep 0.05
done
queued_t=$(grep -c "queued: 't'" "$dir/root.log")
timeout 180 "$T" submit "$dir/job.json" --root 127.0.0.1:$rport --out-dir "$dir/out" \
  >"$dir/submit5b.log" 2>&1 &
spid2=$!
for _ in $(seq 1200); do
  (($(grep -c "queued: 't'" "$dir/root.log") > queued_t)) && break
  sleep 0.05
done
(($(grep -c "queued: 't'" "$dir/root.log") > queued_t)) || fail "the second job was not queued within 60 s"
for _ in $(seq 1200); do
  (($(ls "$dir/out" | grep -c '^turn') >= 5)) && break
  sleep 0.05
done
turn_job=$(grep "queued: 'turn'" "$dir/root.log" | grep -o 'job-[0-9]*' | tail -1)
kill -9 "$rpid"
wait "$rpid" 2>/dev/null
# The frames the client received before the kill: it may still be writing
# the last of them, so count once the count has held for 0.3 s (no root
# sends any more meanwhile). Counted at once, a frame recorded delivered
# could be missing (seen in CI: 5 saved, 6 recorded delivered).
saved_before=$(ls "$dir/out" | grep -c '^turn')
for _ in $(seq 20); do
  sleep 0.3
  now_saved=$(ls "$dir/out" | grep -c '^turn')
  ((now_saved == saved_before)) && break
  saved_before=$now_saved
done
start=$(date +%s.%N)
"$build/services/root/transtick-root" --listen 127.0.0.1:$rport --data-dir "$dir/data" \
  --state-dir "$dir/state" --display 127.0.0.1:$dport >"$dir/root2.log" 2>&1 &
pids+=($!); rpid=$!
for _ in $(seq 100); do
  "$T" status --root 127.0.0.1:$rport 2>/dev/null | grep -q '^2 workers' && break
  sleep 0.1
done
if "$T" status --root 127.0.0.1:$rport | grep -q '^2 workers'; then
  printf 'root restart: both workers registered again %.1f s after the restart\n' \
    "$(echo "$(date +%s.%N) - $start" | bc)"
else
  fail "workers did not register again with a restarted root"
fi
if wait "$spid"; then
  printf 'root restart: the 40-frame job done %.1f s after the restart\n' \
    "$(echo "$(date +%s.%N) - $start" | bc)"
  for i in $(seq 0 39); do
    cmp -s "$dir/out/turn$i.png" "$dir/turn_ref$i.png" || fail "frame $i across a root restart differs"
  done
else
  fail "job across a root restart did not complete: $(tail -3 "$dir/submit5.log")"
fi
wait "$spid2" || fail "queued job across a root restart: $(tail -3 "$dir/submit5b.log")"
cmp -s "$dir/out/a.png" "$dir/ref.png" || fail "image of the queued job after a root restart differs"
# What the new root rendered of the running job: its undelivered frames
# only (a frame or two more when their images were in flight at the kill).
delivered=$(grep -o "$turn_job recovered: [0-9]* of 40" "$dir/root2.log" | awk '{print $3}')
rendered=$(grep -c "($turn_job [0-9]*/[0-9]*)" "$dir/root2.log")
echo "root restart: $saved_before frames saved before the kill, $delivered recorded delivered, $rendered rendered after"
if [[ -z $delivered ]] || ((delivered < 1 || rendered > 40 - delivered + 2 || delivered > saved_before)); then
  fail "resume after a root restart: $delivered of 40 delivered, $rendered rendered again"
fi
grep -q "recovered: 0 of 1 frames delivered" "$dir/root2.log" ||
  fail "the queued job was not recovered: $(grep -h "queued\|recovered" "$dir/root.log" "$dir/root2.log" | tail -5)"

# The display killed in the middle of a job and started again: the root
# retries the frame with backoff until it is back, and the job completes.
rm -f "$dir/out/long.png"
timeout 120 "$T" submit "$dir/long.json" --root 127.0.0.1:$rport --out-dir "$dir/out" \
  >"$dir/submit6.log" 2>&1 &
spid=$!
sleep 1
kill -9 "$dpid"
wait "$dpid" 2>/dev/null
"$build/services/display/transtick-display" --listen 127.0.0.1:$dport >"$dir/display2.log" 2>&1 &
pids+=($!); dpid=$!
if wait "$spid"; then
  cmp -s "$dir/out/long.png" "$dir/long_ref.png" || fail "image after a display restart differs"
else
  fail "job across a display restart did not complete: $(tail -3 "$dir/submit6.log")"
fi

# SIGTERM: every daemon exits 0 within docker's 10 s grace period.
for p in "${wpids[0]}" "${wpids[2]}" "$rpid" "$dpid"; do
  kill -TERM "$p"
  for _ in $(seq 100); do kill -0 "$p" 2>/dev/null || break; sleep 0.1; done
  if kill -0 "$p" 2>/dev/null; then fail "pid $p still running 10 s after SIGTERM"; continue; fi
  wait "$p"; rc=$?
  [[ $rc == 0 ]] || fail "pid $p exited $rc on SIGTERM"
done
# Stopped daemons: health names each one that does not answer, and fails.
"$T" health --addr 127.0.0.1:$rport,127.0.0.1:$dport --timeout 2 >"$dir/health2.log" 2>&1
[[ $? == 1 ]] && grep -q "127.0.0.1:$rport: no daemon answers" "$dir/health2.log" &&
  grep -q "127.0.0.1:$dport: no daemon answers" "$dir/health2.log" ||
  fail "health of stopped daemons: $(cat "$dir/health2.log")"
# JSON lines: every line of a root's log is one JSON object, even for a job
# whose name holds quotes, backslashes and a newline.
jport=$(port)
TRANSTICK_LOG_FORMAT=json "$build/services/root/transtick-root" --listen 127.0.0.1:$jport \
  --data-dir "$dir/data" --display 127.0.0.1:1 --metrics off >"$dir/json.log" 2>&1 &
jpid=$!
for _ in $(seq 100); do "$T" health --addr 127.0.0.1:$jport --timeout 1 >/dev/null 2>&1 && break; sleep 0.1; done
printf '{"name":"a\\"b\\\\c\\nd","datasets":[{"volume":"box.nrrd","materials_file":"m.json","views":[{"width":8,"height":8}]}]}' \
  >"$dir/odd-name.json"
timeout 3 "$T" submit "$dir/odd-name.json" --root 127.0.0.1:$jport --out-dir "$dir/out" \
  >/dev/null 2>&1
kill -TERM $jpid; wait $jpid
python3 -c '
import json, sys
lines = open(sys.argv[1]).read().splitlines()
msgs = [json.loads(l)["msg"] for l in lines]
assert all(set(json.loads(l)) == {"time", "level", "daemon", "msg"} for l in lines)
assert any("queued" in m and "a\"b" in m for m in msgs), msgs
' "$dir/json.log" || fail "JSON log lines: $(cat "$dir/json.log")"

echo "daemons_test: $((fails == 0 ? 1 : 0)) passed, $fails failed checks"
[[ $fails == 0 ]]
