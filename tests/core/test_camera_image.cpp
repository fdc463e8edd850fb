// Pinhole projection and back-projection, images across backends, the
// parallel primitives, and pixel boxes (projected_box, for_each_pixel_in,
// for_each_pixel_tiled), for every scalar and backend.
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>
#include <vector>

#include "emfusion/core/camera.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/core/pixel_box.hpp"
#include "emfusion/core/se3.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"

using namespace emfusion;

namespace {
template <class S>
struct BackProjectThenProject {
  PinholeCamera<S> camera;
  ImageView<Vec2<S>> out;
  EMF_HD void operator()(int i) const {
    const int u = i % camera.width, v = i / camera.width;
    const S depth = S(0.5) + S(0.01) * S(i % 97);
    out[i] = camera.project(camera.back_project(S(u), S(v), depth));
  }
};

/// Marks pixel i.
struct Mark {
  ImageView<int> out;
  EMF_HD void operator()(int i) const { out[i] += 1; }
};

struct Square {
  EMF_HD double operator()(int i) const { return double(i) * double(i); }
};
struct Plus {
  EMF_HD double operator()(double a, double b) const { return a + b; }
};

/// p[i] = value; p[i] *= factor; p[i] read as a double (the lanes' test).
struct SetTo {
  float* p;
  float value;
  EMF_HD void operator()(int i) const { p[i] = value; }
};
struct ScaleBy {
  float* p;
  float factor;
  EMF_HD void operator()(int i) const { p[i] *= factor; }
};
struct ReadAt {
  const float* p;
  EMF_HD double operator()(int i) const { return double(p[i]); }
};
}  // namespace

TEMPLATE_LIST_TEST_CASE("Work on lanes between fork and join follows the base queue and precedes what comes after",
                        "[core]", emfusion::test::AllConfigs) {
  using B = typename TestType::Backend;
  const B backend{};
  ConcurrentLanes<B> lanes;
  const int n = 1 << 18, count = 4;
  typename B::template Vector<float> data(std::size_t(n) * count, 0.0f);
  float* p = thrust::raw_pointer_cast(data.data());
  for (int round = 1; round <= 3; ++round) {
    // The base queue sets every value; each lane scales its quarter; the
    // base queue sums. Out of order, a lane would scale old values or the
    // sum would read unscaled ones.
    for_each_index(backend, n * count, SetTo{p, float(round)});
    lanes.fork(backend, std::size_t(count));
    for (int k = 0; k < count; ++k)
      for_each_index(lanes.lane(std::size_t(k), backend), n, ScaleBy{p + std::size_t(k) * n, float(k + 2)});
    lanes.join(backend, std::size_t(count));
    const double sum = transform_reduce_index(backend, n * count, ReadAt{p}, 0.0, Plus{});
    double expected = 0;
    for (int k = 0; k < count; ++k) expected += double(n) * round * (k + 2);
    INFO("round " << round);
    CHECK(sum == expected);
  }
}

TEMPLATE_LIST_TEST_CASE("Camera back-projection and projection are inverse", "[core]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const PinholeCamera<S> camera{S(585), S(580), S(320), S(240), 64, 48};
  Image<Vec2<S>, B> out(camera.width, camera.height, Vec2<S>::zero());
  for_each_index(out.backend(), out.size(), BackProjectThenProject<S>{camera, out.view()});
  const auto px = out.to_host();
  double worst = 0;
  for (int i = 0; i < out.size(); ++i) {
    worst = std::fmax(worst, std::fabs(double(px[i].x()) - i % camera.width));
    worst = std::fmax(worst, std::fabs(double(px[i].y()) - i / camera.width));
  }
  CHECK(worst < (sizeof(S) <= 4 ? 1e-3 : 1e-9));

  // A point on the optical axis projects to the principal point.
  const auto c = camera.project(vec3(S(0), S(0), S(2)));
  CHECK(double(c.x()) == test::Approx(320.0));
  CHECK(double(c.y()) == test::Approx(240.0));
  // Depth is z: the back-projected point has the given z.
  CHECK(double(camera.back_project(S(10), S(20), S(1.5)).z()) == test::Approx(1.5));
}

