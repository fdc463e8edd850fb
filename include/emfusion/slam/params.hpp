// Every parameter of the EM-Fusion system in one struct, with the paper's
// and the reference implementation's values as defaults
// (shared/PARAMETERS.md; docs/parameters.md explains each one).
#pragma once

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include "emfusion/core/error.hpp"
#include "emfusion/detect/proposal.hpp"
#include "emfusion/likelihood/measurement_likelihood.hpp"
#include "emfusion/preprocess/bilateral_filter.hpp"
#include "emfusion/solve/solvers.hpp"
#include "emfusion/volume/integrate.hpp"

namespace emfusion {

/// The largest motion a pose may make from one frame to the next; a solved
/// pose that moves further is refused and the previous one kept (hostile
/// input: a frame of another scene, a solve that ran away). Infinity turns a
/// bound off.
template <class S>
struct MotionBound {
  S translation = S(0.3);       ///< metres per frame
  S rotation_degrees = S(30);   ///< degrees per frame

  /// True if moving `translation_m` metres and `rotation_rad` radians exceeds the bound.
  bool exceeded_by(double translation_m, double rotation_rad) const {
    const double degrees = rotation_rad * (180.0 / std::numbers::pi);
    return !(translation_m <= double(translation)) || !(degrees <= double(rotation_degrees));
  }
};

template <class S>
struct SystemParams {
  // Preprocessing.
  BilateralParams<S> bilateral{};
  /// Metres: depth beyond this is no measurement (like 0, NaN, inf or a
  /// negative value), so that sensor garbage never carves the map; 0 = no
  /// limit. Structured-light sensors stop well before 10 m.
  S max_depth = S(10);

  // Background volume (slam/background.hpp): sparse voxel blocks,
  // unbounded, at most background_blocks of them (the memory bound); with
  // sparse_background = false the paper's cube of background_voxels^3 with
  // the camera at the centre of one face in the first frame.
  bool sparse_background = true;
  int background_blocks = 1 << 18;  ///< 8^3-voxel blocks: 1 GiB of float voxels at most
  int background_voxels = 512;
  S background_voxel_size = S(0.01);
  S truncation_voxels = S(10);  ///< truncation of every volume, in its voxels

  // Objects.
  int object_voxels = 64;        ///< initial resolution of a new object
  S object_padding = S(2);       ///< volume side / largest extent of the 10-90 % box
  /// A detection's points split into groups at depth gaps wider than this;
  /// only the largest group sizes a new or growing volume (largest_depth_group).
  S object_depth_gap = S(0.1);
  int max_object_voxels = 256;   ///< resizing stops growing a volume beyond this per axis
  int max_objects = 16;          ///< live objects; detections beyond it create none (bounds memory)

