// Objects found again (extensions of the paper; docs/system.md, "Lost
// objects" and "Objects left behind"): a detection that matches no live
// object is aligned to every lost object of its class, and the one on whose
// surface enough of the detection's points land returns to the map with its
// id and model, instead of a new object being made (reidentify); before
// that, with relocalize_below > 0, live objects that tracking left behind
// (unmatched, weakly associated) are tried the same way and moved onto the
// detection (relocalize_objects).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <thrust/functional.h>

#include "emfusion/core/pixel_box.hpp"
#include "emfusion/detect/detection.hpp"
#include "emfusion/detect/matching.hpp"
#include "emfusion/detect/proposal.hpp"
#include "emfusion/robust/norms.hpp"
#include "emfusion/slam/association.hpp"
#include "emfusion/slam/detection_masks.hpp"
#include "emfusion/slam/frame.hpp"
#include "emfusion/slam/frame_result.hpp"
#include "emfusion/slam/map.hpp"
#include "emfusion/slam/tracking.hpp"
#include "emfusion/solve/batched_solve.hpp"
#include "emfusion/solve/pose_prior.hpp"
#include "emfusion/solve/sdf_alignment.hpp"
#include "emfusion/volume/raycast.hpp"

namespace emfusion {

namespace detail::reidentification {

/// A "norm" whose cost counts residuals at least `delta` (weight 1): with
/// unit term weights, linearize() then returns the terms (NormalEquations6::terms)
/// and how many of them are off the surface (cost).
template <class S>
struct OffSurfaceCount {
  S delta;
  EMF_HD S cost(S r) const { return std::fabs(r) < delta ? S(0) : S(1); }
  EMF_HD S weight(S) const { return S(1); }
};

/// An object's model drawn into the frame (`hit`, at `depth`: a depth-only
/// raycast) beside the frame's measured points.
template <class S>
struct ModelInFrame {
  ImageView<const std::uint8_t> hit;
  ImageView<const S> depth;
  ImageView<const Vec3<S>> points;
  /// The measured depth at pixel i less the model's there (not finite where
  /// nothing was measured); only where hit[i].
  EMF_HD S gap(int i) const { return points[i].z() - depth[i]; }
};

/// Of the pixels of a detection (`mask`) that an object's model draws, how
/// many show the measured surface within `tolerance` of the model's.
struct DrawnPixels {
  int drawn = 0, agree = 0, masked = 0;
  EMF_HD DrawnPixels operator+(const DrawnPixels& o) const {
    return {drawn + o.drawn, agree + o.agree, masked + o.masked};
  }
};
template <class S>
struct CountDrawnPixels {
  ModelInFrame<S> model;
  ImageView<const S> mask;
  S tolerance;
  EMF_HD DrawnPixels operator()(int i) const {
    if (!(mask[i] > S(0))) return {};
    if (!model.hit[i]) return {0, 0, 1};
    const S gap = model.gap(i);
    return {1, std::isfinite(gap) && std::fabs(gap) <= tolerance ? 1 : 0, 1};
  }
};

/// Of the pixels inside the visibility border that a lost object's model
/// draws and no live object claims (`segmentation` 0): how many show the
/// measured surface within `tolerance` of the model's (agree), and how many
/// show it further away (behind: the frame sees through where the model
/// would stand). A nearer surface is an occluder and counts neither way.
struct InViewPixels {
  int agree = 0, behind = 0;
  EMF_HD InViewPixels operator+(const InViewPixels& o) const { return {agree + o.agree, behind + o.behind}; }
};
template <class S>
struct CountInView {
  ModelInFrame<S> model;
  ImageView<const int> segmentation;
  int border;
  S tolerance;
  EMF_HD InViewPixels operator()(int i) const {
    if (!segmentation.inside_border(i, border) || !model.hit[i] || segmentation[i] > 0) return {};
    const S gap = model.gap(i);
    if (!std::isfinite(gap)) return {};
    if (std::fabs(gap) <= tolerance) return {1, 0};
    return {0, gap > S(0) ? 1 : 0};
  }
};

/// Whether the frame shows object `o` placed at T_volume_camera, as far as
/// no live object covers it: of the pixels inside the visibility border
/// that its model draws (surfaces of p_fg above 1/2, depth only) and no
/// live object claims, at least keep_mask_pixels show the measured surface
/// within likelihood.sigma of its own, and those are at least
/// reidentify_min_inliers of the ones that do or show a surface behind it
/// (CountInView). `drawn` keeps the cast's images between calls.
template <class S, Backend B>
bool shown_in_view(const ObjectModel<S, B>& o, const SE3<S>& T_volume_camera, const Frame<S, B>& frame,
                   const PinholeCamera<S>& camera, const SystemParams<S>& params, RaycastResult<S, B>& drawn) {
  const int min_pixels = params.keep_mask_pixels_for(camera.width, camera.height);
  // Only the pixels its volume projects to can show it: none when it is
  // out of view (no cast, no count).
  const PixelBox box = projected_box(camera, T_volume_camera.inverse(), Vec3<S>::zero(), o.volume().view().extent());
  if (box.area() < min_pixels) return false;
  RaycastParams<S> rp;
  rp.surface = false;
  raycast(o.volume(), camera, o.volume().pose() * T_volume_camera, drawn, rp, &o.foreground());
  const InViewPixels n = transform_reduce_index(
      frame.points.backend(), box.area(),
      PixelsInBox<CountInView<S>>{{{std::as_const(drawn.hit).view(), std::as_const(drawn.depth).view(),
                                    frame.points.view()},
                                   frame.segmentation.view(),
                                   params.visibility_border_for(camera.width),
                                   params.likelihood.sigma},
                                  box,
                                  camera.width},
      InViewPixels{}, thrust::plus<InViewPixels>());
  return n.agree >= min_pixels && double(n.agree) >= double(params.reidentify_min_inliers) * (n.agree + n.behind);
}

}  // namespace detail::reidentification

namespace detail::reidentification {

/// Detection d's points as models are aligned to them: how many there are
/// (the largest depth group of its own pixels), their centroid and viewing
/// ray, and the detection's own pixels as a weight image on the backend.
template <class S, Backend B>
struct DetectionTarget {
  std::size_t points = 0;
  Vec3<S> centroid, ray;
  Image<S, B> mask;
};

/// The target of detection d, or nothing when it is of a static class or
/// has fewer than `min_points` points of its own (min_mask_pixels when
/// not given).
template <class S, Backend B>
std::optional<DetectionTarget<S, B>> detection_target(const Frame<S, B>& frame, const Detections& det, int d,
                                                      const std::vector<int>& seg, const std::vector<Vec3<S>>& points,
                                                      const PinholeCamera<S>& camera, const SystemParams<S>& params,
                                                      std::optional<int> min_points = std::nullopt) {
  const Instance& inst = det.instances[std::size_t(d)];
  if (is_listed_class(inst.class_name, params.static_classes)) return std::nullopt;
  const std::vector<Vec3<S>> p = largest_depth_group(detection_points(points, det.labels.view().data, inst.label, &seg),
                                                     params.object_depth_gap);
  if (int(p.size()) < min_points.value_or(params.min_mask_pixels_for(camera.width, camera.height)))
    return std::nullopt;
  DetectionTarget<S, B> t;
  t.points = p.size();
  t.centroid = Vec3<S>::zero();
  for (const Vec3<S>& x : p) t.centroid = t.centroid + x;
  t.centroid = t.centroid / S(p.size());
  t.ray = normalized(t.centroid);
  const std::vector<std::uint8_t> own = own_mask(det, d, seg);
  const std::vector<S> in_mask(own.begin(), own.end());
  t.mask = Image<S, Host>::from_host(camera.width, camera.height, in_mask).template to<B>(frame.points.backend());
  return t;
}

/// Whether a solve of object `o` to a target (`report`, the solved
/// T_volume_camera `T`) may be a fit (fit_from): it converged with at least
/// params.min_object_terms terms and, with `frames_lost` > 0 (a lost
/// object, lost that many frames ago), it puts the object's box centre no
/// further from where it was last, and turns it no further, than
/// frames_lost times params.max_object_motion.
template <class S, Backend B>
bool may_be_fit(const ObjectModel<S, B>& o, const SolveReport& report, const SE3<S>& T, const SE3<S>& T_world_camera,
                const SystemParams<S>& params, int frames_lost) {
  if (!report.converged() || report.terms < double(params.min_object_terms)) return false;
  if (frames_lost <= 0) return true;
  // The move from the last pose: of the box centre, and the turn.
  const Vec3<S> centre = S(0.5) * o.volume().view().extent();
  const SE3<S> last = o.volume().pose(), now = T_world_camera * T.inverse();
  const double moved = double(emfusion::norm(now * centre - last * centre));
  const double turned = double(emfusion::norm(so3_log((last.inverse() * now).rotation())));
  const MotionBound<S>& bound = params.max_object_motion;
  return !MotionBound<S>{S(frames_lost) * bound.translation, S(frames_lost) * bound.rotation_degrees}.exceeded_by(
      moved, turned);
}

/// The terms that count a target's points on the surface of object `o`
/// (with OffSurfaceCount: the detection's own pixels, unit weights).
template <class S, Backend B>
auto surface_count_terms(const ObjectModel<S, B>& o, const DetectionTarget<S, B>& target, const Frame<S, B>& frame,
                         const SystemParams<S>& params) {
  SdfAlignmentParams<S> count = alignment_params(params, params.object_integration.max_weight);
  count.use_map_confidence = false;
  return make_sdf_alignment(o.volume(), frame.points, &target.mask, count);
}

/// The pull of a fit of object `o` towards its start
/// (params.reidentify_pose_prior; its pose is set per start).
template <class S, Backend B>
PosePrior<S> fit_prior(const ObjectModel<S, B>& o, const SystemParams<S>& params) {
  return PosePrior<S>::in_box(o.volume().view().extent(), params.reidentify_pose_prior);
}

/// Object `o` aligned (`norm` in its voxels, `solver`, pulled towards
/// `start` by params.reidentify_pose_prior) to the target's
/// points from `start` (T_volume_camera): the share of the points within a
/// Huber delta of its surface and the solved T_volume_camera; nothing when
/// the solve may not be a fit (may_be_fit: no convergence, too few terms,
/// or, for a lost object lost `frames_lost` frames ago, a move it cannot
/// have made since).
template <class S, Backend B, class Norm, class Solver>
std::optional<std::pair<double, SE3<S>>> fit_from(const ObjectModel<S, B>& o, const DetectionTarget<S, B>& target,
                                                  const Frame<S, B>& frame, const SE3<S>& T_world_camera,
                                                  const SystemParams<S>& params, const Norm& norm,
                                                  const Solver& solver, int frames_lost, const SE3<S>& start) {
  const auto& volume = o.volume();
  const SdfAlignmentParams<S> align = alignment_params(params, params.object_integration.max_weight);
  const PosePrior<S> prior = fit_prior(o, params).towards(start);
  SolveReport report;
  LinearizationCache<S, B> values;
  const SE3<S> T = align_in_volume(volume, frame.points, &target.mask, start, scaled_norm(norm, volume.voxel_size()),
                                   align, solver, &report, &values, &volume.backend(), &prior);
  if (!may_be_fit(o, report, T, T_world_camera, params, frames_lost)) return std::nullopt;
  const NormalEquations6 n = linearize(frame.points.backend(), surface_count_terms(o, target, frame, params),
                                       OffSurfaceCount<S>{params.huber_voxels * volume.voxel_size()}, T);
  return std::pair{(n.terms - n.cost) / double(target.points), T};
}

/// fit_from from each of `starts`, in their order. With the library's
/// LevenbergMarquardt (solved_in_batches) the solves run as one batch
/// (solve_coarse_to_fine_batch) and the counts of the points on the surface
/// as another (linearize_batch): on a GPU a few waits for the host instead
/// of one every iteration of every solve (a re-identification tries up to
/// 51 starts an object). Any other solver: fit_from, one after another.
template <class S, Backend B, class Norm, class Solver>
std::vector<std::optional<std::pair<double, SE3<S>>>> fits_from(const ObjectModel<S, B>& o,
                                                                const DetectionTarget<S, B>& target,
                                                                const Frame<S, B>& frame, const SE3<S>& T_world_camera,
                                                                const SystemParams<S>& params, const Norm& norm,
                                                                const Solver& solver, int frames_lost,
                                                                const std::vector<SE3<S>>& starts) {
  const std::size_t n = starts.size();
  std::vector<std::optional<std::pair<double, SE3<S>>>> fits(n);
  if constexpr (!solved_in_batches<Solver>) {
    for (std::size_t k = 0; k < n; ++k)
      fits[k] = fit_from(o, target, frame, T_world_camera, params, norm, solver, frames_lost, starts[k]);
  } else if (n > 0) {
    const auto& volume = o.volume();
    const B& backend = frame.points.backend();
    const SdfAlignmentParams<S> align = alignment_params(params, params.object_integration.max_weight);
    const auto terms = sdf_alignment_in_box(volume, frame.points, &target.mask, align, backend);
    const auto scaled = scaled_norm(norm, volume.voxel_size());
    BatchedSolveWorkspace<S, B> ws;
    std::vector<SolveReport> reports;
    const PosePrior<S> prior = fit_prior(o, params);
    std::vector<PosePrior<S>> priors;
    for (const SE3<S>& start : starts) priors.push_back(prior.towards(start));
    const std::vector<SE3<S>> T = solve_coarse_to_fine_batch(backend, std::vector(n, terms), std::vector(n, scaled),
                                                             align, solver, starts, reports, ws, &priors);
    using Count = BatchedProblem<decltype(surface_count_terms(o, target, frame, params)), OffSurfaceCount<S>>;
    const Count count{surface_count_terms(o, target, frame, params),
                      OffSurfaceCount<S>{params.huber_voxels * volume.voxel_size()}};
    std::vector<Count> counts;
    std::vector<LinearizationRequest<S>> at;
    std::vector<std::size_t> which;
    for (std::size_t k = 0; k < n; ++k) {
      if (!may_be_fit(o, reports[k], T[k], T_world_camera, params, frames_lost)) continue;
      LinearizationRequest<S> request;
      request.T = request.reference = T[k];
      request.active = 1;
      counts.push_back(count), at.push_back(request), which.push_back(k);
    }
    const std::vector<NormalEquations6> sums = linearize_batch(backend, counts, at, ws);
    for (std::size_t i = 0; i < which.size(); ++i)
      fits[which[i]] = std::pair{(sums[i].terms - sums[i].cost) / double(target.points), T[which[i]]};
  }
  return fits;
}

/// A start for aligning object `o` to the target: its last orientation as
/// the camera sees it now (`R`, of T_volume_camera) turned by `turn` (in
/// the camera's frame), with its box centre placed at the points' centroid
/// pushed back along the ray by h/16 of the box side (the visible surface
/// lies in front of the object's centre; an object fills about half its
/// box).
template <class S, Backend B>
SE3<S> start_at_target(const ObjectModel<S, B>& o, const DetectionTarget<S, B>& target, const Mat3<S>& R,
                       const Mat3<S>& turn, int h) {
  const Vec3<S> extent = o.volume().view().extent();
  const Mat3<S> Rt = R * turn;
  const S step = extent.x() / S(16);
  return SE3<S>(Rt, S(0.5) * extent - Rt * (target.centroid + (S(h) * step) * target.ray));
}

/// Sums over a fit's points on the model's surface of the model's gray
/// value c there and the frame's I: how many, and the sums of c, I, c^2,
/// I^2 and cI.
struct ColourMoments {
  double n = 0, c = 0, i = 0, cc = 0, ii = 0, ci = 0;
  EMF_HD ColourMoments operator+(const ColourMoments& o) const {
    return {n + o.n, c + o.c, i + o.i, cc + o.cc, ii + o.ii, ci + o.ci};
  }
  /// The spread (standard deviation) of the model's gray values.
  double model_spread() const { return n > 0 ? std::sqrt(std::max(cc / n - (c / n) * (c / n), 0.0)) : 0.0; }
  /// The correlation of the model's gray values with the frame's (Pearson;
  /// 0 when either does not vary).
  double correlation() const {
    if (!(n > 0)) return 0;
    const double cov = ci / n - (c / n) * (i / n), vc = cc / n - (c / n) * (c / n), vi = ii / n - (i / n) * (i / n);
    return vc > 0 && vi > 0 ? cov / std::sqrt(vc * vi) : 0.0;
  }
};

/// ColourMoments of pixel i: the point of a pixel of `mask`, placed in the
/// model's volume by T_volume_camera, within `near` of its surface and
/// where the model has colour.
template <class S, class View>
struct ColourOnSurface {
  View volume;
  IntensityView<S, const float> colour;
  ImageView<const Vec3<S>> points;
  ImageView<const S> intensity;
  ImageView<const S> mask;
  SE3<S> T_volume_camera;
  S near;

