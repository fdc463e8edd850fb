// Dense truncated signed distance volume: a grid of SDF values and
// integration weights with a pose in the world, a voxel size and a truncation
// distance. `TsdfView` is what kernels capture: trilinear SDF sampling and
// gradients in the volume frame.
//
// Geometry: voxel (x, y, z) has its centre at ((x + 1/2) s, (y + 1/2) s,
// (z + 1/2) s) in the volume frame (s = voxel size), so the volume covers the
// box [0, n s) on each axis; T_world_volume places that frame in the world.
// Storage is x-fastest. SDF values are metres, clamped to [-truncation,
// truncation]; weight 0 means "never observed".
#pragma once

#include <cmath>
#include <cstdint>
#include <string>
#include <type_traits>
#include <vector>

#include <thrust/copy.h>
#include <thrust/fill.h>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/error.hpp"
#include "emfusion/core/host_device.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/volume/detail/trilinear.hpp"

namespace emfusion {

/// Kernel-side view of a TSDF volume: S is the compute scalar, Store the
/// scalar the grid is stored in.
template <class S, class Store = S>
struct TsdfView {
  Store* sdf = nullptr;
  Store* weight = nullptr;
  int nx = 0, ny = 0, nz = 0;
  S voxel_size = S(0);
  S truncation = S(0);

  /// A read-only view of the same volume (only for views of mutable voxels).
  template <class U = Store>
    requires(!std::is_const_v<U>)
  EMF_HD operator TsdfView<S, const U>() const {
    return {sdf, weight, nx, ny, nz, voxel_size, truncation};
  }

  EMF_HD std::int64_t index(int x, int y, int z) const {
    return (std::int64_t(z) * ny + y) * nx + x;
  }
  EMF_HD std::int64_t voxel_count() const { return std::int64_t(nx) * ny * nz; }
  EMF_HD bool contains_voxel(int x, int y, int z) const {
    return x >= 0 && y >= 0 && z >= 0 && x < nx && y < ny && z < nz;
  }
  /// Volume-frame position of a voxel centre.
  EMF_HD Vec3<S> voxel_center(int x, int y, int z) const {
    return vec3((S(x) + S(0.5)) * voxel_size, (S(y) + S(0.5)) * voxel_size, (S(z) + S(0.5)) * voxel_size);
  }
  /// Volume-frame extent of the grid along each axis.
  EMF_HD Vec3<S> extent() const { return vec3(S(nx) * voxel_size, S(ny) * voxel_size, S(nz) * voxel_size); }
  /// True if the volume-frame point lies in the box [0, extent) (false for NaN).
  EMF_HD bool contains_point(const Vec3<S>& p) const {
    const Vec3<S> e = extent();
    return p.x() >= S(0) && p.y() >= S(0) && p.z() >= S(0) && p.x() < e.x() && p.y() < e.y() && p.z() < e.z();
  }

  /// Trilinear SDF at volume-frame point p. Returns false (and leaves the
  /// outputs alone) if p is outside the grid of voxel centres or any of the
  /// eight voxels around it was never observed. `weight_out`, if given,
  /// receives the interpolated weight.
  EMF_HD bool sample(const Vec3<S>& p, S& sdf_out, S* weight_out = nullptr) const {
    Corner c;
    if (!corner(p, c)) return false;
    S v[8], w[8];
    if (!load(c, v, w)) return false;
    sdf_out = interpolate(v, c);
    if (weight_out) *weight_out = interpolate(w, c);
    return true;
  }

  /// Trilinear SDF over the observed voxels of the eight around p, their
  /// interpolation weights renormalised: true where those voxels carry at
  /// least `min_coverage` of the weight. Rendering uses it, so that the
  /// holes a single noisy frame leaves (missing depth pixels) do not punch
  /// holes into the drawn surface; tracking keeps the strict `sample`.
  EMF_HD bool sample_observed(const Vec3<S>& p, S& sdf_out, S min_coverage = S(0.5)) const {
    Corner c;
    if (!corner(p, c)) return false;
    S v[8], w[8];
    for (int k = 0; k < 8; ++k) {
      const std::int64_t i = index(c.x + (k & 1), c.y + ((k >> 1) & 1), c.z + ((k >> 2) & 1));
      v[k] = S(sdf[i]), w[k] = S(weight[i]);
    }
    return detail::trilinear::interpolate_observed(v, w, c.fx, c.fy, c.fz, min_coverage, sdf_out);
  }

