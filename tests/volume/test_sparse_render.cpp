// Ray casting and marching cubes written once over the volume concept, on the
// sparse voxel-block volume: against the dense volume holding the same voxel
// values (depths, normals, hits; vertices and triangles), empty-space
// skipping over unallocated blocks, a scene 10 m from the origin, a closed
// mesh across block borders, and bad inputs.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <limits>
#include <map>
#include <ostream>
#include <set>
#include <stdexcept>
#include <vector>

#include "emfusion/core/parallel.hpp"
#include "emfusion/volume/integrate.hpp"
#include "emfusion/volume/marching_cubes.hpp"
#include "emfusion/volume/raycast.hpp"
#include "emfusion/volume/sparse_tsdf_volume.hpp"
#include "emfusion/volume/tsdf_volume.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"
#include "support/fusion.hpp"

using namespace emfusion;

namespace {

using Key = detail::sparse::Key;

/// 160x120 pixels, 53 degrees across: about 7 mm a pixel at 1.2 m, finer
/// than the 1 cm voxels, and cheap enough for the sanitizer builds.
template <class S>
PinholeCamera<S> render_camera() {
  return PinholeCamera<S>{S(160), S(160), S(79.5), S(59.5), 160, 120};
}

template <class S, class B>
std::vector<Image<S, B>> render_frames(const sim::Scene<S>& scene, const PinholeCamera<S>& camera,
                                       const std::vector<SE3<S>>& poses) {
  std::vector<Image<S, B>> frames(poses.size());
  for (std::size_t k = 0; k < poses.size(); ++k)
    sim::render_depth(scene, camera, poses[k], frames[k], static_cast<Image<int, B>*>(nullptr), {}, B{});
  return frames;
}

/// A dense 112^3 cube at 1 cm around the sphere and box (all of their
/// truncation band inside it), and a sparse volume
/// in the same frame with every block the frames touch allocated before the
/// first update: then every allocated voxel equals the dense voxel.
template <class S, class B>
struct FusedPair {
  TsdfVolume<S, B> dense;
  SparseTsdfVolume<S, B> sparse;
  std::vector<SE3<S>> poses;