  EMF_HD ColourMoments operator()(int i) const {
    const Vec3<S> p = points[i];
    const S I = intensity[i];
    const bool measured = std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z()) && std::isfinite(I);
    if (!(mask[i] > S(0)) || !measured) return {};
    const Vec3<S> x = T_volume_camera * p;
    S sdf, c;
    Vec3<S> gradient;
    if (!volume.sample(x, sdf) || !(std::fabs(sdf) < near) || !colour.sample_with_gradient(x, c, gradient)) return {};
    const double cd = double(c), id = double(I);
    return {1.0, cd, id, cd * cd, id * id, cd * id};
  }
};

/// Whether object `o`'s colour agrees with the frame at T_volume_camera
/// (params.reidentify_colour_agreement): over the pixels of `mask` whose
/// points lie within the Huber delta of the model's surface, the model's
/// gray values there and the frame's correlate by at least that much. A
/// correlation, not a difference: the generator's (and the world's)
/// shading changes the gray values as an object turns, the pattern stays.
/// A part view of a box, a cylinder or a ball fits in depth as well
/// turned as right; its colour tells them apart (docs/system.md, "Lost
/// objects"). True when the rule is off, the model or the frame has no
/// colour, fewer than keep_mask_pixels such points have colour, or the
/// model's colour there hardly varies (a spread under 0.02: nothing to
/// judge by).
template <class S, Backend B>
bool colour_agrees(const ObjectModel<S, B>& o, const SE3<S>& T_volume_camera, const Frame<S, B>& frame,
                   const Image<S, B>& mask, const SystemParams<S>& params) {
  if (!(params.reidentify_colour_agreement > 0) || o.colour().empty() || frame.intensity.empty()) return true;
  const auto volume = o.volume().view();
  const ColourMoments m = transform_reduce_index(
      frame.points.backend(), frame.points.size(),
      ColourOnSurface<S, decltype(volume)>{volume, std::as_const(o.colour()).view(), frame.points.view(),
                                           frame.intensity.view(), mask.view(), T_volume_camera,
                                           params.huber_voxels * o.volume().voxel_size()},
      ColourMoments{}, thrust::plus<ColourMoments>());
  if (m.n < double(params.keep_mask_pixels_for(frame.points.width(), frame.points.height())) ||
      m.model_spread() < 0.02)
    return true;
  return m.correlation() >= params.reidentify_colour_agreement;
}

/// A fit of object `o` to the target whose colour disagrees
/// (colour_agrees) solved again from its pose `start` with the model's
/// colour terms (object_colour_weight, 10 when that is 0): where the depth
/// leaves the pose free along a face or an axis (a box slid by a square of
/// its checker), the pattern holds it. Its share of the points on the
/// surface and its T_volume_camera when it may be a fit (may_be_fit) and
/// its colour agrees; nothing otherwise.
template <class S, Backend B, class Norm, class Solver>
std::optional<std::pair<double, SE3<S>>> colour_refined_fit(const ObjectModel<S, B>& o,
                                                            const DetectionTarget<S, B>& target,
                                                            const Frame<S, B>& frame, const SE3<S>& T_world_camera,
                                                            const SystemParams<S>& params, const Norm& norm,
                                                            const Solver& solver, int frames_lost,
                                                            const SE3<S>& start) {
  const auto& volume = o.volume();
  const B& backend = frame.points.backend();
  const SdfAlignmentParams<S> align = alignment_params(params, params.object_integration.max_weight);
  auto terms = sdf_alignment_in_box(volume, frame.points, &target.mask, align, backend);
  terms.colour = o.colour().view();
  terms.intensity = frame.intensity.view();
  terms.colour_scale = (params.object_colour_weight > S(0) ? params.object_colour_weight : S(10)) * volume.voxel_size();
  const PosePrior<S> prior = fit_prior(o, params).towards(start);
  SolveReport report;
  LinearizationCache<S, B> values;
  const SE3<S> T = solve_coarse_to_fine(backend, terms, scaled_norm(norm, volume.voxel_size()), align, solver, start,
                                        &report, values, &prior);
  if (!may_be_fit(o, report, T, T_world_camera, params, frames_lost) ||
      !colour_agrees(o, T, frame, target.mask, params))
    return std::nullopt;
  const NormalEquations6 n = linearize(backend, surface_count_terms(o, target, frame, params),
                                       OffSurfaceCount<S>{params.huber_voxels * volume.voxel_size()}, T);
  return std::pair{(n.terms - n.cost) / double(target.points), T};
}

/// How well object `o` fits the target (fit_from): aligned first from its
/// last pose, then from its last orientation placed at the target
/// (start_at_target, h = 0, 1, 2, 3). Returns the best share of the points
/// on its surface over the fits (0: none) and that fit's T_volume_camera.
/// The fit from the last pose is kept unless another puts
/// params.reidentify_keep_margin more of the points on the surface: an
/// object of symmetric shape (a box, a cylinder) fits its points as well
/// turned by a quarter or half turn, and the pose it was last seen in is
/// the likelier one. `frames_lost`: see fit_from.
template <class S, Backend B, class Norm, class Solver>
std::pair<double, SE3<S>> fit_to_target(const ObjectModel<S, B>& o, const DetectionTarget<S, B>& target,
                                        const Frame<S, B>& frame, const SE3<S>& T_world_camera,
                                        const SystemParams<S>& params, const Norm& norm, const Solver& solver,
                                        int frames_lost = 0) {
  const SE3<S> last_seen = o.volume().pose().inverse() * T_world_camera;  // T_volume_camera at its last pose
  std::vector<SE3<S>> starts{last_seen};
  for (int h = 0; h < 4; ++h)
    starts.push_back(start_at_target(o, target, last_seen.rotation(), Mat3<S>::identity(), h));
  const auto fits = fits_from(o, target, frame, T_world_camera, params, norm, solver, frames_lost, starts);
  double best_inliers = 0, to_beat = 0;
  SE3<S> best_T;
  for (std::size_t k = 0; k < fits.size(); ++k) {
    if (!fits[k]) continue;
    const auto [inliers, T] = *fits[k];
    if (k == 0) to_beat = inliers + params.reidentify_keep_margin;
    if (inliers > best_inliers && (k == 0 || inliers > to_beat)) best_inliers = inliers, best_T = T;
  }
  // A fit whose colour disagrees is solved again with the colour
  // (reidentify_colour_agreement; colour_agrees is true when it is off).
  if (best_inliers >= params.reidentify_min_inliers && !colour_agrees(o, best_T, frame, target.mask, params))
    if (const auto refined =
            colour_refined_fit(o, target, frame, T_world_camera, params, norm, solver, frames_lost, best_T))
      return *refined;
  return {best_inliers, best_T};
}

/// The 23 turns other than none that map a cube onto itself (quarter and
/// half turns about its faces, third turns about its corners, half turns
/// about its edges): every orientation is within 63 degrees of one of
/// them or of none.
template <class S>
std::vector<Mat3<S>> cube_turns() {
  const S quarter = S(1.5707963267948966);
  const Vec3<S> x{S(1), S(0), S(0)}, y{S(0), S(1), S(0)}, z{S(0), S(0), S(1)};
  // Where the x axis goes (six faces), times the four turns about it.
  const Mat3<S> faces[6] = {Mat3<S>::identity(), so3_exp(z * quarter),        so3_exp(z * (S(2) * quarter)),
                            so3_exp(z * -quarter), so3_exp(y * quarter), so3_exp(y * -quarter)};
  std::vector<Mat3<S>> turns;
  for (int f = 0; f < 6; ++f)
    for (int k = 0; k < 4; ++k)
      if (f > 0 || k > 0) turns.push_back(faces[f] * so3_exp(x * (S(k) * quarter)));
  return turns;
}

/// Which of `starts` turned_fits solves to the end, in their order: all of
/// them, or, with params.reidentify_turned_keep > 0 and fewer kept than
/// there are starts (solved_in_batches only), the reidentify_turned_keep
/// whose fits (fits_from) after params.reidentify_turned_rank_iterations
/// Levenberg-Marquardt iterations put the largest share of the target's
/// points on the surface (ties: the earlier start); a start whose short
/// solve may not be a fit is not kept. On the CPU, where a batch solves
/// its problems one after another, the 46 turned solves were most of a
/// re-identification (docs/decisions.md, "Fewer turned starts carried to
/// the end").
template <class S, Backend B, class Norm, class Solver>
std::vector<std::size_t> ranked_starts(const ObjectModel<S, B>& o, const DetectionTarget<S, B>& target,
                                       const Frame<S, B>& frame, const SE3<S>& T_world_camera,
                                       const SystemParams<S>& params, const Norm& norm, const Solver& solver,
                                       int frames_lost, const std::vector<SE3<S>>& starts) {
  std::vector<std::size_t> kept(starts.size());
  for (std::size_t k = 0; k < kept.size(); ++k) kept[k] = k;
  if constexpr (solved_in_batches<Solver>) {
    const std::size_t keep = std::size_t(std::max(params.reidentify_turned_keep, 0));
    if (keep == 0 || keep >= starts.size()) return kept;
    Solver brief = solver;
    brief.params.max_iterations = params.reidentify_turned_rank_iterations;
    const auto ranked = fits_from(o, target, frame, T_world_camera, params, norm, brief, frames_lost, starts);
    std::erase_if(kept, [&](std::size_t k) { return !ranked[k]; });
    std::stable_sort(kept.begin(), kept.end(),
                     [&](std::size_t a, std::size_t b) { return ranked[a]->first > ranked[b]->first; });
    if (kept.size() > keep) kept.resize(keep);
    std::sort(kept.begin(), kept.end());
  }
  return kept;
}

/// Object `o` aligned to the target from its last orientation turned by
/// each of cube_turns (start_at_target, h = 1 and 2, the better kept): one
/// fit per turn that converged (fit_from), for an object that turned while
/// it was out of view. With params.reidentify_turned_keep > 0 and the
/// library's Levenberg-Marquardt (solved_in_batches), in two rounds: every
/// start solved for reidentify_turned_rank_iterations iterations, then
/// only the reidentify_turned_keep starts with the most points on the
/// surface there solved again, from the start, to the end (ranked_starts):
/// those fits are the ones solving every start gives them.
template <class S, Backend B, class Norm, class Solver>
std::vector<std::pair<double, SE3<S>>> turned_fits(const ObjectModel<S, B>& o, const DetectionTarget<S, B>& target,
                                                   const Frame<S, B>& frame, const SE3<S>& T_world_camera,
                                                   const SystemParams<S>& params, const Norm& norm,
                                                   const Solver& solver, int frames_lost) {
  const Mat3<S> R = (o.volume().pose().inverse() * T_world_camera).rotation();
  std::vector<SE3<S>> starts;  // h = 1 and 2 of each turn
  for (const Mat3<S>& turn : cube_turns<S>())
    for (int h = 1; h <= 2; ++h) starts.push_back(start_at_target(o, target, R, turn, h));
  std::vector<std::optional<std::pair<double, SE3<S>>>> tried(starts.size());
  const std::vector<std::size_t> kept =
      ranked_starts(o, target, frame, T_world_camera, params, norm, solver, frames_lost, starts);
  std::vector<SE3<S>> from;
  for (const std::size_t k : kept) from.push_back(starts[k]);
  const auto solved = fits_from(o, target, frame, T_world_camera, params, norm, solver, frames_lost, from);
  for (std::size_t i = 0; i < kept.size(); ++i) tried[kept[i]] = solved[i];
  std::vector<std::pair<double, SE3<S>>> fits;
  for (std::size_t k = 0; k + 1 < tried.size(); k += 2) {
    const auto& a = tried[k];
    const auto& b = tried[k + 1];
    if (a && (!b || a->first >= b->first))
      fits.push_back(*a);
    else if (b)
      fits.push_back(*b);
  }
  return fits;
}

/// Whether object `o`, placed at T_volume_camera (a fit_to_target), is
/// what the frame shows in the detection's pixels `mask`: its model, drawn
/// there (surfaces of p_fg above 1/2, as RaycastParams draws objects),
/// must cover at least half of the mask's pixels, and show in at least
/// half of those it covers, within the volume's truncation of the measured
/// depth. The share of a detection's points on the model's surface
/// (fit_to_target) is one-sided: an object's volume also holds what was
/// fused around it (the floor under a cup, a wall behind it), so a false
/// positive of the object's class on bare floor or wall can fit that
/// patch, with the object itself standing out in front of it or sunk
/// behind it; or, where those surroundings count as foreground, the model
/// is drawn as that floor and agrees, but over a part of the detection
/// only (on synthetic:corridor a false positive of class cup on a bin 5 m
/// away: the cup's model drawn on 1593 of its 4799 pixels, where the true
/// re-identifications of the corridor and of three generated sequences
/// drew 66-99 % of theirs).
template <class S, Backend B>
bool consistent_with_frame(const ObjectModel<S, B>& o, const SE3<S>& T_volume_camera, const Frame<S, B>& frame,
                           const Image<S, B>& mask, const PinholeCamera<S>& camera) {
  RaycastResult<S, B> drawn;
  RaycastParams<S> rp;
  rp.surface = false;
  raycast(o.volume(), camera, o.volume().pose() * T_volume_camera, drawn, rp, &o.foreground());
  const DrawnPixels n = transform_reduce_index(
      frame.points.backend(), frame.points.size(),
      CountDrawnPixels<S>{{std::as_const(drawn.hit).view(), std::as_const(drawn.depth).view(), frame.points.view()},
                          mask.view(),
                          o.volume().truncation()},
      DrawnPixels{}, thrust::plus<DrawnPixels>());
  return n.drawn > 0 && 2 * n.drawn >= n.masked && 2 * n.agree >= n.drawn;
}

/// Whether the frame shows object `o` placed at T_volume_camera both in
/// the pixels `mask` (consistent_with_frame, and in colour: colour_agrees)
/// and wherever its model is drawn (shown_in_view; `drawn` keeps the
/// cast's images between calls): the test of a fit found without the pose
/// it was lost in to go on from (refind_unexplained, and reidentify's
/// turned fits).
template <class S, Backend B>
bool shown_in_mask_and_view(const ObjectModel<S, B>& o, const SE3<S>& T_volume_camera, const Frame<S, B>& frame,
                            const Image<S, B>& mask, const PinholeCamera<S>& camera, const SystemParams<S>& params,
                            RaycastResult<S, B>& drawn) {
  return consistent_with_frame(o, T_volume_camera, frame, mask, camera) &&
         colour_agrees(o, T_volume_camera, frame, mask, params) &&
         shown_in_view(o, T_volume_camera, frame, camera, params, drawn);
}

/// Detector frames an object must have been detected in to be looked for
/// without a detection (refind_in_view, refind_unexplained), or to be
/// moved onto a detection it was not matched to (relocalize_objects): a false
/// positive is seldom seen twice, and a model of nothing fits some patch
/// of the frame, or is drawn where the frame shows the surface its false
/// detection covered (on c214-tab600 a false "person", detected once,
/// came back in view four times and took pixels of the book and the cup).
inline constexpr int min_detections = 2;

/// True for a lost object that is looked for without a detection
/// (refind_in_view, refind_unexplained, hold_unexplained): not lost in
/// this frame, not of an ignored class, and detected on at least
/// min_detections detector frames.
template <class S, Backend B>
bool may_come_back(const LostObject<S, B>& l, int frame, const SystemParams<S>& params) {
  return l.lost_at < frame && !params.ignores(l.object->class_name()) &&
         l.object->existence_count() >= min_detections;
}

/// One candidate's fit to a detection (fit_to_target): the candidate's
/// index in the caller's list, the share of the detection's points on its
/// surface, and T_volume_camera.
template <class S>
struct CandidateFit {
  int candidate = -1;
  double inliers = 0;
  SE3<S> T_volume_camera;
};

/// The share of the points a turned fit must have on the surface to
/// replace `fit`, the best fit from the last orientation (or none):
/// reidentify_min_inliers, and reidentify_keep_margin more than `fit`.
template <class S>
double turned_to_beat(const std::optional<CandidateFit<S>>& fit, const SystemParams<S>& params) {
  return std::max(params.reidentify_min_inliers, fit ? fit->inliers + params.reidentify_keep_margin : 0.0);
}

/// best_shown_fit where the test may also change the fit: `accept(fit)`
/// returns the fit to act on (the same, or one solved again from it:
/// shown_or_colour_refined) or nothing; the first it returns one for, in
/// the order best_shown_fit tries them.
template <class S, class Accept>
std::optional<CandidateFit<S>> best_accepted_fit(std::vector<CandidateFit<S>> fits, double min_inliers,
                                                 Accept accept) {
  std::stable_sort(fits.begin(), fits.end(),
                   [](const CandidateFit<S>& a, const CandidateFit<S>& b) { return a.inliers > b.inliers; });
  for (const CandidateFit<S>& f : fits) {
    if (!(f.inliers > 0) || f.inliers < min_inliers) break;
    if (std::optional<CandidateFit<S>> taken = accept(f)) return taken;
  }
  return std::nullopt;
}

/// The fit to act on: of those with at least `min_inliers` (and some) of
/// the points on the surface, the one with most that `shown(fit)` accepts
/// (consistent_with_frame: the frame shows the model there), tried from
/// most to fewest (ties in list order); nothing when none. A fit the
/// frame refuses does not end the search: a wrong candidate of the same
/// class (a false object lost nearby) can fit the points a little better
/// than the right one, and would otherwise keep it from coming back (on
/// c211 of bench/generalisation.py, CPU, frame 210: a false book 0.858 and
/// refused, the lost book 0.806 and shown; the detection made a third book).
template <class S, class Shown>
std::optional<CandidateFit<S>> best_shown_fit(std::vector<CandidateFit<S>> fits, double min_inliers, Shown shown) {
  return best_accepted_fit(std::move(fits), min_inliers,
                           [&](const CandidateFit<S>& f) { return shown(f) ? std::optional{f} : std::nullopt; });
}

/// best_shown_fit with consistent_with_frame as the test: `object_of(i)` is
/// candidate i's model, `mask` the detection's pixels.
template <class S, Backend B, class ObjectOf>
std::optional<CandidateFit<S>> best_shown_fit(std::vector<CandidateFit<S>> fits, double min_inliers,
                                              ObjectOf object_of, const Frame<S, B>& frame, const Image<S, B>& mask,
                                              const PinholeCamera<S>& camera) {
  return best_shown_fit(std::move(fits), min_inliers, [&](const CandidateFit<S>& f) {
    return consistent_with_frame(object_of(f.candidate), f.T_volume_camera, frame, mask, camera);
  });
}

/// The fit to take of object `o` from `fit` (a turned fit of
/// reidentify): `fit` itself when the frame shows it in the mask and
/// wherever it is drawn and its colour agrees (shown_in_mask_and_view);
/// when only its colour disagrees, the fit solved again from it with the
/// model's colour (colour_refined_fit) if that keeps `min_inliers` of the
/// points on the surface and the frame shows it too; nothing otherwise. A
/// turned start settles where the shape fits, and on a face that depth
/// leaves free (a book's cover, a box's side cut by the image border) that
/// can be off the pattern by a slide: the colour's solve finds the rest.
/// Refinement runs only for fits the depth tests pass
/// (reidentify_colour_agreement > 0; with it 0 colour always agrees).
/// `refused_by_colour`, when given, is set where the depth tests passed and
/// the colour (refined or not) refused the fit.
template <class S, Backend B, class Norm, class Solver>
std::optional<CandidateFit<S>> shown_or_colour_refined(const ObjectModel<S, B>& o, const CandidateFit<S>& fit,
                                                       const DetectionTarget<S, B>& target, const Frame<S, B>& frame,
                                                       const SE3<S>& T_world_camera, const PinholeCamera<S>& camera,
                                                       const SystemParams<S>& params, const Norm& norm,
                                                       const Solver& solver, int frames_lost, double min_inliers,
                                                       RaycastResult<S, B>& drawn, bool* refused_by_colour = nullptr) {
  const auto shown_in_depth = [&](const SE3<S>& T) {
    return consistent_with_frame(o, T, frame, target.mask, camera) &&
           shown_in_view(o, T, frame, camera, params, drawn);
  };
  if (!shown_in_depth(fit.T_volume_camera)) return std::nullopt;
  if (colour_agrees(o, fit.T_volume_camera, frame, target.mask, params)) return fit;
  const auto refined = colour_refined_fit(o, target, frame, T_world_camera, params, norm, solver, frames_lost,
                                          fit.T_volume_camera);
  if (!refined || refined->first < min_inliers || !shown_in_depth(refined->second)) {
    if (refused_by_colour) *refused_by_colour = true;
    return std::nullopt;
  }
  return CandidateFit<S>{fit.candidate, refined->first, refined->second};
}

/// Whether a detection that lost objects fitted in depth but not in colour
/// (`refused`: their indices in `lost`, from reidentify) is kept from
/// making a new object: yes when one of them has not held a detection
/// since it was lost (LostObject::held_detection, then set for all of
/// them). A lost object fitted by its shape in the right place but
/// refused by its colour is mostly that object seen from a side its fits
/// could not place (on c211 of bench/generalisation.py the book at frame
/// 210, its fits correlating -0.87 to 0.24): a new model there is a second
/// fragment of it. Once per loss only: a second such detection makes its
/// object, since two objects of one shape and class are told apart by
/// their colour.
template <class S, Backend B>
bool hold_for_colour(std::vector<LostObject<S, B>>& lost, const std::vector<int>& refused) {
  bool hold = false;
  for (const int k : refused) hold = hold || !lost[std::size_t(k)].held_detection;
  if (hold)
    for (const int k : refused) lost[std::size_t(k)].held_detection = true;
  return hold;
}

/// Object `o` moved to where `fit` puts it (T_world_camera: this frame's camera).
template <class S, Backend B>
void move_to_fit(ObjectModel<S, B>& o, const SE3<S>& T_world_camera, const CandidateFit<S>& fit) {
  o.set_pose(T_world_camera * fit.T_volume_camera.inverse() * o.T_object_volume().inverse());
}

/// The mean association of Map::objects[k] over the pixels it is drawn on
/// (`seg` on the host), from the frame's association images; 1 when they
/// do not cover it (the E-step did not run) or it is drawn nowhere.
template <class S, Backend B>
double mean_association(const Frame<S, B>& frame, const std::vector<int>& seg, int k) {
  if (frame.associations.model_count() <= k + 1) return 1.0;
  const std::vector<S> q = frame.associations.image(k + 1).to_host();
  double sum = 0;
  int n = 0;
  for (std::size_t i = 0; i < seg.size() && i < q.size(); ++i)
    if (seg[i] == k + 1) sum += double(q[i]), ++n;
  return n > 0 ? sum / n : 1.0;
}

}  // namespace detail::reidentification

