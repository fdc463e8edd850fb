// evaluate_trajectory: ATE and RPE of an estimated TUM trajectory against a
// ground-truth one (shared FORMATS.md section 6).
//
//   evaluate_trajectory <groundtruth.txt> <estimate.txt>
#include <cstdio>
#include <stdexcept>

#include "emfusion/eval/ate.hpp"
#include "emfusion/eval/rpe.hpp"
#include "emfusion/io/tum.hpp"

int main(int argc, char** argv) {
  try {
    if (argc != 3) throw std::invalid_argument("usage: evaluate_trajectory <groundtruth.txt> <estimate.txt>");
    const auto gt = emfusion::read_tum_trajectory(argv[1]);
    const auto est = emfusion::read_tum_trajectory(argv[2]);
    const auto ate = emfusion::eval::absolute_trajectory_error(est, gt);
    const auto rpe = emfusion::eval::relative_pose_error(est, gt);
    std::printf("ATE RMSE %.4f m (mean %.4f, median %.4f, max %.4f) over %zu poses\n", ate.rmse, ate.mean,
                ate.median, ate.max, ate.matched);
    std::printf("RPE RMSE %.4f m/s, %.3f deg/s over %zu pairs\n", rpe.translation_rmse, rpe.rotation_rmse_deg,
                rpe.pairs);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "evaluate_trajectory: error: %s\n", e.what());
    return 1;
  }
}
