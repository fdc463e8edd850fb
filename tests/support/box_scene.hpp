// Test fixture of the whole-system rule tests (tests/slam/test_system_rules.cpp,
// test_lost_objects.cpp, test_hidden_objects.cpp): a wall with a box in
// front of it seen by a small camera, detections made from the rendered
// labels, parameters for small frames, a system that saw the first frame,
// and the camera pans that lose the box and come back to it.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "emfusion/sim/primitives.hpp"
#include "emfusion/sim/render.hpp"
#include "support/catch.hpp"
#include "support/system_instances.hpp"

namespace emfusion::test {

/// A wall 2 m ahead and a box 0.8 m in front of it, seen by a 160x120 camera
/// (`scale` 2: 320x240). With `slats`, six slats 3 cm from the wall, level
/// and upright, spread over 3.4 m and clear of where the box stands or is
/// moved to (shapes 2-7, never detected): a bare wall leaves the camera
/// free to slide along it, and once the box moved while out of view
/// nothing else in the frame holds it (a pan back over the bare wall slid
/// 16-25 cm on the CPU, 30 cm on a GPU, each way its own).
template <class S>
struct BoxScene {
  PinholeCamera<S> camera;
  sim::Scene<S> scene;
  /// `turn`: a rotation of the box about its centre (in the world frame).
  explicit BoxScene(const Vec3<S>& box_center = vec3(S(0), S(0), S(1.2)), int scale = 1, bool slats = false,
                    const Mat3<S>& turn = Mat3<S>::identity())
      : camera{S(140 * scale), S(140 * scale), S(80 * scale - 0.5), S(60 * scale - 0.5), 160 * scale, 120 * scale} {
    scene.add(sim::make_plane(sim::look_at(vec3(S(0), S(0), S(2)), Vec3<S>::zero(), vec3(S(0), S(-1), S(0)))));
    scene.add(
        sim::make_box(SE3<S>(turn * so3_exp(vec3(S(0.2), S(0.4), S(0))), box_center), vec3(S(0.15), S(0.1), S(0.12))));
    const double slat_x[6] = {-1.2, -0.65, 0.55, 1.1, 1.65, 2.2};
    for (int k = 0; slats && k < 6; ++k) {
      const Vec3<S> at = vec3(S(slat_x[k]), k % 2 ? S(0.3) : S(-0.3), S(1.97));
      const Vec3<S> half = k % 3 == 1 ? vec3(S(0.03), S(0.22), S(0.04)) : vec3(S(0.22), S(0.03), S(0.04));
      scene.add(sim::make_box(SE3<S>::translation(at), half));
    }
  }
  template <class B>
  Image<S, B> depth(const SE3<S>& T_world_camera, Image<int, Host>* labels = nullptr) const {
    Image<S, Host> d;
    sim::render_depth(scene, camera, T_world_camera, d, labels);
    return d.template to<B>();
  }
};

/// Detections from rendered labels: shape `shape` becomes instance 5 of
/// `class_name`; an empty class_name gives "ran and found nothing".
inline Detections detections_of(const Image<int, Host>& labels, int shape, const std::string& class_name,
                                double timestamp) {
  Detections d;
  d.timestamp = timestamp;
  std::vector<std::uint16_t> px;
  for (int l : labels.to_host()) px.push_back(std::uint16_t(!class_name.empty() && l == shape ? 5 : 0));
  d.labels = Image<std::uint16_t, Host>::from_host(labels.width(), labels.height(), px);
  if (!class_name.empty()) d.instances.push_back({5, class_name, 0.95});
  return d;
}

/// Parameters for 160x120 frames: a 128^3 background of 2.5 cm (the pixel
/// thresholds scale with the image by themselves: 1600 px at 640x480 is
/// 100 px here).
template <class S>
SystemParams<S> small_params() {
  SystemParams<S> p;
  p.background_voxels = 128;
  p.background_voxel_size = S(0.025);
  return p;
}

/// A system that processed the box scene's first frame (the box at
/// `box_center`) with a detection of the box as `class_name`.
template <class S, class B>
struct FirstFrame {
  BoxScene<S> scene;
  Image<int, Host> labels;
  Image<S, B> depth = scene.template depth<B>(SE3<S>::identity(), &labels);
  System<S, B> system;
  FrameResult result;
  explicit FirstFrame(const std::string& class_name, int scale = 1, const SystemParams<S>& params = small_params<S>(),
                      const Vec3<S>& box_center = vec3(S(0), S(0), S(1.2)), bool slats = false)
      : scene(box_center, scale, slats), system(scene.camera, params) {
    const Detections det = detections_of(labels, 1, class_name, 0.0);
    result = system.process(depth, 0.0, &det);
  }
  /// The same object detected again on a second frame (at 0.5 / 30 s),
  /// seen from `pose`: its existence count becomes 2.
  void detect_again(const std::string& class_name, const SE3<S>& pose = SE3<S>::identity()) {
    Image<int, Host> seen;
    const Image<S, B> again_depth = scene.template depth<B>(pose, &seen);
    const Detections again = detections_of(seen, 1, class_name, 0.5 / 30.0);
    system.process(again_depth, 0.5 / 30.0, &again);
    REQUIRE(system.objects().size() == 1);
    REQUIRE(system.objects()[0]->existence_count() == 2);
  }
};



/// Pans the camera right in small steps until the object is deleted; returns
/// the frame count used (0: never deleted).
template <class S, class B>
int pan_until_deleted(System<S, B>& sys, const BoxScene<S>& scene) {
  for (int k = 1; k <= 40; ++k) {
    const SE3<S> pose = SE3<S>(so3_exp(vec3(S(0), S(0.02) * S(k), S(0))), Vec3<S>::zero());
    if (!sys.process(scene.template depth<B>(pose), k / 30.0).deleted.empty()) return k;
  }
  return 0;
}

/// Pans back from frame `k` to the start over `now` (the box where it is
/// now), without a detection; returns the pan step at which object 1 came
/// back (-1: never), checking that nothing else was created or came back
/// and that the frame reports it found `by` the rule the caller expects.
template <class S, class B>
int pan_back_until_found(System<S, B>& sys, const BoxScene<S>& now, int k, FoundBy by) {
  int found_at = -1;
  for (int j = k - 1, frame = k; j >= 0; --j) {
    const SE3<S> pose = SE3<S>(so3_exp(vec3(S(0), S(0.02) * S(j), S(0))), Vec3<S>::zero());
    const FrameResult r = sys.process(now.template depth<B>(pose), ++frame / 30.0);
    CHECK(r.created.empty());
    if (!r.reidentified.empty() && found_at < 0) {
      CHECK(r.reidentified == std::vector<int>{1});
      CHECK(r.found_by == std::vector<FoundBy>{by});
      found_at = j;
    }
  }
  return found_at;
}

/// Pans back from frame `k` to the start, then shows `scene` (the box where
/// it is now) with a detection of it as `class_name`: of all of it, or of
/// about `mask_pixels` of its pixels spread over it (every n-th in row
/// order).
template <class S, class B>
FrameResult pan_back_and_detect(System<S, B>& sys, const BoxScene<S>& before, const BoxScene<S>& now, int k,
                                const std::string& class_name, int mask_pixels = -1) {
  int frame = k;
  for (int j = k - 1; j >= 1; --j) {
    const SE3<S> pose = SE3<S>(so3_exp(vec3(S(0), S(0.02) * S(j), S(0))), Vec3<S>::zero());
    // The box moves while out of view: the way back sees it where it is now.
    sys.process((j > k / 2 ? before : now).template depth<B>(pose), ++frame / 30.0);
  }
  Image<int, Host> labels;
  const Image<S, B> depth = now.template depth<B>(SE3<S>::identity(), &labels);
  if (mask_pixels > 0) {
    std::vector<int> cut = labels.to_host();
    const auto all = std::count(cut.begin(), cut.end(), 1);
    const auto every = std::max<std::ptrdiff_t>(1, all / mask_pixels);
    std::ptrdiff_t seen = 0;
    for (int& label : cut)
      if (label == 1 && seen++ % every != 0) label = 0;
    const auto kept = std::count(cut.begin(), cut.end(), 1);
    INFO("a detection of " << kept << " of the box's " << all << " pixels");
    REQUIRE(kept >= mask_pixels);
    REQUIRE(kept <= mask_pixels * 5 / 4);
    labels = Image<int, Host>::from_host(labels.width(), labels.height(), cut);
  }
  const Detections det = detections_of(labels, 1, class_name, ++frame / 30.0);
  return sys.process(depth, frame / 30.0, &det);
}

}  // namespace emfusion::test
