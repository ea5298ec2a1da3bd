# Shared by the ParaView benchmarks (sourced): installs ParaView when pvbatch
# is missing and runs a pvbatch script under Xvfb. Expects die() and note().

# Installs paraview, python3-paraview, xvfb and xauth with apt-get.
install_paraview() {
  local sudo=()
  if [[ $(id -u) -ne 0 ]]; then
    command -v sudo >/dev/null || die "pvbatch is missing and installing it needs root (or sudo)"
    sudo=(sudo)
  fi
  command -v apt-get >/dev/null || die "pvbatch is missing and there is no apt-get to install it"
  local packages=(paraview python3-paraview xvfb xauth)
  note "installing ${packages[*]} with apt-get (a few minutes, ~1 GB)"
  export DEBIAN_FRONTEND=noninteractive
  # Without package lists (fresh container) there is no candidate: update first.
  if ! apt-cache policy paraview 2>/dev/null | grep -q 'Candidate: [0-9]'; then
    "${sudo[@]}" apt-get update -q || die "apt-get update failed"
  fi
  if ! "${sudo[@]}" apt-get install -y -q --no-install-recommends "${packages[@]}"; then
    note "install failed; updating the package lists and trying once more"
    "${sudo[@]}" apt-get update -q || die "apt-get update failed"
    "${sudo[@]}" apt-get install -y -q --no-install-recommends "${packages[@]}" ||
      die "apt-get install ${packages[*]} failed"
  fi
}

# Makes sure pvbatch and an X server wrapper are here; sets pv_version.
ensure_paraview() {
  if ! command -v pvbatch >/dev/null || ! command -v xvfb-run >/dev/null ||
     ! command -v xauth >/dev/null; then
    install_paraview
  fi
  command -v pvbatch >/dev/null || die "pvbatch still missing after installing paraview"
  pv_version=$(pvbatch --version 2>/dev/null | grep -o '[0-9][0-9.]*' | head -n1 || true)
  [[ $pv_version == 5.11* ]] ||
    echo "warning: expected ParaView 5.11, found '${pv_version:-unknown}'" >&2
}

# pvbatch SCRIPT ARGS... under Xvfb (Debian's ParaView has no EGL/OSMesa
# offscreen path: it needs an X server), stdout to $pv_out, stderr to $pv_err.
run_pvbatch() {
  local cmd=(pvbatch "$@")
  if command -v xvfb-run >/dev/null; then
    cmd=(xvfb-run -a -s "-screen 0 1280x1024x24" "${cmd[@]}")
  else
    cmd=(pvbatch --force-offscreen-rendering "$@")
  fi
  # Xvfb sometimes is not up when pvbatch connects ("bad X server
  # connection"), more so on a busy machine: try a few times.
  local attempt
  for attempt in 1 2 3; do
    if PYTHONPATH="$script_dir${PYTHONPATH:+:$PYTHONPATH}" "${cmd[@]}" >"$pv_out" 2>"$pv_err"; then
      return 0
    fi
    grep -q "bad X server connection" "$pv_err" || break
    sleep "$attempt"
  done
  cat "$pv_out" "$pv_err" >&2
  die "pvbatch failed (command: ${cmd[*]})"
}
