// Several samples of one volume close together, from one thread: SDF
// alignment samples a term's point and, with central differences, six more
// one voxel around it; a ray cast marches along a ray in steps of half a
// voxel to a truncation. On the sparse volume each sample would look its
// block up in the hash table again; `NearbySparseSampler` remembers the last
// blocks it found, so that the seven samples of a term cost one or two
// lookups instead of seven, and a ray one per block it passes. It samples
// exactly as SparseTsdfView does (the same arithmetic, bit for bit).
// `nearby_sampler(view)` gives it for a sparse view and the view itself for
// any other (a dense view indexes directly).
#pragma once

#include <cmath>
#include <cstdint>

#include "emfusion/core/host_device.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/volume/detail/sparse_blocks.hpp"
#include "emfusion/volume/detail/trilinear.hpp"
#include "emfusion/volume/sparse_tsdf_volume.hpp"

namespace emfusion {

/// Samples of a SparseTsdfView with a cache of the last `Slots` blocks
/// looked up (round robin). A local variable of one thread: its cache
/// changes as it samples, so it is never shared; it refers to the view,
/// which must outlive it. One slot keeps the cache in registers on a CUDA
/// device (an array indexed at run time would live in local memory).
template <class S, class Store, int Slots = 4>
struct NearbySparseSampler {
  static constexpr int slots = Slots;
  static_assert(Slots >= 1);
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
    for (int k = 0; k < slots; ++k)  // a fixed trip count: unrolled, constant indices
      if (k < cached && keys[k] == key) return found[k];
    const int b = detail::sparse::find_block(view.slot_keys, view.slot_blocks, view.slot_mask, key);
    if constexpr (slots == 1) {
      keys[0] = key, found[0] = b, cached = 1;
    } else {
      keys[next] = key, found[next] = b;
      next = (next + 1) % slots;
      if (cached < slots) ++cached;
    }
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

  /// SparseTsdfView::sample_observed.
  EMF_HD bool sample_observed(const Vec3<S>& p, S& sdf_out, S min_coverage = S(0.5)) {
    Corner c;
    if (!corner(p, c)) return false;
    S v[8], w[8];
    gather(c, v, w);
    return detail::trilinear::interpolate_observed(v, w, c.fx, c.fy, c.fz, min_coverage, sdf_out);
  }

  /// SparseTsdfView::observed_gradient.
  EMF_HD bool observed_gradient(const Vec3<S>& p, Vec3<S>& gradient) {
    return detail::trilinear::observed_gradient(*this, p, view.voxel_size, gradient);
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
  /// +z), each with its weight; truncation and weight 0 in a block that is
  /// not allocated (SparseTsdfView's gather, blocks from the cache).
  EMF_HD void gather(const Corner& c, S* v, S* w) {
    detail::sparse::gather_eight([this](int bx, int by, int bz) { return find_block(bx, by, bz); }, c.x, c.y, c.z,
                                 view.sdf, view.weight, view.truncation, v, w);
  }
  /// gather(), false if one of the eight was never observed.
  EMF_HD bool load(const Corner& c, S* v, S* w) {
    gather(c, v, w);
    for (int k = 0; k < 8; ++k)
      if (!(w[k] > S(0))) return false;
    return true;
  }
  EMF_HD static S interpolate(const S* v, const Corner& c) {
    return detail::trilinear::interpolate(v, c.fx, c.fy, c.fz);
  }
};

/// The sampler for several samples close together: a caching one (of
/// `Slots` blocks) for a sparse view, the view itself otherwise.
template <int Slots = 4, class View>
EMF_HD const View& nearby_sampler(const View& view) {
  return view;
}
template <int Slots = 4, class S, class Store>
EMF_HD NearbySparseSampler<S, Store, Slots> nearby_sampler(const SparseTsdfView<S, Store>& view) {
  return NearbySparseSampler<S, Store, Slots>(view);
}

}  // namespace emfusion
