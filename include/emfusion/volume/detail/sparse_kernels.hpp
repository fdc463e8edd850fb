// Per-element work of the sparse TSDF volume (sparse_tsdf_volume.hpp):
// the block keys a depth pixel's truncation band touches, the table checks
// and insertions of allocation, the frustum test of a block, and the
// integration of one column of a block's voxels. Written once for both
// backends, as functors over raw pointers and views.
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include "emfusion/core/atomic.hpp"
#include "emfusion/core/camera.hpp"
#include "emfusion/core/host_device.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/volume/detail/sparse_blocks.hpp"

namespace emfusion::detail::sparse {

/// Most samples along one pixel's truncation band.
inline constexpr int max_band_samples = 32;

/// floor(x) for x well inside the int range (checked by the caller): without
/// SSE4.1 std::floor is a library call, and allocation calls it per sample.
template <class S>
EMF_HD int floor_to_int(S x) {
  const int i = int(x);
  return i - (S(i) > x ? 1 : 0);
}

/// True for keys the volume already holds: through its index grid when it
/// has one, else its table.
struct IsStored {
  const Key* slot_keys;
  const int* slot_blocks;
  Key slot_mask;
  BlockGrid grid;
  EMF_HD bool operator()(Key key) const {
    if (grid.cells) {
      int bx, by, bz;
      unpack_key(key, bx, by, bz);
      return grid.find(bx, by, bz) >= 0;
    }
    return find_block(slot_keys, slot_blocks, slot_mask, key) >= 0;
  }
};

/// The blocks the truncation band of each valid depth pixel touches that the
/// table does not hold yet: points along the pixel's ray from d - truncation
/// to d + truncation (distances along the ray, as integration measures
/// them), `samples` of them evenly spaced. Once a place is mapped, a frame
/// there finds few or none, and the sort that follows has little to do.
///
/// De-duplication, exact and independent of the order threads run in: a
/// pixel leaves out a key that its left or upper neighbour's band also
/// touches. That neighbour writes the key itself or leaves it to its own
/// left or upper neighbour, and so on back to some pixel that writes it, so
/// the union of what is written is the union of every band's blocks (less
/// the stored ones, the same for every pixel). On a device each pixel is a
/// thread (operator(), recomputing its neighbours' keys) appending to one
/// list through an atomic counter; on the CPU each chunk of rows is one
/// (BandBlockKeyRows), keeping the previous row's keys.
template <class S>
struct BandBlockKeys {
  ImageView<const S> depth;
  ImageView<const S> weights;  // empty: every valid pixel; else those with weight > 0
  PinholeCamera<S> camera;
  SE3<S> T_volume_camera;
  S truncation;
  S block_size;  // metres
  int samples;   // 2 .. max_band_samples
  IsStored stored;
  Key* out;                   // room for `samples` keys per pixel
  unsigned long long* count;  // operator(): keys appended to `out` so far

  /// The keys of pixel (u, v)'s band, consecutive repeats dropped; returns
  /// how many (0 for a pixel without a valid measurement).
  EMF_HD int pixel_keys(int u, int v, Key* keys) const {
    if (!depth.contains(u, v)) return 0;
    const S d = depth(u, v);
    if (!is_valid_depth(d)) return 0;
    if (!weights.empty() && !(weights(u, v) > S(0))) return 0;
    const Vec3<S> ray = camera.ray(S(u), S(v));  // z = 1
    const S half_band = truncation / norm(ray);  // in camera z
    const S dz = S(2) * half_band / S(samples - 1);
    // In block units: the block of a point is the floor of its coordinates.
    const S to_blocks = S(1) / block_size;
    const Vec3<S> origin = T_volume_camera.translation() * to_blocks;
    const Vec3<S> direction = T_volume_camera.rotate(ray) * to_blocks;
    const S limit = S(block_limit);
    int count = 0;
    for (int j = 0; j < samples; ++j) {
      const S z = d - half_band + S(j) * dz;
      if (!(z > S(0))) continue;
      const Vec3<S> g = origin + z * direction;
      // Written so that NaN fails too.
      if (!(g.x() >= -limit && g.y() >= -limit && g.z() >= -limit && g.x() < limit && g.y() < limit && g.z() < limit))
        continue;
      const Key key = pack_key(floor_to_int(g.x()), floor_to_int(g.y()), floor_to_int(g.z()));
      if (count > 0 && keys[count - 1] == key) continue;
      keys[count++] = key;
    }
    return count;
  }

  /// Calls emit(key) for each of a pixel's keys (`own`, n of them) that
  /// neither neighbour's band has (`left`, `up`: their keys, nl and nu of
  /// them) and the table does not hold.
  template <class Emit>
  EMF_HD void survivors(const Key* own, int n, const Key* left, int nl, const Key* up, int nu, Emit&& emit) const {
    for (int a = 0; a < n; ++a) {
      bool covered = false;
      for (int b = 0; b < nl && !covered; ++b) covered = own[a] == left[b];
      for (int b = 0; b < nu && !covered; ++b) covered = own[a] == up[b];
      if (!covered && !stored(own[a])) emit(own[a]);
    }
  }

