// Raycasting a TSDF volume into a camera: per pixel, the first zero crossing
// (outside to inside) of the SDF along the pixel's ray gives depth, a
// camera-frame vertex, a camera-frame normal and a hit flag. Written once for
// any volume whose view is a TsdfSampler (volume_view.hpp): the dense
// TsdfVolume and the SparseTsdfVolume. What differs between them is two small
// overloaded helpers: the range of a ray inside the volume (the dense box,
// or the box of the allocated blocks) and the step over unobserved space
// (a truncation, or on the sparse volume straight to the next allocated block
// when the ray is in an unallocated one).
//
// Along one ray the samples of a sparse volume come from a sampler chosen
// once per ray (with_nearby_sampler, volume/nearby_samples.hpp): one that
// reads the volume's index grid alone, or one that remembers the blocks it
// looked up in the hash table, so that a ray pays one table lookup per block
// it marches through, not per sample. A sparse ray takes all its samples at
// one place in its loop (march_one_site); a dense one refines a crossing in
// a loop of its own.
//
// March steps: the truncation distance while the SDF is truncated (as the
// reference implementation), then half the SDF value, at least half a voxel
// (the reference took one voxel, then half a voxel everywhere below 0.8
// truncation: three times the samples between the band's edge and the
// surface; docs/decisions.md, "Raycasting"). "Truncated" allows for
// rounding: a voxel that fused free space many times holds the truncation
// distance to within a few ulps, often just below it, and an exact
// comparison marched the whole free space voxel by voxel (ten times the
// steps). A crossing is refined by regula falsi inside its bracket, so the
// surface is found to a small fraction of a voxel.
//
// Object volumes pass their foreground counts: a crossing counts only where
// the foreground probability exceeds `min_foreground` (paper sec. 3.5), so
// that surfaces fused into an object's box but not belonging to it (the
// table under a cup) are not drawn; the ray then marches on. Foreground
// counts are per voxel of a dense grid: only dense volumes take them.
#pragma once

#include <algorithm>
#include <cmath>
#include <concepts>
#include <cstdint>
#include <limits>

#include "emfusion/core/camera.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/core/pixel_box.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/volume/foreground.hpp"
#include "emfusion/volume/nearby_samples.hpp"
#include "emfusion/volume/sparse_tsdf_volume.hpp"
#include "emfusion/volume/tsdf_volume.hpp"
#include "emfusion/volume/volume_view.hpp"

namespace emfusion {

template <class S>
struct RaycastParams {
  S min_depth = S(0.1);  ///< metres along the optical axis
  S max_depth = S(20);
  S min_foreground = S(0.5);  ///< with foreground counts: draw only where p_fg exceeds this
  /// Vertices and normals too. false: depth and hit only, vertices and
  /// normals left empty, and a crossing is a hit without the SDF gradient
  /// there (sampling it is a quarter of a ray's samples; a segmentation
  /// needs depth alone).
  bool surface = true;
};

/// Images a raycast writes; reuse one across frames to avoid allocations.
template <class S, Backend B = Host>
struct RaycastResult {
  Image<S, B> depth;             ///< metres, 0 where nothing was hit
  Image<Vec3<S>, B> vertices;    ///< camera frame, NaN where nothing was hit
  Image<Vec3<S>, B> normals;     ///< camera frame, unit, facing the camera; NaN where no hit
  Image<std::uint8_t, B> hit;    ///< 1 where the ray hit a surface

