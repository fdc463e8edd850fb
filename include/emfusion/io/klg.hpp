// The .klg log format of ElasticFusion and Co-Fusion (shared/FORMATS.md
// section 1): an int32 frame count, then per frame an int64 timestamp
// (microseconds), an int32 depth byte count, an int32 colour byte count,
// the depth bytes (uint16 millimetres, little-endian, row by row; zlib-
// compressed unless the count is exactly width*height*2) and the colour
// bytes (raw RGB when the count is exactly width*height*3, else JPEG; 0 for
// no colour). The file holds no intrinsics: the caller passes the camera.
//
// KlgSequence is a FrameSource. open() walks the frame headers once (16
// bytes read per frame, no pixel data) and checks them against the file's
// size: frame count, sizes, strictly increasing timestamps, no trailing
// bytes, a zlib header where depth is compressed. depth(i) reads and, if
// needed, inflates one frame. write_klg writes logs (raw or zlib depth) for
// tests and conversions.
//
// Errors are std::runtime_error naming the file, the frame and its byte
// offset: "KlgSequence::open: 'log.klg': frame 3 (byte offset 1234): ...".
// Bad arguments (camera, depth_scale, frames to write) are
// std::invalid_argument. Colour JPEGs are not decoded here: colour_bytes(i)
// hands them out as stored.
#pragma once

#include <cerrno>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include <sys/types.h>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/camera.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/io/detail/bytes.hpp"
#include "emfusion/io/detail/failure.hpp"
#include "emfusion/io/detail/files.hpp"
#include "emfusion/io/detail/zlib.hpp"
#include "emfusion/io/frame_source.hpp"

namespace emfusion {

/// One frame for write_klg.
struct KlgFrame {
  /// Microseconds; must increase strictly from frame to frame.
  std::int64_t timestamp = 0;
  /// Depth in millimetres (or whatever unit the reader's depth_scale says),
  /// 0 = no measurement. Every frame of a log has the same size.
  Image<std::uint16_t, Host> depth;
  /// Written as given: empty (no colour), raw RGB (width*height*3 bytes) or
  /// an encoded JPEG (any other size).
  std::vector<std::uint8_t> colour;
};

/// How write_klg stores depth.
enum class KlgDepthEncoding {
  Raw,   ///< width*height*2 bytes
  Zlib,  ///< zlib (as ElasticFusion's logger); raw for a frame whose stream would be exactly the raw size
};

namespace detail::klg {

constexpr std::size_t frame_header_bytes = 16;

inline std::string at(std::size_t frame, std::uint64_t offset) {
  return "frame " + std::to_string(frame) + " (byte offset " + std::to_string(offset) + ")";
}

/// Random access to a file's bytes.
class Reader {
 public:
  Reader(const char* where, const std::string& path) : fail_{where, path} {
    errno = 0;
    file_.reset(std::fopen(path.c_str(), "rb"));
    if (!file_) fail_("cannot open for reading: " + io::errno_text(errno));
    if (fseeko(file_.get(), 0, SEEK_END) != 0) fail_("cannot seek: " + io::errno_text(errno));
    const off_t end = ftello(file_.get());
    if (end < 0) fail_("cannot tell the file size: " + io::errno_text(errno));
    size_ = std::uint64_t(end);
  }

  std::uint64_t size() const { return size_; }

  /// Reads `count` bytes at `offset` (which the caller checked against
  /// size()); a short read means the file changed or failed.
  void read(std::uint64_t offset, std::size_t count, unsigned char* out, const std::string& what) const {
    errno = 0;
    if (fseeko(file_.get(), off_t(offset), SEEK_SET) != 0 || std::fread(out, 1, count, file_.get()) != count)
      fail_(what + ": cannot read " + std::to_string(count) + " bytes at byte offset " + std::to_string(offset) + " (" +
            (std::ferror(file_.get()) ? io::errno_text(errno) : "the file is shorter than when opened") + ")");
  }

 private:
  io::Failure fail_;
  io::File file_;
  std::uint64_t size_ = 0;
};

}  // namespace detail::klg

/// A .klg log (see the top of this header) as a FrameSource.
class KlgSequence {
 public:
  /// Indexes the log at `path`. `camera` gives the image size (which
  /// decides raw versus compressed data) and intrinsics; depth in metres is
  /// the stored value / depth_scale (1000 for millimetres).
  static KlgSequence open(const std::string& path, const PinholeCamera<double>& camera, double depth_scale = 1000.0);

