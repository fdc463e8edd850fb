// The EM-Fusion system: background and object TSDFs, the E-step, direct SDF
// tracking of the camera and of every object, detection handling and
// association-weighted mapping, per frame as in DESIGN.md section 1:
//
//   1. preprocess: bilateral filter, back-projection;
//   2. E-step at the previous poses;
//   3. track the camera against the background, re-associate, track every
//      object; associate once more at the final poses (the mapping weights);
//   4. raycast every model (objects only where p_fg > 0.5, nearest wins);
//   5. on detector frames: match, existence, lost objects re-identified,
//      new objects, resizing;
//   6. integrate the frame into every model, weighted by its association;
//      update foreground counts from the matched detections;
//   7. delete objects that are unlikely, invisible or weakly associated
//      (invisible ones are kept as lost, for re-identification: an
//      extension of the paper, docs/system.md "Lost objects").
//
// Generic over the scalar and the backend; everything per pixel or voxel
// runs on the backend, detection handling (every 30th frame) on the host.
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <future>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include "emfusion/core/camera.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/core/timed_pose.hpp"
#include "emfusion/detect/detection.hpp"
#include "emfusion/detect/matching.hpp"
#include "emfusion/detect/proposal.hpp"
#include "emfusion/likelihood/e_step.hpp"
#include "emfusion/likelihood/measurement_likelihood.hpp"
#include "emfusion/preprocess/bilateral_filter.hpp"
#include "emfusion/preprocess/vertex_map.hpp"
#include "emfusion/robust/norms.hpp"
#include "emfusion/slam/object_model.hpp"
#include "emfusion/slam/params.hpp"
#include "emfusion/solve/sdf_alignment.hpp"
#include "emfusion/volume/foreground.hpp"
#include "emfusion/volume/integrate.hpp"
#include "emfusion/volume/raycast.hpp"

