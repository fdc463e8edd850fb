// Constant-velocity motion prediction (slam/motion_prediction.hpp): the
// motion of the last two poses repeated, scaled by the time steps and
// clamped, and nothing predicted from poses that were not the last frames';
// carrying on over longer gaps in a straight line.
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

TEST_CASE("Carrying on goes in a straight line at the mean velocity of the last 0.2 s, for a bounded time",
          "[slam]") {
  // An object moving 1.5 cm a frame along x at 30 frames a second, turning
  // a little (0.2 degrees a frame) about its own z axis.
  const double dt = 1.0 / 30;
  const Mat3<double> turn = so3_exp(Vec3<double>{{0, 0, 0.0035}});
  Trajectory t;
  Mat3<double> R = Mat3<double>::identity();
  for (int k = 0; k <= 10; ++k) {
    t.push_back({k * dt, SE3<double>(R, Vec3<double>{{0.015 * k, 0, 1}})});
    R = R * turn;
  }
  const double last = 10 * dt;
  // 20 frames on: the position on the line, the turn carried on apart.
  const auto p = carry_on(t, last, 30 * dt, 1.0);
  REQUIRE(p);
  CHECK(norm(p->translation() - Vec3<double>{{0.45, 0, 1}}) < 1e-9);
  const Mat3<double> R30 = t.back().pose.rotation() * so3_exp(Vec3<double>{{0, 0, 0.0035 * 20}});
  CHECK(norm(so3_log(p->rotation().transpose() * R30)) < 1e-9);
  // The screw motion of the last two poses, repeated, bends the path away.
  SE3<double> screw = t.back().pose;
  for (int k = 0; k < 20; ++k) screw = screw * (t[9].pose.inverse() * t[10].pose);
  CHECK(norm(screw.translation() - Vec3<double>{{0.45, 0, 1}}) > 0.005);
  // The mean over the window (0.19 s: five steps): a last pose pulled aside
  // by 3 mm adds a fifth of that a frame.
  Trajectory pulled = t;
  pulled.back().pose.translation() = pulled.back().pose.translation() + Vec3<double>{{0, 0, 0.003}};
  const auto q = carry_on(pulled, last, last + dt, 1.0, 0.19);
  REQUIRE(q);
  CHECK(q->translation().z() == emfusion::test::Approx(1.003 + 0.003 / 5).margin(1e-9));
  // Nothing beyond max_seconds, not ahead, or without a pose at `last`.
  CHECK_FALSE(carry_on(t, last, last + 1.5, 1.0));
  CHECK_FALSE(carry_on(t, last, last, 1.0));
  CHECK_FALSE(carry_on(t, 9 * dt, last, 1.0));
  CHECK_FALSE(carry_on(Trajectory{{last, start}}, last, last + dt, 1.0));
  // Nor from a pose before a gap longer than the window (an object found
  // again after it was lost): its jump is no velocity.
  const Trajectory found{{last - 0.5, start}, {last, SE3<double>::translation(Vec3<double>{{0.3, 0, 1}})}};
  CHECK_FALSE(carry_on(found, last, last + dt, 1.0));
  CHECK(carry_on(found, last, last + dt, 1.0, 0.5));
}
