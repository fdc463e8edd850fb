// Colour pictures: RGB PNG round trips and conversions, JPEG decoding
// (files written here with libjpeg's compressor), read_colour's choice by
// content, clear errors for bad input to each reader; the segmentation
// overlay, the association heat map, the 5x7 font and the trajectory plot.
#include <algorithm>
#include <cmath>
#include <csetjmp>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <random>
#include <set>
#include <stdexcept>
#include <string>
#include <tuple>
#include <vector>

#include <jpeglib.h>
#include <png.h>

#include "emfusion/eval/ate.hpp"
#include "emfusion/io/colour.hpp"
#include "emfusion/io/jpeg.hpp"
#include "emfusion/io/pictures.hpp"
#include "emfusion/io/png.hpp"
#include "support/catch.hpp"
#include "support/files.hpp"

using namespace emfusion;
namespace fs = std::filesystem;
using emfusion::test::contains;
using emfusion::test::error_of;
using emfusion::test::read_bytes;
using emfusion::test::ScratchDir;
using emfusion::test::write_bytes;

namespace Catch {
template <>
struct StringMaker<emfusion::Rgb8> {
  static std::string convert(const emfusion::Rgb8& c) {
    // Appended piece by piece: "(" + std::to_string(...) draws a false
    // -Wrestrict warning from GCC 12.
    std::string text = "(";
    text += std::to_string(c.r);
    text += ", ";
    text += std::to_string(c.g);
    text += ", ";
    text += std::to_string(c.b);
    text += ")";
    return text;
  }
};
}  // namespace Catch

namespace {

std::string describe(Rgb8 c) { return Catch::StringMaker<Rgb8>::convert(c); }

int distance(Rgb8 a, Rgb8 b) {
  return std::max({std::abs(int(a.r) - int(b.r)), std::abs(int(a.g) - int(b.g)), std::abs(int(a.b) - int(b.b))});
}

ColourImage random_colour(int width, int height, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> value(0, 255);
  std::vector<Rgb8> pixels(std::size_t(width) * std::size_t(height));
  for (auto& p : pixels) p = Rgb8{std::uint8_t(value(rng)), std::uint8_t(value(rng)), std::uint8_t(value(rng))};
  pixels[0] = Rgb8{0, 0, 0};
  pixels[1] = Rgb8{255, 255, 255};
  pixels[2] = Rgb8{255, 0, 1};  // channel order
  return ColourImage::from_host(width, height, pixels);
}

// ---- test files written with libpng and libjpeg directly ---------------------

/// Writes a PNG of any type from packed rows as the file stores them
/// (big-endian 16-bit samples). Returns false if libpng failed.
bool write_raw_png_stage(std::FILE* file, png_structp png, png_infop info, int width, int height, int bit_depth,
                         int colour_type, const unsigned char* rows, std::size_t row_bytes, const png_color* palette,
                         int palette_size, const unsigned char* transparency, int transparency_size) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_init_io(png, file);
  png_set_IHDR(png, info, png_uint_32(width), png_uint_32(height), bit_depth, colour_type, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  if (palette) png_set_PLTE(png, info, palette, palette_size);
  if (transparency) png_set_tRNS(png, info, transparency, transparency_size, nullptr);
  png_write_info(png, info);
  for (int y = 0; y < height; ++y) png_write_row(png, rows + std::size_t(y) * row_bytes);
  png_write_end(png, nullptr);
  return true;
}

void write_raw_png(const std::string& path, int width, int height, int bit_depth, int colour_type,
                   const std::vector<unsigned char>& rows, const std::vector<png_color>& palette = {},
                   const std::vector<unsigned char>& palette_alpha = {}) {
  std::FILE* file = std::fopen(path.c_str(), "wb");
  REQUIRE(file);
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png_create_info_struct(png);
  const bool ok = write_raw_png_stage(file, png, info, width, height, bit_depth, colour_type, rows.data(),
                                      rows.size() / std::size_t(height), palette.empty() ? nullptr : palette.data(),
                                      int(palette.size()), palette_alpha.empty() ? nullptr : palette_alpha.data(),
                                      int(palette_alpha.size()));
  png_destroy_write_struct(&png, &info);
  std::fclose(file);
  REQUIRE(ok);
}

struct JpegErrors {
  jpeg_error_mgr manager;
  std::jmp_buf jump;
};

void jpeg_test_error_exit(j_common_ptr cinfo) { std::longjmp(reinterpret_cast<JpegErrors*>(cinfo->err)->jump, 1); }

bool write_jpeg_stage(jpeg_compress_struct* cinfo, JpegErrors* errors, std::FILE* file, int width, int height,
                      int components, J_COLOR_SPACE space, const unsigned char* pixels, int quality, bool progressive) {
  if (setjmp(errors->jump)) return false;
  jpeg_create_compress(cinfo);
  jpeg_stdio_dest(cinfo, file);
  cinfo->image_width = JDIMENSION(width);
  cinfo->image_height = JDIMENSION(height);
  cinfo->input_components = components;
  cinfo->in_color_space = space;
  jpeg_set_defaults(cinfo);
  jpeg_set_quality(cinfo, quality, TRUE);
  if (progressive) jpeg_simple_progression(cinfo);
  jpeg_start_compress(cinfo, TRUE);
  while (cinfo->next_scanline < cinfo->image_height) {
    JSAMPROW row = const_cast<unsigned char*>(pixels) +
                   std::size_t(cinfo->next_scanline) * std::size_t(width) * std::size_t(components);
    jpeg_write_scanlines(cinfo, &row, 1);
  }
  jpeg_finish_compress(cinfo);
  return true;
}

/// Writes a JPEG of `components` (1 gray, 3 RGB, 4 CMYK) interleaved 8-bit
/// samples per pixel with libjpeg's compressor.
void write_test_jpeg(const std::string& path, int width, int height, int components,
                     const std::vector<unsigned char>& pixels, bool progressive = false, int quality = 95) {
  REQUIRE(pixels.size() == std::size_t(width) * std::size_t(height) * std::size_t(components));
  std::FILE* file = std::fopen(path.c_str(), "wb");
  REQUIRE(file);
  jpeg_compress_struct cinfo;
  JpegErrors errors;
  cinfo.err = jpeg_std_error(&errors.manager);
  errors.manager.error_exit = jpeg_test_error_exit;
  const J_COLOR_SPACE space = components == 1 ? JCS_GRAYSCALE : components == 3 ? JCS_RGB : JCS_CMYK;
  const bool ok =
      write_jpeg_stage(&cinfo, &errors, file, width, height, components, space, pixels.data(), quality, progressive);
  jpeg_destroy_compress(&cinfo);
  std::fclose(file);
  REQUIRE(ok);
}

/// 32x32 RGB: four 16x16 quadrants of solid colour.
const Rgb8 quadrant_colours[4] = {{220, 30, 30}, {30, 200, 40}, {20, 40, 210}, {250, 250, 250}};

std::vector<unsigned char> quadrant_pixels() {
  std::vector<unsigned char> pixels;
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 32; ++x) {
      const Rgb8 c = quadrant_colours[(y / 16) * 2 + x / 16];
      pixels.insert(pixels.end(), {c.r, c.g, c.b});
    }
  return pixels;
}