  FusedPair()
      : dense(test::cube_around<S>(Vec3<S>::zero(), 112, S(0.01))),
        sparse(S(0.01), S(0), dense.pose(), 4096),
        poses(test::orbit_poses<S>(Vec3<S>::zero(), S(1.2), 12)) {
    const auto camera = render_camera<S>();
    const auto frames = render_frames<S, B>(test::sphere_and_box<S>(), camera, poses);
    for (std::size_t k = 0; k < poses.size(); ++k) allocate_blocks(sparse, frames[k], camera, poses[k]);
    // The refined update, as for clean synthetic depth elsewhere
    // (test::fuse_views): the paper's update leaves thin phantom crossings
    // beside silhouettes that make first crossings depend on the march.
    const auto params = IntegrationParams<S>::refined();
    const Image<S, B>* no_weights = nullptr;
    for (std::size_t k = 0; k < poses.size(); ++k) {
      integrate(dense, frames[k], camera, poses[k], no_weights, params);
      integrate(sparse, frames[k], camera, poses[k], no_weights, params);
    }
  }
};

/// The dense volume with every voxel outside the sparse volume's blocks made
/// unobserved: then both hold the same values everywhere.
template <class S, class B>
TsdfVolume<S, B> masked_to_sparse(const TsdfVolume<S, B>& dense, const SparseTsdfVolume<S, B>& sparse) {
  const auto host = sparse.template to<Host>();
  const auto sv = host.view();
  TsdfVolume<S, Host> out = dense.template to<Host>();
  std::vector<S> sdf = out.sdf_to_host(), weight = out.weight_to_host();
  const auto dv = out.view();
  for (int z = 0; z < dv.nz; ++z)
    for (int y = 0; y < dv.ny; ++y)
      for (int x = 0; x < dv.nx; ++x)
        if (sv.voxel_index(x, y, z) < 0) {
          const auto i = std::size_t(dv.index(x, y, z));
          sdf[i] = dense.truncation(), weight[i] = S(0);
        }
  out.assign_from_host(sdf, weight);
  return out.template to<B>();
}

/// Writes clamp(sdf(voxel centre)) with weight 1 into every allocated voxel.
template <class S, class Sdf>
struct FillBlocks {
  SparseTsdfView<S> volume;
  Sdf sdf;
  EMF_HD void operator()(std::int64_t i) const {
    const int b = int(i / 512), local = int(i % 512);
    const Vec3i c = volume.block_coordinates(b);
    const S d = sdf(volume.voxel_center(c[0] * 8 + (local & 7), c[1] * 8 + ((local >> 3) & 7), c[2] * 8 + (local >> 6)));
    volume.sdf[i] = clamp(d, -volume.truncation, volume.truncation);
    volume.weight[i] = S(1);
  }
};

template <class S>
struct SphereSdf {
  Vec3<S> centre;
  S radius;
  EMF_HD S operator()(const Vec3<S>& p) const { return norm(p - centre) - radius; }
};

template <class S>
struct TwoSpheres {
  SphereSdf<S> a, b;
  EMF_HD S operator()(const Vec3<S>& p) const {
    const S da = a(p), db = b(p);
    return da < db ? da : db;
  }
};

/// Allocates the blocks within `band` (block-centre distance, in metres) of
/// the zero set of `sdf` among blocks lo..hi, then fills them.
template <class S, class B, class Sdf>
void fill_sparse(SparseTsdfVolume<S, B>& volume, const Sdf& sdf, const Vec3i& lo, const Vec3i& hi, S band) {
  std::vector<Key> keys;
  const S side = volume.block_size();
  for (int z = lo[2]; z <= hi[2]; ++z)
    for (int y = lo[1]; y <= hi[1]; ++y)
      for (int x = lo[0]; x <= hi[0]; ++x) {
        const Vec3<S> centre = vec3((S(x) + S(0.5)) * side, (S(y) + S(0.5)) * side, (S(z) + S(0.5)) * side);
        if (std::fabs(double(sdf(centre))) < double(band)) keys.push_back(detail::sparse::pack_key(x, y, z));
      }
  typename B::template Vector<Key> device_keys(keys.begin(), keys.end());
  const BlockAllocation a = volume.allocate_keys(device_keys, device_keys.size());
  REQUIRE(a.refused == 0);
  for_each_index(volume.backend(), volume.voxel_count(), FillBlocks<S, Sdf>{volume.view(), sdf});
  volume.backend().synchronize();
}

/// Two renderings pixel by pixel. Where both hit, the depths differ by the
/// refinement of the crossing (regula falsi from brackets that depend on
/// where the march stepped) and, at a few grazing rays, by which crossing
/// was bracketed first.
struct RenderComparison {
  std::size_t hits_a = 0, hits_b = 0, both = 0, only_a = 0, only_b = 0;
  std::size_t misses_with_depth = 0;      // must be 0: a miss has depth 0
  std::vector<double> depth_differences;  // sorted, where both hit
  std::vector<double> normal_cosines;     // sorted, where both hit

