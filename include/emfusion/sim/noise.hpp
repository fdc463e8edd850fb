// Randomness for the synthetic sensor and detector, and a Kinect-v1-like
// depth noise model.
//
// Every random number is a pure function of (seed, a, b, c) through a 64-bit
// mix hash: a pixel's noise does not depend on which thread, in which order or
// on which backend it is computed, so images are reproducible everywhere and
// no generator state has to live on the device.
#pragma once

#include <cmath>
#include <cstdint>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/error.hpp"
#include "emfusion/core/host_device.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/parallel.hpp"

namespace emfusion::sim {

/// The splitmix64 finaliser: a bijection on 64 bits whose output bits each
/// depend on every input bit.
EMF_HD inline std::uint64_t mix64(std::uint64_t x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ull;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebull;
  x ^= x >> 31;
  return x;
}

/// A hash of four counters. Chaining the mix (rather than xor-ing the inputs
/// together) keeps (a, b) and (b, a) apart.
EMF_HD inline std::uint64_t hash64(std::uint64_t seed, std::uint64_t a, std::uint64_t b = 0, std::uint64_t c = 0) {
  std::uint64_t h = mix64(seed + 0x9e3779b97f4a7c15ull);
  h = mix64(h ^ (a + 0x632be59bd9b4e019ull));
  h = mix64(h ^ (b + 0x85157af5ull));
  return mix64(h ^ (c + 0x2545f4914f6cdd1dull));
}

/// Uniform in the open interval (0, 1): never 0, so log() is safe.
EMF_HD inline double uniform01(std::uint64_t seed, std::uint64_t a, std::uint64_t b = 0, std::uint64_t c = 0) {
  return (double(hash64(seed, a, b, c) >> 11) + 0.5) * (1.0 / 9007199254740992.0);
}

/// Standard normal sample (Box-Muller on two uniforms of the same key).
EMF_HD inline double standard_normal(std::uint64_t seed, std::uint64_t a, std::uint64_t b = 0, std::uint64_t c = 0) {
  const double u1 = uniform01(seed, a, b, 2 * c);
  const double u2 = uniform01(seed, a, b, 2 * c + 1);
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(6.283185307179586 * u2);
}

/// A sequential generator over the same hash, for host-side decisions (paths,
/// detector choices): the n-th draw of stream s is hash(seed, s, n), so
/// adding draws to one stream never shifts another.
class HashRng {
 public:
  EMF_HD HashRng(std::uint64_t seed, std::uint64_t stream) : seed_(seed), stream_(stream) {}
  EMF_HD double uniform() { return uniform01(seed_, stream_, counter_++); }
  EMF_HD double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  /// An integer in [lo, hi] (both included).
  EMF_HD int integer(int lo, int hi) {
    const int n = hi - lo + 1;
    const int k = int(uniform() * n);
    return lo + (k < n ? k : n - 1);
  }
  EMF_HD bool bernoulli(double p) { return uniform() < p; }

 private:
  std::uint64_t seed_, stream_, counter_ = 0;
};

/// Kinect v1 depth errors (Nguyen et al. 2012 for the axial noise, Khoshelham
/// and Elberink 2012 for the disparity quantisation). The quantisation uses
/// the sensor's own disparity units (f * b = 43.5 px m at 640 px), whatever
/// size the images are rendered at, so the depth error does not change with
/// the test image size.
struct DepthNoise {
  double sigma_base = 0.0012;        ///< m: sigma(z) = base + quadratic (z - offset)^2
  double sigma_quadratic = 0.0019;   ///< 1/m
  double sigma_offset = 0.4;         ///< m
  double focal_baseline = 43.5;      ///< px m: disparity = focal_baseline / z
  double disparity_step = 0.125;     ///< px: disparities are multiples of this (0 = no quantisation)
  double dropout_probability = 0.3;  ///< chance that a pixel near a depth discontinuity is lost
  int edge_radius = 2;               ///< px: "near" a discontinuity (Chebyshev distance)
  double edge_jump = 0.03;           ///< m: depth step between neighbours that counts as a discontinuity
  double min_range = 0.4;            ///< m: closer measurements are invalid (the sensor's near limit)
  double max_range = 4.5;            ///< m: farther measurements are invalid

  /// Standard deviation of the axial noise at depth z (m).
  EMF_HD double sigma(double z) const { return sigma_base + sigma_quadratic * (z - sigma_offset) * (z - sigma_offset); }

