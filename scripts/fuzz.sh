#!/usr/bin/env bash
# Builds the libFuzzer targets of tests/fuzz/ with clang (build-fuzz/,
# -fsanitize=fuzzer,address,undefined, CPU only, no tests/examples/benchmarks)
# and runs each for EMFUSION_FUZZ_SECONDS seconds (default 60), starting from
# its seeds (tests/fuzz/corpus/<target>/) and regression inputs
# (tests/fuzz/regressions/<target>/). New corpus entries go to
# build-fuzz/fuzz-corpus/<target>/, never into the repository. Prints one
# summary line per target; exits non-zero naming the target and the crash
# file when a target finds a crash, a leak, a timeout or an out-of-memory.
#
#   scripts/fuzz.sh [target...]        # default: every target
#   EMFUSION_FUZZ_SECONDS=600 scripts/fuzz.sh klg
#
# A crash file replays with build-fuzz/tests/fuzz/fuzz_<target> <file>, or
# without libFuzzer with emfusion_fuzz_replay <target> <file> of a normal
# build. Fix the parser, then keep the file in tests/fuzz/regressions/<target>/
# under a name that says what it was (docs/io.md, "Fuzzing").
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="$root/build-fuzz"
seconds="${EMFUSION_FUZZ_SECONDS:-60}"
jobs="${EMFUSION_JOBS:-$(nproc)}"
all_targets=(tum_trajectory tum_list calibration intrinsics masks config klg exr png)
targets=("$@")
[[ ${#targets[@]} -eq 0 ]] && targets=("${all_targets[@]}")

log() { echo "[fuzz] $*"; }

build_targets=()
for target in "${targets[@]}"; do
  if [[ " ${all_targets[*]} " != *" $target "* ]]; then
    log "unknown target '$target' (targets: ${all_targets[*]})" >&2
    exit 2
  fi
  build_targets+=("fuzz_$target")
done

bash "$root/scripts/setup-debian.sh"
if ! command -v clang++ >/dev/null 2>&1; then
  log "clang++ not found (Debian packages clang and libclang-rt-14-dev)" >&2
  exit 1
fi

mkdir -p "$build"
cmake -S "$root" -B "$build" -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DEMFUSION_BUILD_FUZZERS=ON -DEMFUSION_CUDA=OFF -DEMFUSION_BUILD_TESTS=OFF -DEMFUSION_BUILD_EXAMPLES=OFF \
  -DEMFUSION_BUILD_BENCHMARKS=OFF -DEMFUSION_WERROR=ON >"$build/configure.log" 2>&1 ||
  { cat "$build/configure.log" >&2; exit 1; }
cmake --build "$build" -j "$jobs" --target "${build_targets[@]}"

failed=()
for target in "${targets[@]}"; do
  exe="$build/tests/fuzz/fuzz_$target"
  corpus="$build/fuzz-corpus/$target"
  artifacts="$build/fuzz-artifacts/$target"
  out="$build/fuzz-logs/$target.log"
  mkdir -p "$corpus" "$artifacts" "$(dirname "$out")"
  seeds=("$root/tests/fuzz/corpus/$target")
  [[ -d "$root/tests/fuzz/regressions/$target" ]] && seeds+=("$root/tests/fuzz/regressions/$target")
  start=$SECONDS
  status=0
  # The first directory receives new entries; the seeds are only read.
  (cd "$build" && "$exe" -max_total_time="$seconds" -rss_limit_mb=2048 -timeout=10 -print_final_stats=1 \
     -artifact_prefix="$artifacts/" "$corpus" "${seeds[@]}") >"$out" 2>&1 || status=$?
  elapsed=$((SECONDS - start))
  runs="$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$out" | grep -o '[0-9]*$' || true)"
  cov="$(grep -oE '(#[0-9]+|DONE).*cov: [0-9]+ ft: [0-9]+' "$out" | tail -n 1 | grep -oE 'cov: [0-9]+ ft: [0-9]+' || true)"
  corpus_size="$(find "$corpus" -type f | wc -l)"
  if [[ $status -eq 0 ]]; then
    log "$target: ${runs:-?} runs, ${cov:-cov: ?}, scratch corpus $corpus_size files, ${elapsed} s: ok"
  else
    crash="$(grep -oE "Test unit written to [^ ]+" "$out" | tail -n 1 | awk '{print $NF}' || true)"
    log "$target: FAILED after ${elapsed} s (exit $status, ${runs:-?} runs): crash file ${crash:-none written}; log $out"
    grep -E "ERROR: |SUMMARY: |fuzz invariant violated|fuzz: " "$out" | head -n 5 | sed 's/^/[fuzz]   /' || true
    failed+=("$target")
  fi
done

if [[ ${#failed[@]} -gt 0 ]]; then
  log "failed: ${failed[*]}"
  exit 1
fi
log "all ${#targets[@]} targets ran ${seconds} s without a failure"
