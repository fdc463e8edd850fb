// The run report's writers: SVG plots (ticks, labels, legend, escaping,
// degenerate data) and the HTML page (sections, nothing fetched from the
// network, pictures embedded or the way to get them).
#include <cmath>
#include <cstddef>
#include <limits>
#include <string>
#include <vector>

#include "emfusion/core/se3.hpp"
#include "emfusion/eval/report_html.hpp"
#include "emfusion/eval/rpe.hpp"
#include "emfusion/eval/svg_plot.hpp"
#include "support/catch.hpp"

using namespace emfusion::eval;
using emfusion::test::Approx;

namespace {

std::size_t count(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (std::size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + what.size())) ++n;
  return n;
}

bool contains(const std::string& text, const std::string& what) { return text.find(what) != std::string::npos; }

/// The texts of the elements of class `cls` ("xtick", "legend-entry", ...).
std::vector<std::string> texts(const std::string& svg, const std::string& cls) {
  std::vector<std::string> out;
  const std::string key = "class=\"" + cls + "\"";
  for (std::size_t at = svg.find(key); at != std::string::npos; at = svg.find(key, at + 1)) {
    const std::size_t open = svg.find('>', at) + 1;
    out.push_back(svg.substr(open, svg.find('<', open) - open));
  }
  return out;
}

bool is_nice(double step) {
  const double power = std::pow(10.0, std::floor(std::log10(step) + 1e-9));
  const double m = step / power;
  return std::fabs(m - 1) < 1e-9 || std::fabs(m - 2) < 1e-9 || std::fabs(m - 5) < 1e-9;
}

}  // namespace

TEST_CASE("nice_ticks are 1, 2 or 5 times a power of ten and cover the range", "[eval][report]") {
  const double ranges[][2] = {{0, 1}, {0.013, 0.087}, {-3.2, 7.9}, {1234, 98765}, {-0.5, -0.4}, {0, 2.3e-4}, {5, 5.5}};
  for (const auto& r : ranges) {
    const Ticks t = nice_ticks(r[0], r[1]);
    CAPTURE(r[0], r[1], t.step);
    CHECK(is_nice(t.step));
    CHECK(t.first <= r[0]);
    CHECK(t.last >= r[1]);
    REQUIRE(t.values.size() >= 2);
    CHECK(t.values.size() <= 12);
    CHECK(t.values.front() == t.first);
    for (std::size_t k = 0; k < t.values.size(); ++k) {
      const double multiple = t.values[k] / t.step;
      CHECK(std::fabs(multiple - std::round(multiple)) < 1e-6);
    }
  }
  CHECK(nice_step(0.3) == 0.5);
  CHECK(nice_step(3) == 5);
  CHECK(nice_step(7) == 10);
  CHECK(nice_step(0.02) == 0.02);
  CHECK(tick_text(0.25, 0.05) == "0.25");
  CHECK(tick_text(10, 5) == "10");
  CHECK(tick_text(-1e-17, 0.1) == "0.0");
}

TEST_CASE("nice_ticks handle a single value and non-finite bounds", "[eval][report]") {
  const Ticks constant = nice_ticks(3, 3);
  CHECK(constant.first < 3);
  CHECK(constant.last > 3);
  const Ticks zero = nice_ticks(0, 0);
  CHECK(zero.first < 0);
  CHECK(zero.last > 0);
  const Ticks nan = nice_ticks(std::nan(""), 1);
  CHECK(nan.first == 0);
  CHECK(nan.last == 1);
}

TEST_CASE("svg_plot labels its axes, ticks and legend", "[eval][report]") {
  SvgPlot p;
  p.title = "Error";
  p.x_label = "time (s)", p.y_label = "error (cm)";
  p.series.push_back({"estimate", {0, 1, 2, 3}, {0.5, 1.5, 2.5, 0.1}});
  p.series.push_back({"ground truth", {0, 1, 2, 3}, {0, 0, 1, 1}, "#000000", true, true});
  const std::string svg = svg_plot(p);
  CHECK(svg.rfind("<svg", 0) == 0);
  CHECK(contains(svg, "</svg>"));
  CHECK(contains(svg, ">time (s)</text>"));
  CHECK(contains(svg, ">error (cm)</text>"));
  CHECK(texts(svg, "legend-entry") == std::vector<std::string>{"estimate", "ground truth"});
  const std::vector<std::string> x = texts(svg, "xtick"), y = texts(svg, "ytick");
  REQUIRE(x.size() >= 3);
  REQUIRE(y.size() >= 3);
  CHECK(x.front() == "0");
  CHECK(x.back() == "3");
  CHECK(std::stod(y.front()) <= 0);
  CHECK(std::stod(y.back()) >= 2.5);
  CHECK(count(svg, "<polyline") == 2);
  CHECK(count(svg, "<circle") == 4 + 1);  // the second series' markers and its legend swatch
  CHECK(!contains(svg, "http://"));
}

