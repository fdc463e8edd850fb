// SDF alignment (eq. 8/9) and the likelihood (eq. 5, 7) over a sparse volume:
// the terms and normal equations equal the dense volume's where the voxels
// agree, a known camera motion is recovered as accurately as in the dense
// volume, coarse to fine and the start test work over it, and the E-step
// with a sparse background gives the dense background's associations.
#include <cmath>
#include <cstdint>
#include <random>
#include <span>
#include <type_traits>
#include <vector>

#include "emfusion/likelihood/e_step.hpp"
#include "emfusion/solve/photometric.hpp"
#include "emfusion/solve/sdf_alignment.hpp"
#include "emfusion/volume/sparse_tsdf_volume.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"
#include "support/room.hpp"

using namespace emfusion;
using emfusion::test::Approx;

// One set of functions for both volumes; the dense types are those they were.
static_assert(std::is_same_v<sdf_alignment_terms_t<float, TsdfVolume<float, Host>>, SdfAlignmentTerms<float>>);
static_assert(std::is_same_v<sdf_alignment_terms_t<float, SparseTsdfVolume<float, Host>>,
                             SdfAlignmentTerms<float, SparseTsdfView<float, const float>>>);
static_assert(std::is_same_v<SdfAlignmentTerms<double>::View, TsdfView<double, const double>>);
static_assert(std::is_same_v<PaperLikelihood<float>::View, TsdfView<float, const float>>);
static_assert(VolumeLikelihood<PaperLikelihood<float, SparseTsdfView<float, const float>>, float,
                               SparseTsdfView<float, const float>>);
static_assert(std::is_same_v<with_volume_t<PaperLikelihood<double>, SparseTsdfView<double, const double>>,
                             PaperLikelihood<double, SparseTsdfView<double, const double>>>);
static_assert(std::is_same_v<with_volume_t<PaperLikelihood<double, SparseTsdfView<double, const double>>,
                                           TsdfView<double, const double>>,
                             PaperLikelihood<double>>);