  /// (Re)allocates the images for a width x height camera on `backend`;
  /// without `surface`, vertices and normals are released (left empty).
  void resize(int width, int height, const B& backend, bool surface = true) {
    if (!depth.same_size(width, height)) {
      depth = Image<S, B>(width, height, S(0), backend);
      hit = Image<std::uint8_t, B>(width, height, 0, backend);
    }
    if (!surface) {
      vertices = Image<Vec3<S>, B>();
      normals = Image<Vec3<S>, B>();
    } else if (!vertices.same_size(width, height)) {
      vertices = Image<Vec3<S>, B>(width, height, Vec3<S>{}, backend);
      normals = Image<Vec3<S>, B>(width, height, Vec3<S>{}, backend);
    }
  }
};

namespace detail {

/// Entry and exit distances of a ray (origin o, unit direction d) through the
/// box [lo, hi]^3; false if it misses.
template <class S>
EMF_HD bool clip_ray_to_box(const Vec3<S>& o, const Vec3<S>& d, const Vec3<S>& lo, const Vec3<S>& hi, S& t_in,
                            S& t_out) {
  for (int a = 0; a < 3; ++a) {
    if (std::fabs(d[a]) < S(1e-12)) {
      if (o[a] < lo[a] || o[a] > hi[a]) return false;
      continue;
    }
    S t0 = (lo[a] - o[a]) / d[a], t1 = (hi[a] - o[a]) / d[a];
    if (t0 > t1) {
      const S tmp = t0;
      t0 = t1, t1 = tmp;
    }
    t_in = t0 > t_in ? t0 : t_in;
    t_out = t1 < t_out ? t1 : t_out;
  }
  return t_in <= t_out;
}

// ---- the per-volume parts of the march ---------------------------------------

/// Dense: the part of the ray inside the grid, half a voxel in from its
/// faces (samples need the eight voxel centres around them).
template <class S, class Store>
EMF_HD bool ray_range(const TsdfView<S, Store>& volume, const Vec3<S>& origin, const Vec3<S>& dir, S& t, S& t_end) {
  const S half = S(0.5) * volume.voxel_size;
  return clip_ray_to_box(origin, dir, Vec3<S>::constant(half), volume.extent() - Vec3<S>::constant(half), t, t_end);
}

/// Dense: where the march goes on from an unobserved sample at t.
template <class S, class Store>
EMF_HD S skip_unobserved(const TsdfView<S, Store>& volume, const Vec3<S>&, const Vec3<S>&, S t, S) {
  return t + volume.truncation;
}

/// Sparse: the part of the ray inside the box of the allocated blocks
/// (outside it, fewer than half of the weights around a point are in an
/// allocated block, so no sample there counts as observed).
template <class S, class Store>
EMF_HD bool ray_range(const SparseTsdfView<S, Store>& volume, const Vec3<S>& origin, const Vec3<S>& dir, S& t,
                      S& t_end) {
  Vec3<S> lo, hi;
  return volume.block_box(lo, hi) && clip_ray_to_box(origin, dir, lo, hi, t, t_end);
}

/// Sparse, through the ray's sampler (with_nearby_sampler): in an
/// unallocated block, straight to where the ray enters the next allocated
/// one (a hundredth of a voxel in, so that the first sample there is inside
/// it); in an allocated block, a truncation as on the dense volume.
template <class Sampler, class S>
requires requires(const Sampler& s, const Vec3<S>& o, S& t) { s.skip_unallocated(o, o, t, t); }
EMF_HD S skip_unobserved(const Sampler& sampler, const Vec3<S>& origin, const Vec3<S>& dir, S t, S t_end) {
  if (sampler.skip_unallocated(origin, dir, t, t_end)) return t + S(0.01) * sampler.view.voxel_size;
  return t + sampler.view.truncation;
}

/// Regula falsi on [ta, tb] with f(ta) > 0 >= f(tb): t is the estimate of
/// the crossing, to be sampled next; update(f(t)) replaces the end of its
/// sign and moves t, false once the bracket has closed (t stays). A ray
/// takes at most `samples` of them.
template <class S>
struct Crossing {
  static constexpr int samples = 4;
  S ta = S(0), fa = S(0), tb = S(0), fb = S(0), t = S(0);
  Crossing() = default;
  EMF_HD Crossing(S ta_, S fa_, S tb_, S fb_)
      : ta(ta_), fa(fa_), tb(tb_), fb(fb_), t(ta + (tb - ta) * fa / (fa - fb)) {}
  EMF_HD bool update(S f) {
    if (f > S(0)) {
      ta = t, fa = f;
    } else {
      tb = t, fb = f;
    }
    if (!(fa - fb > S(0))) return false;
    t = ta + (tb - ta) * fa / (fa - fb);
    return true;
  }
};

/// True for the view of a dense volume.
template <class View>
inline constexpr bool is_dense_view = false;
template <class S, class Store>
inline constexpr bool is_dense_view<TsdfView<S, Store>> = true;

/// Dense volumes check that their object's foreground counts have their grid.
template <class S, Backend B, class Store>
void check_foreground(const TsdfVolume<S, B, Store>& volume, const ForegroundCounts<S, B>& foreground) {
  detail::require(foreground.dims()[0] == volume.dims()[0] && foreground.dims()[1] == volume.dims()[1] &&
                      foreground.dims()[2] == volume.dims()[2],
                  "raycast", "foreground counts and volume differ in size");
}

/// The sparse volume has no foreground counts (objects are dense).
template <class S, Backend B, class Store>
void check_foreground(const SparseTsdfVolume<S, B, Store>&, const ForegroundCounts<S, B>&) {
  detail::require(false, "raycast",
                  "foreground counts are per voxel of a dense TsdfVolume; a SparseTsdfVolume takes none (pass nullptr)");
}

/// Where a raycast needs to march: whether anything can be drawn at all,
/// the box [lo, hi] (volume frame) its rays are confined to when the
/// volume has one, and whether that box is narrower than the part
/// ray_range already keeps (then each ray is clipped to it too).
template <class S>
struct MarchBox {
  bool drawable = true;
  bool bounded = false;   ///< [lo, hi] holds every surface that may be drawn
  bool narrowed = false;  ///< ... and is narrower than the grid
  Vec3<S> lo{}, hi{};
};

/// Dense: the grid, or with foreground counts and min_foreground >= 1/2
/// the voxels of their majority_box and the points whose samples reach
/// them (half a voxel beyond their centres' box each way): only there is
/// p_fg > 1/2. A ray's march then starts where it enters that box instead
/// of the grid's face, which finds the same crossings (one exactly on the
/// entry plane aside) from other sample positions. Not drawable when no
/// voxel has Fg > Bg.
template <class S, Backend B, class Store>
MarchBox<S> march_box(const TsdfVolume<S, B, Store>& volume, const ForegroundCounts<S, B>* foreground,
                      const RaycastParams<S>& params) {
  MarchBox<S> m;
  m.bounded = true;
  m.lo = Vec3<S>::zero(), m.hi = volume.view().extent();
  if (!foreground || !(params.min_foreground >= S(0.5))) return m;
  const VoxelBox& box = foreground->majority_box();
  if (box.empty()) {
    m.drawable = false;
    return m;
  }
  const S vs = volume.voxel_size();
  for (int a = 0; a < 3; ++a) {
    m.lo[a] = std::max(m.lo[a], (S(box.lo[a]) - S(0.5)) * vs);
    m.hi[a] = std::min(m.hi[a], (S(box.hi[a]) + S(0.5)) * vs);
  }
  m.narrowed = true;
  return m;
}

/// Sparse: no box (a background map surrounds its camera; it takes no
/// foreground counts).
template <class S, Backend B, class Store>
MarchBox<S> march_box(const SparseTsdfVolume<S, B, Store>&, const ForegroundCounts<S, B>*, const RaycastParams<S>&) {
  return MarchBox<S>{};
}

/// Blocks a ray's sampler of a sparse volume remembers (nearby_sampler):
/// one on a CUDA device, where it stays in registers; four on the CPU, for
/// a normal's samples either side of a block border.
#if defined(__CUDA_ARCH__)
inline constexpr int ray_cache_blocks = 1;
#else
inline constexpr int ray_cache_blocks = 4;
#endif

/// The samples of trilinear::observed_gradient at a point p taken one at a
/// time, for a march that takes all its samples at one site
/// (RaycastPixel::march_one_site): stage 1 samples p, stages 2 and 3 one
/// voxel either side of it along x, 4 and 5 along y, 6 and 7 along z; after
/// each axis's pair its component of `gradient`, by observed_gradient's
/// own trilinear::observed_difference. Written without arrays indexed at run
/// time, which a CUDA device would keep in local memory.
template <class S>
struct NormalSamples {
  static constexpr int samples = 7;
  int stage = 0;  // the next sample, 1..samples; 0: none begun
  S vs;
  bool has_centre = false, has_plus = false;
  S centre = S(0), plus = S(0);
  Vec3<S> gradient{};

