// frames.csv (io/frame_log.hpp): a line per frame, on disk after every
// append, read back as written; malformed files are errors naming the file
// and the line. The run report (io/run_report.hpp) built from a run folder:
// a malformed frames.csv leaves the rest of the report and says why;
// pictures are embedded when the run has them.
#include <cmath>
#include <filesystem>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "emfusion/core/se3.hpp"
#include "emfusion/io/frame_log.hpp"
#include "emfusion/io/run_report.hpp"
#include "emfusion/io/tum.hpp"
#include "support/catch.hpp"
#include "support/files.hpp"

using namespace emfusion;
namespace fs = std::filesystem;
using emfusion::test::Approx;
using emfusion::test::contains;
using emfusion::test::error_of;
using emfusion::test::read_bytes;
using emfusion::test::ScratchDir;

namespace {

FrameLogRow row(std::size_t frame) {
  FrameLogRow r;
  r.frame = frame;
  r.timestamp = 1305031102.175304 + double(frame) / 30.0;
  r.times.preprocess = 1.25, r.times.e_step = 2.5, r.times.track_background = 10.125;
  r.times.integrate = 3, r.times.total = 20.5 + double(frame);
  r.objects = int(frame % 3);
  r.rss_mib = 512.5;
  if (frame % 2 == 1) r.device_mib = 1024.25;
  return r;
}

std::size_t lines(const std::string& text) {
  std::size_t n = 0;
  for (const char c : text) n += c == '\n';
  return n;
}

}  // namespace

TEST_CASE("frames.csv has a header and a line per frame, on disk after each append", "[io][frame_log]") {
  ScratchDir dir;
  const std::string path = dir.file("frames.csv");
  FrameLog log(path);
  CHECK(read_bytes(path) == frame_log_header() + "\n");
  CHECK(frame_log_header() ==
        "frame,timestamp,total_ms,preprocess_ms,e_step_ms,track_background_ms,track_objects_ms,raycast_ms,"
        "detections_ms,integrate_ms,foreground_ms,objects,rss_mib,device_mib");
  for (std::size_t i = 0; i < 5; ++i) {
    log.append(row(i));
    CHECK(lines(read_bytes(path)) == i + 2);  // flushed: no close needed
  }
  CHECK(log.rows() == 5);
  const std::string text = read_bytes(path);
  CHECK(contains(text, "\n0,1305031102.175304,20.500,1.250,2.500,10.125,0.000,0.000,0.000,3.000,0.000,0,512.5,\n"));
  CHECK(contains(text, ",1,512.5,1024.2\n"));  // %.1f of 1024.25: round half to even
  const std::vector<FrameLogRow> back = read_frame_log(path);
  REQUIRE(back.size() == 5);
  for (std::size_t i = 0; i < 5; ++i) {
    CHECK(back[i].frame == i);
    CHECK(back[i].timestamp == Approx(row(i).timestamp).margin(1e-6));
    CHECK(back[i].times.total == Approx(row(i).times.total));
    CHECK(back[i].times.track_background == Approx(10.125));
    CHECK(back[i].objects == row(i).objects);
    CHECK(back[i].device_mib.has_value() == (i % 2 == 1));
  }
  log.close();
  // A resumed run keeps the frames before its checkpoint.
  FrameLog resumed(path, {back[0], back[1]});
  resumed.append(row(2));
  resumed.close();
  CHECK(read_frame_log(path).size() == 3);
}

TEST_CASE("read_frame_log: malformed files are errors naming the file and the line", "[io][frame_log]") {
  ScratchDir dir;
  const std::string header = frame_log_header() + "\n";
  const std::string good = FrameLog::line(row(0));
  CHECK(read_frame_log(dir.write("ok.csv", header + good)).size() == 1);
  // A torn last line (killed mid-write) is left out.
  CHECK(read_frame_log(dir.write("torn.csv", header + good + "1,0.03,12")).size() == 1);
  const std::string missing = dir.file("missing.csv");
  CHECK(contains(error_of([&] { read_frame_log(missing); }), "missing.csv"));
  CHECK(contains(error_of([&] { read_frame_log(dir.write("empty.csv", "")); }), "empty.csv': empty file"));
  CHECK(contains(error_of([&] { read_frame_log(dir.write("header.csv", "frame,time\n" + good)); }),
                 "header.csv': line 1: expected the header"));
  CHECK(contains(error_of([&] { read_frame_log(dir.write("cells.csv", header + good + "1,2,3\n")); }),
                 "cells.csv': line 3: expected 14 comma-separated values, got 3"));
  std::string bad = good;
  bad.replace(bad.find(",20.500,"), 8, ",fast,");
  CHECK(contains(error_of([&] { read_frame_log(dir.write("value.csv", header + bad)); }),
                 "value.csv': line 2: value 3 'fast' is not a number"));
  CHECK(contains(error_of([&] { read_frame_log(dir.write("frame.csv", header + "-1" + good.substr(1))); }),
                 "frame.csv': line 2: frame '-1' is not a frame index"));
}

