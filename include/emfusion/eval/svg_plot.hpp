// Line and scatter plots written as SVG text, for the run report
// (eval/report_html.hpp): axes with "nice" tick values (1, 2 or 5 times a
// power of ten), axis labels with their units, a legend naming every
// series, and optionally the same scale along both axes (a map of
// trajectories). Standard library only; docs/decisions.md says why the SVG
// is written here rather than by a plotting library.
//
//   SvgPlot plot;
//   plot.title = "Translation error";
//   plot.x_label = "time (s)", plot.y_label = "error (cm)";
//   plot.series.push_back({"estimate", times, errors_cm, "#1f77b4"});
//   const std::string svg = svg_plot(plot);  // "<svg ...>...</svg>", to inline in HTML
//
// Non-finite points are skipped and break a line. A plot with no finite
// point draws its axes over [0, 1] and says "no data"; a constant series
// gets a range around its value. Text goes through xml_escape.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <limits>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace emfusion::eval {

/// `text` with &, <, >, " and ' replaced by their entities, for SVG and HTML
/// text and attribute values.
inline std::string xml_escape(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (const char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&#39;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

/// The colours given to series without one: ten well-separated hues.
inline const char* plot_colour(std::size_t k) {
  static constexpr const char* colours[] = {"#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd",
                                            "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf"};
  return colours[k % 10];
}

/// One curve: points (x[i], y[i]) joined by lines (`line`) and/or drawn as
/// dots (`markers`), listed in the legend as `name`.
struct SvgSeries {
  SvgSeries() = default;
  SvgSeries(std::string name_, std::vector<double> x_, std::vector<double> y_, std::string colour_ = {},
            bool line_ = true, bool markers_ = false, bool dashed_ = false, double width_ = 1.8)
      : name(std::move(name_)),
        x(std::move(x_)),
        y(std::move(y_)),
        colour(std::move(colour_)),
        line(line_),
        markers(markers_),
        dashed(dashed_),
        width(width_) {}

  std::string name;
  std::vector<double> x, y;
  std::string colour;  ///< CSS colour; empty: plot_colour(index of the series)
  bool line = true;
  bool markers = false;
  bool dashed = false;
  double width = 1.8;  ///< line width, pixels
};

struct SvgPlot {
  std::string title, x_label, y_label;  ///< labels name the quantity and its unit: "time (s)"
  std::vector<SvgSeries> series;
  int width = 560, height = 360;  ///< pixels of the whole picture
  bool equal_scale = false;       ///< one unit is as long along x as along y
  bool y_from_zero = false;       ///< the y axis includes 0 (errors, times)
};

/// Tick values of an axis: multiples of `step`, from `first` to `last`.
struct Ticks {
  double first = 0, last = 1, step = 0.2;
  std::vector<double> values;
};

/// The smallest of 1, 2 and 5 times a power of ten that is at least
/// `target` (> 0); 1 for anything that is not a positive finite number.
inline double nice_step(double target) {
  if (!(target > 0) || !std::isfinite(target)) return 1;
  const double power = std::pow(10.0, std::floor(std::log10(target)));
  for (const double m : {1.0, 2.0, 5.0, 10.0})
    if (m * power >= target * (1 - 1e-12)) return m * power;
  return 10 * power;
}

namespace detail::svg {
/// Multiples of step within [lo, hi] (with a little slack for rounding).
inline std::vector<double> multiples(double lo, double hi, double step) {
  std::vector<double> v;
  const double eps = step * 1e-9;
  for (double k = std::ceil((lo - eps) / step); k * step <= hi + eps && v.size() < 1000; k += 1) {
    const double value = k * step;
    v.push_back(std::fabs(value) < eps ? 0.0 : value);
  }
  return v;
}
}  // namespace detail::svg

/// About `count` nice ticks whose range covers [lo, hi]: first <= lo, last
/// >= hi. An empty or non-finite range is [0, 1]; a single value v gets a
/// range around it.
inline Ticks nice_ticks(double lo, double hi, int count = 6) {
  if (!std::isfinite(lo) || !std::isfinite(hi)) lo = 0, hi = 1;
  if (lo > hi) std::swap(lo, hi);
  if (hi - lo <= 1e-12 * std::max(1.0, std::fabs(lo))) {
    const double pad = lo == 0 ? 1 : std::fabs(lo) * 0.1;
    lo -= pad, hi += pad;
  }
  Ticks t;
  t.step = nice_step((hi - lo) / std::max(1, count - 1));
  t.first = std::floor(lo / t.step + 1e-9) * t.step;
  t.last = std::ceil(hi / t.step - 1e-9) * t.step;
  t.values = detail::svg::multiples(t.first, t.last, t.step);
  return t;
}

/// A tick value with as many decimals as the step needs ("0.25" for step
/// 0.05, "10" for 5); never "-0".
inline std::string tick_text(double value, double step) {
  const int decimals = step > 0 && std::isfinite(step) ? std::max(0, int(-std::floor(std::log10(step) + 1e-9))) : 2;
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%.*f", std::min(decimals, 12), value);
  std::string s = buffer;
  if (s.find_first_not_of("-0.") == std::string::npos && s[0] == '-') s.erase(0, 1);
  return s;
}

namespace detail::svg {
inline std::string num(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.1f", v);
  return buffer;
}
/// Rough width of `text` at `size` px in a sans-serif font.
inline double text_width(std::string_view text, double size) { return 0.58 * size * double(text.size()); }
}  // namespace detail::svg

/// The plot as one <svg> element for inlining in HTML5 (no XML declaration
/// and no namespace attribute, which inline SVG does not need).
inline std::string svg_plot(const SvgPlot& plot) {
  using detail::svg::num;
  const double font = 13, small = 12;
  const double width = std::max(plot.width, 200), height = std::max(plot.height, 150);
  // Data range over the finite points.
  double x0 = std::numeric_limits<double>::infinity(), x1 = -x0, y0 = x0, y1 = -x0;
  std::size_t points = 0;
  for (const SvgSeries& s : plot.series)
    for (std::size_t i = 0; i < std::min(s.x.size(), s.y.size()); ++i)
      if (std::isfinite(s.x[i]) && std::isfinite(s.y[i])) {
        x0 = std::min(x0, s.x[i]), x1 = std::max(x1, s.x[i]);
        y0 = std::min(y0, s.y[i]), y1 = std::max(y1, s.y[i]);
        ++points;
      }
  if (points == 0) x0 = 0, x1 = 1, y0 = 0, y1 = 1;
  if (plot.y_from_zero) y0 = std::min(y0, 0.0), y1 = std::max(y1, 0.0);

  // Legend rows above the plot area: entries side by side, wrapped.
  struct Entry {
    std::string name, colour;
    bool line, markers, dashed;
    double width, x, y;
  };
  std::vector<Entry> legend;
  const double left = 72, right = 16;
  double lx = left, ly = plot.title.empty() ? 8 : 30;
  const double row = 20;
  bool any_legend = false;
  for (std::size_t k = 0; k < plot.series.size(); ++k) {
    const SvgSeries& s = plot.series[k];
    if (s.name.empty()) continue;
    const double w = 30 + detail::svg::text_width(s.name, small) + 18;
    if (lx + w > width - right && lx > left) lx = left, ly += row;
    legend.push_back(
        {s.name, s.colour.empty() ? plot_colour(k) : s.colour, s.line, s.markers, s.dashed, s.width, lx, ly});
    lx += w;
    any_legend = true;
  }
  const double top = (any_legend ? ly + row : ly) + 8;
  const double bottom = 48;
  const double pw = width - left - right, ph = height - top - bottom;

  Ticks xt = nice_ticks(x0, x1), yt = nice_ticks(y0, y1);
  double ax0 = xt.first, ax1 = xt.last, ay0 = yt.first, ay1 = yt.last;
  if (plot.equal_scale && ph > 10 && pw > 10) {
    // One step for both axes; the shorter side of the data gets more room.
    const double step = std::max(xt.step, yt.step);
    ax0 = std::floor(x0 / step + 1e-9) * step, ax1 = std::ceil(x1 / step - 1e-9) * step;
    ay0 = std::floor(y0 / step + 1e-9) * step, ay1 = std::ceil(y1 / step - 1e-9) * step;
    if (ax1 <= ax0) ax0 -= step, ax1 += step;
    if (ay1 <= ay0) ay0 -= step, ay1 += step;
    const double per_pixel = std::max((ax1 - ax0) / pw, (ay1 - ay0) / ph);
    const double cx = 0.5 * (ax0 + ax1), cy = 0.5 * (ay0 + ay1);
    ax0 = cx - 0.5 * per_pixel * pw, ax1 = cx + 0.5 * per_pixel * pw;
    ay0 = cy - 0.5 * per_pixel * ph, ay1 = cy + 0.5 * per_pixel * ph;
    xt.step = yt.step = step;
    xt.values = detail::svg::multiples(ax0, ax1, step);
    yt.values = detail::svg::multiples(ay0, ay1, step);
    // Too many ticks along the longer axis: every second (or fifth) one.
    for (Ticks* t : {&xt, &yt})
      if (t->values.size() > 11) {
        const double s2 = nice_step(t->step * double(t->values.size()) / 8);
        t->values = detail::svg::multiples(t == &xt ? ax0 : ay0, t == &xt ? ax1 : ay1, s2);
        t->step = s2;
      }
  }
  const auto px = [&](double x) { return left + (x - ax0) / (ax1 - ax0) * pw; };
  const auto py = [&](double y) { return top + ph - (y - ay0) / (ay1 - ay0) * ph; };

  std::string o;
  o += "<svg width=\"" + num(width) + "\" height=\"" + num(height) + "\" viewBox=\"0 0 " + num(width) + " " +
       num(height) + "\" font-family=\"sans-serif\" role=\"img\" class=\"plot\">\n";
  if (!plot.title.empty()) o += "<title>" + xml_escape(plot.title) + "</title>\n";
  o += "<rect x=\"0\" y=\"0\" width=\"" + num(width) + "\" height=\"" + num(height) + "\" fill=\"#ffffff\"/>\n";
  if (!plot.title.empty())
    o += "<text x=\"" + num(left) + "\" y=\"20\" font-size=\"15\" font-weight=\"bold\" fill=\"#222\">" +
         xml_escape(plot.title) + "</text>\n";
  // Grid and ticks.
  o += "<g class=\"grid\" stroke=\"#e3e3e3\" stroke-width=\"1\">\n";
  for (const double v : xt.values)
    o += "<line x1=\"" + num(px(v)) + "\" y1=\"" + num(top) + "\" x2=\"" + num(px(v)) + "\" y2=\"" + num(top + ph) +
         "\"/>\n";
  for (const double v : yt.values)
    o += "<line x1=\"" + num(left) + "\" y1=\"" + num(py(v)) + "\" x2=\"" + num(left + pw) + "\" y2=\"" + num(py(v)) +
         "\"/>\n";
  o += "</g>\n";
  o += "<g class=\"ticks\" font-size=\"" + num(small) + "\" fill=\"#333\">\n";
  for (const double v : xt.values)
    o += "<line x1=\"" + num(px(v)) + "\" y1=\"" + num(top + ph) + "\" x2=\"" + num(px(v)) + "\" y2=\"" +
         num(top + ph + 5) + "\" stroke=\"#555\"/><text class=\"xtick\" x=\"" + num(px(v)) + "\" y=\"" +
         num(top + ph + 18) + "\" text-anchor=\"middle\">" + xml_escape(tick_text(v, xt.step)) + "</text>\n";
  for (const double v : yt.values)
    o += "<line x1=\"" + num(left - 5) + "\" y1=\"" + num(py(v)) + "\" x2=\"" + num(left) + "\" y2=\"" + num(py(v)) +
         "\" stroke=\"#555\"/><text class=\"ytick\" x=\"" + num(left - 8) + "\" y=\"" + num(py(v) + 4) +
         "\" text-anchor=\"end\">" + xml_escape(tick_text(v, yt.step)) + "</text>\n";
  o += "</g>\n";
  o += "<rect x=\"" + num(left) + "\" y=\"" + num(top) + "\" width=\"" + num(pw) + "\" height=\"" + num(ph) +
       "\" fill=\"none\" stroke=\"#555\"/>\n";
  // Axis labels.
  o += "<text class=\"xlabel\" x=\"" + num(left + pw / 2) + "\" y=\"" + num(height - 10) + "\" font-size=\"" +
       num(font) + "\" text-anchor=\"middle\" fill=\"#222\">" + xml_escape(plot.x_label) + "</text>\n";
  o += "<text class=\"ylabel\" transform=\"translate(16 " + num(top + ph / 2) + ") rotate(-90)\" font-size=\"" +
       num(font) + "\" text-anchor=\"middle\" fill=\"#222\">" + xml_escape(plot.y_label) + "</text>\n";
  // Series, clipped to the plot area.
  static int clip_counter = 0;
  const std::string clip = "plotclip" + std::to_string(++clip_counter);
  o += "<clipPath id=\"" + clip + "\"><rect x=\"" + num(left) + "\" y=\"" + num(top) + "\" width=\"" + num(pw) +
       "\" height=\"" + num(ph) + "\"/></clipPath>\n";
  o += "<g clip-path=\"url(#" + clip + ")\" fill=\"none\" stroke-linejoin=\"round\">\n";
  for (std::size_t k = 0; k < plot.series.size(); ++k) {
    const SvgSeries& s = plot.series[k];
    const std::string colour = xml_escape(s.colour.empty() ? plot_colour(k) : s.colour);
    const std::size_t n = std::min(s.x.size(), s.y.size());
    if (s.line) {
      std::string points;
      double last_x = 0, last_y = 0;
      const auto flush = [&] {
        if (points.find(' ') != std::string::npos)  // two points at least
          o += "<polyline class=\"series\" points=\"" + points + "\" stroke=\"" + colour + "\" stroke-width=\"" +
               num(s.width) + "\"" + (s.dashed ? " stroke-dasharray=\"6 4\"" : "") + "/>\n";
        else if (!points.empty() && !s.markers)  // a lone point: a dot, or it would not show
          o += "<circle cx=\"" + num(last_x) + "\" cy=\"" + num(last_y) + "\" r=\"2\" fill=\"" + colour + "\"/>\n";
        points.clear();
      };
      for (std::size_t i = 0; i < n; ++i) {
        if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) {
          flush();
          continue;
        }
        if (!points.empty()) points += ' ';
        last_x = px(s.x[i]), last_y = py(s.y[i]);
        points += num(last_x) + "," + num(last_y);
      }
      flush();
    }
    if (s.markers || !s.line) {
      o += "<g fill=\"" + colour + "\" stroke=\"none\">";
      for (std::size_t i = 0; i < n; ++i)
        if (std::isfinite(s.x[i]) && std::isfinite(s.y[i]))
          o += "<circle cx=\"" + num(px(s.x[i])) + "\" cy=\"" + num(py(s.y[i])) + "\" r=\"2.5\"/>";
      o += "</g>\n";
    }
  }
  o += "</g>\n";
  if (points == 0)
    o += "<text x=\"" + num(left + pw / 2) + "\" y=\"" + num(top + ph / 2) + "\" font-size=\"" + num(font) +
         "\" text-anchor=\"middle\" fill=\"#888\">no data</text>\n";
  // Legend.
  o += "<g class=\"legend\" font-size=\"" + num(small) + "\" fill=\"#222\">\n";
  for (const Entry& e : legend) {
    const std::string colour = xml_escape(e.colour);
    const double cy = e.y + row / 2;
    if (e.line)
      o += "<line x1=\"" + num(e.x) + "\" y1=\"" + num(cy) + "\" x2=\"" + num(e.x + 24) + "\" y2=\"" + num(cy) +
           "\" stroke=\"" + colour + "\" stroke-width=\"" + num(std::max(2.5, e.width)) + "\"" +
           (e.dashed ? " stroke-dasharray=\"6 4\"" : "") + "/>";
    if (e.markers || !e.line)
      o += "<circle cx=\"" + num(e.x + 12) + "\" cy=\"" + num(cy) + "\" r=\"3.5\" fill=\"" + colour + "\"/>";
    o += "<text class=\"legend-entry\" x=\"" + num(e.x + 30) + "\" y=\"" + num(cy + 4) + "\">" + xml_escape(e.name) +
         "</text>\n";
  }
  o += "</g>\n</svg>\n";
  return o;
}

}  // namespace emfusion::eval
