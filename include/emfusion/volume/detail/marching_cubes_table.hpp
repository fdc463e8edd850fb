// The marching cubes case table, generated at compile time from the cube's
// geometry rather than written out by hand.
//
// A cell is the cube between eight neighbouring voxel centres. Corner k sits at
// offset (k & 1, (k >> 1) & 1, (k >> 2) & 1), the bit order TsdfView uses for
// trilinear samples. Edge e runs along axis e / 4 from its lower corner to the
// corner one step further along that axis; the four edges of an axis are
// numbered in the order of their lower corners.
//
// For each of the 256 inside/outside patterns the generator cuts every cube
// face into inside and outside parts with straight segments between the
// midpoints of the face's crossed edges, chains the segments into closed
// loops, and fans each loop into triangles. On a face whose inside corners are
// diagonal to each other the cut is ambiguous; the generator always keeps the
// diagonal through the face's lowest corner joined and cuts off the other two
// corners. That rule depends only on where the face is, so the two cells that
// share a face cut it the same way (the mesh is watertight), and it does not
// depend on which diagonal is inside, so flipping every sign gives the same
// surface with the opposite orientation.
#pragma once

#include <cstdint>

#include "emfusion/core/host_device.hpp"

namespace emfusion::detail {

/// An edge of a cell: its lower corner, the corner one step along `axis`.
struct CellEdge {
  int lower;
  int upper;
  int axis;
};

/// Edge e of a cell (0 <= e < 12).
EMF_HD constexpr CellEdge cell_edge(int e) {
  const int axis = e / 4, rank = e % 4;
  // Spread the two-bit rank over the corner bits other than `axis`.
  const int low_bits = (1 << axis) - 1;
  const int lower = (rank & low_bits) | ((rank >> axis) << (axis + 1));
  return {lower, lower | (1 << axis), axis};
}

/// The edge between two corners that differ in one bit.
constexpr int edge_between(int a, int b) {
  const int lower = a < b ? a : b;
  const int bit = a ^ b;
  const int axis = bit == 1 ? 0 : (bit == 2 ? 1 : 2);
  const int low_bits = (1 << axis) - 1;
  return axis * 4 + ((lower & low_bits) | ((lower >> (axis + 1)) << axis));
}

struct MarchingCubesTable {
  /// A loop through all 12 edges fans into 10 triangles; more loops give fewer.
  static constexpr int max_triangles = 10;
  static constexpr int case_count = 256;

