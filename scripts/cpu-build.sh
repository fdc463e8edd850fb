# Sourced by scripts/run.sh and scripts/run-demo.sh: cpu_build installs what
# is missing and configures build/ (CPU, Release), cuda_build the same for
# build-cuda/ (CUDA, for the GPUs of this machine), then either builds the
# target given as the first argument. Sets `say`, `jobs` and `repo_root`,
# and leaves the shell in the repository root.
repo_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo_root"

jobs="${EMFUSION_JOBS:-$(nproc)}"
export OMP_WAIT_POLICY="${OMP_WAIT_POLICY:-passive}"

say() { echo "==> [$(basename "$0")] $*"; }

cpu_build() {
  say "checking dependencies (scripts/setup-debian.sh run)"
  bash scripts/setup-debian.sh run
  say "configuring build/ (CPU, Release)"
  cmake -S . -B build -DEMFUSION_CUDA=OFF -DCMAKE_BUILD_TYPE=Release
  say "building $1 with -j${jobs}"
  cmake --build build -j "$jobs" --target "$1"
}

cuda_build() {
  say "checking dependencies (scripts/setup-debian.sh cuda)"
  bash scripts/setup-debian.sh cuda
  local nvcc
  nvcc="$(command -v nvcc || echo "${CUDA_HOME:-/usr/local/cuda}/bin/nvcc")"
  say "configuring build-cuda/ (CUDA with $nvcc for this machine's GPUs, Release)"
  cmake -S . -B build-cuda -DEMFUSION_CUDA=ON -DCMAKE_CUDA_COMPILER="$nvcc" -DCMAKE_CUDA_ARCHITECTURES=native \
    -DCMAKE_BUILD_TYPE=Release
  say "building $1 with -j${jobs}"
  cmake --build build-cuda -j "$jobs" --target "$1"
}
