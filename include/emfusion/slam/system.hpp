// The EM-Fusion system: a composition of the public stages of slam/, per
// frame as in DESIGN.md section 1 and the paper's overview:
//
//   1. preprocess: bilateral filter, back-projection    (preprocessing.hpp)
//   2. E-step at the previous poses                      (association.hpp)
//   3. track the camera against the background, re-associate, track every
//      object; associate once more at the final poses    (tracking.hpp)
//   4. raycast every model: the segmentation             (rendering.hpp)
//   5. on detector frames: match, existence, lost objects re-identified,
//      new objects, resizing                             (detection_handling.hpp)
//   6. integrate the frame into every model, weighted by its association
//      (while lost objects may come back, the background leaves out what
//      no model explains: unexplained.hpp); foreground counts from the
//      matched detections                                (mapping.hpp)
//   7. delete unlikely, invisible or weakly associated objects
//                                                        (lifecycle.hpp)
//   8. on detector frames: merge two models found to be one object
//                                                        (merging.hpp)
//   9. lost objects found again without a detection: where the frame shows
//      them where they were lost (reidentification.hpp), or in what no
//      model explains, between detector frames             (unexplained.hpp)
//  10. objects created or found by a detection tracked back through the last
//      frames, which the system keeps                      (track_back.hpp)
//
// The state is a Map (map.hpp) and the frame's images a Frame (frame.hpp);
// a user's own loop calls the same stages on its own Map and Frame
// (examples/own_em_loop.cpp). System is generic over the scalar, the
// backend and its exchangeable parts: the measurement likelihood of the
// E-step, the robust norms of the camera's and the objects' alignment and
// the solver, the paper's choices by default (examples/custom_likelihood.cpp
// plugs in its own).
#pragma once

#include <algorithm>
#include <concepts>
#include <cstdint>
#include <vector>

#include "emfusion/core/camera.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/stage_clock.hpp"
#include "emfusion/detect/detection.hpp"
#include "emfusion/likelihood/measurement_likelihood.hpp"
#include "emfusion/robust/norms.hpp"
#include "emfusion/slam/association.hpp"
#include "emfusion/slam/detection_handling.hpp"
#include "emfusion/slam/frame.hpp"
#include "emfusion/slam/frame_result.hpp"
#include "emfusion/slam/lifecycle.hpp"
#include "emfusion/slam/map.hpp"
#include "emfusion/slam/mapping.hpp"
#include "emfusion/slam/merging.hpp"
#include "emfusion/slam/params.hpp"
#include "emfusion/slam/preprocessing.hpp"
#include "emfusion/slam/rendering.hpp"
#include "emfusion/slam/track_back.hpp"
#include "emfusion/slam/tracking.hpp"
#include "emfusion/slam/unexplained.hpp"
#include "emfusion/solve/solvers.hpp"

namespace emfusion {

/// The exchangeable parts of the system. The norms are in voxels of the
/// volume each problem tracks (scaled_norm).
template <class Likelihood, class BackgroundNorm, class ObjectNorm, class Solver>
struct SystemParts {
  Likelihood likelihood{};          ///< E-step (eq. 5): a VolumeLikelihood
  BackgroundNorm background_norm{};  ///< camera tracking (eq. 8/9): a RobustNorm
  ObjectNorm object_norm{};          ///< object tracking and re-identification: a RobustNorm
  Solver solver{};                  ///< every pose solve: a PoseSolver
};

/// The parts of `params`: the paper's types (PaperLikelihood, HuberNorm,
/// LevenbergMarquardt) take their values from it; other types are
/// value-initialised (give them to System's constructor instead).
template <class Parts, class S>
Parts parts_from(const SystemParams<S>& params) {
  Parts parts{};
  if constexpr (std::same_as<decltype(parts.likelihood), PaperLikelihood<S>>) parts.likelihood.params = params.likelihood;
  if constexpr (std::same_as<decltype(parts.background_norm), HuberNorm<S>>) parts.background_norm.delta = params.huber_voxels;
  if constexpr (std::same_as<decltype(parts.object_norm), HuberNorm<S>>) parts.object_norm.delta = params.huber_voxels;
  if constexpr (std::same_as<decltype(parts.solver), LevenbergMarquardt>) parts.solver.params = params.lm;
  return parts;
}

template <class S, Backend B = Host, VolumeLikelihood<S> Likelihood = PaperLikelihood<S>,
          RobustNorm<S> BackgroundNorm = HuberNorm<S>, RobustNorm<S> ObjectNorm = HuberNorm<S>,
          PoseSolver<S> Solver = LevenbergMarquardt>
class System {
 public:
  using Object = ObjectModel<S, B>;
  using Parts = SystemParts<Likelihood, BackgroundNorm, ObjectNorm, Solver>;

