// Stage 5 of the EM-Fusion frame, on frames with a detector result (paper
// sec. 3.5): detections are matched to the rendered object masks by IoU;
// matched objects count an existence, the others a miss where they are
// visible; a matched
// detection that overflows its object's volume grows it; an unmatched one
// first tries to bring back a lost object (reidentification.hpp) and else
// creates an object (10th-90th percentile box, padding, 64^3 voxels, within
// 5 m, volumetric IoU with every other object below 0.5, at least 40x40
// pixels of its own, never of a static class).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "emfusion/core/error.hpp"
#include "emfusion/detect/detection.hpp"
#include "emfusion/detect/matching.hpp"
#include "emfusion/detect/proposal.hpp"
#include "emfusion/slam/association.hpp"
#include "emfusion/slam/detection_masks.hpp"
#include "emfusion/slam/frame.hpp"
#include "emfusion/slam/frame_result.hpp"
#include "emfusion/slam/map.hpp"
#include "emfusion/slam/reidentification.hpp"

namespace emfusion {

/// What detection handling leaves for mapping: the first-view weights of
/// the objects it added (the last fresh.size() of Map::objects), and per
/// detection the index of the object it matched (-1: none).
template <class S, Backend B>
struct DetectionUpdate {
  std::vector<NewObjectWeights<S, B>> fresh;
  std::vector<int> object_of_detection;
};

/// Per object (labels 1..objects of the rendered segmentation `seg`) the
/// pixels it covers inside a `border` wide margin of the image.
inline std::vector<int> inner_pixels_per_object(const std::vector<int>& seg, int width, int height, int objects,
                                                int border) {
  std::vector<int> count(std::size_t(std::max(objects, 0)), 0);
  for (int v = border; v < height - border; ++v)
    for (int u = border; u < width - border; ++u) {
      const int label = seg[std::size_t(v) * std::size_t(width) + std::size_t(u)];
      if (label >= 1 && label <= objects) ++count[std::size_t(label - 1)];
    }
  return count;
}

/// The detections without instances the system cannot use: a label outside
/// 1..65535 (the label image's values) or one an earlier instance has, or a
/// score that is not finite; counts them in result.invalid_detections.
/// Returns `det` itself when none is dropped, else `checked` filled.
inline const Detections& usable_detections(const Detections& det, Detections& checked, FrameResult& result) {
  std::vector<bool> taken(65536, false), keep(det.instances.size(), true);
  for (std::size_t d = 0; d < det.instances.size(); ++d) {
    const Instance& inst = det.instances[d];
    keep[d] = inst.label >= 1 && inst.label <= 65535 && std::isfinite(inst.score) && !taken[std::size_t(inst.label)];
    if (keep[d]) taken[std::size_t(inst.label)] = true;
    else ++result.invalid_detections;
  }
  if (result.invalid_detections == 0) return det;
  checked.timestamp = det.timestamp;
  checked.labels = det.labels;
  for (std::size_t d = 0; d < det.instances.size(); ++d)
    if (keep[d]) checked.instances.push_back(det.instances[d]);
  return checked;
}

/// Grows `obj` to hold the box of the detection's points (label `label`,
/// camera at T_world_camera) with the same relative padding a new object
/// would get around it, per axis (paper: "resized by determining an
/// increased r_i required to fit the new detection").
template <class S, Backend B>
void grow_for_detection(ObjectModel<S, B>& obj, const std::vector<Vec3<S>>& points, const std::uint16_t* labels,
                        int label, const SE3<S>& T_world_camera, const PinholeCamera<S>& camera,
                        const SystemParams<S>& params) {
  const SE3<S> T_volume_camera = obj.volume().pose().inverse() * T_world_camera;
  std::vector<Vec3<S>> p = largest_depth_group(detection_points(points, labels, label), params.object_depth_gap);
  if (int(p.size()) < params.min_mask_pixels_for(camera.width, camera.height)) return;
  for (Vec3<S>& x : p) x = T_volume_camera * x;
  const Box<S> box = percentile_box(p);
  const S pad = S(0.5) * (params.object_padding - S(1));
  const Vec3<S> margin =
      vec3(pad * (box.hi.x() - box.lo.x()), pad * (box.hi.y() - box.lo.y()), pad * (box.hi.z() - box.lo.z()));
  obj.grow_to_fit(box.lo - margin, box.hi + margin, params.max_object_voxels);
}

/// Creates an object from detection d if the rules of sec. 3.5 allow it
/// (see the header comment); appends it to map.objects and its record, and
/// returns its first-view weights. `seg` and `points`: the frame's
/// segmentation and points on the host.
template <class S, Backend B>
std::optional<NewObjectWeights<S, B>> create_object(Map<S, B>& map, const Detections& det, int d,
                                                    const std::vector<int>& seg, const std::vector<Vec3<S>>& points,
                                                    const PinholeCamera<S>& camera, const SystemParams<S>& params,
                                                    S outside, FrameResult& result) {
  const Instance& inst = det.instances[std::size_t(d)];
  if (is_listed_class(inst.class_name, params.static_classes)) return std::nullopt;
  if (int(map.objects.size()) >= params.max_objects) {
    ++result.detections_over_cap;
    return std::nullopt;
  }
  int covered = 0, total = 0;
  const std::vector<Vec3<S>> p = largest_depth_group(
      detection_points(points, det.labels.view().data, inst.label, &seg, &covered, &total), params.object_depth_gap);
  if (total == 0 || double(covered) >= params.max_covered_fraction * double(total)) return std::nullopt;
  if (int(p.size()) < params.min_mask_pixels_for(camera.width, camera.height)) return std::nullopt;
  const Box<S> cube = padded_cube(percentile_box(p), params.object_padding);
  const S side = cube.hi.x() - cube.lo.x();
  if (!(side > S(0)) || !(norm(cube.center()) <= params.max_object_distance)) return std::nullopt;
  const SE3<S> T_world_center = map.T_world_camera * SE3<S>::translation(cube.center());
  const SE3<S> T_world_volume = T_world_center * SE3<S>::translation(Vec3<S>::constant(-side / S(2)));
  for (const auto& o : map.objects) {
    const Vec3<S> ext = o->volume().view().extent();
    if (volume_iou(T_world_volume, Vec3<S>::constant(side), o->volume().pose(), ext) >= params.max_volume_iou)
      return std::nullopt;
  }
  const int id = map.next_id++;
  const B& backend = map.background.backend();
  auto obj = std::make_unique<ObjectModel<S, B>>(id, inst.class_name, T_world_center, params.object_voxels,
                                                 side / S(params.object_voxels), params.truncation_voxels, backend);
  obj->add_class_score(inst.class_name, inst.score);
  ObjectRecord rec;
  rec.id = id;
  rec.class_name = inst.class_name;
  rec.person = params.ignores(obj->class_name());
  map.records.push_back(rec);
  map.objects.push_back(std::move(obj));
  result.created.push_back(id);
  return first_view_weights(det, d, seg, outside, camera, backend);
}

/// Stage 5: matching, existence counts, resizing, re-identification and
/// creation for the detections `det` of a mapped frame (usable_detections
/// first), against `seg`, frame.segmentation as rendered this frame, on the
/// host. With `seen` (seen_segmentation), a detection matches an object by
/// the pixels where the frame shows it, and a miss counts only for an
/// object the frame shows: one drawn behind something nearer that no model
/// holds neither takes that thing's detection nor misses it. `likelihood`
/// gives the first-view weights' `outside` value; `norm` (in voxels of each
/// object) and `solver` align lost objects.
template <class S, Backend B, class Likelihood, class Norm, class Solver>
  requires VolumeLikelihood<Likelihood, S> && RobustNorm<Norm, S> && PoseSolver<Solver, S>
DetectionUpdate<S, B> handle_detections(Map<S, B>& map, const Frame<S, B>& frame, const Detections& det,
                                        const std::vector<int>& seg, const PinholeCamera<S>& camera,
                                        const SystemParams<S>& params, const Likelihood& likelihood,
                                        const Norm& norm, const Solver& solver, FrameResult& result,
                                        const std::vector<int>* seen = nullptr) {
  detail::require(det.labels.width() == camera.width && det.labels.height() == camera.height, "handle_detections",
                  "detection label image is " + std::to_string(det.labels.width()) + "x" +
                      std::to_string(det.labels.height()) + " but the camera is " + std::to_string(camera.width) +
                      "x" + std::to_string(camera.height));
  DetectionUpdate<S, B> update;
  const std::vector<int>& shown = seen ? *seen : seg;
  const DetectionMatch match = match_detections(mask_iou(det, shown, int(map.objects.size())), params.match_iou);
  update.object_of_detection = match.object_of;

  std::vector<bool> matched(map.objects.size(), false);
  const std::vector<Vec3<S>> points = frame.points.to_host();
  const std::uint16_t* labels = det.labels.view().data;
  for (std::size_t d = 0; d < det.instances.size(); ++d) {
    const int o = match.object_of[d];
    if (o < 0) continue;
    ++result.matched;
    matched[std::size_t(o)] = true;
    ObjectModel<S, B>& obj = *map.objects[std::size_t(o)];
    obj.add_class_score(det.instances[d].class_name, det.instances[d].score);
    grow_for_detection(obj, points, labels, det.instances[d].label, map.T_world_camera, camera, params);
  }
  // A miss counts only for an object the detector could have seen: visible
  // in the segmentation (the lifecycle's rule, rendered pixels only; with
  // `seen`, where the frame shows it), or a person kept for association
  // only (never rendered).
  const std::vector<int> drawn = inner_pixels_per_object(
      shown, camera.width, camera.height, int(map.objects.size()), params.visibility_border_for(camera.width));
  const int min_pixels = params.keep_mask_pixels_for(camera.width, camera.height);
  for (std::size_t o = 0; o < map.objects.size(); ++o) {
    if (matched[o])
      map.objects[o]->count_detected();
    else if (drawn[o] >= min_pixels || params.ignores(map.objects[o]->class_name()))
      map.objects[o]->count_missed();
  }
  const S outside = unexplained_association<S>(likelihood);
  for (std::size_t d = 0; d < det.instances.size(); ++d) {
    if (match.object_of[d] >= 0) continue;
    bool held = false;
    if (auto w = reidentify(map, frame, det, int(d), seg, points, camera, params, norm, solver, outside, &held)) {
      result.found_again(map.objects.back()->id(), FoundBy::detection);
      update.fresh.push_back(std::move(*w));
      continue;
    }
    if (held) {  // a lost object fitted it in depth but not in colour: no second model of it
      ++result.held_for_colour;
      continue;
    }
    if (auto w = create_object(map, det, int(d), seg, points, camera, params, outside, result))
      update.fresh.push_back(std::move(*w));
  }
  return update;
}

}  // namespace emfusion
