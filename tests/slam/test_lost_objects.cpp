// Lost objects found again, on the box scene of support/box_scene.hpp: an
// object that left the view is re-identified when detected again (moved,
// from a small detection, not by a detection of another class), a model
// fits a frame only where the frame does not see through it and the best
// fit the frame shows is taken, fitted first from the pose it was lost in
// and only as far as it can have moved (and, with
// reidentify_colour_agreement, by its colour), found turned when it turned
// while out of view (on a detection, and in what no model explains when
// wholly in view), found again without a detection where the frame shows
// it where it was lost (refind_in_view), and found in what no model
// explains when it comes back elsewhere (a group no lost object fitted is
// not fitted again until it changes; marks either side of a thin band are
// one group). The long ones run in float only (SystemRuleConfigs).
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "emfusion/io/checkpoint.hpp"
#include "support/box_scene.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"
#include "support/files.hpp"
#include "support/fusion.hpp"
#include "support/system_instances.hpp"

using namespace emfusion;
using namespace emfusion::test;

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
    // A turned fit of reidentify is taken the same way
    // (shown_or_colour_refined): where the frame shows it in depth and only
    // its colour disagrees, solved again with the colour; where the frame
    // does not show it, refused; with the rule off, taken as it is.
    moved.segmentation = Image<int, B>(camera.width, camera.height, 0);  // no live object claims a pixel
    std::vector<std::uint8_t> panel_px;  // the models are drawn where they were foreground
    for (const S m : whole) panel_px.push_back(std::uint8_t(m > S(0)));
    update_foreground(panel.foreground(), panel.volume().pose(), panel.volume().truncation(), first.depth,
                      Image<std::uint8_t, Host>::from_host(camera.width, camera.height, panel_px).template to<B>(),
                      Image<std::uint8_t, B>(camera.width, camera.height, std::uint8_t(1)), camera,
                      SE3<S>::identity(), panel.volume().backend());
    const auto target = target_of(moved, patch);
    RaycastResult<S, B> drawn;
    const auto take = [&](const SE3<S>& T_fit) {
      return detail::reidentification::shown_or_colour_refined(
          panel, detail::reidentification::CandidateFit<S>{7, depth_inliers, T_fit}, target, moved,
          SE3<S>::identity(), camera, params, HuberNorm<S>{params.huber_voxels}, LevenbergMarquardt{params.lm}, 1,
          0.5, drawn);
    };
    const auto refined = take(depth_T);
    REQUIRE(refined);
    CHECK(refined->candidate == 7);
    CHECK(std::fabs(moved_by(panel, refined->T_volume_camera) - double(slide)) < 0.008);
    CHECK(detail::reidentification::colour_agrees(panel, refined->T_volume_camera, moved, target.mask, params));
    const auto agreeing = take(T);  // agrees already: taken as it is
    REQUIRE(agreeing);
    CHECK(double(norm(agreeing->T_volume_camera.translation() - T.translation())) == 0);
    CHECK_FALSE(take(SE3<S>::translation(vec3(S(0), S(0), S(-0.3))) * depth_T));  // drawn 30 cm off the surface
    params.reidentify_colour_agreement = 0;
    const auto off = take(depth_T);
    REQUIRE(off);
    CHECK(double(norm(off->T_volume_camera.translation() - depth_T.translation())) == 0);
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

namespace {

/// An L of two boxes 1.2 m ahead of a wall 2 m ahead (320x240 camera at
/// the world origin), fused into a model (id 1, class cup) from one view
/// at T_was and lost; then seen moved 3 cm and turned by 105 degrees
/// (T_now), further than an alignment from its last orientation reaches.
/// With `book`: a box of a book's size (the generator's, 26 x 18 x 14 cm)
/// instead, turned a quarter turn about its shortest side.
template <class S, class B>
struct TurnedL {
  bool book = false;
  /// The box's half sides (`book`).
  static Vec3<S> book_half() { return vec3(S(0.13), S(0.09), S(0.07)); }
  PinholeCamera<S> camera{S(280), S(280), S(159.5), S(119.5), 320, 240};
  SE3<S> T_was{so3_exp(vec3(S(0.2), S(0.4), S(0))), vec3(S(0), S(0), S(1.2))};
  SE3<S> T_now{so3_exp(normalized(vec3(S(0.1), S(0.2), S(1))) * S(105 * 3.14159265358979 / 180)) * T_was.rotation(),
               T_was.translation() + vec3(S(0.03), S(0), S(0))};

