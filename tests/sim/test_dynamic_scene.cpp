// Dynamic synthetic scenes and the simulated detector: trajectories (rest,
// bounded speed, no overlap, on their support), rendered labels against the
// poses, the depth noise model, determinism, visibility, the FrameSource
// adapter, and the detector's schedule, masks and error rates.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <set>
#include <stdexcept>
#include <utility>
#include <vector>

#include "emfusion/io/frame_source.hpp"
#include "emfusion/sim/detector.hpp"
#include "emfusion/sim/dynamic_scene.hpp"
#include "emfusion/sim/render.hpp"
#include "support/catch.hpp"
#include "support/small_room.hpp"
#include "support/configs.hpp"

using namespace emfusion;

namespace {

double angle_between(const SE3<double>& a, const SE3<double>& b) { return norm(so3_log((a.inverse() * b).rotation())); }

/// Lowest world z of a shape posed in the world (rims of cylinders sampled).
double lowest_point(const sim::Shape<double>& s) {
  const SE3<double> T = s.T_shape_world.inverse();
  double z = 1e30;
  switch (s.type) {
    case sim::ShapeType::box:
      for (int c = 0; c < 8; ++c)
        z = std::min(z, (T * vec3(c & 1 ? s.size.x() : -s.size.x(), c & 2 ? s.size.y() : -s.size.y(),
                                  c & 4 ? s.size.z() : -s.size.z()))
                            .z());
      break;
    case sim::ShapeType::sphere:
      z = T.translation().z() - s.size.x();
      break;
    case sim::ShapeType::cylinder:
      for (int i = 0; i < 256; ++i)
        for (double h : {-s.size.y(), s.size.y()})
          z = std::min(z,
                       (T * vec3(s.size.x() * std::cos(i * M_PI / 128), s.size.x() * std::sin(i * M_PI / 128), h)).z());
      break;
    case sim::ShapeType::plane:
      break;
  }
  return z;
}

/// Pixels of `labels` equal to `value`.
template <class T>
std::vector<bool> mask_of(const std::vector<T>& labels, int value) {
  std::vector<bool> m(labels.size());
  for (std::size_t i = 0; i < labels.size(); ++i) m[i] = int(labels[i]) == value;
  return m;
}

double iou(const std::vector<bool>& a, const std::vector<bool>& b) {
  int inter = 0, uni = 0;
  for (std::size_t i = 0; i < a.size(); ++i) inter += a[i] && b[i], uni += a[i] || b[i];
  return uni ? double(inter) / uni : 0.0;
}

int area(const std::vector<bool>& m) { return int(std::count(m.begin(), m.end(), true)); }

}  // namespace

TEST_CASE("make_dynamic_room and DynamicScene reject bad arguments", "[sim]") {
  auto params = test::small_room(3, 10);
  params.moving_objects = -1;
  CHECK_THROWS_WITH(sim::make_dynamic_room<float>(params), EMF_CONTAINS("moving_objects must be in 0..16, got -1"));
  params.moving_objects = 17;
  CHECK_THROWS_WITH(sim::make_dynamic_room<float>(params), EMF_CONTAINS("moving_objects must be in 0..16, got 17"));
  params = test::small_room(3, 10);
  params.camera_path = sim::CameraPath(7);
  CHECK_THROWS_WITH(sim::make_dynamic_room<float>(params),
                    EMF_CONTAINS("camera_path must be hand_held or hand_held_fast, got 7"));
  params = test::small_room(3, 0);
  CHECK_THROWS_WITH(sim::make_dynamic_room<float>(params), EMF_CONTAINS("frames must be >= 1, got 0"));
  params = test::small_room(3, 10);
  params.width = 8;
  CHECK_THROWS_WITH(sim::make_dynamic_room<float>(params),
                    EMF_CONTAINS("image size must be at least 16x16, got 8x120"));
  params = test::small_room(3, 10);
  params.noise.dropout_probability = 2;
  CHECK_THROWS_WITH(sim::make_dynamic_room<float>(params), EMF_CONTAINS("dropout_probability must be in [0, 1]"));

  const auto scene = sim::make_dynamic_room<float>(test::small_room(3, 10));
  CHECK_THROWS_WITH(scene.object_pose(3, 0), EMF_CONTAINS("DynamicScene::object_pose: object 3 is not in 0..2"));
  CHECK_THROWS_WITH(scene.camera_pose(10), EMF_CONTAINS("DynamicScene::camera_pose: frame 10 is not in 0..9"));
  Image<float, Host> depth;
  CHECK_THROWS_WITH(scene.render(-1, depth), EMF_CONTAINS("frame -1 is not in 0..9"));

  // A hand-made scene: every trajectory needs one pose per frame.
  sim::MovingObject<float> ball{
      "ball_1", "sports_ball", {sim::make_sphere(Vec3<float>::zero(), 0.1f)}, {SE3<double>()}};
  CHECK_THROWS_WITH(sim::DynamicScene<float>(PinholeCamera<float>{}, {}, {ball}, {SE3<double>(), SE3<double>()}),
                    EMF_CONTAINS("object 'ball_1' has 1 poses but the camera has 2"));
  ball.shapes.push_back(sim::make_plane(SE3<float>()));
  CHECK_THROWS_WITH(sim::DynamicScene<float>(PinholeCamera<float>{}, {}, {ball}, {SE3<double>()}),
                    EMF_CONTAINS("objects must be bounded"));
  std::vector<sim::Shape<float>> many(50, sim::make_sphere(Vec3<float>::zero(), 1.0f));
  CHECK_THROWS_WITH(sim::DynamicScene<float>(PinholeCamera<float>{}, many, {}, {SE3<double>()}),
                    EMF_CONTAINS("50 shapes do not fit into a Scene (capacity 48)"));
}

