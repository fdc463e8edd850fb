// Detector output for one frame (instance masks with class names and scores)
// and the Segmenter concept: anything that can say, for a frame, whether the
// detector ran and what it found (Mask R-CNN results read from a mask
// directory, the ground truth of a synthetic scene, a user's network).
//
// Detections live on the host: detectors produce them there, they are few,
// and the matching rules run on the host. The system uploads the label image
// once per detector frame.
#pragma once

#include <concepts>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "emfusion/core/image.hpp"

namespace emfusion {

/// One instance found by the detector.
struct Instance {
  int label = 0;            ///< its pixel value in the label image (> 0)
  std::string class_name;   ///< COCO name, spaces written as '_' (e.g. "teddy_bear")
  double score = 1.0;       ///< detector confidence in [0, 1]
};

/// The detector's result for one frame: an instance-label image (pixel value
/// k > 0 belongs to the instance with label k, 0 to none) and the instances.
/// An empty `instances` means "the detector ran and found nothing".
struct Detections {
  double timestamp = 0;
  Image<std::uint16_t, Host> labels;
  std::vector<Instance> instances;

  /// The instance with this label, or nullptr.
  const Instance* find(int label) const {
    for (const Instance& i : instances)
      if (i.label == label) return &i;
    return nullptr;
  }
};

/// A source of detector results: `detect(frame_index, timestamp)` returns the
/// result for that frame, or nothing when the detector did not run on it.
template <class T>
concept Segmenter = requires(T& segmenter, int frame_index, double timestamp) {
  { segmenter.detect(frame_index, timestamp) } -> std::same_as<std::optional<Detections>>;
};

/// A segmenter that never runs (camera-only use, or ablations).
struct NoSegmenter {
  std::optional<Detections> detect(int, double) { return std::nullopt; }
};
static_assert(Segmenter<NoSegmenter>);

}  // namespace emfusion
