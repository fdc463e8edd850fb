// Several samples of one volume close together, from one thread: SDF
// alignment samples a term's point and, with central differences, six more
// one voxel around it; a ray cast marches along a ray in steps of half a
// voxel to a truncation. On the sparse volume each sample would look its
// block up in the hash table again; `NearbySparseSampler` remembers the last
// blocks it found, so that the seven samples of a term cost one or two
// lookups instead of seven, and a ray one per block it passes. It samples
// exactly as SparseTsdfView does: both through detail/sparse_samples.hpp.
// `nearby_sampler(view)` gives it for a sparse view and the view itself for
// any other (a dense view indexes directly).
#pragma once

#include <cmath>
#include <cstdint>
#include <type_traits>

#include "emfusion/core/host_device.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/volume/detail/sparse_blocks.hpp"
#include "emfusion/volume/detail/sparse_samples.hpp"
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
    return samples().sample(p, sdf_out, weight_out);
  }

  /// SparseTsdfView::sample_with_gradient.
  EMF_HD bool sample_with_gradient(const Vec3<S>& p, S& sdf_out, Vec3<S>& gradient, S* weight_out = nullptr) {
    return samples().sample(p, sdf_out, weight_out, &gradient);
  }

  /// SparseTsdfView::central_gradient.
  EMF_HD bool central_gradient(const Vec3<S>& p, Vec3<S>& gradient) {
    return detail::trilinear::central_gradient(*this, p, view.voxel_size, gradient);
  }

  /// SparseTsdfView::sample_observed.
  EMF_HD bool sample_observed(const Vec3<S>& p, S& sdf_out, S min_coverage = S(0.5)) {
    return samples().sample_observed(p, sdf_out, min_coverage);
  }

  /// SparseTsdfView::observed_gradient.
  EMF_HD bool observed_gradient(const Vec3<S>& p, Vec3<S>& gradient) {
    return detail::trilinear::observed_gradient(*this, p, view.voxel_size, gradient);
  }

 private:
  /// The samples, their blocks from the cache (detail/sparse_samples.hpp).
  EMF_HD auto samples() {
    return detail::sparse::samples_of<S, std::add_const_t<Store>>(
        [this](int bx, int by, int bz) { return find_block(bx, by, bz); }, view.sdf, view.weight, view.voxel_size,
        view.truncation);
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
