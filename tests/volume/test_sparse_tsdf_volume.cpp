// The sparse voxel-block TSDF volume: agreement with the dense volume on the
// same frames (values, gradients, voxel by voxel), memory against the dense
// cube, a scene far from the origin, lookups through the index grid against
// the hash table, a full table, hash collisions, parallel allocation against
// a serial reference, unallocated space, bad parameters.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <limits>
#include <random>
#include <set>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "emfusion/core/half.hpp"
#include "emfusion/volume/integrate.hpp"
#include "emfusion/volume/nearby_samples.hpp"
#include "emfusion/volume/raycast.hpp"
#include "emfusion/volume/sparse_tsdf_volume.hpp"
#include "emfusion/volume/tsdf_volume.hpp"
#include "emfusion/volume/volume_view.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"
#include "support/files.hpp"
#include "support/fusion.hpp"
#include "support/room.hpp"

using namespace emfusion;

// Both volumes, and their views, are what algorithms written once over the
// volume concept (volume/volume_view.hpp) take.
static_assert(TsdfSampler<TsdfView<float, const float>, float> && TsdfSampler<TsdfView<float, const Half>, float>);
static_assert(TsdfSampler<SparseTsdfView<float, const float>, float>);
static_assert(TsdfSampler<SparseTsdfView<double, const double>, double>);
static_assert(TsdfVolumeType<TsdfVolume<double, Host>, double> && TsdfVolumeType<SparseTsdfVolume<float, Host>, float>);
static_assert(!TsdfSampler<Vec3<float>, float>);

