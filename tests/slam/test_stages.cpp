// The per-frame stages of slam/ called one at a time, without System, on a
// small scene (a wall, a box in front of it, a floor and a ball): preprocessing, mapping of
// the first frame, creation of an object from a mask, the E-step at known
// poses, one camera tracking step, rendering (and an object seen through a
// trace in the background, occlusion_seen_through), resizing from a detection,
// deletion by the existence rule, and the rules counted only where the
// object is visible, with unseen and weakly associated objects kept as lost,
// an object left behind by its tracking moved onto its detection, detections
// matched only where the frame shows an object, what no model explains kept
// out of the background while a lost object is looked for (and a point in
// space the background never saw unexplained only in front of a surface it
// saw), two models of one object merged, and an object's refused solves
// taken when they agree from frame to frame; then the full system with a
// likelihood, a norm and a solver defined here, as a user would, and with
// colour in its objects' models (object_colour_weight).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "emfusion/sim/primitives.hpp"
#include "emfusion/sim/render.hpp"
#include "support/system_instances.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"

using namespace emfusion;

// Outside the anonymous namespace: nvcc warns that a member template of a
// type with internal linkage, instantiated only by the PoseSolver
// concept's check, is "declared but never referenced".
namespace stages_test {

/// The library's Levenberg-Marquardt behind a type of its own: a user's
/// solver, which tracking runs one problem at a time.
struct LevenbergMarquardtOneByOne {
  LevenbergMarquardt lm;
  template <class F, class S>
  SE3<S> solve(F&& linearize, const SE3<S>& start, SolveReport* report = nullptr) const {
    return lm.solve(std::forward<F>(linearize), start, report);
  }
};

}  // namespace stages_test
using stages_test::LevenbergMarquardtOneByOne;

namespace {

/// A wall 2 m ahead, a box 0.8 m in front of it, a floor and a ball, seen by a
// 160x120 camera.
template <class S>
struct WallAndBox {
  PinholeCamera<S> camera{S(140), S(140), S(79.5), S(59.5), 160, 120};
  sim::Scene<S> scene;
  SystemParams<S> params;
  /// The wall, 2 m ahead.
  static sim::Shape<S> wall() {
    return sim::make_plane(sim::look_at(vec3(S(0), S(0), S(2)), Vec3<S>::zero(), vec3(S(0), S(-1), S(0))));
  }
  /// The box, 1.2 m ahead, moved by `T_moved` (in the world).
  static sim::Shape<S> box(const SE3<S>& T_moved = SE3<S>::identity()) {
    return sim::make_box(T_moved * SE3<S>(so3_exp(vec3(S(0.2), S(0.4), S(0))), vec3(S(0), S(0), S(1.2))),
                         vec3(S(0.15), S(0.1), S(0.12)));
  }
  WallAndBox() {
    scene.add(wall());
    scene.add(box());
    // A floor and a ball on it, so that every direction of the camera's
    // motion shows in the depth (a wall alone does not fix motion along it).
    scene.add(sim::make_plane(sim::look_at(vec3(S(0), S(0.5), S(0)), Vec3<S>::zero(), vec3(S(0), S(0), S(1)))));
    scene.add(sim::make_sphere(vec3(S(-0.45), S(0.3), S(1.6)), S(0.2)));
    params.background_voxels = 128;
    params.background_voxel_size = S(0.025);
  }
  /// Depth from `pose` on backend B; `labels` gets the shape per pixel (1: the box).
  template <class B>
  Image<S, B> depth(const SE3<S>& pose, Image<int, Host>* labels = nullptr) const {
    Image<S, Host> d;
    sim::render_depth(scene, camera, pose, d, labels);
    return d.template to<B>();
  }
};

/// The pixels of scene shape `shape` (`labels`, as sim::render_depth
/// writes them) as detection instance 5 of `class_name`.
inline Detections shape_detection(const Image<int, Host>& labels, int shape, const std::string& class_name) {
  Detections d;
  std::vector<std::uint16_t> px;
  for (int l : labels.to_host()) px.push_back(std::uint16_t(l == shape ? 5 : 0));
  d.labels = Image<std::uint16_t, Host>::from_host(labels.width(), labels.height(), px);
  d.instances.push_back({5, class_name, 0.9});
  return d;
}

/// The box's pixels (shape 1) as detection instance 5 of `class_name`.
inline Detections box_detection(const Image<int, Host>& labels, const std::string& class_name) {
  return shape_detection(labels, 1, class_name);
}

/// The mean of `values` over the pixels where `labels` is `label`.
template <class S>
double mean_where(const std::vector<S>& values, const std::vector<int>& labels, int label) {
  double sum = 0;
  int n = 0;
  for (std::size_t i = 0; i < values.size(); ++i)
    if (labels[i] == label) sum += double(values[i]), ++n;
  return n > 0 ? sum / n : -1.0;
}


/// A map that fused the first view and holds an object made from the box's
/// mask, as the stages leave it after one frame.
template <class S, class B>
struct OneFrameMap {
  WallAndBox<S> s;
  Image<int, Host> labels;
  Image<S, B> depth = s.template depth<B>(SE3<S>::identity(), &labels);
  Map<S, B> map{s.params};
  Frame<S, B> frame;
  FrameResult result;
  explicit OneFrameMap(const std::string& class_name = "cup") {
    result.depth = preprocess(depth, s.camera, s.params, frame);
    render_models(map, frame, s.camera, s.params, workspace);
    const Detections det = box_detection(labels, class_name);
    const std::vector<int> seg = frame.segmentation.to_host();
    const S outside = unexplained_association<S>(PaperLikelihood<S>{});
    auto created = create_object(map, det, 0, seg, frame.points.to_host(), s.camera, s.params, outside, result);
    std::vector<NewObjectWeights<S, B>> fresh;
    if (created) fresh.push_back(std::move(*created));
    integrate_models(map, frame, s.camera, s.params, fresh, true);
    update_foreground_counts(map, frame, det, seg, {-1}, fresh, s.camera);
    map.started = true;
  }
  RenderWorkspace<S, B> workspace;
};

}  // namespace

TEMPLATE_LIST_TEST_CASE("Stages alone: preprocessing, first mapping and object creation", "[slam]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  OneFrameMap<S, B> m;
  const std::vector<int> shape = m.labels.to_host();
  int seen = 0;
  for (int l : shape) seen += l >= 0;
  // Every rendered pixel is a measurement; the rest are holes.
  CHECK(m.result.depth.valid == seen);
  CHECK(m.result.depth.valid + m.result.depth.missing == int(shape.size()));
  // Without objects, the segmentation is the background wherever there is depth.
  REQUIRE(m.result.created.size() == 1);
  REQUIRE(m.map.objects.size() == 1);
  REQUIRE(m.map.records.size() == 1);
  CHECK(m.map.records[0].id == m.result.created[0]);
  CHECK(m.map.objects[0]->class_name() == "cup");
  CHECK(m.map.next_id == 2);
  // The object sits on the box (1.2 m ahead), the background was fused.
  CHECK(std::abs(double(m.map.objects[0]->pose().translation().z()) - 1.2) < 0.12);
  S sdf = S(1);
  const bool sampled = m.map.background.visit([&](const auto& volume) {
    const auto background = volume.template to<Host>();
    return background.view().sample(background.pose().inverse() * vec3(S(0.5), S(0.3), S(2)), sdf);
  });
  CHECK(sampled);
  CHECK(std::abs(double(sdf)) < 0.02);
  // A static class makes nothing.
  OneFrameMap<S, B> table("dining_table");
  CHECK(table.map.objects.empty());
  CHECK(table.result.created.empty());
}

