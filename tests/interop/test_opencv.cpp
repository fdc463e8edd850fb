// interop/opencv.hpp: views that share the cv::Mat's pixels (same pointer,
// writes showing through) and Mats that share an image's; copies of 16-bit
// and float depth with the scale applied and holes kept, as TumSequence
// reads the same PNG; colour in both channel orders; label images and
// detections from label Mats and from per-instance masks; every wrong Mat
// (empty, wrong type, not continuous, 3-D, bad values) refused naming the
// function and the problem. Small images only: the whole file runs in
// milliseconds.
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "emfusion/interop/opencv.hpp"
#include "emfusion/io/tum.hpp"
#include "support/catch.hpp"
#include "support/files.hpp"

using namespace emfusion;
using emfusion::test::contains;
using emfusion::test::error_of;
using emfusion::test::ScratchDir;

namespace {

/// A 4x3 Mat of type `type` whose pixel (x, y) is f(x, y).
template <class T, class F>
cv::Mat make_mat(int type, F f, int width = 4, int height = 3) {
  cv::Mat m(height, width, type);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) m.at<T>(y, x) = f(x, y);
  return m;
}

/// The message of the std::invalid_argument `f` throws ("" for none, and a
/// failed check for another exception type).
template <class F>
std::string invalid_argument_of(F f) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    return e.what();
  } catch (const std::exception& e) {
    FAIL("expected std::invalid_argument, got: " << e.what());
  }
  return "";
}

}  // namespace

TEST_CASE("opencv::view shares the Mat's pixels", "[interop]") {
  cv::Mat m = make_mat<float>(CV_32FC1, [](int x, int y) { return float(10 * y + x); });
  const ImageView<const float> v = opencv::view<const float>(m);
  CHECK(static_cast<const void*>(v.data) == static_cast<const void*>(m.data));
  CHECK(v.width == 4);
  CHECK(v.height == 3);
  CHECK(v(3, 2) == 23.f);
  // A writable view writes into the Mat.
  const ImageView<float> w = opencv::view<float>(m);
  w(1, 2) = -5.f;
  CHECK(m.at<float>(2, 1) == -5.f);

  cv::Mat labels = make_mat<std::uint16_t>(CV_16UC1, [](int x, int) { return std::uint16_t(x); });
  CHECK(static_cast<const void*>(opencv::view<const std::uint16_t>(labels).data) ==
        static_cast<const void*>(labels.data));
  cv::Mat ints = make_mat<int>(CV_32SC1, [](int x, int y) { return x - y; });
  CHECK(opencv::view<const int>(ints)(0, 2) == -2);
}

TEST_CASE("opencv::view refuses Mats it cannot view", "[interop]") {
  const cv::Mat floats(3, 4, CV_32FC1, cv::Scalar(1.0));
  std::string e = invalid_argument_of([] { opencv::view<const float>(cv::Mat()); });
  CHECK(contains(e, "opencv::view: the Mat is empty"));
  e = invalid_argument_of([&] { opencv::view<const std::uint16_t>(floats); });
  CHECK(contains(e, "opencv::view: the Mat is CV_32FC1, expected CV_16UC1"));
  e = invalid_argument_of([] { opencv::view<const float>(cv::Mat(3, 4, CV_32FC3)); });
  CHECK(contains(e, "the Mat is CV_32FC3, expected CV_32FC1"));
  // A region of a larger Mat has padded rows: no single block to view.
  const cv::Mat big(6, 8, CV_32FC1, cv::Scalar(2.0));
  const cv::Mat region = big(cv::Rect(1, 1, 4, 3));
  REQUIRE(!region.isContinuous());
  e = invalid_argument_of([&] { opencv::view<const float>(region); });
  CHECK(contains(e, "opencv::view: the Mat is not continuous"));
  CHECK(contains(e, "clone() it"));
  const int sizes[] = {2, 3, 4};
  e = invalid_argument_of([&] { opencv::view<const float>(cv::Mat(3, sizes, CV_32FC1)); });
  CHECK(contains(e, "the Mat has 3 dimensions, expected 2"));
}

