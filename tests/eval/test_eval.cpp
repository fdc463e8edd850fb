// Trajectory evaluation: timestamp association, rigid alignment, camera ATE
// and RPE, object ATE (shared FORMATS.md section 6), against exact answers
// and values worked out by hand, and clear errors for bad input.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "emfusion/core/se3.hpp"
#include "emfusion/eval/alignment.hpp"
#include "emfusion/eval/ate.hpp"
#include "emfusion/eval/object_ate.hpp"
#include "emfusion/eval/rpe.hpp"
#include "emfusion/eval/trajectory.hpp"
#include "support/catch.hpp"

using namespace emfusion;
using namespace emfusion::eval;
using emfusion::test::Approx;

namespace {

SE3d random_pose(std::mt19937& rng, double max_angle = 3.1, double max_translation = 5.0) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Vec3d axis = normalized(vec3(u(rng), u(rng), u(rng)));
  const double angle = max_angle * std::fabs(u(rng));
  return SE3d::exp(Vec6<double>{{max_translation * u(rng), max_translation * u(rng), max_translation * u(rng),
                                 angle * axis[0], angle * axis[1], angle * axis[2]}});
}

Vec3d random_point(std::mt19937& rng, double extent = 3.0) {
  std::uniform_real_distribution<double> u(-extent, extent);
  return vec3(u(rng), u(rng), u(rng));
}

SE3d rotation_z(double angle) { return SE3d::exp(Vec6<double>{{0, 0, 0, 0, 0, angle}}); }

double rotation_determinant(const Mat3<double>& R) {
  return dot(vec3(R(0, 0), R(1, 0), R(2, 0)), cross(vec3(R(0, 1), R(1, 1), R(2, 1)), vec3(R(0, 2), R(1, 2), R(2, 2))));
}

/// max |R^T R - I| + |det R - 1|: zero for a proper rotation.
double rotation_defect(const Mat3<double>& R) {
  return max_abs_diff(R.transpose() * R, Mat3<double>::identity()) + std::fabs(rotation_determinant(R) - 1.0);
}

double pose_difference(const SE3d& a, const SE3d& b) {
  return std::max(max_abs_diff(a.rotation(), b.rotation()), max_abs_diff(a.translation(), b.translation()));
}

Vec3d centroid_of(const std::vector<Vec3d>& points) {
  Vec3d sum = Vec3d::zero();
  for (const Vec3d& p : points) sum += p;
  return sum / double(points.size());
}

double alignment_cost(const SE3d& T, const std::vector<Vec3d>& source, const std::vector<Vec3d>& target) {
  double cost = 0.0;
  for (std::size_t i = 0; i < source.size(); ++i) cost += squared_norm(T * source[i] - target[i]);
  return cost;
}

/// The cost of rotation R with its best translation (centroids mapped onto each other).
double cost_with_rotation(const Mat3<double>& R, const std::vector<Vec3d>& source, const std::vector<Vec3d>& target) {
  const SE3d rotation(R, Vec3d::zero());
  const Vec3d t = centroid_of(target) - rotation.rotate(centroid_of(source));
  return alignment_cost(SE3d(R, t), source, target);
}

/// A smooth camera-like trajectory at `rate` Hz over `seconds`, timestamps k / rate.
Trajectory smooth_trajectory(double seconds, double rate, double t0 = 0.0) {
  Trajectory trajectory;
  const int frames = int(std::lround(seconds * rate));
  for (int k = 0; k <= frames; ++k) {
    const double t = t0 + double(k) / rate;
    const SE3d pose = SE3d::exp(Vec6<double>{
        {std::sin(t), 0.5 * std::cos(0.7 * t), 0.2 * t, 0.3 * std::sin(0.9 * t), 0.4 * t, 0.1 * std::cos(1.3 * t)}});
    trajectory.push_back({t, pose});
  }
  return trajectory;
}

Trajectory left_multiplied(const SE3d& W, const Trajectory& trajectory) {
  Trajectory out = trajectory;
  for (TimedPose& p : out) p.pose = W * p.pose;
  return out;
}

Trajectory from_timestamps(const std::vector<double>& timestamps) {
  Trajectory trajectory;
  for (double t : timestamps) trajectory.push_back({t, SE3d::translation(vec3(t, 0.0, 0.0))});
  return trajectory;
}

}  // namespace

