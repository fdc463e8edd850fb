// Matching detections to the objects of the map (paper sec. 3.5): the IoU
// of every detected instance mask with every object's rendered mask, and the
// assignment "each detection to the object it overlaps most, above a
// threshold; when two detections claim one object, the higher IoU wins".
//
// Host code: detections arrive on the host every few frames, and the
// matrices are tiny.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "emfusion/core/error.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/detect/detection.hpp"

namespace emfusion {

/// iou[d][o]: IoU of detection d's mask (pixels labelled instances[d].label)
/// with object o's rendered mask (pixels where segmentation == o + 1;
/// segmentation 0 is the background, negative values nothing).
inline std::vector<std::vector<double>> mask_iou(const Detections& detections,
                                                 const std::vector<int>& segmentation, int object_count) {
  const Image<std::uint16_t, Host>& labels = detections.labels;
  detail::require(segmentation.size() == std::size_t(labels.size()), "mask_iou",
                  "segmentation has " + std::to_string(segmentation.size()) + " pixels, the label image " +
                      std::to_string(labels.size()));
  const int n_det = int(detections.instances.size());
  // Label value -> detection index.
  std::vector<int> detection_of_label(65536, -1);
  for (int d = 0; d < n_det; ++d) detection_of_label[std::size_t(detections.instances[std::size_t(d)].label)] = d;
  std::vector<double> intersection(std::size_t(n_det) * std::size_t(object_count), 0);
  std::vector<double> det_area(std::size_t(n_det), 0), obj_area(std::size_t(object_count), 0);
  const std::uint16_t* l = labels.view().data;
  for (std::size_t i = 0; i < segmentation.size(); ++i) {
    const int d = detection_of_label[l[i]];
    const int o = segmentation[i] - 1;
    const bool is_object = o >= 0 && o < object_count;
    if (d >= 0) det_area[std::size_t(d)] += 1;
    if (is_object) obj_area[std::size_t(o)] += 1;
    if (d >= 0 && is_object) intersection[std::size_t(d) * std::size_t(object_count) + std::size_t(o)] += 1;
  }
  std::vector<std::vector<double>> iou(std::size_t(n_det), std::vector<double>(std::size_t(object_count), 0.0));
  for (int d = 0; d < n_det; ++d)
    for (int o = 0; o < object_count; ++o) {
      const double inter = intersection[std::size_t(d) * std::size_t(object_count) + std::size_t(o)];
      const double uni = det_area[std::size_t(d)] + obj_area[std::size_t(o)] - inter;
      iou[std::size_t(d)][std::size_t(o)] = uni > 0 ? inter / uni : 0.0;
    }
  return iou;
}

/// object_of[d]: the object detection d is matched to, or -1.
struct DetectionMatch {
  std::vector<int> object_of;
  std::vector<double> iou;  ///< of the match; 0 when unmatched
};

/// Each detection goes to the object it overlaps most if that IoU exceeds
/// `min_iou`; of several detections that pick the same object, the one with
/// the highest IoU keeps it and the others stay unmatched.
inline DetectionMatch match_detections(const std::vector<std::vector<double>>& iou, double min_iou) {
  DetectionMatch m;
  m.object_of.assign(iou.size(), -1);
  m.iou.assign(iou.size(), 0.0);
  for (std::size_t d = 0; d < iou.size(); ++d)
    for (std::size_t o = 0; o < iou[d].size(); ++o)
      if (iou[d][o] > min_iou && iou[d][o] > m.iou[d]) m.object_of[d] = int(o), m.iou[d] = iou[d][o];
  for (std::size_t d = 0; d < iou.size(); ++d)
    for (std::size_t e = 0; e < iou.size(); ++e) {
      if (e == d || m.object_of[d] < 0 || m.object_of[d] != m.object_of[e]) continue;
      // The loser of a conflict; ties go to the earlier detection.
      if (m.iou[d] < m.iou[e] || (m.iou[d] == m.iou[e] && d > e)) {
        m.object_of[d] = -1;
        m.iou[d] = 0;
        break;
      }
    }
  return m;
}

}  // namespace emfusion
