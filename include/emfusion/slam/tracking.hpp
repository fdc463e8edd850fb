// Stage 3 of the EM-Fusion frame, the M-step for the poses (paper eq. 8/9):
// the camera against the background, then every object against the frame,
// each a direct SDF alignment weighted by its association image, the map's
// confidence and a robust norm, minimised by a PoseSolver. A solved pose is
// taken only if the solve converged with enough terms and moved less than
// the per-frame bound (docs/system.md, "Hostile input"); otherwise the pose
// stays and the outcome says why.
#pragma once

#include <cmath>
#include <cstddef>
#include <future>
#include <vector>

#include "emfusion/core/parallel.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/robust/norms.hpp"
#include "emfusion/slam/frame.hpp"
#include "emfusion/slam/frame_result.hpp"
#include "emfusion/slam/map.hpp"
#include "emfusion/slam/params.hpp"
#include "emfusion/solve/sdf_alignment.hpp"
#include "emfusion/solve/solvers.hpp"

namespace emfusion {

/// Buffers the solves keep between frames: per-term values of the camera's
/// and of each object's solve, and the streams object solves run on
/// concurrently (CUDA). Optional in every call: without one, each solve
/// allocates its own.
template <class S, Backend B>
struct TrackingWorkspace {
  LinearizationCache<S, B> camera_cache;
  std::vector<LinearizationCache<S, B>> object_caches;  ///< one per object solve (they may run at once)
  ConcurrentLanes<B> lanes;
};

/// How far `to` lies from `from`: translation and rotation angle.
template <class S>
PoseStep step_between(const SE3<S>& from, const SE3<S>& to) {
  const SE3<double> d = from.template cast<double>().inverse() * to.template cast<double>();
  return {double(norm(d.translation())), double(norm(so3_log(d.rotation())))};
}

template <class S>
bool is_finite(const SE3<S>& T) {
  const auto m = T.matrix();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c)
      if (!std::isfinite(double(m(r, c)))) return false;
  return true;
}

/// The outcome of a solve that proposed `T_new`: accepted only if it found a
/// solution with at least `min_terms` terms that moves less than `bound`.
template <class S>
TrackingOutcome tracking_outcome(const SolveReport& r, double min_terms, const SE3<S>& T_new, const PoseStep& step,
                                 const MotionBound<S>& bound) {
  if (r.reason == StopReason::too_few_terms) return TrackingOutcome::too_few_terms;
  if (!r.converged() || !is_finite(T_new)) return TrackingOutcome::solve_failed;
  if (r.terms < min_terms) return TrackingOutcome::too_few_terms;
  if (bound.exceeded_by(step.translation, step.rotation)) return TrackingOutcome::jump_rejected;
  return TrackingOutcome::tracked;
}

/// The alignment weights of the system's tracking problems (eq. 8/9): the
/// association image (p_fg in the ablation without association), and map
/// confidence normalised by `max_weight`, the tracked volume's W_max.
template <class S>
SdfAlignmentParams<S> alignment_params(const SystemParams<S>& params, S max_weight) {
  SdfAlignmentParams<S> a;
  a.use_association = true;
  a.use_map_confidence = params.use_map_confidence;
  a.confidence_normalizer = max_weight;
  a.pixel_stride = params.pixel_stride;
  a.depth_noise_reference = params.depth_noise_reference;
  return a;
}

/// Tracks the camera against the background from map.T_world_camera with
/// frame.points weighted by frame.associations.image(0); moves
/// map.T_world_camera when the outcome is `tracked`. `norm` is in voxels of
/// the background (scaled_norm).
template <class S, Backend B, class Norm, class Solver>
  requires RobustNorm<Norm, S> && PoseSolver<Solver, S>
PoseTrack track_camera(Map<S, B>& map, const Frame<S, B>& frame, const SystemParams<S>& params, const Norm& norm,
                       const Solver& solver, TrackingWorkspace<S, B>* workspace = nullptr) {
  PoseTrack t;
  const SE3<S> T_solved =
      align_to_volume(map.background, frame.points, &frame.associations.image(0), map.T_world_camera,
                      scaled_norm(norm, map.background.voxel_size()),
                      alignment_params(params, params.background_integration.max_weight), solver, &t.report,
                      workspace ? &workspace->camera_cache : nullptr);
  t.step = step_between(map.T_world_camera, T_solved);
  t.outcome = tracking_outcome(t.report, double(params.min_camera_terms), T_solved, t.step, params.max_camera_motion);
  if (t.outcome == TrackingOutcome::tracked) map.T_world_camera = T_solved;
  return t;
}

/// Tracks every live object from its pose with the camera at
/// map.T_world_camera, object k's terms weighted by
/// frame.associations.image(k + 1); moves the objects whose outcome is
/// `tracked`. Returns one PoseTrack per object, in Map::objects order. `norm`
/// is in voxels of each object. Each solve is independent of the others':
/// on CUDA they run from host threads on streams of their own, so that
/// their small kernels and the host's solver steps overlap; the poses are
/// applied afterwards in object order.
template <class S, Backend B, class Norm, class Solver>
  requires RobustNorm<Norm, S> && PoseSolver<Solver, S>
std::vector<PoseTrack> track_objects(Map<S, B>& map, const Frame<S, B>& frame, const SystemParams<S>& params,
                                     const Norm& norm, const Solver& solver,
                                     TrackingWorkspace<S, B>* workspace = nullptr) {
  const std::size_t n = map.objects.size();
  TrackingWorkspace<S, B> local;
  TrackingWorkspace<S, B>& ws = workspace ? *workspace : local;
  ws.object_caches.resize(n);
  const SdfAlignmentParams<S> align = alignment_params(params, params.object_integration.max_weight);
  const B& backend = frame.points.backend();
  std::vector<PoseTrack> tracks(n);
  std::vector<SE3<S>> T_volume_camera(n);
  const auto solve = [&](std::size_t k, const B& run_on) {
    const ObjectModel<S, B>& o = *map.objects[k];
    // The object starts where it was; the solver finds how it moved
    // relative to the camera.
    T_volume_camera[k] = align_in_volume(o.volume(), frame.points, &frame.associations.image(int(k) + 1),
                                         o.volume().pose().inverse() * map.T_world_camera,
                                         scaled_norm(norm, o.volume().voxel_size()), align, solver,
                                         &tracks[k].report, &ws.object_caches[k], &run_on);
  };
  if (ConcurrentLanes<B>::concurrent && n > 1) {
    std::vector<B> lanes;
    for (std::size_t k = 0; k < n; ++k) lanes.push_back(ws.lanes.lane(k, backend));
    std::vector<std::future<void>> running;
    for (std::size_t k = 0; k < n; ++k) running.push_back(std::async(std::launch::async, solve, k, lanes[k]));
    for (auto& r : running) r.get();  // rethrows a solve's exception here
  } else {
    for (std::size_t k = 0; k < n; ++k) solve(k, backend);
  }
  for (std::size_t k = 0; k < n; ++k) {
    ObjectModel<S, B>& o = *map.objects[k];
    const SE3<S> T_world_object = map.T_world_camera * T_volume_camera[k].inverse() * o.T_object_volume().inverse();
    PoseTrack& t = tracks[k];
    t.step = step_between(o.pose(), T_world_object);
    t.outcome = tracking_outcome(t.report, double(params.min_object_terms), T_world_object, t.step,
                                 params.max_object_motion);
    if (t.outcome == TrackingOutcome::tracked) o.set_pose(T_world_object);
  }
  return tracks;
}

}  // namespace emfusion