TEMPLATE_LIST_TEST_CASE("Stages alone: the E-step at known poses, one tracking step, rendering", "[slam]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  OneFrameMap<S, B> m;
  REQUIRE(m.map.objects.size() == 1);
  const std::vector<int> shape = m.labels.to_host();
  PaperLikelihood<S> likelihood;
  likelihood.params = m.s.params.likelihood;

  // The E-step of the same view: the wall belongs to the background, the
  // box mostly to the object (the background also holds the box's surface
  // from the first frame, so it keeps a share).
  preprocess(m.depth, m.s.camera, m.s.params, m.frame);
  associate(m.map, m.frame, likelihood, m.s.params);
  REQUIRE(m.frame.associations.model_count() == 2);
  const auto q_bg = m.frame.associations.image(0).to_host();
  const auto q_obj = m.frame.associations.image(1).to_host();
  CHECK(mean_where(q_bg, shape, 0) > 0.99);
  CHECK(mean_where(q_obj, shape, 0) < 0.01);
  CHECK(mean_where(q_bg, shape, 2) > 0.99);
  CHECK(mean_where(q_obj, shape, 1) > 0.5);
  for (std::size_t i = 0; i < q_bg.size(); ++i)
    if (shape[i] >= 0) CHECK(double(q_bg[i] + q_obj[i]) == emfusion::test::Approx(1.0).epsilon(1e-4));

  // One camera tracking step: the camera moved 2 cm sideways and turned a
  // little; the E-step at the previous pose, then the solve.
  const SE3<S> truth = SE3<S>(so3_exp(vec3(S(0), S(0.01), S(0))), vec3(S(0.02), S(0), S(0)));
  preprocess(m.s.template depth<B>(truth), m.s.camera, m.s.params, m.frame);
  associate(m.map, m.frame, likelihood, m.s.params);
  const PoseTrack camera = track_camera(m.map, m.frame, m.s.params, HuberNorm<S>{S(2)}, LevenbergMarquardt{});
  CHECK(camera.outcome == TrackingOutcome::tracked);
  CHECK(double(norm(m.map.T_world_camera.translation() - truth.translation())) < 0.004);
  CHECK(camera.step.translation > 0.015);

  // Rendering at the tracked pose draws the object over the box's pixels.
  Image<int, Host> moved;
  m.s.template depth<B>(truth, &moved);
  render_models(m.map, m.frame, m.s.camera, m.s.params, m.workspace);
  const std::vector<int> seg = m.frame.segmentation.to_host(), box = moved.to_host();
  int box_pixels = 0, drawn = 0;
  for (std::size_t i = 0; i < seg.size(); ++i)
    if (box[i] == 1) ++box_pixels, drawn += seg[i] == 1;
  CHECK(drawn > 0.8 * box_pixels);

  // The object's own solve from there keeps it where it is.
  associate(m.map, m.frame, likelihood, m.s.params);
  const SE3<S> before = m.map.objects[0]->pose();
  const std::vector<PoseTrack> tracks =
      track_objects(m.map, m.frame, m.s.params, HuberNorm<S>{S(2)}, LevenbergMarquardt{});
  REQUIRE(tracks.size() == 1);
  CHECK(tracks[0].outcome == TrackingOutcome::tracked);
  CHECK(double(norm(m.map.objects[0]->pose().translation() - before.translation())) < 0.01);

  // The library's solver runs batched (solved_in_batches), any other one
  // problem at a time: the same solver behind another type ends at the
  // same pose, with the same stop.
  static_assert(solved_in_batches<LevenbergMarquardt> && !solved_in_batches<LevenbergMarquardtOneByOne>);
  const SE3<S> batched = m.map.objects[0]->pose();
  m.map.objects[0]->set_pose(before);
  const std::vector<PoseTrack> one_by_one =
      track_objects(m.map, m.frame, m.s.params, HuberNorm<S>{S(2)}, LevenbergMarquardtOneByOne{});
  REQUIRE(one_by_one.size() == 1);
  CHECK(one_by_one[0].outcome == TrackingOutcome::tracked);
  CHECK(one_by_one[0].report.reason == tracks[0].report.reason);
  CHECK(one_by_one[0].report.terms == tracks[0].report.terms);
  CHECK(double(norm(m.map.objects[0]->pose().translation() - batched.translation())) < 1e-4);

  // An object flagged to be skipped (hold_decisions) is not solved, with
  // either solver: not tracked, no terms, its pose left as it was.
  const std::vector<bool> skip{true};
  const SE3<S> unsolved = SE3<S>::translation(before.translation() + vec3(S(0.03), S(0), S(0))) *
                          SE3<S>(before.rotation(), Vec3<S>::zero());
  TrackingWorkspace<S, B>* const no_workspace = nullptr;
  const std::vector<PoseStarts<S>>* const no_starts = nullptr;
  for (int solver = 0; solver < 2; ++solver) {
    m.map.objects[0]->set_pose(unsolved);
    const std::vector<PoseTrack> skipped =
        solver == 0 ? track_objects(m.map, m.frame, m.s.params, HuberNorm<S>{S(2)}, LevenbergMarquardt{},
                                    no_workspace, no_starts, &skip)
                    : track_objects(m.map, m.frame, m.s.params, HuberNorm<S>{S(2)}, LevenbergMarquardtOneByOne{},
                                    no_workspace, no_starts, &skip);
    REQUIRE(skipped.size() == 1);
    CHECK(skipped[0].outcome == TrackingOutcome::not_tracked);
    CHECK(skipped[0].attempts == 0);
    CHECK(skipped[0].report.terms == 0);
    CHECK(double(norm(m.map.objects[0]->pose().translation() - unsolved.translation())) == 0);
  }
  const std::vector<bool> wrong_size{false, false};
  CHECK_THROWS_WITH(track_objects(m.map, m.frame, m.s.params, HuberNorm<S>{S(2)}, LevenbergMarquardt{},
                                  no_workspace, no_starts, &wrong_size),
                    EMF_CONTAINS("one skip flag per live object"));
}

TEMPLATE_LIST_TEST_CASE(
    "Stages alone: a trace the object left in the background hides it only where the frame "
    "does not see through the trace (occlusion_seen_through)",
    "[slam]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // The first frame fused the box into the background too. The box then
  // moved 0.4 m back towards the wall: the background's box, a trace,
  // stands in front of the object's model, and the frame sees the box
  // behind it.
  OneFrameMap<S, B> m;
  REQUIRE(m.map.objects.size() == 1);
  const SE3<S> back = SE3<S>::translation(vec3(S(0), S(0), S(0.4)));
  sim::Scene<S> moved;
  moved.add(WallAndBox<S>::wall());
  moved.add(WallAndBox<S>::box(back));
  Image<S, Host> depth;
  Image<int, Host> labels;
  sim::render_depth(moved, m.s.camera, SE3<S>::identity(), depth, &labels);
  preprocess(depth.template to<B>(), m.s.camera, m.s.params, m.frame);
  m.map.objects[0]->set_pose(back * m.map.objects[0]->pose());
  const std::vector<int> box = labels.to_host();
  const auto drawn_on_box = [&](bool seen_through) {
    m.s.params.occlusion_seen_through = seen_through;
    render_models(m.map, m.frame, m.s.camera, m.s.params, m.workspace);
    const std::vector<int> seg = m.frame.segmentation.to_host();
    int pixels = 0, drawn = 0;
    for (std::size_t i = 0; i < seg.size(); ++i)
      if (box[i] == 1) ++pixels, drawn += seg[i] == 1;
    return double(drawn) / std::max(pixels, 1);
  };
  // The paper's rule: behind the trace by more than occlusion_margin, the
  // object loses most of its pixels.
  CHECK(drawn_on_box(false) < 0.5);
  // The frame's depth lies behind the trace too, on the object's surface:
  // the object keeps them.
  CHECK(drawn_on_box(true) > 0.8);
  // Behind the trace but not on the object (the box gone, the frame shows
  // the wall): the trace hides it still.
  sim::Scene<S> wall;
  wall.add(WallAndBox<S>::wall());
  sim::render_depth(wall, m.s.camera, SE3<S>::identity(), depth);
  preprocess(depth.template to<B>(), m.s.camera, m.s.params, m.frame);
  CHECK(drawn_on_box(true) < 0.5);
  // Where the frame shows the trace's surface (the box put back), the
  // trace hides the object either way.
  preprocess(m.depth, m.s.camera, m.s.params, m.frame);
  CHECK(drawn_on_box(true) < 0.5);
}

TEMPLATE_LIST_TEST_CASE("Stages alone: resizing from a detection, deletion by the existence rule", "[slam]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  OneFrameMap<S, B> m, r;
  REQUIRE(m.map.objects.size() == 1);
  REQUIRE(r.map.objects.size() == 1);

  // Resizing: a 16^3 object of the same voxels cannot hold the box; the
  // box's detection grows it on the sides it needs, keeping the voxel size.
  const ObjectModel<S, B>& made = *r.map.objects[0];
  const S voxel = made.volume().voxel_size();
  r.map.objects[0] = std::make_unique<ObjectModel<S, B>>(made.id(), "cup", made.pose(), 16, voxel, S(10));
  ObjectModel<S, B>& small = *r.map.objects[0];
  const Vec3i before = small.volume().dims();
  grow_for_detection(small, r.frame.points.to_host(), box_detection(r.labels, "cup").labels.view().data, 5,
                     r.map.T_world_camera, r.s.camera, r.s.params);
  const Vec3i after = small.volume().dims();
  CHECK(after[0] > before[0]);
  CHECK(after[1] > before[1]);
  CHECK(small.volume().voxel_size() == voxel);

  // Existence: created with one detection; nine misses leave p_ex = 0.1
  // (kept), a tenth takes it below (deleted, for good: not lost).
  ObjectModel<S, B>& obj = *m.map.objects[0];
  render_models(m.map, m.frame, m.s.camera, m.s.params, m.workspace);
  for (int k = 0; k < 9; ++k) obj.count_missed();
  FrameResult kept;
  delete_objects(m.map, m.frame, m.s.params, kept, true, 0, false);
  CHECK(kept.deleted.empty());
  REQUIRE(kept.object_status.size() == 1);
  CHECK(kept.object_status[0].visible_pixels > 0);
  obj.count_missed();
  // Not on a frame without the detector: existence is counted on detector frames.
  FrameResult between;
  delete_objects(m.map, m.frame, m.s.params, between, false, 0, false);
  CHECK(between.deleted.empty());
  FrameResult gone;
  delete_objects(m.map, m.frame, m.s.params, gone, true, 0, false);
  REQUIRE(gone.deleted.size() == 1);
  CHECK(gone.object_status[0].deleted == DeletionReason::existence);
  CHECK(m.map.objects.empty());
  CHECK(m.map.lost.empty());
  CHECK(m.map.records[0].deleted);
  CHECK(m.map.records[0].reason == DeletionReason::existence);
}

TEMPLATE_LIST_TEST_CASE("Stages alone: deletion rules count where the object is visible; unseen and weakly "
                        "associated objects are kept as lost",
                        "[slam]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  PaperLikelihood<S> likelihood;
  // A tracked frame at the first camera pose: the E-step and the rendering
  // that delete_objects reads, as System leaves them.
  const auto observe = [&](OneFrameMap<S, B>& m, const Image<S, B>& depth) {
    likelihood.params = m.s.params.likelihood;
    preprocess(depth, m.s.camera, m.s.params, m.frame);
    associate(m.map, m.frame, likelihood, m.s.params);
    render_models(m.map, m.frame, m.s.camera, m.s.params, m.workspace);
  };
  const SE3<S> behind_camera(so3_exp(vec3(S(0), S(0), S(0))), vec3(S(0), S(0), S(-5)));

  SECTION("an object that renders nowhere is lost as not visible (it had a mean association of 0)") {
    OneFrameMap<S, B> m;
    REQUIRE(m.map.objects.size() == 1);
    m.map.objects[0]->set_pose(behind_camera * m.map.objects[0]->pose());
    observe(m, m.depth);
    FrameResult r;
    delete_objects(m.map, m.frame, m.s.params, r, false, 0, true);
    REQUIRE(r.object_status.size() == 1);
    CHECK(r.object_status[0].visible_pixels == 0);
    CHECK(r.object_status[0].deleted == DeletionReason::not_visible);
    CHECK(m.map.objects.empty());
    CHECK(m.map.lost.size() == 1);
  }

  SECTION("an object drawn where its box no longer is: weakly associated while visible, kept as lost") {
    OneFrameMap<S, B> m;
    REQUIRE(m.map.objects.size() == 1);
    // The box moved 0.45 m sideways (a move tracking did not follow): the
    // model is drawn over the wall behind where the box was.
    m.s.scene.shapes[1] = sim::make_box(SE3<S>(so3_exp(vec3(S(0.2), S(0.4), S(0))), vec3(S(0.45), S(0), S(1.2))),
                                        vec3(S(0.15), S(0.1), S(0.12)));
    observe(m, m.s.template depth<B>(SE3<S>::identity()));
    FrameResult r;
    delete_objects(m.map, m.frame, m.s.params, r, false, 0, true);
    REQUIRE(r.object_status.size() == 1);
    const ObjectStatus& st = r.object_status[0];
    CHECK(st.rendered_pixels >= m.s.params.min_mask_pixels_for(m.s.camera.width, m.s.camera.height));
    CHECK(st.mean_association < m.s.params.min_association);
    CHECK(st.deleted == DeletionReason::weak_association);
    CHECK(m.map.objects.empty());
    REQUIRE(m.map.lost.size() == 1);
    CHECK(m.map.records[0].reason == DeletionReason::weak_association);
  }

  SECTION("a detector frame counts a miss only for an object that is visible") {
    OneFrameMap<S, B> m;
    REQUIRE(m.map.objects.size() == 1);
    ObjectModel<S, B>& obj = *m.map.objects[0];
    Detections none;
    none.labels = Image<std::uint16_t, Host>::from_host(
        m.s.camera.width, m.s.camera.height,
        std::vector<std::uint16_t>(std::size_t(m.s.camera.width) * std::size_t(m.s.camera.height), 0));
    const auto detector_frame = [&] {
      FrameResult r;
      handle_detections(m.map, m.frame, none, m.frame.segmentation.to_host(), m.s.camera, m.s.params, likelihood,
                        HuberNorm<S>{S(2)}, LevenbergMarquardt{}, r);
    };
    observe(m, m.depth);
    detector_frame();
    CHECK(obj.non_existence_count() == 1);
    obj.set_pose(behind_camera * obj.pose());  // out of sight: the detector could not have seen it
    observe(m, m.depth);
    detector_frame();
    CHECK(obj.non_existence_count() == 1);
    CHECK(obj.existence_count() == 1);
  }
}

