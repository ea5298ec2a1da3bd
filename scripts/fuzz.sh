#!/usr/bin/env bash
# Fuzzes what transtick reads from outside for a bounded time, under ASan and
# UBSan (docs/design.md, "Fuzzing"): volume files (volume_fuzzer), job files
# (job_fuzzer), the ray and deposit batches a worker and the display
# receive (batch_fuzzer), and the sticks blocks, brick map, field
# summary and scalars of a slab (sticks_fuzzer). Builds them with clang and libFuzzer into
# build-fuzz/, writes the seed corpora, runs each fuzzer for
# SECONDS_PER_FUZZER seconds (default 60) and fails on any crash, leak,
# undefined behaviour, hang (an input slower than 20 s) or large allocation.
# A failing input is kept under build-fuzz/fuzz/artifacts/. Run by CI, after
# scripts/test.sh has installed the build's packages.
#
# Usage: scripts/fuzz.sh [SECONDS_PER_FUZZER]
# One fuzzer for longer, by hand (after one run of this script):
#   build-fuzz/tests/job_fuzzer -dict=tests/fuzz/job.dict -max_len=4096 \
#       build-fuzz/fuzz/corpus/job build-fuzz/fuzz/seeds/job
# and to replay a failing input: build-fuzz/tests/job_fuzzer FILE
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-60}
if ! [[ $seconds =~ ^[1-9][0-9]*$ ]]; then
  echo "usage: scripts/fuzz.sh [SECONDS_PER_FUZZER]" >&2
  exit 2
fi

# clang, and its libFuzzer and sanitizer runtimes, which Debian ships apart
# (libclang-rt-dev; clang only recommends it).
links_a_fuzzer() {
  command -v clang++ >/dev/null || return 1
  local dir
  dir=$(mktemp -d)
  echo 'extern "C" int LLVMFuzzerTestOneInput(const char*, unsigned long) { return 0; }' \
    >"$dir/probe.cc"
  clang++ -fsanitize=fuzzer,address,undefined "$dir/probe.cc" -o "$dir/probe" 2>/dev/null
  local ok=$?
  rm -rf "$dir"
  return $ok
}
if ! links_a_fuzzer; then
  SUDO=""
  [[ $(id -u) == 0 ]] || SUDO=sudo
  echo "fuzz: installing clang libclang-rt-dev"
  $SUDO apt-get update -q
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends \
    clang libclang-rt-dev
fi

build=${TRANSTICK_FUZZ_BUILD_DIR:-build-fuzz}
# -DTRANSTICK_FUZZ=ON instruments every target (CMakeLists.txt). -O2 -g
# without -DNDEBUG: the DCHECKs stay on, so a hostile input that breaks a
# REQUIRES fails here too.
cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O2 -g" -DCMAKE_CXX_COMPILER=clang++ \
  -DTRANSTICK_FUZZ=ON >/dev/null
ninja -C "$build" -j "$(nproc)" fuzzers

work=$build/fuzz
rm -rf "$work/seeds" "$work/tmp"
"$build/tests/fuzz_seeds" "$work/seeds"
mkdir -p "$work/seeds/job" "$work/seeds/sticks" "$work/artifacts" "$work/tmp"
cp examples/*_job.json tests/fuzz/corpus/job/*.json "$work/seeds/job/"
# Inputs that once failed, kept as seeds so that every run replays them.
cp tests/fuzz/corpus/volume/* "$work/seeds/volume/"
cp tests/fuzz/corpus/batch/* "$work/seeds/batch/"

# UB already aborts (-fno-sanitize-recover); print where.
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1}
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1}
failed=()
for name in volume job batch sticks; do
  mkdir -p "$work/corpus/$name"
  options=(-max_total_time="$seconds" -timeout=20 -rss_limit_mb=2048 -malloc_limit_mb=512
    -max_len=4096 -print_final_stats=1 -artifact_prefix="$work/artifacts/$name-")
  [[ -f tests/fuzz/$name.dict ]] && options+=(-dict="tests/fuzz/$name.dict")
  log=$work/$name.log
  # New inputs go to the first directory, which a later run starts from.
  # The scratch files go to tmp/; stdin is empty, so no input can wait on it.
  rc=0
  TMPDIR=$work/tmp "$build/tests/${name}_fuzzer" "${options[@]}" "$work/corpus/$name" \
    "$work/seeds/$name" </dev/null >"$log" 2>&1 || rc=$?
  runs=$(awk '/^stat::number_of_executed_units:/ {print $2; exit}' "$log")
  rate=$(awk '/^stat::average_exec_per_sec:/ {print $2; exit}' "$log")
  if ((rc == 0)); then
    echo "fuzz: ${name}_fuzzer: ${runs:-?} inputs in ${seconds} s (${rate:-?}/s), no failure"
  else
    echo "fuzz: ${name}_fuzzer FAILED (exit $rc) after ${runs:-?} inputs; the end of $log:"
    tail -n 40 "$log"
    failed+=("${name}_fuzzer")
  fi
done
if ((${#failed[@]})); then
  echo "fuzz: ${failed[*]} failed; inputs in $work/artifacts/ (replay: $build/tests/NAME FILE)"
  exit 1
fi
echo "fuzz: all fuzzers ran ${seconds} s each without a failure"
