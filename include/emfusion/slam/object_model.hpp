// One object of the EM-Fusion map: its TSDF and foreground counts, its pose,
// existence counts and class scores, and resizing that keeps the voxel size
// and the grid alignment (paper sec. 3.5); and how much of it a camera has
// in view (shows_less_than: too little of it to align).
//
// Frames: the object frame is fixed to the object (its origin is the centre
// of the volume it was created with); the volume frame (corner of the grid)
// sits at T_object_volume in it, which changes only when the volume grows.
// Trajectories and meshes are written in the object frame.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "emfusion/core/camera.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/core/pixel_box.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/volume/foreground.hpp"
#include "emfusion/volume/intensity_grid.hpp"
#include "emfusion/volume/raycast.hpp"
#include "emfusion/volume/tsdf_volume.hpp"

namespace emfusion {

namespace detail {
/// Copies voxel i of the old grid to its place in the grown grid.
template <class S>
struct CopyIntoGrown {
  TsdfView<S, const S> from;
  TsdfView<S, S> to;
  ForegroundView<S, const float> fg_from;
  ForegroundView<S, float> fg_to;
  IntensityView<S, const float> colour_from;  // empty: no colour to copy
  IntensityView<S, float> colour_to;
  Vec3i offset;

  EMF_HD void operator()(std::int64_t i) const {
    const int x = int(i % from.nx), y = int((i / from.nx) % from.ny), z = int(i / (std::int64_t(from.nx) * from.ny));
    const std::int64_t j = to.index(x + offset[0], y + offset[1], z + offset[2]);
    to.sdf[j] = from.sdf[i];
    to.weight[j] = from.weight[i];
    fg_to.fg[j] = fg_from.fg[i];
    fg_to.bg[j] = fg_from.bg[i];
    if (!colour_from.empty()) {
      colour_to.value[j] = colour_from.value[i];
      colour_to.weight[j] = colour_from.weight[i];
    }
  }
};
}  // namespace detail

template <class S, Backend B = Host>
class ObjectModel {
 public:
  /// A new object with a cubic volume of `voxels`^3 voxels of `voxel_size`
  /// centred on the object frame's origin, which is at T_world_object.
  ObjectModel(int id, std::string class_name, const SE3<S>& T_world_object, int voxels, S voxel_size,
              S truncation_voxels, B backend = B{})
      : id_(id), class_name_(std::move(class_name)), T_world_object_(T_world_object),
        T_object_volume_(SE3<S>::translation(Vec3<S>::constant(-S(voxels) * voxel_size / S(2)))),
        volume_(geometry(Vec3i{{voxels, voxels, voxels}}, voxel_size, truncation_voxels), backend),
        foreground_(Vec3i{{voxels, voxels, voxels}}, voxel_size, backend) {
    sync_volume_pose();
  }

  /// An object with all its state given (io/checkpoint.hpp loads one so):
  /// the volume and counts must share their dimensions and voxel size.
  static ObjectModel restore(int id, std::string class_name, std::vector<std::pair<std::string, double>> class_scores,
                             const SE3<S>& T_world_object, const SE3<S>& T_object_volume, TsdfVolume<S, B> volume,
                             ForegroundCounts<S, B> foreground, int existence, int non_existence) {
    const Vec3i& d = volume.dims();
    const Vec3i& f = foreground.dims();
    detail::require(d[0] == f[0] && d[1] == f[1] && d[2] == f[2] && volume.voxel_size() == foreground.voxel_size(),
                    "ObjectModel::restore", "the volume and the foreground counts differ in their grid");
    return ObjectModel(id, std::move(class_name), std::move(class_scores), T_world_object, T_object_volume,
                       std::move(volume), std::move(foreground), existence, non_existence);
  }

  int id() const { return id_; }
  /// The class with the highest accumulated score.
  const std::string& class_name() const { return class_name_; }

  const SE3<S>& pose() const { return T_world_object_; }  ///< T_world_object
  /// Sets T_world_object (its rotation made orthonormal: the pose is
  /// updated every frame from products of poses).
  void set_pose(const SE3<S>& T_world_object) {
    T_world_object_ = T_world_object.orthonormalized();
    sync_volume_pose();
  }
  /// Puts back a pose the object had before, bit for bit (set_pose would
  /// orthonormalise it once more): tracking undoes a motion prediction with it.
  void restore_pose(const SE3<S>& earlier_pose) {
    T_world_object_ = earlier_pose;
    sync_volume_pose();
  }
  const SE3<S>& T_object_volume() const { return T_object_volume_; }

