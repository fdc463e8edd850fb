// The colour of an object's model: a gray value per voxel on the grid of its
// dense TSDF, fused from the frames' intensity images (preprocess/
// intensity.hpp) as the SDF is (a running weighted mean with a capped
// weight), so that tracking can align the frame's texture to the model's
// and not only its shape (solve/sdf_alignment.hpp, the colour terms). A
// cylinder, a sphere or a box seen from one side have shapes that leave a
// turn about their axis or a slide along it free; their texture does not.
// Not in the EM-Fusion paper, which aligns depth alone; off unless
// SystemParams::object_colour_weight is positive (docs/system.md).
//
// Voxels of colour weight 0 were never coloured; samples need all eight
// voxels around a point coloured, as TSDF samples need them observed.
#pragma once

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include <thrust/copy.h>
#include <thrust/fill.h>

#include "emfusion/core/camera.hpp"
#include "emfusion/core/error.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/volume/detail/trilinear.hpp"
#include "emfusion/volume/tsdf_volume.hpp"

namespace emfusion {

/// Kernel-side view of an IntensityGrid: `Value` is float or const float.
template <class S, class Value = const float>
struct IntensityView {
  Value* value = nullptr;
  Value* weight = nullptr;
  int nx = 0, ny = 0, nz = 0;
  S voxel_size = S(0);

  EMF_HD bool empty() const { return value == nullptr; }
  EMF_HD std::int64_t index(int x, int y, int z) const { return (std::int64_t(z) * ny + y) * nx + x; }

  /// Trilinear gray value at volume-frame point p and its gradient (per
  /// metre, of the trilinear interpolant); false outside the grid of voxel
  /// centres or where one of the eight voxels around p is not coloured.
  EMF_HD bool sample_with_gradient(const Vec3<S>& p, S& out, Vec3<S>& gradient) const {
    detail::trilinear::Cell<S> c;
    if (!detail::trilinear::cell_in_grid(p, voxel_size, nx, ny, nz, c)) return false;
    S v[8];
    for (int k = 0; k < 8; ++k) {
      const std::int64_t i = index(c.x + (k & 1), c.y + ((k >> 1) & 1), c.z + ((k >> 2) & 1));
      if (!(weight[i] > 0.0f)) return false;
      v[k] = S(value[i]);
    }
    out = detail::trilinear::interpolate(v, c.fx, c.fy, c.fz);
    gradient = detail::trilinear::gradient(v, c.fx, c.fy, c.fz, voxel_size);
    return true;
  }
};

/// The gray values and colour weights of one object's voxels on backend B
/// (float storage: 8 bytes a voxel).
template <class S, Backend B = Host>
class IntensityGrid {
 public:
  IntensityGrid() = default;
  /// Uncoloured voxels (weight 0) on a grid of `dims` voxels of `voxel_size`.
  IntensityGrid(const Vec3i& dims, S voxel_size, B backend = B{})
      : dims_(dims), voxel_size_(voxel_size), backend_(backend) {
    const std::size_t n = std::size_t(dims[0]) * std::size_t(dims[1]) * std::size_t(dims[2]);
    value_.resize(n);
    weight_.resize(n);
    thrust::fill(backend_.policy(), value_.begin(), value_.end(), 0.0f);
    thrust::fill(backend_.policy(), weight_.begin(), weight_.end(), 0.0f);
  }

  bool empty() const { return value_.empty(); }
  const Vec3i& dims() const { return dims_; }
  S voxel_size() const { return voxel_size_; }
  std::size_t memory_bytes() const { return 2 * value_.size() * sizeof(float); }

  // An uncoloured grid's view is the empty one (value == nullptr, raw_data of
  // an empty vector), which IntensityView::empty and the copy when an object
  // grows rely on.
  IntensityView<S, float> view() {
    return {raw_data(value_), raw_data(weight_), dims_[0], dims_[1], dims_[2], voxel_size_};
  }
  IntensityView<S, const float> view() const {
    return {raw_data(value_), raw_data(weight_), dims_[0], dims_[1], dims_[2], voxel_size_};
  }

