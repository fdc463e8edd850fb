// Stage 7 of the EM-Fusion frame, the object lifecycle (paper sec. 3.5 and
// 4.2 with the reference implementation's rules): an object is deleted when
// its existence probability falls below 0.1 on a detector frame, when it is
// no longer visible (fewer than 40x40 rendered or associated pixels inside a
// 20-pixel border), or, while visible, when its mean association over its
// rendered mask falls below 0.1. One deleted as not visible or as weakly
// associated is kept as lost for re-identification (an extension of the
// paper; docs/system.md, "Lost objects"): the first is out of sight, the
// second is drawn where the camera no longer sees it, as after a fast move
// its tracking could not follow. Objects created or re-identified on a
// detector frame are spared the visibility rule until first seen, and not
// tracked meanwhile while the image border cuts them; objects standing
// still that the camera leaves keep their pose once too little of them is
// in view to align, and objects hidden behind a nearer surface move on at
// their velocity, instead of being tracked (all hold_decisions, which
// System runs before tracking the objects, so that the held ones are not
// solved). Partly hidden objects whose solves slid where the frame sees
// through the model stay at their starts (keep_starts_seen_through, which
// System runs right after tracking them).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <numbers>
#include <optional>
#include <utility>
#include <vector>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include "emfusion/core/camera.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/slam/frame.hpp"
#include "emfusion/slam/frame_result.hpp"
#include "emfusion/slam/map.hpp"
#include "emfusion/slam/motion_prediction.hpp"
#include "emfusion/slam/params.hpp"
#include "emfusion/volume/raycast.hpp"

