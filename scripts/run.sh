#!/usr/bin/env bash
# The README's main command: installs the dependencies, builds the app (CPU,
# Release, in build/) and runs the full EM-Fusion system on the built-in
# synthetic scene `synthetic:room-small` (320x240, 150 frames, three moving
# objects, simulated detector), printing the camera and object errors and
# writing trajectories, meshes and run.json to out/room-small/. Extra
# arguments go to `emfusion run`, e.g.
#   bash scripts/run.sh --max-frames 60
#   bash scripts/run.sh --input synthetic:room --output out/room   (640x480, slower)
# Environment: EMFUSION_JOBS overrides the parallel build jobs (default: nproc).
set -euo pipefail

repo_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo_root"

jobs="${EMFUSION_JOBS:-$(nproc)}"
export OMP_WAIT_POLICY="${OMP_WAIT_POLICY:-passive}"

say() { echo "==> [run.sh] $*"; }

input="synthetic:room-small"
output="out/room-small"
args=()
while (($#)); do
  case "$1" in
    --input) input="$2"; shift 2 ;;
    --output) output="$2"; shift 2 ;;
    *) args+=("$1"); shift ;;
  esac
done

say "installing dependencies (scripts/setup-debian.sh)"
bash scripts/setup-debian.sh

say "configuring build/ (CPU, Release)"
cmake -S . -B build -DEMFUSION_CUDA=OFF -DCMAKE_BUILD_TYPE=Release
say "building the app with -j${jobs}"
cmake --build build -j "$jobs" --target emfusion_app

say "running: build/examples/emfusion run $input --output $output ${args[*]:-}"
build/examples/emfusion run "$input" --output "$output" "${args[@]}"
say "done; results are in ${repo_root}/${output}"
