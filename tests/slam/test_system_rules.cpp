// Rules of the object map, one at a time, on small static scenes with
// hand-made detections: resizing keeps the fused surface in place, objects
// are created from detections but never from static classes, a mask that
// spills onto the wall behind still sizes the volume by the object, existence
// falls below 0.1 after repeated misses and the object is deleted, objects
// that leave the view are deleted, kept as lost and re-identified when
// detected again (with lost_object_frames = 0: gone for good; fitted first
// from the pose they were lost in and only as far as they can have moved;
// with refind_in_view found again without a detection where the frame shows
// them where they were lost; found in what no model explains when it comes
// back elsewhere, a group no lost object fitted not fitted again until it
// changes), a new object at the border survives until
// seen, an object that passes behind another moves on at its velocity
// and is found where it comes out, and of the fits of lost objects to a
// detection the best that the frame shows is taken; a lost object that
// turned while out of view is found turned; marks on either side of a thin
// band are one group; an object created late is tracked back through the
// frames kept before it, as far as they show it.
// The two longest (resting, re-identification) run in float only
// (SystemRuleConfigs, support/configs.hpp).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "support/system_instances.hpp"
#include "emfusion/io/checkpoint.hpp"
#include "emfusion/slam/object_history.hpp"
#include "emfusion/volume/marching_cubes.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"
#include "support/files.hpp"
#include "support/fusion.hpp"

using namespace emfusion;
using emfusion::test::Approx;

namespace {

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

}  // namespace

TEMPLATE_LIST_TEST_CASE("Resizing an object keeps its fused surface in place", "[slam]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const PinholeCamera<S> camera = emfusion::test::small_camera<S>();
  sim::Scene<S> scene;
  const Vec3<S> center = vec3(S(0.02), S(-0.01), S(1.2));
  scene.add(sim::make_sphere(center, S(0.1)));
  ObjectModel<S, B> obj(1, "ball", SE3<S>::translation(center), 32, S(0.01), S(10));
  emfusion::test::fuse_views(obj.volume(), scene, camera, emfusion::test::orbit_poses(center, S(1), 6));
  const TriangleMesh<S> before = transformed(marching_cubes(obj.volume()), obj.T_object_volume());
  const auto sdf_before = obj.volume().sdf_to_host();
  const Vec3i old_dims = obj.volume().dims();
  const SE3<S> old_T = obj.T_object_volume();

  // A box reaching 5 voxels below the grid on x and 3 above it on z.
  const S s = obj.volume().voxel_size();
  REQUIRE(obj.grow_to_fit(vec3(S(-4.5) * s, S(1) * s, S(2) * s), vec3(S(20) * s, S(30) * s, S(34.5) * s), 256));
  const Vec3i dims = obj.volume().dims();
  CHECK(dims[0] == old_dims[0] + 5);
  CHECK(dims[1] == old_dims[1]);
  CHECK(dims[2] == old_dims[2] + 3);
  CHECK(obj.volume().voxel_size() == s);
  // The grid moved by whole voxels in the object frame.
  const Vec3<S> shift = old_T.translation() - obj.T_object_volume().translation();
  CHECK(double(shift.x()) == Approx(5 * double(s)).margin(1e-6));
  CHECK(double(shift.y()) == Approx(0.0).margin(1e-6));
  // Every old voxel is where it was, with its value.
  const auto sdf_after = obj.volume().sdf_to_host();
  int mismatches = 0;
  for (int z = 0; z < old_dims[2]; ++z)
    for (int y = 0; y < old_dims[1]; ++y)
      for (int x = 0; x < old_dims[0]; ++x) {
        const std::size_t i = std::size_t((z * old_dims[1] + y) * old_dims[0] + x);
        const std::size_t j = std::size_t(((z) * dims[1] + y) * dims[0] + (x + 5));
        mismatches += sdf_before[i] != sdf_after[j];
      }
  CHECK(mismatches == 0);
  // The surface in the object frame is the same mesh.
  const TriangleMesh<S> after = transformed(marching_cubes(obj.volume()), obj.T_object_volume());
  REQUIRE(before.triangles.size() > 100);
  CHECK(after.triangles.size() == before.triangles.size());
  CHECK(double(surface_area(after)) == Approx(double(surface_area(before))).epsilon(1e-4));
  // Nothing to do when the box fits; the cap holds.
  CHECK_FALSE(obj.grow_to_fit(vec3(S(1) * s, S(1) * s, S(1) * s), vec3(S(2) * s, S(2) * s, S(2) * s), 256));
  CHECK_FALSE(obj.grow_to_fit(vec3(S(-10) * s, S(0), S(0)), vec3(S(1) * s, S(1) * s, S(1) * s), obj.volume().dims()[0]));
}

TEMPLATE_LIST_TEST_CASE("A detection creates an object; a static class never does", "[slam]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const FirstFrame<S, B> table("dining_table");
  CHECK(table.result.detector_frame);
  CHECK(table.result.detections == 1);
  CHECK(table.result.created.empty());
  CHECK(table.system.objects().empty());

  FirstFrame<S, B> first("cup");
  System<S, B>& cup = first.system;
  const auto& depth = first.depth;
  const auto& labels = first.labels;
  REQUIRE(first.result.created.size() == 1);
  REQUIRE(cup.objects().size() == 1);
  const auto& obj = *cup.objects()[0];
  CHECK(obj.class_name() == "cup");
  // The volume is centred near the box and about twice its visible size.
  const Vec3<S> c = obj.pose().translation();
  CHECK(std::abs(double(c.x())) < 0.05);
  CHECK(std::abs(double(c.z()) - 1.2) < 0.12);
  const double side = double(obj.volume().voxel_size()) * obj.volume().dims()[0];
  CHECK(side > 0.3);
  CHECK(side < 0.9);
  // A second frame: the object renders where the box is and is tracked in place.
  const FrameResult r2 = cup.process(depth, 1.0 / 30);
  CHECK(r2.live_objects == 1);
  const auto seg = cup.segmentation().to_host();
  const auto lab = labels.to_host();
  int box = 0, box_as_object = 0;
  for (std::size_t i = 0; i < seg.size(); ++i)
    if (lab[i] == 1) ++box, box_as_object += seg[i] == 1;
  // After one frame the voxels along the silhouette are only partly
  // observed (the silhouette guard); rendering interpolates over the
  // observed ones, so the object covers nearly all of the box.
  CHECK(box_as_object > 0.9 * box);
  CHECK(double(norm(cup.objects()[0]->pose().translation() - c)) < 0.005);
}

TEMPLATE_LIST_TEST_CASE("A detection that spills onto the wall behind sizes the volume by the object", "[slam]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // Detector masks are a few pixels too wide: grow the box's mask by 3 px,
  // which puts about 30 % of its pixels on the wall 0.8 m behind it.
  const BoxScene<S> scene;
  Image<int, Host> labels;
  const Image<S, B> depth = scene.template depth<B>(SE3<S>::identity(), &labels);
  const std::vector<int> lab = labels.to_host();
  std::vector<int> grown(lab.size(), 0);
  const int w = labels.width(), h = labels.height(), r = 3;
  int box = 0;
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u) {
      box += lab[std::size_t(v * w + u)] == 1;
      for (int dv = -r; dv <= r; ++dv)
        for (int du = -r; du <= r; ++du) {
          const int x = u + du, y = v + dv;
          if (x >= 0 && y >= 0 && x < w && y < h && lab[std::size_t(y * w + x)] == 1) grown[std::size_t(v * w + u)] = 1;
        }
    }
  const auto grown_count = std::count(grown.begin(), grown.end(), 1);
  REQUIRE(grown_count > 1.3 * box);
  const Detections det = detections_of(Image<int, Host>::from_host(w, h, grown), 1, "cup", 0.0);
  const auto created_center_and_side = [&](S gap) {
    SystemParams<S> p = small_params<S>();
    p.object_depth_gap = gap;
    System<S, B> sys(scene.camera, p);
    sys.process(depth, 0.0, &det);
    REQUIRE(sys.objects().size() == 1);
    const auto& o = *sys.objects()[0];
    return std::pair{o.pose().translation(), double(o.volume().voxel_size()) * o.volume().dims()[0]};
  };
  const auto [c, side] = created_center_and_side(S(0.1));
  CHECK(std::abs(double(c.z()) - 1.2) < 0.12);
  CHECK(side < 0.9);
  // Without the depth split (a gap wider than the scene) the wall pulls the
  // volume back and blows it up: what this rule is for.
  const auto [c_all, side_all] = created_center_and_side(S(10));
  CHECK(double(c_all.z()) - 1.2 > 0.2);
  CHECK(side_all > 1.5 * side);
}

TEMPLATE_LIST_TEST_CASE("A resting object settles and stays associated", "[slam]",
                        emfusion::test::SystemRuleConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  FirstFrame<S, B> first("cup", 2);
  System<S, B>& sys = first.system;
  REQUIRE(sys.objects().size() == 1);
  const SE3<S> start = sys.objects()[0]->pose();  // the first camera is the world frame
  // Without a detector, the same view for 30 frames. Object voxels here are
  // about a pixel wide, so the first solves move the object by the
  // discretisation bias of a one-view model (a few mm and about a degree,
  // docs/system.md: 6.2 to 6.4 mm with the system's LM settings, measured
  // on CPU and CUDA in float and double); after that it must stay put. Before object poses were
  // orthonormalised, the pose error tripled every frame and the object was
  // lost within 15 frames.
  SE3<S> at_15;
  FrameResult last;
  for (int k = 1; k <= 30; ++k) {
    last = sys.process(first.depth, k / 30.0);
    REQUIRE(last.live_objects == 1);
    if (k == 15) at_15 = sys.objects()[0]->pose();
  }
  const SE3<S> total = start.inverse() * sys.objects()[0]->pose();
  CHECK(double(norm(total.translation())) < 0.008);
  CHECK(double(norm(so3_log(total.rotation()))) < 0.05);
  const SE3<S> late = at_15.inverse() * sys.objects()[0]->pose();
  CHECK(double(norm(late.translation())) < 0.002);
  CHECK(double(norm(so3_log(late.rotation()))) < 0.01);
  // It keeps its share of the pixels (the paper's Fig. 2: a resting object
  // shares them with the background).
  const auto seg = sys.segmentation().to_host();
  const auto q = sys.associations().image(1).to_host();
  double sum = 0;
  int n = 0;
  for (std::size_t i = 0; i < seg.size(); ++i)
    if (seg[i] == 1) sum += double(q[i]), ++n;
  REQUIRE(n > 0);
  CHECK(sum / n > 0.3);
  // The frame's report says what the deletion rules saw.
  REQUIRE(last.object_status.size() == 1);
  const ObjectStatus& st = last.object_status[0];
  CHECK(st.id == sys.objects()[0]->id());
  CHECK(st.mean_association == Approx(sum / n).epsilon(1e-4));
  CHECK(st.rendered_pixels > 0);
  CHECK(st.rendered_pixels <= n);
  CHECK(st.associated_pixels > 0);
  CHECK(st.visible_pixels == std::max(st.rendered_pixels, st.associated_pixels));
  CHECK(st.deleted == DeletionReason::none);
}

