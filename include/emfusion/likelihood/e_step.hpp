// The E-step of EM-Fusion (paper eq. 5): per pixel, the association
// likelihood of its measured point to each of any number of models,
//   q_k(u) = p(u | k) / sum_k' p(u | k'),
// with a uniform prior over models. Pixels without a measurement, or whose
// point lies outside every model, get 0 for every model.
//
// One association image per model, in the order the models are given
// (the system puts the background first). Models are of one type M
// satisfying MeasurementLikelihood; each comes with the pose that maps camera
// points into its volume frame. A second form takes the background's model
// apart, of a type of its own (a model of a sparse background beside dense
// objects), and gives the same numbers as the first when the types agree.
#pragma once

#include <algorithm>
#include <cstddef>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include <thrust/copy.h>

#include "emfusion/core/error.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/likelihood/measurement_likelihood.hpp"

namespace emfusion {

template <class S, Backend B>
class Associations;

namespace detail {
/// The background model of the E-step's first form: none.
struct NoBackground {};
template <class S, Backend B, class M, class Objects>
void run_e_step(const B& backend, const Image<Vec3<S>, B>& points, const M* background,
                const SE3<S>& T_background_camera, std::span<const Objects> objects,
                std::span<const SE3<S>> T_object_camera, Associations<S, B>& out, bool background_unchanged);
}  // namespace detail

/// The E-step's output: one association image per model. Reuse one object
/// across frames: images and scratch buffers are kept while sizes stay.
template <class S, Backend B = Host>
class Associations {
 public:
  int model_count() const { return int(images_.size()); }
  /// q_k(u) for model k.
  const Image<S, B>& image(int k) const { return images_.at(std::size_t(k)); }
  Image<S, B>& image(int k) { return images_.at(std::size_t(k)); }

  /// Makes room for `models` images of width x height (contents undefined).
  void resize(int models, int width, int height, const B& backend) {
    if (int(images_.size()) > models) images_.resize(std::size_t(models));
    for (Image<S, B>& img : images_)
      if (!img.same_size(width, height)) img = Image<S, B>(width, height, S(0), backend);
    while (int(images_.size()) < models) images_.emplace_back(width, height, S(0), backend);
  }

  /// p(u | background) of the last E-step with the background apart
  /// (before normalisation), and the pose it was computed at: a later
  /// E-step of the same frame whose only change is objects' poses reuses it
  /// (e_step's `background_unchanged`).
  const Image<S, B>& background_likelihood() const { return background_likelihood_; }

 private:
  template <class S2, Backend B2, class M, class Objects>
  friend void detail::run_e_step(const B2&, const Image<Vec3<S2>, B2>&, const M*, const SE3<S2>&,
                                 std::span<const Objects>, std::span<const SE3<S2>>, Associations<S2, B2>&, bool);

  std::vector<Image<S, B>> images_;
  Image<S, B> background_likelihood_;
  SE3<S> background_pose_ = SE3<S>::identity();
  // Models, poses and output views as bytes on the backend, so that a kernel
  // can read any number of them without a fixed capacity.
  typename B::template Vector<unsigned char> scratch_;
};

namespace detail {

template <class S, class M>
struct EStepPixel {
  ImageView<const Vec3<S>> points;
  const M* models;
  const SE3<S>* T_volume_camera;
  ImageView<S>* out;
  int model_count;

  EMF_HD void operator()(int i) const {
    const Vec3<S> p = points[i];
    S total = S(0);
    const bool valid = std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z());
    for (int k = 0; k < model_count; ++k) {
      const S l = valid ? likelihood_of(models[k], T_volume_camera[k] * p, p) : S(0);
      out[k][i] = l;
      total += l;
    }
    const S scale = total > S(0) ? S(1) / total : S(0);
    for (int k = 0; k < model_count; ++k) out[k][i] *= scale;
  }
};

/// EStepPixel with a background model of its own type before the others;
/// the same sums in the same order.
template <class S, class MB, class M>
struct EStepBackgroundPixel {
  ImageView<const Vec3<S>> points;
  MB background;
  SE3<S> T_background_camera;
  const M* models;
  const SE3<S>* T_volume_camera;
  ImageView<S>* out;  ///< the background's first, then one per model
  int model_count;
  ImageView<S> kept;  ///< p(u | background): written, or read when `reuse`
  bool reuse;

  EMF_HD void operator()(int i) const {
    const Vec3<S> p = points[i];
    const bool valid = std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z());
    S total = S(0);
    S l0;
    if (reuse) {
      l0 = kept[i];
    } else {
      l0 = valid ? likelihood_of(background, T_background_camera * p, p) : S(0);
      kept[i] = l0;
    }
    out[0][i] = l0;
    total += l0;
    for (int k = 0; k < model_count; ++k) {
      const S l = valid ? likelihood_of(models[k], T_volume_camera[k] * p, p) : S(0);
      out[k + 1][i] = l;
      total += l;
    }
    const S scale = total > S(0) ? S(1) / total : S(0);
    for (int k = 0; k <= model_count; ++k) out[k][i] *= scale;
  }
};

/// Whether two poses are the same, bit for bit (no tolerance: a pose that
/// moved at all gives other likelihoods).
template <class S>
bool same_bits(const SE3<S>& a, const SE3<S>& b) {
  const auto ma = a.matrix(), mb = b.matrix();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c)
      if (!(ma(r, c) == mb(r, c))) return false;
  return true;
}