TEST_CASE("opencv::depth_view views float metres and sends 16-bit depth to the copy", "[interop]") {
  const cv::Mat metres = make_mat<float>(CV_32FC1, [](int x, int) { return x == 0 ? 0.f : 0.5f * float(x); });
  const ImageView<const float> v = opencv::depth_view(metres);
  CHECK(static_cast<const void*>(v.data) == static_cast<const void*>(metres.data));
  CHECK(v(0, 1) == 0.f);
  CHECK(v(3, 1) == 1.5f);

  const cv::Mat raw(3, 4, CV_16UC1, cv::Scalar(5000));
  std::string e = invalid_argument_of([&] { opencv::depth_view(raw); });
  CHECK(contains(e, "opencv::depth_view: the depth Mat is CV_16UC1, expected CV_32FC1 in metres"));
  CHECK(contains(e, "depth_from_mat(mat, depth_scale)"));
  e = invalid_argument_of([] { opencv::depth_view(cv::Mat()); });
  CHECK(contains(e, "opencv::depth_view: the depth Mat is empty"));
  const cv::Mat big(6, 8, CV_32FC1, cv::Scalar(1.0));
  e = invalid_argument_of([&] { opencv::depth_view(big(cv::Rect(0, 0, 3, 3))); });
  CHECK(contains(e, "not continuous"));
  CHECK(contains(e, "depth_from_mat"));
}

TEST_CASE("opencv::depth_from_mat converts 16-bit depth with its scale, holes kept", "[interop]") {
  const cv::Mat raw = make_mat<std::uint16_t>(CV_16UC1, [](int x, int y) { return std::uint16_t((x + y) * 2500); });
  const Image<float, Host> d = opencv::depth_from_mat(raw, 5000);
  REQUIRE(d.same_size(4, 3));
  const ImageView<const float> v = d.view();
  CHECK(static_cast<const void*>(v.data) != static_cast<const void*>(raw.data));
  CHECK(v(0, 0) == 0.f);  // no measurement stays no measurement
  CHECK(v(1, 0) == 0.5f);
  CHECK(v(3, 2) == float(12500.0 / 5000.0));
  // Millimetres.
  CHECK(opencv::depth_from_mat(raw, 1000).view()(1, 1) == 5.f);
  // A region of a larger Mat is copied row by row.
  cv::Mat big(6, 8, CV_16UC1, cv::Scalar(0));
  raw.copyTo(big(cv::Rect(2, 1, 4, 3)));
  const Image<float, Host> from_region = opencv::depth_from_mat(big(cv::Rect(2, 1, 4, 3)), 5000);
  CHECK(from_region.to_host() == d.to_host());
  // Float Mats in other units take the scale too.
  const cv::Mat mm = make_mat<float>(CV_32FC1, [](int x, int) { return 1000.f * float(x); });
  CHECK(opencv::depth_from_mat(mm, 1000).view()(2, 0) == 2.f);
  CHECK(opencv::depth_from_mat(mm, 1000).view()(0, 0) == 0.f);
}

TEST_CASE("opencv::depth_from_mat of a 16-bit PNG equals TumSequence::depth", "[interop]") {
  ScratchDir dir;
  const cv::Mat raw = make_mat<std::uint16_t>(
      CV_16UC1, [](int x, int y) { return std::uint16_t(x == 1 && y == 1 ? 0 : 3 + 7919 * (x + 4 * y)); }, 8, 6);
  std::filesystem::create_directories(dir.file("depth"));
  REQUIRE(cv::imwrite(dir.file("depth/0.png"), raw));
  dir.write("depth.txt", "0.0 depth/0.png\n");
  dir.write("calibration.txt", "10 10 3.5 2.5 8 6\n");
  const TumSequence seq = TumSequence::open(dir.path());
  const cv::Mat read = cv::imread(seq.depth_path(0), cv::IMREAD_UNCHANGED);
  REQUIRE(read.type() == CV_16UC1);
  CHECK(opencv::depth_from_mat(read, 5000).to_host() == seq.depth(0).to_host());
}

