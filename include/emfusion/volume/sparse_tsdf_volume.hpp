// Sparse truncated signed distance volume: the TSDF stored only in blocks of
// 8^3 voxels near observed surfaces, found through a spatial hash table on the
// backend, so that the map is unbounded and its memory follows the observed
// surface instead of a cube. `SparseTsdfView` is what kernels capture; it
// samples like `TsdfView` (tsdf_volume.hpp), trilinear across block borders.
// `allocate_blocks` adds the blocks a depth frame's truncation band touches;
// `integrate` allocates and then applies the dense volume's per-voxel update
// (eq. 10, integrate.hpp) to every allocated voxel in view.
//
// Geometry and values are those of the dense volume: voxel (x, y, z) has its
// centre at ((x + 1/2) s, (y + 1/2) s, (z + 1/2) s) in the volume frame, here
// for any integer x, y, z in [-2^23, 2^23) (about +-84 km at 1 cm); SDF values
// are metres clamped to [-truncation, truncation]; weight 0 means never
// observed, and a voxel of a block that was never allocated reads as never
// observed. Block (bx, by, bz) holds voxels 8 bx .. 8 bx + 7 (and so on).
//
// Memory: the hash table (12 bytes a slot, the next power of two at least
// twice the block capacity) and the list of block keys are reserved at
// construction; voxel storage grows with the allocated blocks (doubling, at
// most to the capacity). When the capacity is reached, allocation refuses the
// new blocks that do not fit and counts them; stored blocks are never moved
// or dropped. The volume keeps the box of its allocated blocks and, while it
// fits a budget of cells per block of capacity, a dense grid of block indices
// over that box, so that finding a block is one read instead of a walk of
// the table's probe sequence. The view skips unallocated blocks along a ray
// (skip_unallocated), for ray casting (raycast.hpp). docs/volumes.md has the
// details.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <type_traits>
#include <vector>

#include <thrust/copy.h>
#include <thrust/fill.h>
#include <thrust/functional.h>
#include <thrust/iterator/counting_iterator.h>
#include <thrust/remove.h>
#include <thrust/sort.h>
#include <thrust/unique.h>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/camera.hpp"
#include "emfusion/core/error.hpp"
#include "emfusion/core/host_device.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/core/pixel_box.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/volume/detail/sparse_blocks.hpp"
#include "emfusion/volume/detail/trilinear.hpp"
#include "emfusion/volume/detail/sparse_kernels.hpp"
#include "emfusion/volume/detail/sparse_samples.hpp"
#include "emfusion/volume/integrate.hpp"

namespace emfusion {

/// Kernel-side view of a sparse TSDF volume: S is the compute scalar, Store
/// the scalar the voxels are stored in. The hash table is read-only here;
/// blocks are added by allocate_blocks / integrate on the volume.
template <class S, class Store = S>
struct SparseTsdfView {
  static constexpr int block_side = detail::sparse::block_side;
  static constexpr int block_voxels = detail::sparse::block_voxels;
  using const_store = std::add_const_t<Store>;

  Store* sdf = nullptr;     ///< block b's voxels at [b * 512, (b + 1) * 512), x fastest
  Store* weight = nullptr;  ///< same layout
  const unsigned long long* slot_keys = nullptr;
  const int* slot_blocks = nullptr;
  unsigned long long slot_mask = 0;                ///< table slots - 1
  const unsigned long long* block_keys = nullptr;  ///< key of each allocated block
  int blocks = 0;                                  ///< allocated blocks
  S voxel_size = S(0);
  S truncation = S(0);
  /// The box of block coordinates around every allocated block, inclusive
  /// (block_lo > block_hi when none is): where rays may find anything.
  Vec3i block_lo{{0, 0, 0}};
  Vec3i block_hi{{-1, -1, -1}};
  /// The dense index over a box holding every allocated block, when the
  /// volume keeps one (grid.cells not null): lookups read it, not the table.
  detail::sparse::BlockGrid grid{};

  /// A read-only view of the same volume (only for views of mutable voxels).
  template <class U = Store>
  requires(!std::is_const_v<U>) EMF_HD operator SparseTsdfView<S, const U>() const {
    return {sdf,    weight,     slot_keys,  slot_blocks, slot_mask, block_keys,
            blocks, voxel_size, truncation, block_lo,    block_hi,  grid};
  }

