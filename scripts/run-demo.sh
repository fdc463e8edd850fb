#!/usr/bin/env bash
# The static-scene demo: installs the dependencies, builds the demo (CPU,
# Release, in build/) and runs it on the built-in synthetic scene, writing to
# out/demo/. Extra arguments are passed on to the demo, e.g.
#   bash scripts/run-demo.sh --help
# Environment: EMFUSION_JOBS overrides the parallel build jobs (default: nproc).
set -euo pipefail

source "$(dirname "${BASH_SOURCE[0]}")/cpu-build.sh"
cpu_build emfusion_demo

mkdir -p out/demo
say "running: build/examples/emfusion_demo --output out/demo${*:+ $*}"
build/examples/emfusion_demo --output out/demo "$@"
say "done; results are in ${repo_root}/out/demo"