  TsdfVolume<S, B>& volume() { return volume_; }
  const TsdfVolume<S, B>& volume() const { return volume_; }
  ForegroundCounts<S, B>& foreground() { return foreground_; }
  const ForegroundCounts<S, B>& foreground() const { return foreground_; }
  /// The model's colour (volume/intensity_grid.hpp): empty until
  /// enable_colour, then on the volume's grid, growing with it.
  IntensityGrid<S, B>& colour() { return colour_; }
  const IntensityGrid<S, B>& colour() const { return colour_; }
  /// Gives the model an uncoloured IntensityGrid if it has none.
  void enable_colour() {
    if (colour_.empty()) colour_ = IntensityGrid<S, B>(volume_.dims(), volume_.voxel_size(), volume_.backend());
  }
  /// The last raycast of this object: depth and hit, which the system's
  /// segmentation uses (vertices and normals are left empty: render_models
  /// casts with RaycastParams::surface off; raycast the volume for them).
  RaycastResult<S, B>& rendering() { return rendering_; }
  const RaycastResult<S, B>& rendering() const { return rendering_; }

  // Existence (counted on detector frames).
  void count_detected() { ++existence_; }
  void count_missed() { ++non_existence_; }
  int existence_count() const { return existence_; }
  int non_existence_count() const { return non_existence_; }
  double existence_probability() const { return double(existence_) / double(existence_ + non_existence_); }

  /// Adds a detection's score to its class; the object's class is the
  /// class with the highest sum.
  void add_class_score(const std::string& name, double score) {
    auto it = std::find_if(class_scores_.begin(), class_scores_.end(), [&](auto& c) { return c.first == name; });
    if (it == class_scores_.end()) {
      class_scores_.emplace_back(name, 0.0);
      it = class_scores_.end() - 1;
    }
    it->second += score;
    const auto best = std::max_element(class_scores_.begin(), class_scores_.end(),
                                       [](auto& a, auto& b) { return a.second < b.second; });
    class_name_ = best->first;
  }
  const std::vector<std::pair<std::string, double>>& class_scores() const { return class_scores_; }
  /// Takes over another model's existence counts and class scores (two
  /// models found to be one object, slam/merging.hpp).
  void add_counts_of(const ObjectModel& other) {
    existence_ += other.existence_;
    non_existence_ += other.non_existence_;
    for (const auto& [name, score] : other.class_scores_) add_class_score(name, score);
  }

  /// Grows the volume so that the volume-frame box [lo, hi] fits, adding
  /// whole voxels on the sides that need them (the voxel size and the
  /// positions of existing voxels in the object frame stay), at most
  /// `max_voxels` per axis. Returns true if the volume changed.
  bool grow_to_fit(const Vec3<S>& lo, const Vec3<S>& hi, int max_voxels) {
    const Vec3i old_dims = volume_.dims();
    const S s = volume_.voxel_size();
    Vec3i below{{0, 0, 0}}, dims = old_dims;
    // Voxels to add below and above, clamped to the cap before the
    // conversion: a box from absurd points (1e30 m, inf) must not overflow
    // an int; NaN adds nothing.
    const auto voxels_to_add = [&](S metres) {
      const S v = std::ceil(metres / s);
      return v > S(0) ? int(std::min(double(v), double(max_voxels))) : 0;
    };
    for (int a = 0; a < 3; ++a) {
      int add_lo = voxels_to_add(-lo[a]);
      int add_hi = voxels_to_add(hi[a] - S(old_dims[a]) * s);
      // Within the cap, keep what can be kept: split the room between both sides.
      const int room = std::max(0, max_voxels - old_dims[a]);
      if (add_lo + add_hi > room) {
        const int total = add_lo + add_hi;
        add_lo = int(std::floor(double(add_lo) * room / total));
        add_hi = room - add_lo;
      }
      below[a] = add_lo;
      dims[a] = old_dims[a] + add_lo + add_hi;
    }
    if (dims[0] == old_dims[0] && dims[1] == old_dims[1] && dims[2] == old_dims[2]) return false;
    const B backend = volume_.backend();
    TsdfVolume<S, B> volume(geometry(dims, s, volume_.truncation() / s), backend);
    ForegroundCounts<S, B> counts(dims, s, backend);
    IntensityGrid<S, B> colour = colour_.empty() ? IntensityGrid<S, B>{} : IntensityGrid<S, B>(dims, s, backend);
    detail::CopyIntoGrown<S> f{std::as_const(volume_).view(),
                               volume.view(),
                               std::as_const(foreground_).view(),
                               counts.view(),
                               std::as_const(colour_).view(),
                               colour.view(),
                               below};
    for_each_index(backend, volume_.voxel_count(), f);
    volume_ = std::move(volume);
    foreground_ = std::move(counts);
    colour_ = std::move(colour);
    T_object_volume_ = T_object_volume_ * SE3<S>::translation(-s * vec3(S(below[0]), S(below[1]), S(below[2])));
    sync_volume_pose();
    return true;
  }

  std::size_t memory_bytes() const {
    return volume_.memory_bytes() + foreground_.memory_bytes() + colour_.memory_bytes();
  }