  /// One pixel per thread: its keys appended to `out` at *count.
  EMF_HD void operator()(int i) const {
    const int u = i % depth.width, v = i / depth.width;
    Key own[max_band_samples], left[max_band_samples], up[max_band_samples];
    const int n = pixel_keys(u, v, own);
    if (n == 0) return;
    const int nl = pixel_keys(u - 1, v, left), nu = pixel_keys(u, v - 1, up);
    survivors(own, n, left, nl, up, nu, [this](Key key) { out[atomic_fetch_add(count, 1)] = key; });
  }
};

/// The CPU's BandBlockKeys: chunk c walks rows [c H / chunks, (c + 1) H /
/// chunks) in order, computing each pixel's keys once, and writes its keys
/// contiguously from the slots of its first pixel; counts[c] says how many.
template <class S>
struct BandBlockKeyRows {
  BandBlockKeys<S> band;
  int chunks;
  std::int64_t* counts;

  void operator()(int c) const {
    const int width = band.depth.width, height = band.depth.height, k = band.samples;
    const int v0 = int(std::int64_t(c) * height / chunks), v1 = int(std::int64_t(c + 1) * height / chunks);
    // Keys and counts of the previous and the current row.
    std::vector<Key> above(std::size_t(width) * std::size_t(k)), row(above.size());
    std::vector<int> n_above(std::size_t(width), 0), n_row(std::size_t(width), 0);
    if (v0 > 0)
      for (int u = 0; u < width; ++u) n_above[std::size_t(u)] = band.pixel_keys(u, v0 - 1, &above[std::size_t(u) * k]);
    Key* const first = band.out + std::int64_t(v0) * width * k;
    Key* next = first;
    const auto emit = [&next](Key key) { *next++ = key; };
    for (int v = v0; v < v1; ++v) {
      for (int u = 0; u < width; ++u) {
        Key* own = &row[std::size_t(u) * k];
        const int n = n_row[std::size_t(u)] = band.pixel_keys(u, v, own);
        if (n == 0) continue;
        const Key* left = u > 0 ? own - k : own;
        const int nl = u > 0 ? n_row[std::size_t(u - 1)] : 0;
        band.survivors(own, n, left, nl, &above[std::size_t(u) * k], n_above[std::size_t(u)], emit);
      }
      above.swap(row);
      n_above.swap(n_row);
    }
    counts[c] = next - first;
  }
};

/// Inserts new key i as block first_block + i.
struct InsertBlock {
  const Key* keys;  // new, distinct, not yet stored
  Key* slot_keys;
  int* slot_blocks;
  Key slot_mask;
  Key* block_keys;
  int first_block;
  EMF_HD void operator()(int i) const {
    block_keys[first_block + i] = keys[i];
    insert_block(slot_keys, slot_blocks, slot_mask, keys[i], first_block + i);
  }
};

/// True for blocks that may hold a voxel projecting into the image in front
/// of the far plane: the sphere around the block against the frustum's
/// planes, which lie a pixel outside the image (as clip_column_to_frustum's),
/// so every voxel the per-voxel update would change is in a block that
/// passes.
template <class S>
struct BlockInView {
  const Key* block_keys;
  PinholeCamera<S> camera;
  SE3<S> T_camera_volume;
  S block_size;
  S far;
  EMF_HD bool operator()(int b) const {
    int bx, by, bz;
    unpack_key(block_keys[b], bx, by, bz);
    const S half = S(0.5) * block_size;
    const Vec3<S> c =
        T_camera_volume * vec3((S(bx) * block_size + half), (S(by) * block_size + half), (S(bz) * block_size + half));
    const S r = std::sqrt(S(3)) * half;
    if (!(c.z() > -r) || !(c.z() - r < far)) return false;
    const S u_lo = -S(1.5), u_hi = S(camera.width) + S(0.5), v_lo = -S(1.5), v_hi = S(camera.height) + S(0.5);
    const Vec3<S> planes[4] = {vec3(camera.fx, S(0), camera.cx - u_lo), vec3(-camera.fx, S(0), u_hi - camera.cx),
                               vec3(S(0), camera.fy, camera.cy - v_lo), vec3(S(0), -camera.fy, v_hi - camera.cy)};
    for (int k = 0; k < 4; ++k)
      if (dot(planes[k], c) < -r * norm(planes[k])) return false;
    return true;
  }
};

/// Integrates one column (x, y; all 8 z) of a block in view: the voxel
/// centres computed as the dense volume's column does (start + z step), so
/// that both volumes feed the shared per-voxel update the same points.
template <class S, class View, class Update>
struct IntegrateBlockColumn {
  View volume;
  const int* blocks;  // the blocks in view
  Update update;
  SE3<S> T_camera_volume;
  EMF_HD void operator()(std::int64_t i) const {
    const int b = blocks[i / (block_side * block_side)];
    const int column = int(i % (block_side * block_side));
    int bx, by, bz;
    unpack_key(volume.block_keys[b], bx, by, bz);
    const int x = bx * block_side + column % block_side, y = by * block_side + column / block_side;
    const int z0 = bz * block_side;
    const Vec3<S> start = T_camera_volume * volume.voxel_center(x, y, 0);
    const Vec3<S> step = T_camera_volume.rotate(vec3(S(0), S(0), volume.voxel_size));
    const std::int64_t first = std::int64_t(b) * block_voxels + column;
    for (int lz = 0; lz < block_side; ++lz) {
      const std::int64_t k = first + lz * block_side * block_side;
      update(start + S(z0 + lz) * step, volume.sdf[k], volume.weight[k]);
    }
  }
};

}  // namespace emfusion::detail::sparse
