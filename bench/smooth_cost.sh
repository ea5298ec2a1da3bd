#!/usr/bin/env bash
# What smooth surfaces cost against voxel surfaces, side by side in one run:
# render_bench on cthead.nrrd at 400x400, azimuth 45, shadows on, 1 and 2
# threads, for
#   - the voxel surfaces of BASE, the last commit before smooth surfaces
#     were begun (553426a~1 by default: the day the smooth-surfaces issue
#     was written and its "at most 1.3x the voxel frame" measured), built
#     here in a temporary worktree;
#   - the smooth surfaces of BUILD_DIR (the default model);
#   - the voxel surfaces of BUILD_DIR (`"surface": "voxel"`), which have
#     become faster since BASE.
# Each round runs the three one after the other (each the median of 5
# frames after a warm-up); prints every round and the median ratios of the
# smooth frame to each voxel frame. The voxel frames of BASE and of today
# trace the same rays (the bench prints them).
#
# Usage: bench/smooth_cost.sh [BUILD_DIR] [ROUNDS] [BASE]
#   defaults: build 5 553426a~1. Builds BASE's render_bench (a few minutes
#   the first time; ccache is used when installed). Needs the repository's
#   history (a clone, not an export).
set -euo pipefail
src=$(cd "$(dirname "$0")/.." && pwd)
build=$(cd "${1:-$src/build}" && pwd)
rounds=${2:-5}
base=${3:-553426a~1}
export TRANSTICK_DATA_DIR=${TRANSTICK_DATA_DIR:-$src/../shared/data}
volume=$TRANSTICK_DATA_DIR/cthead.nrrd
[[ -f $volume ]] || { echo "smooth_cost: no cthead.nrrd in $TRANSTICK_DATA_DIR" >&2; exit 1; }
git -C "$src" rev-parse --verify -q "$base^{commit}" >/dev/null ||
  { echo "smooth_cost: no commit $base in $src (a clone with its history is needed)" >&2; exit 1; }
tmp=$(mktemp -d /tmp/transtick-smooth-cost.XXXXXX)
cleanup() {
  git -C "$src" worktree remove --force "$tmp/src" >/dev/null 2>&1 || true
  rm -rf "$tmp"
}
trap cleanup EXIT

git -C "$src" worktree add -q --detach "$tmp/src" "$base"
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
echo "smooth_cost: building render_bench at $(git -C "$src" rev-parse --short "$base")" >&2
cmake -S "$tmp/src" -B "$tmp/build" -G Ninja -DCMAKE_BUILD_TYPE=Release "${launcher[@]}" \
  >"$tmp/cmake.log" 2>&1 || { tail -20 "$tmp/cmake.log" >&2; exit 1; }
ninja -C "$tmp/build" bench/render_bench >"$tmp/ninja.log" 2>&1 ||
  { tail -20 "$tmp/ninja.log" >&2; exit 1; }

python3 - "$src/examples/cthead_materials.json" "$tmp/voxel.json" <<'EOF'
import json, sys
m = json.load(open(sys.argv[1]))
m["surface"] = "VOXEL"
json.dump(m, open(sys.argv[2], "w"))
EOF
# Prints "median_ms rays" of one render_bench run.
frame() {
  "$@" --volume "$volume" --azimuth 45 --repeat 5 2>&1 |
    awk '/^az45/ {print $3, $(NF - 2) "+" $NF}'
}
printf '%-7s %-5s %14s %14s %14s %12s %12s\n' threads round "voxel of base" smooth "voxel today" \
  "smooth/base" "smooth/today"
: >"$tmp/ratios"
for threads in 1 2; do
  for ((r = 0; r < rounds; ++r)); do
    read -r old old_rays < <(frame "$tmp/build/bench/render_bench" --threads "$threads")
    read -r smooth _ < <(frame "$build/bench/render_bench" --threads "$threads")
    read -r voxel voxel_rays < <(frame "$build/bench/render_bench" --materials "$tmp/voxel.json" \
      --threads "$threads")
    if [[ $old_rays != "$voxel_rays" ]]; then
      echo "smooth_cost: the voxel frames traced different rays ($old_rays, $voxel_rays)" >&2
      exit 1
    fi
    read -r a b < <(python3 -c "print(f'{$smooth / $old:.3f} {$smooth / $voxel:.3f}')")
    printf '%-7s %-5s %14s %14s %14s %12s %12s\n' "$threads" "$r" "$old" "$smooth" "$voxel" "$a" "$b"
    echo "$threads $a $b" >>"$tmp/ratios"
  done
done
python3 - "$tmp/ratios" <<'EOF'
import statistics, sys
rows = [l.split() for l in open(sys.argv[1])]
for t in ("1", "2"):
    a = [float(r[1]) for r in rows if r[0] == t]
    b = [float(r[2]) for r in rows if r[0] == t]
    print(f"{t} thread(s): smooth frame / voxel frame of the base {statistics.median(a):.2f} "
          f"(range {min(a):.2f}-{max(a):.2f}); / voxel frame today {statistics.median(b):.2f} "
          f"(range {min(b):.2f}-{max(b):.2f})")
EOF
