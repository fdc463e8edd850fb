// Co-Fusion image folders (shared/FORMATS.md section 1), the layout of the
// Co-Fusion synthetic scenes: <dir>/colour/Color%04d.png, <dir>/depth/
// Depth%04d.exr (float32 metres, one channel or one picked as read_exr
// says) and a calibration.txt ("fx fy cx cy width height").
//
// The format has no timestamps: frame i (counted from 0, whatever number
// its files carry) has timestamp i / frame_rate, 30 Hz by default, as
// Co-Fusion itself assumes. Co-Fusion numbers its files from 0 or from 1;
// here the numbering may start at any number but must be consecutive and
// every colour file must have its depth file and vice versa.
//
// CoFusionSequence is a FrameSource. open() lists both folders and checks
// the numbering and the calibration; depth(i) reads one EXR on demand.
// Errors are std::runtime_error naming the function and the folder or file:
// "CoFusionSequence::open: '<dir>/depth/Depth0004.exr': not found (needed
// by '<dir>/colour/Color0004.png')". Bad options are std::invalid_argument.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <filesystem>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <system_error>
#include <vector>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/camera.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/io/detail/files.hpp"
#include "emfusion/io/exr.hpp"
#include "emfusion/io/frame_source.hpp"
#include "emfusion/io/tum.hpp"

namespace emfusion {

/// Options of CoFusionSequence::open.
struct CoFusionOptions {
  /// Intrinsics to use instead of calibration.txt.
  std::optional<PinholeCamera<double>> camera;
  /// Frames per second: frame i has timestamp i / frame_rate.
  double frame_rate = 30.0;
  /// EXR channel holding the depth; empty: chosen as read_exr does.
  std::string depth_channel;
};

namespace detail::cofusion {

/// The frame number of a file called "<prefix>NNNN<extension>" with at least
/// four digits, written as %04d writes them; -1 for any other name.
inline long frame_number(const std::string& name, const std::string& prefix, const std::string& extension) {
  if (name.size() < prefix.size() + 4 + extension.size()) return -1;
  if (name.compare(0, prefix.size(), prefix) != 0) return -1;
  if (name.compare(name.size() - extension.size(), extension.size(), extension) != 0) return -1;
  const std::string digits = name.substr(prefix.size(), name.size() - prefix.size() - extension.size());
  if (digits.size() > 9) return -1;
  long number = 0;
  for (const char c : digits) {
    if (c < '0' || c > '9') return -1;
    number = number * 10 + (c - '0');
  }
  if (digits.size() > 4 && digits[0] == '0') return -1;  // not what %04d writes
  return number;
}

inline std::string file_name(const std::string& prefix, long number, const std::string& extension) {
  char digits[32];
  std::snprintf(digits, sizeof(digits), "%04ld", number);
  return prefix + digits + extension;
}

/// The numbered files of a folder, by number.
inline std::map<long, std::string> numbered_files(const std::filesystem::path& folder, const std::string& prefix,
                                                  const std::string& extension) {
  std::map<long, std::string> files;
  for (const auto& entry : std::filesystem::directory_iterator(folder)) {
    std::error_code ec;
    if (!entry.is_regular_file(ec)) continue;
    const std::string name = entry.path().filename().string();
    const long number = frame_number(name, prefix, extension);
    if (number >= 0) files.emplace(number, entry.path().string());
  }
  return files;
}

}  // namespace detail::cofusion

/// A Co-Fusion image folder (see the top of this header) as a FrameSource.
class CoFusionSequence {
 public:
  static CoFusionSequence open(const std::string& dir, const CoFusionOptions& options = {});

  /// Number of frames.
  std::size_t size() const { return depth_paths_.size(); }
  /// i / frame_rate seconds (the format has no timestamps).
  double timestamp(std::size_t i) const {
    check(i, "CoFusionSequence::timestamp");
    return double(i) / options_.frame_rate;
  }
  /// Depth of frame i in metres, from its EXR file; non-finite and negative
  /// values become 0 (no measurement). The EXR must have the camera's size.
  Image<float, Host> depth(std::size_t i) const;
  /// Path of frame i's depth EXR.
  const std::string& depth_path(std::size_t i) const {
    check(i, "CoFusionSequence::depth_path");
    return depth_paths_[i];
  }
  /// Path of frame i's colour PNG.
  const std::string& colour_path(std::size_t i) const {
    check(i, "CoFusionSequence::colour_path");
    return colour_paths_[i];
  }
  /// The number in the file names of frame 0 (0 or 1 in Co-Fusion's data).
  long first_number() const { return first_number_; }

  const PinholeCamera<double>& camera() const { return camera_; }
  /// "CoFusionOptions::camera" or the path of the calibration file used.
  const std::string& camera_source() const { return camera_source_; }
  const std::string& dir() const { return dir_; }
  const CoFusionOptions& options() const { return options_; }

 private:
  void check(std::size_t i, const char* where) const {
    if (i >= depth_paths_.size())
      throw std::out_of_range(std::string(where) + ": frame " + std::to_string(i) + " out of range (" +
                              std::to_string(depth_paths_.size()) + " frames in " + detail::io::quoted(dir_) + ")");
  }

