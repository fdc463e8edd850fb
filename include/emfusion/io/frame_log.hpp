// frames.csv: one line per processed frame with its stage times, the
// objects alive and the memory in use (docs/io.md, "frames.csv"), written
// while the run goes so that a run stopped at any moment keeps the lines of
// the frames it processed, as camera.txt does (io/trajectory_stream.hpp):
// each line is handed to the kernel (fflush) as soon as it is appended.
//
//   FrameLog log(out + "/frames.csv");
//   log.append({i, t, result.times, result.live_objects, resident_memory_mib(), device_memory_mib<B>()});
//
// read_frame_log reads the file back (for `emfusion eval`'s report): a
// malformed line is std::runtime_error naming the file and the line; a last
// line without its newline (a process killed in the middle of a write) is
// left out.
#pragma once

#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "emfusion/core/backend.hpp"
#include "emfusion/io/detail/files.hpp"
#include "emfusion/slam/frame_result.hpp"

namespace emfusion {

/// One stage time of StageTimes: its frames.csv column (without "_ms").
struct FrameLogStage {
  // Through an alias: nvcc's generated code words a plain member-pointer
  // member with parentheses that g++ warns about (-Wparentheses).
  using Field = double StageTimes::*;
  const char* name;
  Field field;
};

/// The stage columns in file order, after total_ms.
inline constexpr FrameLogStage frame_log_stages[] = {{"preprocess", &StageTimes::preprocess},
                                                     {"e_step", &StageTimes::e_step},
                                                     {"track_background", &StageTimes::track_background},
                                                     {"track_objects", &StageTimes::track_objects},
                                                     {"raycast", &StageTimes::raycast},
                                                     {"detections", &StageTimes::detections},
                                                     {"integrate", &StageTimes::integrate},
                                                     {"foreground", &StageTimes::foreground}};

/// One line of frames.csv.
struct FrameLogRow {
  std::size_t frame = 0;             ///< index of the frame in the input
  double timestamp = 0;              ///< seconds
  StageTimes times;                  ///< milliseconds
  int objects = 0;                   ///< objects alive after the frame
  double rss_mib = 0;                ///< resident memory of the process, MiB
  std::optional<double> device_mib;  ///< device memory in use, MiB (CUDA only)
};

/// The header line (without its newline).
inline std::string frame_log_header() {
  std::string h = "frame,timestamp,total_ms";
  for (const FrameLogStage& s : frame_log_stages) {
    h += ',';
    h += s.name;
    h += "_ms";
  }
  h += ",objects,rss_mib,device_mib";
  return h;
}

/// Resident set size of this process now (/proc/self/statm), MiB; 0 where
/// that file cannot be read.
inline double resident_memory_mib() {
  std::FILE* f = std::fopen("/proc/self/statm", "r");
  if (!f) return 0;
  long pages = 0, resident = 0;
  const int n = std::fscanf(f, "%ld %ld", &pages, &resident);
  std::fclose(f);
  return n == 2 ? double(resident) * double(sysconf(_SC_PAGESIZE)) / (1024.0 * 1024.0) : 0.0;
}

/// Device memory in use on the current GPU (cudaMemGetInfo: all processes),
/// MiB; none on the host backend.
template <class B>
std::optional<double> device_memory_mib() {
#if EMFUSION_HAS_CUDA
  if constexpr (B::is_device) {
    std::size_t free = 0, total = 0;
    if (cudaMemGetInfo(&free, &total) != cudaSuccess) return std::nullopt;
    return double(total - free) / (1024.0 * 1024.0);
  }
#endif
  return std::nullopt;
}

class FrameLog {
 public:
  /// Creates `path` (emptying an existing file), writes the header and the
  /// lines `kept` (a resumed run's frames before its checkpoint) at once: a
  /// file that cannot be written fails here, before the first frame.
  explicit FrameLog(std::string path, const std::vector<FrameLogRow>& kept = {}) : path_(std::move(path)) {
    errno = 0;
    file_.reset(std::fopen(path_.c_str(), "w"));
    if (!file_) detail::io::fail("FrameLog", path_, "cannot open for writing: " + detail::io::errno_text(errno));
    std::string text = frame_log_header() + "\n";
    for (const FrameLogRow& row : kept) text += line(row);
    write(text);
  }

  /// Writes `row` as one line and flushes it.
  void append(const FrameLogRow& row) {
    write(line(row));
    ++rows_;
  }

