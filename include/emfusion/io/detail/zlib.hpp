// zlib streams for the .klg depth frames of io/: inflating a stream that
// must decode to an exact number of bytes, which tells a short, long or
// corrupt stream apart in words, and deflating a buffer.
#pragma once

#include <climits>
#include <cstddef>
#include <new>
#include <stdexcept>
#include <string>
#include <vector>

#include <zlib.h>

namespace emfusion::detail::zlib {

/// Inflates the zlib stream `in[0, size)` into `out`, which it resizes to
/// `expected` bytes. Returns "" on success, else the problem in words: not a
/// zlib stream, corrupt data, a stream that ends early or decodes to more
/// than `expected` bytes, or bytes left over after the end of the stream.
inline std::string inflate_exact(const unsigned char* in, std::size_t size, std::size_t expected,
                                 std::vector<unsigned char>& out) {
  if (size > UINT_MAX || expected >= UINT_MAX) return "the stream is too large";
  if (size < 2) return "not a zlib stream (only " + std::to_string(size) + " bytes)";
  // One spare byte of room: a stream that would decode to more than
  // `expected` bytes fills it, which is how we notice.
  out.resize(expected + 1);
  z_stream stream{};
  if (inflateInit(&stream) != Z_OK) throw std::bad_alloc();
  stream.next_in = const_cast<unsigned char*>(in);  // zlib's API is not const-correct; it does not write
  stream.avail_in = uInt(size);
  stream.next_out = out.data();
  stream.avail_out = uInt(out.size());
  const int result = ::inflate(&stream, Z_FINISH);
  const std::size_t produced = stream.total_out;
  const std::size_t left_over = stream.avail_in;
  const std::string message = stream.msg ? stream.msg : "";
  inflateEnd(&stream);
  out.resize(expected);
  switch (result) {
    case Z_STREAM_END:
      if (produced != expected)
        return "the zlib stream decodes to " + std::to_string(produced) + " bytes, expected " +
               std::to_string(expected);
      if (left_over != 0) return std::to_string(left_over) + " bytes follow the end of the zlib stream";
      return "";
    case Z_BUF_ERROR:
      if (produced > expected)
        return "the zlib stream decodes to more than the expected " + std::to_string(expected) + " bytes";
      return "the zlib stream ends early (after " + std::to_string(produced) + " of " + std::to_string(expected) +
             " bytes): truncated";
    case Z_MEM_ERROR:
      throw std::bad_alloc();
    default:
      return "not a valid zlib stream" + (message.empty() ? std::string() : " (" + message + ")");
  }
}

/// True if the two bytes at `p` can start a zlib stream (deflate method,
/// window <= 32 KiB, header check, no preset dictionary): a cheap test
/// before inflating.
inline bool plausible_header(const unsigned char* p) {
  return (p[0] & 0x0f) == 8 && (p[0] >> 4) <= 7 && ((unsigned(p[0]) << 8) | p[1]) % 31 == 0 && (p[1] & 0x20) == 0;
}

/// The zlib stream of `in[0, size)`.
inline std::vector<unsigned char> deflate(const unsigned char* in, std::size_t size,
                                          int level = Z_DEFAULT_COMPRESSION) {
  uLongf out_size = compressBound(uLong(size));
  std::vector<unsigned char> out(out_size);
  const int result = compress2(out.data(), &out_size, in, uLong(size), level);
  if (result == Z_MEM_ERROR) throw std::bad_alloc();
  if (result != Z_OK) throw std::runtime_error("zlib compress2 failed (code " + std::to_string(result) + ")");
  out.resize(out_size);
  return out;
}

}  // namespace emfusion::detail::zlib
