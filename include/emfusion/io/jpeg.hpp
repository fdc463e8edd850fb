// Decoding JPEG images through libjpeg (jpeglib.h; libjpeg-turbo on the
// project's machines), without OpenCV: colour frames of sequences stored as
// JPEG files, and the JPEG colour bytes of .klg logs (KlgSequence::
// colour_bytes), which are decoded from memory.
//
// read_jpeg(path) and decode_jpeg(bytes, name) take baseline and progressive
// JPEGs, colour (YCbCr or RGB) or grayscale, and return 8-bit RGB; a gray
// JPEG comes back with r = g = b. CMYK/YCCK JPEGs are rejected. read_colour
// (path) reads a PNG (read_png_rgb) or a JPEG, chosen by the file's first
// bytes, not by its name; decode_colour does the same for bytes in memory.
//
// Errors are std::runtime_error "read_jpeg: '<path>': <problem>" (for bytes
// in memory the caller's name stands for the path): a file that cannot be
// opened, empty input, input that is not a JPEG, a truncated file (any read
// past the end of the data is an error, even one that only misses the final
// end-of-image marker: libjpeg's default would pad the image with gray and
// carry on), corrupt data (libjpeg's message is kept) and unsupported colour
// spaces. libjpeg's warnings (recoverable corruption) are not errors and are
// not printed. read_colour's own errors start "read_colour:".
//
// libjpeg reports fatal errors through the error_exit callback, whose
// default calls exit(). Here it keeps libjpeg's message and longjmps back to
// a setjmp. As in png.hpp, every libjpeg call that can fail runs inside a
// small function that holds only trivially destructible locals and turns the
// longjmp into a return value, and the decompressor is destroyed by a guard
// outside it (which frees all of libjpeg's memory), so bad data neither
// leaks nor skips a C++ destructor. The input is read from memory through a
// source manager written here (jpeg_mem_src is not in every libjpeg).
#pragma once

#include <csetjmp>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include <jpeglib.h>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/io/colour.hpp"
#include "emfusion/io/detail/files.hpp"
#include "emfusion/io/png.hpp"

namespace emfusion {

namespace detail::jpeg {

using io::fail;

/// libjpeg's error manager followed by what the callbacks share with the
/// reader. Trivially destructible on purpose (it lives across longjmps).
struct ErrorManager {
  jpeg_error_mgr manager;  // first: libjpeg's j_common_ptr->err points here
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX + 64];
};

/// The source manager that feeds libjpeg the input bytes, all at once.
struct Source {
  jpeg_source_mgr manager;  // first: libjpeg's cinfo->src points here
  const unsigned char* data;
  std::size_t size;
};

[[noreturn]] inline void jump_back(j_common_ptr cinfo) {
  auto* errors = reinterpret_cast<ErrorManager*>(cinfo->err);
  std::longjmp(errors->jump, 1);
}

/// libjpeg's error_exit: keep the message, then jump back to the setjmp of
/// the stage function that made the failing call (never exit()).
inline void on_error(j_common_ptr cinfo) {
  auto* errors = reinterpret_cast<ErrorManager*>(cinfo->err);
  (*cinfo->err->format_message)(cinfo, errors->message);
  jump_back(cinfo);
}

/// Warnings and trace messages go nowhere (the default prints to stderr).
inline void on_output_message(j_common_ptr) {}

inline void init_source(j_decompress_ptr) {}
inline void term_source(j_decompress_ptr) {}

/// libjpeg asks for more data only when it has used all of it: the data
/// ends before the image does.
inline boolean fill_input_buffer(j_decompress_ptr cinfo) {
  auto* errors = reinterpret_cast<ErrorManager*>(cinfo->err);
  std::snprintf(errors->message, sizeof(errors->message), "%s", "unexpected end of file (the file is truncated)");
  jump_back(reinterpret_cast<j_common_ptr>(cinfo));
}

inline void skip_input_data(j_decompress_ptr cinfo, long count) {
  if (count <= 0) return;
  jpeg_source_mgr* source = cinfo->src;
  if (static_cast<unsigned long>(count) > source->bytes_in_buffer) fill_input_buffer(cinfo);
  source->next_input_byte += count;
  source->bytes_in_buffer -= std::size_t(count);
}

/// A decompressor and its error and source managers; destroys the
/// decompressor (freeing all of libjpeg's memory) when it goes.
struct Decompressor {
  jpeg_decompress_struct cinfo;
  ErrorManager errors;
  Source source;
  bool created = false;