TEST_CASE("FrameLog: an unwritable file fails before the first frame", "[io][frame_log]") {
  CHECK(contains(error_of([] { FrameLog("/proc/emfusion-no-such-dir/frames.csv"); }),
                 "FrameLog: '/proc/emfusion-no-such-dir/frames.csv': cannot open for writing"));
  if (fs::exists("/dev/full"))
    CHECK(contains(error_of([] { FrameLog full("/dev/full"); }), "FrameLog: '/dev/full': cannot write"));
}

namespace {

Trajectory circle(int n, double offset) {
  Trajectory t;
  for (int i = 0; i < n; ++i) {
    const double a = 0.05 * i;
    t.push_back({i / 30.0, SE3<double>::from_quaternion(0, 0, 0, 1, vec3(std::cos(a) + offset, std::sin(a), 1.4))});
  }
  return t;
}

}  // namespace

TEST_CASE("The run report: a malformed frames.csv is reported, the rest is written", "[io][frame_log]") {
  ScratchDir dir;
  const Trajectory gt = circle(60, 0), est = circle(60, 0.01);
  std::vector<std::string> warnings;
  dir.write("frames.csv", frame_log_header() + "\n" + FrameLog::line(row(0)) + "1,0.03,oops\n");
  const std::string path = write_run_report("room", dir.path(), gt, {}, est, {}, warnings);
  REQUIRE(warnings.size() == 1);
  CHECK(contains(warnings[0], dir.file("frames.csv")));
  CHECK(contains(warnings[0], "line 3"));
  const std::string html = read_bytes(path);
  CHECK(contains(html, "line 3"));
  CHECK(contains(html, "camera ATE RMSE"));
  CHECK(contains(html, ">Top view</text>"));
  CHECK(contains(html, "run with <code>--pictures</code>"));
  CHECK(!contains(html, "http://"));
}

TEST_CASE("The run report embeds a run's pictures of a few frames", "[io][frame_log]") {
  ScratchDir dir;
  const Trajectory gt = circle(60, 0), est = circle(60, 0.01);
  FrameLog log(dir.file("frames.csv"));
  for (std::size_t i = 0; i < 60; ++i) {
    FrameLogRow r = row(i);
    r.timestamp = double(i) / 30.0;
    log.append(r);
  }
  log.close();
  const std::string png("\x89PNG\r\n\x1a\n", 8);
  for (int frame = 0; frame < 60; frame += 6) {
    char number[16];
    std::snprintf(number, sizeof(number), "%06d", frame);
    dir.write("pictures/segmentation_" + std::string(number) + ".png", png);
    dir.write("pictures/association_" + std::string(number) + "_background.png", png);
    dir.write("pictures/association_" + std::string(number) + "_object_2.png", png);
  }
  std::vector<std::string> warnings;
  const eval::ReportData d = run_report_data("room", dir.path(), gt, {}, est, {}, warnings);
  CHECK(warnings.empty());
  REQUIRE(d.frames.size() == report_picture_frames);
  CHECK(d.frames.front().title == "frame 0");
  CHECK(d.frames.back().title == "frame 54");
  CHECK(d.frames[0].pictures.size() == 3);
  CHECK(d.frames[0].pictures[1].caption == "association: background");
  CHECK(d.timings.time.size() == 60);
  CHECK(d.timings.stages.front().first == "total");
  CHECK(d.error_m.size() == 60);
  CHECK(d.rpe_m.size() > 0);
  const std::string html = eval::report_html(d);
  CHECK(contains(html, "src=\"data:image/png;base64,iVBORw0KGgo=\""));
  CHECK(!contains(html, "run with <code>--pictures</code>"));
}
