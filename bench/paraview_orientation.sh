#!/usr/bin/env bash
# Is an oriented volume the same way up as in ParaView with the same camera?
# Writes a small L-shaped object (a foot along x, a stem along y, the stem
# deeper in z) as a NRRD whose index axes are a permutation with a flip
# (x along world -y, y along world z, z along world x: a reflection), and
# the same object with identity axes. Renders each with transtick (voxel
# surfaces, shadows off) and with ParaView 5.11 (Contour at the same
# threshold), from the same orbit cameras, and compares where the lit
# pixels are: the centroid of the lit pixels and the share of them in each
# quadrant of the image. It fails when an image of transtick's is further
# from ParaView's than the threshold, or nearer to ParaView's mirror image.
#
#   bench/paraview_orientation.sh [BUILD_DIR] [OUT_DIR]
#
# ParaView 5.11's NRRD reader ignores "space directions" (it takes their
# lengths as the spacing and the identity as the direction, as transtick did
# before issue 16), and its Contour filter ignores an image's
# DirectionMatrix (tried: the contour stays in index space). The script
# therefore contours in the file's index space (times spacing) and places
# the contour in world space by the file's direction with a
# vtkTransformPolyDataFilter: ParaView applies the matrix, reflection and
# all, to the geometry, where transtick reverses x and rotates its camera.
# The orbit camera is the one pv_transtick.py gives ParaView elsewhere.
set -euo pipefail

die() { echo "paraview_orientation: $*" >&2; exit 1; }
note() { echo "== $*"; }

script_dir=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
repo_root=$(cd "$script_dir/.." && pwd)
# shellcheck source=bench/paraview_common.sh
source "$script_dir/paraview_common.sh"

build_dir=${1:-$repo_root/build}
out_dir=${2:-$repo_root/out/paraview-orientation}
cli=$build_dir/cli/transtick
[[ -x $cli ]] || die "$cli not found (build first: scripts/setup.sh)"
size=${SIZE:-160}
mkdir -p "$out_dir"
ensure_paraview