void check_quadrants(const ColourImage& image) {
  REQUIRE(image.width() == 32);
  REQUIRE(image.height() == 32);
  const auto v = image.view();
  for (int q = 0; q < 4; ++q) {
    // The quadrant's middle, away from edges that chroma subsampling blurs.
    const Rgb8 got = v(8 + 16 * (q % 2), 8 + 16 * (q / 2));
    INFO("quadrant " << q << ": got " << describe(got) << ", wrote " << describe(quadrant_colours[q]));
    CHECK(distance(got, quadrant_colours[q]) <= 10);
  }
}

/// The pixels of `image` equal to `colour`.
std::vector<std::pair<int, int>> pixels_of(const ColourImage& image, Rgb8 colour) {
  std::vector<std::pair<int, int>> out;
  const auto v = image.view();
  for (int y = 0; y < v.height; ++y)
    for (int x = 0; x < v.width; ++x)
      if (v(x, y) == colour) out.emplace_back(x, y);
  return out;
}

/// True if a pixel of `colour` lies within `radius` of (x, y).
bool colour_near(const ColourImage& image, double x, double y, Rgb8 colour, int radius = 1) {
  const auto v = image.view();
  const int cx = int(std::lround(x)), cy = int(std::lround(y));
  for (int dy = -radius; dy <= radius; ++dy)
    for (int dx = -radius; dx <= radius; ++dx)
      if (v.contains(cx + dx, cy + dy) && v(cx + dx, cy + dy) == colour) return true;
  return false;
}

}  // namespace

// ---- PNG -----------------------------------------------------------------------

TEST_CASE("write_png and read_png_rgb round-trip 8-bit RGB images exactly", "[io][pictures]") {
  ScratchDir dir;
  const ColourImage image = random_colour(29, 17, 5);
  write_png(dir.file("c.png"), image);
  CHECK_FALSE(fs::exists(dir.file("c.png.tmp")));
  const ColourImage back = read_png_rgb(dir.file("c.png"));
  REQUIRE(back.width() == 29);
  REQUIRE(back.height() == 17);
  CHECK(back.to_host() == image.to_host());
  // The same bytes from memory, and through read_colour.
  const std::string bytes = read_bytes(dir.file("c.png"));
  CHECK(decode_png_rgb(bytes.data(), bytes.size(), "mem").to_host() == image.to_host());
  CHECK(read_colour(dir.file("c.png")).to_host() == image.to_host());
  // An RGB file on disk: colour type 2, 8 bits in IHDR.
  CHECK(bytes.substr(24, 2) == std::string("\x08\x02", 2));
  // Empty images are refused as for gray ones.
  CHECK_THROWS_AS(write_png(dir.file("e.png"), ColourImage()), std::invalid_argument);
}

