#!/usr/bin/env bash
# The deployment test, for real: builds the image, brings up a root, a
# display and 4 workers in 2 rings with docker compose, renders a job on a
# real volume with the client from this host, checks the images are
# bit-identical to `transtick render --local 0` (one process, same image, so
# same binary and floating point), scales to 2 workers without touching the
# root, renders again, stops everything (each daemon must exit on SIGTERM
# within the grace period) and removes it, leaving no container, network or
# volume of the test behind.
#
#   deploy/test.sh                # everything (CI runs this)
#   deploy/test.sh --build-only   # docker, base image, image build, compose config
#
# Needs root or sudo (installs docker.io, docker-compose and debootstrap
# from Debian when missing, and starts dockerd when none answers) and the
# volume TRANSTICK_TEST_VOLUME (default cthead.nrrd) in TRANSTICK_DATA
# (default ../shared/data beside the repository).
set -euo pipefail
# shellcheck source=deploy/common.sh
source "$(dirname "$0")/common.sh"
cd "$TT_REPO"

build_only=0
[[ ${1:-} == --build-only ]] && build_only=1

image=${TRANSTICK_TEST_IMAGE:-transtick:test}
data=$(cd "${TRANSTICK_DATA:-$TT_REPO/../shared/data}" 2>/dev/null && pwd) || data=""
volume=${TRANSTICK_TEST_VOLUME:-cthead.nrrd}
project=transtick-test-$$
client=$TT_REPO/build/cli/transtick
passed=0
failed=0
t0=$SECONDS

pass() { passed=$((passed + 1)); tt_log "ok: $*"; }
fail() { failed=$((failed + 1)); tt_log "FAIL: $*"; }
finish() {
  tt_log "done in $((SECONDS - t0)) s"
  echo "deploy: $passed passed, $failed failed"
  ((failed == 0))
}

# ---------------------------------------------------------------- docker
step=$SECONDS
tt_ensure_docker
tt_pick_clients
tt_log "docker client $TT_DOCKER ($("$TT_DOCKER" version --format '{{.Client.Version}}')," \
  "server $("$TT_DOCKER" version --format '{{.Server.Version}}')), compose: ${TT_COMPOSE[*]}" \
  "($("${TT_COMPOSE[@]}" version --short 2>/dev/null || true))"
tt_ensure_base_image
tt_log "docker ready in $((SECONDS - step)) s"

# Compose projects of earlier runs that were killed before cleaning up.
for stale in $("$TT_DOCKER" ps -a --format '{{.Label "com.docker.compose.project"}}' | sort -u |
  grep '^transtick-test-' || true); do
  tt_log "removing stale project $stale"
  TRANSTICK_IMAGE=$image "${TT_COMPOSE[@]}" -p "$stale" -f deploy/docker-compose.yml \
    down -v --remove-orphans -t 10 >/dev/null 2>&1 || true
done

# ---------------------------------------------------------------- image
tt_build_image "$image"
"$TT_DOCKER" image prune -f --filter label=org.opencontainers.image.title=transtick >/dev/null || true
for b in transtick transtick-root transtick-worker transtick-display transtick-web; do
  if "$TT_DOCKER" run --rm --network none --entrypoint sh "$image" -c "command -v $b" >/dev/null; then
    pass "image has $b"
  elif ((build_only)); then
    tt_log "image has no $b (yet)"
  else
    fail "image has no $b"
  fi
done

export TRANSTICK_IMAGE=$image TRANSTICK_DATA=${data:-/nonexistent} TRANSTICK_RINGS=2
# A fixed free port (not 0): a restarted root container must come back on
# the address its client watches.
root_port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])' 2>/dev/null ||
  echo $((20000 + RANDOM % 20000)))
export TRANSTICK_ROOT_PORT=$root_port  # published on 127.0.0.1, the default
export TRANSTICK_METRICS_PORT=0         # the root's /metrics: any free port
export TRANSTICK_WEB_PORT=0             # the web gateway's HTTPS: any free port
compose() { "${TT_COMPOSE[@]}" -p "$project" -f deploy/docker-compose.yml "$@"; }
if compose config -q; then pass "compose file accepted by ${TT_COMPOSE[*]}"; else fail "compose config"; fi
if ((build_only)); then finish; exit; fi
((failed == 0)) || { finish; exit 1; }

