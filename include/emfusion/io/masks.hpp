// Instance-mask directories (shared/FORMATS.md section 2): the saved output of
// a detector such as Mask R-CNN, read back as a Segmenter so that a SLAM run
// can use precomputed masks, and written by tools and tests.
//
// A directory holds masks.txt, one line per frame the detector ran on:
//
//   timestamp label_png [id:class:score ...]
//
// and the label images it names (8- or 16-bit single-channel PNGs, relative to
// the directory; pixel value k > 0 belongs to instance k, 0 to none). Lines
// follow the TUM text rules of io/tum.hpp: '#' comments, blank lines, fields
// split at spaces, tabs or commas (so neither paths nor class names can hold
// those characters).
//
// MaskDirectory::open reads and checks masks.txt at once (and that every
// label image exists); label images are read only by read() / detect().
// MaskDirectory::parse checks a masks.txt text in memory (tests/fuzz/).
// Errors are std::runtime_error naming the function, the file and, for a bad
// line, its number: "MaskDirectory::open: 'masks/masks.txt' line 4:
// instance '0:cup:0.9': id '0' is not an integer in [1, 65535]"; bad
// arguments are std::invalid_argument. docs/io.md has the rules in full.
#pragma once

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/detect/detection.hpp"
#include "emfusion/io/detail/files.hpp"
#include "emfusion/io/png.hpp"
#include "emfusion/io/tum.hpp"

