// OpenCV interop: frames held as cv::Mat (a camera driver's, cv::imread's)
// as emfusion images and detections, and emfusion images back as cv::Mat.
// Optional: CMake builds and installs it, as the target emfusion::opencv,
// only where OpenCV is found; nothing else in emfusion includes it.
//
// Which calls copy:
//
//   no copy  view<T>(mat), depth_view(mat), rgb_view(mat): an ImageView over
//            the Mat's own pixels (a continuous Mat of exactly that type);
//            mat_view(image) and mat_view(view): a cv::Mat header over a
//            host image's pixels. Both share memory: the owner of the
//            pixels must outlive the view, and writes show through.
//   copy     depth_from_mat, colour_from_mat, labels_from_mat,
//            detections_from_labels, detections_from_masks (cv::Mat to
//            emfusion) and to_mat, depth_to_mat, bgr_from_colour (emfusion
//            to cv::Mat). These take any 2-D Mat of an accepted type,
//            continuous or not (a region of a larger Mat, padded rows).
//
// System::process takes an owned Image<S, B> and Detections hold an owned
// label image, so frames for the system go through the copying calls (one
// pass over the pixels, cheap beside the system's work; a 16-bit depth needs
// its scale applied anyway). The views are for a user's own loop over the
// stages' kernels (ImageView<const float> depth) and for looking at results.
//
// Conventions match io/: depth in metres, 0 (or a non-finite value) meaning
// "no measurement"; a 16-bit depth value k is k / depth_scale metres and 0
// stays 0, as TumSequence::depth reads a PNG. Colour Mats are in OpenCV's
// blue-green-red order; emfusion's Rgb8 is red-green-blue (io/colour.hpp).
// Labels follow detect/detection.hpp: pixel value k > 0 belongs to instance
// k, 0 to none.
//
// Bad arguments throw std::invalid_argument "<function>: <problem>", naming
// the Mat's type where it is the wrong one (core/error.hpp).
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <initializer_list>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include <opencv2/core.hpp>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/error.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/detect/detection.hpp"
#include "emfusion/io/colour.hpp"

