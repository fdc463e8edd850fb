// Measurement likelihood models: p(u | c, theta), how well a measured 3D
// point is explained by one model (the background or an object) at its
// current pose. The E-step (likelihood/e_step.hpp) normalises these over all
// models into association likelihoods.
//
// A model is any copyable type with a device-callable
//   S likelihood(const Vec3<S>& p_volume) const
// taking the point in the model's volume frame, or
//   S likelihood(const Vec3<S>& p_volume, const Vec3<S>& p_camera) const
// which also sees the point in the camera frame (its depth, for a noise
// model that grows with it). `PaperLikelihood` is the model of the paper
// (eq. 7):
//   alpha * Laplace(|sdf(p)|; sigma) * p_fg(p) + (1 - alpha) * p_U
// inside the model's volume and 0 outside it. The system evaluates one type
// of model on the background and on every object: a VolumeLikelihood, whose
// `volume` and `foreground` members it points at each one's maps. Users
// substitute their own type, with parameters of their own, without touching
// the library: examples/custom_likelihood.cpp defines one whose Laplace
// scale grows with depth and runs it through the full system.
//
// A model reads its volume through a view, a dense TsdfView by default; the
// volume parameter of PaperLikelihood (solve/volume_parameter.hpp) makes it
// read a sparse one instead, `PaperLikelihood<S, SparseTsdfView<S, const S>>`
// for a sparse background, and `with_volume_t<M, View>` names a model type
// moved onto another view. e_step (likelihood/e_step.hpp) takes a background
// model of one type and object models of another.
#pragma once

#include <cmath>
#include <concepts>
#include <type_traits>

#include "emfusion/core/host_device.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/solve/volume_parameter.hpp"
#include "emfusion/volume/foreground.hpp"
#include "emfusion/volume/tsdf_volume.hpp"
#include "emfusion/volume/volume_view.hpp"

namespace emfusion {

/// What the E-step needs from a likelihood model: the likelihood of a point
/// given in the model's volume frame (and, in the second form, also in the
/// camera frame).
template <class M, class S>
concept MeasurementLikelihood =
    std::copyable<M> && (requires(const M& model, const Vec3<S>& p_volume) {
      { model.likelihood(p_volume) } -> std::convertible_to<S>;
    } || requires(const M& model, const Vec3<S>& p_volume, const Vec3<S>& p_camera) {
      { model.likelihood(p_volume, p_camera) } -> std::convertible_to<S>;
    });

/// The likelihood of `model` for a point (volume and camera frame), in
/// whichever form the model has.
template <class S, class M>
EMF_HD S likelihood_of(const M& model, const Vec3<S>& p_volume, const Vec3<S>& p_camera) {
  if constexpr (requires { model.likelihood(p_volume, p_camera); })
    return S(model.likelihood(p_volume, p_camera));
  else
    return S(model.likelihood(p_volume));
}

/// A likelihood model over a TSDF volume and its foreground counts, as the
/// system uses one for the background and every object: the system copies
/// the model the user configured and points `volume` and `foreground` at
/// each model's maps (`foreground` is empty for the background). Copied to
/// the backend as bytes, so trivially copyable. `View` is the view of the
/// volumes it reads: the dense TsdfView by default, SparseTsdfView for a
/// model of a sparse volume.
template <class M, class S, class View = TsdfView<S, const S>>
concept VolumeLikelihood = MeasurementLikelihood<M, S> && std::is_trivially_copyable_v<M> &&
                           requires(M& model, View volume, ForegroundView<S, const float> fg) {
                             model.volume = volume;
                             model.foreground = fg;
                           };

/// `prototype` pointed at a volume (its view, dense or sparse) and its
/// foreground counts (empty: none, as for the background).
template <class S, class M, class View>
  requires VolumeLikelihood<M, S, View>
M bind_volume(const M& prototype, const View& volume, ForegroundView<S, const float> foreground = {}) {
  M model = prototype;
  model.volume = volume;
  model.foreground = foreground;
  return model;
}

/// Model type M moved onto volumes of view type `View`: M's member template
/// `with_volume<View>` (PaperLikelihood has one; a user's model that can
/// read other volumes declares its own).
template <class M, class View>
using with_volume_t = typename M::template with_volume<View>;

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
/// (the background). `Volume` names the volume read (volume_parameter.hpp):
/// the storage scalar of a dense volume (the default, S: TsdfView<S,
/// const S>, as before) or a view type, e.g. SparseTsdfView<S, const S>.
template <class S, class Volume = S, class Count = float>
struct PaperLikelihood {
  using View = volume_sampler_t<S, Volume>;
  /// The same model over volumes of another view type.
  template <class OtherView>
  using with_volume = PaperLikelihood<S, volume_parameter_t<OtherView>, Count>;

  View volume;
  ForegroundView<S, const Count> foreground;  ///< empty for the background
  LikelihoodParams<S> params;

  EMF_HD S likelihood(const Vec3<S>& p) const {
    // Outside the grid the model says nothing about the point (a sparse
    // volume's grid is its whole addressable range).
    if constexpr (requires { volume.contains_point(p); }) {
      if (!volume.contains_point(p)) return S(0);
    }
    // Inside it, space never observed is as far from a surface as the map
    // can say: the truncation distance. This keeps a new object's empty
    // volume at the outlier level instead of zero.
    S sdf;
    if (!volume.sample(p, sdf)) sdf = volume.truncation;
    return params.mixture(sdf, foreground.empty() ? S(1) : foreground.probability(p));
  }
};

static_assert(VolumeLikelihood<PaperLikelihood<float>, float>);
static_assert(VolumeLikelihood<PaperLikelihood<double>, double>);
static_assert(std::is_same_v<with_volume_t<PaperLikelihood<float>, TsdfView<float, const float>>,
                             PaperLikelihood<float>>);

}  // namespace emfusion
