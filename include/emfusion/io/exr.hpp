// OpenEXR depth maps, as Co-Fusion's image folders store them
// (depth/Depth%04d.exr, float metres), read and written through the OpenEXR
// library (Debian: libopenexr-dev), which decodes every compression of the
// format so that the library does not have to.
//
// read_exr reads single-part flat images, scanline or tiled (the full
// resolution level of a tiled file), compressed with any of NONE, RLE, ZIPS,
// ZIP, PIZ, PXR24, B44, B44A, DWAA and DWAB, into one float image whose
// pixel (0, 0) is the data window's top-left corner. Of the file's channels
// it takes the one named by the caller, else the only channel, else the one
// called Z, then depth (any case), then Y, then R (compared after the last
// '.', so "ViewLayer.Depth.Z" counts as Z); renderers that write depth into
// R, G and B write the same value to each. The chosen channel must be HALF
// (converted exactly) or FLOAT and not subsampled; multi-part and deep files
// are refused. Before OpenEXR sees the header, its attributes are walked to
// check that each fits in the file, the data window is bounded (1 << 20
// pixels a side, 1 << 28 in all) and tiles may not exceed the image (or 256
// pixels a side): OpenEXR allocates after those fields first and checks later.
//
// decode_exr reads a file's bytes in memory (tests/fuzz/ does).
//
// write_exr writes one FLOAT channel (default name "Z") in any of the
// compressions above, through "<path>.tmp" renamed over `path` when complete.
//
// Errors are std::runtime_error "read_exr: '<path>': <problem>" (OpenEXR's
// own exceptions on bad, truncated or corrupt files become one of these,
// their text after "OpenEXR: "); bad arguments to write_exr are
// std::invalid_argument. Built without OpenEXR (EMFUSION_HAS_OPENEXR unset:
// CMake did not find it), every read or write is a std::runtime_error naming
// the file and saying so. docs/io.md has the rules.
#pragma once

#include <algorithm>
#include <cctype>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/io/detail/failure.hpp"
#include "emfusion/io/detail/files.hpp"

#if EMFUSION_HAS_OPENEXR
#include <IexBaseExc.h>
#include <ImfChannelList.h>
#include <ImfCompression.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfIO.h>
#include <ImfInputFile.h>
#include <ImfOutputFile.h>
#include <ImfThreading.h>

#include <cerrno>
#include <cstdio>
#include <memory>
#endif