  double depth_quantile(double q) const {
    return depth_differences.empty() ? 0 : depth_differences[std::size_t(q * double(depth_differences.size() - 1))];
  }
  double cosine_quantile(double q) const {
    return normal_cosines.empty() ? 1 : normal_cosines[std::size_t(q * double(normal_cosines.size() - 1))];
  }
  /// Share of the pixels both hit whose depths differ by more than d.
  double share_apart(double d) const {
    const auto n = depth_differences.end() - std::upper_bound(depth_differences.begin(), depth_differences.end(), d);
    return both == 0 ? 0 : double(n) / double(both);
  }
  /// Share of the pixels either hits that only the first (a) or only the
  /// second (b) hits.
  double share_only_a() const { return both + only_a + only_b == 0 ? 0 : double(only_a) / double(both + only_a + only_b); }
  double share_only_b() const { return both + only_a + only_b == 0 ? 0 : double(only_b) / double(both + only_a + only_b); }
};

std::ostream& operator<<(std::ostream& os, const RenderComparison& c) {
  return os << "hits " << c.hits_a << " / " << c.hits_b << ", only the first " << c.share_only_a() * 100
            << " %, only the second " << c.share_only_b() * 100 << " %; |depth difference| median " << c.depth_quantile(0.5) << ", 99th percentile "
            << c.depth_quantile(0.99) << ", max " << c.depth_quantile(1) << ", over 1 mm " << c.share_apart(1e-3) * 100
            << " %; normal cosine 1st percentile " << c.cosine_quantile(0.01);
}

template <class S, class B>
RenderComparison compare_renderings(const RaycastResult<S, B>& a, const RaycastResult<S, B>& b) {
  const auto da = a.depth.to_host(), db = b.depth.to_host();
  const auto ha = a.hit.to_host(), hb = b.hit.to_host();
  const auto na = a.normals.to_host(), nb = b.normals.to_host();
  RenderComparison c;
  for (std::size_t i = 0; i < da.size(); ++i) {
    c.hits_a += ha[i], c.hits_b += hb[i];
    if (ha[i] && hb[i]) {
      ++c.both;
      c.depth_differences.push_back(std::fabs(double(da[i] - db[i])));
      c.normal_cosines.push_back(double(dot(na[i], nb[i])));
    } else if (ha[i]) {
      ++c.only_a;
    } else if (hb[i]) {
      ++c.only_b;
    }
    if ((!ha[i] && da[i] != S(0)) || (!hb[i] && db[i] != S(0))) ++c.misses_with_depth;
  }
  std::sort(c.depth_differences.begin(), c.depth_differences.end());
  std::sort(c.normal_cosines.begin(), c.normal_cosines.end());
  return c;
}

/// Vertex positions (exact) and triangles as triples of positions.
template <class S>
struct MeshSets {
  std::set<std::array<S, 3>> vertices;
  std::set<std::array<std::array<S, 3>, 3>> triangles;
};
template <class S>
MeshSets<S> mesh_sets(const TriangleMesh<S>& mesh) {
  MeshSets<S> m;
  const auto at = [&](int i) {
    const Vec3<S>& v = mesh.vertices[std::size_t(i)];
    return std::array<S, 3>{v.x(), v.y(), v.z()};
  };
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) m.vertices.insert(at(int(i)));
  for (const auto& t : mesh.triangles) {
    // Rotated to start at the smallest corner: the same triangle, same winding.
    std::array<std::array<S, 3>, 3> p{at(t[0]), at(t[1]), at(t[2])};
    std::rotate(p.begin(), std::min_element(p.begin(), p.end()), p.end());
    m.triangles.insert(p);
  }
  return m;
}

template <class T>
std::size_t symmetric_difference_size(const std::set<T>& a, const std::set<T>& b) {
  std::vector<T> out;
  std::set_symmetric_difference(a.begin(), a.end(), b.begin(), b.end(), std::back_inserter(out));
  return out.size();
}

/// On the CPU both volumes' voxels are equal bit for bit; a device may
/// contract multiply-adds differently in the two integrations.
template <class S, class B>
double value_tolerance() {
  if (!B::is_device) return 0;
  return sizeof(S) <= 4 ? 1e-5 : 1e-9;
}

}  // namespace