TEMPLATE_LIST_TEST_CASE("Stages alone: an object left behind by its tracking moves onto its detection",
                        "[slam]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  OneFrameMap<S, B> m;
  REQUIRE(m.map.objects.size() == 1);
  const SE3<S> before = m.map.objects[0]->pose();
  // The box moved 0.3 m sideways in one step that tracking did not follow:
  // the model is still drawn where the box was, over the wall behind.
  const Vec3<S> shift = vec3(S(0.3), S(0), S(0));
  m.s.scene.shapes[1] = sim::make_box(SE3<S>(so3_exp(vec3(S(0.2), S(0.4), S(0))), vec3(S(0), S(0), S(1.2)) + shift),
                                      vec3(S(0.15), S(0.1), S(0.12)));
  Image<int, Host> labels;
  const Image<S, B> depth = m.s.template depth<B>(SE3<S>::identity(), &labels);
  PaperLikelihood<S> likelihood;
  likelihood.params = m.s.params.likelihood;
  const auto observe = [&] {
    preprocess(depth, m.s.camera, m.s.params, m.frame);
    associate(m.map, m.frame, likelihood, m.s.params);
    render_models(m.map, m.frame, m.s.camera, m.s.params, m.workspace);
  };
  observe();
  const Detections det = box_detection(labels, "cup");
  const HuberNorm<S> huber{S(2)};
  // Relocalization with `detections` moves nothing.
  const auto stays = [&](const Detections& detections) {
    CHECK(relocalize_objects(m.map, m.frame, detections, m.frame.segmentation.to_host(), m.s.camera, m.s.params,
                             huber, LevenbergMarquardt{})
              .empty());
    CHECK(double(norm(m.map.objects[0]->pose().translation() - before.translation())) == 0.0);
  };

  SECTION("off (0): nothing moves") {
    m.s.params.relocalize_below = 0;
    stays(det);
  }
  SECTION("a detection of another class does not take it") {
    m.s.params.relocalize_below = 0.5;
    m.map.objects[0]->count_detected();
    stays(box_detection(labels, "book"));
  }
  SECTION("detected once, as a model made from a false positive is, it stays") {
    m.s.params.relocalize_below = 0.5;
    REQUIRE(m.map.objects[0]->existence_count() == 1);
    stays(det);
  }
  SECTION("on, detected twice: it moves onto the detection, which then matches it; no second object") {
    m.s.params.relocalize_below = 0.5;
    m.map.objects[0]->count_detected();
    const std::vector<int> moved = relocalize_objects(m.map, m.frame, det, m.frame.segmentation.to_host(), m.s.camera,
                                                      m.s.params, huber, LevenbergMarquardt{});
    REQUIRE(moved.size() == 1);
    CHECK(moved[0] == m.map.objects[0]->id());
    const Vec3<S> moved_by = m.map.objects[0]->pose().translation() - before.translation();
    INFO("moved by (" << moved_by.x() << ", " << moved_by.y() << ", " << moved_by.z() << ") m");
    CHECK(double(norm(moved_by - shift)) < 0.02);
    observe();
    FrameResult r;
    handle_detections(m.map, m.frame, det, m.frame.segmentation.to_host(), m.s.camera, m.s.params, likelihood, huber,
                      LevenbergMarquardt{}, r);
    CHECK(r.matched == 1);
    CHECK(r.created.empty());
    CHECK(m.map.objects.size() == 1);
  }
}

TEMPLATE_LIST_TEST_CASE("Stages alone: detections match an object only where the frame shows it", "[slam]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  OneFrameMap<S, B> m;
  REQUIRE(m.map.objects.size() == 1);
  ObjectModel<S, B>& box = *m.map.objects[0];
  // Something no model holds (shape 4, a ball 0.5 m nearer) passes in front
  // of the box's object and hides it; the detector sees the ball, of the
  // box object's class.
  m.s.scene.add(sim::make_sphere(vec3(S(0), S(0), S(0.7)), S(0.15)));
  Image<int, Host> labels;
  const Image<S, B> depth = m.s.template depth<B>(SE3<S>::identity(), &labels);
  PaperLikelihood<S> likelihood;
  likelihood.params = m.s.params.likelihood;
  preprocess(depth, m.s.camera, m.s.params, m.frame);
  associate(m.map, m.frame, likelihood, m.s.params);
  render_models(m.map, m.frame, m.s.camera, m.s.params, m.workspace);
  const Detections ball = shape_detection(labels, 4, box.class_name());
  const std::vector<int> drawn = m.frame.segmentation.to_host();
  const std::vector<int> seen = seen_segmentation(m.frame, m.s.params, m.workspace);
  const std::vector<int> shape = labels.to_host();
  REQUIRE(seen.size() == drawn.size());
  int drawn_on_ball = 0, seen_on_ball = 0, changed_elsewhere = 0;
  for (std::size_t i = 0; i < seen.size(); ++i) {
    if (shape[i] == 4) {
      drawn_on_ball += drawn[i] == 1, seen_on_ball += seen[i] == 1;
      if (drawn[i] == 1) CHECK(seen[i] == 0);  // behind the ball: background, as the frame shows it
    } else {
      changed_elsewhere += seen[i] != drawn[i];
    }
  }
  INFO("object drawn on " << drawn_on_ball << " of the ball's pixels");
  REQUIRE(drawn_on_ball > 200);  // the model is drawn behind the ball ...
  CHECK(seen_on_ball == 0);      // ... and seen nowhere there
  CHECK(changed_elsewhere == 0);

  const HuberNorm<S> huber{S(2)};
  SECTION("the drawn segmentation would give the ball's detection to the hidden object") {
    FrameResult r;
    const DetectionUpdate<S, B> u = handle_detections(m.map, m.frame, ball, drawn, m.s.camera, m.s.params, likelihood,
                                                      huber, LevenbergMarquardt{}, r);
    CHECK(r.matched == 1);
    CHECK(u.object_of_detection[0] == 0);
  }
  SECTION("matched as the frame shows it, it does not: the ball is an object of its own, the box is neither "
          "detected nor missed") {
    const int detected = box.existence_count(), missed = box.non_existence_count();
    FrameResult r;
    const DetectionUpdate<S, B> u = handle_detections(m.map, m.frame, ball, drawn, m.s.camera, m.s.params, likelihood,
                                                      huber, LevenbergMarquardt{}, r, &seen);
    CHECK(r.matched == 0);
    CHECK(u.object_of_detection[0] == -1);
    CHECK(r.created.size() == 1);
    CHECK(m.map.objects.size() == 2);
    CHECK(box.existence_count() == detected);
    CHECK(box.non_existence_count() == missed);
  }
}

namespace {

/// OneFrameMap with its box's object lost (it left the view), detected on
/// `detections` detector frames, and the next frame, in which a ball 1 m
/// ahead (shape 4), in space the background saw empty, is what no model
/// explains: preprocessed, drawn and associated.
template <class S, class B>
struct LostBoxAndBall : OneFrameMap<S, B> {
  Image<int, Host> ball_labels;
  explicit LostBoxAndBall(int detections) {
    Map<S, B>& map = this->map;
    REQUIRE(map.objects.size() == 1);
    for (int k = 1; k < detections; ++k) map.objects[0]->count_detected();
    map.lost.push_back({std::move(map.objects[0]), 0});
    map.objects.clear();
    map.frames = 1;
    this->s.scene.add(sim::make_sphere(vec3(S(0.35), S(-0.15), S(1.0)), S(0.12)));
    const Image<S, B> depth = this->s.template depth<B>(SE3<S>::identity(), &ball_labels);
    PaperLikelihood<S> likelihood;
    likelihood.params = this->s.params.likelihood;
    preprocess(depth, this->s.camera, this->s.params, this->frame);
    render_models(map, this->frame, this->s.camera, this->s.params, this->workspace);
    associate(map, this->frame, likelihood, this->s.params);
  }
  /// How many of the ball's pixels MarkUnexplained marks now.
  int ball_marked() {
    Image<std::uint8_t, B> marked;
    detail::unexplained::mark_unexplained(this->map, this->frame, this->s.params, 0,
                                          this->frame.associations.image(0), marked);
    const std::vector<std::uint8_t> v = marked.to_host();
    const std::vector<int> shape = ball_labels.to_host();
    int n = 0;
    for (std::size_t i = 0; i < v.size(); ++i) n += shape[i] == 4 && v[i];
    return n;
  }
};

}  // namespace

