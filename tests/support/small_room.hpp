// Test fixture: the simulated dynamic room (sim/dynamic_scene.hpp) at
// 160x120 pixels, small enough for the sanitizer build.
#pragma once

#include <cstdint>

#include "emfusion/sim/dynamic_scene.hpp"

namespace emfusion::test {

/// The room with `objects` moving objects, `frames` frames and `seed`, at
/// 160x120.
inline sim::DynamicSceneParams small_room(int objects, int frames = 300, std::uint64_t seed = 1) {
  sim::DynamicSceneParams p;
  p.moving_objects = objects;
  p.frames = frames;
  p.width = 160;
  p.height = 120;
  p.seed = seed;
  return p;
}

}  // namespace emfusion::test
