// Trilinear samples of a sparse TSDF volume, written once for its two
// readers: SparseTsdfView, whose every sample looks its blocks up in the hash
// table, and NearbySparseSampler (volume/nearby_samples.hpp), which looks
// them up in a cache of the last blocks first. Both hand SparseSamples the
// way they find a block; the arithmetic is this file's, so the two agree bit
// for bit.
#pragma once

#include <cmath>

#include "emfusion/core/host_device.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/volume/detail/sparse_blocks.hpp"
#include "emfusion/volume/detail/trilinear.hpp"

namespace emfusion::detail::sparse {

/// The lower corner of the eight voxel centres around a point, and the
/// point's fractions between them.
template <class S>
struct Corner {
  int x, y, z;
  S fx, fy, fz;
};

/// Corner of volume-frame point p; false outside the addressable range, with
/// a voxel to spare (and for NaN).
template <class S>
EMF_HD bool corner_of(const Vec3<S>& p, S voxel_size, Corner<S>& c) {
  const S gx = p.x() / voxel_size - S(0.5), gy = p.y() / voxel_size - S(0.5), gz = p.z() / voxel_size - S(0.5);
  // Written so that NaN coordinates fail the test.
  const S l = S(voxel_limit - 2);
  if (!(gx >= -l && gy >= -l && gz >= -l && gx < l && gy < l && gz < l)) return false;
  c.x = int(std::floor(gx)), c.y = int(std::floor(gy)), c.z = int(std::floor(gz));
  c.fx = gx - S(c.x), c.fy = gy - S(c.y), c.fz = gz - S(c.z);
  return true;
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
  EMF_HD void gather(const Corner<S>& c, S* v, S* w) const {
    gather_eight(find, c.x, c.y, c.z, sdf, weight, truncation, v, w);
  }

  /// Trilinear SDF at p, its interpolated weight (if `weight_out`) and the
  /// interpolant's exact gradient (if `gradient`); false, the outputs left
  /// alone, if one of the eight voxels was never observed.
  EMF_HD bool sample(const Vec3<S>& p, S& sdf_out, S* weight_out, Vec3<S>* gradient = nullptr) const {
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
  EMF_HD bool sample_observed(const Vec3<S>& p, S& sdf_out, S min_coverage) const {
    Corner<S> c;
    if (!corner_of(p, voxel_size, c)) return false;
    S v[8], w[8];
    gather(c, v, w);
    return trilinear::interpolate_observed(v, w, c.fx, c.fy, c.fz, min_coverage, sdf_out);
  }
};

template <class S, class Store, class Find>
EMF_HD SparseSamples<S, Store, Find> samples_of(Find find, const Store* sdf, const Store* weight, S voxel_size,
                                                S truncation) {
  return {find, sdf, weight, voxel_size, truncation};
}

}  // namespace emfusion::detail::sparse
