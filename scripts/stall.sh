#!/usr/bin/env bash
# Rehearses a stalled machine: runs a command (by default the whole test
# suite) in a cgroup of its own and freezes every process in it, all at
# once, for STALL seconds every PERIOD seconds. That is what a virtual
# machine whose host stops it, or a laptop that sleeps, does to a cluster
# on one machine: every daemon and client stops together and then runs on
# as if nothing happened, except that the clocks jumped. The daemons must
# not take the gap for silence (docs/design.md, "Liveness"): no worker
# dropped, no frame retried or lost, no image saved half-written.
#
# A test that fails under the freezes and passes without them is a defect
# of this kind, or of the test's own patience (tests/nodes_fixture.h,
# Eventually). The freezes fall at random points of the suite, so one run
# covers different ground from the next; a clean run takes two to three
# minutes with the defaults on 2 cores.
#
# Usage: scripts/stall.sh [--period S] [--stall S] [--build DIR] [--] [COMMAND...]
#   defaults: period 15, stall 6, build/ beside this script, and the command
#   ctest --test-dir BUILD -j2 --timeout 600 --output-on-failure
# Exits with the command's status, or 77 when it cannot make a freezer
# cgroup (it needs root, and cgroup v1's freezer or cgroup v2).
set -uo pipefail
src=$(cd "$(dirname "$0")/.." && pwd)
period=15 stall=6 build=$src/build
while (($#)); do
  case $1 in
    --period) period=$2; shift 2 ;;
    --stall) stall=$2; shift 2 ;;
    --build) build=$2; shift 2 ;;
    --) shift; break ;;
    -h|--help) sed -n '2,21p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    -*) echo "stall: unknown option $1" >&2; exit 2 ;;
    *) break ;;
  esac
done
for n in "$period" "$stall"; do
  [[ $n =~ ^[0-9]+([.][0-9]+)?$ ]] || { echo "stall: $n is not a number of seconds" >&2; exit 2; }
done
(($#)) || set -- ctest --test-dir "$build" -j2 --timeout 600 --output-on-failure

# The freezer: cgroup v1's freezer hierarchy when mounted, else cgroup v2
# (cgroup.freeze, Linux 5.2 and later).
name=transtick-stall.$$
if [[ -d /sys/fs/cgroup/freezer ]]; then
  cg=/sys/fs/cgroup/freezer/$name
  freeze() { echo FROZEN >"$cg/freezer.state"; }
  thaw() { echo THAWED >"$cg/freezer.state"; }
else
  root=/sys/fs/cgroup
  [[ -f $root/cgroup.controllers ]] || root=/sys/fs/cgroup/unified
  cg=$root/$name
  freeze() { echo 1 >"$cg/cgroup.freeze"; }
  thaw() { echo 0 >"$cg/cgroup.freeze"; }
fi
if ! mkdir "$cg" 2>/dev/null; then
  echo "stall: cannot make the cgroup $cg (root and a cgroup freezer are needed)" >&2
  exit 77
fi
if ! freeze 2>/dev/null || ! thaw 2>/dev/null; then
  rmdir "$cg" 2>/dev/null
  echo "stall: $cg cannot be frozen" >&2
  exit 77
fi

# The command, inside the cgroup from its first instruction: its children
# (daemons, clients, browsers) are born there too.
(echo "$BASHPID" >"$cg/cgroup.procs" && exec "$@") &
pid=$!
cleanup() {
  thaw 2>/dev/null
  kill "$pid" 2>/dev/null
  wait "$pid" 2>/dev/null
  # The cgroup goes once its last process has: a straggler keeps it a while.
  for _ in $(seq 50); do rmdir "$cg" 2>/dev/null && break; sleep 0.2; done
}
trap cleanup EXIT
trap 'exit 130' INT TERM

# Sleeps up to $1 seconds, returning early (false) when the command ends.
nap() {
  local until
  until=$(awk -v s="$1" -v now="$(date +%s.%N)" 'BEGIN {printf "%.3f", now + s}')
  while kill -0 "$pid" 2>/dev/null; do
    awk -v u="$until" -v now="$(date +%s.%N)" 'BEGIN {exit !(now < u)}' || return 0
    sleep 0.2
  done
  return 1
}
freezes=0
start=$(date +%s)
while nap "$period"; do
  freeze
  freezes=$((freezes + 1))
  echo "stall: $(date +%T) froze everything for ${stall} s (freeze $freezes)" >&2
  sleep "$stall"
  thaw
done
wait "$pid"
status=$?
echo "stall: $freezes freezes of ${stall} s every ${period} s in $(($(date +%s) - start)) s;" \
  "the command exited with $status" >&2
exit "$status"
