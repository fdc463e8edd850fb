// The FrameSource concept: what the SLAM loop needs from anything that yields
// timestamped depth frames (a TUM sequence on disk, a synthetic scene, a
// live camera wrapper).
#pragma once

#include <concepts>
#include <cstddef>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/camera.hpp"
#include "emfusion/core/image.hpp"

namespace emfusion {

/// A source of `size()` frames, numbered from 0 in time order; frame i has a
/// timestamp in seconds and a depth image in metres (0 = no measurement) of
/// the camera's size.
template <class F>
concept FrameSource = requires(const F& source, std::size_t i) {
  { source.size() } -> std::convertible_to<std::size_t>;
  { source.timestamp(i) } -> std::convertible_to<double>;
  { source.depth(i) } -> std::same_as<Image<float, Host>>;
  { source.camera() } -> std::convertible_to<PinholeCamera<double>>;
};

}  // namespace emfusion