TEST_CASE("svg_plot escapes its text", "[eval][report]") {
  SvgPlot p;
  p.title = "a < b & c";
  p.x_label = "<x>", p.y_label = "\"y\" & 'z'";
  p.series.push_back({"<script>alert(1)</script>", {0, 1}, {0, 1}});
  const std::string svg = svg_plot(p);
  CHECK(!contains(svg, "<script>"));
  CHECK(!contains(svg, "a < b"));
  CHECK(contains(svg, "a &lt; b &amp; c"));
  CHECK(contains(svg, "&lt;x&gt;"));
  CHECK(contains(svg, "&quot;y&quot; &amp; &#39;z&#39;"));
  CHECK(contains(svg, "&lt;script&gt;alert(1)&lt;/script&gt;"));
}

TEST_CASE("svg_plot survives empty, NaN and constant series", "[eval][report]") {
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  SvgPlot empty;
  empty.x_label = "x (m)", empty.y_label = "y (m)";
  CHECK(contains(svg_plot(empty), "no data"));
  empty.series.push_back({"nothing", {}, {}});
  empty.series.push_back({"all NaN", {nan, nan}, {nan, 1}});
  const std::string none = svg_plot(empty);
  CHECK(contains(none, "no data"));
  CHECK(count(none, "<polyline") == 0);
  CHECK(!contains(none, "nan"));
  CHECK(!contains(none, "inf"));

  SvgPlot constant;
  constant.series.push_back({"flat", {1, 2, 3}, {4, 4, 4}});
  constant.series.push_back({"one point", {2}, {4}});
  for (const bool equal : {false, true}) {
    constant.equal_scale = equal;
    const std::string svg = svg_plot(constant);
    CHECK(!contains(svg, "nan"));
    CHECK(!contains(svg, "inf"));
    CHECK(texts(svg, "ytick").size() >= 2);
    CHECK(count(svg, "<polyline") == 1);  // one point makes no line
  }

  SvgPlot gaps;
  gaps.series.push_back({"gaps", {0, 1, 2, 3, 4, 5}, {0, 1, nan, 3, inf, 5}, "", true, false});
  const std::string svg = svg_plot(gaps);
  CHECK(count(svg, "<polyline") == 1);  // 0-1 joined; 3 and 5 alone
  CHECK(!contains(svg, "nan"));
  SvgPlot mismatched;
  mismatched.series.push_back({"short y", {0, 1, 2}, {0, 1}});
  CHECK(count(svg_plot(mismatched), "<polyline") == 1);
}

TEST_CASE("svg_plot with equal scale gives both axes the same step", "[eval][report]") {
  SvgPlot p;
  p.equal_scale = true, p.width = 600, p.height = 300;
  p.series.push_back({"path", {0, 4, 4, 0}, {0, 0, 1, 1}});
  const std::string svg = svg_plot(p);
  const std::vector<std::string> x = texts(svg, "xtick"), y = texts(svg, "ytick");
  REQUIRE(x.size() >= 2);
  REQUIRE(y.size() >= 2);
  CHECK(std::stod(x[1]) - std::stod(x[0]) == Approx(std::stod(y[1]) - std::stod(y[0])));
}

TEST_CASE("base64 encodes as RFC 4648", "[eval][report]") {
  CHECK(base64("") == "");
  CHECK(base64("f") == "Zg==");
  CHECK(base64("fo") == "Zm8=");
  CHECK(base64("foo") == "Zm9v");
  CHECK(base64("foobar") == "Zm9vYmFy");
  CHECK(base64(std::string("\xff\x00\x80", 3)) == "/wCA");
}

namespace {

ReportData sample_report() {
  ReportData d;
  d.sequence = "room & <dyn>", d.output = "/tmp/out";
  d.summary = {{"camera ATE RMSE", "1.00 cm"}};
  for (int k = 0; k < 20; ++k) {
    const double t = 0.1 * k;
    d.ground_truth.push_back({std::cos(t), std::sin(t), 1.5});
    d.estimate.push_back({std::cos(t) + 0.01, std::sin(t), 1.49});
    d.error_time.push_back(t);
    d.error_m.push_back(0.01);
    if (k < 10) d.rpe_time.push_back(t), d.rpe_m.push_back(0.02);
  }
  ReportObject cup;
  cup.name = "cup_2", cup.estimate = "3", cup.class_name = "cup", cup.evaluated = true, cup.ate_m = 0.031;
  cup.coverage = 0.8, cup.first_time = 0.1, cup.last_time = 1.9;
  ReportObject stray;
  stray.estimate = "7", stray.class_name = "book", stray.problem = "matches no ground-truth object";
  d.objects = {cup, stray};
  d.timings.time = {0, 0.1, 0.2};
  d.timings.stages = {{"total", {10, 12, 11}}, {"preprocess", {1, 2, 1}}};
  d.timings.objects = {0, 1, 1};
  d.timings.rss_mib = {100, 110, 120};
  d.timings.device_mib = {std::nan(""), std::nan(""), std::nan("")};
  return d;
}

}  // namespace

