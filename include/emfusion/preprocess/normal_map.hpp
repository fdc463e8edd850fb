// Normal maps: a surface normal per pixel of a vertex map, from the cross
// product of central differences of the neighbouring vertices. Normals are
// unit length and face the camera (n . p < 0), the convention point-to-plane
// terms and shading assume; pixels where no trustworthy normal exists hold
// invalid_vertex() (NaN), like holes in the vertex map.
#pragma once

#include <string>
#include <utility>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/error.hpp"
#include "emfusion/core/host_device.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/preprocess/vertex_map.hpp"

namespace emfusion {

/// Parameters of compute_normals, in the scalar type of the vertex map.
template <class S>
struct NormalParams {
  /// A pixel gets no normal if any of its four neighbours differs from it in
  /// depth (z) by more than this fraction of its own depth: across a depth
  /// discontinuity the difference spans two surfaces and its "normal" belongs
  /// to neither. Relative, because sensor noise and the spacing of neighbouring
  /// points on a slanted surface both grow with depth. 0.05 still keeps
  /// surfaces seen at ~85 degrees incidence with a 525 px focal length.
  /// Infinity disables the check.
  S max_relative_depth_jump = S(0.05);

  void validate(const char* where = "NormalParams") const {
    detail::require(max_relative_depth_jump > S(0), where,
                    "max_relative_depth_jump must be positive, got " + std::to_string(double(max_relative_depth_jump)));
  }
};

namespace detail {

template <class S>
struct NormalKernel {
  ImageView<const Vec3<S>> vertices;
  ImageView<Vec3<S>> normals;
  S max_relative_depth_jump;

  EMF_HD bool continuous(const Vec3<S>& neighbour, S max_jump, S center_z) const {
    return is_valid(neighbour) && std::fabs(neighbour.z() - center_z) <= max_jump;
  }

  EMF_HD void operator()(int i) const {
    const int x = i % vertices.width, y = i / vertices.width;
    normals[i] = invalid_vertex<S>();
    if (x == 0 || y == 0 || x == vertices.width - 1 || y == vertices.height - 1) return;
    const Vec3<S> p = vertices[i];
    if (!is_valid(p)) return;
    const Vec3<S> left = vertices(x - 1, y), right = vertices(x + 1, y);
    const Vec3<S> up = vertices(x, y - 1), down = vertices(x, y + 1);
    const S max_jump = max_relative_depth_jump * std::fabs(p.z());
    if (!continuous(left, max_jump, p.z()) || !continuous(right, max_jump, p.z()) || !continuous(up, max_jump, p.z()) ||
        !continuous(down, max_jump, p.z()))
      return;
    Vec3<S> n = cross(right - left, down - up);
    const S length = norm(n);
    if (!(length > S(0))) return;  // coincident neighbours: no plane
    n = n / length;
    normals[i] = dot(n, p) > S(0) ? -n : n;
  }
};

}  // namespace detail

/// Normals of the vertex map `vertices` into `normals`, which is
/// (re)allocated to the image size unless it already has it; `normals` may be
/// `vertices` itself. The normal at (x, y) is the normalised cross product
/// (v(x+1, y) - v(x-1, y)) x (v(x, y+1) - v(x, y-1)), flipped to face the
/// camera. It is invalid_vertex() on the one-pixel image border, where the
/// pixel or any of its four neighbours is invalid, and across depth
/// discontinuities (NormalParams). Throws std::invalid_argument if `vertices`
/// is empty. Work runs on the backend of `normals` (that of `vertices` when
/// allocated here).
template <class S, Backend B>
void compute_normals(const Image<Vec3<S>, B>& vertices, Image<Vec3<S>, B>& normals,
                     const NormalParams<S>& params = {}) {
  constexpr const char* where = "emfusion::compute_normals";
  detail::require(!vertices.empty(), where, "vertex map is empty");
  params.validate(where);
  if (&normals == &vertices) {  // every pixel reads its neighbours: compute into a copy
    Image<Vec3<S>, B> computed;
    compute_normals(vertices, computed, params);
    normals = std::move(computed);
    return;
  }
  if (!normals.same_size(vertices.width(), vertices.height()))
    normals = Image<Vec3<S>, B>(vertices.width(), vertices.height(), Vec3<S>{}, vertices.backend());
  for_each_index(normals.backend(), vertices.size(),
                 detail::NormalKernel<S>{vertices.view(), normals.view(), params.max_relative_depth_jump});
}

}  // namespace emfusion
