// The TUM RGB-D formats (shared/FORMATS.md sections 1, 3, 4): trajectories
// ("timestamp tx ty tz qx qy qz qw"), camera calibration files ("fx fy cx cy
// width height") and sequence directories (associations.txt, or rgb.txt and
// depth.txt, 16-bit PNG depth), the input of the SLAM system.
//
// All text files allow '#' comments (to the end of the line), blank lines,
// and spaces, tabs or commas between fields, as the TUM benchmark's own
// scripts do. Paths in lists cannot contain spaces.
//
// The readers also take text in memory (parse_tum_trajectory,
// parse_calibration, parse_tum_list; format_tum_trajectory is the writer's
// text), with a name standing for the file in messages: the fuzz targets of
// tests/fuzz/ call them without touching the file system.
//
// Errors are std::runtime_error naming the function, the file and, for a bad
// line, its number: "read_tum_trajectory: 'gt.txt' line 7: expected 8
// fields ..."; bad arguments (options, poses to write) are
// std::invalid_argument. docs/io.md has the rules in full.
#pragma once

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <system_error>
#include <vector>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/camera.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/core/timed_pose.hpp"
#include "emfusion/io/detail/files.hpp"
#include "emfusion/io/frame_source.hpp"
#include "emfusion/io/png.hpp"

namespace emfusion {

namespace detail::tum {

using io::fail;
using io::quoted;
[[noreturn]] inline void fail_at(const char* where, const std::string& path, int line, const std::string& problem) {
  throw std::runtime_error(std::string(where) + ": " + quoted(path) + " line " + std::to_string(line) + ": " + problem);
}

/// Shortest text that reads back as `value` (timestamps like
/// 1305031102.175304 stay readable, unlike with %g).
inline std::string format(double value) {
  char buffer[64];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return std::string(buffer, result.ptr);
}

inline std::string join(const std::string& dir, const std::string& relative) {
  return (std::filesystem::path(dir) / relative).string();
}

inline bool is_file(const std::string& path) {
  std::error_code ignored;
  return std::filesystem::is_regular_file(path, ignored);
}

using io::read_file;

/// A line that holds data: its number (from 1) and its fields.
struct Line {
  int number = 0;
  std::vector<std::string> fields;
};

/// The data lines of a text file: comments ('#' to the end of the line) and
/// blank lines dropped, fields split at spaces, tabs and commas.
inline std::vector<Line> data_lines(const std::string& text) {
  const auto separator = [&](std::size_t k) {
    const char c = text[k];
    return c == ' ' || c == '\t' || c == ',' || c == '\r' || c == '\v' || c == '\f';
  };
  std::vector<Line> lines;
  std::size_t pos = 0;
  for (int number = 1; pos < text.size(); ++number) {
    std::size_t end = text.find('\n', pos);
    if (end == std::string::npos) end = text.size();
    // Search for a comment within this line only: a search to the end of
    // the text would make reading quadratic in the file size.
    const std::size_t stop = std::size_t(
        std::find(text.begin() + std::ptrdiff_t(pos), text.begin() + std::ptrdiff_t(end), '#') - text.begin());
    Line line;
    line.number = number;
    std::size_t i = pos;
    while (i < stop) {
      while (i < stop && separator(i)) ++i;
      const std::size_t start = i;
      while (i < stop && !separator(i)) ++i;
      if (i > start) line.fields.emplace_back(text, start, i - start);
    }
    if (!line.fields.empty()) lines.push_back(std::move(line));
    pos = end + 1;
  }
  return lines;
}

/// Parses a whole field as a finite number; the messages name the field.
class LineParser {
 public:
  LineParser(const char* where, const std::string& path, const Line& line) : where_(where), path_(path), line_(line) {}

  void expect_fields(std::size_t count, const char* layout) const {
    if (line_.fields.size() != count)
      fail(std::to_string(count) + " fields expected (" + layout + "), got " + std::to_string(line_.fields.size()));
  }

