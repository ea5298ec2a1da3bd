#!/usr/bin/env bash
# The transtick command as a user runs it: a render that works, and bad
# input that gets a clear error and the documented exit code.
set -u
bin=$1
src=$2
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
fails=0

# expect CODE PATTERN -- ARGS...: runs transtick, checks exit code and stderr.
expect() {
  local code=$1 pattern=$2
  shift 3
  "$bin" "$@" >"$dir/out" 2>"$dir/err"
  local got=$?
  if [[ $got != "$code" ]] || ! grep -q -- "$pattern" "$dir/err" "$dir/out"; then
    echo "FAIL: transtick $* -> exit $got (want $code), output:"
    cat "$dir/err" "$dir/out"
    fails=$((fails + 1))
  else
    echo "ok: transtick $* -> $code, '$pattern'"
  fi
}

# A 32^3 uint8 volume: a block of value 200 inside zeros.
{
  printf 'NRRD0004\ntype: uint8\ndimension: 3\nsizes: 32 32 32\nencoding: raw\nspacings: 1 1 1\n\n'
  head -c $((32 * 32 * 8)) /dev/zero
  for _ in $(seq 16); do
    for _ in $(seq 8); do head -c 32 /dev/zero; done
    for _ in $(seq 16); do head -c 8 /dev/zero; printf '\310%.0s' $(seq 16); head -c 8 /dev/zero; done
    for _ in $(seq 8); do head -c 32 /dev/zero; done
  done
  head -c $((32 * 32 * 8)) /dev/zero
} >"$dir/cube.nrrd"
cat >"$dir/m.json" <<'JSON'
{"materials":[{"name":"block","min":100,"max":256,"color":[0.8,0.8,0.8]}]}
JSON
cat >"$dir/t.json" <<'JSON'
{"points":[{"value":0,"rgba":[0,0,0,0]},{"value":200,"rgba":[1,1,1,0.5]}]}
JSON

expect 0 "64x64 surfaces" -- render --volume "$dir/cube.nrrd" --materials "$dir/m.json" \
  --size 64x64 --azimuth 30 --out "$dir/a.png" --stats "$dir/s.json"
[[ -s $dir/a.png ]] || { echo "FAIL: no image written"; fails=$((fails + 1)); }
grep -q '"frame_ms"' "$dir/s.json" && grep -q '"workers"' "$dir/s.json" &&
  grep -q '"active_ms"' "$dir/s.json" || { echo "FAIL: cluster stats lack fields"; fails=$((fails + 1)); }
# --local 0: the in-process reference renderer, and the same image.
expect 0 "64x64 surfaces" -- render --local 0 --volume "$dir/cube.nrrd" --materials "$dir/m.json" \
  --size 64x64 --azimuth 30 --out "$dir/a0.png" --stats "$dir/s0.json"
grep -q '"primary"' "$dir/s0.json" && grep -q '"encoded_bytes"' "$dir/s0.json" ||
  { echo "FAIL: stats lack fields"; fails=$((fails + 1)); }
cmp "$dir/a.png" "$dir/a0.png" || { echo "FAIL: cluster and in-process images differ"; fails=$((fails + 1)); }
# An explicit view takes --zoom too (the demo's view): a narrower field, a
# different image.
expect 0 "32x32 surfaces" -- render --local 0 --volume "$dir/cube.nrrd" --materials "$dir/m.json" \
  --size 32x32 --eye=-100,-40,-30 --target 0,0,0 --up 0,-1,0 --out "$dir/e1.png"
expect 0 "32x32 surfaces" -- render --local 0 --volume "$dir/cube.nrrd" --materials "$dir/m.json" \
  --size 32x32 --eye=-100,-40,-30 --target 0,0,0 --up 0,-1,0 --zoom 1.6 --out "$dir/e16.png"
cmp -s "$dir/e1.png" "$dir/e16.png" && { echo "FAIL: --zoom with --eye changed nothing"; fails=$((fails + 1)); }
expect 0 "dvr" -- render --volume "$dir/cube.nrrd" --transfer "$dir/t.json" --size 32x32 \
  --out "$dir/b.exr"
[[ -s $dir/b.exr ]] || { echo "FAIL: no EXR written"; fails=$((fails + 1)); }
expect 0 "values 0 .. 200" -- info --volume "$dir/cube.nrrd"
# A float volume with NaN and infinities: its range and histogram leave them
# out and count them apart (no undefined float-to-int conversion).
python3 -c "
import struct, sys
vals = [float('nan'), float('inf'), -float('inf'), 1.0, 3.0e38, -3.0e38, 2.0, 0.5]
sys.stdout.buffer.write(b'NRRD0004\\ntype: float\\ndimension: 3\\nsizes: 2 2 2\\nencoding: raw\\nendian: little\\n\\n' + struct.pack('<8f', *vals))
" >"$dir/odd.nrrd"
expect 0 "NaN or infinite         37.50%" -- info --volume "$dir/odd.nrrd"
# Output formats come from one list (core's image_io): .hdr is written as
# float, and a format outside the list is refused before anything renders.
expect 0 "16x16 surfaces" -- render --local 0 --volume "$dir/cube.nrrd" --materials "$dir/m.json" \
  --size 16x16 --out "$dir/c.hdr"