TEMPLATE_LIST_TEST_CASE("Stages alone: while a lost object is looked for, the background leaves out what no model "
                        "explains",
                        "[slam]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  Image<S, B> weights;
  SECTION("not held for an object detected once, on a detector frame, or with hold_unexplained off") {
    LostBoxAndBall<S, B> once(1);
    CHECK_FALSE(hold_unexplained(once.map, once.frame, once.s.params, false, weights));
    LostBoxAndBall<S, B> m(2);
    CHECK_FALSE(hold_unexplained(m.map, m.frame, m.s.params, true, weights));
    SystemParams<S> off = m.s.params;
    off.hold_unexplained = false;
    CHECK_FALSE(hold_unexplained(m.map, m.frame, off, false, weights));
    CHECK(weights.empty());
  }
  SECTION("held: weight 0 on the ball, the E-step's elsewhere; ten frames later the ball is still unexplained, "
          "where without the hold the background has taken it in") {
    LostBoxAndBall<S, B> m(2), unheld(2);
    REQUIRE(hold_unexplained(m.map, m.frame, m.s.params, false, weights));
    const std::vector<S> held = weights.to_host(), association = m.frame.associations.image(0).to_host();
    const std::vector<int> shape = m.ball_labels.to_host();
    REQUIRE(held.size() == association.size());
    int ball = 0, ball_held = 0, other_changed = 0;
    for (std::size_t i = 0; i < held.size(); ++i) {
      if (shape[i] == 4)
        ++ball, ball_held += held[i] == S(0);
      else
        other_changed += held[i] != association[i];
    }
    INFO(ball_held << " of the ball's " << ball << " pixels held, " << other_changed << " others changed");
    REQUIRE(ball > 300);
    CHECK(ball_held > 0.9 * ball);
    // Elsewhere the marks of the first frame's rough surfaces (2.5 cm voxels
    // from one view): 82 pixels, 62 of them on the box.
    CHECK(other_changed < 0.01 * double(held.size()));
    const int marked_before = m.ball_marked();
    CHECK(marked_before > 0.9 * ball);
    for (int k = 0; k < 10; ++k) {
      REQUIRE(hold_unexplained(m.map, m.frame, m.s.params, false, weights));
      integrate_models(m.map, m.frame, m.s.camera, m.s.params, {}, false, &weights);
      integrate_models(unheld.map, unheld.frame, unheld.s.camera, unheld.s.params, {}, false);
    }
    const int marked_held = m.ball_marked(), marked_unheld = unheld.ball_marked();
    INFO("ball pixels marked: " << marked_before << " at first, after ten frames " << marked_held << " held, "
                                << marked_unheld << " not held");
    CHECK(marked_held > 0.9 * marked_before);
    CHECK(marked_unheld < 0.1 * marked_before);
  }
}

namespace {

/// `scene`'s depth seen from the origin by `camera`, on backend B;
/// `labels` (if given) gets the shape per pixel.
template <class S, class B>
Image<S, B> depth_from_origin(const sim::Scene<S>& scene, const PinholeCamera<S>& camera,
                              Image<int, Host>* labels = nullptr) {
  Image<S, Host> d;
  sim::render_depth(scene, camera, SE3<S>::identity(), d, labels);
  return d.template to<B>();
}

/// MarkUnexplained's marks of `depth` against `map`, read on the host:
/// the frame preprocessed into `frame`, the models rendered, the E-step,
/// then the marks over the whole image (no border).
template <class S, class B>
std::vector<std::uint8_t> unexplained_marks(Map<S, B>& map, const Image<S, B>& depth, const PinholeCamera<S>& camera,
                                            const SystemParams<S>& params, Frame<S, B>& frame) {
  preprocess(depth, camera, params, frame);
  RenderWorkspace<S, B> workspace;
  render_models(map, frame, camera, params, workspace);
  PaperLikelihood<S> likelihood;
  likelihood.params = params.likelihood;
  associate(map, frame, likelihood, params);
  Image<std::uint8_t, B> marked;
  detail::unexplained::mark_unexplained(map, frame, params, 0, frame.associations.image(0), marked);
  return marked.to_host();
}

}  // namespace

TEMPLATE_LIST_TEST_CASE("Stages alone: a point in space the background never saw is unexplained only in front of a "
                        "surface it saw",
                        "[slam]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // A dense background that saw a wall 2 m ahead, but for a pocket in front
  // of it (0.3 m each side of the axis, 1.2 to `pocket_end` m ahead) that
  // something hid, and a box of 0.2 m standing in the pocket, 1.5 m ahead.
  const S pocket_end = GENERATE(S(1.8), S(2.6));  // ... before the wall, or through it
  WallAndBox<S> s;
  s.params.sparse_background = false;
  Map<S, B> map(s.params);
  sim::Scene<S> wall, boxed;
  wall.add(WallAndBox<S>::wall());
  boxed = wall;
  boxed.add(sim::make_box(SE3<S>::translation(vec3(S(0), S(0), S(1.5))), vec3(S(0.1), S(0.1), S(0.1))));
  Frame<S, B> frame;
  preprocess(depth_from_origin<S, B>(wall, s.camera), s.camera, s.params, frame);
  integrate_models(map, frame, s.camera, s.params, {}, true);
  map.started = true;
  TsdfVolume<S, B>& volume = *map.background.dense();
  std::vector<S> sdf = volume.sdf_to_host(), weight = volume.weight_to_host();
  const auto view = volume.view();
  int emptied = 0;
  for (int z = 0; z < volume.dims()[2]; ++z)
    for (int y = 0; y < volume.dims()[1]; ++y)
      for (int x = 0; x < volume.dims()[0]; ++x) {
        const Vec3<S> p = volume.pose() * view.voxel_center(x, y, z);
        if (std::fabs(p.x()) < S(0.3) && std::fabs(p.y()) < S(0.3) && p.z() > S(1.2) && p.z() < pocket_end) {
          weight[std::size_t(view.index(x, y, z))] = S(0);
          ++emptied;
        }
      }
  REQUIRE(emptied > 1000);
  volume.assign_from_host(sdf, weight);
  Image<int, Host> labels;
  const std::vector<std::uint8_t> marks =
      unexplained_marks(map, depth_from_origin<S, B>(boxed, s.camera, &labels), s.camera, s.params, frame);
  const std::vector<int> shape = labels.to_host();
  int box = 0, box_marked = 0, wall_marked = 0;
  for (std::size_t i = 0; i < marks.size(); ++i) {
    if (shape[i] == 1)
      ++box, box_marked += marks[i];
    else
      wall_marked += marks[i];
  }
  INFO("pocket to " << pocket_end << " m: " << box_marked << " of the box's " << box << " pixels marked, "
                    << wall_marked << " of the wall's");
  REQUIRE(box > 300);
  CHECK(wall_marked < 0.02 * box);
  if (pocket_end < S(2))
    CHECK(box_marked > 0.9 * box);  // in front of the wall the background saw: unexplained
  else
    CHECK(box_marked < 0.05 * box);  // nothing seen behind it: new background
}

TEMPLATE_LIST_TEST_CASE("Stages alone: a floor seen at a grazing angle is not unexplained a little off its surface; "
                        "a box above it is (refind_unexplained_across)",
                        "[slam]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // The background saw a floor 0.5 m below the camera, 1.5-3 m ahead at
  // 10-18 degrees; the next frame measures it 1.5 cm higher (depth noise,
  // a camera a little off), 6-9 cm nearer along those rays than the
  // background's surface, and a box floating 0.25 m above it.
  WallAndBox<S> s;
  s.params.sparse_background = false;
  const auto floor_at = [](S y) {
    return sim::make_plane(sim::look_at(vec3(S(0), y, S(0)), Vec3<S>::zero(), vec3(S(0), S(0), S(1))));
  };
  sim::Scene<S> seen, now;
  seen.add(floor_at(S(0.5)));
  now.add(floor_at(S(0.485)));
  now.add(sim::make_box(SE3<S>::translation(vec3(S(0), S(0.2), S(2.2))), vec3(S(0.1), S(0.05), S(0.1))));
  // The shares of the floor's pixels 1.5-3 m ahead and of the box's marked.
  const auto marked_shares = [&](bool across) {
    s.params.refind_unexplained_across = across;
    Map<S, B> map(s.params);
    Frame<S, B> frame;
    preprocess(depth_from_origin<S, B>(seen, s.camera), s.camera, s.params, frame);
    integrate_models(map, frame, s.camera, s.params, {}, true);
    map.started = true;
    Image<int, Host> labels;
    const std::vector<std::uint8_t> marks =
        unexplained_marks(map, depth_from_origin<S, B>(now, s.camera, &labels), s.camera, s.params, frame);
    const std::vector<int> shape = labels.to_host();
    const std::vector<Vec3<S>> points = frame.points.to_host();
    std::array<int, 4> n{};  // floor, floor marked, box, box marked
    for (std::size_t i = 0; i < marks.size(); ++i) {
      if (shape[i] == 1) ++n[2], n[3] += marks[i];
      else if (shape[i] == 0 && points[i].z() > S(1.5) && points[i].z() < S(3)) ++n[0], n[1] += marks[i];
    }
    REQUIRE(n[0] > 300);
    REQUIRE(n[2] > 100);
    return std::pair{double(n[1]) / n[0], double(n[3]) / n[2]};
  };
  const auto [floor_along, box_along] = marked_shares(false);
  const auto [floor_across, box_across] = marked_shares(true);
  INFO("floor marked: " << floor_along << " along the rays, " << floor_across << " across; box " << box_along
                        << " and " << box_across);
  CHECK(floor_along > 0.5);    // the stored distances run along the rays
  CHECK(floor_across < 0.05);  // across the surface they are within the tolerance
  CHECK(box_along > 0.9);
  CHECK(box_across > 0.9);     // what stands off the surface stays unexplained
}

