// Rules of the object map, one at a time, on small static scenes with
// hand-made detections (the box scene of support/box_scene.hpp): resizing
// keeps the fused surface in place, objects are created from detections but
// never from static classes, a mask that spills onto the wall behind still
// sizes the volume by the object, a resting object stays associated,
// existence falls below 0.1 after repeated misses and the object is deleted,
// objects that leave the view are deleted (with lost_object_frames = 0 gone
// for good), a new object at the border survives until seen, a young object
// is lost at once when the frame no longer shows it and keeps its pose until
// seen, an object leaving the view keeps its pose, and an object created
// late is tracked back through the frames kept before it, as far as they
// show it. Losing and finding again: test_lost_objects.cpp; objects hidden
// behind others: test_hidden_objects.cpp.
// The long ones run in float only (SystemRuleConfigs, support/configs.hpp).
#include <algorithm>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "emfusion/slam/object_history.hpp"
#include "emfusion/volume/marching_cubes.hpp"
#include "support/box_scene.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"
#include "support/fusion.hpp"
#include "support/system_instances.hpp"

using namespace emfusion;
using namespace emfusion::test;

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
