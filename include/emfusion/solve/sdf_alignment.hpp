// Direct alignment of a depth image with a TSDF volume (paper eq. 8/9,
// after Bylow et al. 2013): per pixel, the residual is the SDF value of the
// measured point moved into the volume, r = psi(T_volume_camera * p), with
// Jacobian d r / d xi = grad psi^T [I | -hat(x)] for a left perturbation of
// T_volume_camera. Each term is weighted by the pixel's association
// likelihood q(u) and the normalised map confidence W(x) / W_norm; the
// robust norm's IRLS weight comes on top (solve/normal_equations.hpp). Each
// weight can be switched off, as the paper's ablations need. Written once for
// every volume of the volume concept (volume/volume_view.hpp): the dense
// TsdfVolume of any storage and the sparse SparseTsdfVolume.
//
// Colour terms (beyond the paper; on when SdfAlignmentTerms::colour holds a
// model's gray values, volume/intensity_grid.hpp): per pixel a second
// residual r_c = s (c(x) - I(u)), c the model's trilinear gray value at x,
// I(u) the frame's, s = colour_scale, with the same weight as the pixel's
// SDF term and Jacobian s grad_t c^T [I | -hat(x)], where grad_t c is c's
// gradient less its part along the SDF's gradient: across the surface
// the model's gray values change only with how far from it the voxels were
// coloured, and the SDF term already fixes that direction.
#pragma once

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "emfusion/core/image.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/core/pixel_box.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/robust/norms.hpp"
#include "emfusion/solve/batched_solve.hpp"
#include "emfusion/solve/normal_equations.hpp"
#include "emfusion/solve/pose_prior.hpp"
#include "emfusion/solve/solvers.hpp"
#include "emfusion/solve/volume_parameter.hpp"
#include "emfusion/volume/intensity_grid.hpp"
#include "emfusion/volume/nearby_samples.hpp"
#include "emfusion/volume/tsdf_volume.hpp"
#include "emfusion/volume/volume_view.hpp"