/// Bytes needed to place `count` objects of T after `offset`, aligned.
template <class T>
std::size_t place(std::size_t& offset, std::size_t count) {
  const std::size_t a = alignof(T) > 16 ? alignof(T) : 16;
  offset = (offset + a - 1) / a * a;
  const std::size_t at = offset;
  offset += count * sizeof(T);
  return at;
}

}  // namespace detail

/// Computes the association images of `models` (poses T_volume_camera[k])
/// for the camera-frame points (non-finite = no measurement).
template <class S, Backend B, class M>
void e_step(const B& backend, const Image<Vec3<S>, B>& points, std::span<const M> models,
            std::span<const SE3<S>> T_volume_camera, Associations<S, B>& out) {
  detail::run_e_step(backend, points, static_cast<const detail::NoBackground*>(nullptr), SE3<S>::identity(), models,
                     T_volume_camera, out, false);
}

/// The same with the background's model apart, of a type of its own (e.g.
/// PaperLikelihood over a SparseTsdfView beside dense objects): image 0 is
/// the background's, image k + 1 object k's. With models of one type it
/// gives exactly what the first form gives for {background, objects...}.
/// `background_unchanged` promises that the background's volume and
/// `points` are those of the last call with `out`, so that only objects may
/// have moved: p(u | background) is then taken from that call
/// (Associations::background_likelihood) when it was computed at the same
/// T_background_camera, bit for bit, and computed otherwise. The numbers are
/// the same either way; the system's last E-step of a frame, after the
/// objects' solves, skips the background's samples with it.
template <class S, Backend B, class Background, class M>
void e_step(const B& backend, const Image<Vec3<S>, B>& points, const Background& background,
            const SE3<S>& T_background_camera, std::span<const M> objects, std::span<const SE3<S>> T_object_camera,
            Associations<S, B>& out, bool background_unchanged = false) {
  static_assert(MeasurementLikelihood<Background, S>, "the background model must satisfy MeasurementLikelihood");
  static_assert(std::is_trivially_copyable_v<Background>, "likelihood models are copied to the backend as bytes");
  detail::run_e_step(backend, points, &background, T_background_camera, objects, T_object_camera, out,
                     background_unchanged);
}

namespace detail {

/// Both forms of e_step: `background` (a NoBackground: none) before the
/// models of `objects`.
template <class S, Backend B, class M, class Objects>
void run_e_step(const B& backend, const Image<Vec3<S>, B>& points, const M* background,
                const SE3<S>& T_background_camera, std::span<const Objects> objects,
                std::span<const SE3<S>> T_object_camera, Associations<S, B>& out, bool background_unchanged) {
  static_assert(MeasurementLikelihood<Objects, S>, "the model type must satisfy MeasurementLikelihood");
  static_assert(std::is_trivially_copyable_v<Objects>, "likelihood models are copied to the backend as bytes");
  require(objects.size() == T_object_camera.size(), "e_step",
          std::to_string(objects.size()) + " models but " + std::to_string(T_object_camera.size()) + " poses");
  require(!points.empty(), "e_step", "the vertex map is empty");
  constexpr bool apart = !std::is_same_v<M, NoBackground>;
  const int first = apart ? 1 : 0;
  const int n = int(objects.size()) + first;
  out.resize(n, points.width(), points.height(), backend);
  if (n == 0) return;

  std::vector<ImageView<S>> views;
  for (int k = 0; k < n; ++k) views.push_back(out.image(k).view());
  std::size_t size = 0;
  const std::size_t at_models = place<Objects>(size, objects.size());
  const std::size_t at_poses = place<SE3<S>>(size, objects.size());
  const std::size_t at_views = place<ImageView<S>>(size, views.size());
  std::vector<unsigned char> bytes(size);
  const auto put = [&](std::size_t at, const void* from, std::size_t count) {
    if (count == 0 || at + count > bytes.size()) return;  // never past the end: `size` covers every entry
    const auto* b = static_cast<const unsigned char*>(from);
    std::copy(b, b + count, bytes.begin() + std::ptrdiff_t(at));
  };
  put(at_models, objects.data(), objects.size() * sizeof(Objects));
  put(at_poses, T_object_camera.data(), objects.size() * sizeof(SE3<S>));
  put(at_views, views.data(), views.size() * sizeof(ImageView<S>));
  if (out.scratch_.size() < size) out.scratch_.resize(size);
  thrust::copy(bytes.begin(), bytes.end(), out.scratch_.begin());
  unsigned char* base = raw_data(out.scratch_);
  const auto* models = reinterpret_cast<const Objects*>(base + at_models);
  const auto* poses = reinterpret_cast<const SE3<S>*>(base + at_poses);
  auto* images = reinterpret_cast<ImageView<S>*>(base + at_views);
  if constexpr (apart) {
    // The kept image is allocated by the first E-step of this size that
    // wrote it, so its size says whether there is one to reuse.
    const bool kept = out.background_likelihood_.same_size(points.width(), points.height());
    const bool reuse = background_unchanged && kept && same_bits(out.background_pose_, T_background_camera);
    if (!kept) out.background_likelihood_ = Image<S, B>(points.width(), points.height(), S(0), backend);
    out.background_pose_ = T_background_camera;
    for_each_index(backend, points.size(),
                   EStepBackgroundPixel<S, M, Objects>{points.view(), *background, T_background_camera, models, poses,
                                                       images, int(objects.size()),
                                                       out.background_likelihood_.view(), reuse});
  } else {
    for_each_index(backend, points.size(), EStepPixel<S, Objects>{points.view(), models, poses, images, n});
  }
}

}  // namespace detail

}  // namespace emfusion
