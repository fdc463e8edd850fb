// Writing and reading the outputs of a run (shared FORMATS.md section 5):
//   <out>/camera.txt, <out>/objects.txt, <out>/objects/<id>.txt,
//   <out>/meshes/background.ply, <out>/meshes/object_<id>.ply, <out>/run.json
//   (JSON through nlohmann-json: Json, json_text, write_json_file).
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

#include <nlohmann/json.hpp>

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

/// run.json, eval.json and the benchmarks' JSON documents (docs/io.md,
/// "run.json"), through nlohmann-json: an ordered_json keeps its keys in the
/// order they were set, so files read in the order the program wrote them.
using Json = nlohmann::ordered_json;

/// The text of a JSON document as emfusion writes it: two-space
/// indentation, one member per line, a final newline. Numbers that are not
/// finite (NaN, infinities) are written as null; bytes of a string that are
/// not UTF-8 (a path on a filesystem of another encoding) become U+FFFD
/// instead of failing the run when its summary is written.
inline std::string json_text(const Json& document) {
  return document.dump(2, ' ', false, Json::error_handler_t::replace) + "\n";
}

/// Writes `document` (json_text) to `path` atomically.
inline void write_json_file(const std::string& path, const Json& document) {
  detail::tum::write_text(path, json_text(document), "write_json_file");
}

/// Writes `text` to `path` atomically.
inline void write_text_file(const std::string& path, const std::string& text) {
  detail::tum::write_text(path, text, "write_text_file");
}

}  // namespace emfusion
