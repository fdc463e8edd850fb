// Lost objects found again in what no model explains (an extension of the
// paper; docs/system.md, "Lost objects"): between detector frames an object
// that comes back into view, anywhere, is a patch of measured points that
// no live object is drawn on and that lies off the background's surface.
// Each such patch (a connected group of pixels, depth-continuous) is treated
// as a detection of unknown class: every lost object is aligned to it as
// re-identification aligns one to a detection (fit_to_target), and the best
// fit the frame shows (best_shown_fit) brings its object back. While a lost
// object may come back, the background does not fuse those points
// (hold_unexplained): it would take an object that stands still in within a
// few frames, from its edges and from space it had not seen before.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <type_traits>
#include <utility>
#include <vector>

#include <thrust/functional.h>

#include "emfusion/core/image.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/robust/norms.hpp"
#include "emfusion/slam/frame.hpp"
#include "emfusion/slam/frame_result.hpp"
#include "emfusion/slam/map.hpp"
#include "emfusion/slam/params.hpp"
#include "emfusion/slam/reidentification.hpp"

namespace emfusion {

namespace detail::unexplained {

/// How far behind an unobserved point MarkUnexplained looks for a surface
/// the background has observed: this many steps of half its truncation
/// (1 m at the paper's 10 cm).
inline constexpr int behind_steps = 20;

/// 1 where pixel i (inside the visibility border) shows a measured point
/// that no live object is drawn on (`segmentation` 0) or claims in the
/// E-step (the background's association is 1 where the point is in no
/// live object's volume: the parts of a live object its model has not
/// seen yet are not unexplained) and that lies further
/// than `tolerance` from the background's surface where the background has
/// observed that place (with `across`, the stored SDF divided by the length
/// of its gradient where that exceeds 1: a surface seen at a grazing angle
/// stores distances along the rays, longer than across it; x251's kitchen
/// floor 2 m away held 3-5 cm a little off its surface). Where it has
/// not, the point is unexplained only if it stands in front of a surface
/// the background has observed (in_front):
/// something in space a moving object hid before (on c215 of the
/// generalisation benchmark, a lost bottle uncovered by a teddy bear
/// walking away from in front of it). A place seen for the first time with
/// nothing known behind it is new background, not an object.
template <class S, class View>
struct MarkUnexplained {
  ImageView<const Vec3<S>> points;
  ImageView<const int> segmentation;
  ImageView<const S> background_association;  // the E-step's q for the background
  View background;
  SE3<S> T_volume_camera;
  int border;
  S tolerance;
  bool across = false;  ///< SystemParams::refind_unexplained_across
  std::uint8_t* out;

  /// True where the ray through camera-frame point p, beyond p by more
  /// than `tolerance`, meets observed free space and then an observed
  /// surface within behind_steps steps of half a truncation.
  EMF_HD bool in_front(const Vec3<S>& p) const {
    const Vec3<S> dir = normalized(p);
    const S step = S(0.5) * background.truncation;
    bool free_space = false;
    for (int k = 0; k < behind_steps; ++k) {
      S f;
      if (!background.sample_observed(T_volume_camera * (p + (tolerance + S(k) * step) * dir), f)) continue;
      if (!(f > S(0))) return free_space;
      free_space = true;
    }
    return false;
  }