  // Tracking (eq. 8/9).
  S huber_voxels = S(2);         ///< Huber delta in voxels of the tracked volume
  /// The reference solver (tau 1e3, eps2 1e-8) with tau 1e-3 and eps2 1e-6:
  /// the same poses within 0.03 cm on every shared sequence in a third of
  /// the iterations (docs/decisions.md). LevenbergMarquardtParams{} is the
  /// reference. lm.converged_step stays off for objects: on the
  /// generalisation benchmark it moved them both ways (docs/decisions.md,
  /// "Solver stops, pyramid and pixel stride"); the camera's solve has
  /// camera_converged_step and camera_converged_gain.
  LevenbergMarquardtParams lm = fast_lm();
  int pixel_stride = 1;          ///< object solves use every n-th pixel in x and y
  /// Colour in the objects' models (volume/intensity_grid.hpp): each
  /// object fuses the frames' gray values per voxel, and its solves add a
  /// colour term per pixel, the gray-value difference to the model times
  /// this many voxels of SDF residual per unit of gray value (so the Huber
  /// delta of huber_voxels voxels falls at a difference of huber_voxels /
  /// object_colour_weight). Needs the frames' colour (System::process with
  /// an intensity image) and the library's Levenberg-Marquardt; 0 (the
  /// default) aligns depth alone, as the paper does.
  S object_colour_weight = S(0);
  /// Coarse-to-fine levels of every object solve (SdfAlignmentParams::
  /// pyramid_levels): level l takes every (pixel_stride * 2^l)-th pixel; 1:
  /// the paper's single level.
  int pyramid_levels = 1;
  /// The camera's solve has its own stride, pyramid and stop: it aligns a
  /// whole frame, mostly background, against the largest map, where
  /// track_camera measured the same ATE with them in a fraction of the time
  /// (docs/decisions.md, "The camera's own solve settings; work objects
  /// skip"); objects keep pixel_stride, pyramid_levels and lm as they are.
  /// The paper: 1, 1, 0, 0.
  int camera_pixel_stride = 0;           ///< 0: auto_pixel_stride (every 2nd pixel of a 640x480 frame)
  int camera_pyramid_levels = 3;         ///< as pyramid_levels, for the camera
  double camera_converged_step = 1e-5;   ///< lm.converged_step for the camera (0: off)
  /// lm.converged_gain for the camera (0: off): its solve ends once a step
  /// lowers the cost by at most this fraction (docs/decisions.md, "The
  /// camera's solve ends where the cost stops falling").
  double camera_converged_gain = 3e-5;
  /// Start the camera's and every object's solve at its constant-velocity
  /// prediction (slam/motion_prediction.hpp) when the frame agrees with it at
  /// least as well as with the last pose, and associate the frame there.
  bool predict_motion = false;
  /// A solve whose outcome is not `tracked` is run again from the other
  /// start (the last pose when it began at the prediction, or the reverse).
  bool retry_tracking = false;
  /// Each object's solve pulled towards its start (the pose it had, or its
  /// prediction) by six terms of this weight each, in surface points
  /// (solve/pose_prior.hpp): the directions its depth does not observe (a
  /// cylinder's axis seen from its side, the plane of a flat side) stay
  /// there. 0: off (the paper).
  S object_pose_prior = S(0);
  /// Depth-noise weighting of tracking terms (SdfAlignmentParams): 0 = off.
  S depth_noise_reference = S(0);
  /// An object whose alignment has fewer terms keeps its previous pose.
  int min_object_terms = 100;
  /// Camera tracking with fewer terms keeps the previous pose and the frame
  /// is not mapped; a frame with fewer valid depth pixels does not start the map.
  int min_camera_terms = 100;
  /// Per-frame bounds on the camera's and every object's motion: a solve
  /// that moves further is refused (FrameResult reports jump_rejected).
  MotionBound<S> max_camera_motion{};
  MotionBound<S> max_object_motion{};
  /// An object's solve refused by max_object_motion is taken after all
  /// when it is the last of this many consecutive frames' refused solves,
  /// each within max_object_motion of the one before (0: never): solves
  /// that agree with each other from frame to frame find the object, and
  /// the pose they move away from is what is wrong (an object that fell
  /// behind in a fast turn, or was found again at a pose a few degrees or
  /// centimetres off, would otherwise stay there while every later solve is
  /// refused; track_objects, docs/system.md "Refused solves that agree").
  int confirm_jump_frames = 2;

  // Association (eq. 5/7).
  LikelihoodParams<S> likelihood{};

  // Mapping (eq. 10): the paper's update plus the silhouette guard (free
  // space is not carved along silhouettes): on synthetic scenes without it a
  // static camera drifts 5 mm in one frame, with it 0.3 mm; on redkitchen_300
  // camera ATE is 2.24 cm with it and 2.25 cm without (docs/system.md). The
  // background also forgets what it holds 0.2 truncations or more in front
  // of points an object drawn there owns (unowned_free_from: the trace of an
  // object that stood still goes once it moves; docs/system.md, "Forgetting
  // the traces"); 0 turns that off.
  IntegrationParams<S> background_integration = forgetting_traces();
  IntegrationParams<S> object_integration = guarded();

  // Detections (sec. 3.5).
  double match_iou = 0.2;             ///< a detection matches an object above this mask IoU
  /// 40 x 40: smaller detections create nothing, objects with fewer visible
  /// pixels are deleted. This and visibility_border are pixels of a 640x480
  /// image; the system scales them to other image sizes (area and width).
  int min_mask_pixels = 1600;
  S max_object_distance = S(5);       ///< metres from the camera to a new object's centre
  double max_volume_iou = 0.5;        ///< a new volume must overlap every other less
  double max_covered_fraction = 0.5;  ///< drop a mask when existing objects cover this much of it
  double min_existence = 0.1;         ///< delete when Ex / (Ex + NonEx) falls below
  int visibility_border = 20;         ///< pixels (at 640 wide); mask pixels nearer the image edge do not count
  /// An object already in the map stays visible down to this fraction of
  /// min_mask_pixels (hysteresis: a new object still needs all of them);
  /// 1 is the paper's single threshold.
  double keep_visible_fraction = 1.0;
  double min_association = 0.1;       ///< delete when the mean association over the mask falls below
  std::vector<std::string> static_classes = default_static_classes();
  bool ignore_person = false;         ///< keep person objects for association only

