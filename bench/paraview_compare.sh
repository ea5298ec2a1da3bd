#!/usr/bin/env bash
# Times ParaView's CPU ray caster (vtkFixedPointVolumeRayCastMapper, chosen by
# VolumeRenderingMode 'Ray Cast Only') beside transtick on the same volume,
# view and image size, in one run on one machine.
#
#   bench/paraview_compare.sh [BUILD_DIR]
#
# BUILD_DIR (default: build) holds bench/render_bench (preferred) or
# cli/transtick; a relative path is tried from the current directory, then
# from the repository root. Environment:
#   REPEAT=5             timed frames (after one untimed warm-up) per renderer
#   SIZE=400             square image size in pixels
#   AZIMUTH=45           orbit azimuth in degrees (0 looks along -Z)
#   TRANSTICK_DATA_DIR   where cthead.nrrd lives (default: ../shared/data)
#
# Installs paraview, python3-paraview, xvfb and xauth with apt-get when pvbatch
# is missing (needs root or sudo). ParaView renders under xvfb-run, so its
# frame time includes handing the image to (software) OpenGL; the volume
# work itself is the CPU ray caster on every core. The ParaView camera copies
# transtick's orbit camera: 30 degree perspective, the volume's bounding
# sphere framed with 5% margin, +Y up.
#
# Two kinds of work are timed against the one ParaView frame. Surfaces: the
# transfer functions are alike, not equal: transtick shades threshold
# surfaces (skin 600..1350 with opacity 0.3 per crossing, bone >= 1350
# opaque) and casts shadow rays; ParaView composites shaded samples with
# opacity 0.3 (skin) and 1 (bone) per unit distance. Read those ratios as
# orders of magnitude. Dvr: transtick's dvr with ParaView's very transfer
# function (the same points, opacity per unit distance, gradient shading)
# sampled every world unit, as ParaView's mapper samples: the same work.

set -euo pipefail

die() { echo "paraview_compare: $*" >&2; exit 1; }
note() { echo "== $*"; }

script_dir=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
repo_root=$(cd "$script_dir/.." && pwd)

build_arg=${1:-build}
if [[ -d $build_arg ]]; then
  build_dir=$(cd "$build_arg" && pwd)
