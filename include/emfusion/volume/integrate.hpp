// Weighted TSDF integration of a depth image (paper eq. 10):
//
//   sdf(v) <- (W(v) sdf(v) + q(u) d(v)) / (W(v) + q(u)),
//   W(v)   <- min(W_max, W(v) + q(u)),
//
// where u is the pixel voxel v projects to, d(v) the measured signed distance
// along the ray, truncated to [-truncation, truncation], and q(u) a per-pixel
// weight (the association likelihood in EM-Fusion; 1 without a weight image).
// Voxels in free space (d >= truncation) are updated with weight 1 whatever
// q(u) is, so that a surface that moved away is carved out of every model.
// With `unowned_free_from` > 0, a voxel in front of the pixel's point by at
// least that fraction of the truncation is free space for the share 1 - q(u)
// of the pixel the model does not own, and forgets that share of what it
// held: a trace of an object in the background (fused while the object
// stood still) goes as soon as the rays end on the object behind it.
// IntegrationWeights::others_drawn confines that to the pixels where
// another model is drawn (the system passes its rendered object depth).
//
// Refinements of the plain projective update, all off by default and on in
// IntegrationParams::refined() (docs/decisions.md has the measurements):
// - point-to-plane distance (Bylow et al. 2013, the paper's [4]): d is the
//   ray distance times the cosine of the incidence angle, i.e. the distance
//   to the observed surface's tangent plane, also when deciding free space;
// - silhouette guard: a voxel counts as free space only if it lies a
//   truncation distance in front of every depth within a lateral distance of
//   `silhouette_guard` voxels around its pixel, so that rays passing just
//   beside an object's silhouette do not carve the voxels along the object's
//   border (they erode otherwise);
// - behind-surface falloff: weight 1 + d / truncation for d < 0, so voxels
//   hidden just behind a silhouette are not pulled inside by rays that only
//   graze the surface in front of them;
// - incidence: the cosine between the pixel's ray and the surface normal
//   estimated from neighbouring depth pixels, so grazing measurements (whose
//   projective distance overestimates the true one) count less.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include "emfusion/core/camera.hpp"
#include "emfusion/core/error.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/core/pixel_box.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/volume/tsdf_volume.hpp"

namespace emfusion {

/// Defaults are the paper's update (eq. 10) with the reference parameters;
/// `refined()` switches on the refinements described above.
template <class S>
struct IntegrationParams {
  S max_weight = S(64);          ///< W_max
  S free_space_weight = S(1);    ///< update weight of voxels with d >= truncation
  bool behind_surface_falloff = false;
  bool weight_by_incidence = false;
  S min_incidence_weight = S(0.05);  ///< floor of the incidence weight
  bool point_to_plane = false;       ///< distance to the tangent plane instead of along the ray
  S silhouette_guard = S(0);         ///< voxels (lateral); 0 turns the guard off
  /// Depth of the band updated behind a surface, as a fraction of the
  /// truncation (1 = the symmetric band of the paper).
  S behind_band = S(1);
  /// Voxels this fraction of the truncation or more in front of a pixel's
  /// point are free space for the share 1 - q(u) of the pixel that the model
  /// does not own: what they held keeps the weight W(v) q(u) (the paper's
  /// "reweigh the accumulated weight W(v) with w_u", in front of the points
  /// only) and, within the truncation, +truncation takes the weight
  /// (1 - q(u)) free_space_weight beside q(u)'s update, at the pixels
  /// where IntegrationWeights::others_drawn is positive (every pixel without
  /// it). 0 = off (the paper). Needs a weight image.
  S unowned_free_from = S(0);

