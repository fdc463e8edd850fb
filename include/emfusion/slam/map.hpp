// The state the EM-Fusion system estimates and carries from frame to frame:
// the background TSDF (dense or sparse, background.hpp), the live objects
// (ObjectModel: volume, foreground counts, pose, existence), the lost ones
// kept for re-identification, the camera pose, and the trajectories and
// records of everything so far. The stages (slam/*.hpp) read and write a Map
// they are handed; System owns one.
#pragma once

#include <algorithm>
#include <cstddef>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/core/timed_pose.hpp"
#include "emfusion/slam/background.hpp"
#include "emfusion/slam/frame_result.hpp"
#include "emfusion/slam/object_model.hpp"
#include "emfusion/slam/params.hpp"
#include "emfusion/volume/tsdf_volume.hpp"

namespace emfusion {

/// Everything known about an object ever created, kept after deletion.
struct ObjectRecord {
  int id = 0;
  std::string class_name;
  double first_timestamp = 0, last_timestamp = 0;
  bool deleted = false;
  DeletionReason reason = DeletionReason::none;
  bool person = false;     ///< class person with ignore_person: not rendered or exported
  Trajectory trajectory;   ///< T_world_object per frame it existed
  /// While it is held hidden behind others (hold_occluded_objects): the
  /// time of the last frame it was tracked in; NaN otherwise.
  double hidden_since = std::numeric_limits<double>::quiet_NaN();
  /// Its solves refused by the motion bound on consecutive frames, each
  /// within the bound of the one before (SystemParams::confirm_jump_frames):
  /// how many, the frame of the last, and the pose it solved (world).
  int refused_run = 0;
  int refused_frame = -1;
  SE3<double> refused_pose{};
};

/// An object deleted as not visible, kept for re-identification
/// (docs/system.md, "Lost objects"): neither tracked, rendered nor mapped.
template <class S, Backend B>
struct LostObject {
  std::unique_ptr<ObjectModel<S, B>> object;
  int lost_at = 0;  ///< the frame it was deleted as not visible
  /// A detection it fitted in depth but not in colour was kept from making
  /// a new object since it was lost (reidentify_colour_agreement; once per
  /// loss: detail::reidentification::hold_for_colour).
  bool held_detection = false;
};

template <class S, Backend B = Host>
struct Map {
  using Object = ObjectModel<S, B>;

  /// An empty map: the background of `params`, no objects, the camera at the identity.
  explicit Map(const SystemParams<S>& params, B backend = B{}) : background(params, backend) {}

  BackgroundVolume<S, B> background;  ///< dense or sparse (SystemParams::sparse_background)
  /// Live objects, in creation order; association image and segmentation
  /// label k + 1 of a frame are objects[k].
  std::vector<std::unique_ptr<Object>> objects;
  std::vector<LostObject<S, B>> lost;  ///< oldest first
  /// Ids created or re-identified on the last detector frame: spared the
  /// visibility rule until first seen (SystemParams::young_object_grace).
  std::vector<int> young;
  /// True if object `id` is among the young ones.
  bool is_young(int id) const { return std::find(young.begin(), young.end(), id) != young.end(); }
  std::vector<ObjectRecord> records;  ///< every object ever created, in creation order
  int next_id = 1;

  SE3<S> T_world_camera = SE3<S>::identity();  ///< the camera of the last frame
  Trajectory camera_trajectory;
  int frames = 0;        ///< frames processed
  bool started = false;  ///< a frame has been mapped (the first camera defines the world)

  ObjectRecord& record_of(int id) { return const_cast<ObjectRecord&>(std::as_const(*this).record_of(id)); }
  const ObjectRecord& record_of(int id) const {
    for (const ObjectRecord& r : records)
      if (r.id == id) return r;
    throw std::logic_error("Map: no record for object " + std::to_string(id));
  }
  /// Moves lost object k back among the live objects (its record no longer
  /// deleted) and returns it, now the last of `objects`.
  Object& bring_back(std::size_t k) {
    objects.push_back(std::move(lost.at(k).object));
    lost.erase(lost.begin() + std::ptrdiff_t(k));
    ObjectRecord& rec = record_of(objects.back()->id());
    rec.deleted = false;
    rec.reason = DeletionReason::none;
    rec.hidden_since = std::numeric_limits<double>::quiet_NaN();
    return *objects.back();
  }

  /// Bytes of the models on the backend: the background and every live and
  /// lost object's volume and foreground counts (docs/system.md, "Memory bound").
  std::size_t memory_bytes() const {
    std::size_t bytes = background.memory_bytes();
    for (const auto& o : objects) bytes += o->memory_bytes();
    for (const auto& l : lost) bytes += l.object->memory_bytes();
    return bytes;
  }

  /// Appends the frame's poses to the camera's and every live object's trajectory.
  void record_poses(double timestamp) {
    camera_trajectory.push_back({timestamp, T_world_camera.template cast<double>()});
    for (const auto& o : objects) {
      ObjectRecord& r = record_of(o->id());
      if (r.trajectory.empty()) r.first_timestamp = timestamp;
      r.last_timestamp = timestamp;
      r.class_name = o->class_name();
      r.trajectory.push_back({timestamp, o->pose().template cast<double>()});
    }
  }
};

}  // namespace emfusion