TEST_CASE("associate matches nearest timestamps one-to-one, greedily", "[eval]") {
  SECTION("jitter, missing poses and a far estimate") {
    // gt 0.0 0.1 0.2 (no 0.3), est 0.001 0.008 0.19 0.5 (max 0.02): 0.001-0.0
    // (0.001) is taken first, so 0.008 finds 0.0 taken and 0.1 too far;
    // 0.19-0.2 matches; 0.5 has nothing near.
    const Trajectory gt = from_timestamps({0.0, 0.1, 0.2});
    const Trajectory est = from_timestamps({0.001, 0.008, 0.19, 0.5});
    const std::vector<Match> m = associate(est, gt);
    REQUIRE(m.size() == 2);
    CHECK(m[0].est == 0);
    CHECK(m[0].gt == 0);
    CHECK(m[1].est == 2);
    CHECK(m[1].gt == 2);
  }
  SECTION("an estimate takes its second-nearest pose when a closer estimate took the nearest") {
    // Candidates: b-y 0.005, a-y 0.010, a-x 0.015 (b-x 0.03 is too far).
    // Greedy: b-y, then a-y is taken, then a-x.
    const Trajectory gt = from_timestamps({0.0, 0.025});     // x, y
    const Trajectory est = from_timestamps({0.015, 0.030});  // a, b
    const std::vector<Match> m = associate(est, gt);
    REQUIRE(m.size() == 2);
    CHECK((m[0].est == 0 && m[0].gt == 0));
    CHECK((m[1].est == 1 && m[1].gt == 1));
  }
  SECTION("unsorted input: indices refer to the input order, matches come in estimate time order") {
    const Trajectory gt = from_timestamps({0.2, 0.0, 0.1});
    const Trajectory est = from_timestamps({0.105, 0.205, 0.003});
    const std::vector<Match> m = associate(est, gt);
    REQUIRE(m.size() == 3);
    CHECK((m[0].est == 2 && m[0].gt == 1));
    CHECK((m[1].est == 0 && m[1].gt == 2));
    CHECK((m[2].est == 1 && m[2].gt == 0));
  }
  SECTION("the time limit is inclusive; 0 matches equal timestamps only") {
    const Trajectory gt = from_timestamps({1.0, 2.0});
    CHECK(associate(from_timestamps({1.5}), gt, 0.5).size() == 1);
    CHECK(associate(from_timestamps({1.5}), gt, 0.49).empty());
    const std::vector<Match> exact = associate(from_timestamps({2.0, 1.0, 1.5}), gt, 0.0);
    REQUIRE(exact.size() == 2);
    CHECK((exact[0].est == 1 && exact[0].gt == 0));
    CHECK((exact[1].est == 0 && exact[1].gt == 1));
  }
  SECTION("empty trajectories give no matches") {
    CHECK(associate({}, from_timestamps({1.0})).empty());
    CHECK(associate(from_timestamps({1.0}), {}).empty());
  }
  SECTION("bad arguments") {
    CHECK_THROWS_AS(associate(from_timestamps({1.0}), from_timestamps({1.0}), -0.1), std::invalid_argument);
    CHECK_THROWS_WITH(associate(from_timestamps({1.0}), from_timestamps({1.0}), -0.1),
                      EMF_CONTAINS("associate: max_difference must be finite and >= 0, got -0.1"));
    const Trajectory bad = from_timestamps({0.0, std::numeric_limits<double>::quiet_NaN()});
    CHECK_THROWS_WITH(associate(bad, from_timestamps({1.0})),
                      EMF_CONTAINS("estimated pose 1 has a non-finite timestamp"));
    CHECK_THROWS_WITH(associate(from_timestamps({1.0}), bad),
                      EMF_CONTAINS("ground-truth pose 1 has a non-finite timestamp"));
  }
}

TEST_CASE("align_rigid recovers a rigid transform exactly from noiseless points", "[eval]") {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 50; ++trial) {
    // Angles over the whole range, including near pi; 3 points (the minimum)
    // up to 40; every tenth set planar (z = 0), where the SVD method needs
    // its reflection sign correction.
    const SE3d T = trial == 0 ? SE3d::exp(Vec6<double>{{1, 2, 3, 0, 0, 3.14159265}}) : random_pose(rng);
    const std::size_t n = 3 + std::size_t(trial) % 38;
    std::vector<Vec3d> source, target;
    for (std::size_t i = 0; i < n; ++i) {
      Vec3d p = random_point(rng);
      if (trial % 10 == 5) p[2] = 0.0;
      source.push_back(p);
      target.push_back(T * p);
    }
    const SE3d found = align_rigid(source, target);
    INFO("trial " << trial << ", " << n << " points");
    CHECK(pose_difference(found, T) < 1e-9);
    CHECK(rotation_defect(found.rotation()) < 1e-12);
  }
}