TEST_CASE("read_png_rgb converts gray, palette and alpha PNGs to RGB; the gray readers still refuse colour",
          "[io][pictures]") {
  ScratchDir dir;
  SECTION("8-bit gray is replicated") {
    write_raw_png(dir.file("g.png"), 3, 1, 8, PNG_COLOR_TYPE_GRAY, {0, 100, 255});
    CHECK(read_png_rgb(dir.file("g.png")).to_host() == std::vector<Rgb8>{gray_rgb(0), gray_rgb(100), gray_rgb(255)});
  }
  SECTION("1-bit gray is scaled to 0 and 255") {
    write_raw_png(dir.file("g1.png"), 3, 1, 1, PNG_COLOR_TYPE_GRAY, {0xA0});  // 1 0 1
    CHECK(read_png_rgb(dir.file("g1.png")).to_host() == std::vector<Rgb8>{gray_rgb(255), gray_rgb(0), gray_rgb(255)});
  }
  SECTION("palette entries are looked up") {
    const std::vector<png_color> palette = {{10, 20, 30}, {200, 100, 50}};
    write_raw_png(dir.file("p.png"), 3, 1, 8, PNG_COLOR_TYPE_PALETTE, {1, 0, 1}, palette);
    CHECK(read_png_rgb(dir.file("p.png")).to_host() == std::vector<Rgb8>{{200, 100, 50}, {10, 20, 30}, {200, 100, 50}});
    CHECK_THROWS_WITH(read_png_u8(dir.file("p.png")), EMF_CONTAINS("expected a single-channel"));
  }
  SECTION("a palette with tRNS transparency: entries looked up, transparency dropped") {
    // libpng expands a palette's tRNS to alpha; the reader failed on the
    // 4-byte rows until it stripped that alpha too (found by tests/fuzz).
    const std::vector<png_color> palette = {{10, 20, 30}, {200, 100, 50}};
    write_raw_png(dir.file("pt.png"), 3, 1, 8, PNG_COLOR_TYPE_PALETTE, {1, 0, 1}, palette, {0, 128});
    CHECK(read_png_rgb(dir.file("pt.png")).to_host() == std::vector<Rgb8>{{200, 100, 50}, {10, 20, 30}, {200, 100, 50}});
  }
  SECTION("RGBA and gray+alpha: alpha dropped, colour kept as stored") {
    write_raw_png(dir.file("a.png"), 2, 1, 8, PNG_COLOR_TYPE_RGB_ALPHA, {1, 2, 3, 0, 250, 251, 252, 128});
    CHECK(read_png_rgb(dir.file("a.png")).to_host() == std::vector<Rgb8>{{1, 2, 3}, {250, 251, 252}});
    write_raw_png(dir.file("ga.png"), 1, 1, 8, PNG_COLOR_TYPE_GRAY_ALPHA, {77, 0});
    CHECK(read_png_rgb(dir.file("ga.png")).to_host() == std::vector<Rgb8>{gray_rgb(77)});
  }
  SECTION("RGB PNGs stay errors for read_png_u8 and read_png_u16") {
    write_png(dir.file("rgb.png"), random_colour(4, 4, 1));
    const std::string path = dir.file("rgb.png");
    CHECK_THROWS_WITH(read_png_u8(path), EMF_CONTAINS("expected a single-channel (grayscale) PNG, got RGB"));
    CHECK_THROWS_WITH(read_png_u16(path), EMF_CONTAINS("expected a single-channel (grayscale) PNG, got RGB"));
  }
}

TEST_CASE("read_png_rgb rejects 16-bit PNGs and bad files with messages naming the file", "[io][pictures]") {
  ScratchDir dir;
  SECTION("16-bit gray (a depth image) and 16-bit RGB") {
    write_png(dir.file("depth.png"), Image<std::uint16_t, Host>(4, 3, 1000));
    const std::string message = error_of([&] { read_png_rgb(dir.file("depth.png")); });
    INFO(message);
    CHECK(contains(message, "read_png: '" + dir.file("depth.png") + "': 16-bit grayscale PNG"));
    CHECK(contains(message, "must be 8-bit"));
    write_raw_png(dir.file("rgb16.png"), 1, 1, 16, PNG_COLOR_TYPE_RGB, {1, 2, 3, 4, 5, 6});
    CHECK_THROWS_WITH(read_png_rgb(dir.file("rgb16.png")), EMF_CONTAINS("16-bit RGB (3 channels) PNG"));
  }
  SECTION("missing, empty, not a PNG, truncated") {
    const std::string missing = dir.file("missing.png");
    CHECK_THROWS_WITH(read_png_rgb(missing), EMF_CONTAINS("read_png: '" + missing + "': cannot open for reading"));
    const std::string empty = dir.write("empty.png", "");
    CHECK_THROWS_WITH(read_png_rgb(empty),
                      EMF_CONTAINS("read_png: '" + empty + "': not a PNG file (the file is empty)"));
    const std::string text = dir.write("text.png", "hello, not a picture");
    CHECK_THROWS_WITH(read_png_rgb(text), EMF_CONTAINS("read_png: '" + text + "': not a PNG file (bad signature)"));
    write_png(dir.file("full.png"), random_colour(40, 40, 3));
    const std::string bytes = read_bytes(dir.file("full.png"));
    write_bytes(dir.file("cut.png"), bytes.substr(0, bytes.size() / 2));
    const std::string message = error_of([&] { read_png_rgb(dir.file("cut.png")); });
    INFO(message);
    CHECK(contains(message, "read_png: '" + dir.file("cut.png") + "': corrupt or truncated PNG"));
    CHECK(contains(message, "truncated"));
    CHECK_THROWS_WITH(decode_png_rgb(bytes.data(), 0, "klg frame"), EMF_CONTAINS("read_png: 'klg frame': not a PNG"));
  }
}

