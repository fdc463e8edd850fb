// Photometric alignment (solve/photometric.hpp) on scenes with a texture
// painted on their surfaces: the terms' Jacobian against finite
// differences, frame-to-frame alignment alone recovering a known motion, and
// the case it is for: a wall, along which SDF alignment cannot see a motion
// and the sum of the SDF and photometric terms can. Also the intensity
// images it reads (preprocess/intensity.hpp), and colour in a model
// (volume/intensity_grid.hpp): fused gray values, the colour terms of
// SDF alignment against them, and an object's colour growing with it.
#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "emfusion/io/colour.hpp"
#include "emfusion/preprocess/intensity.hpp"
#include "emfusion/preprocess/vertex_map.hpp"
#include "emfusion/sim/primitives.hpp"
#include "emfusion/sim/render.hpp"
#include "emfusion/slam/object_model.hpp"
#include "emfusion/solve/photometric.hpp"
#include "emfusion/volume/integrate.hpp"
#include "emfusion/volume/intensity_grid.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"

using namespace emfusion;
using emfusion::test::Approx;

namespace {

/// A smooth texture on world points: periods of 20-35 cm, so that the
/// basin of photometric alignment spans a few centimetres.
template <class S>
S texture(const Vec3<S>& X) {
  return S(0.5) + S(0.2) * std::sin(S(25) * X.x() + S(3) * X.z()) * std::sin(S(22) * X.y()) +
         S(0.15) * std::sin(S(18) * X.z() + S(13) * X.x() - S(9) * X.y());
}

/// Depth, the vertex map and the intensity of `scene` seen from `pose` by
/// `camera`, the intensity painted by texture() (0 where nothing is seen).
template <class S, class B>
struct TexturedView {
  Image<S, B> depth;
  Image<Vec3<S>, B> points;
  Image<S, B> intensity;
  Image<Vec2<S>, B> gradient;
  TexturedView(const sim::Scene<S>& scene, const PinholeCamera<S>& camera, const SE3<S>& pose) {
    Image<S, Host> d;
    sim::render_depth(scene, camera, pose, d);
    std::vector<S> gray(std::size_t(camera.pixel_count()), S(0));
    const std::vector<S> z = d.to_host();
    for (int v = 0; v < camera.height; ++v)
      for (int u = 0; u < camera.width; ++u) {
        const std::size_t i = std::size_t(v * camera.width + u);
        if (z[i] > S(0)) gray[i] = texture(pose * camera.back_project(S(u), S(v), z[i]));
      }
    depth = d.template to<B>();
    back_project(depth, camera, points);
    intensity = Image<S, Host>::from_host(camera.width, camera.height, gray).template to<B>();
    intensity_gradient(intensity, gradient);
  }
};

template <class S>
sim::Scene<S> textured_room() {
  sim::Scene<S> scene;
  scene.add(sim::make_plane(sim::look_at(vec3(S(0), S(0), S(2)), Vec3<S>::zero(), vec3(S(0), S(-1), S(0)))));
  scene.add(sim::make_plane(sim::look_at(vec3(S(0), S(0.5), S(0)), Vec3<S>::zero(), vec3(S(0), S(0), S(1)))));
  scene.add(sim::make_box(SE3<S>(so3_exp(vec3(S(0.2), S(0.4), S(0))), vec3(S(0.1), S(0), S(1.3))),
                          vec3(S(0.15), S(0.1), S(0.12))));
  return scene;
}

template <class S>
sim::Scene<S> wall() {
  sim::Scene<S> scene;
  scene.add(sim::make_plane(sim::look_at(vec3(S(0), S(0), S(1.5)), Vec3<S>::zero(), vec3(S(0), S(-1), S(0)))));
  return scene;
}

template <class S>
PinholeCamera<S> small_camera() {
  return PinholeCamera<S>{S(140), S(140), S(79.5), S(59.5), 160, 120};
}

template <class S>
double translation_error(const SE3<S>& a, const SE3<S>& b) {
  return norm((a.inverse() * b).template cast<double>().translation());
}

}  // namespace