namespace {

using Key = detail::sparse::Key;
using emfusion::test::contains;
using emfusion::test::error_of;

template <class S>
double value_tolerance() {
  return sizeof(S) <= 4 ? 1e-5 : 1e-9;
}

template <class S, class B>
std::vector<Image<S, B>> render_frames(const sim::Scene<S>& scene, const PinholeCamera<S>& camera,
                                       const std::vector<SE3<S>>& poses, const B& backend = B{}) {
  std::vector<Image<S, B>> frames(poses.size());
  for (std::size_t k = 0; k < poses.size(); ++k)
    sim::render_depth(scene, camera, poses[k], frames[k], static_cast<Image<int, B>*>(nullptr), {}, backend);
  return frames;
}

/// A per-pixel weight image with values in [0.2, 1] and a few zeros, like the
/// association weights of an object.
template <class S, class B>
Image<S, B> weight_pattern(const PinholeCamera<S>& camera) {
  std::vector<S> w(std::size_t(camera.width) * std::size_t(camera.height));
  for (int v = 0; v < camera.height; ++v)
    for (int u = 0; u < camera.width; ++u)
      w[std::size_t(v) * camera.width + u] =
          (u / 10 + v / 10) % 7 == 0 ? S(0) : S(0.6) + S(0.4) * S(std::sin(0.1 * u + 0.07 * v));
  return Image<S, B>::from_host(camera.width, camera.height, w);
}

/// The blocks a serial loop over every pixel's band finds: the reference
/// for the parallel allocation.
template <class S, class B, class Store>
std::set<Key> serial_band_keys(const SparseTsdfVolume<S, B, Store>& volume, const Image<S, B>& depth,
                               const PinholeCamera<S>& camera, const SE3<S>& T_world_camera) {
  const Image<S, Host> host = depth.template to<Host>();
  const S block = volume.block_size();
  const int samples =
      std::clamp(int(std::ceil(S(4) * volume.truncation() / block)) + 1, 2, detail::sparse::max_band_samples);
  const detail::sparse::BandBlockKeys<S> f{host.view(),
                                           {},
                                           camera,
                                           volume.pose().inverse() * T_world_camera,
                                           volume.truncation(),
                                           block,
                                           samples,
                                           {nullptr, nullptr, 0, {}},
                                           nullptr,
                                           nullptr};
  std::set<Key> keys;
  Key own[detail::sparse::max_band_samples];
  for (int v = 0; v < camera.height; ++v)
    for (int u = 0; u < camera.width; ++u) {
      const int n = f.pixel_keys(u, v, own);
      keys.insert(own, own + n);
    }
  return keys;
}

/// The keys of the allocated blocks in storage order.
template <class S, class B, class Store>
std::vector<Key> block_list(const SparseTsdfVolume<S, B, Store>& volume) {
  std::vector<Key> keys;
  for (const Vec3i& c : volume.blocks_to_host()) keys.push_back(detail::sparse::pack_key(c[0], c[1], c[2]));
  return keys;
}

template <class S, class B, class Store>
std::set<Key> stored_keys(const SparseTsdfVolume<S, B, Store>& volume) {
  std::set<Key> keys;
  for (const Vec3i& c : volume.blocks_to_host()) keys.insert(detail::sparse::pack_key(c[0], c[1], c[2]));
  return keys;
}

/// Every stored block is found under its own key at its own index, in the
/// table and in the index grid (when the volume keeps one), and the grid
/// holds nothing else: the table, the grid and the block list agree.
template <class S, class Store>
bool map_is_consistent(const SparseTsdfVolume<S, Host, Store>& host) {
  const auto view = host.view();
  for (int b = 0; b < view.blocks; ++b) {
    const Vec3i c = view.block_coordinates(b);
    if (view.find_block(c[0], c[1], c[2]) != b) return false;
    const Key key = detail::sparse::pack_key(c[0], c[1], c[2]);
    if (detail::sparse::find_block(view.slot_keys, view.slot_blocks, view.slot_mask, key) != b) return false;
  }
  if (view.grid.cells) {
    const std::int64_t cells = std::int64_t(view.grid.size[0]) * view.grid.size[1] * view.grid.size[2];
    if (cells != host.index_grid_cells()) return false;
    if (std::count_if(view.grid.cells, view.grid.cells + cells, [](int b) { return b >= 0; }) != view.blocks)
      return false;
  }
  return true;
}

/// Volume-frame centre of voxel x.
template <class S>
Vec3<S> view_center(const Vec3i& x, S voxel) {
  return vec3((S(x[0]) + S(0.5)) * voxel, (S(x[1]) + S(0.5)) * voxel, (S(x[2]) + S(0.5)) * voxel);
}

struct Agreement {
  std::size_t compared = 0, gradients = 0, sparse_only = 0, dense_only_allocated = 0, observed_mismatch = 0;
  double max_value = 0, max_gradient = 0, max_observed = 0;
};

/// Samples both volumes at random points within `band` of the surface inside
/// the dense grid and compares where they both answer. A sparse sample must
/// not exist without the dense one, and a dense one only where the sparse
/// volume lacks a block.
template <class S, class StoreD, class StoreS>
Agreement compare_samples(const TsdfView<S, StoreD>& dense, const SparseTsdfView<S, StoreS>& sparse,
                          const sim::Scene<S>& scene, const SE3<S>& T_world_volume, S band, int points) {
  std::mt19937 rng(7);
  const Vec3<S> e = dense.extent();
  std::uniform_real_distribution<double> ux(0, double(e.x())), uy(0, double(e.y())), uz(0, double(e.z()));
  Agreement a;
  int tried = 0;
  while (tried < points) {
    const Vec3<S> p = vec3(S(ux(rng)), S(uy(rng)), S(uz(rng)));
    if (!(std::fabs(double(scene.distance(T_world_volume * p))) < double(band))) continue;
    // The eight voxels around p: inside the dense grid, and allocated?
    const int x = int(std::floor(p.x() / sparse.voxel_size - S(0.5)));
    const int y = int(std::floor(p.y() / sparse.voxel_size - S(0.5)));
    const int z = int(std::floor(p.z() / sparse.voxel_size - S(0.5)));
    if (!dense.contains_voxel(x, y, z) || !dense.contains_voxel(x + 1, y + 1, z + 1)) continue;
    ++tried;
    bool all_allocated = true;
    for (int k = 0; k < 8; ++k)
      all_allocated = all_allocated && sparse.voxel_index(x + (k & 1), y + ((k >> 1) & 1), z + ((k >> 2) & 1)) >= 0;
    S vd = 0, vs = 0;
    Vec3<S> gd, gs;
    const bool hd = dense.sample_with_gradient(p, vd, gd), hs = sparse.sample_with_gradient(p, vs, gs);
    if (hs && !hd) ++a.sparse_only;
    if (hd && !hs && all_allocated) ++a.dense_only_allocated;
    if (hd && hs) {
      ++a.compared;
      a.max_value = std::max(a.max_value, std::fabs(double(vd - vs)));
      a.max_gradient = std::max(a.max_gradient, double(norm(gd - gs)));
      Vec3<S> cd, cs;
      if (dense.central_gradient(p, cd) && sparse.central_gradient(p, cs)) {
        ++a.gradients;
        a.max_gradient = std::max(a.max_gradient, double(norm(cd - cs)));
      }
    }
    // The renormalised samples agree where every voxel they may use is
    // allocated (elsewhere the dense volume has free-space voxels that the
    // sparse one never stored).
    if (!all_allocated) continue;
    S od = 0, os = 0;
    const bool has_od = dense.sample_observed(p, od), has_os = sparse.sample_observed(p, os);
    if (has_od != has_os) ++a.observed_mismatch;
    if (has_od && has_os) a.max_observed = std::max(a.max_observed, std::fabs(double(od - os)));
  }
  return a;
}

struct VoxelComparison {
  std::size_t voxels = 0, equal_weight = 0, heavier_sparse = 0;
  double max_difference = 0;  // SDF, where the weights are equal
};

/// Every voxel of the sparse volume's blocks that lies in the dense grid
/// against the dense voxel.
template <class S, class StoreD, class StoreS>
VoxelComparison compare_voxels(const TsdfVolume<S, Host, StoreD>& dense,
                               const SparseTsdfVolume<S, Host, StoreS>& sparse) {
  const auto dv = dense.view();
  const auto sv = sparse.view();
  VoxelComparison c;
  for (int b = 0; b < sv.blocks; ++b) {
    const Vec3i block = sv.block_coordinates(b);
    for (int lz = 0; lz < 8; ++lz)
      for (int ly = 0; ly < 8; ++ly)
        for (int lx = 0; lx < 8; ++lx) {
          const int x = block[0] * 8 + lx, y = block[1] * 8 + ly, z = block[2] * 8 + lz;
          if (!dv.contains_voxel(x, y, z)) continue;
          S sdf, weight;
          sv.voxel(x, y, z, sdf, weight);
          const auto i = dv.index(x, y, z);
          const S dense_weight = S(dv.weight[i]);
          ++c.voxels;
          if (weight > dense_weight + S(1e-6)) ++c.heavier_sparse;
          if (std::fabs(double(weight - dense_weight)) <= 1e-6) {
            ++c.equal_weight;
            c.max_difference = std::max(c.max_difference, std::fabs(double(sdf - S(dv.sdf[i]))));
          }
        }
  }
  return c;
}

}  // namespace