TEST_CASE("Objects start at rest, move smoothly within the limits and never overlap", "[sim]") {
  for (int objects : {1, 3, 8}) {
    CAPTURE(objects);
    const auto scene = sim::make_dynamic_room<double>(test::small_room(objects));
    REQUIRE(scene.frame_count() == 300);
    REQUIRE(scene.object_count() == objects);
    CHECK(scene.timestamp(45) == test::Approx(1.5));
    const double dt = 1.0 / 30;
    double total_path = 0;
    for (int k = 0; k < objects; ++k) {
      CAPTURE(k);
      const auto traj = scene.object_trajectory(k);
      REQUIRE(traj.size() == 300u);
      CHECK(traj[30].timestamp == test::Approx(1.0));
      // At rest for the first half second: exactly the first pose.
      for (int f = 1; f < 15; ++f) CHECK(max_abs_diff(traj[f].pose.matrix(), traj[0].pose.matrix()) == 0.0);
      const double z_rest = traj[0].pose.translation().z();
      CHECK(traj[0].pose.rotation()(2, 2) == test::Approx(1.0));  // upright at rest
      double path = 0, max_speed = 0, max_rate = 0;
      int resting = 0;
      for (int f = 1; f < 300; ++f) {
        const SE3<double>& a = traj[f - 1].pose;
        const SE3<double>& b = traj[f].pose;
        const double step = norm(b.translation() - a.translation());
        path += step;
        max_speed = std::max(max_speed, step / dt);
        max_rate = std::max(max_rate, angle_between(a, b) / dt);
        if (step == 0 && angle_between(a, b) == 0) {
          ++resting;
          // Resting objects stand upright on their support.
          CHECK(b.translation().z() == test::Approx(z_rest).margin(1e-12));
          CHECK(b.rotation()(2, 2) == test::Approx(1.0).margin(1e-12));
        }
      }
      CHECK(max_speed <= 0.4);
      CHECK(max_rate <= 60 * M_PI / 180);
      CHECK(path > 0.2);  // it does move (crowded objects less)
      total_path += path;
      CHECK(resting > 60);  // and rests in between
    }
    CHECK(total_path / objects > 0.6);
    // Bounding spheres stay apart, and no shape dips into the support
    // (lifted and tilted objects included).
    std::vector<double> support(std::size_t(objects), 1e30);
    for (int f = 0; f < 300; ++f) {
      const auto world = scene.scene_at(f);
      std::vector<double> low(std::size_t(objects), 1e30);
      for (int s = 0; s < world.count; ++s)
        if (scene.object_of_shape(s) >= 0) {
          double& l = low[std::size_t(scene.object_of_shape(s))];
          l = std::min(l, lowest_point(world.shapes[s]));
        }
      for (int k = 0; k < objects; ++k) {
        if (f == 0) support[std::size_t(k)] = low[std::size_t(k)];
        CHECK(low[std::size_t(k)] >= support[std::size_t(k)] - 1e-6);
        for (int j = 0; j < k; ++j)
          CHECK(norm(scene.object_pose(k, f).translation() - scene.object_pose(j, f).translation()) >=
                scene.object_radius(k) + scene.object_radius(j));
      }
    }
    for (int k = 0; k < objects; ++k) {
      const double s = support[std::size_t(k)];
      CHECK((std::fabs(s) < 1e-6 || std::fabs(s - 0.5) < 1e-6));  // on the floor or on the table
    }
  }

  // The camera: smooth and slow; still when asked.
  auto params = test::small_room(3);
  const auto scene = sim::make_dynamic_room<double>(params);
  const auto camera = scene.camera_trajectory();
  REQUIRE(camera.size() == 300u);
  double max_speed = 0, path = 0;
  for (std::size_t f = 1; f < camera.size(); ++f) {
    const double step = norm(camera[f].pose.translation() - camera[f - 1].pose.translation());
    max_speed = std::max(max_speed, step * 30), path += step;
  }
  CHECK(max_speed <= 0.3);
  CHECK(path > 0.5);
  CHECK(max_abs_diff(camera[7].pose.matrix(), scene.camera_pose(7).matrix()) == 0.0);
  params.moving_camera = false;
  const auto still = sim::make_dynamic_room<double>(params).camera_trajectory();
  CHECK(max_abs_diff(still[299].pose.matrix(), still[0].pose.matrix()) == 0.0);
  CHECK(max_abs_diff(still[0].pose.matrix(), camera[0].pose.matrix()) == 0.0);

  CHECK(scene.object_name(0) == "car_1");
  CHECK(scene.object_name(2) == "book_3");
  CHECK(scene.object_class(1) == "cup");
}

