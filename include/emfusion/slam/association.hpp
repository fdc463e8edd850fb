// Stage 2 of the EM-Fusion frame, the E-step (paper eq. 5 with the
// likelihood of eq. 7): per pixel, the association likelihood of its point
// to the background and to every live object at their current poses, in
// frame.associations ([0] background, [k + 1] Map::objects[k]). The
// likelihood is any VolumeLikelihood (PaperLikelihood by default), read
// over a sparse background through its with_volume (measurement_likelihood.hpp);
// the system runs this stage three times a frame (docs/system.md), the last
// time reusing the background's likelihoods of the second (only objects
// moved in between).
#pragma once

#include <span>
#include <type_traits>
#include <utility>
#include <vector>

#include "emfusion/core/error.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/likelihood/e_step.hpp"
#include "emfusion/likelihood/measurement_likelihood.hpp"
#include "emfusion/slam/frame.hpp"
#include "emfusion/slam/map.hpp"
#include "emfusion/slam/params.hpp"

namespace emfusion {

namespace detail::association {

/// Ablation weights: the foreground probability of the pixel's point inside
/// an object's volume, 0 outside it.
template <class S>
struct ForegroundWeight {
  ImageView<const Vec3<S>> points;
  TsdfView<S, const S> volume;
  ForegroundView<S, const float> foreground;
  SE3<S> T_volume_camera;
  ImageView<S> out;
  EMF_HD void operator()(int i) const {
    const Vec3<S> p = points[i];
    out[i] = S(0);
    if (!is_valid(p)) return;
    const Vec3<S> x = T_volume_camera * p, e = volume.extent();
    if (x.x() >= S(0) && x.y() >= S(0) && x.z() >= S(0) && x.x() < e.x() && x.y() < e.y() && x.z() < e.z())
      out[i] = foreground.probability(x);
  }
};

/// `prototype`'s settings in a model of type M (the same model over another
/// view, with_volume_t): its `params`, when it has them; the maps are bound
/// after.
template <class M, class Prototype>
M rebound(const Prototype& prototype) {
  M model{};
  if constexpr (requires { model.params = prototype.params; }) model.params = prototype.params;
  return model;
}

/// Refuses, naming `where`, a sparse background for a likelihood that has no
/// with_volume (it reads dense volumes only).
template <class S, class Likelihood>
void require_sparse_capable(bool sparse_background, const char* where) {
  constexpr bool capable = requires {
    typename Likelihood::template with_volume<SparseTsdfView<S, const S>>;
  };
  detail::require(capable || !sparse_background, where,
                  "this likelihood reads dense volumes only (it has no with_volume): set sparse_background = false, "
                  "or give it a with_volume member (likelihood/measurement_likelihood.hpp)");
}

}  // namespace detail::association

/// `f(model)` with `likelihood` (the user's configured model) pointed at
/// the background's volume, as the E-step reads it: over a dense
/// background the same model type, over a sparse one the likelihood's own
/// model of the sparse view (Likelihood::with_volume; a likelihood without
/// one is refused, naming `where`).
template <class S, Backend B, class Likelihood, class F>
void visit_background_model(const BackgroundVolume<S, B>& background, const Likelihood& likelihood, F&& f,
                            const char* where = "associate") {
  background.visit([&](const auto& volume) {
    using View = decltype(volume.view());
    if constexpr (std::is_same_v<View, TsdfView<S, const S>>) {
      f(bind_volume<S>(likelihood, volume.view()));
    } else if constexpr (requires { typename Likelihood::template with_volume<View>; }) {
      using Model = typename Likelihood::template with_volume<View>;
      f(bind_volume<S>(detail::association::rebound<Model>(likelihood), volume.view()));
    } else {
      detail::association::require_sparse_capable<S, Likelihood>(true, where);
    }
  });
}

/// The ablation without association likelihoods (paper Table 3, Fig. 3):
/// objects weight a pixel by the foreground probability of its point, the
/// background takes every pixel with weight 1.
template <class S, Backend B>
void foreground_weights(const Map<S, B>& map, Frame<S, B>& frame) {
  const B& backend = frame.points.backend();
  frame.associations.resize(int(map.objects.size()) + 1, frame.points.width(), frame.points.height(), backend);
  frame.associations.image(0).fill(S(1));
  for (std::size_t k = 0; k < map.objects.size(); ++k) {
    const ObjectModel<S, B>& o = *map.objects[k];
    for_each_index(backend, frame.points.size(),
                   detail::association::ForegroundWeight<S>{
                       std::as_const(frame.points).view(), o.volume().view(), o.foreground().view(),
                       o.volume().pose().inverse() * map.T_world_camera,
                       frame.associations.image(int(k) + 1).view()});
  }
}

/// The E-step for frame.points against `background` with the camera at
/// T_world_camera and the object models `models` (`likelihood` bound to
/// each object's volume and counts) at T_volume_camera `poses`:
/// frame.associations [0] the background, [k + 1] models[k]. associate's
/// E-step over a map's objects; tracking an object back (track_back.hpp)
/// gives it one object at a pose of its own. `background_unchanged`: as
/// e_step's.
template <class S, Backend B, class Likelihood>
  requires VolumeLikelihood<Likelihood, S>
void associate_with(const BackgroundVolume<S, B>& background, const SE3<S>& T_world_camera,
                    const std::vector<Likelihood>& models, const std::vector<SE3<S>>& poses, Frame<S, B>& frame,
                    const Likelihood& likelihood, bool background_unchanged = false) {
  const SE3<S> T_background_camera = background.pose().inverse() * T_world_camera;
  visit_background_model(background, likelihood, [&](const auto& model) {
    e_step(frame.points.backend(), frame.points, model, T_background_camera, std::span<const Likelihood>(models),
           std::span<const SE3<S>>(poses), frame.associations, background_unchanged);
  });
}

/// The E-step for frame.points with the camera at map.T_world_camera and
/// every object at its pose: `likelihood` (the user's configured model) is
/// pointed at the background's volume and at each object's volume and
/// foreground counts. With params.use_association off, the ablation weights
/// of foreground_weights instead. `background_unchanged`: since the last
/// call for this frame only objects have moved (the camera may not have:
/// then the background is evaluated again), so the background's
/// likelihoods are reused (e_step); the system says so for its last E-step
/// of a frame, after the objects' solves.
template <class S, Backend B, class Likelihood>
  requires VolumeLikelihood<Likelihood, S>
void associate(const Map<S, B>& map, Frame<S, B>& frame, const Likelihood& likelihood,
               const SystemParams<S>& params, bool background_unchanged = false) {
  if (!params.use_association) return foreground_weights(map, frame);
  std::vector<Likelihood> models;
  std::vector<SE3<S>> poses;
  for (const auto& o : map.objects) {
    // Through the const object: a mutable view of the counts would make
    // raycasting compute their majority_box afresh.
    const ObjectModel<S, B>& object = *o;
    models.push_back(bind_volume<S>(likelihood, object.volume().view(), object.foreground().view()));
    poses.push_back(object.volume().pose().inverse() * map.T_world_camera);
  }
  associate_with(map.background, map.T_world_camera, models, poses, frame, likelihood, background_unchanged);
}

/// Eq. 5 for a pixel that one model explains perfectly (its point on the
/// surface, p_fg 1) and another not at all (on its surface, p_fg 0): the
/// second's share, as `likelihood` gives it for a point 1 m ahead of the
/// camera. A new object's first frame weighs the pixels outside its
/// detection with it, as later frames' E-steps would (detection handling).
template <class S, class Likelihood>
  requires VolumeLikelihood<Likelihood, S>
S unexplained_association(const Likelihood& likelihood) {
  // Eight observed voxels of 1 m on the zero level set, all foreground or
  // all background; their common corner is the point asked about.
  const S sdf[8] = {}, weight[8] = {S(1), S(1), S(1), S(1), S(1), S(1), S(1), S(1)};
  const float ones[8] = {1, 1, 1, 1, 1, 1, 1, 1}, zeros[8] = {};
  const TsdfView<S, const S> volume{sdf, weight, 2, 2, 2, S(1), S(1)};
  const ForegroundView<S, const float> foreground{ones, zeros, 2, 2, 2, S(1)}, background{zeros, ones, 2, 2, 2, S(1)};
  const Vec3<S> p_volume = vec3(S(1), S(1), S(1)), p_camera = vec3(S(0), S(0), S(1));
  const S explained = likelihood_of(bind_volume<S>(likelihood, volume, foreground), p_volume, p_camera);
  const S unexplained = likelihood_of(bind_volume<S>(likelihood, volume, background), p_volume, p_camera);
  return unexplained / (explained + unexplained);
}

}  // namespace emfusion