namespace emfusion {

/// What the deletion rules count of one object over the image: its
/// rendered pixels, the association summed over them, the pixels inside
/// the visibility border that it renders or that the E-step gives it (q >
/// 0.5), and those the E-step gives it anywhere.
struct ObjectPixels {
  double association_sum = 0;
  int rendered = 0, rendered_inner = 0, associated_inner = 0, associated = 0;
  EMF_HD ObjectPixels operator+(const ObjectPixels& o) const {
    return {association_sum + o.association_sum, rendered + o.rendered, rendered_inner + o.rendered_inner,
            associated_inner + o.associated_inner, associated + o.associated};
  }
};

namespace detail::lifecycle {

template <class S>
struct CountObjectPixels {
  ImageView<const int> label;
  ImageView<const S> association;  // empty: not computed this frame
  int model, border;
  EMF_HD ObjectPixels operator()(int i) const {
    const bool inner = label.inside_border(i, border);
    const bool drawn = label[i] == model;
    const S q = association.empty() ? S(0) : association[i];
    ObjectPixels p;
    p.association_sum = drawn ? double(q) : 0.0;
    p.rendered = drawn ? 1 : 0;
    p.rendered_inner = drawn && inner ? 1 : 0;
    p.associated_inner = inner && q > S(0.5) ? 1 : 0;
    p.associated = q > S(0.5) ? 1 : 0;
    return p;
  }
};

struct AddObjectPixels {
  EMF_HD ObjectPixels operator()(const ObjectPixels& a, const ObjectPixels& b) const { return a + b; }
};

/// ObjectPixels as five doubles (counts below 2^53 are exact), the form
/// grouped_accumulate sums.
struct PixelSums {
  static constexpr int components = 5;
  double v[components] = {0, 0, 0, 0, 0};
  EMF_HD double& component(int c) { return v[c]; }
  EMF_HD double component(int c) const { return v[c]; }
  EMF_HD PixelSums& operator+=(const PixelSums& o) {
    for (int c = 0; c < components; ++c) v[c] += o.v[c];
    return *this;
  }
  ObjectPixels counts() const {
    return {v[0], int(v[1]), int(v[2]), int(v[3]), int(v[4])};
  }
};

/// Pixel i's part of object g's counts (its association image `q`).
template <class S>
struct AddObjectPixel {
  ImageView<const int> label;
  int border;
  EMF_HD void operator()(int g, const ImageView<const S>& q, int i, PixelSums& acc) const {
    const ObjectPixels p = CountObjectPixels<S>{label, q, g + 1, border}(i);
    acc.v[0] += p.association_sum;
    acc.v[1] += double(p.rendered), acc.v[2] += double(p.rendered_inner), acc.v[3] += double(p.associated_inner);
    acc.v[4] += double(p.associated);
  }
};

/// Of the pixels inside the border that a model's rendering draws, those
/// whose measured surface agrees with the model's and those where the frame
/// shows a surface in front of it.
struct DrawnCover {
  int drawn = 0, agree = 0, front = 0;
};

/// An object's last rendering, as the hidden rule reads it (empty: none).
template <class S>
struct DrawnModel {
  ImageView<const std::uint8_t> hit;
  ImageView<const S> depth;
};

/// DrawnCover as three doubles, the form grouped_accumulate sums.
struct CoverSums {
  static constexpr int components = 3;
  double v[components] = {0, 0, 0};
  EMF_HD double& component(int c) { return v[c]; }
  EMF_HD double component(int c) const { return v[c]; }
  EMF_HD CoverSums& operator+=(const CoverSums& o) {
    for (int c = 0; c < components; ++c) v[c] += o.v[c];
    return *this;
  }
  DrawnCover counts() const { return {int(v[0]), int(v[1]), int(v[2])}; }
};

/// Pixel i's part of object g's DrawnCover: drawn inside the border, the
/// frame's surface within `tolerance` of the model's, or nearer by more
/// than twice that. With `interior`, only pixels whose four neighbours are
/// drawn too (the model's outline, where a model fused from few frames
/// and the frame's silhouette part by a pixel or two, left out).
template <class S>
struct AddCoverPixel {
  ImageView<const Vec3<S>> points;
  int border;
  S tolerance;
  bool interior = false;
  EMF_HD void operator()(int, const DrawnModel<S>& m, int i, CoverSums& acc) const {
    if (m.hit.empty() || !m.hit[i] || !points.inside_border(i, border)) return;
    if (interior) {
      const int u = i % m.hit.width, v = i / m.hit.width;
      if (u == 0 || v == 0 || u + 1 == m.hit.width || v + 1 == m.hit.height || !m.hit[i - 1] || !m.hit[i + 1] ||
          !m.hit[i - m.hit.width] || !m.hit[i + m.hit.width])
        return;
    }
    const S gap = points[i].z() - m.depth[i];  // NaN where nothing was measured
    acc.v[0] += 1.0;
    if (std::fabs(gap) <= tolerance) acc.v[1] += 1.0;
    if (gap < -S(2) * tolerance) acc.v[2] += 1.0;
  }
};

}  // namespace detail::lifecycle

/// What counting every object's pixels keeps between frames.
template <class S, Backend B>
using ObjectPixelsWorkspace = PerGroupWorkspace<ImageView<const S>, detail::lifecycle::PixelSums, B>;

/// What counting how the frame covers every object's model keeps between frames.
template <class S, Backend B>
using DrawnCoverWorkspace = PerGroupWorkspace<detail::lifecycle::DrawnModel<S>, detail::lifecycle::CoverSums, B>;

/// Hands free heap memory back to the system. glibc keeps freed blocks
/// below its dynamic mmap threshold (which rises to the size of the largest
/// block freed, so object volumes land there) on its heap: without this a
/// CPU system's resident memory stays at the peak of the object volumes it
/// ever held (docs/system.md, "Memory bound"). A no-op with other C libraries.
inline void release_free_host_memory() {
#if defined(__GLIBC__)
  malloc_trim(0);
#endif
}

/// Map::objects[k]'s pixel counts in the frame (ObjectPixels), reduced on the backend.
template <class S, Backend B>
ObjectPixels object_pixels(const Frame<S, B>& frame, int k, int border) {
  const Associations<S, B>& q = frame.associations;
  const ImageView<const S> a = k + 1 < q.model_count() ? q.image(k + 1).view() : ImageView<const S>{};
  return transform_reduce_index(frame.segmentation.backend(), frame.segmentation.size(),
                                detail::lifecycle::CountObjectPixels<S>{frame.segmentation.view(), a, k + 1, border},
                                ObjectPixels{}, detail::lifecycle::AddObjectPixels{});
}

/// object_pixels of Map::objects[0..count-1], in one pass over the frame
/// on the backend and one copy: one after another, each object's reduction
/// and its copy to the host added 0.03 ms a frame per object on a GPU
/// (H100, bench_system --objects 1 to 16).
template <class S, Backend B>
std::vector<ObjectPixels> all_object_pixels(const Frame<S, B>& frame, int count, int border,
                                            ObjectPixelsWorkspace<S, B>& ws) {
  const Associations<S, B>& q = frame.associations;
  std::vector<ImageView<const S>> images;
  for (int k = 0; k < count; ++k)
    images.push_back(k + 1 < q.model_count() ? q.image(k + 1).view() : ImageView<const S>{});
  std::vector<ObjectPixels> out;
  for (const auto& sum : reduce_per_group(frame.segmentation.backend(), images, frame.segmentation.size(),
                                          detail::lifecycle::AddObjectPixel<S>{frame.segmentation.view(), border},
                                          detail::lifecycle::PixelSums{}, ws))
    out.push_back(sum.counts());
  return out;
}

/// How this frame meets every live object's model as drawn at its last
/// pose (its rendering of the last frame), in one pass over the frame: per
/// object the pixels drawn inside the visibility border, those where the
/// frame's surface lies within likelihood.sigma of the model's, and those
/// where it is nearer by more than twice that (detail::lifecycle::
/// DrawnCover). Zero for young objects and for objects without a rendering
/// of the frame's size. It needs only the frame's points, so it can run
/// before the E-step: partly_hidden and hold_decisions's hidden rule read it.
template <class S, Backend B>
std::vector<detail::lifecycle::DrawnCover> drawn_covers(const Map<S, B>& map, const Frame<S, B>& frame,
                                                        const SystemParams<S>& params,
                                                        DrawnCoverWorkspace<S, B>* workspace = nullptr) {
  const std::size_t n = map.objects.size();
  std::vector<detail::lifecycle::DrawnModel<S>> models(n);
  for (std::size_t k = 0; k < n; ++k) {
    const ObjectModel<S, B>& o = *map.objects[k];
    const RaycastResult<S, B>& r = o.rendering();
    if (!map.is_young(o.id()) && r.hit.same_size(frame.points.width(), frame.points.height()))
      models[k] = {std::as_const(r.hit).view(), std::as_const(r.depth).view()};
  }
  const int border = params.visibility_border_for(frame.points.width());
  DrawnCoverWorkspace<S, B> local;
  std::vector<detail::lifecycle::DrawnCover> covers;
  for (const detail::lifecycle::CoverSums& c :
       reduce_per_group(frame.points.backend(), models, frame.points.size(),
                        detail::lifecycle::AddCoverPixel<S>{frame.points.view(), border, params.likelihood.sigma},
                        detail::lifecycle::CoverSums{}, workspace ? *workspace : local))
    covers.push_back(c.counts());
  return covers;
}

/// Per live object, whether it is partly hidden (SystemParams::
/// predict_hidden_share): its model, drawn at its last pose over at least
/// keep_mask_pixels inside the border, lies behind a nearer surface of the
/// frame on at least that share of them (`covers`: drawn_covers of a frame
/// of width x height). All false when the share is 0.
template <class S>
std::vector<bool> partly_hidden(const std::vector<detail::lifecycle::DrawnCover>& covers, const SystemParams<S>& params,
                                int width, int height) {
  std::vector<bool> out(covers.size(), false);
  if (!(params.predict_hidden_share > S(0))) return out;
  const int min_pixels = params.keep_mask_pixels_for(width, height);
  for (std::size_t k = 0; k < covers.size(); ++k) {
    const detail::lifecycle::DrawnCover& c = covers[k];
    out[k] = c.drawn >= min_pixels && double(c.front) >= double(params.predict_hidden_share) * double(c.drawn);
  }
  return out;
}

/// How this frame meets object `o`'s model cast at `T_world_object` from
/// the camera at `T_world_camera`: of its pixels at least `inside` from the
/// image's edge (with `interior`, not on its outline), those a nearer
/// surface covers and those within likelihood.sigma of the frame's
/// (detail::lifecycle::DrawnCover). One depth-only ray cast, into `cast`.
template <class S, Backend B>
detail::lifecycle::DrawnCover cover_at_pose(const ObjectModel<S, B>& o, const SE3<S>& T_world_object,
                                            const SE3<S>& T_world_camera, const Frame<S, B>& frame,
                                            const PinholeCamera<S>& camera, const SystemParams<S>& params,
                                            int inside, bool interior, RaycastResult<S, B>& cast,
                                            DrawnCoverWorkspace<S, B>& workspace) {
  const SE3<S> T_volume_camera = (T_world_object * o.T_object_volume()).inverse() * T_world_camera;
  RaycastParams<S> rp;
  rp.surface = false;
  raycast(o.volume(), camera, o.volume().pose() * T_volume_camera, cast, rp, &o.foreground());
  const std::vector<detail::lifecycle::DrawnModel<S>> one{
      {std::as_const(cast.hit).view(), std::as_const(cast.depth).view()}};
  return reduce_per_group(frame.points.backend(), one, frame.points.size(),
                          detail::lifecycle::AddCoverPixel<S>{frame.points.view(), inside, params.likelihood.sigma,
                                                              interior},
                          detail::lifecycle::CoverSums{}, workspace)[0]
      .counts();
}

/// Puts every partly hidden object (`hidden_in_part`, partly_hidden's)
/// whose solve was taken (`tracks`, track_objects's, from `starts`,
/// predict_objects's) back at the pose its solve started from when the
/// frame sees through its model there more than at the start and does not
/// agree with it correspondingly more: of the model's pixels inside the
/// visibility border (cast at either pose, its outline left out), those
/// that no nearer surface covers and that do not agree with the frame (its
/// surface behind the model's, or nothing measured) grew by more than
/// params.slide_seen_through_share of the pixels drawn at the solved pose,
/// and those that agree by less than half as many. What a nearer surface
/// leaves of an object in view can fit its model slid along itself: on
/// h244-noisy of bench/generalisation.py a capsule hidden behind a book
/// but for its top went 8 cm up its axis in two frames, as many pixels
/// agreeing and the frame seeing the wall through the model's top; its
/// start, its prediction (which the frame agreed with at least as well as
/// with its last pose), had half as many seen through. Sets
/// PoseTrack::kept_start; returns how many were kept. Two ray casts per
/// partly hidden object tracked.
template <class S, Backend B>
int keep_starts_seen_through(Map<S, B>& map, const Frame<S, B>& frame, const PinholeCamera<S>& camera,
                             const SystemParams<S>& params, const std::vector<PoseStarts<S>>& starts,
                             const std::vector<bool>& hidden_in_part, std::vector<PoseTrack>& tracks,
                             DrawnCoverWorkspace<S, B>* workspace = nullptr) {
  const std::size_t n = map.objects.size();
  detail::require(starts.size() == n && hidden_in_part.size() == n && tracks.size() == n, "keep_starts_seen_through",
                  "need one start, one partly hidden flag and one track per live object");
  if (!(params.slide_seen_through_share > S(0))) return 0;
  const int border = params.visibility_border_for(frame.points.width());
  RaycastResult<S, B> cast;
  DrawnCoverWorkspace<S, B> local;
  DrawnCoverWorkspace<S, B>& ws = workspace ? *workspace : local;
  // Pixels of a cover that no nearer surface covers and that do not agree.
  const auto seen_through = [](const detail::lifecycle::DrawnCover& c) { return c.drawn - c.front - c.agree; };
  int kept = 0;
  for (std::size_t k = 0; k < n; ++k) {
    PoseTrack& t = tracks[k];
    if (!hidden_in_part[k] || t.outcome != TrackingOutcome::tracked) continue;
    ObjectModel<S, B>& o = *map.objects[k];
    const SE3<S> start = t.from_prediction && starts[k].predicted ? *starts[k].predicted : starts[k].previous;
    const detail::lifecycle::DrawnCover at_start =
        cover_at_pose(o, start, map.T_world_camera, frame, camera, params, border, true, cast, ws);
    const detail::lifecycle::DrawnCover solved =
        cover_at_pose(o, o.pose(), map.T_world_camera, frame, camera, params, border, true, cast, ws);
    const int more_seen = seen_through(solved) - seen_through(at_start), more_agree = solved.agree - at_start.agree;
    if (double(more_seen) > double(params.slide_seen_through_share) * double(solved.drawn) &&
        2 * more_agree < more_seen) {
      o.set_pose(start);
      t.kept_start = true;
      ++kept;
    }
  }
  return kept;
}

/// A held object's pose in this frame and its outcome (hold_decisions).
template <class S>
struct HeldPose {
  SE3<S> pose;
  TrackingOutcome outcome = TrackingOutcome::not_tracked;
};

/// Objects the frame does not show well enough to track, decided before
/// their solves (from this frame's E-step at the predicted poses, the
/// objects' renderings of the last frame and, for the leaving rule, a cast
/// of the model at its last pose): per object the pose it goes to
/// and its outcome, not_tracked (young, leaving) or moved_on (hidden), or nothing
/// where it is tracked. System has track_objects skip the held objects
/// and then puts them at their poses (apply_holds).
/// - The grace's other half (SystemParams::hold_unseen_objects): a young
///   object (Map::young) that this frame's E-step shows cut by the image
///   border or gone from it (fewer than keep_mask_pixels of its
///   association above 1/2 inside the visibility border, and less there
///   than in the border band, or fewer than min_object_terms in all) goes
///   back to the pose it had before the frame (`before`). Where the frame
///   sees through it there (its model, cast at `before` from this frame's
///   camera, border band included, outline left out: of its pixels no
///   nearer surface covers, at least min_object_terms and fewer than two in
///   three agree with the frame) it has moved on: it leaves Map::young, and
///   delete_objects loses it unless it is visible. A small object wholly in
///   view is tracked as ever.
/// - Leaving (SystemParams::leaving_share): any other object that stands
///   still (SystemParams::leaving_still over the last 0.2 s), of whose
///   extent, seen from this frame's camera at its last pose, less than
///   leaving_share lies inside the image less the visibility border
///   (shows_less_than), and that the frame still shows where it stands
///   (its model, cast there from this frame's camera, agrees with the
///   frame on two in three of the pixels no nearer surface covers, or
///   fewer than keep_mask_pixels are left to tell) keeps its pose
///   `before`, not_tracked: a partial view slid such objects centimetres
///   (docs/system.md, "Held while the camera leaves it").
/// - Hidden (SystemParams::hold_occluded_objects): any other object whose
///   model, as drawn at its last pose (its rendering of the last frame),
///   covers at least keep_mask_pixels inside the border and is more often
///   behind a surface of the frame nearer by twice likelihood.sigma than
///   within likelihood.sigma of it, and to which this frame's E-step gives
///   fewer than keep_mask_pixels inside the border (one that shows as much
///   of itself as keeps it visible is tracked on that), moves on at its
///   mean velocity of the last 0.2 s (carry_on; stays at `before` without
///   one) for up to hidden_moving_seconds after its last tracked frame,
///   then stays: something passes in front of it, and the part left of it
///   would pull it along with the surface in front (docs/system.md, "Held
///   while hidden"). Its record keeps since when (ObjectRecord::hidden_since).
/// The segmentation is the last frame's, whose labels may no longer be the
/// objects' order, so it is not used. With the hidden rule one pass over
/// the frame for every object's cover (none where `drawn_covers_given`
/// holds this frame's drawn_covers); one more for the E-step counts on
/// frames with young objects or an object the cover finds behind others.
template <class S, Backend B>
std::vector<std::optional<HeldPose<S>>> hold_decisions(
    Map<S, B>& map, const Frame<S, B>& frame, const PinholeCamera<S>& camera, const SystemParams<S>& params,
    const std::vector<SE3<S>>& before, double timestamp, ObjectPixelsWorkspace<S, B>* workspace = nullptr,
    DrawnCoverWorkspace<S, B>* cover_workspace = nullptr,
    const std::vector<detail::lifecycle::DrawnCover>* drawn_covers_given = nullptr) {
  const int n = int(map.objects.size());
  detail::require(int(before.size()) == n, "hold_decisions", "need one pose per live object");
  std::vector<std::optional<HeldPose<S>>> held(static_cast<std::size_t>(n));
  bool any_young = false;
  for (const auto& o : map.objects) any_young = any_young || map.is_young(o->id());
  const bool young_rule = params.hold_unseen_objects && any_young;
  const bool leaving_rule = params.leaving_share > S(0);
  if (!young_rule && !params.hold_occluded_objects && !leaving_rule) return held;
  const int border = params.visibility_border_for(frame.segmentation.width());
  const int min_pixels = params.keep_mask_pixels_for(frame.segmentation.width(), frame.segmentation.height());
  // The hidden rule: more of its model is behind a nearer surface than
  // shows, and the E-step gives it fewer pixels than keep it visible
  // (with as many, what shows of it is enough to track it on: c214's book
  // behind a chair's slats, held, fell behind its turn) and not twice as
  // many as show (then the frame shows it beside where it is drawn: it is
  // displaced, not hidden, and tracking it brings it back). Every object's
  // cover in one pass; the E-step counts in another only where a rule
  // needs them.
  std::vector<detail::lifecycle::DrawnCover> covers;
  if (params.hold_occluded_objects)
    covers = drawn_covers_given ? *drawn_covers_given : drawn_covers(map, frame, params, cover_workspace);
  detail::require(covers.empty() || int(covers.size()) == n, "hold_decisions", "need one drawn cover per live object");
  const auto covered = [&](int k) {
    const detail::lifecycle::DrawnCover& c = covers[std::size_t(k)];
    return c.drawn >= min_pixels && c.front > c.agree;
  };
  bool any_covered = false;
  for (int k = 0; k < n && params.hold_occluded_objects; ++k) any_covered = any_covered || covered(k);
  ObjectPixelsWorkspace<S, B> local;
  const std::vector<ObjectPixels> pixels = young_rule || any_covered
                                               ? all_object_pixels(frame, n, border, workspace ? *workspace : local)
                                               : std::vector<ObjectPixels>{};
  const auto hidden = [&](int k) {
    if (!covered(k)) return false;
    const int associated = pixels[std::size_t(k)].associated_inner;
    return associated < min_pixels && associated <= 2 * covers[std::size_t(k)].agree;
  };
  // The young rule: cut by the border or gone.
  const auto unseen = [&](int k) {
    const ObjectPixels& px = pixels[std::size_t(k)];
    const bool cut = 2 * px.associated_inner < px.associated, gone = px.associated < params.min_object_terms;
    return px.associated_inner < min_pixels && (cut || gone);
  };
  const Trajectory& trajectory = map.camera_trajectory;
  // The leaving rule: standing still, too little of its extent in view to
  // align it, and the frame still shows it where it stands: of its model's
  // pixels, cast at its last pose from this frame's camera, that no nearer
  // surface covers, at least two in three within likelihood.sigma of the
  // frame's (one that starts to move while held is tracked again), unless
  // fewer than keep_mask_pixels are left to tell (a sliver's edges disagree
  // with any model). The cast only for objects that pass the first two.
  RaycastResult<S, B> cast;
  DrawnCoverWorkspace<S, B> cast_cover;
  // Object o's model cast at T_world_object from this frame's camera.
  const auto cover_at = [&](const ObjectModel<S, B>& o, const SE3<S>& T_world_object, int inside, bool interior) {
    return cover_at_pose(o, T_world_object, map.T_world_camera, frame, camera, params, inside, interior, cast,
                         cast_cover);
  };
  const auto still_shown = [&](const ObjectModel<S, B>& o, const SE3<S>& T_world_object) {
    const detail::lifecycle::DrawnCover c = cover_at(o, T_world_object, border, false);
    const int open = c.drawn - c.front;
    return open < min_pixels || 3 * c.agree >= 2 * open;
  };
  // Whether the frame sees through a young object held where it was found:
  // of its model's pixels, cast there (border band included: a young
  // object held is mostly there; not its outline, where a model fused from
  // a frame or two parts from the frame's silhouette), that no nearer
  // surface covers, at least min_object_terms and fewer than two in three
  // agree with the frame. Then it has moved on (on s208-long900-fast of
  // bench/generalisation.py a cup re-identified at the border as it came
  // into view at 1.2 cm a frame, held, fell 1.3 -> 9.7 cm behind).
  const auto seen_through = [&](const ObjectModel<S, B>& o, const SE3<S>& T_world_object) {
    const detail::lifecycle::DrawnCover c = cover_at(o, T_world_object, 0, true);
    const int open = c.drawn - c.front;
    return open >= params.min_object_terms && 3 * c.agree < 2 * open;
  };
  const auto leaving = [&](int k) {
    if (!leaving_rule || trajectory.empty()) return false;
    const ObjectModel<S, B>& o = *map.objects[std::size_t(k)];
    const SE3<S>& pose = before[std::size_t(k)];
    return standing_still(map.record_of(o.id()).trajectory, trajectory.back().timestamp, 0.2,
                          double(params.leaving_still.translation),
                          double(params.leaving_still.rotation_degrees) * std::numbers::pi / 180.0) &&
           shows_less_than(o, pose, map.T_world_camera, camera, border, double(params.leaving_share)) &&
           still_shown(o, pose);
  };
  for (int k = 0; k < n; ++k) {
    const ObjectModel<S, B>& o = *map.objects[std::size_t(k)];
    const bool young = map.is_young(o.id());
    ObjectRecord& record = map.record_of(o.id());
    std::optional<HeldPose<S>>& h = held[std::size_t(k)];
    if ((young && young_rule && unseen(k)) || (!young && leaving(k))) {
      h = HeldPose<S>{before[std::size_t(k)], TrackingOutcome::not_tracked};
      // Seen through where it is held, it has moved on: its grace ends
      // (delete_objects then loses it unless it is visible).
      if (young && seen_through(o, before[std::size_t(k)])) std::erase(map.young, o.id());
    } else if (!young && params.hold_occluded_objects && hidden(k)) {
      h = HeldPose<S>{before[std::size_t(k)], TrackingOutcome::moved_on};
      // From its pose of the last frame (a frame or two dropped between:
      // still within a second), while it was tracked at most
      // hidden_moving_seconds ago.
      if (!trajectory.empty()) {
        const double last = trajectory.back().timestamp;
        if (std::isnan(record.hidden_since)) record.hidden_since = last;
        if (timestamp - record.hidden_since <= double(params.hidden_moving_seconds))
          if (const std::optional<SE3<double>> p = carry_on(record.trajectory, last, timestamp, 1.0))
            if (is_finite(p->template cast<S>())) h->pose = p->template cast<S>();
      }
    }
    if (!h || h->outcome != TrackingOutcome::moved_on) record.hidden_since = std::numeric_limits<double>::quiet_NaN();
  }
  return held;
}

/// Puts each object held (hold_decisions) at its pose and its outcome into
/// `tracks` (one per live object, from track_objects); returns how many.
template <class S, Backend B>
int apply_holds(Map<S, B>& map, const std::vector<std::optional<HeldPose<S>>>& held, std::vector<PoseTrack>& tracks) {
  const std::size_t n = map.objects.size();
  detail::require(held.size() == n && tracks.size() == n, "apply_holds",
                  "need one decision and one track per live object");
  int count = 0;
  for (std::size_t k = 0; k < n; ++k) {
    if (!held[k]) continue;
    map.objects[k]->restore_pose(held[k]->pose);
    tracks[k].outcome = held[k]->outcome;
    ++count;
  }
  return count;
}

/// What tracking did with Map::objects[k] this frame and what the deletion
/// rules see of it (`associated`: the association images are this frame's).
/// `pixels`: its object_pixels, when already counted (all_object_pixels).
template <class S, Backend B>
ObjectStatus object_status(const Map<S, B>& map, const Frame<S, B>& frame, int k, bool associated,
                           const SystemParams<S>& params, const ObjectPixels* pixels = nullptr) {
  const ObjectModel<S, B>& o = *map.objects[std::size_t(k)];
  const ObjectPixels px =
      pixels ? *pixels : object_pixels(frame, k, params.visibility_border_for(frame.segmentation.width()));
  ObjectStatus status;
  status.id = o.id();
  if (std::size_t(k) < frame.object_tracks.size()) {
    const PoseTrack& t = frame.object_tracks[std::size_t(k)];
    status.tracking = t.outcome;
    status.step = t.step;
    status.from_prediction = t.from_prediction;
    status.attempts = t.attempts;
    status.confirmed = t.confirmed;
    status.kept_start = t.kept_start;
  }
  status.rendered_pixels = px.rendered_inner;
  status.associated_pixels = px.associated_inner;
  // Visible where the model is drawn or where the frame's points belong
  // to it: a model built from a few views renders a smaller mask than the
  // object shows (about 20 % on the dynamic sequences), the E-step sees
  // the measured object whole.
  status.visible_pixels = std::max(px.rendered_inner, px.associated_inner);
  if (!params.ignores(o.class_name()) && associated)
    status.mean_association = px.rendered > 0 ? px.association_sum / px.rendered : 0.0;
  return status;
}

/// Stage 7 on a mapped frame: applies the deletion rules to the objects
/// that existed before the frame (all but the last `created`, which
/// detection handling added), reports every one in result.object_status,
/// moves those deleted as not visible or weakly associated to map.lost
/// (existence deletes for good), forgets lost objects
/// beyond lost_object_frames and max_lost_objects, and renews the grace of
/// young objects on detector frames. A young object's grace ends when it is
/// visible, or when the frame neither draws it nor associates it on
/// min_object_terms pixels anywhere or on any pixel inside the visibility
/// border (it has left the view: lost at once).
/// `tracked`: tracking ran this frame, so association images exist for
/// every object that existed before it.
/// `workspace` (optional) keeps the buffers of the objects' pixel counts.
template <class S, Backend B>
void delete_objects(Map<S, B>& map, const Frame<S, B>& frame, const SystemParams<S>& params, FrameResult& result,
                    bool detector_frame, int created, bool tracked,
                    ObjectPixelsWorkspace<S, B>* workspace = nullptr) {
  const int old_objects = int(map.objects.size()) - created;
  ObjectPixelsWorkspace<S, B> local;
  const std::vector<ObjectPixels> pixels =
      all_object_pixels(frame, old_objects, params.visibility_border_for(frame.segmentation.width()),
                        workspace ? *workspace : local);
  const int min_pixels = params.keep_mask_pixels_for(frame.segmentation.width(), frame.segmentation.height());
  // Grace lasts until the object is first seen or the detector runs again.
  if (detector_frame) map.young.clear();
  std::vector<DeletionReason> why(map.objects.size(), DeletionReason::none);
  const bool associated = params.use_association && tracked;
  for (int k = 0; k < old_objects; ++k) {
    const ObjectModel<S, B>& o = *map.objects[std::size_t(k)];
    ObjectStatus status = object_status(map, frame, k, associated, params, &pixels[std::size_t(k)]);
    const bool visible = status.visible_pixels >= min_pixels;
    // The grace is for an object the frame shows too little of to count
    // as visible, not for one it shows nothing of: one neither drawn nor
    // associated on min_object_terms pixels anywhere, or on any pixel
    // inside the visibility border, has left the view.
    const ObjectPixels& px = pixels[std::size_t(k)];
    if ((px.associated < params.min_object_terms && px.rendered < params.min_object_terms) ||
        (px.associated_inner == 0 && px.rendered_inner == 0))
      std::erase(map.young, o.id());
    if (detector_frame && o.existence_probability() < params.min_existence)
      why[std::size_t(k)] = DeletionReason::existence;
    else if (!params.ignores(o.class_name()) && !visible && !map.is_young(o.id()))
      why[std::size_t(k)] = DeletionReason::not_visible;
    else if (visible && status.mean_association < params.min_association)
      why[std::size_t(k)] = DeletionReason::weak_association;
    if (visible) std::erase(map.young, o.id());
    status.deleted = why[std::size_t(k)];
    result.object_status.push_back(status);
  }
  std::vector<std::unique_ptr<ObjectModel<S, B>>> keep;
  for (std::size_t k = 0; k < map.objects.size(); ++k) {
    if (why[k] == DeletionReason::none) {
      keep.push_back(std::move(map.objects[k]));
      continue;
    }
    ObjectRecord& rec = map.record_of(map.objects[k]->id());
    rec.deleted = true;
    rec.reason = why[k];
    result.deleted.push_back(map.objects[k]->id());
    if (why[k] != DeletionReason::existence && params.lost_object_frames > 0 && params.max_lost_objects > 0)
      map.lost.push_back(LostObject<S, B>{std::move(map.objects[k]), map.frames});
  }
  map.objects = std::move(keep);
  // Lost objects are forgotten when too old, the oldest first beyond the cap.
  std::erase_if(map.lost, [&](const LostObject<S, B>& l) { return map.frames - l.lost_at > params.lost_object_frames; });
  while (int(map.lost.size()) > params.max_lost_objects) map.lost.erase(map.lost.begin());
  if (detector_frame && params.young_object_grace) {
    map.young = result.created;
    map.young.insert(map.young.end(), result.reidentified.begin(), result.reidentified.end());
  }
}

}  // namespace emfusion