namespace emfusion {

/// Milliseconds per stage of one frame (the stages of the header comment).
struct StageTimes {
  double preprocess = 0, e_step = 0, track_background = 0, track_objects = 0, raycast = 0, detections = 0,
         integrate = 0, foreground = 0, total = 0;
};

/// Why an object left the map.
enum class DeletionReason { none, existence, not_visible, weak_association };

inline const char* to_string(DeletionReason r) {
  switch (r) {
    case DeletionReason::none: return "none";
    case DeletionReason::existence: return "existence";
    case DeletionReason::not_visible: return "not_visible";
    case DeletionReason::weak_association: return "weak_association";
  }
  return "unknown";
}

/// Everything known about an object ever created, kept after deletion.
struct ObjectRecord {
  int id = 0;
  std::string class_name;
  double first_timestamp = 0, last_timestamp = 0;
  bool deleted = false;
  DeletionReason reason = DeletionReason::none;
  bool person = false;     ///< class person with ignore_person: not rendered or exported
  Trajectory trajectory;   ///< T_world_object per frame it existed
};

/// What tracking did with a pose in one frame: the camera's
/// (FrameResult::camera_tracking) or an object's (ObjectStatus::tracking).
/// Every outcome but `tracked` leaves the previous pose in place.
enum class TrackingOutcome {
  /// No solve: a frame before or starting the map, an object created this
  /// frame, or the objects of a frame whose camera was not tracked.
  not_tracked,
  tracked,        ///< the solved pose was accepted
  too_few_terms,  ///< too few measurements met the model (no valid depth, out of view, outside the volume)
  solve_failed,   ///< no solution: non-finite or singular normal equations, or a non-finite pose
  jump_rejected,  ///< moved further than the per-frame bound (max_camera_motion, max_object_motion)
};

inline const char* to_string(TrackingOutcome t) {
  switch (t) {
    case TrackingOutcome::not_tracked: return "not_tracked";
    case TrackingOutcome::tracked: return "tracked";
    case TrackingOutcome::too_few_terms: return "too_few_terms";
    case TrackingOutcome::solve_failed: return "solve_failed";
    case TrackingOutcome::jump_rejected: return "jump_rejected";
  }
  return "unknown";
}

/// How far a solve moved a pose from the previous frame's, whether or not
/// the move was accepted.
struct PoseStep {
  double translation = 0;  ///< metres
  double rotation = 0;     ///< radians
};

/// The pixels of the depth image a frame received, by kind. Only `valid`
/// pixels are measurements; every other kind is treated as a hole (0).
struct DepthCounts {
  int valid = 0;         ///< finite, positive and within SystemParams::max_depth
  int missing = 0;       ///< 0: no measurement
  int not_finite = 0;    ///< NaN, +inf or -inf
  int negative = 0;      ///< finite and below 0
  int beyond_range = 0;  ///< finite and beyond SystemParams::max_depth (when it is set)
  EMF_HD DepthCounts operator+(const DepthCounts& o) const {
    return {valid + o.valid, missing + o.missing, not_finite + o.not_finite, negative + o.negative,
            beyond_range + o.beyond_range};
  }
};

/// What the deletion rules saw of one object in a frame, and what tracking did with it.
struct ObjectStatus {
  int id = 0;
  TrackingOutcome tracking = TrackingOutcome::not_tracked;
  PoseStep step;                  ///< the motion its solve proposed (world frame, object origin)
  int rendered_pixels = 0;        ///< rendered pixels inside the visibility border
  int associated_pixels = 0;      ///< pixels inside the border whose association to it exceeds 0.5
  int visible_pixels = 0;         ///< the larger of the two: what the visibility rule compares
  double mean_association = 1.0;  ///< mean association over its rendered pixels (1 when not computed)
  DeletionReason deleted = DeletionReason::none;
};

/// What happened in one frame.
struct FrameResult {
  int frame = 0;
  double timestamp = 0;
  DepthCounts depth;                    ///< the received depth's pixels by kind
  SolveReport camera;                   ///< background tracking (empty before the map starts)
  TrackingOutcome camera_tracking = TrackingOutcome::not_tracked;
  PoseStep camera_step;                 ///< the motion the camera's solve proposed (also when refused)
  /// The frame entered the map: integration, foreground counts, detection
  /// handling and the deletion rules ran. False when the camera was not
  /// tracked, or before the map started (the first frame with at least
  /// SystemParams::min_camera_terms valid depth pixels starts it).
  bool mapped = false;
  std::vector<SolveReport> objects;     ///< per live object tracked, in objects() order before changes
  bool detector_frame = false;          ///< the detector ran (its result is used only when `mapped`)
  int detections = 0, matched = 0;      ///< instances received; detections matched to objects
  int invalid_detections = 0;           ///< instances ignored: label outside 1..65535 or repeated, score not finite
  int detections_over_cap = 0;          ///< unmatched detections not considered: max_objects objects were live
  std::vector<int> created, deleted;    ///< object ids
  /// Lost objects (deleted as not visible) that a detection brought back,
  /// with their ids; they were in an earlier frame's `deleted`.
  std::vector<int> reidentified;
  std::vector<ObjectStatus> object_status;  ///< objects that existed before this frame, in objects() order
  int live_objects = 0;
  StageTimes times;
};

namespace detail::system {

/// The kind of each received depth pixel (DepthCounts).
template <class S>
struct ClassifyDepth {
  ImageView<const S> depth;
  S max_depth;  // 0: no limit
  EMF_HD DepthCounts operator()(int i) const {
    const S d = depth[i];
    DepthCounts c;
    if (d == S(0)) c.missing = 1;
    else if (!std::isfinite(d)) c.not_finite = 1;
    else if (d < S(0)) c.negative = 1;
    else if (max_depth > S(0) && d > max_depth) c.beyond_range = 1;
    else c.valid = 1;
    return c;
  }
};

struct AddDepthCounts {
  EMF_HD DepthCounts operator()(const DepthCounts& a, const DepthCounts& b) const { return a + b; }
};

/// Copies the measurements of a depth image and turns everything else
/// (non-finite, not positive, beyond max_depth) into holes.
template <class S>
struct SanitizeDepth {
  ImageView<const S> in;
  ImageView<S> out;
  S max_depth;  // 0: no limit
  EMF_HD void operator()(int i) const {
    const S d = in[i];
    out[i] = is_valid_depth(d) && (max_depth <= S(0) || d <= max_depth) ? d : S(0);
  }
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

/// Hands free heap memory back to the system. glibc keeps freed blocks
/// below its dynamic mmap threshold (which rises to the size of the largest
/// block freed, so object volumes land there) on its heap: without this a
/// CPU system's resident memory stays at the peak of the object volumes it
/// ever held (docs/system.md, "Memory bound"). A no-op with other C libraries.
inline void release_free_host_memory() {
#if defined(__GLIBC__)
  malloc_trim(0);
#endif
}

/// Keeps, per pixel, the nearest object surface of all objects raycast so far.
template <class S>
struct NearestObject {
  ImageView<const S> depth;
  ImageView<S> best_depth;
  ImageView<int> label;
  int model;
  EMF_HD void operator()(int i) const {
    const S d = depth[i];
    if (!(d > S(0))) return;
    if (best_depth[i] > S(0) && !(d < best_depth[i])) return;
    best_depth[i] = d;
    label[i] = model;
  }
};

/// Where the background's rays end: `margin` in front of the object drawn
/// at the pixel (nothing drawn or too near: 0, no ray).
template <class S>
struct BackgroundRayEnd {
  ImageView<const S> object_depth;
  ImageView<S> end;
  S margin;
  EMF_HD void operator()(int i) const {
    const S d = object_depth[i] - margin;
    end[i] = object_depth[i] > S(0) && d > S(0) ? d : S(0);
  }
};

/// The background wins a pixel where no object was drawn, or where the
/// object lies more than `margin` behind the background surface (rendered
/// only where objects were drawn). Pixels without an object are background
/// where the frame has a point, and nothing (-1) elsewhere.
template <class S>
struct ResolveBackground {
  ImageView<const S> background;  // empty when there are no objects
  ImageView<const S> object_depth;
  ImageView<int> label;
  S margin;
  ImageView<const Vec3<S>> points;
  EMF_HD void operator()(int i) const {
    if (label[i] > 0) {
      const S bg = background.empty() ? S(0) : background[i];
      if (bg > S(0) && object_depth[i] > bg + margin) label[i] = 0;
      return;
    }
    label[i] = is_valid(points[i]) ? 0 : -1;
  }
};

/// What the deletion rules count of one object over the image: its
/// rendered pixels, the association summed over them, and the pixels inside
/// the visibility border that it renders or that the E-step gives it (q > 0.5).
struct ObjectPixels {
  double association_sum = 0;
  int rendered = 0, rendered_inner = 0, associated_inner = 0;
  EMF_HD ObjectPixels operator+(const ObjectPixels& o) const {
    return {association_sum + o.association_sum, rendered + o.rendered, rendered_inner + o.rendered_inner,
            associated_inner + o.associated_inner};
  }
};

template <class S>
struct CountObjectPixels {
  ImageView<const int> label;
  ImageView<const S> association;  // empty: not computed this frame
  int model, border;
  EMF_HD ObjectPixels operator()(int i) const {
    const int u = i % label.width, v = i / label.width;
    const bool inner = u >= border && v >= border && u < label.width - border && v < label.height - border;
    const bool drawn = label[i] == model;
    const S q = association.empty() ? S(0) : association[i];
    ObjectPixels p;
    p.association_sum = drawn ? double(q) : 0.0;
    p.rendered = drawn ? 1 : 0;
    p.rendered_inner = drawn && inner ? 1 : 0;
    p.associated_inner = inner && q > S(0.5) ? 1 : 0;
    return p;
  }
};

struct AddObjectPixels {
  EMF_HD ObjectPixels operator()(const ObjectPixels& a, const ObjectPixels& b) const { return a + b; }
};

/// A "norm" whose cost counts residuals at least `delta` (weight 1): with
/// unit term weights, linearize() then returns the terms (NormalEquations6::terms)
/// and how many of them are off the surface (cost).
template <class S>
struct OffSurfaceCount {
  S delta;
  EMF_HD S cost(S r) const { return std::fabs(r) < delta ? S(0) : S(1); }
  EMF_HD S weight(S) const { return S(1); }
};

}  // namespace detail::system

template <class S, Backend B = Host>
class System {
 public:
  using Object = ObjectModel<S, B>;
  using Model = PaperLikelihood<S>;

