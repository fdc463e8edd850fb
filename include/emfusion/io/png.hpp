// Reading and writing PNG images through libpng, without OpenCV: single-
// channel ones (depth maps, instance-label masks) and 8-bit colour ones
// (colour frames, the pictures of io/pictures.hpp).
//
// read_png_u16 reads 16-bit grayscale PNGs, and also 8-bit (or 1/2/4-bit)
// grayscale ones, whose values it widens unchanged (a label 7 stays 7; it is
// not rescaled to 16 bits): instance masks come in either depth, and callers
// that need 16 bits (depth images) check that themselves, as TumSequence does.
// read_png_u8 reads 8-bit (or 1/2/4-bit, values unchanged) grayscale PNGs and
// rejects 16-bit ones rather than drop their low byte. Colour, palette and
// alpha PNGs are rejected by these two: there is no silent conversion to gray.
//
// decode_png_u16 and decode_png_u8 do the same from bytes in memory.
//
// read_png_rgb (and decode_png_rgb, from bytes in memory) reads any 8-bit
// (or 1/2/4-bit) PNG as colour: RGB as stored, palette entries looked up,
// gray replicated to r = g = b (1/2/4-bit gray scaled to 0..255, so a 1-bit
// white is 255), alpha and tRNS transparency dropped (the colour samples are
// kept as stored, not blended over anything). 16-bit PNGs are rejected, not
// scaled: colour frames are 8-bit, and a 16-bit file there is almost always
// a depth image passed by mistake.
//
// write_png writes 8- or 16-bit grayscale, or 8-bit RGB, non-interlaced.
// Like write_ply it writes "<path>.tmp" and renames it over `path` only once
// it is complete.
//
// Errors are std::runtime_error "read_png: '<path>': <problem>" (or
// "write_png: ..."): a file that cannot be opened, a file that is not a PNG,
// corrupt or truncated data, the wrong bit depth or channel count. libpng
// reports errors by longjmp; every libpng call that can fail runs inside a
// small function that holds only trivially destructible locals and turns the
// longjmp into a return value, and the libpng structures are freed by a guard
// outside it, so a bad file neither leaks nor skips a C++ destructor.
#pragma once

#include <bit>
#include <cerrno>
#include <csetjmp>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <type_traits>
#include <vector>

#include <png.h>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/io/colour.hpp"
#include "emfusion/io/detail/files.hpp"

namespace emfusion {

namespace detail::png {

using io::errno_text;
using io::fail;
using io::File;
using io::quoted;

/// What the libpng callbacks share with the reader: the file's bytes and
/// room for libpng's error message. Trivially destructible on purpose.
struct Context {
  const unsigned char* data = nullptr;
  std::size_t size = 0;
  std::size_t offset = 0;
  char message[256] = {};
};

/// libpng's error callback: keep the message, then jump back to the setjmp
/// of the stage function that made the failing call.
[[noreturn]] inline void on_error(png_structp png, png_const_charp message) {
  auto* context = static_cast<Context*>(png_get_error_ptr(png));
  if (context) std::snprintf(context->message, sizeof(context->message), "%s", message ? message : "unknown error");
  png_longjmp(png, 1);
}

/// Warnings (unknown colour profiles and the like) do not stop a read.
inline void on_warning(png_structp, png_const_charp) {}

inline void read_from_memory(png_structp png, png_bytep out, std::size_t count) {
  auto* context = static_cast<Context*>(png_get_io_ptr(png));
  if (context->size - context->offset < count) png_error(png, "unexpected end of file (the file is truncated)");
  std::memcpy(out, context->data + context->offset, count);
  context->offset += count;
}

struct Header {
  png_uint_32 width = 0, height = 0;
  int bit_depth = 0, color_type = 0, interlace = 0;
  std::size_t row_bytes = 0;  // after the transformations
};

// The stage functions below call libpng between a setjmp and its possible
// longjmp. They hold no locals with destructors and touch no local after the
// jump, which is what makes the longjmp well defined in C++.

/// Reads the header, sets up the transformations (1/2/4-bit samples to one
/// byte each, values kept; 16-bit samples in host byte order) and reports
/// the row size they give.
inline bool read_header(png_structp png, png_infop info, Header* header) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_read_info(png, info);
  png_get_IHDR(png, info, &header->width, &header->height, &header->bit_depth, &header->color_type, &header->interlace,
               nullptr, nullptr);
  png_set_packing(png);
  // PNG stores 16-bit samples big-endian.
  if constexpr (std::endian::native == std::endian::little) png_set_swap(png);
  png_set_interlace_handling(png);
  png_read_update_info(png, info);
  header->row_bytes = png_get_rowbytes(png, info);
  return true;
}

/// Reads the header and, for files of 8 bits or fewer, sets up the
/// transformations to 8-bit RGB: palette to RGB, 1/2/4-bit gray scaled to
/// 8 bits, gray to RGB, alpha stripped (tRNS is ignored: libpng expands it
/// to alpha along with a palette, and that alpha is stripped too). 16-bit
/// files get no transformation; the caller rejects them.
inline bool read_header_rgb(png_structp png, png_infop info, Header* header) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_read_info(png, info);
  png_get_IHDR(png, info, &header->width, &header->height, &header->bit_depth, &header->color_type, &header->interlace,
               nullptr, nullptr);
  if (header->bit_depth > 8) return true;
  if (header->color_type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
  if (header->color_type == PNG_COLOR_TYPE_GRAY && header->bit_depth < 8) png_set_expand_gray_1_2_4_to_8(png);
  if (header->color_type == PNG_COLOR_TYPE_GRAY || header->color_type == PNG_COLOR_TYPE_GRAY_ALPHA)
    png_set_gray_to_rgb(png);
  if ((header->color_type & PNG_COLOR_MASK_ALPHA) ||
      (header->color_type == PNG_COLOR_TYPE_PALETTE && png_get_valid(png, info, PNG_INFO_tRNS)))
    png_set_strip_alpha(png);
  png_set_interlace_handling(png);
  png_read_update_info(png, info);
  header->row_bytes = png_get_rowbytes(png, info);
  return true;
}

inline bool read_rows(png_structp png, png_bytepp rows) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_read_image(png, rows);
  png_read_end(png, nullptr);
  return true;
}

