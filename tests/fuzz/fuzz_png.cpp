// Fuzz target: PNG images (TUM depth, instance-label masks, colour frames)
// through decode_png_u16, decode_png_u8 and decode_png_rgb. Errors must not
// be the readers' own consistency check of libpng's row size; decoded
// images must be non-empty; what decode_png_u8 reads, decode_png_u16 must read with
// the same values, and for an 8-bit grayscale file decode_png_rgb must give
// r = g = b = that value.
#include <cstddef>
#include <cstdint>
#include <string>

#include "emfusion/io/png.hpp"
#include "fuzz_check.hpp"

namespace fuzz_png {

inline void check(const std::uint8_t* data, std::size_t size) {
  using emfusion::Host;
  using emfusion::Image;
  const std::string name = "fuzz/000000.png";
  Image<std::uint16_t, Host> wide;
  Image<std::uint8_t, Host> narrow;
  Image<emfusion::Rgb8, Host> colour;
  // The readers check that libpng's transformations give the row size they
  // expect; failing that check means they set up the wrong transformations.
  const char* never = "unexpected decoded row size";
  const bool read_wide =
      emfusion::fuzz::returns([&] { wide = emfusion::decode_png_u16(data, size, name); }, name, never);
  const bool read_narrow =
      emfusion::fuzz::returns([&] { narrow = emfusion::decode_png_u8(data, size, name); }, name, never);
  const bool read_colour =
      emfusion::fuzz::returns([&] { colour = emfusion::decode_png_rgb(data, size, name); }, name, never);
  if (read_wide) EMF_FUZZ_CHECK(!wide.empty());
  if (read_colour) EMF_FUZZ_CHECK(!colour.empty());
  if (!read_narrow) return;
  EMF_FUZZ_CHECK(!narrow.empty() && read_wide && wide.same_size(narrow.width(), narrow.height()));
  const emfusion::ImageView<const std::uint8_t> n = narrow.view();
  const emfusion::ImageView<const std::uint16_t> w = wide.view();
  for (int k = 0; k < n.size(); ++k) EMF_FUZZ_CHECK(w[k] == n[k]);
  // IHDR is the first chunk: bit depth at byte 24.
  const bool eight_bit = size > 24 && std::string(reinterpret_cast<const char*>(data) + 12, 4) == "IHDR" &&
                         data[24] == 8;
  if (!eight_bit) return;
  EMF_FUZZ_CHECK(read_colour && colour.same_size(narrow.width(), narrow.height()));
  const emfusion::ImageView<const emfusion::Rgb8> c = colour.view();
  for (int k = 0; k < n.size(); ++k) EMF_FUZZ_CHECK(c[k].r == n[k] && c[k].g == n[k] && c[k].b == n[k]);
}

}  // namespace fuzz_png

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  fuzz_png::check(data, size);
  return 0;
}
