// Analytic signed distance primitives (plane, box, sphere, cylinder) and a
// small scene of them: ground truth for tests, the demo and benchmarks.
//
// Each shape has a pose T_world_shape; distances are Euclidean (exact for
// each primitive, the minimum over shapes for a scene), negative inside.
#pragma once

#include <cmath>
#include <string>

#include "emfusion/core/error.hpp"
#include "emfusion/core/host_device.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/core/se3.hpp"

namespace emfusion::sim {

enum class ShapeType : int {
  plane,     ///< the shape's x-y plane, +z is outside
  box,       ///< half extents size
  sphere,    ///< radius size.x
  cylinder,  ///< axis z, radius size.x, half height size.y, capped
};

template <class S>
struct Shape {
  ShapeType type = ShapeType::sphere;
  SE3<S> T_shape_world{};  ///< inverse pose, so that distance() needs one transform
  Vec3<S> size = Vec3<S>::zero();

  EMF_HD S distance(const Vec3<S>& p_world) const {
    const Vec3<S> p = T_shape_world * p_world;
    switch (type) {
      case ShapeType::plane:
        return p.z();
      case ShapeType::sphere:
        return norm(p) - size.x();
      case ShapeType::box: {
        Vec3<S> q, outside;
        for (int a = 0; a < 3; ++a) {
          q[a] = std::fabs(p[a]) - size[a];
          outside[a] = q[a] > S(0) ? q[a] : S(0);
        }
        S inside = q.x() > q.y() ? q.x() : q.y();
        inside = inside > q.z() ? inside : q.z();
        return norm(outside) + (inside < S(0) ? inside : S(0));
      }
      case ShapeType::cylinder: {
        const S dr = std::sqrt(p.x() * p.x() + p.y() * p.y()) - size.x();
        const S dz = std::fabs(p.z()) - size.y();
        const S inside = dr > dz ? dr : dz;
        const S ox = dr > S(0) ? dr : S(0), oz = dz > S(0) ? dz : S(0);
        return std::sqrt(ox * ox + oz * oz) + (inside < S(0) ? inside : S(0));
      }
    }
    return S(0);
  }
};

template <class S>
Shape<S> make_plane(const SE3<S>& T_world_shape) {
  return Shape<S>{ShapeType::plane, T_world_shape.inverse(), Vec3<S>::zero()};
}
template <class S>
Shape<S> make_sphere(const Vec3<S>& center, S radius) {
  emfusion::detail::require(radius > S(0), "make_sphere", "radius must be positive");
  return Shape<S>{ShapeType::sphere, SE3<S>::translation(-center), vec3(radius, S(0), S(0))};
}
template <class S>
Shape<S> make_box(const SE3<S>& T_world_shape, const Vec3<S>& half_extents) {
  emfusion::detail::require(half_extents.x() > S(0) && half_extents.y() > S(0) && half_extents.z() > S(0), "make_box",
                  "half extents must be positive");
  return Shape<S>{ShapeType::box, T_world_shape.inverse(), half_extents};
}
template <class S>
Shape<S> make_cylinder(const SE3<S>& T_world_shape, S radius, S half_height) {
  emfusion::detail::require(radius > S(0) && half_height > S(0), "make_cylinder", "radius and half height must be positive");
  return Shape<S>{ShapeType::cylinder, T_world_shape.inverse(), vec3(radius, half_height, S(0))};
}

/// A fixed-capacity union of shapes, copied by value into kernels.
template <class S>
struct Scene {
  static constexpr int capacity = 48;
  Shape<S> shapes[capacity];
  int count = 0;

  /// Adds a shape and returns its index (its label in rendered label images).
  int add(const Shape<S>& shape) {
    emfusion::detail::require(count < capacity, "Scene::add",
                    "a scene holds at most " + std::to_string(capacity) + " shapes");
    shapes[count] = shape;
    return count++;
  }

  /// Signed distance to the nearest shape; `nearest`, if given, gets its index.
  EMF_HD S distance(const Vec3<S>& p, int* nearest = nullptr) const {
    S best = S(1e30);
    int which = -1;
    for (int i = 0; i < count; ++i) {
      const S d = shapes[i].distance(p);
      if (d < best) best = d, which = i;
    }
    if (nearest) *nearest = which;
    return best;
  }
};

/// Camera pose at `eye` looking at `target` (camera z forward, x right, y
/// down), with `up` roughly the world's up direction in the image.
template <class S>
SE3<S> look_at(const Vec3<S>& eye, const Vec3<S>& target, const Vec3<S>& up) {
  const Vec3<S> z = normalized(target - eye);
  Vec3<S> x = cross(z, up);
  emfusion::detail::require(norm(x) > S(1e-9) * norm(up), "look_at", "the up vector is parallel to the viewing direction");
  x = normalized(x);
  const Vec3<S> y = cross(z, x);
  Mat3<S> R;
  for (int i = 0; i < 3; ++i) R(i, 0) = x[i], R(i, 1) = y[i], R(i, 2) = z[i];
  return SE3<S>(R, eye);
}

}  // namespace emfusion::sim
