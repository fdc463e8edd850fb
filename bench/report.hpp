// What the benchmarks print and write about a run's objects: each
// ground-truth object's ATE and coverage (eval/object_matching.hpp), on
// stdout and as the JSON object "objects".
#pragma once

#include <cmath>
#include <map>
#include <string>

#include <fmt/core.h>

#include "emfusion/core/timed_pose.hpp"
#include "emfusion/eval/object_matching.hpp"
#include "emfusion/io/run_outputs.hpp"

namespace emfusion::bench {

/// Evaluates every object the system ever created against `object_truth`.
template <class System>
void report_objects(const System& system, const Trajectory& camera_truth,
                    const std::map<std::string, Trajectory>& object_truth, Json& json) {
  std::map<int, Trajectory> estimates;
  for (const auto& r : system.object_records()) estimates[r.id] = r.trajectory;
  Json& objects = json["objects"] = Json::object();
  for (const auto& e : eval::evaluate_objects(system.camera_trajectory(), camera_truth, estimates, object_truth)) {
    if (e.evaluated)
      fmt::print("object {:<14} ATE {:.2f} cm, coverage {:.0f} %\n", e.name, 100 * e.result.ate.rmse,
                 100 * e.result.coverage);
    else
      fmt::print("object {:<14} not evaluated ({})\n", e.name, e.problem);
    Json& object = objects[e.name] = Json::object();
    object["evaluated"] = e.evaluated;
    object["ate_rmse_m"] = e.evaluated ? e.result.ate.rmse : NAN;  // written as null
    object["coverage"] = e.evaluated ? e.result.coverage : 0.0;
  }
}

}  // namespace emfusion::bench
