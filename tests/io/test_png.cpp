// PNG images through libpng: exact 8/16-bit round trips, byte order checked
// against hand-made files, the bit depths and colour types read_png accepts
// and rejects, and clear errors (no crash, no leak) for missing, non-PNG,
// truncated and corrupt files.
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "emfusion/io/png.hpp"
#include "support/catch.hpp"
#include "support/files.hpp"

using namespace emfusion;
namespace fs = std::filesystem;
using emfusion::test::ScratchDir;
using emfusion::test::contains;
using emfusion::test::error_of;
using emfusion::test::read_bytes;
using emfusion::test::write_bytes;


namespace {



// ---- hand-made PNG files, independent of libpng's writer ----------------------

std::uint32_t crc32(const std::string& bytes) {
  std::uint32_t crc = 0xffffffffu;
  for (const char c : bytes) {
    crc ^= static_cast<unsigned char>(c);
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xedb88320u & (0u - (crc & 1u)));
  }
  return ~crc;
}

std::string be32(std::uint32_t v) {
  return {char((v >> 24) & 0xff), char((v >> 16) & 0xff), char((v >> 8) & 0xff), char(v & 0xff)};
}

std::string chunk(const std::string& type, const std::string& data) {
  return be32(std::uint32_t(data.size())) + type + data + be32(crc32(type + data));
}

/// A zlib stream holding `raw` in one stored (uncompressed) deflate block.
std::string zlib_stored(const std::string& raw) {
  std::uint32_t a = 1, b = 0;
  for (const char c : raw) {
    a = (a + static_cast<unsigned char>(c)) % 65521u;
    b = (b + a) % 65521u;
  }
  const auto n = std::uint16_t(raw.size());
  const auto nn = std::uint16_t(~n);
  std::string out = "\x78\x01";
  out += '\x01';  // final block, stored
  out += {char(n & 0xff), char(n >> 8), char(nn & 0xff), char(nn >> 8)};
  return out + raw + be32((b << 16) | a);
}

/// A PNG with the given header and filtered rows (a filter byte, 0, before
/// each row's samples).
std::string make_png(std::uint32_t width, std::uint32_t height, int bit_depth, int colour_type, const std::string& rows,
                     int interlace = 0) {
  const std::string ihdr =
      be32(width) + be32(height) + std::string{char(bit_depth), char(colour_type), 0, 0, char(interlace)};
  return std::string("\x89PNG\r\n\x1a\n", 8) + chunk("IHDR", ihdr) + chunk("IDAT", zlib_stored(rows)) +
         chunk("IEND", "");
}

template <class T>
Image<T, Host> random_image(int width, int height, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> value(0, int(std::numeric_limits<T>::max()));
  std::vector<T> pixels(std::size_t(width) * std::size_t(height));
  for (auto& p : pixels) p = T(value(rng));
  // The extremes and values whose two bytes differ, to catch byte-order bugs.
  pixels[0] = 0;
  pixels[1] = std::numeric_limits<T>::max();
  pixels[2] = T(1);
  if constexpr (sizeof(T) == 2) pixels[3] = T(0x0102);
  return Image<T, Host>::from_host(width, height, pixels);
}

}  // namespace

