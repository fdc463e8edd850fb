// Camera tracking on real Kinect data (the first 40 frames of redkitchen_300,
// read from shared/data; skipped when absent): the loop of
// examples/track_camera.cpp at a size CI affords, on every backend. With the
// long simulated runs (label integration, release build only): under the
// sanitizers its 40 integrations of a 256^3 volume took 96 s of one core.
#include <filesystem>

#include "emfusion/eval/ate.hpp"
#include "emfusion/io/tum.hpp"
#include "emfusion/preprocess/bilateral_filter.hpp"
#include "emfusion/preprocess/vertex_map.hpp"
#include "emfusion/solve/sdf_alignment.hpp"
#include "emfusion/volume/integrate.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"

using namespace emfusion;

TEMPLATE_LIST_TEST_CASE("The camera tracker follows a real Kinect sequence", "[integration][solve]",
                        emfusion::test::AllBackends) {
  using S = float;
  using B = TestType;
  const std::string dir = std::string(EMFUSION_SHARED_DATA_DIR) + "/redkitchen_300";
  if (!std::filesystem::exists(dir + "/depth.txt")) {
    WARN("skipped: " << dir << " not found (shared data is not part of the repository)");
    return;
  }
  const TumSequence seq = TumSequence::open(dir);
  const auto camera = seq.camera().cast<S>();
  VolumeGeometry<S> g;
  g.dims = Vec3i{{256, 256, 256}};
  g.voxel_size = S(0.02);
  g.T_world_volume = volume_pose_in_front_of(SE3<S>::identity(), S(5.12));
  TsdfVolume<S, B> volume(g);
  SdfAlignmentParams<S> align;
  align.pixel_stride = 2;

  Image<S, B> filtered;
  Image<Vec3<S>, B> points;
  SE3<S> T;
  Trajectory estimate;
  int converged = 0;
  const int frames = 40;
  for (int i = 0; i < frames; ++i) {
    const auto depth = seq.depth(i).template to<B>();
    bilateral_filter(depth, filtered);
    back_project(filtered, camera, points);
    SolveReport report;
    if (i > 0) {
      T = align_to_volume(volume, points, static_cast<const Image<S, B>*>(nullptr), T,
                          HuberNorm<S>{S(2) * volume.voxel_size()}, align, LevenbergMarquardtParams{}, &report);
      converged += report.converged();
    }
    integrate(volume, depth, camera, T);
    estimate.push_back({seq.timestamp(i), T.cast<double>()});
  }
  const auto ate = eval::absolute_trajectory_error(estimate, *seq.ground_truth());
  INFO("ATE over " << frames << " frames: " << ate.rmse * 100 << " cm");
  CHECK(converged == frames - 1);
  CHECK(ate.rmse < 0.01);  // measured 0.33 cm (CPU and H200)
}