  double number(std::size_t k, const char* name) const {
    const std::string& text = line_.fields[k];
    const char* first = text.data();
    const char* last = first + text.size();
    if (first != last && *first == '+') ++first;
    double value = 0;
    const auto result = std::from_chars(first, last, value);
    if (first == last || result.ptr != last ||
        (result.ec != std::errc() && result.ec != std::errc::result_out_of_range))
      fail(std::string(name) + " '" + text + "' is not a number");
    if (result.ec == std::errc::result_out_of_range || !std::isfinite(value))
      fail(std::string(name) + " '" + text + "' is not a finite number");
    return value;
  }

  /// A positive integer written as an integral number ("640" or "640.0").
  int positive_integer(std::size_t k, const char* name) const {
    const double value = number(k, name);
    if (!(value >= 1) || value != std::floor(value) || value > 1e6)
      fail(std::string(name) + " '" + line_.fields[k] + "' is not a positive integer (at most 1000000)");
    return int(value);
  }

  [[noreturn]] void fail(const std::string& problem) const { fail_at(where_, path_, line_.number, problem); }

 private:
  const char* where_;
  const std::string& path_;
  const Line& line_;
};

/// The poses of a trajectory file's text; `path` names it in messages.
inline std::vector<TimedPose> parse_trajectory(const std::string& text, const std::string& path, const char* where) {
  const std::vector<Line> lines = data_lines(text);
  std::vector<TimedPose> poses;
  poses.reserve(lines.size());
  int previous_line = 0;
  for (const Line& line : lines) {
    const LineParser p(where, path, line);
    p.expect_fields(8, "timestamp tx ty tz qx qy qz qw");
    static constexpr const char* names[8] = {"timestamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw"};
    double v[8];
    for (std::size_t k = 0; k < 8; ++k) v[k] = p.number(k, names[k]);
    // Scaled by the largest component first: the squares of components
    // near 1e200 would overflow the norm to infinity (and normalising by it
    // would give the identity rotation instead of the one written).
    const double largest = std::max({std::fabs(v[4]), std::fabs(v[5]), std::fabs(v[6]), std::fabs(v[7])});
    if (largest > 0)
      for (std::size_t k = 4; k < 8; ++k) v[k] /= largest;
    const double norm = largest * std::sqrt(v[4] * v[4] + v[5] * v[5] + v[6] * v[6] + v[7] * v[7]);
    if (norm < 1e-6) p.fail("the quaternion (qx qy qz qw) has zero norm");
    if (!poses.empty() && !(v[0] > poses.back().timestamp))
      p.fail("timestamp " + line.fields[0] + " is not after the previous one (" + format(poses.back().timestamp) +
             " on line " + std::to_string(previous_line) + "): timestamps must increase strictly");
    poses.push_back({v[0], SE3<double>::from_quaternion(v[4], v[5], v[6], v[7], vec3(v[1], v[2], v[3]))});
    previous_line = line.number;
  }
  return poses;
}

inline std::vector<TimedPose> read_trajectory(const std::string& path, const char* where) {
  return parse_trajectory(read_file(path, where), path, where);
}

/// Appends `value` with `decimals` digits after the point ("%.*f").
inline void append_fixed(std::string& out, double value, int decimals) {
  char buffer[512];  // %f of the largest double needs about 320 characters
  const int n = std::snprintf(buffer, sizeof(buffer), "%.*f", decimals, value);
  out.append(buffer, std::size_t(std::clamp(n, 0, int(sizeof(buffer)) - 1)));
}

inline void write_text(const std::string& path, const std::string& text, const char* where) {
  io::AtomicFile file(where, path);
  errno = 0;
  const bool written = std::fwrite(text.data(), 1, text.size(), file.get()) == text.size();
  file.commit(written ? "" : io::errno_text(errno));
}

}  // namespace detail::tum

/// One entry of rgb.txt or depth.txt (parse_tum_list).
struct TumListEntry {
  double timestamp = 0;
  std::string path;  // as written in the list, relative to the sequence directory
  int line = 0;      // its line number, from 1
};

namespace detail::tum {

using ListEntry = TumListEntry;

/// The entries of a "timestamp path" list's text (rgb.txt, depth.txt),
/// timestamps strictly increasing; `path` names it in messages.
inline std::vector<ListEntry> parse_list(const std::string& text, const std::string& path, const char* where) {
  std::vector<ListEntry> entries;
  for (const Line& line : data_lines(text)) {
    const LineParser p(where, path, line);
    p.expect_fields(2, "timestamp path");
    const double t = p.number(0, "timestamp");
    if (!entries.empty() && !(t > entries.back().timestamp))
      p.fail("timestamp " + line.fields[0] + " is not after the previous one (" + format(entries.back().timestamp) +
             " on line " + std::to_string(entries.back().line) + "): timestamps must increase strictly");
    entries.push_back({t, line.fields[1], line.number});
  }
  return entries;
}

/// Reads "timestamp path" lines (rgb.txt, depth.txt), timestamps strictly
/// increasing.
inline std::vector<ListEntry> read_list(const std::string& path, const char* where) {
  return parse_list(read_file(path, where), path, where);
}

}  // namespace detail::tum

/// Reads a TUM trajectory file: "timestamp tx ty tz qx qy qz qw" per line,
/// timestamps strictly increasing. Quaternions (Hamilton, w last) are
/// normalised; one of (near) zero norm is an error, as is a non-finite
/// value. A file without pose lines gives an empty trajectory.
inline std::vector<TimedPose> read_tum_trajectory(const std::string& path) {
  return detail::tum::read_trajectory(path, "read_tum_trajectory");
}

/// read_tum_trajectory of a file's text in memory; `name` stands for the
/// file in error messages ("read_tum_trajectory: '<name>' line 7: ...").
inline std::vector<TimedPose> parse_tum_trajectory(const std::string& text, const std::string& name) {
  return detail::tum::parse_trajectory(text, name, "read_tum_trajectory");
}

/// The "timestamp path" entries of an rgb.txt or depth.txt file's text in
/// memory, as TumSequence::open reads them: timestamps finite and strictly
/// increasing, exactly two fields per data line. Errors are
/// std::runtime_error "TumSequence::open: '<name>' line 3: ...".
inline std::vector<TumListEntry> parse_tum_list(const std::string& text, const std::string& name) {
  return detail::tum::parse_list(text, name, "TumSequence::open");
}

namespace detail::tum {

/// The first line of every trajectory file written here.
inline constexpr const char* trajectory_header = "# timestamp tx ty tz qx qy qz qw\n";

/// Pose lines as write_tum_trajectory writes them, one call per pose. It
/// remembers the previous timestamp as written, so that a file written
/// whole (format_tum_trajectory) and one written pose by pose
/// (TumTrajectoryStream) hold the same text and pass the same checks.
class PoseLines {
 public:
  /// Appends `p`'s line to `text`; throws std::invalid_argument naming
  /// `where`, `path` and the pose's index, adding nothing, if a value is not
  /// finite or the timestamp as written is not after the previous one.
  void append(std::string& text, const TimedPose& p, const char* where, const std::string& path) {
    const auto bad = [&](const std::string& problem) {
      throw std::invalid_argument(std::string(where) + ": " + quoted(path) + ": pose " + std::to_string(count_) + ": " +
                                  problem);
    };
    const auto& t = p.pose.translation();
    const auto q = p.pose.quaternion();
    bool finite = true;
    for (int k = 0; k < 3; ++k) finite = finite && std::isfinite(t[k]);
    for (int k = 0; k < 4; ++k) finite = finite && std::isfinite(q[k]);
    if (!std::isfinite(p.timestamp)) bad("the timestamp is not finite");
    if (!finite) bad("the pose has a non-finite translation or rotation");
    std::string stamp;
    append_fixed(stamp, p.timestamp, 6);
    // Compare what a reader will see: timestamps closer than the written
    // precision would read back equal.
    double written = 0;
    std::from_chars(stamp.data(), stamp.data() + stamp.size(), written);
    if (count_ > 0 && !(written > previous_))
      bad("timestamp " + stamp + " is not after the previous one (" + previous_text_ + ") as written with 6 decimals");
    previous_ = written, previous_text_ = stamp;
    ++count_;
    text += stamp;
    for (int k = 0; k < 3; ++k) {
      text.push_back(' ');
      append_fixed(text, t[k], 9);
    }
    for (int k = 0; k < 4; ++k) {
      text.push_back(' ');
      append_fixed(text, q[k], 9);
    }
    text.push_back('\n');
  }

