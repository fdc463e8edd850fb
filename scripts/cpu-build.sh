# Sourced by scripts/run.sh and scripts/run-demo.sh: installs the
# dependencies and configures build/ (CPU, Release), then builds the target
# given as the first argument. Sets `say`, `jobs` and `repo_root`, and leaves
# the shell in the repository root.
repo_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo_root"

jobs="${EMFUSION_JOBS:-$(nproc)}"
export OMP_WAIT_POLICY="${OMP_WAIT_POLICY:-passive}"

say() { echo "==> [$(basename "$0")] $*"; }

cpu_build() {
  say "installing dependencies (scripts/setup-debian.sh)"
  bash scripts/setup-debian.sh
  say "configuring build/ (CPU, Release)"
  cmake -S . -B build -DEMFUSION_CUDA=OFF -DCMAKE_BUILD_TYPE=Release
  say "building $1 with -j${jobs}"
  cmake --build build -j "$jobs" --target "$1"
}