TEST_CASE("opencv::depth_from_mat keeps float metres and refuses what it cannot convert", "[interop]") {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const cv::Mat metres = make_mat<float>(CV_32FC1, [&](int x, int) { return x == 0 ? 0.f : x == 1 ? nan : 1.25f; });
  const Image<float, Host> d = opencv::depth_from_mat(metres);
  const ImageView<const float> v = d.view();
  CHECK(v(0, 2) == 0.f);
  CHECK(std::isnan(v(1, 2)));
  CHECK(v(3, 2) == 1.25f);
  CHECK(!is_valid_depth(v(1, 0)));

  std::string e = invalid_argument_of([] { opencv::depth_from_mat(cv::Mat(2, 2, CV_16UC1, cv::Scalar(1))); });
  CHECK(contains(e, "opencv::depth_from_mat: the depth Mat is CV_16UC1, expected CV_32FC1 in metres"));
  CHECK(contains(e, "give the depth scale"));
  e = invalid_argument_of([] { opencv::depth_from_mat(cv::Mat(2, 2, CV_8UC1), 5000); });
  CHECK(contains(e, "opencv::depth_from_mat: the depth Mat is CV_8UC1, expected CV_16UC1 or CV_32FC1"));
  e = invalid_argument_of([] { opencv::depth_from_mat(cv::Mat(2, 2, CV_16UC1), 0); });
  CHECK(contains(e, "opencv::depth_from_mat: depth_scale must be positive and finite"));
  e = invalid_argument_of([] { opencv::depth_from_mat(cv::Mat(2, 2, CV_16UC1), std::nan("")); });
  CHECK(contains(e, "depth_scale must be positive and finite"));
  e = invalid_argument_of([] { opencv::depth_from_mat(cv::Mat(), 5000); });
  CHECK(contains(e, "opencv::depth_from_mat: the depth Mat is empty"));
}

TEST_CASE("opencv colour: BGR, BGRA and gray Mats copied as RGB; an RGB Mat viewed", "[interop]") {
  cv::Mat bgr(2, 3, CV_8UC3);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 3; ++x) bgr.at<cv::Vec3b>(y, x) = cv::Vec3b(std::uint8_t(x), std::uint8_t(y), 200);
  const ColourImage c = opencv::colour_from_mat(bgr);
  CHECK(c.view()(2, 1) == Rgb8{200, 1, 2});
  // And back to OpenCV's order, pixel for pixel.
  const cv::Mat back = opencv::bgr_from_colour(c);
  REQUIRE(back.type() == CV_8UC3);
  CHECK(cv::norm(back, bgr, cv::NORM_INF) == 0);

  cv::Mat bgra(1, 2, CV_8UC4, cv::Scalar(10, 20, 30, 255));
  CHECK(opencv::colour_from_mat(bgra).view()(1, 0) == Rgb8{30, 20, 10});
  cv::Mat gray(1, 2, CV_8UC1, cv::Scalar(77));
  CHECK(opencv::colour_from_mat(gray).view()(0, 0) == gray_rgb(77));

  // An RGB Mat is viewed in place.
  const cv::Mat rgb(2, 3, CV_8UC3, cv::Scalar(1, 2, 3));
  const ImageView<const Rgb8> v = opencv::rgb_view(rgb);
  CHECK(static_cast<const void*>(v.data) == static_cast<const void*>(rgb.data));
  CHECK(v(2, 1) == Rgb8{1, 2, 3});

  std::string e = invalid_argument_of([] { opencv::colour_from_mat(cv::Mat(2, 2, CV_16UC3)); });
  CHECK(contains(e, "opencv::colour_from_mat: the colour Mat is CV_16UC3, expected CV_8UC3 (BGR)"));
  e = invalid_argument_of([] { opencv::rgb_view(cv::Mat(2, 2, CV_8UC1)); });
  CHECK(contains(e, "opencv::rgb_view: the colour Mat is CV_8UC1, expected CV_8UC3 in RGB order"));
  e = invalid_argument_of([] { opencv::colour_from_mat(cv::Mat()); });
  CHECK(contains(e, "opencv::colour_from_mat: the colour Mat is empty"));
}