// ---- JPEG ----------------------------------------------------------------------

TEST_CASE("read_jpeg decodes baseline and progressive colour JPEGs and gray ones", "[io][pictures]") {
  ScratchDir dir;
  SECTION("baseline colour") {
    write_test_jpeg(dir.file("q.jpg"), 32, 32, 3, quadrant_pixels());
    const ColourImage image = read_jpeg(dir.file("q.jpg"));
    check_quadrants(image);
    // From memory, identical to the file read; read_colour picks JPEG by content.
    const std::string bytes = read_bytes(dir.file("q.jpg"));
    const std::vector<std::uint8_t> vector(bytes.begin(), bytes.end());
    CHECK(decode_jpeg(vector, "frame 0").to_host() == image.to_host());
    CHECK(decode_colour(bytes.data(), bytes.size(), "frame 0").to_host() == image.to_host());
    write_bytes(dir.file("named-png.png"), bytes);  // the extension does not matter
    CHECK(read_colour(dir.file("named-png.png")).to_host() == image.to_host());
  }
  SECTION("progressive colour") {
    write_test_jpeg(dir.file("p.jpg"), 32, 32, 3, quadrant_pixels(), /*progressive=*/true);
    const std::string bytes = read_bytes(dir.file("p.jpg"));
    REQUIRE(bytes.find("\xff\xc2") != std::string::npos);  // SOF2: progressive
    check_quadrants(read_jpeg(dir.file("p.jpg")));
  }
  SECTION("gray: r = g = b, close to what was written") {
    std::vector<unsigned char> pixels;
    for (int y = 0; y < 24; ++y)
      for (int x = 0; x < 40; ++x) pixels.push_back((unsigned char)(x * 6));  // a horizontal ramp
    write_test_jpeg(dir.file("g.jpg"), 40, 24, 1, pixels);
    const ColourImage image = read_jpeg(dir.file("g.jpg"));
    REQUIRE(image.width() == 40);
    REQUIRE(image.height() == 24);
    const auto v = image.view();
    int worst = 0;
    for (int y = 0; y < 24; ++y)
      for (int x = 0; x < 40; ++x) {
        const Rgb8 c = v(x, y);
        REQUIRE(c.r == c.g);
        REQUIRE(c.g == c.b);
        worst = std::max(worst, std::abs(int(c.r) - x * 6));
      }
    CHECK(worst <= 6);
  }
}

TEST_CASE("read_jpeg and read_colour refuse bad input with messages naming the file and the problem",
          "[io][pictures]") {
  ScratchDir dir;
  write_test_jpeg(dir.file("good.jpg"), 32, 32, 3, quadrant_pixels());
  const std::string good = read_bytes(dir.file("good.jpg"));

  SECTION("missing file") {
    const std::string path = dir.file("missing.jpg");
    CHECK_THROWS_WITH(read_jpeg(path), EMF_CONTAINS("read_jpeg: '" + path + "': cannot open for reading"));
    CHECK_THROWS_WITH(read_colour(path), EMF_CONTAINS("read_colour: '" + path + "': cannot open for reading"));
  }
  SECTION("truncated file, and one that only misses its end marker") {
    for (const std::size_t keep : {good.size() / 2, good.size() - 2}) {
      const std::string path = dir.file("cut.jpg");
      write_bytes(path, good.substr(0, keep));
      const std::string message = error_of([&] { read_jpeg(path); });
      INFO(message);
      CHECK(contains(message, "read_jpeg: '" + path + "': corrupt or truncated JPEG"));
      CHECK(contains(message, "the file is truncated"));
      CHECK(contains(error_of([&] { read_colour(path); }), "read_jpeg: '" + path + "'"));
    }
  }
  SECTION("corrupt data after a valid start") {
    const std::string path = dir.write("corrupt.jpg", std::string("\xff\xd8\xff\xe0\x00\x02garbage garbage", 19));
    const std::string message = error_of([&] { read_jpeg(path); });
    INFO(message);
    CHECK(contains(message, "read_jpeg: '" + path + "': corrupt or truncated JPEG: "));
  }
  SECTION("neither PNG nor JPEG") {
    const std::string path = dir.write("text.jpg", "GIF89a, say");
    CHECK_THROWS_WITH(read_jpeg(path), EMF_CONTAINS("read_jpeg: '" + path + "': not a JPEG file"));
    const std::string message = error_of([&] { read_colour(path); });
    INFO(message);
    CHECK(contains(message, "read_colour: '" + path + "': neither a PNG nor a JPEG file"));
    CHECK(contains(message, "47 49 46 38 39 61 2c 20"));  // "GIF89a, "
    const std::string empty = dir.write("empty.jpg", "");
    CHECK_THROWS_WITH(read_colour(empty),
                      EMF_CONTAINS("read_colour: '" + empty + "': neither a PNG nor a JPEG file (the file is empty)"));
    CHECK_THROWS_WITH(read_jpeg(empty),
                      EMF_CONTAINS("read_jpeg: '" + empty + "': not a JPEG file (the file is empty)"));
    // A PNG is not a JPEG (but is colour).
    write_png(dir.file("x.png"), random_colour(2, 2, 9));
    CHECK_THROWS_WITH(read_jpeg(dir.file("x.png")), EMF_CONTAINS("not a JPEG file"));
    CHECK_THROWS_WITH(read_png_rgb(dir.file("good.jpg")), EMF_CONTAINS("not a PNG file (bad signature)"));
  }
  SECTION("empty and short memory buffers") {
    CHECK_THROWS_WITH(decode_jpeg(nullptr, 0, "klg frame 7 colour"),
                      EMF_CONTAINS("read_jpeg: 'klg frame 7 colour': not a JPEG file (the file is empty)"));
    CHECK_THROWS_WITH(decode_jpeg(std::vector<std::uint8_t>{}, "klg frame 7 colour"),
                      EMF_CONTAINS("read_jpeg: 'klg frame 7 colour': not a JPEG file (the file is empty)"));
    CHECK_THROWS_WITH(decode_jpeg(good.data(), 3, "three bytes"),
                      EMF_CONTAINS("read_jpeg: 'three bytes': corrupt or truncated JPEG: unexpected end of file"));
    CHECK_THROWS_WITH(decode_colour(nullptr, 0, "nothing"), EMF_CONTAINS("read_colour: 'nothing': neither"));
  }
  SECTION("CMYK JPEGs are not converted") {
    write_test_jpeg(dir.file("cmyk.jpg"), 8, 8, 4, std::vector<unsigned char>(8 * 8 * 4, 100));
    CHECK_THROWS_WITH(read_jpeg(dir.file("cmyk.jpg")), EMF_CONTAINS("unsupported colour space: CMYK"));
  }
}

