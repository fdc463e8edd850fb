// Absolute trajectory error (ATE), as the TUM RGB-D benchmark's evaluate_ate:
// match estimated to ground-truth poses by timestamp, fit the estimated
// positions to the ground-truth positions with the best rigid transform (no
// scale), and report statistics of the remaining translation errors
// (shared FORMATS.md section 6, "Camera ATE"). Rotations do not enter ATE.
// Alignment::similarity also fits a scale: a diagnostic (how much of the
// error is a scale difference between estimate and ground truth), not the
// benchmark's number.
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

/// How the estimated positions are fitted to the ground truth before the
/// errors are taken: rigidly (FORMATS.md's ATE) or with a scale as well.
enum class Alignment { rigid, similarity };

/// Statistics of the translation errors |T_gt_est * (scale * p_est(t)) - p_gt(t)|
/// over the matched poses, in metres (scale is 1 for the rigid alignment).
struct AteResult {
  double rmse;           ///< sqrt(mean of squared errors): the number the TUM benchmark and the papers report
  double mean;           ///< mean error
  double median;         ///< median error (mean of the two middle ones for an even count, as numpy)
  double max;            ///< largest error
  std::size_t matched;   ///< number of matched poses the statistics are over
  SE3<double> T_gt_est;  ///< the fitted alignment: maps the estimate's world frame into the ground truth's
  double scale = 1.0;    ///< the fitted scale (Alignment::similarity), applied before T_gt_est; 1 for rigid
};

namespace detail {

/// The scale s minimising sum |R (s a_i) + t - b_i|^2 for the rotation R of
/// the rigid fit (Umeyama: the optimal rotation does not depend on the scale),
/// given the centroids ca and cb of the a_i and b_i:
/// s = sum (b_i - cb) . R (a_i - ca) / sum |a_i - ca|^2; 1 when the a_i
/// coincide, 0 when the b_i do (a ground truth at rest is best matched by
/// shrinking the estimate to a point).
inline double similarity_scale(const std::vector<Vec3d>& a, const std::vector<Vec3d>& b, const Vec3d& ca,
                               const Vec3d& cb, const SE3<double>& rigid) {
  double num = 0.0, den = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const Vec3d da = a[i] - ca;
    num += dot(b[i] - cb, rigid.rotate(da));
    den += dot(da, da);
  }
  return den > 0.0 ? num / den : 1.0;
}

}  // namespace detail

/// ATE of positions that are already matched pair by pair (est[i] belongs
/// with gt[i]): rigid fit (align_rigid), with Alignment::similarity also the
/// best scale, then the error statistics. Needs at least 3 pairs; throws
/// std::invalid_argument otherwise or if the counts differ.
inline AteResult ate_of_positions(const std::vector<Vec3d>& est, const std::vector<Vec3d>& gt,
                                  Alignment alignment = Alignment::rigid) {
  constexpr const char* where = "ate_of_positions";
  emfusion::detail::require(
      est.size() == gt.size(), where,
      "estimate has " + std::to_string(est.size()) + " positions but ground truth has " + std::to_string(gt.size()));
  emfusion::detail::require(est.size() >= 3, where,
                            "need at least 3 matched positions, got " + std::to_string(est.size()));
  AteResult result{};
  result.T_gt_est = align_rigid(est, gt);
  if (alignment == Alignment::similarity) {
    const Vec3d ce = detail::centroid(est), cg = detail::centroid(gt);
    result.scale = detail::similarity_scale(est, gt, ce, cg, result.T_gt_est);
    // With the rotation R fixed, the best translation maps the scaled centroid onto gt's.
    result.T_gt_est = SE3<double>(result.T_gt_est.rotation(), cg - result.T_gt_est.rotate(ce * result.scale));
  }
  result.matched = est.size();
  std::vector<double> errors(est.size());
  double sum = 0.0, sum_sq = 0.0, largest = 0.0;
  for (std::size_t i = 0; i < est.size(); ++i) {
    const double e = norm(result.T_gt_est * (est[i] * result.scale) - gt[i]);
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
inline AteResult absolute_trajectory_error(const Trajectory& est, const Trajectory& gt, double max_difference = 0.02,
                                           Alignment alignment = Alignment::rigid) {
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
  return ate_of_positions(est_positions, gt_positions, alignment);
}

}  // namespace emfusion::eval
