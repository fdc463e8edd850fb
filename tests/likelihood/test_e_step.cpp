// The E-step (eq. 5) with the paper's likelihood (eq. 7): exact numbers on
// volumes with hand-set SDF values and foreground counts, zero outside every
// volume, a user-defined model type, and an occluding object taking the
// association of the pixels it covers.
#include <cmath>
#include <vector>

#include "emfusion/likelihood/e_step.hpp"
#include "emfusion/preprocess/vertex_map.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"
#include "support/fusion.hpp"

using namespace emfusion;
using emfusion::test::Approx;

namespace {

/// Sets every voxel of a volume to one SDF value with weight 1, and the
/// foreground counts (if any) to fg / bg.
template <class S>
struct FillVoxels {
  TsdfView<S, S> volume;
  ForegroundView<S, float> counts;
  S sdf;
  float fg, bg;
  EMF_HD void operator()(std::int64_t i) const {
    volume.sdf[i] = sdf;
    volume.weight[i] = S(1);
    if (!counts.empty()) counts.fg[i] = fg, counts.bg[i] = bg;
  }
};

template <class S, class B>
TsdfVolume<S, B> constant_volume(const Vec3<S>& corner, S sdf, ForegroundCounts<S, B>* counts = nullptr, float fg = 0,
                                 float bg = 0) {
  VolumeGeometry<S> g;
  g.dims = Vec3i{{8, 8, 8}};
  g.voxel_size = S(0.05);
  g.T_world_volume = SE3<S>::translation(corner);
  TsdfVolume<S, B> v(g);
  if (counts) *counts = ForegroundCounts<S, B>(g.dims, g.voxel_size);
  for_each_index(B{}, v.voxel_count(),
                 FillVoxels<S>{v.view(), counts ? counts->view() : ForegroundView<S, float>{}, sdf, fg, bg});
  return v;
}

/// The paper's likelihood for a given |sdf| and p_fg, computed here by hand.
double paper_likelihood(double sdf, double p_fg) {
  return 0.8 * std::exp(-std::abs(sdf) / 0.02) / (2 * 0.02) * p_fg + 0.2 * 1.0;
}

/// A model of the user's own: a Gaussian on the SDF, to show that any type
/// with likelihood() plugs into the E-step.
template <class S>
struct GaussianOnSdf {
  TsdfView<S, const S> volume;
  S sigma;
  EMF_HD S likelihood(const Vec3<S>& p) const {
    S sdf;
    if (!volume.sample(p, sdf)) return S(0);
    return std::exp(-S(0.5) * sdf * sdf / (sigma * sigma));
  }
};

}  // namespace

TEMPLATE_LIST_TEST_CASE("E-step reproduces eq. 5 with the eq. 7 mixture on hand-made volumes", "[likelihood]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // Three volumes cover the point (0.2, 0.2, 0.2) (world = camera frame);
  // a fourth lies elsewhere.
  ForegroundCounts<S, B> counts;
  const auto bg = constant_volume<S, B>(Vec3<S>::zero(), S(0.01));
  const auto a = constant_volume<S, B>(Vec3<S>::zero(), S(-0.03), &counts, 3.0f, 1.0f);
  const auto far = constant_volume<S, B>(vec3(S(5), S(5), S(5)), S(0));
  std::vector<Vec3<S>> host_points{vec3(S(0.2), S(0.2), S(0.2)), Vec3<S>::constant(std::numeric_limits<S>::quiet_NaN()),
                                   vec3(S(3), S(3), S(3))};
  const auto points = Image<Vec3<S>, Host>::from_host(3, 1, host_points).template to<B>();

  using M = PaperLikelihood<S>;
  std::vector<M> models(3);
  models[0].volume = bg.view();
  models[1].volume = a.view();
  models[1].foreground = counts.view();
  models[2].volume = far.view();
  std::vector<SE3<S>> poses{bg.pose().inverse(), a.pose().inverse(), far.pose().inverse()};
  Associations<S, B> q;
  e_step(B{}, points, std::span<const M>(models), std::span<const SE3<S>>(poses), q);
  REQUIRE(q.model_count() == 3);

  const double l_bg = paper_likelihood(0.01, 1.0), l_a = paper_likelihood(0.03, 0.75);
  const double tol = emfusion::test::eps_for<S>() * 10;
  const auto q0 = q.image(0).to_host(), q1 = q.image(1).to_host(), q2 = q.image(2).to_host();
  CHECK(double(q0[0]) == Approx(l_bg / (l_bg + l_a)).epsilon(tol));
  CHECK(double(q1[0]) == Approx(l_a / (l_bg + l_a)).epsilon(tol));
  CHECK(q2[0] == S(0));  // outside its volume: likelihood 0
  for (int k = 0; k < 3; ++k) {
    const auto img = q.image(k).to_host();
    CHECK(img[1] == S(0));  // no measurement
    CHECK(img[2] == S(0));  // outside every volume
  }

  // A user's model type goes through the same E-step.
  using G = GaussianOnSdf<S>;
  std::vector<G> gauss{G{bg.view(), S(0.02)}, G{a.view(), S(0.02)}};
  std::vector<SE3<S>> two{poses[0], poses[1]};
  e_step(B{}, points, std::span<const G>(gauss), std::span<const SE3<S>>(two), q);
  REQUIRE(q.model_count() == 2);
  const double g_bg = std::exp(-0.5 * 0.25), g_a = std::exp(-0.5 * 2.25);
  CHECK(double(q.image(0).to_host()[0]) == Approx(g_bg / (g_bg + g_a)).epsilon(tol));
}

