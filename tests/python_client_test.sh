#!/usr/bin/env bash
# The Python client against real daemons: a display, a root and two workers
# on loopback, and Debian's Python (python3-grpcio, python3-numpy,
# python3-pil) running tests/python_client_test.py.
set -u
build=$1
src=$2
python=${TRANSTICK_PYTHON:-/usr/bin/python3}
dir=$(mktemp -d)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null; done
  wait 2>/dev/null
  rm -rf "$dir"
}
trap cleanup EXIT
source "$(dirname "${BASH_SOURCE[0]}")/free_port.sh"

mkdir -p "$dir/data"
"$python" - "$dir/data/box.nrrd" <<'PY'
import sys
nx, ny, nz = 24, 20, 16
voxels = bytes(200 if 5 < x < 18 and 4 < y < 15 and 3 < z < 12 else 0
               for z in range(nz) for y in range(ny) for x in range(nx))
with open(sys.argv[1], "wb") as f:
    f.write(b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 24 20 16\nencoding: raw\n\n" + voxels)
PY
dport=$(port); rport=$(port)
"$build/services/display/transtick-display" --listen 127.0.0.1:$dport --metrics off \
  >"$dir/display.log" 2>&1 &
pids+=($!)
"$build/services/root/transtick-root" --listen 127.0.0.1:$rport --data-dir "$dir/data" \
  --display 127.0.0.1:$dport --metrics off >"$dir/root.log" 2>&1 &
pids+=($!)
for _ in 1 2; do
  "$build/services/worker/transtick-worker" --root 127.0.0.1:$rport --listen 127.0.0.1:0 \
    --threads 1 --metrics off >>"$dir/workers.log" 2>&1 &
  pids+=($!)
done
for _ in $(seq 100); do
  "$build/cli/transtick" status --root 127.0.0.1:$rport 2>/dev/null | grep -q '^2 workers' && break
  sleep 0.1
done
TRANSTICK_ROOT=127.0.0.1:$rport TRANSTICK_TEST_DATA="$dir/data" TRANSTICK_BIN="$build/cli/transtick" \
  PYTHONPATH="$build/clients/python" "$python" "$src/tests/python_client_test.py"
rc=$?
if ((rc != 0)); then
  echo "--- root log"; tail -20 "$dir/root.log"
fi
exit $rc