TEMPLATE_LIST_TEST_CASE("Existence falls below 0.1 after repeated misses and the object is deleted", "[slam]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  FirstFrame<S, B> first("cup");
  System<S, B>& sys = first.system;
  const auto& depth = first.depth;
  const auto& labels = first.labels;
  REQUIRE(sys.objects().size() == 1);
  // The detector keeps running and finding nothing: p_ex = 1 / (1 + misses).
  int misses = 0;
  while (!sys.objects().empty() && misses < 20) {
    const Detections none = detections_of(labels, 1, "", 0.0);
    const FrameResult r = sys.process(depth, 0.1 * (misses + 1), &none);
    ++misses;
    if (!sys.objects().empty()) CHECK(sys.objects()[0]->existence_probability() >= 0.1);
    else CHECK(r.deleted == std::vector<int>{1});
  }
  CHECK(misses == 10);  // 1 / 11 < 0.1 <= 1 / 10
  REQUIRE(sys.object_records().size() == 1);
  CHECK(sys.object_records()[0].deleted);
  CHECK(sys.object_records()[0].reason == DeletionReason::existence);
  CHECK(sys.object_records()[0].trajectory.size() == 11);  // frames 0-10: the frame that deletes it is the last
}

namespace {

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

}  // namespace

TEMPLATE_LIST_TEST_CASE("An object that left the view is re-identified when detected again", "[slam]",
                        emfusion::test::SystemRuleConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  SystemParams<S> params = small_params<S>();
  // Near the border the weak-association rule may take the object first
  // (on some backends): this test is about the visibility rule.
  params.min_association = 0;
  // It is about re-identification by a detection: on the way back the box
  // stands where it was lost, and refind_in_view would find it first.
  params.refind_in_view = false;
  FirstFrame<S, B> first("cup", 1, params);
  System<S, B>& sys = first.system;
  const BoxScene<S>& scene = first.scene;
  REQUIRE(sys.objects().size() == 1);
  const SE3<S> start = sys.objects()[0]->pose();  // the first camera is the world frame
  // The pan away is the slow part (Catch2 runs it again for each section):
  // it runs once, and the other section goes on from a checkpoint saved at
  // its end, so the lost object comes back through a checkpoint too.
  static const test::ScratchDir scratch;  // one per configuration, removed at exit
  static int k = 0;
  const std::string saved = scratch.file("lost.emfckpt");
  if (k == 0) {
    k = pan_until_deleted(sys, scene);
    REQUIRE(k > 0);
    save_checkpoint(saved, sys);
  } else {
    restore_checkpoint(sys, saved);
  }
  REQUIRE(sys.object_records()[0].reason == DeletionReason::not_visible);
  REQUIRE(sys.map().lost.size() == 1);
  const std::size_t bytes_lost = sys.memory_bytes();
  CHECK(bytes_lost > sys.background().memory_bytes());  // the lost object is kept

  SECTION("the box moved 4 cm while out of view: the same object returns, moved") {
    const BoxScene<S> moved(vec3(S(0.04), S(0), S(1.2)));
    const FrameResult r = pan_back_and_detect(sys, scene, moved, k, "cup");
    CHECK(r.reidentified == std::vector<int>{1});
    CHECK(r.found_by == std::vector<FoundBy>{FoundBy::detection});
    CHECK(r.created.empty());
    REQUIRE(sys.objects().size() == 1);
    CHECK(sys.objects()[0]->id() == 1);
    CHECK_FALSE(sys.object_records()[0].deleted);
    // Relative to the camera: on this scene (a plane and the box) the camera
    // follows a box that moved while it was background, so world poses move too.
    const Vec3<S> shift = (sys.camera_pose().inverse() * sys.objects()[0]->pose()).translation() - start.translation();
    INFO("shift " << shift.x() << " " << shift.y() << " " << shift.z());
    CHECK(std::fabs(double(shift.x()) - 0.04) < 0.01);
    CHECK(std::fabs(double(shift.y())) < 0.01);
    CHECK(std::fabs(double(shift.z())) < 0.01);
    CHECK(sys.memory_bytes() == bytes_lost);  // the lost object's volume is the live one now
  }
  SECTION("a detection smaller than the creation rule brings it back, by reidentify_mask_fraction") {
    // About 70 of its pixels, spread over it (a detector's sparse mask):
    // fewer than the 100 (40x40 at 640x480) an object needs to be
    // created, more than the half of them a re-identification needs. The
    // same state in systems that take a fit of 40 terms (parameters are
    // not part of a checkpoint), with the default and with the creation
    // rule.
    REQUIRE(params.min_mask_pixels_for(scene.camera.width, scene.camera.height) == 100);
    REQUIRE(params.reidentify_mask_pixels_for(scene.camera.width, scene.camera.height) == 50);
    const double fractions[] = {params.reidentify_mask_fraction, 1.0};
    for (const double fraction : fractions) {
      SystemParams<S> p = params;
      p.min_object_terms = 40;
      p.reidentify_mask_fraction = fraction;
      System<S, B> other(scene.camera, p);
      restore_checkpoint(other, saved);
      REQUIRE(other.map().lost.size() == 1);
      const FrameResult r = pan_back_and_detect(other, scene, scene, k, "cup", 70);
      INFO("reidentify_mask_fraction " << fraction);
      CHECK(r.created.empty());
      if (fraction < 1) {
        CHECK(r.reidentified == std::vector<int>{1});
        REQUIRE(other.objects().size() == 1);
        const SE3<S> now = other.camera_pose().inverse() * other.objects()[0]->pose();
        CHECK(double(norm(now.translation() - start.translation())) < 0.01);
      } else {
        CHECK(r.reidentified.empty());
        CHECK(other.objects().empty());
      }
    }
  }
  SECTION("a detection of another class creates a new object") {
    const FrameResult r = pan_back_and_detect(sys, scene, scene, k, "book");
    CHECK(r.reidentified.empty());
    CHECK(r.created == std::vector<int>{2});
  }
}

TEMPLATE_LIST_TEST_CASE("A model fits a frame only where the frame does not see through it", "[slam]",
                        emfusion::test::SystemRuleConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // A ball 1.5 m ahead of a wall 2 m ahead, fused into an object model from
  // one view with the ball as its detection.
  const PinholeCamera<S> camera = BoxScene<S>().camera;
  const auto plane_at = [](S z) {
    return sim::make_plane(sim::look_at(vec3(S(0), S(0), z), Vec3<S>::zero(), vec3(S(0), S(-1), S(0))));
  };
  sim::Scene<S> with_ball, wall_only;
  with_ball.add(plane_at(S(2)));
  with_ball.add(sim::make_sphere(vec3(S(0), S(0), S(1.5)), S(0.1)));
  wall_only.add(plane_at(S(2)));
  const auto frame_of = [&](const sim::Scene<S>& scene, Image<int, Host>* labels = nullptr) {
    Image<S, Host> d;
    sim::render_depth(scene, camera, SE3<S>::identity(), d, labels);
    Frame<S, B> f;
    f.depth = d.template to<B>();
    back_project(f.depth, camera, f.points);
    return f;
  };
  Image<int, Host> labels;
  const Frame<S, B> seen = frame_of(with_ball, &labels);
  ObjectModel<S, B> ball(1, "sports_ball", SE3<S>::translation(vec3(S(0), S(0), S(1.5))), 64, S(0.005), S(4));
  std::vector<std::uint8_t> mask_px;
  for (int l : labels.to_host()) mask_px.push_back(std::uint8_t(l == 1));
  const auto mask = Image<std::uint8_t, Host>::from_host(camera.width, camera.height, mask_px).template to<B>();
  const Image<S, B> weights = Image<S, Host>::from_host(camera.width, camera.height,
                                                        std::vector<S>(mask_px.begin(), mask_px.end()))
                                  .template to<B>();
  const Image<std::uint8_t, B> counted(camera.width, camera.height, std::uint8_t(1));
  for (int k = 0; k < 3; ++k) {
    integrate(ball.volume(), seen.depth, camera, SE3<S>::identity(), &weights);
    update_foreground(ball.foreground(), ball.volume().pose(), ball.volume().truncation(), seen.depth, mask, counted,
                      camera, SE3<S>::identity(), ball.volume().backend());
  }
  const SE3<S> T_volume_camera = ball.volume().pose().inverse();  // the camera at the world origin
  const Image<S, B>& in_mask = weights;  // the detection's pixels
  using detail::reidentification::consistent_with_frame;
  // Where the ball is seen: the frame shows it.
  CHECK(consistent_with_frame(ball, T_volume_camera, seen, in_mask, camera));
  // The same place with the ball gone: the frame sees the wall through it.
  CHECK_FALSE(consistent_with_frame(ball, T_volume_camera, frame_of(wall_only), in_mask, camera));
  // The ball sunk 0.7 m deeper, behind the wall: the frame shows the wall, not the ball.
  CHECK_FALSE(consistent_with_frame(ball, SE3<S>::translation(vec3(S(0), S(0), S(-0.7))) * T_volume_camera, seen,
                                    in_mask, camera));
  // A detection elsewhere in the image: the ball draws nothing there.
  const Image<S, B> elsewhere(camera.width, camera.height, S(0));
  CHECK_FALSE(consistent_with_frame(ball, T_volume_camera, seen, elsewhere, camera));
  // A detection around the ball (9 px in radius): one a little wider, as
  // masks bleed, still shows it; one far wider (a false positive of its
  // class on the wall around it) is covered by the model in a part only,
  // though every pixel the model draws agrees with the frame.
  const auto disc = [&](double radius) {
    std::vector<S> px;
    for (int v = 0; v < camera.height; ++v)
      for (int u = 0; u < camera.width; ++u)
        px.push_back(std::hypot(u - double(camera.cx), v - double(camera.cy)) <= radius ? S(1) : S(0));
    return Image<S, Host>::from_host(camera.width, camera.height, px).template to<B>();
  };
  CHECK(consistent_with_frame(ball, T_volume_camera, seen, disc(11), camera));
  CHECK_FALSE(consistent_with_frame(ball, T_volume_camera, seen, disc(20), camera));
}