  System(const PinholeCamera<S>& camera, const SystemParams<S>& params = {}, B backend = B{})
      : camera_(camera), params_(params), backend_(backend), background_(background_geometry(params), backend) {
    camera_.validate("System");  // the parameters were validated by background_geometry
  }

  /// Processes one depth frame (metres, camera size) with the detector's
  /// result for it, if the detector ran. Pixels that are 0, NaN, infinite,
  /// negative or beyond SystemParams::max_depth are holes. A frame whose
  /// camera cannot be tracked (too few terms, a failed solve, a jump beyond
  /// max_camera_motion) keeps the previous poses and is not mapped; the
  /// result says which (docs/system.md, "Hostile input").
  FrameResult process(const Image<S, B>& depth, double timestamp, const Detections* detections = nullptr) {
    detail::require_image(depth.view(), camera_.width, camera_.height, "System::process", "depth image");
    FrameResult result;
    result.frame = frame_;
    result.timestamp = timestamp;
    result.detector_frame = detections != nullptr;
    result.detections = detections ? int(detections->instances.size()) : 0;
    Clock clock(backend_);

    result.depth = sanitize_depth(depth);
    bilateral_filter(depth_, filtered_, params_.bilateral);
    back_project(filtered_, camera_, points_);
    result.times.preprocess = clock.lap();

    // Until a frame with enough depth has started the map there is nothing
    // to track against: such a frame is mapped at the current pose (the
    // first camera defines the world).
    const bool starts_map = !map_started_ && result.depth.valid >= std::max(params_.min_camera_terms, 1);
    object_tracks_.assign(objects_.size(), ObjectTrack{});
    if (map_started_) track(result, clock);
    result.mapped = starts_map || result.camera_tracking == TrackingOutcome::tracked;
    render_models();
    result.times.raycast = clock.lap();
    if (!result.mapped) {
      // Integrating a frame at a pose that is not its own would corrupt every
      // model; the detections and the deletion rules need that pose too.
      report_objects(result);
      record(timestamp);
      finish(result, clock);
      return result;
    }
    // Detection handling reads the segmentation on the host (detector
    // frames only); it does not change for the rest of the frame.
    const std::vector<int> seg = detections ? segmentation_.to_host() : std::vector<int>{};
    Detections checked;
    const Detections* det = detections ? usable_detections(*detections, checked, result) : nullptr;

    // Mapping weights of new objects: their detection masks.
    std::vector<NewObjectWeights> fresh;
    std::vector<int> matched_object_of_detection;
    if (det) handle_detections(*det, seg, result, fresh, matched_object_of_detection);
    result.times.detections = clock.lap();

    integrate_models(depth_, fresh, starts_map);
    map_started_ = true;
    result.times.integrate = clock.lap();
    if (det) update_foreground_counts(depth_, *det, seg, matched_object_of_detection, fresh);
    result.times.foreground = clock.lap();

    // Objects deleted now were tracked in this frame: its pose is the last
    // of their trajectories.
    record(timestamp);
    delete_objects(result, det != nullptr, int(fresh.size()), !starts_map);
    // Deleted and resized (detector frames) object volumes are freed memory
    // the C library may keep; on the CPU that is resident memory.
    if constexpr (!B::is_device)
      if (!result.deleted.empty() || det) detail::system::release_free_host_memory();
    finish(result, clock);
    return result;
  }

  const PinholeCamera<S>& camera() const { return camera_; }
  const SystemParams<S>& params() const { return params_; }
  /// Bytes of the models: the background volume and every live object's
  /// volume and foreground counts (on the backend's memory). The bound of
  /// docs/system.md, "Memory bound", is on this.
  std::size_t memory_bytes() const {
    std::size_t bytes = background_.memory_bytes();
    for (const auto& o : objects_) bytes += o->memory_bytes();
    for (const auto& l : lost_) bytes += l.object->memory_bytes();
    return bytes;
  }
  int frame_count() const { return frame_; }
  const SE3<S>& camera_pose() const { return T_world_camera_; }  ///< T_world_camera of the last frame
  const Trajectory& camera_trajectory() const { return camera_trajectory_; }
  const TsdfVolume<S, B>& background() const { return background_; }
  /// Live objects; association image k + 1 and segmentation label k + 1 are objects()[k].
  const std::vector<std::unique_ptr<Object>>& objects() const { return objects_; }
  /// Every object ever created, in creation order.
  const std::vector<ObjectRecord>& object_records() const { return records_; }
  /// The association images of the last frame: [0] background, [k + 1] objects()[k] (before deletions).
  const Associations<S, B>& associations() const { return associations_; }
  /// Per pixel: -1 no object drawn and no depth, 0 background, k + 1 objects()[k] (rendered at the final poses).
  const Image<int, B>& segmentation() const { return segmentation_; }
  /// The preprocessed frame as camera-frame points.
  const Image<Vec3<S>, B>& points() const { return points_; }

 private:
  struct Clock {
    using clock = std::chrono::steady_clock;
    explicit Clock(const B& b) : backend(b), start(clock::now()), last(start) {}
    double lap() {
      backend.synchronize();
      const auto now = clock::now();
      const double ms = std::chrono::duration<double, std::milli>(now - last).count();
      last = now;
      return ms;
    }
    double total() const { return std::chrono::duration<double, std::milli>(clock::now() - start).count(); }
    const B& backend;
    clock::time_point start, last;
  };
  struct ObjectTrack {
    TrackingOutcome outcome = TrackingOutcome::not_tracked;
    PoseStep step;
  };
  struct NewObjectWeights {
    Image<S, B> weights;              // 1 inside the usable mask, 0 elsewhere
    Image<std::uint8_t, B> mask;      // the same as bytes, for the foreground counts
    int detection = -1;
  };

  /// Validates the parameters first: the background is the first thing
  /// built from them (a member initializer, before the constructor's body).
  static VolumeGeometry<S> background_geometry(const SystemParams<S>& p) {
    p.validate();
    VolumeGeometry<S> g;
    g.dims = Vec3i{{p.background_voxels, p.background_voxels, p.background_voxels}};
    g.voxel_size = p.background_voxel_size;
    g.truncation = p.truncation_voxels * p.background_voxel_size;
    g.T_world_volume = volume_pose_in_front_of(SE3<S>::identity(), S(p.background_voxels) * p.background_voxel_size);
    return g;
  }