// One fusion, two checks (it is what costs): ray casting, then marching cubes.
TEMPLATE_LIST_TEST_CASE("Sparse raycast and marching cubes: what the dense volume gives for the same voxels",
                        "[volume]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const FusedPair<S, B> pair;
  const auto camera = render_camera<S>();
  const TsdfVolume<S, B> masked = masked_to_sparse(pair.dense, pair.sparse);
  // Views of the fusion, views moved from them, one further away, and one
  // close by from a new side (the last).
  const SE3<S> nudge = SE3<S>::exp(Vec6<S>{{S(0.04), S(-0.03), S(0.05), S(0.03), S(-0.04), S(0.02)}});
  const std::vector<SE3<S>> views{pair.poses[5] * nudge, test::orbit_poses<S>(Vec3<S>::zero(), S(2), 12)[7],
                                  test::orbit_poses<S>(vec3(S(0.05), S(0), S(0)), S(0.9), 3)[0]};
  RaycastResult<S, B> first;  // the sparse rendering of views[0]
  for (std::size_t k = 0; k < views.size(); ++k) {
    INFO("view " << k);
    RaycastResult<S, B> dense, sparse, same_values;
    raycast(pair.dense, camera, views[k], dense);
    raycast(pair.sparse, camera, views[k], sparse);
    raycast(masked, camera, views[k], same_values);
    if (k == 0) first = sparse;
    // Against the dense volume with the same voxels: the march differs only
    // in where it steps through unobserved space.
    const RenderComparison m = compare_renderings(same_values, sparse);
    const RenderComparison d = compare_renderings(dense, sparse);
    INFO("same voxels: " << m);
    INFO("as fused:    " << d);
    CHECK(m.misses_with_depth + d.misses_with_depth == 0);
    for (const RenderComparison* c : {&m, &d}) {
      CHECK(c->both > 1000);
      // The march steps a truncation through unobserved space, which may
      // overshoot a thin observed band behind it; the sparse march enters
      // allocated blocks at their faces and so finds what the dense one
      // finds, and more where the dense one overshot (the close view from
      // a new side, whose rays reach the surface through unobserved space).
      CHECK(c->share_only_a() < 0.002);
      if (k + 1 < views.size()) CHECK(c->share_only_b() < 0.003);
      CHECK(c->depth_quantile(0.5) < 2e-6);
      CHECK(c->depth_quantile(0.99) < 3e-5);
      CHECK(c->share_apart(1e-3) < 0.003);
      CHECK(c->cosine_quantile(0.01) > 0.9999);
    }
  }

  // ray_end: rays only where it is positive, ending there.
  const SE3<S>& view = views[0];
  const RaycastResult<S, B>& full = first;
  RaycastResult<S, B> part;
  std::vector<S> end(std::size_t(camera.width) * std::size_t(camera.height), S(0));
  for (std::size_t i = 0; i < end.size(); ++i) end[i] = (i % std::size_t(camera.width)) < 80 ? S(5) : S(0);
  const Image<S, B> ray_end = Image<S, Host>::from_host(camera.width, camera.height, end).template to<B>();
  raycast(pair.sparse, camera, view, part, {}, static_cast<const ForegroundCounts<S, B>*>(nullptr), &ray_end);
  const auto hf = full.hit.to_host(), hp = part.hit.to_host();
  const auto df = full.depth.to_host(), dp = part.depth.to_host();
  std::size_t kept = 0, different = 0, outside = 0;
  for (std::size_t i = 0; i < end.size(); ++i) {
    if (end[i] > S(0)) {
      kept += hp[i];
      different += hp[i] != hf[i] || dp[i] != df[i];
    } else {
      outside += hp[i];
    }
  }
  CHECK(kept > 1000);
  CHECK(different == 0);
  CHECK(outside == 0);

  // Marching cubes: the same triangles as the dense volume with the same
  // voxels, with and without a weight threshold.
  for (const S min_weight : {S(0), S(2)}) {
    INFO("min_weight " << min_weight);
    const TriangleMesh<S> sparse = marching_cubes(pair.sparse, S(0), min_weight);
    const TriangleMesh<S> same_values = marching_cubes(masked, S(0), min_weight);
    const TriangleMesh<S> dense = marching_cubes(pair.dense, S(0), min_weight);
    REQUIRE(sparse.triangles.size() > (min_weight > S(0) ? 1000u : 10000u));
    REQUIRE(sparse.normals.size() == sparse.vertices.size());
    INFO("triangles: sparse " << sparse.triangles.size() << ", dense with the same voxels "
                              << same_values.triangles.size() << ", dense as fused " << dense.triangles.size());
    CHECK(sparse.triangles.size() == same_values.triangles.size());
    CHECK(sparse.vertices.size() == same_values.vertices.size());
    if (value_tolerance<S, B>() == 0) {
      // The same vertices bit for bit and the same triangles.
      const MeshSets<S> a = mesh_sets(sparse), b = mesh_sets(same_values);
      CHECK(a.vertices.size() == sparse.vertices.size());  // no vertex twice
      CHECK(symmetric_difference_size(a.vertices, b.vertices) == 0);
      CHECK(symmetric_difference_size(a.triangles, b.triangles) == 0);
      // Normals too: vertex by vertex, matched by position.
      std::map<std::array<S, 3>, Vec3<S>> normals;
      for (std::size_t i = 0; i < same_values.vertices.size(); ++i) {
        const Vec3<S>& v = same_values.vertices[i];
        normals[{v.x(), v.y(), v.z()}] = same_values.normals[i];
      }
      std::size_t different_normals = 0;
      for (std::size_t i = 0; i < sparse.vertices.size(); ++i) {
        const Vec3<S>& v = sparse.vertices[i];
        const auto found = normals.find({v.x(), v.y(), v.z()});
        if (found == normals.end() || max_abs_diff(found->second, sparse.normals[i]) != S(0)) ++different_normals;
      }
      CHECK(different_normals == 0);
    } else {
      CHECK(std::fabs(surface_area(sparse) - surface_area(same_values)) < 1e-4 * surface_area(same_values));
    }
    // The dense volume as fused also holds free space the sparse one never
    // stored; its surface is the same but for a few cells at the edge of the
    // observed band.
    CHECK(sparse.triangles.size() <= dense.triangles.size());
    CHECK(double(sparse.triangles.size()) > 0.99 * double(dense.triangles.size()));
    const EdgeCounts es = count_edges(sparse), ed = count_edges(same_values);
    CHECK(es.nonmanifold == ed.nonmanifold);
    CHECK(es.boundary == ed.boundary);
  }
}