  static sim::Scene<S> wall() {
    sim::Scene<S> scene;
    scene.add(sim::make_plane(sim::look_at(vec3(S(0), S(0), S(2)), Vec3<S>::zero(), vec3(S(0), S(-1), S(0)))));
    return scene;
  }
  sim::Scene<S> scene_at(const SE3<S>& T_world_object) const {
    sim::Scene<S> scene = wall();
    if (book) {
      scene.add(sim::make_box(T_world_object, book_half()));
      return scene;
    }
    scene.add(sim::make_box(T_world_object * SE3<S>::translation(vec3(S(-0.03), S(0), S(0))),
                            vec3(S(0.13), S(0.035), S(0.05))));
    scene.add(sim::make_box(T_world_object * SE3<S>::translation(vec3(S(0.065), S(0.0775), S(0))),
                            vec3(S(0.035), S(0.0425), S(0.05))));
    return scene;
  }
  struct View {
    Frame<S, B> frame;
    Detections det;
    std::vector<S> mask;
  };
  /// The frame of `scene` (its points and an empty segmentation) and a
  /// detection (label 5, class cup) of the L's pixels.
  View view_of(const sim::Scene<S>& scene) const {
    View v;
    Image<S, Host> d;
    Image<int, Host> labels;
    sim::render_depth(scene, camera, SE3<S>::identity(), d, &labels);
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
  }
  /// The L's model, fused from the view at T_was, in `map` as lost a
  /// second ago (frame 30; detected twice, so that it is looked for without
  /// a detection too).
  void lose_into(Map<S, B>& map) const {
    auto model = std::make_unique<ObjectModel<S, B>>(1, "cup", T_was, 64, book ? S(0.009) : S(0.006), S(10));
    const View was = view_of(scene_at(T_was));
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
    model->count_detected();
    model->count_detected();
    ObjectRecord rec;
    rec.id = 1;
    rec.class_name = "cup";
    rec.deleted = true;
    map.records.push_back(rec);
    map.lost.push_back({std::move(model), 0});
    map.next_id = 2;
    map.frames = 30;  // lost a second ago: the turn is within max_object_motion
  }
  /// How far a pose is from where the L stands now: metres and degrees.
  std::pair<double, double> off(const SE3<S>& pose) const {
    const SE3<S> d = pose.inverse() * T_now;
    return {double(norm(pose.translation() - T_now.translation())),
            double(norm(so3_log(d.rotation()))) * 180 / 3.14159265358979};
  }
};

}  // namespace

