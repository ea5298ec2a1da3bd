# Shared by deploy/build-image.sh and deploy/test.sh (source it; it only
# defines functions and variables). Runs as root on Debian bookworm, or uses
# sudo; everything comes from Debian's packages and nothing is pulled from a
# registry except, when it can be, debian:bookworm-slim itself.
# shellcheck shell=bash
#
#   tt_ensure_docker      installs docker.io and docker-compose when missing,
#                         starts dockerd when none answers (log: TT_DOCKERD_LOG)
#   tt_pick_clients       sets TT_DOCKER (a client that can build with BuildKit
#                         when one is here) and TT_COMPOSE (docker compose v2,
#                         else docker-compose 1.29; TRANSTICK_COMPOSE=v1|v2
#                         chooses, and v2 is fetched from Debian when missing)
#   tt_ensure_base_image  makes debian:bookworm-slim with debootstrap and
#                         docker import when the daemon does not have it
#   tt_build_image TAG    builds deploy/Dockerfile from the repository's
#                         source files into TAG
#   tt_log ...            one timestamped line on stderr

TT_REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
TT_DOCKERD_LOG=${TT_DOCKERD_LOG:-/var/log/transtick-dockerd.log}
TT_BASE_IMAGE=debian:bookworm-slim
TT_SUDO=""
[[ $(id -u) == 0 ]] || TT_SUDO=sudo

tt_log() { printf '%s deploy: %s\n' "$(date +%H:%M:%S)" "$*" >&2; }

tt_apt_install() {
  local missing=() p
  for p in "$@"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  ((${#missing[@]})) || return 0
  tt_log "installing ${missing[*]}"
  $TT_SUDO apt-get update -q >/dev/null
  DEBIAN_FRONTEND=noninteractive $TT_SUDO apt-get install -y -q --no-install-recommends \
    "${missing[@]}" >/dev/null
}

tt_ensure_docker() {
  # docker.io brings dockerd, containerd, runc and docker-init (for `init: true`);
  # iptables for its bridge networks; debootstrap for the base image.
  tt_apt_install docker.io docker-compose debootstrap iptables ca-certificates
  if /usr/bin/docker info >/dev/null 2>&1; then return 0; fi
  if pgrep -x dockerd >/dev/null; then
    tt_log "dockerd is running but does not answer yet"
  else
    tt_log "starting dockerd (log: $TT_DOCKERD_LOG)"
    # setsid: dockerd outlives this script and is not in its process group.
    $TT_SUDO setsid dockerd >>"$TT_DOCKERD_LOG" 2>&1 </dev/null &
  fi
  local i
  for ((i = 0; i < 60; i++)); do
    /usr/bin/docker info >/dev/null 2>&1 && return 0
    sleep 1
  done
  tt_log "dockerd did not come up in 60 s; last lines of $TT_DOCKERD_LOG:"
  tail -20 "$TT_DOCKERD_LOG" >&2 || true
  return 1
}

tt_pick_clients() {
  # BuildKit honours deploy/Dockerfile.dockerignore and keeps a ccache
  # directory between builds. Docker 23 and later build with BuildKit only
  # through the buildx plugin; the 20.10 client of Debian's docker.io has it
  # built in (DOCKER_BUILDKIT=1). A machine may have both clients on PATH.
  TT_DOCKER=""
  TT_BUILDKIT=0
  local d major
  for d in $(type -ap docker); do
    if "$d" buildx version >/dev/null 2>&1; then
      TT_DOCKER=$d TT_BUILDKIT=1
      break
    fi
    major=$("$d" version --format '{{.Client.Version}}' 2>/dev/null | cut -d. -f1)
    if [[ $major =~ ^[0-9]+$ ]] && ((major >= 19 && major < 23)); then
      TT_DOCKER=$d TT_BUILDKIT=1
      break
    fi
  done
  if [[ -z $TT_DOCKER ]]; then
    TT_DOCKER=$(type -P docker)
    tt_log "no docker client with BuildKit here: using the classic builder (no ccache)"
  fi
  # TRANSTICK_COMPOSE: v2 (docker compose), v1 (docker-compose 1.29), or
  # auto (v2 when this machine has it).
  case ${TRANSTICK_COMPOSE:-auto} in
    v2)
      tt_compose_v2 || return 1
      ;;
    v1)
      if ! type -P docker-compose >/dev/null; then
        tt_log "docker-compose 1.29 is not installed"
        return 1
      fi
      # shellcheck disable=SC2034  # used by the scripts that source this file
      TT_COMPOSE=(docker-compose)
      ;;
    *)
      if "$TT_DOCKER" compose version >/dev/null 2>&1; then
        # shellcheck disable=SC2034
        TT_COMPOSE=("$TT_DOCKER" compose)
      elif type -P docker-compose >/dev/null; then
        # shellcheck disable=SC2034
        TT_COMPOSE=(docker-compose)
      else
        tt_log "neither 'docker compose' nor docker-compose is installed"
        return 1
      fi
      ;;
  esac
}

