// Surface extraction from a TSDF volume by marching cubes, on any backend,
// giving an indexed, watertight host mesh in the volume frame. Written once
// for the dense TsdfVolume and the SparseTsdfVolume: what differs is the grid
// of cells (every cell of the box, or the 8^3 cells whose lower corner lies
// in an allocated block, reading the voxels of neighbouring blocks across
// block borders) and how a grid edge is named.
//
// Cells are the cubes between eight neighbouring voxel centres. A cell takes
// part only if all eight voxels are observed (weight above `min_weight`):
// the SDF of unobserved voxels is the reset value, not a measurement, and a
// crossing against it would be a phantom surface. A voxel of an unallocated
// block is unobserved.
//
// Each vertex lies on a grid edge between two voxel centres and is named by
// that edge (its lower voxel's storage index * 3 + axis; in the sparse
// volume every voxel, border or not, has one storage index). Neighbouring
// cells compute the same name for a shared vertex, also across block
// borders, so welding by name is exact: the mesh has one vertex per crossed
// grid edge and, where the observed region is closed, no boundary. Each
// cell belongs to exactly one block (that of its lower corner), so no
// triangle is made twice. Vertices come out sorted by that name, so the
// result does not depend on the backend or on thread scheduling.
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
#include <type_traits>
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
#include "emfusion/volume/sparse_tsdf_volume.hpp"
#include "emfusion/volume/tsdf_volume.hpp"
#include "emfusion/volume/volume_view.hpp"

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

/// The vertex on the edge from the voxel centre `lower` one voxel along
/// `axis`, with SDF a at the lower and b at the upper end (the edge is
/// crossed, so a != b and t lies in (0, 1]).
template <class S>
EMF_HD Vec3<S> edge_vertex(Vec3<S> lower, int axis, S a, S b, S iso, S voxel_size) {
  const S t = (iso - a) / (b - a);
  lower[axis] += t * voxel_size;
  return lower;
}

/// The vertex normal: the voxel gradients at the edge's ends, interpolated.
template <class S>
EMF_HD Vec3<S> edge_normal(const Vec3<S>& g_lower, const Vec3<S>& g_upper, int axis, S a, S b, S iso) {
  const S t = (iso - a) / (b - a);
  Vec3<S> g = (S(1) - t) * g_lower + t * g_upper;
  if (!(squared_norm(g) > S(0))) {
    // Flat neighbourhood: the edge itself still says which way is out.
    g = Vec3<S>::zero();
    g[axis] = b > a ? S(1) : S(-1);
  }
  return normalized(g);
}

/// The cells of a dense volume: every cube of eight neighbouring voxels of
/// the box.
template <class S, class Store>
struct MarchingCubesGrid {
  TsdfView<S, const Store> volume;
  MarchingCubesTableView table;
  S iso;
  S min_weight;

  struct Cell {
    int x, y, z;  // lower corner voxel
  };

  EMF_HD std::int64_t cell_count() const {
    return std::int64_t(volume.nx - 1) * std::int64_t(volume.ny - 1) * std::int64_t(volume.nz - 1);
  }
  EMF_HD Cell cell(std::int64_t index) const {
    const std::int64_t cells_x = volume.nx - 1, cells_y = volume.ny - 1;
    Cell c;
    c.x = int(index % cells_x);
    const std::int64_t rest = index / cells_x;
    c.y = int(rest % cells_y);
    c.z = int(rest / cells_y);
    return c;
  }
  EMF_HD bool observed(std::int64_t voxel) const { return S(volume.weight[voxel]) > min_weight; }

  /// The case index of a cell, or -1 if one of its voxels is unobserved.
  EMF_HD int cell_case(const Cell& c) const {
    std::int64_t voxels[8];
    int inside_bits = 0;
    for (int k = 0; k < 8; ++k) {
      voxels[k] = volume.index(c.x + (k & 1), c.y + ((k >> 1) & 1), c.z + ((k >> 2) & 1));
      if (S(volume.sdf[voxels[k]]) < iso) inside_bits |= 1 << k;
    }
    // Most cells are far from the surface: decide those without reading
    // the weights, which halves the memory traffic of the counting pass.
    if (inside_bits == 0 || inside_bits == 255) return inside_bits;
    for (int k = 0; k < 8; ++k)
      if (!observed(voxels[k])) return -1;
    return inside_bits;
  }

  /// Name of cell edge e of cell c: its lower voxel * 3 + axis.
  EMF_HD std::int64_t edge_key(const Cell& c, int e) const {
    const CellEdge edge = cell_edge(e);
    const std::int64_t voxel =
        volume.index(c.x + (edge.lower & 1), c.y + ((edge.lower >> 1) & 1), c.z + ((edge.lower >> 2) & 1));
    return voxel * 3 + edge.axis;
  }

