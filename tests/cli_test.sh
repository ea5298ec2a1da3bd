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

echo "cli_test: $fails failed"
[[ $fails == 0 ]]