  /// Throws std::invalid_argument on bad parameters or camera.
  System(const PinholeCamera<S>& camera, const SystemParams<S>& params = {}, B backend = B{})
      : System(camera, params, backend, parts_from<Parts>(params)) {}
  System(const PinholeCamera<S>& camera, const SystemParams<S>& params, B backend, const Parts& parts)
      : camera_(camera), params_(params), parts_(parts), backend_(backend), map_(params, backend) {
    camera_.validate("System");  // the parameters were validated by the map's background
    detail::association::require_sparse_capable<S, Likelihood>(params.sparse_background, "System");
  }

  /// Processes one depth frame (metres, camera size) with the detector's
  /// result for it, if the detector ran. Pixels that are 0, NaN, infinite,
  /// negative or beyond SystemParams::max_depth are holes. A frame whose
  /// camera cannot be tracked (too few terms, a failed solve, a jump beyond
  /// max_camera_motion) keeps the previous poses and is not mapped; the
  /// result says which (docs/system.md, "Hostile input"). `intensity`
  /// (optional): the frame's gray values in [0, 1] (intensity_image of its
  /// colour image, camera size), which the objects' colour takes when
  /// SystemParams::object_colour_weight is positive; otherwise unused.
  FrameResult process(const Image<S, B>& depth, double timestamp, const Detections* detections = nullptr,
                      const Image<S, B>* intensity = nullptr) {
    FrameResult result;
    result.frame = map_.frames;
    result.timestamp = timestamp;
    result.detector_frame = detections != nullptr;
    result.detections = detections ? int(detections->instances.size()) : 0;
    clock_.start(backend_);

    result.depth = preprocess(depth, camera_, params_, frame_);
    take_intensity(intensity);
    clock_.lap(result.times.preprocess);
    // Until a frame with enough depth has started the map there is nothing
    // to track against: that frame is mapped at the current pose (the
    // first camera defines the world).
    const bool starts_map = !map_.started && result.depth.valid >= std::max(params_.min_camera_terms, 1);
    frame_.object_tracks.assign(map_.objects.size(), PoseTrack{});
    if (map_.started) track(result, timestamp);
    result.mapped = starts_map || result.camera_tracking == TrackingOutcome::tracked;
    render_models(map_, frame_, camera_, params_, render_workspace_);
    clock_.lap(result.times.raycast);
    if (!result.mapped) {
      // Integrating a frame at a pose that is not its own would corrupt every
      // model; the detections and the deletion rules need that pose too.
      const int n = int(map_.objects.size());
      const std::vector<ObjectPixels> pixels = all_object_pixels(
          frame_, n, params_.visibility_border_for(frame_.segmentation.width()), object_pixels_workspace_);
      for (int k = 0; k < n; ++k)
        result.object_status.push_back(object_status(map_, frame_, k, false, params_, &pixels[std::size_t(k)]));
      map_.record_poses(timestamp);
      return finish(result);
    }
    // Detection handling reads the segmentation on the host (detector
    // frames only), and matches by it as the frame shows it; both change
    // only when objects are relocalized below.
    std::vector<int> seg = detections ? frame_.segmentation.to_host() : std::vector<int>{};
    std::vector<int> seen = detections ? seen_segmentation(frame_, params_, render_workspace_) : std::vector<int>{};
    Detections checked;
    const Detections* det = detections ? &usable_detections(*detections, checked, result) : nullptr;
    if (det) {
      // Objects left behind by their tracking move onto their detection
      // first (relocalize_below; 0 turns it off); the frame's E-step and
      // rendering are then redone at their new poses.
      result.relocalized =
          relocalize_objects(map_, frame_, *det, seg, camera_, params_, parts_.object_norm, parts_.solver, &seen);
      if (!result.relocalized.empty()) {
        associate(map_, frame_, parts_.likelihood, params_, true);  // only objects moved
        render_models(map_, frame_, camera_, params_, render_workspace_);
        seg = frame_.segmentation.to_host();
        seen = seen_segmentation(frame_, params_, render_workspace_);
      }
    }
    DetectionUpdate<S, B> update;
    if (det)
      update = handle_detections(map_, frame_, *det, seg, camera_, params_, parts_.likelihood, parts_.object_norm,
                                 parts_.solver, result, &seen);
    clock_.lap(result.times.detections);

    // While a lost object may come back as what no model explains, the
    // background does not take that in (hold_unexplained).
    const bool held = hold_unexplained(map_, frame_, params_, det != nullptr, held_background_weights_,
                                       &unexplained_.marks);
    integrate_models(map_, frame_, camera_, params_, update.fresh, starts_map,
                     held ? &held_background_weights_ : nullptr, &integration_workspace_, &sparse_workspace_,
                     &object_integration_workspace_);
    map_.started = true;
    clock_.lap(result.times.integrate);
    if (det) update_foreground_counts(map_, frame_, *det, seg, update.object_of_detection, update.fresh, camera_);
    clock_.lap(result.times.foreground);

    // Objects deleted now were tracked in this frame: its pose is the last
    // of their trajectories.
    map_.record_poses(timestamp);
    std::vector<int> ids_drawn;  // the objects the segmentation was rendered with (for merging)
    if (det)
      for (const auto& o : map_.objects) ids_drawn.push_back(o->id());
    delete_objects(map_, frame_, params_, result, det != nullptr, int(update.fresh.size()), !starts_map,
                   &object_pixels_workspace_);
    // Two models of one object (merge_min_inliers; 0 turns it off).
    if (det)
      result.merged = merge_objects(map_, frame_, *det, seg, update.object_of_detection, ids_drawn, camera_, params_,
                                    parts_.object_norm, parts_.solver);
    // Lost objects that the frame shows where they were lost come back
    // (refind_in_view).
    refind_in_view(map_, frame_, camera_, params_, result);
    // ... and those back in view elsewhere, in what no model explains
    // (refind_unexplained_every; 0 turns it off).
    refind_unexplained(map_, frame_, camera_, params_, parts_.object_norm, parts_.solver, result,
                       &unexplained_);
    // Objects created or found by a detection this frame, tracked back through
    // the frames kept (track_back_frames; 0 turns it off); then this frame
    // is kept.
    track_back_new_objects(map_, history_, timestamp, camera_, params_, parts_.likelihood, parts_.object_norm,
                           parts_.solver, result, &track_back_workspace_);
    history_.keep(frame_.filtered, map_.T_world_camera, timestamp, params_.track_back_frames);
    // Deleted and resized (detector frames) object volumes are freed memory
    // the C library may keep; on the CPU that is resident memory.
    if constexpr (!B::is_device)
      if (!result.deleted.empty() || det) release_free_host_memory();
    return finish(result);
  }

