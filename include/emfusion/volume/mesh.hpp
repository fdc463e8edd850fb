// Host-side indexed triangle meshes, as produced by marching cubes and written
// to PLY, and the few measurements that tests and evaluation need from them.
//
// Triangles are wound counter-clockwise seen from the side their normal
// points to; for a surface extracted from an SDF that is the outside
// (positive SDF), so a closed mesh encloses a positive volume.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "emfusion/core/math.hpp"
#include "emfusion/core/se3.hpp"

namespace emfusion {

template <class S>
struct TriangleMesh {
  using Scalar = S;

  std::vector<Vec3<S>> vertices;
  /// One unit normal per vertex, or none at all.
  std::vector<Vec3<S>> normals;
  /// Vertex indices, counter-clockwise seen from the outside.
  std::vector<std::array<int, 3>> triangles;

  bool empty() const { return triangles.empty(); }
  bool has_normals() const { return !normals.empty(); }
};

/// The mesh with every vertex mapped by T_b_a (normals rotated), e.g.
/// `transformed(mesh, volume.pose())` takes a volume-frame mesh to the world.
template <class S>
TriangleMesh<S> transformed(TriangleMesh<S> mesh, const SE3<S>& T_b_a) {
  for (auto& v : mesh.vertices) v = T_b_a * v;
  for (auto& n : mesh.normals) n = T_b_a.rotate(n);
  return mesh;
}

/// Sum of the triangle areas (accumulated in double).
template <class S>
double surface_area(const TriangleMesh<S>& mesh) {
  double area = 0;
  for (const auto& t : mesh.triangles) {
    const Vec3d a = mesh.vertices[t[0]].template cast<double>();
    const Vec3d b = mesh.vertices[t[1]].template cast<double>();
    const Vec3d c = mesh.vertices[t[2]].template cast<double>();
    area += 0.5 * norm(cross(b - a, c - a));
  }
  return area;
}

/// Volume enclosed by a closed mesh by the divergence theorem: positive when
/// the triangles face outwards, negative when they face inwards. Meaningless
/// for open meshes (it then depends on the origin).
template <class S>
double enclosed_volume(const TriangleMesh<S>& mesh) {
  // Accumulated relative to the first vertex, which keeps the terms small
  // when the mesh is far from the origin.
  if (mesh.triangles.empty()) return 0;
  const Vec3d origin = mesh.vertices[mesh.triangles[0][0]].template cast<double>();
  double six_volume = 0;
  for (const auto& t : mesh.triangles) {
    const Vec3d a = mesh.vertices[t[0]].template cast<double>() - origin;
    const Vec3d b = mesh.vertices[t[1]].template cast<double>() - origin;
    const Vec3d c = mesh.vertices[t[2]].template cast<double>() - origin;
    six_volume += dot(a, cross(b, c));
  }
  return six_volume / 6;
}

/// Counts of the mesh's edges by how they are shared, from the triangles'
/// vertex indices alone.
struct EdgeCounts {
  std::size_t interior = 0;     ///< in two triangles that traverse it in opposite directions
  std::size_t boundary = 0;     ///< in one triangle only
  std::size_t nonmanifold = 0;  ///< in three or more, or twice in the same direction

  /// Every edge is shared by exactly two consistently oriented triangles.
  bool closed() const { return boundary == 0 && nonmanifold == 0 && interior > 0; }
};

template <class S>
EdgeCounts count_edges(const TriangleMesh<S>& mesh) {
  // Directed edges sorted by their undirected key: the two halves of an
  // interior edge end up next to each other.
  struct HalfEdge {
    std::uint64_t key;
    bool forward;  // from the lower to the higher vertex index
  };
  std::vector<HalfEdge> half_edges;
  half_edges.reserve(3 * mesh.triangles.size());
  for (const auto& t : mesh.triangles)
    for (int i = 0; i < 3; ++i) {
      const auto a = std::uint32_t(t[i]), b = std::uint32_t(t[(i + 1) % 3]);
      const auto lo = std::min(a, b), hi = std::max(a, b);
      half_edges.push_back({(std::uint64_t(lo) << 32) | hi, a < b});
    }
  std::sort(half_edges.begin(), half_edges.end(), [](const HalfEdge& x, const HalfEdge& y) { return x.key < y.key; });
  EdgeCounts counts;
  for (std::size_t i = 0; i < half_edges.size();) {
    std::size_t j = i;
    int forward = 0;
    for (; j < half_edges.size() && half_edges[j].key == half_edges[i].key; ++j) forward += half_edges[j].forward;
    const std::size_t n = j - i;
    if (n == 1)
      ++counts.boundary;
    else if (n == 2 && forward == 1)
      ++counts.interior;
    else
      ++counts.nonmanifold;
    i = j;
  }
  return counts;
}

}  // namespace emfusion