  /// Central differences one voxel apart of `sample_observed`, one-sided
  /// where one side is not observed: the normals of what rendering draws.
  EMF_HD bool observed_gradient(const Vec3<S>& p, Vec3<S>& gradient) const {
    return detail::trilinear::observed_gradient(*this, p, voxel_size, gradient);
  }

  /// Trilinear SDF and its exact gradient (of the trilinear interpolant) at p.
  EMF_HD bool sample_with_gradient(const Vec3<S>& p, S& sdf_out, Vec3<S>& gradient, S* weight_out = nullptr) const {
    Corner c;
    if (!corner(p, c)) return false;
    S v[8], w[8];
    if (!load(c, v, w)) return false;
    sdf_out = interpolate(v, c);
    if (weight_out) *weight_out = interpolate(w, c);
    gradient = detail::trilinear::gradient(v, c.fx, c.fy, c.fz, voxel_size);
    return true;
  }

  /// SDF gradient by central differences of trilinear samples one voxel
  /// apart: smoother than the trilinear gradient, used for surface normals.
  EMF_HD bool central_gradient(const Vec3<S>& p, Vec3<S>& gradient) const {
    return detail::trilinear::central_gradient(*this, p, voxel_size, gradient);
  }

 private:
  using Corner = detail::trilinear::Cell<S>;
  EMF_HD bool corner(const Vec3<S>& p, Corner& c) const {
    return detail::trilinear::cell_in_grid(p, voxel_size, nx, ny, nz, c);
  }
  EMF_HD bool load(const Corner& c, S* v, S* w) const {
    for (int k = 0; k < 8; ++k) {
      const std::int64_t i = index(c.x + (k & 1), c.y + ((k >> 1) & 1), c.z + ((k >> 2) & 1));
      w[k] = S(weight[i]);
      if (!(w[k] > S(0))) return false;
      v[k] = S(sdf[i]);
    }
    return true;
  }
  EMF_HD static S interpolate(const S* v, const Corner& c) {
    return detail::trilinear::interpolate(v, c.fx, c.fy, c.fz);
  }

};

/// Size and placement of a volume.
template <class S>
struct VolumeGeometry {
  Vec3i dims{{0, 0, 0}};      ///< voxels along x, y, z
  S voxel_size = S(0);        ///< metres
  S truncation = S(0);        ///< metres; 0 selects 10 voxels
  SE3<S> T_world_volume{};    ///< volume frame (corner of the grid) in the world
};

/// A TSDF volume on backend B with compute scalar S and storage scalar Store.
template <class S, Backend B = Host, class Store = S>
class TsdfVolume {
 public:
  using Scalar = S;
  using backend_type = B;
  using View = TsdfView<S, Store>;
  using ConstView = TsdfView<S, const Store>;

  /// Truncation defaults to 10 voxels when geometry.truncation is 0.
  explicit TsdfVolume(const VolumeGeometry<S>& geometry, B backend = B{}) : backend_(backend) {
    const Vec3i& d = geometry.dims;
    detail::require(d[0] > 0 && d[1] > 0 && d[2] > 0, "TsdfVolume",
                    "dimensions must be positive, got " + std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" +
                        std::to_string(d[2]));
    detail::require(std::isfinite(double(geometry.voxel_size)) && geometry.voxel_size > S(0), "TsdfVolume",
                    "voxel size must be positive, got " + std::to_string(double(geometry.voxel_size)));
    detail::require(geometry.truncation >= S(0), "TsdfVolume",
                    "truncation must not be negative, got " + std::to_string(double(geometry.truncation)));
    geometry_ = geometry;
    if (geometry_.truncation == S(0)) geometry_.truncation = S(10) * geometry.voxel_size;
    const std::size_t n = std::size_t(d[0]) * std::size_t(d[1]) * std::size_t(d[2]);
    sdf_.resize(n);
    weight_.resize(n);
    reset();
  }