inline bool write_rows(png_structp png, png_infop info, std::FILE* file, png_uint_32 width, png_uint_32 height,
                       int bit_depth, int color_type, png_bytepp rows) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_init_io(png, file);
  png_set_IHDR(png, info, width, height, bit_depth, color_type, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
               PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  if (bit_depth == 16 && std::endian::native == std::endian::little) png_set_swap(png);
  png_write_image(png, rows);  // libpng copies each row before swapping: `rows` stays as it was
  png_write_end(png, nullptr);
  return true;
}

struct ReadStructs {
  png_structp png = nullptr;
  png_infop info = nullptr;
  ReadStructs() = default;
  ReadStructs(const ReadStructs&) = delete;
  ReadStructs& operator=(const ReadStructs&) = delete;
  ~ReadStructs() {
    if (png) png_destroy_read_struct(&png, &info, nullptr);
  }
};

struct WriteStructs {
  png_structp png = nullptr;
  png_infop info = nullptr;
  WriteStructs() = default;
  WriteStructs(const WriteStructs&) = delete;
  WriteStructs& operator=(const WriteStructs&) = delete;
  ~WriteStructs() {
    if (png) png_destroy_write_struct(&png, &info);
  }
};

inline std::string color_type_name(int color_type) {
  switch (color_type) {
    case PNG_COLOR_TYPE_GRAY:
      return "grayscale";
    case PNG_COLOR_TYPE_GRAY_ALPHA:
      return "grayscale+alpha (2 channels)";
    case PNG_COLOR_TYPE_RGB:
      return "RGB (3 channels)";
    case PNG_COLOR_TYPE_RGB_ALPHA:
      return "RGBA (4 channels)";
    case PNG_COLOR_TYPE_PALETTE:
      return "palette (colour-mapped)";
  }
  return "colour type " + std::to_string(color_type);
}

/// Checks the signature of the `size` bytes at `data` (a PNG file named
/// `path` in messages) and sets up `s` to read them through `context`.
inline void start_read(const unsigned char* data, std::size_t size, const std::string& path, Context& context,
                       ReadStructs& s) {
  constexpr const char* where = "read_png";
  if (size < 8 || png_sig_cmp(data, 0, 8) != 0)
    fail(where, path, size == 0 ? "not a PNG file (the file is empty)" : "not a PNG file (bad signature)");
  context.data = data;
  context.size = size;
  s.png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &context, on_error, on_warning);
  if (s.png) s.info = png_create_info_struct(s.png);
  if (!s.png || !s.info) fail(where, path, "cannot initialise libpng (out of memory or a libpng version mismatch)");
  png_set_read_fn(s.png, &context, read_from_memory);
}

/// Throws for a header whose size cannot be stored in `file_size` bytes or
/// does not fit an Image.
inline void check_size(const Header& header, std::size_t file_size, const std::string& path) {
  constexpr const char* where = "read_png";
  const std::size_t width = header.width, height = header.height;
  // Deflate compresses at most about 1032:1: a header that promises more
  // pixels than the file could hold is corrupt, and must not make us
  // allocate gigabytes.
  if (height * (header.row_bytes + 1) > 1100 * file_size + 4096)
    fail(where, path,
         "corrupt header: a " + std::to_string(width) + "x" + std::to_string(height) + " image cannot be stored in " +
             std::to_string(file_size) + " bytes");
  if (width == 0 || height == 0 || width * height > std::size_t(INT32_MAX))
    fail(where, path, "unsupported image size " + std::to_string(width) + "x" + std::to_string(height));
}

