// Pictures of a run, drawn on the host into colour images (io/colour.hpp)
// that write_png saves: the rendered segmentation over the colour frame and
// each model's association likelihood (like the paper's Figures 1 and 2),
// and a top view of camera trajectories (estimate against ground truth).
// Plain loops, no graphics library; text comes from a 5x7 bitmap font
// defined here (upper-case letters, digits and a few symbols).
//
//   segmentation_overlay  labels of System::segmentation() (-1 no object
//                         and no depth, 0 background, k + 1 object k) as colours
//                         over the frame
//   association_heatmap   an association image (0..1) through a viridis-like
//                         colour map
//   trajectory_plot       positions of PlotSeries (trajectory_series makes
//                         one of a Trajectory) seen from above, equal scale
//
// Colours: object k gets label_colour(k) (or label_colour(id) with the
// object ids passed), a fixed cycle of 12 well-separated colours, the same
// in every frame (and handy as plot series colours). Association values go
// through heat_colour, a viridis-like map (dark violet 0, yellow 1).
//
// A ground truth / estimate plot as the ATE sees them (eval/ate.hpp):
//
//   const eval::AteResult ate = eval::absolute_trajectory_error(estimate, ground_truth);
//   write_png(path, trajectory_plot({trajectory_series(ground_truth, "ground truth", plot_black),
//                                    trajectory_series(estimate, "estimate", label_colour(0), ate.T_gt_est)}));
//
// ate.T_gt_est maps the estimate's world frame into the ground truth's, so
// both series are drawn in the ground-truth frame.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <initializer_list>
#include <limits>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/error.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/core/timed_pose.hpp"
#include "emfusion/io/colour.hpp"
#include "emfusion/io/jpeg.hpp"
#include "emfusion/io/png.hpp"