TEST_CASE("Camera validation and scaling", "[core]") {
  PinholeCamera<double> bad{0.0, 525.0, 319.5, 239.5, 640, 480};
  CHECK_THROWS_AS(bad.validate(), std::invalid_argument);
  PinholeCamera<double> empty{525.0, 525.0, 319.5, 239.5, 0, 480};
  CHECK_THROWS_WITH(empty.validate("test"), EMF_CONTAINS("image size must be positive"));
  const PinholeCamera<double> full{};
  const auto half = full.scaled(0.5);
  CHECK(half.width == 320);
  CHECK(half.height == 240);
  // The image corner maps to the corner: pixel edges, not centres, scale.
  CHECK(half.cx == test::Approx(159.5));
  CHECK(half.fx == test::Approx(262.5));
}

TEMPLATE_LIST_TEST_CASE("Images copy between backends and reduce", "[core]", emfusion::test::AllConfigs) {
  using B = typename TestType::Backend;
  std::vector<float> pixels(12 * 7);
  for (std::size_t i = 0; i < pixels.size(); ++i) pixels[i] = float(i) * 0.5f;
  const auto host = Image<float, Host>::from_host(12, 7, pixels);
  const Image<float, B> there = host.template to<B>();
  CHECK(there.width() == 12);
  CHECK(there.height() == 7);
  CHECK(there.to_host() == pixels);
  const auto back = there.template to<Host>();
  CHECK(back.view()(3, 2) == pixels[2 * 12 + 3]);

  const B backend{};
  const double sum = transform_reduce_index(backend, 1000, Square{}, 0.0, Plus{});
  CHECK(sum == test::Approx(999.0 * 1000.0 * 1999.0 / 6.0));
  // Empty ranges return the initial value.
  CHECK(transform_reduce_index(backend, 0, Square{}, 5.0, Plus{}) == 5.0);

  CHECK_THROWS_AS((Image<float, Host>::from_host(3, 3, std::vector<float>(8))), std::invalid_argument);
  CHECK_THROWS_AS((Image<float, B>{-1, 3}), std::invalid_argument);
}

TEST_CASE("inside_border keeps the pixels at least `border` from every edge", "[core]") {
  const ImageView<const int> view{nullptr, 7, 5};
  int inside = 0;
  for (int i = 0; i < view.size(); ++i) {
    const int x = i % 7, y = i / 7;
    CHECK(view.inside_border(i, 0));
    CHECK(view.inside_border(i, 1) == (x >= 1 && y >= 1 && x <= 5 && y <= 3));
    inside += view.inside_border(i, 2);
  }
  CHECK(inside == 3);  // the middle row's three middle pixels
}

TEST_CASE("projected_box holds every pixel a box can project to, and little more", "[core]") {
  using S = double;
  const PinholeCamera<S> camera;  // 640x480, f = 525
  const Vec3<S> lo = Vec3<S>::zero(), hi = vec3(S(0.4), S(0.3), S(0.5));
  // Box poses in the camera: ahead, off to a side (partly outside the
  // image), turned, and far.
  const std::vector<SE3<S>> poses{
      SE3<S>::translation(vec3(S(-0.2), S(-0.15), S(1))),
      SE3<S>::translation(vec3(S(0.6), S(0.1), S(0.9))),
      SE3<S>::exp(Vec6<S>{{-0.1, 0.0, 1.2, 0.3, -0.5, 0.2}}),
      SE3<S>::translation(vec3(S(0), S(0), S(6)))};
  for (const SE3<S>& T : poses) {
    const PixelBox box = projected_box(camera, T, lo, hi);
    REQUIRE_FALSE(box.empty());
    CHECK(box.x0 >= 0);
    CHECK(box.y0 >= 0);
    CHECK(box.x1 <= camera.width);
    CHECK(box.y1 <= camera.height);
    // Every point of the box (a 21^3 lattice, corners included) that lands
    // on a pixel lands inside; the extremes lie within 3 pixels of the edges.
    int u_min = 1 << 30, u_max = -1, v_min = 1 << 30, v_max = -1;
    bool all_inside = true;
    for (int i = 0; i <= 20; ++i)
      for (int j = 0; j <= 20; ++j)
        for (int k = 0; k <= 20; ++k) {
          const Vec3<S> p = T * vec3(hi.x() * i / 20, hi.y() * j / 20, hi.z() * k / 20);
          const Vec2<S> uv = camera.project(p);
          const int u = int(std::floor(uv.x() + 0.5)), v = int(std::floor(uv.y() + 0.5));
          u_min = std::min(u_min, u), u_max = std::max(u_max, u);
          v_min = std::min(v_min, v), v_max = std::max(v_max, v);
          if (camera.contains(uv.x(), uv.y())) all_inside = all_inside && box.contains(u, v);
        }
    CHECK(all_inside);
    CHECK(std::max(u_min, 0) - box.x0 <= 3);
    CHECK(std::max(v_min, 0) - box.y0 <= 3);
    CHECK(box.x1 - 1 - std::min(u_max, camera.width - 1) <= 3);
    CHECK(box.y1 - 1 - std::min(v_max, camera.height - 1) <= 3);
  }
  // A box reaching behind the camera may cover any pixel; one wholly off to
  // a side covers none.
  const PixelBox around = projected_box(camera, SE3<S>::translation(vec3(S(-0.2), S(-0.15), S(-0.1))), lo, hi);
  CHECK((around.x0 == 0 && around.y0 == 0 && around.x1 == camera.width && around.y1 == camera.height));
  CHECK(projected_box(camera, SE3<S>::translation(vec3(S(5), S(0), S(1))), lo, hi).empty());
}