TEMPLATE_LIST_TEST_CASE("Sparse raycast: rays through unallocated space miss and skip it", "[volume]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // Two balls 2.4 m apart: the box of allocated blocks spans both, and the
  // space between them is unallocated.
  SparseTsdfVolume<S, B> sparse(S(0.02), S(0), SE3<S>::identity(), 4096);
  const TwoSpheres<S> balls{{vec3(S(-1.2), S(0.013), S(2.007)), S(0.2)}, {vec3(S(1.2), S(0.013), S(2.007)), S(0.2)}};
  fill_sparse(sparse, balls, Vec3i{{-12, -4, 7}}, Vec3i{{11, 4, 16}}, S(0.6));
  REQUIRE(sparse.allocated_blocks() > 20);
  const Vec3i lo = sparse.block_min(), hi = sparse.block_max();
  CHECK(lo[0] < -5);
  CHECK(hi[0] > 5);
  CHECK(lo[2] > 0);

  const auto camera = render_camera<S>();
  RaycastResult<S, B> out;
  // Looking at the gap between the balls from in front: everything misses.
  const SE3<S> gap = sim::look_at<S>(vec3(S(0), S(0), S(0.5)), vec3(S(0), S(0), S(3)), vec3(S(0), S(-1), S(0)));
  raycast(sparse, camera, gap, out);
  const auto gap_hits = out.hit.to_host();
  CHECK(std::count(gap_hits.begin(), gap_hits.end(), std::uint8_t(1)) == 0);
  // Looking along the x axis through both: the rays cross the unallocated
  // metres between and hit the near ball; seen from the other side, the
  // other ball.
  const SE3<S> along = sim::look_at<S>(vec3(S(-3), S(0.013), S(2.007)), vec3(S(0), S(0.013), S(2.007)),
                                       vec3(S(0), S(-1), S(0)));
  raycast(sparse, camera, along, out);
  const auto hits = out.hit.to_host();
  const auto depth = out.depth.to_host();
  const int centre = camera.width * (camera.height / 2) + camera.width / 2;  // half a pixel off the axis
  REQUIRE(hits[std::size_t(centre)] == 1);
  CHECK(double(depth[std::size_t(centre)]) == test::Approx(3 - 1.2 - 0.2).margin(2e-3));
  const SE3<S> back = sim::look_at<S>(vec3(S(3), S(0.013), S(2.007)), vec3(S(0), S(0.013), S(2.007)),
                                      vec3(S(0), S(-1), S(0)));
  raycast(sparse, camera, back, out);
  CHECK(double(out.depth.to_host()[std::size_t(centre)]) == test::Approx(1.6).margin(2e-3));

  // The skip itself: from a point in the gap, straight to the face of the
  // first allocated block of the far ball, one lookup per block.
  const auto host = sparse.template to<Host>();
  const auto view = host.view();
  const Vec3<S> o = vec3(S(0.01), S(0.013), S(2.007)), d = vec3(S(1), S(0), S(0));
  S t = S(0);
  REQUIRE(view.skip_unallocated(o, d, t, S(10)));
  int first_x = 1000;
  for (const Vec3i& b : host.blocks_to_host())
    if (b[1] == 0 && b[2] == int(std::floor(2.007 / 0.16)) && b[0] > 0) first_x = std::min(first_x, b[0]);
  CHECK(double(o.x() + t) == test::Approx(first_x * 0.16).margin(1e-5));
  S t_short = S(0);
  CHECK(view.skip_unallocated(o, d, t_short, S(0.2)));
  CHECK(t_short > S(0.2));  // nothing allocated before t_end: beyond it
  // From inside an allocated block: no skip, t unchanged.
  S t_allocated = S(1.19) - S(0.01);
  CHECK_FALSE(view.skip_unallocated(o, d, t_allocated, S(10)));
  CHECK(t_allocated == S(1.19) - S(0.01));

  // An empty volume: every ray misses.
  SparseTsdfVolume<S, B> empty(S(0.02), S(0), SE3<S>::identity(), 16);
  raycast(empty, camera, along, out);
  const auto none = out.hit.to_host();
  CHECK(std::count(none.begin(), none.end(), std::uint8_t(1)) == 0);
  CHECK(empty.block_min()[0] > empty.block_max()[0]);
  // reset() empties the box too.
  sparse.reset();
  CHECK(sparse.block_min()[0] > sparse.block_max()[0]);
  raycast(sparse, camera, along, out);
  const auto after_reset = out.hit.to_host();
  CHECK(std::count(after_reset.begin(), after_reset.end(), std::uint8_t(1)) == 0);
}

