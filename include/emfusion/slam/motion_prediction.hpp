// Where a pose is expected in the next frame: constant velocity, the motion
// between the last two poses of a trajectory repeated over the time to the
// new frame. Tracking starts its solve there when the frame agrees with the
// prediction at least as well as with the last pose (slam/tracking.hpp),
// and the E-step associates the frame at the predicted poses. Over longer
// gaps (an object hidden or lost for up to a second) carry_on goes on in a
// straight line at the mean velocity of the last poses.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <optional>

#include "emfusion/core/se3.hpp"
#include "emfusion/core/timed_pose.hpp"

namespace emfusion {

/// Where a pose's solve may start: the pose of the last frame and, with
/// motion prediction, where the pose is expected now.
template <class S>
struct PoseStarts {
  SE3<S> previous;
  std::optional<SE3<S>> predicted;
};

/// The pose at `timestamp` if the motion from `before` to `last` goes on at
/// the same velocity (in the body frame: turns are about the body's origin).
/// The motion is scaled by the ratio of the time steps, clamped to
/// [0, max_ratio], so that a dropped frame doubles it and a frame with a
/// broken timestamp cannot fling the pose away; a time step that is not
/// positive and finite on either side repeats the motion once.
inline SE3<double> constant_velocity(const TimedPose& before, const TimedPose& last, double timestamp,
                                     double max_ratio = 2) {
  const SE3<double> motion = before.pose.inverse() * last.pose;
  const double step = last.timestamp - before.timestamp, ahead = timestamp - last.timestamp;
  double ratio = 1;
  if (std::isfinite(step) && std::isfinite(ahead) && step > 0 && ahead > 0) ratio = std::min(ahead / step, max_ratio);
  if (ratio == 1) return last.pose * motion;
  return last.pose * SE3<double>::exp(motion.log() * ratio);
}

/// The constant-velocity prediction at `timestamp` from the last two poses of
/// `trajectory`, if it has two and they were the frames at `previous` and
/// `last` (the two frames before this one: a pose that was not estimated in
/// both, an object that was lost in between, predicts nothing).
inline std::optional<SE3<double>> predict_pose(const Trajectory& trajectory, double previous, double last,
                                               double timestamp) {
  const std::size_t n = trajectory.size();
  if (n < 2 || trajectory[n - 2].timestamp != previous || trajectory[n - 1].timestamp != last) return std::nullopt;
  return constant_velocity(trajectory[n - 2], trajectory[n - 1], timestamp);
}

namespace detail {
/// The index of the first pose of `trajectory` within the `window` seconds
/// up to `last`, when its last pose is at `last` and the one before lies in
/// that window too (at least two poses there); else nothing.
inline std::optional<std::size_t> window_start(const Trajectory& trajectory, double last, double window) {
  const std::size_t n = trajectory.size();
  if (n < 2 || trajectory[n - 1].timestamp != last || trajectory[n - 2].timestamp < last - window) return std::nullopt;
  std::size_t first = n - 2;
  while (first > 0 && trajectory[first - 1].timestamp >= last - window) --first;
  return first;
}
}  // namespace detail

/// Where an object last estimated at `last` (the time of its trajectory's
/// last pose, else nothing) is at `timestamp`, up to `max_seconds` later
/// (else nothing), if it goes on at the mean velocity of its poses over the
/// `window` seconds up to `last` (at least two poses there, else nothing:
/// the pose before a gap, as an object's before it was lost and found
/// again elsewhere, says nothing of its velocity now): in a straight line,
/// turning about its origin at their mean rate, the two apart so that a
/// small turn does not bend its path over many frames.
inline std::optional<SE3<double>> carry_on(const Trajectory& trajectory, double last, double timestamp,
                                           double max_seconds, double window = 0.2) {
  const double ahead = timestamp - last;
  const std::optional<std::size_t> first = detail::window_start(trajectory, last, window);
  if (!first || !(ahead > 0) || !(ahead <= max_seconds)) return std::nullopt;
  const TimedPose &a = trajectory[*first], &b = trajectory.back();
  const double span = b.timestamp - a.timestamp;
  if (!(span > 0) || !std::isfinite(span)) return std::nullopt;
  const double s = ahead / span;
  const Mat3<double> R = b.pose.rotation() * so3_exp(so3_log(a.pose.rotation().transpose() * b.pose.rotation()) * s);
  return SE3<double>(R, b.pose.translation() + (b.pose.translation() - a.pose.translation()) * s);
}

/// Whether an object last estimated at `last` (the time of its
/// trajectory's last pose, else false) moved at most `max_translation`
/// metres and turned at most `max_rotation` radians between its first pose
/// of the `window` seconds up to `last` and that one (at least two poses
/// there, else false: nothing says it stands still).
inline bool standing_still(const Trajectory& trajectory, double last, double window, double max_translation,
                           double max_rotation) {
  const std::optional<std::size_t> first = detail::window_start(trajectory, last, window);
  if (!first) return false;
  const SE3<double> &a = trajectory[*first].pose, &b = trajectory.back().pose;
  return norm(b.translation() - a.translation()) <= max_translation &&
         norm(so3_log((a.inverse() * b).rotation())) <= max_rotation;
}

}  // namespace emfusion
