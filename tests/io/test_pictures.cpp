// Colour pictures: RGB PNG round trips and conversions, JPEG decoding
// (files written here with libjpeg's compressor), read_colour's choice by
// content, clear errors for bad input to each reader; the segmentation
// overlay and the association heat map.
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
