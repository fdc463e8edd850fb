// Marching cubes: the generated case table checked case by case, then
// surfaces extracted from volumes filled with analytic SDFs (sphere, rotated
// box) checked for area, enclosed volume, orientation, watertightness and
// normals, and the handling of unobserved voxels.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <set>
#include <utility>
#include <vector>

#include "emfusion/core/parallel.hpp"
#include "emfusion/volume/marching_cubes.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"

using namespace emfusion;

namespace {

// ---- analytic SDFs ---------------------------------------------------------

template <class S>
struct SphereSdf {
  Vec3<S> centre;
  S radius;
  EMF_HD S operator()(const Vec3<S>& p) const { return norm(p - centre) - radius; }
};

/// Exact SDF of a box with half extents `half`, placed by T_box_volume.
template <class S>
struct BoxSdf {
  SE3<S> T_box_volume;
  Vec3<S> half;
  EMF_HD S operator()(const Vec3<S>& p_volume) const {
    const Vec3<S> p = T_box_volume * p_volume;
    Vec3<S> outside = Vec3<S>::zero();
    S inside = -half[0] - half[1] - half[2];
    for (int a = 0; a < 3; ++a) {
      const S q = std::fabs(p[a]) - half[a];
      outside[a] = q > S(0) ? q : S(0);
      inside = q > inside ? q : inside;
    }
    return norm(outside) + (inside < S(0) ? inside : S(0));
  }
};

/// Writes sign * sdf(voxel centre), clamped to the truncation band, into every
/// voxel; voxels with x below `first_observed_x` get weight 0 (unobserved).
template <class S, class Sdf>
struct FillVolume {
  TsdfView<S> volume;
  Sdf sdf;
  S sign;
  int first_observed_x;
  EMF_HD void operator()(std::int64_t i) const {
    const int x = int(i % volume.nx);
    const int y = int((i / volume.nx) % volume.ny);
    const int z = int(i / (std::int64_t(volume.nx) * volume.ny));
    const S d = sign * sdf(volume.voxel_center(x, y, z));
    volume.sdf[i] = clamp(d, -volume.truncation, volume.truncation);
    volume.weight[i] = x < first_observed_x ? S(0) : S(1);
  }
};

template <class S, class B, class Sdf>
void fill(TsdfVolume<S, B>& volume, const Sdf& sdf, S sign = S(1), int first_observed_x = 0) {
  for_each_index(volume.backend(), volume.voxel_count(),
                 FillVolume<S, Sdf>{volume.view(), sdf, sign, first_observed_x});
  volume.backend().synchronize();
}

template <class S>
VolumeGeometry<S> cube_geometry(int n, S voxel) {
  VolumeGeometry<S> g;
  g.dims = Vec3i{{n, n, n}};
  g.voxel_size = voxel;
  return g;
}

/// A point a little off the voxel lattice, so that no voxel centre lies
/// exactly on the surface.
template <class S>
Vec3<S> centre_of_64_cm_cube() {
  return vec3(S(0.3213), S(0.3187), S(0.3241));
}

double relative_error(double value, double expected) { return std::fabs(value - expected) / std::fabs(expected); }

// ---- table helpers ---------------------------------------------------------

using Segment = std::pair<int, int>;  // directed, between two cell edges

/// Triangle edges of one case that are not shared with another triangle of
/// the case: the cuts through the cube faces.
std::set<Segment> boundary_segments(int c) {
  const auto& table = detail::marching_cubes_table;
  std::multiset<Segment> directed;
  for (int t = 0; t < table.triangle_count[c]; ++t)
    for (int i = 0; i < 3; ++i) directed.insert({table.edges[c][3 * t + i], table.edges[c][3 * t + (i + 1) % 3]});
  std::set<Segment> boundary;
  for (const auto& s : directed)
    if (directed.count({s.second, s.first}) == 0) boundary.insert(s);
  return boundary;
}

bool crossed(int c, int e) {
  const auto edge = detail::cell_edge(e);
  return ((c >> edge.lower) & 1) != ((c >> edge.upper) & 1);
}

/// The face (axis, side) both ends of a segment lie on, or -1.
int common_face(const Segment& s) {
  const auto a = detail::cell_edge(s.first), b = detail::cell_edge(s.second);
  for (int axis = 0; axis < 3; ++axis)
    for (int side = 0; side < 2; ++side) {
      const auto on_face = [&](const detail::CellEdge& e) { return e.axis != axis && ((e.lower >> axis) & 1) == side; };
      if (on_face(a) && on_face(b)) return 2 * axis + side;
    }
  return -1;
}

}  // namespace