namespace emfusion::opencv {

namespace detail {

/// The cv::Mat type of a pixel type (unsupported types have no `value`).
template <class T>
struct MatType {};
template <> struct MatType<std::uint8_t> { static constexpr int value = CV_8UC1; };
template <> struct MatType<std::int8_t> { static constexpr int value = CV_8SC1; };
template <> struct MatType<std::uint16_t> { static constexpr int value = CV_16UC1; };
template <> struct MatType<std::int16_t> { static constexpr int value = CV_16SC1; };
template <> struct MatType<std::int32_t> { static constexpr int value = CV_32SC1; };
template <> struct MatType<float> { static constexpr int value = CV_32FC1; };
template <> struct MatType<double> { static constexpr int value = CV_64FC1; };
template <> struct MatType<Rgb8> { static constexpr int value = CV_8UC3; };

/// "CV_16UC1" for a cv::Mat type.
inline std::string type_name(int type) {
  static const char* const depths[] = {"CV_8U", "CV_8S", "CV_16U", "CV_16S", "CV_32S", "CV_32F", "CV_64F", "CV_16F"};
  return std::string(depths[CV_MAT_DEPTH(type)]) + "C" + std::to_string(CV_MAT_CN(type));
}

/// Throws unless `mat` is a non-empty 2-D Mat; `what` names it ("depth Mat").
inline void require_2d(const cv::Mat& mat, const char* where, const std::string& what) {
  emfusion::detail::require(!mat.empty(), where, "the " + what + " is empty");
  emfusion::detail::require(mat.dims == 2, where,
                            "the " + what + " has " + std::to_string(mat.dims) + " dimensions, expected 2");
}

/// Throws unless `mat` is a non-empty 2-D Mat of one of `types`; `expected`
/// says what they are ("CV_16UC1 (with a depth scale) or CV_32FC1 (metres)").
inline void require_type(const cv::Mat& mat, std::initializer_list<int> types, const char* where,
                         const std::string& what, const std::string& expected) {
  require_2d(mat, where, what);
  bool ok = false;
  for (const int t : types) ok = ok || mat.type() == t;
  emfusion::detail::require(ok, where, "the " + what + " is " + type_name(mat.type()) + ", expected " + expected);
}

/// Throws unless `mat` is continuous (views need one block of pixels).
inline void require_continuous(const cv::Mat& mat, const char* where, const std::string& what, const char* instead) {
  emfusion::detail::require(mat.isContinuous(), where,
                            "the " + what + " is not continuous (a region of a larger Mat, or padded rows): a view "
                            "needs one block of pixels; clone() it, or use " + std::string(instead) + ", which copies");
}

/// Calls f(x, y, pixel) for every pixel of a Mat of element type T, row by
/// row (works for non-continuous Mats).
template <class T, class F>
void for_each_pixel(const cv::Mat& mat, F&& f) {
  for (int y = 0; y < mat.rows; ++y) {
    const T* row = mat.ptr<T>(y);
    for (int x = 0; x < mat.cols; ++x) f(x, y, row[x]);
  }
}

/// A number for messages, as short as %g writes it ("5000", "13.107").
inline std::string number(double value) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%g", value);
  return buffer;
}

/// "x 3, y 7" for messages.
inline std::string at(int x, int y) { return "x " + std::to_string(x) + ", y " + std::to_string(y); }

/// Checks instances as masks.txt would hold them (detect/detection.hpp):
/// labels in [1, 65535], none twice, a class name, a score in [0, 1].
inline void require_instances(const std::vector<Instance>& instances, const char* where) {
  std::vector<unsigned char> seen(65536, 0);
  for (const Instance& inst : instances) {
    const std::string name = "instance " + std::to_string(inst.label);
    emfusion::detail::require(inst.label >= 1 && inst.label <= 65535, where,
                              name + ": the label must be in [1, 65535]");
    emfusion::detail::require(!seen[std::size_t(inst.label)], where, name + " is listed twice");
    seen[std::size_t(inst.label)] = 1;
    emfusion::detail::require(!inst.class_name.empty(), where, name + ": the class name is empty");
    emfusion::detail::require(inst.score >= 0.0 && inst.score <= 1.0, where,
                              name + ": the score " + number(inst.score) + " is not in [0, 1]");
  }
}

}  // namespace detail

/// A pixel type with a cv::Mat type: std::uint8_t (CV_8UC1), std::int8_t
/// (CV_8SC1), std::uint16_t (CV_16UC1), std::int16_t (CV_16SC1), int
/// (CV_32SC1), float (CV_32FC1), double (CV_64FC1), Rgb8 (CV_8UC3).
template <class T>
concept MatPixel = requires { detail::MatType<std::remove_const_t<T>>::value; };

/// The cv::Mat type of pixel type T (CV_32FC1 for float).
template <MatPixel T>
inline constexpr int mat_type = detail::MatType<std::remove_const_t<T>>::value;

// ---- cv::Mat to emfusion, no copy ------------------------------------------

/// NO COPY. An ImageView over `mat`'s pixels, which must be a continuous 2-D
/// Mat of exactly T's type (mat_type<T>). view<const float>(m) is read-only,
/// view<float>(m) writes into the Mat. Valid while the Mat's pixels live.
template <MatPixel T>
ImageView<T> view(const cv::Mat& mat) {
  constexpr const char* where = "opencv::view";
  detail::require_type(mat, {mat_type<T>}, where, "Mat", detail::type_name(mat_type<T>) + " for this view");
  detail::require_continuous(mat, where, "Mat", "labels_from_mat, depth_from_mat or colour_from_mat");
  return {reinterpret_cast<T*>(mat.data), mat.cols, mat.rows};
}

