// Timestamped trajectories for evaluation, and associating the poses of two
// trajectories by timestamp the way the TUM RGB-D benchmark's associate.py does.
//
// A pose maps body points (camera or object) into the world frame
// (shared FORMATS.md section 4). Trajectories need not be sorted; associate
// and the evaluations sort what they need and report indices into the
// trajectories as given.
#pragma once

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <string>
#include <vector>

#include "emfusion/core/error.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/core/timed_pose.hpp"

namespace emfusion::eval {

/// Trajectories are emfusion::Trajectory (core/timed_pose.hpp), the same
/// type the TUM reader returns.
using emfusion::TimedPose;
using emfusion::Trajectory;

/// A pose of the estimate matched to a pose of the ground truth: indices into
/// the two trajectories given to `associate`.
struct Match {
  std::size_t est;
  std::size_t gt;
};

namespace detail {

/// Shortest text that reads back as `value` ("0.02", not "0.020000").
inline std::string number(double value) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return std::string(buffer, result.ptr);
}

inline void require_finite_timestamps(const Trajectory& trajectory, const char* where, const char* name) {
  for (std::size_t i = 0; i < trajectory.size(); ++i)
    emfusion::detail::require(std::isfinite(trajectory[i].timestamp), where,
                              std::string(name) + " pose " + std::to_string(i) + " has a non-finite timestamp");
}

/// Indices of `trajectory` in timestamp order (stable, so equal timestamps
/// keep their order).
inline std::vector<std::size_t> time_order(const Trajectory& trajectory) {
  std::vector<std::size_t> order(trajectory.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return trajectory[a].timestamp < trajectory[b].timestamp; });
  return order;
}

/// Position in `order` (a time_order of `trajectory`) of the pose nearest in
/// time to `t`, the earlier one on a tie; order.size() if `order` is empty.
inline std::size_t nearest_in_order(const Trajectory& trajectory, const std::vector<std::size_t>& order, double t) {
  if (order.empty()) return 0;
  const auto it = std::lower_bound(order.begin(), order.end(), t,
                                   [&](std::size_t i, double value) { return trajectory[i].timestamp < value; });
  const std::size_t after = std::size_t(it - order.begin());
  if (after == order.size()) return after - 1;
  if (after == 0) return 0;
  const double d_before = t - trajectory[order[after - 1]].timestamp;
  const double d_after = trajectory[order[after]].timestamp - t;
  return d_before <= d_after ? after - 1 : after;
}

}  // namespace detail

/// Matches poses of `est` to poses of `gt` by timestamp, as TUM's
/// associate.py: every pair at most `max_difference` seconds apart is a
/// candidate; candidates are taken greedily, smallest time difference first
/// (ties: earlier estimate timestamp, then earlier ground-truth timestamp),
/// skipping any whose estimate or ground-truth pose is already taken. So every
/// pose is used at most once, and an estimate whose nearest ground-truth pose
/// went to a closer estimate may take its second-nearest one.
///
/// Returns the matches sorted by estimate timestamp. Differs from associate.py
/// only in that a difference of exactly `max_difference` still matches (the
/// script needs it strictly smaller), so 0 matches equal timestamps, and in
/// that poses with equal timestamps are all kept (the script's dictionaries
/// keep only one of them).
///
/// Throws std::invalid_argument for a negative or non-finite max_difference
/// or a non-finite timestamp.
inline std::vector<Match> associate(const Trajectory& est, const Trajectory& gt, double max_difference = 0.02) {
  constexpr const char* where = "associate";
  emfusion::detail::require(std::isfinite(max_difference) && max_difference >= 0.0, where,
                            "max_difference must be finite and >= 0, got " + detail::number(max_difference));
  detail::require_finite_timestamps(est, where, "estimated");
  detail::require_finite_timestamps(gt, where, "ground-truth");

  struct Candidate {
    double difference;
    std::size_t est, gt;
  };
  const std::vector<std::size_t> gt_order = detail::time_order(gt);
  std::vector<Candidate> candidates;
  for (std::size_t e = 0; e < est.size(); ++e) {
    const double t = est[e].timestamp;
    auto it = std::lower_bound(gt_order.begin(), gt_order.end(), t - max_difference,
                               [&](std::size_t i, double value) { return gt[i].timestamp < value; });
    for (; it != gt_order.end() && gt[*it].timestamp <= t + max_difference; ++it) {
      const double difference = std::fabs(gt[*it].timestamp - t);
      if (difference <= max_difference) candidates.push_back({difference, e, *it});
    }
  }
  std::sort(candidates.begin(), candidates.end(), [&](const Candidate& a, const Candidate& b) {
    if (a.difference != b.difference) return a.difference < b.difference;
    if (est[a.est].timestamp != est[b.est].timestamp) return est[a.est].timestamp < est[b.est].timestamp;
    if (gt[a.gt].timestamp != gt[b.gt].timestamp) return gt[a.gt].timestamp < gt[b.gt].timestamp;
    return a.est != b.est ? a.est < b.est : a.gt < b.gt;
  });

  std::vector<bool> est_taken(est.size(), false), gt_taken(gt.size(), false);
  std::vector<Match> matches;
  for (const Candidate& c : candidates) {
    if (est_taken[c.est] || gt_taken[c.gt]) continue;
    est_taken[c.est] = gt_taken[c.gt] = true;
    matches.push_back({c.est, c.gt});
  }
  std::sort(matches.begin(), matches.end(), [&](const Match& a, const Match& b) {
    if (est[a.est].timestamp != est[b.est].timestamp) return est[a.est].timestamp < est[b.est].timestamp;
    return a.est < b.est;
  });
  return matches;
}

}  // namespace emfusion::eval
