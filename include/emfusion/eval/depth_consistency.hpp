// How well a depth frame agrees with a fused map at a given camera pose: the
// map's SDF at the frame's back-projected points. It needs no ground truth:
// fuse part of a sequence at a trajectory's poses, then measure the frames of
// another part against that map at their poses. Of two trajectories of one
// sequence, the one whose frames agree better with the map fused at its own
// poses is the more consistent with the recorded depth (docs/evaluation.md,
// "Depth consistency"); a ground truth with errors of its own shows up this
// way too.
//
// Unlike the rest of eval/, this header depends on volume/ and runs on any
// backend (one reduction over the frame's pixels).
#pragma once

#include <cmath>
#include <string>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/error.hpp"
#include "emfusion/core/host_device.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/volume/tsdf_volume.hpp"

namespace emfusion::eval {

/// Sums over the points whose SDF could be sampled (every voxel around them
/// observed) and lies within `max_abs` of zero; `+=` merges frames.
struct DepthResiduals {
  double sum_abs = 0;      ///< sum of |SDF|, metres
  double sum_squares = 0;  ///< sum of SDF^2, m^2
  double points = 0;       ///< points counted
  double within = 0;       ///< of those, points with |SDF| <= `near`

  EMF_HD DepthResiduals& operator+=(const DepthResiduals& o) {
    sum_abs += o.sum_abs, sum_squares += o.sum_squares, points += o.points, within += o.within;
    return *this;
  }
  double mean_abs() const { return points > 0 ? sum_abs / points : 0.0; }
  double rms() const { return points > 0 ? std::sqrt(sum_squares / points) : 0.0; }
  /// Share of the counted points within `near` of the surface, in [0, 1].
  double share_within() const { return points > 0 ? within / points : 0.0; }
};

namespace detail {

template <class S, class View>
struct DepthResidualTerm {
  View volume;
  ImageView<const Vec3<S>> points;
  SE3<S> T_volume_camera;
  S max_abs, near;
  EMF_HD void operator()(int i, DepthResiduals& acc) const {
    const Vec3<S> p = points[i];
    if (!(p.z() > S(0))) return;
    S sdf;
    if (!volume.sample(T_volume_camera * p, sdf)) return;
    const S a = sdf < S(0) ? -sdf : sdf;
    if (!(a <= max_abs)) return;
    acc.sum_abs += double(a);
    acc.sum_squares += double(a) * double(a);
    acc.points += 1;
    if (a <= near) acc.within += 1;
  }
};

}  // namespace detail

/// Residuals of one frame: `points` are camera-frame points (z <= 0 or NaN
/// for none, as back_project writes), `T_world_camera` the frame's pose.
/// Points whose |SDF| exceeds `max_abs` (metres; e.g. surfaces the map never
/// saw, or free space) are left out; `near` (metres) sets share_within().
/// Throws std::invalid_argument for max_abs or near not positive.
template <class S, Backend B, class Store>
DepthResiduals depth_residuals(const TsdfVolume<S, B, Store>& volume, const Image<Vec3<S>, B>& points,
                               const SE3<S>& T_world_camera, S max_abs, S near) {
  constexpr const char* where = "depth_residuals";
  emfusion::detail::require(max_abs > S(0) && std::isfinite(double(max_abs)), where,
                            "max_abs must be a positive number of metres, got " + std::to_string(double(max_abs)));
  emfusion::detail::require(near > S(0) && std::isfinite(double(near)), where,
                            "near must be a positive number of metres, got " + std::to_string(double(near)));
  using View = typename TsdfVolume<S, B, Store>::ConstView;
  const detail::DepthResidualTerm<S, View> f{volume.view(), points.view(), volume.pose().inverse() * T_world_camera,
                                             max_abs, near};
  return accumulate_index(points.backend(), points.size(), f, DepthResiduals{});
}

}  // namespace emfusion::eval
