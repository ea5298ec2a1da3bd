#!/usr/bin/env bash
# Every speed figure of transtick in one run, each paired and repeated by
# the bench that measures it (this machine is shared: compare within a run):
#   1. in process: frame time on 1 thread and on every core, rays/s per
#      core, traversal steps per ray and the frame's ns per step, for smooth
#      and for voxel surfaces (render_bench, cthead 400x400, 45 degrees,
#      shadows on), and with valgrind installed the instructions a frame
#      costs, which the load does not move (bench/instructions.sh);
#   2. the cluster: the embedded cluster of 1, 2 and 4 workers against the
#      in-process frame in the same rounds, and the summed tracer CPU of N
#      workers over 1 (cluster_bench scaling); what packing a frame's
#      deposits and the display's ingest cost per deposit (cluster_bench
#      deposits);
#   3. balance: tracer CPU max/mean before and after balancing, 2, 4 and 8
#      workers, frontal and 45 degrees (cluster_bench tables), and over
#      60-frame jobs of one view, as measured frames refine the cuts, 4 and
#      8 workers (cluster_bench refine);
#   4. a turntable through 2 worker daemons: steady frames/s, frame time,
#      and the time a one-frame job on a loaded dataset spends outside its
#      frame (bench/turntable.sh), smooth and voxel;
#   5. with --paraview, ParaView 5.11's CPU ray caster on the same work
#      (bench/paraview_compare.sh; installs ParaView when missing).
#
# Usage: bench/speed.sh [--paraview] [BUILD_DIR]
# Takes about 12 minutes (16 with ParaView) on 2 cores.
set -euo pipefail
src=$(cd "$(dirname "$0")/.." && pwd)
paraview=0
if [[ ${1:-} == --paraview ]]; then
  paraview=1
  shift
fi
build=${1:-$src/build}
export TRANSTICK_DATA_DIR=${TRANSTICK_DATA_DIR:-$src/../shared/data}
volume=$TRANSTICK_DATA_DIR/cthead.nrrd
[[ -f $volume ]] || { echo "speed: no cthead.nrrd in $TRANSTICK_DATA_DIR" >&2; exit 1; }
tmp=$(mktemp -d /tmp/transtick-speed.XXXXXX)
trap 'rm -rf "$tmp"' EXIT
python3 - "$src/examples/cthead_materials.json" "$tmp/voxel.json" <<'EOF'
import json, sys
m = json.load(open(sys.argv[1]))
m["surface"] = "VOXEL"
json.dump(m, open(sys.argv[2], "w"))
EOF
section() { printf '\n== %s\n' "$1"; }

section "1. in process (render_bench): smooth surfaces"
"$build/bench/render_bench" --volume "$volume" --azimuth 45 --repeat 8
section "1. in process (render_bench): voxel surfaces"
"$build/bench/render_bench" --volume "$volume" --materials "$tmp/voxel.json" --azimuth 45 --repeat 8
if command -v valgrind >/dev/null; then
  section "1. in process: instructions a frame (bench/instructions.sh)"
  bash "$src/bench/instructions.sh" "$build"
fi

section "2. cluster over in-process (cluster_bench scaling, smooth)"
"$build/bench/cluster_bench" scaling --volume "$volume" --repeat 5
section "2. cluster over in-process (cluster_bench scaling, voxel)"
"$build/bench/cluster_bench" scaling --volume "$volume" --materials "$tmp/voxel.json" --repeat 5

section "2. deposits on their way to the display (cluster_bench deposits)"
"$build/bench/cluster_bench" deposits --volume "$volume" --repeat 9

section "3. balance before and after (cluster_bench tables)"
"$build/bench/cluster_bench" tables --volume "$volume"
section "3. balance refined by measured frames over 60-frame jobs (cluster_bench refine)"
"$build/bench/cluster_bench" refine --volume "$volume" --workers 4,8 --repeat 60

section "4. turntable through 2 worker daemons (bench/turntable.sh)"
"$src/bench/turntable.sh" "$build" 2 30 3 smooth
"$src/bench/turntable.sh" "$build" 2 30 3 voxel

if ((paraview)); then
  section "5. against ParaView 5.11 (bench/paraview_compare.sh)"
  "$src/bench/paraview_compare.sh" "$build"
fi