elif [[ $build_arg != /* && -d $repo_root/$build_arg ]]; then
  build_dir=$repo_root/$build_arg
else
  die "build directory '$build_arg' not found (build first: cmake -S . -B build -G Ninja" \
      "-DCMAKE_BUILD_TYPE=Release && ninja -C build -j2 render_bench)"
fi

repeat=${REPEAT:-5}
size=${SIZE:-400}
azimuth=${AZIMUTH:-45}
[[ $repeat =~ ^[1-9][0-9]*$ ]] || die "REPEAT must be a positive integer, got '$repeat'"
[[ $size =~ ^[1-9][0-9]*$ ]] || die "SIZE must be a positive integer, got '$size'"
[[ $azimuth =~ ^-?[0-9]+(\.[0-9]+)?$ ]] || die "AZIMUTH must be a number, got '$azimuth'"

data_dir=${TRANSTICK_DATA_DIR:-$repo_root/../shared/data}
[[ -d $data_dir ]] || die "data directory $data_dir not found (set TRANSTICK_DATA_DIR)"
data_dir=$(cd "$data_dir" && pwd)
volume=$data_dir/cthead.nrrd
materials=$repo_root/examples/cthead_materials.json
[[ -r $volume ]] || die "cannot read $volume (set TRANSTICK_DATA_DIR to the directory holding cthead.nrrd)"
[[ -r $materials ]] || die "cannot read $materials"

render_bench=$build_dir/bench/render_bench
cli=$build_dir/cli/transtick
if [[ ! -x $render_bench && ! -x $cli ]]; then
  die "neither $render_bench nor $cli exists; build with: ninja -C $build_dir -j2 render_bench"
fi

# --- ParaView -----------------------------------------------------------------

# shellcheck source=bench/paraview_common.sh
source "$script_dir/paraview_common.sh"
ensure_paraview

tmp=$(mktemp -d "${TMPDIR:-/tmp}/paraview_compare.XXXXXX")
trap 'rm -rf "$tmp"' EXIT

cat >"$tmp/pv_bench.py" <<'PYEOF'
# pvbatch script: times ParaView's CPU ray caster on one volume.
#   pvbatch pv_bench.py VOLUME SIZE AZIMUTH REPEAT
import statistics
import sys
import time

import pv_transtick
from pv_transtick import black_background, volume_geometry
from paraview.simple import (ColorBy, GetActiveViewOrCreate, GetColorTransferFunction,
                             GetOpacityTransferFunction, OpenDataFile, Render, Show)

volume, size, azimuth, repeat = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4])

reader = OpenDataFile(volume)  # ParaView 5.11 picks its NrrdReader for .nrrd
if reader is None:
    sys.exit("pv_bench: ParaView cannot open " + volume)
reader.UpdatePipeline()
bounds, dims, spacing = volume_geometry(reader)
arrays = reader.PointData.keys()
if not arrays:
    sys.exit("pv_bench: " + volume + " has no point scalars")
array = arrays[0]
print("pv_bench: %s %dx%dx%d, spacing %g %g %g, %s range %g .. %g" %
      (volume, dims[0], dims[1], dims[2], spacing[0], spacing[1], spacing[2], array,
       *reader.PointData[array].GetRange()))

view = GetActiveViewOrCreate('RenderView')
black_background(view, size)

display = Show(reader, view)
display.SetRepresentationType('Volume')
display.VolumeRenderingMode = 'Ray Cast Only'  # vtkFixedPointVolumeRayCastMapper, CPU
ColorBy(display, ('POINTS', array))
display.Shade = 1

# Like examples/cthead_materials.json: void below 600, skin 600..1350 at 0.3,
# bone from 1350 opaque.
hi = max(4000.0, reader.PointData[array].GetRange()[1])
opacity = GetOpacityTransferFunction(array)
opacity.Points = [0, 0, 0.5, 0, 599.9, 0, 0.5, 0, 600, 0.3, 0.5, 0, 1349.9, 0.3, 0.5, 0,
                  1350, 1, 0.5, 0, hi, 1, 0.5, 0]
color = GetColorTransferFunction(array)
color.RGBPoints = [0, 0, 0, 0, 599.9, 0, 0, 0, 600, 0.92, 0.72, 0.6, 1349.9, 0.92, 0.72, 0.6,
                   1350, 0.96, 0.94, 0.86, hi, 0.96, 0.94, 0.86]
color.ScalarRangeInitialized = 1
opacity.ScalarRangeInitialized = 1

centre = [(bounds[2 * a] + bounds[2 * a + 1]) / 2 for a in range(3)]


def place_camera(az_deg):
    pv_transtick.place_camera(view, bounds, dims, spacing, az_deg)


place_camera(azimuth)
view.CenterOfRotation = centre

start = time.perf_counter()
Render(view)  # warm-up: also builds the mapper's gradient/normal tables
warm_ms = (time.perf_counter() - start) * 1e3

# Each timed frame moves the camera by 0.001 degree (alternately + and -),
# so the view is modified and every Render() really ray casts again.
times = []
for i in range(repeat):
    place_camera(azimuth + (0.001 if i % 2 == 0 else -0.001))
    start = time.perf_counter()
    Render(view)
    times.append((time.perf_counter() - start) * 1e3)
place_camera(azimuth)

print("pv_bench: warm-up %.1f ms; frames %s ms" % (warm_ms, " ".join("%.1f" % t for t in times)))
print("PV_MEDIAN_MS %.3f" % statistics.median(times))
print("PV_MIN_MS %.3f" % min(times))
PYEOF

note "ParaView ${pv_version:-?}: ${size}x${size}, azimuth $azimuth, 'Ray Cast Only', $repeat frames after 1 warm-up"
pv_out=$tmp/pv.out
pv_err=$tmp/pv.err
run_pvbatch "$tmp/pv_bench.py" "$volume" "$size" "$azimuth" "$repeat"
grep '^pv_bench:' "$tmp/pv.out" || true
pv_ms=$(awk '/^PV_MEDIAN_MS/ {print $2}' "$tmp/pv.out")
pv_min=$(awk '/^PV_MIN_MS/ {print $2}' "$tmp/pv.out")
[[ -n $pv_ms ]] || { cat "$tmp/pv.out" "$tmp/pv.err" >&2; die "pvbatch printed no timing"; }

# --- transtick ----------------------------------------------------------------

# ParaView's transfer function (pv_bench.py above) as transtick's.
cat >"$tmp/transfer.json" <<'EOF'
{"points": [{"value": 0, "rgba": [0, 0, 0, 0]}, {"value": 599.9, "rgba": [0, 0, 0, 0]},
            {"value": 600, "rgba": [0.92, 0.72, 0.6, 0.3]},
            {"value": 1349.9, "rgba": [0.92, 0.72, 0.6, 0.3]},
            {"value": 1350, "rgba": [0.96, 0.94, 0.86, 1]},
            {"value": 4000, "rgba": [0.96, 0.94, 0.86, 1]}],
 "reference_step": 1, "shading": true}
EOF

# Writes "median_ms min_ms rays_per_frame" for one shadows setting (or dvr)
# to $tmp/tt_SHADOWS.res and shows what the benchmark printed.
transtick_ms() {
  local shadows=$1 out=$tmp/tt_$1.out res=$tmp/tt_$1.res
  local -a work=(--materials "$materials" --shadows "$shadows")
  [[ $shadows == dvr ]] && work=(--transfer "$tmp/transfer.json" --step 1 --shadows off)
  if [[ -x $render_bench ]]; then
    "$render_bench" --volume "$volume" "${work[@]}" --size "${size}x${size}" \
      --repeat "$repeat" --azimuth "$azimuth" --threads 0 >"$out" ||
      { cat "$out" >&2; die "render_bench failed (shadows $shadows)"; }
    grep -E '^(view|frontal|az|OK|FAIL)' "$out" | sed 's/^/   /'
    # The table row: view threads median min rays/s Mrays/s speedup Mrays/s/c
    # steps/ray ns/step primary + shadow[, samples]
    awk '$1 ~ /^(frontal|az)/ && NF >= 13 {print $3, $4, $11 + $13; exit}' "$out" >"$res"
  else
    # Fallback: the CLI, one process per frame; frame_ms excludes load and scene build.
    local i
    local -a frames=()
    for ((i = 0; i <= repeat; i++)); do
      "$cli" render --volume "$volume" "${work[@]}" --size "${size}x${size}" \
        --azimuth "$azimuth" --out "$tmp/tt.png" --stats "$tmp/tt.json" \
        2>"$out" || { cat "$out" >&2; die "transtick render failed (shadows $shadows)"; }
      ((i == 0)) && continue
      frames+=("$(python3 -c 'import json, sys; print(json.load(open(sys.argv[1]))["frame_ms"])' \
        "$tmp/tt.json")")
    done
    echo "   frames ${frames[*]} ms"
    python3 -c 'import json, statistics, sys
f = [float(x) for x in sys.argv[2:]]
print(statistics.median(f), min(f), json.load(open(sys.argv[1]))["rays"]["total"])' \
      "$tmp/tt.json" "${frames[@]}" >"$res"
  fi
}

if [[ -x $render_bench ]]; then tool=$render_bench; else tool="$cli (no render_bench: fallback)"; fi
note "transtick ($tool): same view, all $(nproc) cores, shadows off"
transtick_ms off
note "transtick: shadows on"
transtick_ms on
note "transtick: dvr, ParaView's transfer function, step 1"
transtick_ms dvr
read -r tt_off tt_off_min tt_off_rays <"$tmp/tt_off.res" || true
read -r tt_on tt_on_min tt_on_rays <"$tmp/tt_on.res" || true
read -r tt_dvr tt_dvr_min tt_dvr_rays <"$tmp/tt_dvr.res" || true
[[ -n ${tt_off:-} && -n ${tt_on:-} && -n ${tt_dvr:-} ]] || die "could not read transtick's timings"

echo
printf '%dx%d, azimuth %s, %d cores, median of %d frames after 1 warm-up\n' \
  "$size" "$size" "$azimuth" "$(nproc)" "$repeat"
printf '  %-34s %10s %10s %16s %14s\n' renderer "median ms" "min ms" "ParaView/this" "this/ParaView"
printf '  %-34s %10.1f %10.1f %16s %14s\n' "ParaView ${pv_version:-?} 'Ray Cast Only'" "$pv_ms" "$pv_min" - -
printf '  %-34s %10.1f %10.1f %15.2fx %13.2fx\n' "transtick, shadows off ($tt_off_rays rays)" \
  "$tt_off" "$tt_off_min" "$(awk -v a="$pv_ms" -v b="$tt_off" 'BEGIN {print a / b}')" \
  "$(awk -v a="$pv_ms" -v b="$tt_off" 'BEGIN {print b / a}')"
printf '  %-34s %10.1f %10.1f %15.2fx %13.2fx\n' "transtick, shadows on ($tt_on_rays rays)" \
  "$tt_on" "$tt_on_min" "$(awk -v a="$pv_ms" -v b="$tt_on" 'BEGIN {print a / b}')" \
  "$(awk -v a="$pv_ms" -v b="$tt_on" 'BEGIN {print b / a}')"
printf '  %-34s %10.1f %10.1f %15.2fx %13.2fx\n' "transtick dvr, step 1 ($tt_dvr_rays rays)" \
  "$tt_dvr" "$tt_dvr_min" "$(awk -v a="$pv_ms" -v b="$tt_dvr" 'BEGIN {print a / b}')" \
  "$(awk -v a="$pv_ms" -v b="$tt_dvr" 'BEGIN {print b / a}')"
