#!/usr/bin/env bash
# Validates deploy/k8s/*.yaml against the Kubernetes API schema, offline
# (deploy/k8s-validate/validate.mjs says how), then proves the check bites:
# copies of the manifests with a misspelt field must fail. Installs Node.js
# from Debian when missing and the pinned npm packages with `npm ci`.
#
#   deploy/validate-k8s.sh              # all manifests + the typo self-test
#   deploy/validate-k8s.sh FILE.yaml... # just these
set -euo pipefail
deploy=$(cd "$(dirname "$0")" && pwd)
cd "$deploy"

if ! type -P node >/dev/null || ! type -P npm >/dev/null; then
  SUDO=""
  [[ $(id -u) == 0 ]] || SUDO=sudo
  echo "validate-k8s: installing nodejs and npm"
  $SUDO apt-get update -q >/dev/null
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends nodejs npm >/dev/null
fi

# npm ci only when the installed tree is missing or older than the lock file.
if [[ ! -f k8s-validate/node_modules/.package-lock.json ||
  k8s-validate/package-lock.json -nt k8s-validate/node_modules/.package-lock.json ]]; then
  (cd k8s-validate && npm ci --no-audit --no-fund --loglevel=error >/dev/null)
fi

validate() { node k8s-validate/validate.mjs "$@"; }

if (($#)); then
  validate "$@"
  exit
fi

validate k8s/*.yaml

# kustomize (built into kubectl) renders the set offline, when kubectl is here.
if type -P kubectl >/dev/null && kubectl kustomize --help >/dev/null 2>&1; then
  kubectl kustomize k8s >/dev/null
  echo "ok    kubectl kustomize k8s"
fi

# Self-test: each misspelling must make the validator fail.
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
typos=(
  "worker.yaml|s/^      containers:/      contaners:/"
  "root.yaml|s/^            exec:/            exce:/"
  "display.yaml|s/imagePullPolicy:/imagePullPolicyy:/"
  "worker.yaml|s/^  maxUnavailable:/  maxUnavailble:/"
  "worker.yaml|/kind: PodDisruptionBudget/,$ s/component: worker$/component: workers/"
  "config.yaml|s/^  TRANSTICK_ROOT:/  TRANSTICK_ROOTS:/"
)
bad=0
for t in "${typos[@]}"; do
  file=${t%%|*} edit=${t#*|}
  rm -f "$tmp"/*.yaml
  cp k8s/*.yaml "$tmp"/
  sed -i "$edit" "$tmp/$file"
  if cmp -s "k8s/$file" "$tmp/$file"; then
    echo "FAIL  self-test: '$edit' changed nothing in $file"
    bad=1
  elif validate "$tmp"/*.yaml >"$tmp/out" 2>&1; then
    echo "FAIL  self-test: $file with '$edit' passed validation"
    bad=1
  else
    echo "ok    self-test: $file with '$edit' fails: $(grep -m1 '^        ' "$tmp/out" | sed 's/^ *//')"
  fi
done
exit $bad
