// Tests of depth preprocessing: bilateral filter, back-projection, normals and
// depth pyramids, on every scalar and backend, against synthetic planes whose
// true depth and normal are known analytically.
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "support/catch.hpp"
#include "support/configs.hpp"

#include "emfusion/core/camera.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/preprocess/bilateral_filter.hpp"
#include "emfusion/preprocess/normal_map.hpp"
#include "emfusion/preprocess/pyramid.hpp"
#include "emfusion/preprocess/vertex_map.hpp"

namespace {

using namespace emfusion;

constexpr double kPi = 3.14159265358979323846;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// A 640x480-like camera shrunk to 80x60 (same field of view) to keep the CPU
// tests fast.
template <class S>
PinholeCamera<S> small_camera() {
  PinholeCamera<S> c;
  c.fx = S(75), c.fy = S(75), c.cx = S(39.5), c.cy = S(29.5);
  c.width = 80, c.height = 60;
  return c;
}

/// Host depth values (double, so ground truth is exact) into an image on B.
template <class S, class B>
Image<S, B> make_depth(int width, int height, const std::vector<double>& metres) {
  std::vector<S> pixels(metres.begin(), metres.end());
  return Image<S, Host>::from_host(width, height, pixels).template to<B>();
}

/// The plane {p : dot(normal, p) = offset} (normal unit, facing the camera
/// when offset < 0) seen through `camera`: depth z at every pixel.
std::vector<double> plane_depth(const PinholeCamera<double>& camera, const Vec3d& normal, double offset) {
  std::vector<double> depth(std::size_t(camera.pixel_count()));
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x)
      depth[std::size_t(y * camera.width + x)] = offset / dot(normal, camera.ray(x, y));
  return depth;
}

std::vector<double> with_noise(std::vector<double> depth, double sigma, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, sigma);
  for (double& d : depth) d += noise(rng);
  return depth;
}

double rms_error(const std::vector<double>& values, double truth) {
  double sum = 0;
  for (double v : values) sum += (v - truth) * (v - truth);
  return std::sqrt(sum / double(values.size()));
}

/// True if f throws std::invalid_argument whose message contains `text`.
/// (Catch2 v2 and v3 name their string matchers differently, so no matchers.)
template <class F>
bool throws_invalid_argument_mentioning(F&& f, const std::string& text) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    UNSCOPED_INFO("std::invalid_argument: " << e.what());
    return std::string(e.what()).find(text) != std::string::npos;
  }
  UNSCOPED_INFO("no std::invalid_argument thrown");
  return false;
}

template <class S>
double angle_degrees(const Vec3<S>& a, const Vec3d& b) {
  const Vec3d ad = a.template cast<double>();
  const double c = dot(ad, b) / (norm(ad) * norm(b));
  return std::acos(std::clamp(c, -1.0, 1.0)) * 180.0 / kPi;
}

}  // namespace

TEMPLATE_LIST_TEST_CASE("bilateral filter keeps a constant plane", "[preprocess]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const int w = 80, h = 60;
  const auto depth = make_depth<S, B>(w, h, std::vector<double>(std::size_t(w * h), 1.5));
  Image<S, B> out;
  bilateral_filter(depth, out);
  REQUIRE(out.same_size(w, h));
  for (S d : out.to_host()) REQUIRE(std::fabs(double(d) - 1.5) <= 1.5 * test::eps_for<S>());
}

TEMPLATE_LIST_TEST_CASE("bilateral filter reduces noise on a fronto-parallel plane", "[preprocess]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const int w = 80, h = 60;
  const double truth = 1.5, sigma = 0.01;
  const auto noisy = with_noise(std::vector<double>(std::size_t(w * h), truth), sigma, 7);
  const auto depth = make_depth<S, B>(w, h, noisy);
  Image<S, B> out;
  bilateral_filter(depth, out);
  const auto filtered = out.to_host();
  const double before = rms_error(noisy, truth);
  const double after = rms_error(std::vector<double>(filtered.begin(), filtered.end()), truth);
  const double reduction = before / after;
  INFO("depth rms error " << before << " m -> " << after << " m, reduction x" << reduction);
  CHECK(reduction >= 2.0);
}