TEST_CASE("The best fit to a detection that the frame shows is taken", "[slam]") {
  using Fit = detail::reidentification::CandidateFit<double>;
  using detail::reidentification::best_shown_fit;
  const SE3<double> id = SE3<double>::identity(), moved = SE3<double>::translation(vec3(0.1, 0.0, 0.0));
  // Candidate 1 (a false object of the class) fits the points best, but the
  // frame does not show it there; candidate 0 (the object) is shown.
  const std::vector<Fit> fits{{0, 0.806, moved}, {1, 0.858, id}, {2, 0.4, id}};
  std::vector<int> asked;
  const auto fit = best_shown_fit(fits, 0.5, [&](const Fit& f) {
    asked.push_back(f.candidate);
    return f.candidate != 1;
  });
  REQUIRE(fit);
  CHECK(fit->candidate == 0);
  CHECK(fit->inliers == 0.806);
  CHECK(fit->T_volume_camera.translation().x() == 0.1);
  CHECK(asked == std::vector<int>{1, 0});  // most points first
  // None shown: nothing, and a fit under the minimum is never asked about.
  asked.clear();
  CHECK_FALSE(best_shown_fit(fits, 0.5, [&](const Fit& f) {
    asked.push_back(f.candidate);
    return false;
  }));
  CHECK(asked == std::vector<int>{1, 0});
  const auto always = [](const Fit&) { return true; };
  CHECK_FALSE(best_shown_fit(fits, 0.9, always));
  // Ties in list order; a fit with no points on the surface never counts.
  CHECK(best_shown_fit(std::vector<Fit>{{3, 0.7, id}, {4, 0.7, moved}}, 0.5, always)->candidate == 3);
  CHECK_FALSE(best_shown_fit(std::vector<Fit>{{5, 0.0, id}}, 0.0, always));
  CHECK_FALSE(best_shown_fit(std::vector<Fit>{}, 0.5, always));
}

TEST_CASE("An object is partly hidden from the share of its drawn model behind nearer surfaces", "[slam]") {
  using Cover = emfusion::detail::lifecycle::DrawnCover;
  SystemParams<float> params;
  params.predict_hidden_share = 0.25f;
  const int min_pixels = params.keep_mask_pixels_for(640, 480);
  REQUIRE(min_pixels > 8);
  const std::vector<Cover> covers{
      {min_pixels, 0, min_pixels / 4},      // a quarter behind: partly hidden
      {min_pixels, 0, min_pixels / 4 - 1},  // just under a quarter
      {min_pixels - 1, 0, min_pixels - 1},  // all behind, but too little drawn to tell
      {4 * min_pixels, 3 * min_pixels, 0},  // wholly in view
  };
  CHECK(partly_hidden(covers, params, 640, 480) == std::vector<bool>{true, false, false, false});
  params.predict_hidden_share = 0;
  CHECK(partly_hidden(covers, params, 640, 480) == std::vector<bool>(4, false));
}

TEST_CASE("The turns tried for a lost object are the cube's 23 other than none", "[slam]") {
  const std::vector<Mat3<double>> turns = detail::reidentification::cube_turns<double>();
  REQUIRE(turns.size() == 23);
  for (std::size_t i = 0; i < turns.size(); ++i) {
    const Mat3<double>& R = turns[i];
    // A rotation that takes each axis onto an axis, either way.
    CHECK(double(norm(so3_log(R * R.transpose()))) < 1e-12);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) CHECK((std::fabs(R(r, c)) < 1e-12 || std::fabs(std::fabs(R(r, c)) - 1) < 1e-12));
    CHECK(double(norm(so3_log(R))) > 1.5);  // not none: a quarter turn at least
    for (std::size_t j = 0; j < i; ++j) CHECK(double(norm(so3_log(turns[j].transpose() * R))) > 1.5);
  }
}

TEST_CASE("Without a class, a group two objects fit about as well is left alone", "[slam]") {
  using Fit = detail::reidentification::CandidateFit<double>;
  using detail::unexplained::unambiguous;
  const SE3<double> id = SE3<double>::identity();
  // Two fits above the minimum within the margin: either object could be there.
  CHECK_FALSE(unambiguous(std::vector<Fit>{{0, 0.95, id}, {1, 0.93, id}}, 0.6, 0.05));
  CHECK_FALSE(unambiguous(std::vector<Fit>{{0, 0.93, id}, {1, 0.4, id}, {2, 0.95, id}}, 0.6, 0.05));
  // One clearly better, or only one above the minimum, or none.
  CHECK(unambiguous(std::vector<Fit>{{0, 0.95, id}, {1, 0.85, id}}, 0.6, 0.05));
  CHECK(unambiguous(std::vector<Fit>{{0, 0.95, id}, {1, 0.58, id}}, 0.6, 0.05));
  CHECK(unambiguous(std::vector<Fit>{{0, 0.5, id}, {1, 0.5, id}}, 0.6, 0.05));
  CHECK(unambiguous(std::vector<Fit>{}, 0.6, 0.05));
}

TEST_CASE("Marked pixels on either side of a thin unmarked band are one group", "[slam]") {
  using detail::unexplained::groups_of;
  // 60x20 pixels: marked at columns 5-24 and 35-54 (a band of 10 between),
  // all at 1 m, or the right part at 1.5 m.
  const int w = 60, h = 20;
  std::vector<std::uint8_t> marked(std::size_t(w * h), 0);
  std::vector<Vec3<double>> points(marked.size(), vec3(0.0, 0.0, 1.0));
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u) marked[std::size_t(v * w + u)] = (u >= 5 && u < 25) || (u >= 35 && u < 55);
  const auto sizes = [&](int bridge) {
    std::vector<std::size_t> n;
    for (const auto& g : groups_of(marked, points, w, h, 0.05, 100, bridge)) n.push_back(g.size());
    return n;
  };
  CHECK(sizes(1) == std::vector<std::size_t>{400, 400});  // four neighbours only
  CHECK(sizes(10) == std::vector<std::size_t>{400, 400});  // the band is 10 wide: 11 steps across
  CHECK(sizes(11) == std::vector<std::size_t>{800});
  CHECK(sizes(20) == std::vector<std::size_t>{800});
  for (int v = 0; v < h; ++v)
    for (int u = 35; u < 55; ++u) points[std::size_t(v * w + u)] = vec3(0.0, 0.0, 1.5);
  CHECK(sizes(20) == std::vector<std::size_t>{400, 400});  // not across a step in depth
  CHECK(groups_of(marked, points, w, h, 0.05, 401, 20).empty());  // each under the minimum
}

TEST_CASE("A group no lost object was found in is not fitted again until it changes", "[slam]") {
  using detail::unexplained::retry_frames;
  using detail::unexplained::tried_before;
  using detail::unexplained::TriedGroup;
  const std::vector<int> ids{3, 5};
  const Vec3<double> c = vec3(1.0, 0.0, 2.0);
  const std::vector<TriedGroup<double>> tried{{c, 2000, 100, ids}};
  CHECK(tried_before(tried, c, 2000, 101, ids));                       // the same group on the next frame
  CHECK(tried_before(tried, vec3(1.03, 0.0, 2.0), 2150, 110, ids));    // 3 cm over, 7.5 % larger
  CHECK_FALSE(tried_before(tried, c, 2000, 100 + retry_frames, ids));  // tried long enough ago
  CHECK_FALSE(tried_before(tried, c, 2200, 101, ids));                 // grown by a tenth
  CHECK_FALSE(tried_before(tried, vec3(1.1, 0.0, 2.0), 2000, 101, ids));  // another group
  CHECK_FALSE(tried_before(tried, c, 2000, 101, std::vector<int>{3, 5, 7}));  // one more object lost since
  CHECK_FALSE(tried_before(std::vector<TriedGroup<double>>{}, c, 2000, 101, ids));
}

