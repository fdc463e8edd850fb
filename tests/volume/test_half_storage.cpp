// TsdfVolume with Half storage (16-bit SDF and weight, float compute): the
// same fusion, raycast and sampling code as float storage, and surfaces that
// agree with float storage's to a small fraction of a voxel.
#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "emfusion/core/half.hpp"
#include "emfusion/volume/raycast.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"
#include "support/fusion.hpp"

using namespace emfusion;

TEMPLATE_LIST_TEST_CASE("Half storage fuses and renders the surfaces float storage does", "[volume]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const auto camera = test::small_camera<S>();
  const sim::Scene<S> scene = test::sphere_and_box<S>();
  const auto geometry = test::cube_around<S>(Vec3<S>::zero(), 64, S(0.01));
  const auto poses = test::orbit_poses<S>(Vec3<S>::zero(), S(1.2), 12);
  TsdfVolume<S, B> full(geometry);
  TsdfVolume<S, B, Half> half(geometry);
  CHECK(2 * half.memory_bytes() == full.memory_bytes() * sizeof(float) / sizeof(S));
  test::fuse_views(full, scene, camera, poses);
  test::fuse_views(half, scene, camera, poses);

  const SE3<S> pose = sim::look_at<S>(vec3(S(0.8), S(-0.7), S(0.4)), Vec3<S>::zero(), vec3(S(0), S(0), S(1)));
  const auto [depth_a, depth_b, hit_a, hit_b] = test::raycast_both(full, half, camera, pose);
  std::size_t hits = 0, both = 0;
  double worst = 0;
  for (std::size_t i = 0; i < depth_a.size(); ++i) {
    hits += hit_a[i];
    if (!hit_a[i] || !hit_b[i]) continue;
    ++both;
    worst = std::max(worst, std::fabs(double(depth_a[i]) - double(depth_b[i])));
  }
  INFO("pixels hit by float storage " << hits << ", by both " << both << ", largest depth difference " << worst);
  CHECK(hits > 5000);
  CHECK(both >= hits - hits / 100);  // silhouettes may differ by a pixel
  CHECK(worst < 1e-3);               // a tenth of a voxel

  // Samples agree to half precision in the SDF (|sdf| <= 0.1 m: 2^-14 m steps
  // at most) and in the weight.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> coordinate(0.05, 0.59);
  const auto host_full = full.template to<Host>();
  const auto host_half = half.template to<Host>();
  int samples = 0;
  for (int k = 0; k < 2000; ++k) {
    const Vec3<S> p = vec3(S(coordinate(rng)), S(coordinate(rng)), S(coordinate(rng)));
    S f = 0, h = 0, wf = 0, wh = 0;
    const bool in_f = host_full.view().sample(p, f, &wf), in_h = host_half.view().sample(p, h, &wh);
    REQUIRE(in_f == in_h);
    if (!in_f) continue;
    ++samples;
    CHECK(std::fabs(double(f - h)) < 2e-4);
    CHECK(std::fabs(double(wf - wh)) < 0.05);
  }
  CHECK(samples > 500);
}