  // ---- Preprocessing -----------------------------------------------------

  /// Counts the received depth's pixels by kind and copies its measurements
  /// into depth_, holes everywhere else: nothing after this sees an invalid value.
  DepthCounts sanitize_depth(const Image<S, B>& depth) {
    if (!depth_.same_size(depth.width(), depth.height()))
      depth_ = Image<S, B>(depth.width(), depth.height(), S(0), backend_);
    const S max_depth = params_.max_depth;
    for_each_index(backend_, depth.size(), detail::system::SanitizeDepth<S>{depth.view(), depth_.view(), max_depth});
    return transform_reduce_index(backend_, depth.size(), detail::system::ClassifyDepth<S>{depth.view(), max_depth},
                                  DepthCounts{}, detail::system::AddDepthCounts{});
  }

  /// The detections without instances the system cannot use: a label
  /// outside 1..65535 (the label image's values) or one an earlier instance
  /// has, or a score that is not finite. Copies only when one is dropped.
  const Detections* usable_detections(const Detections& det, Detections& checked, FrameResult& result) const {
    std::vector<bool> taken(65536, false), keep(det.instances.size(), true);
    for (std::size_t d = 0; d < det.instances.size(); ++d) {
      const Instance& inst = det.instances[d];
      keep[d] = inst.label >= 1 && inst.label <= 65535 && std::isfinite(inst.score) && !taken[std::size_t(inst.label)];
      if (keep[d]) taken[std::size_t(inst.label)] = true;
      else ++result.invalid_detections;
    }
    if (result.invalid_detections == 0) return &det;
    checked.timestamp = det.timestamp;
    checked.labels = det.labels;
    for (std::size_t d = 0; d < det.instances.size(); ++d)
      if (keep[d]) checked.instances.push_back(det.instances[d]);
    return &checked;
  }

  // ---- E-step ------------------------------------------------------------

  Model model_of(const TsdfVolume<S, B>& volume, const ForegroundCounts<S, B>* fg) const {
    Model m;
    m.volume = volume.view();
    if (fg) m.foreground = fg->view();
    m.params = params_.likelihood;
    return m;
  }

  /// Association images for the camera at T_world_camera_ and the objects at
  /// their current poses.
  void associate() {
    if (!params_.use_association) return foreground_weights();
    std::vector<Model> models;
    std::vector<SE3<S>> poses;
    models.push_back(model_of(background_, nullptr));
    poses.push_back(background_.pose().inverse() * T_world_camera_);
    for (const auto& o : objects_) {
      models.push_back(model_of(o->volume(), &o->foreground()));
      poses.push_back(o->volume().pose().inverse() * T_world_camera_);
    }
    e_step(backend_, points_, std::span<const Model>(models), std::span<const SE3<S>>(poses), associations_);
  }

  /// The ablation without association likelihoods (paper Table 3, Fig. 3):
  /// objects weight a pixel by the foreground probability of its point,
  /// the background takes every pixel with weight 1.
  void foreground_weights() {
    associations_.resize(int(objects_.size()) + 1, camera_.width, camera_.height, backend_);
    associations_.image(0).fill(S(1));
    for (std::size_t k = 0; k < objects_.size(); ++k) {
      const Object& o = *objects_[k];
      for_each_index(backend_, points_.size(),
                     detail::system::ForegroundWeight<S>{std::as_const(points_).view(), o.volume().view(), o.foreground().view(),
                                      o.volume().pose().inverse() * T_world_camera_,
                                      associations_.image(int(k) + 1).view()});
    }
  }

  const Image<S, B>* association_weights(int model) const { return &associations_.image(model); }

  // ---- Tracking ----------------------------------------------------------

  SdfAlignmentParams<S> alignment_params() const {
    SdfAlignmentParams<S> a;
    a.use_association = true;  // the weights are p_fg in the ablation without association
    a.use_map_confidence = params_.use_map_confidence;
    a.confidence_normalizer = params_.background_integration.max_weight;
    a.pixel_stride = params_.pixel_stride;
    a.depth_noise_reference = params_.depth_noise_reference;
    return a;
  }

  /// Tracks the camera, then (if it was tracked) every object; poses whose
  /// solve is refused stay where they were.
  void track(FrameResult& result, Clock& clock) {
    const SdfAlignmentParams<S> align = alignment_params();
    double e_ms = 0;
    associate();
    e_ms += clock.lap();
    const HuberNorm<S> bg_norm{params_.huber_voxels * background_.voxel_size()};
    const SE3<S> T_solved = align_to_volume(background_, points_, association_weights(0), T_world_camera_, bg_norm,
                                            align, params_.lm, &result.camera, &solve_cache_);
    result.camera_step = detail::system::step_between(T_world_camera_, T_solved);
    result.camera_tracking = detail::system::tracking_outcome(result.camera, double(params_.min_camera_terms), T_solved,
                                                              result.camera_step, params_.max_camera_motion);
    result.times.track_background = clock.lap();
    if (result.camera_tracking != TrackingOutcome::tracked) {
      result.times.e_step = e_ms;
      return;  // the associations stay those at the previous poses
    }
    T_world_camera_ = T_solved;
    if (!objects_.empty()) {
      associate();
      e_ms += clock.lap();
      SdfAlignmentParams<S> obj_align = align;
      obj_align.confidence_normalizer = params_.object_integration.max_weight;
      // Each object's solve is independent of the others': on CUDA they run
      // from host threads on streams of their own, so that their small
      // kernels and the host's LM steps overlap.
      const std::size_t n = objects_.size();
      object_caches_.resize(n);
      std::vector<SolveReport> reports(n);
      std::vector<SE3<S>> T_volume_camera(n);
      const auto solve = [&](std::size_t k, const B& run_on) {
        const Object& o = *objects_[k];
        const HuberNorm<S> norm{params_.huber_voxels * o.volume().voxel_size()};
        // The object starts where it was; the solver finds how it moved
        // relative to the camera.
        T_volume_camera[k] = align_in_volume(o.volume(), points_, association_weights(int(k) + 1),
                                             o.volume().pose().inverse() * T_world_camera_, norm, obj_align,
                                             params_.lm, &reports[k], &object_caches_[k], &run_on);
      };
      if (ConcurrentLanes<B>::concurrent && n > 1) {
        std::vector<B> lanes;
        for (std::size_t k = 0; k < n; ++k) lanes.push_back(lanes_.lane(k, backend_));
        std::vector<std::future<void>> running;
        for (std::size_t k = 0; k < n; ++k) running.push_back(std::async(std::launch::async, solve, k, lanes[k]));
        for (auto& r : running) r.get();  // rethrows a solve's exception here
      } else {
        for (std::size_t k = 0; k < n; ++k) solve(k, backend_);
      }
      for (std::size_t k = 0; k < n; ++k) {
        Object& o = *objects_[k];
        const SE3<S> T_world_object = T_world_camera_ * T_volume_camera[k].inverse() * o.T_object_volume().inverse();
        ObjectTrack& t = object_tracks_[k];
        t.step = detail::system::step_between(o.pose(), T_world_object);
        t.outcome = detail::system::tracking_outcome(reports[k], double(params_.min_object_terms), T_world_object,
                                                     t.step, params_.max_object_motion);
        if (t.outcome == TrackingOutcome::tracked) o.set_pose(T_world_object);
        result.objects.push_back(reports[k]);
      }
      result.times.track_objects = clock.lap();
    }
    associate();
    e_ms += clock.lap();
    result.times.e_step = e_ms;
  }