  /// Number of frames.
  std::size_t size() const { return frames_.size(); }
  /// Timestamp of frame i in seconds (the stored microseconds / 1e6).
  double timestamp(std::size_t i) const { return double(frame(i, "KlgSequence::timestamp").timestamp) / 1e6; }
  /// Timestamp of frame i as stored, microseconds.
  std::int64_t timestamp_us(std::size_t i) const { return frame(i, "KlgSequence::timestamp_us").timestamp; }
  /// Depth of frame i in metres (stored value / depth_scale, 0 stays 0).
  Image<float, Host> depth(std::size_t i) const;
  /// Depth of frame i as stored (uint16, depth_scale units per metre).
  Image<std::uint16_t, Host> raw_depth(std::size_t i) const;
  /// True when frame i's depth is zlib-compressed.
  bool depth_is_compressed(std::size_t i) const {
    return frame(i, "KlgSequence::depth_is_compressed").depth_size != raw_depth_size();
  }
  /// Number of colour bytes of frame i (0: no colour).
  std::size_t colour_size(std::size_t i) const { return frame(i, "KlgSequence::colour_size").colour_size; }
  /// True when frame i's colour is a JPEG (any size other than 0 and width*height*3).
  bool colour_is_jpeg(std::size_t i) const {
    const std::size_t n = frame(i, "KlgSequence::colour_is_jpeg").colour_size;
    return n != 0 && n != raw_depth_size() / 2 * 3;
  }
  /// Frame i's colour bytes as stored: raw RGB row by row, or a JPEG file.
  std::vector<std::uint8_t> colour_bytes(std::size_t i) const;

  const PinholeCamera<double>& camera() const { return camera_; }
  const std::string& path() const { return path_; }
  double depth_scale() const { return depth_scale_; }

 private:
  struct Frame {
    std::int64_t timestamp = 0;
    std::uint64_t offset = 0;  // of the frame header
    std::size_t depth_size = 0;
    std::size_t colour_size = 0;
  };

  const Frame& frame(std::size_t i, const char* where) const {
    if (i >= frames_.size())
      throw std::out_of_range(std::string(where) + ": frame " + std::to_string(i) + " out of range (" +
                              std::to_string(frames_.size()) + " frames in " + detail::io::quoted(path_) + ")");
    return frames_[i];
  }
  std::size_t raw_depth_size() const { return std::size_t(camera_.width) * std::size_t(camera_.height) * 2; }