TEST_CASE("colour_from_rgb_bytes takes raw interleaved RGB", "[io][pictures]") {
  const ColourImage image = colour_from_rgb_bytes({1, 2, 3, 4, 5, 6}, 2, 1);
  CHECK(image.to_host() == std::vector<Rgb8>{{1, 2, 3}, {4, 5, 6}});
  CHECK_THROWS_AS(colour_from_rgb_bytes({1, 2, 3}, 2, 1), std::invalid_argument);
}

// ---- segmentation overlay --------------------------------------------------------

TEST_CASE("label colours are fixed and distinct", "[io][pictures]") {
  std::set<std::tuple<int, int, int>> seen;
  for (int k = 0; k < 36; ++k) {
    const Rgb8 c = label_colour(k);
    seen.insert({c.r, c.g, c.b});
    CHECK(label_colour(k) == label_colour(k + 36));  // the cycle
  }
  CHECK(seen.size() == 36);
  for (int a = 0; a < 12; ++a)
    for (int b = a + 1; b < 12; ++b) {
      INFO(a << " " << describe(label_colour(a)) << " vs " << b << " " << describe(label_colour(b)));
      CHECK(distance(label_colour(a), label_colour(b)) >= 60);
    }
  CHECK(label_colour(3) == Rgb8{255, 225, 25});
}

TEST_CASE("segmentation_overlay: background as is, objects blended and outlined, unrendered darker", "[io][pictures]") {
  // 10x8: background 0, nothing rendered on the top row, object 1 (label 2)
  // a 4x4 square at x 3..6, y 2..5.
  const int w = 10, h = 8;
  std::vector<int> labels(std::size_t(w * h), 0);
  for (int x = 0; x < w; ++x) labels[std::size_t(x)] = -1;
  for (int y = 2; y <= 5; ++y)
    for (int x = 3; x <= 6; ++x) labels[std::size_t(y * w + x)] = 2;
  const auto label_image = Image<int, Host>::from_host(w, h, labels);
  const ColourImage colour = random_colour(w, h, 11);
  const auto in = colour.view();
  const Rgb8 object = label_colour(1);

  const ColourImage out = segmentation_overlay(&colour, label_image, 0.5f);
  const auto o = out.view();
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      INFO("pixel " << x << "," << y);
      const int label = labels[std::size_t(y * w + x)];
      if (label == 0) {
        CHECK(o(x, y) == in(x, y));
      } else if (label < 0) {
        CHECK(int(o(x, y).r) <= int(in(x, y).r));
        CHECK(int(o(x, y).g) <= int(in(x, y).g));
        CHECK(int(o(x, y).b) <= int(in(x, y).b));
        CHECK(distance(o(x, y), Rgb8{std::uint8_t(in(x, y).r * 0.35f + 0.5f), std::uint8_t(in(x, y).g * 0.35f + 0.5f),
                                     std::uint8_t(in(x, y).b * 0.35f + 0.5f)}) <= 1);
      } else {
        const bool edge = x == 3 || x == 6 || y == 2 || y == 5;
        if (edge) {
          CHECK(o(x, y) == object);  // the solid outline
        } else {
          const Rgb8 expected{std::uint8_t((in(x, y).r + object.r + 1) / 2),
                              std::uint8_t((in(x, y).g + object.g + 1) / 2),
                              std::uint8_t((in(x, y).b + object.b + 1) / 2)};
          CHECK(distance(o(x, y), expected) <= 1);
        }
      }
    }
  // The outline is exactly the square's 12 border pixels.
  CHECK(pixels_of(out, object).size() >= 12);

  SECTION("stable: the same label has the same colour in another frame") {
    std::vector<int> other(std::size_t(w * h), 0);
    other[0] = 2;  // a single pixel: all boundary
    const ColourImage again = segmentation_overlay(&colour, Image<int, Host>::from_host(w, h, other), 0.5f);
    CHECK(again.view()(0, 0) == object);
  }
  SECTION("object ids choose the colour") {
    const std::vector<int> ids = {4, 9};  // label 2 is object 1, id 9
    const ColourImage by_id = segmentation_overlay(&colour, label_image, 0.5f, &ids);
    CHECK(by_id.view()(3, 2) == label_colour(9));
    const std::vector<int> short_ids = {4};
    CHECK_THROWS_WITH(segmentation_overlay(&colour, label_image, 0.5f, &short_ids),
                      EMF_CONTAINS("label 2 (object 1) but only 1 object ids"));
  }
  SECTION("without a colour image: a gray canvas") {
    const ColourImage plain = segmentation_overlay(nullptr, label_image);
    CHECK(plain.view()(0, 7) == overlay_gray);
    CHECK(plain.view()(3, 2) == object);
    CHECK(plain.view()(0, 0).r < overlay_gray.r);
  }
  SECTION("opacity 0 leaves object interiors as the colour image") {
    const ColourImage none = segmentation_overlay(&colour, label_image, 0.0f);
    CHECK(none.view()(4, 3) == in(4, 3));
    CHECK(none.view()(3, 3) == object);
  }
  SECTION("bad arguments") {
    const ColourImage small = random_colour(3, 3, 1);
    CHECK_THROWS_WITH(segmentation_overlay(&small, label_image), EMF_CONTAINS("the colour image is 3x3"));
    CHECK_THROWS_AS(segmentation_overlay(&colour, label_image, 1.5f), std::invalid_argument);
    CHECK_THROWS_AS(segmentation_overlay(&colour, label_image, std::nanf("")), std::invalid_argument);
  }
}

