// What an algorithm needs of a TSDF volume, whatever stores it: the
// `TsdfSampler` concept that the dense view (TsdfView, tsdf_volume.hpp) and
// the sparse one (SparseTsdfView, sparse_tsdf_volume.hpp) both satisfy, and
// `TsdfVolumeType` for the owning volumes, so that ray casting, SDF
// alignment, the likelihood and mesh extraction are written once for both
// (docs/volumes.md, "One volume concept").
#pragma once

#include <concepts>
#include <type_traits>

#include "emfusion/core/math.hpp"
#include "emfusion/core/se3.hpp"

namespace emfusion {

/// A trivially copyable, device-callable view of a TSDF: SDF in metres
/// (clamped to +-truncation), weight 0 where never observed, trilinear
/// sampling in the volume frame that fails where any of the eight voxels
/// around a point was never observed (`sample`, `sample_with_gradient`,
/// `central_gradient`) or where too little of them was (`sample_observed`,
/// `observed_gradient`, what rendering uses).
template <class V, class S>
concept TsdfSampler = std::is_trivially_copyable_v<V> && requires(const V& v, const Vec3<S>& p, S& sdf, S* weight,
                                                                  Vec3<S>& gradient) {
  { v.voxel_size } -> std::convertible_to<S>;
  { v.truncation } -> std::convertible_to<S>;
  { v.sample(p, sdf, weight) } -> std::same_as<bool>;
  { v.sample_observed(p, sdf, S(0.5)) } -> std::same_as<bool>;
  { v.sample_with_gradient(p, sdf, gradient, weight) } -> std::same_as<bool>;
  { v.central_gradient(p, gradient) } -> std::same_as<bool>;
  { v.observed_gradient(p, gradient) } -> std::same_as<bool>;
};

/// An owning TSDF volume on a backend: its pose in the world, voxel size,
/// truncation, backend and a read-only view that is a TsdfSampler.
template <class Volume, class S>
concept TsdfVolumeType = requires(const Volume& v) {
  { v.pose() } -> std::convertible_to<SE3<S>>;
  { v.voxel_size() } -> std::convertible_to<S>;
  { v.truncation() } -> std::convertible_to<S>;
  v.backend();
  requires TsdfSampler<decltype(v.view()), S>;
};

}  // namespace emfusion