namespace emfusion {

/// A pixel stride for tracking a width x height frame: every 2nd pixel
/// while that leaves at least 50000 pixels (a 640x480 frame keeps 76800 for
/// the six unknowns), else every pixel (a 320x240 frame, or a small test
/// image, where every term counts). track_camera measured the same ATE on
/// every shared sequence with it (docs/decisions.md, "Solver stops, pyramid
/// and pixel stride").
inline int auto_pixel_stride(int width, int height) { return (width / 2) * (height / 2) >= 50000 ? 2 : 1; }

template <class S>
struct SdfAlignmentParams {
  bool use_association = true;     ///< weight terms by q(u) (needs an association image)
  bool use_map_confidence = true;  ///< weight terms by W(x) / confidence_normalizer
  /// W_norm: the map's weight cap W_max, so that confidence reaches 1 where the
  /// map is saturated (the paper normalises by the largest W in the frame,
  /// which equals W_max once the map is mature).
  S confidence_normalizer = S(64);
  int pixel_stride = 1;  ///< use every n-th pixel in x and y
  /// Coarse-to-fine levels: the solve runs on level L-1 first and on level 0
  /// last, level l taking every (pixel_stride * 2^l)-th pixel of the
  /// bilateral-filtered frame in x and y (a decimation pyramid: no images of
  /// its own, and each term keeps its pixel's association and map
  /// confidence). 1: one level, the paper's solve.
  int pyramid_levels = 1;
  /// Jacobian from the SDF gradient by central differences one voxel apart
  /// (smoother across voxel cells, six more samples per pixel) instead of the
  /// exact gradient of the trilinear interpolant.
  bool central_gradient = false;
  /// Depth-noise weighting: 0 = off; otherwise a term at depth z (metres)
  /// weighs min(1, (sigma(reference) / sigma(z))^2), with the Kinect
  /// axial noise model sigma(z) = 0.0012 + 0.0019 (z - 0.4)^2 m (Nguyen et
  /// al. 2012), so that far, noisy points count less.
  S depth_noise_reference = S(0);
};

/// Axial depth noise of a structured-light sensor at depth z (metres): the
/// model of Nguyen, Izadi and Lovell (3DIMPVT 2012) for the Kinect v1.
template <class S>
EMF_HD inline S kinect_depth_sigma(S z) {
  const S d = z - S(0.4);
  return S(0.0012) + S(0.0019) * d * d;
}

namespace detail {
template <class S>
struct PositivePixelBox {  // the one-pixel box of pixel i where q > 0, else an empty one
  ImageView<const S> q;
  EMF_HD PixelBox operator()(int i) const {
    if (!(q[i] > S(0))) return PixelBox{};
    const int u = i % q.width, v = i / q.width;
    return PixelBox{u, v, u + 1, v + 1};
  }
};
struct UniteBoxes {
  EMF_HD PixelBox operator()(const PixelBox& a, const PixelBox& b) const {
    if (a.empty()) return b;
    if (b.empty()) return a;
    return PixelBox{a.x0 < b.x0 ? a.x0 : b.x0, a.y0 < b.y0 ? a.y0 : b.y0, a.x1 > b.x1 ? a.x1 : b.x1,
                    a.y1 > b.y1 ? a.y1 : b.y1};
  }
};
/// positive_boxes' reduction: the boxes of up to `capacity` images at once.
inline constexpr int box_set_capacity = 8;
struct BoxSet {
  PixelBox box[box_set_capacity];
};
// Both loops run over every slot, a constant count, so that a GPU keeps the
// sets in registers: with the count of images in use as the bound, the
// sets went to local memory and the objects' tracking took 0.35 ms longer
// a frame (H100, redkitchen_dyn_300). Slots past the images in use stay
// empty, and uniting empty boxes is a compare.
template <class S>
struct PositivePixelBoxes {  // PositivePixelBox of pixel i in each of q[0..n), empty boxes after
  ImageView<const S> q[box_set_capacity];
  int n = 0;
  EMF_HD BoxSet operator()(int i) const {
    BoxSet set;
    for (int k = 0; k < box_set_capacity; ++k)
      if (k < n) set.box[k] = PositivePixelBox<S>{q[k]}(i);
    return set;
  }
};
struct UniteBoxSets {
  EMF_HD BoxSet operator()(const BoxSet& a, const BoxSet& b) const {
    BoxSet united;
    for (int k = 0; k < box_set_capacity; ++k) united.box[k] = UniteBoxes{}(a.box[k], b.box[k]);
    return united;
  }
};
}  // namespace detail

/// The smallest box holding every pixel where `weights` is positive (empty
/// when there is none), computed on `backend`. An object's association is
/// zero outside the few pixels it covers: its terms need only this box.
template <class S, Backend B>
PixelBox positive_box(const B& backend, const Image<S, B>& weights) {
  const detail::PositivePixelBox<S> f{weights.view()};
  return transform_reduce_index(backend, weights.size(), f, PixelBox{}, detail::UniteBoxes{});
}

namespace detail {
/// positive_boxes in one reduction for each 8 images (`weights` checked by
/// the caller), on any backend.
template <class S, Backend B>
std::vector<PixelBox> positive_boxes_at_once(const B& backend, const std::vector<const Image<S, B>*>& weights) {
  std::vector<PixelBox> boxes;
  for (std::size_t first = 0; first < weights.size(); first += box_set_capacity) {
    PositivePixelBoxes<S> f;
    f.n = int(std::min<std::size_t>(weights.size() - first, box_set_capacity));
    for (int k = 0; k < f.n; ++k) f.q[k] = weights[first + std::size_t(k)]->view();
    const BoxSet set = transform_reduce_index(backend, weights[first]->size(), f, BoxSet{}, UniteBoxSets{});
    boxes.insert(boxes.end(), set.box, set.box + f.n);
  }
  return boxes;
}
}  // namespace detail

/// positive_box of every image of `weights` (all of one size). On a
/// device in one reduction for each 8 of them: one wait for the host
/// instead of one an image (the objects' boxes before their batched solve).
/// On the CPU, where a reduction waits for nothing, one an image: the
/// reduction of 8 boxes at once did more work there (redkitchen_dyn_300,
/// 2 cores: track_objects 43-45 -> 50-53 ms a frame).
template <class S, Backend B>
std::vector<PixelBox> positive_boxes(const B& backend, const std::vector<const Image<S, B>*>& weights) {
  for (const Image<S, B>* image : weights)
    detail::require(image->same_size(weights[0]->width(), weights[0]->height()), "positive_boxes",
                    "every weight image must have the first one's size");
  if constexpr (B::is_device) {
    return detail::positive_boxes_at_once(backend, weights);
  } else {
    std::vector<PixelBox> boxes;
    for (const Image<S, B>* image : weights) boxes.push_back(positive_box(backend, *image));
    return boxes;
  }
}

/// The per-pixel terms of SDF alignment (a PoseTerms problem over
/// T_volume_camera). Holds views: valid while the volume and images live.
/// The terms are the pixels of `box` (the whole image when it is empty) on
/// the grid of every `stride`-th pixel of the image, so a box changes which
/// pixels take part but not how they are sampled. `Volume` names the volume
/// read (volume_parameter.hpp): the storage scalar of a dense volume, as
/// before, or any TsdfSampler view (SparseTsdfView<S, const Store>).
template <class S, class Volume = S>
struct SdfAlignmentTerms {
  using View = volume_sampler_t<S, Volume>;
  View volume;
  ImageView<const Vec3<S>> points;  ///< camera frame; non-finite = no point
  ImageView<const S> association;   ///< q(u); empty = 1 everywhere
  S confidence_scale = S(0);        ///< 1 / W_norm; 0 = map confidence off
  int stride = 1;
  bool central_gradient = false;
  S noise_reference_sigma = S(0);   ///< sigma at the reference depth; 0 = no depth weighting
  PixelBox box{};                   ///< pixels that may take part; empty = the whole image