namespace emfusion {

inline constexpr Rgb8 plot_black{0, 0, 0};
inline constexpr Rgb8 plot_white{255, 255, 255};

namespace detail::pictures {

/// a * (1 - t) + b * t per channel, rounded; t in [0, 1].
inline Rgb8 mix(Rgb8 a, Rgb8 b, float t) {
  const auto channel = [t](std::uint8_t x, std::uint8_t y) {
    const float v = float(x) + (float(y) - float(x)) * t;
    return std::uint8_t(std::clamp(v + 0.5f, 0.0f, 255.0f));
  };
  return {channel(a.r, b.r), channel(a.g, b.g), channel(a.b, b.b)};
}

inline Rgb8 scaled(Rgb8 c, float factor) { return mix(plot_black, c, factor); }

/// Rec. 709 luma of the stored (gamma-encoded) values, 0..255.
inline float luma(Rgb8 c) { return 0.2126f * float(c.r) + 0.7152f * float(c.g) + 0.0722f * float(c.b); }

inline void require_unit(float value, const char* where, const char* name) {
  require(value >= 0.0f && value <= 1.0f, where,
          std::string(name) + " must be in [0, 1], got " + std::to_string(value));
}

/// The colour image `colour` must be labels-sized when given.
template <class T>
void require_same_size(const ColourImage* colour, const Image<T, Host>& image, const char* where) {
  if (!colour) return;
  require(colour->same_size(image.width(), image.height()), where,
          "the colour image is " + std::to_string(colour->width()) + "x" + std::to_string(colour->height()) +
              " but the other image is " + std::to_string(image.width()) + "x" + std::to_string(image.height()));
}

// ---- drawing primitives (all clip to the image) ----------------------------

inline void put(ImageView<Rgb8> image, int x, int y, Rgb8 colour) {
  if (image.contains(x, y)) image(x, y) = colour;
}

inline void fill_rect(ImageView<Rgb8> image, int x0, int y0, int x1, int y1, Rgb8 colour) {
  x0 = std::max(x0, 0), y0 = std::max(y0, 0);
  x1 = std::min(x1, image.width - 1), y1 = std::min(y1, image.height - 1);
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x) image(x, y) = colour;
}

inline void outline_rect(ImageView<Rgb8> image, int x0, int y0, int x1, int y1, Rgb8 colour) {
  for (int x = x0; x <= x1; ++x) put(image, x, y0, colour), put(image, x, y1, colour);
  for (int y = y0; y <= y1; ++y) put(image, x0, y, colour), put(image, x1, y, colour);
}

/// A line from (x0, y0) to (x1, y1) by Bresenham's algorithm, every step a
/// thickness x thickness block whose top-left pixel is on the line: the
/// pixels form one connected stroke, the end points included.
inline void draw_line(ImageView<Rgb8> image, int x0, int y0, int x1, int y1, Rgb8 colour, int thickness = 2) {
  const int dx = std::abs(x1 - x0), dy = -std::abs(y1 - y0);
  const int sx = x0 < x1 ? 1 : -1, sy = y0 < y1 ? 1 : -1;
  int error = dx + dy;
  for (;;) {
    fill_rect(image, x0, y0, x0 + thickness - 1, y0 + thickness - 1, colour);
    if (x0 == x1 && y0 == y1) break;
    const int twice = 2 * error;
    if (twice >= dy) error += dy, x0 += sx;
    if (twice <= dx) error += dx, y0 += sy;
  }
}

/// Rounds a pixel coordinate to int; far-away and non-finite values land
/// well outside any image (casting them directly would be undefined).
inline int pixel(double v) {
  constexpr double limit = 1 << 20;
  if (!(v > -limit)) return -int(limit);  // also NaN
  if (v > limit) return int(limit);
  return int(std::floor(v + 0.5));
}

// ---- 5x7 bitmap font ----------------------------------------------------------

/// Rows of a 5x7 glyph, top to bottom; bit 4 is the leftmost column.
using Glyph = std::array<std::uint8_t, 7>;

inline Glyph glyph(char c) {
  if (c >= 'a' && c <= 'z') c = char(c - 'a' + 'A');
  // clang-format off
  switch (c) {
    case 'A': return {0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11};
    case 'B': return {0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E};
    case 'C': return {0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E};
    case 'D': return {0x1E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x1E};
    case 'E': return {0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F};
    case 'F': return {0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10};
    case 'G': return {0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F};
    case 'H': return {0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11};
    case 'I': return {0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E};
    case 'J': return {0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C};
    case 'K': return {0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11};
    case 'L': return {0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F};
    case 'M': return {0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11};
    case 'N': return {0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11};
    case 'O': return {0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E};
    case 'P': return {0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10};
    case 'Q': return {0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D};
    case 'R': return {0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11};
    case 'S': return {0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E};
    case 'T': return {0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04};
    case 'U': return {0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E};
    case 'V': return {0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04};
    case 'W': return {0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A};
    case 'X': return {0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11};
    case 'Y': return {0x11, 0x11, 0x0A, 0x04, 0x04, 0x04, 0x04};
    case 'Z': return {0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F};
    case '0': return {0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E};
    case '1': return {0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E};
    case '2': return {0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F};
    case '3': return {0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E};
    case '4': return {0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02};
    case '5': return {0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E};
    case '6': return {0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E};
    case '7': return {0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08};
    case '8': return {0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E};
    case '9': return {0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C};
    case ' ': return {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00};
    case '.': return {0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C};
    case ',': return {0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08};
    case '-': return {0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00};
    case '_': return {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F};
    case ':': return {0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00};
    case '/': return {0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00};
    case '(': return {0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02};
    case ')': return {0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08};
    case '+': return {0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00};
    case '=': return {0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00};
    default: return {0x0E, 0x11, 0x01, 0x02, 0x04, 0x00, 0x04};  // '?' (and anything without a glyph)
  }
  // clang-format on
}

}  // namespace detail::pictures

// ---- text ----------------------------------------------------------------------

/// Width in pixels of `text` drawn at `scale`: 6 * scale per character (5
/// columns and a gap); the height is 7 * scale.
inline int text_width(std::string_view text, int scale = 1) { return int(text.size()) * 6 * std::max(scale, 1); }

