// Absolute trajectory error (ATE), as the TUM RGB-D benchmark's evaluate_ate:
// match estimated to ground-truth poses by timestamp, fit the estimated
// positions to the ground-truth positions with the best rigid transform (no
// scale), and report statistics of the remaining translation errors
// (shared FORMATS.md section 6, "Camera ATE"). Rotations do not enter ATE.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <string>
#include <vector>

#include "emfusion/core/error.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/eval/alignment.hpp"
#include "emfusion/eval/trajectory.hpp"

namespace emfusion::eval {

/// Statistics of the translation errors |T_gt_est * p_est(t) - p_gt(t)| over
/// the matched poses, in metres.
struct AteResult {
  double rmse;           ///< sqrt(mean of squared errors): the number the TUM benchmark and the papers report
  double mean;           ///< mean error
  double median;         ///< median error (mean of the two middle ones for an even count, as numpy)
  double max;            ///< largest error
  std::size_t matched;   ///< number of matched poses the statistics are over
  SE3<double> T_gt_est;  ///< the fitted alignment: maps the estimate's world frame into the ground truth's
};

/// ATE of positions that are already matched pair by pair (est[i] belongs
/// with gt[i]): rigid fit (align_rigid), then the error statistics. Needs at
/// least 3 pairs; throws std::invalid_argument otherwise or if the counts
/// differ.
inline AteResult ate_of_positions(const std::vector<Vec3d>& est, const std::vector<Vec3d>& gt) {
  constexpr const char* where = "ate_of_positions";
  emfusion::detail::require(
      est.size() == gt.size(), where,
      "estimate has " + std::to_string(est.size()) + " positions but ground truth has " + std::to_string(gt.size()));
  emfusion::detail::require(est.size() >= 3, where,
                            "need at least 3 matched positions, got " + std::to_string(est.size()));
  AteResult result{};
  result.T_gt_est = align_rigid(est, gt);
  result.matched = est.size();
  std::vector<double> errors(est.size());
  double sum = 0.0, sum_sq = 0.0, largest = 0.0;
  for (std::size_t i = 0; i < est.size(); ++i) {
    const double e = norm(result.T_gt_est * est[i] - gt[i]);
    errors[i] = e;
    sum += e;
    sum_sq += e * e;
    largest = std::max(largest, e);
  }
  const double n = double(errors.size());
  result.rmse = std::sqrt(sum_sq / n);
  result.mean = sum / n;
  result.max = largest;
  std::sort(errors.begin(), errors.end());
  const std::size_t half = errors.size() / 2;
  result.median = errors.size() % 2 == 1 ? errors[half] : 0.5 * (errors[half - 1] + errors[half]);
  return result;
}

/// Camera ATE as TUM's evaluate_ate: `associate(est, gt, max_difference)`,
/// then ate_of_positions of the matched translations. Throws
/// std::invalid_argument if fewer than 3 poses match.
inline AteResult absolute_trajectory_error(const Trajectory& est, const Trajectory& gt, double max_difference = 0.02) {
  const std::vector<Match> matches = associate(est, gt, max_difference);
  emfusion::detail::require(matches.size() >= 3, "absolute_trajectory_error",
                            "only " + std::to_string(matches.size()) + " of " + std::to_string(est.size()) +
                                " estimated poses match a ground-truth pose (of " + std::to_string(gt.size()) +
                                ") within " + detail::number(max_difference) +
                                " s; at least 3 are needed (do the timestamps use the same clock?)");
  std::vector<Vec3d> est_positions, gt_positions;
  est_positions.reserve(matches.size());
  gt_positions.reserve(matches.size());
  for (const Match& m : matches) {
    est_positions.push_back(est[m.est].pose.translation());
    gt_positions.push_back(gt[m.gt].pose.translation());
  }
  return ate_of_positions(est_positions, gt_positions);
}

}  // namespace emfusion::eval
