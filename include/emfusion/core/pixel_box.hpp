// Rectangles of pixels, and the work a per-pixel pass can leave out with
// them: an object's volume covers a small part of the frame, so the passes
// that concern only that volume (its raycast, the images its integration
// reads) need only the pixels its box projects to (projected_box), walked
// by for_each_pixel_in. A pass over every pixel whose neighbours do similar
// work (a ray cast) runs on a GPU in square tiles (for_each_pixel_tiled).
#pragma once

#include <algorithm>
#include <cmath>
#include <optional>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/camera.hpp"
#include "emfusion/core/host_device.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/core/se3.hpp"

namespace emfusion {

/// A rectangle of pixels, [x0, x1) x [y0, y1); empty when x1 <= x0 or y1 <= y0.
struct PixelBox {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  EMF_HD bool empty() const { return x1 <= x0 || y1 <= y0; }
  EMF_HD int width() const { return empty() ? 0 : x1 - x0; }
  EMF_HD int height() const { return empty() ? 0 : y1 - y0; }
  EMF_HD int area() const { return width() * height(); }
  EMF_HD bool contains(int u, int v) const { return u >= x0 && u < x1 && v >= y0 && v < y1; }

  /// Every pixel of a width x height image.
  static PixelBox whole(int width, int height) { return PixelBox{0, 0, width, height}; }
  /// This box grown by `dx` columns and `dy` rows each way, within a
  /// width x height image.
  PixelBox grown(int dx, int dy, int width, int height) const {
    if (empty()) return *this;
    return PixelBox{std::max(0, x0 - dx), std::max(0, y0 - dy), std::min(width, x1 + dx), std::min(height, y1 + dy)};
  }
};

/// A rectangle in pixel coordinates, neither rounded nor clipped to an image.
struct PixelRect {
  double u_min = 1e300, u_max = -1e300, v_min = 1e300, v_max = -1e300;
};

/// The rectangle around the projections of the eight corners of the box
/// [lo, hi] (in its own frame) seen at T_camera_box; nothing when a corner
/// is closer to the camera's plane than `min_z` (or behind it) or does not
/// project to a finite point: then the box may cover any part of the view.
template <class S>
std::optional<PixelRect> projected_rect(const PinholeCamera<S>& camera, const SE3<S>& T_camera_box, const Vec3<S>& lo,
                                        const Vec3<S>& hi, S min_z = S(1e-3)) {
  PixelRect r;
  for (int k = 0; k < 8; ++k) {
    const Vec3<S> corner = vec3(k & 1 ? hi.x() : lo.x(), k & 2 ? hi.y() : lo.y(), k & 4 ? hi.z() : lo.z());
    const Vec3<S> p = T_camera_box * corner;
    if (!(p.z() >= min_z) || !std::isfinite(double(p.x())) || !std::isfinite(double(p.y()))) return std::nullopt;
    const double u = double(camera.fx) * double(p.x()) / double(p.z()) + double(camera.cx);
    const double v = double(camera.fy) * double(p.y()) / double(p.z()) + double(camera.cy);
    r.u_min = std::min(r.u_min, u), r.u_max = std::max(r.u_max, u);
    r.v_min = std::min(r.v_min, v), r.v_max = std::max(r.v_max, v);
  }
  return r;
}

/// The pixels of `camera` whose rays can meet the box [lo, hi] (a volume's
/// extent in its own frame) seen at T_camera_box: the rectangle around the
/// projections of its eight corners (projected_rect), one pixel wider each
/// way (rounding), within the image. A box with a corner closer to the
/// camera's plane than `min_z` (or behind it) may cover any pixel: the
/// whole image. Exact for what it promises: a ray outside the rectangle
/// misses the box, and a point of the box projects (rounded to the nearest
/// pixel) inside it.
template <class S>
PixelBox projected_box(const PinholeCamera<S>& camera, const SE3<S>& T_camera_box, const Vec3<S>& lo, const Vec3<S>& hi,
                       S min_z = S(1e-3)) {
  const std::optional<PixelRect> r = projected_rect(camera, T_camera_box, lo, hi, min_z);
  if (!r) return PixelBox::whole(camera.width, camera.height);
  // Outside the image on one side: nothing to do (an empty box).
  if (r->u_max < -1.0 || r->v_max < -1.0 || r->u_min > camera.width || r->v_min > camera.height) return PixelBox{};
  const auto lower = [](double x, int size) { return int(std::clamp(std::floor(x) - 1.0, 0.0, double(size))); };
  const auto upper = [](double x, int size) { return int(std::clamp(std::ceil(x) + 2.0, 0.0, double(size))); };
  return PixelBox{lower(r->u_min, camera.width), lower(r->v_min, camera.height), upper(r->u_max, camera.width),
                  upper(r->v_max, camera.height)};
}

namespace detail {
/// f(i) for the image index i of the k-th pixel of `box` (row by row;
/// image `width` wide), and what f returns (a reduction's term).
template <class F>
struct PixelsInBox {
  F f;
  PixelBox box;
  int width;
  EMF_HD decltype(auto) operator()(int k) const {
    const int bw = box.x1 - box.x0;
    return f((box.y0 + k / bw) * width + box.x0 + k % bw);
  }
};
}  // namespace detail

/// Tiles of pixels for a kernel whose neighbouring pixels do similar work
/// (for_each_pixel_tiled): a thread block takes 16 x 16 pixels and each of
/// its warps 8 x 4 of them, so that the 32 threads a GPU runs in lockstep
/// hold a compact patch instead of 32 pixels of one row.
struct PixelTiles {
  static constexpr int side = 16;                 ///< pixels a tile has along each axis
  static constexpr int threads = side * side;     ///< threads a tile's block has
  static constexpr int warp_w = 8, warp_h = 4;    ///< a warp's patch
  /// The pixel of thread `thread` (0 .. threads - 1) of tile (tile_x,
  /// tile_y): warps 0 and 1 hold the tile's first four rows, left and right.
  EMF_HD static void pixel_of(int tile_x, int tile_y, int thread, int& u, int& v) {
    const int warp = thread >> 5, lane = thread & 31;
    u = tile_x * side + (lane % warp_w) + warp_w * (warp & 1);
    v = tile_y * side + (lane / warp_w) + warp_h * (warp >> 1);
  }
  static int tiles(int pixels) { return (pixels + side - 1) / side; }
};

#if EMFUSION_HAS_CUDA
namespace detail {
/// for_each_pixel_tiled on a device: a thread block a tile.
template <int MinBlocks, class F>
__global__ void __launch_bounds__(PixelTiles::threads, MinBlocks) pixel_tiles_kernel(F f, int width, int height) {
  int u, v;
  PixelTiles::pixel_of(int(blockIdx.x), int(blockIdx.y), int(threadIdx.x), u, v);
  if (u < width && v < height) f(v * width + u);
}
}  // namespace detail
#endif

/// Calls f(i) on the backend for the image index i (row-major) of every
/// pixel of a width x height image. On a CUDA device in tiles
/// (PixelTiles), with `MinBlocks` the kernel's launch bound (tiles an SM
/// should hold at once: more means fewer registers a thread). A ray cast
/// launched so ran 0.28 ms instead of 0.49 (sparse volume) and 0.29
/// instead of 0.41 (dense, MinBlocks 3) on the H100: neighbouring rays
/// march to similar depths, so a warp's threads finish together
/// (docs/benchmarks.md). On the CPU, for_each_index over the pixels.
template <int MinBlocks = 1, Backend B, class F>
void for_each_pixel_tiled(const B& backend, int width, int height, F f) {
  if (width <= 0 || height <= 0) return;
  if constexpr (B::is_device) {
#if EMFUSION_HAS_CUDA
    const dim3 tiles(unsigned(PixelTiles::tiles(width)), unsigned(PixelTiles::tiles(height)));
    detail::pixel_tiles_kernel<MinBlocks><<<tiles, PixelTiles::threads, 0, backend.stream>>>(f, width, height);
    detail::check_cuda(cudaGetLastError(), "for_each_pixel_tiled: kernel launch");
#endif
  } else {
    for_each_index(backend, width * height, f);
  }
}

/// Calls f(i) on the backend for the image index i (row-major, `width`
/// pixels a row) of every pixel in `box`; nothing for an empty box.
template <Backend B, class F>
void for_each_pixel_in(const B& backend, const PixelBox& box, int width, F f) {
  if (box.empty()) return;
  for_each_index(backend, box.area(), detail::PixelsInBox<F>{f, box, width});
}

}  // namespace emfusion