TEST_CASE("opencv::labels_from_mat copies 8-, 16- and 32-bit label Mats", "[interop]") {
  const auto f = [](int x, int y) { return x + 4 * y; };
  const std::vector<std::uint16_t> expected = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11};
  CHECK(opencv::labels_from_mat(make_mat<std::uint8_t>(CV_8UC1, f)).to_host() == expected);
  CHECK(opencv::labels_from_mat(make_mat<std::uint16_t>(CV_16UC1, f)).to_host() == expected);
  CHECK(opencv::labels_from_mat(make_mat<int>(CV_32SC1, f)).to_host() == expected);

  std::string e = invalid_argument_of(
      [] { opencv::labels_from_mat(make_mat<int>(CV_32SC1, [](int x, int y) { return x == 2 && y == 1 ? -1 : 0; })); });
  CHECK(contains(e, "opencv::labels_from_mat: the label Mat has value -1 at x 2, y 1: labels must be in [0, 65535]"));
  e = invalid_argument_of([] { opencv::labels_from_mat(make_mat<int>(CV_32SC1, [](int, int) { return 70000; })); });
  CHECK(contains(e, "value 70000 at x 0, y 0"));
  e = invalid_argument_of([] { opencv::labels_from_mat(cv::Mat(2, 2, CV_32FC1)); });
  CHECK(contains(e, "opencv::labels_from_mat: the label Mat is CV_32FC1, expected CV_8UC1, CV_16UC1 or CV_32SC1"));
}

TEST_CASE("opencv::detections_from_labels with listed instances", "[interop]") {
  const cv::Mat labels =
      make_mat<std::uint8_t>(CV_8UC1, [](int x, int y) { return std::uint8_t(y == 0 ? 0 : x < 2 ? 1 : 3); });
  const Detections d = opencv::detections_from_labels(labels, {{1, "cup", 0.9}, {3, "car", 0.5}, {4, "book", 0.7}}, 2.5);
  CHECK(d.timestamp == 2.5);
  REQUIRE(d.instances.size() == 3);
  REQUIRE(d.find(3) != nullptr);
  CHECK(d.find(3)->class_name == "car");
  CHECK(d.labels.view()(3, 2) == 3);
  CHECK(d.labels.view()(0, 1) == 1);

  std::string e = invalid_argument_of([&] { opencv::detections_from_labels(labels, {{1, "cup", 0.9}}); });
  CHECK(contains(e, "opencv::detections_from_labels: the label Mat has value 3 at x 2, y 1, which is not the label of "
                    "a listed instance"));
  e = invalid_argument_of([&] { opencv::detections_from_labels(labels, {{1, "cup", 0.9}, {1, "car", 0.5}}); });
  CHECK(contains(e, "opencv::detections_from_labels: instance 1 is listed twice"));
  e = invalid_argument_of([&] { opencv::detections_from_labels(labels, {{1, "cup", 1.5}, {3, "car", 0.5}}); });
  CHECK(contains(e, "instance 1: the score 1.5"));
  e = invalid_argument_of([&] { opencv::detections_from_labels(labels, {{0, "cup", 0.5}}); });
  CHECK(contains(e, "instance 0: the label must be in [1, 65535]"));
  e = invalid_argument_of([&] { opencv::detections_from_labels(labels, {{1, "", 0.5}, {3, "car", 0.5}}); });
  CHECK(contains(e, "instance 1: the class name is empty"));
  e = invalid_argument_of([] { opencv::detections_from_labels(cv::Mat(2, 2, CV_32FC1), std::vector<Instance>{}); });
  CHECK(contains(e, "opencv::detections_from_labels: the label Mat is CV_32FC1"));

  // Nothing found: an all-zero image and no instances.
  const Detections none = opencv::detections_from_labels(cv::Mat(3, 4, CV_8UC1, cv::Scalar(0)), std::vector<Instance>{});
  CHECK(none.instances.empty());
  CHECK(none.labels.same_size(4, 3));
}

