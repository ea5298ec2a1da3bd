#!/usr/bin/env bash
# The demo: installs and builds transtick, fetches a real head (the UNC MRI
# head brainsmall.den from Debian's libvolpack1-dev, unpacked without
# installing) and renders skin and brain to out/brain.png.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh

den=/usr/share/doc/libvolpack1-dev/examples/brainsmall.den
if [[ ! -f $den ]]; then
  cache=.cache/volpack
  den=$cache/usr/share/doc/libvolpack1-dev/examples/brainsmall.den
  if [[ ! -f $den ]]; then
    mkdir -p "$cache"
    (cd "$cache" && apt-get download libvolpack1-dev && dpkg-deb -x libvolpack1-dev_*.deb .)
  fi
fi

mkdir -p out
build=${TRANSTICK_BUILD_DIR:-build}
"$build/cli/transtick" render --volume "$den" --materials examples/brain_materials.json \
  --eye=-250,-100,-60 --target 0,0,0 --up 0,-1,0 --zoom 1.6 --size 400x400 --shadows on \
  --samples 4 --out out/brain.png --stats out/brain.json
echo "demo: wrote out/brain.png and out/brain.json"