TEMPLATE_LIST_TEST_CASE("bilateral filter preserves a depth step", "[preprocess]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const int w = 80, h = 60, step_x = 40;  // columns < step_x are near, the rest 0.5 m further
  const double near = 1.0, far = 1.5;
  std::vector<double> truth(std::size_t(w * h));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) truth[std::size_t(y * w + x)] = x < step_x ? near : far;
  const auto depth = make_depth<S, B>(w, h, with_noise(truth, 0.003, 11));
  Image<S, B> out;
  bilateral_filter(depth, out);
  const auto filtered = out.to_host();
  double worst = 0;
  for (int y = 0; y < h; ++y)
    for (int x : {step_x - 3, step_x - 2, step_x - 1, step_x, step_x + 1, step_x + 2}) {
      const std::size_t i = std::size_t(y * w + x);
      worst = std::max(worst, std::fabs(double(filtered[i]) - truth[i]));
    }
  INFO("largest error within 3 px of the step: " << worst << " m");
  CHECK(worst <= 0.01);
}

TEMPLATE_LIST_TEST_CASE("bilateral filter keeps holes and ignores them", "[preprocess]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const int w = 20, h = 16;
  // A plane so close that a hole read as depth 0 would carry real weight
  // (exp(-0.05^2 / (2 0.04^2)) ~ 0.46) and pull its neighbours toward 0; NaN
  // and inf holes would poison any sum they entered.
  const double plane = 0.05;
  std::vector<double> values(std::size_t(w * h), plane);
  const std::vector<int> holes = {5 * w + 5, 5 * w + 6, 8 * w + 10, 12 * w + 3, 0, w * h - 1};
  const std::vector<double> hole_values = {0.0, kNaN, kInf, -1.0, -kInf, 0.0};
  for (std::size_t k = 0; k < holes.size(); ++k) values[std::size_t(holes[k])] = hole_values[k];
  const auto depth = make_depth<S, B>(w, h, values);
  Image<S, B> out;
  bilateral_filter(depth, out);
  const auto filtered = out.to_host();
  for (int i = 0; i < w * h; ++i) {
    const bool hole = std::find(holes.begin(), holes.end(), i) != holes.end();
    INFO("pixel " << i);
    if (hole)
      CHECK(filtered[std::size_t(i)] == S(0));
    else
      CHECK(std::fabs(double(filtered[std::size_t(i)]) - plane) <= plane * test::eps_for<S>());
  }
}

TEMPLATE_LIST_TEST_CASE("bilateral filter in place equals out of place", "[preprocess]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const int w = 32, h = 24;
  auto depth = make_depth<S, B>(w, h, with_noise(std::vector<double>(std::size_t(w * h), 2.0), 0.01, 3));
  Image<S, B> out;
  bilateral_filter(depth, out);
  bilateral_filter(depth, depth);
  CHECK(depth.to_host() == out.to_host());
}