TEMPLATE_LIST_TEST_CASE("Rendered labels agree with the object poses", "[sim]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const auto scene = sim::make_dynamic_room<S>(test::small_room(3, 120));
  const auto& cam = scene.camera();
  CHECK(double(cam.fx) == test::Approx(525.0 * 160 / 640));
  CHECK(double(cam.cx) == test::Approx(79.5));
  CHECK(double(cam.cy) == test::Approx(59.5));
  const double tol = sizeof(S) <= 4 ? 2e-4 : 1e-7;
  for (int f : {0, 60, 119}) {
    CAPTURE(f);
    Image<S, B> depth;
    Image<int, B> labels;
    scene.render(f, depth, &labels, false);
    const auto d = depth.to_host();
    const auto l = labels.to_host();
    const auto world = scene.scene_at(f);
    const SE3<S> T_wc = scene.camera_pose(f);
    std::vector<int> counts(4, 0);
    double worst_object = 0, worst_static = 0;
    for (int v = 0; v < cam.height; ++v)
      for (int u = 0; u < cam.width; ++u) {
        const int i = v * cam.width + u;
        REQUIRE(d[i] > S(0));  // a closed room: every ray hits something
        REQUIRE(l[i] >= 0);
        REQUIRE(l[i] <= 3);
        ++counts[std::size_t(l[i])];
        const Vec3<S> p = T_wc * cam.back_project(S(u), S(v), d[i]);
        // The point lies on a shape of the labelled object (or on a static
        // one for label 0), and inside no shape at all.
        double on = 1e30, inside = 1e30;
        for (int s = 0; s < world.count; ++s) {
          const double dist = double(world.shapes[s].distance(p));
          inside = std::min(inside, dist);
          if (scene.object_of_shape(s) + 1 == l[i]) on = std::min(on, std::fabs(dist));
        }
        double& worst = l[i] > 0 ? worst_object : worst_static;
        worst = std::max(worst, on);
        CHECK(inside > -tol);
      }
    CHECK(worst_object < tol);
    CHECK(worst_static < tol * 10);  // the far walls are 4 m away
    for (int k = 1; k <= 3; ++k) CHECK(counts[std::size_t(k)] > 100);
  }

  // The exact ray caster agrees with the sphere tracer of render.hpp.
  Image<S, B> depth, traced;
  Image<int, B> labels, shapes;
  scene.render(30, depth, &labels, false);
  sim::render_depth(scene.scene_at(30), cam, scene.camera_pose(30), traced, &shapes);
  const auto d = depth.to_host(), t = traced.to_host();
  const auto l = labels.to_host(), s = shapes.to_host();
  int same = 0;
  for (std::size_t i = 0; i < d.size(); ++i)
    same += s[i] >= 0 && std::fabs(double(d[i]) - double(t[i])) < 1e-3 && l[i] == scene.object_of_shape(s[i]) + 1;
  CHECK(same >= int(0.995 * d.size()));
}