// ---- association heat map --------------------------------------------------------

TEST_CASE("association_heatmap: 0 and 1 at the colour map's ends, luma rising, invalid black", "[io][pictures]") {
  CHECK(heat_colour(0.0f) == Rgb8{68, 1, 84});
  CHECK(heat_colour(1.0f) == Rgb8{253, 231, 37});
  CHECK(heat_colour(-3.0f) == heat_colour(0.0f));
  CHECK(heat_colour(7.0f) == heat_colour(1.0f));
  float previous = -1;
  for (int i = 0; i <= 1000; ++i) {
    const Rgb8 c = heat_colour(float(i) / 1000.0f);
    const float luma = 0.2126f * c.r + 0.7152f * c.g + 0.0722f * c.b;
    INFO("t " << i / 1000.0 << " " << describe(c));
    CHECK(luma >= previous - 0.75f);  // non-decreasing up to rounding to bytes
    previous = luma;
  }
  CHECK(0.2126f * 253 + 0.7152f * 231 + 0.0722f * 37 - (0.2126f * 68 + 0.7152f * 1 + 0.0722f * 84) > 150);

  const float nan = std::numeric_limits<float>::quiet_NaN();
  const auto association = Image<float, Host>::from_host(6, 1, {0.0f, 1.0f, 0.5f, nan, -0.25f, 2.0f});
  const auto map = association_heatmap(association).to_host();
  CHECK(map[0] == heat_colour(0.0f));
  CHECK(map[1] == heat_colour(1.0f));
  CHECK(map[2] == heat_colour(0.5f));
  CHECK(map[3] == Rgb8{0, 0, 0});
  CHECK(map[4] == Rgb8{0, 0, 0});
  CHECK(map[5] == heat_colour(1.0f));

  SECTION("double images too") {
    const auto d = Image<double, Host>::from_host(2, 1, {0.0, 1.0});
    CHECK(association_heatmap(d).to_host() == std::vector<Rgb8>{heat_colour(0.0f), heat_colour(1.0f)});
  }
  SECTION("over a colour image: the map blended over its gray") {
    const ColourImage colour = ColourImage::from_host(6, 1, std::vector<Rgb8>(6, Rgb8{200, 0, 0}));
    const auto over = association_heatmap(association, &colour, 1.0f).to_host();
    CHECK(over[1] == heat_colour(1.0f));
    const auto gray = association_heatmap(association, &colour, 0.0f).to_host();
    CHECK(gray[0] == gray_rgb(43));  // luma of (200, 0, 0) = 42.5
    CHECK(gray[3] == Rgb8{0, 0, 0});
    const ColourImage small(2, 2);
    CHECK_THROWS_AS(association_heatmap(association, &small), std::invalid_argument);
  }
}

// ---- text and trajectory plots ------------------------------------------------------

TEST_CASE("draw_text draws the 5x7 glyphs, clipped to the image", "[io][pictures]") {
  ColourImage image(20, 10, plot_white);
  draw_text(image.view(), 1, 1, "T", plot_black);
  // T: a full top row, then the middle column.
  for (int x = 1; x <= 5; ++x) CHECK(image.view()(x, 1) == plot_black);
  for (int y = 2; y <= 7; ++y) CHECK(image.view()(3, y) == plot_black);
  CHECK(image.view()(1, 2) == plot_white);
  CHECK(pixels_of(image, plot_black).size() == 11);
  ColourImage lower(20, 10, plot_white);
  draw_text(lower.view(), 1, 1, "t", plot_black);
  CHECK(lower.to_host() == image.to_host());
  CHECK(text_width("abc", 2) == 36);
  // Far outside, and partly outside: no crash, nothing written out of bounds.
  draw_text(image.view(), -100, -100, "HELLO 0.5 M", plot_black, 3);
  draw_text(image.view(), 15, 5, "WIDE TEXT: 123/456_-", plot_black, 2);
}