TEMPLATE_TEST_CASE("the host's row filter equals the per-pixel kernel and the exact weights", "[preprocess]", float,
                   double) {
  using S = TestType;
  // Wider than two of the row filter's chunks and not a multiple of one,
  // holes of every kind, radii up to past the image's height.
  const int w = 2 * detail::BilateralRow<S>::chunk + 37, h = 6;
  std::vector<double> values = with_noise(std::vector<double>(std::size_t(w * h), 1.5), 0.03, 11);
  for (int i = 0; i < w * h; i += 13) values[std::size_t(i)] = std::vector<double>{0.0, kNaN, kInf, -2.0}[(i / 13) % 4];
  for (int x = 0; x < w; x += 40) values[std::size_t(2 * w + x)] = 0.4;  // depth steps
  const Image<S, Host> depth = make_depth<S, Host>(w, h, values);
  for (const int radius : {0, 1, 3, 7}) {
    BilateralParams<S> params;
    params.radius = radius;
    Image<S, Host> by_rows;
    bilateral_filter(depth, by_rows, params);
    Image<S, Host> by_pixels(w, h, S(0), Host{});
    const S ks = S(-1) / (S(2) * params.sigma_space * params.sigma_space);
    const S kd = S(-1) / (S(2) * params.sigma_depth * params.sigma_depth);
    const detail::BilateralKernel<S> kernel{depth.view(), by_pixels.view(), ks, kd, radius};
    for (int i = 0; i < w * h; ++i) kernel(i);
    const auto rows = std::as_const(by_rows).view(), pixels = std::as_const(by_pixels).view();
    const auto in = depth.view();
    int different = 0;
    double worst = 0;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        different += rows(x, y) != pixels(x, y);
        // The exact filter, in double with std::exp.
        const double c = double(in(x, y));
        double sum = 0, sum_w = 0;
        if (!is_valid_depth(c)) continue;
        for (int v = std::max(0, y - radius); v <= std::min(h - 1, y + radius); ++v)
          for (int u = std::max(0, x - radius); u <= std::min(w - 1, x + radius); ++u) {
            const double d = double(in(u, v));
            if (!is_valid_depth(d)) continue;
            const double wt = std::exp(double((u - x) * (u - x) + (v - y) * (v - y)) * double(ks) +
                                       (d - c) * (d - c) * double(kd));
            sum += wt * d, sum_w += wt;
          }
        worst = std::max(worst, std::fabs(double(rows(x, y)) - sum / sum_w));
      }
    INFO("radius " << radius << ": " << different << " pixels differ, worst error " << worst << " m");
    CHECK(different == 0);  // the same weights summed in the same order
    CHECK(worst <= (sizeof(S) == 4 ? 5e-6 : 1e-12));  // metres, at 1.5 m: float rounding of the sums
  }
}

TEMPLATE_LIST_TEST_CASE("back_project then project gives the pixel back", "[preprocess]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const auto camera = small_camera<S>();
  const int w = camera.width, h = camera.height;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> range(0.3, 6.0);
  std::vector<double> values(std::size_t(w * h));
  for (double& d : values) d = range(rng);
  values[17] = 0.0, values[300] = kNaN, values[999] = -2.0;
  const auto depth = make_depth<S, B>(w, h, values);
  Image<Vec3<S>, B> vertices;
  back_project(depth, camera, vertices);
  REQUIRE(vertices.same_size(w, h));
  const auto points = vertices.to_host();
  double worst_pixel = 0, worst_depth = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y * w + x);
      if (i == 17 || i == 300 || i == 999) {
        CHECK_FALSE(is_valid(points[i]));
        CHECK(std::isnan(points[i].z()));
        continue;
      }
      REQUIRE(is_valid(points[i]));
      const Vec2<S> uv = camera.project(points[i]);
      worst_pixel = std::max({worst_pixel, std::fabs(double(uv.x()) - x), std::fabs(double(uv.y()) - y)});
      worst_depth = std::max(worst_depth, std::fabs(double(points[i].z()) - double(S(values[i]))));
    }
  INFO("largest reprojection error " << worst_pixel << " px");
  CHECK(worst_pixel <= 100 * test::eps_for<S>());
  CHECK(worst_depth == 0.0);
}

