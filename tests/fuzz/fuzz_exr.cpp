// Fuzz target: OpenEXR depth images (Co-Fusion's depth/Depth%04d.exr)
// through decode_exr, which hands them to the OpenEXR library. A decoded
// image must have the size limits the reader promises; a small one written
// back with write_exr in each lossless compression (through one temporary
// file per process, in /dev/shm when there is one, removed at exit) must
// read back bit for bit. OpenEXR's own limits on image and tile sizes are
// set far below the reader's (256 pixels a side, 64 a tile side) so that
// a few hostile header bytes cannot make one run allocate hundreds of
// megabytes; without OpenEXR every input is the error that says so.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>

#include "emfusion/io/exr.hpp"
#include "fuzz_check.hpp"

#if EMFUSION_HAS_OPENEXR
#include <ImfHeader.h>
#include <ImfThreading.h>
#endif

namespace fuzz_exr {

class TemporaryPath {
 public:
  TemporaryPath() : path_(emfusion::fuzz::scratch_file("depth.exr")) {}
  ~TemporaryPath() { std::remove(path_.c_str()); }
  TemporaryPath(const TemporaryPath&) = delete;
  TemporaryPath& operator=(const TemporaryPath&) = delete;
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

inline bool same_bits(const emfusion::Image<float, emfusion::Host>& a,
                      const emfusion::Image<float, emfusion::Host>& b) {
  if (!a.same_size(b.width(), b.height())) return false;
  const emfusion::ImageView<const float> x = a.view(), y = b.view();
  return std::memcmp(x.data, y.data, sizeof(float) * std::size_t(x.size())) == 0;
}

inline bool limit_openexr() {
#if EMFUSION_HAS_OPENEXR
  // One thread: a crash is then reported in the thread that read the input.
  Imf::setGlobalThreadCount(0);
  Imf::Header::setMaxImageSize(256, 256);
  Imf::Header::setMaxTileSize(64, 64);
#endif
  return true;
}

inline void check(const std::uint8_t* data, std::size_t size) {
  [[maybe_unused]] static const bool limited = limit_openexr();
  const std::string name = "fuzz/Depth0000.exr";
  emfusion::Image<float, emfusion::Host> image;
  if (!emfusion::fuzz::returns([&] { image = emfusion::decode_exr(data, size, name); }, name)) return;
  EMF_FUZZ_CHECK(image.width() >= 1 && image.height() >= 1);
  EMF_FUZZ_CHECK(image.width() <= (1 << 20) && image.height() <= (1 << 20));
  EMF_FUZZ_CHECK(std::int64_t(image.width()) * image.height() <= (std::int64_t(1) << 28));
  if (image.width() * image.height() > 4096) return;

  static const TemporaryPath temporary;
  for (const emfusion::ExrCompression compression :
       {emfusion::ExrCompression::None, emfusion::ExrCompression::Rle, emfusion::ExrCompression::Zips,
        emfusion::ExrCompression::Zip, emfusion::ExrCompression::Piz}) {
    emfusion::ExrWriteOptions options;
    options.compression = compression;
    emfusion::write_exr(temporary.path(), image, options);
    EMF_FUZZ_CHECK(same_bits(emfusion::read_exr(temporary.path()), image));
  }
}

}  // namespace fuzz_exr

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  fuzz_exr::check(data, size);
  return 0;
}