  /// Closes the file, reporting an error the close finds.
  void close() {
    if (!file_) return;
    errno = 0;
    if (std::fclose(file_.release()) != 0) fail("cannot close");
  }

  std::size_t rows() const { return rows_; }
  const std::string& path() const { return path_; }

  /// The line of `row`, newline included.
  static std::string line(const FrameLogRow& row) {
    std::string s = std::to_string(row.frame);
    const auto cell = [&s](const std::string& text) {
      s += ',';
      s += text;
    };
    cell(number(row.timestamp, 6));
    cell(number(row.times.total, 3));
    for (const FrameLogStage& st : frame_log_stages) cell(number(row.times.*st.field, 3));
    cell(std::to_string(row.objects));
    cell(number(row.rss_mib, 1));
    cell(row.device_mib ? number(*row.device_mib, 1) : std::string());
    s += '\n';
    return s;
  }

 private:
  static std::string number(double v, int digits) {
    if (!std::isfinite(v)) return "";
    char buffer[64];
    std::snprintf(buffer, sizeof(buffer), "%.*f", digits, v);
    return buffer;
  }
  void write(const std::string& text) {
    if (!file_) fail("already closed");
    errno = 0;
    if (std::fwrite(text.data(), 1, text.size(), file_.get()) != text.size() || std::fflush(file_.get()) != 0)
      fail("cannot write");
  }
  [[noreturn]] void fail(const char* what) const {
    detail::io::fail("FrameLog", path_, std::string(what) + ": " + detail::io::errno_text(errno));
  }

  std::string path_;
  detail::io::File file_;
  std::size_t rows_ = 0;
};

/// The lines of a frames.csv. Empty cells (a non-finite time, no device
/// memory) read as NaN / none. Errors name the file and the line: a header
/// other than frame_log_header(), a line with another number of cells, a
/// cell that is not a number.
inline std::vector<FrameLogRow> read_frame_log(const std::string& path) {
  const std::string text = detail::io::read_file(path, "read_frame_log");
  std::vector<FrameLogRow> rows;
  std::size_t at = 0, line_number = 0;
  const std::string header = frame_log_header();
  const std::size_t cells = 3 + std::size(frame_log_stages) + 3;
  while (at < text.size()) {
    const std::size_t end = text.find('\n', at);
    if (end == std::string::npos) break;  // torn last line: a run killed mid-write
    std::string l = text.substr(at, end - at);
    at = end + 1;
    ++line_number;
    if (!l.empty() && l.back() == '\r') l.pop_back();
    const auto bad = [&](const std::string& problem) {
      detail::io::fail("read_frame_log", path, "line " + std::to_string(line_number) + ": " + problem);
    };
    if (line_number == 1) {
      if (l != header) bad("expected the header '" + header + "', got '" + l + "'");
      continue;
    }
    if (l.empty()) continue;
    std::vector<std::string> c;
    std::size_t from = 0;
    for (;;) {
      const std::size_t comma = l.find(',', from);
      c.push_back(l.substr(from, comma == std::string::npos ? std::string::npos : comma - from));
      if (comma == std::string::npos) break;
      from = comma + 1;
    }
    if (c.size() != cells)
      bad("expected " + std::to_string(cells) + " comma-separated values, got " + std::to_string(c.size()));
    const auto value = [&](std::size_t k, bool may_be_empty) {
      if (c[k].empty()) {
        if (!may_be_empty) bad("value " + std::to_string(k + 1) + " is empty");
        return std::nan("");
      }
      char* stop = nullptr;
      const double v = std::strtod(c[k].c_str(), &stop);
      if (stop != c[k].c_str() + c[k].size()) bad("value " + std::to_string(k + 1) + " '" + c[k] + "' is not a number");
      return v;
    };
    FrameLogRow row;
    const double frame = value(0, false);
    if (frame < 0 || frame != std::floor(frame)) bad("frame '" + c[0] + "' is not a frame index");
    row.frame = std::size_t(frame);
    row.timestamp = value(1, false);
    row.times.total = value(2, true);
    std::size_t k = 3;
    for (const FrameLogStage& st : frame_log_stages) row.times.*st.field = value(k++, true);
    row.objects = int(value(k++, false));
    row.rss_mib = value(k++, true);
    if (!c[k].empty()) row.device_mib = value(k, false);
    rows.push_back(row);
  }
  if (line_number == 0) detail::io::fail("read_frame_log", path, "empty file (expected the header '" + header + "')");
  return rows;
}

}  // namespace emfusion