TEST_CASE("align_rigid is rigid, not a similarity", "[eval]") {
  // target = 2 (R p) + t: the best rotation is still R, the fit does not
  // scale, and the residual cannot vanish.
  std::mt19937 rng(5);
  const SE3d T = random_pose(rng);
  std::vector<Vec3d> source, target;
  for (int i = 0; i < 20; ++i) {
    source.push_back(random_point(rng));
    target.push_back(2.0 * T.rotate(source.back()) + T.translation());
  }
  const SE3d found = align_rigid(source, target);
  CHECK(max_abs_diff(found.rotation(), T.rotation()) < 1e-9);
  CHECK(rotation_defect(found.rotation()) < 1e-12);
  // Best translation for a fixed rotation maps the centroids onto each other.
  const Vec3d expected_t = centroid_of(target) - found.rotate(centroid_of(source));
  CHECK(max_abs_diff(found.translation(), expected_t) < 1e-9);
  // Distances are preserved by the fitted transform, so they stay half those of the target.
  CHECK(norm(found * source[0] - found * source[1]) == Approx(norm(source[0] - source[1])).epsilon(1e-12));
  CHECK(alignment_cost(found, source, target) > 1.0);
}

TEST_CASE("align_rigid gives the best proper rotation for mirrored and degenerate sets", "[eval]") {
  std::mt19937 rng(3);
  SECTION("a mirrored point set gets the best proper rotation, not the reflection") {
    std::vector<Vec3d> source, target;
    for (int i = 0; i < 30; ++i) {
      source.push_back(random_point(rng));
      const Vec3d& p = source.back();
      target.push_back(vec3(-p[0], p[1], p[2]) + vec3(0.5, -1.0, 2.0));
    }
    const SE3d found = align_rigid(source, target);
    CHECK(rotation_defect(found.rotation()) < 1e-12);
    const double best = alignment_cost(found, source, target);
    CHECK(best == Approx(cost_with_rotation(found.rotation(), source, target)).epsilon(1e-12));
    // No other rotation, near or far, does better.
    for (int k = 0; k < 500; ++k) {
      const Mat3<double> R = k < 250 ? (random_pose(rng, 1e-3, 0.0) * SE3d(found.rotation(), Vec3d::zero())).rotation()
                                     : random_pose(rng, 3.14, 0.0).rotation();
      CHECK(cost_with_rotation(R, source, target) >= best * (1.0 - 1e-12));
    }
  }
  SECTION("collinear points: one of the optimal rotations, still proper") {
    const SE3d T = random_pose(rng);
    const Vec3d origin = vec3(0.3, -0.2, 1.0), direction = normalized(vec3(1.0, 2.0, -0.5));
    std::vector<Vec3d> source, target;
    for (double s : {-2.0, -0.5, 0.1, 1.0, 3.0}) {
      source.push_back(origin + s * direction);
      target.push_back(T * source.back());
    }
    const SE3d found = align_rigid(source, target);
    CHECK(rotation_defect(found.rotation()) < 1e-12);
    CHECK(alignment_cost(found, source, target) < 1e-18);
  }
  SECTION("coincident points: identity rotation, translation between them") {
    const std::vector<Vec3d> source(4, vec3(1.0, 2.0, 3.0));
    const std::vector<Vec3d> target(4, vec3(-1.0, 0.0, 5.0));
    const SE3d found = align_rigid(source, target);
    CHECK(max_abs_diff(found.rotation(), Mat3<double>::identity()) == 0.0);
    CHECK(max_abs_diff(found.translation(), vec3(-2.0, -2.0, 2.0)) < 1e-15);
  }
  SECTION("bad arguments") {
    const std::vector<Vec3d> three(3, Vec3d::zero()), four(4, Vec3d::zero()), two(2, Vec3d::zero());
    CHECK_THROWS_AS(align_rigid(three, four), std::invalid_argument);
    CHECK_THROWS_WITH(align_rigid(three, four), EMF_CONTAINS("align_rigid: source has 3 points but target has 4"));
    CHECK_THROWS_WITH(align_rigid(two, two), EMF_CONTAINS("align_rigid: need at least 3 point pairs, got 2"));
    std::vector<Vec3d> nan = three;
    nan[1][2] = std::numeric_limits<double>::quiet_NaN();
    CHECK_THROWS_WITH(align_rigid(nan, three), EMF_CONTAINS("point pair 1 is not finite"));
  }
}

