// Objects tracked back through the frames before they started (an extension
// of the paper; docs/system.md, "Tracked back"). An object is created on a
// detector frame and found again when a detection or the frame shows it;
// in the frames before, it was often in view already: a missed first
// detection puts its creation off by a whole detector period, and a lost
// object that came back into view waits for the next detection that finds
// it. The system keeps the last track_back_frames frames (FrameHistory:
// the filtered depth and the camera pose), and an object created or found
// again by a detection is aligned to them one after another, newest first,
// from the pose it has now; the poses found go into its trajectory in time
// order.
#pragma once

#include <algorithm>
#include <cstddef>
#include <deque>
#include <iterator>
#include <limits>
#include <optional>
#include <type_traits>
#include <vector>

#include <thrust/functional.h>

#include "emfusion/core/camera.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/likelihood/measurement_likelihood.hpp"
#include "emfusion/preprocess/vertex_map.hpp"
#include "emfusion/robust/norms.hpp"
#include "emfusion/slam/association.hpp"
#include "emfusion/slam/frame_result.hpp"
#include "emfusion/slam/map.hpp"
#include "emfusion/slam/motion_prediction.hpp"
#include "emfusion/slam/params.hpp"
#include "emfusion/slam/tracking.hpp"

namespace emfusion {

/// The last frames the map took in, oldest first: each one's filtered depth
/// (Frame::filtered), the camera's pose and the time. The system keeps
/// params.track_back_frames of them (a depth image each: 4 bytes a pixel
/// in float, 8 in double).
template <class S, Backend B>
struct FrameHistory {
  struct Kept {
    Image<S, B> filtered;
    SE3<S> T_world_camera;
    double timestamp = 0;
  };
  std::deque<Kept> frames;

