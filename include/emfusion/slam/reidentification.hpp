// Lost objects found again (an extension of the paper; docs/system.md,
// "Lost objects"): a detection that matches no live object is aligned to
// every lost object of its class, and the one on whose surface enough of the
// detection's points land returns to the map with its id and model, instead
// of a new object being made.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "emfusion/detect/detection.hpp"
#include "emfusion/detect/proposal.hpp"
#include "emfusion/robust/norms.hpp"
#include "emfusion/slam/association.hpp"
#include "emfusion/slam/detection_masks.hpp"
#include "emfusion/slam/frame.hpp"
#include "emfusion/slam/map.hpp"
#include "emfusion/slam/tracking.hpp"
#include "emfusion/solve/sdf_alignment.hpp"

namespace emfusion {

namespace detail::reidentification {

/// A "norm" whose cost counts residuals at least `delta` (weight 1): with
/// unit term weights, linearize() then returns the terms (NormalEquations6::terms)
/// and how many of them are off the surface (cost).
template <class S>
struct OffSurfaceCount {
  S delta;
  EMF_HD S cost(S r) const { return std::fabs(r) < delta ? S(0) : S(1); }
  EMF_HD S weight(S) const { return S(1); }
};

}  // namespace detail::reidentification

/// Tries to bring back a lost object of detection d's class: each is
/// aligned (`norm` in its voxels, `solver`) to the detection's points from
/// its orientation when lost, its box centre placed at the points' centroid
/// pushed back along the ray by 0, 1/16, 1/8 and 3/16 of the box side (the
/// visible surface lies in front of the object's centre; an object fills
/// about half its box); the best solve with at least
/// params.reidentify_min_inliers of the points within a Huber delta of the
/// surface wins. The object moves from map.lost back to map.objects at the
/// solved pose; returns its first-view weights (`outside`: see
/// first_view_weights). `seg` and `points` are the frame's segmentation and
/// points on the host.
template <class S, Backend B, class Norm, class Solver>
  requires RobustNorm<Norm, S> && PoseSolver<Solver, S>
std::optional<NewObjectWeights<S, B>> reidentify(Map<S, B>& map, const Frame<S, B>& frame, const Detections& det,
                                                 int d, const std::vector<int>& seg,
                                                 const std::vector<Vec3<S>>& points, const PinholeCamera<S>& camera,
                                                 const SystemParams<S>& params, const Norm& norm,
                                                 const Solver& solver, S outside) {
  if (map.lost.empty() || int(map.objects.size()) >= params.max_objects) return std::nullopt;
  const Instance& inst = det.instances[std::size_t(d)];
  if (is_listed_class(inst.class_name, params.static_classes)) return std::nullopt;
  const std::vector<Vec3<S>> p = largest_depth_group(detection_points(points, det.labels.view().data, inst.label, &seg),
                                                     params.object_depth_gap);
  if (int(p.size()) < params.min_mask_pixels_for(camera.width, camera.height)) return std::nullopt;
  Vec3<S> centroid = Vec3<S>::zero();
  for (const Vec3<S>& x : p) centroid = centroid + x;
  centroid = centroid / S(p.size());
  const Vec3<S> ray = normalized(centroid);
  // The detection's own pixels with weight 1.
  const B& backend = frame.points.backend();
  const std::vector<std::uint8_t> own = own_mask(det, d, seg);
  const std::vector<S> in_mask(own.begin(), own.end());
  const auto mask = Image<S, Host>::from_host(camera.width, camera.height, in_mask).template to<B>(backend);

  const SdfAlignmentParams<S> align = alignment_params(params, params.object_integration.max_weight);
  SdfAlignmentParams<S> count = align;
  count.use_map_confidence = false;
  int best = -1;
  double best_inliers = 0;
  SE3<S> best_T;
  for (std::size_t k = 0; k < map.lost.size(); ++k) {
    const ObjectModel<S, B>& o = *map.lost[k].object;
    if (o.class_name() != inst.class_name) continue;
    const auto& volume = o.volume();
    const S delta = params.huber_voxels * volume.voxel_size();
    const Vec3<S> centre = S(0.5) * volume.view().extent();
    const auto R = (volume.pose().inverse() * map.T_world_camera).rotation();
    const S step = volume.view().extent().x() / S(16);
    for (int h = 0; h < 4; ++h) {
      const Vec3<S> at = centroid + (S(h) * step) * ray;
      const SE3<S> start(R, centre - R * at);
      SolveReport report;
      const SE3<S> T = align_in_volume(volume, frame.points, &mask, start, scaled_norm(norm, volume.voxel_size()),
                                       align, solver, &report);
      if (!report.converged() || report.terms < double(params.min_object_terms)) continue;
      const NormalEquations6 n = linearize(backend, make_sdf_alignment(volume, frame.points, &mask, count),
                                           detail::reidentification::OffSurfaceCount<S>{delta}, T);
      const double inliers = (n.terms - n.cost) / double(p.size());
      if (inliers > best_inliers) best = int(k), best_inliers = inliers, best_T = T;
    }
  }
  if (best < 0 || best_inliers < params.reidentify_min_inliers) return std::nullopt;
  std::unique_ptr<ObjectModel<S, B>> obj = std::move(map.lost[std::size_t(best)].object);
  map.lost.erase(map.lost.begin() + best);
  obj->set_pose(map.T_world_camera * best_T.inverse() * obj->T_object_volume().inverse());
  obj->add_class_score(inst.class_name, inst.score);
  obj->count_detected();
  ObjectRecord& rec = map.record_of(obj->id());
  rec.deleted = false;
  rec.reason = DeletionReason::none;
  map.objects.push_back(std::move(obj));
  return first_view_weights(det, d, seg, outside, camera, backend);
}

}  // namespace emfusion
