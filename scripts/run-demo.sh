#!/usr/bin/env bash
# The README's main command: installs the dependencies, builds the demo (CPU,
# Release, in build/) and runs it on the built-in synthetic scene, writing to
# out/demo/. Extra arguments are passed on to the demo, e.g.
#   bash scripts/run-demo.sh --help
# Environment: EMFUSION_JOBS overrides the parallel build jobs (default: nproc).
set -euo pipefail

repo_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo_root"

jobs="${EMFUSION_JOBS:-$(nproc)}"
export OMP_WAIT_POLICY="${OMP_WAIT_POLICY:-passive}"

say() { echo "==> [run-demo.sh] $*"; }

say "installing dependencies (scripts/setup-debian.sh)"
bash scripts/setup-debian.sh

say "configuring build/ (CPU, Release)"
cmake -S . -B build -DEMFUSION_CUDA=OFF -DCMAKE_BUILD_TYPE=Release
say "building emfusion_demo with -j${jobs}"
cmake --build build -j "$jobs" --target emfusion_demo

mkdir -p out/demo
say "running: build/examples/emfusion_demo --output out/demo${*:+ $*}"
build/examples/emfusion_demo --output out/demo "$@"
say "done; results are in ${repo_root}/out/demo"
