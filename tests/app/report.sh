#!/usr/bin/env bash
# ctest driver: the run report (docs/evaluation.md, "The run report").
#
#   report.sh <emfusion> <work dir>
#
# A short `emfusion run --pictures` of a built-in scene writes frames.csv
# with one line per frame; `emfusion eval` writes report.html with every
# section, the pictures embedded and nothing fetched from the network; a
# malformed frames.csv makes eval warn, naming the file and the line, and the
# report still comes out with everything else. Then headless Chromium opens
# the page: its screenshot is not blank, its DOM has the sections, and its
# console shows no error. Without Chromium the browser part is skipped (77,
# ctest SKIP_RETURN_CODE) after the other checks passed.
set -u
app=$1 work=$2
scene=synthetic:room-small
frames=34   # over 1 s at 30 fps: the report has an RPE plot

fail() { echo "FAIL: $*" >&2; exit 1; }

rm -rf "$work"
mkdir -p "$work"
out=$work/run
"$app" run "$scene" --max-frames $frames --output "$out" --pictures >"$work/run.log" 2>&1 ||
  { cat "$work/run.log" >&2; fail "emfusion run failed"; }

# frames.csv: the header and one line per frame, 14 cells each.
[ -f "$out/frames.csv" ] || fail "no frames.csv"
head -n 1 "$out/frames.csv" | grep -q '^frame,timestamp,total_ms,.*,objects,rss_mib,device_mib$' ||
  fail "frames.csv's header is $(head -n 1 "$out/frames.csv")"
lines=$(($(wc -l <"$out/frames.csv") - 1))
[ "$lines" -eq $frames ] || fail "frames.csv has $lines frame lines, expected $frames"
awk -F, 'NR > 1 && NF != 14 { exit 1 }' "$out/frames.csv" || fail "frames.csv has a line without 14 cells"
awk -F, -v n=$frames 'NR > 1 && $1 != NR - 2 { exit 1 }' "$out/frames.csv" || fail "frames.csv's frame column is not 0..$((frames - 1))"

"$app" eval "$scene" "$out" >"$work/eval.log" 2>&1 || { cat "$work/eval.log" >&2; fail "emfusion eval failed"; }
report=$out/report.html
[ -f "$report" ] || fail "no report.html"
grep -q "wrote $report" "$work/eval.log" || fail "eval does not say it wrote $report"
[ ! -e "$out/trajectory.png" ] || fail "trajectory.png is still written"
for id in summary trajectory error rpe objects timing memory pictures; do
  grep -q "<section id=\"$id\">" "$report" || fail "report.html has no section '$id'"
done
grep -q 'src="data:image/png;base64,' "$report" || fail "report.html embeds no picture"
grep -Eiq '(src|href)="?(https?:)?//' "$report" && fail "report.html refers to something on the network"
grep -Eq 'https?://' "$report" && fail "report.html has an http(s) address"

# A malformed frames.csv: a warning naming the file and the line, and the rest of the report.
bad=$work/bad
cp -r "$out" "$bad"
rm -f "$bad/report.html"
sed -i '3s/^\([0-9]*\),[^,]*,/\1,soon,/' "$bad/frames.csv"
"$app" eval "$scene" "$bad" >"$work/bad.log" 2>&1 || { cat "$work/bad.log" >&2; fail "emfusion eval failed on a malformed frames.csv"; }
grep -q "warning: .*$bad/frames.csv.*line 3" "$work/bad.log" ||
  { cat "$work/bad.log" >&2; fail "no warning naming $bad/frames.csv and its line 3"; }
[ -f "$bad/report.html" ] || fail "no report.html with a malformed frames.csv"
grep -q "line 3: value 2 &#39;soon&#39; is not a number" "$bad/report.html" || fail "the report does not say why frames.csv was not read"
grep -q '<section id="objects">' "$bad/report.html" || fail "the report with a malformed frames.csv misses sections"
grep -q 'src="data:image/png;base64,' "$bad/report.html" || fail "the report with a malformed frames.csv has no pictures"

# In a browser.
browser=
for b in chromium chromium-browser google-chrome; do
  command -v "$b" >/dev/null 2>&1 && { browser=$b; break; }
done
if [ -z "$browser" ]; then
  echo "SKIPPED: the report's files are checked, but no Chromium to open it (apt-get install chromium)"
  exit 77
fi
flags=(--headless --disable-gpu --no-sandbox --hide-scrollbars --user-data-dir="$work/profile" --window-size=1200,3000)
shot=$work/report.png
timeout 120 "$browser" "${flags[@]}" --enable-logging=stderr --v=0 --screenshot="$shot" "file://$report" \
  >"$work/browser.log" 2>&1 || { cat "$work/browser.log" >&2; fail "$browser failed to take a screenshot"; }
[ -f "$shot" ] || fail "no screenshot"
size=$(stat -c %s "$shot")
[ "$size" -gt 50000 ] || fail "the screenshot is $size bytes: blank?"
if grep -E 'CONSOLE|Uncaught|net::ERR' "$work/browser.log"; then fail "the browser's console shows errors (above)"; fi
# Many distinct pixel values (a blank page has one or two), by the PNG's
# rows (zlib, Python's standard library).
if command -v python3 >/dev/null 2>&1; then
  python3 - "$shot" <<'EOF' || fail "the screenshot looks blank"
import struct, sys, zlib
data = open(sys.argv[1], "rb").read()
pos, idat = 8, b""
while pos < len(data):
    n, kind = struct.unpack(">I4s", data[pos:pos + 8])
    if kind == b"IDAT":
        idat += data[pos + 8:pos + 8 + n]
    pos += 12 + n
raw = zlib.decompress(idat)
colours = len(set(raw[i:i + 3] for i in range(0, min(len(raw), 3_000_000) - 3, 3)))
print(f"screenshot: {len(raw)} bytes of rows, {colours} distinct 3-byte values")
sys.exit(0 if colours > 200 else 1)
EOF
fi
timeout 120 "$browser" "${flags[@]}" --dump-dom "file://$report" >"$work/dom.html" 2>"$work/dom.log" ||
  { cat "$work/dom.log" >&2; fail "$browser failed to dump the DOM"; }
for text in "Camera trajectory" "Translation error over time" "Relative pose error" "Objects" "Time per frame" \
  "Memory" "Segmentation and association"; do
  grep -q "$text" "$work/dom.html" || fail "the page's DOM has no '$text'"
done
[ "$(grep -o '<svg' "$work/dom.html" | wc -l)" -ge 7 ] || fail "the page's DOM has fewer than 7 plots"
echo "report: $report ($(stat -c %s "$report") bytes), screenshot $shot ($size bytes)"