  EMF_HD explicit NormalSamples(S voxel_size) : vs(voxel_size) {}

  /// Where the stage's sample is taken around p.
  EMF_HD Vec3<S> point(const Vec3<S>& p) const {
    if (stage == 1) return p;
    const int a = (stage - 2) >> 1;
    const S offset = (stage & 1) == 0 ? vs : -vs;
    return Vec3<S>{a == 0 ? p.x() + offset : p.x(), a == 1 ? p.y() + offset : p.y(),
                   a == 2 ? p.z() + offset : p.z()};
  }

  /// Takes the stage's sample (f where `observed`) and moves to the next
  /// stage; false where an axis has no two observed samples (no normal).
  EMF_HD bool take(bool observed, S f) {
    const int s = stage++;
    if (s == 1) {
      has_centre = observed, centre = observed ? f : S(0);
      return true;
    }
    if ((s & 1) == 0) {
      has_plus = observed, plus = observed ? f : S(0);
      return true;
    }
    S component;
    if (!trilinear::observed_difference(has_plus, plus, observed, f, has_centre, centre, vs, component)) return false;
    const int a = (s - 2) >> 1;
    if (a == 0) {
      gradient.x() = component;
    } else if (a == 1) {
      gradient.y() = component;
    } else {
      gradient.z() = component;
    }
    return true;
  }
};

// ---- the march, written once -------------------------------------------------

template <class S, class View>
struct RaycastPixel {
  View volume;
  PinholeCamera<S> camera;
  SE3<S> T_volume_camera;
  RaycastParams<S> params;
  ImageView<S> depth;
  ImageView<Vec3<S>> vertices;
  ImageView<Vec3<S>> normals;
  ImageView<std::uint8_t> hit;
  ForegroundView<S, const float> foreground;  // empty: every crossing counts
  ImageView<const S> ray_end;                 // empty: every pixel; else rays only where > 0, ending there
  bool narrowed = false;  // march only inside [march_lo, march_hi] (march_box)
  Vec3<S> march_lo{}, march_hi{};
  PixelBox pixels{};  // rays only here (the march box's projection); every other pixel misses

