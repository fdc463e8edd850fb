// Colour pixels for the pictures that io/ reads and writes: `Rgb8`, one
// 8-bit red, green and blue sample per pixel (sRGB values as stored in PNG
// and JPEG files, no gamma conversion), and `ColourImage`, a host image of
// them. The core image type is reused; only the pixel type lives here, so
// core/ stays free of anything colour-specific.
//
// Readers: read_png_rgb (io/png.hpp), read_jpeg / decode_jpeg and
// read_colour (PNG or JPEG by the file's first bytes; io/jpeg.hpp). Writer:
// write_png's Rgb8 overload. Drawing: io/pictures.hpp.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/error.hpp"
#include "emfusion/core/image.hpp"

namespace emfusion {

/// One colour pixel: red, green, blue, 0..255 each. An aggregate of three
/// bytes (no padding), so an image of them is the interleaved RGB layout of
/// PNG and JPEG rows. `Rgb8{}` is black.
struct Rgb8 {
  std::uint8_t r, g, b;

  friend constexpr bool operator==(const Rgb8& a, const Rgb8& b) { return a.r == b.r && a.g == b.g && a.b == b.b; }
  friend constexpr bool operator!=(const Rgb8& a, const Rgb8& b) { return !(a == b); }
};
static_assert(sizeof(Rgb8) == 3, "Rgb8 must be three bytes without padding (interleaved RGB rows)");

using ColourImage = Image<Rgb8, Host>;

/// A gray pixel (r = g = b = value).
constexpr Rgb8 gray_rgb(std::uint8_t value) { return {value, value, value}; }

/// The colour image of raw interleaved RGB bytes, row by row (width * height
/// * 3 of them), e.g. a .klg frame's colour when KlgSequence::colour_is_jpeg
/// is false. Throws std::invalid_argument for a negative size or the wrong
/// byte count.
inline ColourImage colour_from_rgb_bytes(const std::vector<std::uint8_t>& bytes, int width, int height) {
  constexpr const char* where = "colour_from_rgb_bytes";
  detail::require(width >= 0 && height >= 0, where,
                  "negative size " + std::to_string(width) + "x" + std::to_string(height));
  const std::size_t pixels = std::size_t(width) * std::size_t(height);
  detail::require(bytes.size() == pixels * 3, where,
                  "expected " + std::to_string(pixels * 3) + " bytes (3 per pixel) for " + std::to_string(width) + "x" +
                      std::to_string(height) + ", got " + std::to_string(bytes.size()));
  ColourImage image(width, height);
  Rgb8* out = image.view().data;
  for (std::size_t i = 0; i < pixels; ++i) out[i] = Rgb8{bytes[3 * i], bytes[3 * i + 1], bytes[3 * i + 2]};
  return image;
}

}  // namespace emfusion