  // ---- Rendering ---------------------------------------------------------

  void render_models() {
    RaycastParams<S> rp;
    rp.min_foreground = params_.min_foreground;
    const int w = camera_.width, h = camera_.height;
    if (!segmentation_.same_size(w, h)) {
      segmentation_ = Image<int, B>(w, h, -1, backend_);
      object_depth_ = Image<S, B>(w, h, S(0), backend_);
    }
    // Nearest object per pixel first; then the background, rendered only
    // where an object was drawn (elsewhere nothing competes with it) and
    // only up to the depth where it would lose.
    object_depth_.fill(S(0));
    segmentation_.fill(-1);
    for (std::size_t k = 0; k < objects_.size(); ++k) {
      Object& o = *objects_[k];
      if (is_person(o)) continue;
      raycast(o.volume(), camera_, T_world_camera_, o.rendering(), rp, &o.foreground());
      for_each_index(backend_, w * h,
                     detail::system::NearestObject<S>{std::as_const(o).rendering().depth.view(), object_depth_.view(),
                                   segmentation_.view(), int(k) + 1});
    }
    if (!objects_.empty()) {
      // The background wins only in front of object depth - margin: its
      // rays stop there.
      if (!background_ray_end_.same_size(w, h)) background_ray_end_ = Image<S, B>(w, h, S(0), backend_);
      for_each_index(backend_, w * h,
                     detail::system::BackgroundRayEnd<S>{std::as_const(object_depth_).view(),
                                                         background_ray_end_.view(), params_.occlusion_margin});
      raycast(background_, camera_, T_world_camera_, background_render_, rp,
              static_cast<const ForegroundCounts<S, B>*>(nullptr), &std::as_const(background_ray_end_));
    }
    const ImageView<const S> bg =
        objects_.empty() ? ImageView<const S>{} : std::as_const(background_render_).depth.view();
    for_each_index(backend_, w * h,
                   detail::system::ResolveBackground<S>{bg, std::as_const(object_depth_).view(), segmentation_.view(),
                                     params_.occlusion_margin, points_.view()});
  }

  /// Pixel thresholds are given for 640x480 images.
  int min_mask_pixels() const {
    return std::max(1, int(std::lround(double(params_.min_mask_pixels) * camera_.width * camera_.height / (640.0 * 480.0))));
  }
  int visibility_border() const { return int(std::lround(double(params_.visibility_border) * camera_.width / 640.0)); }

  bool is_person(const Object& o) const { return params_.ignore_person && o.class_name() == "person"; }

  // ---- Detections --------------------------------------------------------

  void handle_detections(const Detections& det, const std::vector<int>& seg, FrameResult& result,
                         std::vector<NewObjectWeights>& fresh, std::vector<int>& object_of_detection) {
    detail::require(det.labels.width() == camera_.width && det.labels.height() == camera_.height, "System::process",
                    "detection label image is " + std::to_string(det.labels.width()) + "x" +
                        std::to_string(det.labels.height()) + " but the camera is " + std::to_string(camera_.width) +
                        "x" + std::to_string(camera_.height));
    const DetectionMatch match =
        match_detections(mask_iou(det, seg, int(objects_.size())), params_.match_iou);
    object_of_detection = match.object_of;

    std::vector<bool> seen(objects_.size(), false);
    const std::vector<Vec3<S>> points = points_.to_host();
    const std::uint16_t* labels = det.labels.view().data;
    for (std::size_t d = 0; d < det.instances.size(); ++d) {
      const Instance& inst = det.instances[d];
      const int o = match.object_of[d];
      if (o < 0) continue;
      ++result.matched;
      seen[std::size_t(o)] = true;
      Object& obj = *objects_[std::size_t(o)];
      obj.add_class_score(inst.class_name, inst.score);
      grow_for_detection(obj, points, labels, inst.label);
    }
    for (std::size_t o = 0; o < objects_.size(); ++o) {
      if (seen[o])
        objects_[o]->count_detected();
      else
        objects_[o]->count_missed();
    }
    for (std::size_t d = 0; d < det.instances.size(); ++d) {
      if (match.object_of[d] >= 0) continue;
      if (std::optional<NewObjectWeights> w = reidentify(det, int(d), seg, points, result)) {
        fresh.push_back(std::move(*w));
        continue;
      }
      if (std::optional<NewObjectWeights> w = create_object(det, int(d), seg, points, result)) fresh.push_back(std::move(*w));
    }
  }

  /// Camera-frame points of a detection's pixels (without those of pixels
  /// another object covers, when `seg` is given).
  std::vector<Vec3<S>> detection_points(const std::vector<Vec3<S>>& points, const std::uint16_t* labels, int label,
                                        const std::vector<int>* seg = nullptr,
                                        int* covered = nullptr, int* total = nullptr) const {
    std::vector<Vec3<S>> out;
    for (std::size_t i = 0; i < points.size(); ++i) {
      if (labels[i] != label) continue;
      if (total) ++*total;
      if (seg && (*seg)[i] > 0) {
        if (covered) ++*covered;
        continue;
      }
      if (is_valid(points[i])) out.push_back(points[i]);
    }
    return out;
  }