TEMPLATE_LIST_TEST_CASE("Stages alone: object_pose_prior holds an object's solve at its start", "[slam]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // The object's pose put 1.5 cm off the box it was made from: its solve
  // goes back onto the box; with a prior of overwhelming weight it stays
  // where it started.
  const auto offset_after_tracking = [](S prior) {
    OneFrameMap<S, B> m;
    REQUIRE(m.map.objects.size() == 1);
    m.s.params.object_pose_prior = prior;
    PaperLikelihood<S> likelihood;
    likelihood.params = m.s.params.likelihood;
    const SE3<S> made = m.map.objects[0]->pose();
    m.map.objects[0]->set_pose(SE3<S>::translation(vec3(S(0.015), S(0), S(0))) * made);
    preprocess(m.depth, m.s.camera, m.s.params, m.frame);
    associate(m.map, m.frame, likelihood, m.s.params);
    const std::vector<PoseTrack> tracks =
        track_objects(m.map, m.frame, m.s.params, HuberNorm<S>{S(2)}, LevenbergMarquardt{});
    REQUIRE(tracks.size() == 1);
    CHECK(tracks[0].outcome == TrackingOutcome::tracked);
    return double(norm(m.map.objects[0]->pose().translation() - made.translation()));
  };
  const double free = offset_after_tracking(S(0)), held = offset_after_tracking(S(1e7));
  INFO("offset from the box after the solve: " << free << " m free, " << held << " m held");
  CHECK(free < 0.005);
  CHECK(held > 0.013);
}

TEMPLATE_LIST_TEST_CASE("Stages alone: a partly hidden object whose solve slid where the frame sees through it stays "
                        "at its start",
                        "[slam]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // The box's model as a solve might leave it, 5 cm to the side of the box
  // it was made from: a strip of it is drawn over the wall 0.8 m behind,
  // which the frame shows through it, and no more of it agrees.
  OneFrameMap<S, B> m;
  REQUIRE(m.map.objects.size() == 1);
  ObjectModel<S, B>& box = *m.map.objects[0];
  const SE3<S> made = box.pose();
  const SE3<S> aside = SE3<S>::translation(vec3(S(0.05), S(0), S(0))) * made;
  const auto apart = [](const SE3<S>& a, const SE3<S>& b) { return double(norm(a.translation() - b.translation())); };
  // Tracked from `start` to `solved`; returns the track and where the box is.
  const auto check = [&](const SE3<S>& start, const SE3<S>& solved, bool hidden_in_part, TrackingOutcome outcome,
                         S share) {
    box.set_pose(solved);
    SystemParams<S> params = m.s.params;
    params.slide_seen_through_share = share;
    std::vector<PoseTrack> tracks(1);
    tracks[0].outcome = outcome;
    const int kept = keep_starts_seen_through(m.map, m.frame, m.s.camera, params,
                                              std::vector{PoseStarts<S>{start, std::nullopt}},
                                              std::vector{hidden_in_part}, tracks);
    CHECK(kept == int(tracks[0].kept_start));
    return std::pair{tracks[0], box.pose()};
  };
  const S share = SystemParams<S>{}.slide_seen_through_share;
  REQUIRE(share > S(0));
  SECTION("slid aside, partly hidden: back at its start") {
    const auto [track, pose] = check(made, aside, true, TrackingOutcome::tracked, share);
    CHECK(track.kept_start);
    CHECK(track.outcome == TrackingOutcome::tracked);
    CHECK(apart(pose, made) < 1e-5);
  }
  SECTION("solved back onto the box from a start aside: taken") {
    const auto [track, pose] = check(aside, made, true, TrackingOutcome::tracked, share);
    CHECK_FALSE(track.kept_start);
    CHECK(apart(pose, made) == 0);
  }
  SECTION("not partly hidden, not tracked, or off (0): the pose stays where the solve left it") {
    for (const auto& [hidden, outcome, s] : {std::tuple{false, TrackingOutcome::tracked, share},
                                             std::tuple{true, TrackingOutcome::jump_rejected, share},
                                             std::tuple{true, TrackingOutcome::tracked, S(0)}}) {
      const auto [track, pose] = check(made, aside, hidden, outcome, s);
      CHECK_FALSE(track.kept_start);
      CHECK(apart(pose, aside) == 0);
    }
  }
}

TEMPLATE_LIST_TEST_CASE(
    "Stages alone: with background_unowned_free_from the background forgets an object's trace "
    "where the object is drawn",
    "[slam]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // The first frame fused the box into the background too (as the paper's
  // still objects are, sec. 3.6). The box then moves 8 cm away from the
  // camera, its object with it: the E-step gives the box's pixels to the
  // object, rendering draws it there, and the background's surface where
  // the box stood is a trace in front of the frame's points.
  const SE3<S> T_moved = SE3<S>::translation(vec3(S(0), S(0), S(0.08)));
  // The background's SDF on the optical axis where the box's face was, and
  // on the wall away from the box, after one frame of the moved box.
  const auto after_move = [&](bool drawn) {
    OneFrameMap<S, B> m;
    REQUIRE(m.map.objects.size() == 1);
    const int centre = (m.s.camera.height / 2) * m.s.camera.width + m.s.camera.width / 2;
    const S face = m.depth.to_host()[std::size_t(centre)];
    m.s.scene.shapes[1] = WallAndBox<S>::box(T_moved);
    m.map.objects[0]->set_pose(T_moved * m.map.objects[0]->pose());
    m.s.params.background_integration.unowned_free_from = S(0.2);
    PaperLikelihood<S> likelihood;
    likelihood.params = m.s.params.likelihood;
    preprocess(m.s.template depth<B>(SE3<S>::identity()), m.s.camera, m.s.params, m.frame);
    associate(m.map, m.frame, likelihood, m.s.params);
    render_models(m.map, m.frame, m.s.camera, m.s.params, m.workspace);
    CHECK(double(m.frame.object_depth.to_host()[std::size_t(centre)] - face) > 0.06);  // drawn where it went
    if (!drawn) m.frame.object_depth.fill(S(0));
    integrate_models(m.map, m.frame, m.s.camera, m.s.params, {}, false);
    const Vec3<S> old_face = m.s.camera.back_project(S(m.s.camera.width / 2), S(m.s.camera.height / 2), face);
    std::array<S, 2> sdf{S(-1), S(-1)};
    m.map.background.visit([&](const auto& volume) {
      const auto background = volume.template to<Host>();
      const auto at = [&](const Vec3<S>& p, S& out) {
        CHECK(background.view().sample(background.pose().inverse() * p, out));
      };
      at(old_face, sdf[0]);
      at(vec3(S(0.5), S(0.3), S(2)), sdf[1]);
    });
    return sdf;
  };
  const std::array<S, 2> forgotten = after_move(true), kept = after_move(false);
  INFO("SDF at the box's old face: " << forgotten[0] << " drawn, " << kept[0] << " not drawn");
  // Drawn: the old face is free space now (the truncation is 0.25 m). Not
  // drawn (the same frame without the rendered object depth): the paper's
  // update, the old surface stays within a voxel.
  CHECK(double(forgotten[0]) > 0.05);
  CHECK(std::abs(double(kept[0])) < 0.025);
  // Where no object is drawn the rule does nothing either way.
  CHECK(forgotten[1] == kept[1]);
}

namespace {

TEMPLATE_LIST_TEST_CASE("Stages alone: two models of one object merge into the older id", "[slam]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  OneFrameMap<S, B> m;
  REQUIRE(m.map.objects.size() == 1);
  PaperLikelihood<S> likelihood;
  likelihood.params = m.s.params.likelihood;
  const HuberNorm<S> huber{S(2)};
  const S outside = unexplained_association<S>(likelihood);
  const int a_id = m.map.objects[0]->id();
  const SE3<S> a_pose = m.map.objects[0]->pose();
  m.map.record_poses(0.0);
  const auto weight_sum = [](const ObjectModel<S, B>& o) {
    double sum = 0;
    for (S w : o.volume().weight_to_host()) sum += double(w);
    return sum;
  };
  const auto observe = [&] {
    preprocess(m.depth, m.s.camera, m.s.params, m.frame);
    associate(m.map, m.frame, likelihood, m.s.params);
    render_models(m.map, m.frame, m.s.camera, m.s.params, m.workspace);
  };
  // A second model of the box from a detection at time t (what a missed
  // re-identification, or a creation beside an object, leaves).
  const auto make_second = [&](double t, const Detections& det) {
    observe();
    const std::vector<int> seg = m.frame.segmentation.to_host();
    FrameResult r;
    auto w = create_object(m.map, det, 0, seg, m.frame.points.to_host(), m.s.camera, m.s.params, outside, r);
    REQUIRE(w);
    std::vector<NewObjectWeights<S, B>> fresh;
    fresh.push_back(std::move(*w));
    integrate_models(m.map, m.frame, m.s.camera, m.s.params, fresh, false);
    update_foreground_counts(m.map, m.frame, det, seg, {-1}, fresh, m.s.camera);
    m.map.record_poses(t);
    return r.created.at(0);
  };
  // A detector frame at time t: matching, then the merge stage.
  const auto detector_frame = [&](double t, const Detections& det) {
    observe();
    const std::vector<int> seg = m.frame.segmentation.to_host();
    std::vector<int> ids_drawn;
    for (const auto& o : m.map.objects) ids_drawn.push_back(o->id());
    FrameResult r;
    const DetectionUpdate<S, B> update = handle_detections(m.map, m.frame, det, seg, m.s.camera, m.s.params,
                                                           likelihood, huber, LevenbergMarquardt{}, r);
    m.map.record_poses(t);
    return merge_objects(m.map, m.frame, det, seg, update.object_of_detection, ids_drawn, m.s.camera, m.s.params,
                         huber, LevenbergMarquardt{});
  };
  const auto lose_first = [&] {
    ObjectRecord& rec = m.map.record_of(a_id);
    rec.deleted = true;
    rec.reason = DeletionReason::not_visible;
    m.map.lost.push_back(LostObject<S, B>{std::move(m.map.objects[0]), 0});
    m.map.objects.clear();
  };
  const Detections cup = box_detection(m.labels, "cup");

  SECTION("a lost object and the model made of it later: the lost one goes on, with both models and one trajectory") {
    lose_first();
    const double a_weight = weight_sum(*m.map.lost[0].object);
    const int b_id = make_second(1.0, cup);
    const std::vector<ObjectMerge> merges = detector_frame(2.0, cup);
    REQUIRE(merges.size() == 1);
    CHECK(merges[0].from == b_id);
    CHECK(merges[0].into == a_id);
    REQUIRE(m.map.objects.size() == 1);
    CHECK(m.map.objects[0]->id() == a_id);
    CHECK(m.map.lost.empty());
    CHECK(double(norm(m.map.objects[0]->pose().translation() - a_pose.translation())) < 0.01);
    CHECK(weight_sum(*m.map.objects[0]) > 1.5 * a_weight);  // the second model's two frames fused in
    CHECK(m.map.objects[0]->existence_count() == 3);        // created once, then two detections
    const ObjectRecord& a = m.map.record_of(a_id);
    const ObjectRecord& b = m.map.record_of(b_id);
    CHECK_FALSE(a.deleted);
    CHECK(b.deleted);
    CHECK(b.reason == DeletionReason::merged);
    REQUIRE(a.trajectory.size() == 3);  // its own pose, then the second model's two, in its own frame
    for (const TimedPose& p : a.trajectory)
      CHECK(norm(p.pose.translation() - a_pose.template cast<double>().translation()) < 0.01);
    CHECK(a.trajectory[1].timestamp == 1.0);
    CHECK(a.last_timestamp == 2.0);
    CHECK(b.trajectory.size() == 2);  // its trajectory ends
  }
  SECTION("off (0): both stay") {
    m.s.params.merge_min_inliers = 0;
    lose_first();
    make_second(1.0, cup);
    CHECK(detector_frame(2.0, cup).empty());
    CHECK(m.map.objects.size() == 1);
    CHECK(m.map.lost.size() == 1);
  }
  SECTION("a lost object of another class, or lost after the other was made, is another object") {
    lose_first();
    SECTION("another class") {
      const Detections book = box_detection(m.labels, "book");
      make_second(1.0, book);
      CHECK(detector_frame(2.0, book).empty());
    }
    SECTION("both existed at once") {
      make_second(1.0, cup);
      m.map.record_of(a_id).last_timestamp = 1.5;
      CHECK(detector_frame(2.0, cup).empty());
    }
    CHECK(m.map.lost.size() == 1);
  }
  SECTION("two live models in one place: the unmatched one merges, the older id goes on") {
    // The second is made while the first is drawn elsewhere; then both are on the box.
    m.map.objects[0]->set_pose(SE3<S>::translation(vec3(S(0), S(0), S(-5))) * a_pose);
    const int b_id = make_second(1.0, cup);
    m.map.objects[0]->set_pose(a_pose);
    REQUIRE(m.map.objects.size() == 2);
    const std::vector<ObjectMerge> merges = detector_frame(2.0, cup);
    REQUIRE(merges.size() == 1);
    CHECK(merges[0].from == b_id);
    CHECK(merges[0].into == a_id);
    REQUIRE(m.map.objects.size() == 1);
    CHECK(m.map.objects[0]->id() == a_id);
    CHECK(m.map.record_of(b_id).reason == DeletionReason::merged);
    CHECK(m.map.record_of(a_id).trajectory.size() == 3);  // it was tracked throughout: nothing carried over
  }
}

/// A user's likelihood, with parameters of its own: a Gaussian on the SDF
/// (instead of the paper's Laplace) times p_fg, plus a constant outlier
/// level, and nothing outside the volume. Written over any volume view
/// (`with_volume`), so that the system can give it the sparse background.
template <class S, class View = TsdfView<S, const S>>
struct GaussianLikelihood {
  template <class OtherView>
  using with_volume = GaussianLikelihood<S, OtherView>;
  View volume;
  ForegroundView<S, const float> foreground;
  S sigma = S(0.015);
  S outlier = S(0.5);
  EMF_HD S likelihood(const Vec3<S>& p) const {
    if (!volume.contains_point(p)) return S(0);
    S sdf;
    if (!volume.sample(p, sdf)) sdf = volume.truncation;
    const S fg = foreground.empty() ? S(1) : foreground.probability(p);
    return std::exp(S(-0.5) * (sdf / sigma) * (sdf / sigma)) / sigma * fg + outlier;
  }
};

}  // namespace