# ---------------------------------------------------------------- inputs
if [[ -z $data || ! -f $data/$volume ]]; then
  fail "no volume $volume in ${TRANSTICK_DATA:-../shared/data}"
  finish
  exit 1
fi
if [[ -f build/build.ninja ]]; then
  ninja -C build transtick >/dev/null
else
  scripts/setup.sh >/dev/null
fi

work=$(mktemp -d /tmp/transtick-deploy.XXXXXX)
chmod 755 "$work"
mkdir -p "$work/ref" "$work/cluster4" "$work/cluster2"
# TLS on every port: the cluster's CA, certificates and tokens, the
# daemons' files owned by the image's user (docs/security.md).
"$TT_REPO/deploy/make-certs.sh" "$work/secrets" --uid 10001 2>/dev/null
export TRANSTICK_SECRETS=$work/secrets
client_tls=(--tls-ca "$work/secrets/ca.crt" --token-file "$work/secrets/client.token")

cleanup() {
  local rc=$?
  if ((rc != 0 || failed != 0)); then
    tt_log "logs of $project (last 60 lines each):"
    compose logs --no-color --tail=60 >&2 2>/dev/null || true
  fi
  compose down -v --remove-orphans -t 10 >/dev/null 2>&1 || true
  rm -rf "$work"
}
trap cleanup EXIT

materials='{"materials":[
  {"name":"skin","min":600,"max":1350,"color":[0.92,0.72,0.6],"opacity":0.3},
  {"name":"bone","min":1350,"max":4000,"color":[0.96,0.94,0.86],"opacity":1.0}]}'
echo "$materials" >"$work/materials.json"
# Two views; the reference renders below use the same parameters as flags.
cat >"$work/job.json" <<EOF
{"name":"deploy-test","balance":"test-rays","datasets":[{"volume":"$volume","materials":$materials,"views":[
  {"azimuth":45,"width":200,"height":200,"shadows":true,"output":"view45.png"},
  {"azimuth":120,"elevation":20,"width":160,"height":120,"shadows":true,"output":"view120.png"}]}]}
EOF
views=("view45.png|--azimuth 45 --size 200x200"
  "view120.png|--azimuth 120 --elevation 20 --size 160x120")