TEST_CASE("Intensity images: Rec. 601 gray in [0, 1], central-difference gradients", "[solve][photometric]") {
  Image<Rgb8, Host> colour(4, 3, Rgb8{0, 0, 0});
  std::vector<Rgb8> px(12);
  for (int i = 0; i < 12; ++i) px[std::size_t(i)] = Rgb8{std::uint8_t(20 * i), std::uint8_t(10 * i), 255};
  colour = Image<Rgb8, Host>::from_host(4, 3, px);
  Image<double, Host> I;
  intensity_image(colour, I);
  const std::vector<double> gray = I.to_host();
  CHECK(gray[5] == Approx((0.299 * 100 + 0.587 * 50 + 0.114 * 255) / 255));
  Image<Vec2<double>, Host> g;
  intensity_gradient(I, g);
  const std::vector<Vec2<double>> grad = g.to_host();
  CHECK(grad[5].x() == Approx(0.5 * (gray[6] - gray[4])));  // inside: central
  CHECK(grad[5].y() == Approx(0.5 * (gray[9] - gray[1])));
  CHECK(grad[0].x() == Approx(gray[1] - gray[0]));  // border: one-sided
  CHECK_THROWS_WITH(intensity_image(Image<Rgb8, Host>{}, I), EMF_CONTAINS("the colour image is empty"));
}

TEST_CASE("The photometric terms' Jacobian matches finite differences", "[solve][photometric]") {
  using S = double;
  const PinholeCamera<S> camera = small_camera<S>();
  const sim::Scene<S> scene = textured_room<S>();
  const SE3<S> T_ref = SE3<S>::identity();
  const SE3<S> T = SE3<S>::exp(Vec6<S>{{0.01, -0.005, 0.01, 0.004, -0.006, 0.002}});
  const TexturedView<S, Host> ref(scene, camera, T_ref);
  // The current image an affine ramp: its central differences are its exact
  // gradient and bilinear sampling reproduces it, so the analytic Jacobian
  // must match the residual's finite differences to rounding.
  std::vector<S> ramp(std::size_t(camera.pixel_count()));
  for (int v = 0; v < camera.height; ++v)
    for (int u = 0; u < camera.width; ++u) ramp[std::size_t(v * camera.width + u)] = 0.3 + 0.004 * u - 0.003 * v;
  const Image<S, Host> current = Image<S, Host>::from_host(camera.width, camera.height, ramp);
  Image<Vec2<S>, Host> gradient;
  intensity_gradient(current, gradient);
  PhotometricParams<S> params;
  params.pixel_stride = 7;
  const PhotometricTerms<S> terms =
      make_photometric(ref.points, ref.intensity, T_ref, current, gradient, camera, params);
  int checked = 0;
  const double eps = 1e-6;
  for (int i = 0; i < terms.term_count(); ++i) {
    S r, w;
    Vec6<S> J;
    if (!terms.term(i, T, r, J, w)) continue;
    for (int k = 0; k < 6; ++k) {
      Vec6<S> d{};
      d[k] = eps;
      S rp, rm, wp, wm;
      Vec6<S> Jp, Jm;
      if (!terms.term(i, SE3<S>::exp(d) * T, rp, Jp, wp)) continue;
      d[k] = -eps;
      if (!terms.term(i, SE3<S>::exp(d) * T, rm, Jm, wm)) continue;
      const double numeric = (rp - rm) / (2 * eps);
      INFO("term " << i << ", parameter " << k);
      CHECK(J[k] == Approx(numeric).margin(1e-6 * (1 + std::fabs(numeric))));
    }
    ++checked;
  }
  CHECK(checked > 100);
}

TEMPLATE_LIST_TEST_CASE("Photometric alignment alone recovers a known camera motion", "[solve][photometric]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const PinholeCamera<S> camera = small_camera<S>();
  const sim::Scene<S> scene = textured_room<S>();
  const SE3<S> truth = SE3<S>::exp(Vec6<S>{{S(0.02), S(-0.01), S(0.015), S(0.01), S(-0.015), S(0.005)}});
  const TexturedView<S, B> ref(scene, camera, SE3<S>::identity()), cur(scene, camera, truth);
  const PhotometricTerms<S> terms =
      make_photometric(ref.points, ref.intensity, SE3<S>::identity(), cur.intensity, cur.gradient, camera);
  SolveReport report;
  const SE3<S> found =
      align_photometric(B{}, terms, HuberNorm<S>{S(0.05)}, LevenbergMarquardt{}, SE3<S>::identity(), &report);
  INFO("error " << translation_error(found, truth) * 1000 << " mm after " << report.iterations << " iterations ("
                << to_string(report.reason) << "), start " << translation_error(SE3<S>::identity(), truth) * 1000
                << " mm");
  CHECK(report.converged());
  CHECK(translation_error(found, truth) < 0.002);
  CHECK(norm(so3_log((found.inverse() * truth).rotation())) < S(0.002));
}