  /// Index of block (bx, by, bz) in the voxel storage, or -1 if it is not
  /// allocated (or outside the addressable range): one read of the index
  /// grid when there is one, else a walk of the table's probe sequence.
  EMF_HD int find_block(int bx, int by, int bz) const {
    if (grid.cells) return grid.find(bx, by, bz);
    if (!detail::sparse::block_in_range(bx, by, bz)) return -1;
    return detail::sparse::find_block(slot_keys, slot_blocks, slot_mask, detail::sparse::pack_key(bx, by, bz));
  }
  /// Coordinates of allocated block b (0 <= b < blocks).
  EMF_HD Vec3i block_coordinates(int b) const {
    Vec3i c;
    detail::sparse::unpack_key(block_keys[b], c[0], c[1], c[2]);
    return c;
  }
  /// Storage index of voxel (x, y, z), or -1 if its block is not allocated.
  EMF_HD std::int64_t voxel_index(int x, int y, int z) const {
    const int b = find_block(x >> 3, y >> 3, z >> 3);
    if (b < 0) return -1;
    return std::int64_t(b) * block_voxels + detail::sparse::local_index(x & 7, y & 7, z & 7);
  }
  /// SDF and weight of voxel (x, y, z); truncation and 0 (never observed)
  /// when its block is not allocated, and then false.
  EMF_HD bool voxel(int x, int y, int z, S& sdf_out, S& weight_out) const {
    const std::int64_t i = voxel_index(x, y, z);
    sdf_out = i < 0 ? truncation : S(sdf[i]);
    weight_out = i < 0 ? S(0) : S(weight[i]);
    return i >= 0;
  }

  /// True if (x, y, z) is addressable (allocated or not).
  EMF_HD bool contains_voxel(int x, int y, int z) const {
    const int l = detail::sparse::voxel_limit;
    return x >= -l && y >= -l && z >= -l && x < l && y < l && z < l;
  }
  /// Volume-frame position of a voxel centre.
  EMF_HD Vec3<S> voxel_center(int x, int y, int z) const {
    return vec3((S(x) + S(0.5)) * voxel_size, (S(y) + S(0.5)) * voxel_size, (S(z) + S(0.5)) * voxel_size);
  }
  /// True if the volume-frame point lies in the addressable range, with a
  /// voxel to spare for interpolation (false for NaN). The sparse volume has
  /// no box: whether anything was observed there is what sample() says.
  EMF_HD bool contains_point(const Vec3<S>& p) const {
    const S l = S(detail::sparse::voxel_limit - 2) * voxel_size;
    return p.x() >= -l && p.y() >= -l && p.z() >= -l && p.x() < l && p.y() < l && p.z() < l;
  }

  /// The volume-frame box [lo, hi] of the allocated blocks (block_lo,
  /// block_hi in metres); false when no block is allocated.
  EMF_HD bool block_box(Vec3<S>& lo, Vec3<S>& hi) const {
    if (blocks <= 0 || block_hi[0] < block_lo[0] || block_hi[1] < block_lo[1] || block_hi[2] < block_lo[2])
      return false;
    const S side = S(block_side) * voxel_size;
    lo = vec3(S(block_lo[0]) * side, S(block_lo[1]) * side, S(block_lo[2]) * side);
    hi = vec3(S(block_hi[0] + 1) * side, S(block_hi[1] + 1) * side, S(block_hi[2] + 1) * side);
    return true;
  }

  /// Empty-space skipping along the ray o + t d (volume frame, d of any
  /// length but not zero). If the block at o + t d is allocated, returns
  /// false and leaves t alone. Otherwise walks the blocks the ray passes
  /// through (detail::sparse::walk_to_allocated: one lookup per block) and
  /// returns true with t at the distance where the ray enters the first
  /// allocated block, or beyond t_end when there is none before it.
  EMF_HD EMF_NOINLINE_ON_CUDA bool skip_unallocated(const Vec3<S>& o, const Vec3<S>& d, S& t, S t_end) const {
    return detail::sparse::walk_to_allocated([this](int bx, int by, int bz) { return find_block(bx, by, bz); },
                                             S(block_side) * voxel_size, o, d, t, t_end);
  }

  /// Trilinear SDF at volume-frame point p. Returns false (and leaves the
  /// outputs alone) if any of the eight voxels around p was never observed
  /// (an unallocated block counts as never observed). `weight_out`, if
  /// given, receives the interpolated weight.
  EMF_HD bool sample(const Vec3<S>& p, S& sdf_out, S* weight_out = nullptr) const {
    return samples().sample(p, sdf_out, weight_out);
  }

  /// Trilinear SDF over the observed voxels of the eight around p, their
  /// interpolation weights renormalised: true where those voxels carry at
  /// least `min_coverage` of the weight (TsdfView::sample_observed).
  EMF_HD bool sample_observed(const Vec3<S>& p, S& sdf_out, S min_coverage = S(0.5)) const {
    return samples().sample_observed(p, sdf_out, min_coverage);
  }

  /// Central differences one voxel apart of `sample_observed`, one-sided
  /// where one side is not observed (TsdfView::observed_gradient).
  EMF_HD bool observed_gradient(const Vec3<S>& p, Vec3<S>& gradient) const {
    return detail::trilinear::observed_gradient(*this, p, voxel_size, gradient);
  }