  void grow_for_detection(Object& obj, const std::vector<Vec3<S>>& points, const std::uint16_t* labels, int label) {
    const SE3<S> T_volume_camera = obj.volume().pose().inverse() * T_world_camera_;
    std::vector<Vec3<S>> p =
        largest_depth_group(detection_points(points, labels, label), params_.object_depth_gap);
    if (int(p.size()) < min_mask_pixels()) return;
    for (Vec3<S>& x : p) x = T_volume_camera * x;
    const Box<S> box = percentile_box(p);
    // Grow to hold the detection's box with the same relative padding as a
    // new object would get around it, per axis.
    const S pad = S(0.5) * (params_.object_padding - S(1));
    const Vec3<S> margin = vec3(pad * (box.hi.x() - box.lo.x()), pad * (box.hi.y() - box.lo.y()),
                                pad * (box.hi.z() - box.lo.z()));
    obj.grow_to_fit(box.lo - margin, box.hi + margin, params_.max_object_voxels);
  }

  std::optional<NewObjectWeights> create_object(const Detections& det, int d, const std::vector<int>& seg,
                                                 const std::vector<Vec3<S>>& points, FrameResult& result) {
    const Instance& inst = det.instances[std::size_t(d)];
    if (is_listed_class(inst.class_name, params_.static_classes)) return std::nullopt;
    if (int(objects_.size()) >= params_.max_objects) {
      ++result.detections_over_cap;
      return std::nullopt;
    }
    int covered = 0, total = 0;
    const std::uint16_t* labels = det.labels.view().data;
    const std::vector<Vec3<S>> p = largest_depth_group(
        detection_points(points, labels, inst.label, &seg, &covered, &total),
        params_.object_depth_gap);
    if (total == 0 || double(covered) >= params_.max_covered_fraction * double(total)) return std::nullopt;
    if (int(p.size()) < min_mask_pixels()) return std::nullopt;
    const Box<S> cube = padded_cube(percentile_box(p), params_.object_padding);
    const S side = cube.hi.x() - cube.lo.x();
    if (!(side > S(0)) || !(norm(cube.center()) <= params_.max_object_distance)) return std::nullopt;
    const SE3<S> T_world_center = T_world_camera_ * SE3<S>::translation(cube.center());
    const SE3<S> T_world_volume = T_world_center * SE3<S>::translation(Vec3<S>::constant(-side / S(2)));
    for (const auto& o : objects_) {
      const Vec3<S> ext = o->volume().view().extent();
      if (volume_iou(T_world_volume, Vec3<S>::constant(side), o->volume().pose(), ext) >= params_.max_volume_iou)
        return std::nullopt;
    }
    const int id = next_id_++;
    auto obj = std::make_unique<Object>(id, inst.class_name, T_world_center, params_.object_voxels,
                                        side / S(params_.object_voxels), params_.truncation_voxels, backend_);
    obj->add_class_score(inst.class_name, inst.score);
    NewObjectWeights w = first_view_weights(det, d, seg);
    ObjectRecord rec;
    rec.id = id;
    rec.class_name = inst.class_name;
    rec.person = is_person(*obj);
    records_.push_back(rec);
    objects_.push_back(std::move(obj));
    result.created.push_back(id);
    return w;
  }

  /// Per pixel, 1 where detection d's mask is and no other object is drawn
  /// (`seg`): the pixels that are the detection's own.
  std::vector<std::uint8_t> own_mask(const Detections& det, int d, const std::vector<int>& seg) const {
    const std::uint16_t* labels = det.labels.view().data;
    const int label = det.instances[std::size_t(d)].label;
    std::vector<std::uint8_t> mask(seg.size(), 0);
    for (std::size_t i = 0; i < seg.size(); ++i) mask[i] = labels[i] == label && !(seg[i] > 0);
    return mask;
  }

  /// The mapping weights of an object's first frame (new or re-identified):
  /// 1 on the detection's own pixels, 0 on other objects' pixels.
  NewObjectWeights first_view_weights(const Detections& det, int d, const std::vector<int>& seg) const {
    NewObjectWeights w;
    w.detection = d;
    // Outside the mask a pixel gets the association the E-step would give a
    // model that does not explain it beside one that does, so that the
    // border of the first view is observed as on later frames.
    const S outside = unexplained_association();
    const std::vector<std::uint8_t> mask = own_mask(det, d, seg);
    std::vector<S> weights(seg.size(), S(0));
    for (std::size_t i = 0; i < seg.size(); ++i) weights[i] = mask[i] ? S(1) : seg[i] > 0 ? S(0) : outside;
    w.weights = Image<S, Host>::from_host(camera_.width, camera_.height, weights).template to<B>(backend_);
    w.mask = Image<std::uint8_t, Host>::from_host(camera_.width, camera_.height, mask).template to<B>(backend_);
    return w;
  }

  // ---- Lost objects --------------------------------------------------------

