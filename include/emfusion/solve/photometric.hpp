// Photometric alignment: a pose term on intensity images, beside the SDF
// term of solve/sdf_alignment.hpp, for stretches where geometry alone is
// weak (a wall, a floor, a corridor). Dense direct RGB-D odometry after
// Steinbrücker, Sturm and Cremers (2011) and Kerl, Sturm and Cremers (2013);
// not in the EM-Fusion paper.
//
// Every `stride`-th pixel u of a reference frame with a 3D point p (its
// camera frame) and intensity I_ref(u) is a term. With X = T_frame_reference
// p the point in the pose's frame and T the current camera's pose in that
// frame, the residual is
//     r = I(pi(T^-1 X)) - I_ref(u),
// I sampled bilinearly, and for a left perturbation T <- exp(xi) T,
// xi = (v, w), with a = grad I^T d pi / d x at x = T^-1 X and b = R a,
//     d r / d xi = (-b, b x X).
// A PhotometricTerms is a PoseTerms problem, so every robust norm and solver
// of the library applies to it alone (align_photometric), and its normal
// equations add to the SDF term's (align_to_volume_and_intensity: the sum
// of the SDF cost and `weight` times the photometric cost, each with its
// own norm).
#pragma once

#include <cmath>

#include "emfusion/core/camera.hpp"
#include "emfusion/core/error.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/robust/norms.hpp"
#include "emfusion/solve/normal_equations.hpp"
#include "emfusion/solve/sdf_alignment.hpp"
#include "emfusion/solve/solvers.hpp"

namespace emfusion {

template <class S>
struct PhotometricParams {
  int pixel_stride = 2;  ///< every n-th reference pixel in x and y
  /// Reference pixels whose intensity gradient is below this (per pixel, in
  /// intensity units of [0, 1]) take no part: flat regions carry no
  /// information about the motion, only noise.
  S min_gradient = S(0.004);
};

/// The per-pixel photometric terms (a PoseTerms problem over the current
/// camera's pose in the frame of T_frame_reference). Holds views: valid
/// while the images live.
template <class S>
struct PhotometricTerms {
  ImageView<const Vec3<S>> reference_points;  ///< reference camera frame; non-finite = no point
  ImageView<const S> reference_intensity;
  ImageView<const S> intensity;               ///< the current frame
  ImageView<const Vec2<S>> gradient;          ///< of `intensity` (intensity_gradient)
  SE3<S> T_frame_reference;                   ///< the reference camera in the pose's frame
  PinholeCamera<S> camera;                    ///< of the current frame
  int stride = 1;
  S min_gradient = S(0);

  EMF_HD int columns() const { return (reference_points.width + stride - 1) / stride; }
  EMF_HD int term_count() const { return columns() * ((reference_points.height + stride - 1) / stride); }

  EMF_HD bool term(int i, const SE3<S>& T, S& r, Vec6<S>& J, S& w) const {
    const int u = (i % columns()) * stride, v = (i / columns()) * stride;
    const int pixel = v * reference_points.width + u;
    const Vec3<S> p = reference_points[pixel];
    if (!(std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z()))) return false;
    if (min_gradient > S(0) && !textured(u, v)) return false;
    const Vec3<S> X = T_frame_reference * p;
    const Vec3<S> x = T.inverse() * X;
    if (!(x.z() > S(1e-3))) return false;
    const S px = camera.fx * x.x() / x.z() + camera.cx, py = camera.fy * x.y() / x.z() + camera.cy;
    // Inside by a pixel, so that the bilinear cell and its gradient exist.
    if (!(px >= S(1) && py >= S(1) && px < S(intensity.width - 2) && py < S(intensity.height - 2))) return false;
    const int x0 = int(px), y0 = int(py);
    const S fx = px - S(x0), fy = py - S(y0);
    const S I = bilinear(intensity, x0, y0, fx, fy);
    const Vec2<S> g = bilinear(gradient, x0, y0, fx, fy);
    r = I - reference_intensity[pixel];
    // a = grad I^T d pi / d x, a row of three.
    const S iz = S(1) / x.z();
    const Vec3<S> a = vec3(g.x() * camera.fx * iz, g.y() * camera.fy * iz,
                           -(g.x() * camera.fx * x.x() + g.y() * camera.fy * x.y()) * iz * iz);
    const Vec3<S> b = T.rotation() * a;
    const Vec3<S> bX = cross(b, X);
    J = Vec6<S>{{-b.x(), -b.y(), -b.z(), bX.x(), bX.y(), bX.z()}};
    w = S(1);
    return true;
  }

  /// `image` between pixels (x0, y0) and (x0 + 1, y0 + 1), at fractions fx, fy.
  template <class T>
  EMF_HD static T bilinear(const ImageView<const T>& image, int x0, int y0, S fx, S fy) {
    const T top = image(x0, y0) * (S(1) - fx) + image(x0 + 1, y0) * fx;
    const T bottom = image(x0, y0 + 1) * (S(1) - fx) + image(x0 + 1, y0 + 1) * fx;
    return top * (S(1) - fy) + bottom * fy;
  }