TEMPLATE_LIST_TEST_CASE("Sparse volume: once allocated, voxels evolve exactly as the dense volume's", "[volume]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const auto camera = test::small_camera<S>();
  const auto scene = test::sphere_and_box<S>();
  const auto poses = test::orbit_poses<S>(Vec3<S>::zero(), S(1.2), 12);
  const auto frames = render_frames<S, B>(scene, camera, poses);
  const Image<S, B> weights = weight_pattern<S, Host>(camera).template to<B>();

  for (const bool weighted : {false, true}) {
    INFO((weighted ? "the paper's update with a weight image" : "the refined update"));
    const IntegrationParams<S> params = weighted ? IntegrationParams<S>{} : IntegrationParams<S>::refined();
    const Image<S, B>* w = weighted ? &weights : nullptr;
    TsdfVolume<S, B> dense(test::cube_around<S>(Vec3<S>::zero(), 64, S(0.01)));
    SparseTsdfVolume<S, B> sparse(S(0.01), S(0), dense.pose(), 4096);
    REQUIRE(sparse.truncation() == dense.truncation());
    // Every block the frames will touch, allocated before the first update:
    // then every allocated voxel sees every update the dense voxel sees.
    for (std::size_t k = 0; k < poses.size(); ++k) allocate_blocks(sparse, frames[k], camera, poses[k], w);
    const int preallocated = sparse.allocated_blocks();
    for (std::size_t k = 0; k < poses.size(); ++k) {
      integrate(dense, frames[k], camera, poses[k], w, params);
      const SparseIntegration r = integrate(sparse, frames[k], camera, poses[k], w, params);
      CHECK(r.allocation.inserted == 0);
      CHECK(r.allocation.refused == 0);
      CHECK(r.blocks_in_view > 0);
    }
    CHECK(sparse.allocated_blocks() == preallocated);

    const auto dense_host = dense.template to<Host>();
    const auto sparse_host = sparse.template to<Host>();
    REQUIRE(map_is_consistent(sparse_host));
    const VoxelComparison v = compare_voxels(dense_host, sparse_host);
    INFO("voxels compared " << v.voxels << ", equal weight " << v.equal_weight << ", max |sdf difference| "
                            << v.max_difference);
    CHECK(v.voxels > 100000);
    CHECK(v.equal_weight == v.voxels);
    CHECK(v.max_difference <= value_tolerance<S>());

    const Agreement a =
        compare_samples(dense_host.view(), sparse_host.view(), scene, dense.pose(), dense.truncation(), 20000);
    INFO("samples compared " << a.compared << ", max |value difference| " << a.max_value
                             << ", max |gradient difference| " << a.max_gradient << ", observed " << a.max_observed
                             << ", dense only (all blocks allocated) " << a.dense_only_allocated);
    CHECK(a.compared > 10000);
    CHECK(a.gradients > 5000);
    CHECK(a.sparse_only == 0);
    CHECK(a.dense_only_allocated == 0);
    CHECK(a.max_value <= value_tolerance<S>());
    CHECK(a.max_gradient <= 100 * value_tolerance<S>());  // differences over a voxel of 1 cm
    CHECK(a.observed_mismatch == 0);
    CHECK(a.max_observed <= value_tolerance<S>());
  }
}

TEMPLATE_LIST_TEST_CASE("Sparse volume fused frame by frame: a subset of the dense updates, accurate near surfaces",
                        "[volume]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const auto camera = test::small_camera<S>();
  const auto scene = test::sphere_and_box<S>();
  const auto poses = test::orbit_poses<S>(Vec3<S>::zero(), S(1.2), 24);
  const auto frames = render_frames<S, B>(scene, camera, poses);
  for (const bool refined : {false, true}) {
    TsdfVolume<S, B> dense(test::cube_around<S>(Vec3<S>::zero(), 64, S(0.01)));
    SparseTsdfVolume<S, B> sparse(S(0.01), S(0), dense.pose(), 4096);
    const IntegrationParams<S> params = refined ? IntegrationParams<S>::refined() : IntegrationParams<S>{};
    for (std::size_t k = 0; k < poses.size(); ++k) {
      integrate(dense, frames[k], camera, poses[k], static_cast<const Image<S, B>*>(nullptr), params);
      integrate(sparse, frames[k], camera, poses[k], static_cast<const Image<S, B>*>(nullptr), params);
    }
    const auto dense_host = dense.template to<Host>();
    const auto sparse_host = sparse.template to<Host>();
    if (!refined) {
      // The paper's update with weight 1: a voxel's weight counts its
      // updates. A sparse voxel misses the updates from before its block was
      // allocated (free space seen from far away) and no other: never
      // heavier than the dense voxel, and equal to it wherever it saw as
      // many updates.
      const VoxelComparison v = compare_voxels(dense_host, sparse_host);
      INFO("voxels " << v.voxels << ", equal weight " << v.equal_weight << ", max |sdf difference| there "
                     << v.max_difference);
      CHECK(v.heavier_sparse == 0);
      CHECK(v.equal_weight > v.voxels / 2);
      CHECK(v.max_difference <= value_tolerance<S>());
      continue;
    }
    // The refined update: as close to the analytic SDF near the surface as
    // the dense volume (within a voxel but at the box's contact with the
    // sphere, where the dense volume is off by up to about 3 voxels too).
    const auto band_errors = [&](const auto& read, const std::vector<Vec3i>& voxels) {
      std::vector<double> errors;
      for (const Vec3i& x : voxels) {
        const double truth = double(scene.distance(dense.pose() * view_center<S>(x, S(0.01))));
        S sdf, weight;
        if (std::fabs(truth) >= 0.01 || !read(x, sdf, weight) || !(weight > S(0))) continue;
        errors.push_back(std::fabs(double(sdf) - truth));
      }
      std::sort(errors.begin(), errors.end());
      return errors;
    };
    std::vector<Vec3i> sparse_voxels, dense_voxels;
    for (const Vec3i& block : sparse_host.blocks_to_host())
      for (int k = 0; k < 512; ++k)
        sparse_voxels.push_back(Vec3i{{block[0] * 8 + k % 8, block[1] * 8 + (k / 8) % 8, block[2] * 8 + k / 64}});
    const auto dv = dense_host.view();
    for (int z = 0; z < dv.nz; ++z)
      for (int y = 0; y < dv.ny; ++y)
        for (int x = 0; x < dv.nx; ++x) dense_voxels.push_back(Vec3i{{x, y, z}});
    const auto sv = sparse_host.view();
    const auto s =
        band_errors([&](const Vec3i& x, S& sdf, S& w) { return sv.voxel(x[0], x[1], x[2], sdf, w); }, sparse_voxels);
    const auto d = band_errors(
        [&](const Vec3i& x, S& sdf, S& w) {
          const auto i = dv.index(x[0], x[1], x[2]);
          sdf = S(dv.sdf[i]), w = S(dv.weight[i]);
          return true;
        },
        dense_voxels);
    REQUIRE(!s.empty());
    REQUIRE(!d.empty());
    const auto percentile = [](const std::vector<double>& e, double q) {
      return e[std::size_t(q * double(e.size() - 1))];
    };
    INFO("near-surface voxels: sparse " << s.size() << ", dense " << d.size() << "; |fused - analytic| in voxels: "
                                        << "sparse median " << percentile(s, 0.5) / 0.01 << ", 98th percentile "
                                        << percentile(s, 0.98) / 0.01 << ", max " << s.back() / 0.01
                                        << "; dense median " << percentile(d, 0.5) / 0.01 << ", 98th percentile "
                                        << percentile(d, 0.98) / 0.01 << ", max " << d.back() / 0.01);
    CHECK(s.size() > 5000);
    CHECK(percentile(s, 0.98) < 0.01);
    CHECK(percentile(s, 0.5) <= percentile(d, 0.5) + 1e-4);
    CHECK(s.back() <= d.back() + 1e-4);
  }
}

