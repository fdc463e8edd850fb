// Robust norms for iteratively reweighted least squares: a norm gives the
// cost rho(r) of a residual and the IRLS weight w(r) = rho'(r) / r, so that
// minimising sum w(r_i) r_i^2 / 2 with the weights held fixed has the
// stationary points of sum rho(r_i). Users add their own by providing the
// two functions (concept RobustNorm).
//
// The system's norms are given in voxels of the volume a problem tracks
// (the paper's Huber delta is 2 voxels: 2 cm for the background, a few
// millimetres for a small object); scaled_norm(norm, voxel_size) gives the
// norm in metres: the norm's own `scaled(s)` where it has one (every norm
// here does), else ScaledNorm, which works for any RobustNorm.
#pragma once

#include <cmath>
#include <concepts>

#include "emfusion/core/host_device.hpp"

namespace emfusion {

template <class N, class S>
concept RobustNorm = requires(const N& norm, S r) {
  { norm.cost(r) } -> std::convertible_to<S>;
  { norm.weight(r) } -> std::convertible_to<S>;
};

/// rho(r) = r^2 / 2: plain least squares.
template <class S>
struct L2Norm {
  EMF_HD S cost(S r) const { return S(0.5) * r * r; }
  EMF_HD S weight(S) const { return S(1); }
  L2Norm scaled(S) const { return *this; }
};

/// Quadratic within delta, linear beyond (the paper's tracking norm).
template <class S>
struct HuberNorm {
  S delta = S(1);
  EMF_HD S cost(S r) const {
    const S a = std::fabs(r);
    return a <= delta ? S(0.5) * r * r : delta * (a - S(0.5) * delta);
  }
  EMF_HD S weight(S r) const {
    const S a = std::fabs(r);
    return a <= delta ? S(1) : delta / a;
  }
  HuberNorm scaled(S s) const { return {delta * s}; }
};

/// Tukey's biweight: residuals beyond c get zero weight.
template <class S>
struct TukeyNorm {
  S c = S(1);
  EMF_HD S cost(S r) const {
    if (std::fabs(r) >= c) return c * c / S(6);
    const S u = S(1) - (r / c) * (r / c);
    return c * c / S(6) * (S(1) - u * u * u);
  }
  EMF_HD S weight(S r) const {
    if (std::fabs(r) >= c) return S(0);
    const S u = S(1) - (r / c) * (r / c);
    return u * u;
  }
  TukeyNorm scaled(S s) const { return {c * s}; }
};

/// Cauchy (Lorentzian): logarithmic growth, weight 1 / (1 + (r/c)^2).
template <class S>
struct CauchyNorm {
  S c = S(1);
  EMF_HD S cost(S r) const { return S(0.5) * c * c * std::log1p((r / c) * (r / c)); }
  EMF_HD S weight(S r) const { return S(1) / (S(1) + (r / c) * (r / c)); }
  CauchyNorm scaled(S s) const { return {c * s}; }
};

/// A norm of residuals in units of `scale` applied to residuals in metres:
/// rho(r) = scale^2 rho_N(r / scale), w(r) = w_N(r / scale), so that the
/// IRLS weights and the cost's minimisers are those of N on r / scale.
template <class N, class S>
struct ScaledNorm {
  N norm;
  S scale = S(1);
  EMF_HD S cost(S r) const { return scale * scale * S(norm.cost(r / scale)); }
  EMF_HD S weight(S r) const { return S(norm.weight(r / scale)); }
};

/// `norm` (its parameters in units of `scale`, e.g. voxels) for residuals in metres.
template <class S, class N>
  requires RobustNorm<N, S>
auto scaled_norm(const N& norm, S scale) {
  if constexpr (requires { { norm.scaled(scale) } -> RobustNorm<S>; })
    return norm.scaled(scale);
  else
    return ScaledNorm<N, S>{norm, scale};
}

static_assert(RobustNorm<HuberNorm<float>, float>);
static_assert(RobustNorm<ScaledNorm<TukeyNorm<double>, double>, double>);

}  // namespace emfusion