  // Objects that leave the view (an extension of the paper, docs/system.md,
  // "Lost objects"). An object deleted as not visible or as weakly
  // associated while visible is kept as lost, with
  // neither tracking nor mapping, for lost_object_frames frames (0: deleted
  // for good, the paper's rule), at most max_lost_objects of them. A
  // detection of its class that matches no live object is aligned to each
  // lost object; the one on whose surface at least reidentify_min_inliers of
  // the detection's points lie returns, with its id and model, instead of a
  // new object.
  int lost_object_frames = 900;
  int max_lost_objects = 8;
  double reidentify_min_inliers = 0.6;
  /// A re-identification or relocalisation fit from the object's last pose
  /// is kept unless a fit from another start puts this much more of the
  /// detection's points on its surface (a symmetric object fits as well
  /// turned; docs/system.md, "Lost objects"). 1: the last pose always wins
  /// when it fits; 0: the best fit wins.
  double reidentify_keep_margin = 0.05;
  /// Every solve that fits a lost object to a detection or to a group of
  /// unexplained pixels (and a merge's) pulled towards its start by six
  /// terms of this weight, as object_pose_prior pulls tracking
  /// (solve/pose_prior.hpp): what the points do not observe (a ball's
  /// turn, a cylinder's slide along its axis) stays where the start put it
  /// instead of drifting, and a fit a few frames after the loss is not
  /// refused as a turn it cannot have made (docs/system.md, "Lost
  /// objects"). 0: off.
  S reidentify_pose_prior = S(0);
  /// When the best fit of a detection from a lost object's last
  /// orientation puts fewer than this share of its points on the surface,
  /// or is not shown in view (the model, drawn there, agrees with the
  /// frame wherever it is drawn), the lost objects are also aligned from
  /// their last orientation turned by each of the 23 other turns that map
  /// a cube onto itself; a turned fit shown in view that adds
  /// reidentify_keep_margin to that share wins (docs/system.md, "Lost
  /// objects": an object that turned while out of view). 0: the last
  /// orientation only.
  double reidentify_turn_below = 0.9;
  /// Colour in re-identification: a fit of a lost object (to a detection,
  /// from its last orientation or turned, or to a group of unexplained
  /// pixels) is taken only where the gray values of the model's colour at
  /// the points on its surface and the frame's there correlate by at least
  /// this much (docs/system.md, "Lost objects": a part view of a box fits
  /// as well turned by a quarter). Every object then keeps its colour (as
  /// object_colour_weight does), which needs the frames' colour; tracking
  /// stays on depth unless object_colour_weight is set. 0: off.
  double reidentify_colour_agreement = 0;
  /// The turned starts (reidentify_turn_below) in two rounds, with the
  /// library's Levenberg-Marquardt: every start solved for
  /// reidentify_turned_rank_iterations iterations, then only this many,
  /// those with the largest share of the detection's points on the surface
  /// there, solved again from their starts to the end (the fits solving
  /// every start gives them; docs/system.md, "Lost objects"). 0: every
  /// start solved to the end (the whole generalisation benchmark found
  /// the same fits with 12: docs/decisions.md).
  int reidentify_turned_keep = 12;
  /// The iterations of the first round of reidentify_turned_keep (at least 1).
  int reidentify_turned_rank_iterations = 3;
  /// A detection re-identifies a lost object with at least this fraction
  /// of min_mask_pixels points of its own (creating an object takes all of
  /// them, the paper's 40x40 pixels): the known model, its fit and its
  /// drawn cover check a smaller one (docs/system.md, "Lost objects"). 1:
  /// the creation rule.
  double reidentify_mask_fraction = 0.5;
  /// Objects left behind (docs/system.md): on a detector frame, a live
  /// object that no detection matched, that was detected twice or more and
  /// whose mean association over the pixels it is drawn on is below this
  /// is tried against the unmatched detections of its class, as a lost
  /// object is, and moved onto the one it fits (reidentify_min_inliers).
  /// 0: off (the paper).
  double relocalize_below = 0.5;
  /// Duplicates (docs/system.md, "Merging duplicates"): on a detector
  /// frame, an object that a detection matched is one with a lost object
  /// of its class that was lost before it was created, or with a live one
  /// that no detection matched and whose box overlaps its own by
  /// max_volume_iou, when at least this share of the detection's points lie
  /// on that object's surface once aligned; the older id goes on with both
  /// models fused. 0: off (the paper).
  double merge_min_inliers = 0.6;
  /// An object created or re-identified on a detector frame is not deleted
  /// as not visible until it has been visible once or the detector runs
  /// again: one that enters the view across the image border would
  /// otherwise go on the next frame. Not one of which the frame shows
  /// nothing (fewer than min_object_terms pixels drawn and associated,
  /// border band included, or none inside the visibility border): that one
  /// has left the view and is lost at once.
  bool young_object_grace = true;
  /// During that grace, an object the frame shows cut by the image border
  /// or no longer shows (fewer than keep_mask_pixels of its E-step
  /// association inside the visibility border, and less there than in the
  /// border band, or fewer in all than min_object_terms) is not
  /// tracked: it keeps the pose it was found at instead of following the
  /// few pixels left of it at the border. Where the frame sees through that
  /// pose (of its model's pixels cast there, its outline left out, that no
  /// nearer surface covers, at least min_object_terms and fewer than two
  /// in three agree with the frame) it has moved on: its grace ends, and
  /// it is lost unless visible.
  bool hold_unseen_objects = true;
  /// An object whose model, drawn at its last pose, covers at least
  /// keep_mask_pixels and is more often behind a nearer surface of the frame
  /// than shown by it, and to which the E-step gives fewer than
  /// keep_mask_pixels, is not tracked: it moves on at its velocity instead
  /// of following the part left of it (hold_decisions, lifecycle.hpp).
  bool hold_occluded_objects = true;
  /// ... for up to this long after its last tracked frame (seconds); after
  /// that it stays where its motion took it until it shows again: objects
  /// stop, and a velocity carried on over seconds runs away from them.
  S hidden_moving_seconds = S(0.5);
  /// An object whose model, drawn at its last pose, lies behind a nearer
  /// surface of the frame on at least this share of its pixels inside the
  /// visibility border is associated and solved from its constant-velocity
  /// prediction, as predict_motion does for every object: what another
  /// object leaves of it in view may not say where it went (a face whose
  /// edges are hidden slides along itself), so the E-step at its last pose
  /// gave it only what had not moved and its solves fell behind (c214's
  /// book under a cup: 0.3 cm a frame for 0.93). The frame still decides
  /// between the prediction and the last pose (agrees_at_least_as_well).
  /// 0 = off (docs/decisions.md, "Partly hidden objects start at their
  /// prediction").
  S predict_hidden_share = S(0.25);
  /// A partly hidden object (predict_hidden_share) whose solve ends where
  /// the frame sees through its model more than at the solve's start, by at
  /// least this share of the model's pixels, and agrees with it on fewer
  /// than half as many more pixels, stays at the start
  /// (keep_starts_seen_through, lifecycle.hpp): what the nearer surface
  /// leaves of it in view may fit the model slid along itself, as a
  /// capsule hidden but for its top fits it pulled up its axis. 0 = off
  /// (docs/decisions.md, "Partly hidden solves that the frame sees
  /// through").
  S slide_seen_through_share = S(0.05);
  /// An object (past its grace) that stands still (leaving_still) and of
  /// whose extent less than this share lies inside the image less the
  /// visibility border, as the camera now sees it at its last pose
  /// (shows_less_than, lifecycle.hpp), is not tracked: it keeps its pose.
  /// The part of it left in view is too little to align (its model is
  /// least accurate at its edges and corners, and a face or two constrain
  /// few directions): tracked, objects the camera left slid 2-6 cm in
  /// their last frames in view. 0 = off (tracked to the last pixel, as the
  /// paper), the default: at 0.5 the benchmark's fifteen sequences failed
  /// 9 targets of 240 instead of 10, but a held-out one lost 0.1-0.6 cm on
  /// three objects (an object whose tracking had stalled looks still;
  /// docs/decisions.md, "Objects the camera leaves keep their pose").
  S leaving_share = S(0);
  /// Standing still: moved at most this (metres, degrees) over the last
  /// 0.2 s of its trajectory. A moving object leaving the view is tracked:
  /// held at its velocity, one that slowed or turned was lost (in the
  /// benchmark, a car held 50 frames while it drove out of view).
  MotionBound<S> leaving_still{S(0.01), S(3)};
  /// Lost objects come back without a detection when the frame shows their
  /// model where they were lost (refind_in_view, reidentification.hpp):
  /// an object that left the view, or stood hidden behind another, while
  /// it did not move, is tracked again from the frame it is back instead
  /// of from the next detector frame.
  bool refind_in_view = true;
  /// ... and a lost object that was moving is looked for where its motion
  /// would have carried it, for up to this long after it was lost (seconds;
  /// 0: only where it was lost): one that passed behind another object
  /// comes out on the other side.
  S refind_moving_seconds = S(1);
  /// Lost objects are also looked for, on every this many frames (0: off),
  /// in what no model explains: groups of measured points on no live object
  /// and off the background's surface, each aligned to every lost object as
  /// a detection would be (refind_unexplained, unexplained.hpp). An object
  /// that comes back into view anywhere is tracked again without waiting for
  /// the detector.
  int refind_unexplained_every = 1;
  /// ... where "off the surface" is further than this many likelihood.sigma.
  double refind_unexplained_sigmas = 2.0;
  /// ... measured across the background's surface: its SDF divided by the
  /// length of its gradient where that is above 1 (a surface seen at a
  /// grazing angle holds distances along the rays, longer than across it
  /// by about that factor). false (the default): the SDF as stored
  /// (docs/decisions.md, "Unexplained across the background's surface: off
  /// by default").
  bool refind_unexplained_across = false;
  /// ... and an object is looked for only as far from where it was last
  /// tracked as it can have gone at this speed (m/s).
  double refind_unexplained_speed = 1.0;
  /// While such a lost object exists, the background does not fuse what no
  /// model explains on frames without detections (hold_unexplained,
  /// unexplained.hpp): otherwise it takes in an object that comes back and
  /// stands still before refind_unexplained sees enough of it.
  bool hold_unexplained = true;
  /// Objects tracked back (an extension of the paper; track_back.hpp): the
  /// system keeps this many of the last frames, and an object created or
  /// found again by a detection is aligned to those since its last pose,
  /// newest first, its trajectory starting or going on there. 0: off (no
  /// frames kept).
  int track_back_frames = 30;

