// The run report: one self-contained HTML page (report.html of `emfusion
// eval`, docs/evaluation.md "The run report") made of plain data, so that it
// can be built and tested without a run. Everything is inline: CSS in a
// <style> element, plots as SVG (eval/svg_plot.hpp), pictures as base64 PNG
// data: URIs; no script, font or style sheet is fetched, so the page opens
// offline and can be mailed or archived as one file.
//
// Sections (their element ids): summary, trajectory (top and side view of
// the camera against ground truth after the ATE alignment), error
// (translation error over time), rpe (relative translation error over 1 s
// windows), objects (per-object table), timing (per-stage time per frame and
// objects alive), memory (resident and device memory), pictures
// (segmentation and association of selected frames, or how to get them).
// A part without data says why in its section ("problem" strings).
//
// Standard library only.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "emfusion/eval/svg_plot.hpp"

namespace emfusion::eval {

/// `bytes` in base64 (RFC 4648, with padding), for data: URIs.
inline std::string base64(std::string_view bytes) {
  static constexpr char table[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const unsigned v = unsigned(static_cast<unsigned char>(bytes[i])) << 16 |
                       unsigned(static_cast<unsigned char>(bytes[i + 1])) << 8 |
                       unsigned(static_cast<unsigned char>(bytes[i + 2]));
    out += table[v >> 18 & 63], out += table[v >> 12 & 63], out += table[v >> 6 & 63], out += table[v & 63];
  }
  if (i < bytes.size()) {
    unsigned v = unsigned(static_cast<unsigned char>(bytes[i])) << 16;
    if (i + 1 < bytes.size()) v |= unsigned(static_cast<unsigned char>(bytes[i + 1])) << 8;
    out += table[v >> 18 & 63], out += table[v >> 12 & 63];
    out += i + 1 < bytes.size() ? table[v >> 6 & 63] : '=';
    out += '=';
  }
  return out;
}

/// One row of the object table.
struct ReportObject {
  std::string name;        ///< ground-truth name, or "" for an estimate matched to none
  std::string estimate;    ///< id(s) of the estimated object(s), "" for none
  std::string class_name;  ///< the estimate's class, "" when unknown
  bool evaluated = false;
  double ate_m = std::nan("");
  double coverage = std::nan("");                              ///< 0..1
  double first_time = std::nan(""), last_time = std::nan("");  ///< seconds since the first frame
  std::string problem;                                         ///< why not evaluated
};

/// Per-frame figures of frames.csv.
struct ReportTimings {
  std::vector<double> time;  ///< seconds since the first frame
  /// Milliseconds per frame by stage; the first is the frame's total.
  std::vector<std::pair<std::string, std::vector<double>>> stages;
  std::vector<double> objects;
  std::vector<double> rss_mib, device_mib;  ///< NaN where not measured
};

/// An embedded picture: PNG bytes and a caption.
struct ReportPicture {
  std::string caption;
  std::string png;
};

/// The pictures of one frame.
struct ReportFrame {
  std::string title;
  std::vector<ReportPicture> pictures;
};

struct ReportData {
  std::string title = "EM-Fusion run report";
  std::string sequence, output;
  /// Lines of the summary table, e.g. {"camera ATE RMSE", "2.31 cm"}.
  std::vector<std::pair<std::string, std::string>> summary;

  /// Ground truth and estimate positions (x, y, z in metres, the estimate
  /// mapped by the ATE alignment), one entry per matched pose.
  std::vector<std::array<double, 3>> ground_truth, estimate;
  std::vector<double> error_time, error_m;  ///< per matched pose: seconds since the first frame, metres
  std::string camera_problem;               ///< why there is no camera evaluation ("" if there is)
  std::vector<double> rpe_time, rpe_m;      ///< per 1 s window: its start, translation error in metres
  std::string rpe_problem;

  std::vector<ReportObject> objects;
  std::string objects_problem;

  ReportTimings timings;
  std::string timings_problem;  ///< e.g. frames.csv missing or malformed