  /// The refinements for accurate geometry from clean depth (synthetic data,
  /// multi-view scans): within one voxel of the true surface where the
  /// paper's update is off by up to four (docs/decisions.md). On noisy
  /// Kinect depth they cost camera-tracking accuracy, hence not the default.
  static IntegrationParams refined() {
    IntegrationParams p;
    p.behind_surface_falloff = p.weight_by_incidence = p.point_to_plane = true;
    p.silhouette_guard = S(1.5);
    p.behind_band = S(0.3);
    return p;
  }
};

namespace detail {

/// Narrows [z_begin, z_end) to the voxels of the column p(z) = start + z step
/// (camera frame) that can project into the image with positive depth. Each
/// side of the frustum is a plane through the camera, a linear constraint
/// c0 + c1 z >= 0 along the column, and so is the far plane z <= far (the
/// deepest measurement plus the truncation: voxels beyond are never
/// updated). The planes lie a pixel outside the image and the range is
/// widened by a voxel, so the per-voxel tests still decide. False when no
/// voxel remains.
template <class S>
EMF_HD bool clip_column_to_frustum(const PinholeCamera<S>& camera, const Vec3<S>& start, const Vec3<S>& step, S far,
                                   int& z_begin, int& z_end) {
  const S u_lo = -S(1.5), u_hi = S(camera.width) + S(0.5), v_lo = -S(1.5), v_hi = S(camera.height) + S(0.5);
  // Planes a . p >= 0: z > 0, u >= u_lo, u <= u_hi, v >= v_lo, v <= v_hi.
  const Vec3<S> planes[5] = {vec3(S(0), S(0), S(1)), vec3(camera.fx, S(0), camera.cx - u_lo),
                             vec3(-camera.fx, S(0), u_hi - camera.cx), vec3(S(0), camera.fy, camera.cy - v_lo),
                             vec3(S(0), -camera.fy, v_hi - camera.cy)};
  S lo = S(z_begin), hi = S(z_end);
  for (int k = 0; k < 6; ++k) {
    const Vec3<S> a = k < 5 ? planes[k] : vec3(S(0), S(0), -S(1));
    const S c0 = dot(a, start) + (k < 5 ? S(0) : far), c1 = dot(a, step);
    if (c1 > S(0)) {
      const S z = -c0 / c1 - S(1);
      lo = z > lo ? z : lo;
    } else if (c1 < S(0)) {
      const S z = -c0 / c1 + S(2);
      hi = z < hi ? z : hi;
    } else if (c0 < S(0)) {
      return false;
    }
    if (!(lo < hi)) return false;
  }
  z_begin = int(std::ceil(lo));
  z_end = int(std::ceil(hi));
  return z_begin < z_end;
}

/// The per-voxel update of eq. 10 with the refinements of IntegrationParams:
/// what one measurement does to one voxel at camera-frame point p. Shared by
/// the dense and the sparse volume (sparse_tsdf_volume.hpp), so that the two
/// cannot drift apart.
template <class S>
struct VoxelUpdate {
  ImageView<const S> depth;
  ImageView<const S> weights;     // empty: weight 1
  ImageView<const S> incidence;   // empty: cosine 1 (refinements off)
  ImageView<const S> near_depth;  // empty: no silhouette guard
  ImageView<const S> others_drawn;  // empty: unowned_free_from at every pixel
  PinholeCamera<S> camera;
  IntegrationParams<S> params;
  S truncation;

  template <class Store>
  EMF_HD void operator()(const Vec3<S>& p, Store& voxel_sdf, Store& voxel_weight) const {
    if (!(p.z() > S(0))) return;
    const Vec2<S> uv = camera.project(p);
    const int u = int(std::floor(uv.x() + S(0.5))), v = int(std::floor(uv.y() + S(0.5)));
    if (!depth.contains(u, v)) return;
    const S d = depth(u, v);
    if (!is_valid_depth(d)) return;
    const S trunc = truncation;
    // Distance along the ray through the pixel, not along the optical axis.
    const S ray_scale = std::sqrt(S(1) + (p.x() * p.x() + p.y() * p.y()) / (p.z() * p.z()));
    S sdf = (d - p.z()) * ray_scale;
    const S behind = params.behind_band * trunc;
    if (sdf < -trunc) return;
    const S c = incidence.empty() ? S(1) : incidence(u, v);
    if (params.point_to_plane) sdf *= c;
    if (sdf < -behind) return;
    const S q = weights.empty() ? S(1) : weights(u, v);
    // Weights of the measured distance, of +truncation and of what the voxel held.
    S w = q, w_free = S(0), keep = S(1);
    // Beside a silhouette a voxel may belong to the nearer surface.
    const auto free_beside = [&](S from) {
      return near_depth.empty() || (near_depth(u, v) - p.z()) * ray_scale >= from;
    };
    if (sdf >= trunc) {
      if (!free_beside(trunc)) return;
      w = params.free_space_weight;
    } else {
      if (params.behind_surface_falloff && sdf < S(0)) w *= S(1) + sdf / behind;
      if (params.weight_by_incidence) w *= c;
    }
    const S from = params.unowned_free_from * trunc;
    if (from > S(0) && sdf >= from && q < S(1) && free_beside(from) &&
        (others_drawn.empty() || others_drawn(u, v) > S(0))) {
      keep = q;
      if (sdf < trunc) w_free = params.free_space_weight * (S(1) - q);
    }
    if (!(w + w_free > S(0))) return;
    const S tsdf = sdf < trunc ? sdf : trunc;
    const S w_old = keep * S(voxel_weight);
    const S w_sum = w_old + w + w_free;
    voxel_sdf = Store((w_old * S(voxel_sdf) + w * tsdf + w_free * trunc) / w_sum);
    voxel_weight = Store(w_sum < params.max_weight ? w_sum : params.max_weight);
  }
};

/// Integrates a run of `z_run` voxels of one column (x, y, z in [r z_run,
/// (r + 1) z_run)), index i = column + r * columns: consecutive z share the
/// ray arithmetic, and neighbouring threads touch neighbouring voxels. On
/// the CPU a run is the whole column; on a device a column is cut into
/// runs, since an object's volume has too few columns (64^2 to 128^2) to
/// fill the GPU with a thread each.
template <class S, class Store>
struct IntegrateColumn {
  TsdfView<S, Store> volume;
  VoxelUpdate<S> update;
  SE3<S> T_camera_volume;
  S far;  ///< no voxel deeper than this (camera z) is updated
  int z_run;