  // Rendering (sec. 3.5).
  S min_foreground = S(0.5);     ///< object voxels render where p_fg exceeds this
  S occlusion_margin = S(0.05);  ///< an object pixel this far behind the background loses
  /// An object pixel behind the background keeps its label where the
  /// frame's depth lies behind the background's surface too (by more than
  /// occlusion_margin) and on the object's (within it): the frame sees the
  /// object through that surface, a trace a moving object left in the
  /// background before the E-step gave its points to the object (beyond
  /// the paper). false: the background's surface hides the object
  /// whatever the frame shows.
  bool occlusion_seen_through = false;

  // Ablations (paper Table 3).
  bool use_association = true;     ///< false: q(u) = 1 for tracking and mapping of every model
  bool use_map_confidence = true;  ///< false: no W / W_max weights in tracking

  /// min_mask_pixels for a width x height image (it is given for 640x480).
  int min_mask_pixels_for(int width, int height) const {
    return std::max(1, int(std::lround(double(min_mask_pixels) * width * height / (640.0 * 480.0))));
  }
  /// The points of its own a detection needs to re-identify a lost object
  /// in a width x height image (min_mask_pixels_for times
  /// reidentify_mask_fraction, at least 1).
  int reidentify_mask_pixels_for(int width, int height) const {
    return std::max(1, int(std::lround(reidentify_mask_fraction * min_mask_pixels_for(width, height))));
  }
  /// The visible pixels below which an object in the map is not visible
  /// (min_mask_pixels_for times keep_visible_fraction, at least 1).
  int keep_mask_pixels_for(int width, int height) const {
    return std::max(1, int(std::lround(keep_visible_fraction * min_mask_pixels_for(width, height))));
  }
  /// Whether objects keep colour (object_colour_weight or
  /// reidentify_colour_agreement): the frames' gray values are then used.
  bool uses_colour() const { return object_colour_weight > S(0) || reidentify_colour_agreement > 0; }
  /// visibility_border for an image `width` pixels wide (it is given for 640).
  int visibility_border_for(int width) const { return int(std::lround(double(visibility_border) * width / 640.0)); }
  /// An object of this class is a person kept for association only: not
  /// rendered, not exported, never deleted as not visible (ignore_person).
  bool ignores(const std::string& class_name) const { return ignore_person && class_name == "person"; }

