#!/usr/bin/env bash
# What one device call runs (docs/benchmarks.md): the CUDA build with every
# test, camera-only tracking of redkitchen_300 with and without the bilateral
# filter, and the app on synthetic scenes (each with the filter's default
# radius and with it off).
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
  for r in 3 2 0; do
    build-gpu/examples/track_camera "$seq" "$out/rk_bilateral_$r.txt" --backend cuda --silhouette-guard 1.5 \
      --bilateral-radius "$r" > "$out/rk_bilateral_$r.log" 2>&1
    echo "bilateral $r: $(head -1 "$out/rk_bilateral_$r.log") | $(build-gpu/examples/evaluate_trajectory "$seq/groundtruth.txt" "$out/rk_bilateral_$r.txt" | tr '\n' ' ')"
  done
fi
for scene in room room8; do
  for r in 3 0; do
    build-gpu/examples/emfusion run "synthetic:$scene" --output "$out/${scene}_bf$r" --backend cuda --verbose \
      --set bilateral_radius=$r > "$out/${scene}_bf$r.log" 2>&1
    echo "== $scene bilateral_radius=$r: $(grep -c created "$out/${scene}_bf$r.log") created, $(grep -c deleted "$out/${scene}_bf$r.log") deleted"
    tail -12 "$out/${scene}_bf$r.log"
  done
done