  /// Trilinear SDF and its exact gradient (of the trilinear interpolant) at p.
  EMF_HD bool sample_with_gradient(const Vec3<S>& p, S& sdf_out, Vec3<S>& gradient, S* weight_out = nullptr) const {
    return samples().sample(p, sdf_out, weight_out, &gradient);
  }

  /// SDF gradient by central differences of trilinear samples one voxel
  /// apart (TsdfView::central_gradient).
  EMF_HD bool central_gradient(const Vec3<S>& p, Vec3<S>& gradient) const {
    return detail::trilinear::central_gradient(*this, p, voxel_size, gradient);
  }

 private:
  /// The samples, each looking its blocks up in the table
  /// (detail/sparse_samples.hpp).
  EMF_HD auto samples() const {
    return detail::sparse::samples_of<S, const_store>([this](int bx, int by, int bz) { return find_block(bx, by, bz); },
                                                      sdf, weight, voxel_size, truncation);
  }
};

static_assert(std::is_trivially_copyable_v<SparseTsdfView<float>>);
static_assert(std::is_trivially_copyable_v<SparseTsdfView<double, const double>>);

/// Parameters of a sparse volume.
template <class S>
struct SparseVolumeParams {
  S voxel_size = S(0);      ///< metres
  S truncation = S(0);      ///< metres; 0 selects 10 voxels
  SE3<S> T_world_volume{};  ///< the volume frame (corner of voxel (0, 0, 0)) in the world
  /// Most blocks of 8^3 voxels the volume holds: its memory bound
  /// (SparseTsdfVolume::memory_bound_bytes).
  int block_capacity = 0;
  /// Most cells of the index grid (4 bytes each) per block of capacity. The
  /// volume keeps a dense grid of block indices over the box of its
  /// allocated blocks (with room to grow) while the box fits in
  /// block_capacity * grid_cells_per_block cells, so that a lookup is one
  /// read; beyond that, and with 0, every lookup walks the hash table.
  /// 16 adds at most 64 bytes a block to the bound (a block of float voxels
  /// is 4096).
  int grid_cells_per_block = 16;
};

/// What one allocation did with the distinct blocks it was given (a frame's
/// truncation band) that were not stored before: `inserted` were added and
/// `refused` did not fit (capacity reached).
struct BlockAllocation {
  std::int64_t inserted = 0;
  std::int64_t refused = 0;
};

/// A sparse TSDF volume on backend B with compute scalar S and storage scalar
/// Store.
template <class S, Backend B = Host, class Store = S>
class SparseTsdfVolume {
 public:
  using Scalar = S;
  using backend_type = B;
  using View = SparseTsdfView<S, Store>;
  using ConstView = SparseTsdfView<S, const Store>;
  using Key = detail::sparse::Key;
  static constexpr int block_side = detail::sparse::block_side;
  static constexpr int block_voxels = detail::sparse::block_voxels;
  using const_store = std::add_const_t<Store>;
  /// The largest block capacity accepted (2^26 blocks: 2^35 voxels).
  static constexpr int max_block_capacity = 1 << 26;
  /// The largest SparseVolumeParams::grid_cells_per_block accepted.
  static constexpr int max_grid_cells_per_block = 1024;

  explicit SparseTsdfVolume(const SparseVolumeParams<S>& params, B backend = B{})
      : backend_(backend), scratch_(make_scratch(backend)) {
    constexpr const char* where = "SparseTsdfVolume";
    detail::require(std::isfinite(double(params.voxel_size)) && params.voxel_size > S(0), where,
                    "voxel size must be positive and finite, got " + std::to_string(double(params.voxel_size)));
    detail::require(std::isfinite(double(params.truncation)) && params.truncation >= S(0), where,
                    "truncation must be finite and not negative (0 selects 10 voxels), got " +
                        std::to_string(double(params.truncation)));
    detail::require(params.block_capacity >= 1 && params.block_capacity <= max_block_capacity, where,
                    "block capacity must be between 1 and " + std::to_string(max_block_capacity) + " blocks, got " +
                        std::to_string(params.block_capacity));
    detail::require(params.grid_cells_per_block >= 0 && params.grid_cells_per_block <= max_grid_cells_per_block, where,
                    "index grid cells per block must be between 0 and " + std::to_string(max_grid_cells_per_block) +
                        ", got " + std::to_string(params.grid_cells_per_block));
    params_ = params;
    if (params_.truncation == S(0)) params_.truncation = S(10) * params.voxel_size;
    std::size_t slots = 2;
    while (slots < 2 * std::size_t(params.block_capacity)) slots *= 2;
    slot_keys_.resize(slots);
    slot_blocks_.resize(slots);
    block_keys_.resize(std::size_t(params.block_capacity));
    reset();
  }
  /// The same from the parameters one by one.
  SparseTsdfVolume(S voxel_size, S truncation, const SE3<S>& T_world_volume, int block_capacity, B backend = B{})
      : SparseTsdfVolume(SparseVolumeParams<S>{voxel_size, truncation, T_world_volume, block_capacity}, backend) {}