  /// The vertex on the edge named `key` and its normal.
  EMF_HD void place_vertex(std::int64_t key, Vec3<S>& vertex, Vec3<S>& normal) const {
    const auto& v = volume;
    const int axis = int(key % 3);
    const std::int64_t voxel = key / 3;
    int lower[3] = {int(voxel % v.nx), int((voxel / v.nx) % v.ny), int(voxel / (std::int64_t(v.nx) * v.ny))};
    int upper[3] = {lower[0], lower[1], lower[2]};
    ++upper[axis];
    const S a = S(v.sdf[voxel]);
    const S b = S(v.sdf[v.index(upper[0], upper[1], upper[2])]);
    vertex = edge_vertex(v.voxel_center(lower[0], lower[1], lower[2]), axis, a, b, iso, v.voxel_size);
    normal = edge_normal(voxel_gradient(lower), voxel_gradient(upper), axis, a, b, iso);
  }

  /// SDF gradient at a voxel centre by central differences, one-sided where
  /// a neighbour is missing or unobserved; zero along an axis with neither.
  EMF_HD Vec3<S> voxel_gradient(const int* at) const {
    const auto& v = volume;
    const S centre = S(v.sdf[v.index(at[0], at[1], at[2])]);
    Vec3<S> g = Vec3<S>::zero();
    for (int axis = 0; axis < 3; ++axis) {
      int lo[3] = {at[0], at[1], at[2]}, hi[3] = {at[0], at[1], at[2]};
      --lo[axis];
      ++hi[axis];
      const bool has_lo = v.contains_voxel(lo[0], lo[1], lo[2]) && observed(v.index(lo[0], lo[1], lo[2]));
      const bool has_hi = v.contains_voxel(hi[0], hi[1], hi[2]) && observed(v.index(hi[0], hi[1], hi[2]));
      const S below = has_lo ? S(v.sdf[v.index(lo[0], lo[1], lo[2])]) : centre;
      const S above = has_hi ? S(v.sdf[v.index(hi[0], hi[1], hi[2])]) : centre;
      const int steps = int(has_lo) + int(has_hi);
      if (steps > 0) g[axis] = (above - below) / (S(steps) * v.voxel_size);
    }
    return g;
  }
};

/// The cells of a sparse volume: the 8^3 cells whose lower corner voxel lies
/// in an allocated block, so that every cell belongs to one block. A cell on
/// a block's upper faces reads voxels of the neighbouring blocks, found once
/// per block beforehand (`neighbours`); a voxel of an unallocated block is
/// unobserved (SDF = truncation, weight 0, as the dense volume's reset).
template <class S, class Store>
struct SparseMarchingCubesGrid {
  SparseTsdfView<S, const Store> volume;
  const int* neighbours;  // 8 per block: the block at offset o (bits 1 -> +x, 2 -> +y, 4 -> +z), or -1
  MarchingCubesTableView table;
  S iso;
  S min_weight;

  struct Cell {
    int block;
    int x, y, z;  // lower corner, local to the block (0..7)
  };

  EMF_HD std::int64_t cell_count() const { return std::int64_t(volume.blocks) * sparse::block_voxels; }
  EMF_HD Cell cell(std::int64_t index) const {
    const int local = int(index % sparse::block_voxels);
    return {int(index / sparse::block_voxels), local & 7, (local >> 3) & 7, local >> 6};
  }
  EMF_HD bool observed(std::int64_t voxel) const { return voxel >= 0 && S(volume.weight[voxel]) > min_weight; }

  /// Storage index of the voxel at local offset (x, y, z) of cell c's block
  /// (0..8 each: 8 is the neighbouring block's first layer), or -1 if its
  /// block is not allocated.
  EMF_HD std::int64_t storage(const Cell& c, int x, int y, int z) const {
    const int o = (x >> 3) | ((y >> 3) << 1) | ((z >> 3) << 2);
    const int block = neighbours[std::int64_t(c.block) * 8 + o];
    if (block < 0) return -1;
    return std::int64_t(block) * sparse::block_voxels + sparse::local_index(x & 7, y & 7, z & 7);
  }
  EMF_HD S value(std::int64_t voxel) const { return voxel < 0 ? volume.truncation : S(volume.sdf[voxel]); }

