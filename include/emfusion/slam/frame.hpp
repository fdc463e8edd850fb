// The images of one frame that the stages hand on to each other: the
// received depth made safe, its filtered version and camera-frame points
// (preprocessing), the association images (E-step), the rendered
// segmentation and object depth (rendering) and what tracking did with
// every object. Keep one Frame across frames: its images are reused while
// the camera's size stays.
#pragma once

#include <vector>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/likelihood/e_step.hpp"
#include "emfusion/slam/frame_result.hpp"

namespace emfusion {

template <class S, Backend B = Host>
struct Frame {
  Image<S, B> depth;        ///< the received depth, every invalid pixel a hole (0)
  Image<S, B> filtered;     ///< after the bilateral filter
  Image<Vec3<S>, B> points;  ///< camera frame; NaN where there is no measurement
  /// The frame's gray values in [0, 1] (preprocess/intensity.hpp) when the
  /// caller gave them and object_colour_weight uses them; else empty.
  Image<S, B> intensity;
  /// [0] the background, [k + 1] Map::objects[k], as the last E-step left them.
  Associations<S, B> associations;
  /// Per pixel: -1 nothing drawn and no depth, 0 background, k + 1 Map::objects[k].
  Image<int, B> segmentation;
  /// Per pixel: the depth of the nearest object surface drawn (rendering),
  /// 0 where no object is, whether or not the background hides it.
  Image<S, B> object_depth;
  /// What tracking did with Map::objects[k] this frame (not_tracked for
  /// objects created after tracking).
  std::vector<PoseTrack> object_tracks;
};

}  // namespace emfusion
