// Pinhole camera without distortion: projection of camera-frame points to
// pixels and back-projection of pixels with depth. Pixel centres lie at
// integer coordinates; depth is the z coordinate in metres.
#pragma once

#include <string>

#include "emfusion/core/error.hpp"
#include "emfusion/core/host_device.hpp"
#include "emfusion/core/math.hpp"

namespace emfusion {

template <class S>
struct PinholeCamera {
  using Scalar = S;

  S fx = S(525), fy = S(525), cx = S(319.5), cy = S(239.5);
  int width = 640, height = 480;

  /// Pixel coordinates of camera-frame point p (z > 0 assumed).
  EMF_HD Vec2<S> project(const Vec3<S>& p) const {
    return vec2(fx * p.x() / p.z() + cx, fy * p.y() / p.z() + cy);
  }
  /// Camera-frame point seen at pixel (u, v) with the given depth (z).
  EMF_HD Vec3<S> back_project(S u, S v, S depth) const {
    return vec3((u - cx) / fx * depth, (v - cy) / fy * depth, depth);
  }
  /// Direction of the ray through pixel (u, v), scaled so that its z is 1.
  EMF_HD Vec3<S> ray(S u, S v) const { return vec3((u - cx) / fx, (v - cy) / fy, S(1)); }
  /// True if pixel coordinates (u, v) round to a pixel inside the image.
  EMF_HD bool contains(S u, S v) const {
    return u > S(-0.5) && v > S(-0.5) && u < S(width) - S(0.5) && v < S(height) - S(0.5);
  }
  EMF_HD int pixel_count() const { return width * height; }

  /// The camera for an image scaled by `factor` (e.g. 0.5 for a pyramid level).
  PinholeCamera scaled(S factor) const {
    PinholeCamera c = *this;
    c.fx = fx * factor, c.fy = fy * factor;
    c.cx = (cx + S(0.5)) * factor - S(0.5), c.cy = (cy + S(0.5)) * factor - S(0.5);
    c.width = static_cast<int>(width * factor), c.height = static_cast<int>(height * factor);
    return c;
  }

  template <class T>
  PinholeCamera<T> cast() const {
    return PinholeCamera<T>{T(fx), T(fy), T(cx), T(cy), width, height};
  }

  /// Throws std::invalid_argument if the intrinsics cannot describe a camera.
  void validate(const char* where = "PinholeCamera") const {
    detail::require(fx > S(0) && fy > S(0), where,
                    "focal lengths must be positive (fx=" + std::to_string(double(fx)) +
                        ", fy=" + std::to_string(double(fy)) + ")");
    detail::require(width > 0 && height > 0, where,
                    "image size must be positive (" + std::to_string(width) + "x" +
                        std::to_string(height) + ")");
  }
};

}  // namespace emfusion