  EMF_HD void operator()(int i) const {
    const int columns = volume.nx * volume.ny;
    const int column = i % columns, run = i / columns;
    const int x = column % volume.nx, y = column / volume.nx;
    const Vec3<S> start = T_camera_volume * volume.voxel_center(x, y, 0);
    const Vec3<S> step = T_camera_volume.rotate(vec3(S(0), S(0), volume.voxel_size));
    int z_begin = run * z_run, z_end = z_begin + z_run < volume.nz ? z_begin + z_run : volume.nz;
    if (!clip_column_to_frustum(update.camera, start, step, far, z_begin, z_end)) return;
    for (int z = z_begin; z < z_end; ++z) {
      const std::int64_t v = volume.index(x, y, z);
      update(start + S(z) * step, volume.sdf[v], volume.weight[v]);
    }
  }

  /// Voxels a thread walks along z on backend B.
  template <class B>
  static int run_length(int nz) {
    return B::is_device ? (nz < 8 ? nz : 8) : nz;
  }
};

/// Per pixel, once per frame: |cos| of the angle between the pixel's ray and
/// the surface normal from the depth neighbours (central differences,
/// one-sided where a neighbour is missing), floored at min_incidence_weight;
/// 0 where the depth is invalid.
template <class S>
struct IncidencePixel {
  ImageView<const S> depth;
  PinholeCamera<S> camera;
  S floor;
  ImageView<S> out;

  EMF_HD void operator()(int i) const {
    const int u = i % depth.width, v = i / depth.width;
    const S d = valid_depth(u, v);
    out[i] = d > S(0) ? incidence_weight(u, v, d) : S(0);
  }
  EMF_HD S incidence_weight(int u, int v, S d) const {
    const Vec3<S> p = camera.back_project(S(u), S(v), d);
    const Vec3<S> du = neighbour_difference(u, v, 1, 0, d);
    const Vec3<S> dv = neighbour_difference(u, v, 0, 1, d);
    const Vec3<S> n = cross(du, dv);
    const S nn = norm(n);
    if (!(nn > S(0))) return floor;
    const S c = std::fabs(dot(n, p)) / (nn * norm(p));
    return c > floor ? c : floor;
  }
  EMF_HD Vec3<S> neighbour_difference(int u, int v, int su, int sv, S d) const {
    const S dp = valid_depth(u + su, v + sv), dm = valid_depth(u - su, v - sv);
    const Vec3<S> p = camera.back_project(S(u), S(v), d);
    if (dp > S(0) && dm > S(0))
      return camera.back_project(S(u + su), S(v + sv), dp) - camera.back_project(S(u - su), S(v - sv), dm);
    if (dp > S(0)) return camera.back_project(S(u + su), S(v + sv), dp) - p;
    if (dm > S(0)) return p - camera.back_project(S(u - su), S(v - sv), dm);
    return Vec3<S>::zero();  // isolated pixel: no normal, lowest weight
  }
  EMF_HD S valid_depth(int u, int v) const {
    if (!depth.contains(u, v)) return S(0);
    const S d = depth(u, v);
    return is_valid_depth(d) ? d : S(0);
  }
};


/// One pass of the silhouette guard's minimum filter: the smallest valid
/// depth within a radius along rows (dx = 1) or columns (dy = 1). The radius
/// of a pixel is `lateral` metres at its own depth, in pixels, at most
/// max_radius: two passes give (nearly) a square window.
template <class S>
struct NearestDepthPass {
  ImageView<const S> depth;  // the frame's depth: sets each pixel's radius
  ImageView<const S> in;     // depth or the row pass's output
  ImageView<S> out;
  S lateral_pixels_at_1m;  // lateral * f
  int dx, dy;
  static constexpr int max_radius = 16;