TEMPLATE_LIST_TEST_CASE("Depth noise follows the Kinect model", "[sim]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // Camera at the origin looking along +z at a wall 1.5 m away, with a box
  // in front of it whose outline gives depth discontinuities.
  const PinholeCamera<S> cam{S(131.25), S(131.25), S(79.5), S(59.5), 160, 120};
  const auto wall_at = [](double z) {
    return sim::make_plane(sim::look_at(vec3(S(0), S(0), S(z)), Vec3<S>::zero(), vec3(S(0), S(-1), S(0))));
  };
  sim::MovingObject<S> box{
      "box_1",
      "suitcase",
      {sim::make_box(SE3<S>(), vec3(S(0.15), S(0.12), S(0.1)))},
      {SE3<double>::translation(vec3(0.0, 0.0, 1.0)), SE3<double>::translation(vec3(0.05, 0.0, 1.0))}};
  const std::vector<SE3<double>> still(2);
  const sim::DynamicScene<S> scene(cam, {wall_at(1.5)}, {box}, still);

  Image<S, B> clean, noisy, again;
  Image<int, B> labels;
  scene.render(0, clean, &labels, false);
  scene.render(0, noisy, &labels, true);
  scene.render(0, again, nullptr, true);
  const auto c = clean.to_host(), n = noisy.to_host(), n2 = again.to_host();
  CHECK(n == n2);  // deterministic

  // A discontinuity lies between two 4-neighbours whose depths differ by
  // more than 3 cm; a pixel is near it when within 2 px of both (within 2 px
  // of the boundary between them), and far from it when more than 3 px from
  // either.
  const int w = 160, h = 120;
  std::vector<bool> near(c.size(), false), far_from(c.size(), true);
  auto mark = [&](int u0, int v0, int u1, int v1) {
    for (int v = std::max(0, std::min(v0, v1) - 3); v <= std::min(h - 1, std::max(v0, v1) + 3); ++v)
      for (int u = std::max(0, std::min(u0, u1) - 3); u <= std::min(w - 1, std::max(u0, u1) + 3); ++u) {
        const int d0 = std::max(std::abs(u - u0), std::abs(v - v0)), d1 = std::max(std::abs(u - u1), std::abs(v - v1));
        if (d0 <= 2 && d1 <= 2) near[std::size_t(v * w + u)] = true;
        if (std::min(d0, d1) <= 3) far_from[std::size_t(v * w + u)] = false;
      }
  };
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u) {
      const int i = v * w + u;
      if (u + 1 < w && std::fabs(double(c[i]) - double(c[i + 1])) > 0.03) mark(u, v, u + 1, v);
      if (v + 1 < h && std::fabs(double(c[i]) - double(c[i + w])) > 0.03) mark(u, v, u, v + 1);
    }

  int near_count = 0, near_dropped = 0, far_dropped = 0;
  double sum = 0, sum2 = 0;
  int wall = 0, off_grid = 0;
  for (std::size_t i = 0; i < c.size(); ++i) {
    if (near[i]) near_count++, near_dropped += n[i] == S(0);
    if (far_from[i] && n[i] == S(0)) ++far_dropped;
    if (!far_from[i] || n[i] == S(0)) continue;
    // Disparities are multiples of 1/8 px.
    const double disparity = 43.5 / double(n[i]);
    off_grid += std::fabs(disparity * 8 - std::round(disparity * 8)) > 1e-2;
    if (std::fabs(double(c[i]) - 1.5) < 0.05) {
      const double e = double(n[i]) - double(c[i]);
      sum += e, sum2 += e * e, ++wall;
    }
  }
  CHECK(far_dropped == 0);  // dropout only near edges
  REQUIRE(near_count > 300);
  CHECK(double(near_dropped) / near_count == test::Approx(0.3).margin(0.06));
  CHECK(off_grid == 0);
  REQUIRE(wall > 5000);
  const double mean = sum / wall, sd = std::sqrt(sum2 / wall - mean * mean);
  const double sigma = 0.0012 + 0.0019 * (1.5 - 0.4) * (1.5 - 0.4);
  const double step = 1.5 * 1.5 * 0.125 / 43.5;  // depth step of one disparity step
  CHECK(std::fabs(mean) < 3e-4);
  CHECK(sd == test::Approx(std::sqrt(sigma * sigma + step * step / 12)).epsilon(0.15));

  // The noise is fresh every frame and for every seed.
  scene.render(1, again, nullptr, true);
  const auto next = again.to_host();
  int differ = 0;
  for (std::size_t i = 0; i < n.size(); ++i) differ += next[i] != n[i];
  CHECK(differ > int(n.size() / 3));
  const sim::DynamicScene<S> reseeded(cam, {wall_at(1.5)}, {box}, still, sim::DepthNoise{}, 2);
  reseeded.render(0, again, nullptr, true);
  const auto other = again.to_host();
  differ = 0;
  for (std::size_t i = 0; i < n.size(); ++i) differ += other[i] != n[i];
  CHECK(differ > int(n.size() / 3));

  // Beyond 4.5 m the sensor sees nothing; noise-free renders keep the geometry.
  const sim::DynamicScene<S> far(cam, {wall_at(5.0)}, {}, still);
  far.render(0, noisy, nullptr, true);
  far.render(0, clean, nullptr, false);
  const auto fn = noisy.to_host(), fc = clean.to_host();
  CHECK(std::count(fn.begin(), fn.end(), S(0)) == std::ptrdiff_t(fn.size()));
  CHECK(double(fc[60 * 160 + 80]) == test::Approx(5.0).margin(1e-4));
}

