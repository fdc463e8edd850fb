// Fuzz target: .klg logs (KlgSequence::open, then raw_depth, depth and
// colour_bytes of every frame) with a 4x3 camera baked in, so raw depth is
// 24 bytes and raw colour 36; the seeds in corpus/klg/ are 4x3 logs.
//
// KlgSequence reads its file by random access (open() walks the frame
// headers; every depth/colour call opens the file anew and seeks), so an
// in-memory entry point would mean a second reader; instead the input is
// written to one temporary file per process (in /dev/shm when there is one,
// removed at exit) and read back through the real code path.
//
// An opened log is compared with an independent walk of the same bytes:
// frame count, timestamps, colour sizes, which frames are compressed, that
// the frames exactly fill the file, and raw depth equal to the stored
// little-endian values (or to zlib's own uncompress of a compressed frame).
#include <zlib.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include "emfusion/io/klg.hpp"
#include "fuzz_check.hpp"

namespace fuzz_klg {

constexpr int width = 4, height = 3;
constexpr std::size_t raw_depth_bytes = width * height * 2, raw_colour_bytes = width * height * 3;

/// The per-process file the input goes through.
class TemporaryFile {
 public:
  TemporaryFile() : path_(emfusion::fuzz::scratch_file("log.klg")) {}
  ~TemporaryFile() { std::remove(path_.c_str()); }
  TemporaryFile(const TemporaryFile&) = delete;
  TemporaryFile& operator=(const TemporaryFile&) = delete;

  const std::string& write(const std::uint8_t* data, std::size_t size) const {
    std::FILE* file = std::fopen(path_.c_str(), "wb");
    if (!file) {
      std::perror(path_.c_str());
      __builtin_trap();
    }
    const bool ok = std::fwrite(data, 1, size, file) == size;
    if (std::fclose(file) != 0 || !ok) {
      std::perror(path_.c_str());
      __builtin_trap();
    }
    return path_;
  }

 private:
  std::string path_;
};

struct Header {
  std::int64_t timestamp;
  std::size_t depth_size, colour_size, offset;
};

inline void check(const std::uint8_t* data, std::size_t size) {
  namespace bytes = emfusion::detail::bytes;
  static const TemporaryFile temporary;
  const std::string& path = temporary.write(data, size);
  const emfusion::PinholeCamera<double> camera{3.0, 3.0, 1.5, 1.0, width, height};
  std::optional<emfusion::KlgSequence> opened;
  if (!emfusion::fuzz::returns([&] { opened = emfusion::KlgSequence::open(path, camera, 1000.0); }, path)) return;
  const emfusion::KlgSequence& log = *opened;

  // The independent walk: the open log promises all of this.
  EMF_FUZZ_CHECK(size >= 4);
  const std::int32_t count = bytes::i32(data);
  EMF_FUZZ_CHECK(count > 0 && log.size() == std::size_t(count));
  std::vector<Header> headers;
  std::size_t offset = 4;
  for (std::int32_t i = 0; i < count; ++i) {
    EMF_FUZZ_CHECK(size - offset >= 16);
    const unsigned char* h = data + offset;
    const std::int32_t depth_size = bytes::i32(h + 8), colour_size = bytes::i32(h + 12);
    EMF_FUZZ_CHECK(depth_size > 0 && colour_size >= 0);
    headers.push_back({bytes::i64(h), std::size_t(depth_size), std::size_t(colour_size), offset});
    EMF_FUZZ_CHECK(size - offset - 16 >= headers.back().depth_size + headers.back().colour_size);
    offset += 16 + std::size_t(depth_size) + std::size_t(colour_size);
  }
  EMF_FUZZ_CHECK(offset == size);

  for (std::size_t i = 0; i < log.size(); ++i) {
    const Header& h = headers[i];
    EMF_FUZZ_CHECK(log.timestamp_us(i) == h.timestamp);
    EMF_FUZZ_CHECK(i == 0 || log.timestamp_us(i) > log.timestamp_us(i - 1));
    EMF_FUZZ_CHECK(log.timestamp(i) == double(h.timestamp) / 1e6);
    EMF_FUZZ_CHECK(log.colour_size(i) == h.colour_size);
    EMF_FUZZ_CHECK(log.colour_is_jpeg(i) == (h.colour_size != 0 && h.colour_size != raw_colour_bytes));
    EMF_FUZZ_CHECK(log.depth_is_compressed(i) == (h.depth_size != raw_depth_bytes));

    const unsigned char* stored = data + h.offset + 16;
    std::vector<unsigned char> expected(stored, stored + h.depth_size);
    bool inflates = true;
    if (h.depth_size != raw_depth_bytes) {
      // zlib's own answer: exactly 24 bytes and the whole stream used.
      std::vector<unsigned char> out(raw_depth_bytes + 1);
      uLongf out_size = uLongf(out.size());
      uLong in_size = uLong(h.depth_size);
      inflates = ::uncompress2(out.data(), &out_size, stored, &in_size) == Z_OK && out_size == raw_depth_bytes &&
                 in_size == h.depth_size;
      expected.assign(out.begin(), out.begin() + std::ptrdiff_t(raw_depth_bytes));
    }
    emfusion::Image<std::uint16_t, emfusion::Host> raw;
    const bool read = emfusion::fuzz::returns([&] { raw = log.raw_depth(i); }, path);
    EMF_FUZZ_CHECK(read == inflates);
    if (read) {
      EMF_FUZZ_CHECK(raw.width() == width && raw.height() == height);
      const emfusion::ImageView<const std::uint16_t> pixels = raw.view();
      for (int k = 0; k < pixels.size(); ++k)
        EMF_FUZZ_CHECK(pixels[k] == bytes::u16(expected.data() + 2 * std::size_t(k)));
      const emfusion::Image<float, emfusion::Host> metres = log.depth(i);
      const emfusion::ImageView<const float> m = metres.view();
      for (int k = 0; k < m.size(); ++k)
        EMF_FUZZ_CHECK(pixels[k] == 0 ? m[k] == 0.f : std::isfinite(m[k]) && m[k] > 0.f);
    }
    const std::vector<std::uint8_t> colour = log.colour_bytes(i);
    EMF_FUZZ_CHECK(colour.size() == h.colour_size);
    for (std::size_t k = 0; k < colour.size(); ++k) EMF_FUZZ_CHECK(colour[k] == stored[h.depth_size + k]);
  }
  EMF_FUZZ_CHECK(!emfusion::fuzz::returns([&] { (void)log.raw_depth(log.size()); }, path));
}

}  // namespace fuzz_klg

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  fuzz_klg::check(data, size);
  return 0;
}
