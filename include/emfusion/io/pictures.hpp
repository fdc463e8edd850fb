// Pictures of a run, drawn on the host into colour images (io/colour.hpp)
// that write_png saves: the rendered segmentation over the colour frame and
// each model's association likelihood (like the paper's Figures 1 and 2).
// Plain loops, no graphics library. (Plots of trajectories and timings are
// SVG in the run report: eval/svg_plot.hpp, io/run_report.hpp.)
//
//   segmentation_overlay  labels of System::segmentation() (-1 no object
//                         and no depth, 0 background, k + 1 object k) as colours
//                         over the frame
//   association_heatmap   an association image (0..1) through a viridis-like
//                         colour map
//
// Colours: object k gets label_colour(k) (or label_colour(id) with the
// object ids passed), a fixed cycle of 12 well-separated colours, the same
// in every frame. Association values go through heat_colour, a viridis-like
// map (dark violet 0, yellow 1).
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

}  // namespace detail::pictures

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

}  // namespace emfusion
