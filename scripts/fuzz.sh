#!/usr/bin/env bash
# Builds the libFuzzer targets of tests/fuzz/ with clang (build-fuzz/,
# -fsanitize=fuzzer,address,undefined, CPU only, no tests/examples/benchmarks)
# and runs each for EMFUSION_FUZZ_SECONDS seconds (default 60; EMFUSION_JOBS
# targets at a time, default nproc), starting from
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
# The targets are the ones tests/fuzz/CMakeLists.txt builds (EMFUSION_FUZZ_TARGETS),
# read from there so that a new parser's target is fuzzed without a second list.
read -r -a all_targets < <(sed -n 's/^set(EMFUSION_FUZZ_TARGETS \(.*\))$/\1/p' "$root/tests/fuzz/CMakeLists.txt")
if [[ ${#all_targets[@]} -eq 0 ]]; then
  echo "[fuzz] no EMFUSION_FUZZ_TARGETS in $root/tests/fuzz/CMakeLists.txt" >&2
  exit 1
fi
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
# Every target at once through emfusion_fuzzers, so that make compiles them
# EMFUSION_JOBS at a time: targets named one by one on make's command line are
# built one after another (CMake's top-level Makefile is .NOTPARALLEL), and
# each fuzzer is one unit, so that left every core but one idle while the
# fuzzers compiled (about two of the three minutes of CI's fuzzing step).
# A selection of targets is still built one by one.
if [[ ${#targets[@]} -eq ${#all_targets[@]} ]]; then
  cmake --build "$build" -j "$jobs" --target emfusion_fuzzers
else
  cmake --build "$build" -j "$jobs" --target "${build_targets[@]}"
fi

# One target: runs it and writes its summary (and, on failure, the first
# lines of the report) to $build/fuzz-logs/<target>.summary; status file
# <target>.failed marks a failure.
run_target() {
  local target="$1"
  local exe="$build/tests/fuzz/fuzz_$target"
  local corpus="$build/fuzz-corpus/$target"
  local artifacts="$build/fuzz-artifacts/$target"
  local out="$build/fuzz-logs/$target.log"
  local summary="$build/fuzz-logs/$target.summary"
  mkdir -p "$corpus" "$artifacts" "$(dirname "$out")"
  rm -f "$build/fuzz-logs/$target.failed"
  local seeds=("$root/tests/fuzz/corpus/$target")
  [[ -d "$root/tests/fuzz/regressions/$target" ]] && seeds+=("$root/tests/fuzz/regressions/$target")
  local start=$SECONDS status=0
  # The first directory receives new entries; the seeds are only read.
  (cd "$build" && "$exe" -max_total_time="$seconds" -rss_limit_mb=2048 -timeout=10 -print_final_stats=1 \
     -artifact_prefix="$artifacts/" "$corpus" "${seeds[@]}") >"$out" 2>&1 || status=$?
  local elapsed=$((SECONDS - start))
  local runs cov corpus_size
  runs="$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$out" | grep -o '[0-9]*$' || true)"
  cov="$(grep -oE '(#[0-9]+|DONE).*cov: [0-9]+ ft: [0-9]+' "$out" | tail -n 1 | grep -oE 'cov: [0-9]+ ft: [0-9]+' || true)"
  corpus_size="$(find "$corpus" -type f | wc -l)"
  if [[ $status -eq 0 ]]; then
    log "$target: ${runs:-?} runs, ${cov:-cov: ?}, scratch corpus $corpus_size files, ${elapsed} s: ok" >"$summary"
  else
    local crash
    crash="$(grep -oE "(Test unit written to|artifact_prefix.*; Test unit written to) [^ ]+" "$out" | tail -n 1 |
             awk '{print $NF}' || true)"
    {
      log "$target: FAILED after ${elapsed} s (exit $status, ${runs:-?} runs): crash file ${crash:-none written}; log $out"
      grep -E "ERROR: |SUMMARY: |fuzz invariant violated|fuzz: " "$out" | head -n 5 | sed 's/^/[fuzz]   /' || true
    } >"$summary"
    touch "$build/fuzz-logs/$target.failed"
  fi
}

# EMFUSION_JOBS targets at a time (each fuzzer is one process on one core).
log "running ${#targets[@]} targets, ${seconds} s each, ${jobs} at a time"
running=0
for target in "${targets[@]}"; do
  run_target "$target" &
  running=$((running + 1))
  if [[ $running -ge $jobs ]]; then
    wait -n || true
    running=$((running - 1))
  fi
done
wait

failed=()
for target in "${targets[@]}"; do
  cat "$build/fuzz-logs/$target.summary"
  [[ -e "$build/fuzz-logs/$target.failed" ]] && failed+=("$target")
done

if [[ ${#failed[@]} -gt 0 ]]; then
  log "failed: ${failed[*]}"
  exit 1
fi
log "all ${#targets[@]} targets ran ${seconds} s without a failure"
