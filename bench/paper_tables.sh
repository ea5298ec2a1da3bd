#!/usr/bin/env bash
# The paper's Table 1 and Table 2 measured today: builds transtick when
# needed and runs `cluster_bench tables` on cthead.nrrd at 400x400, or on
# the volume and materials given.
#
#   bench/paper_tables.sh [VOLUME MATERIALS [more cluster_bench flags]]
#
# Table 1: per worker elapsed, active and tracer CPU times for 2 and 4
# workers, frontal and 45 degree views, without and with balancing.
# Table 2: frame time for 2, 4 and 8 workers and the relative efficiency
# T_2W / ((n/2) T_nW). On a machine with fewer cores than workers the
# elapsed times say little; read the active and summed CPU columns.
set -euo pipefail
cd "$(dirname "$0")/.."
build=${TRANSTICK_BUILD_DIR:-build}
[[ -x "$build/bench/cluster_bench" ]] || scripts/setup.sh
ninja -C "$build" cluster_bench >/dev/null
args=()
if (($# >= 2)); then
  args=(--volume "$1" --materials "$2")
  shift 2
fi
exec "$build/bench/cluster_bench" tables "${args[@]}" "$@"