  /// Forgets everything: SDF = truncation, weight = 0.
  void reset() {
    thrust::fill(backend_.policy(), sdf_.begin(), sdf_.end(), Store(geometry_.truncation));
    thrust::fill(backend_.policy(), weight_.begin(), weight_.end(), Store(0));
  }

  const VolumeGeometry<S>& geometry() const { return geometry_; }
  const Vec3i& dims() const { return geometry_.dims; }
  S voxel_size() const { return geometry_.voxel_size; }
  S truncation() const { return geometry_.truncation; }
  const SE3<S>& pose() const { return geometry_.T_world_volume; }
  void set_pose(const SE3<S>& T_world_volume) { geometry_.T_world_volume = T_world_volume; }
  std::int64_t voxel_count() const { return std::int64_t(sdf_.size()); }
  const B& backend() const { return backend_; }
  /// Bytes of voxel storage.
  std::size_t memory_bytes() const { return 2 * sdf_.size() * sizeof(Store); }

  View view() { return make_view<View>(raw_data(sdf_), raw_data(weight_)); }
  ConstView view() const { return make_view<ConstView>(raw_data(sdf_), raw_data(weight_)); }

  /// SDF values and weights as host vectors (x-fastest), synchronising first.
  std::vector<Store> sdf_to_host() const { return vector_to_host(backend_, sdf_); }
  std::vector<Store> weight_to_host() const { return vector_to_host(backend_, weight_); }
  /// Replaces every voxel with host values in the layout of sdf_to_host and
  /// weight_to_host: how a saved volume comes back (io/checkpoint.hpp).
  void assign_from_host(const std::vector<Store>& sdf, const std::vector<Store>& weight) {
    detail::require(sdf.size() == sdf_.size() && weight.size() == weight_.size(), "TsdfVolume::assign_from_host",
                    "expected " + std::to_string(sdf_.size()) + " voxels, got " + std::to_string(sdf.size()) + " SDF values and " +
                        std::to_string(weight.size()) + " weights");
    backend_.synchronize();
    thrust::copy(sdf.begin(), sdf.end(), sdf_.begin());
    thrust::copy(weight.begin(), weight.end(), weight_.begin());
  }

  /// A copy of this volume on another backend.
  template <Backend B2>
  TsdfVolume<S, B2, Store> to(B2 backend = B2{}) const {
    backend_.synchronize();
    TsdfVolume<S, B2, Store> out(geometry_, backend);
    thrust::copy(sdf_.begin(), sdf_.end(), out.sdf_.begin());
    thrust::copy(weight_.begin(), weight_.end(), out.weight_.begin());
    return out;
  }

 private:
  template <class, Backend, class>
  friend class TsdfVolume;

  template <class V, class P>
  V make_view(P* sdf, P* weight) const {
    V v;
    v.sdf = sdf, v.weight = weight;
    v.nx = geometry_.dims[0], v.ny = geometry_.dims[1], v.nz = geometry_.dims[2];
    v.voxel_size = geometry_.voxel_size, v.truncation = geometry_.truncation;
    return v;
  }

  VolumeGeometry<S> geometry_;
  B backend_;
  typename B::template Vector<Store> sdf_;
  typename B::template Vector<Store> weight_;
};

/// Pose of a cubic volume of side `extent` that has the camera at the centre
/// of one face, looking along the volume's z axis: the background placement
/// of the paper (volume centre extent/2 in front of the camera).
template <class S>
SE3<S> volume_pose_in_front_of(const SE3<S>& T_world_camera, S extent) {
  const SE3<S> T_camera_volume = SE3<S>::translation(vec3(-extent / S(2), -extent / S(2), S(0)));
  return T_world_camera * T_camera_volume;
}

}  // namespace emfusion