  /// Replaces the whole state with `map` (a loaded checkpoint,
  /// io/checkpoint.hpp): processing goes on from map.frames as if this
  /// system had built it. The map must have this system's background grid.
  void restore(Map<S, B>&& map) {
    detail::require(map.background.is_sparse() == params_.sparse_background &&
                        map.background.voxel_size() == params_.background_voxel_size,
                    "System::restore", "the map's background differs from the parameters' one (kind or voxel size)");
    if (const auto* dense = map.background.dense()) {
      const VolumeGeometry<S> want = background_geometry(params_);
      const Vec3i& d = dense->dims();
      detail::require(d[0] == want.dims[0] && d[1] == want.dims[1] && d[2] == want.dims[2], "System::restore",
                      "the map's background grid differs from the parameters' one");
    }
    map_ = std::move(map);
    unexplained_ = {};  // its groups are of the frames before
    history_ = {};      // ... and so are its frames
  }

  const PinholeCamera<S>& camera() const { return camera_; }
  const SystemParams<S>& params() const { return params_; }
  const Parts& parts() const { return parts_; }
  /// The whole state: models, poses, records (map.hpp).
  const Map<S, B>& map() const { return map_; }
  /// The last frame's images: points, associations, segmentation (frame.hpp).
  const Frame<S, B>& frame() const { return frame_; }

  /// Bytes of the models (Map::memory_bytes); the bound of docs/system.md,
  /// "Memory bound", is on this.
  std::size_t memory_bytes() const { return map_.memory_bytes(); }
  int frame_count() const { return map_.frames; }
  const SE3<S>& camera_pose() const { return map_.T_world_camera; }  ///< T_world_camera of the last frame
  const Trajectory& camera_trajectory() const { return map_.camera_trajectory; }
  /// The background volume, dense or sparse (BackgroundVolume::dense(), sparse(), visit()).
  const BackgroundVolume<S, B>& background() const { return map_.background; }
  /// Live objects; association image k + 1 and segmentation label k + 1 are objects()[k].
  const std::vector<std::unique_ptr<Object>>& objects() const { return map_.objects; }
  /// Every object ever created, in creation order.
  const std::vector<ObjectRecord>& object_records() const { return map_.records; }
  /// The association images of the last frame: [0] background, [k + 1] objects()[k] (before deletions).
  const Associations<S, B>& associations() const { return frame_.associations; }
  /// Per pixel: -1 no object drawn and no depth, 0 background, k + 1 objects()[k] (rendered at the final poses).
  const Image<int, B>& segmentation() const { return frame_.segmentation; }
  /// The preprocessed frame as camera-frame points.
  const Image<Vec3<S>, B>& points() const { return frame_.points; }