TEMPLATE_TEST_CASE("Sparse raycast: the normal's samples one at a time are observed_gradient's", "[volume]", float,
                   double) {
  using S = TestType;
  // A ball whose band of blocks ends close to its surface: about the blocks'
  // edges some of a normal's samples are unobserved (one-sided differences,
  // or no normal), as at the border of what a background has seen.
  SparseTsdfVolume<S, Host> sparse(S(0.01), S(0.03), SE3<S>::identity(), 4096);
  const SphereSdf<S> ball{vec3(S(0.003), S(-0.002), S(0.001)), S(0.2)};
  fill_sparse(sparse, ball, Vec3i{{-4, -4, -4}}, Vec3i{{3, 3, 3}}, S(0.05));
  const auto view = sparse.view();
  std::size_t agree = 0, one_sided = 0, none = 0;
  for (int k = 0; k < 4000; ++k) {
    // Points on a spiral over the ball, from 4 cm inside to 4 cm outside.
    const double z = 1.0 - 2.0 * (k + 0.5) / 4000.0, phi = 2.399963 * k, r = std::sqrt(1.0 - z * z);
    const Vec3<S> dir = vec3(S(r * std::cos(phi)), S(r * std::sin(phi)), S(z));
    const Vec3<S> p = ball.centre + (ball.radius + S(0.04 * std::sin(0.37 * k))) * dir;
    Vec3<S> expected{};
    const bool has_expected = detail::trilinear::observed_gradient(view, p, view.voxel_size, expected);
    detail::NormalSamples<S> normal(view.voxel_size);
    bool has = true;
    for (normal.stage = 1; has && normal.stage <= detail::NormalSamples<S>::samples;) {
      S f = S(0);
      const bool observed = view.sample_observed(normal.point(p), f);
      has = normal.take(observed, f);
    }
    INFO("point " << k);
    REQUIRE(has == has_expected);
    if (!has) {
      ++none;
      continue;
    }
    CHECK(normal.gradient.x() == expected.x());
    CHECK(normal.gradient.y() == expected.y());
    CHECK(normal.gradient.z() == expected.z());
    // One-sided where a neighbour is unobserved: the sum of the six.
    S f = S(0);
    int observed = 0;
    for (int a = 0; a < 3; ++a)
      for (const S sign : {S(1), S(-1)}) {
        Vec3<S> q = p;
        q[a] += sign * view.voxel_size;
        observed += view.sample_observed(q, f);
      }
    one_sided += observed < 6;
    ++agree;
  }
  // All three kinds were met.
  CHECK(agree > 1000);
  CHECK(one_sided > 20);
  CHECK(none > 20);
}

