// Surface extraction from a TSDF volume by marching cubes, on any backend,
// giving an indexed, watertight host mesh in the volume frame.
//
// Cells are the cubes between eight neighbouring voxel centres. A cell takes
// part only if all eight voxels are observed (weight above `min_weight`):
// the SDF of unobserved voxels is the reset value, not a measurement, and a
// crossing against it would be a phantom surface.
//
// Each vertex lies on a grid edge between two voxel centres and is named by
// that edge (voxel index * 3 + axis). Neighbouring cells compute the same
// name for a shared vertex, so welding by name is exact: the mesh has one
// vertex per crossed grid edge and, where the observed region is closed, no
// boundary. Vertices come out sorted by that name, so the result does not
// depend on the backend or on thread scheduling.
//
// Stages, each a data-parallel loop: count triangles per cell; compact the
// cells that have any and scan their counts into output offsets; write each
// triangle's three edge names; sort and deduplicate the names (the vertices)
// and look up each corner's vertex (the triangles); place each vertex on its
// edge and take its normal from the SDF gradient.
#pragma once

#include <array>
#include <climits>
#include <cstdint>
#include <string>
#include <vector>

#include <thrust/binary_search.h>
#include <thrust/copy.h>
#include <thrust/count.h>
#include <thrust/iterator/counting_iterator.h>
#include <thrust/sort.h>
#include <thrust/transform_scan.h>
#include <thrust/unique.h>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/error.hpp"
#include "emfusion/core/host_device.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/volume/detail/marching_cubes_table.hpp"
#include "emfusion/volume/mesh.hpp"
#include "emfusion/volume/tsdf_volume.hpp"

namespace emfusion {

namespace detail {

/// The case table as kernels see it: triangle counts (256) followed by the
/// edge lists (256 x 3 * max_triangles), in one backend vector.
struct MarchingCubesTableView {
  const std::int8_t* entries = nullptr;

  EMF_HD int triangle_count(int c) const { return entries[c]; }
  EMF_HD int edge(int c, int corner_of_case) const {
    return entries[MarchingCubesTable::case_count + c * 3 * MarchingCubesTable::max_triangles + corner_of_case];
  }
};

inline std::vector<std::int8_t> marching_cubes_table_entries() {
  constexpr int n = MarchingCubesTable::case_count;
  constexpr int per_case = 3 * MarchingCubesTable::max_triangles;
  std::vector<std::int8_t> entries(n + n * per_case);
  for (int c = 0; c < n; ++c) {
    entries[c] = marching_cubes_table.triangle_count[c];
    for (int i = 0; i < per_case; ++i) entries[n + c * per_case + i] = marching_cubes_table.edges[c][i];
  }
  return entries;
}

/// What every stage needs to know about the grid of cells.
template <class S, class Store>
struct MarchingCubesGrid {
  TsdfView<S, const Store> volume;
  MarchingCubesTableView table;
  S iso;
  S min_weight;

  EMF_HD std::int64_t cell_count() const {
    return std::int64_t(volume.nx - 1) * std::int64_t(volume.ny - 1) * std::int64_t(volume.nz - 1);
  }
  EMF_HD void cell_origin(std::int64_t cell, int& x, int& y, int& z) const {
    const std::int64_t cells_x = volume.nx - 1, cells_y = volume.ny - 1;
    x = int(cell % cells_x);
    const std::int64_t rest = cell / cells_x;
    y = int(rest % cells_y);
    z = int(rest / cells_y);
  }
  EMF_HD bool observed(std::int64_t voxel) const { return S(volume.weight[voxel]) > min_weight; }

  /// The case index of a cell, or -1 if one of its voxels is unobserved.
  EMF_HD int cell_case(int x, int y, int z) const {
    std::int64_t voxels[8];
    int inside_bits = 0;
    for (int k = 0; k < 8; ++k) {
      voxels[k] = volume.index(x + (k & 1), y + ((k >> 1) & 1), z + ((k >> 2) & 1));
      if (S(volume.sdf[voxels[k]]) < iso) inside_bits |= 1 << k;
    }
    // Most cells are far from the surface: decide those without reading
    // the weights, which halves the memory traffic of the counting pass.
    if (inside_bits == 0 || inside_bits == 255) return inside_bits;
    for (int k = 0; k < 8; ++k)
      if (!observed(voxels[k])) return -1;
    return inside_bits;
  }

