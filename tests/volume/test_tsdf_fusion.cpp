// Fusion accuracy of the TSDF volume: a sphere and a box rendered by `sim`,
// integrated from 24 poses, checked against their analytic SDFs; raycasting
// checked against rendered depth; bad arguments checked for clear errors.
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "emfusion/volume/marching_cubes.hpp"
#include "emfusion/volume/mesh.hpp"
#include "emfusion/volume/raycast.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"
#include "support/fusion.hpp"

using namespace emfusion;

namespace {

template <class S>
sim::Scene<S> sphere_scene() {
  sim::Scene<S> scene;
  scene.add(sim::make_sphere(Vec3<S>::zero(), S(0.25)));
  return scene;
}

template <class S>
sim::Scene<S> box_scene() {
  sim::Scene<S> scene;
  const SE3<S> pose = SE3<S>::exp(Vec6<S>{{S(0.01), S(-0.02), S(0.0), S(0.3), S(-0.2), S(0.5)}});
  scene.add(sim::make_box(pose, vec3(S(0.2), S(0.15), S(0.1))));
  return scene;
}

struct SdfErrors {
  double max_error = 0;      // voxels
  std::size_t checked = 0;   // voxels near the surface that were observed
  std::size_t unobserved = 0;
};

/// Compares fused SDF values with the analytic SDF where |analytic| is below
/// `band` voxels.
template <class S, class B>
SdfErrors compare_near_surface(const TsdfVolume<S, B>& volume, const sim::Scene<S>& scene, double band) {
  const auto sdf = volume.sdf_to_host();
  const auto weight = volume.weight_to_host();
  const auto view = volume.view();
  const double vs = double(volume.voxel_size());
  SdfErrors e;
  for (int z = 0; z < view.nz; ++z)
    for (int y = 0; y < view.ny; ++y)
      for (int x = 0; x < view.nx; ++x) {
        const double truth = double(scene.distance(volume.pose() * view.voxel_center(x, y, z)));
        if (std::fabs(truth) >= band * vs) continue;
        const auto i = view.index(x, y, z);
        if (!(weight[i] > 0)) {
          ++e.unobserved;
          continue;
        }
        e.max_error = std::max(e.max_error, std::fabs(double(sdf[i]) - truth) / vs);
        ++e.checked;
      }
  return e;
}

/// A camera looking along the z axis of a 32 x 32 x 64 grid of 2 cm voxels
/// that starts 0.4 m in front of it: fronto-parallel walls at constant depth
/// fill its view.
template <class S>
PinholeCamera<S> wall_camera() {
  return {S(100), S(100), S(31.5), S(23.5), 64, 48};
}
template <class S>
VolumeGeometry<S> wall_geometry() {
  VolumeGeometry<S> g;
  g.dims = Vec3i{{32, 32, 64}};
  g.voxel_size = S(0.02);
  g.T_world_volume = SE3<S>::translation(vec3(S(-0.32), S(-0.32), S(0.4)));
  return g;
}

}  // namespace

TEMPLATE_LIST_TEST_CASE("Fused sphere and box match their analytic SDF near the surface", "[volume]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const auto camera = test::small_camera<S>();
  const auto poses = test::orbit_poses<S>(Vec3<S>::zero(), S(1.2), 24);

  for (const auto& [name, scene] : {std::pair{"sphere", sphere_scene<S>()}, std::pair{"box", box_scene<S>()}}) {
    TsdfVolume<S, B> volume(test::cube_around<S>(Vec3<S>::zero(), 64, S(0.01)));
    test::fuse_views(volume, scene, camera, poses);  // IntegrationParams::refined()
    const SdfErrors e = compare_near_surface(volume, scene, 1.0);
    // The paper's update on the same views, for comparison.
    TsdfVolume<S, B> plain(test::cube_around<S>(Vec3<S>::zero(), 64, S(0.01)));
    test::fuse_views(plain, scene, camera, poses, IntegrationParams<S>{});
    const SdfErrors p = compare_near_surface(plain, scene, 1.0);
    INFO(name << ": max |fused - analytic| = " << e.max_error << " voxels over " << e.checked
              << " voxels, unobserved " << e.unobserved << "; the paper's update: " << p.max_error << " voxels");
    CHECK(e.checked > 1000);
    CHECK(e.max_error < 1.0);
    CHECK(p.max_error > e.max_error);
    // 24 views around the object see nearly all of its surface band.
    CHECK(double(e.unobserved) < 0.02 * double(e.checked));
  }
}