TEMPLATE_LIST_TEST_CASE("Sparse volume of a room: a fraction of the dense cube's voxels", "[volume]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const auto camera = test::room_camera<S>();
  const auto poses = test::room_views<S>();
  const auto frames = render_frames<S, B>(test::room_scene<S>(), camera, poses);
  // The paper's background at 1 cm: 512^3 voxels, here the sparse volume in
  // the same frame (camera at the centre of one face).
  const SE3<S> pose = volume_pose_in_front_of(SE3<S>::identity(), S(5.12));
  SparseTsdfVolume<S, B> sparse(S(0.01), S(0), pose, 1 << 16);
  const std::size_t empty_bytes = sparse.memory_bytes();
  for (std::size_t k = 0; k < poses.size(); ++k) {
    const SparseIntegration r = integrate(sparse, frames[k], camera, poses[k]);
    CHECK(r.allocation.refused == 0);
    if (k == 0) CHECK(r.allocation.inserted > 0);
  }
  const double dense_voxels = 512.0 * 512.0 * 512.0;
  const double share = double(sparse.voxel_count()) / dense_voxels;
  INFO("allocated blocks " << sparse.allocated_blocks() << ", voxels " << sparse.voxel_count() << " = " << share
                           << " of 512^3; memory " << sparse.memory_bytes() << " bytes, bound "
                           << sparse.memory_bound_bytes());
  CHECK(share < 0.05);
  CHECK(sparse.memory_bytes() > empty_bytes);
  CHECK(sparse.memory_bytes() <= sparse.memory_bound_bytes());
  CHECK(sparse.memory_bytes() < std::size_t(0.1 * dense_voxels * 2 * sizeof(S)));
}

TEMPLATE_LIST_TEST_CASE("Sparse volume: a scene 10 m from the origin integrates and samples", "[volume]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // The sphere and box moved by a whole number of voxels, outside any 5 m
  // cube around the origin, and fused from the same relative views into a
  // sparse volume at the origin: it must hold what a dense volume around the
  // objects at the origin holds.
  const Vec3<S> offset = vec3(S(10), S(-4), S(6));
  const Vec3i voxel_offset{{1000, -400, 600}};
  const auto near_scene = test::sphere_and_box<S>();
  sim::Scene<S> far_scene;
  far_scene.add(sim::make_sphere(offset, S(0.25)));
  far_scene.add(sim::make_box(SE3<S>::translation(offset + vec3(S(0.3), S(0.1), S(0))), vec3(S(0.1), S(0.2), S(0.15))));
  const auto camera = test::small_camera<S>();
  const auto near_poses = test::orbit_poses<S>(Vec3<S>::zero(), S(1.2), 12);
  std::vector<SE3<S>> far_poses;
  for (const auto& pose : near_poses) far_poses.push_back(SE3<S>::translation(offset) * pose);
  const auto near_frames = render_frames<S, B>(near_scene, camera, near_poses);
  const auto far_frames = render_frames<S, B>(far_scene, camera, far_poses);

  TsdfVolume<S, B> dense(test::cube_around<S>(Vec3<S>::zero(), 64, S(0.01)));
  SparseTsdfVolume<S, B> sparse(S(0.01), S(0), SE3<S>::identity(), 8192);
  for (std::size_t k = 0; k < far_poses.size(); ++k) allocate_blocks(sparse, far_frames[k], camera, far_poses[k]);
  for (std::size_t k = 0; k < far_poses.size(); ++k) {
    integrate(dense, near_frames[k], camera, near_poses[k]);
    CHECK(integrate(sparse, far_frames[k], camera, far_poses[k]).allocation.refused == 0);
  }
  REQUIRE(sparse.allocated_blocks() > 0);
  for (const Vec3i& b : sparse.blocks_to_host()) CHECK(b[0] * 8 * 0.01 > 8.0);

  // Voxel by voxel: dense voxel (x, y, z) is sparse voxel (x, y, z) + the
  // offset of the dense grid's corner (-32 voxels) + the scene's offset.
  const auto dense_host = dense.template to<Host>();
  const auto sparse_host = sparse.template to<Host>();
  const auto dv = dense_host.view();
  const auto sv = sparse_host.view();
  // Voxel centres 10 m out carry float rounding of 1e-6 m: enough, now and
  // then, to move a voxel's projection to the next pixel. Double matches
  // everywhere, float all but a few voxels.
  const double tolerance = sizeof(S) <= 4 ? 1e-4 : 1e-9;
  const double allowed_share = sizeof(S) <= 4 ? 1e-3 : 0.0;
  std::size_t compared = 0, unequal_weight = 0, different = 0;
  for (int z = 0; z < dv.nz; ++z)
    for (int y = 0; y < dv.ny; ++y)
      for (int x = 0; x < dv.nx; ++x) {
        S sdf, weight;
        if (!sv.voxel(x - 32 + voxel_offset[0], y - 32 + voxel_offset[1], z - 32 + voxel_offset[2], sdf, weight))
          continue;
        const auto i = dv.index(x, y, z);
        if (!(S(dv.weight[i]) > S(0)) && !(weight > S(0))) continue;
        ++compared;
        if (std::fabs(double(weight - S(dv.weight[i]))) > 1e-6) ++unequal_weight;
        if (std::fabs(double(sdf - S(dv.sdf[i]))) > tolerance) ++different;
      }
  INFO("voxels compared " << compared << ", unequal weights " << unequal_weight << ", SDF differing by more than "
                          << tolerance << ": " << different);
  CHECK(compared > 50000);
  CHECK(double(unequal_weight) <= allowed_share * double(compared));
  CHECK(double(different) <= allowed_share * double(compared));

  // Sampling across block borders, against the dense volume at the origin.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> c(-0.3, 0.3);
  std::size_t sampled = 0, different_samples = 0;
  for (int tried = 0; tried < 20000; ++tried) {
    const Vec3<S> p = vec3(S(c(rng)), S(c(rng)), S(c(rng)));
    S a, b;
    Vec3<S> ga, gb;
    if (!dv.sample_with_gradient(p - dense.pose().translation(), a, ga) || !sv.sample_with_gradient(p + offset, b, gb))
      continue;
    ++sampled;
    if (std::fabs(double(a - b)) > tolerance || double(norm(ga - gb)) > 100 * tolerance) ++different_samples;
  }
  INFO("sampled " << sampled << ", differing from the dense volume at the origin: " << different_samples);
  CHECK(sampled > 5000);
  CHECK(double(different_samples) <= 10 * allowed_share * double(sampled));
  S unused;
  CHECK_FALSE(sv.sample(vec3(S(0), S(0), S(0)), unused));  // nothing was seen at the origin
}