/// Reads a grayscale PNG into an image of T (std::uint8_t or std::uint16_t).
/// A 16-bit T also takes files of 8 bits or fewer when `allow_narrower`,
/// values unchanged.
/// The `size` bytes at `data` are the PNG; `path` names it in messages.
template <class T>
Image<T, Host> read_gray(const unsigned char* data, std::size_t size, const std::string& path, bool allow_narrower) {
  static_assert(std::is_same_v<T, std::uint8_t> || std::is_same_v<T, std::uint16_t>);
  constexpr const char* where = "read_png";
  constexpr int target_bits = 8 * int(sizeof(T));

  Context context;
  ReadStructs s;
  start_read(data, size, path, context, s);

  const auto corrupt = [&] { fail(where, path, std::string("corrupt or truncated PNG: ") + context.message); };
  Header header;
  if (!read_header(s.png, s.info, &header)) corrupt();

  if (header.color_type != PNG_COLOR_TYPE_GRAY)
    fail(where, path,
         "expected a single-channel (grayscale) PNG, got " + color_type_name(header.color_type) + " " +
             std::to_string(header.bit_depth) + "-bit");
  if (header.bit_depth > target_bits)
    fail(where, path,
         std::to_string(header.bit_depth) + "-bit grayscale PNG, but " + std::to_string(target_bits) +
             "-bit was requested (read it with read_png_u16)");
  if (header.bit_depth < target_bits && !allow_narrower)
    fail(where, path,
         std::to_string(header.bit_depth) + "-bit grayscale PNG, but " + std::to_string(target_bits) +
             "-bit is required");
  const bool widen = header.bit_depth <= 8 && target_bits == 16;
  const std::size_t sample_bytes = widen ? 1 : sizeof(T);
  const std::size_t width = header.width, height = header.height;
  if (header.row_bytes != width * sample_bytes)
    fail(where, path,
         "unexpected decoded row size " + std::to_string(header.row_bytes) + " for width " + std::to_string(width));
  check_size(header, size, path);

  Image<T, Host> image(static_cast<int>(width), static_cast<int>(height));
  T* pixels = image.view().data;
  std::vector<unsigned char> narrow;  // the file's 8-bit samples, when widening
  if (widen) narrow.resize(width * height);
  std::vector<png_bytep> rows(height);
  for (std::size_t y = 0; y < height; ++y)
    rows[y] = widen ? narrow.data() + y * width : reinterpret_cast<png_bytep>(pixels + y * width);
  if (!read_rows(s.png, rows.data())) corrupt();
  if (widen)
    for (std::size_t i = 0; i < narrow.size(); ++i) pixels[i] = T(narrow[i]);
  return image;
}

template <class T>
Image<T, Host> read_gray(const std::string& path, bool allow_narrower) {
  const std::string file = io::read_file(path, "read_png");
  return read_gray<T>(reinterpret_cast<const unsigned char*>(file.data()), file.size(), path, allow_narrower);
}

/// Reads the `size` bytes at `data`, a PNG of 8 bits or fewer per sample,
/// as 8-bit RGB (see read_header_rgb); `path` names it in messages.
inline Image<Rgb8, Host> read_rgb(const unsigned char* data, std::size_t size, const std::string& path) {
  constexpr const char* where = "read_png";
  Context context;
  ReadStructs s;
  start_read(data, size, path, context, s);
  const auto corrupt = [&] { fail(where, path, std::string("corrupt or truncated PNG: ") + context.message); };
  Header header;
  if (!read_header_rgb(s.png, s.info, &header)) corrupt();
  if (header.bit_depth > 8)
    fail(where, path,
         std::to_string(header.bit_depth) + "-bit " + color_type_name(header.color_type) +
             " PNG, but colour images must be 8-bit (is it a depth image?)");
  const std::size_t width = header.width, height = header.height;
  if (header.row_bytes != width * 3)
    fail(where, path,
         "unexpected decoded row size " + std::to_string(header.row_bytes) + " for width " + std::to_string(width) +
             " (expected 3 bytes per pixel)");
  check_size(header, size, path);

  Image<Rgb8, Host> image(static_cast<int>(width), static_cast<int>(height));
  Rgb8* pixels = image.view().data;
  std::vector<png_bytep> rows(height);
  for (std::size_t y = 0; y < height; ++y) rows[y] = reinterpret_cast<png_bytep>(pixels + y * width);
  if (!read_rows(s.png, rows.data())) corrupt();
  return image;
}

