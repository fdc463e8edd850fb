// Which estimated object is which ground-truth object. The estimate's object
// frames are arbitrary, but each object's frame origin is near the object
// (the centre of the volume it was created with), so objects are matched by
// the distance between their origins seen from the camera,
//   | est_cam(t)^-1 est_obj(t) origin - gt_cam(t)^-1 gt_obj(t) origin |,
// averaged over the frames both exist: a camera-frame comparison needs no
// alignment of the two world frames. Each estimated object goes to the
// nearest ground-truth object within `max_distance`; a ground-truth object
// may collect several estimates (an object deleted and created again).
#pragma once

#include <cmath>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "emfusion/core/timed_pose.hpp"
#include "emfusion/eval/object_ate.hpp"
#include "emfusion/eval/trajectory.hpp"

namespace emfusion::eval {

/// Mean camera-frame distance between the origins of two object
/// trajectories over their common frames, and how many there were.
struct OriginDistance {
  double mean = std::numeric_limits<double>::infinity();
  std::size_t frames = 0;
};

inline OriginDistance origin_distance(const Trajectory& est_cam, const Trajectory& gt_cam, const Trajectory& est_obj,
                                      const Trajectory& gt_obj, double max_difference = 0.02) {
  const std::vector<Match> objects = associate(est_obj, gt_obj, max_difference);
  const std::vector<std::size_t> ec_order = detail::time_order(est_cam), gc_order = detail::time_order(gt_cam);
  double sum = 0;
  OriginDistance d;
  for (const Match& m : objects) {
    if (est_cam.empty() || gt_cam.empty()) break;
    const std::size_t ec = ec_order[detail::nearest_in_order(est_cam, ec_order, est_obj[m.est].timestamp)];
    const std::size_t gc = gc_order[detail::nearest_in_order(gt_cam, gc_order, gt_obj[m.gt].timestamp)];
    if (std::fabs(est_cam[ec].timestamp - est_obj[m.est].timestamp) > max_difference ||
        std::fabs(gt_cam[gc].timestamp - gt_obj[m.gt].timestamp) > max_difference)
      continue;
    const Vec3d e = (est_cam[ec].pose.inverse() * est_obj[m.est].pose).translation();
    const Vec3d g = (gt_cam[gc].pose.inverse() * gt_obj[m.gt].pose).translation();
    sum += norm(e - g);
    ++d.frames;
  }
  if (d.frames > 0) d.mean = sum / double(d.frames);
  return d;
}

/// The evaluation of one ground-truth object.
struct ObjectEvaluation {
  std::string name;              ///< ground-truth object name
  std::vector<int> estimates;    ///< ids of the estimated objects matched to it
  int primary = -1;              ///< the estimate with the most frames (-1: none)
  bool evaluated = false;        ///< an ATE could be computed for the primary
  ObjectAteResult result{};      ///< object ATE of the primary (coverage = its share of the true frames)
  std::string problem;           ///< why it was not evaluated
};

/// Matches estimated objects (id -> trajectory) to ground-truth objects
/// (name -> trajectory) and computes each ground-truth object's ATE.
inline std::vector<ObjectEvaluation> evaluate_objects(const Trajectory& est_cam, const Trajectory& gt_cam,
                                                      const std::map<int, Trajectory>& estimates,
                                                      const std::map<std::string, Trajectory>& truth,
                                                      double max_distance = 0.25, double max_difference = 0.02) {
  std::map<std::string, ObjectEvaluation> by_name;
  for (const auto& [name, traj] : truth) by_name[name].name = name;
  for (const auto& [id, est] : estimates) {
    std::string best;
    double best_d = max_distance;
    for (const auto& [name, gt] : truth) {
      const OriginDistance d = origin_distance(est_cam, gt_cam, est, gt, max_difference);
      if (d.frames >= 3 && d.mean < best_d) best_d = d.mean, best = name;
    }
    if (!best.empty()) by_name[best].estimates.push_back(id);
  }
  std::vector<ObjectEvaluation> out;
  for (auto& [name, ev] : by_name) {
    std::size_t most = 0;
    for (const int id : ev.estimates)
      if (estimates.at(id).size() > most) most = estimates.at(id).size(), ev.primary = id;
    if (ev.primary < 0) {
      ev.problem = "no estimated object matches it";
    } else {
      try {
        ev.result = object_absolute_trajectory_error(est_cam, gt_cam, estimates.at(ev.primary), truth.at(name),
                                                     max_difference);
        ev.evaluated = true;
      } catch (const std::exception& e) {
        ev.problem = e.what();
      }
    }
    out.push_back(ev);
  }
  return out;
}

}  // namespace emfusion::eval