TEST_CASE("Dynamic rooms are reproducible from their seed", "[sim]") {
  const auto a = sim::make_dynamic_room<float>(test::small_room(3, 40, 5));
  const auto b = sim::make_dynamic_room<float>(test::small_room(3, 40, 5));
  const auto c = sim::make_dynamic_room<float>(test::small_room(3, 40, 6));
  Image<float, Host> da, db, dc;
  a.render(20, da);
  b.render(20, db);
  c.render(20, dc);
  CHECK(da.to_host() == db.to_host());
  CHECK(da.to_host() != dc.to_host());
  CHECK(max_abs_diff(a.object_pose(1, 39).matrix(), b.object_pose(1, 39).matrix()) == 0.0f);
  CHECK(max_abs_diff(a.object_pose(1, 0).matrix(), c.object_pose(1, 0).matrix()) > 0.01f);
}

TEST_CASE("A static room: no moving objects, only the camera moves", "[sim]") {
  const auto scene = sim::make_dynamic_room<float>(test::small_room(0, 20));
  CHECK(scene.object_count() == 0);
  Image<float, Host> depth;
  Image<int, Host> labels;
  scene.render(10, depth, &labels, false);
  const auto d = depth.to_host();
  const auto l = labels.to_host();
  CHECK(std::count_if(d.begin(), d.end(), [](float z) { return z > 0; }) > int(d.size()) * 9 / 10);
  CHECK(std::all_of(l.begin(), l.end(), [](int k) { return k == 0; }));
  // The static shapes render the same as in a room with objects wherever
  // no object is seen.
  const auto with_objects = sim::make_dynamic_room<float>(test::small_room(3, 20));
  Image<float, Host> depth3;
  Image<int, Host> labels3;
  with_objects.render(10, depth3, &labels3, false);
  const auto d3 = depth3.to_host();
  const auto l3 = labels3.to_host();
  int same = 0, background = 0;
  for (std::size_t i = 0; i < d.size(); ++i)
    if (l3[i] == 0) ++background, same += d[i] == d3[i];
  CHECK(same == background);
  CHECK(max_abs_diff(scene.camera_pose(19).matrix(), with_objects.camera_pose(19).matrix()) == 0.0f);
}

namespace {

/// Linear (m/s) and angular (deg/s) speed of the camera between frames f - 1 and f.
std::pair<double, double> camera_speed(const sim::DynamicScene<float>& scene, int f) {
  const Trajectory t = scene.camera_trajectory();
  const SE3<double>& a = t[std::size_t(f - 1)].pose;
  const SE3<double>& b = t[std::size_t(f)].pose;
  return {norm(b.translation() - a.translation()) * scene.fps(), angle_between(a, b) * scene.fps() * 180 / M_PI};
}

}  // namespace