  Decompressor() = default;
  Decompressor(const Decompressor&) = delete;
  Decompressor& operator=(const Decompressor&) = delete;
  ~Decompressor() {
    if (created) jpeg_destroy_decompress(&cinfo);
  }
};

// The stage functions below call libjpeg between a setjmp and its possible
// longjmp. They hold no locals with destructors and touch no local after the
// jump, which is what makes the longjmp well defined in C++.

inline bool create(Decompressor* d) {
  if (setjmp(d->errors.jump)) return false;
  jpeg_create_decompress(&d->cinfo);
  d->created = true;
  return true;
}

/// Reads the header and picks the output colour space: RGB for colour
/// JPEGs, gray for gray ones (replicated to RGB by the caller: libjpeg 6b
/// cannot convert gray to RGB itself). Leaves CMYK/YCCK alone for the
/// caller to reject.
inline bool read_header(Decompressor* d) {
  if (setjmp(d->errors.jump)) return false;
  jpeg_read_header(&d->cinfo, TRUE);
  if (d->cinfo.jpeg_color_space == JCS_GRAYSCALE)
    d->cinfo.out_color_space = JCS_GRAYSCALE;
  else if (d->cinfo.jpeg_color_space == JCS_YCbCr || d->cinfo.jpeg_color_space == JCS_RGB)
    d->cinfo.out_color_space = JCS_RGB;
  return true;
}

/// Decodes every row into `pixels` (output_width * output_components bytes
/// per row, rows one after another) and reads to the end of the image.
inline bool decode_rows(Decompressor* d, unsigned char* pixels, std::size_t row_bytes) {
  if (setjmp(d->errors.jump)) return false;
  jpeg_start_decompress(&d->cinfo);
  while (d->cinfo.output_scanline < d->cinfo.output_height) {
    JSAMPROW row = pixels + std::size_t(d->cinfo.output_scanline) * row_bytes;
    jpeg_read_scanlines(&d->cinfo, &row, 1);
  }
  jpeg_finish_decompress(&d->cinfo);
  return true;
}

inline bool starts_with_jpeg_signature(const unsigned char* data, std::size_t size) {
  // Start-of-image marker FF D8, then the next marker's FF.
  return size >= 3 && data[0] == 0xFF && data[1] == 0xD8 && data[2] == 0xFF;
}

inline bool starts_with_png_signature(const unsigned char* data, std::size_t size) {
  static constexpr unsigned char signature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  if (size < 8) return false;
  for (int i = 0; i < 8; ++i)
    if (data[i] != signature[i]) return false;
  return true;
}

inline const char* colour_space_name(J_COLOR_SPACE space) {
  switch (space) {
    case JCS_GRAYSCALE:
      return "grayscale";
    case JCS_RGB:
      return "RGB";
    case JCS_YCbCr:
      return "YCbCr";
    case JCS_CMYK:
      return "CMYK";
    case JCS_YCCK:
      return "YCCK";
    default:
      return "an unknown colour space";
  }
}

/// Decodes the `size` bytes at `data`; `path` names them in messages.
inline Image<Rgb8, Host> decode(const unsigned char* data, std::size_t size, const std::string& path) {
  constexpr const char* where = "read_jpeg";
  if (size == 0) fail(where, path, "not a JPEG file (the file is empty)");
  if (!starts_with_jpeg_signature(data, size))
    fail(where, path, "not a JPEG file (it does not start with the JPEG start-of-image marker FF D8 FF)");

  Decompressor d;
  d.cinfo.err = jpeg_std_error(&d.errors.manager);
  d.errors.manager.error_exit = on_error;
  d.errors.manager.output_message = on_output_message;
  d.errors.message[0] = '\0';
  const auto corrupt = [&] { fail(where, path, std::string("corrupt or truncated JPEG: ") + d.errors.message); };
  if (!create(&d)) fail(where, path, std::string("cannot initialise libjpeg: ") + d.errors.message);

  d.source.manager.init_source = init_source;
  d.source.manager.fill_input_buffer = fill_input_buffer;
  d.source.manager.skip_input_data = skip_input_data;
  d.source.manager.resync_to_restart = jpeg_resync_to_restart;
  d.source.manager.term_source = term_source;
  d.source.manager.next_input_byte = data;
  d.source.manager.bytes_in_buffer = size;
  d.source.data = data;
  d.source.size = size;
  d.cinfo.src = &d.source.manager;

  if (!read_header(&d)) corrupt();
  const J_COLOR_SPACE space = d.cinfo.jpeg_color_space;
  if (space != JCS_GRAYSCALE && space != JCS_YCbCr && space != JCS_RGB)
    fail(where, path,
         std::string("unsupported colour space: ") + colour_space_name(space) + " with " +
             std::to_string(d.cinfo.num_components) + " components (only gray and RGB/YCbCr JPEGs are read)");

  const std::size_t width = d.cinfo.image_width, height = d.cinfo.image_height;
  if (width == 0 || height == 0 || width * height > std::size_t(INT32_MAX))
    fail(where, path, "unsupported image size " + std::to_string(width) + "x" + std::to_string(height));
  // Even a uniform image needs a few bits per 8x8 block; a header promising
  // far more pixels than the data could encode is corrupt and must not make
  // us allocate gigabytes. (Generous: 4096 pixels per byte, plus 16
  // megapixels for any file.)
  if (width * height > 4096 * size + (std::size_t(1) << 24))
    fail(where, path,
         "corrupt header: a " + std::to_string(width) + "x" + std::to_string(height) + " image cannot be stored in " +
             std::to_string(size) + " bytes");

  const std::size_t components = d.cinfo.out_color_space == JCS_GRAYSCALE ? 1 : 3;
  Image<Rgb8, Host> image(static_cast<int>(width), static_cast<int>(height));
  Rgb8* pixels = image.view().data;
  std::vector<unsigned char> gray;  // the decoded samples of a gray JPEG
  if (components == 1) gray.resize(width * height);
  unsigned char* target = components == 1 ? gray.data() : reinterpret_cast<unsigned char*>(pixels);
  if (!decode_rows(&d, target, width * components)) corrupt();
  if (d.cinfo.output_width != width || d.cinfo.output_height != height ||
      std::size_t(d.cinfo.output_components) != components)
    fail(where, path,
         "unexpected decoded layout " + std::to_string(d.cinfo.output_width) + "x" +
             std::to_string(d.cinfo.output_height) + "x" + std::to_string(d.cinfo.output_components));
  if (components == 1)
    for (std::size_t i = 0; i < gray.size(); ++i) pixels[i] = gray_rgb(gray[i]);
  return image;
}

}  // namespace detail::jpeg

