#!/usr/bin/env bash
# The project's test command (README; CI runs exactly this via .ci/run):
#   1. installs the Debian packages (scripts/setup-debian.sh; no-op when present),
#   2. configures, builds and tests the CPU-only build in build/ (ctest),
#   3. when nvcc is present, configures build-cuda/ and compiles every target
#      of the CUDA build without running it (CI has no GPU), so that the CUDA
#      code path keeps compiling.
# Environment: EMFUSION_JOBS overrides the parallel build jobs (default: nproc).
set -euo pipefail

repo_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo_root"

jobs="${EMFUSION_JOBS:-$(nproc)}"
# OpenMP's busy-waiting makes small parallel regions very slow on machines with
# few cores that are shared with other work.
export OMP_WAIT_POLICY=passive

say() { echo "==> [test.sh] $*"; }

say "installing dependencies (scripts/setup-debian.sh)"
bash scripts/setup-debian.sh

say "CPU build: configuring build/"
cmake -S . -B build \
  -DEMFUSION_CUDA=OFF \
  -DCMAKE_BUILD_TYPE=Release \
  -DEMFUSION_WERROR=ON
say "CPU build: building with -j${jobs}"
cmake --build build -j "$jobs"
say "CPU build: running ctest (OMP_WAIT_POLICY=${OMP_WAIT_POLICY})"
(cd build && ctest --output-on-failure)

nvcc_path=""
if command -v nvcc >/dev/null 2>&1; then
  nvcc_path="$(command -v nvcc)"
elif [[ -x /usr/local/cuda/bin/nvcc ]]; then
  nvcc_path=/usr/local/cuda/bin/nvcc
fi

if [[ -n "$nvcc_path" ]]; then
  say "CUDA build: configuring build-cuda/ with ${nvcc_path}"
  cmake -S . -B build-cuda \
    -DEMFUSION_CUDA=ON \
    -DCMAKE_CUDA_COMPILER="$nvcc_path" \
    -DCMAKE_CUDA_ARCHITECTURES=90 \
    -DCMAKE_BUILD_TYPE=Release \
    -DEMFUSION_WERROR=ON
  say "CUDA build: building all targets with -j${jobs}"
  cmake --build build-cuda -j "$jobs"
  say "CUDA build: compiled all targets in build-cuda/ but did NOT run them (no GPU is assumed here)."
else
  say "CUDA build: SKIPPED (nvcc not found on PATH nor at /usr/local/cuda/bin/nvcc)."
fi

say "all done."