  /// The same model with every effect off except the range limits.
  static DepthNoise none() {
    DepthNoise n;
    n.sigma_base = n.sigma_quadratic = 0;
    n.disparity_step = 0;
    n.dropout_probability = 0;
    return n;
  }

  void validate(const char* where) const {
    emfusion::detail::require(sigma_base >= 0 && sigma_quadratic >= 0, where, "noise sigma coefficients must be >= 0");
    emfusion::detail::require(focal_baseline > 0 && disparity_step >= 0, where,
                              "focal_baseline must be > 0 and disparity_step >= 0");
    emfusion::detail::require(dropout_probability >= 0 && dropout_probability <= 1, where,
                              "dropout_probability must be in [0, 1]");
    emfusion::detail::require(edge_radius >= 0 && edge_jump > 0, where, "edge_radius must be >= 0 and edge_jump > 0");
    emfusion::detail::require(min_range >= 0 && max_range > min_range, where, "need 0 <= min_range < max_range");
  }
};

namespace detail {

// Random streams, so that the draws of different effects are independent.
enum NoiseStream : std::uint64_t { noise_axial = 1, noise_dropout = 2 };

template <class S>
struct DepthNoisePixel {
  ImageView<const S> clean;
  ImageView<S> noisy;
  DepthNoise model;
  std::uint64_t seed;
  std::uint64_t frame;

  EMF_HD bool jump(int a, int b) const {
    const S za = clean[a], zb = clean[b];
    const bool va = is_valid_depth(za), vb = is_valid_depth(zb);
    if (va != vb) return true;  // a surface next to nothing is the strongest edge
    return va && std::fabs(double(za) - double(zb)) > model.edge_jump;
  }

  /// True if two 4-neighbours within edge_radius of (u, v) straddle a jump.
  EMF_HD bool near_edge(int u, int v) const {
    const int r = model.edge_radius, w = clean.width, h = clean.height;
    const int u0 = u - r < 0 ? 0 : u - r, u1 = u + r >= w ? w - 1 : u + r;
    const int v0 = v - r < 0 ? 0 : v - r, v1 = v + r >= h ? h - 1 : v + r;
    for (int y = v0; y <= v1; ++y)
      for (int x = u0; x <= u1; ++x) {
        const int i = y * w + x;
        if (x < u1 && jump(i, i + 1)) return true;
        if (y < v1 && jump(i, i + w)) return true;
      }
    return false;
  }

  EMF_HD void operator()(int i) const {
    const double z = double(clean[i]);
    if (!is_valid_depth(z)) {
      noisy[i] = S(0);
      return;
    }
    const int u = i % clean.width, v = i / clean.width;
    if (model.dropout_probability > 0 &&
        uniform01(seed, frame, std::uint64_t(i), noise_dropout) < model.dropout_probability && near_edge(u, v)) {
      noisy[i] = S(0);
      return;
    }
    double zn = z + model.sigma(z) * standard_normal(seed, frame, std::uint64_t(i), noise_axial);
    if (model.disparity_step > 0 && zn > 0) {
      const double d = model.focal_baseline / zn;
      const double dq = std::round(d / model.disparity_step) * model.disparity_step;
      zn = dq > 0 ? model.focal_baseline / dq : 0.0;
    }
    noisy[i] = (zn >= model.min_range && zn <= model.max_range) ? S(zn) : S(0);
  }
};

}  // namespace detail

/// Writes `clean` depth with sensor noise into `noisy` (reallocated to its size
/// if needed; must not be the same image). The noise of a pixel is a function
/// of (seed, frame, pixel) only.
template <class S, Backend B>
void add_depth_noise(const Image<S, B>& clean, Image<S, B>& noisy, const DepthNoise& model, std::uint64_t seed,
                     int frame) {
  model.validate("add_depth_noise");
  emfusion::detail::require(&clean != &noisy, "add_depth_noise", "clean and noisy must be different images");
  if (!noisy.same_size(clean.width(), clean.height()))
    noisy = Image<S, B>(clean.width(), clean.height(), S(0), clean.backend());
  detail::DepthNoisePixel<S> f{clean.view(), noisy.view(), model, seed, std::uint64_t(std::int64_t(frame))};
  for_each_index(noisy.backend(), clean.size(), f);
}

}  // namespace emfusion::sim