TEST_CASE("write_png and read_png round-trip 16-bit and 8-bit images exactly", "[io][png]") {
  ScratchDir dir;
  SECTION("16-bit") {
    const auto image = random_image<std::uint16_t>(37, 23, 1);
    write_png(dir.file("a.png"), image);
    const auto back = read_png_u16(dir.file("a.png"));
    REQUIRE(back.width() == 37);
    REQUIRE(back.height() == 23);
    CHECK(back.to_host() == image.to_host());
    CHECK_FALSE(fs::exists(dir.file("a.png.tmp")));
  }
  SECTION("8-bit, read as 8 bits and widened to 16") {
    const auto image = random_image<std::uint8_t>(5, 64, 2);
    write_png(dir.file("b.png"), image);
    CHECK(read_png_u8(dir.file("b.png")).to_host() == image.to_host());
    const auto wide = read_png_u16(dir.file("b.png")).to_host();
    const auto narrow = image.to_host();
    REQUIRE(wide.size() == narrow.size());
    for (std::size_t i = 0; i < wide.size(); ++i) CHECK(wide[i] == narrow[i]);  // values kept, not rescaled
  }
  SECTION("a 1x1 image, and overwriting an existing file") {
    write_png(dir.file("c.png"), Image<std::uint16_t, Host>(1, 1, 7));
    write_png(dir.file("c.png"), Image<std::uint16_t, Host>(1, 1, 65000));
    CHECK(read_png_u16(dir.file("c.png")).to_host() == std::vector<std::uint16_t>{65000});
  }
  SECTION("decode_png_u16 and decode_png_u8 read the same bytes from memory") {
    const auto image = random_image<std::uint8_t>(6, 5, 3);
    write_png(dir.file("d.png"), image);
    const std::string bytes = read_bytes(dir.file("d.png"));
    CHECK(decode_png_u8(bytes.data(), bytes.size(), "mem").to_host() == image.to_host());
    CHECK(decode_png_u16(bytes.data(), bytes.size(), "mem").to_host() == read_png_u16(dir.file("d.png")).to_host());
    CHECK_THROWS_WITH(decode_png_u16(bytes.data(), 20, "mem"), EMF_CONTAINS("read_png: 'mem': corrupt or truncated"));
  }
}

TEST_CASE("read_png reads samples in PNG (big-endian) order and unpacks low bit depths", "[io][png]") {
  ScratchDir dir;
  SECTION("16-bit samples are big-endian in the file") {
    // 2x1: 0x0102 and 0xff00.
    write_bytes(dir.file("be.png"), make_png(2, 1, 16, 0, std::string("\0\x01\x02\xff\x00", 5)));
    CHECK(read_png_u16(dir.file("be.png")).to_host() == std::vector<std::uint16_t>{0x0102, 0xff00});
  }
  SECTION("our writer stores them big-endian too") {
    write_png(dir.file("w.png"), Image<std::uint16_t, Host>::from_host(2, 1, {0x0102, 0xff00}));
    const std::string bytes = read_bytes(dir.file("w.png"));
    CHECK(bytes.substr(8 + 8 + 8, 5) == std::string("\x10\x00\x00\x00\x00", 5));  // IHDR: depth 16, gray
  }
  SECTION("4-bit grayscale: values unchanged in both readers") {
    // 2x2 pixels 3 10 / 15 0.
    write_bytes(dir.file("g4.png"), make_png(2, 2, 4, 0, std::string("\0\x3a\0\xf0", 4)));
    CHECK(read_png_u8(dir.file("g4.png")).to_host() == std::vector<std::uint8_t>{3, 10, 15, 0});
    CHECK(read_png_u16(dir.file("g4.png")).to_host() == std::vector<std::uint16_t>{3, 10, 15, 0});
  }
  SECTION("an interlaced image") {
    // Adam7 of a 1x1 image is its only pass.
    write_bytes(dir.file("i.png"), make_png(1, 1, 16, 0, std::string("\0\x12\x34", 3), 1));
    CHECK(read_png_u16(dir.file("i.png")).to_host() == std::vector<std::uint16_t>{0x1234});
  }
}

TEST_CASE("read_png rejects the wrong bit depth or channel count", "[io][png]") {
  ScratchDir dir;
  write_png(dir.file("16.png"), Image<std::uint16_t, Host>(4, 4, 1000));
  const std::string e16 = error_of([&] { read_png_u8(dir.file("16.png")); });
  CHECK(contains(e16, "read_png: '" + dir.file("16.png") + "': "));
  CHECK(contains(e16, "16-bit"));

  write_bytes(dir.file("rgb.png"), make_png(1, 1, 8, 2, std::string("\0\x01\x02\x03", 4)));
  const std::string rgb = error_of([&] { read_png_u16(dir.file("rgb.png")); });
  CHECK(contains(rgb, dir.file("rgb.png")));
  CHECK(contains(rgb, "grayscale"));
  CHECK(contains(rgb, "RGB"));

  write_bytes(dir.file("ga.png"), make_png(1, 1, 8, 4, std::string("\0\x01\x02", 3)));
  CHECK_THROWS_WITH(read_png_u8(dir.file("ga.png")), EMF_CONTAINS("alpha"));
}

