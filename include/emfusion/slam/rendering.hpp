// Stage 4 of the EM-Fusion frame (paper sec. 3.5, "raycasting for
// visualization and generation of model masks"): every live object is
// raycast at the current poses where its voxels' p_fg exceeds
// SystemParams::min_foreground, the nearest surface winning each pixel; an
// object pixel lies behind the background by more than the occlusion
// margin loses to it. The result is frame.segmentation: the model masks that
// detection handling and the deletion rules read. Detections are matched
// to them as the frame shows them (seen_segmentation): not where a
// measured surface stands in front of the model.
#pragma once

#include <cmath>
#include <utility>

#include "emfusion/core/camera.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/slam/frame.hpp"
#include "emfusion/slam/map.hpp"
#include "emfusion/slam/params.hpp"
#include "emfusion/volume/raycast.hpp"

namespace emfusion {

/// Images rendering keeps between frames.
template <class S, Backend B>
struct RenderWorkspace {
  Image<S, B> background_ray_end;  ///< where the background's rays stop
  RaycastResult<S, B> background;  ///< the background's rendering, where objects were drawn
  Image<int, B> seen;              ///< seen_segmentation's labels
  ConcurrentLanes<B> lanes;        ///< on a GPU, the objects' casts run at once, one stream each
};

namespace detail::rendering {

/// Keeps, per pixel, the nearest object surface of all objects raycast so far.
template <class S>
struct NearestObject {
  ImageView<const S> depth;
  ImageView<S> best_depth;
  ImageView<int> label;
  int model;
  EMF_HD void operator()(int i) const {
    const S d = depth[i];
    if (!(d > S(0))) return;
    if (best_depth[i] > S(0) && !(d < best_depth[i])) return;
    best_depth[i] = d;
    label[i] = model;
  }
};

/// Where the background's rays end: `margin` in front of the object drawn
/// at the pixel (nothing drawn or too near: 0, no ray).
template <class S>
struct BackgroundRayEnd {
  ImageView<const S> object_depth;
  ImageView<S> end;
  S margin;
  EMF_HD void operator()(int i) const {
    const S d = object_depth[i] - margin;
    end[i] = object_depth[i] > S(0) && d > S(0) ? d : S(0);
  }
};

/// The background wins a pixel where no object was drawn, or where the
/// object lies more than `margin` behind the background surface (rendered
/// only where objects were drawn), unless, with `seen_through`, the frame's
/// point there lies more than `margin` behind that surface too and within
/// `margin` of the object's: the frame sees the object through it (a trace
/// a moving object left in the background), and the object keeps the
/// pixel. Pixels without an object are background
/// where the frame has a point, and nothing (-1) elsewhere.
template <class S>
struct ResolveBackground {
  ImageView<const S> background;  // empty when there are no objects
  ImageView<const S> object_depth;
  ImageView<int> label;
  S margin;
  ImageView<const Vec3<S>> points;
  bool seen_through = false;
  /// The frame's point p lies behind the background's surface at depth
  /// `bg` and on the object's drawn surface at depth `object`.
  EMF_HD bool shows_object_behind(const Vec3<S>& p, S bg, S object) const {
    return is_valid(p) && p.z() > bg + margin && std::fabs(p.z() - object) < margin;
  }
  EMF_HD void operator()(int i) const {
    if (label[i] > 0) {
      const S bg = background.empty() ? S(0) : background[i];
      const bool hidden = bg > S(0) && object_depth[i] > bg + margin;
      if (hidden && !(seen_through && shows_object_behind(points[i], bg, object_depth[i]))) label[i] = 0;
      return;
    }
    label[i] = is_valid(points[i]) ? 0 : -1;
  }
};

/// An object's label where the frame shows the object (or shows nothing);
/// 0 (background) where the frame's point lies more than `margin` in front
/// of the object's drawn surface.
template <class S>
struct SeenLabel {
  ImageView<const int> label;
  ImageView<const S> object_depth;
  ImageView<const Vec3<S>> points;
  ImageView<int> seen;
  S margin;
  EMF_HD void operator()(int i) const {
    const int l = label[i];
    seen[i] = l > 0 && is_valid(points[i]) && points[i].z() < object_depth[i] - margin ? 0 : l;
  }
};

}  // namespace detail::rendering

/// Renders every live object (ObjectModel::rendering), the segmentation of
/// the frame (frame.segmentation) and the nearest object surface per pixel
/// (frame.object_depth) at map.T_world_camera. Person objects that
/// params.ignores are not drawn.
template <class S, Backend B>
void render_models(Map<S, B>& map, Frame<S, B>& frame, const PinholeCamera<S>& camera, const SystemParams<S>& params,
                   RenderWorkspace<S, B>& ws) {
  const B& backend = frame.points.backend();
  RaycastParams<S> rp;
  rp.min_foreground = params.min_foreground;
  rp.surface = false;  // the segmentation needs depth alone
  const int w = camera.width, h = camera.height;
  if (!frame.segmentation.same_size(w, h)) frame.segmentation = Image<int, B>(w, h, -1, backend);
  if (!frame.object_depth.same_size(w, h)) frame.object_depth = Image<S, B>(w, h, S(0), backend);
  // Nearest object per pixel first; then the background, rendered only
  // where an object was drawn (elsewhere nothing competes with it) and
  // only up to the depth where it would lose.
  frame.object_depth.fill(S(0));
  frame.segmentation.fill(-1);
  // The objects' casts are independent, each a few thousand rays marching
  // through a small volume, too few to fill a GPU: on CUDA each goes on a
  // stream of its own (one after another they added 0.09 ms a frame per
  // object, H100). Their renderings are then merged in object order.
  const std::size_t n = map.objects.size();
  ws.lanes.fork(backend, n);
  for (std::size_t k = 0; k < n; ++k) {
    ObjectModel<S, B>& o = *map.objects[k];
    if (params.ignores(o.class_name())) continue;
    const B lane = ws.lanes.lane(k, backend);
    raycast(o.volume(), camera, map.T_world_camera, o.rendering(), rp, &std::as_const(o.foreground()),
            static_cast<const Image<S, B>*>(nullptr), &lane);
  }
  ws.lanes.join(backend, n);
  for (std::size_t k = 0; k < n; ++k) {
    const ObjectModel<S, B>& o = *map.objects[k];
    if (params.ignores(o.class_name())) continue;
    for_each_index(backend, w * h,
                   detail::rendering::NearestObject<S>{o.rendering().depth.view(), frame.object_depth.view(),
                                                       frame.segmentation.view(), int(k) + 1});
  }
  if (!map.objects.empty()) {
    // The background wins only in front of object depth - margin: its
    // rays stop there.
    if (!ws.background_ray_end.same_size(w, h)) ws.background_ray_end = Image<S, B>(w, h, S(0), backend);
    for_each_index(backend, w * h,
                   detail::rendering::BackgroundRayEnd<S>{std::as_const(frame.object_depth).view(),
                                                          ws.background_ray_end.view(), params.occlusion_margin});
    map.background.visit([&](const auto& background) {
      raycast(background, camera, map.T_world_camera, ws.background, rp,
              static_cast<const ForegroundCounts<S, B>*>(nullptr), &std::as_const(ws.background_ray_end));
    });
  }
  const ImageView<const S> bg = map.objects.empty() ? ImageView<const S>{} : std::as_const(ws.background).depth.view();
  for_each_index(backend, w * h,
                 detail::rendering::ResolveBackground<S>{bg, std::as_const(frame.object_depth).view(),
                                                         frame.segmentation.view(), params.occlusion_margin,
                                                         frame.points.view(), params.occlusion_seen_through});
}

/// frame.segmentation (render_models, with `ws` its workspace) as the
/// frame shows it, on the host: a pixel where the frame's point lies more
/// than params.occlusion_margin in front of the object drawn there is
/// background (0). The object is hidden there behind something no live
/// model holds, a lost object or a person; a detection of that thing would
/// otherwise match the model behind it, and a miss would count for an
/// object the detector could not see (on c212 of bench/generalisation.py
/// a false bottle, a patch of the room behind, took the detection of the
/// lost bottle passing in front of it). Detection handling matches by it
/// (handle_detections, relocalize_objects); everything else reads the
/// drawn segmentation.
template <class S, Backend B>
std::vector<int> seen_segmentation(const Frame<S, B>& frame, const SystemParams<S>& params, RenderWorkspace<S, B>& ws) {
  const int w = frame.segmentation.width(), h = frame.segmentation.height();
  if (!frame.object_depth.same_size(w, h)) return frame.segmentation.to_host();  // nothing drawn yet
  if (!ws.seen.same_size(w, h)) ws.seen = Image<int, B>(w, h, -1, frame.segmentation.backend());
  for_each_index(frame.segmentation.backend(), w * h,
                 detail::rendering::SeenLabel<S>{std::as_const(frame.segmentation).view(),
                                                 std::as_const(frame.object_depth).view(), frame.points.view(),
                                                 ws.seen.view(), params.occlusion_margin});
  return ws.seen.to_host();
}

}  // namespace emfusion
