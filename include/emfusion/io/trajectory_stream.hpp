// A TUM trajectory file written while the poses come (shared/FORMATS.md
// section 4), for runs that may never reach their end: a process killed at
// any moment (SIGKILL, a crash) leaves a file that reads as the poses
// flushed so far, and sync() makes them survive a power loss too.
//
// The lines are write_tum_trajectory's, byte for byte (same header, same
// precision, same checks). Unlike the files written whole, this one lives
// under its final name from the start: a file cannot be renamed into place
// at an end that never comes. Instead each flush() hands all pending lines
// to the kernel in one write, and a write that fails half-way is cut back to
// the last complete line before the error is thrown, so the file never ends
// in a torn line that would read as a wrong pose.
//
// Write errors (a full disk, a quota, an I/O error) are std::runtime_error
// naming the file and the system's text ("TumTrajectoryStream:
// 'out/camera.txt': cannot write: No space left on device"); bad poses are
// std::invalid_argument as for write_tum_trajectory. POSIX only (open,
// write, ftruncate, fdatasync).
#pragma once

#include <fcntl.h>
#include <sys/types.h>
#include <unistd.h>

#include <cerrno>
#include <cstddef>
#include <string>
#include <utility>

#include "emfusion/core/timed_pose.hpp"
#include "emfusion/io/detail/files.hpp"
#include "emfusion/io/tum.hpp"

namespace emfusion {

class TumTrajectoryStream {
 public:
  /// A stream with no file; assign an opened one to use it.
  TumTrajectoryStream() = default;

  /// Creates `path` (emptying an existing file) and writes the header line
  /// at once, so that a file that cannot be written fails here, before the
  /// first pose.
  explicit TumTrajectoryStream(std::string path) : path_(std::move(path)) {
    open(O_CREAT | O_TRUNC);
    pending_ = detail::tum::trajectory_header;
    flush();
  }

  TumTrajectoryStream(TumTrajectoryStream&& other) noexcept { swap(other); }
  TumTrajectoryStream& operator=(TumTrajectoryStream&& other) noexcept {
    TumTrajectoryStream moved(std::move(other));
    swap(moved);
    return *this;
  }
  TumTrajectoryStream(const TumTrajectoryStream&) = delete;
  TumTrajectoryStream& operator=(const TumTrajectoryStream&) = delete;

  /// Closes the file; lines not flushed are dropped (a destructor cannot
  /// report that they failed to reach the disk: call close() for that).
  ~TumTrajectoryStream() {
    if (fd_ >= 0) ::close(fd_);
  }

  /// Adds `pose` after the poses before it, in memory until flush(). The
  /// checks of write_tum_trajectory; a bad pose adds nothing.
  void append(const TimedPose& pose) { lines_.append(pending_, pose, "TumTrajectoryStream", path_); }

  /// Writes the pending lines to the file, reopening it (to append) if it
  /// was closed. On failure the file is cut back to its last complete line
  /// and the error names it; the pending lines are dropped.
  void flush() {
    if (pending_.empty()) return;
    if (fd_ < 0) open(0);
    const std::string text = std::exchange(pending_, std::string());
    std::size_t done = 0;
    while (done < text.size()) {
      errno = 0;
      const ssize_t n = ::write(fd_, text.data() + done, text.size() - done);
      if (n > 0) {
        done += std::size_t(n);
        continue;
      }
      if (n < 0 && errno == EINTR) continue;
      const int error = errno;
      // Best effort: a device cannot be cut back (ftruncate fails there),
      // and the error below is what the caller needs either way.
      if (done > 0) {
        [[maybe_unused]] const int cut = ::ftruncate(fd_, bytes_);
      }
      fail("cannot write", error);
    }
    bytes_ += off_t(text.size());
  }

  /// flush(), then asks the disk to keep what the file holds through a
  /// power loss (fdatasync; a no-op for files that cannot be synced, such as
  /// devices and pipes).
  void sync() {
    flush();
    if (fd_ < 0) return;
    if (::fdatasync(fd_) != 0 && errno != EINVAL && errno != EROFS && errno != ENOTSUP) fail("cannot sync", errno);
  }

  /// flush() and closes the file, reporting an error close() finds. append()
  /// and flush() afterwards reopen it to add more poses.
  void close() {
    flush();
    if (fd_ < 0) return;
    const int fd = std::exchange(fd_, -1);
    if (::close(fd) != 0 && errno != EINTR) fail("cannot close", errno);
  }

  /// The poses appended, flushed or not.
  std::size_t size() const { return lines_.count(); }
  const std::string& path() const { return path_; }
  bool is_open() const { return fd_ >= 0; }

 private:
  void open(int flags) {
    errno = 0;
    // Always O_APPEND: after a cut-back, the next write lands at the new end.
    fd_ = ::open(path_.c_str(), O_WRONLY | O_APPEND | O_CLOEXEC | flags, 0666);
    if (fd_ < 0) fail("cannot open for writing", errno);
  }

  [[noreturn]] void fail(const char* what, int error) const {
    detail::io::fail("TumTrajectoryStream", path_, std::string(what) + ": " + detail::io::errno_text(error));
  }

  void swap(TumTrajectoryStream& other) noexcept {
    std::swap(path_, other.path_);
    std::swap(pending_, other.pending_);
    std::swap(lines_, other.lines_);
    std::swap(bytes_, other.bytes_);
    std::swap(fd_, other.fd_);
  }

  std::string path_;
  std::string pending_;           // lines appended but not yet written
  detail::tum::PoseLines lines_;  // formats them and remembers the last timestamp
  off_t bytes_ = 0;               // the file's size after the last complete flush
  int fd_ = -1;
};

}  // namespace emfusion
