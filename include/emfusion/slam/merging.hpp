// Two models found to be one object, merged (an extension of the paper;
// docs/system.md, "Merging duplicates"). When re-identification misses a
// lost object (it came back seen from a side its model lacks), the
// detection makes a second model of it; when tracking puts two models onto
// one object, both stay drawn there. Later, with more views, the detection
// that one of them matches fits the other too: then the older id goes on
// with both models fused, the other's trajectory ends, and its poses while
// the older one was lost are carried over, so that one object has one
// trajectory (merge_objects).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <utility>
#include <vector>

#include "emfusion/core/parallel.hpp"
#include "emfusion/detect/detection.hpp"
#include "emfusion/detect/proposal.hpp"
#include "emfusion/slam/frame.hpp"
#include "emfusion/slam/frame_result.hpp"
#include "emfusion/slam/map.hpp"
#include "emfusion/slam/reidentification.hpp"

namespace emfusion {

namespace detail::merging {

/// Fuses one voxel i of `into` with the other model: its SDF sampled
/// trilinearly at the voxel's centre (T_from_into maps into's volume frame
/// to from's) enters as one more measurement of eq. 10 weighted by its own
/// weight, capped at max_weight; the foreground counts of the other's voxel
/// there are added.
template <class S>
struct FuseVoxel {
  TsdfView<S, S> into;
  TsdfView<S, const S> from;
  ForegroundView<S, float> fg_into;
  ForegroundView<S, const float> fg_from;
  SE3<S> T_from_into;
  S max_weight;
  EMF_HD void operator()(std::int64_t i) const {
    const int x = int(i % into.nx), y = int((i / into.nx) % into.ny),
              z = int(i / (std::int64_t(into.nx) * into.ny));
    const Vec3<S> p = T_from_into * into.voxel_center(x, y, z);
    S d = S(0), w = S(0);
    if (from.sample(p, d, &w) && w > S(0)) {
      const S wi = S(into.weight[i]);
      into.sdf[i] = (wi * S(into.sdf[i]) + w * d) / (wi + w);
      into.weight[i] = wi + w < max_weight ? wi + w : max_weight;
    }
    const int fx = int(std::floor(p.x() / from.voxel_size)), fy = int(std::floor(p.y() / from.voxel_size)),
              fz = int(std::floor(p.z() / from.voxel_size));
    if (from.contains_voxel(fx, fy, fz)) {
      const std::int64_t j = from.index(fx, fy, fz);
      fg_into.fg[i] += fg_from.fg[j];
      fg_into.bg[i] += fg_from.bg[j];
    }
  }
};

}  // namespace detail::merging

/// Fuses model `from` into `into`, both at their current world poses:
/// `into` grows (up to max_voxels per axis, keeping its voxels) to hold
/// from's box, then every voxel of it takes from's SDF, weight (capped at
/// max_weight) and foreground counts where from has them; existence counts
/// and class scores are added. `from` is unchanged.
template <class S, Backend B>
void fuse_object_models(ObjectModel<S, B>& into, const ObjectModel<S, B>& from, int max_voxels, S max_weight) {
  const SE3<S> T_into_from = into.volume().pose().inverse() * from.volume().pose();
  const Vec3<S> e = from.volume().view().extent();
  Vec3<S> lo = Vec3<S>::constant(S(1e30)), hi = Vec3<S>::constant(S(-1e30));
  for (int c = 0; c < 8; ++c) {
    const Vec3<S> p = T_into_from * vec3((c & 1) ? e.x() : S(0), (c & 2) ? e.y() : S(0), (c & 4) ? e.z() : S(0));
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], p[a]), hi[a] = std::max(hi[a], p[a]);
  }
  into.grow_to_fit(lo, hi, max_voxels);
  detail::merging::FuseVoxel<S> f{into.volume().view(),
                                  from.volume().view(),
                                  into.foreground().view(),
                                  from.foreground().view(),
                                  from.volume().pose().inverse() * into.volume().pose(),
                                  max_weight};
  for_each_index(into.volume().backend(), into.volume().voxel_count(), f);
  into.add_counts_of(from);
}