  /// Forgets everything: no block allocated. The voxel storage grown so far
  /// stays reserved (reset to SDF = truncation, weight = 0) for reuse.
  void reset() {
    thrust::fill(backend_.policy(), slot_keys_.begin(), slot_keys_.end(), detail::sparse::empty_key);
    thrust::fill(backend_.policy(), slot_blocks_.begin(), slot_blocks_.end(), -1);
    thrust::fill(backend_.policy(), sdf_.begin(), sdf_.end(), Store(params_.truncation));
    thrust::fill(backend_.policy(), weight_.begin(), weight_.end(), Store(0));
    allocated_ = 0;
    box_ = detail::sparse::BlockBox{};
    grid_on_ = false;
  }

  const SparseVolumeParams<S>& params() const { return params_; }
  S voxel_size() const { return params_.voxel_size; }
  S truncation() const { return params_.truncation; }
  /// Side of a block in metres.
  S block_size() const { return S(block_side) * params_.voxel_size; }
  const SE3<S>& pose() const { return params_.T_world_volume; }
  void set_pose(const SE3<S>& T_world_volume) { params_.T_world_volume = T_world_volume; }
  const B& backend() const { return backend_; }
  /// Most blocks the volume holds.
  int capacity() const { return params_.block_capacity; }
  int allocated_blocks() const { return allocated_; }
  /// Block coordinates of the box around every allocated block, inclusive;
  /// min > max on some axis when no block is allocated. Kept up to date by
  /// allocation and reset(); ray casting clips its rays to it.
  Vec3i block_min() const { return Vec3i{{box_.lo[0], box_.lo[1], box_.lo[2]}}; }
  Vec3i block_max() const { return Vec3i{{box_.hi[0], box_.hi[1], box_.hi[2]}}; }
  /// Voxels in allocated blocks.
  std::int64_t voxel_count() const { return std::int64_t(allocated_) * block_voxels; }
  /// True while the volume keeps its index grid (lookups read it instead of
  /// the table; SparseVolumeParams::grid_cells_per_block).
  bool has_index_grid() const { return grid_on_; }
  /// Cells of the index grid now (0 without one).
  std::int64_t index_grid_cells() const { return grid_on_ ? std::int64_t(grid_cells_.size()) : 0; }
  /// Bytes reserved now: the hash table, the block keys, the index grid and
  /// the voxel storage grown so far.
  std::size_t memory_bytes() const {
    return table_bytes() + grid_cells_.size() * sizeof(int) + 2 * sdf_.size() * sizeof(Store);
  }
  /// Bytes the volume reserves when every block of its capacity is in use
  /// (and the index grid at its largest).
  std::size_t memory_bound_bytes() const {
    return table_bytes() + std::size_t(grid_limit()) * sizeof(int) +
           2 * std::size_t(params_.block_capacity) * block_voxels * sizeof(Store);
  }

  View view() { return make_view<View>(raw_data(sdf_), raw_data(weight_)); }
  ConstView view() const { return make_view<ConstView>(raw_data(sdf_), raw_data(weight_)); }

  /// Coordinates of the allocated blocks, in storage order (block b's voxels
  /// are b * 512 .. b * 512 + 511 of sdf_to_host()), synchronising first.
  std::vector<Vec3i> blocks_to_host() const {
    const std::vector<Key> keys = vector_to_host(backend_, block_keys_, std::size_t(allocated_));
    std::vector<Vec3i> out(keys.size());
    for (std::size_t b = 0; b < keys.size(); ++b) detail::sparse::unpack_key(keys[b], out[b][0], out[b][1], out[b][2]);
    return out;
  }
  /// SDF values and weights of the allocated blocks as host vectors, 512 per
  /// block in the order of blocks_to_host(), x fastest within a block.
  std::vector<Store> sdf_to_host() const {
    return vector_to_host(backend_, sdf_, std::size_t(allocated_) * block_voxels);
  }
  std::vector<Store> weight_to_host() const {
    return vector_to_host(backend_, weight_, std::size_t(allocated_) * block_voxels);
  }

