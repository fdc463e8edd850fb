// The synthetic sensor: analytic distances of each primitive, look_at
// orientation, and rendered depth and labels against closed-form values.
#include <cmath>
#include <stdexcept>

#include "emfusion/sim/primitives.hpp"
#include "emfusion/sim/render.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"

using namespace emfusion;

TEMPLATE_LIST_TEST_CASE("Primitive distances are exact", "[sim]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  const double eps = sizeof(S) <= 4 ? 1e-5 : 1e-12;
  const auto sphere = sim::make_sphere(vec3(S(1), S(0), S(0)), S(0.5));
  CHECK(double(sphere.distance(vec3(S(3), S(0), S(0)))) == test::Approx(1.5).margin(eps));
  CHECK(double(sphere.distance(vec3(S(1), S(0), S(0)))) == test::Approx(-0.5).margin(eps));

  const auto box = sim::make_box(SE3<S>::translation(vec3(S(0), S(0), S(1))), vec3(S(1), S(2), S(3)));
  CHECK(double(box.distance(vec3(S(2), S(0), S(1)))) == test::Approx(1.0).margin(eps));      // face
  CHECK(double(box.distance(vec3(S(2), S(3), S(1)))) == test::Approx(std::sqrt(2.0)).margin(eps));  // edge
  CHECK(double(box.distance(vec3(S(0.5), S(0), S(1)))) == test::Approx(-0.5).margin(eps));   // inside

  // Rotated box: 90 degrees about z swaps the x and y extents.
  const auto rotated = sim::make_box(SE3<S>::exp(Vec6<S>{{0, 0, 0, 0, 0, S(M_PI / 2)}}), vec3(S(1), S(2), S(3)));
  CHECK(double(rotated.distance(vec3(S(3), S(0), S(0)))) == test::Approx(1.0).margin(10 * eps));

  const auto cylinder = sim::make_cylinder(SE3<S>::identity(), S(0.5), S(1));
  CHECK(double(cylinder.distance(vec3(S(1), S(0), S(0)))) == test::Approx(0.5).margin(eps));  // side
  CHECK(double(cylinder.distance(vec3(S(0), S(0), S(1.5)))) == test::Approx(0.5).margin(eps));  // cap
  CHECK(double(cylinder.distance(vec3(S(0), S(0), S(0)))) == test::Approx(-0.5).margin(eps));

  const auto floor = sim::make_plane(SE3<S>::translation(vec3(S(0), S(0), S(-1))));
  CHECK(double(floor.distance(vec3(S(5), S(5), S(1)))) == test::Approx(2.0).margin(eps));

  sim::Scene<S> scene;
  scene.add(sphere);
  const int box_label = scene.add(box);
  int nearest = -1;
  CHECK(double(scene.distance(vec3(S(0), S(0), S(-2.5)), &nearest)) == test::Approx(0.5).margin(eps));
  CHECK(nearest == box_label);
  CHECK_THROWS_AS(sim::make_sphere(Vec3<S>::zero(), S(0)), std::invalid_argument);
}

TEMPLATE_LIST_TEST_CASE("look_at points the optical axis at the target", "[sim]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  const SE3<S> pose = sim::look_at(vec3(S(1), S(2), S(3)), vec3(S(1), S(5), S(3)), vec3(S(0), S(0), S(1)));
  const Vec3<S> ahead = pose * vec3(S(0), S(0), S(3));
  CHECK(double(max_abs_diff(ahead, vec3(S(1), S(5), S(3)))) < 1e-5);
  // Image "down" (+y) is world "down" (-z).
  CHECK(double(pose.rotate(vec3(S(0), S(1), S(0))).z()) == test::Approx(-1.0));
  CHECK_THROWS_AS(sim::look_at(Vec3<S>::zero(), vec3(S(0), S(0), S(1)), vec3(S(0), S(0), S(2))),
                  std::invalid_argument);
}

TEMPLATE_LIST_TEST_CASE("Rendered depth and labels match closed-form values", "[sim]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // Camera at the origin looking along +z at a wall 2 m away and a sphere.
  const PinholeCamera<S> camera{S(100), S(100), S(39.5), S(29.5), 80, 60};
  sim::Scene<S> scene;
  const int wall = scene.add(sim::make_plane(sim::look_at(vec3(S(0), S(0), S(2)), Vec3<S>::zero(),
                                                          vec3(S(0), S(-1), S(0)))));
  const int ball = scene.add(sim::make_sphere(vec3(S(0.3), S(0), S(1)), S(0.1)));
  Image<S, B> depth;
  Image<int, B> labels;
  sim::render_depth(scene, camera, SE3<S>::identity(), depth, &labels);
  const auto d = depth.to_host();
  const auto l = labels.to_host();
  // A wall pixel: depth is the wall's z exactly.
  CHECK(double(d[5 * 80 + 5]) == test::Approx(2.0).margin(1e-4));
  CHECK(l[5 * 80 + 5] == wall);
  // The sphere's centre projects to u = 39.5 + 100 * 0.3 = 69.5: pixel 69
  // sees the sphere's front, about 0.1 m before its centre.
  const int i = 29 * 80 + 69;
  const double x = (69 - 39.5) / 100, y = (29 - 29.5) / 100;
  // Ray (x, y, 1) t meets |p - c| = r: solve the quadratic.
  const double a = x * x + y * y + 1, b = -2 * (0.3 * x + 1.0), c = 0.3 * 0.3 + 1.0 - 0.01;
  const double t = (-b - std::sqrt(b * b - 4 * a * c)) / (2 * a);
  CHECK(l[i] == ball);
  CHECK(double(d[i]) == test::Approx(t).margin(1e-4));
}
