// Robust norms for iteratively reweighted least squares: a norm gives the
// cost rho(r) of a residual and the IRLS weight w(r) = rho'(r) / r, so that
// minimising sum w(r_i) r_i^2 / 2 with the weights held fixed has the
// stationary points of sum rho(r_i). Users add their own by providing the
// two functions (concept RobustNorm).
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
};

/// Cauchy (Lorentzian): logarithmic growth, weight 1 / (1 + (r/c)^2).
template <class S>
struct CauchyNorm {
  S c = S(1);
  EMF_HD S cost(S r) const { return S(0.5) * c * c * std::log1p((r / c) * (r / c)); }
  EMF_HD S weight(S r) const { return S(1) / (S(1) + (r / c) * (r / c)); }
};

static_assert(RobustNorm<HuberNorm<float>, float>);

}  // namespace emfusion