/// NO COPY. A depth view of a continuous CV_32FC1 Mat in metres (0 or NaN:
/// no measurement). A 16-bit depth needs its scale: depth_from_mat copies.
inline ImageView<const float> depth_view(const cv::Mat& metres) {
  constexpr const char* where = "opencv::depth_view";
  detail::require_2d(metres, where, "depth Mat");
  emfusion::detail::require(metres.type() == CV_32FC1, where,
                            "the depth Mat is " + detail::type_name(metres.type()) +
                                ", expected CV_32FC1 in metres" +
                                (metres.type() == CV_16UC1
                                     ? std::string(" (16-bit depth needs its scale: depth_from_mat(mat, depth_scale) "
                                                   "converts it, copying)")
                                     : std::string()));
  detail::require_continuous(metres, where, "depth Mat", "depth_from_mat");
  return {reinterpret_cast<const float*>(metres.data), metres.cols, metres.rows};
}

/// NO COPY. A colour view of a continuous CV_8UC3 Mat whose channels are in
/// red-green-blue order (cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB) makes
/// one). The order cannot be checked: a BGR Mat gives swapped colours; use
/// colour_from_mat for those.
inline ImageView<const Rgb8> rgb_view(const cv::Mat& rgb) {
  constexpr const char* where = "opencv::rgb_view";
  detail::require_type(rgb, {CV_8UC3}, where, "colour Mat", "CV_8UC3 in RGB order");
  detail::require_continuous(rgb, where, "colour Mat", "colour_from_mat");
  return {reinterpret_cast<const Rgb8*>(rgb.data), rgb.cols, rgb.rows};
}

// ---- cv::Mat to emfusion, copying --------------------------------------------

/// COPY. Depth in metres from a CV_32FC1 Mat in metres, values unchanged (0,
/// NaN, infinite or negative: no measurement, as the system reads them).
inline Image<float, Host> depth_from_mat(const cv::Mat& metres) {
  constexpr const char* where = "opencv::depth_from_mat";
  detail::require_2d(metres, where, "depth Mat");
  emfusion::detail::require(metres.type() == CV_32FC1, where,
                            "the depth Mat is " + detail::type_name(metres.type()) +
                                ", expected CV_32FC1 in metres; give the depth scale for other types "
                                "(depth_from_mat(mat, depth_scale), e.g. 5000 for TUM's 16-bit PNGs)");
  Image<float, Host> out(metres.cols, metres.rows);
  const ImageView<float> o = out.view();
  detail::for_each_pixel<float>(metres, [&](int x, int y, float v) { o(x, y) = v; });
  return out;
}

/// COPY. Depth in metres from a CV_16UC1 or CV_32FC1 Mat holding
/// `depth_scale` units per metre (5000 for TUM PNGs, 1000 for millimetres):
/// value / depth_scale, 0 staying 0 (TumSequence::depth's conversion, bit
/// for bit for 16-bit Mats). depth_scale must be positive and finite.
inline Image<float, Host> depth_from_mat(const cv::Mat& depth, double depth_scale) {
  constexpr const char* where = "opencv::depth_from_mat";
  emfusion::detail::require(depth_scale > 0 && std::isfinite(depth_scale), where,
                            "depth_scale must be positive and finite, got " + detail::number(depth_scale));
  detail::require_type(depth, {CV_16UC1, CV_32FC1}, where, "depth Mat",
                       "CV_16UC1 or CV_32FC1 (units per metre given by depth_scale)");
  Image<float, Host> out(depth.cols, depth.rows);
  const ImageView<float> o = out.view();
  if (depth.type() == CV_16UC1)
    detail::for_each_pixel<std::uint16_t>(depth, [&](int x, int y, std::uint16_t v) {
      o(x, y) = v == 0 ? 0.f : float(double(v) / depth_scale);
    });
  else
    detail::for_each_pixel<float>(depth, [&](int x, int y, float v) {
      o(x, y) = v == 0 ? 0.f : float(double(v) / depth_scale);
    });
  return out;
}