TEST_CASE("trajectory_plot draws each series where the frame projects it, at equal scale", "[io][pictures]") {
  const Rgb8 red{220, 20, 20}, blue{20, 40, 220};
  // In the x-z plane (y constant): an L and a diagonal.
  const PlotSeries a{"ground truth", {{0, 0, 0}, {2, 0, 0}, {2, 0, 1}}, red};
  const PlotSeries b{"estimate", {{0, 0, 1}, {1, 0, 0.5}}, blue};
  PlotOptions options;
  options.width = 600, options.height = 500;
  const PlotFrame frame = trajectory_plot_frame({a, b}, options);
  CHECK(frame.axis_right == 0);  // x right, z up: y has no spread
  CHECK(frame.axis_up == 2);
  const ColourImage plot = trajectory_plot({a, b}, options);
  REQUIRE(plot.width() == 600);
  REQUIRE(plot.height() == 500);

  for (const Vec3d& p : a.points) {
    INFO("a at " << frame.pixel_x(p) << ", " << frame.pixel_y(p));
    CHECK(colour_near(plot, frame.pixel_x(p), frame.pixel_y(p), red));
    CHECK(frame.pixel_x(p) > frame.left);
    CHECK(frame.pixel_x(p) < frame.right);
    CHECK(frame.pixel_y(p) > frame.top);
    CHECK(frame.pixel_y(p) < frame.bottom);
  }
  for (const Vec3d& p : b.points) CHECK(colour_near(plot, frame.pixel_x(p), frame.pixel_y(p), blue));
  // The middle of a's first segment, along x.
  CHECK(colour_near(plot, frame.pixel_x({1, 0, 0}), frame.pixel_y({1, 0, 0}), red));
  // Orientation: +x to the right, +z up; and one scale for both axes.
  CHECK(frame.pixel_x({2, 0, 0}) - frame.pixel_x({0, 0, 0}) == emfusion::test::Approx(2 * frame.scale));
  CHECK(frame.pixel_y({0, 0, 0}) - frame.pixel_y({0, 0, 1}) == emfusion::test::Approx(frame.scale));
  // Width 2 m fills the (wider) area's width less the inner margin.
  CHECK(2 * frame.scale > 0.8 * (frame.right - frame.left));
  // Grid step: a round number giving a handful of lines.
  CHECK(frame.grid_step == emfusion::test::Approx(0.5).margin(1e-12));
  // The legend lists both names in black below the plot area.
  bool text_below = false;
  for (const auto& [x, y] : pixels_of(plot, plot_black)) text_below = text_below || y > frame.bottom;
  CHECK(text_below);
  // Every blue pixel of the segment lies on it: continuous line, no stray dots.
  const auto blue_pixels = pixels_of(plot, blue);
  std::set<int> columns;
  for (const auto& [x, y] : blue_pixels)
    if (y < frame.bottom) columns.insert(x);
  const int x0 = int(std::lround(frame.pixel_x(b.points[0]))), x1 = int(std::lround(frame.pixel_x(b.points[1])));
  for (int x = x0; x <= x1; ++x) CHECK(columns.count(x) == 1);
}

TEST_CASE("trajectory_plot keeps squares square and chooses the floor plane", "[io][pictures]") {
  const Rgb8 green{0, 160, 60};
  // A 3 m square in x-y at height z = 1.5 (a z-up world), in a wide image.
  const PlotSeries square{"", {{0, 0, 1.5}, {3, 0, 1.5}, {3, 3, 1.5}, {0, 3, 1.5}, {0, 0, 1.5}}, green};
  PlotOptions options;
  options.width = 900, options.height = 400;
  const PlotFrame frame = trajectory_plot_frame({square}, options);
  CHECK(frame.axis_right == 0);
  CHECK(frame.axis_up == 1);
  const ColourImage plot = trajectory_plot({square}, options);
  int lo_x = 1 << 30, hi_x = -1, lo_y = 1 << 30, hi_y = -1;
  for (const auto& [x, y] : pixels_of(plot, green))
    lo_x = std::min(lo_x, x), hi_x = std::max(hi_x, x), lo_y = std::min(lo_y, y), hi_y = std::max(hi_y, y);
  REQUIRE(hi_x > lo_x);
  const int side_x = hi_x - lo_x, side_y = hi_y - lo_y;
  INFO("square drawn " << side_x << " x " << side_y);
  CHECK(std::abs(side_x - side_y) <= 2);
  CHECK(side_y > 200);

  SECTION("explicit axes") {
    options.axis_right = 1, options.axis_up = 2;
    const PlotFrame yz = trajectory_plot_frame({square}, options);
    CHECK(yz.axis_right == 1);
    CHECK(yz.axis_up == 2);
    options.axis_up = 1;
    CHECK_THROWS_AS(trajectory_plot_frame({square}, options), std::invalid_argument);
    options.axis_right = -1;
    CHECK_THROWS_AS(trajectory_plot({square}, options), std::invalid_argument);
  }
}