TEST_CASE("opencv::detections_from_labels with one class: every value present is an instance", "[interop]") {
  const cv::Mat labels = make_mat<std::uint16_t>(
      CV_16UC1, [](int x, int) { return std::uint16_t(x == 0 ? 0 : x == 1 ? 700 : 3); });
  const Detections d = opencv::detections_from_labels(labels, "person", 1.0, 0.8);
  REQUIRE(d.instances.size() == 2);
  CHECK(d.instances[0].label == 3);
  CHECK(d.instances[1].label == 700);
  CHECK(d.instances[1].class_name == "person");
  CHECK(d.instances[1].score == 0.8);
  CHECK(d.timestamp == 1.0);

  std::string e = invalid_argument_of([&] { opencv::detections_from_labels(labels, std::string()); });
  CHECK(contains(e, "opencv::detections_from_labels: the class name is empty"));
  e = invalid_argument_of([&] { opencv::detections_from_labels(labels, "person", 0.0, -0.1); });
  CHECK(contains(e, "the score -0.1"));
}

TEST_CASE("opencv::detections_from_masks: one label per mask, the higher score wins overlaps", "[interop]") {
  // Mask 0 (cup, 0.6) covers x < 3, mask 1 (book, 0.9) x >= 2: x == 2 is
  // both's, and the book's by its score. Mask 2 is a soft mask of row 2.
  const cv::Mat cup = make_mat<std::uint8_t>(CV_8UC1, [](int x, int) { return std::uint8_t(x < 3 ? 255 : 0); });
  const cv::Mat book = make_mat<std::uint8_t>(CV_8UC1, [](int x, int) { return std::uint8_t(x >= 2 ? 1 : 0); });
  const cv::Mat soft = make_mat<float>(CV_32FC1, [](int, int y) { return y == 2 ? 0.7f : 0.2f; });
  const Detections d =
      opencv::detections_from_masks({{cup, "cup", 0.6}, {book, "book", 0.9}, {soft, "table", 0.95}}, 4, 3, 0.5);
  REQUIRE(d.instances.size() == 3);
  CHECK(d.instances[0].label == 1);
  CHECK(d.instances[0].class_name == "cup");
  CHECK(d.instances[2].label == 3);
  const ImageView<const std::uint16_t> v = d.labels.view();
  CHECK(v(0, 0) == 1);
  CHECK(v(2, 0) == 2);
  CHECK(v(3, 1) == 2);
  CHECK(v(1, 2) == 3);

  // Nothing found: all zero, no instances, the frame's size.
  const Detections none = opencv::detections_from_masks({}, 4, 3);
  CHECK(none.instances.empty());
  CHECK(none.labels.to_host() == std::vector<std::uint16_t>(12, 0));

  std::string e = invalid_argument_of([&] { opencv::detections_from_masks({{cup, "cup", 0.6}}, 5, 3); });
  CHECK(contains(e, "opencv::detections_from_masks: the mask 0 (cup) is 4x3, expected 5x3"));
  e = invalid_argument_of([&] { opencv::detections_from_masks({{cv::Mat(3, 4, CV_16UC1), "cup", 0.6}}, 4, 3); });
  CHECK(contains(e, "the mask 0 (cup) is CV_16UC1, expected CV_8UC1 (non-zero inside) or CV_32FC1"));
  e = invalid_argument_of([&] { opencv::detections_from_masks({{cv::Mat(), "cup", 0.6}}, 4, 3); });
  CHECK(contains(e, "the mask 0 (cup) is empty"));
  e = invalid_argument_of([&] { opencv::detections_from_masks({{cup, "cup", 2.0}}, 4, 3); });
  CHECK(contains(e, "instance 1: the score 2"));
  e = invalid_argument_of([] { opencv::detections_from_masks({}, 0, 3); });
  CHECK(contains(e, "opencv::detections_from_masks: the size must be positive, got 0x3"));
}

