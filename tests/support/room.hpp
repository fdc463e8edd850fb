// Test fixture: a small synthetic room (floor, two walls, three objects) fused
// from a handful of views around the origin, the world frame being the first
// camera's (x right, y down, z forward).
#pragma once

#include <vector>

#include "emfusion/preprocess/vertex_map.hpp"
#include "emfusion/robust/norms.hpp"
#include "support/fusion.hpp"

namespace emfusion::test {

template <class S>
sim::Scene<S> room_scene() {
  sim::Scene<S> scene;
  const Vec3<S> down = vec3(S(0), S(1), S(0));
  // A plane's pose has its normal as z: look from a point on it towards the room.
  scene.add(sim::make_plane(sim::look_at(vec3(S(0), S(0.8), S(0)), Vec3<S>::zero(), vec3(S(0), S(0), S(1)))));
  scene.add(sim::make_plane(sim::look_at(vec3(S(0), S(0), S(2.2)), Vec3<S>::zero(), down)));
  scene.add(sim::make_plane(sim::look_at(vec3(S(-1.1), S(0), S(0)), Vec3<S>::zero(), down)));
  scene.add(sim::make_sphere(vec3(S(0.35), S(0.3), S(1.4)), S(0.25)));
  scene.add(sim::make_box(SE3<S>(so3_exp(vec3(S(0.1), S(0.5), S(0))), vec3(S(-0.35), S(0.5), S(1.1))),
                          vec3(S(0.2), S(0.3), S(0.15))));
  scene.add(sim::make_cylinder(SE3<S>::translation(vec3(S(0.6), S(0.3), S(1.9))), S(0.15), S(0.5)));
  return scene;
}

/// A camera of 160x120 pixels with a 60 degree horizontal field of view.
template <class S>
PinholeCamera<S> room_camera() {
  return PinholeCamera<S>{S(138), S(138), S(79.5), S(59.5), 160, 120};
}

/// Views around the origin: small translations and rotations that cover the
/// room seen from the identity pose.
template <class S>
std::vector<SE3<S>> room_views() {
  std::vector<SE3<S>> poses{SE3<S>::identity()};
  for (int k = 0; k < 8; ++k) {
    const S a = S(0.785398) * S(k);
    poses.push_back(SE3<S>::exp(Vec6<S>{{S(0.15) * std::cos(a), S(0.1) * std::sin(a), S(-0.1),
                                         S(0.12) * std::sin(a), S(0.15) * std::cos(a), S(0.05)}}));
  }
  return poses;
}

/// The room fused into 128^3 voxels of `voxel` metres.
template <class S, class B>
TsdfVolume<S, B> fused_room(S voxel = S(0.02)) {
  VolumeGeometry<S> g;
  g.dims = Vec3i{{128, 128, 128}};
  g.voxel_size = voxel;
  const S half = S(64) * voxel;
  g.T_world_volume = SE3<S>::translation(vec3(-half, -half, S(-0.2)));
  TsdfVolume<S, B> volume(g);
  fuse_views(volume, room_scene<S>(), room_camera<S>(), room_views<S>());
  return volume;
}

/// Camera-frame points seen from `pose` in the room.
template <class S, class B>
Image<Vec3<S>, B> room_points(const SE3<S>& pose) {
  Image<S, B> depth;
  sim::render_depth(room_scene<S>(), room_camera<S>(), pose, depth);
  Image<Vec3<S>, B> points;
  back_project(depth, room_camera<S>(), points);
  return points;
}

/// The fused room seen from a known pose off the origin, and the Huber
/// norm of two voxels: what the alignment tests solve.
template <class S, class B>
struct RoomAtKnownPose {
  TsdfVolume<S, B> volume = fused_room<S, B>();
  SE3<S> truth = SE3<S>::exp(Vec6<S>{{S(0.03), S(-0.02), S(0.04), S(0.02), S(-0.03), S(0.01)}});
  Image<Vec3<S>, B> points = room_points<S, B>(truth);
  HuberNorm<S> huber{S(2) * volume.voxel_size()};
};

}  // namespace emfusion::test