TEMPLATE_LIST_TEST_CASE("Sparse volume: lookups through the index grid find what the hash table finds", "[volume]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // The same frames fused into three volumes: with the index grid (the
  // default), without (every lookup hashes), and with a budget that the
  // grid outgrows when the camera moves 3 m on, so that it is dropped. A
  // second scene there makes the blocks' box grow: the grid is built anew.
  const auto camera = test::small_camera<S>();
  const Vec3<S> far = vec3(S(3), S(0.5), S(-2));
  sim::Scene<S> scene = test::sphere_and_box<S>();
  scene.add(sim::make_sphere(far, S(0.3)));
  std::vector<SE3<S>> poses = test::orbit_poses<S>(Vec3<S>::zero(), S(1.2), 4);
  for (const SE3<S>& pose : test::orbit_poses<S>(far, S(1.0), 4)) poses.push_back(pose);
  const auto frames = render_frames<S, B>(scene, camera, poses);

  SparseVolumeParams<S> params{S(0.01), S(0), SE3<S>::identity(), 8192};
  SparseTsdfVolume<S, B> gridded(params);
  params.grid_cells_per_block = 0;
  SparseTsdfVolume<S, B> hashed(params);
  // 16384 cells: enough for the first scene's box (1859 cells with room to
  // grow on the CPU in float), not for both scenes'.
  params.grid_cells_per_block = 2;
  SparseTsdfVolume<S, B> outgrown(params);
  std::int64_t first_cells = 0;
  for (std::size_t k = 0; k < poses.size(); ++k) {
    for (auto* v : {&gridded, &hashed, &outgrown}) integrate(*v, frames[k], camera, poses[k]);
    if (k == 3) {
      first_cells = gridded.index_grid_cells();
      CHECK(outgrown.has_index_grid());
    }
  }
  CHECK(gridded.has_index_grid());
  CHECK_FALSE(hashed.has_index_grid());
  CHECK_FALSE(outgrown.has_index_grid());
  CHECK(outgrown.index_grid_cells() == 0);
  INFO("grid cells after the first scene " << first_cells << ", after both " << gridded.index_grid_cells());
  CHECK(first_cells > 0);
  CHECK(gridded.index_grid_cells() > first_cells);  // built anew over the grown box
  CHECK(gridded.memory_bytes() == hashed.memory_bytes() + std::size_t(gridded.index_grid_cells()) * sizeof(int));
  CHECK(gridded.memory_bound_bytes() == hashed.memory_bound_bytes() + 8192u * 16u * sizeof(int));

  // The same blocks in the same order, the same voxels, bit for bit.
  const auto g = gridded.template to<Host>(), h = hashed.template to<Host>(), o = outgrown.template to<Host>();
  REQUIRE(h.allocated_blocks() > 0);
  CHECK(block_list(g) == block_list(h));
  CHECK(block_list(o) == block_list(h));
  CHECK(g.sdf_to_host() == h.sdf_to_host());
  CHECK(g.weight_to_host() == h.weight_to_host());
  CHECK(map_is_consistent(g));
  CHECK(map_is_consistent(h));
  CHECK(g.has_index_grid());  // the host copy builds its own

  // with_nearby_sampler hands the grid's sampler where there is a grid,
  // else the caching one (or with no cache asked for, the view).
  const auto gv = g.view(), hv = h.view();
  const auto kind = [](const auto& sampler) {
    using T = std::decay_t<decltype(sampler)>;
    if constexpr (std::is_same_v<T, GriddedSparseSampler<S, const S>>) return 1;
    if constexpr (std::is_same_v<T, NearbySparseSampler<S, const S, 4>>) return 2;
    if constexpr (std::is_same_v<T, SparseTsdfView<S, const S>>) return 3;
    return 0;
  };
  CHECK(with_nearby_sampler(gv, kind) == 1);
  CHECK(with_nearby_sampler(hv, kind) == 2);
  CHECK(with_nearby_sampler<0>(hv, kind) == 3);

  // Samples, through the view and through the nearby sampler, bit for bit,
  // at random points around both scenes and beyond the blocks' box.
  auto gn = nearby_sampler(gv);
  auto hn = nearby_sampler(hv);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> c(-0.6, 0.6);
  std::size_t sampled = 0, differing = 0;
  for (int tried = 0; tried < 20000; ++tried) {
    const Vec3<S> centre = tried % 3 == 0 ? Vec3<S>::zero() : (tried % 3 == 1 ? far : vec3(S(-9), S(4), S(1)));
    const Vec3<S> p = centre + vec3(S(c(rng)), S(c(rng)), S(c(rng)));
    S a = 0, b = 0, an = 0, bn = 0, wa = 0, wb = 0;
    Vec3<S> ga{}, gb{};
    const bool sa = gv.sample_with_gradient(p, a, ga, &wa), sb = hv.sample_with_gradient(p, b, gb, &wb);
    const bool na = gn.sample_observed(p, an), nb = hn.sample_observed(p, bn);
    S ag = 0;
    if (GriddedSparseSampler<S, const S>(gv).sample_observed(p, ag) != nb || ag != bn) ++differing;
    if (sa) ++sampled;
    if (sa != sb || na != nb || a != b || wa != wb || !(squared_norm(ga - gb) == S(0)) || an != bn) ++differing;
  }
  INFO("sampled " << sampled << ", differing " << differing);
  CHECK(sampled > 1000);
  CHECK(differing == 0);

  // Ray casts skip unallocated blocks through either: the same depths.
  for (std::size_t k : {std::size_t(1), std::size_t(6)}) {
    RaycastResult<S, Host> rg, rh;
    raycast(g, camera, poses[k], rg);
    raycast(h, camera, poses[k], rh);
    CHECK(rg.depth.to_host() == rh.depth.to_host());
    const std::vector<std::uint8_t> hits = rg.hit.to_host();
    CHECK(std::count(hits.begin(), hits.end(), 1) > camera.width * camera.height / 10);
  }
}