TEST_CASE("The fast hand-held path: eased fast segments within the stated peaks", "[sim]") {
  auto params = test::small_room(0, 900, 1);
  params.camera_path = sim::CameraPath::hand_held_fast;
  const auto fast = sim::make_dynamic_room<float>(params);
  params.camera_path = sim::CameraPath::hand_held;
  const auto slow = sim::make_dynamic_room<float>(params);
  double v_fast = 0, w_fast = 0, v_slow = 0, w_slow = 0, max_accel = 0;
  int fast_frames = 0, segments = 0, last_fast = -100;
  double v_previous = 0;
  for (int f = 1; f < 900; ++f) {
    const auto [v, w] = camera_speed(fast, f);
    const auto [vs, ws] = camera_speed(slow, f);
    v_fast = std::max(v_fast, v), w_fast = std::max(w_fast, w);
    v_slow = std::max(v_slow, vs), w_slow = std::max(w_slow, ws);
    if (f > 1) max_accel = std::max(max_accel, std::fabs(v - v_previous) * fast.fps());
    v_previous = v;
    // Fast frames more than a second apart belong to different segments.
    if (v > 0.4 || w > 15) {
      ++fast_frames;
      segments += f - last_fast > 30;
      last_fast = f;
    }
  }
  CAPTURE(v_fast, w_fast, v_slow, w_slow, max_accel, fast_frames, segments);
  // The slow path stays slow; the fast one peaks where a real recording's
  // fastest parts do (frame differences at 30 Hz slightly under-read the
  // 0.70-0.85 m/s and 35-42 deg/s of the path itself).
  CHECK(v_slow < 0.25);
  CHECK(w_slow < 5);
  CHECK(v_fast > 0.6);
  CHECK(v_fast < 0.9);
  CHECK(w_fast > 30);
  CHECK(w_fast < 45);
  // Fast segments every few seconds, each a few dozen frames, not the whole path.
  CHECK(segments >= 4);
  CHECK(segments <= 10);
  CHECK(fast_frames < 900 / 3);
  // Eased: no jump in speed between frames. A sin^2 swing peaking at v over
  // a segment of T seconds accelerates at most 2 pi v / T (3.3 m/s^2 for
  // 0.85 m/s in 1.6 s); a 0.4 m/s step between frames would read 12 m/s^2.
  CHECK(max_accel < 4.0);
  // Reproducible from the seed; another seed places the segments elsewhere.
  const auto again = sim::make_dynamic_room<float>([&] {
    auto p = params;
    p.camera_path = sim::CameraPath::hand_held_fast;
    return p;
  }());
  CHECK(max_abs_diff(again.camera_pose(450).matrix(), fast.camera_pose(450).matrix()) == 0.0f);
  auto other = params;
  other.camera_path = sim::CameraPath::hand_held_fast;
  other.seed = 2;
  const auto moved = sim::make_dynamic_room<float>(other);
  double differ = 0;
  for (int f = 0; f < 900; f += 30)
    differ = std::max(differ, double(max_abs_diff(moved.camera_pose(f).matrix(), fast.camera_pose(f).matrix())));
  CHECK(differ > 0.01);
  // The camera stays inside the room, away from the walls, and sees it.
  float max_x = 0, min_y = 0;
  for (int f = 0; f < 900; ++f) {
    const Vec3<float> eye = fast.camera_pose(f).translation();
    max_x = std::max(max_x, std::fabs(eye.x())), min_y = std::min(min_y, eye.y());
  }
  CHECK(max_x < 2.0f);
  CHECK(min_y > -1.8f);
  Image<float, Host> depth;
  for (int f = 0; f < 900; f += 45) {
    fast.render(f, depth, nullptr, false);
    const auto d = depth.to_host();
    CAPTURE(f);
    CHECK(std::count_if(d.begin(), d.end(), [](float z) { return z > 0; }) > int(d.size()) * 9 / 10);
  }
}

TEST_CASE("Every object is visible in most frames", "[sim]") {
  const int w = 160, h = 120;
  const double min_area = 1600.0 * w * h / (640.0 * 480.0);  // 40 x 40 px at 640 x 480
  for (int objects : {1, 3, 8}) {
    CAPTURE(objects);
    const auto scene = sim::make_dynamic_room<float>(test::small_room(objects, 300, 3));
    std::vector<int> visible(std::size_t(objects), 0);
    int frames = 0;
    Image<float, Host> depth;
    Image<int, Host> labels;
    for (int f = 0; f < 300; f += 15, ++frames) {
      scene.render(f, depth, &labels, false);
      const auto l = labels.to_host();
      for (int k = 0; k < objects; ++k) visible[std::size_t(k)] += area(mask_of(l, k + 1)) >= min_area;
    }
    for (int k = 0; k < objects; ++k) {
      CAPTURE(k);
      CHECK(visible[std::size_t(k)] >= frames * 9 / 10);
    }
  }
}

TEST_CASE("SyntheticSequence is a FrameSource of noisy depth", "[sim]") {
  static_assert(FrameSource<sim::SyntheticSequence>);
  const sim::SyntheticSequence sequence(test::small_room(2, 12));
  CHECK(sequence.size() == 12u);
  CHECK(sequence.timestamp(6) == test::Approx(0.2));
  const PinholeCamera<double> cam = sequence.camera();
  CHECK(cam.fx == test::Approx(131.25));
  CHECK(cam.width == 160);
  const Image<float, Host> depth = sequence.depth(3);
  CHECK(depth.same_size(160, 120));
  Image<float, Host> expected;
  sequence.scene().render(3, expected);
  CHECK(depth.to_host() == expected.to_host());
  CHECK_THROWS_WITH(sequence.depth(12), EMF_CONTAINS("frame 12 is not in 0..11"));
}

TEST_CASE("The simulated detector runs every period frames", "[sim]") {
  static_assert(Segmenter<sim::SimulatedDetector<float>>);
  auto params = sim::SimulatedDetectorParams{};
  params.period = 30;
  sim::SimulatedDetector<float> detector(sim::make_dynamic_room<float>(test::small_room(3, 91)), params);
  std::vector<int> ran;
  for (int f = 0; f < 91; ++f)
    if (auto d = detector.detect(f, f / 30.0)) {
      ran.push_back(f);
      CHECK(d->timestamp == test::Approx(f / 30.0));
      CHECK(d->labels.same_size(160, 120));
    }
  CHECK(ran == std::vector<int>{0, 30, 60, 90});
  CHECK_THROWS_WITH(detector.detect(91, 0), EMF_CONTAINS("frame 91 is not in 0..90"));

  params.period = 0;
  CHECK_THROWS_WITH(sim::SimulatedDetector<float>(detector.scene(), params),
                    EMF_CONTAINS("period must be >= 1, got 0"));
  params.period = 30;
  params.miss_probability = 1.5;
  CHECK_THROWS_WITH(sim::SimulatedDetector<float>(detector.scene(), params),
                    EMF_CONTAINS("miss_probability must be in [0, 1], got 1.5"));
}