  EMF_HD void miss(int i) const {
    depth[i] = S(0);
    hit[i] = 0;
    if (!params.surface) return;
    const S nan = std::numeric_limits<S>::quiet_NaN();
    vertices[i] = Vec3<S>::constant(nan);
    normals[i] = Vec3<S>::constant(nan);
  }

  EMF_HD void operator()(int i) const {
    const int u = i % camera.width, v = i / camera.width;
    if (!pixels.contains(u, v) || (!ray_end.empty() && !(ray_end[i] > S(0)))) {
      miss(i);
      return;
    }
    const Vec3<S> ray_cam = normalized(camera.ray(S(u), S(v)));  // z = cos of the off-axis angle
    const Vec3<S> origin = T_volume_camera.translation();
    const Vec3<S> dir = T_volume_camera.rotate(ray_cam);
    const S end_depth = !ray_end.empty() && ray_end[i] < params.max_depth ? ray_end[i] : params.max_depth;
    S t = params.min_depth / ray_cam.z(), t_end = end_depth / ray_cam.z();
    if (!ray_range(volume, origin, dir, t, t_end) ||
        (narrowed && !clip_ray_to_box(origin, dir, march_lo, march_hi, t, t_end))) {
      miss(i);
      return;
    }
    if constexpr (is_dense_view<View>) {
      march_then_refine(volume, i, ray_cam, origin, dir, t, t_end);
    } else {
      with_nearby_sampler<ray_cache_blocks>(
          volume, [&](auto& sampler) { march_one_site(sampler, i, ray_cam, origin, dir, t, t_end); });
    }
  }