/// COPY. A colour image from a CV_8UC3 Mat in OpenCV's BGR order (what
/// cv::imread gives), a CV_8UC4 BGRA Mat (alpha dropped) or a CV_8UC1 gray
/// one.
inline ColourImage colour_from_mat(const cv::Mat& bgr) {
  constexpr const char* where = "opencv::colour_from_mat";
  detail::require_type(bgr, {CV_8UC3, CV_8UC4, CV_8UC1}, where, "colour Mat",
                       "CV_8UC3 (BGR), CV_8UC4 (BGRA) or CV_8UC1 (gray)");
  ColourImage out(bgr.cols, bgr.rows);
  const ImageView<Rgb8> o = out.view();
  const int channels = bgr.channels();
  for (int y = 0; y < bgr.rows; ++y) {
    const std::uint8_t* row = bgr.ptr<std::uint8_t>(y);
    for (int x = 0; x < bgr.cols; ++x) {
      const std::uint8_t* p = row + std::size_t(x) * std::size_t(channels);
      o(x, y) = channels == 1 ? gray_rgb(p[0]) : Rgb8{p[2], p[1], p[0]};
    }
  }
  return out;
}

namespace detail {
/// labels_from_mat, its messages naming `where`.
inline Image<std::uint16_t, Host> copy_labels(const cv::Mat& labels, const char* where) {
  require_type(labels, {CV_8UC1, CV_16UC1, CV_32SC1}, where, "label Mat",
               "CV_8UC1, CV_16UC1 or CV_32SC1 (one instance id per pixel)");
  Image<std::uint16_t, Host> out(labels.cols, labels.rows);
  const ImageView<std::uint16_t> o = out.view();
  if (labels.type() == CV_8UC1)
    for_each_pixel<std::uint8_t>(labels, [&](int x, int y, std::uint8_t v) { o(x, y) = v; });
  else if (labels.type() == CV_16UC1)
    for_each_pixel<std::uint16_t>(labels, [&](int x, int y, std::uint16_t v) { o(x, y) = v; });
  else
    for_each_pixel<std::int32_t>(labels, [&](int x, int y, std::int32_t v) {
      emfusion::detail::require(v >= 0 && v <= 65535, where,
                                "the label Mat has value " + std::to_string(v) + " at " + at(x, y) +
                                    ": labels must be in [0, 65535]");
      o(x, y) = std::uint16_t(v);
    });
  return out;
}
}  // namespace detail

/// COPY. A label image (detect/detection.hpp: k > 0 instance k, 0 none) from
/// a CV_8UC1, CV_16UC1 or CV_32SC1 Mat whose values are in [0, 65535].
inline Image<std::uint16_t, Host> labels_from_mat(const cv::Mat& labels) {
  return detail::copy_labels(labels, "opencv::labels_from_mat");
}

/// COPY. Detections from a label Mat (as labels_from_mat) and the instances
/// it holds, as a masks.txt line lists them: labels in [1, 65535] and none
/// twice, a class name, a score in [0, 1]. Every non-zero pixel value must
/// be a listed label; a listed label absent from the image is allowed (its
/// mask is empty). An empty `instances` with an all-zero Mat is "the
/// detector ran and found nothing".
inline Detections detections_from_labels(const cv::Mat& labels, const std::vector<Instance>& instances,
                                         double timestamp = 0) {
  constexpr const char* where = "opencv::detections_from_labels";
  detail::require_instances(instances, where);
  Detections d;
  d.timestamp = timestamp;
  d.labels = detail::copy_labels(labels, where);
  d.instances = instances;
  std::vector<unsigned char> listed(65536, 0);
  listed[0] = 1;
  for (const Instance& inst : instances) listed[std::size_t(inst.label)] = 1;
  const ImageView<const std::uint16_t> px = d.labels.view();
  for (int k = 0; k < px.size(); ++k)
    emfusion::detail::require(listed[px[k]], where,
                              "the label Mat has value " + std::to_string(px[k]) + " at " +
                                  detail::at(k % px.width, k / px.width) +
                                  ", which is not the label of a listed instance");
  return d;
}