TEMPLATE_LIST_TEST_CASE("Sparse raycast of a scene 10 m from the origin", "[volume]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const Vec3<S> offset = vec3(S(10), S(-4), S(6));
  sim::Scene<S> near_scene, far_scene;
  near_scene.add(sim::make_sphere(Vec3<S>::zero(), S(0.25)));
  far_scene.add(sim::make_sphere(offset, S(0.25)));
  const auto camera = render_camera<S>();
  const auto near_poses = test::orbit_poses<S>(Vec3<S>::zero(), S(1.2), 6);
  std::vector<SE3<S>> far_poses;
  for (const auto& pose : near_poses) far_poses.push_back(SE3<S>::translation(offset) * pose);
  const auto near_frames = render_frames<S, B>(near_scene, camera, near_poses);
  const auto far_frames = render_frames<S, B>(far_scene, camera, far_poses);
  TsdfVolume<S, B> dense(test::cube_around<S>(Vec3<S>::zero(), 80, S(0.01)));
  SparseTsdfVolume<S, B> sparse(S(0.01), S(0), SE3<S>::identity(), 8192);
  for (std::size_t k = 0; k < far_poses.size(); ++k) allocate_blocks(sparse, far_frames[k], camera, far_poses[k]);
  const auto params = IntegrationParams<S>::refined();
  const Image<S, B>* no_weights = nullptr;
  for (std::size_t k = 0; k < far_poses.size(); ++k) {
    integrate(dense, near_frames[k], camera, near_poses[k], no_weights, params);
    integrate(sparse, far_frames[k], camera, far_poses[k], no_weights, params);
  }
  // Far from the origin, the box of the blocks is far too.
  CHECK(sparse.block_min()[0] * 0.08 > 9.0);
  for (const std::size_t k : {std::size_t(1), std::size_t(4)}) {
    RaycastResult<S, B> near, far;
    raycast(dense, camera, near_poses[k], near);
    raycast(sparse, camera, far_poses[k], far);
    const RenderComparison c = compare_renderings(near, far);
    INFO("view " << k << ": " << c);
    CHECK(c.both > 3000);
    CHECK(c.misses_with_depth == 0);
    // Rays that graze the sphere's silhouette hit or miss by where their
    // samples fall, and the two marches start from different places (the
    // grid's face, a block's face): up to 0.33 % of the hits (12 pixels)
    // since the march steps half the SDF value (docs/decisions.md,
    // "Raycasting"), 0.2 % before.
    CHECK(c.share_only_a() < 0.005);
    CHECK(c.share_only_b() < 0.005);
    // 10 m out, float positions carry rounding of about 1e-6 m.
    CHECK(c.depth_quantile(0.5) < (sizeof(S) <= 4 ? 2e-5 : 2e-6));
    CHECK(c.depth_quantile(0.99) < (sizeof(S) <= 4 ? 2e-4 : 3e-5));
    CHECK(c.share_apart(1e-3) < 0.003);
    CHECK(c.cosine_quantile(0.01) > 0.999);
  }
}

