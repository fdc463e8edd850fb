// Trilinear samples and the empty-space walk of a sparse TSDF volume,
// written once for its readers: SparseTsdfView, which looks its blocks up in
// its index grid or its hash table, and the samplers of
// volume/nearby_samples.hpp (a cache of the last blocks before the table, or
// the grid alone). Each hands SparseSamples and walk_to_allocated the way it
// finds a block; the arithmetic is this file's, so all agree bit for bit.
#pragma once

#include <cmath>
#include <limits>

#include "emfusion/core/host_device.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/volume/detail/sparse_blocks.hpp"
#include "emfusion/volume/detail/trilinear.hpp"

namespace emfusion::detail::sparse {

template <class S>
using Corner = trilinear::Cell<S>;

/// Corner of volume-frame point p; false outside the addressable range, with
/// a voxel to spare (and for NaN).
template <class S>
EMF_HD EMF_INLINE_ON_HOST inline bool corner_of(const Vec3<S>& p, S voxel_size, Corner<S>& c) {
  const S l = S(voxel_limit - 2);
  return trilinear::cell_of(p, voxel_size, vec3(-l, -l, -l), vec3(l, l, l), c);
}

/// The samples of a sparse volume's voxels (`sdf`, `weight`, blocks of
/// block_voxels) through `find(bx, by, bz)`, a block's storage index or -1.
/// A temporary of one sample call: it holds pointers and the finder.
template <class S, class Store, class Find>
struct SparseSamples {
  Find find;
  const Store* sdf;
  const Store* weight;
  S voxel_size;
  S truncation;

  /// The eight voxels around c (index bits: 1 -> +x, 2 -> +y, 4 -> +z),
  /// truncation and weight 0 in a block that is not allocated.
  EMF_HD EMF_INLINE_ON_HOST void gather(const Corner<S>& c, S* v, S* w) const {
    gather_eight(find, c.x, c.y, c.z, sdf, weight, truncation, v, w);
  }

  /// Trilinear SDF at p, its interpolated weight (if `weight_out`) and the
  /// interpolant's exact gradient (if `gradient`); false, the outputs left
  /// alone, if one of the eight voxels was never observed.
  EMF_HD EMF_INLINE_ON_HOST bool sample(const Vec3<S>& p, S& sdf_out, S* weight_out,
                                        Vec3<S>* gradient = nullptr) const {
    Corner<S> c;
    if (!corner_of(p, voxel_size, c)) return false;
    S v[8], w[8];
    gather(c, v, w);
    for (int k = 0; k < 8; ++k)
      if (!(w[k] > S(0))) return false;
    sdf_out = trilinear::interpolate(v, c.fx, c.fy, c.fz);
    if (weight_out) *weight_out = trilinear::interpolate(w, c.fx, c.fy, c.fz);
    if (gradient) *gradient = trilinear::gradient(v, c.fx, c.fy, c.fz, voxel_size);
    return true;
  }

  /// Trilinear SDF over the observed voxels of the eight, their weights
  /// renormalised: true where they carry at least `min_coverage` of it.
  EMF_HD EMF_INLINE_ON_HOST bool sample_observed(const Vec3<S>& p, S& sdf_out, S min_coverage) const {
    Corner<S> c;
    if (!corner_of(p, voxel_size, c)) return false;
    S v[8], w[8];
    gather(c, v, w);
    return trilinear::interpolate_observed(v, w, c.fx, c.fy, c.fz, min_coverage, sdf_out);
  }
};

/// One axis of walk_to_allocated: the direction it steps blocks in, the
/// distance t of its next block border, and the distance between its
/// borders (the largest S where the ray runs parallel to it).
template <class S>
struct DdaAxis {
  int step;
  S next, delta;
  EMF_HD static DdaAxis of(S p, S d, int b, S side, S t) {
    if (d > S(0)) return {1, t + (S(b + 1) * side - p) / d, side / d};
    if (d < S(0)) return {-1, t + (S(b) * side - p) / d, -side / d};
    const S huge = std::numeric_limits<S>::max();
    return {0, huge, huge};
  }
};

/// Empty-space skipping along the ray o + t d (volume frame, d of any
/// length but not zero) through `find(bx, by, bz)` (a block's storage index
/// or -1) over blocks of `side` metres: if the block at o + t d is
/// allocated, returns false and leaves t alone; otherwise walks the blocks
/// the ray passes through (a 3D digital differential analyser, one lookup
/// per block) and returns true with t where the ray enters the first
/// allocated block, or beyond t_end when there is none before it. Written
/// with one variable per axis, no arrays indexed at run time: on a CUDA
/// device those would live in local memory.
template <class S, class Find>
EMF_HD bool walk_to_allocated(Find&& find, S side, const Vec3<S>& o, const Vec3<S>& d, S& t, S t_end) {
  const Vec3<S> p = o + t * d;
  const S limit = S(block_limit);
  const S gx = p.x() / side, gy = p.y() / side, gz = p.z() / side;
  // Written so that NaN fails too; out of range counts as allocated (no skip).
  if (!(gx >= -limit && gx < limit && gy >= -limit && gy < limit && gz >= -limit && gz < limit)) return false;
  int bx = int(std::floor(gx)), by = int(std::floor(gy)), bz = int(std::floor(gz));
  if (find(bx, by, bz) >= 0) return false;
  const DdaAxis<S> ax = DdaAxis<S>::of(p.x(), d.x(), bx, side, t), ay = DdaAxis<S>::of(p.y(), d.y(), by, side, t),
                   az = DdaAxis<S>::of(p.z(), d.z(), bz, side, t);
  S next_x = ax.next, next_y = ay.next, next_z = az.next;
  // Each axis crosses at most (t_end - t) |d_a| / side + 1 block borders.
  const S span = (t_end - t) * (std::fabs(d[0]) + std::fabs(d[1]) + std::fabs(d[2])) / side;
  const int max_blocks = span < S(1 << 24) ? int(span) + 4 : (1 << 24);
  for (int k = 0; k < max_blocks; ++k) {
    S t_cross;
    if (next_x <= next_y && next_x <= next_z) {
      if (!((t_cross = next_x) <= t_end)) break;
      bx += ax.step, next_x += ax.delta;
    } else if (next_y <= next_z) {
      if (!((t_cross = next_y) <= t_end)) break;
      by += ay.step, next_y += ay.delta;
    } else {
      if (!((t_cross = next_z) <= t_end)) break;
      bz += az.step, next_z += az.delta;
    }
    if (find(bx, by, bz) >= 0) {
      t = t_cross > t ? t_cross : t;
      return true;
    }
  }
  t = t_end + side;
  return true;
}

template <class S, class Store, class Find>
EMF_HD SparseSamples<S, Store, Find> samples_of(Find find, const Store* sdf, const Store* weight, S voxel_size,
                                                S truncation) {
  return {find, sdf, weight, voxel_size, truncation};
}

}  // namespace emfusion::detail::sparse
