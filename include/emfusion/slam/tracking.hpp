// Stage 3 of the EM-Fusion frame, the M-step for the poses (paper eq. 8/9):
// the camera against the background, then every object against the frame,
// each a direct SDF alignment weighted by its association image, the map's
// confidence and a robust norm, minimised by a PoseSolver, coarse to fine
// over SystemParams::pyramid_levels (the camera over camera_pyramid_levels,
// with its own stride and stop: camera_alignment_params, camera_solver). A
// solve starts at the last pose or at
// its motion prediction (predict_camera, predict_objects), whichever the
// frame agrees with better. A solved pose is taken only if the solve
// converged with enough terms and moved less than the per-frame bound
// (docs/system.md, "Hostile input"); otherwise it is solved once more from
// the other start (retry_tracking), and failing that the last pose stays
// and the outcome says why. With the library's Levenberg-Marquardt the
// solves run in batches (solve/batched_solve.hpp): all objects' iterations
// together, the camera's without a host round trip per iteration.
#pragma once

#include <cmath>
#include <cstddef>
#include <future>
#include <optional>
#include <utility>
#include <vector>

#include "emfusion/core/parallel.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/robust/norms.hpp"
#include "emfusion/slam/frame.hpp"
#include "emfusion/slam/frame_result.hpp"
#include "emfusion/slam/map.hpp"
#include "emfusion/slam/motion_prediction.hpp"
#include "emfusion/slam/params.hpp"
#include "emfusion/solve/pose_prior.hpp"
#include "emfusion/solve/sdf_alignment.hpp"
#include "emfusion/solve/solvers.hpp"