  /// Replaces the contents with `blocks` (block coordinates: distinct, in
  /// the addressable range, at most the capacity), stored in that order, and
  /// their voxels, 512 per block in the same order, x fastest within a block
  /// (what blocks_to_host(), sdf_to_host() and weight_to_host() give): the
  /// volume then equals the one they were read from, storage order
  /// included. Throws std::invalid_argument, the volume unchanged, when
  /// they do not fit.
  void assign_from_host(const std::vector<Vec3i>& blocks, const std::vector<Store>& sdf,
                        const std::vector<Store>& weight) {
    constexpr const char* where = "SparseTsdfVolume::assign_from_host";
    const std::size_t n = blocks.size();
    detail::require(n <= std::size_t(params_.block_capacity), where,
                    std::to_string(n) + " blocks exceed the capacity of " + std::to_string(params_.block_capacity));
    detail::require(sdf.size() == n * block_voxels && weight.size() == n * block_voxels, where,
                    "need " + std::to_string(n * block_voxels) + " SDF values and weights for " + std::to_string(n) +
                        " blocks, got " + std::to_string(sdf.size()) + " and " + std::to_string(weight.size()));
    // The table is built here and copied: the same lookups as insertion on
    // the backend would give.
    std::vector<Key> slot_keys(slot_keys_.size(), detail::sparse::empty_key), block_keys(n);
    std::vector<int> slot_blocks(slot_blocks_.size(), -1);
    detail::sparse::BlockBox box;
    for (std::size_t b = 0; b < n; ++b) {
      const Vec3i& c = blocks[b];
      detail::require(detail::sparse::block_in_range(c[0], c[1], c[2]), where,
                      "block " + std::to_string(b) + " (" + std::to_string(c[0]) + ", " + std::to_string(c[1]) + ", " +
                          std::to_string(c[2]) + ") is outside the addressable range");
      block_keys[b] = detail::sparse::pack_key(c[0], c[1], c[2]);
      detail::require(detail::sparse::insert_block(slot_keys.data(), slot_blocks.data(), Key(slot_keys.size() - 1),
                                                   block_keys[b], int(b)),
                      where, "block " + std::to_string(b) + " repeats an earlier one");
      for (int a = 0; a < 3; ++a) {
        box.lo[a] = std::min(box.lo[a], c[a]);
        box.hi[a] = std::max(box.hi[a], c[a]);
      }
    }
    reset();
    grow_storage(int(n));
    thrust::copy(slot_keys.begin(), slot_keys.end(), slot_keys_.begin());
    thrust::copy(slot_blocks.begin(), slot_blocks.end(), slot_blocks_.begin());
    if (n > 0) {  // thrust forms a pointer from an empty vector's begin()
      thrust::copy(block_keys.begin(), block_keys.end(), block_keys_.begin());
      thrust::copy(sdf.begin(), sdf.end(), sdf_.begin());
      thrust::copy(weight.begin(), weight.end(), weight_.begin());
    }
    allocated_ = int(n);
    box_ = box;
    update_grid(0, allocated_);
  }

  /// A copy of this volume on another backend (the same blocks at the same
  /// storage indices; the voxel storage sized to the allocated blocks).
  template <Backend B2>
  SparseTsdfVolume<S, B2, Store> to(B2 backend = B2{}) const {
    backend_.synchronize();
    SparseTsdfVolume<S, B2, Store> out(params_, backend);
    thrust::copy(slot_keys_.begin(), slot_keys_.end(), out.slot_keys_.begin());
    thrust::copy(slot_blocks_.begin(), slot_blocks_.end(), out.slot_blocks_.begin());
    thrust::copy(block_keys_.begin(), block_keys_.end(), out.block_keys_.begin());
    out.grow_storage(allocated_);
    const auto voxels = std::ptrdiff_t(allocated_) * block_voxels;
    if (voxels > 0) {  // thrust forms a pointer from an empty vector's begin()
      thrust::copy(sdf_.begin(), sdf_.begin() + voxels, out.sdf_.begin());
      thrust::copy(weight_.begin(), weight_.begin() + voxels, out.weight_.begin());
    }
    out.allocated_ = allocated_;
    out.box_ = box_;
    out.update_grid(0, allocated_);
    return out;
  }

  /// Allocates the blocks of keys[0, count) (detail::sparse::pack_key; on the
  /// volume's backend) that are not stored yet, in parallel: drops the keys
  /// already stored, sorts and de-duplicates the rest in place, and inserts
  /// them, as many as the capacity allows. The ones refused are the largest
  /// keys (the order of the sort), so the outcome does not depend on thread
  /// timing. allocate_blocks() gives it a depth frame's keys.
  BlockAllocation allocate_keys(typename B::template Vector<Key>& keys, std::size_t count) {
    detail::require(count <= keys.size(), "SparseTsdfVolume::allocate_keys",
                    "count " + std::to_string(count) + " exceeds the " + std::to_string(keys.size()) + " keys given");
    if (count == 0) return {};
    const auto end = thrust::remove_if(scratch_policy(backend_, scratch_), keys.begin(),
                                       keys.begin() + std::ptrdiff_t(count), stored());
    return allocate_new_keys(keys, std::size_t(end - keys.begin()));
  }

  /// The test "is this key stored?" on the volume's backend.
  detail::sparse::IsStored stored() const {
    return {raw_data(slot_keys_), raw_data(slot_blocks_), Key(slot_keys_.size() - 1), grid_view()};
  }