TEST_CASE("The exact simulated detector reports the ground-truth masks", "[sim]") {
  const auto scene = sim::make_dynamic_room<float>(test::small_room(8, 61));
  sim::SimulatedDetector<float> detector(scene, sim::SimulatedDetectorParams::exact());
  const double min_area = 1600.0 / 16;
  for (int f : {0, 30, 60}) {
    CAPTURE(f);
    const auto d = detector.detect(f, 0);
    REQUIRE(d);
    Image<float, Host> depth;
    Image<int, Host> truth;
    scene.render(f, depth, &truth, false);
    const auto t = truth.to_host();
    const auto l = d->labels.to_host();
    std::vector<int> expected;
    for (int k = 0; k < 8; ++k)
      if (area(mask_of(t, k + 1)) >= min_area) expected.push_back(k + 1);
    std::vector<int> got;
    for (const Instance& i : d->instances) {
      got.push_back(i.label);
      CHECK(i.class_name == scene.object_class(i.label - 1));
      CHECK((i.score >= 0.8 && i.score <= 1.0));
    }
    CHECK(got == expected);
    for (std::size_t i = 0; i < t.size(); ++i) {
      const bool reported = std::find(expected.begin(), expected.end(), t[i]) != expected.end();
      REQUIRE(int(l[i]) == (reported ? t[i] : 0));
    }
  }
}

TEST_CASE("The simulated detector's masks, misses and false positives", "[sim]") {
  const auto scene = sim::make_dynamic_room<float>(test::small_room(8, 24, 2));
  auto params = sim::SimulatedDetectorParams{};
  params.period = 1;
  params.false_positive_probability = 0.25;  // see some in a short run
  sim::SimulatedDetector<float> detector(scene, params);
  const double min_area = 1600.0 / 16;
  int shuffled = 0, false_positives = 0, detected = 0;
  for (int f = 0; f < 24; ++f) {
    CAPTURE(f);
    const auto d = detector.detect(f, 0);
    REQUIRE(d);
    Image<float, Host> depth;
    Image<int, Host> truth;
    scene.render(f, depth, &truth, false);
    const auto t = truth.to_host();
    const auto l = d->labels.to_host();
    std::set<int> labels;
    bool false_positive = false;
    for (const Instance& inst : d->instances) {
      CAPTURE(inst.label, inst.class_name, inst.score);
      labels.insert(inst.label);
      const auto m = mask_of(l, inst.label);
      CHECK(area(m) >= min_area);
      if (inst.score < 0.75) {  // false positives score 0.5-0.7, detections 0.8-1
        CHECK(inst.score >= 0.5);
        false_positive = true;
        continue;
      }
      // A true detection overlaps its object well and carries its class.
      int best = -1;
      double best_iou = 0;
      for (int k = 0; k < 8; ++k)
        if (iou(m, mask_of(t, k + 1)) > best_iou) best_iou = iou(m, mask_of(t, k + 1)), best = k;
      CHECK(best_iou > 0.5);
      REQUIRE(best >= 0);
      CHECK(inst.class_name == scene.object_class(best));
      CHECK(!detector.misses(f, best));
      CHECK(area(mask_of(t, best + 1)) >= min_area);
      shuffled += inst.label != best + 1;
      ++detected;
      // Its pixels on the static background hug the object's outline
      // (dilation by at most (4 + 1.5) / 4 px here).
      for (int i = 0; i < int(t.size()); ++i) {
        if (!m[std::size_t(i)] || t[std::size_t(i)] != 0) continue;
        bool close = false;
        const int u = i % 160, v = i / 160;
        for (int dv = -2; dv <= 2 && !close; ++dv)
          for (int du = -2; du <= 2 && !close; ++du)
            close = u + du >= 0 && u + du < 160 && v + dv >= 0 && v + dv < 120 &&
                    t[std::size_t((v + dv) * 160 + u + du)] == best + 1;
        REQUIRE(close);
      }
    }
    CHECK(false_positive == detector.has_false_positive(f));
    false_positives += false_positive;
    // Labels are 1..n in some order; unlabelled instances have no pixels.
    CHECK(int(labels.size()) == int(d->instances.size()));
    if (!labels.empty()) CHECK((*labels.begin() == 1 && *labels.rbegin() == int(labels.size())));
    for (auto v : l) CHECK((v == 0 || labels.count(int(v)) == 1));
  }
  CHECK(detected > 24 * 5);  // most of the 8 objects are found in most frames
  CHECK(shuffled > 0);
  CHECK(false_positives > 0);

  // The random decisions over many frames match the parameters.
  sim::SimulatedDetector<float> defaults(scene);
  int misses = 0, spurious = 0;
  const int n = 20000;
  for (int f = 0; f < n; ++f) {
    spurious += defaults.has_false_positive(f);
    for (int k = 0; k < 8; ++k) misses += defaults.misses(f, k);
  }
  CHECK(double(misses) / (8.0 * n) == test::Approx(0.1).margin(0.006));
  CHECK(double(spurious) / n == test::Approx(0.05).margin(0.006));

  // Same seed, same detections; another seed, others.
  sim::SimulatedDetector<float> twin(scene, params);
  CHECK(twin.detect(6, 0)->labels.to_host() == detector.detect(6, 0)->labels.to_host());
  params.seed = 99;
  sim::SimulatedDetector<float> other(scene, params);
  CHECK(other.detect(6, 0)->labels.to_host() != detector.detect(6, 0)->labels.to_host());
}