  /// The number of lines appended.
  std::size_t count() const { return count_; }

 private:
  std::size_t count_ = 0;
  double previous_ = 0;
  std::string previous_text_;
};

}  // namespace detail::tum

/// The text that write_tum_trajectory (below) writes for `poses`, in memory;
/// `name` stands for the file in messages (same checks, same
/// std::invalid_argument).
inline std::string format_tum_trajectory(const std::vector<TimedPose>& poses, const std::string& name) {
  std::string text = detail::tum::trajectory_header;
  detail::tum::PoseLines lines;
  for (const TimedPose& p : poses) lines.append(text, p, "write_tum_trajectory", name);
  return text;
}

/// Writes a TUM trajectory file (a "# timestamp tx ty tz qx qy qz qw" comment,
/// then one pose per line: timestamp with 6 decimals, translation and
/// quaternion with 9, quaternion w >= 0), via "<path>.tmp" and a rename.
/// Throws std::invalid_argument, writing nothing, if a value is not finite
/// or the timestamps, as written with 6 decimals, do not increase strictly.
inline void write_tum_trajectory(const std::string& path, const std::vector<TimedPose>& poses) {
  detail::tum::write_text(path, format_tum_trajectory(poses, path), "write_tum_trajectory");
}

/// read_calibration (below) of a file's text in memory; `name` stands for the file
/// in error messages ("read_calibration: '<name>' line 2: ...").
inline PinholeCamera<double> parse_calibration(const std::string& text, const std::string& name) {
  namespace tum = detail::tum;
  const std::string& path = name;
  constexpr const char* where = "read_calibration";
  const std::vector<tum::Line> lines = tum::data_lines(text);
  if (lines.empty()) tum::fail(where, path, "no calibration line (fx fy cx cy width height)");
  if (lines.size() > 1)
    tum::fail_at(where, path, lines[1].number,
                 "a second calibration line (the first is line " + std::to_string(lines[0].number) + ")");
  const tum::LineParser p(where, path, lines[0]);
  p.expect_fields(6, "fx fy cx cy width height");
  PinholeCamera<double> camera;
  camera.fx = p.number(0, "fx");
  camera.fy = p.number(1, "fy");
  camera.cx = p.number(2, "cx");
  camera.cy = p.number(3, "cy");
  camera.width = p.positive_integer(4, "width");
  camera.height = p.positive_integer(5, "height");
  if (!(camera.fx > 0)) p.fail("fx " + lines[0].fields[0] + " is not positive");
  if (!(camera.fy > 0)) p.fail("fy " + lines[0].fields[1] + " is not positive");
  return camera;
}

/// Reads a calibration file: one line "fx fy cx cy width height" (comments
/// allowed). fx and fy must be positive, width and height positive integers;
/// cx and cy any finite value.
inline PinholeCamera<double> read_calibration(const std::string& path) {
  return parse_calibration(detail::tum::read_file(path, "read_calibration"), path);
}

/// Options of TumSequence::open.
struct TumOptions {
  /// Depth PNG value per metre (5000 for TUM, 1000 for millimetres).
  double depth_scale = 5000;
  /// Pairing of rgb.txt and depth.txt (seconds): see TumSequence.
  double max_time_difference = 0.02;
  /// Intrinsics to use instead of calibration.txt.
  std::optional<PinholeCamera<double>> camera;
};

/// A sequence in the TUM RGB-D layout (shared/FORMATS.md section 1).
///
/// Frames come from associations.txt ("t_rgb rgb_path t_depth depth_path")
/// when it exists, taken as they are. Otherwise from depth.txt, each depth
/// frame paired with the rgb.txt frame nearest in time (an rgb frame may
/// serve two depth frames); a depth frame whose nearest rgb frame is more
/// than max_time_difference away (plus 1 us of slack for decimal rounding)
/// is dropped. Without rgb.txt every depth frame is kept, without colour.
/// Lists must have strictly increasing timestamps (depth timestamps in
/// associations.txt).
///
/// Depth-only copies: when the list names colour images but none of the
/// kept frames' colour images exists (a sequence copied without rgb/), the
/// sequence opens without colour: the same frames, has_colour() false,
/// colour_path(i) empty and colour_timestamp(i) NaN, as without rgb.txt.
/// Some colour images present and others missing is an error (a partial
/// copy), naming the first missing one and the count.
///
/// open() checks everything it can cheaply: the lists, that every depth
/// image it refers to exists (and the colour images, all or none), the
/// calibration. Depth images are read on demand.
class TumSequence {
 public:
  static TumSequence open(const std::string& dir, const TumOptions& options = {});

