// What every reader and writer of io/ shares: error messages that name the
// file ("where: 'path': problem"), reading a whole file, and files written
// atomically, through
// "<path>.tmp" renamed over `path` only once everything reached the disk, so
// a failed write never leaves a half-written file under the target name.
#pragma once

#include <cerrno>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>
#include <system_error>
#include <utility>

namespace emfusion::detail::io {

struct FileCloser {
  void operator()(std::FILE* f) const { std::fclose(f); }
};
using File = std::unique_ptr<std::FILE, FileCloser>;

inline std::string quoted(const std::string& path) { return "'" + path + "'"; }
// Calls below say io::quoted: unqualified, argument-dependent lookup would
// prefer std::quoted's overload for non-const strings.

/// The text of an errno value; 0 (a failure that set no errno) reads as EIO.
inline std::string errno_text(int error) { return std::generic_category().message(error != 0 ? error : EIO); }

[[noreturn]] inline void fail(const char* where, const std::string& path, const std::string& problem) {
  throw std::runtime_error(std::string(where) + ": " + io::quoted(path) + ": " + problem);
}

/// The whole content of a file; errors name `where` and the file.
inline std::string read_file(const std::string& path, const char* where) {
  errno = 0;
  File file(std::fopen(path.c_str(), "rb"));
  if (!file) fail(where, path, "cannot open for reading: " + errno_text(errno));
  std::string data;
  char buffer[1 << 16];
  std::size_t n;
  while ((n = std::fread(buffer, 1, sizeof(buffer), file.get())) > 0) data.append(buffer, n);
  if (std::ferror(file.get())) fail(where, path, "read error: " + errno_text(errno));
  return data;
}

/// A file being written to "<path>.tmp"; commit() moves it to `path`. If
/// commit() is never reached (an exception), the temporary is removed.
class AtomicFile {
 public:
  AtomicFile(const char* where, std::string path)
      : where_(where), path_(std::move(path)), temporary_(path_ + ".tmp") {
    errno = 0;
    file_.reset(std::fopen(temporary_.c_str(), "wb"));
    if (!file_) fail(where_, path_, "cannot open " + io::quoted(temporary_) + " for writing: " + errno_text(errno));
  }
  ~AtomicFile() {
    if (file_) {
      file_.reset();
      std::remove(temporary_.c_str());
    }
  }
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  std::FILE* get() const { return file_.get(); }
  const std::string& temporary() const { return temporary_; }

  /// Finishes the file. `problem` says why writing it failed ("" if it did
  /// not); buffered data can still fail to reach the disk (full disk, quota)
  /// when the file is flushed and closed. On any failure the temporary is
  /// removed and the error names it; otherwise it is renamed over the path.
  void commit(std::string problem = {}) {
    errno = 0;
    if (problem.empty() && std::fflush(file_.get()) != 0) problem = errno_text(errno);
    errno = 0;
    if (std::fclose(file_.release()) != 0 && problem.empty()) problem = errno_text(errno);
    if (!problem.empty()) {
      std::remove(temporary_.c_str());
      fail(where_, path_, "cannot write " + io::quoted(temporary_) + ": " + problem);
    }
    if (std::rename(temporary_.c_str(), path_.c_str()) != 0) {
      const int error = errno;
      std::remove(temporary_.c_str());
      fail(where_, path_, "cannot rename " + io::quoted(temporary_) + " to it: " + errno_text(error));
    }
  }

 private:
  const char* where_;
  std::string path_;
  std::string temporary_;
  File file_;
};

}  // namespace emfusion::detail::io