TEMPLATE_LIST_TEST_CASE("Sparse marching cubes: a closed sphere across block borders, negative blocks included",
                        "[volume]", emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // A sphere around a point near the origin of the volume frame: its blocks
  // have coordinates of both signs on every axis, and it crosses block
  // borders everywhere.
  const S r = S(0.3);
  const SphereSdf<S> sphere{vec3(S(-0.0213), S(0.0187), S(0.0041)), r};
  SparseTsdfVolume<S, B> sparse(S(0.01), S(0.05), SE3<S>::identity(), 4096);
  fill_sparse(sparse, sphere, Vec3i{{-6, -6, -6}}, Vec3i{{5, 5, 5}}, S(0.05) + S(0.08));
  REQUIRE(sparse.block_min()[0] < 0);
  REQUIRE(sparse.block_max()[0] >= 0);
  const TriangleMesh<S> mesh = marching_cubes(sparse);
  REQUIRE(!mesh.empty());
  const EdgeCounts edges = count_edges(mesh);
  CHECK(edges.closed());
  CHECK(edges.boundary == 0);
  CHECK(edges.nonmanifold == 0);
  CHECK(std::int64_t(mesh.vertices.size()) - std::int64_t(edges.interior) + std::int64_t(mesh.triangles.size()) == 2);
  const double exact_area = 4 * M_PI * double(r) * double(r);
  const double exact_volume = 4.0 / 3.0 * M_PI * double(r) * double(r) * double(r);
  CHECK(std::fabs(surface_area(mesh) - exact_area) < 0.01 * exact_area);
  CHECK(std::fabs(enclosed_volume(mesh) - exact_volume) < 0.01 * exact_volume);
  double worst = 0;
  for (const auto& v : mesh.vertices) worst = std::max(worst, std::fabs(double(norm(v - sphere.centre) - r)));
  CHECK(worst < 0.05 * 0.01);
  // No vertex twice: each crossed grid edge once.
  CHECK(mesh_sets(mesh).vertices.size() == mesh.vertices.size());

  // The same sphere in a dense grid whose voxels coincide with the sparse
  // ones (the dense frame is the sparse frame moved by -40 voxels): the
  // same number of triangles and vertices, the same surface.
  constexpr int n = 80;
  VolumeGeometry<S> g;
  g.dims = Vec3i{{n, n, n}};
  g.voxel_size = S(0.01);
  g.truncation = S(0.05);
  g.T_world_volume = SE3<S>::translation(Vec3<S>::constant(S(-0.4)));
  TsdfVolume<S, B> dense(g);
  const auto sparse_host = sparse.template to<Host>();
  std::vector<S> sdf(std::size_t(n * n * n)), weight(sdf.size(), S(1));
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const Vec3<S> p = sparse_host.view().voxel_center(x - n / 2, y - n / 2, z - n / 2);
        sdf[std::size_t((z * n + y) * n + x)] = clamp(sphere(p), -g.truncation, g.truncation);
      }
  dense.assign_from_host(sdf, weight);
  const TriangleMesh<S> reference = marching_cubes(dense);
  CHECK(reference.triangles.size() == mesh.triangles.size());
  CHECK(reference.vertices.size() == mesh.vertices.size());
  CHECK(surface_area(reference) == test::Approx(surface_area(mesh)).epsilon(1e-5));

  // A sparse volume copied to the host gives the same mesh.
  const TriangleMesh<S> on_host = marching_cubes(sparse_host);
  CHECK(on_host.triangles == mesh.triangles);
  CHECK(on_host.vertices.size() == mesh.vertices.size());
}

TEMPLATE_LIST_TEST_CASE("Sparse raycast and marching cubes: empty volumes and bad inputs", "[volume]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  SparseTsdfVolume<S, B> sparse(S(0.01), S(0), SE3<S>::identity(), 64);
  CHECK(marching_cubes(sparse).empty());
  const auto camera = render_camera<S>();
  RaycastResult<S, B> out;
  PinholeCamera<S> bad_camera = camera;
  bad_camera.fx = S(0);
  CHECK_THROWS_WITH(raycast(sparse, bad_camera, SE3<S>::identity(), out), EMF_CONTAINS("focal lengths"));
  RaycastParams<S> bad;
  bad.min_depth = S(2), bad.max_depth = S(1);
  CHECK_THROWS_WITH(raycast(sparse, camera, SE3<S>::identity(), out, bad), EMF_CONTAINS("min_depth < max_depth"));
  const Image<S, B> wrong(camera.width + 1, camera.height, S(1));
  CHECK_THROWS_WITH(raycast(sparse, camera, SE3<S>::identity(), out, {},
                            static_cast<const ForegroundCounts<S, B>*>(nullptr), &wrong),
                    EMF_CONTAINS("ray_end image"));
  const ForegroundCounts<S, B> counts(Vec3i{{8, 8, 8}}, S(0.01));
  CHECK_THROWS_WITH(raycast(sparse, camera, SE3<S>::identity(), out, {}, &counts),
                    EMF_CONTAINS("raycast: foreground counts are per voxel of a dense TsdfVolume"));
  CHECK_THROWS_AS(raycast(sparse, camera, SE3<S>::identity(), out, {}, &counts), std::invalid_argument);
  // The dense volume keeps its own check.
  TsdfVolume<S, B> dense(test::cube_around<S>(Vec3<S>::zero(), 16, S(0.01)));
  const ForegroundCounts<S, B> other(Vec3i{{8, 8, 8}}, S(0.01));
  CHECK_THROWS_WITH(raycast(dense, camera, SE3<S>::identity(), out, {}, &other), EMF_CONTAINS("differ in size"));
  const ForegroundCounts<S, B> fitting(Vec3i{{16, 16, 16}}, S(0.01));
  CHECK_NOTHROW(raycast(dense, camera, SE3<S>::identity(), out, {}, &fitting));
}