/// COPY. Detections from a label Mat where every value k > 0 that occurs is
/// one instance of class `class_name` with `score` (a class-agnostic
/// segmenter, or one object kind), in increasing order of k.
inline Detections detections_from_labels(const cv::Mat& labels, const std::string& class_name, double timestamp = 0,
                                         double score = 1.0) {
  constexpr const char* where = "opencv::detections_from_labels";
  emfusion::detail::require(!class_name.empty(), where, "the class name is empty");
  emfusion::detail::require(score >= 0.0 && score <= 1.0, where,
                            "the score " + detail::number(score) + " is not in [0, 1]");
  Image<std::uint16_t, Host> image = detail::copy_labels(labels, where);
  std::vector<unsigned char> present(65536, 0);
  const ImageView<const std::uint16_t> px = image.view();
  for (int k = 0; k < px.size(); ++k) present[px[k]] = 1;
  Detections d;
  d.timestamp = timestamp;
  d.labels = std::move(image);
  for (int label = 1; label <= 65535; ++label)
    if (present[std::size_t(label)]) d.instances.push_back({label, class_name, score});
  return d;
}

/// One detector instance as a binary mask (CV_8UC1: non-zero is inside;
/// CV_32FC1: a soft mask, >= 0.5 inside) with its class and score.
struct MaskInstance {
  cv::Mat mask;
  std::string class_name;
  double score = 1.0;
};

/// COPY. Detections from a list of width x height masks (a network's
/// per-instance output): mask k gets label k + 1. A pixel inside several
/// masks goes to the one with the higher score (the earlier on a tie), as
/// the label image holds one instance per pixel. An empty list gives an
/// all-zero label image: "the detector ran and found nothing". At most
/// 65535 masks; class names and scores as detections_from_labels checks them.
inline Detections detections_from_masks(const std::vector<MaskInstance>& masks, int width, int height,
                                        double timestamp = 0) {
  constexpr const char* where = "opencv::detections_from_masks";
  emfusion::detail::require(width > 0 && height > 0, where,
                            "the size must be positive, got " + std::to_string(width) + "x" + std::to_string(height));
  emfusion::detail::require(masks.size() <= 65535, where,
                            std::to_string(masks.size()) + " masks, at most 65535 fit a 16-bit label image");
  Detections d;
  d.timestamp = timestamp;
  for (std::size_t k = 0; k < masks.size(); ++k) d.instances.push_back({int(k + 1), masks[k].class_name, masks[k].score});
  detail::require_instances(d.instances, where);
  d.labels = Image<std::uint16_t, Host>(width, height);
  const ImageView<std::uint16_t> o = d.labels.view();
  std::vector<double> best(std::size_t(width) * std::size_t(height), -1.0);
  for (std::size_t k = 0; k < masks.size(); ++k) {
    const cv::Mat& m = masks[k].mask;
    const std::string what = "mask " + std::to_string(k) + " (" + masks[k].class_name + ")";
    detail::require_type(m, {CV_8UC1, CV_32FC1}, where, what, "CV_8UC1 (non-zero inside) or CV_32FC1 (>= 0.5 inside)");
    emfusion::detail::require(m.cols == width && m.rows == height, where,
                              "the " + what + " is " + std::to_string(m.cols) + "x" + std::to_string(m.rows) +
                                  ", expected " + std::to_string(width) + "x" + std::to_string(height));
    const double score = masks[k].score;
    const std::uint16_t label = std::uint16_t(k + 1);
    const auto take = [&](int x, int y) {
      const std::size_t i = std::size_t(y) * std::size_t(width) + std::size_t(x);
      if (score > best[i]) best[i] = score, o(x, y) = label;
    };
    if (m.type() == CV_8UC1)
      detail::for_each_pixel<std::uint8_t>(m, [&](int x, int y, std::uint8_t v) { if (v != 0) take(x, y); });
    else
      detail::for_each_pixel<float>(m, [&](int x, int y, float v) { if (v >= 0.5f) take(x, y); });
  }
  return d;
}