namespace {

struct PoseError {
  double translation;  // metres
  double rotation;     // degrees
};
template <class S>
PoseError pose_error(const SE3<S>& a, const SE3<S>& b) {
  const auto d = (a.inverse() * b).template cast<double>();
  return {norm(d.translation()), norm(so3_log(d.rotation())) * 180.0 / M_PI};
}

/// Four of the test room's views (the identity and three around it),
/// rendered once for every volume of a case.
template <class S, class B>
struct RoomFrames {
  PinholeCamera<S> camera = test::room_camera<S>();
  std::vector<SE3<S>> poses;
  std::vector<Image<S, B>> depth;
  RoomFrames() {
    const auto views = test::room_views<S>();
    for (std::size_t k : {0, 1, 4, 6}) poses.push_back(views[k]);
    depth.resize(poses.size());
    for (std::size_t k = 0; k < poses.size(); ++k)
      sim::render_depth(test::room_scene<S>(), camera, poses[k], depth[k], static_cast<Image<int, B>*>(nullptr));
  }
  /// Fuses every frame into `volume` (dense or sparse), refined update.
  template <class Volume>
  void fuse(Volume& volume) const {
    for (std::size_t k = 0; k < poses.size(); ++k)
      integrate(volume, depth[k], camera, poses[k], static_cast<const Image<S, B>*>(nullptr),
                IntegrationParams<S>::refined());
  }
};

/// The room in 128^3 voxels of 2 cm (test::fused_room's grid).
template <class S, class B>
TsdfVolume<S, B> dense_room(const RoomFrames<S, B>& frames) {
  VolumeGeometry<S> g;
  g.dims = Vec3i{{128, 128, 128}};
  g.voxel_size = S(0.02);
  g.T_world_volume = SE3<S>::translation(vec3(S(-1.28), S(-1.28), S(-0.2)));
  TsdfVolume<S, B> volume(g);
  frames.fuse(volume);
  return volume;
}

/// A sparse volume in the dense room's frame whose blocks are exactly the
/// dense grid's: all 16^3 allocated before the first frame, in a table of
/// that capacity, so that integration adds none (it refuses them) and every
/// voxel sees the dense voxel's updates.
template <class S, class B>
SparseTsdfVolume<S, B> same_voxels(const TsdfVolume<S, B>& dense, const RoomFrames<S, B>& frames) {
  SparseTsdfVolume<S, B> sparse(dense.voxel_size(), dense.truncation(), dense.pose(), 16 * 16 * 16);
  std::vector<detail::sparse::Key> keys;
  for (int z = 0; z < 16; ++z)
    for (int y = 0; y < 16; ++y)
      for (int x = 0; x < 16; ++x) keys.push_back(detail::sparse::pack_key(x, y, z));
  typename B::template Vector<detail::sparse::Key> on_backend(keys.begin(), keys.end());
  sparse.allocate_keys(on_backend, keys.size());
  frames.fuse(sparse);
  return sparse;
}

/// Largest |SDF| and |weight| difference over the dense grid's voxels.
template <class S, class B>
std::pair<double, double> voxel_difference(const TsdfVolume<S, B>& dense, const SparseTsdfVolume<S, B>& sparse) {
  const auto dh = dense.template to<Host>();
  const auto sh = sparse.template to<Host>();
  const auto dv = dh.view();
  const auto sv = sh.view();
  double sdf = 0, weight = 0;
  for (int z = 0; z < dv.nz; ++z)
    for (int y = 0; y < dv.ny; ++y)
      for (int x = 0; x < dv.nx; ++x) {
        S s, w;
        if (!sv.voxel(x, y, z, s, w)) return {1e9, 1e9};
        const auto i = dv.index(x, y, z);
        sdf = std::max(sdf, std::fabs(double(s - S(dv.sdf[i]))));
        weight = std::max(weight, std::fabs(double(w - S(dv.weight[i]))));
      }
  return {sdf, weight};
}

/// An association image with values in (0, 1] and zeros, like an E-step's.
template <class S, class B>
Image<S, B> association_pattern(int w, int h) {
  std::vector<S> q(std::size_t(w) * std::size_t(h));
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u)
      q[std::size_t(v) * w + u] = (u / 8 + v / 8) % 5 == 0 ? S(0) : S(0.3) + S((u * 7 + v * 3) % 10) / S(14);
  return Image<S, B>::from_host(w, h, q);
}

/// Checks that two normal equations are equal to `tolerance` relative to
/// the largest entry of their kind.
void check_same(const NormalEquations6& a, const NormalEquations6& b, double tolerance) {
  CHECK(a.terms == b.terms);
  CHECK(a.cost == Approx(b.cost).epsilon(tolerance));
  double h = 0, g = 0;
  for (double v : a.H) h = std::max(h, std::fabs(v));
  for (double v : a.g) g = std::max(g, std::fabs(v));
  for (int i = 0; i < 21; ++i) CHECK(std::fabs(a.H[i] - b.H[i]) <= tolerance * h);
  for (int i = 0; i < 6; ++i) CHECK(std::fabs(a.g[i] - b.g[i]) <= tolerance * g);
  CHECK(a.shared_cost == Approx(b.shared_cost).epsilon(tolerance));
  CHECK(a.shared_reference_cost == Approx(b.shared_reference_cost).epsilon(tolerance));
}

/// Sets every foreground count of an object to fg / bg.
template <class S>
struct FillCountsOf {
  ForegroundView<S, float> counts;
  float fg, bg;
  EMF_HD void operator()(std::int64_t i) const { counts.fg[i] = fg, counts.bg[i] = bg; }
};

}  // namespace