TEST_CASE("trajectory_plot survives degenerate input", "[io][pictures]") {
  const Rgb8 red{220, 20, 20};
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double huge = std::numeric_limits<double>::max();
  const std::vector<std::vector<PlotSeries>> cases = {
      {},
      {PlotSeries{"empty", {}, red}},
      {PlotSeries{"one point", {{1, 2, 3}}, red}},
      {PlotSeries{"same point", {{1, 2, 3}, {1, 2, 3}, {1, 2, 3}}, red}},
      {PlotSeries{"not finite", {{nan, 0, 0}, {0, nan, 1}}, red}},
      {PlotSeries{"broken", {{0, 0, 0}, {nan, 0, 0}, {1, 0, 1}}, red}},
      {PlotSeries{"far apart", {{-huge, 0, 0}, {huge, 0, 1}}, red}},
      {PlotSeries{"a line", {{0, 0, 0}, {0, 0, 5}}, red}},
  };
  for (std::size_t i = 0; i < cases.size(); ++i) {
    INFO("case " << i);
    for (const int size : {64, 800}) {
      const ColourImage plot = trajectory_plot(cases[i], size, size);
      CHECK(plot.width() == size);
      CHECK(plot.height() == size);
      const PlotFrame frame = trajectory_plot_frame(cases[i], PlotOptions{size, size});
      CHECK(std::isfinite(frame.scale));
      CHECK(frame.scale > 0);
      CHECK(frame.grid_step > 0);
    }
  }
  // A single point: its marker at the plot area's centre.
  const std::vector<PlotSeries> one = {PlotSeries{"one point", {{1, 2, 3}}, red}};
  const PlotFrame frame = trajectory_plot_frame(one);
  CHECK(frame.pixel_x({1, 2, 3}) == emfusion::test::Approx(0.5 * (frame.left + frame.right)));
  CHECK(colour_near(trajectory_plot(one), frame.pixel_x({1, 2, 3}), frame.pixel_y({1, 2, 3}), red));
  // Many named series: the legend is cut, the image still complete.
  std::vector<PlotSeries> many;
  for (int k = 0; k < 200; ++k)
    many.push_back(PlotSeries{"series " + std::to_string(k), {{double(k), 0, 0}}, label_colour(k)});
  CHECK(trajectory_plot(many, 200, 120).width() == 200);
  CHECK_THROWS_WITH(trajectory_plot({}, 63, 100), EMF_CONTAINS("at least 64x64"));
}

TEST_CASE("trajectory_series maps a trajectory's positions, e.g. by an ATE alignment", "[io][pictures]") {
  Trajectory trajectory = {{0.0, SE3<double>::translation({1, 2, 3})}, {0.1, SE3<double>::translation({4, 5, 6})}};
  const PlotSeries plain = trajectory_series(trajectory, "camera", plot_black);
  REQUIRE(plain.points.size() == 2);
  CHECK(plain.points[1][0] == 4);
  const PlotSeries moved = trajectory_series(trajectory, "aligned", plot_black, SE3<double>::translation({10, 0, 0}));
  CHECK(moved.points[0][0] == 11);
  CHECK(moved.points[0][2] == 3);
  CHECK(moved.name == "aligned");

  // A plot written as PNG reads back unchanged.
  ScratchDir dir;
  const ColourImage plot = trajectory_plot({plain, moved}, 128, 128);
  write_png(dir.file("trajectory.png"), plot);
  CHECK(read_colour(dir.file("trajectory.png")).to_host() == plot.to_host());
}

TEST_CASE("trajectory_series with an ATE alignment draws the estimate over the ground truth", "[io][pictures]") {
  // The estimate is the ground truth seen from another world frame.
  Trajectory ground_truth, estimate;
  const SE3<double> T_est_gt = SE3<double>::from_quaternion(0.1, -0.3, 0.2, 0.92, vec3(0.5, -1.0, 2.0));
  for (int i = 0; i < 40; ++i) {
    const double t = 0.05 * i;
    const SE3<double> pose = SE3<double>::translation(vec3(std::cos(t), 0.1 * t, std::sin(2 * t)));
    ground_truth.push_back({t, pose});
    estimate.push_back({t, T_est_gt * pose});
  }
  const eval::AteResult ate = eval::absolute_trajectory_error(estimate, ground_truth);
  CHECK(ate.rmse < 1e-9);
  const PlotSeries gt = trajectory_series(ground_truth, "ground truth", plot_black);
  const PlotSeries est = trajectory_series(estimate, "estimate", label_colour(0), ate.T_gt_est);
  for (std::size_t i = 0; i < gt.points.size(); ++i)
    for (int k = 0; k < 3; ++k) CHECK(est.points[i][k] == emfusion::test::Approx(gt.points[i][k]).margin(1e-9));
  const ColourImage plot = trajectory_plot({gt, est});
  const PlotFrame frame = trajectory_plot_frame({gt, est});
  // The estimate, drawn last, covers the ground truth's path.
  for (const Vec3d& p : gt.points) CHECK(colour_near(plot, frame.pixel_x(p), frame.pixel_y(p), label_colour(0)));
}
