#!/usr/bin/env bash
# The viewer page (services/web/static) in a real headless browser against a
# real `transtick view`: an embedded cluster of 2 workers with the web
# gateway in front. tests/web/viewer_test.mjs drives Debian's Chromium with
# playwright-core: it opens cthead.nrrd, drags, zooms, toggles shadows,
# edits a material, and compares the page's frames with `transtick render`
# pixel for pixel; it checks the workers table, the histogram and the job
# list (a job submitted with `transtick submit`, and one cancelled from the
# page).
#
#   tests/web_viewer_test.sh BUILD_DIR [DATA_DIR]
#
# DATA_DIR (default $TRANSTICK_DATA_DIR, else ../shared/data beside the
# repository) must hold cthead.nrrd; without it the test is skipped (exit 77).
# playwright-core (the version pinned in tests/web/package.json) is installed
# into BUILD_DIR/web-test with npm the first time. Set TRANSTICK_SCREENSHOT=FILE
# to save a screenshot of the page (docs/images/viewer.png is made so), and
# TRANSTICK_WEB_STATIC=DIR to serve the page from DIR instead of the copy
# compiled into the gateway.
set -u
build=${1:?usage: tests/web_viewer_test.sh BUILD_DIR [DATA_DIR]}
build=$(cd "$build" && pwd)
here=$(cd "$(dirname "$0")" && pwd)
data=${2:-${TRANSTICK_DATA_DIR:-$here/../../shared/data}}
chromium=${TRANSTICK_CHROMIUM:-/usr/bin/chromium}
bin=$build/cli/transtick

if [[ ! -f $data/cthead.nrrd ]]; then
  echo "web_viewer_test: skipped: no cthead.nrrd in $data"
  exit 77
fi
data=$(cd "$data" && pwd)
for tool in node npm; do
  command -v $tool >/dev/null || { echo "web_viewer_test: $tool not found (apt-get install nodejs npm)"; exit 1; }
done
[[ -x $chromium ]] || { echo "web_viewer_test: $chromium not found (apt-get install chromium)"; exit 1; }
[[ -x $bin ]] || { echo "web_viewer_test: $bin not found: build first"; exit 1; }

# playwright-core, once per build directory (again when package.json changes).
mods=$build/web-test
if [[ ! -f $mods/node_modules/playwright-core/package.json ]] ||
   ! cmp -s "$here/web/package.json" "$mods/package.json"; then
  mkdir -p "$mods"
  cp "$here/web/package.json" "$mods/package.json"
  rm -f "$mods/package-lock.json"
  echo "web_viewer_test: installing playwright-core into $mods"
  # npm's cache in the build directory too: nothing is written to $HOME.
  if ! npm install --prefix "$mods" --cache "$mods/.npm-cache" --no-audit --no-fund --loglevel=error; then
    rm -f "$mods/package.json"   # so the next run tries again
    echo "web_viewer_test: npm install failed"
    exit 1
  fi
fi

dir=$(mktemp -d)
view_pid=
cleanup() {
  if [[ -n $view_pid ]] && kill -0 "$view_pid" 2>/dev/null; then
    kill -TERM "$view_pid" 2>/dev/null
    for _ in $(seq 100); do kill -0 "$view_pid" 2>/dev/null || break; sleep 0.1; done
    kill -KILL "$view_pid" 2>/dev/null
  fi
  wait 2>/dev/null
  rm -rf "$dir"
}
trap cleanup EXIT
trap 'exit 1' INT TERM

# The data directory the viewer serves: the head, and a DICOM study written
# by tests/dicom_study beside it when that is built.
study=0
if [[ -x $build/tests/dicom_study ]]; then
  mkdir "$dir/data"
  cp "$data/cthead.nrrd" "$dir/data/"
  "$build/tests/dicom_study" "$dir/data" >/dev/null || { echo "web_viewer_test: dicom_study failed"; exit 1; }
  data=$dir/data
  study=1
fi

static=()
[[ -n ${TRANSTICK_WEB_STATIC:-} ]] && static=(--static-dir "$TRANSTICK_WEB_STATIC")
start=$(date +%s%N)
"$bin" view --local 2 --data-dir "$data" --listen 127.0.0.1:0 "${static[@]}" \
  >"$dir/view.out" 2>"$dir/view.err" &
view_pid=$!

url= root=
for _ in $(seq 600); do
  url=$(sed -n 's|^transtick view: \(http://[^ ]*\)$|\1|p' "$dir/view.out" | head -1)
  root=$(sed -n 's|^transtick view: root \([^ ]*\)$|\1|p' "$dir/view.out" | head -1)
  [[ -n $url && -n $root ]] && break
  kill -0 "$view_pid" 2>/dev/null || break
  sleep 0.1
done
if [[ -z $url || -z $root ]]; then
  echo "web_viewer_test: transtick view printed no 'transtick view: http://...' and 'transtick view: root ...' lines"
  echo "--- stdout"; cat "$dir/view.out"
  echo "--- stderr"; tail -30 "$dir/view.err"
  exit 1
fi
echo "web_viewer_test: $url (root $root) up in $(( ($(date +%s%N) - start) / 1000000 )) ms"

TRANSTICK_VIEW_URL=$url TRANSTICK_ROOT=$root TRANSTICK_BIN=$bin TRANSTICK_DATA_DIR=$data TRANSTICK_STUDY=$study \
  WEB_TEST_DIR=$mods WEB_TEST_TMP=$dir TRANSTICK_CHROMIUM=$chromium \
  timeout 170 node "$here/web/viewer_test.mjs"
rc=$?
if ((rc != 0)); then
  echo "--- transtick view stderr (last 30 lines)"
  tail -30 "$dir/view.err"
fi
exit $rc