/// Draws `text` with its top-left corner at (x, y), each font pixel a
/// scale x scale block, clipped to the image. Lower case is drawn as upper
/// case; characters without a glyph as '?'.
inline void draw_text(ImageView<Rgb8> image, int x, int y, std::string_view text, Rgb8 colour, int scale = 1) {
  scale = std::max(scale, 1);
  for (const char c : text) {
    const detail::pictures::Glyph g = detail::pictures::glyph(c);
    for (int row = 0; row < 7; ++row)
      for (int column = 0; column < 5; ++column)
        if (g[std::size_t(row)] & (0x10 >> column))
          detail::pictures::fill_rect(image, x + column * scale, y + row * scale, x + (column + 1) * scale - 1,
                                      y + (row + 1) * scale - 1, colour);
    x += 6 * scale;
  }
}

// ---- label colours and the segmentation overlay ---------------------------------

/// The colour of object `k` (segmentation label k + 1), the same in every
/// frame: 12 well-separated hues, then the same 12 darker (k = 12..23), then
/// lighter (24..35), and so on in that cycle of 36. A negative k is gray.
inline Rgb8 label_colour(int k) {
  static constexpr Rgb8 palette[12] = {{230, 25, 75},  {60, 180, 75},  {0, 130, 200},  {255, 225, 25},
                                       {245, 130, 48}, {145, 30, 180}, {70, 240, 240}, {240, 50, 230},
                                       {0, 0, 128},    {0, 128, 128},  {170, 110, 40}, {128, 0, 0}};
  if (k < 0) return gray_rgb(160);
  const Rgb8 base = palette[k % 12];
  switch ((k / 12) % 3) {
    case 1:
      return detail::pictures::scaled(base, 0.6f);
    case 2:
      return detail::pictures::mix(base, plot_white, 0.45f);
    default:
      return base;
  }
}

/// The canvas of segmentation_overlay when there is no colour image.
inline constexpr Rgb8 overlay_gray{128, 128, 128};

/// The segmentation `labels` (-1 no object and no depth, 0 background, k + 1
/// object k, as System::segmentation()) drawn over `colour` (nullptr: a
/// uniform gray canvas, overlay_gray):
///   - background (0): the colour pixel unchanged;
///   - nothing (any negative label): the colour pixel at 35% brightness;
///   - object k: the colour pixel blended with label_colour(k), `opacity` of
///     the label colour; its boundary pixels (those with a 4-neighbour of
///     another label) in the solid label colour, a 1-pixel outline inside
///     the object.
/// With `object_ids`, object k takes label_colour((*object_ids)[k]) instead,
/// so an object keeps its colour when earlier objects are deleted (pass the
/// ids of System::objects() in order); a label without an entry there is
/// std::invalid_argument. So are a colour image of another size and an
/// opacity outside [0, 1].
inline ColourImage segmentation_overlay(const ColourImage* colour, const Image<int, Host>& labels, float opacity = 0.5f,
                                        const std::vector<int>* object_ids = nullptr) {
  constexpr const char* where = "segmentation_overlay";
  detail::pictures::require_unit(opacity, where, "opacity");
  detail::pictures::require_same_size(colour, labels, where);
  const int w = labels.width(), h = labels.height();
  const ImageView<const int> l = labels.view();
  const auto colour_of = [&](int label) {
    const int k = label - 1;
    if (!object_ids) return label_colour(k);
    detail::require(std::size_t(k) < object_ids->size(), where,
                    "label " + std::to_string(label) + " (object " + std::to_string(k) + ") but only " +
                        std::to_string(object_ids->size()) + " object ids were given");
    return label_colour((*object_ids)[std::size_t(k)]);
  };
  ColourImage out(w, h, overlay_gray);
  const ImageView<Rgb8> o = out.view();
  if (colour) std::copy(colour->view().data, colour->view().data + colour->size(), o.data);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int label = l(x, y);
      Rgb8& pixel = o(x, y);
      if (label < 0) {
        pixel = detail::pictures::scaled(pixel, 0.35f);
      } else if (label > 0) {
        const bool boundary = (x > 0 && l(x - 1, y) != label) || (x + 1 < w && l(x + 1, y) != label) ||
                              (y > 0 && l(x, y - 1) != label) || (y + 1 < h && l(x, y + 1) != label);
        const Rgb8 c = colour_of(label);
        pixel = boundary ? c : detail::pictures::mix(pixel, c, opacity);
      }
    }
  return out;
}