  /// The state of a ray's march: the last observed sample (have_prev:
  /// whether there is one since the last unobserved one) and the step sizes.
  struct March {
    bool have_prev = false;
    S t_prev, f_prev = S(0);
    S trunc, vs;
    S truncated;  // above every rounding of trunc, even in half precision

    EMF_HD March(S t, S truncation, S voxel_size)
        : t_prev(t), trunc(truncation), vs(voxel_size), truncated(truncation * S(0.999)) {}

    /// True where the last sample and the next one, f_next, enclose a
    /// crossing from the front.
    EMF_HD bool crosses(S f_next) const { return have_prev && f_prev > S(0) && f_next <= S(0); }

    /// What the march does with an observed sample f at t that is not a
    /// crossing it draws: false where the ray ends (leaving a surface from
    /// behind, unless `skipped_surfaces`: an object volume's background);
    /// else it keeps the sample and advances t.
    EMF_HD bool on(S& t, S f, bool skipped_surfaces) {
      if (have_prev && f_prev < S(0) && f > S(0) && !skipped_surfaces) return false;
      have_prev = true;
      t_prev = t, f_prev = f;
      t += f >= truncated ? trunc : (f > vs ? S(0.5) * f : S(0.5) * vs);
      return true;
    }
  };

  /// Bounded: each step of the march advances at least half a voxel.
  EMF_HD int max_steps(S t, S t_end) const { return int((t_end - t) / (S(0.5) * volume.voxel_size)) + 2; }

  /// True where the crossing at p_hit is drawn (always without foreground).
  EMF_HD bool drawn(const Vec3<S>& p_hit) const {
    return foreground.empty() || foreground.probability(p_hit) > params.min_foreground;
  }

  /// The march of a dense volume: samples along the ray, and at a crossing
  /// its refinement (Crossing) in a loop of its own.
  template <class Sampler>
  EMF_HD void march_then_refine(Sampler& sampler, int i, const Vec3<S>& ray_cam, const Vec3<S>& origin,
                                const Vec3<S>& dir, S t, S t_end) const {
    March m(t, volume.truncation, volume.voxel_size);
    const int steps = max_steps(t, t_end);
    for (int k = 0; k < steps && t <= t_end; ++k) {
      S f;
      if (!sampler.sample_observed(origin + t * dir, f)) {
        m.have_prev = false;  // unobserved space: no crossing can be trusted
        t = skip_unobserved(volume, origin, dir, t, t_end);
        continue;
      }
      if (m.crosses(f)) {
        Crossing<S> c(m.t_prev, m.f_prev, t, f);
        for (int it = 0; it < Crossing<S>::samples; ++it) {
          S fc;
          if (!sampler.sample_observed(origin + c.t * dir, fc) || !c.update(fc)) break;
        }
        const Vec3<S> p_hit = origin + c.t * dir;
        if (drawn(p_hit)) {
          write_hit(sampler, i, ray_cam, c.t, p_hit);
          return;
        }
      }
      if (!m.on(t, f, !foreground.empty())) break;
    }
    miss(i);
  }