TEMPLATE_LIST_TEST_CASE("Sparse volume: a full table refuses blocks, counts them and keeps the stored ones", "[volume]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const auto camera = test::small_camera<S>();
  const auto scene = test::sphere_and_box<S>();
  const auto poses = test::orbit_poses<S>(Vec3<S>::zero(), S(1.2), 12);
  const auto frames = render_frames<S, B>(scene, camera, poses);
  constexpr int capacity = 40;
  SparseTsdfVolume<S, B> sparse(S(0.01), S(0), SE3<S>::identity(), capacity);

  const std::set<Key> first = serial_band_keys(sparse, frames[0], camera, poses[0]);
  REQUIRE(first.size() > std::size_t(capacity));
  const SparseIntegration r = integrate(sparse, frames[0], camera, poses[0]);
  CHECK(r.allocation.inserted == capacity);
  CHECK(r.allocation.refused == std::int64_t(first.size()) - capacity);
  CHECK(sparse.allocated_blocks() == capacity);
  // The refused ones are the largest keys: the outcome does not depend on
  // which thread came first.
  const std::set<Key> stored = stored_keys(sparse);
  CHECK(stored == std::set<Key>(first.begin(), std::next(first.begin(), capacity)));
  CHECK(map_is_consistent(sparse.template to<Host>()));
  CHECK(sparse.memory_bytes() <= sparse.memory_bound_bytes());

  // Another view, into the full table: nothing stored changes.
  const auto before_sdf = sparse.sdf_to_host();
  const auto before_weight = sparse.weight_to_host();
  const auto before_blocks = block_list(sparse);
  const std::set<Key> second = serial_band_keys(sparse, frames[6], camera, poses[6]);
  std::int64_t fresh = 0;
  for (Key k : second) fresh += stored.count(k) ? 0 : 1;
  REQUIRE(fresh > 0);
  const BlockAllocation a = allocate_blocks(sparse, frames[6], camera, poses[6]);
  CHECK(a.inserted == 0);
  CHECK(a.refused == fresh);
  CHECK(sparse.allocated_blocks() == capacity);
  CHECK(block_list(sparse) == before_blocks);
  CHECK(sparse.sdf_to_host() == before_sdf);
  CHECK(sparse.weight_to_host() == before_weight);
  CHECK(map_is_consistent(sparse.template to<Host>()));

  // Integrating it still updates the stored blocks, and only them.
  const SparseIntegration again = integrate(sparse, frames[6], camera, poses[6]);
  CHECK(again.allocation.refused == fresh);
  CHECK(sparse.allocated_blocks() == capacity);
  CHECK(stored_keys(sparse) == stored);
  CHECK(map_is_consistent(sparse.template to<Host>()));

  // reset() empties the table.
  sparse.reset();
  CHECK(sparse.allocated_blocks() == 0);
  const auto host = sparse.template to<Host>();
  S sdf;
  CHECK_FALSE(host.view().sample(poses[0].translation() * S(0.8), sdf));
  CHECK(integrate(sparse, frames[0], camera, poses[0]).allocation.inserted == capacity);
}

TEMPLATE_LIST_TEST_CASE("Sparse volume: hash collisions and repeated keys", "[volume]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // A line of blocks and a plane of blocks, with every key given twice.
  std::vector<Key> keys;
  for (int i = -40; i < 40; ++i) keys.push_back(detail::sparse::pack_key(i, 3, -7));
  for (int i = 0; i < 10; ++i)
    for (int j = 0; j < 10; ++j) keys.push_back(detail::sparse::pack_key(i - 1000, j - 5, 1000000));
  const std::size_t distinct = keys.size();
  keys.insert(keys.end(), keys.begin(), keys.end());
  std::reverse(keys.begin(), keys.end());

  // Exactly as many blocks as distinct keys: the table half full.
  SparseTsdfVolume<S, B> sparse(S(0.02), S(0), SE3<S>::identity(), int(distinct));
  typename B::template Vector<Key> device_keys(keys.begin(), keys.end());
  const BlockAllocation a = sparse.allocate_keys(device_keys, device_keys.size());
  CHECK(a.inserted == std::int64_t(distinct));
  CHECK(a.refused == 0);
  const auto host = sparse.template to<Host>();
  const auto view = host.view();
  CHECK(map_is_consistent(host));
  std::size_t displaced = 0;  // keys not in their home slot: collisions that were resolved
  for (Key k : std::set<Key>(keys.begin(), keys.end())) {
    int bx, by, bz;
    detail::sparse::unpack_key(k, bx, by, bz);
    CHECK(view.find_block(bx, by, bz) >= 0);
    if (view.slot_keys[detail::sparse::mix(k) & view.slot_mask] != k) ++displaced;
  }
  INFO("keys displaced by collisions: " << displaced);
  CHECK(displaced > 0);
  CHECK(view.find_block(0, 0, 0) < 0);
  CHECK(view.find_block(40, 3, -7) < 0);

  // The same keys again: all stored already.
  typename B::template Vector<Key> again(keys.begin(), keys.end());
  const BlockAllocation b = sparse.allocate_keys(again, again.size());
  CHECK(b.inserted == 0);
  CHECK(b.refused == 0);

  // A table of three blocks (eight slots) given all of them.
  SparseTsdfVolume<S, B> tiny(S(0.02), S(0), SE3<S>::identity(), 3);
  typename B::template Vector<Key> more(keys.begin(), keys.end());
  const BlockAllocation c = tiny.allocate_keys(more, more.size());
  CHECK(c.inserted == 3);
  CHECK(c.refused == std::int64_t(distinct) - 3);
  CHECK(map_is_consistent(tiny.template to<Host>()));
  CHECK_THROWS_WITH(tiny.allocate_keys(more, more.size() + 1), EMF_CONTAINS("exceeds"));
}

