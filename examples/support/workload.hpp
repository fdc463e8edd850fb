// The workloads of the benchmarks and examples that run the whole system:
// a TUM-layout sequence with its masks/ folder and ground truth, or sim's
// dynamic room with its simulated detector (4:3 images of the given width,
// the given number of moving objects; the detector's minimum mask area
// scaled from 640x480 to the image). Everything is read before the first
// frame is processed, so that timings hold only the system's work.
#pragma once

#include <algorithm>
#include <cstddef>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "emfusion/core/camera.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/timed_pose.hpp"
#include "emfusion/detect/detection.hpp"
#include "emfusion/io/masks.hpp"
#include "emfusion/io/tum.hpp"
#include "emfusion/sim/detector.hpp"
#include "emfusion/sim/dynamic_scene.hpp"

namespace emfusion::examples {

struct SyntheticRoom {
  sim::DynamicSceneParams params;
  sim::SyntheticSequence sequence;
  sim::SimulatedDetector<float> detector;
};

inline SyntheticRoom synthetic_room(int frames, int width, int moving_objects) {
  sim::DynamicSceneParams p;
  p.frames = frames;
  p.width = width;
  p.height = width * 3 / 4;
  p.moving_objects = moving_objects;
  sim::SyntheticSequence sequence(p);
  sim::SimulatedDetectorParams dp;
  dp.min_area = std::max(1, int(dp.min_area * double(p.width) * p.height / (640.0 * 480.0)));
  sim::SimulatedDetector<float> detector(sequence.scene(), dp);
  return {p, std::move(sequence), std::move(detector)};
}

/// Frames, detections and ground truth, all read before timing starts.
struct Workload {
  PinholeCamera<double> camera;
  std::vector<double> timestamps;
  std::vector<Image<float, Host>> depth;
  std::vector<std::optional<Detections>> detections;
  std::optional<Trajectory> camera_truth;
  std::map<std::string, Trajectory> object_truth;
};

inline Workload load_workload(const std::string& sequence, int frames, int width, int moving_objects) {
  Workload w;
  if (!sequence.empty()) {
    const TumSequence seq = TumSequence::open(sequence);
    const std::size_t n = std::min<std::size_t>(seq.size(), std::size_t(frames));
    w.camera = seq.camera();
    std::optional<MaskDirectory> masks;
    const std::string dir = (std::filesystem::path(sequence) / "masks").string();
    if (std::filesystem::exists(std::filesystem::path(dir) / "masks.txt"))
      masks = MaskDirectory::open(dir, w.camera.width, w.camera.height);
    for (std::size_t i = 0; i < n; ++i) {
      w.timestamps.push_back(seq.timestamp(i));
      w.depth.push_back(seq.depth(i));
      w.detections.push_back(masks ? masks->detect(int(i), seq.timestamp(i)) : std::nullopt);
    }
    w.camera_truth = seq.ground_truth();
    for (auto& [name, traj] : seq.ground_truth_objects()) w.object_truth[name] = traj;
    return w;
  }
  SyntheticRoom room = synthetic_room(frames, width, moving_objects);
  const sim::SyntheticSequence& seq = room.sequence;
  sim::SimulatedDetector<float>& detector = room.detector;
  w.camera = seq.camera();
  for (std::size_t i = 0; i < seq.size(); ++i) {
    w.timestamps.push_back(seq.timestamp(i));
    w.depth.push_back(seq.depth(i));
    w.detections.push_back(detector.detect(int(i), seq.timestamp(i)));
  }
  w.camera_truth = seq.scene().camera_trajectory();
  for (int k = 0; k < seq.scene().object_count(); ++k)
    w.object_truth[seq.scene().object_name(k)] = seq.scene().object_trajectory(k);
  return w;
}

}  // namespace emfusion::examples
