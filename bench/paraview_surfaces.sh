#!/usr/bin/env bash
# Side by side with ParaView's contour filter: the same volume, thresholds,
# camera and light rendered by ParaView 5.11 (pvbatch, Contour at each
# interval's lower edge, Phong with the materials' coefficients, one
# directional light at transtick's camera-relative direction) and by
# transtick with smooth and with voxel surfaces. Writes PNGs and prints how
# far apart the images are.
#
#   bench/paraview_surfaces.sh [BUILD_DIR] [OUT_DIR]
#
# OUT_DIR (default out/paraview) gets, for each volume, NAME-paraview.png,
# NAME-smooth.png, NAME-voxel.png and the three in a row, NAME-side.png
# (ParaView, smooth, voxel). Environment:
#   SIZE=400 AZIMUTH=45 ELEVATION=0 SAMPLES=4 SHADOWS=off
#   VOLUMES="cthead.nrrd:examples/cthead_materials.json ..."  (in TRANSTICK_DATA_DIR)
#   TRANSTICK_DATA_DIR   default ../shared/data
# Shadows are off by default: ParaView's rasteriser casts none.
#
# The images differ where the models do: ParaView draws each contour as a
# mesh of triangles from marching cubes on the same trilinear field (flat
# within a triangle, normals from the point gradients), transtick hits the
# field exactly. A translucent skin shows its back faces too in ParaView
# (depth peeling); transtick shades a surface only where a ray enters a
# material, as the paper does.
set -euo pipefail

die() { echo "paraview_surfaces: $*" >&2; exit 1; }
note() { echo "== $*"; }

script_dir=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
repo_root=$(cd "$script_dir/.." && pwd)
# shellcheck source=bench/paraview_common.sh
source "$script_dir/paraview_common.sh"

build_dir=${1:-$repo_root/build}
out_dir=${2:-$repo_root/out/paraview}
cli=$build_dir/cli/transtick
[[ -x $cli ]] || die "$cli not found (build first: scripts/setup.sh)"
size=${SIZE:-400}
azimuth=${AZIMUTH:-45}
elevation=${ELEVATION:-0}
samples=${SAMPLES:-4}
shadows=${SHADOWS:-off}
data_dir=${TRANSTICK_DATA_DIR:-$repo_root/../shared/data}
volumes=${VOLUMES:-"cthead.nrrd:examples/cthead_materials.json engine.nrrd:examples/engine_materials.json"}
mkdir -p "$out_dir"
ensure_paraview

tmp=$(mktemp -d "${TMPDIR:-/tmp}/paraview_surfaces.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
pv_out=$tmp/pv.out
pv_err=$tmp/pv.err

cat >"$tmp/pv_contour.py" <<'PYEOF'
# pvbatch script: a contour per material, shaded like transtick's.
#   pvbatch pv_contour.py VOLUME MATERIALS.json SIZE AZIMUTH ELEVATION OUT.png
import json
import math
import sys
from paraview.simple import (AddLight, ColorBy, Contour, GetActiveViewOrCreate, OpenDataFile,
                             Render, SaveScreenshot, Show)
from pv_transtick import black_background, place_camera, volume_geometry

volume, materials_path, size = sys.argv[1], sys.argv[2], int(sys.argv[3])
azimuth, elevation, out = float(sys.argv[4]), float(sys.argv[5]), sys.argv[6]
materials = json.load(open(materials_path))["materials"]
reader = OpenDataFile(volume)
if reader is None:
    sys.exit("pv_contour: ParaView cannot open " + volume)
reader.UpdatePipeline()
bounds, dims, spacing = volume_geometry(reader)
array = reader.PointData.keys()[0]
view = GetActiveViewOrCreate('RenderView')
black_background(view, size)
for m in materials:
    contour = Contour(Input=reader)
    contour.ContourBy = ['POINTS', array]
    contour.Isosurfaces = [m["min"]]
    contour.ComputeNormals = 1  # from the point gradients, as transtick shades
    d = Show(contour, view)
    ColorBy(d, None)
    d.AmbientColor = d.DiffuseColor = m["color"]
    d.Opacity = m.get("opacity", 1.0)
    d.Ambient = m.get("ambient", 0.25)
    d.Diffuse = m.get("diffuse", 0.7)
    d.Specular = m.get("specular", 0.25)
    d.SpecularPower = m.get("shininess", 24)
    d.SpecularColor = [1, 1, 1]
    d.Interpolation = 'Gouraud'
view.EnableRenderOnInteraction = 0
# transtick's light: camera-relative (-0.35, 0.5, 1), directional; no light
# kit, no headlight.
for attr in ('UseLight', 'LightSwitch'):
    try:
        setattr(view, attr, 0)
    except AttributeError:
        pass
light = AddLight(view=view)
light.Coords = 'Camera'
light.Type = 'Directional'
light.Position = [-0.35, 0.5, 1.0]
light.FocalPoint = [0, 0, 0]
light.Intensity = 1.0
place_camera(view, bounds, dims, spacing, azimuth)
if elevation:
    view.CameraPosition = view.CameraPosition  # orbit elevation: ParaView's Elevation
    from paraview.simple import GetActiveCamera
    GetActiveCamera().Elevation(elevation)
Render(view)
SaveScreenshot(out, view, ImageResolution=[size, size])
print("pv_contour: wrote", out)
PYEOF

for entry in $volumes; do
  file=${entry%%:*} mats=${entry#*:}
  [[ $mats = /* ]] || mats=$repo_root/$mats
  volume=$data_dir/$file
  [[ -r $volume ]] || { echo "skip $file: not in $data_dir"; continue; }
  [[ -r $mats ]] || die "cannot read $mats"
  name=${file%%.*}
  note "$name: ParaView contour"
  run_pvbatch "$tmp/pv_contour.py" "$volume" "$mats" "$size" "$azimuth" "$elevation" \
    "$out_dir/$name-paraview.png"
  for surface in smooth voxel; do
    note "$name: transtick, $surface surfaces, $samples samples per pixel, shadows $shadows"
    "$cli" render --local 0 --volume "$volume" --materials "$mats" --surface "$surface" \
      --azimuth "$azimuth" --elevation "$elevation" --size "${size}x${size}" \
      --samples "$samples" --shadows "$shadows" --out "$out_dir/$name-$surface.png"
  done
done
cat >"$tmp/side.py" <<'PYEOF'
# pvpython script: OUT.png = the PNGs given, left to right.
import sys
from vtkmodules.vtkFiltersCore import vtkImageAppend
from vtkmodules.vtkIOImage import vtkPNGReader, vtkPNGWriter
append = vtkImageAppend()
append.SetAppendAxis(0)
for path in sys.argv[2:]:
    reader = vtkPNGReader()
    reader.SetFileName(path)
    reader.Update()
    append.AddInputData(reader.GetOutput())
append.Update()
writer = vtkPNGWriter()
writer.SetFileName(sys.argv[1])
writer.SetInputData(append.GetOutput())
writer.Write()
PYEOF
for entry in $volumes; do
  name=${entry%%:*}
  name=${name%%.*}
  [[ -f $out_dir/$name-voxel.png ]] || continue
  pvpython "$tmp/side.py" "$out_dir/$name-side.png" "$out_dir/$name-paraview.png" \
    "$out_dir/$name-smooth.png" "$out_dir/$name-voxel.png" ||
    die "could not put the $name images side by side"
done
echo "paraview_surfaces: images in $out_dir"