// ---- association heat maps ------------------------------------------------------

/// A viridis-like colour map: dark blue-violet at 0 through blue and green
/// to yellow at 1, luma rising monotonically (linear interpolation between
/// nine anchor colours). `t` is clamped to [0, 1]; NaN gives black.
inline Rgb8 heat_colour(float t) {
  static constexpr Rgb8 anchors[9] = {{68, 1, 84},    {71, 44, 122}, {59, 81, 139},  {44, 113, 142}, {33, 144, 141},
                                      {39, 173, 129}, {92, 200, 99}, {170, 220, 50}, {253, 231, 37}};
  if (std::isnan(t)) return plot_black;
  t = std::clamp(t, 0.0f, 1.0f) * 8.0f;
  const int i = std::min(int(t), 7);
  return detail::pictures::mix(anchors[i], anchors[i + 1], t - float(i));
}

/// An association image (values in [0, 1], one per model: System::
/// associations().image(m)) through heat_colour; values above 1 are drawn
/// as 1; NaN and negative values (no association) are black. With `colour`
/// (same size), the map is blended, `opacity` of it, over the colour
/// image's gray version (luma), which shows the scene without competing
/// hues; invalid pixels stay black.
template <class S>
ColourImage association_heatmap(const Image<S, Host>& association, const ColourImage* colour = nullptr,
                                float opacity = 0.6f) {
  static_assert(std::is_floating_point_v<S>, "association images hold floating-point values");
  constexpr const char* where = "association_heatmap";
  detail::pictures::require_unit(opacity, where, "opacity");
  detail::pictures::require_same_size(colour, association, where);
  ColourImage out(association.width(), association.height());
  const ImageView<const S> a = association.view();
  const ImageView<Rgb8> o = out.view();
  for (int i = 0; i < a.size(); ++i) {
    const S v = a[i];
    if (!(v >= S(0))) {  // negative or NaN
      o[i] = plot_black;
      continue;
    }
    const Rgb8 heat = heat_colour(float(std::min(v, S(1))));
    if (!colour) {
      o[i] = heat;
    } else {
      const auto gray = std::uint8_t(std::clamp(detail::pictures::luma(colour->view()[i]) + 0.5f, 0.0f, 255.0f));
      o[i] = detail::pictures::mix(gray_rgb(gray), heat, opacity);
    }
  }
  return out;
}

// ---- trajectory plots -----------------------------------------------------------

/// One polyline of a trajectory plot: world positions in order, drawn in
/// `colour` and listed in the legend as `name` (no legend row when empty).
/// Non-finite positions are skipped and break the line.
struct PlotSeries {
  std::string name;
  std::vector<Vec3d> points;
  Rgb8 colour{0, 0, 0};
};

/// The positions of `trajectory` (pose translations, i.e. where the body
/// was in the world), mapped by `transform`: pass an ATE alignment
/// (eval::AteResult::T_gt_est) to draw an estimate in the ground truth's
/// frame.
inline PlotSeries trajectory_series(const Trajectory& trajectory, std::string name, Rgb8 colour,
                                    const SE3<double>& transform = SE3<double>::identity()) {
  PlotSeries series{std::move(name), {}, colour};
  series.points.reserve(trajectory.size());
  for (const TimedPose& p : trajectory) series.points.push_back(transform * p.pose.translation());
  return series;
}

