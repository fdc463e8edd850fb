#!/usr/bin/env bash
# The project's test command (README; CI runs exactly this via .ci/run):
#   1. installs what is missing (scripts/setup-debian.sh test; no-op when all is there),
#   2. configures, builds and tests the CPU-only build in build/ (preset
#      release; every ctest entry but the label integration),
#   3. builds the same (benchmarks aside) under AddressSanitizer + UBSan in
#      build-asan/ (preset asan-ubsan) and runs the whole ctest suite there,
#      two at a time, the long simulated runs (label integration) included,
#   4. fuzzes every parser for EMFUSION_FUZZ_SECONDS each (scripts/fuzz.sh,
#      clang + libFuzzer, build-fuzz/),
#   5. when nvcc is present, configures build-cuda/ and compiles the targets
#      that instantiate every algorithm on CUDA (the app, track_camera and two
#      benchmarks) without running them (CI has no GPU), so that the CUDA
#      code path keeps compiling.
# Environment: EMFUSION_JOBS overrides the parallel build jobs (default:
# nproc); EMFUSION_FUZZ_SECONDS the fuzzing time per target (default 20 here;
# scripts/fuzz.sh alone defaults to 60); EMFUSION_SKIP_SANITIZERS=1 and
# EMFUSION_SKIP_FUZZ=1 skip steps 3 and 4 (for quick local runs; CI runs all).
set -euo pipefail

repo_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo_root"

jobs="${EMFUSION_JOBS:-$(nproc)}"
# OpenMP's busy-waiting makes small parallel regions very slow on machines with
# few cores that are shared with other work.
export OMP_WAIT_POLICY=passive

started=$SECONDS
say() { printf '==> [test.sh %3dm%02ds] %s\n' $(((SECONDS - started) / 60)) $(((SECONDS - started) % 60)) "$*"; }

say "checking dependencies (scripts/setup-debian.sh test: installs only what is missing)"
bash scripts/setup-debian.sh test

say "CPU build: configuring build/ (preset release)"
cmake --preset release
say "CPU build: building with -j${jobs}"
cmake --build --preset release -j "$jobs"
say "CPU build: running ctest without the label integration (it runs under the sanitizers; OMP_WAIT_POLICY=${OMP_WAIT_POLICY})"
ctest --preset release

if [[ "${EMFUSION_SKIP_SANITIZERS:-0}" != 1 ]]; then
  say "sanitizers: configuring build-asan/ (preset asan-ubsan: AddressSanitizer + UBSan)"
  cmake --preset asan-ubsan
  say "sanitizers: building with -j${jobs}"
  cmake --build --preset asan-ubsan -j "$jobs"
  say "sanitizers: running the whole ctest suite under ASan + UBSan (leak checks on)"
  ctest --preset asan-ubsan
else
  say "sanitizers: SKIPPED (EMFUSION_SKIP_SANITIZERS=1)"
fi

if [[ "${EMFUSION_SKIP_FUZZ:-0}" != 1 ]]; then
  say "fuzzing: scripts/fuzz.sh, ${EMFUSION_FUZZ_SECONDS:-20} s per target"
  EMFUSION_FUZZ_SECONDS="${EMFUSION_FUZZ_SECONDS:-20}" bash scripts/fuzz.sh
else
  say "fuzzing: SKIPPED (EMFUSION_SKIP_FUZZ=1)"
fi

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
  # The app, the camera tracker and the two benchmarks instantiate every
  # algorithm on the CUDA backend (System<float, Cuda> and the parts it is
  # built from); the CUDA tests themselves are built and run on a GPU
  # machine (docs/building.md, "CUDA"). Compiling every target here took
  # about 11 minutes of CI's 41. One target depends on the four
  # (emfusion_cuda_compile_check), so that they compile two at a time: named
  # one by one, make built them one after another (5.0 min at 8e1eb67; 3.9
  # min as one target).
  say "CUDA build: building emfusion_cuda_compile_check (emfusion_app track_camera bench_volume bench_system) with -j${jobs}"
  cmake --build build-cuda -j "$jobs" --target emfusion_cuda_compile_check
  say "CUDA build: compiled emfusion_app track_camera bench_volume bench_system in build-cuda/ but did NOT run them (no GPU is assumed here)."
else
  say "CUDA build: SKIPPED (nvcc not found on PATH nor at /usr/local/cuda/bin/nvcc)."
fi

say "all done."