/// Tries to bring back a lost object of detection d's class: each is
/// aligned to the detection's points as detail::reidentification::fit_to_target
/// says, and of those with at least params.reidentify_min_inliers of the
/// points within a Huber delta of their surface, the best that the frame
/// shows where it would put it (consistent_with_frame) wins
/// (best_shown_fit). Where none does, or the winner leaves doubt (fewer
/// than reidentify_turn_below of the points, or drawn where the frame sees
/// through it), each is aligned again from its orientation turned by the
/// cube's 23 turns (turned_fits), and the best turned fit that the frame
/// shows, its colour agreeing or made to by colour_refined_fit
/// (shown_or_colour_refined), wins. The object
/// moves from map.lost back to map.objects at the solved pose; returns its
/// first-view weights (`outside`: see first_view_weights). `seg` and
/// `points` are the frame's segmentation and points on the host. With
/// `held`: where nothing came back but a lost object's fit was refused by
/// its colour alone, set when the detection should make no new object
/// (detail::reidentification::hold_for_colour; reidentify_colour_agreement).
template <class S, Backend B, class Norm, class Solver>
  requires RobustNorm<Norm, S> && PoseSolver<Solver, S>
std::optional<NewObjectWeights<S, B>> reidentify(Map<S, B>& map, const Frame<S, B>& frame, const Detections& det,
                                                 int d, const std::vector<int>& seg,
                                                 const std::vector<Vec3<S>>& points, const PinholeCamera<S>& camera,
                                                 const SystemParams<S>& params, const Norm& norm,
                                                 const Solver& solver, S outside, bool* held = nullptr) {
  if (held) *held = false;
  if (map.lost.empty() || int(map.objects.size()) >= params.max_objects) return std::nullopt;
  const Instance& inst = det.instances[std::size_t(d)];
  const auto target = detail::reidentification::detection_target(
      frame, det, d, seg, points, camera, params, params.reidentify_mask_pixels_for(camera.width, camera.height));
  if (!target) return std::nullopt;
  const auto frames_lost = [&](std::size_t k) { return std::max(map.frames - map.lost[k].lost_at, 1); };
  const auto object_of = [&](int k) -> const ObjectModel<S, B>& { return *map.lost[std::size_t(k)].object; };
  std::vector<std::size_t> of_class;  // the lost objects of the detection's class
  for (std::size_t k = 0; k < map.lost.size(); ++k)
    if (map.lost[k].object->class_name() == inst.class_name) of_class.push_back(k);
  std::vector<detail::reidentification::CandidateFit<S>> fits;
  for (const std::size_t k : of_class) {
    const auto [inliers, T] = detail::reidentification::fit_to_target(*map.lost[k].object, *target, frame,
                                                                       map.T_world_camera, params, norm, solver,
                                                                       frames_lost(k));
    fits.push_back({int(k), inliers, T});
  }
  std::vector<int> refused_by_colour;  // lost objects whose fit only the colour refused
  auto fit = detail::reidentification::best_shown_fit(
      fits, params.reidentify_min_inliers, [&](const detail::reidentification::CandidateFit<S>& f) {
        if (!detail::reidentification::consistent_with_frame(object_of(f.candidate), f.T_volume_camera, frame,
                                                              target->mask, camera))
          return false;
        if (detail::reidentification::colour_agrees(object_of(f.candidate), f.T_volume_camera, frame, target->mask,
                                                    params))
          return true;
        refused_by_colour.push_back(f.candidate);
        return false;
      });
  // An object that turned while out of view: from its last orientation the
  // alignment can settle on a wrong pose that still covers the detection
  // (on c215-tab900 of bench/generalisation.py a car turned 91 degrees was
  // fitted 14 cm and 83 degrees off, 0.85 of its points on the surface,
  // from its points cut by the image border; turned, 0.98).
  RaycastResult<S, B> drawn;
  const auto shown_everywhere = [&](const detail::reidentification::CandidateFit<S>& f) {
    return detail::reidentification::shown_in_view(object_of(f.candidate), f.T_volume_camera, frame, camera, params,
                                                   drawn);
  };
  if (!fits.empty() && params.reidentify_turn_below > 0 &&
      !(fit && fit->inliers >= params.reidentify_turn_below && shown_everywhere(*fit))) {
    std::vector<detail::reidentification::CandidateFit<S>> turned;
    for (const std::size_t k : of_class)
      for (const auto& [inliers, T] : detail::reidentification::turned_fits(
               *map.lost[k].object, *target, frame, map.T_world_camera, params, norm, solver, frames_lost(k)))
        turned.push_back({int(k), inliers, T});
    const double to_beat = detail::reidentification::turned_to_beat(fit, params);
    if (auto better = detail::reidentification::best_accepted_fit(
            std::move(turned), to_beat, [&](const detail::reidentification::CandidateFit<S>& f) {
              bool refused = false;
              auto taken = detail::reidentification::shown_or_colour_refined(
                  object_of(f.candidate), f, *target, frame, map.T_world_camera, camera, params, norm, solver,
                  frames_lost(std::size_t(f.candidate)), to_beat, drawn, &refused);
              if (refused) refused_by_colour.push_back(f.candidate);
              return taken;
            }))
      fit = better;
  }
  if (!fit) {
    if (held) *held = detail::reidentification::hold_for_colour(map.lost, refused_by_colour);
    return std::nullopt;
  }
  ObjectModel<S, B>& obj = map.bring_back(std::size_t(fit->candidate));
  detail::reidentification::move_to_fit(obj, map.T_world_camera, *fit);
  obj.add_class_score(inst.class_name, inst.score);
  obj.count_detected();
  return first_view_weights(det, d, seg, outside, camera, frame.points.backend());
}