TEST_CASE("ATE of a trajectory against a rigidly moved copy of itself is zero", "[eval]") {
  std::mt19937 rng(17);
  const Trajectory est = smooth_trajectory(5.0, 30.0);
  const SE3d W = random_pose(rng);
  // gt world = W * est world; timestamps shifted by 5 ms (well inside 0.02 s).
  Trajectory gt = left_multiplied(W, est);
  for (TimedPose& p : gt) p.timestamp += 0.005;
  const AteResult r = absolute_trajectory_error(est, gt);
  CHECK(r.matched == est.size());
  CHECK(r.rmse < 1e-9);
  CHECK(r.mean < 1e-9);
  CHECK(r.median < 1e-9);
  CHECK(r.max < 1e-9);
  CHECK(pose_difference(r.T_gt_est, W) < 1e-9);
}

TEST_CASE("ATE matches a hand-computed example", "[eval]") {
  // Ground-truth positions c + d_k, c = (1, 2, 3), d = (1,0,0), (-1,0,0),
  // (0,2,0), (0,-2,0). The estimate lives in a world rotated and shifted by
  // W and is stretched by 10% about the centroid: est_k = W (c + 1.1 d_k).
  // The cross-covariance of the centred sets, 1.1 sum d d^T = diag(2.2, 8.8, 0),
  // is symmetric and positive semi-definite, so the best rotation is the
  // identity (after undoing W) and the centroids coincide: T_gt_est = W^-1 and
  // the errors are 0.1 |d_k| = 0.1, 0.1, 0.2, 0.2 m.
  //   RMSE   = sqrt((0.01 + 0.01 + 0.04 + 0.04) / 4) = sqrt(0.025) = 0.158113883...
  //   mean   = (0.1 + 0.1 + 0.2 + 0.2) / 4 = 0.15
  //   median = (0.1 + 0.2) / 2 = 0.15
  //   max    = 0.2
  std::mt19937 rng(23);
  const SE3d W = random_pose(rng);
  const Vec3d c = vec3(1.0, 2.0, 3.0);
  const std::vector<Vec3d> d = {vec3(1.0, 0.0, 0.0), vec3(-1.0, 0.0, 0.0), vec3(0.0, 2.0, 0.0), vec3(0.0, -2.0, 0.0)};
  Trajectory est, gt;
  for (std::size_t k = 0; k < d.size(); ++k) {
    const double t = 10.0 + 0.5 * double(k);
    // Orientations are arbitrary: ATE compares positions only.
    gt.push_back({t, SE3d(random_pose(rng).rotation(), c + d[k])});
    est.push_back({t + 0.01, W * SE3d(random_pose(rng).rotation(), c + 1.1 * d[k])});
  }
  const AteResult r = absolute_trajectory_error(est, gt);
  CHECK(r.matched == 4);
  CHECK(r.rmse == Approx(std::sqrt(0.025)).epsilon(1e-12));
  CHECK(r.mean == Approx(0.15).epsilon(1e-12));
  CHECK(r.median == Approx(0.15).epsilon(1e-12));
  CHECK(r.max == Approx(0.2).epsilon(1e-12));
  CHECK(pose_difference(r.T_gt_est, W.inverse()) < 1e-9);
}

