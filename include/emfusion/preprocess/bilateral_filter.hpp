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
#include "emfusion/core/math.hpp"
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

/// The weight of a neighbour: spatial and range Gaussians as two factors,
/// e^(r2 ks) e^(dd^2 kd), through fast_exp (the filter's time on the CPU was
/// mostly glibc's expf).
template <class S>
EMF_HD S bilateral_weight(S spatial, S depth_difference, S neg_half_inv_var_depth) {
  return spatial * fast_exp(depth_difference * depth_difference * neg_half_inv_var_depth);
}

/// One output pixel a thread (the device's filter).
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
        const S spatial = fast_exp(S((u - x) * (u - x) + (v - y) * (v - y)) * neg_half_inv_var_space);
        const S w = bilateral_weight(spatial, d - center, neg_half_inv_var_depth);
        weighted_sum += w * d;
        weight_sum += w;
      }
    }
    // The centre itself has weight 1, so weight_sum >= 1 here.
    out[i] = weighted_sum / weight_sum;
  }
};

/// One image row a call (the host's filter), in chunks of pixels: the
/// window's offsets outside, the chunk's pixels inside, so that the inner
/// loop has no branch and vectorises. Each pixel sums the same weights in
/// the same order as BilateralKernel.
template <class S>
struct BilateralRow {
  ImageView<const S> depth;
  ImageView<S> out;
  S neg_half_inv_var_space;
  S neg_half_inv_var_depth;
  int radius;
  static constexpr int chunk = 128;

  /// All ones where d is a measurement (finite, positive: is_valid_depth),
  /// zero elsewhere, from integer comparisons of its bits.
  EMF_HD static unsigned valid_depth_mask(float d) {
    const int b = float_bits(d);
    return 0u - unsigned((b > 0) & (b < 0x7f800000));
  }
  EMF_HD static float masked(float x, unsigned mask) { return float_from_bits(int(unsigned(float_bits(x)) & mask)); }
  EMF_HD static bool valid_depth_mask(double d) { return is_valid_depth(d); }
  EMF_HD static double masked(double x, bool keep) { return keep ? x : 0.0; }

  EMF_AVX2_CLONE void operator()(int y) const {
    const int w = depth.width;
    for (int x0 = 0; x0 < w; x0 += chunk) {
      const int n = w - x0 < chunk ? w - x0 : chunk;
      const S* center = &depth(x0, y);
      S weight_sum[chunk], weighted_sum[chunk];
      for (int i = 0; i < n; ++i) weight_sum[i] = weighted_sum[i] = S(0);
      for (int v = y - radius; v <= y + radius; ++v) {
        if (v < 0 || v >= depth.height) continue;
        const S* row = &depth(0, v);
        for (int du = -radius; du <= radius; ++du) {
          const S spatial = fast_exp(S(du * du + (v - y) * (v - y)) * neg_half_inv_var_space);
          // The chunk's pixels whose neighbour x0 + i + du is in the image.
          const int lo = -du - x0 > 0 ? -du - x0 : 0;
          const int hi = w - du - x0 < n ? w - du - x0 : n;
          for (int i = lo; i < hi; ++i) {
            const S d = row[x0 + du + i];
            const S wi = bilateral_weight(spatial, d - center[i], neg_half_inv_var_depth);
            // Holes weigh nothing: masked through the bits, since a float
            // select becomes a branch around the product and the loop
            // stays scalar.
            const auto keep = valid_depth_mask(d);
            const S masked_w = masked(wi, keep), masked_d = masked(d, keep);
            weight_sum[i] += masked_w;
            weighted_sum[i] += masked_w * masked_d;
          }
        }
      }
      for (int i = 0; i < n; ++i)
        out(x0 + i, y) = is_valid_depth(center[i]) ? weighted_sum[i] / weight_sum[i] : S(0);
    }
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
  const S k_space = S(-1) / (S(2) * sigma_space * sigma_space);
  const S k_depth = S(-1) / (S(2) * sigma_depth * sigma_depth);
  // A thread a pixel on a device; a row a call on the CPU, where the rows'
  // inner loops vectorise (the filter took 40 of a frame's 430 ms on 2
  // cores with glibc's expf a pixel at a time).
  if constexpr (B::is_device)
    for_each_index(out.backend(), depth.size(),
                   detail::BilateralKernel<S>{depth.view(), out.view(), k_space, k_depth, params.radius});
  else
    for_each_index(out.backend(), depth.height(),
                   detail::BilateralRow<S>{depth.view(), out.view(), k_space, k_depth, params.radius});
}

}  // namespace emfusion