[[ -s $dir/c.hdr ]] || { echo "FAIL: no HDR written"; fails=$((fails + 1)); }
expect 2 "c.bmp' is not an image format transtick writes (.png, .jpg" -- render --local 0 \
  --volume "$dir/cube.nrrd" --materials "$dir/m.json" --out "$dir/c.bmp"
[[ -e $dir/c.bmp ]] && { echo "FAIL: .bmp written"; fails=$((fails + 1)); }

expect 2 "9000x10" -- render --volume "$dir/cube.nrrd" --materials "$dir/m.json" --size 9000x10
expect 2 "WxH" -- render --volume "$dir/cube.nrrd" --materials "$dir/m.json" --size big
expect 2 "samples 0 must be in" -- render --local 0 --volume "$dir/cube.nrrd" \
  --materials "$dir/m.json" --samples 0
expect 2 "--surface must be smooth or voxel" -- render --local 0 --volume "$dir/cube.nrrd" \
  --materials "$dir/m.json" --surface bumpy
expect 2 "needs --materials" -- render --volume "$dir/cube.nrrd"
expect 2 "unknown flag --colour" -- render --volume "$dir/cube.nrrd" --colour red
expect 2 "shadows" -- render --volume "$dir/cube.nrrd" --materials "$dir/m.json" --shadows maybe
expect 1 "nope.nrrd" -- render --volume "$dir/nope.nrrd" --materials "$dir/m.json"
head -c 5000 "$dir/cube.nrrd" >"$dir/short.nrrd"
expect 2 "short.nrrd" -- render --local 0 --volume "$dir/short.nrrd" --materials "$dir/m.json"
expect 1 "short.nrrd" -- render --volume "$dir/short.nrrd" --materials "$dir/m.json"
printf '{"materials":[{"name":"x","min":5,"max":1,"color":[1,1,1]}]}' >"$dir/bad.json"
expect 2 "bad.json" -- render --volume "$dir/cube.nrrd" --materials "$dir/bad.json"
expect 2 "unknown command" -- frobnicate
expect 1 "127.0.0.1:1: no daemon answers" -- health --addr 127.0.0.1:1 --timeout 2
expect 2 "empty address" -- health --addr 127.0.0.1:1,

# Every command explains itself, exits 0, and names its own flags.
for cmd in render info submit watch status cancel health version; do
  expect 0 "usage: transtick $cmd" -- "$cmd" --help
  expect 0 "usage: transtick $cmd" -- help "$cmd"
done
expect 0 "--balance-grid N" -- render --help
expect 0 "usage: transtick render" -- render --volume x -h
expect 0 "^transtick [0-9]*\.[0-9]*\.[0-9]* (" -- --version
expect 0 "^transtick [0-9]" -- version
expect 2 "no command 'frob'" -- help frob
# Stray arguments, single-dash words, repeated and contradictory flags.
expect 2 "unexpected argument 'extra'" -- render --volume "$dir/cube.nrrd" \
  --materials "$dir/m.json" extra
expect 2 "unexpected argument 'b.json'" -- submit a.json b.json --root 127.0.0.1:1
expect 2 "needs JOB.json" -- submit --root 127.0.0.1:1
expect 2 "needs JOB_ID" -- watch --root 127.0.0.1:1
expect 2 "'-v' is not a flag" -- render -v
expect 2 "--size is given twice" -- render --size 8x8 --size 9x9
expect 2 "--materials and --transfer contradict" -- render --volume "$dir/cube.nrrd" \
  --materials "$dir/m.json" --transfer "$dir/t.json"
expect 2 "--mode dvr and --materials contradict" -- render --volume "$dir/cube.nrrd" \
  --materials "$dir/m.json" --mode dvr
expect 2 "--eye and --azimuth contradict" -- render --volume "$dir/cube.nrrd" \
  --materials "$dir/m.json" --eye 0,0,100 --target 0,0,0 --azimuth 30
expect 2 "--fov and --projection orthographic" -- render --volume "$dir/cube.nrrd" \
  --materials "$dir/m.json" --projection orthographic --fov 20
expect 2 "--shadows is for surfaces mode" -- render --volume "$dir/cube.nrrd" \
  --transfer "$dir/t.json" --shadows on