  /// Keeps `filtered` with the camera at T_world_camera and `timestamp`,
  /// dropping the oldest frames beyond `capacity` (0: keeps none).
  void keep(const Image<S, B>& filtered, const SE3<S>& T_world_camera, double timestamp, int capacity) {
    if (capacity <= 0) return frames.clear();
    Kept kept;
    if (int(frames.size()) >= capacity) {  // the oldest's image is reused
      kept = std::move(frames.front());
      frames.pop_front();
    }
    kept.filtered = filtered;
    kept.T_world_camera = T_world_camera;
    kept.timestamp = timestamp;
    frames.push_back(std::move(kept));
    while (int(frames.size()) > capacity) frames.pop_front();
  }
};

/// What tracking back allocates, kept between calls (System keeps one): a
/// kept frame's points, the object's weights, and the solves' buffers (on
/// a GPU the graph of their iterations, built once).
template <class S, Backend B>
struct TrackBackWorkspace {
  Image<Vec3<S>, B> points;  ///< a kept frame's
  Image<S, B> share;         ///< the object's share of the E-step (object_share)
  Image<S, B> weights;       ///< the object's foreground probability (own_weights)
  TrackingWorkspace<S, B> solves;
  LinearizationCache<S, B> cache;  ///< a solver's other than LevenbergMarquardt
};

namespace detail::track_back {

/// The E-step's association of pixel i to one object beside the background
/// (EStepBackgroundPixel's image of the object: the same sums in the same
/// order), with the background's likelihood evaluated only where the
/// object's is positive: elsewhere the object's share is 0 either way, and
/// an object covers a small part of the frame.
template <class S, class MB, class M>
struct ObjectShare {
  ImageView<const Vec3<S>> points;
  MB background;
  SE3<S> T_background_camera;
  M object;
  SE3<S> T_volume_camera;
  ImageView<S> out;
  EMF_HD void operator()(int i) const {
    const Vec3<S> p = points[i];
    out[i] = S(0);
    if (!is_valid(p)) return;
    const S l = likelihood_of(object, T_volume_camera * p, p);
    if (!(l > S(0))) return;
    S total = S(0);
    total += likelihood_of(background, T_background_camera * p, p);
    total += l;
    out[i] = l * (S(1) / total);
  }
};

/// The object's image of the E-step with `background` (camera at
/// T_world_camera) and `object` alone (at T_volume_camera) for `points`,
/// into `share`: associate_with's image 1, without evaluating the
/// background where the object's likelihood is 0.
template <class S, Backend B, class Likelihood>
void object_share(const BackgroundVolume<S, B>& background, const SE3<S>& T_world_camera, const Likelihood& object,
                  const SE3<S>& T_volume_camera, const Image<Vec3<S>, B>& points, const Likelihood& likelihood,
                  Image<S, B>& share) {
  if (!share.same_size(points.width(), points.height()))
    share = Image<S, B>(points.width(), points.height(), S(0), points.backend());
  const SE3<S> T_background_camera = background.pose().inverse() * T_world_camera;
  visit_background_model(
      background, likelihood,
      [&](const auto& model) {
        for_each_index(points.backend(), points.size(),
                       ObjectShare<S, std::decay_t<decltype(model)>, Likelihood>{
                           points.view(), model, T_background_camera, object, T_volume_camera, share.view()});
      },
      "track_back");
}

/// 1 where pixel i, inside the visibility border, belongs to the object
/// (its weight, the foreground probability, above one half).
template <class S>
struct CountOwn {
  ImageView<const S> weights;
  int border;
  EMF_HD int operator()(int i) const { return weights.inside_border(i, border) && weights[i] > S(0.5) ? 1 : 0; }
};

/// How many pixels of `weights` inside `border` exceed one half.
template <class S, Backend B>
int count_own(const Image<S, B>& weights, int border) {
  return transform_reduce_index(weights.backend(), weights.size(), CountOwn<S>{weights.view(), border}, 0,
                                thrust::plus<int>());
}

/// The object's weights of each point of `points` with the object's volume
/// at T_volume_camera: its foreground probability where the point lies in
/// the volume, 0 elsewhere (association.hpp's ablation weights). Returns
/// how many of them, inside `border`, exceed one half.
template <class S, Backend B>
int own_weights(const ObjectModel<S, B>& o, const Image<Vec3<S>, B>& points, const SE3<S>& T_volume_camera, int border,
                Image<S, B>& weights) {
  const B& backend = points.backend();
  if (!weights.same_size(points.width(), points.height()))
    weights = Image<S, B>(points.width(), points.height(), S(0), backend);
  for_each_index(backend, points.size(),
                 detail::association::ForegroundWeight<S>{points.view(), o.volume().view(), o.foreground().view(),
                                                          T_volume_camera, weights.view()});
  return count_own(std::as_const(weights), border);
}

}  // namespace detail::track_back

/// Object `o` (live, at its pose of the frame just processed, `now`)
/// aligned to the frames of `history` newer than `since`, newest first: each
/// solve starts from the pose found in the frame after it or, where two
/// are found, from their constant-velocity motion carried on backwards
/// (track_one takes the start the frame agrees with better). The
/// weights are the E-step's with `background` and the object alone
/// (`likelihood`, the system's) where it gives the object at least
/// keep_mask_pixels of the frame inside the visibility border; where it
/// does not, and with params.use_association off (the paper's ablation,
/// as associate), the object's foreground probability: before the object
/// existed the background took its points in, and where it stood still
/// the background explains them as well as the object does. It stops at
/// the first frame where the solve is refused (tracking_outcome: too few
/// terms, no convergence, a move beyond max_object_motion) or fewer than
/// keep_mask_pixels of the frame's points inside the border have a
/// foreground probability above one half at the solved pose (it was not in
/// view, or hidden). Each solve is track_one's (with the library's
/// LevenbergMarquardt a batch of one: on a GPU without the host in its
/// iterations); `workspace` keeps what it allocates between calls.
/// Returns the poses (T_world_object) in time order, oldest first; `o`
/// keeps its pose.
template <class S, Backend B, class Likelihood, class Norm, class Solver>
  requires RobustNorm<Norm, S> && PoseSolver<Solver, S>
Trajectory track_back(const BackgroundVolume<S, B>& background, const ObjectModel<S, B>& o,
                      const FrameHistory<S, B>& history, double since, double now, const PinholeCamera<S>& camera,
                      const SystemParams<S>& params, const Likelihood& likelihood, const Norm& norm,
                      const Solver& solver, TrackBackWorkspace<S, B>* workspace = nullptr) {
  Trajectory back;  // newest first while it grows
  const B& backend = o.volume().backend();
  const SdfAlignmentParams<S> align = alignment_params(params, params.object_integration.max_weight);
  const auto scaled = scaled_norm(norm, o.volume().voxel_size());
  const int border = params.visibility_border_for(camera.width);
  const int min_pixels = params.keep_mask_pixels_for(camera.width, camera.height);
  // Through the const object, as associate binds the objects.
  const Likelihood model = bind_volume<S>(likelihood, o.volume().view(), o.foreground().view());
  TrackBackWorkspace<S, B> local;
  TrackBackWorkspace<S, B>& ws = workspace ? *workspace : local;
  Image<S, B>& weights = ws.weights;
  TimedPose later{now, o.pose().template cast<double>()};  // the pose of the frame after the one solved
  std::optional<TimedPose> latest;                         // ... and of the frame after that
  for (auto it = history.frames.rbegin(); it != history.frames.rend() && it->timestamp > since; ++it) {
    if (!it->filtered.same_size(camera.width, camera.height)) break;
    back_project(it->filtered, camera, ws.points);
    const Image<Vec3<S>, B>& points = ws.points;
    const SE3<S>& T_wc = it->T_world_camera;
    const auto in_volume = [&](const SE3<S>& T_wo) { return (T_wo * o.T_object_volume()).inverse() * T_wc; };
    const auto to_world = [&](const SE3<S>& T_vc) { return T_wc * T_vc.inverse() * o.T_object_volume().inverse(); };
    const SE3<S> previous = later.pose.template cast<S>();
    PoseStarts<S> starts{in_volume(previous), std::nullopt};
    if (latest) {
      // Backwards in time: the motion from `latest` to `later` goes on.
      const SE3<S> p =
          constant_velocity({-latest->timestamp, latest->pose}, {-later.timestamp, later.pose}, -it->timestamp)
              .template cast<S>();
      if (is_finite(p)) starts.predicted = in_volume(p);
    }
    // The weights: the E-step with the background and this object alone
    // where it gives the object enough of the frame, else (and always in
    // the ablation without association, as associate) the object's
    // foreground probability.
    const Image<S, B>* w = nullptr;
    if (params.use_association) {
      detail::track_back::object_share(background, T_wc, model, starts.previous, points, likelihood, ws.share);
      w = &std::as_const(ws.share);
    }
    if (!w || detail::track_back::count_own(*w, border) < min_pixels) {
      detail::track_back::own_weights(o, points, starts.previous, border, weights);
      w = &weights;
    }
    PoseTrack track;
    const SE3<S> T_vc = track_one(
        backend, sdf_alignment_in_box(o.volume(), points, w, align, backend), starts, scaled, align, solver,
        params.retry_tracking,
        [&](const SE3<S>& T, PoseTrack& t) {
          const SE3<S> T_wo = to_world(T);
          t.step = step_between(previous, T_wo);
          t.outcome =
              tracking_outcome(t.report, double(params.min_object_terms), T_wo, t.step, params.max_object_motion);
        },
        track, ws.solves.object_batch, ws.cache);
    if (track.outcome != TrackingOutcome::tracked) break;
    if (detail::track_back::own_weights(o, points, T_vc, border, weights) < min_pixels) break;
    latest = later;
    later = {it->timestamp, to_world(T_vc).template cast<double>()};
    back.push_back(later);
  }
  std::reverse(back.begin(), back.end());
  return back;
}

/// The stage after the rest of a mapped frame (params.track_back_frames >
/// 0): every object created this frame (result.created) or found again by
/// a detection (result.reidentified, FoundBy::detection) that is live and
/// not a person kept for association is tracked back (track_back) through
/// the kept frames after the last pose of its trajectory before this
/// frame, and the poses found are put into its ObjectRecord's trajectory
/// in time order (its first_timestamp moves back with them). Each object
/// tracked back at least one frame is added to result.tracked_back with
/// how many. `now`: this frame's time. Objects found again without a
/// detection are not: the refind rules look for them on every frame, and
/// are found on the first that shows enough of them; the frames before show
/// a part of them, where a fit is a guess (on c215-tab900 of
/// bench/generalisation.py a bottle found in what no model explained was
/// tracked back 10-28 cm off through the 13 frames before). `workspace`
/// (System keeps one) keeps what tracking back allocates between frames.
template <class S, Backend B, class Likelihood, class Norm, class Solver>
  requires RobustNorm<Norm, S> && PoseSolver<Solver, S>
void track_back_new_objects(Map<S, B>& map, const FrameHistory<S, B>& history, double now,
                            const PinholeCamera<S>& camera, const SystemParams<S>& params,
                            const Likelihood& likelihood, const Norm& norm, const Solver& solver, FrameResult& result,
                            TrackBackWorkspace<S, B>* workspace = nullptr) {
  if (params.track_back_frames <= 0 || history.frames.empty()) return;
  std::vector<int> ids = result.created;
  for (std::size_t k = 0; k < result.reidentified.size() && k < result.found_by.size(); ++k)
    if (result.found_by[k] == FoundBy::detection) ids.push_back(result.reidentified[k]);
  TrackBackWorkspace<S, B> local;
  TrackBackWorkspace<S, B>* ws = workspace ? workspace : &local;
  for (const auto& o : map.objects) {
    if (std::find(ids.begin(), ids.end(), o->id()) == ids.end() || params.ignores(o->class_name())) continue;
    ObjectRecord& record = map.record_of(o->id());
    // Its poses before this frame end where it was lost (none for a new one).
    const auto first_now = std::lower_bound(record.trajectory.begin(), record.trajectory.end(), now,
                                            [](const TimedPose& p, double t) { return p.timestamp < t; });
    const double since = first_now == record.trajectory.begin() ? -std::numeric_limits<double>::infinity()
                                                                : std::prev(first_now)->timestamp;
    const Trajectory back =
        track_back(map.background, *o, history, since, now, camera, params, likelihood, norm, solver, ws);
    if (back.empty()) continue;
    record.trajectory.insert(first_now, back.begin(), back.end());
    record.first_timestamp = record.trajectory.front().timestamp;
    result.tracked_back.push_back({o->id(), int(back.size())});
  }
}

}  // namespace emfusion