  std::vector<ReportFrame> frames;  ///< pictures of selected frames
  std::string pictures_problem;     ///< shown when `frames` is empty
};

namespace detail::report {

inline std::string fixed(double v, int decimals, const char* unit = "") {
  if (!std::isfinite(v)) return "–";
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%.*f%s", decimals, v, unit);
  return buffer;
}

/// The vertical axis (0 x, 1 y, 2 z): the one along which the ground truth
/// spreads least (a hand-held or robot camera keeps its height better than
/// it keeps its place on the floor). Then the two floor axes in order.
inline std::array<int, 3> floor_axes(const std::vector<std::array<double, 3>>& points) {
  std::array<double, 3> lo{}, hi{};
  lo.fill(INFINITY), hi.fill(-INFINITY);
  for (const auto& p : points)
    for (int a = 0; a < 3; ++a)
      if (std::isfinite(p[std::size_t(a)]))
        lo[std::size_t(a)] = std::min(lo[std::size_t(a)], p[std::size_t(a)]),
        hi[std::size_t(a)] = std::max(hi[std::size_t(a)], p[std::size_t(a)]);
  std::array<double, 3> spread{};
  for (std::size_t a = 0; a < 3; ++a) spread[a] = hi[a] >= lo[a] ? hi[a] - lo[a] : 0;
  int up = 2;
  for (int a = 0; a < 3; ++a)
    if (spread[std::size_t(a)] < spread[std::size_t(up)]) up = a;
  std::array<int, 3> r{};
  int k = 0;
  for (int a = 0; a < 3; ++a)
    if (a != up) r[std::size_t(k++)] = a;
  r[2] = up;
  return r;
}

inline const char* axis_name(int a) { return a == 0 ? "x" : a == 1 ? "y" : "z"; }

inline std::vector<double> coordinate(const std::vector<std::array<double, 3>>& p, int axis) {
  std::vector<double> v;
  v.reserve(p.size());
  for (const auto& q : p) v.push_back(q[std::size_t(axis)]);
  return v;
}

inline std::vector<double> scaled(const std::vector<double>& v, double factor) {
  std::vector<double> out(v);
  for (double& x : out) x *= factor;
  return out;
}

inline std::string problem(const std::string& text) { return "<p class=\"problem\">" + xml_escape(text) + "</p>\n"; }

/// Median and 90th percentile of the finite values.
inline std::pair<double, double> median_p90(std::vector<double> v) {
  v.erase(std::remove_if(v.begin(), v.end(), [](double x) { return !std::isfinite(x); }), v.end());
  if (v.empty()) return {NAN, NAN};
  std::sort(v.begin(), v.end());
  const auto at = [&](double q) { return v[std::min(v.size() - 1, std::size_t(q * double(v.size() - 1) + 0.5))]; };
  return {at(0.5), at(0.9)};
}

constexpr const char* style =
    R"(body{font-family:sans-serif;margin:24px auto;max-width:1180px;color:#222;background:#fafafa}
h1{font-size:24px;margin-bottom:4px}h2{font-size:19px;margin-top:28px;border-bottom:1px solid #ccc;padding-bottom:4px}
section{background:#fff;padding:8px 16px 16px;margin-bottom:12px;border:1px solid #e2e2e2}
table{border-collapse:collapse;font-size:14px}td,th{border:1px solid #ccc;padding:4px 10px;text-align:right}
th{background:#f0f0f0}td.name,th.name{text-align:left}.problem{color:#a33;font-style:italic}
.plots{display:flex;flex-wrap:wrap;gap:12px}.note{color:#555;font-size:14px}
figure{display:inline-block;margin:4px;vertical-align:top}figure img{width:280px;border:1px solid #ccc}
figcaption{font-size:13px;color:#444;max-width:280px}code{background:#f0f0f0;padding:1px 4px}
)";


/// Labels of one curve over time (series_section).
struct SeriesLabels {
  const char* title;
  const char* x_label;
  const char* y_label;
  const char* legend;
  int colour;
};

/// A report section with one curve of metres over time, drawn in centimetres,
/// or the reason it is missing when there are no values.
inline std::string series_section(const char* id, const char* heading, const std::vector<double>& time,
                                  const std::vector<double>& metres, const std::string& missing, const char* note,
                                  const SeriesLabels& labels) {
  std::string h = std::string("<section id=\"") + id + "\"><h2>" + heading + "</h2>\n";
  if (metres.empty()) {
    h += problem(missing);
  } else {
    h += std::string("<p class=\"note\">") + note + "</p>\n";
    SvgPlot p;
    p.title = labels.title, p.width = 1120, p.height = 320, p.y_from_zero = true;
    p.x_label = labels.x_label, p.y_label = labels.y_label;
    p.series.push_back({labels.legend, time, scaled(metres, 100), plot_colour(labels.colour)});
    h += svg_plot(p);
  }
  return h + "</section>\n";
}
}  // namespace detail::report

/// The whole page.
inline std::string report_html(const ReportData& d) {
  using detail::report::fixed;
  using detail::report::problem;
  std::string h;
  h += "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>" + xml_escape(d.title) +
       "</title>\n<style>\n" + detail::report::style + "</style>\n</head>\n<body>\n";
  h += "<h1>" + xml_escape(d.title) + "</h1>\n";
  h += "<p class=\"note\">sequence <code>" + xml_escape(d.sequence) + "</code>, run <code>" + xml_escape(d.output) +
       "</code></p>\n";

  // Summary.
  h += "<section id=\"summary\"><h2>Summary</h2>\n";
  if (d.summary.empty()) {
    h += problem("nothing to summarise");
  } else {
    h += "<table>\n";
    for (const auto& [key, value] : d.summary)
      h += "<tr><th class=\"name\">" + xml_escape(key) + "</th><td>" + xml_escape(value) + "</td></tr>\n";
    h += "</table>\n";
  }
  h += "</section>\n";

  // Trajectory views.
  h += "<section id=\"trajectory\"><h2>Camera trajectory</h2>\n";
  if (!d.camera_problem.empty()) h += problem(d.camera_problem);
  if (!d.ground_truth.empty() || !d.estimate.empty()) {
    const std::array<int, 3> axes = detail::report::floor_axes(d.ground_truth.empty() ? d.estimate : d.ground_truth);
    h += "<p class=\"note\">The estimate after the rigid ATE alignment onto the ground truth (wide gray line "
         "underneath). Top view: the " +
         std::string(detail::report::axis_name(axes[0])) + "-" + detail::report::axis_name(axes[1]) +
         " plane (the ground truth varies least along " + detail::report::axis_name(axes[2]) +
         ", taken as the vertical).</p>\n<div class=\"plots\">\n";
    const auto view = [&](const std::string& title, int a, int b, int w, int ht) {
      SvgPlot p;
      p.title = title, p.width = w, p.height = ht, p.equal_scale = true;
      p.x_label = std::string(detail::report::axis_name(a)) + " (m)";
      p.y_label = std::string(detail::report::axis_name(b)) + " (m)";
      p.series.push_back({"ground truth", detail::report::coordinate(d.ground_truth, a),
                          detail::report::coordinate(d.ground_truth, b), "#9a9a9a", true, false, false, 5});
      p.series.push_back({"estimate (aligned)", detail::report::coordinate(d.estimate, a),
                          detail::report::coordinate(d.estimate, b), plot_colour(0)});
      return svg_plot(p);
    };
    // Side view: the floor axis the camera moves most along against the vertical.
    const auto spread = [&](int a) {
      const std::vector<double> v = detail::report::coordinate(d.ground_truth, a);
      if (v.empty()) return 0.0;
      const auto [lo, hi] = std::minmax_element(v.begin(), v.end());
      return *hi - *lo;
    };
    const int along = spread(axes[0]) >= spread(axes[1]) ? axes[0] : axes[1];
    h += view("Top view", axes[0], axes[1], 560, 480);
    h += view("Side view", along, axes[2], 560, 480);
    h += "</div>\n";
  }
  h += "</section>\n";

  // Translation error and RPE over time: one curve each, in centimetres.
  h += detail::report::series_section(
      "error", "Translation error over time", d.error_time, d.error_m,
      d.camera_problem.empty() ? "no matched poses" : d.camera_problem,
      "Distance between each estimated camera position (after the ATE alignment) and its ground-truth position.",
      {"Camera translation error (ATE, per frame)", "time since the first frame (s)", "error (cm)",
       "translation error", 0});
  h += detail::report::series_section(
      "rpe", "Relative pose error (1 s windows)", d.rpe_time, d.rpe_m,
      d.rpe_problem.empty() ? "no pose pairs 1 s apart" : d.rpe_problem,
      "Translation drift of the camera over each 1 s window (TUM evaluate_rpe, fixed delta), at the start of the "
      "window.",
      {"Relative translation error over 1 s", "window start, time since the first frame (s)", "drift per window (cm)",
       "RPE translation", 1});

  // Objects.
  h += "<section id=\"objects\"><h2>Objects</h2>\n";
  if (!d.objects_problem.empty()) h += problem(d.objects_problem);
  if (!d.objects.empty()) {
    h += "<table>\n<tr><th class=\"name\">ground truth</th><th>estimate</th><th class=\"name\">class</th>"
         "<th>evaluated</th><th>ATE RMSE</th><th>coverage</th><th>first seen (s)</th><th>last seen (s)</th>"
         "<th class=\"name\">note</th></tr>\n";
    for (const ReportObject& o : d.objects)
      h += "<tr><td class=\"name\">" + xml_escape(o.name.empty() ? "–" : o.name) + "</td><td>" +
           xml_escape(o.estimate.empty() ? "–" : o.estimate) + "</td><td class=\"name\">" +
           xml_escape(o.class_name.empty() ? "–" : o.class_name) + "</td><td>" + (o.evaluated ? "yes" : "no") +
           "</td><td>" + (o.evaluated ? fixed(100 * o.ate_m, 2, " cm") : "–") + "</td><td>" +
           fixed(100 * o.coverage, 0, " %") + "</td><td>" + fixed(o.first_time, 2) + "</td><td>" +
           fixed(o.last_time, 2) + "</td><td class=\"name\">" + xml_escape(o.problem) + "</td></tr>\n";
    h += "</table>\n";
  } else if (d.objects_problem.empty()) {
    h += problem("no objects in the ground truth or the run");
  }
  h += "</section>\n";

  // Timing and memory.
  const ReportTimings& t = d.timings;
  h += "<section id=\"timing\"><h2>Time per frame</h2>\n";
  if (!d.timings_problem.empty()) h += problem(d.timings_problem);
  if (!t.time.empty() && !t.stages.empty()) {
    SvgPlot p;
    p.title = "Time per frame by stage", p.width = 1120, p.height = 420, p.y_from_zero = true;
    p.x_label = "time since the first frame (s)", p.y_label = "time (ms)";
    for (std::size_t k = 0; k < t.stages.size(); ++k)
      p.series.push_back({t.stages[k].first, t.time, t.stages[k].second, k == 0 ? "#222222" : plot_colour(k - 1)});
    h += svg_plot(p);
    h += "<table>\n<tr><th class=\"name\">stage</th><th>median (ms)</th><th>90th percentile (ms)</th></tr>\n";
    for (const auto& [name, values] : t.stages) {
      const auto [med, p90] = detail::report::median_p90(values);
      h += "<tr><td class=\"name\">" + xml_escape(name) + "</td><td>" + fixed(med, 2) + "</td><td>" + fixed(p90, 2) +
           "</td></tr>\n";
    }
    h += "</table>\n";
    SvgPlot q;
    q.title = "Objects alive", q.width = 1120, q.height = 260, q.y_from_zero = true;
    q.x_label = "time since the first frame (s)", q.y_label = "objects";
    q.series.push_back({"objects alive after the frame", t.time, t.objects, plot_colour(2)});
    h += svg_plot(q);
  } else if (d.timings_problem.empty()) {
    h += problem("no frames recorded");
  }
  h += "</section>\n";
  h += "<section id=\"memory\"><h2>Memory</h2>\n";
  if (!t.time.empty()) {
    SvgPlot p;
    p.title = "Memory in use", p.width = 1120, p.height = 300, p.y_from_zero = true;
    p.x_label = "time since the first frame (s)", p.y_label = "memory (MiB)";
    p.series.push_back({"resident memory of the process (RSS)", t.time, t.rss_mib, plot_colour(0)});
    const bool device =
        std::any_of(t.device_mib.begin(), t.device_mib.end(), [](double v) { return std::isfinite(v); });
    if (device) p.series.push_back({"device memory in use (GPU)", t.time, t.device_mib, plot_colour(1)});
    h += svg_plot(p);
    if (!device) h += "<p class=\"note\">No device memory: the run used the CPU backend.</p>\n";
  } else {
    h += problem(d.timings_problem.empty() ? "no frames recorded" : "no memory figures (see Time per frame)");
  }
  h += "</section>\n";

  // Pictures.
  h += "<section id=\"pictures\"><h2>Segmentation and association</h2>\n";
  if (d.frames.empty()) {
    h += problem(d.pictures_problem.empty() ? "no pictures" : d.pictures_problem);
    h += "<p class=\"note\">To get them, run with <code>--pictures</code>: <code>emfusion run &lt;input&gt; "
         "--output &lt;dir&gt; --pictures</code>, then <code>emfusion eval &lt;sequence&gt; &lt;dir&gt;</code> "
         "again.</p>\n";
  } else {
    h += "<p class=\"note\">Segmentation: each object's colour over the frame (dark: no depth). Association: "
         "the likelihood that a pixel belongs to the model, dark violet 0 to yellow 1.</p>\n";
    for (const ReportFrame& f : d.frames) {
      h += "<h3>" + xml_escape(f.title) + "</h3>\n<div>\n";
      for (const ReportPicture& pic : f.pictures)
        h += "<figure><img alt=\"" + xml_escape(pic.caption) + "\" src=\"data:image/png;base64," + base64(pic.png) +
             "\"><figcaption>" + xml_escape(pic.caption) + "</figcaption></figure>\n";
      h += "</div>\n";
    }
  }
  h += "</section>\n</body>\n</html>\n";
  return h;
}

}  // namespace emfusion::eval