  /// Tries to bring back a lost object of the detection's class: each is
  /// aligned to the detection's points from its orientation when lost, its
  /// box centre placed at the points' centroid pushed back along the ray by
  /// 0, 1/16, 1/8 and 3/16 of the box side (the visible surface lies in
  /// front of the object's centre; an object fills about half its box); the
  /// best solve with at least reidentify_min_inliers of the points within a
  /// Huber delta of the surface wins. Returns its first-view weights.
  /// (docs/system.md, "Lost objects".)
  std::optional<NewObjectWeights> reidentify(const Detections& det, int d, const std::vector<int>& seg,
                                             const std::vector<Vec3<S>>& points, FrameResult& result) {
    if (lost_.empty() || int(objects_.size()) >= params_.max_objects) return std::nullopt;
    const Instance& inst = det.instances[std::size_t(d)];
    if (is_listed_class(inst.class_name, params_.static_classes)) return std::nullopt;
    const std::uint16_t* labels = det.labels.view().data;
    const std::vector<Vec3<S>> p = largest_depth_group(detection_points(points, labels, inst.label, &seg),
                                                       params_.object_depth_gap);
    if (int(p.size()) < min_mask_pixels()) return std::nullopt;
    Vec3<S> centroid = Vec3<S>::zero();
    for (const Vec3<S>& x : p) centroid = centroid + x;
    centroid = centroid / S(p.size());
    const Vec3<S> ray = normalized(centroid);
    // The detection's own pixels with weight 1.
    const std::vector<std::uint8_t> own = own_mask(det, d, seg);
    const std::vector<S> in_mask(own.begin(), own.end());
    const auto mask = Image<S, Host>::from_host(camera_.width, camera_.height, in_mask).template to<B>(backend_);

    SdfAlignmentParams<S> align = alignment_params();
    align.confidence_normalizer = params_.object_integration.max_weight;
    SdfAlignmentParams<S> count = align;
    count.use_map_confidence = false;
    int best = -1;
    double best_inliers = 0;
    SE3<S> best_T;
    for (std::size_t k = 0; k < lost_.size(); ++k) {
      const Object& o = *lost_[k].object;
      if (o.class_name() != inst.class_name) continue;
      const auto& volume = o.volume();
      const S delta = params_.huber_voxels * volume.voxel_size();
      const Vec3<S> centre = S(0.5) * volume.view().extent();
      const auto R = (volume.pose().inverse() * T_world_camera_).rotation();
      const S step = volume.view().extent().x() / S(16);
      for (int h = 0; h < 4; ++h) {
        const Vec3<S> at = centroid + (S(h) * step) * ray;
        const SE3<S> start(R, centre - R * at);
        SolveReport report;
        const SE3<S> T = align_in_volume(volume, points_, &mask, start, HuberNorm<S>{delta}, align, params_.lm, &report);
        if (!report.converged() || report.terms < double(params_.min_object_terms)) continue;
        const NormalEquations6 n = linearize(backend_, make_sdf_alignment(volume, points_, &mask, count),
                                             detail::system::OffSurfaceCount<S>{delta}, T);
        const double inliers = (n.terms - n.cost) / double(p.size());
        if (inliers > best_inliers) best = int(k), best_inliers = inliers, best_T = T;
      }
    }
    if (best < 0 || best_inliers < params_.reidentify_min_inliers) return std::nullopt;
    std::unique_ptr<Object> obj = std::move(lost_[std::size_t(best)].object);
    lost_.erase(lost_.begin() + best);
    obj->set_pose(T_world_camera_ * best_T.inverse() * obj->T_object_volume().inverse());
    obj->add_class_score(inst.class_name, inst.score);
    obj->count_detected();
    ObjectRecord& rec = record_of(obj->id());
    rec.deleted = false;
    rec.reason = DeletionReason::none;
    result.reidentified.push_back(obj->id());
    objects_.push_back(std::move(obj));
    return first_view_weights(det, d, seg);
  }

  /// Eq. 5 for a pixel that one model explains perfectly (sdf 0, p_fg 1)
  /// and another not at all (p_fg 0: the outlier term only): the second's share.
  S unexplained_association() const {
    const S explained = params_.likelihood.mixture(S(0), S(1)), unexplained = params_.likelihood.mixture(S(0), S(0));
    return unexplained / (explained + unexplained);
  }

  // ---- Mapping -----------------------------------------------------------

  /// `first`: the frame that starts the map, which has no association images.
  void integrate_models(const Image<S, B>& depth, const std::vector<NewObjectWeights>& fresh, bool first) {
    const std::size_t old_objects = objects_.size() - fresh.size();
    integrate(background_, depth, camera_, T_world_camera_, first ? nullptr : association_weights(0),
              params_.background_integration, &integration_workspace_);
    for (std::size_t k = 0; k < objects_.size(); ++k) {
      const Image<S, B>* weights =
          k < old_objects ? association_weights(int(k) + 1) : &fresh[k - old_objects].weights;
      integrate(objects_[k]->volume(), depth, camera_, T_world_camera_, weights, params_.object_integration,
                &integration_workspace_);
    }
  }

  /// Eq. 6 for every object a detection matched or created, where no other
  /// object covers the pixel.
  void update_foreground_counts(const Image<S, B>& depth, const Detections& det, const std::vector<int>& seg,
                                const std::vector<int>& object_of, const std::vector<NewObjectWeights>& fresh) {
    const std::size_t old_objects = objects_.size() - fresh.size();
    const std::uint16_t* labels = det.labels.view().data;
    const auto update = [&](Object& o, int model_label, const Image<std::uint8_t, B>& mask) {
      std::vector<std::uint8_t> counted(seg.size());
      for (std::size_t i = 0; i < seg.size(); ++i) counted[i] = !(seg[i] > 0 && seg[i] != model_label);
      const auto c = Image<std::uint8_t, Host>::from_host(camera_.width, camera_.height, counted).template to<B>(backend_);
      update_foreground(o.foreground(), o.volume().pose(), o.volume().truncation(), depth, mask, c, camera_,
                        T_world_camera_, backend_);
    };
    for (std::size_t d = 0; d < object_of.size(); ++d) {
      const int k = object_of[d];
      if (k < 0 || std::size_t(k) >= old_objects) continue;
      std::vector<std::uint8_t> mask(seg.size());
      for (std::size_t i = 0; i < seg.size(); ++i) mask[i] = labels[i] == det.instances[d].label;
      const auto m = Image<std::uint8_t, Host>::from_host(camera_.width, camera_.height, mask).template to<B>(backend_);
      update(*objects_[std::size_t(k)], k + 1, m);
    }
    for (std::size_t j = 0; j < fresh.size(); ++j)
      update(*objects_[old_objects + j], int(old_objects + j) + 1, fresh[j].mask);
  }

  // ---- Deletion ----------------------------------------------------------

