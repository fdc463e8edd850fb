// Test fixture: render an analytic scene from poses around it and fuse the
// depth images into a TSDF volume, on any backend.
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include "emfusion/sim/primitives.hpp"
#include "emfusion/sim/render.hpp"
#include "emfusion/volume/integrate.hpp"
#include "emfusion/volume/raycast.hpp"
#include "emfusion/volume/tsdf_volume.hpp"

namespace emfusion::test {

/// A small camera that keeps CI fast while resolving ~6 mm at 1.2 m.
template <class S>
PinholeCamera<S> small_camera() {
  return PinholeCamera<S>{S(200), S(200), S(99.5), S(74.5), 200, 150};
}

/// `count` camera poses on a sphere of `radius` around `center`, spread by a
/// Fibonacci lattice so that every side of the target is seen.
template <class S>
std::vector<SE3<S>> orbit_poses(const Vec3<S>& center, S radius, int count) {
  std::vector<SE3<S>> poses;
  const double golden = M_PI * (3.0 - std::sqrt(5.0));
  for (int k = 0; k < count; ++k) {
    const double z = 1.0 - 2.0 * (k + 0.5) / count;
    const double r = std::sqrt(1.0 - z * z);
    const Vec3<S> dir = vec3(S(r * std::cos(golden * k)), S(r * std::sin(golden * k)), S(z));
    const Vec3<S> up = std::fabs(double(dir.z())) > 0.9 ? vec3(S(1), S(0), S(0)) : vec3(S(0), S(0), S(1));
    poses.push_back(sim::look_at<S>(center + radius * dir, center, up));
  }
  return poses;
}

/// A cubic volume of n voxels of size `voxel` centred on `center`.
template <class S>
VolumeGeometry<S> cube_around(const Vec3<S>& center, int n, S voxel) {
  VolumeGeometry<S> g;
  g.dims = Vec3i{{n, n, n}};
  g.voxel_size = voxel;
  g.T_world_volume = SE3<S>::translation(center - Vec3<S>::constant(S(n) * voxel / S(2)));
  return g;
}

/// A sphere of radius 0.25 m at the origin with a box beside it: curved and
/// flat surfaces and edges within 0.4 m of the origin.
template <class S>
sim::Scene<S> sphere_and_box() {
  sim::Scene<S> scene;
  scene.add(sim::make_sphere(Vec3<S>::zero(), S(0.25)));
  scene.add(sim::make_box(SE3<S>::translation(vec3(S(0.3), S(0.1), S(0))), vec3(S(0.1), S(0.2), S(0.15))));
  return scene;
}

/// Renders and integrates every pose; clean synthetic depth, so by default
/// with the refined update (IntegrationParams::refined()).
template <class S, class B, class Store>
void fuse_views(TsdfVolume<S, B, Store>& volume, const sim::Scene<S>& scene, const PinholeCamera<S>& camera,
                const std::vector<SE3<S>>& poses,
                const IntegrationParams<S>& params = IntegrationParams<S>::refined()) {
  Image<S, B> depth;
  for (const auto& T_world_camera : poses) {
    sim::render_depth(scene, camera, T_world_camera, depth, static_cast<Image<int, B>*>(nullptr), {},
                      volume.backend());
    integrate(volume, depth, camera, T_world_camera, static_cast<const Image<S, B>*>(nullptr), params);
  }
}

/// Depth and hit flags of two volumes raycast from the same pose, on the host.
template <class S>
struct TwoRenderings {
  std::vector<S> depth_a, depth_b;
  std::vector<std::uint8_t> hit_a, hit_b;
};
template <class S, class B, class StoreA, class StoreB>
TwoRenderings<S> raycast_both(const TsdfVolume<S, B, StoreA>& a, const TsdfVolume<S, B, StoreB>& b,
                              const PinholeCamera<S>& camera, const SE3<S>& T_world_camera) {
  RaycastResult<S, B> ra, rb;
  raycast(a, camera, T_world_camera, ra);
  raycast(b, camera, T_world_camera, rb);
  return {ra.depth.to_host(), rb.depth.to_host(), ra.hit.to_host(), rb.hit.to_host()};
}

}  // namespace emfusion::test