TEST_CASE("ATE with a similarity alignment undoes a scale difference", "[eval]") {
  // The hand-computed example's estimate, stretched 10 % about its centroid:
  // the rigid fit leaves 0.1 |d_k| of error, the similarity fit none, at scale 1 / 1.1.
  std::mt19937 rng(29);
  const SE3d W = random_pose(rng);
  const Vec3d c = vec3(1.0, 2.0, 3.0);
  const std::vector<Vec3d> d = {vec3(1.0, 0.0, 0.0), vec3(-1.0, 0.0, 0.0), vec3(0.0, 2.0, 0.0), vec3(0.0, -2.0, 0.0),
                                vec3(0.0, 0.0, 0.5)};
  Trajectory est, gt;
  for (std::size_t k = 0; k < d.size(); ++k) {
    const double t = 1.0 + 0.5 * double(k);
    gt.push_back({t, SE3d(SE3d().rotation(), c + d[k])});
    est.push_back({t, W * SE3d(SE3d().rotation(), 1.1 * (c + d[k]))});
  }
  const AteResult rigid = absolute_trajectory_error(est, gt);
  const AteResult similar = absolute_trajectory_error(est, gt, 0.02, Alignment::similarity);
  CHECK(rigid.scale == 1.0);
  CHECK(rigid.rmse > 0.05);
  CHECK(similar.scale == Approx(1.0 / 1.1).epsilon(1e-12));
  CHECK(similar.rmse < 1e-9);
  for (std::size_t k = 0; k < d.size(); ++k)
    CHECK(norm(similar.T_gt_est * (est[k].pose.translation() * similar.scale) - gt[k].pose.translation()) < 1e-9);
}

TEST_CASE("ATE rejects too few matches with a clear message", "[eval]") {
  const Trajectory gt = smooth_trajectory(1.0, 10.0);  // 11 poses at 0, 0.1, ..., 1
  Trajectory est = {gt[0], gt[5], {7.0, SE3d()}};      // only two near a ground-truth time
  CHECK_THROWS_AS(absolute_trajectory_error(est, gt), std::invalid_argument);
  CHECK_THROWS_WITH(absolute_trajectory_error(est, gt),
                    EMF_CONTAINS("absolute_trajectory_error: only 2 of 3 estimated poses match a ground-truth pose "
                                 "(of 11) within 0.02 s; at least 3 are needed"));
  CHECK_THROWS_WITH(ate_of_positions(std::vector<Vec3d>(3), std::vector<Vec3d>(4)),
                    EMF_CONTAINS("ate_of_positions: estimate has 3 positions but ground truth has 4"));
}

TEST_CASE("RPE of a constant drift per second is that drift", "[eval]") {
  const Trajectory gt = smooth_trajectory(4.0, 30.0);  // 121 poses, t = k / 30
  SECTION("translation drift of 0.05 m/s") {
    // est_k = (R_gt_k, p_gt_k + v t_k), v = (0.03, -0.04, 0): over every 1 s
    // window the estimated motion's translation is off by R_i^T v, |v| = 0.05.
    Trajectory est = gt;
    for (TimedPose& p : est) p.pose.translation() += p.timestamp * vec3(0.03, -0.04, 0.0);
    const RpeResult r = relative_pose_error(est, gt);
    // Frames 0..90 have a frame 1 s (30 frames) later; 91..120 would end past 4 s.
    CHECK(r.pairs == 91);
    CHECK(r.translation_rmse == Approx(0.05).epsilon(1e-9));
    CHECK(r.rotation_rmse_deg < 1e-9);
    // A 2 s window sees twice the drift.
    const RpeResult r2 = relative_pose_error(est, gt, 2.0);
    CHECK(r2.pairs == 61);
    CHECK(r2.translation_rmse == Approx(0.10).epsilon(1e-9));
  }
  SECTION("rotation drift of 2 deg/s") {
    // Standing camera: gt_k = G; est_k = G Rz(w t_k), w = 2 deg/s. Then
    // est_i^-1 est_j = Rz(w (t_j - t_i)) = Rz(2 deg) and gt_i^-1 gt_j = I.
    std::mt19937 rng(29);
    const SE3d G = random_pose(rng);
    const double w = 2.0 * 3.14159265358979323846 / 180.0;
    Trajectory still = gt, est = gt;
    for (TimedPose& p : still) p.pose = G;
    for (TimedPose& p : est) p.pose = G * rotation_z(w * p.timestamp);
    const RpeResult r = relative_pose_error(est, still);
    CHECK(r.pairs == 91);
    CHECK(r.rotation_rmse_deg == Approx(2.0).epsilon(1e-9));
    CHECK(r.translation_rmse < 1e-12);
  }
}