// ---- the case table ---------------------------------------------------------

TEST_CASE("marching cubes table: empty cases, crossed edges only, closed per case", "[volume]") {
  const auto& table = detail::marching_cubes_table;
  REQUIRE(table.consistent);
  CHECK(table.triangle_count[0] == 0);
  CHECK(table.triangle_count[255] == 0);
  for (int c = 0; c < 256; ++c) {
    INFO("case " << c);
    const int n = table.triangle_count[c];
    REQUIRE(n <= detail::MarchingCubesTable::max_triangles);
    std::set<int> used;
    for (int i = 0; i < 3 * n; ++i) {
      const int e = table.edges[c][i];
      REQUIRE(e >= 0);
      REQUIRE(e < 12);
      CHECK(crossed(c, e));
      used.insert(e);
    }
    for (int i = 3 * n; i < 3 * detail::MarchingCubesTable::max_triangles; ++i) CHECK(table.edges[c][i] == -1);
    // Every crossed edge carries a vertex.
    for (int e = 0; e < 12; ++e) CHECK(used.count(e) == std::size_t(crossed(c, e)));
    // The open edges of the case's triangles are cuts through cube faces.
    for (const auto& s : boundary_segments(c)) CHECK(common_face(s) >= 0);
  }
}

TEST_CASE("marching cubes table: complementary cases are the same surface reversed", "[volume]") {
  const auto& table = detail::marching_cubes_table;
  for (int c = 0; c < 256; ++c) {
    INFO("case " << c);
    CHECK(table.triangle_count[c] == table.triangle_count[255 - c]);
    std::set<Segment> reversed;
    for (const auto& s : boundary_segments(255 - c)) reversed.insert({s.second, s.first});
    CHECK(boundary_segments(c) == reversed);
  }
}

TEST_CASE("marching cubes table: cells sharing a face cut it the same way", "[volume]") {
  // Cell A's high face on `axis` is cell B's low face. Wherever the four
  // shared corners agree, A's cut must be B's cut traversed backwards (each
  // runs with the inside on its right seen from its own outside).
  for (int axis = 0; axis < 3; ++axis) {
    const int bit = 1 << axis;
    for (int a = 0; a < 256; ++a)
      for (int b = 0; b < 256; ++b) {
        bool agree = true;
        for (int k = 0; k < 8; ++k)
          if (k & bit) agree = agree && (((a >> k) & 1) == ((b >> (k ^ bit)) & 1));
        if (!agree) continue;
        std::set<Segment> cut_a, cut_b;
        for (const auto& s : boundary_segments(a))
          if (common_face(s) == 2 * axis + 1) cut_a.insert(s);
        for (const auto& s : boundary_segments(b))
          if (common_face(s) == 2 * axis) {
            // B's edge with lower corner k is A's edge with lower corner k | bit.
            const auto to_a = [&](int e) {
              const auto edge = detail::cell_edge(e);
              return detail::edge_between(edge.lower | bit, edge.upper | bit);
            };
            cut_b.insert({to_a(s.second), to_a(s.first)});
          }
        INFO("axis " << axis << ", cases " << a << " and " << b);
        REQUIRE(cut_a == cut_b);
      }
  }
}