TEMPLATE_LIST_TEST_CASE("On a wall, SDF alignment misses a sideways motion that the photometric term finds",
                        "[solve][photometric]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const PinholeCamera<S> camera = small_camera<S>();
  const sim::Scene<S> scene = wall<S>();
  VolumeGeometry<S> g;
  g.dims = Vec3i{{96, 96, 96}};
  g.voxel_size = S(0.02);
  g.T_world_volume = volume_pose_in_front_of(SE3<S>::identity(), S(1.92));
  TsdfVolume<S, B> volume(g);
  const TexturedView<S, B> ref(scene, camera, SE3<S>::identity());
  integrate(volume, ref.depth, camera, SE3<S>::identity());
  // 3 cm along the wall and 1 cm towards it.
  const SE3<S> truth(so3_exp(vec3(S(0), S(0), S(0))), vec3(S(0.03), S(0), S(0.01)));
  const TexturedView<S, B> cur(scene, camera, truth);
  const HuberNorm<S> huber{S(2) * volume.voxel_size()};
  const auto* none = static_cast<const Image<S, B>*>(nullptr);

  const SE3<S> sdf_only = align_to_volume(volume, cur.points, none, SE3<S>::identity(), huber);
  const PhotometricTerms<S> photometric =
      make_photometric(ref.points, ref.intensity, SE3<S>::identity(), cur.intensity, cur.gradient, camera);
  SolveReport report;
  const SE3<S> both =
      align_to_volume_and_intensity(volume, cur.points, none, SE3<S>::identity(), huber, SdfAlignmentParams<S>{},
                                    photometric, HuberNorm<S>{S(0.05)}, S(0.03), LevenbergMarquardt{}, &report);
  const SE3<S> weight_zero =
      align_to_volume_and_intensity(volume, cur.points, none, SE3<S>::identity(), huber, SdfAlignmentParams<S>{},
                                    photometric, HuberNorm<S>{S(0.05)}, S(0), LevenbergMarquardt{});
  INFO("SDF alone " << translation_error(sdf_only, truth) * 1000 << " mm, with the photometric term "
                    << translation_error(both, truth) * 1000 << " mm (" << to_string(report.reason) << ")");
  // Depth fixes the distance to the wall, not the position along it.
  CHECK(std::fabs(double(sdf_only.translation().z()) - 0.01) < 0.003);
  CHECK(std::fabs(double(sdf_only.translation().x())) < 0.01);
  CHECK(report.converged());
  CHECK(translation_error(both, truth) < 0.003);
  // Weight 0 is SDF alignment alone.
  CHECK(translation_error(weight_zero, sdf_only) < 1e-5);
  CHECK_THROWS_WITH(
      align_to_volume_and_intensity(volume, cur.points, none, SE3<S>::identity(), huber, SdfAlignmentParams<S>{},
                                    photometric, HuberNorm<S>{S(0.05)}, S(-1), LevenbergMarquardt{}),
      EMF_CONTAINS("photometric weight"));
}

TEST_CASE("make_photometric names the image that does not fit", "[solve][photometric]") {
  using S = float;
  const PinholeCamera<S> camera = small_camera<S>();
  const TexturedView<S, Host> view(wall<S>(), camera, SE3<S>::identity());
  const Image<S, Host> small(10, 10);
  CHECK_THROWS_WITH(make_photometric(view.points, small, SE3<S>::identity(), view.intensity, view.gradient, camera),
                    EMF_CONTAINS("reference intensity image is 10x10"));
  CHECK_THROWS_WITH(make_photometric(view.points, view.intensity, SE3<S>::identity(), small, view.gradient, camera),
                    EMF_CONTAINS("intensity image is 10x10"));
  PhotometricParams<S> bad;
  bad.pixel_stride = 0;
  CHECK_THROWS_WITH(make_photometric(view.points, view.intensity, SE3<S>::identity(), view.intensity, view.gradient,
                                     camera, bad),
                    EMF_CONTAINS("pixel_stride"));
}