TEMPLATE_LIST_TEST_CASE("A lost object is fitted first from its last pose, and only as far as it can have moved",
                        "[slam]", emfusion::test::SystemRuleConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // A box 1.2 m ahead of a wall 2 m ahead (320x240 camera at the world
  // origin), fused into an object model from one view with the box as its
  // detection; then fitted to detections of it.
  const PinholeCamera<S> camera{S(280), S(280), S(159.5), S(119.5), 320, 240};
  const auto frame_of = [&](const SE3<S>& T_world_box, const Vec3<S>& half_extents, std::vector<S>& mask_px) {
    sim::Scene<S> scene;
    scene.add(sim::make_plane(sim::look_at(vec3(S(0), S(0), S(2)), Vec3<S>::zero(), vec3(S(0), S(-1), S(0)))));
    scene.add(sim::make_box(T_world_box, half_extents));
    Image<S, Host> d;
    Image<int, Host> labels;
    sim::render_depth(scene, camera, SE3<S>::identity(), d, &labels);
    Frame<S, B> f;
    f.depth = d.template to<B>();
    back_project(f.depth, camera, f.points);
    mask_px.clear();
    for (int l : labels.to_host()) mask_px.push_back(S(l == 1));
    return f;
  };
  const auto target_of = [&](const Frame<S, B>& f, const std::vector<S>& mask_px) {
    detail::reidentification::DetectionTarget<S, B> t;
    t.centroid = Vec3<S>::zero();
    const std::vector<Vec3<S>> points = f.points.to_host();
    for (std::size_t i = 0; i < points.size(); ++i)
      if (mask_px[i] > S(0) && is_valid(points[i])) t.centroid = t.centroid + points[i], ++t.points;
    t.centroid = t.centroid / S(t.points);
    t.ray = normalized(t.centroid);
    t.mask = Image<S, Host>::from_host(camera.width, camera.height, mask_px).template to<B>();
    return t;
  };
  const auto model_of = [&](const Frame<S, B>& f, const std::vector<S>& mask_px) {
    ObjectModel<S, B> o(1, "book", SE3<S>::translation(vec3(S(0), S(0), S(1.2))), 64, S(0.008), S(10));
    const auto seen = target_of(f, mask_px);
    for (int k = 0; k < 3; ++k) integrate(o.volume(), f.depth, camera, SE3<S>::identity(), &seen.mask);
    return o;
  };
  SystemParams<S> params = small_params<S>();
  const auto fit = [&](const ObjectModel<S, B>& o, const Frame<S, B>& f, const std::vector<S>& mask_px,
                       int frames_lost) {
    return detail::reidentification::fit_to_target(o, target_of(f, mask_px), f, SE3<S>::identity(), params,
                                                   HuberNorm<S>{params.huber_voxels}, LevenbergMarquardt{params.lm},
                                                   frames_lost);
  };
  // How far a fit (T_volume_camera, the camera at the world origin) moved the model from where it was.
  const auto moved_by = [&](const ObjectModel<S, B>& o, const SE3<S>& T_volume_camera) {
    return double(norm(T_volume_camera.inverse().translation() - o.volume().pose().translation()));
  };
  // A box fused where it was last seen, and a frame of it moved 6 cm along x.
  struct MovedBox {
    ObjectModel<S, B> box;
    Frame<S, B> moved;
    std::vector<S> there;  // its mask in that frame
    detail::reidentification::DetectionTarget<S, B> target;
    SE3<S> last_seen;  // T_volume_camera where it was last (the camera at the world origin)
  };
  const auto moved_box = [&] {
    const auto box_at = [](S x) { return SE3<S>(so3_exp(vec3(S(0.2), S(0.4), S(0))), vec3(x, S(0), S(1.2))); };
    const Vec3<S> half = vec3(S(0.15), S(0.1), S(0.12));
    std::vector<S> here, there;
    ObjectModel<S, B> box = model_of(frame_of(box_at(S(0)), half, here), here);
    Frame<S, B> moved = frame_of(box_at(S(0.06)), half, there);
    auto target = target_of(moved, there);
    const SE3<S> last_seen = box.volume().pose().inverse();
    return MovedBox{std::move(box), std::move(moved), std::move(there), std::move(target), last_seen};
  };
  SECTION("a patch of a flat panel where it was: the fit from the last pose is kept, not a slid one") {
    // The detection is a patch of the panel's face off its centre: the
    // model fits it as well slid along the face (the starts at the patch's
    // centroid slide it about 12 cm), and the pose it was last in wins.
    const SE3<S> T_panel = SE3<S>::translation(vec3(S(0), S(0), S(1.2)));
    const Vec3<S> half = vec3(S(0.2), S(0.15), S(0.02));
    std::vector<S> whole, patch;
    const Frame<S, B> f = frame_of(T_panel, half, whole);
    const ObjectModel<S, B> panel = model_of(f, whole);
    patch = whole;
    for (int v = 0; v < camera.height; ++v)
      for (int u = 0; u < camera.width; ++u)  // the upper left quarter of the face, 4 px inside its edges
        if (!(u > 117 + 4 && u < 160 - 4 && v > 88 + 4 && v < 120 - 4)) patch[std::size_t(v * camera.width + u)] = 0;
    const auto [inliers, T] = fit(panel, f, patch, 1);
    CHECK(inliers > 0.9);
    CHECK(moved_by(panel, T) < 0.005);
  }
  SECTION("reidentify_colour_agreement: a striped panel slid along its face is found by its colour") {
    // A patch of the face of a panel with stripes 5 cm wide along x (light
    // and dark) after the panel slid 2.5 cm along x: depth fits it as well
    // where it was, and the fit from the last pose is kept (the section
    // above); its stripes then disagree with the frame's, and the fit
    // solved again with the model's colour finds the slide.
    const Vec3<S> half = vec3(S(0.2), S(0.15), S(0.02));
    const S slide = S(0.025);
    const auto striped = [&](const Frame<S, B>& f, S offset) {
      std::vector<S> g;
      for (const Vec3<S>& p : f.points.to_host())
        g.push_back(is_valid(p) && std::fmod(double(p.x() - offset) + 10.0, 0.1) < 0.05 ? S(0.8) : S(0.2));
      return Image<S, Host>::from_host(camera.width, camera.height, g).template to<B>();
    };
    std::vector<S> whole, moved_mask;
    Frame<S, B> first = frame_of(SE3<S>::translation(vec3(S(0), S(0), S(1.2))), half, whole);
    first.intensity = striped(first, S(0));
    ObjectModel<S, B> panel = model_of(first, whole);
    panel.enable_colour();
    const auto seen = target_of(first, whole);
    fuse_intensity(panel.colour(), panel.volume().pose(), panel.volume().truncation(),
                   params.object_integration.max_weight, first.depth, first.intensity, &seen.mask, camera,
                   SE3<S>::identity(), first.depth.backend());
    Frame<S, B> moved = frame_of(SE3<S>::translation(vec3(slide, S(0), S(1.2))), half, moved_mask);
    moved.intensity = striped(moved, slide);
    std::vector<S> patch = moved_mask;
    for (int v = 0; v < camera.height; ++v)
      for (int u = 0; u < camera.width; ++u)  // the upper left quarter of the face, inside its edges
        if (!(u > 125 && u < 156 && v > 92 && v < 116)) patch[std::size_t(v * camera.width + u)] = 0;
    const auto [depth_inliers, depth_T] = fit(panel, moved, patch, 1);
    CHECK(depth_inliers > 0.9);
    CHECK(moved_by(panel, depth_T) < 0.005);  // depth alone: where it was
    params.reidentify_colour_agreement = 0.5;
    CHECK_FALSE(detail::reidentification::colour_agrees(panel, depth_T, moved, target_of(moved, patch).mask, params));
    const auto [inliers, T] = fit(panel, moved, patch, 1);
    CHECK(inliers > 0.9);
    CHECK(std::fabs(moved_by(panel, T) - double(slide)) < 0.008);
    CHECK(detail::reidentification::colour_agrees(panel, T, moved, target_of(moved, patch).mask, params));
  }
  SECTION("a box detected 6 cm away: found within the bound, refused beyond it") {
    const MovedBox m = moved_box();
    const auto [inliers, T] = fit(m.box, m.moved, m.there, 1);
    CHECK(inliers > 0.9);
    CHECK(std::fabs(moved_by(m.box, T) - 0.06) < 0.01);
    params.max_object_motion.translation = S(0.01);  // 1 cm a frame: 6 cm takes more than 5 frames
    CHECK(fit(m.box, m.moved, m.there, 3).first == 0);
    CHECK(fit(m.box, m.moved, m.there, 8).first > 0.9);
    CHECK(fit(m.box, m.moved, m.there, 0).first > 0.9);  // 0: not a lost object, no bound
  }
  SECTION(
      "reidentify_pose_prior pulls each fit towards its start: a weak pull follows the points, a strong one holds") {
    const MovedBox m = moved_box();
    const auto fit_with = [&](S prior) {
      params.reidentify_pose_prior = prior;
      return detail::reidentification::fit_from(m.box, m.target, m.moved, SE3<S>::identity(), params,
                                                HuberNorm<S>{params.huber_voxels}, LevenbergMarquardt{params.lm}, 0,
                                                m.last_seen);
    };
    const auto free = fit_with(S(0)), weak = fit_with(S(30)), strong = fit_with(S(1e7));
    REQUIRE(free);
    REQUIRE(weak);
    CHECK(std::fabs(moved_by(m.box, free->second) - 0.06) < 0.005);
    CHECK(std::fabs(moved_by(m.box, weak->second) - 0.06) < 0.005);  // 30 points' pull against thousands
    CHECK(weak->first > 0.9);
    if (strong) CHECK(moved_by(m.box, strong->second) < 0.01);  // held near where it was last
    CHECK(!(strong && strong->first > 0.9));                  // and so not on the points
  }
  SECTION("the solves of many starts in one batch: the fits of solving them one after another") {
    const MovedBox m = moved_box();
    std::vector<SE3<S>> starts{m.last_seen};
    for (const Mat3<S>& turn : detail::reidentification::cube_turns<S>())
      starts.push_back(detail::reidentification::start_at_target(m.box, m.target, m.last_seen.rotation(), turn, 1));
    params.max_object_motion.translation = S(0.02);  // some starts' solves go further than 3 frames allow
    const LevenbergMarquardt lm{params.lm};
    const HuberNorm<S> huber{params.huber_voxels};
    int fits = 0, refused = 0;
    params.reidentify_pose_prior = GENERATE(S(0), S(30));  // each solve with and without its pull
    for (const int frames_lost : {3, 0}) {  // 0: no bound on the move
      const auto batched = detail::reidentification::fits_from(m.box, m.target, m.moved, SE3<S>::identity(), params,
                                                               huber, lm, frames_lost, starts);
      REQUIRE(batched.size() == starts.size());
      for (std::size_t k = 0; k < starts.size(); ++k) {
        const auto single = detail::reidentification::fit_from(m.box, m.target, m.moved, SE3<S>::identity(), params,
                                                               huber, lm, frames_lost, starts[k]);
        INFO("start " << k << ", lost " << frames_lost << " frames");
        REQUIRE(bool(batched[k]) == bool(single));
        if (!single) {
          ++refused;
          continue;
        }
        ++fits;
        CHECK(std::fabs(batched[k]->first - single->first) < 0.01);
        CHECK(double(norm(batched[k]->second.translation() - single->second.translation())) < 1e-3);
      }
    }
    INFO(fits << " fits, " << refused << " refused");
    CHECK(fits > 10);  // both kinds occur: the comparison covers both
    CHECK(refused > 10);
  }
}

TEMPLATE_LIST_TEST_CASE("A lost object that turned while out of view is found turned", "[slam]",
                        emfusion::test::SystemRuleConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // An L of two boxes 1.2 m ahead of a wall 2 m ahead (320x240 camera at
  // the world origin), fused into a model from one view and lost; then
  // detected moved 3 cm and turned by 105 degrees, further than an
  // alignment from its last orientation reaches.
  const PinholeCamera<S> camera{S(280), S(280), S(159.5), S(119.5), 320, 240};
  const auto scene_at = [](const SE3<S>& T_world_object) {
    sim::Scene<S> scene;
    scene.add(sim::make_plane(sim::look_at(vec3(S(0), S(0), S(2)), Vec3<S>::zero(), vec3(S(0), S(-1), S(0)))));
    scene.add(sim::make_box(T_world_object * SE3<S>::translation(vec3(S(-0.03), S(0), S(0))),
                            vec3(S(0.13), S(0.035), S(0.05))));
    scene.add(sim::make_box(T_world_object * SE3<S>::translation(vec3(S(0.065), S(0.0775), S(0))),
                            vec3(S(0.035), S(0.0425), S(0.05))));
    return scene;
  };
  struct View {
    Frame<S, B> frame;
    Detections det;
    std::vector<S> mask;
  };
  const auto view_of = [&](const SE3<S>& T_world_object) {
    View v;
    Image<S, Host> d;
    Image<int, Host> labels;
    sim::render_depth(scene_at(T_world_object), camera, SE3<S>::identity(), d, &labels);
    v.frame.depth = d.template to<B>();
    back_project(v.frame.depth, camera, v.frame.points);
    v.frame.segmentation = Image<int, Host>::from_host(camera.width, camera.height,
                                                       std::vector<int>(std::size_t(camera.width * camera.height), 0))
                               .template to<B>();
    std::vector<std::uint16_t> px;
    for (int l : labels.to_host()) {
      px.push_back(std::uint16_t(l == 1 || l == 2 ? 5 : 0));
      v.mask.push_back(S(l == 1 || l == 2));
    }
    v.det.labels = Image<std::uint16_t, Host>::from_host(camera.width, camera.height, px);
    v.det.instances.push_back({5, "cup", 0.95});
    return v;
  };
  const SE3<S> T_was(so3_exp(vec3(S(0.2), S(0.4), S(0))), vec3(S(0), S(0), S(1.2)));
  const SE3<S> T_now(so3_exp(normalized(vec3(S(0.1), S(0.2), S(1))) * S(105 * 3.14159265358979 / 180)) *
                         T_was.rotation(),
                     T_was.translation() + vec3(S(0.03), S(0), S(0)));
  SystemParams<S> params = small_params<S>();
  const auto found_where = [&](bool turned, int keep = 0) -> std::optional<SE3<S>> {
    params.reidentify_turn_below = turned ? SystemParams<S>{}.reidentify_turn_below : 0;
    params.reidentify_turned_keep = keep;
    Map<S, B> map(params);
    auto model = std::make_unique<ObjectModel<S, B>>(1, "cup", T_was, 64, S(0.006), S(10));
    const View was = view_of(T_was);
    const Image<S, B> seen = Image<S, Host>::from_host(camera.width, camera.height, was.mask).template to<B>();
    const auto bytes = [&](const std::vector<S>& v) {
      return Image<std::uint8_t, Host>::from_host(camera.width, camera.height,
                                                  std::vector<std::uint8_t>(v.begin(), v.end()))
          .template to<B>();
    };
    for (int k = 0; k < 3; ++k) {
      integrate(model->volume(), was.frame.depth, camera, SE3<S>::identity(), &seen);
      update_foreground(model->foreground(), model->volume().pose(), model->volume().truncation(), was.frame.depth,
                        bytes(was.mask), bytes(std::vector<S>(was.mask.size(), S(1))), camera, SE3<S>::identity(),
                        B{});
    }
    ObjectRecord rec;
    rec.id = 1;
    rec.class_name = "cup";
    rec.deleted = true;
    map.records.push_back(rec);
    map.lost.push_back({std::move(model), 0});
    map.next_id = 2;
    map.frames = 30;  // lost a second ago: the turn is within max_object_motion
    const View now = view_of(T_now);
    const std::vector<int> seg(std::size_t(camera.width * camera.height), 0);
    const auto back = reidentify(map, now.frame, now.det, 0, seg, now.frame.points.to_host(), camera, params,
                                 HuberNorm<S>{params.huber_voxels}, LevenbergMarquardt{params.lm}, S(0.5));
    if (!back) return std::nullopt;
    REQUIRE(map.objects.size() == 1);
    CHECK(map.lost.empty());
    return map.objects[0]->pose();
  };
  // How far a pose is from where the L stands now: metres and degrees.
  const auto off = [&](const SE3<S>& pose) {
    const SE3<S> d = pose.inverse() * T_now;
    return std::pair{double(norm(pose.translation() - T_now.translation())),
                     double(norm(so3_log(d.rotation()))) * 180 / 3.14159265358979};
  };
  const auto from_last = found_where(false);
  if (from_last) {
    const auto [metres, degrees] = off(*from_last);
    INFO("from its last orientation: " << metres << " m, " << degrees << " deg");
    CHECK((metres > 0.02 || degrees > 20));  // the scene needs the turned starts
  }
  const auto turned = found_where(true);
  REQUIRE(turned);
  const auto [metres, degrees] = off(*turned);
  INFO("turned: " << metres << " m, " << degrees << " deg");
  CHECK(metres < 0.01);
  CHECK(degrees < 3);
  // Two rounds (reidentify_turned_keep): the start that found it is among
  // the eight best after three iterations, and solved again from the start
  // to the end it gives the same fit.
  const auto kept = found_where(true, 8);
  REQUIRE(kept);
  const SE3<S> d = kept->inverse() * *turned;
  CHECK(double(norm(d.translation())) < 1e-4);
  CHECK(double(norm(so3_log(d.rotation()))) < 1e-3);
}