/// Decodes a JPEG file (baseline or progressive, colour or gray) into RGB;
/// gray comes back with r = g = b.
inline Image<Rgb8, Host> read_jpeg(const std::string& path) {
  const std::string file = detail::io::read_file(path, "read_jpeg");
  return detail::jpeg::decode(reinterpret_cast<const unsigned char*>(file.data()), file.size(), path);
}

/// Decodes the `size` bytes of a JPEG file in memory (e.g. a .klg frame's
/// colour_bytes); `name` stands for the file in error messages.
inline Image<Rgb8, Host> decode_jpeg(const void* data, std::size_t size, const std::string& name) {
  return detail::jpeg::decode(static_cast<const unsigned char*>(data), size, name);
}

/// decode_jpeg of a byte vector.
inline Image<Rgb8, Host> decode_jpeg(const std::vector<std::uint8_t>& bytes, const std::string& name) {
  return decode_jpeg(bytes.data(), bytes.size(), name);
}

/// Decodes a PNG (as read_png_rgb) or a JPEG (as read_jpeg) file's bytes in
/// memory, chosen by their first bytes; anything else is a
/// std::runtime_error "read_colour: '<name>': ...".
inline Image<Rgb8, Host> decode_colour(const void* data, std::size_t size, const std::string& name) {
  const auto* bytes = static_cast<const unsigned char*>(data);
  if (detail::jpeg::starts_with_png_signature(bytes, size)) return decode_png_rgb(bytes, size, name);
  if (detail::jpeg::starts_with_jpeg_signature(bytes, size)) return decode_jpeg(bytes, size, name);
  if (size == 0) detail::io::fail("read_colour", name, "neither a PNG nor a JPEG file (the file is empty)");
  static constexpr char hex[] = "0123456789abcdef";
  std::string first;
  for (std::size_t i = 0; i < size && i < 8; ++i) {
    if (i > 0) first += ' ';
    first += hex[bytes[i] >> 4];
    first += hex[bytes[i] & 15];
  }
  detail::io::fail("read_colour", name,
                   "neither a PNG nor a JPEG file (it starts with the bytes " + first +
                       "; PNG starts 89 50 4e 47 0d 0a 1a 0a, JPEG ff d8 ff)");
}

/// Reads a colour image from a PNG or JPEG file, chosen by the file's first
/// bytes, not its name. Errors name the file: "read_colour: ..." for a file
/// that cannot be opened or is neither, else the reader's "read_png: ..." or
/// "read_jpeg: ...".
inline Image<Rgb8, Host> read_colour(const std::string& path) {
  const std::string file = detail::io::read_file(path, "read_colour");
  return decode_colour(file.data(), file.size(), path);
}

}  // namespace emfusion