TEMPLATE_LIST_TEST_CASE("Unobserved space inside a volume counts as truncated, not as outside", "[likelihood]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  VolumeGeometry<S> g;
  g.dims = Vec3i{{8, 8, 8}};
  g.voxel_size = S(0.05);
  const TsdfVolume<S, B> empty(g);  // never integrated
  PaperLikelihood<S> m;
  m.volume = empty.view();
  // Evaluated on the host for a Host volume only (the view points to device
  // memory otherwise).
  if constexpr (!B::is_device) {
    CHECK(double(m.likelihood(vec3(S(0.2), S(0.2), S(0.2)))) ==
          Approx(paper_likelihood(double(empty.truncation()), 1.0)).epsilon(1e-5));
    CHECK(m.likelihood(vec3(S(-0.1), S(0.2), S(0.2))) == S(0));
  }
}

/// A wall 2 m ahead (the background, fused before the box arrived) and a
/// box 0.6 m in front of it (an object whose volume saw only the box, every
/// voxel foreground), with the frame of both rendered: points and labels
/// (0 wall, 1 box).
template <class S, class B>
struct OccludedWall {
  TsdfVolume<S, B> background{emfusion::test::cube_around(vec3(S(0), S(0), S(1.5)), 96, S(0.03))};
  TsdfVolume<S, B> object{emfusion::test::cube_around(vec3(S(0), S(0), S(1.4)), 64, S(0.01))};
  ForegroundCounts<S, B> counts{object.dims(), object.voxel_size()};
  Image<Vec3<S>, B> points;
  Image<int, B> labels;

  OccludedWall() {
    const PinholeCamera<S> camera = emfusion::test::small_camera<S>();
    sim::Scene<S> wall, box, both;
    const auto plane =
        sim::make_plane(sim::look_at(vec3(S(0), S(0), S(2)), Vec3<S>::zero(), vec3(S(0), S(-1), S(0))));
    const auto cube = sim::make_box(SE3<S>::translation(vec3(S(0), S(0), S(1.4))), Vec3<S>::constant(S(0.15)));
    wall.add(plane);
    box.add(cube);
    both.add(plane);
    both.add(cube);
    const std::vector<SE3<S>> views{SE3<S>::identity(), SE3<S>::translation(vec3(S(0.05), S(0), S(0))),
                                    SE3<S>::translation(vec3(S(-0.05), S(0.03), S(0)))};
    emfusion::test::fuse_views(background, wall, camera, views, IntegrationParams<S>{});
    for_each_index(B{}, object.voxel_count(), FillVoxels<S>{object.view(), counts.view(), S(0), 1.0f, 0.0f});
    // (FillVoxels set the SDF too: fuse the box into the reset volume.)
    object.reset();
    emfusion::test::fuse_views(object, box, camera, views, IntegrationParams<S>{});
    Image<S, B> depth;
    sim::render_depth(both, camera, SE3<S>::identity(), depth, &labels);
    back_project(depth, camera, points);
  }
};