  /// Number of frames.
  std::size_t size() const { return frames_.size(); }
  /// Timestamp of frame i (its depth image's), seconds.
  double timestamp(std::size_t i) const { return frame(i, "TumSequence::timestamp").timestamp; }
  /// Timestamp of frame i's colour image; NaN when there is none.
  double colour_timestamp(std::size_t i) const { return frame(i, "TumSequence::colour_timestamp").colour_timestamp; }
  /// Path of frame i's depth image (directory joined with the list entry).
  const std::string& depth_path(std::size_t i) const { return frame(i, "TumSequence::depth_path").depth_path; }
  /// Path of frame i's colour image; empty when the sequence has no colour
  /// (no rgb.txt, or a depth-only copy whose colour images are all absent).
  const std::string& colour_path(std::size_t i) const { return frame(i, "TumSequence::colour_path").colour_path; }
  /// True when every frame has a colour image; false for a sequence without
  /// colour (then no frame has one).
  bool has_colour() const { return has_colour_; }

  const PinholeCamera<double>& camera() const { return camera_; }
  /// Where camera() came from: "TumOptions::camera", the path of
  /// calibration.txt, or a text starting with "default" naming the
  /// intrinsics used when there is no calibration.txt.
  const std::string& camera_source() const { return camera_source_; }
  /// The directory as given to open().
  const std::string& dir() const { return dir_; }
  const TumOptions& options() const { return options_; }

