#!/usr/bin/env bash
# What one device call runs (docs/benchmarks.md): the CUDA build with every
# test, the redkitchen_300 integration sweep, and the app on synthetic scenes.
# Usage on the GPU machine: bash scripts/gpu_session.sh <out-dir>
set -uo pipefail
out=${1:?out dir}
mkdir -p "$out"
cmake -S . -B build-gpu -DEMFUSION_CUDA=ON -DCMAKE_BUILD_TYPE=Release -DEMFUSION_WERROR=ON \
  -DEMFUSION_SHARED_DATA_DIR="$PWD/.device-data" > "$out/configure.log" 2>&1
cmake --build build-gpu -j16 > "$out/build.log" 2>&1 || { tail -50 "$out/build.log"; exit 1; }
(cd build-gpu && ctest --output-on-failure) > "$out/ctest.log" 2>&1; tail -25 "$out/ctest.log"
seq=.device-data/redkitchen_300
if [[ -d $seq ]]; then
  for g in 0 1 1.5 2; do
    build-gpu/examples/track_camera "$seq" "$out/rk_guard_$g.txt" --backend cuda --silhouette-guard "$g" > "$out/rk_guard_$g.log" 2>&1
    echo "guard $g: $(head -1 "$out/rk_guard_$g.log") | $(build-gpu/examples/evaluate_trajectory "$seq/groundtruth.txt" "$out/rk_guard_$g.txt" | tr '\n' ' ')"
  done
fi
for scene in room room8; do
  build-gpu/examples/emfusion run "synthetic:$scene" --output "$out/$scene" --backend cuda --verbose > "$out/$scene.log" 2>&1
  tail -8 "$out/$scene.log"
done