TEMPLATE_LIST_TEST_CASE("normals of a tilted plane match the plane and face the camera", "[preprocess]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const auto camera = small_camera<S>();
  const int w = camera.width, h = camera.height;
  // About 36 degrees from the optical axis; offset < 0 puts the normal toward
  // the camera (dot(n, p) = -1.5 on the plane).
  const Vec3d plane_normal = normalized(vec3(0.6, -0.4, -1.0));
  const auto depth = make_depth<S, B>(w, h, plane_depth(camera.template cast<double>(), plane_normal, -1.5));
  Image<Vec3<S>, B> vertices, normals;
  back_project(depth, camera, vertices);
  compute_normals(vertices, normals);
  const auto n = normals.to_host();
  const auto p = vertices.to_host();
  double worst_angle = 0;
  int valid = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y * w + x);
      const bool border = x == 0 || y == 0 || x == w - 1 || y == h - 1;
      if (border) {
        CHECK_FALSE(is_valid(n[i]));
        continue;
      }
      REQUIRE(is_valid(n[i]));
      ++valid;
      CHECK(std::fabs(double(norm(n[i])) - 1.0) <= 10 * test::eps_for<S>());
      CHECK(dot(n[i], p[i]) < S(0));
      worst_angle = std::max(worst_angle, angle_degrees(n[i], plane_normal));
    }
  INFO("largest normal error " << worst_angle << " degrees over " << valid << " pixels");
  CHECK(valid == (w - 2) * (h - 2));
  CHECK(worst_angle <= 1.0);
}

TEMPLATE_LIST_TEST_CASE("normals are invalid at holes and depth discontinuities", "[preprocess]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const auto camera = small_camera<S>();
  const int w = camera.width, h = camera.height, step_x = 40, hole_x = 20, hole_y = 30;
  std::vector<double> values(std::size_t(w * h));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) values[std::size_t(y * w + x)] = x < step_x ? 1.0 : 1.5;
  values[std::size_t(hole_y * w + hole_x)] = 0.0;
  const auto depth = make_depth<S, B>(w, h, values);
  Image<Vec3<S>, B> vertices, normals;
  back_project(depth, camera, vertices);
  compute_normals(vertices, normals);
  const auto n = normals.to_host();
  for (int y = 1; y < h - 1; ++y)
    for (int x = 1; x < w - 1; ++x) {
      const bool at_step = x == step_x - 1 || x == step_x;
      const bool at_hole = std::abs(x - hole_x) + std::abs(y - hole_y) <= 1;
      const Vec3<S> ni = n[std::size_t(y * w + x)];
      INFO("pixel " << x << "," << y);
      if (at_step || at_hole) {
        CHECK_FALSE(is_valid(ni));
      } else {
        REQUIRE(is_valid(ni));
        CHECK(angle_degrees(ni, vec3(0.0, 0.0, -1.0)) <= 1e-3);
      }
    }
}

TEMPLATE_LIST_TEST_CASE("compute_normals in place equals out of place", "[preprocess]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const auto camera = small_camera<S>();
  const auto depth = make_depth<S, B>(
      camera.width, camera.height, plane_depth(camera.template cast<double>(), normalized(vec3(0.2, 0.3, -1.0)), -2.0));
  Image<Vec3<S>, B> vertices, normals;
  back_project(depth, camera, vertices);
  compute_normals(vertices, normals);
  compute_normals(vertices, vertices);
  const auto a = normals.to_host(), b = vertices.to_host();
  for (std::size_t i = 0; i < a.size(); ++i) {
    REQUIRE(is_valid(a[i]) == is_valid(b[i]));
    if (is_valid(a[i])) REQUIRE(max_abs_diff(a[i], b[i]) == S(0));
  }
}

TEMPLATE_LIST_TEST_CASE("downsample_depth halves a plane consistently with the scaled camera", "[preprocess]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const auto camera = small_camera<S>();
  const Vec3d plane_normal = normalized(vec3(-0.3, 0.5, -1.0));
  const double offset = -2.0;
  const auto depth =
      make_depth<S, B>(camera.width, camera.height, plane_depth(camera.template cast<double>(), plane_normal, offset));
  Image<S, B> half;
  downsample_depth(depth, half);
  const auto level = camera.scaled(S(0.5));
  REQUIRE(half.same_size(level.width, level.height));
  const auto values = half.to_host();
  double worst = 0;
  for (int y = 0; y < level.height; ++y)
    for (int x = 0; x < level.width; ++x) {
      const S d = values[std::size_t(y * level.width + x)];
      REQUIRE(d > S(0));
      const Vec3d p = level.back_project(S(x), S(y), d).template cast<double>();
      worst = std::max(worst, std::fabs(dot(plane_normal, p) - offset));
    }
  // Averaging z (not 1/z) over a block is off by a second-order term only.
  INFO("largest distance of a level-1 point from the plane: " << worst << " m");
  CHECK(worst <= 1e-3);
}

