// A detection's pixels as the object stages use them (paper sec. 3.5): the
// camera-frame points of its mask, the pixels that are its own (no other
// object drawn there), and the mapping weights of an object's first frame,
// which has no association image yet. Host code: detection handling runs on
// detector frames only.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "emfusion/core/camera.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/detect/detection.hpp"
#include "emfusion/preprocess/vertex_map.hpp"

namespace emfusion {

/// The mapping weights of an object in its first frame (new or re-identified).
template <class S, Backend B>
struct NewObjectWeights {
  Image<S, B> weights;          ///< 1 on the detection's own pixels, 0 on other objects', `outside` elsewhere
  Image<std::uint8_t, B> mask;  ///< the detection's own pixels, for the foreground counts
  int detection = -1;           ///< the instance it came from
};

/// Camera-frame points of a detection's pixels (`labels` == `label`),
/// without the pixels another object covers when `seg` (the segmentation,
/// on the host) is given; `covered` and `total` count those and all.
template <class S>
std::vector<Vec3<S>> detection_points(const std::vector<Vec3<S>>& points, const std::uint16_t* labels, int label,
                                      const std::vector<int>* seg = nullptr, int* covered = nullptr,
                                      int* total = nullptr) {
  std::vector<Vec3<S>> out;
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (labels[i] != label) continue;
    if (total) ++*total;
    if (seg && (*seg)[i] > 0) {
      if (covered) ++*covered;
      continue;
    }
    if (is_valid(points[i])) out.push_back(points[i]);
  }
  return out;
}

/// Per pixel, 1 where detection d's mask is and no object is drawn (`seg`):
/// the pixels that are the detection's own.
inline std::vector<std::uint8_t> own_mask(const Detections& det, int d, const std::vector<int>& seg) {
  const std::uint16_t* labels = det.labels.view().data;
  const int label = det.instances[std::size_t(d)].label;
  std::vector<std::uint8_t> mask(seg.size(), 0);
  for (std::size_t i = 0; i < seg.size(); ++i) mask[i] = labels[i] == label && !(seg[i] > 0);
  return mask;
}

/// The mapping weights of an object's first frame from detection d: 1 on
/// its own pixels, 0 on other objects' pixels, and elsewhere `outside`: the
/// association the E-step gives a model that does not explain a pixel beside
/// one that does (unexplained_association), so that the border of the first
/// view is observed as on later frames.
template <class S, Backend B>
NewObjectWeights<S, B> first_view_weights(const Detections& det, int d, const std::vector<int>& seg, S outside,
                                          const PinholeCamera<S>& camera, const B& backend) {
  NewObjectWeights<S, B> w;
  w.detection = d;
  const std::vector<std::uint8_t> mask = own_mask(det, d, seg);
  std::vector<S> weights(seg.size(), S(0));
  for (std::size_t i = 0; i < seg.size(); ++i) weights[i] = mask[i] ? S(1) : seg[i] > 0 ? S(0) : outside;
  w.weights = Image<S, Host>::from_host(camera.width, camera.height, weights).template to<B>(backend);
  w.mask = Image<std::uint8_t, Host>::from_host(camera.width, camera.height, mask).template to<B>(backend);
  return w;
}

}  // namespace emfusion