TEMPLATE_LIST_TEST_CASE("The system runs a user's likelihood, norm and solver", "[slam]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  static_assert(VolumeLikelihood<GaussianLikelihood<S>, S>);
  using UserSystem = System<S, B, GaussianLikelihood<S>, HuberNorm<S>, TukeyNorm<S>, GaussNewton>;
  WallAndBox<S> s;
  Image<int, Host> labels;
  const Image<S, B> first = s.template depth<B>(SE3<S>::identity(), &labels);
  const Detections det = box_detection(labels, "cup");
  typename UserSystem::Parts parts;
  parts.likelihood.sigma = S(0.02);
  parts.background_norm.delta = S(2);
  parts.object_norm.c = S(4.685);
  UserSystem sys(s.camera, s.params, B{}, parts);
  CHECK(sys.parts().object_norm.c == S(4.685));
  sys.process(first, 0.0, &det);
  REQUIRE(sys.objects().size() == 1);
  // The camera moves 1 cm a frame; the box stays: both are followed (to
  // within 0.4 voxels of the 2.5 cm background: this checks that the parts
  // run, not how well they fit the scene).
  FrameResult r;
  for (int k = 1; k <= 5; ++k) {
    const SE3<S> pose = SE3<S>::translation(vec3(S(0.01) * S(k), S(0), S(0)));
    r = sys.process(s.template depth<B>(pose), k / 30.0);
    CHECK(r.camera_tracking == TrackingOutcome::tracked);
    CHECK(double(norm(sys.camera_pose().translation() - pose.translation())) < 0.01);
  }
  REQUIRE(r.object_status.size() == 1);
  CHECK(r.object_status[0].tracking == TrackingOutcome::tracked);
  CHECK(std::abs(double(sys.objects()[0]->pose().translation().z()) - 1.2) < 0.12);
  // The E-step used the user's model: its outlier level makes a pixel on no
  // surface of the object get the object's share of the outlier alone.
  CHECK(double(unexplained_association<S>(parts.likelihood)) > 0);
}

TEMPLATE_LIST_TEST_CASE("The paper's parts given explicitly are the default system", "[slam]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  WallAndBox<S> s;
  s.params.likelihood.sigma = S(0.03);
  s.params.huber_voxels = S(3);
  Image<int, Host> labels;
  const Image<S, B> first = s.template depth<B>(SE3<S>::identity(), &labels);
  const Detections det = box_detection(labels, "cup");
  System<S, B> by_default(s.camera, s.params);
  CHECK(by_default.parts().likelihood.params.sigma == S(0.03));
  CHECK(by_default.parts().object_norm.delta == S(3));
  typename System<S, B>::Parts parts;
  parts.likelihood.params = s.params.likelihood;
  parts.background_norm.delta = parts.object_norm.delta = S(3);
  parts.solver.params = s.params.lm;
  System<S, B> explicit_parts(s.camera, s.params, B{}, parts);
  by_default.process(first, 0.0, &det);
  explicit_parts.process(first, 0.0, &det);
  for (int k = 1; k <= 3; ++k) {
    const Image<S, B> d = s.template depth<B>(SE3<S>::translation(vec3(S(0.01) * S(k), S(0), S(0))));
    by_default.process(d, k / 30.0);
    explicit_parts.process(d, k / 30.0);
  }
  CHECK(max_abs_diff(by_default.camera_pose().matrix(), explicit_parts.camera_pose().matrix()) == S(0));
  REQUIRE(by_default.objects().size() == 1);
  REQUIRE(explicit_parts.objects().size() == 1);
  CHECK(max_abs_diff(by_default.objects()[0]->pose().matrix(), explicit_parts.objects()[0]->pose().matrix()) == S(0));
}