  /// The window's radius in pixels at a pixel of depth d (0 without a
  /// measurement).
  EMF_HD int radius_at(S d) const {
    if (!is_valid_depth(d)) return 0;
    const S r = std::ceil(lateral_pixels_at_1m / d);
    return r < S(max_radius) ? int(r) : max_radius;
  }

  EMF_HD void operator()(int i) const {
    const int u = i % depth.width, v = i / depth.width;
    const S d = depth[i];
    // +inf stands for "none yet"; the comparisons skip holes, NaN and inf.
    const S none = std::numeric_limits<S>::infinity();
    const S own = in[i];
    S nearest = own > S(0) && own < none ? own : none;
    if (is_valid_depth(d)) {
      const int radius = radius_at(d);
      // The window clipped to the image once, so the loop has no branches.
      const int at = dx ? u : v, size = dx ? in.width : in.height;
      const int k0 = at - radius < 0 ? -at : -radius;
      const int k1 = at + radius >= size ? size - 1 - at : radius;
      const S* p = &in(u, v);
      const int stride = dx ? 1 : in.width;
      for (int k = k0; k <= k1; ++k) {
        const S n = p[k * stride];
        nearest = n > S(0) && n < nearest ? n : nearest;
      }
    }
    out[i] = nearest < none ? nearest : S(0);
  }
};

/// NearestDepthPass on the CPU, a row of the output a call (the pixels of
/// columns [x0, x1)), in chunks of columns: the window's offsets outside,
/// the chunk's pixels inside, so that the inner loop has no branch and
/// vectorises (a pixel at a time, the two passes took 17 ms of a frame on 2
/// cores). The same minimum of the same depths as NearestDepthPass: holes,
/// NaN and inf count as +inf, out of the image as well.
template <class S>
struct NearestDepthRows {
  NearestDepthPass<S> pass;
  int x0, x1;
  static constexpr int chunk = 128, r_max = NearestDepthPass<S>::max_radius;

  EMF_HD static S candidate(S n) {
    const S none = std::numeric_limits<S>::infinity();
    return n > S(0) && n < none ? n : none;
  }