tmp=$(mktemp -d "${TMPDIR:-/tmp}/paraview_orientation.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
pv_out=$tmp/pv.out
pv_err=$tmp/pv.err

python3 - "$tmp" <<'PYEOF'
# The L, in world voxels (i, j, k) of a 12 x 10 x 6 grid, spacing 1, 1.5, 2.
import struct, sys
d = sys.argv[1]
nx, ny, nz = 12, 10, 6
def inside(i, j, k):
    foot = 2 <= i < 10 and 2 <= j < 4 and 1 <= k < 3
    stem = 2 <= i < 4 and 2 <= j < 9 and 1 <= k < 5
    return foot or stem
def write(name, header, order):
    with open(f"{d}/{name}", "wb") as f:
        f.write(header.encode())
        for ijk in order:
            f.write(struct.pack("<h", 100 if inside(*ijk) else 0))
write("identity.nrrd",
      "NRRD0004\ntype: int16\ndimension: 3\nsizes: 12 10 6\nencoding: raw\nendian: little\n"
      "space: left-posterior-superior\nspace directions: (1,0,0) (0,1.5,0) (0,0,2)\n"
      "space origin: (0,0,0)\n\n",
      [(i, j, k) for k in range(nz) for j in range(ny) for i in range(nx)])
# Stored sample (p, q, r) is world voxel (r, ny - 1 - p, q).
write("oriented.nrrd",
      "NRRD0004\ntype: int16\ndimension: 3\nsizes: 10 6 12\nencoding: raw\nendian: little\n"
      "space: left-posterior-superior\nspace directions: (0,-1.5,0) (0,0,2) (1,0,0)\n"
      "space origin: (0,0,0)\n\n",
      [(r, ny - 1 - p, q) for r in range(nx) for q in range(nz) for p in range(ny)])
PYEOF
cat >"$tmp/m.json" <<'JSON'
{"materials": [{"name": "L", "min": 50, "max": 200, "color": [1, 1, 1]}], "surface": "VOXEL"}
JSON

cat >"$tmp/pv_orient.py" <<'PYEOF'
# pvbatch script: the NRRD contoured at 50 in index space (times spacing),
# the contour placed in world space by the file's direction, seen from
# transtick's orbit camera.
#   pvbatch pv_orient.py VOLUME "d00 d01 ... d22" SIZE az:AZIMUTH el:ELEVATION OUT.png BENCH_DIR
# (az: and el: keep a negative number from reading as a pvbatch option.)
import math
import sys
sys.path.insert(0, sys.argv[7])
from paraview import simple
from pv_transtick import black_background

# Not "size" or "sum": a Programmable Filter's run puts numpy's names into
# this script's namespace.
path, direction, image_size = sys.argv[1], sys.argv[2], int(sys.argv[3])
az = float(sys.argv[4].split(":")[1])
el = float(sys.argv[5].split(":")[1])
out_png = sys.argv[6]
d = [float(x) for x in direction.split()]
reader = simple.OpenDataFile(path)
contour = simple.Contour(Input=reader, ContourBy=["POINTS", reader.PointData.keys()[0]],
                         Isosurfaces=[50])
placed = simple.ProgrammableFilter(Input=contour)
placed.OutputDataSetType = "vtkPolyData"
placed.Script = (
    "from vtkmodules.vtkCommonTransforms import vtkTransform\n"
    "from vtkmodules.vtkFiltersGeneral import vtkTransformPolyDataFilter\n"
    "t = vtkTransform()\n"
    "d = [%s]\n"
    "t.SetMatrix([d[0], d[1], d[2], 0, d[3], d[4], d[5], 0, d[6], d[7], d[8], 0, 0, 0, 0, 1])\n"
    "f = vtkTransformPolyDataFilter()\n"
    "f.SetTransform(t)\n"
    "f.SetInputData(self.GetInput())\n"
    "f.Update()\n"
    "self.GetOutput().ShallowCopy(f.GetOutput())\n" % ", ".join(repr(x) for x in d))
placed.UpdatePipeline()
print("contour bounds in world space", placed.GetDataInformation().GetBounds())
view = simple.GetActiveViewOrCreate("RenderView")
black_background(view, image_size)
display = simple.Show(placed, view)
simple.ColorBy(display, None)
display.DiffuseColor = [1, 1, 1]
# transtick's orbit is about the volume's centre: the centre of the samples'
# bounds in the file's index space times spacing, placed by the direction.
b = reader.GetDataInformation().GetBounds()
local = [(b[2 * a] + b[2 * a + 1]) / 2 for a in range(3)]
centre = [d[3 * w] * local[0] + d[3 * w + 1] * local[1] + d[3 * w + 2] * local[2] for w in range(3)]
extent = [12 * 1.0, 10 * 1.5, 6 * 2.0]
radius = 0.5 * math.sqrt(math.fsum(x * x for x in extent))
distance = radius / math.sin(math.radians(15)) * 1.05
a, e = math.radians(az), math.radians(el)
view.CameraFocalPoint = centre
view.CameraPosition = [centre[0] + math.sin(a) * math.cos(e) * distance,
                       centre[1] + math.sin(e) * distance,
                       centre[2] + math.cos(a) * math.cos(e) * distance]
view.CameraViewUp = [0, 1, 0] if abs(math.cos(e)) > 1e-6 else [-math.sin(a), 0, -math.cos(a)]
view.CameraViewAngle = 30
simple.Render(view)
simple.SaveScreenshot(out_png, view, ImageResolution=[image_size, image_size])
PYEOF

cat >"$tmp/compare.py" <<'PYEOF'
# pvpython script: where the lit pixels of two PNGs are.
#   pvpython compare.py TRANSTICK.png PARAVIEW.png
import sys
from vtkmodules.vtkIOImage import vtkPNGReader

def lit(path):
    r = vtkPNGReader()
    r.SetFileName(path)
    r.Update()
    img = r.GetOutput()
    w, h, _ = img.GetDimensions()
    s = img.GetPointData().GetScalars()
    n = s.GetNumberOfComponents()
    pts = []
    for y in range(h):
        for x in range(w):
            v = sum(s.GetComponent((y * w + x), c) for c in range(min(3, n)))
            if v > 24:
                pts.append((x, h - 1 - y))  # VTK's rows run bottom-up; make y = 0 the top row
    return w, h, pts

def describe(w, h, pts):
    if not pts:
        return None
    cx = sum(p[0] for p in pts) / len(pts) / w
    cy = sum(p[1] for p in pts) / len(pts) / h
    q = [0, 0, 0, 0]
    for x, y in pts:
        q[(1 if x >= w / 2 else 0) + (2 if y >= h / 2 else 0)] += 1
    return cx, cy, [c / len(pts) for c in q]

w, h, t = lit(sys.argv[1])
_, _, p = lit(sys.argv[2])
dt, dp = describe(w, h, t), describe(w, h, p)
mirror = describe(w, h, [(w - 1 - x, y) for x, y in p])
flip = describe(w, h, [(x, h - 1 - y) for x, y in p])
def dist(a, b):
    return abs(a[0] - b[0]) + abs(a[1] - b[1]) + sum(abs(x - y) for x, y in zip(a[2], b[2]))
print("transtick centroid %.3f %.3f quadrants %s" % (dt[0], dt[1], " ".join("%.2f" % c for c in dt[2])))
print("paraview  centroid %.3f %.3f quadrants %s" % (dp[0], dp[1], " ".join("%.2f" % c for c in dp[2])))
d, dm, df = dist(dt, dp), dist(dt, mirror), dist(dt, flip)
print("distance to paraview %.3f, to its left-right mirror %.3f, to its upside-down %.3f" % (d, dm, df))
print("RESULT", "same" if d < 0.15 and d < dm and d < df else "DIFFERENT")
PYEOF

fails=0
for view in "0 0" "90 0" "30 25" "-120 -20" "0 90"; do
  read -r az el <<<"$view"
  for name in identity oriented; do
    direction="1 0 0 0 1 0 0 0 1"
    # Row-major, the index axes as columns: x -> -y, y -> z, z -> x.
    [[ $name == oriented ]] && direction="0 0 1 -1 0 0 0 1 0"
    tag="$name-az${az}-el${el}"
    "$cli" render --local 0 --volume "$tmp/$name.nrrd" --materials "$tmp/m.json" --size "${size}x$size" \
      --azimuth "$az" --elevation "$el" --shadows off --out "$out_dir/$tag-transtick.png" >/dev/null 2>&1 ||
      die "transtick render of $tag failed"
    run_pvbatch "$tmp/pv_orient.py" "$tmp/$name.nrrd" "$direction" "$size" "az:$az" "el:$el" \
      "$out_dir/$tag-paraview.png" "$script_dir" || die "pvbatch failed for $tag: $(tail -5 "$pv_err")"
    xvfb-run -a pvpython "$tmp/compare.py" "$out_dir/$tag-transtick.png" "$out_dir/$tag-paraview.png" \
      >"$tmp/cmp.out" 2>/dev/null || die "comparison of $tag failed"
    note "$tag"
    grep -v '^$' "$tmp/cmp.out"
    grep -q "RESULT same" "$tmp/cmp.out" || fails=$((fails + 1))
  done
done
((fails == 0)) || die "$fails image(s) differ from ParaView's"
note "every view: transtick's lit pixels lie where ParaView's do (images in $out_dir)"
