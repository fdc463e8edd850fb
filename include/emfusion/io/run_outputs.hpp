// Writing and reading the outputs of a run (shared FORMATS.md section 5):
//   <out>/camera.txt, <out>/objects.txt, <out>/objects/<id>.txt,
//   <out>/meshes/background.ply, <out>/meshes/object_<id>.ply, <out>/run.json.
// Every file is written atomically (a failed run never leaves a half-written
// file under a final name); errors name the path. Trajectories that grow
// while a run goes are streamed instead (io/trajectory_stream.hpp).
#pragma once

#include <cerrno>
#include <cstdio>
#include <filesystem>
#include <map>
#include <string>
#include <system_error>
#include <vector>

#include "emfusion/io/detail/files.hpp"
#include "emfusion/io/tum.hpp"

namespace emfusion {

/// One line of objects.txt.
struct ObjectListEntry {
  int id = 0;
  std::string class_name;
  double first_timestamp = 0, last_timestamp = 0;
  bool deleted = false;
  bool operator==(const ObjectListEntry&) const = default;
};

namespace detail::run_outputs {
inline void make_directory(const std::string& dir, const char* where) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec || !std::filesystem::is_directory(dir)) io::fail(where, dir, "cannot create output directory: " + ec.message());
}
}  // namespace detail::run_outputs

/// Creates `dir` (and parents) or throws naming it.
inline void create_output_directory(const std::string& dir) {
  detail::run_outputs::make_directory(dir, "create_output_directory");
}

/// Creates, writes, flushes and removes a small file in `dir`, so that a
/// directory that exists but cannot be written (read-only, full) fails
/// before a run spends time on frames; throws naming the probe file and
/// the system's text otherwise.
inline void check_writable_directory(const std::string& dir) {
  const std::string probe = (std::filesystem::path(dir) / ".emfusion-write-test").string();
  {
    detail::io::AtomicFile file("check_writable_directory", probe);
    errno = 0;
    const bool written = std::fputs("emfusion\n", file.get()) >= 0;
    file.commit(written ? "" : detail::io::errno_text(errno));
  }
  if (std::remove(probe.c_str()) != 0)
    detail::io::fail("check_writable_directory", probe, "cannot remove: " + detail::io::errno_text(errno));
}

/// objects.txt: "id class first_timestamp last_timestamp deleted(0|1)".
inline void write_object_list(const std::string& path, const std::vector<ObjectListEntry>& objects) {
  std::string text = "# id class first_timestamp last_timestamp deleted\n";
  for (const ObjectListEntry& o : objects) {
    detail::require(!o.class_name.empty() && o.class_name.find_first_of(" \t\n#") == std::string::npos,
                    "write_object_list", "class name '" + o.class_name + "' is empty or contains white space or '#'");
    text += std::to_string(o.id) + " " + o.class_name + " " + detail::tum::format(o.first_timestamp) + " " +
            detail::tum::format(o.last_timestamp) + " " + (o.deleted ? "1" : "0") + "\n";
  }
  detail::tum::write_text(path, text, "write_object_list");
}

/// Reads objects.txt; errors name the file, the line and the problem.
inline std::vector<ObjectListEntry> read_object_list(const std::string& path) {
  constexpr const char* where = "read_object_list";
  std::vector<ObjectListEntry> out;
  for (const auto& line : detail::tum::data_lines(detail::io::read_file(path, where))) {
    const detail::tum::LineParser p(where, path, line);
    p.expect_fields(5, "id class first_timestamp last_timestamp deleted");
    ObjectListEntry e;
    e.id = p.positive_integer(0, "id");
    e.class_name = line.fields[1];
    e.first_timestamp = p.number(2, "first_timestamp");
    e.last_timestamp = p.number(3, "last_timestamp");
    if (line.fields[4] != "0" && line.fields[4] != "1") p.fail("deleted '" + line.fields[4] + "' is not 0 or 1");
    e.deleted = line.fields[4] == "1";
    out.push_back(e);
  }
  return out;
}

/// A small JSON writer for run.json and eval results: enough for numbers,
/// strings, booleans, nested objects and arrays, escaping strings.
class JsonWriter {
 public:
  JsonWriter& begin(const std::string& key = "") {
    separator();
    if (!key.empty()) text_ += quote(key) + ": ";
    text_ += "{";
    first_ = true;
    ++depth_;
    return *this;
  }
  JsonWriter& end() {
    --depth_;
    text_ += "\n" + std::string(std::size_t(2 * depth_), ' ') + "}";
    first_ = false;
    return *this;
  }
  /// An array: its elements are begin() objects or keyless values
  /// (number, integer, string with an empty key).
  JsonWriter& begin_array(const std::string& key) {
    separator();
    text_ += quote(key) + ": [";
    first_ = true;
    ++depth_;
    return *this;
  }
  JsonWriter& end_array() {
    --depth_;
    text_ += "\n" + std::string(std::size_t(2 * depth_), ' ') + "]";
    first_ = false;
    return *this;
  }
  JsonWriter& number(const std::string& key, double value) {
    return raw(key, std::isfinite(value) ? detail::tum::format(value) : "null");
  }
  JsonWriter& integer(const std::string& key, long long value) { return raw(key, std::to_string(value)); }
  JsonWriter& boolean(const std::string& key, bool value) { return raw(key, value ? "true" : "false"); }
  JsonWriter& string(const std::string& key, const std::string& value) { return raw(key, quote(value)); }
  std::string str() const { return text_ + "\n"; }

 private:
  JsonWriter& raw(const std::string& key, const std::string& value) {
    separator();
    text_ += (key.empty() ? std::string() : quote(key) + ": ") + value;
    return *this;
  }
  void separator() {
    if (depth_ == 0) return;
    text_ += first_ ? "\n" : ",\n";
    text_ += std::string(std::size_t(2 * depth_), ' ');
    first_ = false;
  }
  static std::string quote(const std::string& s) {
    std::string out = "\"";
    for (const char c : s) {
      if (c == '"' || c == '\\') out += '\\', out += c;
      else if (c == '\n') out += "\\n";
      else if (c == '\t') out += "\\t";
      else if (static_cast<unsigned char>(c) < 0x20) {
        char buf[8];
        std::snprintf(buf, sizeof(buf), "\\u%04x", c);
        out += buf;
      } else out += c;
    }
    return out + "\"";
  }
  std::string text_;
  int depth_ = 0;
  bool first_ = true;
};

/// Writes `text` to `path` atomically.
inline void write_text_file(const std::string& path, const std::string& text) {
  detail::tum::write_text(path, text, "write_text_file");
}

}  // namespace emfusion
