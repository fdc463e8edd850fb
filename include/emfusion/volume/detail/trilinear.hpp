// The arithmetic every TSDF sampler shares, whatever stores its voxels (the
// dense TsdfView, the sparse SparseTsdfView, volume/nearby_samples.hpp's
// cached sampler): trilinear interpolation of a cell's eight voxels and its
// exact gradient, and the two finite-difference gradients built on a
// sampler's own samples, and the cell of voxel centres around a point. One
// copy, so that the samplers agree bit for bit.
// Corner order everywhere: index bit 1 -> +x, 2 -> +y, 4 -> +z.
#pragma once

#include "emfusion/core/host_device.hpp"
#include "emfusion/core/math.hpp"

namespace emfusion::detail::trilinear {

/// The cell of voxel centres around a volume-frame point (voxel i's centre
/// at (i + 1/2) voxel_size): its lower corner voxel and the point's
/// fractions towards the upper one.
template <class S>
struct Cell {
  int x, y, z;
  S fx, fy, fz;
};

/// The cell around volume-frame point p when p, in voxel units from the
/// first centre, lies in [lo, hi) on every axis; false outside (and for NaN).
template <class S>
EMF_HD EMF_INLINE_ON_HOST inline bool cell_of(const Vec3<S>& p, S voxel_size, const Vec3<S>& lo, const Vec3<S>& hi,
                                              Cell<S>& c) {
  const S gx = p.x() / voxel_size - S(0.5), gy = p.y() / voxel_size - S(0.5), gz = p.z() / voxel_size - S(0.5);
  // Written so that NaN coordinates fail the test.
  if (!(gx >= lo.x() && gy >= lo.y() && gz >= lo.z() && gx < hi.x() && gy < hi.y() && gz < hi.z())) return false;
  // floor without a library call (the samplers' inner loop): truncation,
  // one less below zero where g is not whole.
  const auto lower = [](S g) {
    const int i = int(g);
    return S(i) > g ? i - 1 : i;
  };
  c.x = lower(gx), c.y = lower(gy), c.z = lower(gz);
  c.fx = gx - S(c.x), c.fy = gy - S(c.y), c.fz = gz - S(c.z);
  return true;
}

/// The cell around p in a dense grid of nx x ny x nz voxels: false where p
/// is outside the grid of voxel centres (the eight voxels must exist).
template <class S>
EMF_HD EMF_INLINE_ON_HOST inline bool cell_in_grid(const Vec3<S>& p, S voxel_size, int nx, int ny, int nz, Cell<S>& c) {
  return cell_of(p, voxel_size, Vec3<S>::zero(), vec3(S(nx - 1), S(ny - 1), S(nz - 1)), c);
}

/// The trilinear interpolant of the eight corner values at fractions (fx, fy, fz).
template <class S>
EMF_HD EMF_INLINE_ON_HOST inline S interpolate(const S* v, S fx, S fy, S fz) {
  const S x00 = v[0] + (v[1] - v[0]) * fx, x10 = v[2] + (v[3] - v[2]) * fx;
  const S x01 = v[4] + (v[5] - v[4]) * fx, x11 = v[6] + (v[7] - v[6]) * fx;
  const S y0 = x00 + (x10 - x00) * fy, y1 = x01 + (x11 - x01) * fy;
  return y0 + (y1 - y0) * fz;
}

/// The exact gradient of that interpolant, per metre for voxels of `voxel_size`.
template <class S>
EMF_HD EMF_INLINE_ON_HOST inline Vec3<S> gradient(const S* v, S fx, S fy, S fz, S voxel_size) {
  const S dx = ((v[1] - v[0]) * (1 - fy) + (v[3] - v[2]) * fy) * (1 - fz) +
               ((v[5] - v[4]) * (1 - fy) + (v[7] - v[6]) * fy) * fz;
  const S dy = ((v[2] - v[0]) * (1 - fx) + (v[3] - v[1]) * fx) * (1 - fz) +
               ((v[6] - v[4]) * (1 - fx) + (v[7] - v[5]) * fx) * fz;
  const S dz = ((v[4] - v[0]) * (1 - fx) + (v[5] - v[1]) * fx) * (1 - fy) +
               ((v[6] - v[2]) * (1 - fx) + (v[7] - v[3]) * fx) * fy;
  return vec3(dx, dy, dz) / voxel_size;
}

/// Interpolation over the observed corners (weight > 0) only, their
/// interpolation weights renormalised: false unless they carry at least
/// `min_coverage` of the weight.
template <class S>
EMF_HD EMF_INLINE_ON_HOST inline bool interpolate_observed(const S* v, const S* w, S fx, S fy, S fz, S min_coverage,
                                                           S& out) {
  S sum = S(0), covered = S(0);
  for (int k = 0; k < 8; ++k) {
    if (!(w[k] > S(0))) continue;
    const S a = ((k & 1) ? fx : S(1) - fx) * ((k & 2) ? fy : S(1) - fy) * ((k & 4) ? fz : S(1) - fz);
    sum += a * v[k];
    covered += a;
  }
  if (!(covered >= min_coverage) || !(covered > S(0))) return false;
  out = sum / covered;
  return true;
}

/// Central differences one voxel apart of `sampler.sample` (the strict
/// sample): false where any of the six samples fails.
template <class S, class Sampler>
EMF_HD bool central_gradient(Sampler& sampler, const Vec3<S>& p, S voxel_size, Vec3<S>& gradient) {
  S plus, minus;
  for (int a = 0; a < 3; ++a) {
    Vec3<S> q = p;
    q[a] += voxel_size;
    if (!sampler.sample(q, plus)) return false;
    q[a] -= S(2) * voxel_size;
    if (!sampler.sample(q, minus)) return false;
    gradient[a] = (plus - minus) / (S(2) * voxel_size);
  }
  return true;
}

/// One axis of observed_gradient from its samples one voxel (`voxel_size`)
/// either side of a point and at it (each with whether it was observed):
/// the central difference, else a one-sided one with the centre; false,
/// `out` left alone, where the axis has no two observed samples.
template <class S>
EMF_HD bool observed_difference(bool has_plus, S plus, bool has_minus, S minus, bool has_centre, S centre,
                                S voxel_size, S& out) {
  if (has_plus && has_minus)
    out = (plus - minus) / (S(2) * voxel_size);
  else if (has_plus && has_centre)
    out = (plus - centre) / voxel_size;
  else if (has_minus && has_centre)
    out = (centre - minus) / voxel_size;
  else
    return false;
  return true;
}

/// Central differences one voxel apart of `sampler.sample_observed`,
/// one-sided where one side is not observed: the normals of what rendering
/// draws. False where an axis has no two observed samples.
template <class S, class Sampler>
EMF_HD bool observed_gradient(Sampler& sampler, const Vec3<S>& p, S voxel_size, Vec3<S>& gradient) {
  S centre = S(0);
  const bool has_centre = sampler.sample_observed(p, centre);
  for (int a = 0; a < 3; ++a) {
    Vec3<S> q = p;
    S plus = S(0), minus = S(0);
    q[a] = p[a] + voxel_size;
    const bool has_plus = sampler.sample_observed(q, plus);
    q[a] = p[a] - voxel_size;
    const bool has_minus = sampler.sample_observed(q, minus);
    if (!observed_difference(has_plus, plus, has_minus, minus, has_centre, centre, voxel_size, gradient[a]))
      return false;
  }
  return true;
}

}  // namespace emfusion::detail::trilinear