  /// The case index of a cell, or -1 if one of its voxels is unobserved.
  EMF_HD int cell_case(const Cell& c) const {
    std::int64_t voxels[8];
    int inside_bits = 0;
    for (int k = 0; k < 8; ++k) {
      voxels[k] = storage(c, c.x + (k & 1), c.y + ((k >> 1) & 1), c.z + ((k >> 2) & 1));
      if (value(voxels[k]) < iso) inside_bits |= 1 << k;
    }
    if (inside_bits == 0 || inside_bits == 255) return inside_bits;
    for (int k = 0; k < 8; ++k)
      if (!observed(voxels[k])) return -1;
    return inside_bits;
  }

  /// Name of cell edge e of cell c: its lower voxel's storage index * 3 +
  /// axis (the lower voxel is observed, so its block is allocated).
  EMF_HD std::int64_t edge_key(const Cell& c, int e) const {
    const CellEdge edge = cell_edge(e);
    const std::int64_t voxel =
        storage(c, c.x + (edge.lower & 1), c.y + ((edge.lower >> 1) & 1), c.z + ((edge.lower >> 2) & 1));
    return voxel * 3 + edge.axis;
  }

  EMF_HD void place_vertex(std::int64_t key, Vec3<S>& vertex, Vec3<S>& normal) const {
    const int axis = int(key % 3);
    const std::int64_t voxel = key / 3;
    const int block = int(voxel / sparse::block_voxels), local = int(voxel % sparse::block_voxels);
    const Vec3i b = volume.block_coordinates(block);
    int lower[3] = {b[0] * sparse::block_side + (local & 7), b[1] * sparse::block_side + ((local >> 3) & 7),
                    b[2] * sparse::block_side + (local >> 6)};
    int upper[3] = {lower[0], lower[1], lower[2]};
    ++upper[axis];
    const S a = S(volume.sdf[voxel]);
    const S v_b = value(volume.voxel_index(upper[0], upper[1], upper[2]));
    vertex = edge_vertex(volume.voxel_center(lower[0], lower[1], lower[2]), axis, a, v_b, iso, volume.voxel_size);
    normal = edge_normal(voxel_gradient(lower), voxel_gradient(upper), axis, a, v_b, iso);
  }

  /// As the dense grid's: central differences, one-sided where a neighbour
  /// is unobserved (or its block unallocated).
  EMF_HD Vec3<S> voxel_gradient(const int* at) const {
    const S centre = value(volume.voxel_index(at[0], at[1], at[2]));
    Vec3<S> g = Vec3<S>::zero();
    for (int axis = 0; axis < 3; ++axis) {
      int lo[3] = {at[0], at[1], at[2]}, hi[3] = {at[0], at[1], at[2]};
      --lo[axis];
      ++hi[axis];
      const std::int64_t i_lo = volume.voxel_index(lo[0], lo[1], lo[2]);
      const std::int64_t i_hi = volume.voxel_index(hi[0], hi[1], hi[2]);
      const bool has_lo = observed(i_lo), has_hi = observed(i_hi);
      const S below = has_lo ? value(i_lo) : centre;
      const S above = has_hi ? value(i_hi) : centre;
      const int steps = int(has_lo) + int(has_hi);
      if (steps > 0) g[axis] = (above - below) / (S(steps) * volume.voxel_size);
    }
    return g;
  }
};

/// Finds, for every allocated block, the blocks at the eight offsets of its
/// cells' upper corners (itself included).
template <class View>
struct FindBlockNeighbours {
  View volume;
  int* neighbours;
  EMF_HD void operator()(std::int64_t i) const {
    const int b = int(i / 8), o = int(i % 8);
    const Vec3i c = volume.block_coordinates(b);
    neighbours[i] = o == 0 ? b : volume.find_block(c[0] + (o & 1), c[1] + ((o >> 1) & 1), c[2] + ((o >> 2) & 1));
  }
};

template <class Grid>
struct CountCellTriangles {
  Grid grid;
  std::uint8_t* counts;

