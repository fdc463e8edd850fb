// Relative pose error (RPE) over a fixed time window, as the TUM RGB-D
// benchmark's evaluate_rpe with --fixed_delta (shared FORMATS.md section 6,
// "Camera RPE"): the drift of the estimate over `delta_seconds`, independent
// of the world frames of estimate and ground truth.
//
// Which pose pairs are used:
//  1. Poses are matched by timestamp with `associate(est, gt, max_difference)`
//     and the matched frames sorted by ground-truth timestamp t_0 <= t_1 <= ...
//  2. For every matched frame i, j is the matched frame whose ground-truth
//     timestamp is nearest to t_i + delta_seconds (the earlier on a tie).
//  3. The pair (i, j) is used if j > i and |t_j - (t_i + delta_seconds)| <=
//     tolerance = max(max_difference, half the median of t_{k+1} - t_k over
//     the matched frames): a pose must exist one window later, to within
//     what regular frames guarantee. This drops the frames of the last window
//     of the sequence (their window would end after it) and windows that end
//     inside a gap in the data.
//
// For each pair, with poses body-to-world and A = est_i^-1 est_j, B =
// gt_i^-1 gt_j the estimated and the true motion over the window, the error
// is composed as the evaluate_rpe script does,
//   E = A B^-1 = (est_i^-1 est_j) (gt_i^-1 gt_j)^-1,
// so that the numbers match the tool other users compare with. (Sturm et al.
// 2012, eq. 3 write B^-1 A; the rotation angle is the same, the translations
// differ by at most the rotation error times the distance moved.) The angle
// of rot(E) is the rotation drift over the window. The RMSEs are taken over
// all used pairs; the errors are per window and not divided by the actual
// t_j - t_i, so with delta_seconds = 1 the translation RMSE is in m/s.
//
// The script picks the pairs over estimate timestamps with its own
// tolerances; rule 3 above replaces them.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <string>
#include <vector>

#include "emfusion/core/error.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/eval/trajectory.hpp"

namespace emfusion::eval {

struct RpeResult {
  double translation_rmse;   ///< RMSE of |trans(E)|, metres per delta_seconds (m/s for 1 s)
  double rotation_rmse_deg;  ///< RMSE of the rotation angle of E, degrees per delta_seconds
  std::size_t pairs;         ///< number of pose pairs used
};

/// RPE over windows of `delta_seconds`; see the top of this header for the
/// pairs used. Throws std::invalid_argument for delta_seconds <= 0, fewer than
/// 2 matched poses, or when no pair of matched poses is delta_seconds apart.
/// One pose pair of the RPE: the window from ground-truth time `start` to
/// `end` and the error E's translation (metres) and rotation angle (degrees).
struct RpePair {
  double start, end;
  double translation;
  double rotation_deg;
};

/// The pose pairs relative_pose_error uses, in the order of their start
/// times (for plotting the drift over time); the same checks and errors.
inline std::vector<RpePair> relative_pose_errors(const Trajectory& est, const Trajectory& gt,
                                                 double delta_seconds = 1.0, double max_difference = 0.02) {
  constexpr const char* where = "relative_pose_error";
  emfusion::detail::require(std::isfinite(delta_seconds) && delta_seconds > 0.0, where,
                            "delta_seconds must be finite and > 0, got " + detail::number(delta_seconds));
  std::vector<Match> matches = associate(est, gt, max_difference);
  emfusion::detail::require(matches.size() >= 2, where,
                            "only " + std::to_string(matches.size()) + " of " + std::to_string(est.size()) +
                                " estimated poses match a ground-truth pose (of " + std::to_string(gt.size()) +
                                ") within " + detail::number(max_difference) + " s; at least 2 are needed");
  std::stable_sort(matches.begin(), matches.end(),
                   [&](const Match& a, const Match& b) { return gt[a.gt].timestamp < gt[b.gt].timestamp; });
  const std::size_t n = matches.size();
  std::vector<double> times(n);
  for (std::size_t k = 0; k < n; ++k) times[k] = gt[matches[k].gt].timestamp;

  std::vector<double> spacing(n - 1);
  for (std::size_t k = 0; k + 1 < n; ++k) spacing[k] = times[k + 1] - times[k];
  std::nth_element(spacing.begin(), spacing.begin() + std::ptrdiff_t(spacing.size() / 2), spacing.end());
  const double tolerance = std::max(max_difference, 0.5 * spacing[spacing.size() / 2]);

  const double pi = 3.14159265358979323846;
  std::vector<RpePair> pairs;
  for (std::size_t i = 0; i < n; ++i) {
    const double target = times[i] + delta_seconds;
    std::size_t j = std::size_t(std::lower_bound(times.begin(), times.end(), target) - times.begin());
    if (j == n || (j > 0 && target - times[j - 1] <= times[j] - target)) --j;
    if (j <= i || std::fabs(times[j] - target) > tolerance) continue;
    const SE3<double> gt_motion = gt[matches[i].gt].pose.inverse() * gt[matches[j].gt].pose;
    const SE3<double> est_motion = est[matches[i].est].pose.inverse() * est[matches[j].est].pose;
    const SE3<double> error = est_motion * gt_motion.inverse();
    pairs.push_back({times[i], times[j], norm(error.translation()), norm(so3_log(error.rotation())) * 180.0 / pi});
  }
  emfusion::detail::require(!pairs.empty(), where,
                            "no pair of matched poses is delta_seconds = " + detail::number(delta_seconds) +
                                " s apart (the " + std::to_string(n) + " matched poses span " +
                                detail::number(times.back() - times.front()) + " s)");
  return pairs;
}

inline RpeResult relative_pose_error(const Trajectory& est, const Trajectory& gt, double delta_seconds = 1.0,
                                     double max_difference = 0.02) {
  double sum_sq_translation = 0.0, sum_sq_angle = 0.0;
  const double pi = 3.14159265358979323846;
  const std::vector<RpePair> pairs = relative_pose_errors(est, gt, delta_seconds, max_difference);
  for (const RpePair& p : pairs) {
    sum_sq_translation += p.translation * p.translation;
    const double angle = p.rotation_deg * pi / 180.0;
    sum_sq_angle += angle * angle;
  }
  return RpeResult{std::sqrt(sum_sq_translation / double(pairs.size())),
                   std::sqrt(sum_sq_angle / double(pairs.size())) * 180.0 / pi, pairs.size()};
}

}  // namespace emfusion::eval