namespace emfusion {

/// Pixel-data compression of write_exr (OpenEXR's codecs; read_exr reads
/// them all). PXR24 rounds FLOAT samples to 24 bits; B44, B44A, DWAA and
/// DWAB leave FLOAT channels lossless and the depth channel written here is
/// FLOAT, so only PXR24 loses precision.
enum class ExrCompression {
  None,   ///< uncompressed
  Zips,   ///< zlib, one scanline per chunk
  Zip,    ///< zlib, 16 scanlines per chunk
  Rle,    ///< run-length coding
  Piz,    ///< wavelet and Huffman coding
  Pxr24,  ///< FLOAT rounded to 24 bits, then zlib (lossy)
  B44,    ///< 4x4 blocks of HALF samples (FLOAT stored raw)
  B44a,   ///< B44, flat blocks smaller
  Dwaa,   ///< DCT of colour channels, 32 scanlines per chunk (others zlib)
  Dwab,   ///< as DWAA, 256 scanlines per chunk
};

/// Options of write_exr.
struct ExrWriteOptions {
  ExrCompression compression = ExrCompression::Zip;
  /// Name of the single FLOAT channel (1 to 31 characters).
  std::string channel = "Z";
};

namespace detail::exr {

/// Whether this build reads and writes EXR files (OpenEXR was found).
#if EMFUSION_HAS_OPENEXR
inline constexpr bool available = true;
#else
inline constexpr bool available = false;
#endif

inline const std::string& unavailable() {
  static const std::string text =
      "this build of emfusion has no OpenEXR support (OpenEXR was not found when it was configured): "
      "install libopenexr-dev (scripts/setup-debian.sh) and rebuild";
  return text;
}

// Version field flags above its low byte (the format version).
constexpr std::uint32_t long_names_flag = 0x400;
constexpr std::uint32_t deep_flag = 0x800;
constexpr std::uint32_t multipart_flag = 0x1000;

// Pixel types of the channel list (Imf::PixelType's values).
constexpr int uint_type = 0;
constexpr int half_type = 1;
constexpr int float_type = 2;

// The reader's bounds on the data window, checked before allocating.
constexpr std::int64_t max_side = std::int64_t(1) << 20;
constexpr std::int64_t max_pixels = std::int64_t(1) << 28;

struct Channel {
  std::string name;
  int type = 0;
};

/// The part of a channel name after its last '.' ("layer.Depth.Z" -> "Z").
inline std::string base_name(const std::string& name) {
  const std::size_t dot = name.rfind('.');
  return dot == std::string::npos ? name : name.substr(dot + 1);
}

inline std::string lower(std::string text) {
  for (char& c : text) c = char(std::tolower(static_cast<unsigned char>(c)));
  return text;
}

inline std::string channel_list(const std::vector<Channel>& channels) {
  std::string text;
  for (const Channel& c : channels) text += (text.empty() ? "'" : ", '") + c.name + "'";
  return text;
}

/// Index of the channel to read: `wanted` if given, else the only one, else
/// the one whose base name is Z, depth (any case), Y or R, in that order of
/// preference. Returns a problem text in `problem` when there is no choice.
inline std::size_t choose_channel(const std::vector<Channel>& channels, const std::string& wanted,
                                  std::string& problem) {
  if (!wanted.empty()) {
    for (std::size_t k = 0; k < channels.size(); ++k)
      if (channels[k].name == wanted) return k;
    problem = "no channel '" + wanted + "' (the file has " + channel_list(channels) + ")";
    return 0;
  }
  if (channels.size() == 1) return 0;
  for (const char* key : {"Z", "depth", "Y", "R"}) {
    std::vector<std::size_t> found;
    for (std::size_t k = 0; k < channels.size(); ++k) {
      const std::string base = base_name(channels[k].name);
      if (std::string(key) == "depth" ? lower(base) == "depth" : base == key) found.push_back(k);
    }
    if (found.size() == 1) return found[0];
    if (found.size() > 1) {
      problem = "several channels could be the depth ('" + channels[found[0]].name + "', '" + channels[found[1]].name +
                "'): name the channel to read";
      return 0;
    }
  }
  problem = "cannot tell the depth channel among " + channel_list(channels) +
            ": expected one channel, or one named Z, depth, Y or R; name the channel to read";
  return 0;
}

/// The sizes that check_header read from a header.
struct HeaderBounds {
  bool has_window = false;
  std::int64_t x_min = 0, y_min = 0, x_max = 0, y_max = 0;
  bool has_tiles = false;
  std::uint32_t tile_width = 0, tile_height = 0;
};

inline std::uint32_t le_u32(const unsigned char* p) {
  return std::uint32_t(p[0]) | std::uint32_t(p[1]) << 8 | std::uint32_t(p[2]) << 16 | std::uint32_t(p[3]) << 24;
}

inline std::int32_t le_i32(const unsigned char* p) {
  const std::uint32_t v = le_u32(p);
  std::int32_t out;
  std::memcpy(&out, &v, 4);  // two's complement, without overflow
  return out;
}

/// Size of the value of OpenEXR's attribute types whose values have one
/// (which OpenEXR reads whatever the size field says), else -1.
inline int fixed_value_size(const std::string& type) {
  static const std::pair<const char*, int> sizes[] = {{"box2i", 16},      {"box2f", 16},
                                                      {"compression", 1}, {"lineOrder", 1},
                                                      {"envmap", 1},      {"deepImageState", 1},
                                                      {"float", 4},       {"double", 8},
                                                      {"int", 4},         {"v2i", 8},
                                                      {"v2f", 8},         {"v2d", 16},
                                                      {"v3i", 12},        {"v3f", 12},
                                                      {"v3d", 24},        {"m33f", 36},
                                                      {"m33d", 72},       {"m44f", 64},
                                                      {"m44d", 128},      {"chromaticities", 32},
                                                      {"keycode", 28},    {"rational", 8},
                                                      {"timecode", 8},    {"tiledesc", 9}};
  for (const auto& [name, bytes] : sizes)
    if (type == name) return bytes;
  return -1;
}

/// Whether the `n` bytes at `value` are exactly a channel list: entries
/// "name\0<16 bytes>" (names of 1 to 255 characters) and a final "\0".
inline bool exact_channel_list(const unsigned char* value, std::size_t n) {
  std::size_t p = 0;
  for (;;) {
    const void* zero = p < n ? std::memchr(value + p, 0, std::min<std::size_t>(n - p, 256)) : nullptr;
    if (!zero) return false;
    const std::size_t length = std::size_t(static_cast<const unsigned char*>(zero) - (value + p));
    p += length + 1;
    if (length == 0) return p == n;
    if (n - p < 16) return false;
    p += 16;
  }
}

/// Walks the attributes of a single-part header ("name\0type\0<int32
/// size><value>" up to an empty name) in the `size` bytes at `d`, checking
/// that each fits in the file and that the values OpenEXR reads by their
/// own layout (fixed-size types, channel lists, previews) have the size the
/// size field says, and notes the data window and the tile size. OpenEXR
/// allocates what an attribute's size field says before it reads the value,
/// reads on where a value's own layout ends (not where its size field says),
/// and sizes its tables and buffers after the data window and the tile
/// size: without this a few hostile bytes make it ask for gigabytes (the
/// fuzz target found an attribute claiming 1.7 GB in a file of 248 bytes,
/// then a channel list running past its size into a 2 GB one). Returns the
/// problem, or "" with `bounds` filled in.
inline std::string check_header(const unsigned char* d, std::size_t size, bool long_names, HeaderBounds& bounds) {
  const auto str = [](auto value) { return std::to_string(value); };
  const std::size_t longest = long_names ? 255 : 31;
  std::size_t pos = 8;
  const auto read_name = [&](const char* what, std::string& name) -> std::string {
    const std::size_t limit = std::min(size, pos + longest + 1);
    const void* end = pos < size ? std::memchr(d + pos, 0, limit - pos) : nullptr;
    if (!end) {
      if (limit == size) return std::string("truncated header: the ") + what + " at byte " + str(pos) + " is cut off";
      return std::string("corrupt header: the ") + what + " at byte " + str(pos) + " is longer than " + str(longest) +
             " characters";
    }
    name.assign(reinterpret_cast<const char*>(d + pos), static_cast<const unsigned char*>(end) - (d + pos));
    pos += name.size() + 1;
    return {};
  };
  for (;;) {
    const std::size_t start = pos;
    std::string name, type;
    if (std::string problem = read_name("attribute name", name); !problem.empty()) return problem;
    if (name.empty()) return {};
    if (std::string problem = read_name("attribute type", type); !problem.empty()) return problem;
    if (size - pos < 4) return "truncated header: attribute '" + name + "' at byte " + str(start) + " is cut off";
    const std::int32_t n = le_i32(d + pos);
    pos += 4;
    if (n < 0 || std::size_t(n) > size - pos)
      return "corrupt header: attribute '" + name + "' at byte " + str(start) + " claims " + str(n) +
             " bytes, more than the file holds";
    const unsigned char* value = d + pos;
    const std::string attribute = "corrupt header: attribute '" + name + "' at byte " + str(start) + " (type '" + type +
                                  "', " + str(n) + " bytes)";
    if (const int fixed = fixed_value_size(type); fixed >= 0 && n != fixed)
      return attribute + ": a value of this type has " + str(fixed) + " bytes";
    if (type == "chlist" && !exact_channel_list(value, std::size_t(n)))
      return attribute + ": not a channel list of that size";
    if (type == "preview" && (n < 8 || std::uint64_t(le_u32(value)) * le_u32(value + 4) * 4 != std::uint64_t(n) - 8))
      return attribute + ": not a preview image of that size";
    if (name == "dataWindow" && type == "box2i" && n == 16) {
      bounds.has_window = true;
      bounds.x_min = le_i32(value), bounds.y_min = le_i32(value + 4);
      bounds.x_max = le_i32(value + 8), bounds.y_max = le_i32(value + 12);
    }
    if (name == "tiles" && type == "tiledesc" && n == 9) {
      bounds.has_tiles = true;
      bounds.tile_width = le_u32(value), bounds.tile_height = le_u32(value + 4);
    }
    pos += std::size_t(n);
  }
}

/// The reader's bounds on a data window: "" if it is within them.
inline std::string check_window(std::int64_t x_min, std::int64_t y_min, std::int64_t x_max, std::int64_t y_max) {
  const auto str = [](auto value) { return std::to_string(value); };
  const std::int64_t width = x_max - x_min + 1, height = y_max - y_min + 1;
  if (width < 1 || height < 1)
    return "empty data window (" + str(x_min) + ", " + str(y_min) + ") - (" + str(x_max) + ", " + str(y_max) + ")";
  if (width > max_side || height > max_side || width * height > max_pixels)
    return "data window of " + str(width) + "x" + str(height) + " pixels: too large";
  return {};
}

#if EMFUSION_HAS_OPENEXR

/// Runs `action` (calls into OpenEXR) and turns whatever it throws (Iex's
/// exceptions for bad files, std::bad_alloc, ...) into the io/ error of
/// `bad`, so that callers see one kind of error naming the file.
template <class Action>
decltype(auto) guarded(const detail::io::Failure& bad, Action&& action) {
  try {
    return action();
  } catch (const std::exception& e) {
    bad(std::string("OpenEXR: ") + e.what());
  }
}

/// OpenEXR input from bytes in memory. Reads past the end throw what
/// OpenEXR's own file streams throw there (some of its recovery code
/// expects exactly that), which is how truncated files fail.
class MemoryInput final : public Imf::IStream {
 public:
  MemoryInput(const unsigned char* data, std::size_t size, const std::string& name)
      : Imf::IStream(name.c_str()), data_(data), size_(size) {}

