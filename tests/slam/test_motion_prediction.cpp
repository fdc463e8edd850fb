// Constant-velocity motion prediction (slam/motion_prediction.hpp): the
// motion of the last two poses repeated, scaled by the time steps and
// clamped, and nothing predicted from poses that were not the last frames'.
#include <cmath>
#include <limits>

#include "emfusion/slam/motion_prediction.hpp"
#include "support/catch.hpp"

using namespace emfusion;

namespace {
double distance(const SE3<double>& a, const SE3<double>& b) { return norm((a.inverse() * b).log()); }
const SE3<double> step = SE3<double>::exp(Vec6<double>{{0.02, -0.01, 0.005, 0.01, 0.03, -0.02}});
const SE3<double> start = SE3<double>::exp(Vec6<double>{{1.0, 0.5, -0.3, 0.2, -0.4, 0.1}});
}  // namespace

TEST_CASE("Constant velocity repeats the last motion in the body frame, scaled by the time steps", "[slam]") {
  const TimedPose a{1.0, start}, b{1.1, start * step};
  CHECK(distance(constant_velocity(a, b, 1.2), start * step * step) < 1e-12);
  // A dropped frame: twice the motion.
  CHECK(distance(constant_velocity(a, b, 1.3), start * step * step * step) < 1e-9);
  // Half a step.
  const SE3<double> half = SE3<double>::exp(step.log() * 0.5);
  CHECK(distance(constant_velocity(a, b, 1.15), start * step * half) < 1e-9);
  // A gap of ten frames is clamped to max_ratio (2) steps.
  CHECK(distance(constant_velocity(a, b, 2.1), start * step * step * step) < 1e-9);
  // Broken time steps repeat the motion once.
  const double nan = std::numeric_limits<double>::quiet_NaN();
  CHECK(distance(constant_velocity(a, b, nan), start * step * step) < 1e-12);
  CHECK(distance(constant_velocity(TimedPose{1.1, start}, b, 1.2), start * step * step) < 1e-12);
  CHECK(distance(constant_velocity(a, b, 1.05), start * step * step) < 1e-12);  // not ahead of the last pose
}

TEST_CASE("A pose is predicted only from the poses of the two frames before", "[slam]") {
  Trajectory t{{1.0, start}, {1.1, start * step}};
  const auto p = predict_pose(t, 1.0, 1.1, 1.2);
  REQUIRE(p);
  CHECK(distance(*p, start * step * step) < 1e-12);
  CHECK_FALSE(predict_pose(t, 0.9, 1.1, 1.2));  // lost in between: the frame at 1.0 was not the one before
  CHECK_FALSE(predict_pose(t, 1.1, 1.2, 1.3));  // not tracked in the last frame
  CHECK_FALSE(predict_pose(Trajectory{{1.1, start}}, 1.0, 1.1, 1.2));
  CHECK_FALSE(predict_pose(Trajectory{}, 1.0, 1.1, 1.2));
}
