// Depth and label images of an analytic scene, by sphere tracing: the
// synthetic sensor behind tests, the demo and benchmarks.
#pragma once

#include <cmath>

#include "emfusion/core/camera.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/sim/primitives.hpp"

namespace emfusion::sim {

template <class S>
struct RenderParams {
  S min_depth = S(0.05);
  S max_depth = S(10);
  S hit_tolerance = S(1e-5);  ///< metres: a ray stops closer than this to a surface
  int max_steps = 512;
};

namespace detail {
template <class S>
struct RenderPixel {
  Scene<S> scene;
  PinholeCamera<S> camera;
  SE3<S> T_world_camera;
  RenderParams<S> params;
  ImageView<S> depth;
  ImageView<int> labels;

  EMF_HD void operator()(int i) const {
    const int u = i % camera.width, v = i / camera.width;
    const Vec3<S> ray_cam = normalized(camera.ray(S(u), S(v)));
    const Vec3<S> o = T_world_camera.translation();
    const Vec3<S> d = T_world_camera.rotate(ray_cam);
    S t = params.min_depth / ray_cam.z();
    const S t_max = params.max_depth / ray_cam.z();
    S z = S(0);
    int label = -1;
    for (int k = 0; k < params.max_steps && t < t_max; ++k) {
      int nearest;
      const S dist = scene.distance(o + t * d, &nearest);
      if (dist < params.hit_tolerance) {
        z = t * ray_cam.z();
        label = nearest;
        break;
      }
      t += dist;
    }
    depth[i] = z;
    if (!labels.empty()) labels[i] = label;
  }
};
}  // namespace detail

/// Renders metric depth (0 = nothing within max_depth) and, if `labels` is
/// given, the index of the shape seen at each pixel (-1 = none). Images are
/// (re)allocated to the camera size on `backend`.
template <class S, Backend B>
void render_depth(const Scene<S>& scene, const PinholeCamera<S>& camera, const SE3<S>& T_world_camera,
                  Image<S, B>& depth, Image<int, B>* labels = nullptr, const RenderParams<S>& params = {},
                  const B& backend = B{}) {
  camera.validate("render_depth");
  if (!depth.same_size(camera.width, camera.height)) depth = Image<S, B>(camera.width, camera.height, S(0), backend);
  if (labels && !labels->same_size(camera.width, camera.height))
    *labels = Image<int, B>(camera.width, camera.height, -1, backend);
  detail::RenderPixel<S> f{scene, camera, T_world_camera, params, depth.view(),
                           labels ? labels->view() : ImageView<int>{}};
  for_each_index(depth.backend(), camera.width * camera.height, f);
}

}  // namespace emfusion::sim