  std::string path_;
  PinholeCamera<double> camera_;
  double depth_scale_ = 1000.0;
  std::vector<Frame> frames_;
};

inline KlgSequence KlgSequence::open(const std::string& path, const PinholeCamera<double>& camera, double depth_scale) {
  namespace klg = detail::klg;
  namespace bytes = detail::bytes;
  constexpr const char* where = "KlgSequence::open";
  camera.validate("KlgSequence::open: camera");
  if (std::int64_t(camera.width) * camera.height * 3 > std::numeric_limits<std::int32_t>::max())
    throw std::invalid_argument(std::string(where) + ": camera size " + std::to_string(camera.width) + "x" +
                                std::to_string(camera.height) + " is too large for a .klg frame");
  if (!(depth_scale > 0) || !std::isfinite(depth_scale))
    throw std::invalid_argument(std::string(where) + ": depth_scale must be positive and finite, got " +
                                std::to_string(depth_scale));
  const detail::io::Failure bad{where, path};
  const klg::Reader file(where, path);
  const std::uint64_t size = file.size();
  const auto str = [](auto value) { return std::to_string(value); };

  if (size < 4) bad("truncated header: the file has " + str(size) + " bytes, the frame count needs 4");
  unsigned char header[klg::frame_header_bytes];
  file.read(0, 4, header, "the frame count");
  const std::int32_t count = bytes::i32(header);
  if (count < 0) bad("negative frame count " + str(count) + " (corrupt header, or not a .klg file)");
  if (count == 0) bad("no frames (the frame count is 0)");
  const std::uint64_t most = (size - 4) / klg::frame_header_bytes;
  if (std::uint64_t(count) > most)
    bad("absurd frame count " + str(count) + ": the file's " + str(size) + " bytes could hold at most " + str(most) +
        " frame headers (corrupt header, or not a .klg file)");

  KlgSequence seq;
  seq.path_ = path;
  seq.camera_ = camera;
  seq.depth_scale_ = depth_scale;
  seq.frames_.reserve(std::size_t(count));
  const std::size_t raw_depth = seq.raw_depth_size();
  const std::string size_text = str(camera.width) + "x" + str(camera.height);
  std::uint64_t offset = 4;
  for (std::size_t i = 0; i < std::size_t(count); ++i) {
    const std::string frame = klg::at(i, offset);
    if (offset == size)
      bad("the header says " + str(count) + " frames but the file ends after " + str(i) + " (at byte offset " +
          str(offset) + ")");
    if (size - offset < klg::frame_header_bytes)
      bad(frame + ": truncated frame header (" + str(size - offset) + " bytes left, 16 needed)");
    file.read(offset, klg::frame_header_bytes, header, frame);
    Frame f;
    f.timestamp = bytes::i64(header);
    f.offset = offset;
    const std::int32_t depth_size = bytes::i32(header + 8), colour_size = bytes::i32(header + 12);
    if (depth_size < 0) bad(frame + ": negative depth size " + str(depth_size));
    if (colour_size < 0) bad(frame + ": negative colour size " + str(colour_size));
    if (depth_size == 0) bad(frame + ": no depth data (depth size 0)");
    f.depth_size = std::size_t(depth_size), f.colour_size = std::size_t(colour_size);
    const std::uint64_t left = size - offset - klg::frame_header_bytes;
    if (std::uint64_t(depth_size) + std::uint64_t(colour_size) > left)
      bad(frame + ": its " + str(depth_size) + " bytes of depth and " + str(colour_size) +
          " bytes of colour run past the end of the file (" + str(left) + " bytes left): truncated");
    if (f.depth_size != raw_depth) {
      unsigned char start[2] = {0, 0};
      if (f.depth_size >= 2) file.read(offset + klg::frame_header_bytes, 2, start, frame);
      if (f.depth_size < 2 || !detail::zlib::plausible_header(start))
        bad(frame + ": the depth size " + str(depth_size) + " is not " + str(raw_depth) + " (raw 16-bit depth of " +
            size_text + ") and the depth data is not a zlib stream (wrong camera size?)");
    }
    if (!seq.frames_.empty() && !(f.timestamp > seq.frames_.back().timestamp))
      bad(frame + ": timestamp " + str(f.timestamp) + " us is not after the previous frame's (" +
          str(seq.frames_.back().timestamp) + " us): timestamps must increase strictly");
    seq.frames_.push_back(f);
    offset += klg::frame_header_bytes + f.depth_size + f.colour_size;
  }
  if (offset != size)
    bad(str(size - offset) + " bytes after the last of the " + str(count) + " frames (which ends at byte offset " +
        str(offset) + "): the frame count is smaller than the frames present, or the file is corrupt");
  return seq;
}

inline Image<std::uint16_t, Host> KlgSequence::raw_depth(std::size_t i) const {
  constexpr const char* where = "KlgSequence::depth";
  const Frame& f = frame(i, where);
  const std::string frame_text = detail::klg::at(i, f.offset);
  const detail::klg::Reader file(where, path_);
  if (f.offset + detail::klg::frame_header_bytes + f.depth_size > file.size())
    detail::io::fail(where, path_, frame_text + ": the file is shorter than when it was opened");
  std::vector<unsigned char> data(f.depth_size);
  file.read(f.offset + detail::klg::frame_header_bytes, f.depth_size, data.data(), frame_text);
  const std::size_t raw = raw_depth_size();
  if (f.depth_size != raw) {
    std::vector<unsigned char> inflated;
    const std::string problem = detail::zlib::inflate_exact(data.data(), data.size(), raw, inflated);
    if (!problem.empty())
      detail::io::fail(where, path_,
                       frame_text + ": the depth data (" + std::to_string(f.depth_size) + " bytes) is not raw " +
                           std::to_string(camera_.width) + "x" + std::to_string(camera_.height) + " 16-bit depth (" +
                           std::to_string(raw) + " bytes) nor a zlib stream of it: " + problem);
    data.swap(inflated);
  }
  Image<std::uint16_t, Host> out(camera_.width, camera_.height);
  const ImageView<std::uint16_t> pixels = out.view();
  for (int k = 0; k < pixels.size(); ++k) pixels[k] = detail::bytes::u16(data.data() + 2 * std::size_t(k));
  return out;
}

inline Image<float, Host> KlgSequence::depth(std::size_t i) const {
  const Image<std::uint16_t, Host> raw = raw_depth(i);
  Image<float, Host> out(raw.width(), raw.height());
  const ImageView<const std::uint16_t> in = raw.view();
  const ImageView<float> metres = out.view();
  for (int k = 0; k < in.size(); ++k) metres[k] = in[k] == 0 ? 0.f : float(double(in[k]) / depth_scale_);
  return out;
}

inline std::vector<std::uint8_t> KlgSequence::colour_bytes(std::size_t i) const {
  constexpr const char* where = "KlgSequence::colour_bytes";
  const Frame& f = frame(i, where);
  std::vector<std::uint8_t> out(f.colour_size);
  if (f.colour_size == 0) return out;
  const detail::klg::Reader file(where, path_);
  const std::uint64_t start = f.offset + detail::klg::frame_header_bytes + f.depth_size;
  if (start + f.colour_size > file.size())
    detail::io::fail(where, path_, detail::klg::at(i, f.offset) + ": the file is shorter than when it was opened");
  file.read(start, f.colour_size, out.data(), detail::klg::at(i, f.offset));
  return out;
}

/// Writes a .klg log: the frame count, then each frame with its depth
/// stored as `encoding` says and its colour as given. Through "<path>.tmp"
/// renamed over `path` when complete. Throws std::invalid_argument, writing
/// nothing, for no frames, an empty depth image, depth images of different
/// sizes, or timestamps that do not increase strictly.
inline void write_klg(const std::string& path, const std::vector<KlgFrame>& frames,
                      KlgDepthEncoding encoding = KlgDepthEncoding::Zlib) {
  namespace bytes = detail::bytes;
  constexpr const char* where = "write_klg";
  const auto invalid = [&](const std::string& problem) {
    throw std::invalid_argument(std::string(where) + ": " + detail::io::quoted(path) + ": " + problem);
  };
  if (frames.empty()) invalid("no frames");
  if (frames.size() > std::size_t(std::numeric_limits<std::int32_t>::max())) invalid("too many frames");
  const int width = frames[0].depth.width(), height = frames[0].depth.height();
  if (frames[0].depth.empty()) invalid("frame 0: the depth image is empty");
  if (std::int64_t(width) * height * 3 > std::numeric_limits<std::int32_t>::max())
    invalid("the depth images are too large for a .klg frame");
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const KlgFrame& f = frames[i];
    if (!f.depth.same_size(width, height))
      invalid("frame " + std::to_string(i) + ": the depth image is " + std::to_string(f.depth.width()) + "x" +
              std::to_string(f.depth.height()) + ", frame 0's is " + std::to_string(width) + "x" +
              std::to_string(height));
    if (f.colour.size() > std::size_t(std::numeric_limits<std::int32_t>::max()))
      invalid("frame " + std::to_string(i) + ": too many colour bytes");
    if (i > 0 && !(f.timestamp > frames[i - 1].timestamp))
      invalid("frame " + std::to_string(i) + ": timestamp " + std::to_string(f.timestamp) +
              " us is not after the previous one (" + std::to_string(frames[i - 1].timestamp) + " us)");
  }

