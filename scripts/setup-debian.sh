#!/usr/bin/env bash
# Installs the Debian 12 packages that emfusion's build, tests and demo need.
# Idempotent and non-interactive: when every package is already installed it
# touches nothing (no apt-get at all); otherwise it runs `apt-get update` once
# and installs only the missing packages. Uses sudo only when not root.
set -euo pipefail

# One list, one place: add packages here (e.g. libopencv-dev for io/ and the app).
EMFUSION_DEBIAN_PACKAGES=(
  build-essential
  cmake
  libeigen3-dev
  libthrust-dev
  catch2
  libfmt-dev
  libcli11-dev
  libomp-dev
  zlib1g-dev
  libpng-dev
  libjpeg-dev
  libopenexr-dev
  clang
  libclang-rt-14-dev
)

log() { echo "[setup-debian] $*"; }

if ! command -v dpkg-query >/dev/null 2>&1; then
  log "dpkg-query not found: this script is for Debian (12) and derivatives." >&2
  exit 1
fi

missing=()
for pkg in "${EMFUSION_DEBIAN_PACKAGES[@]}"; do
  status="$(dpkg-query -W -f='${db:Status-Status}' "$pkg" 2>/dev/null || true)"
  if [[ "$status" != "installed" ]]; then
    missing+=("$pkg")
  fi
done

if [[ ${#missing[@]} -eq 0 ]]; then
  log "all ${#EMFUSION_DEBIAN_PACKAGES[@]} packages already installed; nothing to do."
  exit 0
fi

as_root=()
if [[ "$(id -u)" -ne 0 ]]; then
  if command -v sudo >/dev/null 2>&1; then
    as_root=(sudo)
  else
    log "not root and sudo is not available; please install as root: ${missing[*]}" >&2
    exit 1
  fi
fi

export DEBIAN_FRONTEND=noninteractive
log "missing packages: ${missing[*]}"
log "running: ${as_root[*]:+${as_root[*]} }apt-get update"
"${as_root[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update
log "running: ${as_root[*]:+${as_root[*]} }apt-get install -y --no-install-recommends ${missing[*]}"
"${as_root[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${missing[@]}"
log "done."
