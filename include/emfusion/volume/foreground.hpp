// Per-voxel foreground/background counts of an object volume (paper eq. 6):
// how often a voxel near the measured surface projected into the object's
// detected mask (Fg) or outside it (Bg). Their ratio p_fg = Fg / (Fg + Bg)
// says whether a voxel belongs to the object: the E-step multiplies the
// object's likelihood by it, and raycasting draws only voxels with
// p_fg > 0.5, only within the box of the voxels where Fg > Bg
// (majority_box). Voxels never counted have p_fg = 1/2: no evidence either
// way.
#pragma once

#include <cmath>
#include <cstdint>
#include <string>
#include <type_traits>
#include <vector>

#include <thrust/copy.h>
#include <thrust/fill.h>

#include "emfusion/core/camera.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/volume/detail/trilinear.hpp"
#include "emfusion/volume/tsdf_volume.hpp"

namespace emfusion {

/// Kernel-side view of the counts; same grid and geometry as the TSDF.
template <class S, class Count = float>
struct ForegroundView {
  Count* fg = nullptr;
  Count* bg = nullptr;
  int nx = 0, ny = 0, nz = 0;
  S voxel_size = S(0);

  /// A read-only view of the same counts (only for views of mutable counts).
  template <class U = Count>
    requires(!std::is_const_v<U>)
  EMF_HD operator ForegroundView<S, const U>() const {
    return {fg, bg, nx, ny, nz, voxel_size};
  }

  EMF_HD bool empty() const { return fg == nullptr; }

  /// p_fg of one voxel.
  EMF_HD S voxel_probability(std::int64_t i) const {
    const S f = S(fg[i]), b = S(bg[i]);
    return f + b > S(0) ? f / (f + b) : S(0.5);
  }

  /// p_fg at a volume-frame point from trilinearly interpolated counts;
  /// 1/2 outside the grid of voxel centres.
  EMF_HD S probability(const Vec3<S>& p) const {
    detail::trilinear::Cell<S> c;
    if (!detail::trilinear::cell_in_grid(p, voxel_size, nx, ny, nz, c)) return S(0.5);
    S f = S(0), b = S(0);
    for (int k = 0; k < 8; ++k) {
      const int dx = k & 1, dy = (k >> 1) & 1, dz = (k >> 2) & 1;
      const S w = (dx ? c.fx : S(1) - c.fx) * (dy ? c.fy : S(1) - c.fy) * (dz ? c.fz : S(1) - c.fz);
      const std::int64_t i = (std::int64_t(c.z + dz) * ny + (c.y + dy)) * nx + (c.x + dx);
      f += w * S(fg[i]);
      b += w * S(bg[i]);
    }
    return f + b > S(0) ? f / (f + b) : S(0.5);
  }
};

/// A box of voxel indices, [lo, hi) per axis; empty when any hi <= lo.
struct VoxelBox {
  Vec3i lo{{0, 0, 0}}, hi{{0, 0, 0}};
  EMF_HD bool empty() const { return !(hi[0] > lo[0] && hi[1] > lo[1] && hi[2] > lo[2]); }
};

namespace detail {
/// The box of the one voxel at index i (x-fastest) of an nx x ny x nz grid.
EMF_HD inline VoxelBox voxel_box_at(std::int64_t i, int nx, int ny) {
  const std::int64_t plane = std::int64_t(nx) * ny;
  const int x = int(i % nx), y = int((i / nx) % ny), z = int(i / plane);
  return VoxelBox{Vec3i{{x, y, z}}, Vec3i{{x + 1, y + 1, z + 1}}};
}

/// The one-voxel box of voxel i where Fg > Bg, else an empty one.
template <class S, class Count>
struct MajorityVoxel {
  ForegroundView<S, const Count> counts;
  EMF_HD VoxelBox operator()(std::int64_t i) const {
    if (!(S(counts.fg[i]) > S(counts.bg[i]))) return VoxelBox{};
    return voxel_box_at(i, counts.nx, counts.ny);
  }
};
struct UniteVoxelBoxes {
  EMF_HD VoxelBox operator()(const VoxelBox& a, const VoxelBox& b) const {
    if (a.empty()) return b;
    if (b.empty()) return a;
    VoxelBox u;
    for (int k = 0; k < 3; ++k) {
      u.lo[k] = a.lo[k] < b.lo[k] ? a.lo[k] : b.lo[k];
      u.hi[k] = a.hi[k] > b.hi[k] ? a.hi[k] : b.hi[k];
    }
    return u;
  }
};
}  // namespace detail

/// The counts of one object volume on backend B.
template <class S, Backend B = Host, class Count = float>
class ForegroundCounts {
 public:
  using View = ForegroundView<S, Count>;
  using ConstView = ForegroundView<S, const Count>;

  ForegroundCounts() = default;
  /// Zero counts for a grid of `dims` voxels of `voxel_size`.
  ForegroundCounts(const Vec3i& dims, S voxel_size, B backend = B{})
      : dims_(dims), voxel_size_(voxel_size), backend_(backend) {
    const std::size_t n = std::size_t(dims[0]) * std::size_t(dims[1]) * std::size_t(dims[2]);
    fg_.resize(n);
    bg_.resize(n);
    reset();
  }

  void reset() {
    thrust::fill(backend_.policy(), fg_.begin(), fg_.end(), Count(0));
    thrust::fill(backend_.policy(), bg_.begin(), bg_.end(), Count(0));
    majority_known_ = false;
  }

  const Vec3i& dims() const { return dims_; }
  S voxel_size() const { return voxel_size_; }
  std::size_t memory_bytes() const { return 2 * fg_.size() * sizeof(Count); }