  /// The box on the stride grid: first column and row, and how many of each.
  /// Every term calls it: stride 1 (the default) skips the divisions.
  EMF_HD void grid(int& u0, int& v0, int& columns, int& rows) const {
    const PixelBox b = box.empty() ? PixelBox{0, 0, points.width, points.height} : box;
    if (stride == 1) {
      u0 = b.x0, v0 = b.y0;
      columns = b.x1 > u0 ? b.x1 - u0 : 0;
      rows = b.y1 > v0 ? b.y1 - v0 : 0;
      return;
    }
    u0 = (b.x0 + stride - 1) / stride * stride;
    v0 = (b.y0 + stride - 1) / stride * stride;
    columns = b.x1 > u0 ? (b.x1 - u0 + stride - 1) / stride : 0;
    rows = b.y1 > v0 ? (b.y1 - v0 + stride - 1) / stride : 0;
  }
  /// Colour terms (solve/sdf_alignment.hpp's header comment): on while the
  /// model has colour, the frame an intensity image and colour_scale is
  /// positive.
  IntensityView<S, const float> colour{};
  ImageView<const S> intensity;  ///< the frame's gray values in [0, 1]
  S colour_scale = S(0);         ///< metres of residual per unit of gray value

  EMF_HD bool coloured() const { return colour_scale > S(0) && !colour.empty() && !intensity.empty(); }
  EMF_HD int term_count() const {
    int u0, v0, columns, rows;
    grid(u0, v0, columns, rows);
    return columns * rows * (coloured() ? 2 : 1);
  }
  EMF_HD bool term(int i, const SE3<S>& T_volume_camera, S& r, Vec6<S>& J, S& w) const {
    int u0, v0, columns, rows;
    grid(u0, v0, columns, rows);
    // Terms [0, n) are the pixels' SDF terms, [n, 2n) their colour terms.
    const int n = columns * rows;
    const bool colour_term = i >= n;
    if (colour_term) i -= n;
    const int u = u0 + (i % columns) * stride, v = v0 + (i / columns) * stride;
    const int pixel = v * points.width + u;
    const Vec3<S> p = points[pixel];
    if (!(std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z()))) return false;
    S q = association.empty() ? S(1) : association[pixel];
    if (!(q > S(0))) return false;
    const Vec3<S> x = T_volume_camera * p;
    Vec3<S> g;
    S W;
    // The view itself, or for a sparse one with an index grid a sampler that
    // reads the grid alone, or without one on the host a sampler that looks
    // each block up once for the term's samples (volume/nearby_samples.hpp).
    // Not that one on a CUDA device: there the cache's arrays live in local
    // memory and cost more than the lookups they save (H200, redkitchen_300,
    // track_camera --volume sparse: 8.2 ms per frame with the cache, 2.8 ms
    // without; docs/volumes.md).
#if defined(__CUDA_ARCH__)
    constexpr int cached_blocks = 0;
#else
    constexpr int cached_blocks = 4;
#endif
    const bool sampled = with_nearby_sampler<cached_blocks>(volume, [&](auto& sampler) {
      return sampler.sample_with_gradient(x, r, g, &W) && (!central_gradient || sampler.central_gradient(x, g));
    });
    if (!sampled) return false;
    if (confidence_scale > S(0)) q *= (W * confidence_scale < S(1) ? W * confidence_scale : S(1));
    if (noise_reference_sigma > S(0)) {
      const S ratio = noise_reference_sigma / kinect_depth_sigma(p.z());
      q *= ratio < S(1) ? ratio * ratio : S(1);
    }
    if (colour_term && !colour_residual(x, pixel, r, g)) return false;
    const Vec3<S> xg = cross(x, g);
    J = Vec6<S>{{g.x(), g.y(), g.z(), xg.x(), xg.y(), xg.z()}};
    w = q;
    return true;
  }

