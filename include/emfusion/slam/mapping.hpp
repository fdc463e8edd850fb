// Stage 6 of the EM-Fusion frame, the M-step for the maps: the depth is
// integrated into the background and every live object with its association
// image as the per-pixel weight (paper eq. 10; a new object's first frame
// uses its detection mask), and every object a detection matched or created
// updates its foreground counts from that detection's mask where no other
// object covers the pixel (eq. 6). With object_colour_weight, every object
// also fuses the frame's gray values into its colour, with the same weights.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "emfusion/core/camera.hpp"
#include "emfusion/detect/detection.hpp"
#include "emfusion/slam/detection_masks.hpp"
#include "emfusion/slam/frame.hpp"
#include "emfusion/slam/map.hpp"
#include "emfusion/slam/params.hpp"
#include "emfusion/volume/foreground.hpp"
#include "emfusion/volume/integrate.hpp"
#include "emfusion/volume/intensity_grid.hpp"
#include "emfusion/volume/sparse_tsdf_volume.hpp"

namespace emfusion {

/// What integrating the objects keeps between frames: a workspace each
/// and, on a GPU, a stream each, so that the objects integrate at once
/// (one after another, each object's volume of 64^3-128^3 voxels left most
/// of the GPU idle: 0.037 ms a frame per object, H100).
template <class S, Backend B>
struct ObjectIntegrationWorkspace {
  std::vector<IntegrationWorkspace<S, B>> objects;
  ConcurrentLanes<B> lanes;
};

/// Integrates frame.depth at map.T_world_camera into every model (eq. 10):
/// model k with weights frame.associations.image(k), the last fresh.size()
/// objects (added by detection handling) with their first-view weights.
/// `first`: the frame that starts the map, which has no association images;
/// the background then takes every pixel with weight 1. The background
/// forgets traces (params.background_integration.unowned_free_from) only
/// where render_models drew an object (frame.object_depth; everywhere if
/// the frame has none).
/// `background_weights` (optional) replaces the background's association
/// image as its weights (hold_unexplained, unexplained.hpp). The workspaces
/// (optional) keep the buffers of a dense and of a sparse background, and
/// `objects_workspace` those of the objects, which then integrate at once
/// (without it, one after another through `workspace`). With
/// params.object_colour_weight and the frame's gray values
/// (frame.intensity), every object's colour takes them too (fuse_intensity,
/// within its truncation, with its weights).
template <class S, Backend B>
void integrate_models(Map<S, B>& map, const Frame<S, B>& frame, const PinholeCamera<S>& camera,
                      const SystemParams<S>& params, const std::vector<NewObjectWeights<S, B>>& fresh, bool first,
                      const Image<S, B>* background_weights = nullptr, IntegrationWorkspace<S, B>* workspace = nullptr,
                      SparseIntegrationWorkspace<S, B>* sparse_workspace = nullptr,
                      ObjectIntegrationWorkspace<S, B>* objects_workspace = nullptr) {
  const std::size_t old_objects = map.objects.size() - fresh.size();
  if (!background_weights && !first) background_weights = &frame.associations.image(0);
  const bool drawn = frame.object_depth.same_size(frame.depth.width(), frame.depth.height());
  const IntegrationWeights<S, B> weights{background_weights, drawn ? &frame.object_depth : nullptr};
  map.background.visit([&](auto& background) {
    if constexpr (requires { background.allocated_blocks(); })
      integrate(background, frame.depth, camera, map.T_world_camera, weights, params.background_integration,
                sparse_workspace);
    else
      integrate(background, frame.depth, camera, map.T_world_camera, weights, params.background_integration, workspace);
  });
  const std::size_t n = map.objects.size();
  const B& backend = frame.depth.backend();
  // Colour (object_colour_weight, reidentify_colour_agreement): every object fuses the frame's gray
  // values with the weights of its integration, on its lane too. Grids are
  // made before the lanes fork, so that the lanes' work follows their fill.
  const bool coloured = params.uses_colour() && !frame.intensity.empty();
  if (coloured)
    for (std::size_t k = 0; k < n; ++k) map.objects[k]->enable_colour();
  if (objects_workspace) {
    if (objects_workspace->objects.size() < n) objects_workspace->objects.resize(n);
    objects_workspace->lanes.fork(backend, n);
  }
  for (std::size_t k = 0; k < n; ++k) {
    ObjectModel<S, B>& o = *map.objects[k];
    const Image<S, B>* weights =
        k < old_objects ? &frame.associations.image(int(k) + 1) : &fresh[k - old_objects].weights;
    const B lane = objects_workspace ? objects_workspace->lanes.lane(k, backend) : backend;
    if (objects_workspace)
      integrate(o.volume(), frame.depth, camera, map.T_world_camera, weights, params.object_integration,
                &objects_workspace->objects[k], &lane);
    else
      integrate(o.volume(), frame.depth, camera, map.T_world_camera, weights, params.object_integration, workspace);
    if (coloured)
      fuse_intensity(o.colour(), o.volume().pose(), o.volume().truncation(), params.object_integration.max_weight,
                     frame.depth, frame.intensity, weights, camera, map.T_world_camera, lane);
  }
  if (objects_workspace) objects_workspace->lanes.join(backend, n);
}

/// Eq. 6 for every object detection d matched (`object_of[d]`) or created
/// (`fresh`), where no other object is drawn (`seg`, the segmentation on
/// the host that matching used).
template <class S, Backend B>
void update_foreground_counts(Map<S, B>& map, const Frame<S, B>& frame, const Detections& det,
                              const std::vector<int>& seg, const std::vector<int>& object_of,
                              const std::vector<NewObjectWeights<S, B>>& fresh, const PinholeCamera<S>& camera) {
  const std::size_t old_objects = map.objects.size() - fresh.size();
  const std::uint16_t* labels = det.labels.view().data;
  const B& backend = frame.depth.backend();
  const auto to_backend = [&](const std::vector<std::uint8_t>& v) {
    return Image<std::uint8_t, Host>::from_host(camera.width, camera.height, v).template to<B>(backend);
  };
  const auto update = [&](ObjectModel<S, B>& o, int model_label, const Image<std::uint8_t, B>& mask) {
    std::vector<std::uint8_t> counted(seg.size());
    for (std::size_t i = 0; i < seg.size(); ++i) counted[i] = !(seg[i] > 0 && seg[i] != model_label);
    update_foreground(o.foreground(), o.volume().pose(), o.volume().truncation(), frame.depth, mask,
                      to_backend(counted), camera, map.T_world_camera, backend);
  };
  for (std::size_t d = 0; d < object_of.size(); ++d) {
    const int k = object_of[d];
    if (k < 0 || std::size_t(k) >= old_objects) continue;
    std::vector<std::uint8_t> mask(seg.size());
    for (std::size_t i = 0; i < seg.size(); ++i) mask[i] = labels[i] == det.instances[d].label;
    update(*map.objects[std::size_t(k)], k + 1, to_backend(mask));
  }
  for (std::size_t j = 0; j < fresh.size(); ++j)
    update(*map.objects[old_objects + j], int(old_objects + j) + 1, fresh[j].mask);
}

}  // namespace emfusion