  /// The march of a sparse volume, with one place that takes every sample:
  /// the march's, those that refine a crossing (refining = the
  /// refinement's sample, 1.. Crossing::samples, 0 while marching) and
  /// those of the normal at a drawn crossing (NormalSamples: stage 1..7,
  /// 0 before). A warp whose threads are at different stages then runs one
  /// copy of the sampling code (eight block lookups): on the H100 the
  /// sparse kernel ran 0.83 ms instead of 1.20 (0.58 instead of 0.80
  /// through the index grid) with the march's and the refinement's samples
  /// at one site, where the dense one, whose samples are cheap, ran 0.43 ms
  /// instead of 0.37 and so keeps march_then_refine.
  template <class Sampler>
  EMF_HD void march_one_site(Sampler& sampler, int i, const Vec3<S>& ray_cam, const Vec3<S>& origin,
                             const Vec3<S>& dir, S t, S t_end) const {
    March m(t, volume.truncation, volume.voxel_size);
    const int steps = max_steps(t, t_end);
    int k = 0, refining = 0;
    Crossing<S> c;
    NormalSamples<S> normal(volume.voxel_size);
    Vec3<S> p_hit{};
    S f_march = S(0);
    for (;;) {
      if (refining == 0 && normal.stage == 0 && !(k < steps && t <= t_end)) break;
      S f = S(0);  // set by sample_observed; initialised for g++'s -Wmaybe-uninitialized at -O3 (nvcc's host pass)
      const Vec3<S> p = normal.stage > 0 ? normal.point(p_hit) : origin + (refining > 0 ? c.t : t) * dir;
      const bool observed = sampler.sample_observed(p, f);
      if (normal.stage > 0) {
        if (!normal.take(observed, f)) {
          miss(i);
          return;
        }
        if (normal.stage <= NormalSamples<S>::samples) continue;
        write_surface(i, ray_cam, c.t, normal.gradient);
        return;
      }
      if (refining > 0) {
        if (observed && c.update(f) && refining < Crossing<S>::samples) {
          ++refining;
          continue;
        }
        refining = 0;
        p_hit = origin + c.t * dir;
        if (drawn(p_hit)) {
          if (!params.surface) {
            write_depth(i, ray_cam, c.t);
            return;
          }
          normal.stage = 1;
          continue;
        }
        f = f_march;  // not drawn: the march goes on from its sample at t
      } else {
        ++k;
        if (!observed) {
          m.have_prev = false;  // unobserved space: no crossing can be trusted
          t = skip_unobserved(sampler, origin, dir, t, t_end);
          continue;
        }
        if (m.crosses(f)) {
          c = Crossing<S>(m.t_prev, m.f_prev, t, f);
          f_march = f;
          refining = 1;
          continue;
        }
      }
      if (!m.on(t, f, !foreground.empty())) break;
    }
    miss(i);
  }

  /// A hit at distance t along the ray (depth only).
  EMF_HD void write_depth(int i, const Vec3<S>& ray_cam, S t) const {
    depth[i] = (t * ray_cam).z();
    hit[i] = 1;
  }

  /// A hit at distance t along the ray with the SDF gradient `g` there
  /// (volume frame): depth, vertex and normal, or a miss where g is zero.
  EMF_HD void write_surface(int i, const Vec3<S>& ray_cam, S t, const Vec3<S>& g) const {
    if (!(squared_norm(g) > S(0))) {
      miss(i);
      return;
    }
    const Vec3<S> vertex = t * ray_cam;
    // Rotate the gradient into the camera frame: R_camera_volume = R^T.
    Vec3<S> n = normalized(T_volume_camera.rotation().transpose() * g);
    if (dot(n, vertex) > S(0)) n = -n;
    depth[i] = vertex.z();
    vertices[i] = vertex;
    normals[i] = n;
    hit[i] = 1;
  }