  bool read(char c[], int n) override {
    if (n < 0 || position_ > size_ || std::uint64_t(n) > size_ - position_)
      throw Iex::InputExc("unexpected end of file (reading " + std::to_string(n) + " bytes at byte " +
                          std::to_string(position_) + " of " + std::to_string(size_) + ")");
    if (n > 0) std::memcpy(c, data_ + position_, std::size_t(n));
    position_ += std::uint64_t(n);
    return position_ < size_;
  }
  std::uint64_t tellg() override { return position_; }
  void seekg(std::uint64_t position) override { position_ = position; }
  void clear() override {}

 private:
  const unsigned char* data_;
  std::uint64_t size_;
  std::uint64_t position_ = 0;
};

/// OpenEXR output into a string, so that the file reaches the disk through
/// detail::io::AtomicFile like every other writer of io/. OpenEXR seeks back
/// to fill in its chunk offset table, hence the position.
class MemoryOutput final : public Imf::OStream {
 public:
  explicit MemoryOutput(const std::string& name) : Imf::OStream(name.c_str()) {}

  void write(const char c[], int n) override {
    if (n <= 0) return;
    const std::size_t end = std::size_t(position_) + std::size_t(n);
    if (end > bytes_.size()) bytes_.resize(end);
    std::memcpy(bytes_.data() + position_, c, std::size_t(n));
    position_ = end;
  }
  std::uint64_t tellp() override { return position_; }
  void seekp(std::uint64_t position) override { position_ = position; }
  const std::string& bytes() const { return bytes_; }