TEST_CASE("marching cubes table: a single inside corner is cut off facing away from it", "[volume]") {
  for (int k = 0; k < 8; ++k) {
    const int c = 1 << k;
    const auto& table = detail::marching_cubes_table;
    REQUIRE(table.triangle_count[c] == 1);
    // Edge midpoints in units of half a cell; the normal must point away from
    // corner k towards the cube's centre.
    Vec3d p[3];
    for (int i = 0; i < 3; ++i) {
      const auto edge = detail::cell_edge(table.edges[c][i]);
      p[i] = vec3(double(edge.lower & 1), double((edge.lower >> 1) & 1), double((edge.lower >> 2) & 1));
      p[i][edge.axis] += 0.5;
    }
    const Vec3d corner = vec3(double(k & 1), double((k >> 1) & 1), double((k >> 2) & 1));
    const Vec3d normal = cross(p[1] - p[0], p[2] - p[0]);
    CHECK(dot(normal, vec3(0.5, 0.5, 0.5) - corner) > 0);
  }
}

// ---- surfaces of analytic SDFs ---------------------------------------------

TEMPLATE_LIST_TEST_CASE("marching cubes: sphere area, volume, orientation, closure", "[volume]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const S r = S(0.3);
  const Vec3<S> centre = centre_of_64_cm_cube<S>();
  TsdfVolume<S, B> volume(cube_geometry<S>(64, S(0.01)));
  fill(volume, SphereSdf<S>{centre, r});

  const TriangleMesh<S> mesh = marching_cubes(volume);
  REQUIRE(!mesh.empty());
  REQUIRE(mesh.normals.size() == mesh.vertices.size());

  const double area = surface_area(mesh), enclosed = enclosed_volume(mesh);
  const double exact_area = 4 * M_PI * double(r) * double(r);
  const double exact_volume = 4.0 / 3.0 * M_PI * double(r) * double(r) * double(r);
  INFO("area " << area << " (exact " << exact_area << "), volume " << enclosed << " (exact " << exact_volume << ")");
  CHECK(relative_error(area, exact_area) < 0.01);
  CHECK(enclosed > 0);  // triangles face outwards
  CHECK(relative_error(enclosed, exact_volume) < 0.01);

  const EdgeCounts edges = count_edges(mesh);
  CHECK(edges.closed());
  CHECK(edges.boundary == 0);
  CHECK(edges.nonmanifold == 0);
  // A closed triangle mesh of genus 0: V - E + F = 2.
  CHECK(std::int64_t(mesh.vertices.size()) - std::int64_t(edges.interior) + std::int64_t(mesh.triangles.size()) == 2);

  double worst_distance = 0, worst_normal_cosine = 1;
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) {
    const Vec3d p = mesh.vertices[i].template cast<double>() - centre.template cast<double>();
    worst_distance = std::max(worst_distance, std::fabs(norm(p) - double(r)));
    const Vec3d n = mesh.normals[i].template cast<double>();
    CHECK(std::fabs(norm(n) - 1) < 1e-4);
    worst_normal_cosine = std::min(worst_normal_cosine, dot(n, normalized(p)));
  }
  // Linear interpolation of an exact SDF along an edge puts vertices within
  // a small fraction of a voxel of the sphere.
  CHECK(worst_distance < 0.05 * 0.01);
  CHECK(worst_normal_cosine > 0.999);
}

