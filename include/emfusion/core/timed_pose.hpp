// A pose with a timestamp, and trajectories of them: what the TUM format
// stores (io/tum.hpp), what trackers produce and what eval/ compares.
#pragma once

#include <vector>

#include "emfusion/core/se3.hpp"

namespace emfusion {

/// T_world_body at `timestamp` (seconds): maps body points into the world.
struct TimedPose {
  double timestamp = 0;
  SE3<double> pose;
};

using Trajectory = std::vector<TimedPose>;

}  // namespace emfusion