  /// A view that may change the counts: majority_box is computed afresh
  /// after it (read through the const view() to keep it).
  View view() {
    majority_known_ = false;
    return make<View>(raw_data(fg_), raw_data(bg_));
  }
  ConstView view() const { return make<ConstView>(raw_data(fg_), raw_data(bg_)); }

  /// The smallest box of voxel indices, [lo, hi) per axis, holding every
  /// voxel with Fg > Bg (p_fg > 1/2); empty (lo = hi = 0) when there is
  /// none. Where a point's p_fg (ForegroundView::probability) exceeds 1/2,
  /// one of its eight voxels is in it: raycasting an object marches only
  /// there. One reduction over the grid, kept until the counts may have
  /// changed (a mutable view(), reset, assign_from_host); not to be called
  /// from two threads at once.
  const VoxelBox& majority_box() const {
    if (!majority_known_) {
      majority_ = transform_reduce_index(backend_, std::int64_t(fg_.size()), detail::MajorityVoxel<S, Count>{view()},
                                         VoxelBox{}, detail::UniteVoxelBoxes{});
      majority_known_ = true;
    }
    return majority_;
  }

  /// Fg and Bg counts as host vectors (x-fastest), synchronising first.
  std::vector<Count> fg_to_host() const { return vector_to_host(backend_, fg_); }
  std::vector<Count> bg_to_host() const { return vector_to_host(backend_, bg_); }
  /// Replaces every count with host values in the layout of fg_to_host and
  /// bg_to_host: how saved counts come back (io/checkpoint.hpp).
  void assign_from_host(const std::vector<Count>& fg, const std::vector<Count>& bg) {
    detail::require(fg.size() == fg_.size() && bg.size() == bg_.size(), "ForegroundCounts::assign_from_host",
                    "expected " + std::to_string(fg_.size()) + " voxels, got " + std::to_string(fg.size()) + " Fg and " +
                        std::to_string(bg.size()) + " Bg counts");
    backend_.synchronize();
    thrust::copy(fg.begin(), fg.end(), fg_.begin());
    thrust::copy(bg.begin(), bg.end(), bg_.begin());
    majority_known_ = false;
  }

 private:
  template <class V, class P>
  V make(P* fg, P* bg) const {
    V v;
    v.fg = fg, v.bg = bg;
    v.nx = dims_[0], v.ny = dims_[1], v.nz = dims_[2];
    v.voxel_size = voxel_size_;
    return v;
  }

  Vec3i dims_{{0, 0, 0}};
  S voxel_size_ = S(0);
  B backend_{};
  typename B::template Vector<Count> fg_;
  typename B::template Vector<Count> bg_;
  mutable VoxelBox majority_{};
  mutable bool majority_known_ = false;
};

namespace detail {

/// Eq. 6 for one column of voxels: a voxel within the truncation band of the
/// depth its centre projects to gets Fg += m(u), Bg += 1 - m(u), where m is
/// the detection's mask (1 inside); pixels where `counted` is 0 (occluded by
/// another model) are skipped.
template <class S, class Count>
struct ForegroundColumn {
  ForegroundView<S, Count> counts;
  S truncation;
  ImageView<const S> depth;
  ImageView<const std::uint8_t> mask;
  ImageView<const std::uint8_t> counted;
  PinholeCamera<S> camera;
  SE3<S> T_camera_volume;

  EMF_HD void operator()(int column) const {
    const int x = column % counts.nx, y = column / counts.nx;
    const S s = counts.voxel_size;
    const Vec3<S> start = T_camera_volume * vec3((S(x) + S(0.5)) * s, (S(y) + S(0.5)) * s, S(0.5) * s);
    const Vec3<S> step = T_camera_volume.rotate(vec3(S(0), S(0), s));
    for (int z = 0; z < counts.nz; ++z) {
      const Vec3<S> p = start + S(z) * step;
      if (!(p.z() > S(0))) continue;
      const Vec2<S> uv = camera.project(p);
      const int u = int(std::floor(uv.x() + S(0.5))), v = int(std::floor(uv.y() + S(0.5)));
      if (!depth.contains(u, v) || !counted(u, v)) continue;
      const S d = depth(u, v);
      if (!is_valid_depth(d) || !(std::fabs(d - p.z()) < truncation)) continue;
      const std::int64_t i = (std::int64_t(z) * counts.ny + y) * counts.nx + x;
      if (mask(u, v))
        counts.fg[i] = Count(S(counts.fg[i]) + S(1));
      else
        counts.bg[i] = Count(S(counts.bg[i]) + S(1));
    }
  }
};

}  // namespace detail

/// Updates the counts of an object volume (pose T_world_volume, truncation
/// in metres) from a detection mask (1 = object) of the frame `depth` seen
/// at T_world_camera. `counted` (1 = use the pixel) masks out pixels where
/// another model occludes this one. All images live on the counts' backend.
template <class S, Backend B, class Count>
void update_foreground(ForegroundCounts<S, B, Count>& counts, const SE3<S>& T_world_volume, S truncation,
                       const Image<S, B>& depth, const Image<std::uint8_t, B>& mask,
                       const Image<std::uint8_t, B>& counted, const PinholeCamera<S>& camera,
                       const SE3<S>& T_world_camera, const B& backend) {
  constexpr const char* where = "update_foreground";
  detail::require_image(depth.view(), camera.width, camera.height, where, "depth image");
  detail::require_image(mask.view(), camera.width, camera.height, where, "mask");
  detail::require_image(counted.view(), camera.width, camera.height, where, "occlusion mask");
  detail::ForegroundColumn<S, Count> f{counts.view(),  truncation,     depth.view(),
                                      mask.view(),    counted.view(), camera,
                                      T_world_camera.inverse() * T_world_volume};
  for_each_index(backend, counts.dims()[0] * counts.dims()[1], f);
}

}  // namespace emfusion