TEMPLATE_LIST_TEST_CASE("marching cubes: rotated box area, volume, closure", "[volume]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const Vec3<S> half = vec3(S(0.15), S(0.1), S(0.12));
  const SE3<S> T_volume_box = SE3<S>(so3_exp(vec3(S(0.3), S(-0.2), S(0.5))), centre_of_64_cm_cube<S>());
  TsdfVolume<S, B> volume(cube_geometry<S>(64, S(0.01)));
  fill(volume, BoxSdf<S>{T_volume_box.inverse(), half});

  const TriangleMesh<S> mesh = marching_cubes(volume);
  const double exact_area =
      8 * (double(half[0]) * double(half[1]) + double(half[1]) * double(half[2]) + double(half[0]) * double(half[2]));
  const double exact_volume = 8 * double(half[0]) * double(half[1]) * double(half[2]);
  const double area = surface_area(mesh), enclosed = enclosed_volume(mesh);
  INFO("area " << area << " (exact " << exact_area << "), volume " << enclosed << " (exact " << exact_volume << ")");
  // Marching cubes bevels sharp edges by about half a voxel, which loses
  // about 0.3 voxel of area per metre of edge: 2.4 % for this 3 m of edges.
  CHECK(area < exact_area);
  CHECK(relative_error(area, exact_area) < 0.03);
  CHECK(enclosed > 0);
  CHECK(relative_error(enclosed, exact_volume) < 0.01);
  CHECK(count_edges(mesh).closed());
}

TEMPLATE_LIST_TEST_CASE("marching cubes: nothing to extract gives an empty mesh", "[volume]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;

  SECTION("a fresh volume is unobserved") {
    TsdfVolume<S, B> volume(cube_geometry<S>(16, S(0.01)));
    const auto mesh = marching_cubes(volume);
    CHECK(mesh.empty());
    CHECK(mesh.vertices.empty());
    CHECK(mesh.normals.empty());
  }
  SECTION("observed free space has no surface") {
    TsdfVolume<S, B> volume(cube_geometry<S>(16, S(0.01)));
    fill(volume, SphereSdf<S>{vec3(S(1), S(1), S(1)), S(0.1)});  // far outside the volume
    CHECK(marching_cubes(volume).empty());
  }
  SECTION("a volume one voxel thick has no cells") {
    VolumeGeometry<S> g = cube_geometry<S>(16, S(0.01));
    g.dims[2] = 1;
    TsdfVolume<S, B> volume(g);
    fill(volume, SphereSdf<S>{vec3(S(0.08), S(0.08), S(0.005)), S(0.05)});
    CHECK(marching_cubes(volume).empty());
  }
  SECTION("voxels at or below min_weight count as unobserved") {
    TsdfVolume<S, B> volume(cube_geometry<S>(16, S(0.01)));
    fill(volume, SphereSdf<S>{vec3(S(0.08), S(0.081), S(0.079)), S(0.05)});  // weight 1 everywhere
    CHECK(!marching_cubes(volume, S(0), S(0.5)).empty());
    CHECK(marching_cubes(volume, S(0), S(1)).empty());
  }
}

TEMPLATE_LIST_TEST_CASE("marching cubes: unobserved voxels produce no triangles", "[volume]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const S r = S(0.3);
  const Vec3<S> centre = centre_of_64_cm_cube<S>();
  TsdfVolume<S, B> full(cube_geometry<S>(64, S(0.01))), half(cube_geometry<S>(64, S(0.01)));
  fill(full, SphereSdf<S>{centre, r});
  const int first_observed_x = 32;
  fill(half, SphereSdf<S>{centre, r}, S(1), first_observed_x);

  const auto full_mesh = marching_cubes(full);
  const auto half_mesh = marching_cubes(half);
  REQUIRE(!half_mesh.empty());
  // Every cell used lies among observed voxel centres, x >= centre of voxel 32.
  const double x_min = (first_observed_x + 0.5) * 0.01;
  for (const auto& v : half_mesh.vertices) CHECK(double(v.x()) >= x_min - 1e-6);
  CHECK(half_mesh.triangles.size() < full_mesh.triangles.size() * 6 / 10);
  CHECK(half_mesh.triangles.size() > full_mesh.triangles.size() * 4 / 10);
  // The cut leaves one open rim where the observed region ends.
  const EdgeCounts edges = count_edges(half_mesh);
  CHECK(edges.boundary > 0);
  CHECK(edges.nonmanifold == 0);
}