TEMPLATE_LIST_TEST_CASE("An object that leaves the view is deleted; with lost_object_frames = 0 it is gone for good",
                        "[slam]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  SystemParams<S> params = small_params<S>();
  params.lost_object_frames = 0;
  FirstFrame<S, B> first("cup", 1, params);
  System<S, B>& sys = first.system;
  const BoxScene<S>& scene = first.scene;
  REQUIRE(sys.objects().size() == 1);
  // The camera pans right in small steps until the box is out of view.
  const int k = pan_until_deleted(sys, scene);
  REQUIRE(k > 0);
  // Near the border the object either drops below the visible area, or its
  // few remaining pixels stop being explained by it (tracking an object
  // that is mostly outside the image is unreliable, which is why the
  // paper deletes such objects): both mean it left the view.
  const DeletionReason why = sys.object_records()[0].reason;
  CHECK((why == DeletionReason::not_visible || why == DeletionReason::weak_association));
  // Tracking the camera over the pan stayed on the true rotation.
  CHECK(norm(so3_log(sys.camera_pose().rotation())) > 0.1);
  // Nothing of it is kept, and the box seen again is a new object.
  CHECK(sys.map().lost.empty());
  CHECK(sys.memory_bytes() == sys.background().memory_bytes());
  const FrameResult r = pan_back_and_detect(sys, scene, scene, k, "cup");
  CHECK(r.reidentified.empty());
  CHECK(r.created == std::vector<int>{2});
}

/// Where the box scene's box (at y 0, z 1.2 m) sits at the right edge of
/// the image with at least 150 px in view but fewer than 60 inside the
/// 5 px visibility border: big enough to create an object from, not
/// "visible" by the deletion rule (100 px at 160x120). 0.9 or more if no
/// place between 0.5 and 0.9 m does.
template <class S>
S box_x_at_border() {
  S x = S(0.5);
  for (; x < S(0.9); x += S(0.005)) {
    Image<int, Host> l;
    BoxScene<S>(vec3(x, S(0), S(1.2))).template depth<Host>(SE3<S>::identity(), &l);
    int all = 0, inner = 0;
    for (int v = 0; v < l.height(); ++v)
      for (int u = 0; u < l.width(); ++u)
        if (l.view()(u, v) == 1) ++all, inner += u >= 5 && u < l.width() - 5 && v >= 5 && v < l.height() - 5;
    if (all >= 150 && inner < 60) break;
  }
  return x;
}

namespace {

/// The box scene's first frame with the box at the right edge
/// (box_x_at_border: `x`) detected as a cup: one young object, created with
/// little of it inside the visibility border. `scale` as BoxScene's.
template <class S, class B>
struct YoungAtBorder {
  S x = box_x_at_border<S>();
  FirstFrame<S, B> first;
  explicit YoungAtBorder(const SystemParams<S>& params, int scale = 1)
      : first("cup", scale, params, vec3(x, S(0), S(1.2))) {
    REQUIRE(x < S(0.9));
    REQUIRE(first.result.created == std::vector<int>{1});
  }
};

}  // namespace

TEMPLATE_LIST_TEST_CASE("A new object at the image border survives until it is seen or the detector runs again",
                        "[slam]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // A box at the right edge whose detection is large enough to create an
  // object (at least 100 px: 1600 at 640x480), but with fewer than 100 px
  // inside the 5 px visibility border: not "visible" by the deletion rule.
  for (const bool grace : {true, false}) {
    INFO("grace " << grace);
    SystemParams<S> params = small_params<S>();
    params.young_object_grace = grace;
    YoungAtBorder<S, B> young(params);
    FirstFrame<S, B>& first = young.first;
    System<S, B>& sys = first.system;
    const Image<S, B>& depth = first.depth;
    const FrameResult second = sys.process(depth, 1 / 30.0);
    REQUIRE(second.object_status.size() == 1);
    CHECK(second.object_status[0].visible_pixels < 100);  // 1600 px at 640x480 is 100 px at 160x120
    CHECK(second.deleted.empty() == grace);
    if (!grace) continue;
    // The detector runs again and the grace ends: the rule applies.
    const Detections none = detections_of(first.labels, 1, "", 2 / 30.0);
    const FrameResult third = sys.process(depth, 2 / 30.0, &none);
    CHECK(third.deleted == std::vector<int>{1});
  }
}

TEMPLATE_LIST_TEST_CASE("A young object the frame no longer shows at all is lost at once", "[slam]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // The box at the right edge, created from its detection with fewer than
  // 100 px inside the border (young: the grace keeps it). The camera then
  // turns away from it, 0.005 rad a frame (about 0.7 px), and no detector
  // runs again: once the frame neither draws nor associates it on any
  // pixel inside the visibility border (or on min_object_terms pixels
  // anywhere), its grace ends and it is lost as not visible at once.
  const SystemParams<S> params = small_params<S>();
  REQUIRE(params.young_object_grace);
  YoungAtBorder<S, B> young(params);
  FirstFrame<S, B>& first = young.first;
  const BoxScene<S>& scene = first.scene;
  System<S, B>& sys = first.system;
  int deleted_at = -1, gone_at = -1;  // gone: none of the box in the frame
  int out_at = -1;                    // none of it inside the visibility border
  // The box's pixels in the frame it was deleted in, and those inside the
  // visibility border.
  std::ptrdiff_t shown_then = -1, inside_then = -1;
  const int border = params.visibility_border_for(scene.camera.width);
  for (int k = 1; k <= 40 && deleted_at < 0; ++k) {
    Image<int, Host> seen;
    const SE3<S> away(so3_exp(vec3(S(0), S(-0.005) * S(k), S(0))), Vec3<S>::zero());
    const FrameResult r = sys.process(scene.template depth<B>(away, &seen), k / 30.0);
    const std::vector<int> l = seen.to_host();
    const std::ptrdiff_t shown = std::count(l.begin(), l.end(), 1);
    std::ptrdiff_t inside = 0;
    for (std::size_t i = 0; i < l.size(); ++i) inside += l[i] == 1 && seen.view().inside_border(int(i), border);
    if (shown == 0 && gone_at < 0) gone_at = k;
    if (inside == 0 && out_at < 0) out_at = k;
    if (!r.deleted.empty()) {
      CHECK(r.deleted == std::vector<int>{1});
      deleted_at = k, shown_then = shown, inside_then = inside;
    }
  }
  INFO("deleted at step " << deleted_at << " with " << shown_then << " px of the box in the frame, " << inside_then
                          << " inside the border; none from step " << gone_at << ", none inside from step " << out_at);
  REQUIRE(deleted_at > 0);
  // Not while the frame showed enough of it to track, and no later than
  // the first frame without a pixel of it inside the border.
  CHECK((shown_then < params.min_object_terms || inside_then == 0));
  CHECK((out_at < 0 || deleted_at <= out_at));
  CHECK((gone_at < 0 || deleted_at <= gone_at));
  CHECK(sys.object_records()[0].reason == DeletionReason::not_visible);
  CHECK(sys.map().lost.size() == 1);  // kept, to be found again
}

TEMPLATE_LIST_TEST_CASE("A young object not yet visible keeps its pose; once seen, it is tracked", "[slam]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // The box at the right edge, created from its detection with fewer than
  // 100 px inside the border; it then slides 5 mm a frame into the view.
  // Held (hold_unseen_objects), the object stays where it was found while
  // the frame shows too little of it, and is tracked once enough shows; not
  // held, it is tracked from the first frame on. (How well it then follows
  // a box that enters the view at this size is not the question here.)
  for (const bool hold : {true, false}) {
    INFO("hold " << hold);
    SystemParams<S> params = small_params<S>();
    params.hold_unseen_objects = hold;
    YoungAtBorder<S, B> young(params);
    const S x = young.x;
    System<S, B>& sys = young.first.system;
    const Vec3<S> found = sys.objects()[0]->pose().translation();
    int first_tracked = -1;
    for (int f = 1; f <= 24; ++f) {
      const S moved = S(0.005) * S(f);
      const BoxScene<S> scene(vec3(x - moved, S(0), S(1.2)));
      const FrameResult r = sys.process(scene.template depth<B>(SE3<S>::identity()), f / 30.0);
      REQUIRE(sys.objects().size() == 1);
      REQUIRE(r.object_status.size() == 1);
      const TrackingOutcome outcome = r.object_status[0].tracking;
      const Vec3<S> at = sys.objects()[0]->pose().translation();
      INFO("frame " << f << ": " << to_string(outcome) << ", moved " << norm(at - found) << " m of " << moved);
      if (first_tracked < 0 && outcome == TrackingOutcome::tracked) first_tracked = f;
      if (first_tracked > 0) {
        CHECK(outcome == TrackingOutcome::tracked);  // seen once, never held again
      } else {
        // Held: where it was found, bit for bit.
        CHECK(outcome == TrackingOutcome::not_tracked);
        CHECK(at[0] == found[0]);
        CHECK(at[1] == found[1]);
        CHECK(at[2] == found[2]);
      }
    }
    INFO("first tracked at frame " << first_tracked);
    if (hold) {
      CHECK(first_tracked > 2);  // the first frames show too little of it
    } else {
      CHECK(first_tracked == 1);
    }
  }
}