 private:
  /// The colour term at volume-frame point x of pixel `pixel`, where the
  /// SDF's gradient is g: r = colour_scale (c(x) - I(u)), and in g the
  /// gradient of c along the surface (its part along the SDF's gradient
  /// left out: across the surface the model's colour changes only by how
  /// far from it the voxels were coloured), scaled alike.
  EMF_HD bool colour_residual(const Vec3<S>& x, int pixel, S& r, Vec3<S>& g) const {
    S c;
    Vec3<S> gc;
    const S I = intensity[pixel];
    const S gg = dot(g, g);
    if (!(gg > S(0)) || !std::isfinite(I) || !colour.sample_with_gradient(x, c, gc)) return false;
    const Vec3<S> along = gc - (dot(gc, g) / gg) * g;
    r = colour_scale * (c - I);
    g = colour_scale * along;
    return true;
  }
};

/// The terms' type for an owning volume: SdfAlignmentTerms<S, Store> for a
/// dense TsdfVolume<S, B, Store>, SdfAlignmentTerms<S, its ConstView>
/// otherwise.
template <class S, class Volume>
using sdf_alignment_terms_t = SdfAlignmentTerms<S, volume_parameter_of_t<Volume>>;

/// Builds the terms for a volume (dense or sparse: any TsdfVolumeType on the
/// points' backend), a vertex map (camera frame) and an optional association
/// image of the same size.
template <class S, Backend B, class Volume>
  requires TsdfVolumeOn<Volume, S, B>
sdf_alignment_terms_t<S, Volume> make_sdf_alignment(const Volume& volume, const Image<Vec3<S>, B>& points,
                                                    const Image<S, B>* association,
                                                    const SdfAlignmentParams<S>& params = {}) {
  constexpr const char* where = "make_sdf_alignment";
  detail::require(!points.empty(), where, "the vertex map is empty");
  if (params.use_association && association)
    detail::require_image(association->view(), points.width(), points.height(), where, "association image");
  detail::require(params.pixel_stride >= 1, where, "pixel_stride must be at least 1");
  detail::require(params.pyramid_levels >= 1 && params.pyramid_levels <= 6, where, "pyramid_levels must be in 1..6");
  detail::require(!params.use_map_confidence || params.confidence_normalizer > S(0), where,
                  "confidence_normalizer must be positive");
  sdf_alignment_terms_t<S, Volume> t;
  t.volume = volume.view();
  t.points = points.view();
  if (params.use_association && association) t.association = association->view();
  t.confidence_scale = params.use_map_confidence ? S(1) / params.confidence_normalizer : S(0);
  t.stride = params.pixel_stride;
  t.central_gradient = params.central_gradient;
  if (params.depth_noise_reference > S(0)) t.noise_reference_sigma = kinect_depth_sigma(params.depth_noise_reference);
  return t;
}

/// sdf_alignment_in_box (below) with the association's positive_box
/// already computed (`positive`: positive_boxes, several objects at once).
template <class S, Backend B, class Volume>
  requires TsdfVolumeOn<Volume, S, B>
sdf_alignment_terms_t<S, Volume> sdf_alignment_in_box(const Volume& volume, const Image<Vec3<S>, B>& points,
                                                      const Image<S, B>* association,
                                                      const SdfAlignmentParams<S>& params, const PixelBox& positive) {
  sdf_alignment_terms_t<S, Volume> terms = make_sdf_alignment(volume, points, association, params);
  if (!terms.association.empty())
    terms.box = positive.empty() ? PixelBox{0, 0, 1, 1} : positive;  // empty: no term at all; one pixel, q = 0
  return terms;
}