  /// Depth of frame i in metres (PNG value / depth_scale, 0 stays 0). The PNG
  /// must be 16-bit grayscale of the camera's size.
  Image<float, Host> depth(std::size_t i) const;

  /// The camera trajectory in groundtruth.txt, if there is one.
  std::optional<std::vector<TimedPose>> ground_truth() const;
  /// Object trajectories (T_world_object) in groundtruth_objects/<name>.txt,
  /// by name; empty when there are none.
  std::map<std::string, std::vector<TimedPose>> ground_truth_objects() const;

 private:
  struct Frame {
    double timestamp = 0;
    double colour_timestamp = 0;
    std::string depth_path;
    std::string colour_path;
  };

  const Frame& frame(std::size_t i, const char* where) const {
    if (i >= frames_.size())
      throw std::out_of_range(std::string(where) + ": frame " + std::to_string(i) + " out of range (" +
                              std::to_string(frames_.size()) + " frames in " + detail::tum::quoted(dir_) + ")");
    return frames_[i];
  }

  std::string dir_;
  TumOptions options_;
  PinholeCamera<double> camera_;
  std::string camera_source_;
  std::vector<Frame> frames_;
  bool has_colour_ = false;
};

inline TumSequence TumSequence::open(const std::string& dir, const TumOptions& options) {
  namespace tum = detail::tum;
  namespace fs = std::filesystem;
  constexpr const char* where = "TumSequence::open";
  if (!(options.depth_scale > 0) || !std::isfinite(options.depth_scale))
    throw std::invalid_argument(std::string(where) + ": depth_scale must be positive and finite, got " +
                                tum::format(options.depth_scale));
  if (!(options.max_time_difference >= 0) || !std::isfinite(options.max_time_difference))
    throw std::invalid_argument(std::string(where) + ": max_time_difference must be finite and >= 0, got " +
                                tum::format(options.max_time_difference));
  if (options.camera) options.camera->validate("TumSequence::open: TumOptions::camera");

  std::error_code ec;
  if (!fs::exists(dir, ec)) tum::fail(where, dir, "directory not found");
  if (!fs::is_directory(dir, ec)) tum::fail(where, dir, "not a directory");

  TumSequence seq;
  seq.dir_ = dir;
  seq.options_ = options;
  const std::string associations = tum::join(dir, "associations.txt");
  const std::string depth_list = tum::join(dir, "depth.txt");
  const std::string rgb_list = tum::join(dir, "rgb.txt");

  const auto require_file = [&](const std::string& list, int line, const char* what, const std::string& path) {
    if (!tum::is_file(path))
      tum::fail_at(where, list, line, std::string(what) + " " + tum::quoted(path) + " not found");
  };
  // Colour images may all be absent (a depth-only copy), not only some.
  std::size_t colour_missing = 0;  // frames whose colour image does not exist
  std::string first_missing_list, first_missing_colour;
  int first_missing_line = 0;
  const auto check_colour = [&](const std::string& list, int line, const std::string& path) {
    if (tum::is_file(path)) return;
    if (colour_missing++ == 0) first_missing_list = list, first_missing_line = line, first_missing_colour = path;
  };
  const auto settle_colour = [&] {
    if (!seq.has_colour_ || colour_missing == 0) return;
    if (colour_missing < seq.frames_.size())
      tum::fail_at(where, first_missing_list, first_missing_line,
                   "colour image " + tum::quoted(first_missing_colour) + " not found (" +
                       std::to_string(colour_missing) + " of " + std::to_string(seq.frames_.size()) +
                       " frames lack their colour image: a sequence may lack all of them, as a depth-only copy, "
                       "but not only some)");
    seq.has_colour_ = false;
    for (Frame& f : seq.frames_) f.colour_path.clear(), f.colour_timestamp = std::nan("");
  };

  if (tum::is_file(associations)) {
    seq.has_colour_ = true;
    for (const tum::Line& line : tum::data_lines(tum::read_file(associations, where))) {
      const tum::LineParser p(where, associations, line);
      p.expect_fields(4, "t_rgb rgb_path t_depth depth_path");
      Frame f;
      f.colour_timestamp = p.number(0, "t_rgb");
      f.timestamp = p.number(2, "t_depth");
      if (!seq.frames_.empty() && !(f.timestamp > seq.frames_.back().timestamp))
        p.fail("depth timestamp " + line.fields[2] + " is not after the previous one (" +
               tum::format(seq.frames_.back().timestamp) + "): timestamps must increase strictly");
      f.colour_path = tum::join(dir, line.fields[1]);
      f.depth_path = tum::join(dir, line.fields[3]);
      require_file(associations, line.number, "depth image", f.depth_path);
      check_colour(associations, line.number, f.colour_path);
      seq.frames_.push_back(std::move(f));
    }
    if (seq.frames_.empty()) tum::fail(where, associations, "no frames");
    settle_colour();
  } else if (tum::is_file(depth_list)) {
    const std::vector<tum::ListEntry> depth = tum::read_list(depth_list, where);
    if (depth.empty()) tum::fail(where, depth_list, "no frames");
    seq.has_colour_ = tum::is_file(rgb_list);
    std::vector<tum::ListEntry> rgb;
    if (seq.has_colour_) rgb = tum::read_list(rgb_list, where);
    // Slack for timestamps that are exactly max_time_difference apart in
    // decimal but not in binary.
    const double max_difference = options.max_time_difference + 1e-6;
    for (const tum::ListEntry& d : depth) {
      Frame f;
      f.timestamp = d.timestamp;
      f.colour_timestamp = std::nan("");
      f.depth_path = tum::join(dir, d.path);
      if (seq.has_colour_) {
        // Nearest rgb timestamp; on a tie the earlier frame.
        const auto after = std::lower_bound(rgb.begin(), rgb.end(), d.timestamp,
                                            [](const tum::ListEntry& e, double t) { return e.timestamp < t; });
        auto best = rgb.end();
        if (after != rgb.end()) best = after;
        if (after != rgb.begin() &&
            (best == rgb.end() || d.timestamp - (after - 1)->timestamp <= best->timestamp - d.timestamp))
          best = after - 1;
        if (best == rgb.end() || std::abs(best->timestamp - d.timestamp) > max_difference) continue;
        f.colour_timestamp = best->timestamp;
        f.colour_path = tum::join(dir, best->path);
        check_colour(rgb_list, best->line, f.colour_path);
      }
      require_file(depth_list, d.line, "depth image", f.depth_path);
      seq.frames_.push_back(std::move(f));
    }
    if (seq.frames_.empty())
      tum::fail(where, dir,
                "no frames: no depth frame of depth.txt has an rgb.txt frame within " +
                    tum::format(options.max_time_difference) + " s");
    settle_colour();
  } else {
    tum::fail(where, dir, "neither associations.txt nor depth.txt found");
  }

  const std::string calibration = tum::join(dir, "calibration.txt");
  if (options.camera) {
    seq.camera_ = *options.camera;
    seq.camera_source_ = "TumOptions::camera";
  } else if (tum::is_file(calibration)) {
    seq.camera_ = read_calibration(calibration);
    seq.camera_source_ = calibration;
  } else {
    seq.camera_ = PinholeCamera<double>{};
    seq.camera_source_ = "default (no calibration.txt): fx " + tum::format(seq.camera_.fx) + ", fy " +
                         tum::format(seq.camera_.fy) + ", cx " + tum::format(seq.camera_.cx) + ", cy " +
                         tum::format(seq.camera_.cy) + ", " + std::to_string(seq.camera_.width) + "x" +
                         std::to_string(seq.camera_.height);
  }
  return seq;
}

inline Image<float, Host> TumSequence::depth(std::size_t i) const {
  const Frame& f = frame(i, "TumSequence::depth");
  const Image<std::uint16_t, Host> raw = detail::png::read_gray<std::uint16_t>(f.depth_path, /*allow_narrower=*/false);
  if (!raw.same_size(camera_.width, camera_.height))
    detail::tum::fail("TumSequence::depth", f.depth_path,
                      "the image is " + std::to_string(raw.width()) + "x" + std::to_string(raw.height()) +
                          " but the camera (" + camera_source_ + ") is " + std::to_string(camera_.width) + "x" +
                          std::to_string(camera_.height));
  Image<float, Host> out(raw.width(), raw.height());
  const ImageView<const std::uint16_t> in = raw.view();
  const ImageView<float> metres = out.view();
  const double scale = options_.depth_scale;
  for (int k = 0; k < in.size(); ++k) metres[k] = in[k] == 0 ? 0.f : float(double(in[k]) / scale);
  return out;
}

inline std::optional<std::vector<TimedPose>> TumSequence::ground_truth() const {
  const std::string path = detail::tum::join(dir_, "groundtruth.txt");
  if (!detail::tum::is_file(path)) return std::nullopt;
  return read_tum_trajectory(path);
}

inline std::map<std::string, std::vector<TimedPose>> TumSequence::ground_truth_objects() const {
  namespace fs = std::filesystem;
  std::map<std::string, std::vector<TimedPose>> objects;
  const fs::path folder = fs::path(dir_) / "groundtruth_objects";
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) return objects;
  for (const auto& entry : fs::directory_iterator(folder))
    if (entry.is_regular_file() && entry.path().extension() == ".txt")
      objects[entry.path().stem().string()] = read_tum_trajectory(entry.path().string());
  return objects;
}

static_assert(FrameSource<TumSequence>);

}  // namespace emfusion
