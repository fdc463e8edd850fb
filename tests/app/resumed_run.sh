#!/usr/bin/env bash
# ctest driver: a run stopped and resumed from its checkpoint writes the
# same trajectories as one that never stopped (docs/user-guide.md, "Resuming
# a run"), and `emfusion mesh` meshes the checkpoint without the sequence.
#
#   resumed_run.sh <emfusion> <work dir>
#
# Checked: a straight run of 12 frames; a run of 6 frames with
# --checkpoint-every 4 (checkpoints after frame 4 and at its end), resumed
# to 12 with the same option (its last checkpoint at frame 12): camera.txt, objects.txt and every objects/<id>.txt byte for byte
# equal (CPU backend); the meshes of `emfusion mesh` equal the straight
# run's; a damaged checkpoint refused with a clear error.
set -u
app=$1 work=$2
scene=synthetic:room-small
frames=12

fail() { echo "FAIL: $*" >&2; exit 1; }
same_outputs() {  # <dir a> <dir b>
  for f in camera.txt objects.txt; do cmp -s "$1/$f" "$2/$f" || fail "$2/$f differs from $1/$f"; done
  for f in "$1"/objects/*.txt; do
    cmp -s "$f" "$2/objects/$(basename "$f")" || fail "$2/objects/$(basename "$f") differs from $f"
  done
  [ "$(ls "$1/objects" | wc -l)" = "$(ls "$2/objects" | wc -l)" ] || fail "$2 has other object files than $1"
}

rm -rf "$work" && mkdir -p "$work" || fail "cannot make $work"
"$app" run $scene --max-frames $frames --output "$work/straight" > "$work/straight.log" 2>&1 ||
  fail "straight run failed: $(cat "$work/straight.log")"

# Stopped after 6 frames (as --max-frames does), resumed to the end.
"$app" run $scene --max-frames 6 --checkpoint-every 4 --output "$work/resumed" > "$work/first.log" 2>&1 ||
  fail "first half failed: $(cat "$work/first.log")"
[ -f "$work/resumed/checkpoint.emfckpt" ] || fail "no checkpoint written"
"$app" run $scene --max-frames $frames --checkpoint-every 4 --resume "$work/resumed" --output "$work/resumed" > "$work/second.log" 2>&1 ||
  fail "resumed run failed: $(cat "$work/second.log")"
grep -q "resuming from .* at frame 6" "$work/second.log" || fail "no resume message: $(cat "$work/second.log")"
same_outputs "$work/straight" "$work/resumed"
grep -q '"frames": 12' "$work/resumed/run.json" || fail "run.json of the resumed run does not count 12 frames"
# frames.csv: the frames before the checkpoint kept, then the resumed ones.
[ "$(cut -d, -f1 "$work/resumed/frames.csv" | tail -n +2 | tr '\n' ' ')" = "$(seq -s ' ' 0 $((frames - 1))) " ] ||
  fail "frames.csv of the resumed run does not list frames 0..$((frames - 1)) once each"

# Meshes from the checkpoint alone equal the run's.
"$app" mesh "$work/resumed/checkpoint.emfckpt" --output "$work/meshed" > "$work/mesh.log" 2>&1 ||
  fail "mesh failed: $(cat "$work/mesh.log")"
for f in "$work/straight"/meshes/*.ply; do
  cmp -s "$f" "$work/meshed/meshes/$(basename "$f")" || fail "meshed/$(basename "$f") differs from the run's"
done

# A damaged checkpoint: refused, naming the file.
bad="$work/bad"
mkdir -p "$bad" && head -c 1000 "$work/resumed/checkpoint.emfckpt" > "$bad/checkpoint.emfckpt"
if "$app" run $scene --max-frames $frames --resume "$bad" --output "$work/bad-out" > "$work/bad.log" 2>&1; then
  fail "a truncated checkpoint was accepted"
fi
grep -q "bad/checkpoint.emfckpt'.*truncated" "$work/bad.log" || fail "unclear error: $(cat "$work/bad.log")"
echo "resumed run equals the straight run; meshes from the checkpoint equal the run's"
