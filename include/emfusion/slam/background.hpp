// The system's background map: a sparse voxel-block volume by default,
// unbounded and growing with the scene, or the paper's dense cube in front
// of the first camera (SystemParams::sparse_background). One type holds
// either; the stages reach the volume itself through visit(), so that every
// algorithm runs on the concrete volume (volume/volume_view.hpp).
#pragma once

#include <cstddef>
#include <string>
#include <utility>
#include <variant>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/slam/params.hpp"
#include "emfusion/volume/sparse_tsdf_volume.hpp"
#include "emfusion/volume/tsdf_volume.hpp"

namespace emfusion {

/// The dense background of `p`: background_voxels^3 voxels with the first
/// camera at the centre of one face (DESIGN.md section 1). Validates `p`.
template <class S>
VolumeGeometry<S> background_geometry(const SystemParams<S>& p) {
  p.validate();
  VolumeGeometry<S> g;
  g.dims = Vec3i{{p.background_voxels, p.background_voxels, p.background_voxels}};
  g.voxel_size = p.background_voxel_size;
  g.truncation = p.truncation_voxels * p.background_voxel_size;
  g.T_world_volume = volume_pose_in_front_of(SE3<S>::identity(), S(p.background_voxels) * p.background_voxel_size);
  return g;
}

/// The sparse background of `p`: blocks of background_voxel_size voxels,
/// the volume frame at the world's origin, at most background_blocks
/// blocks. Validates `p`.
template <class S>
SparseVolumeParams<S> sparse_background_params(const SystemParams<S>& p) {
  p.validate();
  SparseVolumeParams<S> s;
  s.voxel_size = p.background_voxel_size;
  s.truncation = p.truncation_voxels * p.background_voxel_size;
  s.T_world_volume = SE3<S>::identity();
  s.block_capacity = p.background_blocks;
  return s;
}

/// The background volume, dense or sparse.
template <class S, Backend B = Host>
class BackgroundVolume {
 public:
  using Dense = TsdfVolume<S, B>;
  using Sparse = SparseTsdfVolume<S, B>;

  explicit BackgroundVolume(Dense volume) : volume_(std::move(volume)) {}
  explicit BackgroundVolume(Sparse volume) : volume_(std::move(volume)) {}
  /// The background `params` asks for (sparse_background).
  explicit BackgroundVolume(const SystemParams<S>& params, B backend = B{})
      : volume_(make(params, std::move(backend))) {}

  bool is_sparse() const { return std::holds_alternative<Sparse>(volume_); }
  /// The volume when it is of that kind, else nullptr.
  Dense* dense() { return std::get_if<Dense>(&volume_); }
  const Dense* dense() const { return std::get_if<Dense>(&volume_); }
  Sparse* sparse() { return std::get_if<Sparse>(&volume_); }
  const Sparse* sparse() const { return std::get_if<Sparse>(&volume_); }

  /// Calls f with the volume (Dense& or Sparse&) and returns what it returns.
  template <class F>
  decltype(auto) visit(F&& f) {
    return std::visit(std::forward<F>(f), volume_);
  }
  template <class F>
  decltype(auto) visit(F&& f) const {
    return std::visit(std::forward<F>(f), volume_);
  }

  const SE3<S>& pose() const {
    return visit([](const auto& v) -> const SE3<S>& { return v.pose(); });
  }
  S voxel_size() const {
    return visit([](const auto& v) { return v.voxel_size(); });
  }
  S truncation() const {
    return visit([](const auto& v) { return v.truncation(); });
  }
  const B& backend() const {
    return visit([](const auto& v) -> const B& { return v.backend(); });
  }
  /// Bytes the volume holds on its backend (a sparse one: what its blocks
  /// and table take now, not its bound).
  std::size_t memory_bytes() const {
    return visit([](const auto& v) { return v.memory_bytes(); });
  }
  /// One line for logs and run.json: kind, voxel size and size or blocks.
  std::string describe() const {
    if (const Sparse* s = sparse())
      return "sparse, " + std::to_string(s->allocated_blocks()) + " of at most " + std::to_string(s->capacity()) +
             " blocks of 8^3 voxels";
    const Dense& d = *dense();
    return "dense, " + std::to_string(d.dims()[0]) + "x" + std::to_string(d.dims()[1]) + "x" +
           std::to_string(d.dims()[2]) + " voxels";
  }

 private:
  static std::variant<Dense, Sparse> make(const SystemParams<S>& params, B backend) {
    if (params.sparse_background) return Sparse(sparse_background_params(params), std::move(backend));
    return Dense(background_geometry(params), std::move(backend));
  }
  std::variant<Dense, Sparse> volume_;
};

}  // namespace emfusion