expect 2 "--step is dvr's" -- render --volume "$dir/cube.nrrd" --materials "$dir/m.json" --step 0.5
expect 2 "--rings is for a cluster" -- render --local 0 --volume "$dir/cube.nrrd" \
  --materials "$dir/m.json" --rings 2
expect 2 "--root and --local contradict" -- render --root 127.0.0.1:1 --local 2 \
  --volume "$dir/cube.nrrd" --materials "$dir/m.json"
expect 2 "--raw-type describes a raw volume" -- info --volume "$dir/cube.nrrd" --raw-type int16
# No directory is created for an output: the error names the missing one.
expect 1 "directory '$dir/no/such' does not exist" -- render --local 0 --volume "$dir/cube.nrrd" \
  --materials "$dir/m.json" --out "$dir/no/such/x.png"
expect 1 "directory '$dir/no/such' does not exist" -- render --volume "$dir/cube.nrrd" \
  --materials "$dir/m.json" --out "$dir/no/such/x.png"
[[ -e $dir/no ]] && { echo "FAIL: a directory was created"; fails=$((fails + 1)); }
# A material no voxel can show is named, in-process and on a cluster, and
# in the stats; a transparent transfer function likewise.
cat >"$dir/far.json" <<'JSON'
{"materials":[{"name":"block","min":100,"max":256,"color":[0.8,0.8,0.8]},
              {"name":"ghost","min":300,"max":400,"color":[1,1,1]}]}
JSON
expect 0 "warning: material 'ghost' \[300, 400) shows nothing: the volume's values are 0 .. 200" \
  -- render --local 0 --volume "$dir/cube.nrrd" --materials "$dir/far.json" --size 16x16 \
  --out "$dir/w.png" --stats "$dir/w.json"
grep -q "material 'ghost'" "$dir/w.json" || { echo "FAIL: no warning in stats"; fails=$((fails + 1)); }
expect 0 "warning: material 'ghost'" -- render --local 1 --volume "$dir/cube.nrrd" \
  --materials "$dir/far.json" --size 16x16 --out "$dir/w.png" --stats "$dir/w.json"
grep -q "material 'ghost'" "$dir/w.json" || { echo "FAIL: no warning in cluster stats"; fails=$((fails + 1)); }
if "$bin" render --local 0 --volume "$dir/cube.nrrd" --materials "$dir/m.json" --size 16x16 \
  --out "$dir/w.png" 2>&1 | grep -q warning; then
  echo "FAIL: a warning for a material that shows"; fails=$((fails + 1))
fi
printf '{"points":[{"value":0,"rgba":[1,1,1,0]},{"value":250,"rgba":[1,1,1,0]},{"value":260,"rgba":[1,1,1,1]}]}' >"$dir/clear.json"
expect 0 "transfer function is transparent over the whole volume" -- render --local 0 \
  --volume "$dir/cube.nrrd" --transfer "$dir/clear.json" --size 16x16 --out "$dir/w.png"
# Progress outside a terminal: plain lines with the time left.
TRANSTICK_PROGRESS_EVERY=0.2 "$bin" render --local 0 --threads 1 --volume "$dir/cube.nrrd" \
  --materials "$dir/m.json" --size 3000x3000 --samples 2 --out "$dir/big.png" 2>"$dir/progress" >/dev/null
if ! grep -qE '^rendering: +[0-9.]+%, [0-9.]+ s elapsed, time left [0-9]' "$dir/progress" ||
  grep -q $'\r' "$dir/progress"; then
  echo "FAIL: progress lines:"; cat "$dir/progress"; fails=$((fails + 1))
fi
"$bin" render --local 0 --quiet --volume "$dir/cube.nrrd" --materials "$dir/m.json" --size 16x16 \
  --out "$dir/q.png" >"$dir/quiet" 2>&1
[[ -s $dir/quiet ]] && { echo "FAIL: --quiet printed:"; cat "$dir/quiet"; fails=$((fails + 1)); }

# The cube with its axes permuted and flipped (space directions): info names
# the orientation, and the embedded cluster renders what --local 0 does.
{
  printf 'NRRD0004\ntype: uint8\ndimension: 3\nsizes: 32 32 32\nencoding: raw\n'
  printf 'space: right-anterior-superior\nspace directions: (0,1,0) (0,0,-1) (1,0,0)\n'
  printf 'space origin: (5,6,7)\n\n'
  tail -c $((32 * 32 * 32)) "$dir/cube.nrrd"
} >"$dir/oriented.nrrd"
expect 0 "orientation PIR" -- info --volume "$dir/oriented.nrrd"
expect 0 "48x48 surfaces" -- render --volume "$dir/oriented.nrrd" --preset mr-brain --size 48x48 \
  --azimuth 30 --elevation 20 --local 2 --out "$dir/o2.png"