# The reference: one process, no gRPC, from the same image.
step=$SECONDS
for v in "${views[@]}"; do
  out=${v%%|*}
  # shellcheck disable=SC2086  # the view's flags are words
  "$TT_DOCKER" run --rm --network none --user "$(id -u):$(id -g)" \
    -v "$data:/data:ro" -v "$work:/work" "$image" \
    transtick render --local 0 --volume "/data/$volume" --materials /work/materials.json \
    --shadows on ${v#*|} --out "/work/ref/$out" >/dev/null
done
tt_log "reference renders in $((SECONDS - step)) s"

# ---------------------------------------------------------------- cluster
# `transtick status` starts with "N workers, R ring(s)". Prints N, or -1 when
# the root does not answer.
root_addr=""
status_counts() {
  "$client" status --root "$root_addr" "${client_tls[@]}" 2>/dev/null |
    sed -n -E '1s/^([0-9]+) workers?, ([0-9]+) rings?.*/\1 \2/p' | grep . || echo "-1 -1"
}
workers_registered() { status_counts | cut -d' ' -f1; }
wait_workers() {
  local want=$1 deadline=$((SECONDS + ${2:-90})) n=-1
  while ((SECONDS < deadline)); do
    n=$(workers_registered)
    ((n == want)) && return 0
    sleep 1
  done
  tt_log "root has $n workers registered, want $want"
  return 1
}
healthy_workers() {
  local n=0 id
  for id in $(compose ps -q worker); do
    [[ $("$TT_DOCKER" inspect -f '{{.State.Health.Status}}' "$id") == healthy ]] && n=$((n + 1))
  done
  echo "$n"
}
# The client's progress lines go to a file; its last words are shown on failure.
submit() {
  local rc=0
  timeout "${TRANSTICK_TEST_TIMEOUT:-300}" "$client" submit "$work/job.json" --root "$root_addr" "${client_tls[@]}" \
    --out-dir "$work/$1" >"$work/$1.log" 2>&1 || rc=$?
  ((rc == 0)) || tt_log "submit exited with $rc: $(tail -c 400 "$work/$1.log" | tr '\r' '\n' | tail -3)"
  return $rc
}
compare() {
  local dir=$1 what=$2 v out
  for v in "${views[@]}"; do
    out=${v%%|*}
    if [[ ! -s $work/$dir/$out ]]; then
      fail "$what: no $out saved"
    elif cmp -s "$work/ref/$out" "$work/$dir/$out"; then
      pass "$what: $out is bit-identical to transtick render --local 0"
    else
      fail "$what: $out differs from transtick render --local 0"
    fi
  done
}

step=$SECONDS
if compose up -d --no-build --scale worker=4; then
  pass "compose up with 4 workers and 2 rings"
else
  fail "compose up"
  exit 1
fi
root_addr=$(compose port root 7000 | tail -1)
root_id=$(compose ps -q root)
root_started=$("$TT_DOCKER" inspect -f '{{.State.StartedAt}}' "$root_id")
if wait_workers 4; then pass "4 workers registered with the root"; else fail "4 workers registered"; fi
if "$client" status --root "$root_addr" --tls-ca "$work/secrets/ca.crt" >/dev/null 2>&1; then
  fail "the root answered a client without a token"
else
  pass "the root refuses a client without a token"
fi
if "$client" status --root "$root_addr" >/dev/null 2>&1; then
  fail "the root answered plaintext"
else
  pass "the root refuses plaintext"
fi
rings=$(status_counts | cut -d' ' -f2)
if [[ $rings == 2 ]]; then pass "root forms 2 rings"; else fail "root forms $rings rings, not 2"; fi
# The root's /metrics: HTTPS with its certificate, as a Prometheus scrape
# with the cluster's CA would see it.
metrics_port=$(compose port root 7100 | tail -1 | sed 's/.*://')
if curl -s -f -m 10 --cacert "$work/secrets/ca.crt" \
  --resolve "transtick-root:$metrics_port:127.0.0.1" "https://transtick-root:$metrics_port/metrics" |
  grep -q '^transtick_root_workers 4$'; then
  pass "the root's /metrics over HTTPS counts 4 workers"
else
  fail "the root's /metrics over HTTPS"
fi
# The web viewer's gateway: HTTPS with web.crt (signed by the cluster's CA
# for 127.0.0.1); it holds no token and passes each browser's on.
web_port=$(compose port web 8443 | tail -1 | sed 's/.*://')
web="https://127.0.0.1:$web_port"
web_curl() { curl -s -m 10 --cacert "$work/secrets/ca.crt" "$@"; }
deadline=$((SECONDS + 30))
until web_curl -f "$web/healthz" >/dev/null 2>&1 || ((SECONDS > deadline)); do sleep 1; done
# The page is read whole before grep: with pipefail, `curl | grep -q` fails
# when grep leaves at the first match while curl still has a TLS record to
# write (curl exits 23).
page=$(web_curl -f "$web/" || true)
if grep -q '<html' <<<"$page"; then pass "the web gateway serves the viewer page over HTTPS"; else fail "the viewer page over HTTPS"; fi
code=$(web_curl -o /dev/null -w '%{http_code}' "$web/api/status")
if [[ $code == 401 ]]; then pass "the web gateway refuses a browser without a token"; else fail "web /api/status without a token: $code"; fi
if web_curl -f -H "Authorization: Bearer $(cat "$work/secrets/client.token")" "$web/api/status" |
  python3 -c 'import json,sys; sys.exit(len(json.load(sys.stdin)["workers"]) != 4)'; then
  pass "the web gateway lists 4 workers with the client's token"
else
  fail "web /api/status with the client's token"
fi
deadline=$((SECONDS + 60))
while (($(healthy_workers) < 4 && SECONDS < deadline)); do sleep 1; done
if (($(healthy_workers) == 4)); then pass "4 workers healthy"; else fail "$(healthy_workers) of 4 workers healthy"; fi
tt_log "cluster of 4 up in $((SECONDS - step)) s"

step=$SECONDS
if submit cluster4; then
  pass "job rendered on 4 workers in $((SECONDS - step)) s"
else
  fail "job on 4 workers"
fi
compare cluster4 "4 workers, 2 rings"

# Scale down between jobs: only the workers change.
step=$SECONDS
compose up -d --no-build --no-deps --no-recreate --scale worker=2 worker
if wait_workers 2 30; then pass "2 workers registered after scaling down"; else fail "scale down to 2"; fi
if [[ $(compose ps -q root) == "$root_id" &&
  $("$TT_DOCKER" inspect -f '{{.State.StartedAt}}' "$root_id") == "$root_started" ]]; then
  pass "root kept running while the workers were scaled"
else
  fail "root was restarted or recreated by the scaling"
fi
if submit cluster2; then
  pass "job rendered on 2 workers in $((SECONDS - step)) s"
else
  fail "job on 2 workers"
fi
compare cluster2 "2 workers, 2 rings"

# The root container killed (SIGKILL) while a job runs, and started again:
# it takes the job up from its state volume (frames already delivered are
# not rendered again), the client watches again by itself, the images are
# right, and the jobs before are still in its history.
step=$SECONDS
{
  printf '{"name":"deploy-restart","datasets":[{"volume":"%s","materials":%s,"views":[' "$volume" "$materials"
  # Long enough (2 x 40 frames) that the kill lands in the middle of the job
  # even when the client is slow to see it running.
  for i in $(seq 40); do
    ((i > 1)) && printf ','
    printf '{"azimuth":45,"width":200,"height":200,"shadows":true,"output":"view45.png"},'
    printf '{"azimuth":120,"elevation":20,"width":160,"height":120,"shadows":true,"output":"view120.png"}'
  done
  printf ']}]}\n'
} >"$work/restart.json"
timeout "${TRANSTICK_TEST_TIMEOUT:-300}" "$client" submit "$work/restart.json" --root "$root_addr" "${client_tls[@]}" \
  --out-dir "$work/restart" >"$work/restart.log" 2>&1 &
spid=$!
deadline=$((SECONDS + 60))
until grep -E 'RUNNING +[1-9]' <<<"$("$client" status --root "$root_addr" "${client_tls[@]}" 2>/dev/null)" >/dev/null; do
  ((SECONDS < deadline)) || break
  sleep 0.2
done
"$TT_DOCKER" kill "$root_id" >/dev/null
compose start root >/dev/null 2>&1
if wait "$spid"; then
  pass "job across a root kill and restart done in $((SECONDS - step)) s"
else
  fail "job across a root kill and restart: $(tail -c 400 "$work/restart.log" | tr '\r' '\n' | tail -3)"
fi
compare restart "across a root restart"
# Not `| grep -q`: with pipefail, grep leaving at the first match makes the
# writer die of SIGPIPE once the log outgrows the pipe, and the test fail.
if grep "recovered: [0-9]* of 80 frames delivered" <<<"$(compose logs --no-color root 2>/dev/null)" >/dev/null; then
  pass "the restarted root took the job up from its state volume"
else
  fail "the restarted root did not recover the job from its state volume"
fi
if (($("$client" status --root "$root_addr" "${client_tls[@]}" 2>/dev/null | grep -c ' DONE ') >= 3)); then
  pass "the jobs before the restart are still in the root's history"
else
  fail "the root's history after a restart: $("$client" status --root "$root_addr" "${client_tls[@]}" 2>&1 | tail -4)"
fi

# ---------------------------------------------------------------- teardown
# Stop first to read the exit codes: 137 means SIGKILL after the grace period.
step=$SECONDS
ids=$(compose ps -q)
compose stop -t 10 >/dev/null 2>&1
codes=$(for id in $ids; do "$TT_DOCKER" inspect -f '{{.Name}}={{.State.ExitCode}}' "$id"; done)
if grep -qvE '=(0|143)$' <<<"$codes"; then
  fail "not every daemon exited on SIGTERM: $(tr '\n' ' ' <<<"$codes")"
else
  pass "every daemon exited on SIGTERM within the grace period ($((SECONDS - step)) s)"
fi
compose down -v --remove-orphans -t 10 >/dev/null 2>&1
left=$("$TT_DOCKER" ps -aq --filter "label=com.docker.compose.project=$project")
left+=$("$TT_DOCKER" network ls -q --filter "label=com.docker.compose.project=$project")
left+=$("$TT_DOCKER" volume ls -q --filter "label=com.docker.compose.project=$project")
if [[ -z $left ]]; then pass "no container, network or volume left"; else fail "left behind: $left"; fi

finish
