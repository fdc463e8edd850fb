// Object trajectory error (shared FORMATS.md section 6, "Object ATE"): the
// procedure behind the object tables of the Co-Fusion, MaskFusion and
// EM-Fusion papers.
//
// An estimated object's frame is wherever the system put it when the object
// was created, so before positions can be compared the estimated poses are
// moved to the ground-truth object frame with one constant offset, found
// through the cameras at the first frame f where all four trajectories have a
// pose:
//   C = T_estobj_gtobj = est_obj(f)^-1 * est_cam(f) * gt_cam(f)^-1 * gt_obj(f)
// (all poses body-to-world: est_obj(f)^-1 est_cam(f) is the camera in the
// estimated object frame, gt_cam(f)^-1 gt_obj(f) the true object in the
// camera frame). Then est_obj(t) * C is the estimated pose of the true object
// frame, and the object ATE is the ATE (rigid alignment of positions, then
// translation errors; see ate.hpp) of est_obj(t) * C against gt_obj(t) over
// the matched object poses.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <string>
#include <vector>

#include "emfusion/core/error.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/eval/ate.hpp"
#include "emfusion/eval/trajectory.hpp"

namespace emfusion::eval {

struct ObjectAteResult {
  AteResult ate;                  ///< ATE of est_obj(t) * C against gt_obj(t); ate.matched = matched object poses
  double coverage;                ///< ate.matched / number of gt_obj poses: how much of the true track was estimated
  double first_common_timestamp;  ///< ground-truth timestamp of the frame f that defines C
  SE3<double> T_estobj_gtobj;     ///< the constant offset C
};

/// Object ATE of one estimated object matched to one ground-truth object.
///
/// Object poses are matched with associate(est_obj, gt_obj, max_difference).
/// Frame f is the matched object pose with the earliest ground-truth
/// timestamp for which est_cam has a pose within max_difference of the
/// est_obj timestamp and gt_cam one within max_difference of the gt_obj
/// timestamp (the nearest ones are used). Every matched object pose, before
/// or after f, enters the ATE.
///
/// Throws std::invalid_argument if gt_obj is empty, fewer than 3 object poses
/// match, or no matched frame has both camera poses.
inline ObjectAteResult object_absolute_trajectory_error(const Trajectory& est_cam, const Trajectory& gt_cam,
                                                        const Trajectory& est_obj, const Trajectory& gt_obj,
                                                        double max_difference = 0.02) {
  constexpr const char* where = "object_absolute_trajectory_error";
  emfusion::detail::require(!gt_obj.empty(), where, "the ground-truth object trajectory is empty");
  std::vector<Match> matches = associate(est_obj, gt_obj, max_difference);
  emfusion::detail::require(matches.size() >= 3, where,
                            "only " + std::to_string(matches.size()) + " of " + std::to_string(est_obj.size()) +
                                " estimated object poses match a ground-truth object pose (of " +
                                std::to_string(gt_obj.size()) + ") within " + detail::number(max_difference) +
                                " s; at least 3 are needed");
  detail::require_finite_timestamps(est_cam, where, "estimated camera");
  detail::require_finite_timestamps(gt_cam, where, "ground-truth camera");
  std::stable_sort(matches.begin(), matches.end(),
                   [&](const Match& a, const Match& b) { return gt_obj[a.gt].timestamp < gt_obj[b.gt].timestamp; });

  const std::vector<std::size_t> est_cam_order = detail::time_order(est_cam);
  const std::vector<std::size_t> gt_cam_order = detail::time_order(gt_cam);
  // Index of the pose of `cameras` nearest to t if within max_difference, else cameras.size().
  const auto camera_at = [&](const Trajectory& cameras, const std::vector<std::size_t>& order, double t) {
    if (cameras.empty()) return cameras.size();
    const std::size_t k = order[detail::nearest_in_order(cameras, order, t)];
    return std::fabs(cameras[k].timestamp - t) <= max_difference ? k : cameras.size();
  };

  ObjectAteResult result{};
  bool found = false;
  for (const Match& m : matches) {
    const std::size_t ec = camera_at(est_cam, est_cam_order, est_obj[m.est].timestamp);
    const std::size_t gc = camera_at(gt_cam, gt_cam_order, gt_obj[m.gt].timestamp);
    if (ec == est_cam.size() || gc == gt_cam.size()) continue;
    result.T_estobj_gtobj =
        est_obj[m.est].pose.inverse() * est_cam[ec].pose * gt_cam[gc].pose.inverse() * gt_obj[m.gt].pose;
    result.first_common_timestamp = gt_obj[m.gt].timestamp;
    found = true;
    break;
  }
  emfusion::detail::require(found, where,
                            "no matched object pose has an estimated and a ground-truth camera pose within " +
                                detail::number(max_difference) + " s, so the object-frame offset is undefined");

  std::vector<Vec3d> est_positions, gt_positions;
  est_positions.reserve(matches.size());
  gt_positions.reserve(matches.size());
  for (const Match& m : matches) {
    est_positions.push_back((est_obj[m.est].pose * result.T_estobj_gtobj).translation());
    gt_positions.push_back(gt_obj[m.gt].pose.translation());
  }
  result.ate = ate_of_positions(est_positions, gt_positions);
  result.coverage = double(matches.size()) / double(gt_obj.size());
  return result;
}

}  // namespace emfusion::eval