  /// Writes the indices of the allocated blocks b for which pred(b) holds
  /// (an EMF_HD functor) to the front of `out`, grown as needed, in
  /// increasing order; returns how many.
  template <class Pred>
  std::int64_t select_blocks(typename B::template Vector<int>& out, Pred pred) {
    if (allocated_ == 0) return 0;
    if (out.size() < std::size_t(allocated_)) out.resize(std::size_t(allocated_));
    const auto end = thrust::copy_if(scratch_policy(backend_, scratch_), thrust::counting_iterator<int>(0),
                                     thrust::counting_iterator<int>(allocated_), out.begin(), pred);
    return end - out.begin();
  }

  /// allocate_keys() for keys[0, count) none of which is stored (repeats
  /// allowed): what allocate_blocks() gives, having dropped the stored ones
  /// as it found them.
  BlockAllocation allocate_new_keys(typename B::template Vector<Key>& keys, std::size_t count) {
    BlockAllocation result;
    if (count == 0) return result;
    const auto begin = keys.begin(), end = keys.begin() + std::ptrdiff_t(count);
    thrust::sort(scratch_policy(backend_, scratch_), begin, end);
    const std::int64_t fresh = thrust::unique(scratch_policy(backend_, scratch_), begin, end) - begin;
    const std::int64_t room = std::int64_t(params_.block_capacity) - allocated_;
    const int inserted = int(std::min(fresh, room));
    result.inserted = inserted;
    result.refused = fresh - inserted;
    if (inserted == 0) return result;
    grow_storage(allocated_ + inserted);
    for_each_index(backend_, inserted,
                   detail::sparse::InsertBlock{raw_data(keys), raw_data(slot_keys_), raw_data(slot_blocks_),
                                               Key(slot_keys_.size() - 1), raw_data(block_keys_), allocated_});
    allocated_ += inserted;
    box_ = box_.merged(transform_reduce_index(backend_, inserted, detail::sparse::BoxOfKey{raw_data(keys)},
                                              detail::sparse::BlockBox{}, detail::sparse::MergeBoxes{}));
    update_grid(allocated_ - inserted, inserted);
    return result;
  }

 private:
  template <class, Backend, class>
  friend class SparseTsdfVolume;

  std::size_t table_bytes() const {
    return slot_keys_.size() * (sizeof(Key) + sizeof(int)) + block_keys_.size() * sizeof(Key);
  }
  std::int64_t grid_limit() const { return std::int64_t(params_.block_capacity) * params_.grid_cells_per_block; }
  static std::int64_t cells_of(const detail::sparse::BlockBox& b) {
    std::int64_t n = 1;
    for (int a = 0; a < 3; ++a) n *= b.hi[a] < b.lo[a] ? 0 : std::int64_t(b.hi[a]) - b.lo[a] + 1;
    return n;
  }
  /// The index grid as kernels read it: no cells when there is none.
  detail::sparse::BlockGrid grid_view() const {
    detail::sparse::BlockGrid g;
    if (!grid_on_) return g;
    g.cells = raw_data(grid_cells_);
    for (int a = 0; a < 3; ++a) g.lo[a] = grid_box_.lo[a], g.size[a] = grid_box_.hi[a] - grid_box_.lo[a] + 1;
    return g;
  }
  /// Keeps the index grid in step with the blocks after blocks first ..
  /// first + count - 1 were stored: writes them into it while its box holds
  /// every block; otherwise builds it anew over the blocks' box with a
  /// quarter of its extent to spare on each side (less if that exceeds the
  /// budget), or goes without when even the bare box exceeds it.
  void update_grid(int first, int count) {
    if (grid_limit() == 0 || allocated_ == 0) return;
    if (grid_on_ && grid_box_.contains(box_)) {
      scatter_to_grid(first, count);
      return;
    }
    detail::sparse::BlockBox padded = box_;
    for (int a = 0; a < 3; ++a) {
      const int pad = std::max(2, (box_.hi[a] - box_.lo[a] + 1) / 4);
      padded.lo[a] = std::max(box_.lo[a] - pad, -detail::sparse::block_limit);
      padded.hi[a] = std::min(box_.hi[a] + pad, detail::sparse::block_limit - 1);
    }
    const detail::sparse::BlockBox grid_box = cells_of(padded) <= grid_limit() ? padded : box_;
    const bool fits = cells_of(grid_box) <= grid_limit();
    if (!fits && grid_cells_.empty()) return;  // none to build, none to free: no wait for the backend
    backend_.synchronize();                    // kernels in flight may read the old grid
    if (!fits) {
      grid_on_ = false;
      typename B::template Vector<int>().swap(grid_cells_);
      return;
    }
    typename B::template Vector<int>(std::size_t(cells_of(grid_box))).swap(grid_cells_);
    thrust::fill(backend_.policy(), grid_cells_.begin(), grid_cells_.end(), -1);
    grid_box_ = grid_box;
    grid_on_ = true;
    scatter_to_grid(0, allocated_);
  }
  void scatter_to_grid(int first, int count) {
    if (count > 0)
      for_each_index(backend_, count,
                     detail::sparse::ScatterToGrid{raw_data(block_keys_), raw_data(grid_cells_), grid_view(), first});
  }
  /// Makes the voxel storage hold at least `blocks` blocks: doubling, capped
  /// at the capacity, reallocated to the exact size (a vector's own growth
  /// could overshoot the memory bound). New voxels are never observed.
  void grow_storage(int blocks) {
    const std::size_t stored = sdf_.size() / block_voxels;
    if (std::size_t(blocks) <= stored) return;
    const std::size_t doubled = std::max<std::size_t>(2 * stored, 64);
    const std::size_t target =
        std::max<std::size_t>(std::size_t(blocks), std::min<std::size_t>(doubled, std::size_t(params_.block_capacity)));
    backend_.synchronize();
    grow(sdf_, target * block_voxels, Store(params_.truncation));
    grow(weight_, target * block_voxels, Store(0));
  }
  template <class Vec>
  static void grow(Vec& v, std::size_t size, const Store& fill) {
    Vec grown(size, fill);
    if (!v.empty()) thrust::copy(v.begin(), v.end(), grown.begin());
    v.swap(grown);
  }