  /// Whether the reference intensity varies at (u, v) by at least
  /// min_gradient per pixel (central differences; border pixels do not).
  EMF_HD bool textured(int u, int v) const {
    const int wd = reference_intensity.width, ht = reference_intensity.height;
    if (u < 1 || v < 1 || u >= wd - 1 || v >= ht - 1) return false;
    const S gx = S(0.5) * (reference_intensity(u + 1, v) - reference_intensity(u - 1, v));
    const S gy = S(0.5) * (reference_intensity(u, v + 1) - reference_intensity(u, v - 1));
    return gx * gx + gy * gy >= min_gradient * min_gradient;
  }
};

/// Builds the photometric terms of a reference frame (its vertex map, camera
/// frame, and intensity) against the current frame's intensity and gradient,
/// with the reference camera at T_frame_reference in the frame the pose is
/// solved in (the world for a camera, the volume's frame for
/// align_to_volume_and_intensity, which rebases it itself). Throws
/// std::invalid_argument when an image is empty or the sizes disagree.
template <class S, Backend B>
PhotometricTerms<S> make_photometric(const Image<Vec3<S>, B>& reference_points,
                                     const Image<S, B>& reference_intensity, const SE3<S>& T_frame_reference,
                                     const Image<S, B>& intensity, const Image<Vec2<S>, B>& gradient,
                                     const PinholeCamera<S>& camera, const PhotometricParams<S>& params = {}) {
  constexpr const char* where = "make_photometric";
  detail::require(!reference_points.empty(), where, "the reference vertex map is empty");
  detail::require_image(reference_intensity.view(), reference_points.width(), reference_points.height(), where,
                        "reference intensity image");
  detail::require_image(intensity.view(), camera.width, camera.height, where, "intensity image");
  detail::require_image(gradient.view(), camera.width, camera.height, where, "intensity gradient image");
  detail::require(params.pixel_stride >= 1, where, "pixel_stride must be at least 1");
  detail::require(params.min_gradient >= S(0), where, "min_gradient must not be negative");
  PhotometricTerms<S> t;
  t.reference_points = reference_points.view();
  t.reference_intensity = reference_intensity.view();
  t.intensity = intensity.view();
  t.gradient = gradient.view();
  t.T_frame_reference = T_frame_reference;
  t.camera = camera;
  t.stride = params.pixel_stride;
  t.min_gradient = params.min_gradient;
  return t;
}

/// Minimises the robust photometric cost alone over the current camera's
/// pose (in the frame of terms.T_frame_reference) with `solver`, from
/// `start`: frame-to-frame direct odometry.
template <class S, Backend B, class Norm, class Solver>
  requires RobustNorm<Norm, S> && PoseSolver<Solver, S>
SE3<S> align_photometric(const B& backend, const PhotometricTerms<S>& terms, const Norm& norm, const Solver& solver,
                         const SE3<S>& start, SolveReport* report = nullptr) {
  const auto lin = [&](const SE3<S>& pose, const SE3<S>* reference) {
    return linearize(backend, terms, norm, pose, reference);
  };
  return solver.solve(lin, start, report);
}

/// The SDF term of `volume` (dense or sparse, as align_to_volume) plus
/// `weight` times the photometric term `photometric`, each with its own
/// norm, minimised over T_world_camera with `solver` from `T_world_camera`, coarse to fine over
/// params.pyramid_levels levels (both terms take every 2^level-th of their
/// pixels). photometric.T_frame_reference is the reference camera in the
/// world: the function moves it into the volume's frame. weight = 0 is
/// align_to_volume. The report is the finest level's, with the iterations
/// of all levels added up.
template <class S, Backend B, class Volume, class Norm, class PhotometricNorm, class Solver>
  requires TsdfVolumeOn<Volume, S, B> && RobustNorm<Norm, S> && RobustNorm<PhotometricNorm, S> &&
           PoseSolver<Solver, S>
SE3<S> align_to_volume_and_intensity(const Volume& volume, const Image<Vec3<S>, B>& points,
                                     const Image<S, B>* association, const SE3<S>& T_world_camera,
                                     const Norm& norm, const SdfAlignmentParams<S>& params,
                                     PhotometricTerms<S> photometric, const PhotometricNorm& photometric_norm,
                                     S weight, const Solver& solver, SolveReport* report = nullptr) {
  detail::require(weight >= S(0) && std::isfinite(weight), "align_to_volume_and_intensity",
                  "the photometric weight must be finite and not negative");
  const B& backend = volume.backend();
  const SE3<S> T_volume_world = volume.pose().inverse();
  photometric.T_frame_reference = T_volume_world * photometric.T_frame_reference;
  const sdf_alignment_terms_t<S, Volume> sdf = sdf_alignment_in_box(volume, points, association, params, backend);
  const int photometric_stride = photometric.stride;
  const SE3<S> T = coarse_to_fine(
      params.pyramid_levels, T_volume_world * T_world_camera, report,
      [&](int level, const SE3<S>& from, SolveReport& r) {
        const sdf_alignment_terms_t<S, Volume> sdf_level = at_level(sdf, params, level);
        photometric.stride = photometric_stride << level;
        const auto lin = [&](const SE3<S>& pose, const SE3<S>* reference) {
          NormalEquations6 n = linearize(backend, sdf_level, norm, pose, reference);
          if (weight > S(0)) n += scaled(linearize(backend, photometric, photometric_norm, pose, reference), weight);
          return n;
        };
        return solver_at_level(solver, level, params.pyramid_levels).solve(lin, from, &r);
      });
  return volume.pose() * T;
}

}  // namespace emfusion