TEMPLATE_LIST_TEST_CASE("downsample_depth skips holes and keeps the near side of an edge", "[preprocess]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // Blocks (2x2, row by row): all valid; one hole; all holes; straddling a
  // 0.5 m edge; within tolerance (averaged); odd last column and row dropped.
  const int w = 11, h = 3;
  // clang-format off
  const std::vector<double> values = {
      1.0, 1.1, 2.0, 0.0, 0.0, kNaN, 1.0, 1.5, 2.00, 2.10, 9.0,
      1.5, 1.2, 2.0, 2.3, 0.0, -1.0, 1.0, 1.5, 2.04, 2.06, 9.0,
      9.0, 9.0, 9.0, 9.0, 9.0, 9.0,  9.0, 9.0, 9.0,  9.0,  9.0};
  // clang-format on
  const auto depth = make_depth<S, B>(w, h, values);
  Image<S, B> half;
  downsample_depth(depth, half);
  REQUIRE(half.same_size(5, 1));
  const auto out = half.to_host();
  const double tol = 1e-5;
  CHECK(std::fabs(double(out[0]) - 1.05) <= tol);  // 1.2 and 1.5 lie too far behind 1.0
  CHECK(std::fabs(double(out[1]) - 2.0) <= tol);   // hole skipped; 2.3 beyond 0.12 m
  CHECK(out[2] == S(0));                           // nothing valid
  CHECK(std::fabs(double(out[3]) - 1.0) <= tol);   // near side of the edge
  CHECK(std::fabs(double(out[4]) - 2.05) <= tol);  // all four within 0.12 m
  downsample_depth(depth, half, S(1));
  CHECK(std::fabs(double(half.to_host()[0]) - 1.2) <= tol);  // a looser bound averages all four
  auto in_place = depth;
  downsample_depth(in_place, in_place);
  CHECK(in_place.to_host() == out);
}

TEMPLATE_LIST_TEST_CASE("preprocessing rejects bad arguments", "[preprocess]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const auto camera = small_camera<S>();
  const Image<S, B> empty;
  const auto depth =
      make_depth<S, B>(camera.width, camera.height, std::vector<double>(std::size_t(camera.pixel_count()), 1.0));
  Image<S, B> out;
  Image<Vec3<S>, B> vertices, normals;

  CHECK_THROWS_AS(bilateral_filter(empty, out), std::invalid_argument);
  CHECK(throws_invalid_argument_mentioning([&] { bilateral_filter(empty, out); }, "bilateral_filter"));
  BilateralParams<S> params;
  params.sigma_depth = S(0);
  CHECK(throws_invalid_argument_mentioning([&] { bilateral_filter(depth, out, params); }, "sigma_depth"));
  params = {};
  params.sigma_space = S(-1);
  CHECK(throws_invalid_argument_mentioning([&] { bilateral_filter(depth, out, params); }, "sigma_space"));
  params = {};
  params.sigma_depth = std::numeric_limits<S>::quiet_NaN();
  CHECK_THROWS_AS(bilateral_filter(depth, out, params), std::invalid_argument);
  params = {};
  params.radius = -1;
  CHECK(throws_invalid_argument_mentioning([&] { bilateral_filter(depth, out, params); }, "radius"));

  CHECK(throws_invalid_argument_mentioning([&] { back_project(empty, camera, vertices); }, "back_project"));
  const auto wrong_size = make_depth<S, B>(camera.width / 2, camera.height,
                                           std::vector<double>(std::size_t(camera.pixel_count() / 2), 1.0));
  CHECK_THROWS_AS(back_project(wrong_size, camera, vertices), std::invalid_argument);
  CHECK(throws_invalid_argument_mentioning([&] { back_project(wrong_size, camera, vertices); }, "40x60"));
  auto bad_camera = camera;
  bad_camera.fx = S(0);
  CHECK_THROWS_AS(back_project(depth, bad_camera, vertices), std::invalid_argument);

  CHECK(throws_invalid_argument_mentioning([&] { compute_normals(Image<Vec3<S>, B>{}, normals); }, "compute_normals"));
  back_project(depth, camera, vertices);
  NormalParams<S> normal_params;
  normal_params.max_relative_depth_jump = S(0);
  CHECK_THROWS_AS(compute_normals(vertices, normals, normal_params), std::invalid_argument);

  CHECK(throws_invalid_argument_mentioning([&] { downsample_depth(empty, out); }, "downsample_depth"));
  CHECK_THROWS_AS(downsample_depth(make_depth<S, B>(1, 4, std::vector<double>(4, 1.0)), out), std::invalid_argument);
  CHECK_THROWS_AS(downsample_depth(depth, out, S(-0.1)), std::invalid_argument);

  // Nothing above touched the outputs' sizes before failing.
  CHECK(out.empty());
  CHECK(normals.empty());
}