/// The terms of make_sdf_alignment restricted to the pixels where the
/// association is positive (positive_box, computed on `backend`): an
/// object's association is zero outside the few pixels it covers, so its
/// solve skips the rest in every iteration.
template <class S, Backend B, class Volume>
  requires TsdfVolumeOn<Volume, S, B>
sdf_alignment_terms_t<S, Volume> sdf_alignment_in_box(const Volume& volume, const Image<Vec3<S>, B>& points,
                                                      const Image<S, B>* association,
                                                      const SdfAlignmentParams<S>& params, const B& backend) {
  const bool boxed = params.use_association && association;
  return sdf_alignment_in_box(volume, points, association, params,
                              boxed ? positive_box(backend, *association) : PixelBox{});
}

/// `terms` at coarse-to-fine level `level` of `params` (every
/// (pixel_stride * 2^level)-th pixel).
template <class S, class Volume>
SdfAlignmentTerms<S, Volume> at_level(SdfAlignmentTerms<S, Volume> terms, const SdfAlignmentParams<S>& params,
                                     int level) {
  terms.stride = params.pixel_stride << level;
  return terms;
}

/// The coarse-to-fine loop over `levels` levels for several problems at
/// once: `solve_level(level, starts, reports)` solves every problem at one
/// level, each from its start, fills one report each and returns the
/// poses; the finest (level 0) runs last, each level from where the coarser
/// one stopped. A coarse level without a solution for a problem (too few
/// terms at its spacing) hands on its start: the finer level decides. Each
/// report is its problem's finest level's, with the iterations and accepted
/// steps of all levels added up.
template <class S, class SolveLevel>
std::vector<SE3<S>> coarse_to_fine_each(int levels, std::vector<SE3<S>> T, std::vector<SolveReport>& reports,
                                        SolveLevel&& solve_level) {
  const std::size_t n = T.size();
  std::vector<int> iterations(n, 0), accepted(n, 0);
  reports.assign(n, SolveReport{});
  for (int level = levels - 1; level >= 0; --level) {
    reports.assign(n, SolveReport{});
    const std::vector<SE3<S>> solved = solve_level(level, std::as_const(T), reports);
    for (std::size_t k = 0; k < n; ++k) {
      iterations[k] += reports[k].iterations, accepted[k] += reports[k].accepted_steps;
      if (level == 0 || reports[k].converged()) T[k] = solved[k];
    }
  }
  for (std::size_t k = 0; k < n; ++k) reports[k].iterations = iterations[k], reports[k].accepted_steps = accepted[k];
  return T;
}

/// coarse_to_fine_each for one problem: `solve_level(level, start, report)`
/// solves one level from `start` and returns its pose.
template <class S, class SolveLevel>
SE3<S> coarse_to_fine(int levels, const SE3<S>& start, SolveReport* report, SolveLevel&& solve_level) {
  std::vector<SolveReport> reports;
  const auto one_level = [&](int level, const std::vector<SE3<S>>& from, std::vector<SolveReport>& r) {
    return std::vector<SE3<S>>{solve_level(level, from[0], r[0])};
  };
  const SE3<S> T = coarse_to_fine_each(levels, std::vector<SE3<S>>{start}, reports, one_level)[0];
  if (report) *report = reports[0];
  return T;
}

/// The solver for level `level` of a `levels`-level coarse_to_fine solve:
/// `solver` on the coarsest, refined(solver) on the finer ones, which start
/// where the coarser one stopped.
template <class Solver>
Solver solver_at_level(const Solver& solver, int level, int levels) {
  return level < levels - 1 ? refined(solver) : solver;
}

/// Minimises the robust cost of `terms` with `solver` from `start`, coarse to
/// fine over params.pyramid_levels levels (coarse_to_fine); the levels below
/// the coarsest start where it stopped, with refined(solver). `values` is
/// reset for every level (the terms change with it). With `prior`, every
/// level's terms take its six (WithPosePrior, solve/pose_prior.hpp).
template <class S, Backend B, class Volume, class Norm, class Solver>
  requires RobustNorm<Norm, S> && PoseSolver<Solver, S>