TEST_CASE("report_html has every section and fetches nothing", "[eval][report]") {
  ReportData d = sample_report();
  const std::string html = report_html(d);
  CHECK(html.rfind("<!DOCTYPE html>", 0) == 0);
  for (const char* id : {"summary", "trajectory", "error", "rpe", "objects", "timing", "memory", "pictures"})
    CHECK(contains(html, "<section id=\"" + std::string(id) + "\">"));
  CHECK(count(html, "<svg") == 7);  // top, side, error, RPE, stages, objects, memory
  CHECK(contains(html, ">Top view</text>"));
  CHECK(contains(html, ">Side view</text>"));
  CHECK(contains(html, ">error (cm)</text>"));
  CHECK(contains(html, ">memory (MiB)</text>"));
  CHECK(contains(html, ">estimate (aligned)</text>"));
  CHECK(contains(html, ">x (m)</text>"));  // z is the vertical: the floor is x-y
  CHECK(contains(html, ">z (m)</text>"));
  CHECK(contains(html, "cup_2"));
  CHECK(contains(html, "3.10 cm"));
  CHECK(contains(html, "matches no ground-truth object"));
  CHECK(contains(html, "room &amp; &lt;dyn&gt;"));
  CHECK(!contains(html, "http://"));
  CHECK(!contains(html, "https://"));
  CHECK(!contains(html, "<script"));
  CHECK(!contains(html, "<link"));
  CHECK(!contains(html, "url(http"));
}

TEST_CASE("report_html embeds pictures, or says how to get them", "[eval][report]") {
  ReportData d = sample_report();
  const std::string without = report_html(d);
  CHECK(contains(without, "--pictures"));
  CHECK(!contains(without, "data:image/png;base64,"));

  d.frames.push_back(
      {"frame 12", {{"segmentation", std::string("\x89PNG\r\n\x1a\n", 8)}, {"association: background", "xyz"}}});
  d.frames.push_back({"frame 40", {{"segmentation", "abc"}}});
  const std::string with = report_html(d);
  CHECK(count(with, "src=\"data:image/png;base64,") == 3);
  CHECK(contains(with, "data:image/png;base64,iVBORw0KGgo="));
  CHECK(contains(with, "frame 12"));
  CHECK(contains(with, "association: background"));
  CHECK(!contains(with, "run with <code>--pictures</code>"));
  CHECK(!contains(with, "http://"));
}

TEST_CASE("report_html says why a part is missing", "[eval][report]") {
  ReportData d;
  d.camera_problem = "camera.txt has 2 poses: at least 3 are needed";
  d.timings_problem = "read_frame_log: 'out/frames.csv': line 3: value 2 'x' is not a number";
  d.pictures_problem = "the run has no pictures";
  const std::string html = report_html(d);
  CHECK(contains(html, "camera.txt has 2 poses"));
  CHECK(contains(html, "&#39;out/frames.csv&#39;: line 3"));
  CHECK(contains(html, "the run has no pictures"));
  for (const char* id : {"summary", "trajectory", "error", "rpe", "objects", "timing", "memory", "pictures"})
    CHECK(contains(html, "<section id=\"" + std::string(id) + "\">"));
  CHECK(count(html, "<svg") == 0);
}

TEST_CASE("relative_pose_errors lists the windows relative_pose_error sums", "[eval][report]") {
  // A camera whose estimate drifts 5 cm per second along x.
  emfusion::Trajectory gt, est;
  for (int i = 0; i < 90; ++i) {
    const double t = i / 30.0;
    const auto pose = emfusion::SE3<double>::from_quaternion(0, 0, 0, 1, emfusion::vec3(0.3 * t, 0.1, 1.5));
    gt.push_back({t, pose});
    est.push_back({t, emfusion::SE3<double>::from_quaternion(0, 0, 0, 1, emfusion::vec3(0.35 * t, 0.1, 1.5))});
  }
  const std::vector<RpePair> pairs = relative_pose_errors(est, gt);
  const RpeResult rpe = relative_pose_error(est, gt);
  REQUIRE(pairs.size() == rpe.pairs);
  REQUIRE(pairs.size() == 60);  // the windows that end within the 3 s
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    CHECK(pairs[k].start == Approx(k / 30.0));
    CHECK(pairs[k].end - pairs[k].start == Approx(1.0));
    CHECK(pairs[k].translation == Approx(0.05));
    CHECK(pairs[k].rotation_deg == Approx(0.0).margin(1e-9));
  }
  CHECK(rpe.translation_rmse == Approx(0.05));
}