TEMPLATE_LIST_TEST_CASE("Raycasting the fused volume reproduces rendered depth", "[volume]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const auto camera = test::small_camera<S>();
  const auto scene = box_scene<S>();
  TsdfVolume<S, B> volume(test::cube_around<S>(Vec3<S>::zero(), 64, S(0.01)));
  test::fuse_views(volume, scene, camera, test::orbit_poses<S>(Vec3<S>::zero(), S(1.2), 24));

  // A view that was not integrated.
  const SE3<S> pose = sim::look_at<S>(vec3(S(0.7), S(-0.6), S(0.5)), Vec3<S>::zero(), vec3(S(0), S(0), S(1)));
  Image<S, B> rendered;
  sim::render_depth(scene, camera, pose, rendered, static_cast<Image<int, B>*>(nullptr), {}, volume.backend());
  RaycastResult<S, B> cast;
  raycast(volume, camera, pose, cast);

  const auto truth = rendered.to_host();
  const auto depth = cast.depth.to_host();
  const auto hit = cast.hit.to_host();
  const auto normals = cast.normals.to_host();
  std::vector<double> errors;
  std::size_t truth_pixels = 0, false_hits = 0;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    if (truth[i] > 0) ++truth_pixels;
    if (hit[i] && !(truth[i] > 0)) ++false_hits;
    if (hit[i] && truth[i] > 0) {
      errors.push_back(std::fabs(double(depth[i] - truth[i])));
      CHECK(std::fabs(double(norm(normals[i])) - 1.0) < 1e-3);
    }
  }
  REQUIRE(!errors.empty());
  std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
  const double median = errors[errors.size() / 2];
  INFO("median |raycast - rendered| = " << median / 0.01 << " voxels over " << errors.size() << " of "
                                        << truth_pixels << " pixels; false hits " << false_hits);
  CHECK(median < 0.5 * 0.01);
  CHECK(double(errors.size()) > 0.97 * double(truth_pixels));
  CHECK(false_hits < truth.size() / 200);
}

TEMPLATE_LIST_TEST_CASE("A depth-only raycast gives the full cast's depths and leaves vertices and normals empty",
                        "[volume]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const auto camera = test::small_camera<S>();
  TsdfVolume<S, B> volume(test::cube_around<S>(Vec3<S>::zero(), 64, S(0.01)));
  test::fuse_views(volume, box_scene<S>(), camera, test::orbit_poses<S>(Vec3<S>::zero(), S(1.2), 24));
  const SE3<S> pose = sim::look_at<S>(vec3(S(0.7), S(-0.6), S(0.5)), Vec3<S>::zero(), vec3(S(0), S(0), S(1)));
  RaycastResult<S, B> full, depth_only;
  raycast(volume, camera, pose, full);
  RaycastParams<S> params;
  params.surface = false;
  raycast(volume, camera, pose, depth_only, params);
  CHECK(depth_only.vertices.empty());
  CHECK(depth_only.normals.empty());
  const auto d_full = full.depth.to_host(), d_only = depth_only.depth.to_host();
  const auto h_full = full.hit.to_host(), h_only = depth_only.hit.to_host();
  // The same march: every hit of the full cast at the same depth; a pixel
  // the full cast missed may hit only where its crossing had no gradient.
  std::size_t hits = 0, extra = 0, different = 0;
  for (std::size_t i = 0; i < d_full.size(); ++i) {
    if (h_full[i]) {
      ++hits;
      different += !h_only[i] || d_only[i] != d_full[i];
    } else {
      extra += h_only[i];
      if (!h_only[i]) different += d_only[i] != S(0);
    }
  }
  INFO(hits << " hits, " << extra << " more without the gradient, " << different << " pixels differ");
  CHECK(hits > d_full.size() / 10);
  CHECK(different == 0);
  CHECK(extra <= hits / 100);
  // Casting with surfaces again into the same result allocates them again.
  raycast(volume, camera, pose, depth_only);
  CHECK(depth_only.normals.same_size(camera.width, camera.height));
  CHECK(depth_only.hit.to_host() == h_full);
}