  detail::io::AtomicFile file(where, path);
  std::string out;
  bytes::put_i32(out, std::int32_t(frames.size()));
  bool written = true;
  errno = 0;
  for (const KlgFrame& f : frames) {
    std::string depth;
    depth.reserve(std::size_t(width) * std::size_t(height) * 2);
    const ImageView<const std::uint16_t> pixels = f.depth.view();
    for (int k = 0; k < pixels.size(); ++k) bytes::put_u16(depth, pixels[k]);
    if (encoding == KlgDepthEncoding::Zlib) {
      const std::vector<unsigned char> packed =
          detail::zlib::deflate(reinterpret_cast<const unsigned char*>(depth.data()), depth.size());
      // A stream of exactly the raw size would read back as raw depth.
      if (packed.size() != depth.size() && packed.size() <= std::size_t(std::numeric_limits<std::int32_t>::max()))
        depth.assign(reinterpret_cast<const char*>(packed.data()), packed.size());
    }
    bytes::put_i64(out, f.timestamp);
    bytes::put_i32(out, std::int32_t(depth.size()));
    bytes::put_i32(out, std::int32_t(f.colour.size()));
    out += depth;
    out.append(reinterpret_cast<const char*>(f.colour.data()), f.colour.size());
    written = written && std::fwrite(out.data(), 1, out.size(), file.get()) == out.size();
    out.clear();
  }
  file.commit(written ? "" : detail::io::errno_text(errno));
}

static_assert(FrameSource<KlgSequence>);

}  // namespace emfusion