struct PlotOptions {
  int width = 800, height = 800;  ///< image size in pixels, at least 64 each
  /// The world axes (0 x, 1 y, 2 z) drawn to the right and up. -1 for both
  /// (the default) picks them from the data: the two axes along which the
  /// positions spread most. A camera moves mostly horizontally, so these
  /// span the floor plane whichever axis the world frame has up: y (down)
  /// in frames that start at the first camera, as SLAM estimates do, or z
  /// in TUM's motion-capture ground truth. Ties, and data with no spread,
  /// give x and z. The lower-numbered axis goes right, so (x, z) is seen
  /// from -y (above, with y down) and (x, y) from +z (above, with z up).
  int axis_right = -1, axis_up = -1;
  bool legend = true;  ///< series names and the grid step below the plot
};

/// Where a trajectory plot puts things: the plot area (pixels, inclusive),
/// the axes, the scale (the same along both axes) and the grid step.
struct PlotFrame {
  int axis_right = 0, axis_up = 2;
  int left = 0, top = 0, right = 0, bottom = 0;  ///< plot area, inclusive
  double scale = 1;                              ///< pixels per metre
  double centre_right = 0, centre_up = 0;        ///< the world coordinates at the area's centre
  double grid_step = 1;                          ///< metres between grid lines
  int font_scale = 1;

  double pixel_x(const Vec3d& p) const { return 0.5 * (left + right) + (p[axis_right] - centre_right) * scale; }
  /// Up in the world is up in the picture (image rows grow downwards).
  double pixel_y(const Vec3d& p) const { return 0.5 * (top + bottom) - (p[axis_up] - centre_up) * scale; }
};

namespace detail::pictures {

inline const char* axis_name(int axis) { return axis == 0 ? "X" : axis == 1 ? "Y" : "Z"; }

/// The smallest of 1, 2, 5 times a power of ten that is at least `target`.
inline double nice_step(double target) {
  if (!(target > 0) || !std::isfinite(target)) return 1.0;
  const double power = std::pow(10.0, std::floor(std::log10(target)));
  for (const double m : {1.0, 2.0, 5.0, 10.0})
    if (m * power >= target * (1 - 1e-9)) return m * power;
  return 10.0 * power;
}

inline int legend_rows(const std::vector<PlotSeries>& series) {
  int rows = 1;  // the grid step
  for (const PlotSeries& s : series) rows += s.name.empty() ? 0 : 1;
  return rows;
}

/// "0.5", "0.02", "10": the shortest form of a grid step.
inline std::string step_text(double step) {
  char text[32];
  std::snprintf(text, sizeof(text), "%g", step);
  return text;
}

}  // namespace detail::pictures

