// Downstream smoke test of the installed emfusion package: SE3 exp/log round
// trip, a host reduction over an image, an EXR round trip through
// emfusion::io (whose OpenEXR, when the library was built with it, the
// package config must find again; without it, the error that says so), a
// JSON document through emfusion::io (nlohmann-json, which the package config
// must find too: NaN written as null), and a few frames of the full system with a likelihood and a robust norm
// defined here, as a user's own. Where the package has emfusion::opencv and
// OpenCV is here (CONSUMER_WITH_OPENCV), the system's frames go through
// cv::Mat as a camera driver's would (16-bit depth, a label Mat) and a Mat
// header over an image is checked to share its pixels. Exits non-zero on a
// wrong result.
#include <algorithm>
#include <cstdint>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include <emfusion/core/image.hpp>
#include <emfusion/core/parallel.hpp>
#include <emfusion/core/se3.hpp>
#include <emfusion/io/exr.hpp>
#include <emfusion/io/run_outputs.hpp>
#include <emfusion/sim/primitives.hpp>
#include <emfusion/sim/render.hpp>
#include <emfusion/slam/system.hpp>

#ifndef CONSUMER_WITH_OPENCV
#define CONSUMER_WITH_OPENCV 0
#endif
#if CONSUMER_WITH_OPENCV
#include <emfusion/interop/opencv.hpp>
#endif

namespace {

/// The user's likelihood: a box-shaped inlier band of `band` metres around
/// the surface, times p_fg, over a constant outlier level.
struct BandLikelihood {
  emfusion::TsdfView<float, const float> volume;
  emfusion::ForegroundView<float, const float> foreground;
  float band = 0.03f;
  EMF_HD float likelihood(const emfusion::Vec3<float>& p) const {
    if (!volume.contains_point(p)) return 0.0f;
    float sdf = 0.0f;
    if (!volume.sample(p, sdf)) sdf = volume.truncation;
    const float fg = foreground.empty() ? 1.0f : foreground.probability(p);
    return (std::fabs(sdf) < band ? 1.0f / band : 0.0f) * fg + 1.0f;
  }
};

/// The user's norm: L1 (weight 1 / |r|), bounded at tiny residuals.
struct L1Norm {
  float eps = 0.01f;
  EMF_HD float cost(float r) const { return std::fabs(r); }
  EMF_HD float weight(float r) const { return 1.0f / std::max(std::fabs(r), eps); }
};

/// Five frames of a wall, a floor and a ball with the camera sliding 5 mm a
/// frame, the ball detected in the first: returns the number of failures.
int run_system() {
  using namespace emfusion;
  const PinholeCamera<float> camera{100, 100, 39.5f, 29.5f, 80, 60};
  sim::Scene<float> scene;
  scene.add(sim::make_plane(sim::look_at(vec3(0.f, 0.f, 2.f), Vec3<float>::zero(), vec3(0.f, -1.f, 0.f))));
  scene.add(sim::make_plane(sim::look_at(vec3(0.f, 0.5f, 0.f), Vec3<float>::zero(), vec3(0.f, 0.f, 1.f))));
  scene.add(sim::make_sphere(vec3(0.1f, 0.25f, 1.3f), 0.25f));
  SystemParams<float> params;
  // BandLikelihood reads dense volumes only (no with_volume member): it runs
  // with the paper's dense cube, not the default sparse background.
  params.sparse_background = false;
  params.background_voxels = 96;
  params.background_voxel_size = 0.03f;
  System<float, Host, BandLikelihood, L1Norm, L1Norm> system(camera, params);
  int failures = 0;
  for (int k = 0; k < 5; ++k) {
    const SE3<float> pose = SE3<float>::translation(vec3(0.005f * float(k), 0.f, 0.f));
    Image<float, Host> depth;
    Image<int, Host> labels;
    sim::render_depth(scene, camera, pose, depth, &labels);
    Detections det;
    std::vector<std::uint16_t> ball;
    for (int l : labels.to_host()) ball.push_back(std::uint16_t(l == 2 ? 1 : 0));
    det.labels = Image<std::uint16_t, Host>::from_host(camera.width, camera.height, ball);
    det.instances.push_back({1, "sports_ball", 0.9});
#if CONSUMER_WITH_OPENCV
    // The frame as a driver would give it: 16-bit depth (5000 per metre) and
    // the detector's label image as Mats, turned back by the interop.
    const cv::Mat raw = opencv::depth_to_mat(depth, 5000);
    depth = opencv::depth_from_mat(raw, 5000);
    det = opencv::detections_from_labels(opencv::to_mat(det.labels), det.instances, k / 30.0);
#endif
    const FrameResult r = system.process(depth, k / 30.0, k == 0 ? &det : nullptr);
    const double error = double(norm(system.camera_pose().translation() - pose.translation()));
    if (k > 0 && (r.camera_tracking != TrackingOutcome::tracked || !(error < 0.01))) {
      std::fprintf(stderr, "consumer: frame %d: camera %s, %g m from the truth\n", k, to_string(r.camera_tracking),
                   error);
      ++failures;
    }
  }
  if (system.objects().size() != 1) {
    std::fprintf(stderr, "consumer: %zu objects, expected the ball\n", system.objects().size());
    ++failures;
  }
  return failures;
}

}  // namespace

