// Pinhole projection and back-projection, images across backends, and the
// parallel primitives, for every scalar and backend.
#include <cmath>
#include <stdexcept>
#include <vector>

#include "emfusion/core/camera.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/parallel.hpp"
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

struct Square {
  EMF_HD double operator()(int i) const { return double(i) * double(i); }
};
struct Plus {
  EMF_HD double operator()(double a, double b) const { return a + b; }
};
}  // namespace

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
