#!/usr/bin/env bash
# Builds the daemons' libraries with clang and -Wthread-safety -Werror: the
# compiler checks every ABSL_GUARDED_BY / ABSL_EXCLUSIVE_LOCKS_REQUIRED
# annotation (docs/design.md, "Checks the compiler enforces"). Run by CI.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v clang++ >/dev/null; then
  SUDO=""
  [[ $(id -u) == 0 ]] || SUDO=sudo
  $SUDO apt-get update -q
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends clang
fi
build=${TRANSTICK_TSA_BUILD_DIR:-build-clang}
cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_COMPILER=clang++ \
  -DCMAKE_CXX_FLAGS="-Wthread-safety -Werror=thread-safety" >/dev/null
ninja -C "$build" -j "$(nproc)" transtick_root transtick_worker transtick_display transtick_web transtick_client
echo "thread-safety: the annotated libraries build clean with clang -Wthread-safety"
