#!/usr/bin/env bash
# The README's main command: installs the dependencies, builds the app (CPU,
# Release, in build/) and runs the full EM-Fusion system on the built-in
# synthetic scene `synthetic:room-small` (320x240, 150 frames, three moving
# objects, simulated detector), printing the camera and object errors and
# writing trajectories, meshes and run.json to out/room-small/, then (with
# ground truth, as the built-in scenes have) evaluates the run and writes
# out/room-small/report.html. Extra
# arguments go to `emfusion run`, e.g.
#   bash scripts/run.sh --max-frames 60
#   bash scripts/run.sh --input synthetic:room --output out/room   (640x480, slower)
#   bash scripts/run.sh --backend cuda   (builds build-cuda/ with the CUDA toolkit and runs on the GPU)
# Environment: EMFUSION_JOBS overrides the parallel build jobs (default: nproc).
set -euo pipefail

source "$(dirname "${BASH_SOURCE[0]}")/cpu-build.sh"

input="synthetic:room-small"
output="out/room-small"
backend=cpu
args=()
while (($#)); do
  case "$1" in
    --input) input="$2"; shift 2 ;;
    --output) output="$2"; shift 2 ;;
    --backend) backend="$2"; shift 2 ;;
    *) args+=("$1"); shift ;;
  esac
done

case "$backend" in
  cpu) cpu_build emfusion_app; app=build/examples/emfusion ;;
  cuda) cuda_build emfusion_app; app=build-cuda/examples/emfusion ;;
  *) echo "run.sh: --backend must be cpu or cuda, got '$backend'" >&2; exit 2 ;;
esac

say "running: $app run $input --output $output --backend $backend ${args[*]:-}"
"$app" run "$input" --output "$output" --backend "$backend" "${args[@]}"
[[ $output == /* ]] || output="${repo_root}/${output}"
# With ground truth (built-in scenes, sequences with groundtruth.txt), the
# evaluation and the run report (report.html: plots, tables, pictures).
if [[ $input == synthetic:* || -f $input/groundtruth.txt ]]; then
  say "evaluating: $app eval $input $output"
  "$app" eval "$input" "$output"
  say "done; results are in ${output}; open ${output}/report.html in a browser"
else
  say "done; results are in ${output}"
fi