namespace detail::merging {

/// Appends to `survivor`'s trajectory the poses of `other` after its last
/// one, moved into the survivor's object frame (T_other_survivor: the
/// survivor's object frame in the other's), so that the frames in which
/// only the other model was tracked are the survivor's too.
inline void carry_over_poses(ObjectRecord& survivor, const ObjectRecord& other, const SE3<double>& T_other_survivor) {
  const double after = survivor.trajectory.empty() ? -1e300 : survivor.trajectory.back().timestamp;
  for (const TimedPose& p : other.trajectory)
    if (p.timestamp > after) {
      if (survivor.trajectory.empty()) survivor.first_timestamp = p.timestamp;
      survivor.trajectory.push_back({p.timestamp, p.pose * T_other_survivor});
      survivor.last_timestamp = p.timestamp;
    }
}

/// The live object with this id, or null.
template <class S, Backend B>
ObjectModel<S, B>* live_object(Map<S, B>& map, int id) {
  for (auto& o : map.objects)
    if (o->id() == id) return o.get();
  return nullptr;
}

}  // namespace detail::merging

/// Stage 8 on a detector frame, after the deletion rules (an extension of
/// the paper; docs/system.md, "Merging duplicates"). With
/// params.merge_min_inliers > 0, for each detection d that matched a live
/// object B (`ids_drawn[object_of_detection[d]]`, the ids of the objects
/// `seg` was rendered with), the candidates for being B too are
///  - lost objects of B's class lost before B was created (two models alive
///    at once are two objects), and
///  - live objects of B's class that no detection matched whose world box
///    overlaps B's by at least max_volume_iou (two objects cannot fill the
///    same space);
/// each is aligned to d's points (B's pixels included) as re-identification
/// aligns (fit_to_target), and the best with at least merge_min_inliers of
/// the points on its surface that the frame shows there (best_shown_fit)
/// is merged with B: the older of the two ids
/// goes on at the pose the detection gives it, with the other's model fused
/// into its own (fuse_object_models); the other leaves the map (its record:
/// deleted, DeletionReason::merged) and its poses after the survivor's last
/// one are carried over to the survivor's trajectory. Call after
/// record_poses: this frame's pose of a merged object is its last.
/// Returns the merges, in the order made.
template <class S, Backend B, class Norm, class Solver>
  requires RobustNorm<Norm, S> && PoseSolver<Solver, S>