TEMPLATE_LIST_TEST_CASE("Integration weights: per-pixel weights and the W_max cap", "[volume]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // A fronto-parallel wall at 1 m; the camera looks along the volume's z axis.
  const PinholeCamera<S> camera = wall_camera<S>();
  TsdfVolume<S, B> volume(wall_geometry<S>());
  const Image<S, B> depth(camera.width, camera.height, S(1.0), volume.backend());
  Image<S, B> weights(camera.width, camera.height, S(0.25), volume.backend());

  // The default is the paper's update (eq. 10).
  IntegrationParams<S> params;
  // One frame with weight 0.25: near-surface voxels get weight 0.25, voxels in
  // free space (d >= truncation) weight 1.
  integrate(volume, depth, camera, SE3<S>::identity(), &weights, params);
  const auto view = volume.view();
  auto weight_at = [&](double z_world) {
    const auto w = volume.weight_to_host();
    const int z = int((z_world - 0.4) / 0.02);
    return double(w[view.index(16, 16, z)]);
  };
  CHECK(weight_at(0.99) == test::Approx(0.25));
  CHECK(weight_at(0.5) == test::Approx(1.0));   // 0.5 m in front of the wall: free space
  CHECK(weight_at(1.5) == test::Approx(0.0));   // behind the truncation band: untouched

  // Many frames: the weight saturates at W_max.
  params.max_weight = S(3);
  weights.fill(S(1));
  for (int k = 0; k < 10; ++k) integrate(volume, depth, camera, SE3<S>::identity(), &weights, params);
  CHECK(weight_at(0.99) == test::Approx(3.0));
  // The fused SDF of the voxel centre at z = 0.99 m is the distance to the wall.
  const auto sdf = volume.sdf_to_host();
  const int zi = int((0.99 - 0.4) / 0.02);
  const double centre = 0.4 + (zi + 0.5) * 0.02;
  CHECK(double(sdf[view.index(16, 16, zi)]) == test::Approx(1.0 - centre).margin(1e-3));
}