TEST_CASE("The corridor: an 11 m walk no 5 m volume holds, objects that move while the camera passes", "[sim]") {
  sim::DynamicSceneParams p;
  p.layout = sim::SceneLayout::corridor;
  p.frames = 600;
  p.moving_objects = 6;
  p.width = 80, p.height = 60;
  const auto scene = sim::make_dynamic_scene<double>(p);
  REQUIRE(scene.object_count() == 6);
  const Trajectory camera = scene.camera_trajectory();
  double walked = 0, fastest = 0;
  for (std::size_t i = 1; i < camera.size(); ++i) {
    const double step = norm(camera[i].pose.translation() - camera[i - 1].pose.translation());
    walked += step;
    fastest = std::max(fastest, step * 30);
  }
  CHECK(walked > 10.0);
  CHECK(norm(camera.back().pose.translation() - camera.front().pose.translation()) > 10.0);
  CHECK(fastest < 0.8);  // a walk, not a jump
  // Every object moves, never into another, and is seen while it moves.
  Image<double, Host> depth;
  Image<int, Host> labels;
  std::vector<int> seen_moving(6, 0);
  for (int k = 0; k < 6; ++k) {
    const Trajectory a = scene.object_trajectory(k);
    double moved = 0;
    for (std::size_t i = 1; i < a.size(); ++i) moved += norm(a[i].pose.translation() - a[i - 1].pose.translation());
    INFO(scene.object_name(k));
    CHECK(moved > 0.1);
    for (int j = k + 1; j < 6; ++j) {
      const Trajectory b = scene.object_trajectory(j);
      for (std::size_t i = 0; i < a.size(); i += 10)
        CHECK(norm(a[i].pose.translation() - b[i].pose.translation()) > scene.object_radius(k) + scene.object_radius(j));
    }
  }
  for (int f = 1; f < p.frames; f += 5) {
    scene.render(f, depth, &labels, false);
    const std::vector<int> l = labels.to_host();
    for (int k = 0; k < 6; ++k) {
      const Trajectory a = scene.object_trajectory(k);
      const bool moving = norm(a[std::size_t(f)].pose.translation() - a[std::size_t(f) - 1].pose.translation()) > 1e-6;
      if (moving && std::count(l.begin(), l.end(), k + 1) > 20) ++seen_moving[std::size_t(k)];
    }
  }
  for (int k = 0; k < 6; ++k) {
    INFO(scene.object_name(k));
    CHECK(seen_moving[std::size_t(k)] >= 3);
  }
  // The objects are the table kinds, and the layout picks the generator.
  CHECK(scene.object_name(1) == "cup_2");
  p.moving_objects = 7;
  CHECK_THROWS_WITH(sim::make_dynamic_scene<float>(p), EMF_CONTAINS("make_dynamic_corridor: moving_objects must be in 0..6, got 7"));
  p.moving_objects = 2;
  p.frames = 0;
  CHECK_THROWS_WITH(sim::make_dynamic_corridor<float>(p), EMF_CONTAINS("frames must be >= 1, got 0"));
  p.frames = 10;
  p.layout = sim::SceneLayout(7);
  CHECK_THROWS_WITH(sim::make_dynamic_scene<float>(p), EMF_CONTAINS("layout must be room or corridor, got 7"));
}