TEST_CASE("RPE does not depend on the world frames", "[eval]") {
  std::mt19937 rng(31);
  const Trajectory gt = smooth_trajectory(3.0, 30.0);
  // A noisy, drifting estimate.
  Trajectory est = gt;
  std::normal_distribution<double> noise(0.0, 0.01);
  for (TimedPose& p : est)
    p.pose = p.pose * SE3d::exp(Vec6<double>{{noise(rng) + 0.01 * p.timestamp, noise(rng), noise(rng), noise(rng),
                                              noise(rng), 0.02 * p.timestamp}});
  const RpeResult r = relative_pose_error(est, gt);
  CHECK(r.translation_rmse > 0.005);
  const RpeResult moved_est = relative_pose_error(left_multiplied(random_pose(rng), est), gt);
  const RpeResult moved_gt = relative_pose_error(est, left_multiplied(random_pose(rng), gt));
  for (const RpeResult& m : {moved_est, moved_gt}) {
    CHECK(m.pairs == r.pairs);
    CHECK(m.translation_rmse == Approx(r.translation_rmse).epsilon(1e-9));
    CHECK(m.rotation_rmse_deg == Approx(r.rotation_rmse_deg).epsilon(1e-9));
  }
}

TEST_CASE("RPE uses exactly the documented pairs", "[eval]") {
  // 10 Hz frames k = 0..30 with k = 17..25 missing; tolerance =
  // max(0.02, 0.1 / 2) = 0.05 s. Pairs (k, k + 10): k = 0..6 (targets 10..16
  // exist) and k = 16 (target 26); k = 7..15 target the gap (nearest frame
  // 0.1 s or more away), k = 26..30 would end after the last frame.
  Trajectory gt;
  for (int k = 0; k <= 30; ++k)
    if (k < 17 || k > 25) gt.push_back({double(k) / 10.0, SE3d::translation(vec3(double(k), 0.0, 0.0))});
  // Every pair's estimated motion is 10 cm too long along x (0.01 m per frame).
  Trajectory est = gt;
  for (TimedPose& p : est) p.pose.translation()[0] *= 1.01;
  const RpeResult r = relative_pose_error(est, gt);
  CHECK(r.pairs == 8);
  CHECK(r.translation_rmse == Approx(0.1).epsilon(1e-9));
}

TEST_CASE("RPE rejects bad arguments with clear messages", "[eval]") {
  const Trajectory gt = smooth_trajectory(0.5, 30.0);
  CHECK_THROWS_WITH(relative_pose_error(gt, gt, 0.0),
                    EMF_CONTAINS("relative_pose_error: delta_seconds must be finite and > 0, got 0"));
  CHECK_THROWS_WITH(relative_pose_error(gt, gt),
                    EMF_CONTAINS("relative_pose_error: no pair of matched poses is delta_seconds = 1 s apart "
                                 "(the 16 matched poses span 0.5 s)"));
  CHECK_THROWS_WITH(relative_pose_error({gt[0]}, gt), EMF_CONTAINS("at least 2 are needed"));
}

namespace {

/// Object ATE scene: a moving camera and object in the ground-truth world;
/// the estimate's world is W * (gt world) and its object frame is the true
/// one moved by D. Object positions c + d_k, with d_0 = 0 (the centroid) at
/// the first frame.
struct ObjectScene {
  Trajectory gt_cam, gt_obj, est_cam, est_obj;
  SE3d W, D;
  std::vector<Vec3d> d;

  explicit ObjectScene(std::uint32_t seed) {
    std::mt19937 rng(seed);
    W = random_pose(rng);
    D = random_pose(rng, 3.0, 0.3);
    const Vec3d c = vec3(0.5, -0.3, 2.0);
    d = {Vec3d::zero(),        vec3(1.0, 0.0, 0.0), vec3(-1.0, 0.0, 0.0), vec3(0.0, 2.0, 0.0),
         vec3(0.0, -2.0, 0.0), vec3(0.0, 0.0, 3.0), vec3(0.0, 0.0, -3.0)};
    for (std::size_t k = 0; k < d.size(); ++k) {
      const double t = 100.0 + double(k) / 30.0;
      gt_cam.push_back({t, random_pose(rng)});
      gt_obj.push_back({t, SE3d(random_pose(rng).rotation(), c + d[k])});
      // The estimate's clock runs 4 ms off.
      est_cam.push_back({t + 0.004, W * gt_cam.back().pose});
      est_obj.push_back({t + 0.004, W * gt_obj.back().pose * D});
    }
  }
};

}  // namespace