/// Stage 5a, before detection handling (an extension of the paper;
/// docs/system.md, "Objects left behind"): a live object whose tracking
/// could not follow a fast move stays drawn where the object was, and the
/// detection of the object, matching no live object, would make a second
/// one. With params.relocalize_below > 0, every detection that matches no
/// live object (mask IoU, as handle_detections) is tried against the live
/// objects of its class that no detection matched and whose mean
/// association over the pixels they are drawn on is below
/// params.relocalize_below and that was detected at least
/// detail::reidentification::min_detections times (a model made from one
/// false positive, a patch of a room, fits the points of many a
/// detection): each is aligned to the detection's points as a
/// lost object is (reidentify), and the best with at least
/// reidentify_min_inliers of the points on its surface that is consistent
/// with the frame there (best_shown_fit) moves there, with its id and model. Returns the
/// ids of the objects moved; when there are any, the frame's associations
/// and rendering are out of date: associate
/// and render_models again before detection handling, which then matches
/// the detection to the moved object (System does). With `seen`
/// (seen_segmentation), detections match objects as handle_detections
/// matches them: by the pixels where the frame shows them.
template <class S, Backend B, class Norm, class Solver>
  requires RobustNorm<Norm, S> && PoseSolver<Solver, S>
std::vector<int> relocalize_objects(Map<S, B>& map, const Frame<S, B>& frame, const Detections& det,
                                    const std::vector<int>& seg, const PinholeCamera<S>& camera,
                                    const SystemParams<S>& params, const Norm& norm, const Solver& solver,
                                    const std::vector<int>* seen = nullptr) {
  std::vector<int> moved;
  if (!(params.relocalize_below > 0) || map.objects.empty() || det.instances.empty()) return moved;
  const DetectionMatch match =
      match_detections(mask_iou(det, seen ? *seen : seg, int(map.objects.size())), params.match_iou);
  // Candidates: unmatched objects of a class some unmatched detection has,
  // weakly associated. Their association images and the frame's points are
  // read on the host only when there is one.
  const auto unmatched_detection_of = [&](const std::string& class_name) {
    for (std::size_t d = 0; d < det.instances.size(); ++d)
      if (match.object_of[d] < 0 && det.instances[d].class_name == class_name) return true;
    return false;
  };
  std::vector<bool> candidate(map.objects.size(), true);
  for (int o : match.object_of)
    if (o >= 0) candidate[std::size_t(o)] = false;
  bool any = false;
  for (std::size_t k = 0; k < map.objects.size(); ++k) {
    const std::string& class_name = map.objects[k]->class_name();
    candidate[k] = candidate[k] && !params.ignores(class_name) && unmatched_detection_of(class_name) &&
                   map.objects[k]->existence_count() >= detail::reidentification::min_detections &&
                   detail::reidentification::mean_association(frame, seg, int(k)) < params.relocalize_below;
    any = any || candidate[k];
  }
  if (!any) return moved;
  const std::vector<Vec3<S>> points = frame.points.to_host();
  for (std::size_t d = 0; d < det.instances.size(); ++d) {
    if (match.object_of[d] >= 0) continue;
    const Instance& inst = det.instances[d];
    bool of_its_class = false;
    for (std::size_t k = 0; k < map.objects.size(); ++k)
      of_its_class = of_its_class || (candidate[k] && map.objects[k]->class_name() == inst.class_name);
    if (!of_its_class) continue;
    const auto target = detail::reidentification::detection_target(frame, det, int(d), seg, points, camera, params);
    if (!target) continue;
    std::vector<detail::reidentification::CandidateFit<S>> fits;
    for (std::size_t k = 0; k < map.objects.size(); ++k) {
      if (!candidate[k] || map.objects[k]->class_name() != inst.class_name) continue;
      const auto [inliers, T] = detail::reidentification::fit_to_target(*map.objects[k], *target, frame,
                                                                         map.T_world_camera, params, norm, solver);
      fits.push_back({int(k), inliers, T});
    }
    const auto fit = detail::reidentification::best_shown_fit(
        std::move(fits), params.reidentify_min_inliers,
        [&](int k) -> const ObjectModel<S, B>& { return *map.objects[std::size_t(k)]; }, frame, target->mask, camera);
    if (!fit) continue;
    ObjectModel<S, B>& obj = *map.objects[std::size_t(fit->candidate)];
    detail::reidentification::move_to_fit(obj, map.T_world_camera, *fit);
    candidate[std::size_t(fit->candidate)] = false;
    moved.push_back(obj.id());
  }
  return moved;
}

