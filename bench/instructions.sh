#!/usr/bin/env bash
# Instructions a frame costs, counted: render_bench under valgrind's
# callgrind, collecting only inside TraceRows (the tracer's frame loop:
# camera rays, traversal, crossings, shading, framebuffer), for the smooth
# and the voxel surfaces of cthead at 45 degrees, shadows on, 1 thread.
# Unlike a frame time, the count does not move with the load of a shared
# machine: the same binary gives the same figure on every run, so a change
# to the tracer can be judged by a few tenths of a percent. It does not see
# memory stalls or branch costs; the mispredicts are valgrind's simulated
# predictor, a guide only. Pair it with render_bench or surface_bench for
# times.
#
# Usage: bench/instructions.sh [BUILD_DIR] [WxH]   (defaults: build 200x200)
# Needs valgrind; the volume comes from TRANSTICK_DATA_DIR (default
# ../shared/data beside the repository). Takes about 30 s.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
build=$(cd "${1:-$here/build}" && pwd)
size=${2:-200x200}
export TRANSTICK_DATA_DIR=${TRANSTICK_DATA_DIR:-$here/../shared/data}
command -v valgrind >/dev/null || { echo "instructions: valgrind is not installed" >&2; exit 2; }
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
# The voxel model of the same materials.
sed 's/"materials"/"surface": "voxel", "materials"/' "$here/examples/cthead_materials.json" \
  >"$dir/voxel.json"

# Prints "instructions branches mispredicts" per frame of one surface model.
count() {
  valgrind --tool=callgrind --branch-sim=yes --toggle-collect='transtick::TraceRows*' \
    --callgrind-out-file="$dir/out" "$build/bench/render_bench" --materials "$1" \
    --azimuth 45 --threads 1 --repeat 1 --size "$size" --shadows on >"$dir/log" 2>&1 ||
    { cat "$dir/log" >&2; exit 1; }
  # One warm-up frame and one timed: two frames in the totals.
  local counts
  counts=$(awk '/^totals:/ {printf "%.0f %.0f %.0f\n", $2 / 2, $3 / 2, $4 / 2}' "$dir/out")
  # Nothing counted: the binary has no TraceRows symbol to collect in.
  [[ -n $counts && ${counts%% *} != 0 ]] ||
    { echo "instructions: nothing counted inside transtick::TraceRows in $build/bench/render_bench" >&2; exit 1; }
  echo "$counts"
}
smooth=$(count "$here/examples/cthead_materials.json")
voxel=$(count "$dir/voxel.json")
read -r si sb sm <<<"$smooth"
read -r vi vb vm <<<"$voxel"
echo "instructions per frame: cthead $size, azimuth 45, shadows on, inside TraceRows"
printf '%-8s %14s %14s %14s\n' surface instructions branches mispredicts
printf '%-8s %14s %14s %14s\n' smooth "$si" "$sb" "$sm"
printf '%-8s %14s %14s %14s\n' voxel "$vi" "$vb" "$vm"
awk -v s="$si" -v v="$vi" 'BEGIN {printf "smooth / voxel instructions: %.3f\n", s / v}'