TEMPLATE_LIST_TEST_CASE("marching cubes: a negated SDF gives the same surface facing the other way", "[volume]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const SE3<S> T_volume_box = SE3<S>(so3_exp(vec3(S(-0.4), S(0.1), S(0.2))), vec3(S(0.16), S(0.15), S(0.17)));
  const BoxSdf<S> box{T_volume_box.inverse(), vec3(S(0.08), S(0.05), S(0.06))};
  TsdfVolume<S, B> positive(cube_geometry<S>(32, S(0.01))), negative(cube_geometry<S>(32, S(0.01)));
  fill(positive, box);
  fill(negative, box, S(-1));

  const auto a = marching_cubes(positive);
  const auto b = marching_cubes(negative);
  REQUIRE(!a.empty());
  REQUIRE(a.vertices.size() == b.vertices.size());
  REQUIRE(a.triangles.size() == b.triangles.size());
  for (std::size_t i = 0; i < a.vertices.size(); ++i) {
    CHECK(max_abs_diff(a.vertices[i], b.vertices[i]) == S(0));
    CHECK(max_abs_diff(a.normals[i], -b.normals[i]) == S(0));
  }
  // Same triangles with the opposite winding (as sets: each is stored as
  // its rotation starting at the smallest index).
  const auto canonical = [](std::array<int, 3> t) {
    std::rotate(t.begin(), std::min_element(t.begin(), t.end()), t.end());
    return t;
  };
  std::set<std::array<int, 3>> ta, tb;
  for (const auto& t : a.triangles) ta.insert(canonical(t));
  for (const auto& t : b.triangles) tb.insert(canonical({t[0], t[2], t[1]}));
  CHECK(ta == tb);
  CHECK(enclosed_volume(b) == emfusion::test::Approx(-enclosed_volume(a)).epsilon(1e-9));
}

TEMPLATE_LIST_TEST_CASE("marching cubes: iso value, world frame and backend independence", "[volume]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const Vec3<S> centre = centre_of_64_cm_cube<S>();
  VolumeGeometry<S> g = cube_geometry<S>(64, S(0.01));
  g.T_world_volume = SE3<S>(so3_exp(vec3(S(0.1), S(0.2), S(-0.3))), vec3(S(1), S(-2), S(0.5)));
  TsdfVolume<S, B> volume(g);
  fill(volume, SphereSdf<S>{centre, S(0.25)});

  // The iso-surface SDF = 0.05 of a sphere of radius 0.25 is a sphere of 0.3.
  const auto mesh = marching_cubes(volume, S(0.05));
  CHECK(relative_error(surface_area(mesh), 4 * M_PI * 0.3 * 0.3) < 0.01);

  const auto world = transformed(mesh, volume.pose());
  Vec3d mean = Vec3d::zero(), mean_world = Vec3d::zero();
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) {
    mean += mesh.vertices[i].template cast<double>();
    mean_world += world.vertices[i].template cast<double>();
  }
  mean = mean / double(mesh.vertices.size());
  mean_world = mean_world / double(mesh.vertices.size());
  const Vec3d expected_world = (volume.pose() * mean.template cast<S>()).template cast<double>();
  CHECK(max_abs_diff(mean_world, expected_world) < 1e-4);
  CHECK(surface_area(world) == emfusion::test::Approx(surface_area(mesh)).epsilon(1e-4));
  CHECK(enclosed_volume(world) == emfusion::test::Approx(enclosed_volume(mesh)).epsilon(1e-4));

  // Vertices are named by grid edges and sorted by name, so a copy of the
  // volume on the host gives the same mesh up to rounding.
  const auto on_host = marching_cubes(volume.template to<Host>(), S(0.05));
  REQUIRE(on_host.vertices.size() == mesh.vertices.size());
  REQUIRE(on_host.triangles == mesh.triangles);
  double worst = 0;
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i)
    worst = std::max(worst, double(max_abs_diff(on_host.vertices[i], mesh.vertices[i])));
  CHECK(worst < 1e-6);
}
