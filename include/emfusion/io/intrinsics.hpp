// Camera intrinsics given on the command line, for inputs that carry none
// (.klg logs) or to override a calibration file: named presets (the TUM
// RGB-D benchmark's Freiburg 1/2/3 cameras and the default Kinect-style
// camera of shared/PARAMETERS.md) and "fx,fy,cx,cy[,width,height]" text.
//
// Errors are std::invalid_argument naming the function and the text:
// "intrinsics_preset: unknown preset 'fr4' (valid: default, fr1, fr2, fr3)".
#pragma once

#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <stdexcept>
#include <string>
#include <system_error>
#include <vector>

#include "emfusion/core/camera.hpp"

namespace emfusion {

/// A named set of intrinsics, all 640x480.
struct IntrinsicsPreset {
  const char* name;
  double fx, fy, cx, cy;
  const char* what;
};

/// The presets: "default" (fx = fy = 525, cx = 319.5, cy = 239.5, the
/// project's default camera) and the TUM RGB-D benchmark's published
/// intrinsics of its Freiburg 1, 2 and 3 sequences.
inline const std::array<IntrinsicsPreset, 4>& intrinsics_presets() {
  static constexpr std::array<IntrinsicsPreset, 4> presets = {{
      {"default", 525.0, 525.0, 319.5, 239.5, "default camera (PinholeCamera<double>{})"},
      {"fr1", 517.3, 516.5, 318.6, 255.3, "TUM RGB-D Freiburg 1"},
      {"fr2", 520.9, 521.0, 325.1, 249.7, "TUM RGB-D Freiburg 2"},
      {"fr3", 535.4, 539.2, 320.1, 247.6, "TUM RGB-D Freiburg 3"},
  }};
  return presets;
}

/// The preset called `name` (case-insensitive): "default", "fr1", "fr2" or
/// "fr3", 640x480.
inline PinholeCamera<double> intrinsics_preset(const std::string& name) {
  std::string key = name;
  for (char& c : key) c = char(std::tolower(static_cast<unsigned char>(c)));
  std::string valid;
  for (const IntrinsicsPreset& p : intrinsics_presets()) {
    if (key == p.name) return PinholeCamera<double>{p.fx, p.fy, p.cx, p.cy, 640, 480};
    valid += (valid.empty() ? "" : ", ") + std::string(p.name);
  }
  throw std::invalid_argument("intrinsics_preset: unknown preset '" + name + "' (valid: " + valid + ")");
}

/// Parses "fx,fy,cx,cy" or "fx,fy,cx,cy,width,height" (spaces around the
/// fields allowed); without a size the camera is 640x480. fx and fy must be
/// positive, cx and cy finite, width and height positive integers.
inline PinholeCamera<double> parse_intrinsics(const std::string& text) {
  const auto bad = [&](const std::string& problem) {
    throw std::invalid_argument("parse_intrinsics: '" + text + "': " + problem +
                                " (expected fx,fy,cx,cy or fx,fy,cx,cy,width,height)");
  };
  std::vector<std::string> fields;
  for (std::size_t start = 0;;) {
    const std::size_t comma = text.find(',', start);
    std::string field = text.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    const std::size_t first = field.find_first_not_of(" \t");
    const std::size_t last = field.find_last_not_of(" \t");
    fields.push_back(first == std::string::npos ? std::string() : field.substr(first, last - first + 1));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  if (fields.size() != 4 && fields.size() != 6) bad(std::to_string(fields.size()) + " fields");
  static constexpr const char* names[6] = {"fx", "fy", "cx", "cy", "width", "height"};
  double values[6] = {0, 0, 0, 0, 640, 480};
  for (std::size_t k = 0; k < fields.size(); ++k) {
    const std::string& field = fields[k];
    if (field.empty()) bad(std::string(names[k]) + " is empty");
    const char* begin = field.data();
    const char* end = begin + field.size();
    if (*begin == '+') ++begin;
    double value = 0;
    const auto result = std::from_chars(begin, end, value);
    if (begin == end || result.ptr != end || result.ec != std::errc() || !std::isfinite(value))
      bad(std::string(names[k]) + " '" + field + "' is not a finite number");
    values[k] = value;
  }
  if (!(values[0] > 0)) bad("fx " + fields[0] + " is not positive");
  if (!(values[1] > 0)) bad("fy " + fields[1] + " is not positive");
  for (std::size_t k = 4; k < fields.size(); ++k)
    if (!(values[k] >= 1) || values[k] != std::floor(values[k]) || values[k] > 1e6)
      bad(std::string(names[k]) + " " + fields[k] + " is not a positive integer (at most 1000000)");
  return PinholeCamera<double>{values[0], values[1], values[2], values[3], int(values[4]), int(values[5])};
}

/// A command-line camera argument: a preset name if it is one, else
/// "fx,fy,cx,cy[,width,height]".
inline PinholeCamera<double> intrinsics_from_argument(const std::string& text) {
  if (text.find(',') != std::string::npos) return parse_intrinsics(text);
  try {
    return intrinsics_preset(text);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument("intrinsics_from_argument: '" + text +
                                "' is neither a preset nor fx,fy,cx,cy[,width,height]: " + e.what());
  }
}

}  // namespace emfusion