TEMPLATE_LIST_TEST_CASE("Sparse allocation in parallel finds the blocks of a serial loop, in any frame order",
                        "[volume]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const auto camera = test::room_camera<S>();
  const auto poses = test::room_views<S>();
  const auto frames = render_frames<S, B>(test::room_scene<S>(), camera, poses);
  const SE3<S> pose = SE3<S>::translation(vec3(S(-0.37), S(0.11), S(-0.05)));
  SparseTsdfVolume<S, B> forward(S(0.02), S(0), pose, 1 << 14), backward(S(0.02), S(0), pose, 1 << 14);
  std::set<Key> reference;
  SparseIntegrationWorkspace<S, B> workspace;  // reused across frames
  for (std::size_t k = 0; k < poses.size(); ++k) {
    const std::set<Key> band = serial_band_keys(forward, frames[k], camera, poses[k]);
    std::int64_t fresh = 0;
    for (Key key : band) fresh += reference.count(key) ? 0 : 1;
    reference.insert(band.begin(), band.end());
    const BlockAllocation a =
        allocate_blocks(forward, frames[k], camera, poses[k], static_cast<const Image<S, B>*>(nullptr), &workspace);
    CHECK(a.inserted == fresh);
    CHECK(a.refused == 0);
    CHECK(stored_keys(forward) == reference);
  }
  for (std::size_t k = poses.size(); k-- > 0;) allocate_blocks(backward, frames[k], camera, poses[k]);
  CHECK(stored_keys(backward) == reference);
  CHECK(map_is_consistent(forward.template to<Host>()));
  CHECK(map_is_consistent(backward.template to<Host>()));

  // Independently of the band sampling: the block of every measured surface
  // point is allocated.
  const auto host = forward.template to<Host>();
  const auto depth = frames[0].to_host();
  std::size_t points = 0, missing = 0;
  for (int v = 0; v < camera.height; ++v)
    for (int u = 0; u < camera.width; ++u) {
      const S d = depth[std::size_t(v) * camera.width + u];
      if (!is_valid_depth(d)) continue;
      const Vec3<S> p = pose.inverse() * (poses[0] * camera.back_project(S(u), S(v), d));
      const S block = forward.block_size();
      ++points;
      if (host.view().find_block(int(std::floor(p.x() / block)), int(std::floor(p.y() / block)),
                                 int(std::floor(p.z() / block))) < 0)
        ++missing;
    }
  CHECK(points > 10000);
  CHECK(missing == 0);

  // With a weight image, pixels of weight 0 allocate nothing.
  SparseTsdfVolume<S, B> none(S(0.02), S(0), pose, 1 << 14);
  const Image<S, B> zero(camera.width, camera.height, S(0));
  const BlockAllocation z = allocate_blocks(none, frames[0], camera, poses[0], &zero);
  CHECK(z.inserted == 0);
  CHECK(z.refused == 0);
  CHECK(none.allocated_blocks() == 0);
}

TEMPLATE_LIST_TEST_CASE("Sparse volume: unallocated space reads as never observed", "[volume]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  SparseTsdfVolume<S, B> sparse(S(0.01), S(0.05), SE3<S>::identity(), 16);
  CHECK(sparse.truncation() == S(0.05));
  CHECK(sparse.allocated_blocks() == 0);
  CHECK(sparse.capacity() == 16);
  const auto host = sparse.template to<Host>();
  const auto view = host.view();
  S sdf = S(7), weight = S(7);
  Vec3<S> gradient;
  for (const Vec3<S>& p : {vec3(S(0.3), S(0.2), S(1)), vec3(S(-4), S(2), S(-3)), vec3(S(0), S(0), S(0))}) {
    CHECK(view.contains_point(p));
    CHECK_FALSE(view.sample(p, sdf));
    CHECK_FALSE(view.sample_observed(p, sdf));
    CHECK_FALSE(view.sample_with_gradient(p, sdf, gradient));
    CHECK_FALSE(view.central_gradient(p, gradient));
    CHECK_FALSE(view.observed_gradient(p, gradient));
  }
  CHECK(sdf == S(7));
  CHECK_FALSE(view.voxel(-3, 5, 100, sdf, weight));
  CHECK(sdf == S(0.05));
  CHECK(weight == S(0));
  const S nan = std::numeric_limits<S>::quiet_NaN();
  CHECK_FALSE(view.contains_point(vec3(nan, S(0), S(0))));
  CHECK_FALSE(view.contains_point(vec3(S(1e6), S(0), S(0))));
  CHECK_FALSE(view.sample(vec3(nan, S(0), S(0)), sdf));
  CHECK(view.find_block(detail::sparse::block_limit, 0, 0) < 0);  // out of range, not a wrapped key
}

TEMPLATE_LIST_TEST_CASE("Sparse volume: bad parameters throw clear errors", "[volume]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  using V = SparseTsdfVolume<S, B>;
  const SE3<S> I = SE3<S>::identity();
  const S inf = std::numeric_limits<S>::infinity(), nan = std::numeric_limits<S>::quiet_NaN();
  CHECK_THROWS_WITH(V(S(0), S(0), I, 10), EMF_CONTAINS("SparseTsdfVolume: voxel size must be positive"));
  CHECK_THROWS_WITH(V(S(-0.01), S(0), I, 10), EMF_CONTAINS("voxel size"));
  CHECK_THROWS_WITH(V(nan, S(0), I, 10), EMF_CONTAINS("voxel size"));
  CHECK_THROWS_WITH(V(inf, S(0), I, 10), EMF_CONTAINS("voxel size"));
  CHECK_THROWS_WITH(V(S(0.01), S(-0.1), I, 10), EMF_CONTAINS("truncation must be finite and not negative"));
  CHECK_THROWS_WITH(V(S(0.01), nan, I, 10), EMF_CONTAINS("truncation"));
  CHECK_THROWS_WITH(V(S(0.01), S(0), I, 0), EMF_CONTAINS("block capacity must be between 1 and"));
  CHECK_THROWS_WITH(V(S(0.01), S(0), I, -3), EMF_CONTAINS("got -3"));
  CHECK_THROWS_WITH(V(S(0.01), S(0), I, V::max_block_capacity + 1), EMF_CONTAINS("block capacity"));
  CHECK_THROWS_AS(V(S(0.01), S(0), I, 0), std::invalid_argument);
  CHECK(double(V(S(0.01), S(0), I, 1).truncation()) == test::Approx(0.1));
  for (const int cells : {-1, V::max_grid_cells_per_block + 1}) {
    SparseVolumeParams<S> p{S(0.01), S(0), I, 10};
    p.grid_cells_per_block = cells;
    CHECK_THROWS_WITH(V(p), EMF_CONTAINS("index grid cells per block must be between 0 and 1024, got " +
                                         std::to_string(cells)));
  }

  V sparse(S(0.01), S(0), I, 10);
  const auto camera = test::small_camera<S>();
  const Image<S, B> wrong(camera.width + 1, camera.height, S(1));
  CHECK_THROWS_WITH(allocate_blocks(sparse, wrong, camera, I), EMF_CONTAINS("allocate_blocks"));
  CHECK_THROWS_WITH(integrate(sparse, wrong, camera, I), EMF_CONTAINS("integrate"));
  const Image<S, B> depth(camera.width, camera.height, S(1));
  const Image<S, B> weights(camera.width, camera.height + 1, S(1));
  CHECK_THROWS_WITH(integrate(sparse, depth, camera, I, &weights), EMF_CONTAINS("weight image"));
}

