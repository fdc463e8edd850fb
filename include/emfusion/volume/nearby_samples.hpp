// Several samples of one volume close together, from one thread: SDF
// alignment samples a term's point and, with central differences, six more
// one voxel around it; a ray cast marches along a ray in steps of half a
// voxel to a truncation. On a sparse volume without an index grid each
// sample would look its block up in the hash table again;
// `NearbySparseSampler` remembers the last blocks it found, so that the
// seven samples of a term cost one or two lookups instead of seven, and a
// ray one per block it passes. With the grid a lookup is one read, and
// `GriddedSparseSampler` reads it alone. Both sample exactly as
// SparseTsdfView does: all through detail/sparse_samples.hpp.
// `with_nearby_sampler(view, f)` hands f the right one (the view itself for
// a dense view, which indexes directly); `nearby_sampler(view)` gives the
// caching one.
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
    if (view.grid.cells) return view.grid.find(bx, by, bz);  // one read: nothing to cache
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

  /// SparseTsdfView::skip_unallocated.
  EMF_HD bool skip_unallocated(const Vec3<S>& o, const Vec3<S>& d, S& t, S t_end) const {
    return view.skip_unallocated(o, d, t, t_end);
  }

 private:
  /// The samples, their blocks from the cache (detail/sparse_samples.hpp).
  EMF_HD auto samples() {
    return detail::sparse::samples_of<S, std::add_const_t<Store>>(
        [this](int bx, int by, int bz) { return find_block(bx, by, bz); }, view.sdf, view.weight, view.voxel_size,
        view.truncation);
  }
};

/// Samples of a SparseTsdfView that keeps an index grid (view.grid.cells
/// not null), every block found by one read of the grid: no cache, and no
/// hash table code in the caller's path. The same samples as the view's.
template <class S, class Store>
struct GriddedSparseSampler {
  const SparseTsdfView<S, Store>& view;

  EMF_HD explicit GriddedSparseSampler(const SparseTsdfView<S, Store>& v) : view(v) {}

  /// SparseTsdfView::sample.
  EMF_HD bool sample(const Vec3<S>& p, S& sdf_out, S* weight_out = nullptr) const {
    return samples().sample(p, sdf_out, weight_out);
  }
  /// SparseTsdfView::sample_with_gradient.
  EMF_HD bool sample_with_gradient(const Vec3<S>& p, S& sdf_out, Vec3<S>& gradient, S* weight_out = nullptr) const {
    return samples().sample(p, sdf_out, weight_out, &gradient);
  }
  /// SparseTsdfView::central_gradient.
  EMF_HD bool central_gradient(const Vec3<S>& p, Vec3<S>& gradient) const {
    return detail::trilinear::central_gradient(*this, p, view.voxel_size, gradient);
  }
  /// SparseTsdfView::sample_observed.
  EMF_HD bool sample_observed(const Vec3<S>& p, S& sdf_out, S min_coverage = S(0.5)) const {
    return samples().sample_observed(p, sdf_out, min_coverage);
  }
  /// SparseTsdfView::observed_gradient.
  EMF_HD bool observed_gradient(const Vec3<S>& p, Vec3<S>& gradient) const {
    return detail::trilinear::observed_gradient(*this, p, view.voxel_size, gradient);
  }
  /// SparseTsdfView::skip_unallocated, inline.
  EMF_HD bool skip_unallocated(const Vec3<S>& o, const Vec3<S>& d, S& t, S t_end) const {
    return detail::sparse::walk_to_allocated(finder(), S(detail::sparse::block_side) * view.voxel_size, o, d, t, t_end);
  }

 private:
  EMF_HD auto finder() const {
    return [g = view.grid](int bx, int by, int bz) { return g.find(bx, by, bz); };
  }
  EMF_HD auto samples() const {
    return detail::sparse::samples_of<S, std::add_const_t<Store>>(finder(), view.sdf, view.weight, view.voxel_size,
                                                                  view.truncation);
  }
};

/// Calls f(sampler) with the sampler for several samples close together,
/// and returns what it returns: for a sparse view with an index grid a
/// GriddedSparseSampler; for one without, a NearbySparseSampler of `Slots`
/// blocks (the view itself with Slots = 0); for any other view the view
/// itself. The choice is made once per call, so that on a CUDA device each
/// branch is its own compact copy of f's code: a ray cast that looked up
/// the grid and, failing that, the table at every sample ran 1.20 ms on the
/// H100 where one that reads the grid alone ran 0.80 ms.
template <int Slots = 4, class View, class F>
EMF_HD decltype(auto) with_nearby_sampler(const View& view, F&& f) {
  return f(view);
}
template <int Slots = 4, class S, class Store, class F>
EMF_HD decltype(auto) with_nearby_sampler(const SparseTsdfView<S, Store>& view, F&& f) {
  if (view.grid.cells) {
    GriddedSparseSampler<S, Store> gridded(view);
    return f(gridded);
  }
  if constexpr (Slots == 0) {
    return f(view);
  } else {
    NearbySparseSampler<S, Store, Slots> cached(view);
    return f(cached);
  }
}

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