TEMPLATE_LIST_TEST_CASE("A surface in front of points another model owns is forgotten with unowned_free_from",
                        "[volume]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // A wall at 1 m fused 20 times (a trace of an object that stood still in
  // the background), then the object seen 0.12 m further back (within the
  // truncation of 0.2 m) on pixels the volume's model does not own (q = 0).
  const PinholeCamera<S> camera = wall_camera<S>();
  const VolumeGeometry<S> g = wall_geometry<S>();
  const B backend{};
  const Image<S, B> wall(camera.width, camera.height, S(1.0), backend);
  const Image<S, B> behind(camera.width, camera.height, S(1.12), backend);
  const Image<S, B> owned(camera.width, camera.height, S(1), backend);
  const Image<S, B> not_owned(camera.width, camera.height, S(0), backend);
  // The depth of the first sign change along column (x, 16) (the surface a
  // ray cast would meet; x = 16 is the centre), or 0 where there is none.
  const auto surface_depth = [](const TsdfVolume<S, B>& volume, int x = 16) {
    const auto sdf = volume.sdf_to_host();
    const auto weight = volume.weight_to_host();
    const auto view = volume.view();
    for (int z = 0; z + 1 < view.nz; ++z) {
      const auto a = view.index(x, 16, z), b = view.index(x, 16, z + 1);
      if (weight[a] > 0 && weight[b] > 0 && sdf[a] > 0 && sdf[b] <= 0) return 0.4 + (z + 1) * 0.02;
    }
    return 0.0;
  };
  const auto fuse = [&](S unowned_free_from, int frames_behind, const Image<S, B>* others_drawn = nullptr) {
    IntegrationParams<S> params;
    params.unowned_free_from = unowned_free_from;
    TsdfVolume<S, B> volume(g, backend);
    for (int k = 0; k < 20; ++k) integrate(volume, wall, camera, SE3<S>::identity(), &owned, params);
    for (int k = 0; k < frames_behind; ++k)
      integrate(volume, behind, camera, SE3<S>::identity(), IntegrationWeights<S, B>{&not_owned, others_drawn}, params);
    return volume;
  };
  // The paper's update: rays ending on the other model within the truncation
  // leave the wall where it was, however many.
  CHECK(surface_depth(fuse(S(0), 10)) == test::Approx(1.0).margin(0.021));
  // Free from 0.3 truncations (0.06 m) in front of the points: after one
  // frame the surface left is within that and a voxel of them.
  CHECK(surface_depth(fuse(S(0.3), 1)) >= 1.12 - 0.06 - 0.02);

  // Confined to where another model is drawn: an object drawn on the left
  // half of the image only (u < 32; column x = 8 projects to u = 16.5, x =
  // 24 to u = 48.5) frees the wall there and leaves it on the right.
  std::vector<S> left(std::size_t(camera.width * camera.height), S(0));
  for (int v = 0; v < camera.height; ++v)
    for (int u = 0; u < camera.width / 2; ++u) left[std::size_t(v * camera.width + u)] = S(1.12);
  const auto drawn_left = Image<S, B>::from_host(camera.width, camera.height, left, backend);
  const TsdfVolume<S, B> gated = fuse(S(0.3), 1, &drawn_left);
  CHECK(surface_depth(gated, 8) >= 1.12 - 0.06 - 0.02);
  CHECK(surface_depth(gated, 24) == test::Approx(1.0).margin(0.021));
  // Nothing drawn: the paper's update bit for bit.
  const Image<S, B> none_drawn(camera.width, camera.height, S(0), backend);
  CHECK(fuse(S(0.3), 3, &none_drawn).sdf_to_host() == fuse(S(0), 3).sdf_to_host());
  const Image<S, B> small(8, 8, S(1), backend);
  TsdfVolume<S, B> volume(g, backend);
  CHECK_THROWS_WITH(integrate(volume, behind, camera, SE3<S>::identity(), IntegrationWeights<S, B>{&not_owned, &small}),
                    EMF_CONTAINS("others_drawn image is 8x8"));

  // On pixels the model owns (q = 1) the option changes nothing.
  IntegrationParams<S> on;
  on.unowned_free_from = S(0.3);
  TsdfVolume<S, B> a(g, backend), b(g, backend);
  for (const auto* depth : {&wall, &behind}) {
    integrate(a, *depth, camera, SE3<S>::identity(), &owned);
    integrate(b, *depth, camera, SE3<S>::identity(), &owned, on);
  }
  CHECK(a.sdf_to_host() == b.sdf_to_host());
  CHECK(a.weight_to_host() == b.weight_to_host());

  on.unowned_free_from = S(1.5);
  CHECK_THROWS_WITH(integrate(a, wall, camera, SE3<S>::identity(), &owned, on),
                    EMF_CONTAINS("unowned_free_from must be in [0, 1]"));
}

