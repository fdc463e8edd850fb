// Voxel blocks of the sparse TSDF volume and the spatial hash table that finds
// them: block keys (three signed block coordinates packed into one 64-bit
// word), the hash, and lookup and insertion by linear probing on raw arrays,
// callable in kernels on either backend.
//
// The table is open addressing over a power-of-two number of slots, at least
// twice the volume's block capacity, so it is never more than half full and
// every probe sequence reaches an empty slot. A slot holds a key (empty_key
// when free) and the index of the block's voxels in the volume's storage.
// Slots are claimed with an atomic compare-and-swap on the key; keys are
// never removed (a reset empties the whole table), so a lookup may stop at
// the first empty slot.
#pragma once

#include <cstdint>

#include "emfusion/core/atomic.hpp"
#include "emfusion/core/host_device.hpp"

namespace emfusion::detail::sparse {

using Key = unsigned long long;

inline constexpr int block_side = 8;        ///< voxels along each axis of a block
inline constexpr int block_shift = 3;       ///< log2(block_side)
inline constexpr int block_voxels = 512;    ///< block_side^3
inline constexpr int coordinate_bits = 21;  ///< per axis of a key
/// Block coordinates lie in [-block_limit, block_limit) on each axis.
inline constexpr int block_limit = 1 << (coordinate_bits - 1);
/// Voxel coordinates lie in [-voxel_limit, voxel_limit) on each axis.
inline constexpr int voxel_limit = block_limit * block_side;
/// Marks a free slot: bit 63 is set, which no packed key has.
inline constexpr Key empty_key = ~Key(0);

EMF_HD inline bool block_in_range(int bx, int by, int bz) {
  return bx >= -block_limit && by >= -block_limit && bz >= -block_limit && bx < block_limit && by < block_limit &&
         bz < block_limit;
}

/// The key of block (bx, by, bz), which must be in range. Keys order blocks
/// by x, then y, then z.
EMF_HD inline Key pack_key(int bx, int by, int bz) {
  const Key mask = (Key(1) << coordinate_bits) - 1;
  return ((Key(bx + block_limit) & mask) << (2 * coordinate_bits)) |
         ((Key(by + block_limit) & mask) << coordinate_bits) | (Key(bz + block_limit) & mask);
}

EMF_HD inline void unpack_key(Key key, int& bx, int& by, int& bz) {
  const Key mask = (Key(1) << coordinate_bits) - 1;
  bx = int((key >> (2 * coordinate_bits)) & mask) - block_limit;
  by = int((key >> coordinate_bits) & mask) - block_limit;
  bz = int(key & mask) - block_limit;
}

/// A 64-bit finaliser (the one of splitmix64): neighbouring blocks land in
/// unrelated slots, so runs of occupied slots stay short.
EMF_HD inline Key mix(Key x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ull;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebull;
  x ^= x >> 31;
  return x;
}

/// The block index stored under `key`, or -1.
EMF_HD EMF_NOINLINE_ON_CUDA inline int find_block(const Key* slot_keys, const int* slot_blocks, Key slot_mask, Key key) {
  Key slot = mix(key) & slot_mask;
  for (Key probe = 0; probe <= slot_mask; ++probe) {
    const Key k = slot_keys[slot];
    if (k == key) return slot_blocks[slot];
    if (k == empty_key) return -1;
    slot = (slot + 1) & slot_mask;
  }
  return -1;
}

/// Stores `key` -> `block` in the first free slot of its probe sequence; safe
/// to call from many threads at once with distinct keys. False if the key was
/// already there (its block index is then left as it was) or no slot is free.
EMF_HD inline bool insert_block(Key* slot_keys, int* slot_blocks, Key slot_mask, Key key, int block) {
  Key slot = mix(key) & slot_mask;
  for (Key probe = 0; probe <= slot_mask; ++probe) {
    const Key previous = atomic_compare_and_swap(&slot_keys[slot], empty_key, key);
    if (previous == empty_key) {
      // Nobody reads the slot before the insertion kernel has finished.
      slot_blocks[slot] = block;
      return true;
    }
    if (previous == key) return false;
    slot = (slot + 1) & slot_mask;
  }
  return false;
}

/// A dense index over a box of block coordinates: the storage index of
/// every block in the box, -1 where none is allocated. The volume keeps one
/// around its allocated blocks while it fits its budget
/// (SparseVolumeParams::grid_cells_per_block), so that finding a block is one
/// read instead of a walk along the hash table's probe sequence; the table
/// stays the record of what is stored. `cells` null: no grid.
struct BlockGrid {
  const int* cells = nullptr;
  int lo[3] = {0, 0, 0};    ///< block coordinates of cell 0
  int size[3] = {0, 0, 0};  ///< cells along each axis, x fastest

