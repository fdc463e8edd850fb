// What the system reports of one frame (FrameResult) and the small types it
// is made of: per-stage times, tracking outcomes, the received depth by kind,
// what the deletion rules saw of each object. Every stage fills its part;
// nothing here computes anything.
#pragma once

#include <vector>

#include "emfusion/core/host_device.hpp"
#include "emfusion/solve/solvers.hpp"

namespace emfusion {

/// Milliseconds per stage of one frame (the stages of slam/system.hpp),
/// measured by a StageClock (core/stage_clock.hpp): on CUDA the device's
/// progress from the end of one stage to the end of the next, read once at
/// the end of the frame, so that timing does not drain the device between
/// stages. `total` is the wall clock of System::process.
struct StageTimes {
  double preprocess = 0, e_step = 0, track_background = 0, track_objects = 0, raycast = 0, detections = 0,
         integrate = 0, foreground = 0, total = 0;
};

/// Why an object left the map.
enum class DeletionReason { none, existence, not_visible, weak_association, merged };

inline const char* to_string(DeletionReason r) {
  switch (r) {
    case DeletionReason::none: return "none";
    case DeletionReason::existence: return "existence";
    case DeletionReason::not_visible: return "not_visible";
    case DeletionReason::weak_association: return "weak_association";
    case DeletionReason::merged: return "merged";
  }
  return "unknown";
}

/// How a lost object was found again (FrameResult::found_by).
enum class FoundBy {
  detection,    ///< a detection matched no live object and its points fit the lost model (reidentify)
  in_view,      ///< the frame showed it where it was lost or where its motion took it (refind_in_view)
  unexplained,  ///< its model fit points that no live model explained (refind_unexplained)
};

inline const char* to_string(FoundBy b) {
  switch (b) {
    case FoundBy::detection: return "detection";
    case FoundBy::in_view: return "in_view";
    case FoundBy::unexplained: return "unexplained";
  }
  return "unknown";
}

/// What tracking did with a pose in one frame: the camera's
/// (FrameResult::camera_tracking) or an object's (ObjectStatus::tracking).
/// Every outcome but `tracked` and `moved_on` leaves the previous pose in place.
enum class TrackingOutcome {
  /// No solve (or its pose not taken): a frame before or starting the map,
  /// an object created this frame, the objects of a frame whose camera was
  /// not tracked, or a young object the image border cuts (SystemParams::hold_unseen_objects).
  not_tracked,
  tracked,        ///< the solved pose was accepted
  too_few_terms,  ///< too few measurements met the model (no valid depth, out of view, outside the volume)
  solve_failed,   ///< no solution: non-finite or singular normal equations, or a non-finite pose
  jump_rejected,  ///< moved further than the per-frame bound (max_camera_motion, max_object_motion)
  /// An object not solved: hidden behind a nearer surface, it moved on at
  /// its velocity (hold_occluded_objects; where it has none it stayed).
  moved_on,
};

inline const char* to_string(TrackingOutcome t) {
  switch (t) {
    case TrackingOutcome::not_tracked: return "not_tracked";
    case TrackingOutcome::tracked: return "tracked";
    case TrackingOutcome::too_few_terms: return "too_few_terms";
    case TrackingOutcome::solve_failed: return "solve_failed";
    case TrackingOutcome::jump_rejected: return "jump_rejected";
    case TrackingOutcome::moved_on: return "moved_on";
  }
  return "unknown";
}

/// How far a solve moved a pose from the previous frame's, whether or not
/// the move was accepted.
struct PoseStep {
  double translation = 0;  ///< metres
  double rotation = 0;     ///< radians
};

/// One pose's tracking in one frame: what the solve reported, what became
/// of its pose, and how far it proposed to move it.
struct PoseTrack {
  TrackingOutcome outcome = TrackingOutcome::not_tracked;
  PoseStep step;
  SolveReport report;
  bool from_prediction = false;  ///< the solve taken started at the motion prediction
  int attempts = 0;              ///< solves run: 2 when the first was not tracked and was retried
  /// Refused by the motion bound but taken: the last of
  /// SystemParams::confirm_jump_frames refused solves that agree.
  bool confirmed = false;
  /// Tracked, but at the pose its solve started from: the solved pose made
  /// the frame see through the model (keep_starts_seen_through,
  /// SystemParams::slide_seen_through_share).
  bool kept_start = false;
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
  bool from_prediction = false;   ///< the solve taken started at the motion prediction (PoseTrack)
  int attempts = 0;               ///< solves run (2: retried from the other start)
  bool confirmed = false;         ///< refused by the motion bound, taken as confirmed (PoseTrack)
  bool kept_start = false;        ///< left at its solve's start, the solved pose seen through (PoseTrack)
  int rendered_pixels = 0;        ///< rendered pixels inside the visibility border
  int associated_pixels = 0;      ///< pixels inside the border whose association to it exceeds 0.5
  int visible_pixels = 0;         ///< the larger of the two: what the visibility rule compares
  double mean_association = 1.0;  ///< mean association over its rendered pixels (1 when not computed)
  DeletionReason deleted = DeletionReason::none;
};

/// Two models found to be one object (slam/merging.hpp): `from` ended, its
/// model fused into `into`, which goes on with the older of the two ids.
struct ObjectMerge {
  int from = 0;
  int into = 0;
};

/// An object created or found again, tracked back through `frames` kept
/// frames before this one (slam/track_back.hpp).
struct TrackedBack {
  int id = 0;
  int frames = 0;
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
  std::vector<SolveReport> objects;     ///< per live object tracked, in Map::objects order before changes
  bool detector_frame = false;          ///< the detector ran (its result is used only when `mapped`)
  int detections = 0, matched = 0;      ///< instances received; detections matched to objects
  int invalid_detections = 0;           ///< instances ignored: label outside 1..65535 or repeated, score not finite
  int detections_over_cap = 0;          ///< unmatched detections not considered: max_objects objects were live
  /// Unmatched detections that made no new object because a lost object
  /// fitted them in depth but not in colour (reidentify_colour_agreement,
  /// once per loss: docs/system.md, "Lost objects").
  int held_for_colour = 0;
  std::vector<int> created, deleted;    ///< object ids
  /// Lost objects (deleted as not visible) found again, by id: a detection
  /// brought them back, or the frame showed them where they were lost
  /// (refind_in_view) or in what no live model explains
  /// (refind_unexplained); they were in an earlier frame's `deleted`.
  std::vector<int> reidentified;
  /// How each of `reidentified` was found, in the same order (found_again adds to both).
  std::vector<FoundBy> found_by;
  /// Live objects that tracking had left behind, moved onto a detection
  /// before detection handling (relocalize_below; docs/system.md).
  std::vector<int> relocalized;
  /// Objects found to be one (merge_min_inliers; docs/system.md, "Merging
  /// duplicates"): each `from` left the map (live or lost) and goes on as `into`.
  std::vector<ObjectMerge> merged;
  /// Objects created or found again this frame whose trajectories now also
  /// hold poses of frames before it (track_back_frames).
  std::vector<TrackedBack> tracked_back;
  std::vector<ObjectStatus> object_status;  ///< objects that existed before this frame, in Map::objects order
  int live_objects = 0;
  StageTimes times;

  /// Records that lost object `id` was found again, and how.
  void found_again(int id, FoundBy by) {
    reidentified.push_back(id);
    found_by.push_back(by);
  }
};

}  // namespace emfusion