TEMPLATE_LIST_TEST_CASE("Volume operations reject bad arguments with clear errors", "[volume]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  VolumeGeometry<S> g;
  g.dims = Vec3i{{8, 8, 8}};
  g.voxel_size = S(0);
  CHECK_THROWS_WITH((TsdfVolume<S, B>(g)), EMF_CONTAINS("voxel size must be positive"));
  g.voxel_size = S(0.01);
  g.dims = Vec3i{{8, 0, 8}};
  CHECK_THROWS_WITH((TsdfVolume<S, B>(g)), EMF_CONTAINS("dimensions must be positive"));
  g.dims = Vec3i{{8, 8, 8}};
  g.truncation = S(-1);
  CHECK_THROWS_WITH((TsdfVolume<S, B>(g)), EMF_CONTAINS("truncation"));
  g.truncation = S(0);
  TsdfVolume<S, B> volume(g);
  CHECK(double(volume.truncation()) == test::Approx(0.1));

  const PinholeCamera<S> camera{S(50), S(50), S(15.5), S(11.5), 32, 24};
  const Image<S, B> wrong_size(16, 12, S(1), volume.backend());
  CHECK_THROWS_WITH(integrate(volume, wrong_size, camera, SE3<S>::identity()),
                    EMF_CONTAINS("depth image is 16x12 but 32x24 was expected"));
  const Image<S, B> empty;
  CHECK_THROWS_WITH(integrate(volume, empty, camera, SE3<S>::identity()), EMF_CONTAINS("depth image is empty"));
  const Image<S, B> depth(32, 24, S(1), volume.backend());
  const Image<S, B> small_weights(8, 8, S(1), volume.backend());
  CHECK_THROWS_WITH(integrate(volume, depth, camera, SE3<S>::identity(), &small_weights),
                    EMF_CONTAINS("weight image is 8x8"));
  PinholeCamera<S> bad_camera = camera;
  bad_camera.fx = S(0);
  RaycastResult<S, B> out;
  CHECK_THROWS_WITH(raycast(volume, bad_camera, SE3<S>::identity(), out), EMF_CONTAINS("focal lengths"));
}

#if EMFUSION_HAS_CUDA
TEST_CASE("CPU and CUDA fuse the same volume", "[volume]") {
  using S = float;
  const auto camera = test::small_camera<S>();
  const auto poses = test::orbit_poses<S>(Vec3<S>::zero(), S(1.2), 24);
  sim::Scene<S> scene;
  scene.add(sim::make_sphere(Vec3<S>::zero(), S(0.25)));
  scene.add(sim::make_box(SE3<S>::translation(vec3(S(0.1), S(0.1), S(-0.2))), vec3(S(0.1), S(0.2), S(0.05))));
  TsdfVolume<S, Host> cpu(test::cube_around<S>(Vec3<S>::zero(), 64, S(0.01)));
  TsdfVolume<S, Cuda> gpu(test::cube_around<S>(Vec3<S>::zero(), 64, S(0.01)));
  // The same depth images on both backends, so only integration is compared.
  Image<S, Host> depth;
  for (const auto& pose : poses) {
    sim::render_depth(scene, camera, pose, depth);
    // The refined update runs every kernel of integration.
    const auto params = IntegrationParams<S>::refined();
    integrate(cpu, depth, camera, pose, static_cast<const Image<S, Host>*>(nullptr), params);
    integrate(gpu, depth.to<Cuda>(), camera, pose, static_cast<const Image<S, Cuda>*>(nullptr), params);
  }
  const auto a = cpu.sdf_to_host(), b = gpu.sdf_to_host();
  const auto wa = cpu.weight_to_host(), wb = gpu.weight_to_host();
  double max_sdf = 0;
  std::size_t observed = 0, differing = 0, weight_mismatch = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    observed += wa[i] > 0;
    weight_mismatch += (wa[i] > 0) != (wb[i] > 0);
    const double d = std::fabs(double(a[i]) - double(b[i]));
    max_sdf = std::max(max_sdf, d);
    differing += d > 1e-5;
  }
  INFO("observed " << observed << ", observed-set mismatches " << weight_mismatch << ", voxels differing by > 1e-5 m "
                   << differing << ", max |sdf_cpu - sdf_gpu| = " << max_sdf << " m");
  // nvcc contracts to FMA where g++ does not, so a voxel whose projection lies
  // within rounding of a pixel boundary may read a neighbouring pixel. Such
  // voxels must stay rare; everything else agrees to float rounding.
  CHECK(observed > 10000);
  CHECK(double(weight_mismatch) < 1e-3 * double(observed));
  CHECK(double(differing) < 1e-3 * double(observed));
}
#endif

