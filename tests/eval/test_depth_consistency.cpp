// depth_residuals: a frame agrees with the map fused from other views at its
// true pose, and visibly less at a pose a centimetre off; bad limits are
// refused by name.
#include <cmath>

#include "emfusion/eval/depth_consistency.hpp"
#include "emfusion/preprocess/vertex_map.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"
#include "support/fusion.hpp"

using namespace emfusion;

TEMPLATE_LIST_TEST_CASE("Depth residuals are small at the true pose and grow with a pose error", "[eval]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const auto camera = test::small_camera<S>();
  const sim::Scene<S> scene = test::sphere_and_box<S>();
  TsdfVolume<S, B> volume(test::cube_around<S>(Vec3<S>::zero(), 64, S(0.01)));
  test::fuse_views(volume, scene, camera, test::orbit_poses<S>(Vec3<S>::zero(), S(1.2), 12));

  // A view the map was not fused from.
  const SE3<S> pose = sim::look_at<S>(vec3(S(0.8), S(-0.7), S(0.4)), Vec3<S>::zero(), vec3(S(0), S(0), S(1)));
  Image<S, B> depth;
  sim::render_depth(scene, camera, pose, depth, static_cast<Image<int, B>*>(nullptr), {}, volume.backend());
  Image<Vec3<S>, B> points;
  back_project(depth, camera, points);

  const eval::DepthResiduals at_truth = eval::depth_residuals(volume, points, pose, S(0.05), S(0.005));
  const SE3<S> off = SE3<S>::translation(vec3(S(0.01), S(0), S(0))) * pose;
  const eval::DepthResiduals at_offset = eval::depth_residuals(volume, points, off, S(0.05), S(0.005));
  INFO("true pose: " << at_truth.points << " points, mean " << at_truth.mean_abs() << " m, rms " << at_truth.rms()
                     << ", within 5 mm " << at_truth.share_within() << "; 1 cm off: " << at_offset.points
                     << " points, mean " << at_offset.mean_abs() << " m, within 5 mm " << at_offset.share_within());
  CHECK(at_truth.points > 5000);
  CHECK(at_truth.mean_abs() < 0.001);  // clean depth: a tenth of a voxel
  CHECK(at_truth.rms() >= at_truth.mean_abs());
  CHECK(at_truth.share_within() > 0.99);
  CHECK(at_offset.mean_abs() > 0.003);
  CHECK(at_offset.share_within() < 0.9);

  // Sums merge frame by frame.
  eval::DepthResiduals both = at_truth;
  both += at_offset;
  CHECK(both.points == at_truth.points + at_offset.points);
  CHECK(both.mean_abs() > at_truth.mean_abs());

  CHECK_THROWS_WITH(eval::depth_residuals(volume, points, pose, S(0), S(0.005)),
                    EMF_CONTAINS("depth_residuals: max_abs must be a positive number of metres, got 0"));
  CHECK_THROWS_WITH(eval::depth_residuals(volume, points, pose, S(0.05), S(-1)),
                    EMF_CONTAINS("depth_residuals: near must be a positive number of metres, got -1"));
}

TEST_CASE("Empty depth residuals report zeros, not NaN", "[eval]") {
  const eval::DepthResiduals none;
  CHECK(none.mean_abs() == 0.0);
  CHECK(none.rms() == 0.0);
  CHECK(none.share_within() == 0.0);
}