TEMPLATE_LIST_TEST_CASE("A lost object that turned while out of view is found turned", "[slam]",
                        emfusion::test::SystemRuleConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const TurnedL<S, B> l;
  SystemParams<S> params = small_params<S>();
  const auto found_where = [&](bool turned, int keep = 0) -> std::optional<SE3<S>> {
    params.reidentify_turn_below = turned ? SystemParams<S>{}.reidentify_turn_below : 0;
    params.reidentify_turned_keep = keep;
    Map<S, B> map(params);
    l.lose_into(map);
    const auto now = l.view_of(l.scene_at(l.T_now));
    const std::vector<int> seg(std::size_t(l.camera.width * l.camera.height), 0);
    const auto back = reidentify(map, now.frame, now.det, 0, seg, now.frame.points.to_host(), l.camera, params,
                                 HuberNorm<S>{params.huber_voxels}, LevenbergMarquardt{params.lm}, S(0.5));
    if (!back) return std::nullopt;
    REQUIRE(map.objects.size() == 1);
    CHECK(map.lost.empty());
    return map.objects[0]->pose();
  };
  const auto from_last = found_where(false);
  if (from_last) {
    const auto [metres, degrees] = l.off(*from_last);
    INFO("from its last orientation: " << metres << " m, " << degrees << " deg");
    CHECK((metres > 0.02 || degrees > 20));  // the scene needs the turned starts
  }
  const auto turned = found_where(true);
  REQUIRE(turned);
  const auto [metres, degrees] = l.off(*turned);
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

TEMPLATE_LIST_TEST_CASE("A lost object that turned while out of view is found turned in what no model explains",
                        "[slam]", emfusion::test::SystemRuleConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // A book-sized box, lost, back in view wholly (the image border does not
  // cut it) a quarter turn about its shortest side further, without a
  // detection, in front of the wall the background saw: from its last
  // orientation the fit leaves doubt, and the turned fits find it
  // (reidentify_turn_below; on h242-fast450 and h243-long600 of
  // bench/generalisation.py books came back 87 and 127 degrees off).
  TurnedL<S, B> l;
  l.book = true;
  l.T_now = SE3<S>(l.T_was.rotation() * so3_exp(vec3(S(0), S(0), S(1.5707963267948966))),
                   l.T_was.translation() + vec3(S(0.03), S(0), S(0)));
  SystemParams<S> params = small_params<S>();
  params.sparse_background = false;
  const Image<S, B> wall_depth = l.view_of(l.wall()).frame.depth;
  const auto found_where = [&](bool turned) -> std::optional<SE3<S>> {
    params.reidentify_turn_below = turned ? SystemParams<S>{}.reidentify_turn_below : 0;
    Map<S, B> map(params);
    Frame<S, B> frame;
    for (int k = 0; k < 3; ++k) {  // the background saw the wall alone
      preprocess(wall_depth, l.camera, params, frame);
      integrate_models(map, frame, l.camera, params, {}, true);
    }
    map.started = true;
    l.lose_into(map);
    map.camera_trajectory.push_back({1.0, SE3<double>::identity()});  // now: a second after it was last tracked
    preprocess(l.view_of(l.scene_at(l.T_now)).frame.depth, l.camera, params, frame);
    RenderWorkspace<S, B> render;
    render_models(map, frame, l.camera, params, render);
    PaperLikelihood<S> likelihood;
    likelihood.params = params.likelihood;
    associate(map, frame, likelihood, params);
    FrameResult result;
    if (refind_unexplained(map, frame, l.camera, params, HuberNorm<S>{params.huber_voxels},
                           LevenbergMarquardt{params.lm}, result) == 0)
      return std::nullopt;
    REQUIRE(map.objects.size() == 1);
    CHECK(map.lost.empty());
    REQUIRE(result.found_by.size() == 1);
    CHECK(result.found_by[0] == FoundBy::unexplained);
    return map.objects[0]->pose();
  };
  // How far the box placed at a pose is from the box now, whichever of its
  // symmetries the pose takes: the largest distance from one of its corners
  // to the nearest corner of the box now.
  const auto corner = [](int c) {  // corner c of the box in its own frame
    const Vec3<S> h = TurnedL<S, B>::book_half();
    return Vec3<S>{c & 1 ? h.x() : -h.x(), c & 2 ? h.y() : -h.y(), c & 4 ? h.z() : -h.z()};
  };
  const auto corners_off = [&](const SE3<S>& pose) {
    double worst = 0;
    for (int c = 0; c < 8; ++c) {
      double nearest = 1e9;
      for (int e = 0; e < 8; ++e) nearest = std::min(nearest, double(norm(pose * corner(c) - l.T_now * corner(e))));
      worst = std::max(worst, nearest);
    }
    return worst;
  };
  const auto from_last = found_where(false);
  if (from_last) {
    INFO("from its last orientation: corners " << corners_off(*from_last) << " m off");
    CHECK(corners_off(*from_last) > 0.03);  // the scene needs the turned fits
  }
  const auto turned = found_where(true);
  REQUIRE(turned);
  INFO("turned: corners " << corners_off(*turned) << " m off");
  CHECK(corners_off(*turned) < 0.01);
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