TEMPLATE_LIST_TEST_CASE("Stages alone: tracking from a motion prediction, the retry, a refused solve", "[slam]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  OneFrameMap<S, B> m;
  PaperLikelihood<S> likelihood;
  likelihood.params = m.s.params.likelihood;
  SystemParams<S> params = m.s.params;
  params.predict_motion = true;
  params.pyramid_levels = 2;
  // The camera moved 2 cm per frame along x; now it is at 4.2 cm.
  const auto at_x = [](double x) { return SE3<S>::translation(vec3(S(x), S(0), S(0))); };
  m.map.camera_trajectory = {{0.0, at_x(0.0).template cast<double>()}, {0.1, at_x(0.02).template cast<double>()}};
  m.map.T_world_camera = at_x(0.02);
  const SE3<S> truth = at_x(0.042);
  const auto apart = [](const Vec3<S>& a, const Vec3<S>& b) { return double(norm(a - b)); };
  TrackingWorkspace<S, B>* const no_workspace = nullptr;
  const PoseStarts<S> starts = predict_camera(m.map, 0.2, params);
  REQUIRE(starts.predicted);
  CHECK(double(norm(starts.predicted->translation() - vec3(S(0.04), S(0), S(0)))) < 1e-6);
  CHECK(apart(m.map.T_world_camera.translation(), starts.predicted->translation()) == 0);  // the E-step associates there
  preprocess(m.s.template depth<B>(truth), m.s.camera, params, m.frame);
  associate(m.map, m.frame, likelihood, params);
  const PoseTrack camera = track_camera(m.map, m.frame, params, HuberNorm<S>{S(2)}, LevenbergMarquardt{}, no_workspace, &starts);
  CHECK(camera.outcome == TrackingOutcome::tracked);
  CHECK(camera.from_prediction);
  CHECK(camera.attempts == 1);
  CHECK(double(norm(m.map.T_world_camera.translation() - truth.translation())) < 0.004);
  CHECK(std::abs(camera.step.translation - 0.022) < 0.004);  // from the previous pose, not the prediction

  // A refused solve leaves the previous pose, not the prediction.
  SystemParams<S> strict = params;
  strict.min_camera_terms = 1 << 30;
  m.map.T_world_camera = *starts.predicted;
  const PoseTrack refused =
      track_camera(m.map, m.frame, strict, HuberNorm<S>{S(2)}, LevenbergMarquardt{}, no_workspace, &starts);
  CHECK(refused.outcome == TrackingOutcome::too_few_terms);
  CHECK(apart(m.map.T_world_camera.translation(), starts.previous.translation()) == 0);

  // The retry: a first solve judged failed is run again from the other start.
  const SE3<S> T_volume_world = m.map.background.pose().inverse();
  const PoseStarts<S> in_volume{T_volume_world * starts.previous, T_volume_world * *starts.predicted};
  const auto fail_from_prediction = [](const SE3<S>&, PoseTrack& t) {
    t.outcome = t.from_prediction ? TrackingOutcome::solve_failed : TrackingOutcome::tracked;
  };
  LinearizationCache<S, B> cache;
  const SdfAlignmentParams<S> align = alignment_params(params, params.background_integration.max_weight);
  const auto norm_in_voxels = scaled_norm(HuberNorm<S>{S(2)}, m.map.background.voxel_size());
  for (const bool retry : {false, true}) {
    PoseTrack t;
    m.map.background.visit([&](const auto& volume) {
      track_in_volume(volume, m.frame.points, &m.frame.associations.image(0), in_volume, norm_in_voxels, align,
                      LevenbergMarquardt{}, retry, fail_from_prediction, t, cache, m.map.background.backend());
    });
    CHECK(t.attempts == (retry ? 2 : 1));
    CHECK(t.from_prediction == !retry);
    CHECK(t.outcome == (retry ? TrackingOutcome::tracked : TrackingOutcome::solve_failed));
  }
  // The same through the batched path, beside a problem without a
  // prediction (nothing to retry from): only the first is solved again.
  for (const bool retry : {false, true}) {
    std::vector<PoseTrack> tracks;
    BatchedSolveWorkspace<S, B> batch;
    m.map.background.visit([&](const auto& volume) {
      const auto terms = sdf_alignment_in_box(volume, m.frame.points, &m.frame.associations.image(0), align,
                                              m.map.background.backend());
      const PoseStarts<S> previous_only{in_volume.previous, std::nullopt};
      track_in_volumes(m.map.background.backend(), std::vector{terms, terms},
                       std::vector{norm_in_voxels, norm_in_voxels}, std::vector{in_volume, previous_only}, align,
                       LevenbergMarquardt{}, retry,
                       [&](std::size_t, const SE3<S>& T, PoseTrack& t) { fail_from_prediction(T, t); }, tracks,
                       batch);
    });
    REQUIRE(tracks.size() == 2);
    CHECK(tracks[0].attempts == (retry ? 2 : 1));
    CHECK(tracks[0].from_prediction == !retry);
    CHECK(tracks[0].outcome == (retry ? TrackingOutcome::tracked : TrackingOutcome::solve_failed));
    CHECK(tracks[1].attempts == 1);
    CHECK_FALSE(tracks[1].from_prediction);
    CHECK(tracks[1].outcome == TrackingOutcome::tracked);
  }

  // Objects are predicted only from poses of the two frames before.
  ObjectModel<S, B>& object = *m.map.objects[0];
  const SE3<double> P1 = object.pose().template cast<double>();
  const SE3<double> P0 = SE3<double>::translation(vec3(0.0, -0.01, 0.0)) * P1;
  ObjectRecord& record = m.map.record_of(object.id());
  record.trajectory = {{0.0, P0}, {0.1, P1}};
  const std::vector<PoseStarts<S>> predicted = predict_objects(m.map, 0.2, params);
  REQUIRE(predicted.size() == 1);
  REQUIRE(predicted[0].predicted);
  CHECK(double(norm(object.pose().translation() - P1.template cast<S>().translation() - vec3(S(0), S(0.01), S(0)))) <
        1e-5);
  object.set_pose(P1.template cast<S>());
  record.trajectory = {{0.05, P0}, {0.1, P1}};  // not the frame before: no prediction
  const std::vector<PoseStarts<S>> none = predict_objects(m.map, 0.2, params);
  CHECK_FALSE(none[0].predicted);
  CHECK(apart(object.pose().translation(), P1.template cast<S>().translation()) == 0);
}

TEMPLATE_LIST_TEST_CASE("Stages alone: an object's refused solves that agree on consecutive frames are taken",
                        "[slam]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  OneFrameMap<S, B> m;
  REQUIRE(m.map.objects.size() == 1);
  PaperLikelihood<S> likelihood;
  likelihood.params = m.s.params.likelihood;
  preprocess(m.depth, m.s.camera, m.s.params, m.frame);
  ObjectModel<S, B>& object = *m.map.objects[0];
  const SE3<S> truth = object.pose();
  // The object's pose 2.5 cm off the box it was made from; every solve
  // brings it back, further than a bound of 1 cm a frame allows.
  const SE3<S> off = SE3<S>::translation(vec3(S(0.025), S(0), S(0))) * truth;
  const auto apart = [](const SE3<S>& a, const SE3<S>& b) { return double(norm(a.translation() - b.translation())); };
  SystemParams<S> params = m.s.params;
  params.max_object_motion.translation = S(0.01);
  const ObjectRecord& record = m.map.record_of(object.id());
  // One frame's solve from `off` at frame `frame`; the object stays where the frame leaves it.
  const auto track_at = [&](int frame) {
    m.map.frames = frame;
    associate(m.map, m.frame, likelihood, params);
    const std::vector<PoseTrack> t = track_objects(m.map, m.frame, params, HuberNorm<S>{S(2)}, LevenbergMarquardt{});
    REQUIRE(t.size() == 1);
    return t[0];
  };
  for (const int confirm : {0, 2, 3}) {
    CAPTURE(confirm);
    params.confirm_jump_frames = confirm;
    object.set_pose(off);
    const PoseTrack first = track_at(10);
    CHECK(first.outcome == TrackingOutcome::jump_rejected);
    CHECK_FALSE(first.confirmed);
    CHECK(first.step.translation > 0.015);
    CHECK(record.refused_run == 1);
    CHECK(apart(object.pose(), off) == 0);
    const PoseTrack second = track_at(11);
    if (confirm == 2) {
      CHECK(second.outcome == TrackingOutcome::tracked);
      CHECK(second.confirmed);
      CHECK(apart(object.pose(), truth) < 0.005);
      CHECK(record.refused_run == 0);
    } else {
      CHECK(second.outcome == TrackingOutcome::jump_rejected);
      CHECK(record.refused_run == 2);
      CHECK(apart(object.pose(), off) == 0);
      const PoseTrack third = track_at(12);
      CHECK(third.outcome == (confirm == 3 ? TrackingOutcome::tracked : TrackingOutcome::jump_rejected));
      CHECK(third.confirmed == (confirm == 3));
    }
  }
  // A run is of consecutive frames: after a frame without a refused solve
  // it starts again.
  params.confirm_jump_frames = 2;
  object.set_pose(off);
  CHECK(track_at(20).outcome == TrackingOutcome::jump_rejected);
  CHECK(track_at(22).outcome == TrackingOutcome::jump_rejected);
  CHECK(record.refused_run == 1);
  // ... and of solves that agree: one further than the bound from the last
  // refused solve starts it again too.
  m.map.record_of(object.id()).refused_pose =
      (SE3<S>::translation(vec3(S(0), S(0.03), S(0))) * truth).template cast<double>();
  CHECK(track_at(23).outcome == TrackingOutcome::jump_rejected);
  CHECK(record.refused_run == 1);
  CHECK(track_at(24).outcome == TrackingOutcome::tracked);
  CHECK(apart(object.pose(), truth) < 0.005);

  SystemParams<S> bad = m.s.params;
  bad.confirm_jump_frames = -1;
  CHECK_THROWS_WITH(bad.validate(), EMF_CONTAINS("confirm_jump_frames must not be negative"));
  bad = m.s.params;
  bad.reidentify_turned_keep = -1;
  CHECK_THROWS_WITH(bad.validate(), EMF_CONTAINS("reidentify_turned_keep must not be negative"));
  bad = m.s.params;
  bad.reidentify_turned_rank_iterations = 0;
  CHECK_THROWS_WITH(bad.validate(), EMF_CONTAINS("reidentify_turned_rank_iterations must be at least 1"));
}

TEMPLATE_LIST_TEST_CASE("Every object's pixel counts in one pass equal each object's own reduction", "[slam]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const B backend{};
  // Random labels (-1 nothing, 0 background, k + 1 object k) and association
  // images, some values 0, some above 1/2; the last object has no image (it
  // was created after the E-step).
  const int w = 64, h = 48, objects = 5;
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> label(-1, objects);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<int> labels(std::size_t(w * h));
  for (int& l : labels) l = label(rng);
  Frame<S, B> frame;
  frame.segmentation = Image<int, Host>::from_host(w, h, labels).template to<B>();
  frame.associations.resize(objects, w, h, backend);
  for (int k = 0; k < objects; ++k) {
    std::vector<S> q(std::size_t(w * h));
    for (S& v : q) v = u(rng) < 0.3 ? S(0) : S(u(rng));
    frame.associations.image(k) = Image<S, Host>::from_host(w, h, q).template to<B>();
  }
  ObjectPixelsWorkspace<S, B> ws;
  for (const int count : {objects, 2, objects}) {  // the workspace reused, for fewer and more objects
    for (const int border : {0, 5}) {
      const std::vector<ObjectPixels> all = all_object_pixels(frame, count, border, ws);
      REQUIRE(all.size() == std::size_t(count));
      for (int k = 0; k < count; ++k) {
        const ObjectPixels one = object_pixels(frame, k, border);
        INFO(count << " objects, border " << border << ", object " << k);
        CHECK(all[std::size_t(k)].rendered == one.rendered);
        CHECK(all[std::size_t(k)].rendered_inner == one.rendered_inner);
        CHECK(all[std::size_t(k)].associated_inner == one.associated_inner);
        CHECK(all[std::size_t(k)].associated == one.associated);
        CHECK(one.associated >= one.associated_inner);
        if (border == 0) CHECK(one.associated == one.associated_inner);
        CHECK(all[std::size_t(k)].association_sum == emfusion::test::Approx(one.association_sum).epsilon(1e-12));
        CHECK(one.rendered > 0);
        CHECK((k == objects - 1) == (one.associated_inner == 0));
      }
    }
  }
  CHECK(all_object_pixels(frame, 0, 0, ws).empty());
}