# The Debian mirror this machine's apt uses (the URI of its first source
# that is not the security archive), from deb822 .sources files or the
# one-line format; empty when none is configured, and the tools' defaults
# apply.
tt_apt_mirror() {
  local f uri
  for f in /etc/apt/sources.list.d/*.sources; do
    [[ -f $f ]] || continue
    uri=$(awk '/^URIs:/ { for (i = 2; i <= NF; i++) if ($i !~ /security/) { print $i; exit } }' "$f")
    [[ -n $uri ]] && { echo "$uri"; return 0; }
  done
  for f in /etc/apt/sources.list /etc/apt/sources.list.d/*.list; do
    [[ -f $f ]] || continue
    uri=$(awk '$1 == "deb" && $0 !~ /security/ { for (i = 2; i <= NF; i++) if ($i ~ /:\/\//) { print $i; exit } }' "$f")
    [[ -n $uri ]] && { echo "$uri"; return 0; }
  done
  return 0
}

# Docker Compose v2 as a CLI plugin: the one on this machine, else Debian's
# own package of it (docker-compose 2.x, from the next release, trixie),
# fetched with apt into .cache/ without installing it or touching the
# machine's apt sources. The plugin is found through DOCKER_CONFIG.
tt_compose_v2() {
  if "$TT_DOCKER" compose version >/dev/null 2>&1; then
    TT_COMPOSE=("$TT_DOCKER" compose)
    return 0
  fi
  local cache=$TT_REPO/.cache/compose-v2
  if [[ ! -x $cache/cli-plugins/docker-compose ]]; then
    tt_log "fetching Debian's docker-compose v2 package into $cache"
    mkdir -p "$cache/apt/lists/partial" "$cache/apt/archives/partial" "$cache/cli-plugins"
    local mirror
    mirror=$(tt_apt_mirror)
    if [[ -z $mirror ]]; then
      tt_log "no Debian mirror in this machine's apt sources: cannot fetch docker-compose v2"
      return 1
    fi
    echo "deb $mirror trixie main" >"$cache/apt/sources.list"
    local apt=(-o "Dir::Etc::SourceList=$cache/apt/sources.list" -o Dir::Etc::SourceParts=/dev/null
      -o "Dir::State::Lists=$cache/apt/lists" -o "Dir::Cache::pkgcache=$cache/apt/pkgcache.bin"
      -o "Dir::Cache::srcpkgcache=$cache/apt/srcpkgcache.bin" -o APT::Sandbox::User=root)
    if ! apt-get -q "${apt[@]}" update >"$cache/apt.log" 2>&1 ||
      ! (cd "$cache/apt" && apt-get -q "${apt[@]}" download docker-compose >>"$cache/apt.log" 2>&1); then
      tt_log "could not fetch docker-compose v2; last lines of $cache/apt.log:"
      tail -5 "$cache/apt.log" >&2
      return 1
    fi
    dpkg-deb -x "$cache"/apt/docker-compose_*.deb "$cache/root"
    cp "$cache/root/usr/libexec/docker/cli-plugins/docker-compose" "$cache/cli-plugins/"
    rm -rf "$cache/root" "$cache"/apt/*.deb
  fi
  export DOCKER_CONFIG=$cache
  if ! "$TT_DOCKER" compose version >/dev/null 2>&1; then
    tt_log "$TT_DOCKER does not take the compose plugin in $cache/cli-plugins"
    return 1
  fi
  # shellcheck disable=SC2034
  TT_COMPOSE=("$TT_DOCKER" compose)
}

tt_ensure_base_image() {
  if "${TT_DOCKER:-docker}" image inspect "$TT_BASE_IMAGE" >/dev/null 2>&1; then return 0; fi
  if [[ ${TRANSTICK_PULL:-1} == 1 ]] && timeout 60 "${TT_DOCKER:-docker}" pull -q "$TT_BASE_IMAGE" \
    >/dev/null 2>&1; then
    tt_log "pulled $TT_BASE_IMAGE"
    return 0
  fi
  tt_log "$TT_BASE_IMAGE cannot be pulled: making it with debootstrap"
  local dir start=$SECONDS
  dir=$(mktemp -d /tmp/transtick-bookworm.XXXXXX)
  # A trap would outlive this function; clean up on both paths by hand.
  # The machine's own mirror, or debootstrap's default when it has none.
  local mirror
  mirror=$(tt_apt_mirror)
  if ! $TT_SUDO debootstrap --variant=minbase bookworm "$dir" ${mirror:+"$mirror"} \
    >"$dir.log" 2>&1; then
    tt_log "debootstrap failed; last lines of $dir.log:"
    tail -20 "$dir.log" >&2
    $TT_SUDO rm -rf "$dir"
    return 1
  fi
  # Trim it like Debian's own slim image: no docs, man pages or locales, now
  # or in packages installed later; the same suites as the official image.
  $TT_SUDO tee "$dir/etc/dpkg/dpkg.cfg.d/docker-slim" >/dev/null <<'EOF'
path-exclude /usr/share/doc/*
path-include /usr/share/doc/*/copyright
path-exclude /usr/share/man/*
path-exclude /usr/share/info/*
path-exclude /usr/share/groff/*
path-exclude /usr/share/lintian/*
path-exclude /usr/share/locale/*
EOF
  $TT_SUDO tee "$dir/etc/apt/apt.conf.d/docker-clean" >/dev/null <<'EOF'
DPkg::Post-Invoke { "rm -f /var/cache/apt/archives/*.deb /var/cache/apt/archives/partial/*.deb /var/cache/apt/*.bin || true"; };
APT::Update::Post-Invoke { "rm -f /var/cache/apt/archives/*.deb /var/cache/apt/archives/partial/*.deb /var/cache/apt/*.bin || true"; };
Dir::Cache::pkgcache "";
Dir::Cache::srcpkgcache "";
EOF
  # The image's apt sources are this machine's (the same mirror and suites),
  # or, without any, what debootstrap wrote.
  if compgen -G "/etc/apt/sources.list.d/*.sources" >/dev/null || [[ -s /etc/apt/sources.list ]]; then
    $TT_SUDO rm -f "$dir/etc/apt/sources.list"
    for f in /etc/apt/sources.list /etc/apt/sources.list.d/*.sources /etc/apt/sources.list.d/*.list; do
      [[ -s $f ]] && $TT_SUDO cp "$f" "$dir$f"
    done
  fi
  $TT_SUDO sh -c "cd '$dir' && rm -rf var/lib/apt/lists/* var/cache/apt/*.bin var/cache/apt/archives/*.deb \
    usr/share/doc/*/[!c]* usr/share/man/* usr/share/info/* usr/share/locale/* var/log/*.log var/log/apt/*"
  $TT_SUDO tar --numeric-owner -C "$dir" -c . |
    "${TT_DOCKER:-docker}" import -c 'CMD ["bash"]' -c 'LABEL made-by=transtick-deploy-debootstrap' \
      - "$TT_BASE_IMAGE" >/dev/null
  $TT_SUDO rm -rf "$dir" "$dir.log"
  tt_log "made $TT_BASE_IMAGE in $((SECONDS - start)) s"
}

# Builds from a staged copy of the files the build needs: the repository's
# source (tracked, plus new files git does not ignore) without deploy/, docs,
# scripts and CI files, so editing those does not recompile, and a big build/
# or out/ never goes to the daemon, whichever builder runs.
# TRANSTICK_SOURCE_REF=COMMIT builds that commit's source instead of the work
# tree (deploy/Dockerfile still comes from the work tree).
tt_build_image() {
  local tag=$1 start=$SECONDS rc=0 ctx
  local args=(build -f deploy/Dockerfile -t "$tag")
  if [[ -n ${TRANSTICK_VERSION:-} ]]; then args+=(--build-arg "TRANSTICK_VERSION=$TRANSTICK_VERSION"); fi
  ctx=$(mktemp -d /tmp/transtick-context.XXXXXX)
  (
    set -eo pipefail
    cd "$TT_REPO"
    if [[ -n ${TRANSTICK_SOURCE_REF:-} ]]; then
      git archive --format=tar "$TRANSTICK_SOURCE_REF" | tar -x -C "$ctx"
    elif git rev-parse --git-dir >/dev/null 2>&1; then
      git ls-files -z --cached --others --exclude-standard |
        xargs -0 -r sh -c 'for f; do [ -f "$f" ] && printf "%s\0" "$f"; done' sh |
        tar --null -T - -c | tar -x -C "$ctx"
    else
      tar -c --exclude=./.git --exclude=./build --exclude=./out . | tar -x -C "$ctx"
    fi
    rm -rf "$ctx/deploy" "$ctx/docs" "$ctx/scripts" "$ctx/.ci" "$ctx/.git"
    find "$ctx" -name '*.md' -delete
    mkdir -p "$ctx/deploy"
    cp deploy/Dockerfile deploy/Dockerfile.dockerignore "$ctx/deploy/"
    tt_log "building $tag (BuildKit: $TT_BUILDKIT, context $(du -sh "$ctx" | cut -f1))"
    DOCKER_BUILDKIT=$TT_BUILDKIT "$TT_DOCKER" "${args[@]}" "$ctx"
  ) || rc=$?
  rm -rf "$ctx"
  ((rc == 0)) || return $rc
  tt_log "built $tag in $((SECONDS - start)) s"
}