TEMPLATE_LIST_TEST_CASE("Sparse volume where the voxels agree with the dense one: the same terms, the same E-step",
                        "[solve][likelihood][sparse]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const RoomFrames<S, B> frames;
  const auto dense = dense_room(frames);
  const auto sparse = same_voxels(dense, frames);
  const auto [sdf_difference, weight_difference] = voxel_difference(dense, sparse);
  INFO("voxels: largest SDF difference " << sdf_difference << ", weight " << weight_difference);
  REQUIRE(sparse.allocated_blocks() == 16 * 16 * 16);
  REQUIRE(sdf_difference <= (sizeof(S) <= 4 ? 1e-6 : 1e-12));
  REQUIRE(weight_difference == 0);
  const double tolerance = sizeof(S) <= 4 ? 1e-5 : 1e-10;

  // SDF alignment: the normal equations of every weighting and gradient, at
  // the true pose and 3 cm off it (with the truth as the reference pose).
  const auto& camera = frames.camera;
  const SE3<S> truth = SE3<S>::exp(Vec6<S>{{S(0.03), S(-0.02), S(0.04), S(0.02), S(-0.03), S(0.01)}});
  const auto points = test::room_points<S, B>(truth);
  const Image<S, B> q = association_pattern<S, Host>(camera.width, camera.height).template to<B>();
  const HuberNorm<S> huber{S(0.04)};
  const SE3<S> T_volume_world = dense.pose().inverse();
  const SE3<S> near = SE3<S>::exp(Vec6<S>{{S(0.02), S(0.01), S(-0.02), S(0.02), S(-0.01), S(0.015)}}) * truth;
  for (const bool central : {false, true})
    for (const bool weighted : {false, true}) {
      SdfAlignmentParams<S> params;
      params.central_gradient = central;
      params.depth_noise_reference = weighted ? S(1.5) : S(0);
      const Image<S, B>* association = weighted ? &q : nullptr;
      const auto dense_terms = make_sdf_alignment(dense, points, association, params);
      const auto sparse_terms = make_sdf_alignment(sparse, points, association, params);
      static_assert(std::is_same_v<typename decltype(sparse_terms)::View, SparseTsdfView<S, const S>>);
      for (const bool at_truth : {true, false}) {
        INFO((central ? "central" : "exact") << " gradient" << (weighted ? ", association and depth weights" : "")
                                             << (at_truth ? ", at the truth" : ", 3 cm off"));
        const SE3<S> T = T_volume_world * (at_truth ? truth : near), reference = T_volume_world * truth;
        const NormalEquations6 a = linearize(dense.backend(), dense_terms, huber, T, &reference);
        const NormalEquations6 b = linearize(sparse.backend(), sparse_terms, huber, T, &reference);
        REQUIRE(a.terms > 0.5 * camera.width * camera.height * (weighted ? 0.6 : 1.0));
        check_same(a, b, tolerance);
      }
    }

  // The E-step. An object: the room's sphere in a dense volume with
  // foreground counts of 3 to 1 (p_fg = 3/4).
  TsdfVolume<S, B> object(test::cube_around(vec3(S(0.35), S(0.3), S(1.4)), 40, S(0.02)));
  frames.fuse(object);
  ForegroundCounts<S, B> counts(object.dims(), object.voxel_size());
  for_each_index(B{}, object.voxel_count(), FillCountsOf<S>{counts.view(), 3.0f, 1.0f});
  const SE3<S> camera_pose = SE3<S>::exp(Vec6<S>{{S(0.02), S(-0.01), S(0.03), S(0.01), S(-0.02), S(0.01)}});
  const auto seen = test::room_points<S, B>(camera_pose);
  using Dense = PaperLikelihood<S>;
  using Sparse = PaperLikelihood<S, SparseTsdfView<S, const S>>;
  static_assert(std::is_same_v<with_volume_t<Dense, SparseTsdfView<S, const S>>, Sparse>);
  Dense prototype;
  prototype.params.sigma = S(0.03);
  Sparse sparse_prototype;  // the same parameters over a sparse view
  sparse_prototype.params = prototype.params;
  const Dense background_dense = bind_volume<S>(prototype, dense.view());
  const Sparse background_sparse = bind_volume<S>(sparse_prototype, sparse.view());
  CHECK(background_sparse.foreground.empty());  // p_fg = 1 for the background, as for the dense one
  const Dense object_model = bind_volume<S>(prototype, object.view(), counts.view());
  const SE3<S> T_background_camera = dense.pose().inverse() * camera_pose;
  const SE3<S> T_object_camera = object.pose().inverse() * camera_pose;

  // The dense system's E-step, all models of one type...
  const std::vector<Dense> all{background_dense, object_model};
  const std::vector<SE3<S>> all_poses{T_background_camera, T_object_camera};
  Associations<S, B> reference;
  e_step(B{}, seen, std::span<const Dense>(all), std::span<const SE3<S>>(all_poses), reference);
  // ... the background apart (dense: exactly the same numbers) ...
  const std::vector<Dense> objects{object_model};
  const std::vector<SE3<S>> object_poses{T_object_camera};
  Associations<S, B> apart, with_sparse;
  e_step(B{}, seen, background_dense, T_background_camera, std::span<const Dense>(objects),
         std::span<const SE3<S>>(object_poses), apart);
  // ... and the sparse background.
  e_step(B{}, seen, background_sparse, T_background_camera, std::span<const Dense>(objects),
         std::span<const SE3<S>>(object_poses), with_sparse);
  REQUIRE(with_sparse.model_count() == 2);
  REQUIRE(apart.model_count() == 2);

  const auto p = seen.to_host();
  const auto dense_host = dense.template to<Host>();
  const auto dv = dense_host.view();
  int inside = 0, shared = 0;
  double worst = 0;
  for (int k = 0; k < 2; ++k) {
    const auto r = reference.image(k).to_host(), a = apart.image(k).to_host(), e = with_sparse.image(k).to_host();
    for (std::size_t i = 0; i < r.size(); ++i) {
      CHECK(a[i] == r[i]);
      if (!std::isfinite(double(p[i].z()))) {
        CHECK(e[i] == S(0));
        continue;
      }
      // Outside the dense grid the dense background says nothing (0), the
      // sparse one (no border) that nothing was observed there: compare
      // inside (here every point is).
      if (!dv.contains_point(T_background_camera * p[i])) continue;
      inside += k == 0;
      shared += k == 1 && r[i] > S(0.3);
      worst = std::max(worst, std::fabs(double(e[i] - r[i])));
    }
  }
  INFO("pixels inside the dense grid " << inside << ", shared with the object " << shared
                                       << "; largest association difference " << worst);
  CHECK(inside > 15000);
  CHECK(shared > 500);
  CHECK(worst <= tolerance);

  // Point by point, the background models agree, with p_fg = 1.
  const auto sparse_host = sparse.template to<Host>();
  const Dense dense_model = bind_volume<S>(prototype, dv);
  const Sparse sparse_model = bind_volume<S>(sparse_prototype, sparse_host.view());
  int compared = 0;
  for (std::size_t i = 0; i < p.size(); i += 7) {
    if (!std::isfinite(double(p[i].z()))) continue;
    const Vec3<S> x = T_background_camera * p[i];
    S sdf;
    const S expected = prototype.params.mixture(dv.sample(x, sdf) ? sdf : dv.truncation, S(1));
    CHECK(double(sparse_model.likelihood(x)) == Approx(double(expected)).epsilon(tolerance));
    CHECK(double(dense_model.likelihood(x)) == Approx(double(expected)).epsilon(tolerance));
    ++compared;
  }
  CHECK(compared > 1000);
  // Far outside any block: never observed, the outlier level (not 0 as
  // outside a dense grid).
  CHECK(double(sparse_model.likelihood(vec3(S(40), S(-30), S(25)))) ==
        Approx(double(prototype.params.mixture(sparse.truncation(), S(1)))));
  CHECK(dense_model.likelihood(vec3(S(40), S(-30), S(25))) == S(0));
}

