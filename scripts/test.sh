#!/usr/bin/env bash
# Installs and builds transtick, then runs every test.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
build=${TRANSTICK_BUILD_DIR:-build}
ctest --test-dir "$build" -j "$(nproc)" --output-on-failure