TEMPLATE_LIST_TEST_CASE("With object_colour_weight, objects take the frame's gray values and use them",
                        "[slam][colour]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  WallAndBox<S> s;
  Image<int, Host> labels;
  const Image<S, B> first = s.template depth<B>(SE3<S>::identity(), &labels);
  const Detections det = box_detection(labels, "cup");
  // The box light (0.8), everything else dark (0.2).
  const auto gray = [&](const Image<int, Host>& shapes) {
    std::vector<S> g;
    for (int l : shapes.to_host()) g.push_back(l == 1 ? S(0.8) : S(0.2));
    return Image<S, Host>::from_host(shapes.width(), shapes.height(), g).template to<B>();
  };
  SystemParams<S> coloured = s.params;
  coloured.object_colour_weight = S(10);
  System<S, B> with_colour(s.camera, coloured), without_intensity(s.camera, coloured), depth_alone(s.camera, s.params);
  const Image<S, B> first_gray = gray(labels);
  with_colour.process(first, 0.0, &det, &first_gray);
  without_intensity.process(first, 0.0, &det);
  depth_alone.process(first, 0.0, &det, &first_gray);  // weight 0: the gray values are not used
  for (int k = 1; k <= 3; ++k) {
    const SE3<S> pose = SE3<S>::translation(vec3(S(0.01) * S(k), S(0), S(0)));
    Image<int, Host> shapes;
    const Image<S, B> d = s.template depth<B>(pose, &shapes);
    const Image<S, B> g = gray(shapes);
    const FrameResult r = with_colour.process(d, k / 30.0, nullptr, &g);
    without_intensity.process(d, k / 30.0);
    depth_alone.process(d, k / 30.0, nullptr, &g);
    REQUIRE(r.object_status.size() == 1);
    CHECK(r.object_status[0].tracking == TrackingOutcome::tracked);
    CHECK(double(norm(with_colour.camera_pose().translation() - pose.translation())) < 0.01);
  }
  REQUIRE(with_colour.objects().size() == 1);
  REQUIRE(depth_alone.objects().size() == 1);
  REQUIRE(without_intensity.objects().size() == 1);
  // The object's model is coloured, with the box's gray value where the
  // surface is.
  const ObjectModel<S, B>& o = *with_colour.objects()[0];
  REQUIRE(!o.colour().empty());
  const std::vector<float> value = o.colour().values_to_host(), weight = o.colour().weights_to_host();
  const auto tsdf = o.volume().template to<Host>();
  std::vector<float> on_surface;
  for (std::size_t i = 0; i < value.size(); ++i)
    if (weight[i] > 0.0f && tsdf.view().weight[i] > S(0) && std::abs(double(tsdf.view().sdf[i])) < 0.005)
      on_surface.push_back(value[i]);
  REQUIRE(on_surface.size() > 50);
  std::nth_element(on_surface.begin(), on_surface.begin() + on_surface.size() / 2, on_surface.end());
  CHECK(on_surface[on_surface.size() / 2] == emfusion::test::Approx(0.8).margin(0.01));
  CHECK(o.memory_bytes() > depth_alone.objects()[0]->memory_bytes());
  // Without gray values, or with weight 0, the models take no colour and the
  // poses are those of depth alone.
  CHECK(without_intensity.objects()[0]->colour().empty());
  CHECK(depth_alone.objects()[0]->colour().empty());
  CHECK(max_abs_diff(without_intensity.objects()[0]->pose().matrix(), depth_alone.objects()[0]->pose().matrix()) ==
        S(0));
  // A gray image of another size is refused, naming it.
  const Image<S, B> small(8, 6, S(0.5));
  CHECK_THROWS_WITH(with_colour.process(first, 1.0, nullptr, &small), EMF_CONTAINS("intensity image is 8x6"));
  SystemParams<S> bad = s.params;
  bad.object_colour_weight = S(-1);
  CHECK_THROWS_WITH(bad.validate(), EMF_CONTAINS("object_colour_weight must not be negative"));
}

TEMPLATE_LIST_TEST_CASE("With reidentify_colour_agreement, objects keep colour and a fit must agree with it",
                        "[slam][colour]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  WallAndBox<S> s;
  s.params.reidentify_colour_agreement = 0.8;
  REQUIRE(s.params.uses_colour());
  Image<int, Host> labels;
  const Image<S, B> depth = s.template depth<B>(SE3<S>::identity(), &labels);
  // The box's left half light and its right half dark (or the other way
  // round: a part view of a box fitted turned by half a turn shows the
  // same depth and the other colour), everything else mid-gray.
  int left = labels.width(), right = -1;
  const std::vector<int> shape = labels.to_host();
  for (std::size_t i = 0; i < shape.size(); ++i)
    if (shape[i] == 1) left = std::min(left, int(i) % labels.width()), right = std::max(right, int(i) % labels.width());
  REQUIRE(right > left);
  const auto gray = [&](bool swapped) {
    std::vector<S> g;
    for (std::size_t i = 0; i < shape.size(); ++i) {
      const bool light = 2 * (int(i) % labels.width()) < left + right;
      g.push_back(shape[i] != 1 ? S(0.5) : (light != swapped ? S(0.8) : S(0.2)));
    }
    return Image<S, Host>::from_host(labels.width(), labels.height(), g).template to<B>();
  };
  // The stages of a first frame, with its gray values: the object made from
  // the box's detection takes them.
  Map<S, B> map{s.params};
  Frame<S, B> frame;
  FrameResult result;
  RenderWorkspace<S, B> workspace;
  result.depth = preprocess(depth, s.camera, s.params, frame);
  frame.intensity = gray(false);
  render_models(map, frame, s.camera, s.params, workspace);
  const Detections det = box_detection(labels, "cup");
  const std::vector<int> seg = frame.segmentation.to_host();
  auto created = create_object(map, det, 0, seg, frame.points.to_host(), s.camera, s.params,
                               unexplained_association<S>(PaperLikelihood<S>{}), result);
  REQUIRE(created);
  std::vector<NewObjectWeights<S, B>> fresh;
  fresh.push_back(std::move(*created));
  integrate_models(map, frame, s.camera, s.params, fresh, true);
  update_foreground_counts(map, frame, det, seg, {-1}, fresh, s.camera);
  REQUIRE(map.objects.size() == 1);
  const ObjectModel<S, B>& o = *map.objects[0];
  REQUIRE(!o.colour().empty());
  std::vector<S> box_mask;
  for (int l : shape) box_mask.push_back(l == 1 ? S(1) : S(0));
  const Image<S, B> mask = Image<S, Host>::from_host(labels.width(), labels.height(), box_mask).template to<B>();
  const SE3<S> T_volume_camera = o.volume().pose().inverse() * map.T_world_camera;
  using detail::reidentification::colour_agrees;
  // Where it was made, the same colour agrees; the swapped colour, at the
  // same depth, does not; with the rule off, or a frame without gray
  // values, every fit passes.
  CHECK(colour_agrees(o, T_volume_camera, frame, mask, s.params));
  frame.intensity = gray(true);
  CHECK_FALSE(colour_agrees(o, T_volume_camera, frame, mask, s.params));
  SystemParams<S> off = s.params;
  off.reidentify_colour_agreement = 0;
  CHECK(colour_agrees(o, T_volume_camera, frame, mask, off));
  frame.intensity = Image<S, B>{};
  CHECK(colour_agrees(o, T_volume_camera, frame, mask, s.params));

  // The object lost: a detection of it in depth with gray values in four
  // quarters (a checker no half turn or quarter turn of its light and dark
  // halves matches) brings nothing back and, the first time since it was
  // lost, makes no new object either (held_for_colour); the second time it
  // makes one. In the model's colour the detection brings it back.
  {
    int top = labels.height(), bottom = -1;
    for (std::size_t i = 0; i < shape.size(); ++i)
      if (shape[i] == 1)
        top = std::min(top, int(i) / labels.width()), bottom = std::max(bottom, int(i) / labels.width());
    std::vector<S> g;
    for (std::size_t i = 0; i < shape.size(); ++i) {
      const bool left_half = 2 * (int(i) % labels.width()) < left + right;
      const bool top_half = 2 * (int(i) / labels.width()) < top + bottom;
      g.push_back(shape[i] != 1 ? S(0.5) : (left_half != top_half ? S(0.8) : S(0.2)));
    }
    const Image<S, B> quarters = Image<S, Host>::from_host(labels.width(), labels.height(), g).template to<B>();
    const int id = o.id();
    map.lost.push_back(LostObject<S, B>{std::move(map.objects[0]), map.frames});
    map.objects.clear();
    REQUIRE_FALSE(map.lost[0].held_detection);
    const std::vector<int> no_model(shape.size(), 0);
    const HuberNorm<S> huber{S(2)};
    const auto detect = [&](const Image<S, B>& intensity) {
      frame.intensity = intensity;
      FrameResult r;
      handle_detections(map, frame, det, no_model, s.camera, s.params, PaperLikelihood<S>{}, huber,
                        LevenbergMarquardt{}, r);
      return r;
    };
    const FrameResult held = detect(quarters);
    CHECK(held.held_for_colour == 1);
    CHECK(held.created.empty());
    CHECK(held.reidentified.empty());
    CHECK(map.lost.size() == 1);
    CHECK(map.lost[0].held_detection);
    const FrameResult made = detect(quarters);
    CHECK(made.held_for_colour == 0);
    CHECK(made.created.size() == 1);
    CHECK(made.reidentified.empty());
    const FrameResult back = detect(gray(false));
    CHECK(back.reidentified == std::vector<int>{id});
    CHECK(map.lost.empty());
  }

  // The whole system: objects keep colour, and tracking stays on depth
  // (the poses of a run without the rule).
  System<S, B> with_rule(s.camera, s.params), depth_alone(s.camera, WallAndBox<S>{}.params);
  const Image<S, B> first_gray = gray(false);
  with_rule.process(depth, 0.0, &det, &first_gray);
  depth_alone.process(depth, 0.0, &det, &first_gray);
  for (int k = 1; k <= 2; ++k) {
    const SE3<S> pose = SE3<S>::translation(vec3(S(0.01) * S(k), S(0), S(0)));
    const Image<S, B> d = s.template depth<B>(pose);
    with_rule.process(d, k / 30.0, nullptr, &first_gray);
    depth_alone.process(d, k / 30.0, nullptr, &first_gray);
  }
  REQUIRE(with_rule.objects().size() == 1);
  REQUIRE(depth_alone.objects().size() == 1);
  CHECK(!with_rule.objects()[0]->colour().empty());
  CHECK(depth_alone.objects()[0]->colour().empty());
  CHECK(max_abs_diff(with_rule.objects()[0]->pose().matrix(), depth_alone.objects()[0]->pose().matrix()) == S(0));
  // Shares outside [0, 1] and tolerances that are not positive are refused.
  SystemParams<S> bad = s.params;
  bad.reidentify_colour_agreement = 1.5;
  CHECK_THROWS_WITH(bad.validate(), EMF_CONTAINS("reidentify_colour_agreement must be in [0, 1]"));
}
