#!/usr/bin/env bash
# Installs what transtick needs from Debian's packages (when missing) and
# builds it into build/ (Release, Ninja, ccache). Used by demo.sh, test.sh
# and CI. Runs as root on Debian bookworm; uses sudo when not root.
set -euo pipefail
cd "$(dirname "$0")/.."

packages=(build-essential cmake ninja-build ccache pkg-config git
  libabsl-dev libprotobuf-dev protobuf-compiler libgrpc++-dev protobuf-compiler-grpc
  libspdlog-dev libopenimageio-dev libgtest-dev libgmock-dev zlib1g-dev libsqlite3-dev
  libbz2-dev liblz4-dev liblzma-dev libcpp-httplib-dev libgdcm-dev openssl curl
  iproute2  # ip and tc: the emulated hosts' namespaces and links (tests/emulated_hosts_test.sh)
  python3-grpcio python3-protobuf python3-numpy python3-pil
  chromium)  # the web viewer's browser test (tests/web_viewer_test.sh)
# Node.js and npm for the browser test's driver: Debian's, unless the machine
# has them already (from any package).
if ! type -P node >/dev/null || ! type -P npm >/dev/null; then packages+=(nodejs npm); fi

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  SUDO=""
  [[ $(id -u) == 0 ]] || SUDO=sudo
  echo "setup: installing ${missing[*]}"
  $SUDO apt-get update -q
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
fi

build=${TRANSTICK_BUILD_DIR:-build}
cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
ninja -C "$build" -j "$(nproc)"