/// Where lost object `lost` may be now, besides where it was lost: if its
/// trajectory ends at the frame it was lost in and `timestamp` is at most
/// refind_moving_seconds after that, where its mean motion over its last
/// 0.2 s carried it (carry_on); else nothing.
template <class S, Backend B>
std::optional<SE3<S>> carried_on_pose(const Map<S, B>& map, const LostObject<S, B>& lost, double timestamp,
                                      const SystemParams<S>& params) {
  const Trajectory& camera = map.camera_trajectory;
  const std::size_t at = std::size_t(lost.lost_at);
  if (!(params.refind_moving_seconds > 0) || at >= camera.size()) return std::nullopt;
  const std::optional<SE3<double>> p = carry_on(map.record_of(lost.object->id()).trajectory, camera[at].timestamp,
                                                timestamp, double(params.refind_moving_seconds));
  if (!p || !is_finite(p->template cast<S>())) return std::nullopt;
  return p->template cast<S>();
}

/// Lost objects found again without a detection (params.refind_in_view;
/// docs/system.md, "Lost objects"), at the end of a frame: each lost object
/// (not lost this frame) is drawn where its motion would have carried it
/// (carried_on_pose: lost while moving, up to refind_moving_seconds ago),
/// else at the pose it was lost at, wherever its volume projects to at
/// least keep_mask_pixels pixels (surfaces of p_fg above 1/2, depth only).
/// It comes back to the map at that pose, tracked from the next frame,
/// where at least keep_mask_pixels of the pixels inside the visibility
/// border that it draws and no live object claims show the measured
/// surface within likelihood.sigma of its own, and those are at least
/// reidentify_min_inliers of the ones that do or show a surface behind it.
/// Only objects detected on at least min_detections detector frames are
/// looked for. An object that moved while it was out of view in any other way is drawn
/// where the frame now sees what was behind it, and stays lost until a
/// detection finds it. The ids found are added to result.reidentified;
/// returns how many.
template <class S, Backend B>
int refind_in_view(Map<S, B>& map, const Frame<S, B>& frame, const PinholeCamera<S>& camera,
                   const SystemParams<S>& params, FrameResult& result) {
  if (!params.refind_in_view || map.lost.empty() || map.camera_trajectory.empty()) return 0;
  const double now = map.camera_trajectory.back().timestamp;
  RaycastResult<S, B> drawn;
  // True where the frame shows o's model at its present pose.
  const auto shown = [&](const ObjectModel<S, B>& o) {
    const SE3<S> T_volume_camera = (o.pose() * o.T_object_volume()).inverse() * map.T_world_camera;
    return detail::reidentification::shown_in_view(o, T_volume_camera, frame, camera, params, drawn);
  };
  int found = 0;
  for (std::size_t k = 0; k < map.lost.size() && int(map.objects.size()) < params.max_objects;) {
    ObjectModel<S, B>& o = *map.lost[k].object;
    if (!detail::reidentification::may_come_back(map.lost[k], map.frames, params)) {
      ++k;
      continue;
    }
    const SE3<S> lost_pose = o.pose();
    bool back = false;
    if (const std::optional<SE3<S>> carried = carried_on_pose(map, map.lost[k], now, params)) {
      o.restore_pose(*carried);
      back = shown(o);
      if (!back) o.restore_pose(lost_pose);
    }
    if (!back && !shown(o)) {
      ++k;
      continue;
    }
    result.found_again(map.bring_back(k).id(), FoundBy::in_view);
    ++found;
  }
  return found;
}

}  // namespace emfusion
