#!/usr/bin/env bash
# The project's test command (README; CI runs exactly this via .ci/run):
#   1. installs what is missing (scripts/setup-debian.sh test; no-op when all is there),
#   2. configures, builds and tests the CPU-only build in build/ (preset
#      release) without the Catch2 unit tests (EMFUSION_BUILD_UNIT_TESTS=OFF:
#      they run once, in step 3; with EMFUSION_SKIP_SANITIZERS=1 here): the
#      examples and their runs, the benchmarks' runs, the consumer,
#   3. builds the unit tests under AddressSanitizer + UBSan in build-asan/
#      (preset asan-ubsan; the test files compiled in unity groups and
#      Catch2's runner once, tests/CMakeLists.txt) and runs the ctest suite
#      there, two at a time; not what only the release build runs (label
#      release_only: the long simulated runs, the app and the tools beside
#      it, the consumer),
#   4. fuzzes every parser for EMFUSION_FUZZ_SECONDS each (scripts/fuzz.sh,
#      clang + libFuzzer, build-fuzz/; the fuzzers compiled EMFUSION_JOBS at
#      a time, then run as many at a time),
#   5. when nvcc is present, configures build-cuda/ and compiles the targets
#      that instantiate every algorithm on CUDA (the app and track_camera)
#      without running them (CI has no GPU), so that the CUDA code path keeps
#      compiling.
# Environment: EMFUSION_JOBS overrides the parallel build jobs (default:
# nproc); EMFUSION_FUZZ_SECONDS the fuzzing time per target (default 10 here;
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

# The unit tests are built and run once, under the sanitizers (step 3); this
# build runs what only an optimised build can run in time. Without step 3
# (EMFUSION_SKIP_SANITIZERS=1) it runs them itself.
if [[ "${EMFUSION_SKIP_SANITIZERS:-0}" != 1 ]]; then
  unit_tests=OFF
  say "CPU build: configuring build/ (preset release, EMFUSION_BUILD_UNIT_TESTS=OFF: the unit tests run under the sanitizers)"
else
  unit_tests=ON
  say "CPU build: configuring build/ (preset release, with the unit tests: the sanitizer step is skipped)"
fi
cmake --preset release -DEMFUSION_BUILD_UNIT_TESTS=$unit_tests
say "CPU build: building with -j${jobs}"
cmake --build --preset release -j "$jobs"
say "CPU build: running ctest (OMP_WAIT_POLICY=${OMP_WAIT_POLICY})"
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
  say "fuzzing: scripts/fuzz.sh, ${EMFUSION_FUZZ_SECONDS:-10} s per target"
  EMFUSION_FUZZ_SECONDS="${EMFUSION_FUZZ_SECONDS:-10}" bash scripts/fuzz.sh
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
    -DCMAKE_CUDA_ARCHITECTURES=90-virtual \
    "-DCMAKE_CUDA_FLAGS=-Xcicc -O0" \
    -DCMAKE_CUDA_FLAGS_RELEASE=-DNDEBUG -DCMAKE_CXX_FLAGS_RELEASE=-DNDEBUG \
    -DCMAKE_BUILD_TYPE=Release \
    -DEMFUSION_WERROR=ON
  # The app and the camera tracker instantiate every algorithm on the CUDA
  # backend (System<float, Cuda> and the parts it is built from, half
  # volumes); the CUDA tests themselves are built and run on a GPU machine
  # (docs/building.md, "CUDA"). One target depends on the two
  # (emfusion_cuda_compile_check), so that they compile at once: named one by
  # one, make built them one after another. The benchmarks are compiled where
  # they run, on the GPU machine. 90-virtual: PTX only, no machine code (the
  # whole C++ and CUDA front end and NVVM, not ptxas): 222 s instead of 263 s
  # for the app's unit on this machine; the GPU machine builds sm_90 code.
  # Host code unoptimised (no -O3 in the Release flags) and device code too
  # (-Xcicc -O0: NVVM still lowers every kernel to PTX, without its
  # optimiser, which was most of the step: track_camera's unit took 412 s,
  # its CUDA instantiations compiled alone 382 s of which NVVM 357 s, its
  # sparse volume's kernels alone 137 s of NVVM at -O3 against
  # 11 s at -O0; the whole step 108 s instead of 412 s; docs/building.md):
  # a check that it compiles, not a build to run.
  say "CUDA build: building emfusion_cuda_compile_check (emfusion_app track_camera) with -j${jobs}"
  cmake --build build-cuda -j "$jobs" --target emfusion_cuda_compile_check
  say "CUDA build: compiled emfusion_app and track_camera in build-cuda/ but did NOT run them (no GPU is assumed here)."
else
  say "CUDA build: SKIPPED (nvcc not found on PATH nor at /usr/local/cuda/bin/nvcc)."
fi

say "all done."