SE3<S> solve_coarse_to_fine(const B& backend, const SdfAlignmentTerms<S, Volume>& terms, const Norm& norm,
                            const SdfAlignmentParams<S>& params, const Solver& solver, const SE3<S>& start,
                            SolveReport* report, LinearizationCache<S, B>& values,
                            const PosePrior<S>* prior = nullptr) {
  return coarse_to_fine(params.pyramid_levels, start, report, [&](int level, const SE3<S>& from, SolveReport& r) {
    const WithPosePrior<SdfAlignmentTerms<S, Volume>, S> level_terms{at_level(terms, params, level),
                                                                     prior ? *prior : PosePrior<S>{}};
    values.reset();
    const auto lin = [&](const SE3<S>& pose, const SE3<S>* reference) {
      return linearize(backend, level_terms, norm, pose, reference, values);
    };
    return solver_at_level(solver, level, params.pyramid_levels).solve(lin, from, &r);
  });
}

/// solve_coarse_to_fine for many problems at once with Levenberg-Marquardt
/// (solve_batch): level by level, every problem's terms at that level in one
/// batch, each starting where its coarser level stopped (or, without a
/// solution there, where that level started). Fills one report per problem
/// as solve_coarse_to_fine does; with `priors` (one per problem), each
/// problem's terms take its prior's six at every level.
template <class S, Backend B, class Volume, class Norm>
  requires RobustNorm<Norm, S>
std::vector<SE3<S>> solve_coarse_to_fine_batch(const B& backend, const std::vector<SdfAlignmentTerms<S, Volume>>& terms,
                                               const std::vector<Norm>& norms, const SdfAlignmentParams<S>& params,
                                               const LevenbergMarquardt& solver, std::vector<SE3<S>> starts,
                                               std::vector<SolveReport>& reports, BatchedSolveWorkspace<S, B>& ws,
                                               const std::vector<PosePrior<S>>* priors = nullptr) {
  const std::size_t n = terms.size();
  detail::require(norms.size() == n && starts.size() == n && (!priors || priors->size() == n),
                  "solve_coarse_to_fine_batch", "need one norm, one start and (if any) one prior per problem");
  std::vector<BatchedProblem<WithPosePrior<SdfAlignmentTerms<S, Volume>, S>, Norm>> problems(n);
  const auto batch_level = [&](int level, const std::vector<SE3<S>>& from, std::vector<SolveReport>& r) {
    for (std::size_t k = 0; k < n; ++k)
      problems[k] = {{at_level(terms[k], params, level), priors ? (*priors)[k] : PosePrior<S>{}}, norms[k]};
    const LevenbergMarquardt level_solver = solver_at_level(solver, level, params.pyramid_levels);
    return solve_batch(backend, problems, from, level_solver.params, r, ws);
  };
  return coarse_to_fine_each(params.pyramid_levels, std::move(starts), reports, batch_level);
}

/// The rule of agrees_at_least_as_well below, from the linearisations at
/// the candidate (with the fallback as its reference) and at the fallback.
inline bool agrees_at_least_as_well(const NormalEquations6& at_candidate, const NormalEquations6& at_fallback) {
  return at_candidate.shared_cost <= at_candidate.shared_reference_cost &&
         at_candidate.terms >= 0.9 * at_fallback.terms;
}

/// Whether the frame agrees at least as well with `candidate` as with
/// `fallback` (e.g. a motion prediction and the previous pose): at the
/// coarsest level of `params`, the robust cost over the terms valid at both
/// poses is not higher at `candidate`, and at least as many terms are valid
/// there (within 10 %: a pose that moves the points off the map loses terms,
/// not cost). Two linearisations at the coarsest level.
template <class S, Backend B, class Volume, class Norm>
  requires RobustNorm<Norm, S>
bool agrees_at_least_as_well(const B& backend, const SdfAlignmentTerms<S, Volume>& terms, const Norm& norm,
                             const SdfAlignmentParams<S>& params, const SE3<S>& candidate, const SE3<S>& fallback) {
  const SdfAlignmentTerms<S, Volume> coarse = at_level(terms, params, params.pyramid_levels - 1);
  return agrees_at_least_as_well(linearize(backend, coarse, norm, candidate, &fallback),
                                 linearize(backend, coarse, norm, fallback));
}