namespace emfusion {

/// Buffers the solves keep between frames: per-term values of the camera's
/// and of each object's solve, and the streams object solves run on
/// concurrently (CUDA). Optional in every call: without one, each solve
/// allocates its own.
template <class S, Backend B>
struct TrackingWorkspace {
  BatchedSolveWorkspace<S, B> camera_batch, object_batch;  ///< solved_in_batches
  LinearizationCache<S, B> camera_cache;                   ///< the other solvers'
  std::vector<LinearizationCache<S, B>> object_caches;     ///< one per object solve (they may run at once)
  ConcurrentLanes<B> lanes;
};

/// Whether tracking solves with `Solver` in batches (solve/batched_solve.hpp):
/// the library's LevenbergMarquardt, whose iterations run for all objects at
/// once and, on a GPU, without the host. Any other solver (GaussNewton, a
/// user's PoseSolver) sees one problem at a time through its Linearizer
/// (track_in_volume): the same results, one solve after another.
template <class Solver>
inline constexpr bool solved_in_batches = std::same_as<Solver, LevenbergMarquardt>;

/// How far `to` lies from `from`: translation and rotation angle.
template <class S>
PoseStep step_between(const SE3<S>& from, const SE3<S>& to) {
  const SE3<double> d = from.template cast<double>().inverse() * to.template cast<double>();
  return {double(norm(d.translation())), double(norm(so3_log(d.rotation())))};
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
  a.pyramid_levels = params.pyramid_levels;
  a.depth_noise_reference = params.depth_noise_reference;
  return a;
}

/// Adds object `o`'s colour terms to its solve's `terms`
/// (object_colour_weight): when the model has colour and the frame its gray
/// values; otherwise `terms` stay depth alone.
template <class S, Backend B, class Volume>
void with_colour(SdfAlignmentTerms<S, Volume>& terms, const ObjectModel<S, B>& o, const Frame<S, B>& frame,
                 const SystemParams<S>& params) {
  if (!(params.object_colour_weight > S(0)) || frame.intensity.empty() || o.colour().empty()) return;
  terms.colour = o.colour().view();
  terms.intensity = frame.intensity.view();
  terms.colour_scale = params.object_colour_weight * o.volume().voxel_size();
}

/// The alignment of the camera's solve: alignment_params with the
/// background's W_max and the camera's own stride (camera_pixel_stride; 0:
/// auto_pixel_stride of the frame's size) and camera_pyramid_levels.
template <class S>
SdfAlignmentParams<S> camera_alignment_params(const SystemParams<S>& params, int width, int height) {
  SdfAlignmentParams<S> a = alignment_params(params, params.background_integration.max_weight);
  a.pixel_stride = params.camera_pixel_stride > 0 ? params.camera_pixel_stride : auto_pixel_stride(width, height);
  a.pyramid_levels = params.camera_pyramid_levels;
  return a;
}

/// The solver of the camera's solve: `solver` with camera_converged_step
/// and camera_converged_gain (with_converged_step, with_converged_gain:
/// only a solver that has those stops changes).
template <class S, class Solver>
Solver camera_solver(const Solver& solver, const SystemParams<S>& params) {
  return with_converged_gain(with_converged_step(solver, params.camera_converged_step), params.camera_converged_gain);
}

/// Solves one SDF alignment problem, `terms` (sdf_alignment_in_box's;
/// poses are T_volume_camera), from `starts`: from the prediction when the
/// frame agrees with it at least as well as with the previous pose
/// (agrees_at_least_as_well), else from the previous pose; with `retry`,
/// once more from the other start when `judge(T, track)` (which fills
/// track.step and track.outcome from track.report) does not find the first
/// solve `tracked`. Returns the pose of the solve taken (the retry's if it
/// was tracked, else the first's) and fills `track`. Any PoseSolver, one
/// iteration after another through its Linearizer. With `prior`, each solve
/// is pulled towards its start (the prior's pose is replaced by it).
template <class S, Backend B, class Volume, class Norm, class Solver, class Judge>
  requires RobustNorm<Norm, S> && PoseSolver<Solver, S>
SE3<S> track_terms(const B& backend, const SdfAlignmentTerms<S, Volume>& terms, const PoseStarts<S>& starts,
                   const Norm& norm, const SdfAlignmentParams<S>& align, const Solver& solver, bool retry,
                   Judge&& judge, PoseTrack& track, LinearizationCache<S, B>& cache,
                   const PosePrior<S>* prior = nullptr) {
  const bool predicted_first =
      starts.predicted && agrees_at_least_as_well(backend, terms, norm, align, *starts.predicted, starts.previous);
  const auto solve_from = [&](bool from_prediction, PoseTrack& t) {
    t.from_prediction = from_prediction;
    const SE3<S> start = from_prediction ? *starts.predicted : starts.previous;
    const PosePrior<S> pulled = (prior ? *prior : PosePrior<S>{}).towards(start);
    const SE3<S> T = solve_coarse_to_fine(backend, terms, norm, align, solver, start, &t.report, cache, &pulled);
    judge(T, t);
    return T;
  };
  SE3<S> T = solve_from(predicted_first, track);
  track.attempts = 1;
  if (retry && starts.predicted && track.outcome != TrackingOutcome::tracked) {
    PoseTrack second;
    const SE3<S> T_second = solve_from(!predicted_first, second);
    if (second.outcome == TrackingOutcome::tracked) T = T_second, track = second;
    track.attempts = 2;
  }
  return T;
}

/// track_terms for the SDF alignment of `points` (camera frame) in
/// `volume` (dense or sparse) weighted by `association`, over the box of
/// its positive pixels.
template <class S, Backend B, class Volume, class Norm, class Solver, class Judge>
  requires TsdfVolumeOn<Volume, S, B> && RobustNorm<Norm, S> && PoseSolver<Solver, S>
SE3<S> track_in_volume(const Volume& volume, const Image<Vec3<S>, B>& points, const Image<S, B>* association,
                       const PoseStarts<S>& starts, const Norm& norm, const SdfAlignmentParams<S>& align,
                       const Solver& solver, bool retry, Judge&& judge, PoseTrack& track,
                       LinearizationCache<S, B>& cache, const B& backend, const PosePrior<S>* prior = nullptr) {
  return track_terms(backend, sdf_alignment_in_box(volume, points, association, align, backend), starts, norm, align,
                     solver, retry, std::forward<Judge>(judge), track, cache, prior);
}

/// track_in_volume for problems k = 0..n-1 at once (solved_in_batches):
/// terms[k] with norms[k] from starts[k], `judge(k, T, track)` judging each
/// solve. The starts are chosen from one batch of linearisations at the
/// coarsest level (agrees_at_least_as_well), the solves run as one
/// solve_coarse_to_fine_batch, and with `retry` the problems not `tracked`
/// that have a second start as another. Returns each problem's pose as
/// track_in_volume does and fills `tracks`. With `priors` (one per
/// problem), each solve is pulled towards its start (each prior's pose is
/// replaced by it).
template <class S, Backend B, class Volume, class Norm, class Judge>
  requires RobustNorm<Norm, S>
std::vector<SE3<S>> track_in_volumes(const B& backend, const std::vector<SdfAlignmentTerms<S, Volume>>& terms,
                                     const std::vector<Norm>& norms, const std::vector<PoseStarts<S>>& starts,
                                     const SdfAlignmentParams<S>& align, const LevenbergMarquardt& solver, bool retry,
                                     Judge&& judge, std::vector<PoseTrack>& tracks, BatchedSolveWorkspace<S, B>& ws,
                                     const std::vector<PosePrior<S>>* priors = nullptr) {
  using Terms = SdfAlignmentTerms<S, Volume>;
  const std::size_t n = terms.size();
  detail::require(!priors || priors->size() == n, "track_in_volumes", "need one prior per problem");
  std::vector<char> predicted_first(n, 0);
  std::vector<BatchedProblem<Terms, Norm>> checks;
  std::vector<LinearizationRequest<S>> requests;
  for (std::size_t k = 0; k < n; ++k) {
    if (!starts[k].predicted) continue;
    const Terms coarse = at_level(terms[k], align, align.pyramid_levels - 1);
    checks.push_back({coarse, norms[k]}), checks.push_back({coarse, norms[k]});
    LinearizationRequest<S> at_prediction, at_previous;
    at_prediction.T = *starts[k].predicted, at_prediction.reference = starts[k].previous;
    at_prediction.has_reference = at_prediction.active = 1;
    at_previous.T = at_previous.reference = starts[k].previous;
    at_previous.active = 1;
    requests.push_back(at_prediction), requests.push_back(at_previous);
  }
  if (!checks.empty()) {
    const std::vector<NormalEquations6> sums = linearize_batch(backend, checks, requests, ws);
    for (std::size_t k = 0, c = 0; k < n; ++k)
      if (starts[k].predicted) predicted_first[k] = agrees_at_least_as_well(sums[c], sums[c + 1]), c += 2;
  }
  // Solves problems `which`, each from its prediction where from_prediction(k).
  const auto solve = [&](const std::vector<std::size_t>& which, auto&& from_prediction, std::vector<PoseTrack>& t,
                         std::vector<SE3<S>>& T) {
    std::vector<Terms> some_terms;
    std::vector<Norm> some_norms;
    std::vector<SE3<S>> from;
    std::vector<PosePrior<S>> pulled;
    for (const std::size_t k : which) {
      t[k].from_prediction = from_prediction(k);
      some_terms.push_back(terms[k]), some_norms.push_back(norms[k]);
      from.push_back(t[k].from_prediction ? *starts[k].predicted : starts[k].previous);
      pulled.push_back((priors ? (*priors)[k] : PosePrior<S>{}).towards(from.back()));
    }
    std::vector<SolveReport> reports;
    const std::vector<SE3<S>> solved =
        solve_coarse_to_fine_batch(backend, some_terms, some_norms, align, solver, from, reports, ws, &pulled);
    for (std::size_t i = 0; i < which.size(); ++i) {
      const std::size_t k = which[i];
      t[k].report = reports[i], T[k] = solved[i];
      judge(k, T[k], t[k]);
    }
  };
  std::vector<std::size_t> all(n);
  for (std::size_t k = 0; k < n; ++k) all[k] = k;
  tracks.assign(n, PoseTrack{});
  std::vector<SE3<S>> T(n);
  solve(all, [&](std::size_t k) { return predicted_first[k] != 0; }, tracks, T);
  for (PoseTrack& t : tracks) t.attempts = 1;
  std::vector<std::size_t> again;
  for (std::size_t k = 0; k < n; ++k)
    if (retry && starts[k].predicted && tracks[k].outcome != TrackingOutcome::tracked) again.push_back(k);
  if (again.empty()) return T;
  std::vector<PoseTrack> second(n);
  std::vector<SE3<S>> T_second(n);
  solve(again, [&](std::size_t k) { return predicted_first[k] == 0; }, second, T_second);
  for (const std::size_t k : again) {
    if (second[k].outcome == TrackingOutcome::tracked) T[k] = T_second[k], tracks[k] = second[k];
    tracks[k].attempts = 2;
  }
  return T;
}

/// One problem as track_terms solves it, with the library's
/// LevenbergMarquardt (solved_in_batches) as a batch of one
/// (track_in_volumes, in `batch`): the same starts, retry and judgement,
/// and on a GPU the iterations without the host. Any other solver:
/// track_terms with `cache`.
template <class S, Backend B, class Volume, class Norm, class Solver, class Judge>
  requires RobustNorm<Norm, S> && PoseSolver<Solver, S>
SE3<S> track_one(const B& backend, const SdfAlignmentTerms<S, Volume>& terms, const PoseStarts<S>& starts,
                 const Norm& norm, const SdfAlignmentParams<S>& align, const Solver& solver, bool retry, Judge&& judge,
                 PoseTrack& track, BatchedSolveWorkspace<S, B>& batch, LinearizationCache<S, B>& cache) {
  if constexpr (solved_in_batches<Solver>) {
    std::vector<PoseTrack> tracks;
    const SE3<S> T = track_in_volumes(
        backend, std::vector{terms}, std::vector{norm}, std::vector{starts}, align, solver, retry,
        [&](std::size_t, const SE3<S>& T_vc, PoseTrack& t) { judge(T_vc, t); }, tracks, batch)[0];
    track = tracks[0];
    return T;
  } else {
    return track_terms(backend, terms, starts, norm, align, solver, retry, std::forward<Judge>(judge), track, cache);
  }
}

/// Moves map.T_world_camera to its constant-velocity prediction at
/// `timestamp` (when SystemParams::predict_motion is on and the last two
/// frames have poses), so that the E-step associates the frame there;
/// returns the starts for track_camera.
template <class S, Backend B>
PoseStarts<S> predict_camera(Map<S, B>& map, double timestamp, const SystemParams<S>& params) {
  PoseStarts<S> starts{map.T_world_camera, std::nullopt};
  const Trajectory& t = map.camera_trajectory;
  if (!params.predict_motion || t.size() < 2) return starts;
  const SE3<S> predicted =
      constant_velocity(t[t.size() - 2], t.back(), timestamp).template cast<S>();
  if (!is_finite(predicted)) return starts;
  starts.predicted = predicted;
  map.T_world_camera = predicted;
  return starts;
}

/// Moves every live object that was tracked in the last two frames to its
/// constant-velocity prediction at `timestamp` (when predict_motion is on,
/// else only the objects `partly_hidden` flags, one flag per live object),
/// for the E-step; returns the starts for track_objects, in Map::objects
/// order.
template <class S, Backend B>
std::vector<PoseStarts<S>> predict_objects(Map<S, B>& map, double timestamp, const SystemParams<S>& params,
                                           const std::vector<bool>* partly_hidden = nullptr) {
  detail::require(!partly_hidden || partly_hidden->size() == map.objects.size(), "predict_objects",
                  "need one partly_hidden flag per live object");
  std::vector<PoseStarts<S>> starts;
  const Trajectory& camera = map.camera_trajectory;
  for (auto& o : map.objects) {
    const bool predicted = params.predict_motion || (partly_hidden && (*partly_hidden)[starts.size()]);
    starts.push_back({o->pose(), std::nullopt});
    if (!predicted || camera.size() < 2) continue;
    const std::optional<SE3<double>> p = predict_pose(map.record_of(o->id()).trajectory,
                                                      camera[camera.size() - 2].timestamp, camera.back().timestamp,
                                                      timestamp);
    if (!p || !is_finite(p->template cast<S>())) continue;
    starts.back().predicted = p->template cast<S>();
    o->set_pose(*starts.back().predicted);
  }
  return starts;
}

/// Tracks the camera against the background with frame.points weighted by
/// frame.associations.image(0), from `starts` (predict_camera; without
/// them, from map.T_world_camera), with the camera's own alignment and
/// solver settings (camera_alignment_params, camera_solver); sets
/// map.T_world_camera to the solved pose when the outcome is `tracked`,
/// else to the previous pose. `norm` is in voxels of the background
/// (scaled_norm).
template <class S, Backend B, class Norm, class Solver>
  requires RobustNorm<Norm, S> && PoseSolver<Solver, S>
PoseTrack track_camera(Map<S, B>& map, const Frame<S, B>& frame, const SystemParams<S>& params, const Norm& norm,
                       const Solver& solver, TrackingWorkspace<S, B>* workspace = nullptr,
                       const PoseStarts<S>* starts = nullptr) {
  const PoseStarts<S> from = starts ? *starts : PoseStarts<S>{map.T_world_camera, std::nullopt};
  const SE3<S>& T_world_volume = map.background.pose();
  const SE3<S> T_volume_world = T_world_volume.inverse();
  PoseStarts<S> in_volume{T_volume_world * from.previous, std::nullopt};
  if (from.predicted) in_volume.predicted = T_volume_world * *from.predicted;
  const auto judge = [&](const SE3<S>& T_volume_camera, PoseTrack& t) {
    const SE3<S> T = T_world_volume * T_volume_camera;
    t.step = step_between(from.previous, T);
    t.outcome = tracking_outcome(t.report, double(params.min_camera_terms), T, t.step, params.max_camera_motion);
  };
  PoseTrack t;
  TrackingWorkspace<S, B> local;
  TrackingWorkspace<S, B>& ws = workspace ? *workspace : local;
  const auto align = camera_alignment_params(params, frame.points.width(), frame.points.height());
  const SE3<S> T_volume_camera = map.background.visit([&](const auto& background) {
    // The background's association is positive nearly everywhere: its box
    // would be the whole image, and finding it costs a reduction and, on a
    // GPU, a wait for the host. The terms are those of the box (the stride's
    // grid starts at the image's corner either way).
    const auto terms = sdf_alignment_in_box(background, frame.points, &frame.associations.image(0), align,
                                            PixelBox::whole(frame.points.width(), frame.points.height()));
    return track_one(background.backend(), terms, in_volume, scaled_norm(norm, background.voxel_size()), align,
                     camera_solver(solver, params), params.retry_tracking, judge, t, ws.camera_batch, ws.camera_cache);
  });
  map.T_world_camera = t.outcome == TrackingOutcome::tracked ? T_world_volume * T_volume_camera : from.previous;
  return t;
}

/// Tracks every live object with the camera at map.T_world_camera, object
/// k's terms weighted by frame.associations.image(k + 1), from `starts`
/// (predict_objects; without them, from the objects' poses); sets each
/// object's pose to the solved one when its outcome is `tracked`, else puts
/// back its previous pose (restore_pose). A solve refused by
/// max_object_motion is taken (`tracked`, PoseTrack::confirmed) when it
/// ends a run of params.confirm_jump_frames consecutive frames' refused
/// solves, each within the bound of the one before (the run lives in the
/// object's ObjectRecord). Returns one PoseTrack per object, in Map::objects
/// order. `norm` is in voxels of each object. With the library's
/// LevenbergMarquardt the objects are solved as one batch (track_in_volumes:
/// each iteration one pass over all their terms, and on CUDA no host in the
/// loop); with any other solver one after another, on CUDA from host threads
/// on streams of their own. The poses are applied afterwards in object order.
/// With `skip` (one flag per object), the objects flagged are not solved:
/// their tracks stay not_tracked, and their poses go back as for a solve
/// that was not (hold_decisions gives such flags).
template <class S, Backend B, class Norm, class Solver>
  requires RobustNorm<Norm, S> && PoseSolver<Solver, S>
std::vector<PoseTrack> track_objects(Map<S, B>& map, const Frame<S, B>& frame, const SystemParams<S>& params,
                                     const Norm& norm, const Solver& solver,
                                     TrackingWorkspace<S, B>* workspace = nullptr,
                                     const std::vector<PoseStarts<S>>* starts = nullptr,
                                     const std::vector<bool>* skip = nullptr) {
  const std::size_t n = map.objects.size();
  detail::require(!starts || starts->size() == n, "track_objects", "need one PoseStarts per live object");
  detail::require(!skip || skip->size() == n, "track_objects", "need one skip flag per live object");
  std::vector<std::size_t> solved;  // the objects solved, in object order
  for (std::size_t k = 0; k < n; ++k)
    if (!skip || !(*skip)[k]) solved.push_back(k);
  TrackingWorkspace<S, B> local;
  TrackingWorkspace<S, B>& ws = workspace ? *workspace : local;
  const SdfAlignmentParams<S> align = alignment_params(params, params.object_integration.max_weight);
  const B& backend = frame.points.backend();
  std::vector<PoseTrack> tracks(n);
  std::vector<SE3<S>> T_world_object(n);
  // The solver finds the camera in each object's volume: T_volume_camera of
  // a world pose T_world_object, and back.
  const auto in_volume = [&](std::size_t k, const SE3<S>& T_wo) {
    return (T_wo * map.objects[k]->T_object_volume()).inverse() * map.T_world_camera;
  };
  const auto to_world = [&](std::size_t k, const SE3<S>& T_vc) {
    return map.T_world_camera * T_vc.inverse() * map.objects[k]->T_object_volume().inverse();
  };
  // object_pose_prior: each solve pulled towards its start, measured at
  // the volume's centre and half its diagonal's share of an axis.
  const auto prior_of = [&](std::size_t k) {
    return PosePrior<S>::in_box(map.objects[k]->volume().view().extent(), params.object_pose_prior);
  };
  const auto volume_starts = [&](std::size_t k) {
    const PoseStarts<S> from = starts ? (*starts)[k] : PoseStarts<S>{map.objects[k]->pose(), std::nullopt};
    PoseStarts<S> in{in_volume(k, from.previous), std::nullopt};
    if (from.predicted) in.predicted = in_volume(k, *from.predicted);
    return std::pair{from, in};
  };
  // Refused solves that agree (SystemParams::confirm_jump_frames): the
  // run of them this frame's solve continues, and the pose it solved.
  std::vector<int> refused_run(n, 0);
  std::vector<SE3<S>> refused_pose(n);
  const auto judge = [&](std::size_t k, const PoseStarts<S>& from, const SE3<S>& T_volume_camera, PoseTrack& t) {
    const SE3<S> T = to_world(k, T_volume_camera);
    t.step = step_between(from.previous, T);
    t.outcome = tracking_outcome(t.report, double(params.min_object_terms), T, t.step, params.max_object_motion);
    t.confirmed = false;
    refused_run[k] = 0;
    if (t.outcome != TrackingOutcome::jump_rejected) return;
    const ObjectRecord& r = map.record_of(map.objects[k]->id());
    const PoseStep since = step_between(r.refused_pose, T.template cast<double>());
    const bool continues =
        r.refused_frame == map.frames - 1 && !params.max_object_motion.exceeded_by(since.translation, since.rotation);
    refused_run[k] = continues ? r.refused_run + 1 : 1;
    refused_pose[k] = T;
    if (params.confirm_jump_frames > 0 && refused_run[k] >= params.confirm_jump_frames) {
      t.outcome = TrackingOutcome::tracked;
      t.confirmed = true;
    }
  };
  if constexpr (solved_in_batches<Solver>) {
    using Terms = sdf_alignment_terms_t<S, TsdfVolume<S, B>>;
    const std::size_t m = solved.size();
    std::vector<Terms> terms;
    std::vector<decltype(scaled_norm(norm, S(1)))> norms;
    std::vector<PoseStarts<S>> from, in;
    std::vector<PosePrior<S>> priors;
    // Every object's box of associated pixels in one reduction (on a GPU
    // one wait, not one an object).
    std::vector<const Image<S, B>*> associations;
    for (std::size_t k : solved) associations.push_back(&frame.associations.image(int(k) + 1));
    const std::vector<PixelBox> boxes =
        align.use_association && m > 0 ? positive_boxes(backend, associations) : std::vector<PixelBox>(m);
    for (std::size_t j = 0; j < m; ++j) {
      const TsdfVolume<S, B>& volume = map.objects[solved[j]]->volume();
      terms.push_back(sdf_alignment_in_box(volume, frame.points, associations[j], align, boxes[j]));
      with_colour(terms.back(), *map.objects[solved[j]], frame, params);
      norms.push_back(scaled_norm(norm, volume.voxel_size()));
      const auto world_and_volume = volume_starts(solved[j]);
      from.push_back(world_and_volume.first), in.push_back(world_and_volume.second);
      priors.push_back(prior_of(solved[j]));
    }
    std::vector<PoseTrack> batch(m);
    const std::vector<SE3<S>> T_volume_camera =
        m == 0 ? std::vector<SE3<S>>{}
               : track_in_volumes(
                     backend, terms, norms, in, align, solver, params.retry_tracking,
                     [&](std::size_t j, const SE3<S>& T_vc, PoseTrack& t) { judge(solved[j], from[j], T_vc, t); },
                     batch, ws.object_batch, &priors);
    for (std::size_t j = 0; j < m; ++j) {
      tracks[solved[j]] = batch[j];
      if (batch[j].outcome == TrackingOutcome::tracked)
        T_world_object[solved[j]] = to_world(solved[j], T_volume_camera[j]);
    }
  } else {
    ws.object_caches.resize(n);
    const auto solve = [&](std::size_t k, const B& run_on) {
      // Not a structured binding: clang before 16 does not let lambdas capture one.
      const auto starts_k = volume_starts(k);
      const PoseStarts<S>& from = starts_k.first;
      const PoseStarts<S>& in = starts_k.second;
      const ObjectModel<S, B>& o = *map.objects[k];
      const PosePrior<S> prior = prior_of(k);
      const SE3<S> T_volume_camera = track_in_volume(
          o.volume(), frame.points, &frame.associations.image(int(k) + 1), in,
          scaled_norm(norm, o.volume().voxel_size()), align, solver, params.retry_tracking,
          [&](const SE3<S>& T_vc, PoseTrack& t) { judge(k, from, T_vc, t); }, tracks[k], ws.object_caches[k], run_on,
          &prior);
      if (tracks[k].outcome == TrackingOutcome::tracked) T_world_object[k] = to_world(k, T_volume_camera);
    };
    if (ConcurrentLanes<B>::concurrent && solved.size() > 1) {
      std::vector<B> lanes;
      for (std::size_t k : solved) lanes.push_back(ws.lanes.lane(k, backend));
      std::vector<std::future<void>> running;
      for (std::size_t j = 0; j < solved.size(); ++j)
        running.push_back(std::async(std::launch::async, solve, solved[j], lanes[j]));
      for (auto& r : running) r.get();  // rethrows a solve's exception here
    } else {
      for (std::size_t k : solved) solve(k, backend);
    }
  }
  for (std::size_t k = 0; k < n; ++k) {
    ObjectModel<S, B>& o = *map.objects[k];
    ObjectRecord& r = map.record_of(o.id());
    r.refused_run = tracks[k].outcome == TrackingOutcome::jump_rejected ? refused_run[k] : 0;
    if (r.refused_run > 0) {
      r.refused_frame = map.frames;
      r.refused_pose = refused_pose[k].template cast<double>();
    }
    if (tracks[k].outcome == TrackingOutcome::tracked) o.set_pose(T_world_object[k]);
    else if (starts && (*starts)[k].predicted) o.restore_pose((*starts)[k].previous);  // undo the prediction
  }
  return tracks;
}

}  // namespace emfusion