namespace {
/// A wall's TSDF and its colour fused from the identity view, 2 cm voxels.
template <class S, class B>
struct ColouredWall {
  TsdfVolume<S, B> volume;
  IntensityGrid<S, B> colour;
  static VolumeGeometry<S> geometry() {
    VolumeGeometry<S> g;
    g.dims = Vec3i{{96, 96, 96}};
    g.voxel_size = S(0.02);
    g.T_world_volume = volume_pose_in_front_of(SE3<S>::identity(), S(1.92));
    return g;
  }
  explicit ColouredWall(const PinholeCamera<S>& camera)
      : volume(geometry()), colour(geometry().dims, geometry().voxel_size) {
    const TexturedView<S, B> view(wall<S>(), camera, SE3<S>::identity());
    integrate(volume, view.depth, camera, SE3<S>::identity());
    fuse_intensity(colour, volume.pose(), volume.truncation(), S(64), view.depth, view.intensity,
                   static_cast<const Image<S, B>*>(nullptr), camera, SE3<S>::identity(), B{});
  }
  /// The terms of the frame `view` with colour terms of `scale` (0: none).
  SdfAlignmentTerms<S, S> terms(const TexturedView<S, B>& view, S scale) const {
    SdfAlignmentTerms<S, S> t = make_sdf_alignment(volume, view.points, static_cast<const Image<S, B>*>(nullptr));
    t.colour = colour.view();
    t.intensity = view.intensity.view();
    t.colour_scale = scale;
    return t;
  }
};
}  // namespace

TEST_CASE("Fused colour: the gray values of the surface, on voxels near it only", "[solve][photometric][colour]") {
  using S = double;
  const PinholeCamera<S> camera = small_camera<S>();
  const ColouredWall<S, Host> model(camera);
  const std::vector<float> value = model.colour.values_to_host(), weight = model.colour.weights_to_host();
  const auto& v = model.volume.view();
  int coloured = 0, checked = 0;
  for (int z = 0; z < v.nz; ++z)
    for (int y = 0; y < v.ny; y += 7)
      for (int x = 0; x < v.nx; x += 7) {
        const std::int64_t i = v.index(x, y, z);
        const Vec3<S> world = model.volume.pose() * v.voxel_center(x, y, z);
        if (!(weight[std::size_t(i)] > 0.0f)) continue;
        ++coloured;
        // Only within the truncation of the wall at z = 1.5 m.
        CHECK(std::fabs(world.z() - 1.5) < model.volume.truncation() + 1e-9);
        // The gray value of the pixel the voxel's centre projects to.
        const Vec2<S> uv = camera.project(world);
        const int u = int(std::floor(uv.x() + 0.5)), pv = int(std::floor(uv.y() + 0.5));
        if (u < 1 || pv < 1 || u > camera.width - 2 || pv > camera.height - 2) continue;
        CHECK(double(value[std::size_t(i)]) == Approx(texture(camera.back_project(S(u), S(pv), S(1.5)))).margin(1e-4));
        CHECK(weight[std::size_t(i)] == 1.0f);
        ++checked;
      }
  CHECK(checked > 200);
  CHECK(coloured >= checked);
  IntensityGrid<S, Host> grid = model.colour;
  const Image<S, Host> small(10, 10);
  const TexturedView<S, Host> view(wall<S>(), camera, SE3<S>::identity());
  CHECK_THROWS_WITH(fuse_intensity(grid, model.volume.pose(), S(0.1), S(64), view.depth, small,
                                   static_cast<const Image<S, Host>*>(nullptr), camera, SE3<S>::identity(), Host{}),
                    EMF_CONTAINS("intensity image is 10x10"));
}

