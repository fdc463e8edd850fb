#!/usr/bin/env bash
# Runs track_camera with several settings on one sequence and prints the ATE
# of each: the measurements behind the tracking defaults (docs/decisions.md).
# Usage: scripts/sweep_tracking.sh <build-dir> <sequence-dir> <backend> [extra args]
set -euo pipefail
build=$1 seq=$2 backend=$3
shift 3
out=$(mktemp -d)
for cfg in "--integration paper" "--integration refined" "--integration refined --behind-band 1" \
           "--central-gradient" "--central-gradient --tau 0.001"; do
  name=$(echo "$cfg" | tr -d '-' | tr ' ' '_')
  # shellcheck disable=SC2086
  "$build/examples/track_camera" "$seq" "$out/$name.txt" --backend "$backend" $cfg "$@" > "$out/$name.log"
  printf '%-44s %s\n    %s\n' "$cfg" "$(head -1 "$out/$name.log")" \
    "$("$build/examples/evaluate_trajectory" "$seq/groundtruth.txt" "$out/$name.txt" | tr '\n' ' ')"
done
