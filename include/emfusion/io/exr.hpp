// A minimal OpenEXR reader and writer for single-channel float depth maps,
// as Co-Fusion's image folders store them (depth/Depth%04d.exr, metres), with
// no dependency beyond zlib.
//
// read_exr reads single-part scanline images whose pixel data are
// uncompressed (NONE) or zlib-compressed (ZIPS: one scanline per chunk, ZIP:
// 16), channels of pixel type HALF or FLOAT, any data window. From the
// channels it takes the one named by the caller, else the only channel,
// else the one called Z, then depth (any case), then Y, then R (compared
// after the last '.', so "ViewLayer.Depth.Z" counts as Z); renderers that
// write depth into R, G and B write the same value to each. Everything else
// (tiled, multi-part or deep files, RLE, PIZ, PXR24, B44, DWA compression,
// UINT samples in the chosen channel, subsampled channels) is an error
// naming the unsupported feature. Every offset and size in the file is
// checked against the file's size before it is used.
//
// decode_exr reads a file's bytes in memory (tests/fuzz/ does).
//
// write_exr writes one FLOAT channel (default name "Z") with NONE, ZIPS or
// ZIP compression, through "<path>.tmp" renamed over `path` when complete.
//
// Errors are std::runtime_error "read_exr: '<path>': <problem>", with the
// chunk and its byte offset for bad pixel data; bad arguments to write_exr
// are std::invalid_argument. docs/io.md has the rules.
#pragma once

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/io/detail/bytes.hpp"
#include "emfusion/io/detail/failure.hpp"
#include "emfusion/io/detail/files.hpp"
#include "emfusion/io/detail/zlib.hpp"

