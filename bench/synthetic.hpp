// The benchmarks' synthetic workload: sim's dynamic room (4:3 images of the
// given width, the given number of moving objects) and its simulated
// detector, whose minimum mask area is scaled from 640x480 to the image.
#pragma once

#include <algorithm>
#include <utility>

#include "emfusion/sim/detector.hpp"
#include "emfusion/sim/dynamic_scene.hpp"

namespace emfusion::bench {

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

}  // namespace emfusion::bench