TEMPLATE_LIST_TEST_CASE("A young object is not held where the frame sees through it", "[slam]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // The box at the right edge, created from its detection with little of
  // it inside the border: young, and held (hold_unseen_objects) while the
  // E-step shows it cut by the border. It then moves away from the camera,
  // 1.5 cm a frame: drawn where it was found, the model stands in front of
  // what the frame measures there. Held so, it fell behind (held 4 frames,
  // then tracked, 5.4 cm behind after 8 frames; on the generalisation
  // benchmark a cup that came into view fell 1.3 -> 9.7 cm behind). Now the
  // first frame that sees through it ends its grace: not visible, it is
  // lost there, kept to be found again. At 320x240, where the box shows on
  // more pixels than the min_object_terms that must see through it.
  const SystemParams<S> params = small_params<S>();
  REQUIRE(params.hold_unseen_objects);
  YoungAtBorder<S, B> young(params, 2);
  const S x = young.x;
  System<S, B>& sys = young.first.system;
  const Vec3<S> found = sys.objects()[0]->pose().translation();
  const S step = S(0.015);
  int lost_at = -1;
  for (int f = 1; f <= 8 && lost_at < 0; ++f) {
    const BoxScene<S> scene(vec3(x, S(0), S(1.2) + step * S(f)), 2);
    const FrameResult r = sys.process(scene.template depth<B>(SE3<S>::identity()), f / 30.0);
    REQUIRE(r.object_status.size() == 1);
    if (!r.deleted.empty()) {
      CHECK(r.deleted == std::vector<int>{1});
      CHECK(r.object_status[0].deleted == DeletionReason::not_visible);
      lost_at = f;
    } else {
      // Until then held where it was found.
      CHECK(r.object_status[0].tracking == TrackingOutcome::not_tracked);
      CHECK(sys.objects()[0]->pose().translation()[2] == found[2]);
    }
  }
  INFO("lost at frame " << lost_at);
  CHECK(lost_at > 0);
  CHECK(lost_at <= 2);
  CHECK(sys.objects().empty());
  CHECK(sys.map().lost.size() == 1);
}

TEMPLATE_LIST_TEST_CASE("An object leaving the view keeps its pose instead of following what is left of it", "[slam]",
                        emfusion::test::SystemRuleConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // The box stands still; the camera pans right over the wall with slats
  // until it is lost. In its last frames in view only an edge of it shows,
  // whose alignment to the model slid it centimetres along the viewing ray
  // (the model is least accurate at its edges, and a face or two constrain
  // few directions). With leaving_share the frames that show less than
  // half of its extent do not track it, standing still as it does: it
  // keeps its pose.
  S slide[2] = {S(-1), S(-1)};
  int held[2] = {0, 0};
  for (const bool rule : {true, false}) {
    INFO("leaving_share " << (rule ? "0.5" : "0 (off, the default)"));
    SystemParams<S> params = small_params<S>();
    params.leaving_share = rule ? S(0.5) : S(0);
    FirstFrame<S, B> first("cup", 1, params, vec3(S(0), S(0), S(1.2)), true);
    System<S, B>& sys = first.system;
    first.detect_again("cup");
    const Vec3<S> start = sys.objects()[0]->pose().translation();
    Vec3<S> first_held = start;  // where it was when first held
    int lost_at = -1;
    for (int k = 1; k <= 40 && lost_at < 0; ++k) {
      const Vec3<S> was = sys.objects()[0]->pose().translation();
      const SE3<S> pose(so3_exp(vec3(S(0), S(0.02) * S(k), S(0))), Vec3<S>::zero());
      const FrameResult r = sys.process(first.scene.template depth<B>(pose), k / 30.0);
      REQUIRE(r.object_status.size() == 1);
      if (r.object_status[0].tracking == TrackingOutcome::not_tracked && held[rule]++ == 0) first_held = was;
      if (!r.deleted.empty()) lost_at = k;
    }
    REQUIRE(lost_at > 0);
    REQUIRE(sys.map().lost.size() == 1);
    const Vec3<S> lost = sys.map().lost[0].object->pose().translation();
    slide[rule] = norm(lost - start);
    INFO("lost at pan step " << lost_at << ", " << held[rule] << " frames held, " << slide[rule]
                             << " m from where it was, " << norm(lost - first_held)
                             << " m from where it was first held");
    CHECK((rule ? held[rule] > 0 : held[rule] == 0));
    // Held, it did not move; tracked before that within 1.5 cm.
    if (rule) CHECK(norm(lost - first_held) == S(0));
    if (rule) CHECK(double(slide[rule]) < 0.015);
  }
  // Without the rule the edge's frames moved it 6.1 cm (float, CPU).
  CHECK(double(slide[0]) > double(slide[1]) + 0.02);
}

TEMPLATE_LIST_TEST_CASE("A lost object the frame shows where it was lost comes back without a detection", "[slam]",
                        emfusion::test::SystemRuleConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  SystemParams<S> params = small_params<S>();
  params.min_association = 0;  // this test is about the visibility rule (as the re-identification test)
  params.refind_in_view = true;
  params.refind_unexplained_every = 0;  // the next test's rule
  // Held while the camera leaves it, the box is lost where it stands (off,
  // its last frames in view slid it 5.7 cm, and drawn there on the way back
  // the frame saw through it: not found; the test above).
  params.leaving_share = S(0.5);
  FirstFrame<S, B> first("cup", 1, params, vec3(S(0), S(0), S(1.2)), true);  // slats: see BoxScene
  System<S, B>& sys = first.system;
  REQUIRE(sys.objects().size() == 1);
  // Detected again on the next frame, or on the first frame only (a false
  // positive is seldom seen twice: such an object is not looked for).
  const bool once = GENERATE(false, true);
  // The second detection from a view turned 0.01 rad the other way.
  if (!once) first.detect_again("cup", SE3<S>(so3_exp(vec3(S(0), S(-0.01), S(0))), Vec3<S>::zero()));
  const SE3<S> start = sys.objects()[0]->pose();
  const int k = pan_until_deleted(sys, first.scene);
  REQUIRE(k > 0);
  REQUIRE(sys.map().lost.size() == 1);
  // The way back, without a detection: where the box is now decides.
  const auto pan_back = [&](const BoxScene<S>& now) { return pan_back_until_found(sys, now, k, FoundBy::in_view); };
  SECTION("the box stood still: it is found on the way back and tracked to where it is") {
    const int found_at = pan_back(first.scene);
    INFO("lost at pan step " << k << ", found at step " << found_at << (once ? ", detected once" : ""));
    if (once) {
      CHECK(found_at < 0);
      CHECK(sys.objects().empty());
      CHECK(sys.map().lost.size() == 1);
      return;
    }
    CHECK(found_at >= k - 8);  // once its model shows keep_mask_pixels in view: a few steps
    REQUIRE(sys.objects().size() == 1);
    CHECK(sys.objects()[0]->id() == 1);
    CHECK(sys.map().lost.empty());
    CHECK_FALSE(sys.object_records()[0].deleted);
    // Held while it left the view (leaving_share), it was lost about where
    // it stood; found there, it is tracked back (0.81 cm from where it was
    // in float on the CPU).
    const Vec3<S> shift = (sys.camera_pose().inverse() * sys.objects()[0]->pose()).translation() - start.translation();
    CHECK(double(norm(shift)) < 0.015);
  }
  SECTION("the box moved 0.3 m while out of view: it stays lost until a detection finds it") {
    CHECK(pan_back(BoxScene<S>(vec3(S(0.3), S(0), S(1.2)), 1, true)) < 0);
    CHECK(sys.objects().empty());
    CHECK(sys.map().lost.size() == 1);
  }
}

TEMPLATE_LIST_TEST_CASE("A lost object back in view elsewhere is found in what no model explains", "[slam]",
                        emfusion::test::SystemRuleConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // On, off, and on for an object detected on one detector frame only
  // (a false positive is seldom seen twice: such an object is not looked for);
  // then on for a box that also turned a quarter turn about the viewing
  // direction (3): the fits from its kept orientation placed at the group
  // find it turned once enough of it shows. (Re-identification's 23
  // turned starts, tried here when no fit was shown, found it 85 degrees
  // off from the border-cut group three frames sooner: docs/decisions.md,
  // "Turned fits for groups of unexplained pixels".)
  const int mode = GENERATE(0, 1, 2, 3);
  const bool unexplained = mode == 0 || mode == 3;
  SystemParams<S> params = small_params<S>();
  params.min_association = 0;  // as the test above
  params.refind_unexplained_every = mode == 1 ? 0 : 1;
  const Mat3<S> turn = mode == 3 ? so3_exp(vec3(S(0), S(0), S(1.5707963267948966))) : Mat3<S>::identity();
  // (With leaving_share the box is lost where it stood, and the fit from
  // there to the first border-cut view of it put it 10 cm off in float on
  // the CPU, tracked there after; lost where its last frames in view slid
  // it, the fit was right: a fit to a border-cut view is a guess either
  // way, docs/decisions.md, "Objects the camera leaves keep their pose".)
  FirstFrame<S, B> first("cup", 1, params, vec3(S(0), S(0), S(1.2)), true);  // slats: see BoxScene
  System<S, B>& sys = first.system;
  REQUIRE(sys.objects().size() == 1);
  if (mode != 2) first.detect_again("cup");  // detected again on the next frame
  const SE3<S> start = sys.objects()[0]->pose();
  const int k = pan_until_deleted(sys, first.scene);
  REQUIRE(k > 0);
  REQUIRE(sys.map().lost.size() == 1);
  // The box moved 0.3 m to the left while out of view (drawn where it was
  // lost, its model shows the wall: refind_in_view does not find it); the
  // camera pans back, without a detection, and sees it again about 20
  // frames later (0.67 s: it can have gone 0.67 m at refind_unexplained_speed).
  const BoxScene<S> moved(vec3(S(-0.3), S(0), S(1.2)), 1, true, turn);
  const int found_at = pan_back_until_found(sys, moved, k, FoundBy::unexplained);
  INFO("mode " << mode << ": lost at pan step " << k << ", found at step " << found_at);
  // The object's pose against the camera's, and where the box's move (a
  // turn about its centre, then 0.3 m to the left) put it: the camera is
  // back at the start when the pan ends.
  const auto relative = [&] { return sys.camera_pose().inverse() * sys.objects()[0]->pose(); };
  const SE3<S> expected =
      SE3<S>(turn, vec3(S(-0.3), S(0), S(1.2))) * SE3<S>::translation(vec3(S(0), S(0), S(-1.2))) * start;
  const auto degrees_off = [&] {
    return double(norm(so3_log(relative().rotation() * expected.rotation().transpose()))) * 180 / 3.14159265358979;
  };
  if (unexplained) {
    CHECK(found_at > 0);
    REQUIRE(sys.objects().size() == 1);
    CHECK(sys.objects()[0]->id() == 1);
    CHECK(sys.map().lost.empty());
    // Found while the image border still cuts it: with one lost object
    // looked for, a group the border cuts is a target (cut_by_border; with
    // two it waits until wholly in view).
    Image<int, Host> labels;
    moved.template depth<B>(SE3<S>(so3_exp(vec3(S(0), S(0.02) * S(found_at), S(0))), Vec3<S>::zero()), &labels);
    const std::vector<int> shape = labels.to_host();
    std::vector<int> box;
    for (std::size_t i = 0; i < shape.size(); ++i)
      if (shape[i] == 1) box.push_back(int(i));
    CHECK(detail::unexplained::cut_by_border(box, moved.camera.width, moved.camera.height,
                                             params.visibility_border_for(moved.camera.width)));
    // Tracked to where the box is now (within 1.5 cm), turned as it is.
    CHECK(double(norm(relative().translation() - expected.translation())) < 0.015);
    INFO(degrees_off() << " degrees off");
    CHECK(degrees_off() < 10);  // a wrong turn is 60 degrees or more
  } else {
    CHECK(found_at < 0);
    CHECK(sys.objects().empty());
    CHECK(sys.map().lost.size() == 1);
  }
}