  EMF_AVX2_CLONE void operator()(int v) const {
    const ImageView<const S>& in = pass.in;
    const int width = in.width, height = in.height;
    const S none = std::numeric_limits<S>::infinity();
    for (int c0 = x0; c0 < x1; c0 += chunk) {
      const int n = x1 - c0 < chunk ? x1 - c0 : chunk;
      S radius[chunk], nearest[chunk];
      S row[chunk + 2 * r_max];  // along rows: the chunk's input and r_max either side
      int k_max = 0;
      for (int i = 0; i < n; ++i) {
        const int r = pass.radius_at(pass.depth(c0 + i, v));
        radius[i] = S(r);
        k_max = r > k_max ? r : k_max;
        nearest[i] = candidate(in(c0 + i, v));
      }
      if (pass.dx) {
        for (int i = -r_max; i < n + r_max; ++i) {
          const int u = c0 + i;
          row[i + r_max] = u >= 0 && u < width ? candidate(in(u, v)) : none;
        }
        for (int k = 1; k <= k_max; ++k) {
          const S* left = row + r_max - k;
          const S* right = row + r_max + k;
          for (int i = 0; i < n; ++i) {
            const S a = left[i] < right[i] ? left[i] : right[i];
            const S m = a < nearest[i] ? a : nearest[i];
            nearest[i] = S(k) <= radius[i] ? m : nearest[i];
          }
        }
      } else {
        for (int k = 1; k <= k_max; ++k) {
          const S* above = v - k >= 0 ? &in(c0, v - k) : nullptr;
          const S* below = v + k < height ? &in(c0, v + k) : nullptr;
          for (int i = 0; i < n; ++i) {
            const S a = above ? candidate(above[i]) : none, b = below ? candidate(below[i]) : none;
            const S ab = a < b ? a : b;
            const S m = ab < nearest[i] ? ab : nearest[i];
            nearest[i] = S(k) <= radius[i] ? m : nearest[i];
          }
        }
      }
      for (int i = 0; i < n; ++i) pass.out(c0 + i, v) = nearest[i] < none ? nearest[i] : S(0);
    }
  }
};

/// Runs NearestDepthPass `pass` over the pixels of `box`: a thread a pixel
/// on a device, NearestDepthRows on the CPU.
template <class S, Backend B>
void nearest_depth_pass(const B& backend, const PixelBox& box, const NearestDepthPass<S>& pass) {
  if (box.empty()) return;
  if constexpr (B::is_device)
    for_each_pixel_in(backend, box, pass.depth.width, pass);
  else
    for_each_index(backend, box.height(), [f = NearestDepthRows<S>{pass, box.x0, box.x1}, y0 = box.y0](int r) {
      f(y0 + r);
    });
}

template <class S>
struct ValidDepthOrZero {
  ImageView<const S> depth;
  EMF_HD S operator()(int i) const { return is_valid_depth(depth[i]) ? depth[i] : S(0); }
};
template <class S>
struct Larger {
  EMF_HD S operator()(S a, S b) const { return a > b ? a : b; }
};
}  // namespace detail

/// The largest valid depth of an image (0 when it has none).
template <class S, Backend B>
S max_valid_depth(const Image<S, B>& depth) {
  return transform_reduce_index(depth.backend(), depth.size(), detail::ValidDepthOrZero<S>{depth.view()}, S(0),
                                detail::Larger<S>{});
}

/// The per-pixel images that weigh an integration, each null or of the
/// depth image's size on the volume's backend: `owned`, q(u) of eq. 10
/// (null: 1 at every pixel), and `others_drawn`, positive where another
/// model is drawn (a rendered depth, 0 elsewhere), the only pixels where
/// IntegrationParams::unowned_free_from forgets (null: every pixel). The
/// system passes its background the E-step's image and the nearest object
/// surface render_models drew (Frame::object_depth): a background pixel
/// next to an object that the E-step shares with it is the background's
/// own surface, not a trace, and forgetting there cost the camera 0.01-0.03
/// cm on every composite of bench/generalisation.py (docs/decisions.md).
template <class S, Backend B>
struct IntegrationWeights {
  const Image<S, B>* owned = nullptr;
  const Image<S, B>* others_drawn = nullptr;
};

/// Per-pixel images integrate() derives from the depth (incidence, the
/// silhouette guard's nearest depths); pass one to reuse their memory across
/// calls instead of allocating them every time.
template <class S, Backend B>
struct IntegrationWorkspace {
  Image<S, B> incidence, rows, near_depth;
};

namespace detail {
/// Checks integrate()'s arguments, computes the per-pixel images the chosen
/// refinements need (into `ws`) within `box`, the pixels the volume's
/// voxels can project to (projected_box; elsewhere the images are not read
/// and keep what they held), and returns the per-voxel update over them:
/// the part of integration that does not depend on the volume's layout.
template <class S, Backend B>
VoxelUpdate<S> prepare_voxel_update(const Image<S, B>& depth, const PinholeCamera<S>& camera,
                                    const IntegrationWeights<S, B>& pixel_weights, const IntegrationParams<S>& params,
                                    S voxel_size, S truncation, const B& backend, IntegrationWorkspace<S, B>& ws,
                                    const char* where, const PixelBox& box) {
  camera.validate(where);
  detail::require_image(depth.view(), camera.width, camera.height, where, "depth image");
  const Image<S, B>* weights = pixel_weights.owned;
  const Image<S, B>* others_drawn = pixel_weights.others_drawn;
  if (weights) detail::require_image(weights->view(), depth.width(), depth.height(), where, "weight image");
  if (others_drawn)
    detail::require_image(others_drawn->view(), depth.width(), depth.height(), where, "others_drawn image");
  detail::require(params.silhouette_guard >= S(0), where,
                  "silhouette_guard must not be negative, got " + std::to_string(double(params.silhouette_guard)));
  detail::require(params.max_weight > S(0), where,
                  "max_weight must be positive, got " + std::to_string(double(params.max_weight)));
  detail::require(params.unowned_free_from >= S(0) && params.unowned_free_from <= S(1), where,
                  "unowned_free_from must be in [0, 1], got " + std::to_string(double(params.unowned_free_from)));
  const auto sized = [&](Image<S, B>& image) -> Image<S, B>& {
    if (!image.same_size(depth.width(), depth.height()))
      image = Image<S, B>(depth.width(), depth.height(), S(0), backend);
    return image;
  };
  ImageView<const S> incidence, near_depth;
  if (params.point_to_plane || params.weight_by_incidence) {
    Image<S, B>& image = sized(ws.incidence);
    for_each_pixel_in(backend, box, depth.width(),
                      detail::IncidencePixel<S>{depth.view(), camera, params.min_incidence_weight, image.view()});
    incidence = std::as_const(image).view();
  }
  if (params.silhouette_guard > S(0)) {
    Image<S, B>& rows = sized(ws.rows);
    Image<S, B>& near = sized(ws.near_depth);
    const S lateral = params.silhouette_guard * voxel_size * std::max(camera.fx, camera.fy);
    // The column pass reads the row pass up to max_radius rows away.
    const PixelBox row_box =
        box.grown(0, detail::NearestDepthPass<S>::max_radius, depth.width(), depth.height());
    detail::nearest_depth_pass(backend, row_box,
                               detail::NearestDepthPass<S>{depth.view(), depth.view(), rows.view(), lateral, 1, 0});
    detail::nearest_depth_pass(
        backend, box, detail::NearestDepthPass<S>{depth.view(), std::as_const(rows).view(), near.view(), lateral, 0, 1});
    near_depth = std::as_const(near).view();
  }
  const auto view_of = [](const Image<S, B>* image) { return image ? image->view() : ImageView<const S>{}; };
  return VoxelUpdate<S>{.depth = depth.view(),
                        .weights = view_of(weights),
                        .incidence = incidence,
                        .near_depth = near_depth,
                        .others_drawn = view_of(others_drawn),
                        .camera = camera,
                        .params = params,
                        .truncation = truncation};
}
}  // namespace detail

/// Fuses `depth` (metres, 0 = invalid), seen by `camera` at `T_world_camera`,
/// into `volume`, weighed per pixel by `weights` (IntegrationWeights). Runs
/// on the volume's backend; the images must live there too. `workspace`
/// (optional) keeps the derived images' memory. With `run_on`, the work is
/// queued there (a lane of ConcurrentLanes, so that several objects
/// integrate at once; each then needs a workspace of its own) instead of on
/// the volume's backend.
template <class S, Backend B, class Store>
void integrate(TsdfVolume<S, B, Store>& volume, const Image<S, B>& depth, const PinholeCamera<S>& camera,
               const SE3<S>& T_world_camera, const IntegrationWeights<S, B>& weights,
               const IntegrationParams<S>& params = {}, IntegrationWorkspace<S, B>* workspace = nullptr,
               const B* run_on = nullptr) {
  IntegrationWorkspace<S, B> local;
  const B& backend = run_on ? *run_on : volume.backend();
  const SE3<S> T_camera_volume = T_world_camera.inverse() * volume.pose();
  const detail::VoxelUpdate<S> update = detail::prepare_voxel_update(
      depth, camera, weights, params, volume.voxel_size(), volume.truncation(), backend,
      workspace ? *workspace : local, "integrate",
      projected_box(camera, T_camera_volume, Vec3<S>::zero(), volume.view().extent()));
  const int nz = volume.dims()[2];
  const int z_run = detail::IntegrateColumn<S, Store>::template run_length<B>(nz);
  detail::IntegrateColumn<S, Store> f{volume.view(), update, T_camera_volume, std::numeric_limits<S>::infinity(),
                                      z_run};
  // The far plane pays on the CPU, where voxels are visited one by one; on a
  // device the reduction's round trip costs more than the voxels it skips.
  if constexpr (!B::is_device) {
    f.far = max_valid_depth(depth) + volume.truncation();
    if (!(f.far > volume.truncation())) return;  // no measurement at all
  }
  // A thread a run: fewer than 2^31 of them for volumes below 2^34 voxels
  // (64 GiB even in half storage).
  const int runs = (nz + z_run - 1) / z_run;
  for_each_index(backend, volume.dims()[0] * volume.dims()[1] * runs, f);
}

/// The same with q(u) alone: `weights` (optional) of the depth image's size.
template <class S, Backend B, class Store>
void integrate(TsdfVolume<S, B, Store>& volume, const Image<S, B>& depth, const PinholeCamera<S>& camera,
               const SE3<S>& T_world_camera, const Image<S, B>* weights = nullptr,
               const IntegrationParams<S>& params = {}, IntegrationWorkspace<S, B>* workspace = nullptr,
               const B* run_on = nullptr) {
  integrate(volume, depth, camera, T_world_camera, IntegrationWeights<S, B>{weights, nullptr}, params, workspace,
            run_on);
}

}  // namespace emfusion