  template <class V, class P>
  V make_view(P* sdf, P* weight) const {
    V v;
    v.sdf = sdf, v.weight = weight;
    v.slot_keys = raw_data(slot_keys_), v.slot_blocks = raw_data(slot_blocks_);
    v.slot_mask = Key(slot_keys_.size() - 1);
    v.block_keys = raw_data(block_keys_), v.blocks = allocated_;
    v.voxel_size = params_.voxel_size, v.truncation = params_.truncation;
    v.block_lo = block_min(), v.block_hi = block_max();
    v.grid = grid_view();
    return v;
  }

  SparseVolumeParams<S> params_;
  B backend_;
  ScratchFor<B> scratch_;  // temporaries of the sorts and compactions
  typename B::template Vector<Key> slot_keys_;    // hash table: key per slot (empty_key = free)
  typename B::template Vector<int> slot_blocks_;  // hash table: block index per slot
  typename B::template Vector<Key> block_keys_;   // key of block b (capacity entries)
  typename B::template Vector<Store> sdf_;        // voxel storage, 512 per block
  typename B::template Vector<Store> weight_;
  int allocated_ = 0;
  detail::sparse::BlockBox box_;                // around the allocated blocks
  typename B::template Vector<int> grid_cells_;  // index grid: block per cell of grid_box_, -1 for none
  detail::sparse::BlockBox grid_box_;           // holds box_ while grid_on_
  bool grid_on_ = false;
};

/// Scratch memory of sparse allocation and integration; pass one to reuse it
/// across frames instead of allocating it every call.
template <class S, Backend B>
struct SparseIntegrationWorkspace {
  IntegrationWorkspace<S, B> images;                        ///< integrate()'s derived images
  typename B::template Vector<unsigned long long> keys;     ///< new block keys of the band
  typename B::template Vector<unsigned long long> counter;  ///< how many (on a device)
  typename B::template Vector<int> blocks;                  ///< blocks in view
};

/// Allocates the blocks the truncation band of `depth` touches (metres, 0 =
/// invalid), seen by `camera` at `T_world_camera`: for every valid pixel, the
/// blocks along its ray from d - truncation to d + truncation, sampled at
/// most half a block apart (up to 32 samples, further apart only for
/// truncations over 7.75 blocks). With `weights`, only pixels of positive
/// weight allocate (the rest would not change a voxel near their surface).
/// In parallel on the volume's backend: the keys per pixel that the table
/// does not hold yet, then sort and unique of those, then insertion with
/// compare-and-swap (SparseTsdfVolume::allocate_new_keys).
template <class S, Backend B, class Store>
BlockAllocation allocate_blocks(SparseTsdfVolume<S, B, Store>& volume, const Image<S, B>& depth,
                                const PinholeCamera<S>& camera, const SE3<S>& T_world_camera,
                                const Image<S, B>* weights = nullptr,
                                SparseIntegrationWorkspace<S, B>* workspace = nullptr) {
  constexpr const char* where = "allocate_blocks";
  camera.validate(where);
  detail::require_image(depth.view(), camera.width, camera.height, where, "depth image");
  if (weights) detail::require_image(weights->view(), depth.width(), depth.height(), where, "weight image");
  SparseIntegrationWorkspace<S, B> local;
  SparseIntegrationWorkspace<S, B>& ws = workspace ? *workspace : local;
  const S trunc = volume.truncation(), block = volume.block_size();
  // Samples at most half a block apart over the band of 2 truncations.
  const int samples = std::clamp(int(std::ceil(S(4) * trunc / block)) + 1, 2, detail::sparse::max_band_samples);
  const std::size_t slots = std::size_t(depth.size()) * std::size_t(samples);
  if (ws.keys.size() < slots) ws.keys.resize(slots);
  if (ws.counter.size() < 1) ws.counter.resize(1);
  detail::sparse::BandBlockKeys<S> f{depth.view(),
                                     weights ? weights->view() : ImageView<const S>{},
                                     camera,
                                     volume.pose().inverse() * T_world_camera,
                                     trunc,
                                     block,
                                     samples,
                                     volume.stored(),
                                     raw_data(ws.keys),
                                     raw_data(ws.counter)};
  std::size_t count = 0;
  if constexpr (B::is_device) {
    thrust::fill(volume.backend().policy(), ws.counter.begin(), ws.counter.end(), 0ull);
    for_each_index(volume.backend(), depth.size(), f);
    unsigned long long written = 0;
    copy_to_host(volume.backend(), f.count, 1, &written);
    count = std::size_t(written);
  } else {
    // Chunks of rows; then each chunk's keys moved to follow the previous.
    const int chunks = std::min(depth.height(), 64);
    std::vector<std::int64_t> counts(std::size_t(chunks), 0);
    for_each_index(volume.backend(), chunks, detail::sparse::BandBlockKeyRows<S>{f, chunks, counts.data()});
    unsigned long long* data = f.out;
    for (int c = 0; c < chunks; ++c) {
      const std::int64_t first = std::int64_t(c) * depth.height() / chunks * depth.width() * samples;
      std::copy(data + first, data + first + counts[std::size_t(c)], data + count);
      count += std::size_t(counts[std::size_t(c)]);
    }
  }
  return volume.allocate_new_keys(ws.keys, count);
}

/// What integrate() did to a sparse volume.
struct SparseIntegration {
  BlockAllocation allocation;
  std::int64_t blocks_in_view = 0;  ///< allocated blocks whose voxels were visited
};

/// Fuses `depth` into a sparse volume: allocates the blocks of its truncation
/// band (allocate_blocks, the pixels of positive weight when q(u), i.e.
/// `weights.owned`, is given), then applies the dense volume's per-voxel
/// update (eq. 10 with `params` and `weights`, integrate.hpp) to every voxel
/// of every allocated block in view, so that a voxel, once allocated,
/// evolves exactly as the dense volume's voxel at the same place. Space
/// outside allocated blocks is not carved: it stays never observed.
template <class S, Backend B, class Store>
SparseIntegration integrate(SparseTsdfVolume<S, B, Store>& volume, const Image<S, B>& depth,
                            const PinholeCamera<S>& camera, const SE3<S>& T_world_camera,
                            const IntegrationWeights<S, B>& weights, const IntegrationParams<S>& params = {},
                            SparseIntegrationWorkspace<S, B>* workspace = nullptr) {
  SparseIntegrationWorkspace<S, B> local;
  SparseIntegrationWorkspace<S, B>& ws = workspace ? *workspace : local;
  const B& backend = volume.backend();
  const detail::VoxelUpdate<S> update = detail::prepare_voxel_update(
      depth, camera, weights, params, volume.voxel_size(), volume.truncation(), backend, ws.images, "integrate",
      PixelBox::whole(camera.width, camera.height));
  SparseIntegration result;
  result.allocation = allocate_blocks(volume, depth, camera, T_world_camera, weights.owned, &ws);
  const SE3<S> T_camera_volume = T_world_camera.inverse() * volume.pose();
  S far = std::numeric_limits<S>::infinity();
  // As for the dense volume: the far plane pays on the CPU only.
  if constexpr (!B::is_device) {
    far = max_valid_depth(depth) + volume.truncation();
    if (!(far > volume.truncation())) return result;  // no measurement at all
  }
  const auto view = volume.view();
  result.blocks_in_view = volume.select_blocks(
      ws.blocks, detail::sparse::BlockInView<S>{view.block_keys, camera, T_camera_volume, volume.block_size(), far});
  using Column =
      detail::sparse::IntegrateBlockColumn<S, typename SparseTsdfVolume<S, B, Store>::View, detail::VoxelUpdate<S>>;
  for_each_index(backend, result.blocks_in_view * std::int64_t(detail::sparse::block_side * detail::sparse::block_side),
                 Column{view, raw_data(ws.blocks), update, T_camera_volume});
  return result;
}

/// The same with q(u) alone: `weights` (optional) of the depth image's size.
template <class S, Backend B, class Store>
SparseIntegration integrate(SparseTsdfVolume<S, B, Store>& volume, const Image<S, B>& depth,
                            const PinholeCamera<S>& camera, const SE3<S>& T_world_camera,
                            const Image<S, B>* weights = nullptr, const IntegrationParams<S>& params = {},
                            SparseIntegrationWorkspace<S, B>* workspace = nullptr) {
  return integrate(volume, depth, camera, T_world_camera, IntegrationWeights<S, B>{weights, nullptr}, params,
                   workspace);
}

}  // namespace emfusion