 private:
  ObjectModel(int id, std::string class_name, std::vector<std::pair<std::string, double>> class_scores,
              const SE3<S>& T_world_object, const SE3<S>& T_object_volume, TsdfVolume<S, B> volume,
              ForegroundCounts<S, B> foreground, int existence, int non_existence)
      : id_(id), class_name_(std::move(class_name)), class_scores_(std::move(class_scores)),
        T_world_object_(T_world_object), T_object_volume_(T_object_volume), volume_(std::move(volume)),
        foreground_(std::move(foreground)), existence_(existence), non_existence_(non_existence) {
    sync_volume_pose();
  }

  static VolumeGeometry<S> geometry(const Vec3i& dims, S voxel_size, S truncation_voxels) {
    VolumeGeometry<S> g;
    g.dims = dims;
    g.voxel_size = voxel_size;
    g.truncation = truncation_voxels * voxel_size;
    return g;
  }
  void sync_volume_pose() { volume_.set_pose(T_world_object_ * T_object_volume_); }

  int id_;
  std::string class_name_;
  std::vector<std::pair<std::string, double>> class_scores_;
  SE3<S> T_world_object_;
  SE3<S> T_object_volume_;
  TsdfVolume<S, B> volume_;
  ForegroundCounts<S, B> foreground_;
  IntensityGrid<S, B> colour_;
  RaycastResult<S, B> rendering_;
  int existence_ = 1;  // the detection that created it
  int non_existence_ = 0;
};

namespace detail::object_model {
/// The one-voxel box of voxel i where the object's surface is (observed,
/// |sdf| at most a voxel, Fg > Bg), else an empty one.
template <class S, class Store>
struct SurfaceVoxel {
  TsdfView<S, const Store> tsdf;
  ForegroundView<S, const float> counts;
  EMF_HD VoxelBox operator()(std::int64_t i) const {
    if (!(S(tsdf.weight[i]) > S(0)) || !(std::fabs(S(tsdf.sdf[i])) <= tsdf.voxel_size) ||
        !(S(counts.fg[i]) > S(counts.bg[i])))
      return VoxelBox{};
    return emfusion::detail::voxel_box_at(i, tsdf.nx, tsdf.ny);
  }
};

/// The share of the voxel box `box` of object `o` at T_world_object that a
/// camera at T_world_camera sees inside the image less `border` pixels:
/// of the rectangle around the projections of its eight corners, the part
/// inside over the whole. 1 when a corner is not in front of the camera
/// (the box may cover any part of the view) or the box is empty.
template <class S, Backend B>
double box_share(const ObjectModel<S, B>& o, const VoxelBox& box, const SE3<S>& T_world_object,
                 const SE3<S>& T_world_camera, const PinholeCamera<S>& camera, int border) {
  if (box.empty()) return 1.0;
  const S vs = o.volume().voxel_size();
  const std::optional<PixelRect> r = projected_rect(
      camera, T_world_camera.inverse() * T_world_object * o.T_object_volume(),
      vec3(S(box.lo[0]), S(box.lo[1]), S(box.lo[2])) * vs, vec3(S(box.hi[0]), S(box.hi[1]), S(box.hi[2])) * vs);
  if (!r) return 1.0;
  const double whole = (r->u_max - r->u_min) * (r->v_max - r->v_min);
  if (!(whole > 0)) return 1.0;
  const double w = std::min(r->u_max, double(camera.width - border)) - std::max(r->u_min, double(border));
  const double h = std::min(r->v_max, double(camera.height - border)) - std::max(r->v_min, double(border));
  return w > 0 && h > 0 ? w * h / whole : 0.0;
}
}  // namespace detail::object_model

/// True when less than `share` of object `o`'s extent, at T_world_object,
/// lies inside the image less `border` pixels as a camera at
/// T_world_camera sees it: the share of the rectangle around its surface's
/// projection (the box of voxels on its surface, observed and of p_fg >
/// 1/2) inside (box_share). The box of its foreground counts (majority_box,
/// cached, holding the surface's) is tried first: an object with at least
/// `share` of that box in view is taken as in view without a pass over its
/// volume for the surface's box.
template <class S, Backend B>
bool shows_less_than(const ObjectModel<S, B>& o, const SE3<S>& T_world_object, const SE3<S>& T_world_camera,
                     const PinholeCamera<S>& camera, int border, double share) {
  const auto in_view = [&](const VoxelBox& box) {
    return detail::object_model::box_share(o, box, T_world_object, T_world_camera, camera, border);
  };
  if (in_view(o.foreground().majority_box()) >= share) return false;
  const auto& v = o.volume().view();
  const VoxelBox surface = transform_reduce_index(
      o.volume().backend(), v.voxel_count(),
      detail::object_model::SurfaceVoxel<S, std::remove_cvref_t<decltype(*v.sdf)>>{v, o.foreground().view()},
      VoxelBox{}, detail::UniteVoxelBoxes{});
  return in_view(surface) < share;
}

}  // namespace emfusion
