#!/usr/bin/env bash
# Runs track_camera with several integration settings on one sequence and
# prints the ATE of each: the measurement behind the tracking defaults
# (docs/decisions.md). Usage: scripts/sweep_tracking.sh <build-dir> <sequence-dir> <backend> [extra args]
set -euo pipefail
build=$1 seq=$2 backend=$3
shift 3
out=$(mktemp -d)
for cfg in "paper" "refined" "refined --behind-band 0.5" "refined --behind-band 1"; do
  name=$(echo "$cfg" | tr ' ' '_')
  # shellcheck disable=SC2086
  "$build/examples/track_camera" "$seq" "$out/$name.txt" --backend "$backend" --integration $cfg "$@" > "$out/$name.log"
  printf '%-32s %s | %s\n' "$cfg" "$(head -1 "$out/$name.log")" \
    "$("$build/examples/evaluate_trajectory" "$seq/groundtruth.txt" "$out/$name.txt" | head -1)"
done