std::vector<ObjectMerge> merge_objects(Map<S, B>& map, const Frame<S, B>& frame, const Detections& det,
                                       const std::vector<int>& seg, const std::vector<int>& object_of_detection,
                                       const std::vector<int>& ids_drawn, const PinholeCamera<S>& camera,
                                       const SystemParams<S>& params, const Norm& norm, const Solver& solver) {
  std::vector<ObjectMerge> merges;
  if (!(params.merge_min_inliers > 0)) return merges;
  std::vector<int> matched_ids;
  for (int k : object_of_detection)
    if (k >= 0 && std::size_t(k) < ids_drawn.size()) matched_ids.push_back(ids_drawn[std::size_t(k)]);
  const auto is_matched = [&](int id) { return std::find(matched_ids.begin(), matched_ids.end(), id) != matched_ids.end(); };
  // A candidate: a lost object (lost >= 0, its index in map.lost) or a live one.
  struct Candidate {
    ObjectModel<S, B>* object;
    int lost;
  };
  std::optional<std::vector<Vec3<S>>> points;  // read on the host only when a detection has candidates
  for (std::size_t d = 0; d < det.instances.size() && d < object_of_detection.size(); ++d) {
    const int k = object_of_detection[d];
    if (k < 0 || std::size_t(k) >= ids_drawn.size()) continue;
    ObjectModel<S, B>* b = detail::merging::live_object(map, ids_drawn[std::size_t(k)]);
    if (!b || params.ignores(b->class_name())) continue;
    const ObjectRecord& b_record = map.record_of(b->id());
    std::vector<Candidate> candidates;
    for (std::size_t l = 0; l < map.lost.size(); ++l) {
      const ObjectModel<S, B>& a = *map.lost[l].object;
      if (a.class_name() == b->class_name() && map.record_of(a.id()).last_timestamp < b_record.first_timestamp)
        candidates.push_back({map.lost[l].object.get(), int(l)});
    }
    const Vec3<S> b_extent = b->volume().view().extent();
    for (auto& a : map.objects)
      if (a.get() != b && a->class_name() == b->class_name() && !is_matched(a->id()) &&
          volume_iou(a->volume().pose(), a->volume().view().extent(), b->volume().pose(), b_extent) >=
              params.max_volume_iou)
        candidates.push_back({a.get(), -1});
    if (candidates.empty()) continue;
    if (!points) points = frame.points.to_host();
    // The detection's points with B's own pixels counted as the detection's.
    std::vector<int> seg_without_b = seg;
    for (int& label : seg_without_b)
      if (label == k + 1) label = 0;
    const auto target =
        detail::reidentification::detection_target(frame, det, int(d), seg_without_b, *points, camera, params);
    if (!target) continue;
    std::vector<detail::reidentification::CandidateFit<S>> fits;
    for (std::size_t c = 0; c < candidates.size(); ++c) {
      const auto [inliers, T] = detail::reidentification::fit_to_target(*candidates[c].object, *target, frame,
                                                                         map.T_world_camera, params, norm, solver);
      fits.push_back({int(c), inliers, T});
    }
    const auto fit = detail::reidentification::best_shown_fit(
        std::move(fits), params.merge_min_inliers,
        [&](int c) -> const ObjectModel<S, B>& { return *candidates[std::size_t(c)].object; }, frame, target->mask,
        camera);
    if (!fit) continue;
    ObjectModel<S, B>& a = *candidates[std::size_t(fit->candidate)].object;
    const int lost_index = candidates[std::size_t(fit->candidate)].lost;
    // A's pose where the detection puts it; the survivor is the older id.
    detail::reidentification::move_to_fit(a, map.T_world_camera, *fit);
    const bool a_survives = a.id() < b->id();
    ObjectModel<S, B>& survivor = a_survives ? a : *b;
    const ObjectModel<S, B>& other = a_survives ? *b : a;
    fuse_object_models(survivor, other, params.max_object_voxels, params.object_integration.max_weight);
    ObjectRecord& s_record = map.record_of(survivor.id());
    ObjectRecord& o_record = map.record_of(other.id());
    const SE3<double> T_other_survivor = (other.pose().inverse() * survivor.pose()).template cast<double>();
    // This frame's pose of a live survivor is the one it has now.
    if (lost_index < 0 && !s_record.trajectory.empty() && !map.camera_trajectory.empty() &&
        s_record.trajectory.back().timestamp == map.camera_trajectory.back().timestamp)
      s_record.trajectory.back().pose = survivor.pose().template cast<double>();
    detail::merging::carry_over_poses(s_record, o_record, T_other_survivor);
    s_record.deleted = false;
    s_record.reason = DeletionReason::none;
    o_record.deleted = true;
    o_record.reason = DeletionReason::merged;
    merges.push_back({other.id(), survivor.id()});
    const int other_id = other.id();
    std::erase(map.young, other_id);
    if (lost_index >= 0) {
      // A was lost: it takes B's place among the live objects (B is the
      // newer: only objects lost before B was created are candidates).
      std::unique_ptr<ObjectModel<S, B>> back = std::move(map.lost[std::size_t(lost_index)].object);
      map.lost.erase(map.lost.begin() + lost_index);
      for (auto& o : map.objects)
        if (o.get() == b) o = std::move(back);
    } else {
      std::erase_if(map.objects, [&](const auto& o) { return o->id() == other_id; });
    }
  }
  return merges;
}

}  // namespace emfusion