template <class T>
void write_image(const std::string& path, const Image<T, Host>& image) {
  static_assert(std::is_same_v<T, std::uint8_t> || std::is_same_v<T, std::uint16_t> || std::is_same_v<T, Rgb8>);
  constexpr bool colour = std::is_same_v<T, Rgb8>;
  constexpr int bit_depth = colour ? 8 : 8 * int(sizeof(T));
  constexpr const char* where = "write_png";
  if (image.empty())
    throw std::invalid_argument(std::string(where) + ": " + quoted(path) + ": cannot write an empty image (" +
                                std::to_string(image.width()) + "x" + std::to_string(image.height()) + ")");
  const auto view = image.view();
  std::vector<png_bytep> rows(std::size_t(view.height));
  for (int y = 0; y < view.height; ++y)
    // libpng takes non-const rows but does not write to them.
    rows[std::size_t(y)] =
        reinterpret_cast<png_bytep>(const_cast<T*>(view.data + std::size_t(y) * std::size_t(view.width)));

  Context context;
  WriteStructs s;
  s.png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &context, on_error, on_warning);
  if (s.png) s.info = png_create_info_struct(s.png);
  if (!s.png || !s.info) fail(where, path, "cannot initialise libpng (out of memory or a libpng version mismatch)");

  io::AtomicFile file(where, path);
  errno = 0;
  const bool ok = write_rows(s.png, s.info, file.get(), png_uint_32(view.width), png_uint_32(view.height), bit_depth,
                             colour ? PNG_COLOR_TYPE_RGB : PNG_COLOR_TYPE_GRAY, rows.data());
  file.commit(ok ? "" : std::string(context.message) + (errno != 0 ? " (" + errno_text(errno) + ")" : ""));
}

}  // namespace detail::png

/// Reads a grayscale PNG of 16 bits, or of 8 bits or fewer (values widened
/// unchanged), e.g. a depth image or an instance-label mask.
inline Image<std::uint16_t, Host> read_png_u16(const std::string& path) {
  return detail::png::read_gray<std::uint16_t>(path, /*allow_narrower=*/true);
}

/// Reads a grayscale PNG of 8 bits or fewer (values unchanged); a 16-bit PNG
/// is an error.
inline Image<std::uint8_t, Host> read_png_u8(const std::string& path) {
  return detail::png::read_gray<std::uint8_t>(path, /*allow_narrower=*/true);
}

/// read_png_u16 and read_png_u8 of a PNG file's `size` bytes in memory;
/// `name` stands for the file in error messages.
inline Image<std::uint16_t, Host> decode_png_u16(const void* data, std::size_t size, const std::string& name) {
  return detail::png::read_gray<std::uint16_t>(static_cast<const unsigned char*>(data), size, name,
                                               /*allow_narrower=*/true);
}
inline Image<std::uint8_t, Host> decode_png_u8(const void* data, std::size_t size, const std::string& name) {
  return detail::png::read_gray<std::uint8_t>(static_cast<const unsigned char*>(data), size, name,
                                              /*allow_narrower=*/true);
}

/// Reads an 8-bit (or 1/2/4-bit) PNG of any colour type as RGB: palette
/// looked up, gray replicated, alpha dropped. 16-bit PNGs are an error.
inline Image<Rgb8, Host> read_png_rgb(const std::string& path) {
  const std::string file = detail::io::read_file(path, "read_png");
  return detail::png::read_rgb(reinterpret_cast<const unsigned char*>(file.data()), file.size(), path);
}

/// read_png_rgb of a PNG file's `size` bytes in memory; `name` stands for the
/// file in error messages.
inline Image<Rgb8, Host> decode_png_rgb(const void* data, std::size_t size, const std::string& name) {
  return detail::png::read_rgb(static_cast<const unsigned char*>(data), size, name);
}

/// Writes a 16-bit grayscale PNG. Throws std::invalid_argument for an empty
/// image, std::runtime_error if the file cannot be written (any earlier file
/// at `path` is then left as it was).
inline void write_png(const std::string& path, const Image<std::uint16_t, Host>& image) {
  detail::png::write_image(path, image);
}

/// Writes an 8-bit grayscale PNG (see the 16-bit overload).
inline void write_png(const std::string& path, const Image<std::uint8_t, Host>& image) {
  detail::png::write_image(path, image);
}

/// Writes an 8-bit RGB PNG (see the 16-bit overload).
inline void write_png(const std::string& path, const Image<Rgb8, Host>& image) {
  detail::png::write_image(path, image);
}

}  // namespace emfusion
