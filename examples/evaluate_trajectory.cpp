// evaluate_trajectory: ATE and RPE of an estimated TUM trajectory against a
// ground-truth one (shared FORMATS.md section 6).
//
//   evaluate_trajectory <groundtruth.txt> <estimate.txt> [--offset SECONDS] [--similarity]
//
// --offset adds SECONDS to the estimate's timestamps before matching (as
// TUM's evaluate_ate --offset): a whole number of frame periods compares each
// estimated pose with a ground-truth pose that many frames away. --similarity
// adds a line with the ATE after the best alignment with a scale, and that
// scale. Both are diagnostics of the ground truth's timing and scale; the
// benchmark's numbers are those without them. A trajectory too short for
// RPE's 1 s windows gets its ATE and a line saying why RPE is missing.
#include <cstdio>
#include <stdexcept>
#include <string>
#include <vector>

#include <fmt/core.h>

#include "emfusion/eval/ate.hpp"
#include "emfusion/eval/rpe.hpp"
#include "emfusion/io/tum.hpp"
#include "support/args.hpp"

int main(int argc, char** argv) {
  using namespace emfusion;
  try {
    double offset = 0.0;
    bool similarity = false;
    const auto positional = examples::parse_command_line(
        argc, argv, {"--similarity"}, [&](const std::string& a, const std::string& v) {
          if (a == "--similarity") similarity = true;
          else if (a == "--offset") offset = examples::parse_double(a, v);
          else throw std::invalid_argument("unknown option '" + a + "'");
        });
    if (positional.size() != 2)
      throw std::invalid_argument(
          "usage: evaluate_trajectory <groundtruth.txt> <estimate.txt> [--offset SECONDS] [--similarity]");
    const auto gt = read_tum_trajectory(positional[0]);
    auto est = read_tum_trajectory(positional[1]);
    for (TimedPose& p : est) p.timestamp += offset;
    const auto ate = eval::absolute_trajectory_error(est, gt);
    fmt::print("ATE RMSE {:.4f} m (mean {:.4f}, median {:.4f}, max {:.4f}) over {} poses\n", ate.rmse, ate.mean,
               ate.median, ate.max, ate.matched);
    try {
      const auto rpe = eval::relative_pose_error(est, gt);
      fmt::print("RPE RMSE {:.4f} m/s, {:.3f} deg/s over {} pairs\n", rpe.translation_rmse, rpe.rotation_rmse_deg,
                 rpe.pairs);
    } catch (const std::invalid_argument& e) {  // e.g. a trajectory shorter than the 1 s window
      fmt::print("RPE not computed: {}\n", e.what());
    }
    if (similarity) {
      const auto sim = eval::absolute_trajectory_error(est, gt, 0.02, eval::Alignment::similarity);
      fmt::print("ATE RMSE with scale {:.4f} m at scale {:.4f} (estimate scaled by it to fit the ground truth)\n",
                 sim.rmse, sim.scale);
    }
    return 0;
  } catch (const std::exception& e) {
    fmt::print(stderr, "evaluate_trajectory: error: {}\n", e.what());
    return 1;
  }
}