#ifndef EMFUSION_HAS_OPENEXR
#define EMFUSION_HAS_OPENEXR 0
#endif

int main() {
  int failures = 0;

  // SE3: log(exp(xi)) == xi for a generic tangent vector.
  const emfusion::SE3d::Tangent xi{{0.1, -0.2, 0.3, 0.4, -0.5, 0.6}};
  const emfusion::SE3d::Tangent back = emfusion::SE3d::exp(xi).log();
  double max_err = 0.0;
  for (int i = 0; i < 6; ++i) max_err = std::max(max_err, std::abs(back[i] - xi[i]));
  if (!(max_err < 1e-9)) {
    std::fprintf(stderr, "consumer: SE3 exp/log round trip error %g (expected < 1e-9)\n", max_err);
    ++failures;
  }

  // Image + transform_reduce_index on the host backend.
  const int width = 64, height = 48;
  std::vector<float> pixels(std::size_t(width) * height);
  double expected = 0.0;
  for (std::size_t i = 0; i < pixels.size(); ++i) {
    pixels[i] = float(i % 7);
    expected += pixels[i];
  }
  const auto image = emfusion::Image<float, emfusion::Host>::from_host(width, height, pixels);
  const emfusion::ImageView<const float> view = image.view();
  const double sum = emfusion::transform_reduce_index(
      image.backend(), view.size(), [view](int i) { return double(view[i]); }, 0.0, std::plus<double>());
  if (sum != expected) {
    std::fprintf(stderr, "consumer: transform_reduce_index sum %g, expected %g\n", sum, expected);
    ++failures;
  }

  // EXR through emfusion::io.
  const std::string exr = (std::filesystem::temp_directory_path() / "emfusion-consumer-depth.exr").string();
  try {
    emfusion::write_exr(exr, image);
    const bool same = emfusion::read_exr(exr).to_host() == pixels;
    std::filesystem::remove(exr);
    if (!same || !EMFUSION_HAS_OPENEXR) {
      std::fprintf(stderr, "consumer: EXR round trip %s\n", same ? "worked without OpenEXR" : "changed the pixels");
      ++failures;
    }
  } catch (const std::runtime_error& e) {
    if (EMFUSION_HAS_OPENEXR || std::string(e.what()).find("no OpenEXR support") == std::string::npos) {
      std::fprintf(stderr, "consumer: EXR round trip failed: %s\n", e.what());
      ++failures;
    }
  }

  // JSON through emfusion::io (nlohmann-json): keys in order, NaN as null.
  {
    emfusion::Json json;
    json["status"] = "finished";
    json["rpe_rmse_m_per_s"] = std::nan("");
    const std::string text = emfusion::json_text(json);
    if (text != "{\n  \"status\": \"finished\",\n  \"rpe_rmse_m_per_s\": null\n}\n") {
      std::fprintf(stderr, "consumer: unexpected JSON text: %s", text.c_str());
      ++failures;
    }
  }

#if CONSUMER_WITH_OPENCV
  // A Mat header over the image shares its pixels, and views back to them.
  auto shared = emfusion::Image<float, emfusion::Host>::from_host(width, height, pixels);
  const cv::Mat header = emfusion::opencv::mat_view(shared);
  if (emfusion::opencv::view<const float>(header).data != shared.view().data || header.at<float>(1, 2) != pixels[66]) {
    std::fprintf(stderr, "consumer: opencv::mat_view does not share the image's pixels\n");
    ++failures;
  }
#endif

  failures += run_system();

  if (failures == 0)
    std::printf("consumer: ok (SE3 round trip error %g, image sum %g, EXR, JSON, 5 system frames with a user's likelihood and norm%s)\n",
                max_err, sum, CONSUMER_WITH_OPENCV ? ", frames through cv::Mat" : "");
  return failures == 0 ? 0 : 1;
}