 private:
  std::string bytes_;
  std::uint64_t position_ = 0;
};

inline Imf::Compression openexr_compression(ExrCompression c) {
  switch (c) {
    case ExrCompression::None:
      return Imf::NO_COMPRESSION;
    case ExrCompression::Zips:
      return Imf::ZIPS_COMPRESSION;
    case ExrCompression::Zip:
      return Imf::ZIP_COMPRESSION;
    case ExrCompression::Rle:
      return Imf::RLE_COMPRESSION;
    case ExrCompression::Piz:
      return Imf::PIZ_COMPRESSION;
    case ExrCompression::Pxr24:
      return Imf::PXR24_COMPRESSION;
    case ExrCompression::B44:
      return Imf::B44_COMPRESSION;
    case ExrCompression::B44a:
      return Imf::B44A_COMPRESSION;
    case ExrCompression::Dwaa:
      return Imf::DWAA_COMPRESSION;
    case ExrCompression::Dwab:
      return Imf::DWAB_COMPRESSION;
  }
  return Imf::NUM_COMPRESSION_METHODS;
}

#endif  // EMFUSION_HAS_OPENEXR

}  // namespace detail::exr

/// read_exr (below) of an OpenEXR file's `size` bytes in memory; `name`
/// stands for the file in error messages ("read_exr: '<name>': ...").
inline Image<float, Host> decode_exr(const void* data, std::size_t size, const std::string& name,
                                     const std::string& channel = {}) {
  const detail::io::Failure bad{"read_exr", name};
#if EMFUSION_HAS_OPENEXR
  namespace exr = detail::exr;
  const auto* d = static_cast<const unsigned char*>(data);
  const auto str = [](auto value) { return std::to_string(value); };

  // OpenEXR's messages for these say less (or, for deep data, only that the
  // image is not "flat"), so they are told apart first from the first bytes.
  if (size < 8) bad("not an OpenEXR file (only " + str(size) + " bytes)");
  if (std::memcmp(d, "\x76\x2f\x31\x01", 4) != 0) bad("not an OpenEXR file (wrong magic number)");
  const std::uint32_t version =
      std::uint32_t(d[4]) | std::uint32_t(d[5]) << 8 | std::uint32_t(d[6]) << 16 | std::uint32_t(d[7]) << 24;
  if (version & exr::multipart_flag) bad("unsupported feature: multi-part file (only single-part images)");
  if (version & exr::deep_flag) bad("unsupported feature: deep data (only flat images)");
  exr::HeaderBounds bounds;
  if (std::string problem = exr::check_header(d, size, version & exr::long_names_flag, bounds); !problem.empty())
    bad(problem);
  if (bounds.has_window) {
    if (std::string problem = exr::check_window(bounds.x_min, bounds.y_min, bounds.x_max, bounds.y_max);
        !problem.empty())
      bad(problem);
    // A tile larger than the image (or than 256 pixels a side) serves no
    // purpose but to make OpenEXR allocate its buffers.
    const std::int64_t width = bounds.x_max - bounds.x_min + 1, height = bounds.y_max - bounds.y_min + 1;
    if (bounds.has_tiles && (bounds.tile_width > std::max<std::int64_t>(width, 256) ||
                             bounds.tile_height > std::max<std::int64_t>(height, 256)))
      bad("tiles of " + str(bounds.tile_width) + "x" + str(bounds.tile_height) + " pixels for an image of " +
          str(width) + "x" + str(height) + ": too large");
  }

  exr::MemoryInput stream(d, size, name);
  const std::unique_ptr<Imf::InputFile> file =
      exr::guarded(bad, [&] { return std::make_unique<Imf::InputFile>(stream, Imf::globalThreadCount()); });
  const Imf::Header& header = file->header();

  const Imath::Box2i window = header.dataWindow();
  const std::int64_t x_min = window.min.x, y_min = window.min.y, x_max = window.max.x, y_max = window.max.y;
  if (std::string problem = exr::check_window(x_min, y_min, x_max, y_max); !problem.empty()) bad(problem);
  const int width = int(x_max - x_min + 1), height = int(y_max - y_min + 1);

  std::vector<exr::Channel> channels;
  std::vector<std::pair<int, int>> sampling;
  for (auto it = header.channels().begin(); it != header.channels().end(); ++it) {
    channels.push_back({it.name(), int(it.channel().type)});
    sampling.emplace_back(it.channel().xSampling, it.channel().ySampling);
  }
  if (channels.empty()) bad("the image has no channels");
  std::string problem;
  const std::size_t chosen = exr::choose_channel(channels, channel, problem);
  if (!problem.empty()) bad(problem);
  const exr::Channel& source = channels[chosen];
  if (source.type == exr::uint_type)
    bad("unsupported feature: channel '" + source.name + "' has pixel type UINT (only HALF and FLOAT are read)");
  if (source.type != exr::half_type && source.type != exr::float_type)
    bad("channel '" + source.name + "' has unknown pixel type " + str(source.type));
  if (sampling[chosen] != std::pair<int, int>(1, 1))
    bad("unsupported feature: subsampled channel '" + source.name + "' (sampling " + str(sampling[chosen].first) +
        " x " + str(sampling[chosen].second) + ")");

  Image<float, Host> image(width, height);
  exr::guarded(bad, [&] {
    Imf::FrameBuffer frame;
    // OpenEXR converts HALF samples to FLOAT as it fills the slice.
    frame.insert(source.name, Imf::Slice::Make(Imf::FLOAT, image.view().data, window, sizeof(float),
                                               sizeof(float) * std::size_t(width)));
    file->setFrameBuffer(frame);
    file->readPixels(window.min.y, window.max.y);
  });
  return image;
#else
  (void)data, (void)size, (void)channel;
  bad(detail::exr::unavailable());
#endif
}

/// Reads a single-channel float image from an OpenEXR file (see the top of
/// this header for what is supported). `channel` names the channel to read;
/// empty chooses it as described there. Pixel (0, 0) is the data window's
/// top-left corner.
inline Image<float, Host> read_exr(const std::string& path, const std::string& channel = {}) {
  if (!detail::exr::available) detail::io::fail("read_exr", path, detail::exr::unavailable());
  const std::string file = detail::io::read_file(path, "read_exr");
  return decode_exr(file.data(), file.size(), path, channel);
}

/// Writes `image` as a single-part scanline OpenEXR file with one FLOAT
/// channel (options.channel), compressed as options.compression says.
/// Throws std::invalid_argument for an empty image, a bad channel name or an
/// unknown compression, std::runtime_error if the file cannot be written
/// (or this build has no OpenEXR).
inline void write_exr(const std::string& path, const Image<float, Host>& image, const ExrWriteOptions& options = {}) {
  constexpr const char* where = "write_exr";
  const auto invalid = [&](const std::string& problem) {
    throw std::invalid_argument(std::string(where) + ": " + detail::io::quoted(path) + ": " + problem);
  };
  if (image.empty()) invalid("the image is empty");
  if (options.channel.empty() || options.channel.size() > 31 || options.channel.find('\0') != std::string::npos)
    invalid("the channel name must have 1 to 31 characters and no NUL, got '" + options.channel + "'");
#if EMFUSION_HAS_OPENEXR
  namespace exr = detail::exr;
  const Imf::Compression compression = exr::openexr_compression(options.compression);
  if (compression == Imf::NUM_COMPRESSION_METHODS) invalid("unknown ExrCompression value");
  const detail::io::Failure bad{where, path};
  const int width = image.width(), height = image.height();

  exr::MemoryOutput stream(path);
  exr::guarded(bad, [&] {
    Imf::Header header(width, height);
    header.compression() = compression;
    header.channels().insert(options.channel, Imf::Channel(Imf::FLOAT));
    // The chunk offset table is written when the file is destroyed: the
    // bytes are complete only after this scope.
    Imf::OutputFile file(stream, header, Imf::globalThreadCount());
    Imf::FrameBuffer frame;
    // OpenEXR only reads through the pointer when writing.
    frame.insert(options.channel, Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(const_cast<float*>(image.view().data)),
                                             sizeof(float), sizeof(float) * std::size_t(width)));
    file.setFrameBuffer(frame);
    file.writePixels(height);
  });

  detail::io::AtomicFile target(where, path);
  errno = 0;
  const std::string& out = stream.bytes();
  const bool written = std::fwrite(out.data(), 1, out.size(), target.get()) == out.size();
  target.commit(written ? "" : detail::io::errno_text(errno));
#else
  detail::io::fail(where, path, detail::exr::unavailable());
#endif
}

}  // namespace emfusion