TEMPLATE_LIST_TEST_CASE("An occluding object takes the association of the pixels it covers", "[likelihood]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const OccludedWall<S, B> scene;
  const auto& [background, object, counts, points, labels] = scene;
  using M = PaperLikelihood<S>;
  std::vector<M> models(2);
  models[0].volume = background.view();
  models[1].volume = object.view();
  models[1].foreground = counts.view();
  std::vector<SE3<S>> poses{background.pose().inverse(), object.pose().inverse()};
  Associations<S, B> q;
  e_step(B{}, points, std::span<const M>(models), std::span<const SE3<S>>(poses), q);

  const auto label = labels.to_host();
  const auto q_bg = q.image(0).to_host(), q_obj = q.image(1).to_host();
  int box_pixels = 0, box_to_object = 0, wall_pixels = 0, wall_to_background = 0;
  for (std::size_t i = 0; i < label.size(); ++i) {
    if (label[i] == 1) {
      ++box_pixels;
      box_to_object += q_obj[i] > S(0.9);
      CHECK(double(q_obj[i] + q_bg[i]) == Approx(1.0).epsilon(1e-4));
    } else if (label[i] == 0) {
      ++wall_pixels;
      wall_to_background += q_bg[i] > S(0.9);
    }
  }
  REQUIRE(box_pixels > 500);
  REQUIRE(wall_pixels > 5000);
  // Nearly every pixel on the box goes to the object although the background
  // has a surface along the same rays (the rest lie on the box's silhouette,
  // where the fused box is thinner than the rendered one), and the wall
  // stays with the background, also where its points fall inside the
  // object's volume.
  CHECK(box_to_object >= int(0.9 * box_pixels));
  CHECK(wall_to_background >= int(0.99 * wall_pixels));
}

TEMPLATE_LIST_TEST_CASE("The last E-step of a frame reuses the background's likelihoods when only objects moved",
                        "[likelihood]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const OccludedWall<S, B> scene;
  using M = PaperLikelihood<S>;
  M wall_model, box_model;
  wall_model.volume = scene.background.view();
  box_model.volume = scene.object.view();
  box_model.foreground = scene.counts.view();
  const std::vector<M> objects{box_model};
  const SE3<S> T_wall = scene.background.pose().inverse();
  const auto run = [&](Associations<S, B>& q, const M& background, const SE3<S>& T_background,
                       const SE3<S>& T_object, bool unchanged) {
    const std::vector<SE3<S>> poses{T_object};
    e_step(B{}, scene.points, background, T_background, std::span<const M>(objects), std::span<const SE3<S>>(poses), q,
           unchanged);
  };
  const auto same_images = [](const Associations<S, B>& a, const Associations<S, B>& b) {
    for (int k = 0; k < 2; ++k)
      if (a.image(k).to_host() != b.image(k).to_host()) return false;
    return true;
  };
  const SE3<S> T_box = scene.object.pose().inverse();
  const SE3<S> T_box_moved = SE3<S>::translation(vec3(S(0.02), S(0), S(0))) * T_box;

  Associations<S, B> kept, fresh;
  run(kept, wall_model, T_wall, T_box, false);
  // The object moved: the same numbers as an E-step from nothing.
  run(kept, wall_model, T_wall, T_box_moved, true);
  run(fresh, wall_model, T_wall, T_box_moved, false);
  CHECK(same_images(kept, fresh));
  CHECK(kept.background_likelihood().to_host() == fresh.background_likelihood().to_host());
  // The background's values were taken from the first call, not sampled
  // again: a different background model at the same pose changes nothing
  // while the caller says the background is unchanged (here it lies).
  M empty_wall = wall_model;
  TsdfVolume<S, B> unobserved(emfusion::test::cube_around(vec3(S(0), S(0), S(1.5)), 8, S(0.3)));
  empty_wall.volume = unobserved.view();
  run(kept, empty_wall, T_wall, T_box, true);
  Associations<S, B> with_wall;
  run(with_wall, wall_model, T_wall, T_box, false);
  CHECK(same_images(kept, with_wall));
  // The camera moved: the background is evaluated again.
  const SE3<S> T_wall_moved = T_wall * SE3<S>::translation(vec3(S(0.01), S(0), S(0)));
  run(kept, empty_wall, T_wall_moved, T_box, true);
  Associations<S, B> without_wall;
  run(without_wall, empty_wall, T_wall_moved, T_box, false);
  CHECK(same_images(kept, without_wall));
  CHECK_FALSE(same_images(kept, with_wall));
}