// ---- emfusion to cv::Mat -------------------------------------------------------

/// NO COPY. A cv::Mat header (mat_type<T>) over a view's pixels: writes go
/// both ways; valid while the pixels live. An empty view gives an empty Mat.
/// Rgb8 pixels give a CV_8UC3 Mat in RGB order (bgr_from_colour for BGR).
template <MatPixel T>
  requires(!std::is_const_v<T>)
cv::Mat mat_view(ImageView<T> view) {
  if (view.empty()) return cv::Mat();
  return cv::Mat(view.height, view.width, mat_type<T>, static_cast<void*>(view.data));
}

/// NO COPY. mat_view of a host image's pixels.
template <MatPixel T>
cv::Mat mat_view(Image<T, Host>& image) {
  return mat_view(image.view());
}

/// COPY. A cv::Mat (mat_type<T>) of an image's pixels, on any backend (a
/// device image is copied to the host). Rgb8 images give RGB order.
template <MatPixel T, Backend B>
cv::Mat to_mat(const Image<T, B>& image) {
  if (image.empty()) return cv::Mat();
  const std::vector<T> pixels = image.to_host();
  cv::Mat out(image.height(), image.width(), mat_type<T>);
  std::memcpy(out.data, pixels.data(), pixels.size() * sizeof(T));
  return out;
}

/// COPY. A CV_16UC1 depth Mat (cv::imwrite writes it as a 16-bit PNG) of a
/// depth image in metres: round(metres * depth_scale); holes (0, NaN,
/// infinite, negative) become 0. A depth beyond 65535 / depth_scale metres
/// does not fit and throws, naming the pixel.
template <Backend B>
cv::Mat depth_to_mat(const Image<float, B>& metres, double depth_scale) {
  constexpr const char* where = "opencv::depth_to_mat";
  emfusion::detail::require(depth_scale > 0 && std::isfinite(depth_scale), where,
                            "depth_scale must be positive and finite, got " + detail::number(depth_scale));
  if (metres.empty()) return cv::Mat();
  const std::vector<float> pixels = metres.to_host();
  cv::Mat out(metres.height(), metres.width(), CV_16UC1);
  for (int y = 0; y < out.rows; ++y) {
    std::uint16_t* row = out.ptr<std::uint16_t>(y);
    for (int x = 0; x < out.cols; ++x) {
      const float m = pixels[std::size_t(y) * std::size_t(out.cols) + std::size_t(x)];
      if (!is_valid_depth(m)) {
        row[x] = 0;
        continue;
      }
      const double v = std::round(double(m) * depth_scale);
      emfusion::detail::require(v <= 65535.0, where,
                                "depth " + detail::number(m) + " m at " + detail::at(x, y) +
                                    " does not fit 16 bits at depth_scale " + detail::number(depth_scale) +
                                    " (at most " + detail::number(65535.0 / depth_scale) + " m)");
      row[x] = std::uint16_t(v);
    }
  }
  return out;
}

/// COPY. A CV_8UC3 Mat in OpenCV's BGR order (for cv::imwrite, cv::imshow)
/// of a colour image.
inline cv::Mat bgr_from_colour(const ColourImage& colour) {
  if (colour.empty()) return cv::Mat();
  cv::Mat out(colour.height(), colour.width(), CV_8UC3);
  const ImageView<const Rgb8> in = colour.view();
  for (int y = 0; y < out.rows; ++y) {
    std::uint8_t* row = out.ptr<std::uint8_t>(y);
    for (int x = 0; x < out.cols; ++x) {
      const Rgb8 p = in(x, y);
      row[3 * x] = p.b, row[3 * x + 1] = p.g, row[3 * x + 2] = p.r;
    }
  }
  return out;
}

}  // namespace emfusion::opencv
