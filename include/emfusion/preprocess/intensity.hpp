// Intensity images for photometric alignment (solve/photometric.hpp): the
// gray value of a colour image in [0, 1], and its gradient per pixel.
//
// The colour pixel type is a template argument (anything with 8-bit r, g and
// b members, such as io/colour.hpp's Rgb8), so preprocess/ does not depend
// on io/. Gray is the Rec. 601 luma of the stored sRGB values, without gamma
// conversion, as OpenCV's cvtColor and most RGB-D odometry do.
#pragma once

#include "emfusion/core/backend.hpp"
#include "emfusion/core/error.hpp"
#include "emfusion/core/host_device.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/core/parallel.hpp"

namespace emfusion {

namespace detail {

template <class S, class Pixel>
struct IntensityKernel {
  ImageView<const Pixel> colour;
  ImageView<S> out;
  EMF_HD void operator()(int i) const {
    const Pixel p = colour[i];
    out[i] = (S(0.299) * S(p.r) + S(0.587) * S(p.g) + S(0.114) * S(p.b)) / S(255);
  }
};

template <class S>
struct GradientKernel {
  ImageView<const S> intensity;
  ImageView<Vec2<S>> out;
  EMF_HD void operator()(int i) const {
    const int w = intensity.width, h = intensity.height;
    const int x = i % w, y = i / w;
    const int x0 = x > 0 ? x - 1 : x, x1 = x + 1 < w ? x + 1 : x;
    const int y0 = y > 0 ? y - 1 : y, y1 = y + 1 < h ? y + 1 : y;
    // Central differences inside, one-sided at the border.
    const S gx = x1 > x0 ? (intensity(x1, y) - intensity(x0, y)) / S(x1 - x0) : S(0);
    const S gy = y1 > y0 ? (intensity(x, y1) - intensity(x, y0)) / S(y1 - y0) : S(0);
    out[i] = vec2(gx, gy);
  }
};

}  // namespace detail

/// The gray value in [0, 1] of every pixel of `colour` into `intensity`,
/// (re)allocated to its size on the backend `backend`. Throws
/// std::invalid_argument if `colour` is empty.
template <class S, Backend B, class Pixel, Backend BC>
void intensity_image(const Image<Pixel, BC>& colour, Image<S, B>& intensity, const B& backend = B{}) {
  detail::require(!colour.empty(), "emfusion::intensity_image", "the colour image is empty");
  const Image<Pixel, B> on_backend = colour.template to<B>();
  if (!intensity.same_size(colour.width(), colour.height()))
    intensity = Image<S, B>(colour.width(), colour.height(), S(0), backend);
  for_each_index(intensity.backend(), intensity.size(),
                 detail::IntensityKernel<S, Pixel>{on_backend.view(), intensity.view()});
}

/// The intensity gradient (d I / d u, d I / d v, per pixel) of every pixel
/// of `intensity` into `gradient`: central differences, one-sided at the
/// image border. Throws std::invalid_argument if `intensity` is empty.
template <class S, Backend B>
void intensity_gradient(const Image<S, B>& intensity, Image<Vec2<S>, B>& gradient) {
  detail::require(!intensity.empty(), "emfusion::intensity_gradient", "the intensity image is empty");
  if (!gradient.same_size(intensity.width(), intensity.height()))
    gradient = Image<Vec2<S>, B>(intensity.width(), intensity.height(), Vec2<S>{}, intensity.backend());
  for_each_index(gradient.backend(), gradient.size(), detail::GradientKernel<S>{intensity.view(), gradient.view()});
}

}  // namespace emfusion
