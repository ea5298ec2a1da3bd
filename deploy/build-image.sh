#!/usr/bin/env bash
# Builds the transtick image (default tag transtick:latest, or $1) from this
# repository with deploy/Dockerfile. Installs docker.io and docker-compose
# from Debian when missing, starts dockerd when none answers, and makes
# debian:bookworm-slim with debootstrap when it cannot be pulled.
set -euo pipefail
# shellcheck source=deploy/common.sh
source "$(dirname "$0")/common.sh"
tt_ensure_docker
tt_pick_clients
tt_ensure_base_image
tt_build_image "${1:-${TRANSTICK_IMAGE:-transtick:latest}}"