expect 0 "48x48 surfaces" -- render --volume "$dir/oriented.nrrd" --preset mr-brain --size 48x48 \
  --azimuth 30 --elevation 20 --local 0 --out "$dir/o0.png"
cmp "$dir/o2.png" "$dir/o0.png" || { echo "FAIL: oriented cluster and in-process images differ"; fails=$((fails + 1)); }
expect 0 "dvr" -- render --volume "$dir/oriented.nrrd" --preset hot --size 24x24 --local 0 \
  --out "$dir/o3.png"
expect 2 "unknown preset 'ct-bones'" -- render --volume "$dir/cube.nrrd" --preset ct-bones \
  --out "$dir/p.png"
expect 2 "colormap for dvr" -- render --volume "$dir/cube.nrrd" --preset hot --mode surfaces \
  --out "$dir/p.png"
expect 2 "contradict" -- render --volume "$dir/cube.nrrd" --preset ct-bone --materials "$dir/m.json" \
  --out "$dir/p.png"
# A preset's surfaces in the paper's voxel model: the cluster's image is the
# in-process one, and not the smooth one.
expect 0 "48x48 surfaces" -- render --volume "$dir/oriented.nrrd" --preset mr-brain --surface voxel \
  --size 48x48 --azimuth 30 --elevation 20 --local 2 --out "$dir/v2.png"
expect 0 "48x48 surfaces" -- render --volume "$dir/oriented.nrrd" --preset mr-brain --surface voxel \
  --size 48x48 --azimuth 30 --elevation 20 --local 0 --out "$dir/v0.png"
cmp "$dir/v2.png" "$dir/v0.png" || { echo "FAIL: voxel preset: cluster and in-process images differ"; fails=$((fails + 1)); }
cmp -s "$dir/v0.png" "$dir/o0.png" && { echo "FAIL: --surface voxel left the preset's image smooth"; fails=$((fails + 1)); }
expect 2 "surfaces mode" -- render --volume "$dir/cube.nrrd" --preset hot --surface voxel \
  --out "$dir/p.png"

# A DICOM study of two series (written by tests/dicom_study, the third
# argument): the directory alone lists them as the paths that read them;
# each reads by its path, `study#UID` or `study/#UID`, and renders on the
# cluster as in process.
if [[ -n ${3:-} ]]; then
  "$3" "$dir/dicom" >/dev/null || { echo "FAIL: dicom_study wrote no study"; fails=$((fails + 1)); }
  s=$dir/dicom/study
  expect 2 "2 series in one directory" -- info --volume "$s"
  expect 2 "$s#1.2.840.99.12 (CT, series 4, 6 files)" -- info --volume "$s"
  expect 0 "16x16x12" -- info --volume "$s#1.2.840.99.1"
  expect 0 "passed over 1 file that is not DICOM (README.txt)" -- info --volume "$s#1.2.840.99.1"
  expect 0 "16x16x6" -- info --volume "$s/#1.2.840.99.12"
  expect 1 "no series 1.2.840.99 in" -- info --volume "$s#1.2.840.99"
  expect 2 "a missing slice" -- info --volume "$dir/dicom/gap"
  expect 0 "read series 1.2.840.99.1 (CT, series 3 'AX BONE', 12 files) of 2" -- render \
    --volume "$s/#1.2.840.99.1" --preset ct-bone --size 32x32 --azimuth 30 --local 2 --out "$dir/d2.png"
  expect 0 "32x32 surfaces" -- render --volume "$s#1.2.840.99.1" --preset ct-bone --size 32x32 \
    --azimuth 30 --local 0 --out "$dir/d0.png"
  cmp "$dir/d2.png" "$dir/d0.png" || { echo "FAIL: DICOM series: cluster and in-process images differ"; fails=$((fails + 1)); }
  # What a root serving the directory would list: a line per series of the
  # study, and the series with a gap, saying why it would not open.
  expect 0 "^study#1.2.840.99.1 .* DICOM: CT, series 3 'AX BONE', 12 files, 16x16x12$" -- \
    volumes --data-dir "$dir/dicom"
  expect 0 "^study#1.2.840.99.12 .* DICOM: CT, series 4, 6 files, 16x16x6$" -- volumes --data-dir "$dir/dicom"
  expect 0 "^gap .* cannot open: gap: a gap of 2.000 mm" -- volumes --data-dir "$dir/dicom"
  grep -q "^study " "$dir/out" && { echo "FAIL: volumes lists the study's directory itself"; fails=$((fails + 1)); }
fi
expect 2 "give one of --root HOST:PORT and --data-dir DIR" -- volumes
expect 1 "nowhere" -- volumes --data-dir "$dir/nowhere"

echo "cli_test: $fails failed"
[[ $fails == 0 ]]
