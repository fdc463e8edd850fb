#!/usr/bin/env bash
# ctest driver: stops `emfusion run` in the middle and checks what it left
# (docs/user-guide.md, "Stopping a run").
#
#   stopped_run.sh <emfusion> <case> <work dir>
#
# Cases:
#   sigint, sigterm  one signal after the K-th camera pose: exit 130 / 143,
#                    every output for exactly the frames processed, run.json
#                    "interrupted" with that count, and `emfusion eval` reads it
#   twice            SIGINT and SIGTERM at once: the second to arrive ends
#                    the process (130 or 143: threads may take them in either
#                    order) without writing the final outputs; the streamed
#                    trajectories still parse
#   sigkill          SIGKILL: camera.txt, objects.txt and objects/<id>.txt
#                    parse and `emfusion eval` reads them
#   devfull          camera.txt a symlink to /dev/full: a clear error before
#                    the first frame
#   fullfs           a 64 KiB tmpfs as the output (needs `unshare -m` and
#                    mount, so root; else skipped): a clear error when the
#                    disk fills, no half-written file under a final name
#   fills            the same with a 1 MiB tmpfs that a file fills after the
#                    K-th pose: a clear error at the next write, the frames
#                    before it kept
#   readonly         an output directory that cannot be written (chmod 0555;
#                    as root, where modes do not stop writes, chattr +i; else
#                    skipped): a clear error before the first frame
# Exit 0: passed; 77: skipped (ctest SKIP_RETURN_CODE); anything else: failed.
set -u
app=$1 case=$2 work=$3
scene=synthetic:room-small
frames=40   # requested; the signal comes well before the end, even on a fast machine
K=3         # camera poses on disk before the signal

fail() { echo "FAIL ($case): $*" >&2; [ -f "$work/log.txt" ] && sed 's/^/  log: /' "$work/log.txt" >&2; exit 1; }
skip() { echo "SKIPPED ($case): $*"; exit 77; }

# Pose lines of a TUM file (comments and blank lines not counted).
poses() { if [ -f "$1" ]; then grep -cv -e '^#' -e '^[[:space:]]*$' "$1"; else echo 0; fi; }
# Every pose line has 8 numeric fields: nothing torn.
check_tum() {
  [ -f "$1" ] || fail "$1 is missing"
  awk '!/^#/ && NF { if (NF != 8) exit 1; for (i = 1; i <= 8; ++i) if ($i !~ /^-?[0-9]+\.[0-9]+$/) exit 1 }' "$1" ||
    fail "$1 has a line that is not a whole pose"
}
json_value() { sed -n "s/^  \"$1\": \(.*\),\?$/\1/p" "$2" | sed 's/,$//' | head -n 1; }

# Starts the run in the background (job control on: a shell script starts
# background jobs with SIGINT ignored otherwise) and waits for K poses.
start_run() {
  set -m
  "$app" run "$scene" --max-frames "$frames" --output "$work/out" >"$work/log.txt" 2>&1 &
  pid=$!
  set +m
  local waited=0
  while [ "$(poses "$work/out/camera.txt")" -lt "$K" ]; do
    kill -0 "$pid" 2>/dev/null || fail "the run ended before writing $K poses"
    sleep 0.1
    waited=$((waited + 1))
    [ "$waited" -lt 3000 ] || { kill -KILL "$pid"; fail "no $K poses after 300 s"; }
  done
}

# Waits for the run (bounded: a run that ignores the signal is killed).
finish_run() {
  local waited=0
  while kill -0 "$pid" 2>/dev/null; do
    sleep 0.1
    waited=$((waited + 1))
    [ "$waited" -lt 3000 ] || { kill -KILL "$pid"; fail "still running 300 s after the signal"; }
  done
  wait "$pid"
  status=$?
}

chattr -i "$work/out" 2>/dev/null  # left immutable by a readonly run that was killed
rm -rf "$work"
mkdir -p "$work"
# A shell cannot undo a SIGINT ignored since it started (a CI job started in
# the background without job control), and the app, by convention, keeps
# ignoring it then.
if [ "$case" = sigint ] || [ "$case" = twice ]; then
  ignored=$(sed -n 's/^SigIgn:[[:space:]]*//p' /proc/$$/status 2>/dev/null)
  [ -n "$ignored" ] && [ $((0x$ignored & 2)) != 0 ] && skip "SIGINT is ignored in this shell (inherited), so in the run too"