namespace emfusion {

namespace detail::masks {

/// Largest instance id: the largest value of a 16-bit label image.
inline constexpr int max_id = 65535;

/// `text` as a whole, as an integer in [1, max_id]; digits only.
inline std::optional<int> parse_id(std::string_view text) {
  if (text.empty() || text.size() > 9) return std::nullopt;
  for (const char c : text)
    if (c < '0' || c > '9') return std::nullopt;
  int value = 0;
  const auto result = std::from_chars(text.data(), text.data() + text.size(), value);
  if (result.ec != std::errc() || result.ptr != text.data() + text.size()) return std::nullopt;
  if (value < 1 || value > max_id) return std::nullopt;
  return value;
}

/// `text` as a whole, as a finite number (a leading '+' allowed).
inline std::optional<double> parse_number(std::string_view text) {
  if (!text.empty() && text.front() == '+') text.remove_prefix(1);
  if (text.empty()) return std::nullopt;
  double value = 0;
  const auto result = std::from_chars(text.data(), text.data() + text.size(), value);
  if (result.ec != std::errc() || result.ptr != text.data() + text.size() || !std::isfinite(value)) return std::nullopt;
  return value;
}

/// Why `name` cannot be a class name in masks.txt, or "" if it can.
inline std::string class_name_problem(const std::string& name) {
  if (name.empty()) return "the class name is empty";
  for (const char c : name) {
    if (c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\v' || c == '\f')
      return "the class name '" + name + "' contains white space (write spaces as '_', e.g. teddy_bear)";
    if (c == ',' || c == '#' || c == ':')
      return "the class name '" + name + "' contains '" + std::string(1, c) + "', which masks.txt cannot hold";
  }
  return "";
}

/// Why `name` cannot be a label-image name in masks.txt, or "" if it can.
inline std::string file_name_problem(const std::string& name) {
  if (name.empty()) return "the label image name is empty";
  for (const char c : name)
    if (c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\v' || c == '\f' || c == ',' || c == '#')
      return "the label image name '" + name + "' contains white space, ',' or '#', which masks.txt cannot hold";
  const std::filesystem::path path(name);
  if (path.is_absolute()) return "the label image name '" + name + "' is not relative to the directory";
  for (const auto& part : path)
    if (part == "..") return "the label image name '" + name + "' leaves the directory ('..')";
  if (path.lexically_normal() == "masks.txt") return "a label image cannot be named masks.txt";
  return "";
}

/// Parses one "id:class:score" field; `fail` (which does not return) gets
/// the problem.
template <class Fail>
Instance parse_instance(const std::string& field, const Fail& fail) {
  const std::string prefix = "instance '" + field + "': ";
  const std::size_t first = field.find(':');
  const std::size_t last = field.rfind(':');
  if (first == std::string::npos || first == last) fail(prefix + "expected id:class:score (e.g. 1:cup:0.93)");
  if (field.find(':', first + 1) != last) fail(prefix + "expected id:class:score, got more than 3 ':'-separated parts");
  const std::string id = field.substr(0, first);
  Instance instance;
  instance.class_name = field.substr(first + 1, last - first - 1);
  const std::string score = field.substr(last + 1);
  const std::optional<int> label = parse_id(id);
  if (!label) fail(prefix + "id '" + id + "' is not an integer in [1, " + std::to_string(max_id) + "]");
  instance.label = *label;
  if (instance.class_name.empty()) fail(prefix + "the class name is empty");
  const std::optional<double> value = parse_number(score);
  if (!value) fail(prefix + "score '" + score + "' is not a number");
  if (!(*value >= 0.0 && *value <= 1.0)) fail(prefix + "score '" + score + "' is not in [0, 1]");
  instance.score = *value;
  return instance;
}

}  // namespace detail::masks

/// A mask directory (shared/FORMATS.md section 2) as a Segmenter.
///
/// open() reads <dir>/masks.txt and checks every line: at least the fields
/// "timestamp label_png", a finite timestamp strictly greater than the
/// previous line's, instances "id:class:score" with id an integer in
/// [1, 65535] (no two alike on a line), a non-empty class name and a score in
/// [0, 1], and a label image that exists. A masks.txt with no data lines is a
/// directory of no detector results (every detect() gives nothing).
///
/// read(i) reads the label image of entry i: an 8- or 16-bit (or 1/2/4-bit)
/// grayscale PNG, values unchanged, of the expected size when open() was
/// given one, whose every non-zero value is an id listed on its line. An id
/// whose value does not occur in the image is allowed (its mask is empty).
class MaskDirectory {
 public:
  /// How far (seconds) detect() looks for an entry (FORMATS.md: a mask
  /// timestamp matches an rgb timestamp within 0.02 s). 1 us of slack is
  /// added for timestamps exactly 0.02 s apart in decimal but not in binary.
  static constexpr double max_time_difference = 0.02;

  /// Opens `dir`; width and height are the size every label image must have
  /// (both 0: not checked).
  static MaskDirectory open(const std::string& dir, int width = 0, int height = 0);

  /// open() of a masks.txt text in memory, as if read from <dir>/masks.txt,
  /// without touching the file system: neither the directory nor the label
  /// images are checked for existence (read() still reads them from `dir`).
  /// Same checks of the text and the same errors, naming <dir>/masks.txt.
  static MaskDirectory parse(const std::string& text, const std::string& dir, int width = 0, int height = 0);

  /// Number of entries (lines of masks.txt).
  std::size_t size() const { return entries_.size(); }
  /// Timestamp of entry i, seconds.
  double timestamp(std::size_t i) const { return entry(i, "MaskDirectory::timestamp").timestamp; }
  /// The instances listed for entry i, in the order of the line.
  const std::vector<Instance>& instances(std::size_t i) const { return entry(i, "MaskDirectory::instances").instances; }
  /// Path of entry i's label image (the directory joined with the name).
  const std::string& label_path(std::size_t i) const { return entry(i, "MaskDirectory::label_path").path; }
  /// The directory as given to open().
  const std::string& dir() const { return dir_; }
  /// The path of masks.txt.
  const std::string& list_path() const { return list_; }

  /// Entry i with its label image read and checked.
  Detections read(std::size_t i) const;

  /// The entry whose timestamp is nearest to `timestamp` (the earlier on a
  /// tie), if it is within max_time_difference.
  std::optional<std::size_t> nearest(double timestamp) const;

  /// Segmenter: the detector result for the frame at `timestamp` (the frame
  /// index is not used), or nothing when masks.txt lists no entry within
  /// max_time_difference. A listed entry without instances gives Detections
  /// with no instances ("ran and found nothing").
  std::optional<Detections> detect(int frame_index, double timestamp) const {
    (void)frame_index;
    const std::optional<std::size_t> i = nearest(timestamp);
    if (!i) return std::nullopt;
    return read(*i);
  }

 private:
  struct Entry {
    double timestamp = 0;
    std::string path;  // directory joined with the name as written
    std::vector<Instance> instances;
    int line = 0;
  };

  /// Checks the expected size, then parses masks.txt's `text`; checks that
  /// every label image exists when `check_files`.
  static MaskDirectory parse_list(const std::string& text, const std::string& dir, int width, int height,
                                  bool check_files);
  static void check_size(const std::string& dir, int width, int height);

  const Entry& entry(std::size_t i, const char* where) const {
    if (i >= entries_.size())
      throw std::out_of_range(std::string(where) + ": entry " + std::to_string(i) + " out of range (" +
                              std::to_string(entries_.size()) + " entries in " + detail::io::quoted(list_) + ")");
    return entries_[i];
  }

  std::string dir_;
  std::string list_;
  int width_ = 0, height_ = 0;
  std::vector<Entry> entries_;
};

static_assert(Segmenter<MaskDirectory>);

inline void MaskDirectory::check_size(const std::string& dir, int width, int height) {
  if (width < 0 || height < 0 || (width == 0) != (height == 0))
    throw std::invalid_argument("MaskDirectory::open: " + detail::io::quoted(dir) +
                                ": the expected label-image size must be two positive numbers or both 0 (not "
                                "checked), got " +
                                std::to_string(width) + "x" + std::to_string(height));
}

inline MaskDirectory MaskDirectory::open(const std::string& dir, int width, int height) {
  namespace tum = detail::tum;
  namespace fs = std::filesystem;
  constexpr const char* where = "MaskDirectory::open";
  check_size(dir, width, height);
  std::error_code ec;
  if (!fs::exists(dir, ec)) tum::fail(where, dir, "directory not found");
  if (!fs::is_directory(dir, ec)) tum::fail(where, dir, "not a directory");
  const std::string list = tum::join(dir, "masks.txt");
  if (!tum::is_file(list)) tum::fail(where, list, "not found (a mask directory lists its frames in masks.txt)");
  return parse_list(tum::read_file(list, where), dir, width, height, /*check_files=*/true);
}

inline MaskDirectory MaskDirectory::parse(const std::string& text, const std::string& dir, int width, int height) {
  check_size(dir, width, height);
  return parse_list(text, dir, width, height, /*check_files=*/false);
}

inline MaskDirectory MaskDirectory::parse_list(const std::string& text, const std::string& dir, int width, int height,
                                               bool check_files) {
  namespace tum = detail::tum;
  namespace masks = detail::masks;
  constexpr const char* where = "MaskDirectory::open";
  MaskDirectory masks_dir;
  masks_dir.dir_ = dir;
  masks_dir.list_ = tum::join(dir, "masks.txt");
  masks_dir.width_ = width;
  masks_dir.height_ = height;
  const std::string& list = masks_dir.list_;

  for (const tum::Line& line : tum::data_lines(text)) {
    const tum::LineParser p(where, list, line);
    if (line.fields.size() < 2)
      p.fail("expected at least 2 fields (timestamp label_png [id:class:score ...]), got " +
             std::to_string(line.fields.size()));
    Entry e;
    e.line = line.number;
    e.timestamp = p.number(0, "timestamp");
    if (!masks_dir.entries_.empty()) {
      const Entry& previous = masks_dir.entries_.back();
      if (!(e.timestamp > previous.timestamp))
        p.fail("timestamp " + line.fields[0] + " is not after the previous one (" + tum::format(previous.timestamp) +
               " on line " + std::to_string(previous.line) + "): timestamps must increase strictly");
    }
    const std::string name_problem = masks::file_name_problem(line.fields[1]);
    if (!name_problem.empty()) p.fail(name_problem);
    e.path = tum::join(dir, line.fields[1]);
    const auto fail = [&](const std::string& problem) { p.fail(problem); };
    for (std::size_t k = 2; k < line.fields.size(); ++k) {
      Instance instance = masks::parse_instance(line.fields[k], fail);
      for (std::size_t j = 0; j < e.instances.size(); ++j)
        if (e.instances[j].label == instance.label)
          p.fail("instance id " + std::to_string(instance.label) + " appears twice ('" + line.fields[j + 2] +
                 "' and '" + line.fields[k] + "')");
      e.instances.push_back(std::move(instance));
    }
    if (check_files && !tum::is_file(e.path)) p.fail("label image " + detail::io::quoted(e.path) + " not found");
    masks_dir.entries_.push_back(std::move(e));
  }
  return masks_dir;
}

inline Detections MaskDirectory::read(std::size_t i) const {
  namespace tum = detail::tum;
  constexpr const char* where = "MaskDirectory::read";
  const Entry& e = entry(i, where);
  Detections d;
  d.timestamp = e.timestamp;
  d.instances = e.instances;
  try {
    d.labels = read_png_u16(e.path);
  } catch (const std::runtime_error& error) {
    tum::fail_at(where, list_, e.line, "cannot read the label image: " + std::string(error.what()));
  }
  const std::string size_text = std::to_string(d.labels.width()) + "x" + std::to_string(d.labels.height());
  if (width_ > 0 && !d.labels.same_size(width_, height_))
    tum::fail_at(where, list_, e.line,
                 "label image " + detail::io::quoted(e.path) + " is " + size_text + ", expected " +
                     std::to_string(width_) + "x" + std::to_string(height_));

  // Every non-zero pixel value must be a listed id.
  std::vector<unsigned char> listed(std::size_t(detail::masks::max_id) + 1, 0);
  listed[0] = 1;
  for (const Instance& instance : e.instances) listed[std::size_t(instance.label)] = 1;
  const ImageView<const std::uint16_t> pixels = d.labels.view();
  for (int k = 0; k < pixels.size(); ++k) {
    const std::uint16_t value = pixels[k];
    if (listed[value]) continue;
    int count = 0;
    for (int j = k; j < pixels.size(); ++j) count += pixels[j] == value ? 1 : 0;
    std::string ids;
    for (const Instance& instance : e.instances) {
      if (!ids.empty()) ids += ' ';
      ids += std::to_string(instance.label);
    }
    tum::fail_at(where, list_, e.line,
                 "label image " + detail::io::quoted(e.path) + " has " + std::to_string(count) + " pixel(s) of value " +
                     std::to_string(value) + " (first at x " + std::to_string(k % pixels.width) + ", y " +
                     std::to_string(k / pixels.width) + "), which is not an instance id listed on this line (" +
                     (ids.empty() ? std::string("none listed") : "listed: " + ids) + ")");
  }
  return d;
}

inline std::optional<std::size_t> MaskDirectory::nearest(double timestamp) const {
  if (!std::isfinite(timestamp) || entries_.empty()) return std::nullopt;
  const auto after = std::lower_bound(entries_.begin(), entries_.end(), timestamp,
                                      [](const Entry& e, double t) { return e.timestamp < t; });
  auto best = entries_.end();
  if (after != entries_.end()) best = after;
  if (after != entries_.begin() &&
      (best == entries_.end() || timestamp - (after - 1)->timestamp <= best->timestamp - timestamp))
    best = after - 1;
  if (std::abs(best->timestamp - timestamp) > max_time_difference + 1e-6) return std::nullopt;
  return std::size_t(best - entries_.begin());
}

/// Writes a mask directory: creates `dir` (and its parents) if needed, one
/// 16-bit label PNG per frame, then masks.txt (a comment line, then
/// "timestamp label_png id:class:score ..." per frame, timestamps and scores
/// in the shortest form that reads back exactly). Each file is written to
/// "<path>.tmp" and renamed when complete. `png_names` are the label images'
/// names relative to `dir`, one per frame (subfolders are created); empty:
/// "000000.png", "000001.png", ... by position in `frames`.
///
/// Everything is checked before anything is written; std::invalid_argument
/// for: a different number of names than frames, a bad or repeated name,
/// non-finite or not strictly increasing timestamps, an empty label image,
/// an instance id outside [1, 65535] or repeated in a frame, a class name that
/// is empty or holds white space, ',', '#' or ':', a score outside [0, 1], a
/// non-zero pixel value that is not an instance id of its frame (the reader
/// would reject the file). std::runtime_error, naming the path, if a file or
/// folder cannot be written.
inline void write_mask_directory(const std::string& dir, const std::vector<Detections>& frames,
                                 const std::vector<std::string>& png_names = {}) {
  namespace tum = detail::tum;
  namespace masks = detail::masks;
  namespace fs = std::filesystem;
  constexpr const char* where = "write_mask_directory";
  const auto bad = [&](const std::string& problem) {
    throw std::invalid_argument(std::string(where) + ": " + detail::io::quoted(dir) + ": " + problem);
  };
  if (!png_names.empty() && png_names.size() != frames.size())
    bad(std::to_string(png_names.size()) + " label image names for " + std::to_string(frames.size()) + " frames");

  std::vector<std::string> names(frames.size());
  std::string text = "# timestamp label_png [id:class:score ...]\n";
  std::vector<unsigned char> listed(std::size_t(masks::max_id) + 1);
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const Detections& d = frames[i];
    const std::string frame = "frame " + std::to_string(i) + ": ";
    if (png_names.empty()) {
      char buffer[32];
      std::snprintf(buffer, sizeof(buffer), "%06zu.png", i);
      names[i] = buffer;
    } else {
      names[i] = png_names[i];
      const std::string problem = masks::file_name_problem(names[i]);
      if (!problem.empty()) bad(frame + problem);
      for (std::size_t j = 0; j < i; ++j)
        if (fs::path(names[j]).lexically_normal() == fs::path(names[i]).lexically_normal())
          bad(frame + "label image name '" + names[i] + "' is also the name of frame " + std::to_string(j));
    }
    if (!std::isfinite(d.timestamp)) bad(frame + "the timestamp is not finite");
    if (i > 0 && !(d.timestamp > frames[i - 1].timestamp))
      bad(frame + "timestamp " + tum::format(d.timestamp) + " is not after the previous one (" +
          tum::format(frames[i - 1].timestamp) + ")");
    if (d.labels.empty()) bad(frame + "the label image is empty (every listed frame needs one)");
    text += tum::format(d.timestamp) + " " + names[i];
    std::fill(listed.begin(), listed.end(), 0);
    listed[0] = 1;
    for (const Instance& instance : d.instances) {
      if (instance.label < 1 || instance.label > masks::max_id)
        bad(frame + "instance id " + std::to_string(instance.label) + " is not in [1, 65535]");
      if (listed[std::size_t(instance.label)])
        bad(frame + "instance id " + std::to_string(instance.label) + " appears twice");
      listed[std::size_t(instance.label)] = 1;
      const std::string problem = masks::class_name_problem(instance.class_name);
      if (!problem.empty()) bad(frame + "instance " + std::to_string(instance.label) + ": " + problem);
      if (!(instance.score >= 0.0 && instance.score <= 1.0))
        bad(frame + "instance " + std::to_string(instance.label) + ": score " + tum::format(instance.score) +
            " is not in [0, 1]");
      text += ' ';
      text += std::to_string(instance.label);
      text += ':';
      text += instance.class_name;
      text += ':';
      text += tum::format(instance.score);
    }
    text += "\n";
    const ImageView<const std::uint16_t> pixels = d.labels.view();
    for (int k = 0; k < pixels.size(); ++k)
      if (!listed[pixels[k]])
        bad(frame + "the label image has pixels of value " + std::to_string(pixels[k]) +
            ", which is not an instance id of the frame");
  }

  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir, ec))
    tum::fail(where, dir,
              "cannot create the directory" + (ec ? ": " + ec.message() : std::string(" (not a directory)")));
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const std::string path = tum::join(dir, names[i]);
    const fs::path parent = fs::path(path).parent_path();
    fs::create_directories(parent, ec);
    if (ec) tum::fail(where, parent.string(), "cannot create the directory: " + ec.message());
    write_png(path, frames[i].labels);
  }
  tum::write_text(tum::join(dir, "masks.txt"), text, where);
}

}  // namespace emfusion