TEST_CASE("The colour terms' Jacobian matches finite differences along the surface", "[solve][photometric][colour]") {
  using S = double;
  const PinholeCamera<S> camera = small_camera<S>();
  const ColouredWall<S, Host> model(camera);
  const TexturedView<S, Host> view(wall<S>(), camera, SE3<S>(so3_exp(vec3(0.0, 0.0, 0.01)), vec3(0.01, 0.005, 0.0)));
  SdfAlignmentTerms<S, S> terms = model.terms(view, S(0.2));
  terms.stride = 5;
  const SE3<S> T = model.volume.pose().inverse();
  const int n = terms.term_count() / 2;
  int checked = 0;
  const double eps = 1e-6;
  for (int i = n; i < 2 * n; ++i) {
    S r, w;
    Vec6<S> J;
    if (!terms.term(i, T, r, J, w)) continue;
    // The wall's normal is the volume's z: its gradient along it is left
    // out, and the motions along the wall (x, y, a turn about z) are
    // those of the model's colour.
    CHECK(std::fabs(J[2]) < 1e-3 * (std::fabs(J[0]) + std::fabs(J[1])) + 1e-9);
    bool all = true;
    for (int k : {0, 1, 5}) {
      Vec6<S> d{};
      d[k] = eps;
      S rp, rm, wp, wm;
      Vec6<S> Jp, Jm;
      all = all && terms.term(i, SE3<S>::exp(d) * T, rp, Jp, wp);
      d[k] = -eps;
      all = all && terms.term(i, SE3<S>::exp(d) * T, rm, Jm, wm);
      if (!all) break;
      const double numeric = (rp - rm) / (2 * eps);
      INFO("term " << i << ", parameter " << k);
      // Within 0.1 % of the term's gradient along the wall: the SDF's
      // gradient, whose part is left out, is the wall's normal to ~1e-4.
      CHECK(J[k] == Approx(numeric).margin(1e-3 * (std::fabs(J[0]) + std::fabs(J[1]) + std::fabs(numeric))));
    }
    checked += all;
  }
  CHECK(checked > 100);
  // Without colour, the terms are the SDF terms alone.
  terms.colour_scale = S(0);
  CHECK(terms.term_count() == n);
}

TEMPLATE_LIST_TEST_CASE("On a wall, the model's colour finds the slide that its depth misses",
                        "[solve][photometric][colour]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const PinholeCamera<S> camera = small_camera<S>();
  const ColouredWall<S, B> model(camera);
  // 3 cm along the wall and 1 cm towards it.
  const SE3<S> truth(so3_exp(vec3(S(0), S(0), S(0))), vec3(S(0.03), S(0), S(0.01)));
  const TexturedView<S, B> view(wall<S>(), camera, truth);
  const HuberNorm<S> huber{S(2) * model.volume.voxel_size()};
  const auto solve = [&](S scale, SolveReport* report) {
    LinearizationCache<S, B> cache;
    const SE3<S> T = solve_coarse_to_fine(B{}, model.terms(view, scale), huber, SdfAlignmentParams<S>{},
                                          LevenbergMarquardt{}, model.volume.pose().inverse(), report, cache);
    return model.volume.pose() * T;
  };
  SolveReport report;
  const SE3<S> depth_alone = solve(S(0), nullptr), coloured = solve(S(0.2), &report);
  INFO("depth alone " << translation_error(depth_alone, truth) * 1000 << " mm, with colour "
                      << translation_error(coloured, truth) * 1000 << " mm (" << to_string(report.reason) << ")");
  CHECK(translation_error(depth_alone, truth) > 0.02);
  CHECK(report.converged());
  CHECK(translation_error(coloured, truth) < 0.003);
}

TEMPLATE_LIST_TEST_CASE("An object's colour grows with its volume", "[solve][photometric][colour]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  ObjectModel<S, B> o(1, "cup", SE3<S>::identity(), 8, S(0.01), S(3));
  CHECK(o.colour().empty());
  CHECK(std::as_const(o).colour().view().empty());  // what growing an uncoloured object copies nothing from
  const std::size_t plain = o.memory_bytes();
  o.enable_colour();
  REQUIRE(!o.colour().empty());
  CHECK(o.memory_bytes() == plain + 8 * 8 * 8 * 8);
  // Mark one voxel, grow by two voxels below on x, find it moved by two.
  {
    std::vector<float> value = o.colour().values_to_host(), weight = o.colour().weights_to_host();
    value[std::size_t(o.volume().view().index(3, 4, 5))] = 0.75f;
    weight[std::size_t(o.volume().view().index(3, 4, 5))] = 2.0f;
    o.colour().assign_from_host(value, weight);
  }
  REQUIRE(o.grow_to_fit(vec3(S(-0.015), S(0), S(0)), vec3(S(0.08), S(0.08), S(0.08)), 64));
  REQUIRE(o.volume().dims()[0] == 10);
  CHECK(o.colour().dims()[0] == 10);
  const std::vector<float> value = o.colour().values_to_host(), weight = o.colour().weights_to_host();
  const std::int64_t moved = o.volume().view().index(5, 4, 5);
  CHECK(value[std::size_t(moved)] == 0.75f);
  CHECK(weight[std::size_t(moved)] == 2.0f);
  CHECK(std::count_if(weight.begin(), weight.end(), [](float w) { return w > 0.0f; }) == 1);
  CHECK_THROWS_WITH(o.colour().assign_from_host({}, {}), EMF_CONTAINS("expected 640 voxels, got 0"));
}
