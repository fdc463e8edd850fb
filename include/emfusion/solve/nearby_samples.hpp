// Several samples of one volume close together, from one thread: SDF
// alignment samples a term's point and, with central differences, six more
// one voxel around it. On the sparse volume each sample would look its block
// up in the hash table again; `NearbySparseSampler` remembers the last blocks
// it found, so that the seven samples of a term cost one or two lookups
// instead of seven. It samples exactly as SparseTsdfView does (the same
// arithmetic, bit for bit). `nearby_sampler(view)` gives it for a sparse view
// and the view itself for any other (a dense view indexes directly).
#pragma once

#include <cmath>
#include <cstdint>

#include "emfusion/core/host_device.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/volume/detail/sparse_blocks.hpp"
#include "emfusion/volume/detail/trilinear.hpp"
#include "emfusion/volume/sparse_tsdf_volume.hpp"

namespace emfusion {

/// Samples of a SparseTsdfView with a cache of the last `slots` blocks
/// looked up (round robin). A local variable of one thread: its cache
/// changes as it samples, so it is never shared; it refers to the view,
/// which must outlive it.
template <class S, class Store>
struct NearbySparseSampler {
  static constexpr int slots = 4;
  const SparseTsdfView<S, Store>& view;
  detail::sparse::Key keys[slots] = {};
  int found[slots] = {};
  int cached = 0, next = 0;

  EMF_HD explicit NearbySparseSampler(const SparseTsdfView<S, Store>& v) : view(v) {}

  /// Index of block (bx, by, bz) in the voxel storage, or -1
  /// (SparseTsdfView::find_block), from the cache when it holds it.
  EMF_HD int find_block(int bx, int by, int bz) {
    if (!detail::sparse::block_in_range(bx, by, bz)) return -1;
    const detail::sparse::Key key = detail::sparse::pack_key(bx, by, bz);
    for (int k = 0; k < cached; ++k)
      if (keys[k] == key) return found[k];
    const int b = detail::sparse::find_block(view.slot_keys, view.slot_blocks, view.slot_mask, key);
    keys[next] = key, found[next] = b;
    next = (next + 1) % slots;
    if (cached < slots) ++cached;
    return b;
  }

  /// SparseTsdfView::sample.
  EMF_HD bool sample(const Vec3<S>& p, S& sdf_out, S* weight_out = nullptr) {
    Corner c;
    if (!corner(p, c)) return false;
    S v[8], w[8];
    if (!load(c, v, w)) return false;
    sdf_out = interpolate(v, c);
    if (weight_out) *weight_out = interpolate(w, c);
    return true;
  }

  /// SparseTsdfView::sample_with_gradient.
  EMF_HD bool sample_with_gradient(const Vec3<S>& p, S& sdf_out, Vec3<S>& gradient, S* weight_out = nullptr) {
    Corner c;
    if (!corner(p, c)) return false;
    S v[8], w[8];
    if (!load(c, v, w)) return false;
    sdf_out = interpolate(v, c);
    if (weight_out) *weight_out = interpolate(w, c);
    gradient = detail::trilinear::gradient(v, c.fx, c.fy, c.fz, view.voxel_size);
    return true;
  }

  /// SparseTsdfView::central_gradient.
  EMF_HD bool central_gradient(const Vec3<S>& p, Vec3<S>& gradient) {
    return detail::trilinear::central_gradient(*this, p, view.voxel_size, gradient);
  }

 private:
  struct Corner {
    int x, y, z;
    S fx, fy, fz;
  };
  EMF_HD bool corner(const Vec3<S>& p, Corner& c) const {
    const S gx = p.x() / view.voxel_size - S(0.5), gy = p.y() / view.voxel_size - S(0.5),
            gz = p.z() / view.voxel_size - S(0.5);
    // Written so that NaN coordinates fail the test.
    const S l = S(detail::sparse::voxel_limit - 2);
    if (!(gx >= -l && gy >= -l && gz >= -l && gx < l && gy < l && gz < l)) return false;
    c.x = int(std::floor(gx)), c.y = int(std::floor(gy)), c.z = int(std::floor(gz));
    c.fx = gx - S(c.x), c.fy = gy - S(c.y), c.fz = gz - S(c.z);
    return true;
  }
  /// The eight voxels around corner c (index bits: 1 -> +x, 2 -> +y, 4 ->
  /// +z), false at the first never observed (or in a block not allocated).
  /// Seven times in eight at 8^3 they lie in one block: one lookup and
  /// fixed offsets; else each block they span is looked up once.
  EMF_HD bool load(const Corner& c, S* v, S* w) {
    constexpr int side = detail::sparse::block_side;
    const int bx = c.x >> 3, by = c.y >> 3, bz = c.z >> 3;
    const int lx = c.x & 7, ly = c.y & 7, lz = c.z & 7;
    if (lx < side - 1 && ly < side - 1 && lz < side - 1) {
      const int b = find_block(bx, by, bz);
      if (b < 0) return false;
      const std::int64_t base =
          std::int64_t(b) * detail::sparse::block_voxels + detail::sparse::local_index(lx, ly, lz);
      for (int k = 0; k < 8; ++k) {
        const std::int64_t i = base + (k & 1) + ((k >> 1) & 1) * side + ((k >> 2) & 1) * side * side;
        w[k] = S(view.weight[i]);
        if (!(w[k] > S(0))) return false;
        v[k] = S(view.sdf[i]);
      }
      return true;
    }
    int found_at[8];  // by block offset (bits: 1 -> +x, 2 -> +y, 4 -> +z); -2 = not looked up
    for (int o = 0; o < 8; ++o) found_at[o] = -2;
    for (int k = 0; k < 8; ++k) {
      const int x = lx + (k & 1), y = ly + ((k >> 1) & 1), z = lz + ((k >> 2) & 1);
      const int o = (x >> 3) | ((y >> 3) << 1) | ((z >> 3) << 2);
      if (found_at[o] == -2) found_at[o] = find_block(bx + (x >> 3), by + (y >> 3), bz + (z >> 3));
      if (found_at[o] < 0) return false;
      const std::int64_t i =
          std::int64_t(found_at[o]) * detail::sparse::block_voxels + detail::sparse::local_index(x & 7, y & 7, z & 7);
      w[k] = S(view.weight[i]);
      if (!(w[k] > S(0))) return false;
      v[k] = S(view.sdf[i]);
    }
    return true;
  }
  EMF_HD static S interpolate(const S* v, const Corner& c) {
    return detail::trilinear::interpolate(v, c.fx, c.fy, c.fz);
  }
};

/// The sampler for several samples close together: a caching one for a
/// sparse view, the view itself otherwise.
template <class View>
EMF_HD const View& nearby_sampler(const View& view) {
  return view;
}
template <class S, class Store>
EMF_HD NearbySparseSampler<S, Store> nearby_sampler(const SparseTsdfView<S, Store>& view) {
  return NearbySparseSampler<S, Store>(view);
}

}  // namespace emfusion