  /// The block at (bx, by, bz): -1 outside the box, which holds every
  /// allocated block.
  EMF_HD int find(int bx, int by, int bz) const {
    // Unsigned differences: below lo wraps to a large value, one test a side.
    const unsigned ux = unsigned(bx) - unsigned(lo[0]), uy = unsigned(by) - unsigned(lo[1]),
                   uz = unsigned(bz) - unsigned(lo[2]);
    if (ux >= unsigned(size[0]) || uy >= unsigned(size[1]) || uz >= unsigned(size[2])) return -1;
    return cells[cell(int(ux), int(uy), int(uz))];
  }
  /// The cell of offsets (ux, uy, uz) from lo, each within size: x fastest.
  EMF_HD std::int64_t cell(int ux, int uy, int uz) const {
    return (std::int64_t(uz) * size[1] + uy) * size[0] + ux;
  }
};

/// Writes block first + i into the grid (`cells` writable, its box holding
/// the block).
struct ScatterToGrid {
  const Key* block_keys;
  int* cells;
  BlockGrid grid;  // its box
  int first;
  EMF_HD void operator()(int i) const {
    int bx, by, bz;
    unpack_key(block_keys[first + i], bx, by, bz);
    cells[grid.cell(bx - grid.lo[0], by - grid.lo[1], bz - grid.lo[2])] = first + i;
  }
};

/// Offset of voxel (lx, ly, lz) (0..7 each) inside its block: x fastest.
EMF_HD inline int local_index(int lx, int ly, int lz) { return (lz * block_side + ly) * block_side + lx; }

/// The SDF values and weights of the eight voxels (x + dx, y + dy, z + dz),
/// dx, dy, dz in {0, 1} (index bits: 1 -> dx, 2 -> dy, 4 -> dz), where
/// find(bx, by, bz) gives a block's index in the storage or -1: truncation
/// and weight 0 in a block that is not allocated. Each block the eight span
/// is looked up once (one block seven times in eight), and nothing is
/// indexed at run time, so on a CUDA device everything stays in registers.
template <class S, class Store, class Find>
EMF_HD EMF_INLINE_ON_HOST inline void gather_eight(Find&& find, int x, int y, int z, const Store* sdf,
                                                   const Store* weight, S truncation, S* v, S* w) {
  const int bx = x >> block_shift, by = y >> block_shift, bz = z >> block_shift;
  const int lx = x & (block_side - 1), ly = y & (block_side - 1), lz = z & (block_side - 1);
  const bool ox = lx == block_side - 1, oy = ly == block_side - 1, oz = lz == block_side - 1;
  int b[8];  // the block of voxel k
  b[0] = find(bx, by, bz);
  b[1] = ox ? find(bx + 1, by, bz) : b[0];
  b[2] = oy ? find(bx, by + 1, bz) : b[0];
  b[3] = oy ? (ox ? find(bx + 1, by + 1, bz) : b[2]) : b[1];
  b[4] = oz ? find(bx, by, bz + 1) : b[0];
  b[5] = oz ? (ox ? find(bx + 1, by, bz + 1) : b[4]) : b[1];
  b[6] = oz ? (oy ? find(bx, by + 1, bz + 1) : b[4]) : b[2];
  b[7] = oz ? (oy ? (ox ? find(bx + 1, by + 1, bz + 1) : b[6]) : b[5]) : b[3];
  for (int k = 0; k < 8; ++k) {
    const int vx = (lx + (k & 1)) & (block_side - 1), vy = (ly + ((k >> 1) & 1)) & (block_side - 1),
              vz = (lz + ((k >> 2) & 1)) & (block_side - 1);
    const std::int64_t i = std::int64_t(b[k]) * block_voxels + local_index(vx, vy, vz);
    v[k] = b[k] < 0 ? truncation : S(sdf[i]);
    w[k] = b[k] < 0 ? S(0) : S(weight[i]);
  }
}

/// An axis-aligned box of block coordinates, inclusive; empty (lo > hi) by
/// default. The volume keeps the one around its allocated blocks.
struct BlockBox {
  int lo[3] = {block_limit, block_limit, block_limit};
  int hi[3] = {-block_limit - 1, -block_limit - 1, -block_limit - 1};

  EMF_HD BlockBox merged(const BlockBox& other) const {
    BlockBox r;
    for (int a = 0; a < 3; ++a) {
      r.lo[a] = lo[a] < other.lo[a] ? lo[a] : other.lo[a];
      r.hi[a] = hi[a] > other.hi[a] ? hi[a] : other.hi[a];
    }
    return r;
  }
  /// True if every block of `other` lies in this box.
  EMF_HD bool contains(const BlockBox& other) const {
    for (int a = 0; a < 3; ++a)
      if (other.lo[a] < lo[a] || other.hi[a] > hi[a]) return false;
    return true;
  }
};

/// The box of the one block of keys[i].
struct BoxOfKey {
  const Key* keys;
  EMF_HD BlockBox operator()(std::int64_t i) const {
    BlockBox box;
    unpack_key(keys[i], box.lo[0], box.lo[1], box.lo[2]);
    for (int a = 0; a < 3; ++a) box.hi[a] = box.lo[a];
    return box;
  }
};

struct MergeBoxes {
  EMF_HD BlockBox operator()(const BlockBox& a, const BlockBox& b) const { return a.merged(b); }
};

}  // namespace emfusion::detail::sparse