TEMPLATE_LIST_TEST_CASE("for_each_pixel_tiled visits every pixel once; a warp's pixels are one 8 x 4 patch", "[core]",
                        emfusion::test::AllConfigs) {
  using B = typename TestType::Backend;
  // Image sizes with partial tiles on either side, and none at all.
  for (const auto& [w, h] : {std::pair{37, 29}, std::pair{16, 16}, std::pair{1, 1}, std::pair{40, 3}}) {
    Image<int, B> marks(w, h, 0, B{});
    for_each_pixel_tiled(B{}, w, h, Mark{marks.view()});
    for_each_pixel_tiled<3>(B{}, w, h, Mark{marks.view()});
    for_each_pixel_tiled(B{}, 0, h, Mark{marks.view()});  // nothing
    const std::vector<int> m = marks.to_host();
    CHECK(std::count(m.begin(), m.end(), 2) == w * h);
  }
  // The mapping itself: every pixel of a tile from one thread, each warp a
  // compact patch.
  std::vector<int> seen(PixelTiles::threads * 4, 0);
  bool compact = true;
  for (int tile_x = 0; tile_x < 2; ++tile_x)
    for (int tile_y = 0; tile_y < 2; ++tile_y)
      for (int warp = 0; warp < PixelTiles::threads / 32; ++warp) {
        int u_min = 1 << 30, u_max = -1, v_min = 1 << 30, v_max = -1;
        for (int lane = 0; lane < 32; ++lane) {
          int u, v;
          PixelTiles::pixel_of(tile_x, tile_y, warp * 32 + lane, u, v);
          REQUIRE((u >= tile_x * 16 && u < tile_x * 16 + 16 && v >= tile_y * 16 && v < tile_y * 16 + 16));
          seen[std::size_t(v * 32 + u)] += 1;
          u_min = std::min(u_min, u), u_max = std::max(u_max, u), v_min = std::min(v_min, v), v_max = std::max(v_max, v);
        }
        compact = compact && u_max - u_min == PixelTiles::warp_w - 1 && v_max - v_min == PixelTiles::warp_h - 1;
      }
  CHECK(compact);
  CHECK(std::count(seen.begin(), seen.end(), 1) == int(seen.size()));
}

TEMPLATE_LIST_TEST_CASE("for_each_pixel_in visits each pixel of a box once and no other", "[core]",
                        emfusion::test::AllConfigs) {
  using B = typename TestType::Backend;
  Image<int, B> marks(13, 9, 0, B{});
  const PixelBox box{3, 2, 11, 7};
  for_each_pixel_in(B{}, box, marks.width(), Mark{marks.view()});
  for_each_pixel_in(B{}, PixelBox{5, 5, 5, 8}, marks.width(), Mark{marks.view()});  // empty
  const std::vector<int> m = marks.to_host();
  int wrong = 0;
  for (int v = 0; v < 9; ++v)
    for (int u = 0; u < 13; ++u) wrong += m[std::size_t(v * 13 + u)] != (box.contains(u, v) ? 1 : 0);
  CHECK(wrong == 0);
  CHECK(box.grown(5, 1, 13, 9).x0 == 0);
  CHECK(box.grown(5, 1, 13, 9).x1 == 13);
  CHECK(box.grown(5, 1, 13, 9).y0 == 1);
  CHECK(box.grown(5, 1, 13, 9).y1 == 8);
}