  std::string dir_;
  CoFusionOptions options_;
  PinholeCamera<double> camera_;
  std::string camera_source_;
  std::vector<std::string> colour_paths_;
  std::vector<std::string> depth_paths_;
  long first_number_ = 0;
};

inline CoFusionSequence CoFusionSequence::open(const std::string& dir, const CoFusionOptions& options) {
  namespace fs = std::filesystem;
  namespace cf = detail::cofusion;
  constexpr const char* where = "CoFusionSequence::open";
  using detail::io::fail;
  if (!(options.frame_rate > 0) || !std::isfinite(options.frame_rate))
    throw std::invalid_argument(std::string(where) + ": frame_rate must be positive and finite, got " +
                                std::to_string(options.frame_rate));
  if (options.camera) options.camera->validate("CoFusionSequence::open: CoFusionOptions::camera");

  std::error_code ec;
  if (!fs::exists(dir, ec)) fail(where, dir, "directory not found");
  if (!fs::is_directory(dir, ec)) fail(where, dir, "not a directory");
  const fs::path colour_dir = fs::path(dir) / "colour";
  const fs::path depth_dir = fs::path(dir) / "depth";
  if (!fs::is_directory(colour_dir, ec)) fail(where, dir, "no folder 'colour' (colour/Color%04d.png)");
  if (!fs::is_directory(depth_dir, ec)) fail(where, dir, "no folder 'depth' (depth/Depth%04d.exr)");

  const std::map<long, std::string> colour = cf::numbered_files(colour_dir, "Color", ".png");
  const std::map<long, std::string> depth = cf::numbered_files(depth_dir, "Depth", ".exr");
  if (colour.empty() && depth.empty())
    fail(where, dir, "no frames: neither colour/Color%04d.png nor depth/Depth%04d.exr files");

  CoFusionSequence seq;
  seq.dir_ = dir;
  seq.options_ = options;
  const long first = std::min(colour.empty() ? depth.begin()->first : colour.begin()->first,
                              depth.empty() ? colour.begin()->first : depth.begin()->first);
  const long last = std::max(colour.empty() ? depth.rbegin()->first : colour.rbegin()->first,
                             depth.empty() ? colour.rbegin()->first : depth.rbegin()->first);
  seq.first_number_ = first;
  for (long n = first; n <= last; ++n) {
    const auto c = colour.find(n);
    const auto d = depth.find(n);
    const std::string colour_name = (colour_dir / cf::file_name("Color", n, ".png")).string();
    const std::string depth_name = (depth_dir / cf::file_name("Depth", n, ".exr")).string();
    if (c == colour.end() && d == depth.end())
      fail(where, dir,
           "gap in the frame numbering: neither " + detail::io::quoted(colour_name) + " nor " +
               detail::io::quoted(depth_name) + " exists (frames run from " + std::to_string(first) + " to " +
               std::to_string(last) + ")");
    if (d == depth.end()) fail(where, depth_name, "not found (needed by " + detail::io::quoted(c->second) + ")");
    if (c == colour.end()) fail(where, colour_name, "not found (needed by " + detail::io::quoted(d->second) + ")");
    seq.colour_paths_.push_back(c->second);
    seq.depth_paths_.push_back(d->second);
  }

  const std::string calibration = (fs::path(dir) / "calibration.txt").string();
  const std::string colour_calibration = (colour_dir / "calibration.txt").string();
  if (options.camera) {
    seq.camera_ = *options.camera;
    seq.camera_source_ = "CoFusionOptions::camera";
  } else if (fs::is_regular_file(calibration, ec)) {
    seq.camera_ = read_calibration(calibration);
    seq.camera_source_ = calibration;
  } else if (fs::is_regular_file(colour_calibration, ec)) {
    seq.camera_ = read_calibration(colour_calibration);
    seq.camera_source_ = colour_calibration;
  } else {
    fail(where, dir, "no calibration.txt (nor colour/calibration.txt): give the camera in CoFusionOptions::camera");
  }
  return seq;
}

inline Image<float, Host> CoFusionSequence::depth(std::size_t i) const {
  check(i, "CoFusionSequence::depth");
  const std::string& path = depth_paths_[i];
  Image<float, Host> image = read_exr(path, options_.depth_channel);
  if (!image.same_size(camera_.width, camera_.height))
    detail::io::fail("CoFusionSequence::depth", path,
                     "the image is " + std::to_string(image.width()) + "x" + std::to_string(image.height()) +
                         " but the camera (" + camera_source_ + ") is " + std::to_string(camera_.width) + "x" +
                         std::to_string(camera_.height));
  const ImageView<float> metres = image.view();
  for (int k = 0; k < metres.size(); ++k)
    if (!(std::isfinite(metres[k]) && metres[k] > 0.f)) metres[k] = 0.f;
  return image;
}

static_assert(FrameSource<CoFusionSequence>);

}  // namespace emfusion