TEMPLATE_LIST_TEST_CASE("Sparse volume: assigned from its host copies, the same volume; bad copies refused",
                        "[volume]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const auto camera = test::small_camera<S>();
  const auto poses = test::orbit_poses<S>(Vec3<S>::zero(), S(1.2), 4);
  const auto frames = render_frames<S, B>(test::sphere_and_box<S>(), camera, poses);
  const SE3<S> pose = SE3<S>::translation(vec3(S(0.3), S(-0.2), S(0.1)));
  SparseTsdfVolume<S, B> original(S(0.01), S(0), pose, 1 << 12);
  for (std::size_t k = 0; k < poses.size(); ++k) integrate(original, frames[k], camera, poses[k]);
  const std::vector<Vec3i> blocks = original.blocks_to_host();
  const auto sdf = original.sdf_to_host();
  const auto weight = original.weight_to_host();
  REQUIRE(blocks.size() > 50);

  // Into a volume that held something else: exactly the original.
  SparseTsdfVolume<S, B> copy(S(0.01), S(0), pose, 1 << 12);
  integrate(copy, frames[3], camera, poses[0]);
  copy.assign_from_host(blocks, sdf, weight);
  CHECK(copy.allocated_blocks() == original.allocated_blocks());
  CHECK(block_list(copy) == block_list(original));
  CHECK(copy.sdf_to_host() == sdf);
  CHECK(copy.weight_to_host() == weight);
  for (int a = 0; a < 3; ++a) {
    CHECK(copy.block_min()[a] == original.block_min()[a]);
    CHECK(copy.block_max()[a] == original.block_max()[a]);
  }
  CHECK(stored_keys(copy) == stored_keys(original));
  CHECK(map_is_consistent(copy.template to<Host>()));
  // It goes on as the original does.
  integrate(copy, frames[1], camera, poses[2]);
  integrate(original, frames[1], camera, poses[2]);
  CHECK(block_list(copy) == block_list(original));
  CHECK(copy.sdf_to_host() == original.sdf_to_host());

  // Refused, the volume unchanged.
  const auto before = copy.sdf_to_host();
  const auto refused = [&](std::vector<Vec3i> b, std::size_t voxels) {
    const std::vector<S> v(voxels, S(0.1)), w(voxels, S(1));
    return error_of([&] { copy.assign_from_host(b, v, w); });
  };
  std::vector<Vec3i> repeated = {Vec3i{{1, 2, 3}}, Vec3i{{4, 5, 6}}, Vec3i{{1, 2, 3}}};
  CHECK(contains(refused(repeated, 3 * 512), "block 2 repeats an earlier one"));
  std::vector<Vec3i> far = {Vec3i{{detail::sparse::block_limit, 0, 0}}};
  CHECK(contains(refused(far, 512), "outside the addressable range"));
  CHECK(contains(refused({Vec3i{{0, 0, 0}}}, 511), "need 512 SDF values and weights for 1 blocks"));
  SparseTsdfVolume<S, B> tiny(S(0.01), S(0), pose, 2);
  CHECK_THROWS_WITH(tiny.assign_from_host(repeated, std::vector<S>(3 * 512), std::vector<S>(3 * 512)),
                    EMF_CONTAINS("3 blocks exceed the capacity of 2"));
  CHECK(copy.sdf_to_host() == before);
  CHECK(block_list(copy) == block_list(original));
}

TEMPLATE_LIST_TEST_CASE("Sparse volume with half storage follows the float one", "[volume]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  if constexpr (std::is_same_v<S, float>) {
    const auto camera = test::small_camera<S>();
    const auto scene = test::sphere_and_box<S>();
    const auto poses = test::orbit_poses<S>(Vec3<S>::zero(), S(1.2), 6);
    const auto frames = render_frames<S, B>(scene, camera, poses);
    SparseTsdfVolume<S, B> full(S(0.01), S(0), SE3<S>::identity(), 4096);
    SparseTsdfVolume<S, B, Half> half(S(0.01), S(0), SE3<S>::identity(), 4096);
    for (std::size_t k = 0; k < poses.size(); ++k) {
      integrate(full, frames[k], camera, poses[k]);
      integrate(half, frames[k], camera, poses[k]);
    }
    CHECK(half.allocated_blocks() == full.allocated_blocks());
    CHECK(half.memory_bytes() < full.memory_bytes());
    const auto a = full.template to<Host>();
    const auto b = half.template to<Host>();
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> c(-0.45, 0.45);
    std::size_t compared = 0;
    double max_difference = 0;
    for (int k = 0; k < 5000; ++k) {
      const Vec3<S> p = vec3(S(c(rng)), S(c(rng)), S(c(rng)));
      S va, vb;
      if (!a.view().sample(p, va) || !b.view().sample(p, vb)) continue;
      ++compared;
      max_difference = std::max(max_difference, std::fabs(double(va - vb)));
    }
    INFO("compared " << compared << ", max |float - half| " << max_difference);
    CHECK(compared > 1000);
    CHECK(max_difference < 1e-3);
  }
}