fi
case $case in
  sigint | sigterm)
    signal=${case#sig}; signal=${signal^^}
    expected=$([ "$signal" = INT ] && echo 130 || echo 143)
    start_run
    before=$(poses "$work/out/camera.txt")
    kill -s "$signal" "$pid"
    after=$(poses "$work/out/camera.txt")
    finish_run
    [ "$status" = "$expected" ] || fail "exit status $status, expected $expected"
    grep -q "SIG$signal: stopped after" "$work/log.txt" || fail "no 'stopped after' message"
    grep -q "wrote .*interrupted by SIG$signal" "$work/log.txt" || fail "no 'wrote ... interrupted' message"
    [ "$(json_value status "$work/out/run.json")" = '"interrupted"' ] || fail "run.json does not say interrupted"
    [ "$(json_value signal "$work/out/run.json")" = "\"SIG$signal\"" ] || fail "run.json does not name SIG$signal"
    n=$(json_value frames "$work/out/run.json")
    # It finishes the frame it is on: the poses seen before the signal,
    # plus at most the one in progress.
    [ "$n" -ge "$before" ] && [ "$n" -le $((after + 1)) ] && [ "$n" -lt "$frames" ] ||
      fail "run.json says $n frames; $before poses before the signal, $after just after, $frames requested"
    [ "$(json_value last_frame "$work/out/run.json")" = $((n - 1)) ] || fail "run.json's last_frame is not $((n - 1))"
    check_tum "$work/out/camera.txt"
    [ "$(poses "$work/out/camera.txt")" = "$n" ] || fail "camera.txt has $(poses "$work/out/camera.txt") poses, not $n"
    [ "$(($(wc -l <"$work/out/frames.csv") - 1))" = "$n" ] || fail "frames.csv has not $n frame lines"
    [ -s "$work/out/objects.txt" ] || fail "objects.txt is missing"
    ids=$(awk '!/^#/ && NF { print $1 }' "$work/out/objects.txt")
    [ -n "$ids" ] || fail "objects.txt lists no object (room-small creates some on its first frames)"
    for id in $ids; do
      check_tum "$work/out/objects/$id.txt"
      [ "$(poses "$work/out/objects/$id.txt")" -le "$n" ] || fail "objects/$id.txt has more than $n poses"
    done
    # run.json's objects (their events and tracking counts): one entry per
    # object of objects.txt, each created once and tracked at most n frames.
    python3 - "$work/out/run.json" "$n" $ids <<'PY' || fail "run.json's objects do not match objects.txt"
import json, sys
run = json.load(open(sys.argv[1]))
frames, ids = int(sys.argv[2]), sorted(int(i) for i in sys.argv[3:])
objects = {o['id']: o for o in run['objects']}
assert sorted(objects) == ids, (sorted(objects), ids)
for o in objects.values():
    assert [e['event'] for e in o['events']].count('created') == 1, o
    assert 0 <= o['tracked_frames'] + o['refused_frames'] <= frames, o
PY
    [ -s "$work/out/meshes/background.ply" ] || fail "meshes/background.ply is missing"
    ls "$work/out/meshes/"object_*.ply >/dev/null 2>&1 || fail "no object mesh"
    ls "$work/out" "$work/out/objects" "$work/out/meshes" | grep -q '\.tmp$' && fail "a .tmp file was left"
    "$app" eval "$scene" "$work/out" >"$work/eval.txt" 2>&1 || { cat "$work/eval.txt" >&2; fail "emfusion eval failed"; }
    grep -q "ATE RMSE .* over $n poses" "$work/eval.txt" || { cat "$work/eval.txt" >&2; fail "eval did not use $n poses"; }
    ;;
  twice)
    start_run
    kill -INT "$pid"
    kill -TERM "$pid"
    finish_run
    [ "$status" = 130 ] || [ "$status" = 143 ] || fail "exit status $status, expected 130 or 143"
    grep -q "^wrote" "$work/log.txt" && fail "it wrote the final outputs after a second signal"
    [ "$(json_value status "$work/out/run.json")" = '"running"' ] || fail "run.json was replaced after a second signal"
    check_tum "$work/out/camera.txt"
    [ "$(poses "$work/out/camera.txt")" -ge "$K" ] || fail "camera.txt lost poses"
    ;;
  sigkill)
    start_run
    kill -KILL "$pid"
    finish_run
    [ "$status" = 137 ] || fail "exit status $status, expected 137 (killed)"
    check_tum "$work/out/camera.txt"
    n=$(poses "$work/out/camera.txt")
    [ "$n" -ge "$K" ] || fail "camera.txt has $n poses, fewer than the $K seen before the kill"
    [ "$(json_value status "$work/out/run.json")" = '"running"' ] || fail "run.json does not say running"
    [ -f "$work/out/objects.txt" ] || fail "objects.txt is missing"
    for id in $(awk '!/^#/ && NF { print $1 }' "$work/out/objects.txt"); do
      check_tum "$work/out/objects/$id.txt"
    done
    "$app" eval "$scene" "$work/out" >"$work/eval.txt" 2>&1 || { cat "$work/eval.txt" >&2; fail "emfusion eval failed"; }
    grep -q "ATE RMSE .* over $n poses" "$work/eval.txt" || { cat "$work/eval.txt" >&2; fail "eval did not use $n poses"; }
    ;;
  devfull)
    [ -c /dev/full ] || skip "no /dev/full"
    mkdir -p "$work/out"
    ln -s /dev/full "$work/out/camera.txt"
    "$app" run "$scene" --max-frames "$frames" --output "$work/out" >"$work/log.txt" 2>&1
    status=$?
    [ "$status" = 1 ] || fail "exit status $status, expected 1"
    grep -q "^emfusion: error: TumTrajectoryStream: '.*/out/camera.txt': cannot write: No space left on device$" \
      "$work/log.txt" || fail "not the expected error"
    ;;
  fullfs)
    command -v unshare >/dev/null || skip "no unshare"
    mkdir -p "$work/out"
    unshare -m true 2>/dev/null || skip "cannot make a mount namespace (not root?)"
    # The tmpfs exists only inside the namespace, for the run.
    unshare -m bash -c '
      mount -t tmpfs -o size=64k tmpfs "$2" || exit 77
      "$1" run "$3" --max-frames "$4" --output "$2" >"$5/log.txt" 2>&1
      echo $? >"$5/status"
      cp -r "$2" "$5/left" 2>/dev/null
      exit 0' _ "$app" "$work/out" "$scene" 3 "$work"
    [ $? = 77 ] && skip "cannot mount a tmpfs"
    status=$(cat "$work/status" 2>/dev/null)
    [ "$status" = 1 ] || fail "exit status $status, expected 1"
    grep -q "^emfusion: error: .*'$work/out/[^']*': .*No space left on device" "$work/log.txt" ||
      fail "not an error naming a file of the output and the full disk"
    grep -q "^wrote" "$work/log.txt" && fail "it said it wrote the outputs"
    # What is there under a final name is whole.
    find "$work/left" -name '*.tmp' | grep -q . && fail "a .tmp file was left"
    [ -f "$work/left/camera.txt" ] && check_tum "$work/left/camera.txt"
    for f in "$work/left"/objects/*.txt; do [ -f "$f" ] && check_tum "$f"; done
    ;;
  fills)
    command -v unshare >/dev/null || skip "no unshare"
    mkdir -p "$work/out"
    unshare -m true 2>/dev/null || skip "cannot make a mount namespace (not root?)"
    unshare -m bash -c '
      mount -t tmpfs -o size=1m tmpfs "$2" || exit 77
      "$1" run "$3" --max-frames "$4" --output "$2" >"$5/log.txt" 2>&1 &
      pid=$!
      for i in $(seq 3000); do
        [ "$(grep -cv "^#" "$2/camera.txt" 2>/dev/null)" -ge "$6" ] 2>/dev/null && break
        kill -0 $pid 2>/dev/null || break
        sleep 0.1
      done
      grep -cv "^#" "$2/camera.txt" >"$5/poses-before-fill" 2>/dev/null
      dd if=/dev/zero of="$2/fill" bs=4k 2>/dev/null
      for i in $(seq 3000); do kill -0 $pid 2>/dev/null || break; sleep 0.1; done
      kill -KILL $pid 2>/dev/null
      wait $pid
      echo $? >"$5/status"
      rm -f "$2/fill"
      cp -r "$2" "$5/left" 2>/dev/null
      exit 0' _ "$app" "$work/out" "$scene" "$frames" "$work" "$K"
    [ $? = 77 ] && skip "cannot mount a tmpfs"
    status=$(cat "$work/status" 2>/dev/null)
    [ "$status" = 1 ] || fail "exit status $status, expected 1"
    grep -q "^emfusion: error: .*'$work/out/[^']*': .*No space left on device" "$work/log.txt" ||
      fail "not an error naming a file of the output and the full disk"
    find "$work/left" -name '*.tmp' | grep -q . && fail "a .tmp file was left"
    check_tum "$work/left/camera.txt"
    [ "$(poses "$work/left/camera.txt")" -ge "$(cat "$work/poses-before-fill")" ] || fail "camera.txt lost poses"
    [ "$(poses "$work/left/camera.txt")" -lt "$frames" ] || fail "the run did not stop at the full disk"
    for f in "$work/left"/objects/*.txt; do [ -f "$f" ] && check_tum "$f"; done
    ;;
  readonly)
    mkdir -p "$work/out"
    if [ "$(id -u)" != 0 ]; then
      chmod 0555 "$work/out"
      trap 'chmod 0755 "$work/out"' EXIT
      problem="Permission denied"
    elif chattr +i "$work/out" 2>/dev/null; then
      trap 'chattr -i "$work/out"' EXIT
      problem="Operation not permitted"
    else
      skip "running as root, where chmod does not stop writes, and chattr +i is not available here"
    fi
    "$app" run "$scene" --max-frames "$frames" --output "$work/out" >"$work/log.txt" 2>&1
    status=$?
    [ "$status" = 1 ] || fail "exit status $status, expected 1"
    grep -q "^emfusion: error: check_writable_directory: '.*/out/.emfusion-write-test': cannot open .* for writing: $problem$" \
      "$work/log.txt" || fail "not the expected error"
    grep -q "frame" "$work/log.txt" && fail "it processed frames before failing"
    ;;
  *)
    echo "unknown case '$case'" >&2
    exit 2
    ;;
esac
echo "passed ($case)"