  /// Name of cell edge e of the cell at (x, y, z): its lower voxel * 3 + axis.
  EMF_HD std::int64_t edge_key(int x, int y, int z, int e) const {
    const CellEdge edge = cell_edge(e);
    const std::int64_t voxel =
        volume.index(x + (edge.lower & 1), y + ((edge.lower >> 1) & 1), z + ((edge.lower >> 2) & 1));
    return voxel * 3 + edge.axis;
  }
};

template <class S, class Store>
struct CountCellTriangles {
  MarchingCubesGrid<S, Store> grid;
  std::uint8_t* counts;

  EMF_HD void operator()(std::int64_t cell) const {
    int x, y, z;
    grid.cell_origin(cell, x, y, z);
    const int c = grid.cell_case(x, y, z);
    counts[cell] = std::uint8_t(c < 0 ? 0 : grid.table.triangle_count(c));
  }
};

struct IsNonZero {
  EMF_HD bool operator()(std::uint8_t count) const { return count != 0; }
};

struct CountOfCell {
  const std::uint8_t* counts;
  EMF_HD std::int64_t operator()(std::int64_t cell) const { return counts[cell]; }
};

struct SumInt64 {
  EMF_HD std::int64_t operator()(std::int64_t a, std::int64_t b) const { return a + b; }
};

template <class S, class Store>
struct WriteCellTriangles {
  MarchingCubesGrid<S, Store> grid;
  const std::int64_t* active_cells;
  const std::int64_t* triangle_ends;  // inclusive scan of the active cells' counts
  std::int64_t* corner_keys;          // three per triangle

  EMF_HD void operator()(std::int64_t i) const {
    int x, y, z;
    grid.cell_origin(active_cells[i], x, y, z);
    const int c = grid.cell_case(x, y, z);
    const int count = grid.table.triangle_count(c);
    std::int64_t* out = corner_keys + 3 * (triangle_ends[i] - count);
    for (int j = 0; j < 3 * count; ++j) out[j] = grid.edge_key(x, y, z, grid.table.edge(c, j));
  }
};

template <class S, class Store>
struct PlaceEdgeVertices {
  MarchingCubesGrid<S, Store> grid;
  const std::int64_t* keys;
  Vec3<S>* vertices;
  Vec3<S>* normals;

  EMF_HD void operator()(std::int64_t i) const {
    const auto& v = grid.volume;
    const std::int64_t key = keys[i];
    const int axis = int(key % 3);
    const std::int64_t voxel = key / 3;
    int lower[3] = {int(voxel % v.nx), int((voxel / v.nx) % v.ny), int(voxel / (std::int64_t(v.nx) * v.ny))};
    int upper[3] = {lower[0], lower[1], lower[2]};
    ++upper[axis];
    const S a = S(v.sdf[voxel]);
    const S b = S(v.sdf[v.index(upper[0], upper[1], upper[2])]);
    // The edge is crossed, so a != b and t lies in (0, 1].
    const S t = (grid.iso - a) / (b - a);
    Vec3<S> p = v.voxel_center(lower[0], lower[1], lower[2]);
    p[axis] += t * v.voxel_size;
    vertices[i] = p;

    Vec3<S> g = (S(1) - t) * voxel_gradient(lower) + t * voxel_gradient(upper);
    if (!(squared_norm(g) > S(0))) {
      // Flat neighbourhood: the edge itself still says which way is out.
      g = Vec3<S>::zero();
      g[axis] = b > a ? S(1) : S(-1);
    }
    normals[i] = normalized(g);
  }