TEMPLATE_LIST_TEST_CASE("Sparse map: a known camera motion recovered as accurately as dense, also coarse to fine",
                        "[solve][sparse]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // The sparse map as a mapping loop makes it: blocks allocated as the
  // frames come.
  const RoomFrames<S, B> frames;
  const auto dense = dense_room(frames);
  SparseTsdfVolume<S, B> sparse(dense.voxel_size(), S(0), dense.pose(), 1 << 14);
  frames.fuse(sparse);
  const SE3<S> truth = SE3<S>::exp(Vec6<S>{{S(-0.02), S(0.01), S(0.03), S(-0.01), S(0.02), S(0.01)}});
  const auto points = test::room_points<S, B>(truth);
  const HuberNorm<S> huber{S(2) * dense.voxel_size()};
  const auto* none = static_cast<const Image<S, B>*>(nullptr);
  const S deg = S(M_PI / 180);
  const SE3<S> start = SE3<S>::exp(Vec6<S>{{S(0.04), S(-0.03), S(0.03), S(3) * deg, S(-3) * deg, S(2) * deg}}) * truth;
  LevenbergMarquardtParams lm;
  lm.tau = 1e-3;
  SdfAlignmentParams<S> one, three;
  three.pyramid_levels = 3;

  SolveReport rd, rs, r3;
  const SE3<S> found_dense = align_to_volume(dense, points, none, start, huber, one, lm, &rd);
  const SE3<S> found_sparse = align_to_volume(sparse, points, none, start, huber, one, lm, &rs);
  const SE3<S> pyramid = align_to_volume(sparse, points, none, start, huber, three, lm, &r3);
  const PoseError ed = pose_error(found_dense, truth), es = pose_error(found_sparse, truth);
  const PoseError ep = pose_error(pyramid, truth);
  INFO("dense " << ed.translation * 1000 << " mm, " << ed.rotation << " deg, " << rd.iterations
                << " iterations; sparse " << es.translation * 1000 << " mm, " << es.rotation << " deg, "
                << rs.iterations << " iterations; sparse on three levels " << ep.translation * 1000 << " mm, "
                << ep.rotation << " deg, " << r3.iterations << " iterations");
  CHECK(rd.converged());
  CHECK(rs.converged());
  CHECK(es.translation < 1e-3);
  CHECK(es.rotation < 0.1);
  CHECK(es.translation <= ed.translation + 3e-4);
  CHECK(es.rotation <= ed.rotation + 0.03);
  CHECK(r3.converged());
  CHECK(ep.translation < 1e-3);
  CHECK(ep.rotation < 0.1);
  CHECK(pose_error(pyramid, found_sparse).translation < 5e-4);
  CHECK(r3.terms > 0.5 * rs.terms);

  // The other entry points over the same sparse map: a solver of one's own
  // in the volume's frame, and the photometric form with weight 0 (the SDF
  // term alone, linearised without the per-term cache: the same steps).
  const SE3<S> in_volume =
      sparse.pose() * align_in_volume(sparse, points, none, sparse.pose().inverse() * start, huber, one, GaussNewton{});
  CHECK(pose_error(in_volume, truth).translation < 1e-3);
  const SE3<S> with_intensity =
      align_to_volume_and_intensity(sparse, points, none, start, huber, one, PhotometricTerms<S>{},
                                    HuberNorm<S>{S(0.05)}, S(0), LevenbergMarquardt{lm});
  CHECK(pose_error(with_intensity, found_sparse).translation < 1e-6);

  // The start test and solve_coarse_to_fine on the sparse terms.
  SdfAlignmentParams<S> two;
  two.pyramid_levels = 2;
  const auto terms = sdf_alignment_in_box(sparse, points, none, two, sparse.backend());
  const SE3<S> T_true = sparse.pose().inverse() * truth;
  const SE3<S> off = SE3<S>::exp(Vec6<S>{{S(0.04), S(0), S(-0.03), S(0), S(0.03), S(0)}}) * T_true;
  CHECK(agrees_at_least_as_well(sparse.backend(), terms, huber, two, T_true, off));
  CHECK_FALSE(agrees_at_least_as_well(sparse.backend(), terms, huber, two, off, T_true));
  CHECK(at_level(terms, two, 1).stride == 2);
  LinearizationCache<S, B> cache;
  SolveReport r2;
  const SE3<S> T = solve_coarse_to_fine(sparse.backend(), terms, huber, two, LevenbergMarquardt{lm}, off, &r2, cache);
  CHECK(r2.converged());
  CHECK(pose_error(sparse.pose() * T, truth).translation < 1e-3);

  // The terms sample through nearby_sampler, which remembers the blocks it
  // found: bit for bit the view's own samples, also across block borders;
  // so do ray casts, through its observed samples, with one block remembered
  // on a GPU.
  {
    const auto host = sparse.template to<Host>();
    const auto view = host.view();
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> jitter(-0.05, 0.05);
    const auto pts = points.to_host();
    int sampled = 0, crossing = 0, differing = 0;
    for (std::size_t i = 0; i < pts.size(); i += 3) {
      if (!std::isfinite(double(pts[i].z()))) continue;
      const Vec3<S> x = T_true * pts[i] + vec3(S(jitter(rng)), S(jitter(rng)), S(jitter(rng)));
      auto near = nearby_sampler(view);
      S r0 = 0, r1 = 0, w0 = 0, w1 = 0;
      Vec3<S> g0 = Vec3<S>::zero(), g1 = Vec3<S>::zero(), c0 = Vec3<S>::zero(), c1 = Vec3<S>::zero();
      const bool a = view.sample_with_gradient(x, r0, g0, &w0), b = near.sample_with_gradient(x, r1, g1, &w1);
      const bool ca = a && view.central_gradient(x, c0), cb = b && near.central_gradient(x, c1);
      const auto same = [](const Vec3<S>& u, const Vec3<S>& v) {
        return u.x() == v.x() && u.y() == v.y() && u.z() == v.z();
      };
      differing += a != b || ca != cb || r0 != r1 || w0 != w1 || !same(g0, g1) || !same(c0, c1);
      auto one = nearby_sampler<1>(view);
      S o0 = 0, o1 = 0, o2 = 0;
      Vec3<S> n0 = Vec3<S>::zero(), n1 = Vec3<S>::zero(), n2 = Vec3<S>::zero();
      const bool oa = view.sample_observed(x, o0), ob = near.sample_observed(x, o1), oc = one.sample_observed(x, o2);
      const bool na = view.observed_gradient(x, n0), nb = near.observed_gradient(x, n1),
                 nc = one.observed_gradient(x, n2);
      differing += oa != ob || oa != oc || o0 != o1 || o0 != o2;
      differing += na != nb || na != nc || !same(n0, n1) || !same(n0, n2);
      sampled += a;
      const int cx = int(std::floor(x.x() / view.voxel_size - S(0.5)));
      crossing += a && (cx & 7) == 7;
    }
    INFO("sampled " << sampled << " (" << crossing << " across a block border in x), differing " << differing);
    CHECK(sampled > 2000);
    CHECK(crossing > 100);
    CHECK(differing == 0);
  }

  // An association positive only in a rectangle: the boxed terms are those
  // of the whole image with q > 0.
  const auto& camera = frames.camera;
  std::vector<S> qh(std::size_t(camera.width) * camera.height, S(0));
  for (int v = 30; v < 90; ++v)
    for (int u = 40; u < 120; ++u) qh[std::size_t(v) * camera.width + u] = S(0.5) + S((u + v) % 5) / S(10);
  const Image<S, B> q = Image<S, B>::from_host(camera.width, camera.height, qh);
  const auto whole = make_sdf_alignment(sparse, points, &q, one);
  const auto boxed = sdf_alignment_in_box(sparse, points, &q, one, sparse.backend());
  CHECK(boxed.term_count() < whole.term_count() / 2);
  const NormalEquations6 a = linearize(sparse.backend(), whole, huber, T_true);
  const NormalEquations6 b = linearize(sparse.backend(), boxed, huber, T_true);
  REQUIRE(a.terms > 1000);
  check_same(a, b, 1e-9);
}