TEMPLATE_LIST_TEST_CASE("An object that passes behind another moves on at its velocity and is found coming out",
                        "[slam]", emfusion::test::SystemRuleConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // A wall 2 m ahead, a panel 0.8 m ahead (background: never detected) and
  // a box 1.2 m ahead moving 1.5 cm a frame to the right behind the panel,
  // too little of it in view to be visible for about 20 frames; a static
  // camera, a detection on the first frame only.
  const PinholeCamera<S> camera{S(140), S(140), S(79.5), S(59.5), 160, 120};
  const S speed = S(0.015), x0 = S(-0.45);
  const auto box_at = [&](int frame) { return vec3(x0 + speed * S(frame), S(0), S(1.2)); };
  // low_panel: a panel that hides the lower two thirds of the box only.
  const auto depth_with_box = [&](const Vec3<S>& box, Image<int, Host>* labels, bool low_panel = false) {
    sim::Scene<S> scene;
    scene.add(sim::make_plane(sim::look_at(vec3(S(0), S(0), S(2)), Vec3<S>::zero(), vec3(S(0), S(-1), S(0)))));
    scene.add(sim::make_box(SE3<S>(so3_exp(vec3(S(0.2), S(0.4), S(0))), box), vec3(S(0.08), S(0.06), S(0.07))));
    if (low_panel)
      scene.add(sim::make_box(SE3<S>::translation(vec3(S(0), S(0.17), S(0.8))), vec3(S(0.12), S(0.17), S(0.02))));
    else
      scene.add(sim::make_box(SE3<S>::translation(vec3(S(0), S(0), S(0.8))), vec3(S(0.12), S(0.3), S(0.02))));
    Image<S, Host> d;
    sim::render_depth(scene, camera, SE3<S>::identity(), d, labels);
    return d.template to<B>();
  };
  const auto depth_at = [&](int frame, Image<int, Host>* labels) { return depth_with_box(box_at(frame), labels); };
  // The box's object, made from a detection on the first frame behind the
  // low panel; returns where it starts.
  const auto first_behind_low_panel = [&](System<S, B>& sys) {
    Image<int, Host> labels;
    const Image<S, B> first = depth_with_box(box_at(0), &labels, true);
    const Detections det = detections_of(labels, 1, "cup", 0.0);
    sys.process(first, 0.0, &det);
    REQUIRE(sys.objects().size() == 1);
    return sys.objects()[0]->pose().translation();
  };
  struct Outcome {
    int frames_lost = 0, created = 0;
    bool back = false;    // object 1 is live at the end
    double error = 1e9;   // its distance from where the box went, metres
  };
  const auto run = [&](const SystemParams<S>& params) {
    System<S, B> sys(camera, params);
    Image<int, Host> labels;
    const Image<S, B> first = depth_at(0, &labels);
    const Detections det = detections_of(labels, 1, "cup", 0.0);
    sys.process(first, 0.0, &det);
    REQUIRE(sys.objects().size() == 1);
    const SE3<S> start = sys.objects()[0]->pose();
    Outcome out;
    const int last = 64;
    for (int k = 1; k <= last; ++k) {
      // Detected on the first two frames (refind_unexplained looks only for
      // objects seen by the detector twice).
      Image<int, Host> seen;
      const Image<S, B> depth = depth_at(k, k == 1 ? &seen : nullptr);
      const Detections again = k == 1 ? detections_of(seen, 1, "cup", k / 30.0) : Detections{};
      const FrameResult r = sys.process(depth, k / 30.0, k == 1 ? &again : nullptr);
      out.created += int(r.created.size());
      out.frames_lost += sys.objects().empty() ? 1 : 0;
    }
    out.back = sys.objects().size() == 1 && sys.objects()[0]->id() == 1;
    if (out.back) {
      // The box only translates: so does its object frame.
      const Vec3<S> moved = sys.objects()[0]->pose().translation() - start.translation();
      out.error = double(norm(moved - (box_at(last) - box_at(0))));
    }
    return out;
  };
  SystemParams<S> params = small_params<S>();
  SECTION("held while hidden and looked for where it went: back within a second, where the box is") {
    REQUIRE(params.hold_occluded_objects);
    REQUIRE(params.refind_moving_seconds > S(0));
    const Outcome out = run(params);
    INFO("frames without the object: " << out.frames_lost << ", error " << out.error << " m");
    CHECK(out.created == 0);
    CHECK(out.back);
    CHECK(out.error < 0.015);
    CHECK(out.frames_lost < 30);
  }
  SECTION("the motion is believed for hidden_moving_seconds: a box that stops behind a panel is held near it") {
    // A panel that hides the lower two thirds of the box: the box stops
    // behind it (frame 30, x = 0) and stays there, its top in view. An
    // object carried on at its velocity without end runs on past it. The
    // top third shows at least as many of the 160x120 frame's pixels as
    // keep the object visible (min_mask_pixels 1600 at 640x480, 100
    // here): the hidden rule leaves it to tracking (checked last). With
    // 250 (4000 at 640x480) it shows too little and is held; its model is
    // drawn behind the panel (occlusion_margin of a metre: the rendering
    // does not let the background hide it, as it does not behind a thin
    // or unmapped occluder, c214-tab600's chair), so it stays visible.
    const SystemParams<S> shown_enough = params;
    params.min_mask_pixels = 4000;
    params.occlusion_margin = S(1);
    const auto stopped_at = [&](int frame) { return box_at(std::min(frame, 30)); };
    struct Hidden {
      int moved_on = 0;       // frames 51-70 the object moved on in
      double drift = 0;       // how far it went in them, metres
      double error = 1e9;     // its distance from the box at frame 70
    };
    const auto hidden = [&](S seconds, const SystemParams<S>& with) {
      SystemParams<S> p = with;
      p.hidden_moving_seconds = seconds;
      System<S, B> sys(camera, p);
      const Vec3<S> start = first_behind_low_panel(sys);
      Hidden out;
      Vec3<S> last = start;
      for (int k = 1; k <= 70; ++k) {
        const FrameResult r = sys.process(depth_with_box(stopped_at(k), nullptr, true), k / 30.0);
        REQUIRE(sys.objects().size() == 1);
        const Vec3<S> at = sys.objects()[0]->pose().translation();
        if (k > 50 && r.object_status[0].tracking == TrackingOutcome::moved_on) {
          ++out.moved_on;
          out.drift += double(norm(at - last));
        }
        last = at;
        out.error = double(norm(at - start - (stopped_at(k) - box_at(0))));
      }
      return out;
    };
    const Hidden bounded = hidden(params.hidden_moving_seconds, params), unbounded = hidden(S(100), params);
    INFO("frames 51-70: bounded " << bounded.moved_on << " moved on, " << bounded.drift << " m drift, error "
                                  << bounded.error << " m; unbounded " << unbounded.moved_on << ", "
                                  << unbounded.drift << " m, " << unbounded.error << " m");
    CHECK(bounded.moved_on == 20);
    CHECK(bounded.drift == 0);  // where its motion took it, bit for bit
    CHECK(unbounded.moved_on > 5);
    CHECK(unbounded.drift > 0.01);
    CHECK(bounded.error < unbounded.error);
    // Showing as many pixels as keep it visible, it is tracked on them.
    const Hidden tracked = hidden(shown_enough.hidden_moving_seconds, shown_enough);
    INFO("shown enough: " << tracked.moved_on << " moved on, error " << tracked.error << " m");
    CHECK(tracked.moved_on == 0);
    CHECK(tracked.error < bounded.error);
  }
  SECTION("partly hidden, it is associated and solved from its prediction (predict_hidden_share)") {
    // The box moves on behind the low panel, its top third in view: tracked
    // on that (it shows enough), but from where its velocity takes it.
    REQUIRE_FALSE(params.predict_motion);
    struct Partly {
      int predicted = 0;   // frames whose solve started at the prediction
      double error = 1e9;  // distance from the box at the last frame, metres
    };
    const auto behind_low_panel = [&](S share) {
      SystemParams<S> p = params;
      p.predict_hidden_share = share;
      System<S, B> sys(camera, p);
      const Vec3<S> start = first_behind_low_panel(sys);
      Partly out;
      const int last = 45;
      for (int k = 1; k <= last; ++k) {
        Image<int, Host> seen;
        const Image<S, B> depth = depth_with_box(box_at(k), k == 1 ? &seen : nullptr, true);
        const Detections again = k == 1 ? detections_of(seen, 1, "cup", k / 30.0) : Detections{};
        const FrameResult r = sys.process(depth, k / 30.0, k == 1 ? &again : nullptr);
        REQUIRE(sys.objects().size() == 1);
        out.predicted += r.object_status[0].tracking == TrackingOutcome::tracked && r.object_status[0].from_prediction;
      }
      out.error = double(norm(sys.objects()[0]->pose().translation() - start - (box_at(last) - box_at(0))));
      return out;
    };
    const Partly with = behind_low_panel(params.predict_hidden_share), without = behind_low_panel(S(0));
    INFO("share " << params.predict_hidden_share << ": " << with.predicted << " frames from the prediction, error "
                  << with.error << " m; share 0: " << without.predicted << ", " << without.error << " m");
    REQUIRE(params.predict_hidden_share > S(0));
    CHECK(with.predicted >= 10);
    CHECK(without.predicted == 0);
    // Its top third's edges tell where it is either way: the prediction
    // must not cost accuracy there.
    CHECK(with.error <= without.error + 0.002);
  }
  SECTION("without the hold and the carried pose, found where it went in what no model explains") {
    params.hold_occluded_objects = false;
    params.refind_moving_seconds = S(0);
    REQUIRE(params.refind_unexplained_every > 0);
    const Outcome out = run(params);
    INFO("frames without the object: " << out.frames_lost << ", error " << out.error << " m");
    CHECK(out.created == 0);
    CHECK(out.back);
    CHECK(out.error < 0.015);
  }
  SECTION("without any of the three: lost behind the panel and not found where it went") {
    params.hold_occluded_objects = false;
    params.refind_moving_seconds = S(0);
    params.refind_unexplained_every = 0;
    const Outcome out = run(params);
    INFO("frames without the object: " << out.frames_lost << ", error " << out.error << " m");
    CHECK_FALSE((out.back && out.error < 0.015));
  }
}