  /// Gray values and weights as host vectors (x-fastest), synchronising first.
  std::vector<float> values_to_host() const { return vector_to_host(backend_, value_); }
  std::vector<float> weights_to_host() const { return vector_to_host(backend_, weight_); }
  /// Replaces every voxel's gray value and weight with host values in the
  /// layout of values_to_host and weights_to_host.
  void assign_from_host(const std::vector<float>& values, const std::vector<float>& weights) {
    detail::require(values.size() == value_.size() && weights.size() == weight_.size(),
                    "IntensityGrid::assign_from_host",
                    "expected " + std::to_string(value_.size()) + " voxels, got " + std::to_string(values.size()) +
                        " gray values and " + std::to_string(weights.size()) + " weights");
    backend_.synchronize();
    thrust::copy(values.begin(), values.end(), value_.begin());
    thrust::copy(weights.begin(), weights.end(), weight_.begin());
  }

 private:
  Vec3i dims_{{0, 0, 0}};
  S voxel_size_ = S(0);
  B backend_{};
  typename B::template Vector<float> value_;
  typename B::template Vector<float> weight_;
};

namespace detail {
/// The colour update of one column of voxels: a voxel within `band` of the
/// depth its centre projects to takes that pixel's gray value with the
/// pixel's weight q(u) (1 without weights) into its running mean, its
/// weight capped at `max_weight`.
template <class S>
struct IntensityColumn {
  IntensityView<S, float> grid;
  S band;
  S max_weight;
  ImageView<const S> depth;
  ImageView<const S> intensity;
  ImageView<const S> weights;  // empty: 1
  PinholeCamera<S> camera;
  SE3<S> T_camera_volume;

  EMF_HD void operator()(int column) const {
    const int x = column % grid.nx, y = column / grid.nx;
    const S s = grid.voxel_size;
    const Vec3<S> start = T_camera_volume * vec3((S(x) + S(0.5)) * s, (S(y) + S(0.5)) * s, S(0.5) * s);
    const Vec3<S> step = T_camera_volume.rotate(vec3(S(0), S(0), s));
    for (int z = 0; z < grid.nz; ++z) {
      const Vec3<S> p = start + S(z) * step;
      if (!(p.z() > S(0))) continue;
      const Vec2<S> uv = camera.project(p);
      const int u = int(std::floor(uv.x() + S(0.5))), v = int(std::floor(uv.y() + S(0.5)));
      if (!depth.contains(u, v)) continue;
      const S d = depth(u, v);
      if (!is_valid_depth(d) || !(std::fabs(d - p.z()) < band)) continue;
      const S q = weights.empty() ? S(1) : weights(u, v);
      const S I = intensity(u, v);
      if (!(q > S(0)) || !std::isfinite(I)) continue;
      const std::int64_t i = grid.index(x, y, z);
      const S w_old = S(grid.weight[i]), w_sum = w_old + q;
      grid.value[i] = float((w_old * S(grid.value[i]) + q * I) / w_sum);
      grid.weight[i] = float(w_sum < max_weight ? w_sum : max_weight);
    }
  }
};
}  // namespace detail

/// Fuses the gray values of `intensity` (the frame of `depth`, seen at
/// T_world_camera) into `grid`, whose volume frame is at T_world_volume:
/// every voxel within `band` metres of the depth its centre projects to,
/// with the per-pixel weights `weights` (q(u); none: 1). All images live on
/// `backend` and have the camera's size.
template <class S, Backend B>
void fuse_intensity(IntensityGrid<S, B>& grid, const SE3<S>& T_world_volume, S band, S max_weight,
                    const Image<S, B>& depth, const Image<S, B>& intensity, const Image<S, B>* weights,
                    const PinholeCamera<S>& camera, const SE3<S>& T_world_camera, const B& backend) {
  constexpr const char* where = "fuse_intensity";
  detail::require_image(depth.view(), camera.width, camera.height, where, "depth image");
  detail::require_image(intensity.view(), camera.width, camera.height, where, "intensity image");
  if (weights) detail::require_image(weights->view(), camera.width, camera.height, where, "weight image");
  detail::require(band > S(0) && max_weight > S(0), where, "band and max_weight must be positive");
  detail::IntensityColumn<S> f;
  f.grid = grid.view();
  f.band = band, f.max_weight = max_weight;
  f.depth = depth.view(), f.intensity = intensity.view();
  if (weights) f.weights = weights->view();
  f.camera = camera;
  f.T_camera_volume = T_world_camera.inverse() * T_world_volume;
  for_each_index(backend, grid.dims()[0] * grid.dims()[1], f);
}

}  // namespace emfusion