  static LevenbergMarquardtParams fast_lm() {
    LevenbergMarquardtParams p;
    p.tau = 1e-3;
    p.eps2 = 1e-6;
    return p;
  }

  static IntegrationParams<S> guarded() {
    IntegrationParams<S> p;
    p.silhouette_guard = S(1.5);
    return p;
  }
  static IntegrationParams<S> forgetting_traces() {
    IntegrationParams<S> p = guarded();
    p.unowned_free_from = S(0.2);
    return p;
  }

  /// Throws std::invalid_argument naming the first bad value.
  void validate() const {
    const char* w = "SystemParams";
    bilateral.validate("SystemParams.bilateral");
    detail::require(background_voxels >= 8 && background_voxels <= 2048, w, "background_voxels must be in 8..2048");
    detail::require(background_blocks >= 1 && background_blocks <= (1 << 26), w,
                    "background_blocks must be in 1..67108864");
    detail::require(background_voxel_size > S(0), w, "background_voxel_size must be positive");
    detail::require(truncation_voxels > S(1), w, "truncation_voxels must be greater than 1");
    detail::require(object_voxels >= 8 && object_voxels <= max_object_voxels, w,
                    "object_voxels must be at least 8 and at most max_object_voxels");
    detail::require(max_object_voxels <= 1024, w, "max_object_voxels must be at most 1024");
    detail::require(object_padding >= S(1), w, "object_padding must be at least 1");
    detail::require(object_depth_gap > S(0), w, "object_depth_gap must be positive");
    detail::require(max_objects >= 0 && max_objects <= 256, w, "max_objects must be in 0..256");
    detail::require(max_depth >= S(0), w, "max_depth must not be negative (0 = no limit)");
    detail::require(min_camera_terms >= 0 && min_object_terms >= 0, w,
                    "min_camera_terms and min_object_terms must not be negative");
    detail::require(max_camera_motion.translation > S(0) && max_camera_motion.rotation_degrees > S(0) &&
                        max_object_motion.translation > S(0) && max_object_motion.rotation_degrees > S(0),
                    w, "motion bounds must be positive (infinity: no bound)");
    lm.validate(w);
    detail::require(huber_voxels > S(0), w, "huber_voxels must be positive");
    detail::require(object_pose_prior >= S(0), w, "object_pose_prior must not be negative (0: off)");
    detail::require(object_colour_weight >= S(0), w, "object_colour_weight must not be negative (0: depth alone)");
    detail::require(pixel_stride >= 1, w, "pixel_stride must be at least 1");
    detail::require(pyramid_levels >= 1 && pyramid_levels <= 6, w, "pyramid_levels must be in 1..6");
    detail::require(camera_pixel_stride >= 0, w, "camera_pixel_stride must not be negative (0: auto)");
    detail::require(camera_pyramid_levels >= 1 && camera_pyramid_levels <= 6, w,
                    "camera_pyramid_levels must be in 1..6");
    detail::require(camera_converged_step >= 0 && std::isfinite(camera_converged_step), w,
                    "camera_converged_step must not be negative (0: off)");
    detail::require(camera_converged_gain >= 0 && std::isfinite(camera_converged_gain), w,
                    "camera_converged_gain must not be negative (0: off)");
    detail::require(depth_noise_reference >= S(0), w, "depth_noise_reference must not be negative");
    detail::require(likelihood.sigma > S(0) && likelihood.alpha >= S(0) && likelihood.alpha <= S(1) &&
                        likelihood.p_uniform >= S(0),
                    w, "likelihood needs sigma > 0, alpha in [0, 1], p_uniform >= 0");
    detail::require(match_iou >= 0 && match_iou < 1, w, "match_iou must be in [0, 1)");
    detail::require(min_mask_pixels >= 1, w, "min_mask_pixels must be at least 1");
    detail::require(visibility_border >= 0, w, "visibility_border must not be negative");
    detail::require(keep_visible_fraction > 0 && keep_visible_fraction <= 1, w,
                    "keep_visible_fraction must be in (0, 1]");
    detail::require(lost_object_frames >= 0 && max_lost_objects >= 0, w,
                    "lost_object_frames and max_lost_objects must not be negative");
    detail::require(reidentify_min_inliers > 0 && reidentify_min_inliers <= 1, w,
                    "reidentify_min_inliers must be in (0, 1]");
    detail::require(relocalize_below >= 0 && relocalize_below <= 1, w, "relocalize_below must be in [0, 1]");
    detail::require(refind_unexplained_every >= 0, w, "refind_unexplained_every must not be negative");
    detail::require(track_back_frames >= 0 && track_back_frames <= 1000, w, "track_back_frames must be in [0, 1000]");
    detail::require(refind_unexplained_sigmas > 0 && std::isfinite(refind_unexplained_sigmas), w,
                    "refind_unexplained_sigmas must be positive and finite");
    detail::require(refind_unexplained_speed > 0 && std::isfinite(refind_unexplained_speed), w,
                    "refind_unexplained_speed must be positive and finite");
    detail::require(refind_moving_seconds >= 0 && std::isfinite(double(refind_moving_seconds)), w,
                    "refind_moving_seconds must be finite and not negative");
    detail::require(confirm_jump_frames >= 0, w, "confirm_jump_frames must not be negative");
    detail::require(hidden_moving_seconds >= 0 && std::isfinite(double(hidden_moving_seconds)), w,
                    "hidden_moving_seconds must be finite and not negative");
    detail::require(leaving_share >= 0 && leaving_share <= 1, w, "leaving_share must be in [0, 1] (0: off)");
    detail::require(slide_seen_through_share >= 0 && slide_seen_through_share <= 1, w,
                    "slide_seen_through_share must be in [0, 1] (0: off)");
    detail::require(predict_hidden_share >= 0 && predict_hidden_share <= 1, w,
                    "predict_hidden_share must be in [0, 1] (0: off)");
    detail::require(leaving_still.translation >= 0 && leaving_still.rotation_degrees >= 0, w,
                    "leaving_still_translation and leaving_still_rotation_degrees must not be negative");
    detail::require(reidentify_keep_margin >= 0 && reidentify_keep_margin <= 1, w,
                    "reidentify_keep_margin must be in [0, 1]");
    detail::require(reidentify_pose_prior >= S(0), w, "reidentify_pose_prior must not be negative (0: off)");
    detail::require(reidentify_turn_below >= 0 && reidentify_turn_below <= 1, w,
                    "reidentify_turn_below must be in [0, 1]");
    detail::require(reidentify_colour_agreement >= 0 && reidentify_colour_agreement <= 1, w,
                    "reidentify_colour_agreement must be in [0, 1] (0: off)");
    detail::require(reidentify_turned_keep >= 0, w, "reidentify_turned_keep must not be negative (0: every start)");
    detail::require(reidentify_turned_rank_iterations >= 1, w, "reidentify_turned_rank_iterations must be at least 1");
    detail::require(reidentify_mask_fraction > 0 && reidentify_mask_fraction <= 1, w,
                    "reidentify_mask_fraction must be in (0, 1]");
    detail::require(merge_min_inliers >= 0 && merge_min_inliers <= 1, w, "merge_min_inliers must be in [0, 1]");
    detail::require(background_integration.max_weight > S(0) && object_integration.max_weight > S(0), w,
                    "max_weight must be positive");
    const auto in_unit = [](S v) { return v >= S(0) && v <= S(1); };
    detail::require(in_unit(background_integration.unowned_free_from), w,
                    "background_unowned_free_from must be in [0, 1]");
    detail::require(in_unit(object_integration.unowned_free_from), w,
                    "object_integration.unowned_free_from must be in [0, 1]");
  }
};

}  // namespace emfusion