  /// A hit at distance t along the ray, at p_volume in the volume: its
  /// normal from the sampler's observed_gradient.
  template <class Sampler>
  EMF_HD void write_hit(Sampler& sampler, int i, const Vec3<S>& ray_cam, S t, const Vec3<S>& p_volume) const {
    if (!params.surface) {
      write_depth(i, ray_cam, t);
      return;
    }
    Vec3<S> g;
    if (!sampler.observed_gradient(p_volume, g)) {
      miss(i);
      return;
    }
    write_surface(i, ray_cam, t, g);
  }
};

}  // namespace detail

/// Renders `volume` (a TsdfVolume or a SparseTsdfVolume) into `camera` at
/// `T_world_camera`; writes into `out` (allocated on the volume's backend as
/// needed). With `foreground` (an object's counts, same grid; dense volumes
/// only), only surfaces with p_fg > min_foreground. With `ray_end` (an image
/// of the camera's size), rays are cast only where it is positive, and end at
/// that depth: a pixel's first crossing before it or a miss (a question such
/// as "is the surface in front of this depth?"). With `run_on`, the cast is
/// queued there (a lane of ConcurrentLanes, so that several objects' casts
/// run at once) instead of on the volume's backend.
template <class Volume, class S, Backend B>
  requires TsdfVolumeType<Volume, S> && std::same_as<typename Volume::backend_type, B>
void raycast(const Volume& volume, const PinholeCamera<S>& camera, const SE3<S>& T_world_camera,
             RaycastResult<S, B>& out, const RaycastParams<S>& params = {},
             const ForegroundCounts<S, B>* foreground = nullptr, const Image<S, B>* ray_end = nullptr,
             const B* run_on = nullptr) {
  camera.validate("raycast");
  detail::require(params.min_depth >= S(0) && params.max_depth > params.min_depth, "raycast",
                  "need 0 <= min_depth < max_depth");
  if (foreground) detail::check_foreground(volume, *foreground);
  if (ray_end) detail::require_image(ray_end->view(), camera.width, camera.height, "raycast", "ray_end image");
  out.resize(camera.width, camera.height, volume.backend(), params.surface);
  const SE3<S> T_volume_camera = volume.pose().inverse() * T_world_camera;
  detail::RaycastPixel<S, decltype(volume.view())> f{
      volume.view(),      camera,         T_volume_camera,
      params,             out.depth.view(), out.vertices.view(),
      out.normals.view(), out.hit.view(), {}, {}};
  if (ray_end) f.ray_end = ray_end->view();
  if (foreground) f.foreground = foreground->view();
  // Rays are cast only where they can meet the part of the volume where a
  // surface may be drawn (march_box: an object's is a small part of the
  // frame); every other pixel is a miss.
  const detail::MarchBox<S> m = detail::march_box(volume, foreground, params);
  f.narrowed = m.narrowed, f.march_lo = m.lo, f.march_hi = m.hi;
  f.pixels = !m.drawable ? PixelBox{}
             : m.bounded ? projected_box(camera, T_volume_camera.inverse(), m.lo, m.hi)
                         : PixelBox::whole(camera.width, camera.height);
  // On a GPU one pass over every pixel, those outside the box missing at
  // once; clearing the images first and launching on the box took 0.2 ms
  // more per frame there (H100, redkitchen_dyn_300, four objects). The
  // pass runs in tiles, so that a warp's rays are a compact patch: 0.49 ->
  // 0.28 ms (sparse) and 0.41 -> 0.29 ms (dense, three tiles an SM) in
  // bench_volume on the H100. On the CPU the reverse: cleared images and
  // the box's pixels only (raycast 78 against 88 ms per frame on 2 cores).
  if constexpr (B::is_device) {
    constexpr int min_tiles_per_sm = detail::is_dense_view<decltype(volume.view())> ? 3 : 1;
    for_each_pixel_tiled<min_tiles_per_sm>(run_on ? *run_on : volume.backend(), camera.width, camera.height, f);
  } else {
    if (f.pixels.area() < camera.pixel_count()) {
      const S nan = std::numeric_limits<S>::quiet_NaN();
      out.depth.fill(S(0));
      out.hit.fill(0);
      if (params.surface) {
        out.vertices.fill(Vec3<S>::constant(nan));
        out.normals.fill(Vec3<S>::constant(nan));
      }
    }
    for_each_pixel_in(run_on ? *run_on : volume.backend(), f.pixels, camera.width, f);
  }
}

}  // namespace emfusion