  /// What tracking did with object k and what the deletion rules see of it
  /// (`associated`: the association images are this frame's).
  ObjectStatus object_status(int k, bool associated) const {
    const Object& o = *objects_[std::size_t(k)];
    const detail::system::ObjectPixels px = object_pixels(k);
    ObjectStatus status;
    status.id = o.id();
    if (std::size_t(k) < object_tracks_.size()) {
      status.tracking = object_tracks_[std::size_t(k)].outcome;
      status.step = object_tracks_[std::size_t(k)].step;
    }
    status.rendered_pixels = px.rendered_inner;
    status.associated_pixels = px.associated_inner;
    // Visible where the model is drawn or where the frame's points belong
    // to it: a model built from a few views renders a smaller mask than the
    // object shows (about 20 % on the dynamic sequences), the E-step sees
    // the measured object whole.
    status.visible_pixels = std::max(px.rendered_inner, px.associated_inner);
    if (!is_person(o) && associated) status.mean_association = px.rendered > 0 ? px.association_sum / px.rendered : 0.0;
    return status;
  }

  /// The statuses of a frame that is not mapped: no deletion rule runs (an
  /// empty or untracked frame says nothing about the objects).
  void report_objects(FrameResult& result) const {
    for (int k = 0; k < int(objects_.size()); ++k) result.object_status.push_back(object_status(k, false));
  }

  void finish(FrameResult& result, const Clock& clock) {
    result.live_objects = int(objects_.size());
    result.times.total = clock.total();
    ++frame_;
  }

  /// `tracked`: tracking ran this frame, so association images exist for
  /// every object that existed before it.
  void delete_objects(FrameResult& result, bool detector_frame, int created, bool tracked) {
    const int old_objects = int(objects_.size()) - created;
    // Grace lasts until the object is first seen or the detector runs again.
    if (detector_frame) young_.clear();
    const auto young = [&](int id) { return std::find(young_.begin(), young_.end(), id) != young_.end(); };
    std::vector<DeletionReason> why(objects_.size(), DeletionReason::none);
    const bool associated = params_.use_association && tracked;
    for (int k = 0; k < old_objects; ++k) {
      const Object& o = *objects_[std::size_t(k)];
      ObjectStatus status = object_status(k, associated);
      if (detector_frame && o.existence_probability() < params_.min_existence)
        why[std::size_t(k)] = DeletionReason::existence;
      else if (!is_person(o) && status.visible_pixels < min_mask_pixels() && !young(o.id()))
        why[std::size_t(k)] = DeletionReason::not_visible;
      if (status.visible_pixels >= min_mask_pixels()) std::erase(young_, o.id());
      else if (status.mean_association < params_.min_association)
        why[std::size_t(k)] = DeletionReason::weak_association;
      status.deleted = why[std::size_t(k)];
      result.object_status.push_back(status);
    }
    std::vector<std::unique_ptr<Object>> keep;
    for (std::size_t k = 0; k < objects_.size(); ++k) {
      if (why[k] == DeletionReason::none) {
        keep.push_back(std::move(objects_[k]));
        continue;
      }
      ObjectRecord& rec = record_of(objects_[k]->id());
      rec.deleted = true;
      rec.reason = why[k];
      result.deleted.push_back(objects_[k]->id());
      if (why[k] == DeletionReason::not_visible && params_.lost_object_frames > 0 && params_.max_lost_objects > 0)
        lost_.push_back(LostObject{std::move(objects_[k]), frame_});
    }
    objects_ = std::move(keep);
    // Lost objects are forgotten when too old, the oldest first beyond the cap.
    std::erase_if(lost_, [&](const LostObject& l) { return frame_ - l.lost_at > params_.lost_object_frames; });
    while (int(lost_.size()) > params_.max_lost_objects) lost_.erase(lost_.begin());
    if (detector_frame && params_.young_object_grace) {
      young_ = result.created;
      young_.insert(young_.end(), result.reidentified.begin(), result.reidentified.end());
    }
  }

  /// Object k's pixel counts (ObjectPixels), reduced on the backend.
  detail::system::ObjectPixels object_pixels(int k) const {
    const ImageView<const S> q =
        k + 1 < associations_.model_count() ? associations_.image(k + 1).view() : ImageView<const S>{};
    return transform_reduce_index(backend_, segmentation_.size(),
                                  detail::system::CountObjectPixels<S>{segmentation_.view(), q, k + 1,
                                                                       visibility_border()},
                                  detail::system::ObjectPixels{}, detail::system::AddObjectPixels{});
  }

  ObjectRecord& record_of(int id) {
    for (ObjectRecord& r : records_)
      if (r.id == id) return r;
    throw std::logic_error("System: no record for object " + std::to_string(id));
  }

  void record(double timestamp) {
    camera_trajectory_.push_back({timestamp, T_world_camera_.template cast<double>()});
    for (const auto& o : objects_) {
      ObjectRecord& r = record_of(o->id());
      if (r.trajectory.empty()) r.first_timestamp = timestamp;
      r.last_timestamp = timestamp;
      r.class_name = o->class_name();
      r.trajectory.push_back({timestamp, o->pose().template cast<double>()});
    }
  }

  PinholeCamera<S> camera_;
  SystemParams<S> params_;
  B backend_;
  TsdfVolume<S, B> background_;
  std::vector<std::unique_ptr<Object>> objects_;
  struct LostObject {
    std::unique_ptr<Object> object;
    int lost_at = 0;  ///< the frame it was deleted as not visible
  };
  std::vector<LostObject> lost_;  ///< oldest first
  std::vector<int> young_;        ///< ids created or re-identified on the last detector frame
  std::vector<ObjectRecord> records_;
  int next_id_ = 1;
  int frame_ = 0;
  bool map_started_ = false;  ///< a frame has been mapped
  std::vector<ObjectTrack> object_tracks_;  ///< this frame's, per object in objects() order
  SE3<S> T_world_camera_ = SE3<S>::identity();
  Trajectory camera_trajectory_;

  Image<S, B> depth_;  ///< the received depth with every invalid pixel a hole
  Image<S, B> filtered_;
  Image<Vec3<S>, B> points_;
  Associations<S, B> associations_;
  RaycastResult<S, B> background_render_;
  LinearizationCache<S, B> solve_cache_;                 ///< the camera solve's per-term buffers
  std::vector<LinearizationCache<S, B>> object_caches_;  ///< one per object solve (they may run at once)
  ConcurrentLanes<B> lanes_;                             ///< streams of the concurrent object solves
  IntegrationWorkspace<S, B> integration_workspace_;
  Image<S, B> object_depth_;
  Image<S, B> background_ray_end_;
  Image<int, B> segmentation_;
};

}  // namespace emfusion