/// The frame trajectory_plot draws `series` in (see PlotOptions). Throws
/// std::invalid_argument for a size below 64x64 or bad axes.
inline PlotFrame trajectory_plot_frame(const std::vector<PlotSeries>& series, const PlotOptions& options = {}) {
  constexpr const char* where = "trajectory_plot";
  const int w = options.width, h = options.height;
  detail::require(w >= 64 && h >= 64, where,
                  "the image must be at least 64x64 pixels, got " + std::to_string(w) + "x" + std::to_string(h));
  PlotFrame f;
  // The extent of the finite positions along each axis.
  double low[3], high[3];
  for (int k = 0; k < 3; ++k) low[k] = std::numeric_limits<double>::infinity(), high[k] = -low[k];
  bool any = false;
  for (const PlotSeries& s : series)
    for (const Vec3d& p : s.points) {
      if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) continue;
      any = true;
      for (int k = 0; k < 3; ++k) low[k] = std::min(low[k], p[k]), high[k] = std::max(high[k], p[k]);
    }
  if (!any)
    for (int k = 0; k < 3; ++k) low[k] = 0, high[k] = 0;

  if (options.axis_right < 0 && options.axis_up < 0) {
    // Drop the axis of least spread; on ties drop y, then z, then x.
    const int preference[3] = {1, 2, 0};
    int dropped = 1;
    for (const int k : preference)
      if (high[k] - low[k] < high[dropped] - low[dropped]) dropped = k;
    f.axis_right = dropped == 0 ? 1 : 0;
    f.axis_up = dropped == 2 ? 1 : 2;
  } else {
    detail::require(options.axis_right >= 0 && options.axis_right < 3 && options.axis_up >= 0 && options.axis_up < 3 &&
                        options.axis_right != options.axis_up,
                    where,
                    "axis_right and axis_up must be two different axes of 0 (x), 1 (y), 2 (z), or both -1 "
                    "(automatic); got " +
                        std::to_string(options.axis_right) + " and " + std::to_string(options.axis_up));
    f.axis_right = options.axis_right, f.axis_up = options.axis_up;
  }

  // Layout: a margin all round, the legend box below the plot area.
  f.font_scale = std::max(1, std::min(w, h) / 400);
  const int margin = std::max(6, std::min(w, h) / 25);
  const int line_height = 10 * f.font_scale, pad = 4 * f.font_scale;
  int legend_height = 0;
  if (options.legend) {
    const int rows = std::min(detail::pictures::legend_rows(series), std::max(1, (h / 3 - 2 * pad) / line_height));
    legend_height = rows * line_height + 2 * pad + margin / 2;
  }
  f.left = margin, f.top = margin;
  f.right = w - 1 - margin;
  f.bottom = std::max(f.top + 8, h - 1 - margin - legend_height);

  // Equal scale: fit the larger relative extent, centre the data.
  const double du = high[f.axis_right] - low[f.axis_right], dv = high[f.axis_up] - low[f.axis_up];
  const int inner = 3 * f.font_scale + 3;  // keeps markers and thick lines inside the area
  const double avail_w = std::max(1, f.right - f.left - 2 * inner), avail_h = std::max(1, f.bottom - f.top - 2 * inner);
  const double spread = std::max(du, dv);
  if (spread > 1e-9 && std::isfinite(spread)) {
    const double floor_extent = spread * 1e-6;  // a straight line along one axis
    f.scale = std::min(avail_w / std::max(du, floor_extent), avail_h / std::max(dv, floor_extent));
  } else {
    f.scale = std::min(avail_w, avail_h);  // one point, or none: show 1 m around it
  }
  if (!(f.scale > 0) || !std::isfinite(f.scale)) f.scale = 1;
  f.centre_right = 0.5 * (low[f.axis_right] + high[f.axis_right]);
  f.centre_up = 0.5 * (low[f.axis_up] + high[f.axis_up]);
  if (!std::isfinite(f.centre_right)) f.centre_right = 0;
  if (!std::isfinite(f.centre_up)) f.centre_up = 0;

  // About 4 to 10 grid lines across the larger side.
  const double visible = std::max(f.right - f.left, f.bottom - f.top) / f.scale;
  f.grid_step = detail::pictures::nice_step(visible / 8);
  return f;
}