/// Minimises the robust SDF alignment cost over the camera pose in the frame
/// of `volume` (dense or sparse) with `solver` (a PoseSolver: LevenbergMarquardt,
/// GaussNewton or the user's own), starting at `T_volume_camera`, coarse to
/// fine when params.pyramid_levels > 1; returns the solved T_volume_camera.
/// Use it when the volume's own pose is what is estimated (a moving object):
/// it avoids a round trip through the volume's world pose. `cache`
/// (optional) keeps the per-term buffers of the solve between calls, saving
/// their allocation (LinearizationCache); `run_on` (optional) is the backend
/// the solve's work runs on instead of the volume's, e.g. a CUDA stream of
/// its own so that solves from several host threads overlap
/// (ConcurrentLanes). Each solve needs its own cache. With `prior`
/// (optional), the solve is pulled towards the prior's pose
/// (solve_coarse_to_fine, solve/pose_prior.hpp).
template <class S, Backend B, class Volume, class Norm, class Solver>
  requires TsdfVolumeOn<Volume, S, B> && RobustNorm<Norm, S> && PoseSolver<Solver, S>
SE3<S> align_in_volume(const Volume& volume, const Image<Vec3<S>, B>& points,
                       const Image<S, B>* association, const SE3<S>& T_volume_camera, const Norm& norm,
                       const SdfAlignmentParams<S>& params, const Solver& solver, SolveReport* report = nullptr,
                       LinearizationCache<S, B>* cache = nullptr, const B* run_on = nullptr,
                       const PosePrior<S>* prior = nullptr) {
  const B& backend = run_on ? *run_on : volume.backend();
  LinearizationCache<S, B> local;
  return solve_coarse_to_fine(backend, sdf_alignment_in_box(volume, points, association, params, backend), norm,
                              params, solver, T_volume_camera, report, cache ? *cache : local, prior);
}

/// align_in_volume with Levenberg-Marquardt of parameters `lm`.
template <class S, Backend B, class Volume, class Norm>
  requires TsdfVolumeOn<Volume, S, B> && RobustNorm<Norm, S>
SE3<S> align_in_volume(const Volume& volume, const Image<Vec3<S>, B>& points,
                       const Image<S, B>* association, const SE3<S>& T_volume_camera, const Norm& norm,
                       const SdfAlignmentParams<S>& params = {}, const LevenbergMarquardtParams& lm = {},
                       SolveReport* report = nullptr, LinearizationCache<S, B>* cache = nullptr,
                       const B* run_on = nullptr) {
  return align_in_volume(volume, points, association, T_volume_camera, norm, params, LevenbergMarquardt{lm}, report,
                         cache, run_on);
}

/// Tracks a camera against a volume (dense or sparse): minimises the robust SDF alignment cost
/// over T_world_camera with `solver`, starting at `T_world_camera`.
template <class S, Backend B, class Volume, class Norm, class Solver>
  requires TsdfVolumeOn<Volume, S, B> && RobustNorm<Norm, S> && PoseSolver<Solver, S>
SE3<S> align_to_volume(const Volume& volume, const Image<Vec3<S>, B>& points,
                       const Image<S, B>* association, const SE3<S>& T_world_camera, const Norm& norm,
                       const SdfAlignmentParams<S>& params, const Solver& solver, SolveReport* report = nullptr,
                       LinearizationCache<S, B>* cache = nullptr) {
  return volume.pose() * align_in_volume(volume, points, association, volume.pose().inverse() * T_world_camera,
                                         norm, params, solver, report, cache);
}

/// align_to_volume with Levenberg-Marquardt of parameters `lm`.
template <class S, Backend B, class Volume, class Norm>
  requires TsdfVolumeOn<Volume, S, B> && RobustNorm<Norm, S>
SE3<S> align_to_volume(const Volume& volume, const Image<Vec3<S>, B>& points,
                       const Image<S, B>* association, const SE3<S>& T_world_camera, const Norm& norm,
                       const SdfAlignmentParams<S>& params = {}, const LevenbergMarquardtParams& lm = {},
                       SolveReport* report = nullptr, LinearizationCache<S, B>* cache = nullptr) {
  return align_to_volume(volume, points, association, T_world_camera, norm, params, LevenbergMarquardt{lm}, report,
                         cache);
}

}  // namespace emfusion
