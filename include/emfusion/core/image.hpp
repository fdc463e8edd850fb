// Images: `Image<T, B>` owns width x height pixels on backend B;
// `ImageView<T>` is the raw pointer and size that kernels capture.
//
// Pixels are stored row by row. Depth images hold metres, 0 (or a non-finite
// value) meaning "no measurement".
#pragma once

#include <cmath>
#include <string>
#include <type_traits>
#include <vector>

#include <thrust/copy.h>
#include <thrust/fill.h>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/error.hpp"
#include "emfusion/core/host_device.hpp"

namespace emfusion {

/// Non-owning view of an image; cheap to copy into kernels.
template <class T>
struct ImageView {
  T* data = nullptr;
  int width = 0;
  int height = 0;

  EMF_HD T& operator()(int x, int y) const { return data[y * width + x]; }
  EMF_HD T& operator[](int i) const { return data[i]; }
  EMF_HD int size() const { return width * height; }
  EMF_HD bool empty() const { return data == nullptr || width <= 0 || height <= 0; }
  EMF_HD bool contains(int x, int y) const { return x >= 0 && y >= 0 && x < width && y < height; }
  /// True if pixel index i lies at least `border` pixels inside every edge.
  EMF_HD bool inside_border(int i, int border) const {
    const int x = i % width, y = i / width;
    return x >= border && y >= border && x < width - border && y < height - border;
  }

  /// A read-only view of the same pixels (only for views of mutable pixels:
  /// a conversion of ImageView<const T> to itself would draw nvcc warnings).
  template <class U = T>
    requires(!std::is_const_v<U>)
  EMF_HD operator ImageView<const U>() const {
    return {data, width, height};
  }
};

/// True for a depth that is a measurement: finite and positive. Zero marks a
/// hole; negative depths cannot come from a pinhole camera, so they are holes
/// too.
template <class S>
EMF_HD bool is_valid_depth(S depth) {
  return std::isfinite(depth) && depth > S(0);
}

template <class T, Backend B = Host>
class Image {
 public:
  using value_type = T;
  using backend_type = B;

  Image() = default;
  /// A width x height image filled with `fill`.
  Image(int width, int height, const T& fill = T{}, B backend = B{})
      : width_(checked_extent(width, "width")), height_(checked_extent(height, "height")),
        data_(std::size_t(width) * std::size_t(height), fill), backend_(backend) {}

  /// Copies host pixels (row by row, width * height of them) into a new image.
  static Image from_host(int width, int height, const std::vector<T>& pixels, B backend = B{}) {
    detail::require(pixels.size() == std::size_t(width) * std::size_t(height), "Image::from_host",
                    "expected " + std::to_string(std::size_t(width) * std::size_t(height)) +
                        " pixels for " + std::to_string(width) + "x" + std::to_string(height) +
                        ", got " + std::to_string(pixels.size()));
    Image img(width, height, T{}, backend);
    thrust::copy(pixels.begin(), pixels.end(), img.data_.begin());
    return img;
  }

  int width() const { return width_; }
  int height() const { return height_; }
  int size() const { return width_ * height_; }
  bool empty() const { return size() == 0; }
  const B& backend() const { return backend_; }

  ImageView<T> view() { return {raw(), width_, height_}; }
  ImageView<const T> view() const { return {raw(), width_, height_}; }

  void fill(const T& value) { thrust::fill(backend_.policy(), data_.begin(), data_.end(), value); }

  /// The pixels as a host vector (synchronises with the backend).
  std::vector<T> to_host() const { return vector_to_host(backend_, data_); }

  /// A copy of this image on another backend.
  template <Backend B2>
  Image<T, B2> to(B2 backend = B2{}) const {
    backend_.synchronize();
    Image<T, B2> out;
    out.width_ = width_, out.height_ = height_, out.backend_ = backend;
    out.data_ = data_;
    return out;
  }

  bool same_size(int width, int height) const { return width_ == width && height_ == height; }

 private:
  template <class, Backend>
  friend class Image;

  static int checked_extent(int v, const char* what) {
    detail::require(v >= 0, "Image", std::string(what) + " must not be negative, got " + std::to_string(v));
    return v;
  }
  // No pointer into an empty vector: thrust forms it by dereferencing null.
  T* raw() { return raw_data(data_); }
  const T* raw() const { return raw_data(data_); }

  int width_ = 0;
  int height_ = 0;
  typename B::template Vector<T> data_;
  B backend_{};
};

namespace detail {
/// Throws unless `view` is non-empty and width x height.
template <class T>
void require_image(const ImageView<T>& view, int width, int height, const char* where, const char* name) {
  require(!view.empty(), where, std::string(name) + " is empty");
  require(view.width == width && view.height == height, where,
          std::string(name) + " is " + std::to_string(view.width) + "x" + std::to_string(view.height) +
              " but " + std::to_string(width) + "x" + std::to_string(height) + " was expected");
}
}  // namespace detail

}  // namespace emfusion
