// Turning an unmatched detection into a new object volume (paper sec. 3.5,
// after MaskFusion): the 10th and 90th percentiles of the masked points give
// the volume's centre and size (largest extent times a padding factor), and
// the rules that keep false or duplicate objects out: too few pixels, too far
// away, too much overlap with an existing volume, a static class.
//
// Host code, run on detector frames only.
#pragma once

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "emfusion/core/math.hpp"
#include "emfusion/core/se3.hpp"

namespace emfusion {

/// The classes the paper never makes objects of (Mask R-CNN's masks of large
/// static furniture are too poor to track).
inline std::vector<std::string> default_static_classes() {
  return {"traffic_light", "fire_hydrant", "stop_sign",    "parking_meter", "bench", "couch", "potted_plant",
          "bed",           "dining_table", "toilet",       "oven",          "sink",  "refrigerator"};
}

/// True if `class_name` is in `classes`; spaces and underscores are the same.
inline bool is_listed_class(const std::string& class_name, const std::vector<std::string>& classes) {
  const auto normal = [](std::string s) {
    std::replace(s.begin(), s.end(), ' ', '_');
    return s;
  };
  const std::string c = normal(class_name);
  return std::any_of(classes.begin(), classes.end(), [&](const std::string& s) { return normal(s) == c; });
}

/// An axis-aligned box in some frame.
template <class S>
struct Box {
  Vec3<S> lo = Vec3<S>::zero();
  Vec3<S> hi = Vec3<S>::zero();
  Vec3<S> center() const { return (lo + hi) * S(0.5); }
  S largest_side() const { return std::max({hi.x() - lo.x(), hi.y() - lo.y(), hi.z() - lo.z()}); }
};

/// The box between the `low` and `high` quantiles of the points on each axis
/// (nearest-rank). Needs at least one point.
template <class S>
Box<S> percentile_box(const std::vector<Vec3<S>>& points, double low = 0.1, double high = 0.9) {
  Box<S> box;
  if (points.empty()) return box;
  std::vector<S> axis(points.size());
  for (int a = 0; a < 3; ++a) {
    for (std::size_t i = 0; i < points.size(); ++i) axis[i] = points[i][a];
    const auto at = [&](double q) {
      const std::size_t k = std::min(points.size() - 1, std::size_t(q * double(points.size() - 1) + 0.5));
      std::nth_element(axis.begin(), axis.begin() + std::ptrdiff_t(k), axis.end());
      return axis[k];
    };
    box.lo[a] = at(low);
    box.hi[a] = at(high);
  }
  return box;
}

/// The masked points that belong to the object: a detector's mask spills
/// over the object's silhouette (Mask R-CNN's masks are a few pixels too
/// wide), and the spilled pixels measure whatever lies behind, often metres
/// away. Sorted by depth (camera z), the points split wherever consecutive
/// depths are more than `gap` apart; the largest group is kept (on a tie the
/// nearer). A surface seen by thousands of pixels leaves no such gap within
/// itself, so the object stays whole; an object touching what is behind it
/// keeps a few of those pixels, which the percentiles then ignore.
/// Points must be in the camera frame.
template <class S>
std::vector<Vec3<S>> largest_depth_group(std::vector<Vec3<S>> points, S gap) {
  if (points.size() < 2) return points;
  std::sort(points.begin(), points.end(), [](const Vec3<S>& a, const Vec3<S>& b) { return a.z() < b.z(); });
  std::size_t best_begin = 0, best_size = 0, begin = 0;
  for (std::size_t i = 1; i <= points.size(); ++i) {
    if (i < points.size() && !(points[i].z() - points[i - 1].z() > gap)) continue;
    if (i - begin > best_size) best_begin = begin, best_size = i - begin;
    begin = i;
  }
  return {points.begin() + std::ptrdiff_t(best_begin), points.begin() + std::ptrdiff_t(best_begin + best_size)};
}

/// The cube a new object gets: centred on the percentile box, side = padding
/// times its largest extent.
template <class S>
Box<S> padded_cube(const Box<S>& box, S padding) {
  const S half = S(0.5) * padding * box.largest_side();
  const Vec3<S> c = box.center();
  return {c - Vec3<S>::constant(half), c + Vec3<S>::constant(half)};
}

/// Volumetric IoU of two boxes, each [0, extent] in its own frame placed by
/// T_world_box, estimated on a regular grid of samples^3 points in each box
/// (exact for axis-aligned boxes up to the grid resolution).
template <class S>
double volume_iou(const SE3<S>& T_world_a, const Vec3<S>& extent_a, const SE3<S>& T_world_b,
                  const Vec3<S>& extent_b, int samples = 12) {
  const auto fraction_inside = [&](const SE3<S>& T_world_from, const Vec3<S>& ext_from, const SE3<S>& T_world_to,
                                   const Vec3<S>& ext_to) {
    const SE3<S> T = T_world_to.inverse() * T_world_from;
    int inside = 0;
    for (int z = 0; z < samples; ++z)
      for (int y = 0; y < samples; ++y)
        for (int x = 0; x < samples; ++x) {
          const Vec3<S> p = T * vec3((S(x) + S(0.5)) / S(samples) * ext_from.x(),
                                     (S(y) + S(0.5)) / S(samples) * ext_from.y(),
                                     (S(z) + S(0.5)) / S(samples) * ext_from.z());
          if (p.x() >= S(0) && p.y() >= S(0) && p.z() >= S(0) && p.x() <= ext_to.x() && p.y() <= ext_to.y() &&
              p.z() <= ext_to.z())
            ++inside;
        }
    return double(inside) / double(samples * samples * samples);
  };
  const double va = double(extent_a.x()) * double(extent_a.y()) * double(extent_a.z());
  const double vb = double(extent_b.x()) * double(extent_b.y()) * double(extent_b.z());
  // The intersection measured from both sides, averaged: symmetric.
  const double inter = 0.5 * (fraction_inside(T_world_a, extent_a, T_world_b, extent_b) * va +
                              fraction_inside(T_world_b, extent_b, T_world_a, extent_a) * vb);
  const double uni = va + vb - inter;
  return uni > 0 ? inter / uni : 0.0;
}

}  // namespace emfusion