TEST_CASE("float and double preprocessing agree", "[preprocess]") {
  const auto camera_d = small_camera<double>();
  const auto camera_f = small_camera<float>();
  const int w = camera_d.width, h = camera_d.height;
  const auto values = with_noise(plane_depth(camera_d, normalized(vec3(0.4, 0.2, -1.0)), -1.8), 0.004, 19);
  std::vector<double> with_holes = values;
  for (int i = 0; i < w * h; i += 37) with_holes[std::size_t(i)] = 0.0;

  const auto depth_d = make_depth<double, Host>(w, h, with_holes);
  const auto depth_f = make_depth<float, Host>(w, h, with_holes);
  Image<double> filtered_d, half_d;
  Image<float> filtered_f, half_f;
  Image<Vec3d> vertices_d, normals_d;
  Image<Vec3f> vertices_f, normals_f;
  bilateral_filter(depth_d, filtered_d);
  bilateral_filter(depth_f, filtered_f);
  back_project(filtered_d, camera_d, vertices_d);
  back_project(filtered_f, camera_f, vertices_f);
  compute_normals(vertices_d, normals_d);
  compute_normals(vertices_f, normals_f);
  downsample_depth(filtered_d, half_d);
  downsample_depth(filtered_f, half_f);

  const auto fd = filtered_d.to_host();
  const auto ff = filtered_f.to_host();
  double worst_depth = 0;
  for (std::size_t i = 0; i < fd.size(); ++i) worst_depth = std::max(worst_depth, std::fabs(fd[i] - double(ff[i])));
  const auto nd = normals_d.to_host();
  const auto nf = normals_f.to_host();
  double worst_angle = 0;
  for (std::size_t i = 0; i < nd.size(); ++i) {
    REQUIRE(is_valid(nd[i]) == is_valid(nf[i]));
    if (is_valid(nd[i])) worst_angle = std::max(worst_angle, angle_degrees(nf[i], nd[i]));
  }
  const auto hd = half_d.to_host();
  const auto hf = half_f.to_host();
  double worst_half = 0;
  for (std::size_t i = 0; i < hd.size(); ++i) worst_half = std::max(worst_half, std::fabs(hd[i] - double(hf[i])));
  INFO("float vs double: depth " << worst_depth << " m, normals " << worst_angle << " deg, level 1 " << worst_half
                                 << " m");
  CHECK(worst_depth <= 1e-5);
  CHECK(worst_angle <= 0.05);
  CHECK(worst_half <= 1e-5);
}
