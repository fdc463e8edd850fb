// Edge-preserving smoothing of depth images, the first step of every frame:
// a bilateral filter removes sensor noise along surfaces but, because its
// range weight falls off with the depth difference, does not blur across depth
// discontinuities, where averaging would create points floating between a
// foreground object and the background.
#pragma once

#include <cmath>
#include <string>
#include <utility>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/error.hpp"
#include "emfusion/core/host_device.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/parallel.hpp"

namespace emfusion {

/// Parameters of bilateral_filter. They are in the filter's scalar type S so
/// that kernels use them without conversions (float kernels never touch
/// double). Defaults are those of the EM-Fusion authors' implementation.
template <class S>
struct BilateralParams {
  /// Standard deviation of the range (depth difference) weight, metres.
  S sigma_depth = S(0.04);
  /// Standard deviation of the spatial weight, pixels.
  S sigma_space = S(4.5);
  /// Half-size of the square window: 3 gives 7x7. 0 copies valid pixels.
  int radius = 3;

  /// Throws std::invalid_argument (prefixed with `where`) unless both sigmas
  /// are positive (infinite sigma_depth is allowed: a plain Gaussian blur that
  /// still skips holes) and radius is not negative.
  void validate(const char* where = "BilateralParams") const {
    detail::require(sigma_depth > S(0), where,
                    "sigma_depth must be positive, got " + std::to_string(double(sigma_depth)));
    detail::require(sigma_space > S(0), where,
                    "sigma_space must be positive, got " + std::to_string(double(sigma_space)));
    detail::require(radius >= 0, where, "radius must not be negative, got " + std::to_string(radius));
  }
};

namespace detail {

template <class S>
struct BilateralKernel {
  ImageView<const S> depth;
  ImageView<S> out;
  S neg_half_inv_var_space;  // -1 / (2 sigma_space^2)
  S neg_half_inv_var_depth;  // -1 / (2 sigma_depth^2)
  int radius;

  EMF_HD void operator()(int i) const {
    const S center = depth[i];
    if (!is_valid_depth(center)) {
      out[i] = S(0);
      return;
    }
    const int x = i % depth.width, y = i / depth.width;
    const int x0 = x - radius < 0 ? 0 : x - radius;
    const int y0 = y - radius < 0 ? 0 : y - radius;
    const int x1 = x + radius >= depth.width ? depth.width - 1 : x + radius;
    const int y1 = y + radius >= depth.height ? depth.height - 1 : y + radius;
    S weighted_sum = S(0), weight_sum = S(0);
    for (int v = y0; v <= y1; ++v) {
      for (int u = x0; u <= x1; ++u) {
        const S d = depth(u, v);
        if (!is_valid_depth(d)) continue;
        const S r2 = S((u - x) * (u - x) + (v - y) * (v - y));
        const S dd = d - center;
        const S w = std::exp(r2 * neg_half_inv_var_space + dd * dd * neg_half_inv_var_depth);
        weighted_sum += w * d;
        weight_sum += w;
      }
    }
    // The centre itself has weight 1, so weight_sum >= 1 here.
    out[i] = weighted_sum / weight_sum;
  }
};

}  // namespace detail

/// Bilateral filter of a depth image (metres) into `out`, which is
/// (re)allocated to the size of `depth` unless it already has that size; `out`
/// may be `depth` itself. Pixels without a measurement (<= 0 or non-finite)
/// come out as 0 and never contribute to their neighbours. Work runs on the
/// backend of `out` (that of `depth` when `out` is allocated here).
template <class S, Backend B>
void bilateral_filter(const Image<S, B>& depth, Image<S, B>& out, const BilateralParams<S>& params = {}) {
  constexpr const char* where = "emfusion::bilateral_filter";
  detail::require(!depth.empty(), where, "depth image is empty");
  params.validate(where);
  if (&out == &depth) {  // every pixel reads its neighbours: filter into a copy
    Image<S, B> filtered;
    bilateral_filter(depth, filtered, params);
    out = std::move(filtered);
    return;
  }
  if (!out.same_size(depth.width(), depth.height()))
    out = Image<S, B>(depth.width(), depth.height(), S(0), depth.backend());
  const S sigma_space = params.sigma_space, sigma_depth = params.sigma_depth;
  const detail::BilateralKernel<S> kernel{depth.view(), out.view(), S(-1) / (S(2) * sigma_space * sigma_space),
                                          S(-1) / (S(2) * sigma_depth * sigma_depth), params.radius};
  for_each_index(out.backend(), depth.size(), kernel);
}

}  // namespace emfusion