 private:
  /// Keeps the frame's gray values for the objects' colour, or none.
  void take_intensity(const Image<S, B>* intensity) {
    if (!params_.uses_colour() || !intensity) {
      frame_.intensity = Image<S, B>{};
      return;
    }
    detail::require_image(intensity->view(), camera_.width, camera_.height, "System::process", "intensity image");
    frame_.intensity = *intensity;
  }

  /// Stages 2 and 3: the E-step at the predicted camera pose (the previous
  /// one without motion prediction), the camera, then (if it was tracked)
  /// the E-step again at the objects' predicted poses and every object, and
  /// the E-step at the final poses, which mapping and the deletion rules use.
  void track(FrameResult& result, double timestamp) {
    const PoseStarts<S> camera_starts = predict_camera(map_, timestamp, params_);
    associate(map_, frame_, parts_.likelihood, params_);
    clock_.lap(result.times.e_step);
    const PoseTrack camera = track_camera(map_, frame_, params_, parts_.background_norm, parts_.solver,
                                          &tracking_workspace_, &camera_starts);
    result.camera = camera.report;
    result.camera_tracking = camera.outcome;
    result.camera_step = camera.step;
    clock_.lap(result.times.track_background);
    if (camera.outcome != TrackingOutcome::tracked) return;  // the associations stay those at the previous poses
    if (!map_.objects.empty()) {
      // Objects partly behind nearer surfaces are associated and solved
      // from their prediction; the same covers feed the hidden rule.
      const bool covers_needed = params_.hold_occluded_objects || params_.predict_hidden_share > S(0);
      const std::vector<detail::lifecycle::DrawnCover> covers =
          covers_needed ? drawn_covers(map_, frame_, params_, &drawn_cover_workspace_)
                        : std::vector<detail::lifecycle::DrawnCover>{};
      const std::vector<bool> hidden_in_part =
          covers_needed ? partly_hidden(covers, params_, frame_.points.width(), frame_.points.height())
                        : std::vector<bool>(map_.objects.size(), false);
      const std::vector<PoseStarts<S>> object_starts = predict_objects(map_, timestamp, params_, &hidden_in_part);
      associate(map_, frame_, parts_.likelihood, params_);
      clock_.lap(result.times.e_step);
      // Objects the frame does not show well enough are held, not solved.
      std::vector<SE3<S>> before;
      for (const PoseStarts<S>& s : object_starts) before.push_back(s.previous);
      const auto held = hold_decisions(map_, frame_, camera_, params_, before, timestamp, &object_pixels_workspace_,
                                       &drawn_cover_workspace_, covers_needed ? &covers : nullptr);
      std::vector<bool> skip;
      for (const auto& h : held) skip.push_back(h.has_value());
      frame_.object_tracks = track_objects(map_, frame_, params_, parts_.object_norm, parts_.solver,
                                           &tracking_workspace_, &object_starts, &skip);
      // Partly hidden objects whose solves slid where the frame sees
      // through them stay at their starts.
      keep_starts_seen_through(map_, frame_, camera_, params_, object_starts, hidden_in_part, frame_.object_tracks,
                               &drawn_cover_workspace_);
      apply_holds(map_, held, frame_.object_tracks);
      for (const PoseTrack& t : frame_.object_tracks) result.objects.push_back(t.report);
      clock_.lap(result.times.track_objects);
    }
    // Since the last E-step only objects moved (or, without objects, the
    // camera: then the background is evaluated again).
    associate(map_, frame_, parts_.likelihood, params_, true);
    clock_.lap(result.times.e_step);
  }

  FrameResult& finish(FrameResult& result) {
    result.live_objects = int(map_.objects.size());
    result.times.total = clock_.finish();
    ++map_.frames;
    return result;
  }

  PinholeCamera<S> camera_;
  SystemParams<S> params_;
  Parts parts_;
  B backend_;
  Map<S, B> map_;
  Frame<S, B> frame_;
  TrackingWorkspace<S, B> tracking_workspace_;
  RenderWorkspace<S, B> render_workspace_;
  IntegrationWorkspace<S, B> integration_workspace_;
  ObjectIntegrationWorkspace<S, B> object_integration_workspace_;
  ObjectPixelsWorkspace<S, B> object_pixels_workspace_;
  DrawnCoverWorkspace<S, B> drawn_cover_workspace_;
  UnexplainedWorkspace<S, B> unexplained_;  // hold_unexplained's and refind_unexplained's
  Image<S, B> held_background_weights_;     // hold_unexplained's
  SparseIntegrationWorkspace<S, B> sparse_workspace_;
  FrameHistory<S, B> history_;  // the frames objects are tracked back through
  TrackBackWorkspace<S, B> track_back_workspace_;
  /// The stage times of the frame being processed: on CUDA events queued at
  /// each stage's end and read once at its finish, so the device is not
  /// drained between stages to time them.
  StageClock<B> clock_;
};

}  // namespace emfusion