TEST_CASE("read_png reports missing, non-PNG, truncated and corrupt files", "[io][png]") {
  ScratchDir dir;
  SECTION("missing file") {
    const std::string e = error_of([&] { read_png_u16(dir.file("none.png")); });
    CHECK(contains(e, "read_png: '" + dir.file("none.png") + "': cannot open"));
  }
  SECTION("a directory") { CHECK_THROWS_AS(read_png_u16(dir.file("")), std::runtime_error); }
  SECTION("not a PNG") {
    write_bytes(dir.file("text.png"), "this is not an image\n");
    CHECK_THROWS_WITH(read_png_u16(dir.file("text.png")), EMF_CONTAINS("': not a PNG file"));
    write_bytes(dir.file("empty.png"), "");
    CHECK_THROWS_WITH(read_png_u8(dir.file("empty.png")), EMF_CONTAINS("not a PNG file"));
  }
  SECTION("truncated anywhere") {
    write_png(dir.file("full.png"), random_image<std::uint16_t>(64, 48, 3));
    const std::string bytes = read_bytes(dir.file("full.png"));
    for (const std::size_t keep :
         {std::size_t(12), std::size_t(30), bytes.size() / 2, bytes.size() - 20, bytes.size() - 1}) {
      CAPTURE(keep);
      write_bytes(dir.file("cut.png"), bytes.substr(0, keep));
      const std::string e = error_of([&] { read_png_u16(dir.file("cut.png")); });
      CHECK(contains(e, "read_png: '" + dir.file("cut.png") + "': "));
      CHECK(contains(e, "truncated"));
    }
  }
  SECTION("a damaged chunk") {
    std::string bytes = make_png(2, 1, 16, 0, std::string("\0\x01\x02\xff\x00", 5));
    const std::size_t idat_data = 8 + 25 + 8;  // signature, IHDR chunk, IDAT length and type
    bytes[idat_data + 7 + 1] ^= 0x40;          // a sample (after the zlib and block headers): the CRC fails
    write_bytes(dir.file("crc.png"), bytes);
    CHECK_THROWS_WITH(read_png_u16(dir.file("crc.png")), EMF_CONTAINS("corrupt"));
  }
  SECTION("a header promising more pixels than the file holds") {
    write_bytes(dir.file("huge.png"), make_png(100000, 100000, 16, 0, std::string("\0\0\0", 3)));
    CHECK_THROWS_WITH(read_png_u16(dir.file("huge.png")), EMF_CONTAINS("corrupt header"));
  }
  SECTION("too little image data") {
    write_bytes(dir.file("short.png"), make_png(4, 4, 8, 0, std::string("\0\1\2\3\4", 5)));
    CHECK_THROWS_WITH(read_png_u8(dir.file("short.png")), EMF_CONTAINS("corrupt or truncated"));
  }
}

TEST_CASE("write_png reports what it cannot write and leaves existing files alone", "[io][png]") {
  ScratchDir dir;
  CHECK_THROWS_AS(write_png(dir.file("e.png"), Image<std::uint16_t, Host>()), std::invalid_argument);
  CHECK_FALSE(fs::exists(dir.file("e.png")));

  const std::string missing = dir.file("no/such/dir/x.png");
  const std::string e = error_of([&] { write_png(missing, Image<std::uint8_t, Host>(2, 2, 1)); });
  CHECK(contains(e, "write_png: '" + missing + "': cannot open"));

  // A directory in the way of the rename: the write fails, the temporary is
  // removed.
  fs::create_directories(dir.file("taken.png/inside"));
  CHECK_THROWS_WITH(write_png(dir.file("taken.png"), Image<std::uint8_t, Host>(2, 2, 1)), EMF_CONTAINS("rename"));
  CHECK_FALSE(fs::exists(dir.file("taken.png.tmp")));
}