TEST_CASE("object ATE is zero when only the world and object frames differ", "[eval]") {
  ObjectScene s(41);
  const ObjectAteResult r = object_absolute_trajectory_error(s.est_cam, s.gt_cam, s.est_obj, s.gt_obj);
  CHECK(r.ate.matched == 7);
  CHECK(r.ate.rmse < 1e-9);
  CHECK(r.ate.max < 1e-9);
  CHECK(r.coverage == 1.0);
  CHECK(r.first_common_timestamp == s.gt_obj[0].timestamp);
  CHECK(pose_difference(r.T_estobj_gtobj, s.D.inverse()) < 1e-9);
  CHECK(pose_difference(r.ate.T_gt_est, s.W.inverse()) < 1e-9);

  SECTION("the first common frame is the first with both camera poses") {
    s.est_cam.erase(s.est_cam.begin());    // no estimated camera at frame 0
    s.gt_cam.erase(s.gt_cam.begin() + 1);  // no true camera at frame 1
    const ObjectAteResult later = object_absolute_trajectory_error(s.est_cam, s.gt_cam, s.est_obj, s.gt_obj);
    CHECK(later.first_common_timestamp == s.gt_obj[2].timestamp);
    CHECK(later.ate.matched == 7);
    CHECK(later.ate.rmse < 1e-9);
  }
}

TEST_CASE("object ATE of a known perturbation", "[eval]") {
  // Move the estimated object positions by W (0.01 d_k) (in the estimate's
  // world). Frame 0 (d_0 = 0) is unchanged, so C = D^-1 still and
  // est_obj(t) C = W (c + 1.01 d_k): as in the camera ATE example the best
  // alignment is W^-1 with the centroids matched, and the errors are
  // 0.01 |d_k| = 0, 0.01, 0.01, 0.02, 0.02, 0.03, 0.03 m:
  //   RMSE   = 0.01 sqrt((0 + 1 + 1 + 4 + 4 + 9 + 9) / 7) = 0.01 sqrt(4) = 0.02
  //   mean   = 0.01 (0 + 1 + 1 + 2 + 2 + 3 + 3) / 7 = 0.12 / 7
  //   median = 0.02, max = 0.03
  // The ground truth has an 8th pose the estimate lacks: coverage 7 / 8.
  ObjectScene s(43);
  for (std::size_t k = 0; k < s.d.size(); ++k)
    s.est_obj[k].pose = SE3d::translation(s.W.rotate(0.01 * s.d[k])) * s.est_obj[k].pose;
  s.gt_obj.push_back({s.gt_obj.back().timestamp + 1.0 / 30.0, SE3d::translation(vec3(9.0, 9.0, 9.0))});
  const ObjectAteResult r = object_absolute_trajectory_error(s.est_cam, s.gt_cam, s.est_obj, s.gt_obj);
  CHECK(r.ate.matched == 7);
  CHECK(r.coverage == Approx(7.0 / 8.0).epsilon(1e-15));
  CHECK(r.ate.rmse == Approx(0.02).epsilon(1e-9));
  CHECK(r.ate.mean == Approx(0.12 / 7.0).epsilon(1e-9));
  CHECK(r.ate.median == Approx(0.02).epsilon(1e-9));
  CHECK(r.ate.max == Approx(0.03).epsilon(1e-9));
  CHECK(pose_difference(r.T_estobj_gtobj, s.D.inverse()) < 1e-9);
  CHECK(pose_difference(r.ate.T_gt_est, s.W.inverse()) < 1e-9);
}

TEST_CASE("object ATE rejects unusable input with clear messages", "[eval]") {
  ObjectScene s(47);
  CHECK_THROWS_WITH(object_absolute_trajectory_error(s.est_cam, s.gt_cam, s.est_obj, {}),
                    EMF_CONTAINS("object_absolute_trajectory_error: the ground-truth object trajectory is empty"));
  const Trajectory two(s.est_obj.begin(), s.est_obj.begin() + 2);
  CHECK_THROWS_WITH(object_absolute_trajectory_error(s.est_cam, s.gt_cam, two, s.gt_obj),
                    EMF_CONTAINS("only 2 of 2 estimated object poses match a ground-truth object pose (of 7)"));
  Trajectory late_cam = s.est_cam;
  for (TimedPose& p : late_cam) p.timestamp += 10.0;
  CHECK_THROWS_WITH(object_absolute_trajectory_error(late_cam, s.gt_cam, s.est_obj, s.gt_obj),
                    EMF_CONTAINS("no matched object pose has an estimated and a ground-truth camera pose"));
  CHECK_THROWS_AS(object_absolute_trajectory_error(s.est_cam, {}, s.est_obj, s.gt_obj), std::invalid_argument);
}
