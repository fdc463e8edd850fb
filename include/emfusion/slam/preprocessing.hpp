// Stage 1 of the EM-Fusion frame (paper sec. 3.3): the received depth made
// safe (every pixel that is 0, NaN, infinite, negative or beyond
// SystemParams::max_depth becomes a hole, and is counted by kind), then the
// bilateral filter and back-projection to camera-frame points.
#pragma once

#include <cmath>

#include "emfusion/core/camera.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/preprocess/bilateral_filter.hpp"
#include "emfusion/preprocess/vertex_map.hpp"
#include "emfusion/slam/frame.hpp"
#include "emfusion/slam/frame_result.hpp"
#include "emfusion/slam/params.hpp"

namespace emfusion {

namespace detail::preprocessing {

/// The kind of each received depth pixel (DepthCounts).
template <class S>
struct ClassifyDepth {
  ImageView<const S> depth;
  S max_depth;  // 0: no limit
  EMF_HD DepthCounts operator()(int i) const {
    const S d = depth[i];
    DepthCounts c;
    if (d == S(0)) c.missing = 1;
    else if (!std::isfinite(d)) c.not_finite = 1;
    else if (d < S(0)) c.negative = 1;
    else if (max_depth > S(0) && d > max_depth) c.beyond_range = 1;
    else c.valid = 1;
    return c;
  }
};

struct AddDepthCounts {
  EMF_HD DepthCounts operator()(const DepthCounts& a, const DepthCounts& b) const { return a + b; }
};

/// Copies the measurements of a depth image and turns everything else
/// (non-finite, not positive, beyond max_depth) into holes.
template <class S>
struct SanitizeDepth {
  ImageView<const S> in;
  ImageView<S> out;
  S max_depth;  // 0: no limit
  EMF_HD void operator()(int i) const {
    const S d = in[i];
    out[i] = is_valid_depth(d) && (max_depth <= S(0) || d <= max_depth) ? d : S(0);
  }
};

}  // namespace detail::preprocessing

/// Counts the received depth's pixels by kind and copies its measurements
/// into `out`, holes everywhere else: nothing after this sees an invalid value.
template <class S, Backend B>
DepthCounts sanitize_depth(const Image<S, B>& depth, S max_depth, Image<S, B>& out) {
  const B& backend = depth.backend();
  if (!out.same_size(depth.width(), depth.height())) out = Image<S, B>(depth.width(), depth.height(), S(0), backend);
  for_each_index(backend, depth.size(), detail::preprocessing::SanitizeDepth<S>{depth.view(), out.view(), max_depth});
  return transform_reduce_index(backend, depth.size(),
                                detail::preprocessing::ClassifyDepth<S>{depth.view(), max_depth}, DepthCounts{},
                                detail::preprocessing::AddDepthCounts{});
}

/// Fills frame.depth, frame.filtered and frame.points from a received depth
/// image (metres, camera size); returns its pixels by kind.
template <class S, Backend B>
DepthCounts preprocess(const Image<S, B>& depth, const PinholeCamera<S>& camera, const SystemParams<S>& params,
                       Frame<S, B>& frame) {
  detail::require_image(depth.view(), camera.width, camera.height, "preprocess", "depth image");
  const DepthCounts counts = sanitize_depth(depth, params.max_depth, frame.depth);
  bilateral_filter(frame.depth, frame.filtered, params.bilateral);
  back_project(frame.filtered, camera, frame.points);
  return counts;
}

}  // namespace emfusion
