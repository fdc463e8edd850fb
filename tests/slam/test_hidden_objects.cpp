// An object that passes behind another (a panel of the background, never
// detected) on the box scene's camera: held at its velocity while hidden
// and looked for where it went, believed for hidden_moving_seconds only,
// solved from its prediction while partly hidden (predict_hidden_share),
// and, without those rules, found where it went in what no model explains
// or not at all. Float only (SystemRuleConfigs, support/configs.hpp).
#include <algorithm>

#include "support/box_scene.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"
#include "support/system_instances.hpp"

using namespace emfusion;
using namespace emfusion::test;

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