  EMF_HD void operator()(std::int64_t cell) const {
    const int c = grid.cell_case(grid.cell(cell));
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

template <class Grid>
struct WriteCellTriangles {
  Grid grid;
  const std::int64_t* active_cells;
  const std::int64_t* triangle_ends;  // inclusive scan of the active cells' counts
  std::int64_t* corner_keys;          // three per triangle

  EMF_HD void operator()(std::int64_t i) const {
    const auto cell = grid.cell(active_cells[i]);
    const int c = grid.cell_case(cell);
    const int count = grid.table.triangle_count(c);
    std::int64_t* out = corner_keys + 3 * (triangle_ends[i] - count);
    for (int j = 0; j < 3 * count; ++j) out[j] = grid.edge_key(cell, grid.table.edge(c, j));
  }
};

template <class Grid, class S>
struct PlaceEdgeVertices {
  Grid grid;
  const std::int64_t* keys;
  Vec3<S>* vertices;
  Vec3<S>* normals;

  EMF_HD void operator()(std::int64_t i) const { grid.place_vertex(keys[i], vertices[i], normals[i]); }
};

/// The stages over any grid of cells (MarchingCubesGrid,
/// SparseMarchingCubesGrid), on `backend`.
template <class S, class Grid, Backend B>
TriangleMesh<S> extract_mesh(const Grid& grid, const B& backend) {
  using Index = std::int64_t;
  const auto policy = backend.policy();
  TriangleMesh<S> mesh;
  const Index cells = grid.cell_count();
  if (cells <= 0) return mesh;

  // Triangle corners as the names of the grid edges they lie on.
  typename B::template Vector<Index> corner_keys;
  Index triangle_count = 0;
  {
    typename B::template Vector<std::uint8_t> counts(cells);
    for_each_index(backend, cells, CountCellTriangles<Grid>{grid, raw_data(counts)});
    const Index active_count = thrust::count_if(policy, counts.begin(), counts.end(), IsNonZero{});
    if (active_count == 0) return mesh;

    typename B::template Vector<Index> active(active_count);
    thrust::copy_if(policy, thrust::counting_iterator<Index>(0), thrust::counting_iterator<Index>(cells),
                    counts.begin(), active.begin(), IsNonZero{});
    typename B::template Vector<Index> ends(active_count);
    thrust::transform_inclusive_scan(policy, active.begin(), active.end(), ends.begin(), CountOfCell{raw_data(counts)},
                                     SumInt64{});
    backend.synchronize();
    triangle_count = ends.back();
    require(3 * triangle_count <= Index(INT_MAX), "marching_cubes",
            "the surface has " + std::to_string(triangle_count) + " triangles, too many for int vertex indices");

    corner_keys.resize(3 * triangle_count);
    for_each_index(backend, active_count,
                   WriteCellTriangles<Grid>{grid, raw_data(active), raw_data(ends), raw_data(corner_keys)});
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
                 PlaceEdgeVertices<Grid, S>{grid, raw_data(vertex_keys), raw_data(vertices), raw_data(normals)});
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

/// The case table on `backend`.
template <Backend B>
typename B::template Vector<std::int8_t> marching_cubes_table_on() {
  const std::vector<std::int8_t> host_table = marching_cubes_table_entries();
  return typename B::template Vector<std::int8_t>(host_table.begin(), host_table.end());
}

// ---- the per-volume part: the grid of cells ----------------------------------

template <class S, Backend B, class Store>
TriangleMesh<S> marching_cubes_of(const TsdfVolume<S, B, Store>& volume, S iso, S min_weight) {
  const auto table = marching_cubes_table_on<B>();
  const MarchingCubesGrid<S, Store> grid{volume.view(), {raw_data(table)}, iso, min_weight};
  return extract_mesh<S>(grid, volume.backend());
}

template <class S, Backend B, class Store>
TriangleMesh<S> marching_cubes_of(const SparseTsdfVolume<S, B, Store>& volume, S iso, S min_weight) {
  const auto table = marching_cubes_table_on<B>();
  const auto view = volume.view();
  typename B::template Vector<int> neighbours(std::size_t(view.blocks) * 8);
  for_each_index(volume.backend(), std::int64_t(view.blocks) * 8,
                 FindBlockNeighbours<decltype(view)>{view, raw_data(neighbours)});
  const SparseMarchingCubesGrid<S, Store> grid{view, raw_data(neighbours), {raw_data(table)}, iso, min_weight};
  return extract_mesh<S>(grid, volume.backend());
}

}  // namespace detail

/// Extracts the iso-surface SDF = `iso` of the observed part of `volume` (a
/// TsdfVolume or a SparseTsdfVolume) as an indexed triangle mesh in the
/// VOLUME frame (use `transformed(mesh, volume.pose())` for the world
/// frame), with unit normals from the SDF gradient and triangles facing the
/// positive side. Cells with any voxel of weight <= `min_weight` are skipped.
template <class Volume, class S = typename Volume::Scalar>
  requires TsdfVolumeType<Volume, S>
TriangleMesh<S> marching_cubes(const Volume& volume, std::type_identity_t<S> iso = S(0),
                               std::type_identity_t<S> min_weight = S(0)) {
  return detail::marching_cubes_of(volume, iso, min_weight);
}

}  // namespace emfusion
