// Measurement likelihood models: p(u | c, theta), how well a measured 3D
// point is explained by one model (the background or an object) at its
// current pose. The E-step (likelihood/e_step.hpp) normalises these over all
// models into association likelihoods.
//
// A model is any copyable type with a device-callable
//   S likelihood(const Vec3<S>& p) const
// taking the point in the model's volume frame. `PaperLikelihood` is the
// model of the paper (eq. 7):
//   alpha * Laplace(|sdf(p)|; sigma) * p_fg(p) + (1 - alpha) * p_U
// inside the model's volume and 0 outside it. Users substitute their own type
// (examples/custom_likelihood.cpp shows one) without touching the library.
#pragma once

#include <cmath>
#include <concepts>

#include "emfusion/core/host_device.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/volume/foreground.hpp"
#include "emfusion/volume/tsdf_volume.hpp"

namespace emfusion {

/// What the E-step needs from a likelihood model.
template <class M, class S>
concept MeasurementLikelihood = std::copyable<M> && requires(const M& model, const Vec3<S>& p_volume) {
  { model.likelihood(p_volume) } -> std::convertible_to<S>;
};

/// Parameters of eq. 7 (paper and reference values).
template <class S>
struct LikelihoodParams {
  S alpha = S(0.8);      ///< weight of the Laplace (inlier) component
  S sigma = S(0.02);     ///< Laplace scale, metres
  S p_uniform = S(1);    ///< density of the uniform outlier component

  /// Eq. 7 for a point at signed distance `sdf` from the surface with
  /// foreground probability `p_fg`.
  EMF_HD S mixture(S sdf, S p_fg) const {
    const S laplace = std::exp(-std::fabs(sdf) / sigma) / (S(2) * sigma);
    return alpha * laplace * p_fg + (S(1) - alpha) * p_uniform;
  }
};

/// The paper's mixture (eq. 7) on a TSDF volume, with the voxels' foreground
/// probability when `foreground` is set (objects) and p_fg = 1 without
/// (the background).
template <class S, class Store = S, class Count = float>
struct PaperLikelihood {
  TsdfView<S, const Store> volume;
  ForegroundView<S, const Count> foreground;  ///< empty for the background
  LikelihoodParams<S> params;

  EMF_HD S likelihood(const Vec3<S>& p) const {
    // Outside the grid the model says nothing about the point.
    if (!volume.contains_point(p)) return S(0);
    // Inside it, space never observed is as far from a surface as the map
    // can say: the truncation distance. This keeps a new object's empty
    // volume at the outlier level instead of zero.
    S sdf;
    if (!volume.sample(p, sdf)) sdf = volume.truncation;
    return params.mixture(sdf, foreground.empty() ? S(1) : foreground.probability(p));
  }
};

static_assert(MeasurementLikelihood<PaperLikelihood<float>, float>);
static_assert(MeasurementLikelihood<PaperLikelihood<double>, double>);

}  // namespace emfusion
