// The system over a sparse background (SystemParams::sparse_background,
// slam/background.hpp): on the simulated room, the camera and the objects as
// with the dense background, on a fraction of its memory; what does not take
// a sparse background yet says so (checkpoints, likelihoods without
// with_volume).
#include <cmath>
#include <optional>
#include <string>

#include "emfusion/eval/ate.hpp"
#include "emfusion/io/checkpoint.hpp"
#include "emfusion/sim/detector.hpp"
#include "emfusion/sim/dynamic_scene.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"
#include "support/files.hpp"
#include "support/system_instances.hpp"

using namespace emfusion;

namespace {

/// The room at 160x120, 24 frames, one moving object, its simulated detector.
const sim::DynamicScene<float>& small_room() {
  static const sim::DynamicScene<float> scene = [] {
    sim::DynamicSceneParams p;
    p.width = 160, p.height = 120, p.frames = 24, p.moving_objects = 1;
    return sim::make_dynamic_room<float>(p);
  }();
  return scene;
}

template <class B>
void run(System<float, B>& system, const sim::DynamicScene<float>& scene) {
  sim::SimulatedDetectorParams dp;
  dp.min_area = int(dp.min_area * double(scene.camera().width) * scene.camera().height / (640.0 * 480.0));
  sim::SimulatedDetector<float> detector(scene, dp);
  for (int f = 0; f < scene.frame_count(); ++f) {
    Image<float, Host> depth;
    scene.render(f, depth);
    const std::optional<Detections> det = detector.detect(f, scene.timestamp(f));
    system.process(depth.template to<B>(), scene.timestamp(f), det ? &*det : nullptr);
  }
}

template <class S>
SystemParams<S> room_params(bool sparse) {
  SystemParams<S> p;
  p.background_voxels = 256;
  p.background_voxel_size = S(0.02);
  p.sparse_background = sparse;
  return p;
}

}  // namespace

TEMPLATE_LIST_TEST_CASE("A sparse background tracks the camera and the objects as the dense one, in less memory",
                        "[slam]", emfusion::test::SystemRuleConfigs) {
  using S = typename TestType::Scalar;  // float: the room renders float depth
  using B = typename TestType::Backend;
  const sim::DynamicScene<float>& scene = small_room();
  const PinholeCamera<S> camera = scene.camera().template cast<S>();
  System<S, B> dense(camera, room_params<S>(false)), sparse(camera, room_params<S>(true));
  REQUIRE(sparse.background().is_sparse());
  REQUIRE_FALSE(dense.background().is_sparse());
  run(dense, scene);
  run(sparse, scene);
  const double ate_dense = eval::absolute_trajectory_error(dense.camera_trajectory(), scene.camera_trajectory()).rmse;
  const double ate_sparse = eval::absolute_trajectory_error(sparse.camera_trajectory(), scene.camera_trajectory()).rmse;
  INFO("camera ATE dense " << ate_dense << " m, sparse " << ate_sparse << " m");
  CHECK(ate_sparse < 0.01);
  CHECK(std::abs(ate_sparse - ate_dense) < 0.003);
  CHECK(sparse.object_records().size() == dense.object_records().size());
  CHECK_FALSE(sparse.objects().empty());
  INFO("background bytes dense " << dense.background().memory_bytes() << ", sparse "
                                 << sparse.background().memory_bytes());
  CHECK(sparse.background().memory_bytes() * 4 < dense.background().memory_bytes());
  CHECK(sparse.background().describe().rfind("sparse, ", 0) == 0);
  CHECK(sparse.background().sparse()->allocated_blocks() > 0);

  // A checkpoint of one kind of background does not go into a system of the
  // other: saying so, the system unchanged (tests/io/test_checkpoint.cpp
  // saves, loads and continues both kinds).
  emfusion::test::ScratchDir dir;
  save_checkpoint(dir.file("s.emfckpt"), sparse);
  save_checkpoint(dir.file("d.emfckpt"), dense);
  const int frames = sparse.frame_count();
  CHECK_THROWS_WITH(restore_checkpoint(sparse, dir.file("d.emfckpt")),
                    EMF_CONTAINS("saved with a dense background of") && EMF_CONTAINS("give a sparse background"));
  CHECK_THROWS_WITH(restore_checkpoint(dense, dir.file("s.emfckpt")),
                    EMF_CONTAINS("saved with a sparse background of") && EMF_CONTAINS("give a dense background"));
  CHECK(sparse.frame_count() == frames);
  CHECK(sparse.background().is_sparse());
}

// A named namespace: in an unnamed one nvcc warns that likelihood() is
// never referenced (the test only constructs the System).
namespace sparse_background_test {

/// A user's likelihood over dense volumes only (no with_volume).
struct DenseOnlyLikelihood {
  TsdfView<float, const float> volume;
  ForegroundView<float, const float> foreground;
  EMF_HD float likelihood(const Vec3<float>& p) const {
    float d;
    return volume.sample(p, d) ? std::exp(-std::fabs(d) / 0.02f) : 0.f;
  }
};

}  // namespace sparse_background_test

using sparse_background_test::DenseOnlyLikelihood;

TEST_CASE("A likelihood that reads dense volumes only refuses a sparse background by name", "[slam]") {
  // At construction, not at the first frame that associates (only the
  // constructor is instantiated here: a whole System of its own took over a
  // minute to compile under the sanitizers).
  const PinholeCamera<float> camera = small_room().camera();
  using DenseOnly = System<float, Host, DenseOnlyLikelihood>;
  CHECK_THROWS_WITH(DenseOnly(camera, room_params<float>(true)),
                    EMF_CONTAINS("System") && EMF_CONTAINS("set sparse_background = false"));
  // The stage itself refuses too, for a loop of the user's own.
  const auto require = [](bool sparse) {
    detail::association::require_sparse_capable<float, DenseOnlyLikelihood>(sparse, "associate");
  };
  CHECK_THROWS_WITH(require(true), EMF_CONTAINS("associate") && EMF_CONTAINS("with_volume"));
  CHECK_NOTHROW(require(false));
  const auto require_paper = [] {
    detail::association::require_sparse_capable<float, PaperLikelihood<float>>(true, "associate");
  };
  CHECK_NOTHROW(require_paper());
}