  /// SDF gradient at a voxel centre by central differences, one-sided where
  /// a neighbour is missing or unobserved; zero along an axis with neither.
  EMF_HD Vec3<S> voxel_gradient(const int* at) const {
    const auto& v = grid.volume;
    const S centre = S(v.sdf[v.index(at[0], at[1], at[2])]);
    Vec3<S> g = Vec3<S>::zero();
    for (int axis = 0; axis < 3; ++axis) {
      int lo[3] = {at[0], at[1], at[2]}, hi[3] = {at[0], at[1], at[2]};
      --lo[axis];
      ++hi[axis];
      const bool has_lo = v.contains_voxel(lo[0], lo[1], lo[2]) && grid.observed(v.index(lo[0], lo[1], lo[2]));
      const bool has_hi = v.contains_voxel(hi[0], hi[1], hi[2]) && grid.observed(v.index(hi[0], hi[1], hi[2]));
      const S below = has_lo ? S(v.sdf[v.index(lo[0], lo[1], lo[2])]) : centre;
      const S above = has_hi ? S(v.sdf[v.index(hi[0], hi[1], hi[2])]) : centre;
      const int steps = int(has_lo) + int(has_hi);
      if (steps > 0) g[axis] = (above - below) / (S(steps) * v.voxel_size);
    }
    return g;
  }
};

}  // namespace detail

/// Extracts the iso-surface SDF = `iso` of the observed part of `volume` as
/// an indexed triangle mesh in the VOLUME frame (use
/// `transformed(mesh, volume.pose())` for the world frame), with unit
/// normals from the SDF gradient and triangles facing the positive side.
/// Cells with any voxel of weight <= `min_weight` are skipped.
template <class S, Backend B, class Store>
TriangleMesh<S> marching_cubes(const TsdfVolume<S, B, Store>& volume, S iso = S(0), S min_weight = S(0)) {
  using Index = std::int64_t;
  const B& backend = volume.backend();
  const auto policy = backend.policy();
  TriangleMesh<S> mesh;

  const std::vector<std::int8_t> host_table = detail::marching_cubes_table_entries();
  const typename B::template Vector<std::int8_t> table_entries(host_table.begin(), host_table.end());
  detail::MarchingCubesGrid<S, Store> grid{
      volume.view(), {thrust::raw_pointer_cast(table_entries.data())}, iso, min_weight};
  const Index cells = grid.cell_count();
  if (cells <= 0) return mesh;

  // Triangle corners as the names of the grid edges they lie on.
  typename B::template Vector<Index> corner_keys;
  Index triangle_count = 0;
  {
    typename B::template Vector<std::uint8_t> counts(cells);
    for_each_index(backend, cells, detail::CountCellTriangles<S, Store>{grid, thrust::raw_pointer_cast(counts.data())});
    const Index active_count = thrust::count_if(policy, counts.begin(), counts.end(), detail::IsNonZero{});
    if (active_count == 0) return mesh;

    typename B::template Vector<Index> active(active_count);
    thrust::copy_if(policy, thrust::counting_iterator<Index>(0), thrust::counting_iterator<Index>(cells),
                    counts.begin(), active.begin(), detail::IsNonZero{});
    typename B::template Vector<Index> ends(active_count);
    thrust::transform_inclusive_scan(policy, active.begin(), active.end(), ends.begin(),
                                     detail::CountOfCell{thrust::raw_pointer_cast(counts.data())}, detail::SumInt64{});
    backend.synchronize();
    triangle_count = ends.back();
    detail::require(
        3 * triangle_count <= Index(INT_MAX), "marching_cubes",
        "the surface has " + std::to_string(triangle_count) + " triangles, too many for int vertex indices");

    corner_keys.resize(3 * triangle_count);
    for_each_index(backend, active_count,
                   detail::WriteCellTriangles<S, Store>{grid, thrust::raw_pointer_cast(active.data()),
                                                        thrust::raw_pointer_cast(ends.data()),
                                                        thrust::raw_pointer_cast(corner_keys.data())});
  }

  // Welding: one vertex per distinct edge name.
  typename B::template Vector<Index> vertex_keys = corner_keys;
  thrust::sort(policy, vertex_keys.begin(), vertex_keys.end());
  const Index vertex_count = thrust::unique(policy, vertex_keys.begin(), vertex_keys.end()) - vertex_keys.begin();
  vertex_keys.resize(vertex_count);
  typename B::template Vector<int> corners(3 * triangle_count);
  thrust::lower_bound(policy, vertex_keys.begin(), vertex_keys.end(), corner_keys.begin(), corner_keys.end(),
                      corners.begin());

  typename B::template Vector<Vec3<S>> vertices(vertex_count), normals(vertex_count);
  for_each_index(backend, vertex_count,
                 detail::PlaceEdgeVertices<S, Store>{grid, thrust::raw_pointer_cast(vertex_keys.data()),
                                                     thrust::raw_pointer_cast(vertices.data()),
                                                     thrust::raw_pointer_cast(normals.data())});
  backend.synchronize();

  mesh.vertices.resize(std::size_t(vertex_count));
  mesh.normals.resize(std::size_t(vertex_count));
  thrust::copy(vertices.begin(), vertices.end(), mesh.vertices.begin());
  thrust::copy(normals.begin(), normals.end(), mesh.normals.begin());
  std::vector<int> host_corners(std::size_t(3 * triangle_count));
  thrust::copy(corners.begin(), corners.end(), host_corners.begin());
  mesh.triangles.resize(std::size_t(triangle_count));
  for (std::size_t i = 0; i < mesh.triangles.size(); ++i)
    mesh.triangles[i] = {host_corners[3 * i], host_corners[3 * i + 1], host_corners[3 * i + 2]};
  return mesh;
}

}  // namespace emfusion