/// A top view of `series` (see PlotOptions for the axes): equal scale on
/// both axes, the data centred with a margin, light gray grid lines every
/// frame.grid_step metres (a darker one through the world origin), each
/// series a 2-pixel polyline with a square marker at its first position (a
/// lone position is just the marker), later series over earlier ones; below,
/// a legend box with a swatch and the name of each named series and the
/// line "GRID <step> M, <right axis> RIGHT, <up axis> UP". Never draws out of
/// bounds; empty or single-point series are fine.
inline ColourImage trajectory_plot(const std::vector<PlotSeries>& series, const PlotOptions& options) {
  using namespace detail::pictures;
  const PlotFrame f = trajectory_plot_frame(series, options);
  ColourImage out(options.width, options.height, plot_white);
  const ImageView<Rgb8> image = out.view();
  const int fs = f.font_scale;

  // Grid: world coordinates at the area's edges, lines at multiples of the step.
  const auto grid = [&](bool vertical) {
    const double centre_px = vertical ? 0.5 * (f.left + f.right) : 0.5 * (f.top + f.bottom);
    const double centre_world = vertical ? f.centre_right : f.centre_up;
    const int lo_px = vertical ? f.left : f.top, hi_px = vertical ? f.right : f.bottom;
    const double sign = vertical ? 1.0 : -1.0;  // world up is image rows down
    const double a = centre_world + sign * (lo_px - centre_px) / f.scale;
    const double b = centre_world + sign * (hi_px - centre_px) / f.scale;
    const double first = std::ceil(std::min(a, b) / f.grid_step), last = std::floor(std::max(a, b) / f.grid_step);
    if (!(last - first < 200)) return;  // also NaN
    for (double k = first; k <= last; ++k) {
      const double world = k * f.grid_step;
      const int p = pixel(centre_px + sign * (world - centre_world) * f.scale);
      const Rgb8 c = k == 0 ? gray_rgb(185) : gray_rgb(228);
      if (vertical)
        draw_line(image, p, f.top, p, f.bottom, c, 1);
      else
        draw_line(image, f.left, p, f.right, p, c, 1);
    }
  };
  grid(true);
  grid(false);
  outline_rect(image, f.left, f.top, f.right, f.bottom, gray_rgb(150));

  for (const PlotSeries& s : series) {
    bool have_previous = false, started = false;
    int px = 0, py = 0;
    for (std::size_t i = 0; i < s.points.size(); ++i) {
      const Vec3d& p = s.points[i];
      if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) {
        have_previous = false;
        continue;
      }
      const int x = pixel(f.pixel_x(p)), y = pixel(f.pixel_y(p));
      if (!started) {
        const int r = fs + 2;
        fill_rect(image, x - r, y - r, x + r, y + r, s.colour);
        started = true;
      }
      if (have_previous) draw_line(image, px, py, x, y, s.colour, 2);
      px = x, py = y, have_previous = true;
    }
  }

  if (options.legend) {
    std::vector<std::pair<std::string, const Rgb8*>> rows;
    for (const PlotSeries& s : series)
      if (!s.name.empty()) rows.emplace_back(s.name, &s.colour);
    rows.emplace_back(std::string("GRID ") + step_text(f.grid_step) + " M, " + axis_name(f.axis_right) + " RIGHT, " +
                          axis_name(f.axis_up) + " UP",
                      nullptr);
    const int line_height = 10 * fs, pad = 4 * fs, swatch = 12 * fs;
    const int fit = std::max(1, (options.height / 3 - 2 * pad) / line_height);
    if (int(rows.size()) > fit) rows.erase(rows.begin() + (fit - 1), rows.end() - 1);  // keep the grid line
    int text = 0;
    for (const auto& row : rows) text = std::max(text, text_width(row.first, fs));
    const int x0 = f.left, y0 = f.bottom + std::max(6, std::min(options.width, options.height) / 25) / 2;
    const int x1 = std::min(options.width - 1, x0 + 2 * pad + swatch + pad + text);
    const int y1 = y0 + 2 * pad + int(rows.size()) * line_height - (line_height - 7 * fs);
    fill_rect(image, x0, y0, x1, y1, plot_white);
    outline_rect(image, x0, y0, x1, y1, gray_rgb(150));
    for (std::size_t r = 0; r < rows.size(); ++r) {
      const int y = y0 + pad + int(r) * line_height;
      if (rows[r].second)
        fill_rect(image, x0 + pad, y + 2 * fs, x0 + pad + swatch - 1, y + 5 * fs - 1, *rows[r].second);
      draw_text(image, x0 + 2 * pad + swatch, y, rows[r].first, plot_black, fs);
    }
  }
  return out;
}

/// trajectory_plot with the default options at width x height pixels.
inline ColourImage trajectory_plot(const std::vector<PlotSeries>& series, int width = 800, int height = 800) {
  PlotOptions options;
  options.width = width, options.height = height;
  return trajectory_plot(series, options);
}

}  // namespace emfusion