  /// Triangles of each case; bit k of the case index set means corner k is
  /// inside (below the iso value).
  std::int8_t triangle_count[case_count];
  /// Edge indices, three per triangle, wound so that the right-hand normal
  /// points to the outside (above the iso value); -1 after the last.
  std::int8_t edges[case_count][3 * max_triangles];
  /// False if the generator found a face cut that does not close into loops;
  /// checked by a static_assert below, so it is true in any build.
  bool consistent;
};

namespace marching_cubes_generator {

struct Int3 {
  int x, y, z;
};
constexpr Int3 operator-(Int3 a, Int3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
constexpr Int3 cross(Int3 a, Int3 b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
constexpr int dot(Int3 a, Int3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
constexpr int component(Int3 a, int axis) { return axis == 0 ? a.x : (axis == 1 ? a.y : a.z); }

/// Corner and edge-midpoint positions in units of half a cell, so that both
/// are integers and the orientation tests below are exact.
constexpr Int3 corner_position(int k) { return {2 * (k & 1), 2 * ((k >> 1) & 1), 2 * ((k >> 2) & 1)}; }
constexpr Int3 edge_midpoint(int e) {
  const CellEdge edge = cell_edge(e);
  Int3 p = corner_position(edge.lower);
  if (edge.axis == 0) p.x += 1;
  if (edge.axis == 1) p.y += 1;
  if (edge.axis == 2) p.z += 1;
  return p;
}

struct Case {
  int next[12];  // the edge a segment leaving this edge goes to; -1 if none
  bool consistent;
};

/// Records the face segment between crossed edges e1 and e2, directed so that
/// the inside is on its right seen from outside the cube. A surface patch
/// whose boundary runs that way around it has its right-hand normal pointing
/// from the inside to the outside.
constexpr void add_segment(Case& c, int inside_bits, Int3 face_normal, int e1, int e2) {
  const CellEdge edge = cell_edge(e1);
  const int inside_corner = (inside_bits >> edge.lower) & 1 ? edge.lower : edge.upper;
  const Int3 p = edge_midpoint(e1), q = edge_midpoint(e2);
  const int side = dot(face_normal, cross(q - p, corner_position(inside_corner) - p));
  if (side == 0) c.consistent = false;
  const int from = side < 0 ? e1 : e2, to = side < 0 ? e2 : e1;
  if (c.next[from] != -1) c.consistent = false;
  c.next[from] = to;
}

/// Cuts face (axis, side) of case `inside_bits` into segments.
constexpr void cut_face(Case& c, int inside_bits, int axis, int side) {
  const int u = (axis + 1) % 3, v = (axis + 2) % 3;
  const int base = side << axis;
  // The face's corners in order around it, starting at its lowest corner.
  const int ring[4] = {base, base | (1 << u), base | (1 << u) | (1 << v), base | (1 << v)};
  int crossed[4] = {};  // ring edge i joins ring[i] and ring[i + 1]
  int crossed_count = 0;
  for (int i = 0; i < 4; ++i) {
    const int a = ring[i], b = ring[(i + 1) % 4];
    if (((inside_bits >> a) & 1) != ((inside_bits >> b) & 1)) crossed[crossed_count++] = i;
  }
  Int3 normal{0, 0, 0};
  const int sign = side == 1 ? 1 : -1;
  if (axis == 0) normal.x = sign;
  if (axis == 1) normal.y = sign;
  if (axis == 2) normal.z = sign;
  int ring_edge[4] = {};
  for (int i = 0; i < 4; ++i) ring_edge[i] = edge_between(ring[i], ring[(i + 1) % 4]);
  if (crossed_count == 2) {
    add_segment(c, inside_bits, normal, ring_edge[crossed[0]], ring_edge[crossed[1]]);
  } else if (crossed_count == 4) {
    // Ambiguous face: keep ring[0] and ring[2] joined, cut off ring[1]
    // (between ring edges 0 and 1) and ring[3] (between ring edges 2 and 3).
    add_segment(c, inside_bits, normal, ring_edge[0], ring_edge[1]);
    add_segment(c, inside_bits, normal, ring_edge[2], ring_edge[3]);
  } else if (crossed_count != 0) {
    c.consistent = false;
  }
}

constexpr MarchingCubesTable generate() {
  MarchingCubesTable table{};
  table.consistent = true;
  for (int inside_bits = 0; inside_bits < MarchingCubesTable::case_count; ++inside_bits) {
    Case c{};
    c.consistent = true;
    for (int e = 0; e < 12; ++e) c.next[e] = -1;
    for (int axis = 0; axis < 3; ++axis)
      for (int side = 0; side < 2; ++side) cut_face(c, inside_bits, axis, side);

    bool crossed[12] = {};
    for (int e = 0; e < 12; ++e) {
      const CellEdge edge = cell_edge(e);
      crossed[e] = ((inside_bits >> edge.lower) & 1) != ((inside_bits >> edge.upper) & 1);
      // Every crossed edge lies on two faces and must start exactly one segment.
      if (crossed[e] != (c.next[e] != -1)) c.consistent = false;
    }

    std::int8_t* out = table.edges[inside_bits];
    for (int i = 0; i < 3 * MarchingCubesTable::max_triangles; ++i) out[i] = -1;
    int triangles = 0;
    bool visited[12] = {};
    for (int start = 0; start < 12 && c.consistent; ++start) {
      if (!crossed[start] || visited[start]) continue;
      int loop[12] = {};
      int length = 0;
      int e = start;
      while (e >= 0 && !visited[e]) {
        visited[e] = true;
        loop[length++] = e;
        e = c.next[e];
      }
      if (e != start || length < 3) c.consistent = false;
      for (int i = 1; i + 1 < length && triangles < MarchingCubesTable::max_triangles; ++i, ++triangles) {
        out[3 * triangles + 0] = std::int8_t(loop[0]);
        out[3 * triangles + 1] = std::int8_t(loop[i]);
        out[3 * triangles + 2] = std::int8_t(loop[i + 1]);
      }
    }
    table.triangle_count[inside_bits] = std::int8_t(triangles);
    if (!c.consistent) table.consistent = false;
  }
  return table;
}

}  // namespace marching_cubes_generator

inline constexpr MarchingCubesTable marching_cubes_table = marching_cubes_generator::generate();
static_assert(marching_cubes_table.consistent, "the marching cubes face cuts must close into loops");
static_assert(marching_cubes_table.triangle_count[0] == 0 && marching_cubes_table.triangle_count[255] == 0,
              "a cell entirely inside or outside has no surface");

}  // namespace emfusion::detail