TEMPLATE_LIST_TEST_CASE("Marching cubes of a fused sphere has the sphere's area and volume", "[volume]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const double r = 0.25;
  sim::Scene<S> scene;
  scene.add(sim::make_sphere(Vec3<S>::zero(), S(r)));
  TsdfVolume<S, B> volume(test::cube_around<S>(Vec3<S>::zero(), 64, S(0.01)));
  test::fuse_views(volume, scene, test::small_camera<S>(), test::orbit_poses<S>(Vec3<S>::zero(), S(1.2), 24));
  const auto mesh = marching_cubes(volume);
  const double area = surface_area(mesh), enclosed = enclosed_volume(mesh);
  const double true_area = 4 * M_PI * r * r, true_volume = 4.0 / 3.0 * M_PI * r * r * r;
  INFO("area " << area << " (analytic " << true_area << "), volume " << enclosed << " (analytic " << true_volume
               << ")");
  CHECK(std::fabs(area - true_area) < 0.03 * true_area);
  CHECK(std::fabs(enclosed - true_volume) < 0.03 * true_volume);
}

TEMPLATE_LIST_TEST_CASE("Sampling over the observed voxels renormalises and needs half the weight", "[volume]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  const S vs = S(0.01);
  // A 4^3 grid whose SDF is 0.5 x (volume frame), every voxel observed.
  std::vector<S> sdf(64), weight(64, S(1));
  for (int z = 0; z < 4; ++z)
    for (int y = 0; y < 4; ++y)
      for (int x = 0; x < 4; ++x) sdf[std::size_t((z * 4 + y) * 4 + x)] = S(0.5) * (S(x) + S(0.5)) * vs;
  const TsdfView<S, const S> view{sdf.data(), weight.data(), 4, 4, 4, vs, S(10) * vs};
  const Vec3<S> p = Vec3<S>::constant(S(2) * vs);  // the centre of the middle cell: equal corner weights
  S strict = 0, observed = 0;
  REQUIRE(view.sample(p, strict));
  REQUIRE(view.sample_observed(p, observed));
  CHECK(double(observed) == emfusion::test::Approx(double(strict)).epsilon(1e-6));
  Vec3<S> g;
  REQUIRE(view.observed_gradient(p, g));
  CHECK(double(g.x()) == emfusion::test::Approx(0.5).epsilon(1e-4));
  CHECK(std::fabs(double(g.y())) < 1e-5);

  // One corner of the cell unobserved: the strict sample fails, the other
  // seven are averaged with their weights renormalised.
  weight[std::size_t((2 * 4 + 2) * 4 + 2)] = S(0);
  REQUIRE_FALSE(view.sample(p, strict));
  REQUIRE(view.sample_observed(p, observed));
  double expected = 0;
  for (int k = 0; k < 8; ++k)
    if (k != 7) expected += double(sdf[std::size_t(((1 + (k >> 2)) * 4 + 1 + ((k >> 1) & 1)) * 4 + 1 + (k & 1))]);
  CHECK(double(observed) == emfusion::test::Approx(expected / 7).epsilon(1e-5));
  // The gradient still comes out (one-sided where needed) and along x.
  REQUIRE(view.observed_gradient(p, g));
  CHECK(double(g.x()) > 0.3);

  // Five of the eight unobserved: less than half the weight, no sample.
  for (int k : {0, 1, 2, 3})
    weight[std::size_t(((1 + (k >> 2)) * 4 + 1 + ((k >> 1) & 1)) * 4 + 1 + (k & 1))] = S(0);
  CHECK_FALSE(view.sample_observed(p, observed));
}
