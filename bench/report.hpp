// What the benchmarks print and write about a run's objects: each
// ground-truth object's ATE and coverage (eval/object_matching.hpp), on
// stdout and as the JSON object "objects".
#pragma once

#include <cmath>
#include <cstdio>
#include <map>
#include <string>

#include "emfusion/core/timed_pose.hpp"
#include "emfusion/eval/object_matching.hpp"
#include "emfusion/io/run_outputs.hpp"

namespace emfusion::bench {

/// Evaluates every object the system ever created against `object_truth`.
template <class System>
void report_objects(const System& system, const Trajectory& camera_truth,
                    const std::map<std::string, Trajectory>& object_truth, JsonWriter& json) {
  std::map<int, Trajectory> estimates;
  for (const auto& r : system.object_records()) estimates[r.id] = r.trajectory;
  json.begin("objects");
  for (const auto& e : eval::evaluate_objects(system.camera_trajectory(), camera_truth, estimates, object_truth)) {
    if (e.evaluated)
      std::printf("object %-14s ATE %.2f cm, coverage %.0f %%\n", e.name.c_str(), 100 * e.result.ate.rmse,
                  100 * e.result.coverage);
    else
      std::printf("object %-14s not evaluated (%s)\n", e.name.c_str(), e.problem.c_str());
    json.begin(e.name).boolean("evaluated", e.evaluated);
    json.number("ate_rmse_m", e.evaluated ? e.result.ate.rmse : NAN);
    json.number("coverage", e.evaluated ? e.result.coverage : 0.0).end();
  }
  json.end();
}

}  // namespace emfusion::bench
