// Vertex maps: the camera-frame 3D point seen at every pixel of a depth
// image, the form in which measurements enter association, tracking and
// integration.
//
// A pixel without a measurement holds a NaN vertex instead of being flagged
// in a separate mask, so one image carries both the points and their
// validity; test with is_valid(v). NaN also makes a forgotten check visible:
// anything computed from an invalid vertex stays NaN.
#pragma once

#include <cmath>
#include <limits>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/camera.hpp"
#include "emfusion/core/error.hpp"
#include "emfusion/core/host_device.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/core/parallel.hpp"

namespace emfusion {

/// The vertex (or normal) stored where there is none: all components NaN.
template <class S>
EMF_HD Vec3<S> invalid_vertex() {
  const S nan = std::numeric_limits<S>::quiet_NaN();
  return vec3(nan, nan, nan);
}

/// True if `v` is a point (or normal) rather than the invalid_vertex() marker:
/// all components finite.
template <class S>
EMF_HD bool is_valid(const Vec3<S>& v) {
  return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z());
}

namespace detail {

template <class S>
struct BackProjectKernel {
  ImageView<const S> depth;
  ImageView<Vec3<S>> vertices;
  PinholeCamera<S> camera;

  EMF_HD void operator()(int i) const {
    const S d = depth[i];
    const int x = i % depth.width, y = i / depth.width;
    vertices[i] = is_valid_depth(d) ? camera.back_project(S(x), S(y), d) : invalid_vertex<S>();
  }
};

}  // namespace detail

/// Back-projects every pixel of `depth` (metres, the z coordinate) through
/// `camera` into `vertices`, which is (re)allocated to the image size unless it
/// already has it. Pixels without a measurement (<= 0 or non-finite) give
/// invalid_vertex(). Throws std::invalid_argument if the camera is invalid or
/// `depth` is empty or not camera.width x camera.height. Work runs on the
/// backend of `vertices` (that of `depth` when allocated here).
template <class S, Backend B>
void back_project(const Image<S, B>& depth, const PinholeCamera<S>& camera, Image<Vec3<S>, B>& vertices) {
  constexpr const char* where = "emfusion::back_project";
  camera.validate(where);
  detail::require_image(depth.view(), camera.width, camera.height, where, "depth image");
  if (!vertices.same_size(depth.width(), depth.height()))
    vertices = Image<Vec3<S>, B>(depth.width(), depth.height(), Vec3<S>{}, depth.backend());
  for_each_index(vertices.backend(), depth.size(), detail::BackProjectKernel<S>{depth.view(), vertices.view(), camera});
}

}  // namespace emfusion