TEST_CASE("opencv::mat_view shares an image's pixels; to_mat copies them", "[interop]") {
  Image<float, Host> image = Image<float, Host>::from_host(3, 2, {1, 2, 3, 4, 5, 6});
  cv::Mat header = opencv::mat_view(image);
  REQUIRE(header.type() == CV_32FC1);
  CHECK(header.rows == 2);
  CHECK(header.cols == 3);
  CHECK(static_cast<const void*>(header.data) == static_cast<const void*>(image.view().data));
  header.at<float>(1, 0) = 40.f;
  CHECK(image.view()(0, 1) == 40.f);
  // The round trip is the same memory.
  CHECK(opencv::view<const float>(header).data == image.view().data);

  const cv::Mat copy = opencv::to_mat(image);
  CHECK(static_cast<const void*>(copy.data) != static_cast<const void*>(image.view().data));
  CHECK(copy.at<float>(1, 2) == 6.f);
  CHECK(opencv::to_mat(Image<float, Host>()).empty());
  CHECK(opencv::mat_view(ImageView<float>{}).empty());

  ColourImage colour(2, 1, Rgb8{1, 2, 3});
  const cv::Mat rgb = opencv::to_mat(colour);
  REQUIRE(rgb.type() == CV_8UC3);
  CHECK(rgb.at<cv::Vec3b>(0, 1) == cv::Vec3b(1, 2, 3));
  Image<std::uint16_t, Host> labels(2, 2, std::uint16_t(9));
  CHECK(opencv::to_mat(labels).type() == CV_16UC1);
}

TEST_CASE("opencv::depth_to_mat writes 16-bit depth that reads back", "[interop]") {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const Image<float, Host> metres = Image<float, Host>::from_host(3, 2, {0.f, 1.0f, 2.5002f, nan, -1.f, 13.1f});
  const cv::Mat raw = opencv::depth_to_mat(metres, 5000);
  REQUIRE(raw.type() == CV_16UC1);
  CHECK(raw.at<std::uint16_t>(0, 0) == 0);
  CHECK(raw.at<std::uint16_t>(0, 1) == 5000);
  CHECK(raw.at<std::uint16_t>(0, 2) == 12501);
  CHECK(raw.at<std::uint16_t>(1, 0) == 0);  // NaN: no measurement
  CHECK(raw.at<std::uint16_t>(1, 1) == 0);  // negative: no measurement
  CHECK(raw.at<std::uint16_t>(1, 2) == 65500);
  const std::vector<float> back = opencv::depth_from_mat(raw, 5000).to_host();
  CHECK(back[1] == 1.0f);
  CHECK(back[3] == 0.f);

  std::string e = invalid_argument_of([] {
    opencv::depth_to_mat(Image<float, Host>::from_host(2, 1, {1.f, 14.f}), 5000);
  });
  CHECK(contains(e, "opencv::depth_to_mat: depth 14 m at x 1, y 0 does not fit 16 bits at depth_scale 5000 (at most 13.107 m)"));
  e = invalid_argument_of([&] { opencv::depth_to_mat(metres, -1); });
  CHECK(contains(e, "opencv::depth_to_mat: depth_scale must be positive and finite"));
}