TEMPLATE_LIST_TEST_CASE("Tracking back's E-step of one object is the E-step's image of it, pixel for pixel", "[slam]",
                        emfusion::test::SystemRuleConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // The box (with slats) detected on frame 0 and tracked over three
  // frames, 1 cm a frame; then a frame with it 2 cm further, as a kept frame
  // would show it, against the object at its last pose.
  for (const bool sparse : {true, false}) {
    SystemParams<S> params = small_params<S>();
    params.sparse_background = sparse;
    const auto box_at = [](int k) { return vec3(S(-0.05) + S(0.01) * S(k), S(0), S(1.2)); };
    FirstFrame<S, B> first("cup", 1, params, box_at(0), true);
    System<S, B>& sys = first.system;
    for (int k = 1; k <= 3; ++k)
      sys.process(BoxScene<S>(box_at(k), 1, true).template depth<B>(SE3<S>::identity()), k / 30.0);
    REQUIRE(sys.map().objects.size() == 1);
    const ObjectModel<S, B>& o = *sys.map().objects[0];
    Frame<S, B> f;
    back_project(BoxScene<S>(box_at(5), 1, true).template depth<B>(SE3<S>::identity()), first.scene.camera, f.points);
    const SE3<S> T_vc = o.volume().pose().inverse() * sys.map().T_world_camera;
    const auto& likelihood = sys.parts().likelihood;
    const auto model = bind_volume<S>(likelihood, o.volume().view(), o.foreground().view());
    associate_with(sys.map().background, sys.map().T_world_camera, std::vector{model}, {T_vc}, f, likelihood);
    Image<S, B> share;
    detail::track_back::object_share(sys.map().background, sys.map().T_world_camera, model, T_vc, f.points, likelihood,
                                     share);
    const std::vector<S> e_step = f.associations.image(1).to_host(), shared = share.to_host();
    REQUIRE(e_step.size() == shared.size());
    std::size_t differ = 0, own = 0, partly = 0;
    for (std::size_t i = 0; i < e_step.size(); ++i) {
      differ += !(e_step[i] == shared[i]);
      own += shared[i] > S(0.5);
      partly += shared[i] > S(0) && shared[i] < S(0.5);
    }
    INFO((sparse ? "sparse" : "dense") << " background: " << differ << " pixels differ; " << own << " the object's, "
                                       << partly << " partly");
    CHECK(differ == 0);
    CHECK(own > 500);   // about 1100 pixels are the box's ...
    CHECK(partly > 0);  // ... and the background shares some of them
  }
}

TEMPLATE_LIST_TEST_CASE("An object created late is tracked back through the frames before its creation", "[slam]",
                        emfusion::test::SystemRuleConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // The box of BoxScene (with its slats) moving 2.5 cm a frame to the right
  // before a static camera; the detector runs on frames 0 and 12 and finds
  // it only on 12 (a missed first detection).
  const auto box_at = [](int frame, S x0) { return vec3(x0 + S(0.025) * S(frame), S(0), S(1.2)); };
  const int detected_at = 12;
  struct Run {
    FrameResult created;     // the result of the frame that created it
    ObjectRecord record;     // its record at the end
    Trajectory camera;       // the camera's
    int history_frames = 0;  // ObjectHistories' tracked_back
    std::vector<int> in_view;  // frame k: the box's rendered pixels inside the visibility border
  };
  const auto run = [&](int keep, S x0, bool use_association = true) {
    SystemParams<S> params = small_params<S>();
    params.track_back_frames = keep;
    params.use_association = use_association;
    const BoxScene<S> first(box_at(0, x0), 1, true);
    System<S, B> sys(first.camera, params);
    ObjectHistories histories;
    Run out;
    const int border = params.visibility_border_for(first.camera.width);
    for (int k = 0; k <= detected_at + 3; ++k) {
      const BoxScene<S> scene(box_at(k, x0), 1, true);
      Image<int, Host> labels;
      const Image<S, B> depth = scene.template depth<B>(SE3<S>::identity(), &labels);
      const std::vector<int> shape = labels.to_host();
      int own = 0;
      for (std::size_t i = 0; i < shape.size(); ++i)
        own += shape[i] == 1 && labels.view().inside_border(int(i), border);
      out.in_view.push_back(own);
      const Detections det = detections_of(labels, 1, k == detected_at ? "cup" : "", k / 30.0);
      const bool detector = k == 0 || k == detected_at;
      const FrameResult r = sys.process(depth, k / 30.0, detector ? &det : nullptr);
      histories.add(r, sys.map());
      if (k == detected_at) out.created = r;
      if (k < detected_at) REQUIRE(sys.objects().empty());
    }
    REQUIRE(sys.object_records().size() == 1);
    out.record = sys.object_records()[0];
    out.camera = sys.camera_trajectory();
    out.history_frames = histories.objects().at(1).tracked_back;
    return out;
  };
  // Frame k of a record's trajectory: its pose's timestamp times 30.
  const auto frame_of = [](const TimedPose& p) { return int(std::lround(p.timestamp * 30)); };
  // Where the box went from the frame that created the object, against where
  // the trajectory says it went, seen from the camera (the box only
  // translates, and so does the object frame): the largest difference over
  // the poses before frame 12.
  const auto largest_error = [&](const Run& r, S x0) {
    const Trajectory& t = r.record.trajectory;
    const auto created = std::find_if(t.begin(), t.end(), [&](const TimedPose& p) { return frame_of(p) == detected_at; });
    REQUIRE(created != t.end());
    const auto seen = [&](const TimedPose& p) {  // the object's origin in the camera frame of its frame
      return (r.camera[std::size_t(frame_of(p))].pose.inverse() * p.pose).translation();
    };
    double worst = 0;
    for (auto p = t.begin(); p != created; ++p) {
      const Vec3<double> moved = seen(*p) - seen(*created);
      const Vec3<S> truth = box_at(frame_of(*p), x0) - box_at(detected_at, x0);
      worst = std::max(worst, double(norm(moved - vec3(double(truth.x()), double(truth.y()), double(truth.z())))));
    }
    return worst;
  };
  SECTION("in view from the start: tracked back to frame 0, where the box was") {
    const S x0 = S(-0.12);
    const Run r = run(30, x0);
    REQUIRE(r.created.created == std::vector<int>{1});
    REQUIRE(r.created.tracked_back.size() == 1);
    CHECK(r.created.tracked_back[0].id == 1);
    CHECK(r.created.tracked_back[0].frames == detected_at);
    CHECK(r.history_frames == detected_at);
    // One pose a frame, in time order, from frame 0; first_timestamp with them.
    const Trajectory& t = r.record.trajectory;
    REQUIRE(t.size() == std::size_t(detected_at + 4));
    for (std::size_t k = 0; k < t.size(); ++k) CHECK(frame_of(t[k]) == int(k));
    CHECK(r.record.first_timestamp == t.front().timestamp);
    const double error = largest_error(r, x0);
    INFO("largest error of the poses tracked back: " << error << " m");
    CHECK(error < 0.01);  // the box moved 30 cm over them
  }
  SECTION("in the ablation without association: tracked back by the foreground probability") {
    const S x0 = S(-0.12);
    const Run r = run(30, x0, false);
    REQUIRE(r.created.tracked_back.size() == 1);
    CHECK(r.created.tracked_back[0].frames == detected_at);
    const double error = largest_error(r, x0);
    INFO("largest error of the poses tracked back: " << error << " m");
    CHECK(error < 0.01);
  }
  SECTION("as many frames back as are kept, and none with track_back_frames 0") {
    const S x0 = S(-0.12);
    const Run five = run(5, x0);
    REQUIRE(five.created.tracked_back.size() == 1);
    CHECK(five.created.tracked_back[0].frames == 5);
    CHECK(frame_of(five.record.trajectory.front()) == detected_at - 5);
    const Run off = run(0, x0);
    CHECK(off.created.tracked_back.empty());
    CHECK(off.history_frames == 0);
    CHECK(frame_of(off.record.trajectory.front()) == detected_at);
    CHECK(off.record.first_timestamp == detected_at / 30.0);
  }
  SECTION("coming into view: not tracked back into frames that do not show it") {
    // From beyond the left edge of the image (the view ends 0.69 m left of
    // the centre at the box's depth; the box is 0.3 m wide, turned).
    const S x0 = S(-0.9);
    const Run r = run(30, x0);
    REQUIRE(r.created.tracked_back.size() == 1);
    const int first = frame_of(r.record.trajectory.front());
    std::string shown;  // the box's pixels inside the border, frame by frame
    for (int n : r.in_view) shown += std::to_string(n) + " ";
    INFO("tracked back to frame " << first << "; pixels inside the border by frame: " << shown);
    const int min_pixels = small_params<S>().keep_mask_pixels_for(160, 120);
    REQUIRE(r.in_view[0] < min_pixels);
    REQUIRE(r.in_view[std::size_t(detected_at - 4)] >= 2 * min_pixels);
    CHECK(first > 0);
    for (int k = first; k < detected_at; ++k) CHECK(r.in_view[std::size_t(k)] >= min_pixels);
    CHECK(r.in_view[std::size_t(first - 1)] < 2 * min_pixels);  // it stopped about where the box left the view
    // The first of them show only the part the image border leaves: off by
    // up to 1.7 cm there (float, CPU), as against the 50 cm the box moved.
    const double error = largest_error(r, x0);
    INFO("largest error of the poses tracked back: " << error << " m");
    CHECK(error < 0.025);
  }
}