  EMF_HD void operator()(int i) const {
    std::uint8_t mark = 0;
    const Vec3<S>& p = points[i];
    S sdf;
    if (points.inside_border(i, border) && segmentation[i] <= 0 && p.z() > S(0) &&
        background_association[i] >= S(0.99)) {
      const Vec3<S> x = T_volume_camera * p;
      if (background.sample_observed(x, sdf)) {
        // Across the surface: a grazing surface's stored distances run
        // along the rays, longer by its gradient's length.
        Vec3<S> g;
        S stretch = S(1);
        if (across && std::fabs(sdf) > tolerance && background.observed_gradient(x, g)) {
          const S length = norm(g);
          if (length > S(1)) stretch = length;
        }
        mark = std::fabs(sdf) > tolerance * stretch ? 1 : 0;
      } else
        mark = in_front(p) ? 1 : 0;
    }
    out[i] = mark;
  }
};

/// MarkUnexplained's marks of the frame into `marked` (allocated as needed)
/// for pixels inside `border`, with the background's association image
/// `background_association`.
template <class S, Backend B>
void mark_unexplained(const Map<S, B>& map, const Frame<S, B>& frame, const SystemParams<S>& params, int border,
                      const Image<S, B>& background_association, Image<std::uint8_t, B>& marked) {
  const B& backend = frame.points.backend();
  // Every pixel is written below: the contents of a kept image do not matter.
  if (!marked.same_size(frame.points.width(), frame.points.height()))
    marked = Image<std::uint8_t, B>(frame.points.width(), frame.points.height(), std::uint8_t(0), backend);
  map.background.visit([&](const auto& volume) {
    using View = std::decay_t<decltype(volume.view())>;
    for_each_index(backend, frame.points.size(),
                   MarkUnexplained<S, View>{frame.points.view(), frame.segmentation.view(),
                                            background_association.view(), volume.view(),
                                            volume.pose().inverse() * map.T_world_camera, border,
                                            S(params.refind_unexplained_sigmas) * params.likelihood.sigma,
                                            params.refind_unexplained_across, marked.view().data});
  });
}

/// The background's weight: the E-step's association, 0 where marked.
template <class S>
struct HeldWeight {
  ImageView<const S> association;
  ImageView<const std::uint8_t> marked;
  S* out;
  EMF_HD void operator()(int i) const { out[i] = marked[i] ? S(0) : association[i]; }
};

/// 1 for a marked pixel (the count of MarkUnexplained's marks).
struct CountMarked {
  ImageView<const std::uint8_t> marked;
  EMF_HD int operator()(int i) const { return int(marked[i]); }
};

/// How far (pixels at 640 wide, scaled with the image) groups_of joins
/// marked pixels across unmarked ones: an object standing in view whose
/// middle the background took in on a detector frame (the hold leaves
/// those alone) shows as two parts on either side of that band, neither of
/// keep_mask_pixels (c215-tab900's bottle at frame 350: 1910 of its 3412
/// pixels marked, split by a band about 15 pixels wide).
inline constexpr int bridge_pixels_at_640 = 20;

/// The connected groups of marked pixels of a width x height image, each
/// as its pixel indices; those of fewer than `min_pixels` are left out. A
/// marked pixel joins its four neighbours and, in each of the four
/// directions, the first marked pixel 2 to `bridge` pixels away, where
/// their depths differ by at most `depth_gap`.
template <class S>
std::vector<std::vector<int>> groups_of(const std::vector<std::uint8_t>& marked, const std::vector<Vec3<S>>& points,
                                        int width, int height, S depth_gap, int min_pixels, int bridge = 1) {
  std::vector<std::vector<int>> out;
  std::vector<std::uint8_t> seen(marked.size(), 0);
  std::vector<int> stack;
  const auto join = [&](int i, int j) {
    if (!seen[std::size_t(j)] && std::fabs(points[std::size_t(j)].z() - points[std::size_t(i)].z()) <= depth_gap) {
      seen[std::size_t(j)] = 1;
      stack.push_back(j);
    }
  };
  const int du[4] = {-1, 1, 0, 0}, dv[4] = {0, 0, -1, 1};
  for (int start = 0; start < width * height; ++start) {
    if (!marked[std::size_t(start)] || seen[std::size_t(start)]) continue;
    std::vector<int> group;
    stack.assign(1, start);
    seen[std::size_t(start)] = 1;
    while (!stack.empty()) {
      const int i = stack.back();
      stack.pop_back();
      group.push_back(i);
      const int u = i % width, v = i / width;
      const auto at = [&](int d, int k) {  // pixel k steps in direction d, -1 outside the image
        const int uk = u + k * du[d], vk = v + k * dv[d];
        return uk < 0 || vk < 0 || uk >= width || vk >= height ? -1 : vk * width + uk;
      };
      for (int d = 0; d < 4; ++d)
        if (const int j = at(d, 1); j >= 0 && marked[std::size_t(j)]) join(i, j);
      for (int d = 0; d < 4; ++d)
        for (int k = 2, j; k <= bridge && (j = at(d, k)) >= 0; ++k)
          if (marked[std::size_t(j)]) {
            join(i, j);
            break;
          }
    }
    if (int(group.size()) >= min_pixels) out.push_back(std::move(group));
  }
  return out;
}

/// False when two of the fits put at least `min_inliers` of the points on
/// their surfaces and the second comes within `margin` of the best: without
/// a class, such a group could be either object (a mug and a round box seen
/// from one side fit the same few points; on c214 of the generalisation
/// benchmark the two swapped places).
template <class S>
bool unambiguous(const std::vector<reidentification::CandidateFit<S>>& fits, double min_inliers, double margin) {
  double best = 0, second = 0;
  for (const auto& f : fits)
    if (f.inliers >= min_inliers) {
      second = std::max(second, std::min(best, f.inliers));
      best = std::max(best, f.inliers);
    }
  return !(second >= min_inliers && best - second < margin);
}

/// True when at least 1 % of a group's pixels lie on the visibility
/// border's edge (the outermost pixels MarkUnexplained marks): the image
/// cuts the object it shows, and the part in view fits a lost object at a
/// wrong pose as well as at the right one (on c215 a car coming back across
/// the border was placed 24 cm off), or fits another lost object better
/// than its own (on c214, on the H200, a mug coming back across the border
/// was taken as a lost round box 48 cm away). refind_unexplained looks in
/// such a group only while one lost object is looked for, and only from
/// the lost objects' last orientations.
inline bool cut_by_border(const std::vector<int>& group, int width, int height, int border) {
  std::size_t edge = 0;
  for (int i : group) {
    const int u = i % width, v = i / width;
    edge += u == border || v == border || u == width - 1 - border || v == height - 1 - border;
  }
  return 100 * edge >= group.size();
}

/// A group of pixels as re-identification's target: its points, their
/// centroid and viewing ray, and the group as a weight image on the backend.
template <class S, Backend B>
reidentification::DetectionTarget<S, B> target_of(const std::vector<int>& group, const std::vector<Vec3<S>>& points,
                                                  int width, int height, const B& backend) {
  reidentification::DetectionTarget<S, B> t;
  t.points = group.size();
  t.centroid = Vec3<S>::zero();
  std::vector<S> mask(std::size_t(width) * std::size_t(height), S(0));
  for (int i : group) {
    t.centroid = t.centroid + points[std::size_t(i)];
    mask[std::size_t(i)] = S(1);
  }
  t.centroid = t.centroid / S(group.size());
  t.ray = normalized(t.centroid);
  t.mask = Image<S, Host>::from_host(width, height, mask).template to<B>(backend);
  return t;
}

/// A group in which no lost object was found (refind_unexplained): the
/// centroid of its points (world frame), its pixels, the frame, and the ids
/// of the lost objects tried.
template <class S>
struct TriedGroup {
  Vec3<S> centroid;
  std::size_t pixels = 0;
  int frame = 0;
  std::vector<int> candidates;
};

/// A group tried that long ago (frames) is tried again whatever it looks
/// like: the camera has moved on, and a fit from another view may hold.
inline constexpr int retry_frames = 15;
/// ... and earlier if it has grown by this share of its pixels, or its
/// centroid moved further than same_group_distance (metres).
inline constexpr double retry_growth = 0.1;
inline constexpr double same_group_distance = 0.05;

/// True when `tried` holds the group (centroid `c`, `pixels`) as tried on
/// the same candidates within retry_frames frames of `frame`, and it has
/// not grown by retry_growth since: no lost object was found in it then,
/// and none will be now (a static thing no detector knows, which the
/// background does not take in while lost objects are looked for, would
/// otherwise be fitted to every lost object on every frame).
template <class S>
bool tried_before(const std::vector<TriedGroup<S>>& tried, const Vec3<S>& c, std::size_t pixels, int frame,
                  const std::vector<int>& candidates) {
  for (const TriedGroup<S>& t : tried)
    if (frame - t.frame < retry_frames && t.candidates == candidates &&
        double(norm(t.centroid - c)) <= same_group_distance &&
        double(pixels) < (1.0 + retry_growth) * double(t.pixels))
      return true;
  return false;
}

}  // namespace detail::unexplained

/// What refind_unexplained keeps between frames: the image of marks, and
/// the groups in which no lost object was found, so that they are not
/// fitted again on every frame (detail::unexplained::tried_before).
template <class S, Backend B>
struct UnexplainedWorkspace {
  Image<std::uint8_t, B> marks;
  std::vector<detail::unexplained::TriedGroup<S>> tried;
};

/// The background's weights for stage 6 (integrate_models) while a lost
/// object may come back (params.hold_unexplained): on a frame without
/// detections (`detector_frame` false) in which some lost object is looked
/// for (may_come_back, reidentification.hpp), `weights` becomes the
/// E-step's background association with 0 at every pixel MarkUnexplained
/// marks (the whole image, no border), and the function returns true;
/// otherwise it returns
/// false and leaves `weights` alone (the background then fuses with the
/// E-step's image). Without the hold the background takes in what no model
/// explains within a few frames, and an object that comes back and stands
/// still is gone from the marks before refind_unexplained sees
/// keep_mask_pixels of it: points within the tolerance of the background's
/// surface (where the object meets what stands behind and under it) are
/// fused and pull the surface towards it, so that on the next frame more of
/// it lies within the tolerance, and points in space the background had not
/// observed become background at once. On detector frames the background
/// fuses every pixel as before: something that stays unexplained (a thing
/// no detector knows, put down for good) is still taken in, more slowly.
/// `marks` (optional) keeps the image of marks between frames.
template <class S, Backend B>
bool hold_unexplained(const Map<S, B>& map, const Frame<S, B>& frame, const SystemParams<S>& params,
                      bool detector_frame, Image<S, B>& weights, Image<std::uint8_t, B>* marks = nullptr) {
  if (!params.hold_unexplained || detector_frame || !map.started || frame.associations.model_count() < 1)
    return false;
  if (std::none_of(map.lost.begin(), map.lost.end(), [&](const LostObject<S, B>& l) {
        return detail::reidentification::may_come_back(l, map.frames, params);
      }))
    return false;
  Image<std::uint8_t, B> local;
  Image<std::uint8_t, B>& marked = marks ? *marks : local;
  const Image<S, B>& association = frame.associations.image(0);
  detail::unexplained::mark_unexplained(map, frame, params, 0, association, marked);
  const B& backend = association.backend();
  if (!weights.same_size(association.width(), association.height()))
    weights = Image<S, B>(association.width(), association.height(), S(0), backend);
  for_each_index(backend, association.size(),
                 detail::unexplained::HeldWeight<S>{association.view(), std::as_const(marked).view(),
                                                    weights.view().data});
  return true;
}

/// Stage 9, at the end of a frame after refind_in_view
/// (params.refind_unexplained_every > 0: on every that many frames): lost
/// objects (not lost this frame, not ignored) found again in what no model
/// explains. The frame's unexplained pixels (MarkUnexplained: off the
/// background's surface by more than refind_unexplained_sigmas times
/// likelihood.sigma, on no live object, inside the visibility border) are
/// counted on the backend; only where there are at least keep_mask_pixels
/// of them (what keeps a live object visible) are they and the points read
/// on the host and grouped (groups_of: depth-continuous within object_depth_gap,
/// across unmarked bands up to bridge_pixels_at_640 wide). Each
/// group of at least keep_mask_pixels and at most a quarter of the image
/// (cut by the image border, cut_by_border, only while one lost object is
/// looked for) is a target for every lost object, of any class, detected
/// on at least two
/// detector frames (min_detections): aligned to it as re-identification
/// aligns (fit_to_target), a fit that moves the object's box centre further
/// from where it was last tracked than refind_unexplained_speed times the
/// time since is dropped; when two fits put reidentify_min_inliers of the
/// points on their surfaces within reidentify_keep_margin of each other the
/// group is left alone (unambiguous); otherwise the best fit with at least
/// reidentify_min_inliers that the frame shows there (best_shown_fit,
/// consistent_with_frame) brings its object back at the solved pose,
/// tracked from the next frame. In a group wholly in view, where that fit
/// leaves doubt (none, or fewer than reidentify_turn_below of the points),
/// the objects whose fit put at least reidentify_min_inliers of the points
/// on their surfaces are aligned turned too (turned_fits, as on a
/// detection), and a turned fit shown there that adds
/// reidentify_keep_margin to the share wins: an object that turned while
/// out of view. Not on detector frames, nor after another
/// object came back this frame (the segmentation and the E-step do not show
/// those). Its id is added to result.reidentified; returns how many came
/// back. `workspace` (optional) keeps the image of marks between frames
/// and the groups in which no lost object was found: those are not fitted
/// again for retry_frames frames unless they grow by retry_growth or the
/// lost objects looked for change (without it, every group on every frame).
template <class S, Backend B, class Norm, class Solver>
  requires RobustNorm<Norm, S> && PoseSolver<Solver, S>
int refind_unexplained(Map<S, B>& map, const Frame<S, B>& frame, const PinholeCamera<S>& camera,
                       const SystemParams<S>& params, const Norm& norm, const Solver& solver, FrameResult& result,
                       UnexplainedWorkspace<S, B>* workspace = nullptr) {
  if (params.refind_unexplained_every <= 0 || map.frames % params.refind_unexplained_every != 0) return 0;
  // The segmentation and the E-step do not show objects created or brought
  // back this frame: their pixels would be unexplained.
  if (result.detector_frame || !result.reidentified.empty()) return 0;
  const auto is_candidate = [&](const LostObject<S, B>& l) {
    return detail::reidentification::may_come_back(l, map.frames, params);
  };
  std::vector<int> candidates;  // the ids looked for
  for (const LostObject<S, B>& l : map.lost)
    if (is_candidate(l)) candidates.push_back(l.object->id());
  if (candidates.empty() || int(map.objects.size()) >= params.max_objects || frame.associations.model_count() < 1)
    return 0;
  const int width = camera.width, height = camera.height;
  // As many as keep a live object: one found on fewer would be lost again.
  const int min_points = params.keep_mask_pixels_for(width, height);
  const int border = params.visibility_border_for(width);
  const B& backend = frame.points.backend();
  UnexplainedWorkspace<S, B> local;
  UnexplainedWorkspace<S, B>& ws = workspace ? *workspace : local;
  std::erase_if(ws.tried, [&](const auto& t) { return map.frames - t.frame >= detail::unexplained::retry_frames; });
  Image<std::uint8_t, B>& marked = ws.marks;
  detail::unexplained::mark_unexplained(map, frame, params, border, frame.associations.image(0), marked);
  const int count = transform_reduce_index(backend, marked.size(), detail::unexplained::CountMarked{std::as_const(marked).view()},
                                           0, thrust::plus<int>());
  if (count < min_points) return 0;
  const std::vector<Vec3<S>> points = frame.points.to_host();
  const double now = map.camera_trajectory.empty() ? 0.0 : map.camera_trajectory.back().timestamp;
  const std::vector<std::vector<int>> groups =
      detail::unexplained::groups_of(marked.to_host(), points, width, height, params.object_depth_gap, min_points,
                                     std::max(1, detail::unexplained::bridge_pixels_at_640 * width / 640));
  int found = 0;
  RaycastResult<S, B> drawn;
  for (const std::vector<int>& group : groups) {
    const bool cut = detail::unexplained::cut_by_border(group, width, height, border);
    if (4 * group.size() > std::size_t(width) * std::size_t(height) || int(map.objects.size()) >= params.max_objects ||
        (candidates.size() > 1 && cut))
      continue;
    const auto target = detail::unexplained::target_of<S, B>(group, points, width, height, backend);
    const Vec3<S> centroid = map.T_world_camera * target.centroid;
    if (detail::unexplained::tried_before(ws.tried, centroid, group.size(), map.frames, candidates)) continue;
    const auto frames_lost = [&](std::size_t k) { return std::max(map.frames - map.lost[k].lost_at, 1); };
    // Its box centre can have gone refind_unexplained_speed times the time
    // since it was last tracked.
    const auto within_reach = [&](std::size_t k, const SE3<S>& T) {
      const ObjectModel<S, B>& o = *map.lost[k].object;
      const Vec3<S> centre = S(0.5) * o.volume().view().extent();
      const double moved = double(emfusion::norm((map.T_world_camera * T.inverse()) * centre - o.volume().pose() * centre));
      const double seconds = std::max(now - map.record_of(o.id()).last_timestamp, 0.0);
      return moved <= double(params.refind_unexplained_speed) * seconds;
    };
    std::vector<detail::reidentification::CandidateFit<S>> fits;
    for (std::size_t k = 0; k < map.lost.size(); ++k) {
      if (!is_candidate(map.lost[k])) continue;
      const auto [inliers, T] = detail::reidentification::fit_to_target(*map.lost[k].object, target, frame,
                                                                         map.T_world_camera, params, norm, solver,
                                                                         frames_lost(k));
      if (within_reach(k, T)) fits.push_back({int(k), inliers, T});
    }
    // The frame must show the fit in the group's pixels and, as far as no
    // live object covers it, wherever it is drawn: a model turned the wrong
    // way fits the part of an object in view, and is drawn where the frame
    // sees through it.
    const auto shown = [&](const detail::reidentification::CandidateFit<S>& f) {
      return detail::reidentification::shown_in_mask_and_view(*map.lost[std::size_t(f.candidate)].object,
                                                               f.T_volume_camera, frame, target.mask, camera, params,
                                                               drawn);
    };
    const bool unambiguous =
        detail::unexplained::unambiguous(fits, params.reidentify_min_inliers, params.reidentify_keep_margin);
    auto fit = unambiguous ? detail::reidentification::best_shown_fit(fits, params.reidentify_min_inliers, shown)
                           : std::nullopt;
    // A group wholly in view that a lost object's fit from its last
    // orientation leaves in doubt (fewer than reidentify_turn_below of the
    // points, or not shown): the objects that fit at least
    // reidentify_min_inliers of it are aligned turned too, as on a detection
    // (turned_fits): an object that turned while out of view. On a group the
    // border cuts every turn fits its part (twenty-fifth session).
    if (!cut && unambiguous && params.reidentify_turn_below > 0 &&
        !(fit && fit->inliers >= params.reidentify_turn_below)) {
      std::vector<detail::reidentification::CandidateFit<S>> turned;
      for (const auto& f : fits) {
        if (f.inliers < params.reidentify_min_inliers) continue;
        const std::size_t k = std::size_t(f.candidate);
        for (const auto& [share, T] : detail::reidentification::turned_fits(
                 *map.lost[k].object, target, frame, map.T_world_camera, params, norm, solver, frames_lost(k)))
          if (within_reach(k, T)) turned.push_back({f.candidate, share, T});
      }
      const double to_beat = detail::reidentification::turned_to_beat(fit, params);
      if (auto better = detail::reidentification::best_shown_fit(std::move(turned), to_beat, shown)) fit = better;
    }
    if (!fit) {
      // Remembered, so that it is not fitted again until it changes.
      std::erase_if(ws.tried, [&](const auto& t) {
        return double(emfusion::norm(t.centroid - centroid)) <= detail::unexplained::same_group_distance;
      });
      ws.tried.push_back({centroid, group.size(), map.frames, candidates});
      continue;
    }
    ObjectModel<S, B>& obj = map.bring_back(std::size_t(fit->candidate));
    detail::reidentification::move_to_fit(obj, map.T_world_camera, *fit);
    result.found_again(obj.id(), FoundBy::unexplained);
    ++found;
  }
  return found;
}

}  // namespace emfusion