namespace emfusion {

/// Pixel-data compression of write_exr (the subset that read_exr reads).
enum class ExrCompression {
  None,  ///< uncompressed scanlines
  Zips,  ///< zlib, one scanline per chunk
  Zip,   ///< zlib, 16 scanlines per chunk
};

/// Options of write_exr.
struct ExrWriteOptions {
  ExrCompression compression = ExrCompression::Zip;
  /// Name of the single FLOAT channel (1 to 31 characters).
  std::string channel = "Z";
};

namespace detail::exr {

constexpr std::uint32_t magic = 20000630;  // bytes 76 2f 31 01
constexpr std::uint32_t version = 2;
// Flags in the version field above its low byte.
constexpr std::uint32_t tiled_flag = 0x200;
constexpr std::uint32_t long_names_flag = 0x400;
constexpr std::uint32_t deep_flag = 0x800;
constexpr std::uint32_t multipart_flag = 0x1000;

// Compression codes of the 'compression' attribute.
constexpr unsigned no_compression = 0;
constexpr unsigned zips_compression = 2;
constexpr unsigned zip_compression = 3;

// Pixel types of the channel list.
constexpr int uint_type = 0;
constexpr int half_type = 1;
constexpr int float_type = 2;

inline std::string compression_name(unsigned code) {
  static constexpr const char* names[] = {"NONE", "RLE", "ZIPS", "ZIP", "PIZ", "PXR24", "B44", "B44A", "DWAA", "DWAB"};
  return code < 10 ? names[code] : "unknown (code " + std::to_string(code) + ")";
}

inline unsigned compression_code(ExrCompression c) {
  switch (c) {
    case ExrCompression::None:
      return no_compression;
    case ExrCompression::Zips:
      return zips_compression;
    case ExrCompression::Zip:
      return zip_compression;
  }
  return 255;
}

inline int lines_per_chunk(unsigned compression) { return compression == zip_compression ? 16 : 1; }

inline const char* type_name(int type) {
  return type == uint_type ? "UINT" : type == half_type ? "HALF" : type == float_type ? "FLOAT" : "unknown";
}

struct Channel {
  std::string name;
  int type = 0;
};

/// The zlib codecs store a block's bytes reordered (first every even byte,
/// then every odd one) and delta-coded (each byte minus its predecessor,
/// plus 128, modulo 256), which makes float data compress better. This
/// undoes both, from `coded` into `raw`.
inline void decode_zip_block(std::vector<unsigned char>& coded, unsigned char* raw) {
  const std::size_t n = coded.size();
  for (std::size_t k = 1; k < n; ++k) coded[k] = static_cast<unsigned char>(coded[k - 1] + coded[k] - 128);
  const std::size_t half = (n + 1) / 2;
  for (std::size_t k = 0; k < n; ++k) raw[k] = (k % 2 == 0) ? coded[k / 2] : coded[half + k / 2];
}

/// The reordering and delta coding of decode_zip_block, forwards.
inline std::vector<unsigned char> encode_zip_block(const unsigned char* raw, std::size_t n) {
  std::vector<unsigned char> coded(n);
  const std::size_t half = (n + 1) / 2;
  for (std::size_t k = 0; k < n; ++k) coded[k % 2 == 0 ? k / 2 : half + k / 2] = raw[k];
  for (std::size_t k = n; k-- > 1;) coded[k] = static_cast<unsigned char>(coded[k] - coded[k - 1] + 128);
  return coded;
}

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

inline void put_attribute(std::string& out, const char* name, const char* type, const std::string& value) {
  out += name;
  out.push_back('\0');
  out += type;
  out.push_back('\0');
  bytes::put_i32(out, std::int32_t(value.size()));
  out += value;
}

}  // namespace detail::exr

/// read_exr (below) of an OpenEXR file's `size` bytes in memory; `name`
/// stands for the file in error messages ("read_exr: '<name>': ...").
inline Image<float, Host> decode_exr(const void* data, std::size_t size, const std::string& name,
                                     const std::string& channel = {}) {
  namespace exr = detail::exr;
  namespace bytes = detail::bytes;
  constexpr const char* where = "read_exr";
  const auto* d = static_cast<const unsigned char*>(data);
  const detail::io::Failure bad{where, name};
  const auto str = [](auto value) { return std::to_string(value); };

  if (size < 8) bad("not an OpenEXR file (only " + str(size) + " bytes)");
  if (bytes::u32(d) != exr::magic) bad("not an OpenEXR file (wrong magic number)");
  const std::uint32_t version = bytes::u32(d + 4);
  if ((version & 0xff) != exr::version)
    bad("unsupported OpenEXR file format version " + str(version & 0xff) + " (2 expected)");
  if (version & exr::multipart_flag) bad("unsupported feature: multi-part file (only single-part scanline images)");
  if (version & exr::deep_flag) bad("unsupported feature: deep data (only flat scanline images)");
  if (version & exr::tiled_flag) bad("unsupported feature: tiled image (only scanline images)");
  if (version & ~std::uint32_t(0xff | exr::long_names_flag)) {
    char text[16];
    std::snprintf(text, sizeof(text), "0x%x", unsigned(version & ~0xffu));
    bad(std::string("unknown version flags ") + text);
  }

  // The header: attributes "name\0type\0<int32 size><value>" until an empty name.
  struct Attribute {
    std::string type;
    std::size_t offset = 0, size = 0;
  };
  std::map<std::string, Attribute> attributes;
  std::size_t pos = 8;
  const auto read_name = [&](const char* what) {
    const std::size_t limit = std::min(size, pos + 256);
    const void* end = pos < size ? std::memchr(d + pos, 0, limit - pos) : nullptr;
    if (!end) {
      if (limit == size) bad(std::string("truncated header: the ") + what + " at byte " + str(pos) + " is cut off");
      bad(std::string("corrupt header: the ") + what + " at byte " + str(pos) + " is longer than 255 characters");
    }
    std::string name(reinterpret_cast<const char*>(d + pos), static_cast<const unsigned char*>(end) - (d + pos));
    pos += name.size() + 1;
    return name;
  };
  for (;;) {
    const std::size_t start = pos;
    std::string name = read_name("attribute name");
    if (name.empty()) break;
    Attribute a;
    a.type = read_name("attribute type");
    if (size - pos < 4) bad("truncated header: attribute '" + name + "' at byte " + str(start) + " is cut off");
    const std::int32_t n = bytes::i32(d + pos);
    pos += 4;
    if (n < 0 || std::size_t(n) > size - pos)
      bad("truncated header: attribute '" + name + "' at byte " + str(start) + " has " + str(n) +
          " bytes, more than the file holds");
    a.offset = pos, a.size = std::size_t(n);
    pos += a.size;
    if (attributes.count(name)) bad("corrupt header: attribute '" + name + "' appears twice");
    attributes.emplace(std::move(name), std::move(a));
  }
  const std::size_t header_end = pos;

  const auto attribute = [&](const char* name, const char* type, std::size_t exact) -> const Attribute& {
    const auto it = attributes.find(name);
    if (it == attributes.end()) bad(std::string("the header has no '") + name + "' attribute");
    if (it->second.type != type)
      bad(std::string("attribute '") + name + "' has type '" + it->second.type + "', expected '" + type + "'");
    if (exact != 0 && it->second.size != exact)
      bad(std::string("attribute '") + name + "' has " + str(it->second.size) + " bytes, expected " + str(exact));
    return it->second;
  };
  if (const auto it = attributes.find("type"); it != attributes.end()) {
    std::string type(reinterpret_cast<const char*>(d + it->second.offset), it->second.size);
    type = type.substr(0, type.find('\0'));
    if (type != "scanlineimage") bad("unsupported feature: part type '" + type + "' (only scanline images)");
  }
  if (attributes.count("tiles")) bad("unsupported feature: tiled image (only scanline images)");

  const unsigned compression = d[attribute("compression", "compression", 1).offset];
  if (compression != exr::no_compression && compression != exr::zips_compression && compression != exr::zip_compression)
    bad("unsupported feature: " + exr::compression_name(compression) +
        " compression (only NONE, ZIPS and ZIP are read)");

  const Attribute& window = attribute("dataWindow", "box2i", 16);
  const std::int64_t x_min = bytes::i32(d + window.offset), y_min = bytes::i32(d + window.offset + 4);
  const std::int64_t x_max = bytes::i32(d + window.offset + 8), y_max = bytes::i32(d + window.offset + 12);
  const std::int64_t width64 = x_max - x_min + 1, height64 = y_max - y_min + 1;
  if (width64 < 1 || height64 < 1)
    bad("empty data window (" + str(x_min) + ", " + str(y_min) + ") - (" + str(x_max) + ", " + str(y_max) + ")");
  if (width64 > (1 << 20) || height64 > (1 << 20) || width64 * height64 > (std::int64_t(1) << 28))
    bad("data window of " + str(width64) + "x" + str(height64) + " pixels: too large");
  const int width = int(width64), height = int(height64);

  // The channel list: "name\0<int32 type><u8 pLinear><3 reserved><int32 xs><int32 ys>" until an empty name.
  const Attribute& list = attribute("channels", "chlist", 0);
  std::vector<exr::Channel> channels;
  for (std::size_t p = list.offset, end = list.offset + list.size;;) {
    const void* zero = p < end ? std::memchr(d + p, 0, end - p) : nullptr;
    if (!zero) bad("corrupt header: the channel list is cut off");
    exr::Channel c;
    c.name.assign(reinterpret_cast<const char*>(d + p), static_cast<const unsigned char*>(zero) - (d + p));
    p += c.name.size() + 1;
    if (c.name.empty()) break;
    if (end - p < 16) bad("corrupt header: the channel list entry of '" + c.name + "' is cut off");
    c.type = bytes::i32(d + p);
    const std::int32_t x_sampling = bytes::i32(d + p + 8), y_sampling = bytes::i32(d + p + 12);
    p += 16;
    if (c.type != exr::uint_type && c.type != exr::half_type && c.type != exr::float_type)
      bad("channel '" + c.name + "' has unknown pixel type " + str(c.type));
    if (x_sampling != 1 || y_sampling != 1)
      bad("unsupported feature: subsampled channel '" + c.name + "' (sampling " + str(x_sampling) + " x " +
          str(y_sampling) + ")");
    channels.push_back(std::move(c));
  }
  if (channels.empty()) bad("the image has no channels");
  std::string problem;
  const std::size_t chosen = exr::choose_channel(channels, channel, problem);
  if (!problem.empty()) bad(problem);
  const exr::Channel& source = channels[chosen];
  if (source.type == exr::uint_type)
    bad("unsupported feature: channel '" + source.name + "' has pixel type UINT (only HALF and FLOAT are read)");

  // Within a scanline the channels follow one another in list order, each
  // with `width` samples.
  std::size_t line_bytes = 0, channel_offset = 0;
  for (std::size_t k = 0; k < channels.size(); ++k) {
    if (k == chosen) channel_offset = line_bytes;
    line_bytes += std::size_t(width) * (channels[k].type == exr::half_type ? 2 : 4);
  }
  const int chunk_lines = exr::lines_per_chunk(compression);
  const std::size_t chunks = std::size_t((height + chunk_lines - 1) / chunk_lines);
  // zlib cannot compress by much more than 1032:1: a header that promises
  // more pixels than that is corrupt (and must not make us allocate them).
  const double most = compression == exr::no_compression ? double(size) : 1100.0 * double(size);
  if (double(line_bytes) * height > most)
    bad("the header promises " + str(width) + "x" + str(height) + " pixels in " + str(channels.size()) +
        " channels, more than the file's " + str(size) + " bytes can hold");
  if ((size - header_end) / 8 < chunks)
    bad("truncated file: the chunk offset table at byte " + str(header_end) + " needs " + str(chunks) +
        " entries of 8 bytes");
  const std::size_t table_end = header_end + 8 * chunks;

  Image<float, Host> image(width, height);
  const ImageView<float> out = image.view();
  std::vector<unsigned char> coded, block;
  for (std::size_t b = 0; b < chunks; ++b) {
    const std::uint64_t offset = bytes::u64(d + header_end + 8 * b);
    const std::string chunk = "chunk " + str(b) + " (byte offset " + str(offset) + ")";
    if (offset < table_end || offset >= size || size - offset < 8)
      bad(chunk + ": the offset lies outside the pixel data (the file has " + str(size) + " bytes)");
    const std::int64_t first_line = std::int64_t(b) * chunk_lines;
    const std::int32_t y = bytes::i32(d + offset);
    if (y != y_min + first_line)
      bad(chunk + ": starts at scanline y = " + str(y) + ", expected " + str(y_min + first_line));
    const std::int32_t n = bytes::i32(d + offset + 4);
    if (n < 0 || std::uint64_t(n) > size - offset - 8)
      bad(chunk + ": its " + str(n) + " bytes of data run past the end of the file (truncated?)");
    const int lines = int(std::min<std::int64_t>(chunk_lines, height - first_line));
    const std::size_t expected = std::size_t(lines) * line_bytes;
    const unsigned char* pixels = d + offset + 8;
    // A chunk that would not shrink is stored uncompressed, whatever the
    // file's compression: its size then equals the raw size.
    if (std::size_t(n) != expected) {
      if (compression == exr::no_compression)
        bad(chunk + ": " + str(n) + " bytes of uncompressed data, expected " + str(expected));
      if (std::size_t(n) > expected)
        bad(chunk + ": " + str(n) + " bytes of compressed data, more than the " + str(expected) +
            " bytes of its pixels");
      problem = detail::zlib::inflate_exact(pixels, std::size_t(n), expected, coded);
      if (!problem.empty()) bad(chunk + ": " + problem);
      block.resize(expected);
      exr::decode_zip_block(coded, block.data());
      pixels = block.data();
    }
    for (int l = 0; l < lines; ++l) {
      const unsigned char* row = pixels + std::size_t(l) * line_bytes + channel_offset;
      float* target = &out(0, int(first_line) + l);
      if (source.type == exr::half_type)
        for (int x = 0; x < width; ++x) target[x] = bytes::half_to_float(bytes::u16(row + 2 * std::size_t(x)));
      else
        for (int x = 0; x < width; ++x) target[x] = bytes::f32(row + 4 * std::size_t(x));
    }
  }
  return image;
}

/// Reads a single-channel float image from an OpenEXR file (see the top of
/// this header for what is supported). `channel` names the channel to read;
/// empty chooses it as described there. Pixel (0, 0) is the data window's
/// top-left corner.
inline Image<float, Host> read_exr(const std::string& path, const std::string& channel = {}) {
  const std::string file = detail::io::read_file(path, "read_exr");
  return decode_exr(file.data(), file.size(), path, channel);
}

/// Writes `image` as a single-part scanline OpenEXR file with one FLOAT
/// channel (options.channel), compressed as options.compression says (a
/// chunk that zlib would not shrink is stored raw, as the format allows).
/// Throws std::invalid_argument for an empty image or a bad channel name,
/// std::runtime_error if the file cannot be written.
inline void write_exr(const std::string& path, const Image<float, Host>& image, const ExrWriteOptions& options = {}) {
  namespace exr = detail::exr;
  namespace bytes = detail::bytes;
  constexpr const char* where = "write_exr";
  const auto invalid = [&](const std::string& problem) {
    throw std::invalid_argument(std::string(where) + ": " + detail::io::quoted(path) + ": " + problem);
  };
  if (image.empty()) invalid("the image is empty");
  if (options.channel.empty() || options.channel.size() > 31 || options.channel.find('\0') != std::string::npos)
    invalid("the channel name must have 1 to 31 characters and no NUL, got '" + options.channel + "'");
  const unsigned compression = exr::compression_code(options.compression);
  if (compression > exr::zip_compression) invalid("unknown ExrCompression value");
  const int width = image.width(), height = image.height();

  std::string out;
  bytes::put_u32(out, exr::magic);
  bytes::put_u32(out, exr::version);
  {
    std::string value = options.channel;
    value.push_back('\0');
    bytes::put_i32(value, exr::float_type);
    bytes::put_u32(value, 0);  // pLinear 0 and three reserved bytes
    bytes::put_i32(value, 1);  // x sampling
    bytes::put_i32(value, 1);  // y sampling
    value.push_back('\0');     // end of the list
    exr::put_attribute(out, "channels", "chlist", value);
  }
  exr::put_attribute(out, "compression", "compression", std::string(1, char(compression)));
  std::string box;
  for (const int v : {0, 0, width - 1, height - 1}) bytes::put_i32(box, v);
  exr::put_attribute(out, "dataWindow", "box2i", box);
  exr::put_attribute(out, "displayWindow", "box2i", box);
  exr::put_attribute(out, "lineOrder", "lineOrder", std::string(1, '\0'));  // INCREASING_Y
  std::string value;
  bytes::put_f32(value, 1.f);
  exr::put_attribute(out, "pixelAspectRatio", "float", value);
  value.clear();
  bytes::put_f32(value, 0.f);
  bytes::put_f32(value, 0.f);
  exr::put_attribute(out, "screenWindowCenter", "v2f", value);
  value.clear();
  bytes::put_f32(value, 1.f);
  exr::put_attribute(out, "screenWindowWidth", "float", value);
  out.push_back('\0');  // end of the header

  const int chunk_lines = exr::lines_per_chunk(compression);
  const std::size_t chunks = std::size_t((height + chunk_lines - 1) / chunk_lines);
  const std::size_t table = out.size();
  out.append(8 * chunks, '\0');
  const ImageView<const float> in = image.view();
  std::string raw;
  for (std::size_t b = 0; b < chunks; ++b) {
    const int first_line = int(b) * chunk_lines;
    const int lines = std::min(chunk_lines, height - first_line);
    raw.clear();
    for (int k = 0; k < lines * width; ++k) bytes::put_f32(raw, in[first_line * width + k]);
    bytes::set_u64(out, table + 8 * b, out.size());
    bytes::put_i32(out, first_line);
    const auto* raw_bytes = reinterpret_cast<const unsigned char*>(raw.data());
    if (compression != exr::no_compression) {
      const std::vector<unsigned char> coded = exr::encode_zip_block(raw_bytes, raw.size());
      const std::vector<unsigned char> packed = detail::zlib::deflate(coded.data(), coded.size());
      if (packed.size() < raw.size()) {
        bytes::put_i32(out, std::int32_t(packed.size()));
        out.append(reinterpret_cast<const char*>(packed.data()), packed.size());
        continue;
      }
    }
    bytes::put_i32(out, std::int32_t(raw.size()));
    out += raw;
  }

  detail::io::AtomicFile target(where, path);
  errno = 0;
  const bool written = std::fwrite(out.data(), 1, out.size(), target.get()) == out.size();
  target.commit(written ? "" : detail::io::errno_text(errno));
}

}  // namespace emfusion
