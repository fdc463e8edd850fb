// Depth pyramids for coarse-to-fine processing: halving a depth image without
// mixing surfaces at depth edges.
//
// Output pixel (x, y) covers input pixels 2x..2x+1 by 2y..2y+1 (an odd last
// row or column is dropped), so its centre lies at input coordinates
// (2x + 0.5, 2y + 0.5): exactly where PinholeCamera::scaled(0.5) puts it. The
// camera of a level is therefore `camera.scaled(S(0.5))` of the level below,
// and its size matches the downsampled image.
#pragma once

#include <string>
#include <type_traits>
#include <utility>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/error.hpp"
#include "emfusion/core/host_device.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/parallel.hpp"

namespace emfusion {

/// Default of downsample_depth's max_depth_difference: three times the
/// bilateral filter's sigma_depth, so pixels of one noisy surface average
/// together while a foreground edge against its background (usually
/// decimetres apart) does not.
inline constexpr double default_pyramid_depth_difference = 3 * 0.04;

namespace detail {

template <class S>
struct DownsampleDepthKernel {
  ImageView<const S> depth;
  ImageView<S> out;
  S max_depth_difference;

  EMF_HD void operator()(int i) const {
    const int x = 2 * (i % out.width), y = 2 * (i / out.width);
    const S block[4] = {depth(x, y), depth(x + 1, y), depth(x, y + 1), depth(x + 1, y + 1)};
    // The nearest surface in the block is the reference: it wins at an edge,
    // which is independent of pixel order and never invents a depth between
    // the two surfaces.
    S nearest = S(0);
    for (S d : block)
      if (is_valid_depth(d) && (nearest == S(0) || d < nearest)) nearest = d;
    S sum = S(0);
    int count = 0;
    for (S d : block)
      if (is_valid_depth(d) && d - nearest <= max_depth_difference) sum += d, ++count;
    out[i] = count > 0 ? sum / S(count) : S(0);
  }
};

}  // namespace detail

/// Halves `depth` (metres) into `out`, which is (re)allocated to
/// (width / 2) x (height / 2) unless it already has that size; `out` may be
/// `depth` itself. Each output pixel is the mean of the valid pixels of its
/// 2x2 block that lie at most `max_depth_difference` metres behind the
/// block's nearest valid pixel; a block without valid pixels gives 0. Throws
/// std::invalid_argument if `depth` is smaller than 2x2 or
/// max_depth_difference is negative. Work runs on the backend of `out` (that
/// of `depth` when allocated here).
template <class S, Backend B>
void downsample_depth(const Image<S, B>& depth, Image<S, B>& out,
                      std::type_identity_t<S> max_depth_difference = S(default_pyramid_depth_difference)) {
  constexpr const char* where = "emfusion::downsample_depth";
  detail::require(
      depth.width() >= 2 && depth.height() >= 2, where,
      "depth image must be at least 2x2, got " + std::to_string(depth.width()) + "x" + std::to_string(depth.height()));
  detail::require(max_depth_difference >= S(0), where,
                  "max_depth_difference must not be negative, got " + std::to_string(double(max_depth_difference)));
  if (&out == &depth) {  // reallocating `out` would free the input: downsample into a copy
    Image<S, B> halved;
    downsample_depth(depth, halved, max_depth_difference);
    out = std::move(halved);
    return;
  }
  const int width = depth.width() / 2, height = depth.height() / 2;
  if (!out.same_size(width, height)) out = Image<S, B>(width, height, S(0), depth.backend());
  for_each_index(out.backend(), out.size(),
                 detail::DownsampleDepthKernel<S>{depth.view(), out.view(), max_depth_difference});
}

}  // namespace emfusion
