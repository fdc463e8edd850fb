// OpenEXR through the OpenEXR library: files that OpenEXR itself writes in
// every compression (NONE, RLE, ZIPS, ZIP, PIZ exactly; PXR24, B44, B44A,
// DWAA, DWAB within the precision each codec keeps), HALF and FLOAT,
// scanline and tiled, offset data windows; the choice of the depth channel;
// write_exr/read_exr round trips of every compression; and bad, truncated
// and corrupt files (each an error naming the file, never a crash). Built
// without OpenEXR, only the channel choice and the error saying that the
// build cannot read EXR are tested.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "emfusion/io/exr.hpp"
#include "support/catch.hpp"
#include "support/files.hpp"

#if EMFUSION_HAS_OPENEXR
#include <ImfChannelList.h>
#include <ImfCompression.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfOutputFile.h>
#include <ImfTileDescription.h>
#include <ImfTiledOutputFile.h>
#include <half.h>
#endif

using namespace emfusion;
using emfusion::test::contains;
using emfusion::test::error_of;
using emfusion::test::read_bytes;
using emfusion::test::ScratchDir;

namespace {

// Written by OpenEXR 3.1.5 (Debian's libopenexr-dev) with Imf::OutputFile:
// channel number c (in the order of insertion) holds, at pixel (x, y) of the
// data window, 0.25 x + 1.5 y + 10 c + 0.125, which HALF stores exactly.
//   float_zip:     5x20, channel Z FLOAT, ZIP (two chunks, the second of 4 lines)
//   half_zips:     40x3, channel Y HALF, ZIPS
//   mixed_zip:     6x18, channels A (c=0, HALF) and Z (c=1, FLOAT), ZIP
//   rgb_half_none: 4x3, data window (2,3)-(5,5), channels R, G, B (c=0,1,2;
//                  stored B, G, R), HALF, no compression

[[maybe_unused]] const char* const float_zip_hex =
    "762f3101020000006368616e6e656c730063686c69737400130000005a00020000000000000001000000010000000063"
    "6f6d7072657373696f6e00636f6d7072657373696f6e0001000000036461746157696e646f7700626f78326900100000"
    "0000000000000000000400000013000000646973706c617957696e646f7700626f783269001000000000000000000000"
    "0006000000150000006c696e654f72646572006c696e654f72646572000100000000706978656c417370656374526174"
    "696f00666c6f617400040000000000803f73637265656e57696e646f7743656e74657200763266000800000000000000"
    "0000000073637265656e57696e646f77576964746800666c6f617400040000000000803f002501000000000000ef0100"
    "000000000000000000c2000000785e6368687038b020e18182c087800d05133a2a6664ac8838617143e385c40f0e963f"
    "226f649ea8dcd1b96272c6658fcf969035314b52e694f4d4b434d5b55575954dca9b96352b6d5ed2a2b85561eb8236f9"
    "6df3dae576c8ee98d529b3734697f46ea9dd537a24f74cea95d827be6f5cbfd8fe3131fe67fdcdfe93f33bf757decf82"
    "ef85df8abe167f29f95cf6b1fc43c5fbca77556f6b5ed7beaa7b59ffa2e179d3d3e6272d8f5b1fb53dbccf699fd37e47"
    "183ce0401c3c684f270800c6619fc21000000037000000785e6370dcefbcd775b7fb4ecfedbe9bfd3706ae0f5e1bba3a"
    "7279f4d2d8c5f10b13e7a7ce4e9f99393d7b6aeee483f64441002e8a27c2";

[[maybe_unused]] const char* const half_zips_hex =
    "762f3101020000006368616e6e656c730063686c69737400130000005900010000000000000001000000010000000063"
    "6f6d7072657373696f6e00636f6d7072657373696f6e0001000000026461746157696e646f7700626f78326900100000"
    "0000000000000000002700000002000000646973706c617957696e646f7700626f783269001000000000000000000000"
    "0029000000040000006c696e654f72646572006c696e654f72646572000100000000706978656c417370656374526174"
    "696f00666c6f617400040000000000803f73637265656e57696e646f7743656e74657200763266000800000000000000"
    "0000000073637265656e57696e646f77576964746800666c6f617400040000000000803f002d010000000000005c0100"
    "000000000084010000000000000000000027000000785e63686868600062070608787000156c58000107da9a9b1a41a0"
    "01061b30300800002d1e28c90100000020000000785e6b6870608080070750c18605c880afb1b101061b303008406800"
    "86c129ca020000001e000000785e73606060787000156c588009821a1a81b001038300320d0062cb2ccb";

[[maybe_unused]] const char* const mixed_zip_hex =
    "762f3101020000006368616e6e656c730063686c69737400250000004100010000000000000001000000010000005a00"
    "0200000000000000010000000100000000636f6d7072657373696f6e00636f6d7072657373696f6e0001000000036461"
    "746157696e646f7700626f783269001000000000000000000000000500000011000000646973706c617957696e646f77"
    "00626f7832690010000000000000000000000007000000130000006c696e654f72646572006c696e654f726465720001"
    "00000000706978656c417370656374526174696f00666c6f617400040000000000803f73637265656e57696e646f7743"
    "656e746572007632660008000000000000000000000073637265656e57696e646f77576964746800666c6f6174000400"
    "00000000803f003701000000000000b7020000000000000000000078010000785e636868686068605814b72c6a55d8ba"
    "a04d7edb4e35383030301cd8e5b6cfe990dd31ab5366e78a80fc0707142ee95dd3baa5764fe991dcb35d074060c12bb1"
    "77429ff8be71fd62fba704165160fccffc97f537fb4fceefdc530f6c58b0608100ef67fe8f82ef85df8abe16af5c0002"
    "0192cfa59fca3e967fa8785f59172c3241f5b6fa4dcdebda57752feb3f048b5c303c6f7cd6f4b4f949cbe3d653c12202"
    "b687ed0f3aee77deebbadbdd13c89f3121c373bbf756dfcdfe1b03d7075f9d00021ca1abc357462e8f5e1abb385e132c"
    "b222717ef2dcd4d9e93333a767d782453c7227e74f2cec2fee2ded2ebf08167951d95edd5adb5cdfd8d0d0a80e16e968"
    "aa6bae6da969ad6eab6a5fd9d6dcd4d8e87cd01e0e6b1b1b1b1a1b107cfb83207e63830d92483390dfd0608d24d20ae4"
    "3736582289b481d5582089b483d598238974348000b2482758c40c4504648e29924817d81c1324916eb02e422220738c"
    "91447ac06a6022fb9df63941746d06b2601000265221d21000000032000000785ee39800021a1d159de55d65dda53d25"
    "bdb7c12227fa8afa0b27144ccc9f9437797703086c72da07873d182200407524c3";

[[maybe_unused]] const char* const rgb_half_none_hex =
    "762f3101020000006368616e6e656c730063686c69737400370000004200010000000000000001000000010000004700"
    "0100000000000000010000000100000052000100000000000000010000000100000000636f6d7072657373696f6e0063"
    "6f6d7072657373696f6e0001000000006461746157696e646f7700626f78326900100000000200000003000000050000"
    "0005000000646973706c617957696e646f7700626f7832690010000000000000000000000007000000070000006c696e"
    "654f72646572006c696e654f72646572000100000000706978656c417370656374526174696f00666c6f617400040000"
    "000000803f73637265656e57696e646f7743656e746572007632660008000000000000000000000073637265656e5769"
    "6e646f77576964746800666c6f617400040000000000803f005101000000000000710100000000000091010000000000"
    "000300000018000000084d184d284d384d1049304950497049003000360039003b0400000018000000684d784d884d98"
    "4dd049f049104a304a803e803f4040c0400500000018000000c84dd84de84df84d904ab04ad04af04a4042c0424043c0"
    "43";

std::string from_hex(const char* hex) {
  std::string out;
  for (std::size_t k = 0; hex[k] && hex[k + 1]; k += 2)
    out.push_back(char(std::stoi(std::string(hex + k, 2), nullptr, 16)));
  return out;
}

}  // namespace

TEST_CASE("read_exr chooses the depth channel by name", "[io][exr]") {
  using detail::exr::Channel;
  const auto choose = [](const std::vector<std::string>& names, const std::string& wanted, std::string& problem) {
    std::vector<Channel> channels;
    for (const std::string& n : names) channels.push_back({n, 2});
    problem.clear();
    return detail::exr::choose_channel(channels, wanted, problem);
  };
  std::string problem;
  CHECK(choose({"anything"}, "", problem) == 0);
  CHECK(choose({"A", "B", "G", "R", "Z"}, "", problem) == 4);
  CHECK(choose({"B", "G", "R", "Y"}, "", problem) == 3);
  CHECK(choose({"B", "G", "R"}, "", problem) == 2);
  CHECK(choose({"A", "Depth"}, "", problem) == 1);
  CHECK(choose({"ViewLayer.Combined.R", "ViewLayer.Depth.Z"}, "", problem) == 1);
  CHECK(choose({"B", "G", "R"}, "G", problem) == 1);
  CHECK(problem.empty());
  choose({"left.Z", "right.Z"}, "", problem);
  CHECK(contains(problem, "several channels"));
  choose({"u", "v"}, "", problem);
  CHECK(contains(problem, "cannot tell the depth channel among 'u', 'v'"));
}

#if !EMFUSION_HAS_OPENEXR

TEST_CASE("without OpenEXR, reading or writing EXR fails naming the file and the missing library", "[io][exr]") {
  ScratchDir dir;
  const std::string path = dir.write("float_zip.exr", from_hex(float_zip_hex));
  const std::string e = error_of([&] { read_exr(path); });
  CHECK(contains(e, "read_exr: '" + path + "'"));
  CHECK(contains(e, "no OpenEXR support"));
  CHECK(contains(e, "libopenexr-dev"));
  const std::string bytes = read_bytes(path);
  CHECK(contains(error_of([&] { decode_exr(bytes.data(), bytes.size(), "mem"); }), "read_exr: 'mem': this build"));
  const std::string out = dir.file("out.exr");
  const std::string w = error_of([&] { write_exr(out, Image<float, Host>(3, 2, 1.f)); });
  CHECK(contains(w, "write_exr: '" + out + "'"));
  CHECK(contains(w, "no OpenEXR support"));
  CHECK_THROWS_AS(read_exr(path), std::runtime_error);
}

#else  // EMFUSION_HAS_OPENEXR

namespace {

float reference_value(int x, int y, int c) { return 0.25f * float(x) + 1.5f * float(y) + 10.f * float(c) + 0.125f; }

/// Largest |image - reference_value(., ., c)|.
double reference_error(const Image<float, Host>& image, int c) {
  double error = 0;
  const auto v = image.view();
  for (int y = 0; y < v.height; ++y)
    for (int x = 0; x < v.width; ++x) error = std::max(error, std::abs(double(v(x, y)) - reference_value(x, y, c)));
  return error;
}

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), sizeof(float) * a.size()) == 0);
}

// Little-endian fields for files built by hand.
void le32(std::string& s, std::uint32_t v) {
  for (int k = 0; k < 4; ++k) s.push_back(char((v >> (8 * k)) & 0xff));
}
void le64(std::string& s, std::uint64_t v) {
  for (int k = 0; k < 8; ++k) s.push_back(char((v >> (8 * k)) & 0xff));
}
void attribute(std::string& s, const std::string& name, const std::string& type, const std::string& value) {
  s += name + '\0' + type + '\0';
  le32(s, std::uint32_t(value.size()));
  s += value;
}

/// A 3x2 single-channel uncompressed file built from the format's
/// description: one channel `name` of `pixel_type` (0 UINT, 1 HALF, 2
/// FLOAT) with the given samples (2 or 4 bytes each, row by row), `version`
/// in the version field.
std::string hand_built(const std::vector<std::uint32_t>& samples, int pixel_type = 1, const std::string& name = "depth",
                       std::uint32_t version = 2) {
  const int bytes = pixel_type == 1 ? 2 : 4;
  std::string s;
  le32(s, 20000630);
  le32(s, version);
  std::string channels = name + '\0';
  le32(channels, std::uint32_t(pixel_type));
  channels += std::string(4, '\0');  // pLinear, reserved
  le32(channels, 1);
  le32(channels, 1);
  channels += '\0';
  attribute(s, "channels", "chlist", channels);
  attribute(s, "compression", "compression", std::string(1, '\0'));
  std::string box;
  for (std::uint32_t v : {0u, 0u, 2u, 1u}) le32(box, v);
  attribute(s, "dataWindow", "box2i", box);
  attribute(s, "displayWindow", "box2i", box);
  attribute(s, "lineOrder", "lineOrder", std::string(1, '\0'));
  std::string value;
  const float one = 1.f;
  std::uint32_t one_bits;
  std::memcpy(&one_bits, &one, 4);
  le32(value, one_bits);
  attribute(s, "pixelAspectRatio", "float", value);
  attribute(s, "screenWindowCenter", "v2f", std::string(8, '\0'));
  attribute(s, "screenWindowWidth", "float", value);
  s += '\0';
  // Two chunks of one scanline each: offsets, then "y, size, samples".
  const std::size_t table = s.size();
  const std::size_t chunk = 8 + 3 * std::size_t(bytes);
  le64(s, table + 16);
  le64(s, table + 16 + chunk);
  for (std::uint32_t y = 0; y < 2; ++y) {
    le32(s, y);
    le32(s, std::uint32_t(3 * bytes));
    for (int x = 0; x < 3; ++x) {
      const std::uint32_t v = samples[y * 3 + std::uint32_t(x)];
      for (int k = 0; k < bytes; ++k) s.push_back(char((v >> (8 * k)) & 0xff));
    }
  }
  return s;
}

/// A depth map as a sensor sees a scene of smooth surfaces: 0.6 to 4 m,
/// two planes and a bump, with a little noise; `specials` adds 0 (no
/// measurement), -0, infinity, NaN, a negative value and a subnormal, which
/// only the lossless codecs must keep.
std::vector<float> depth_values(int width, int height, bool specials) {
  std::vector<float> v(std::size_t(width) * std::size_t(height));
  std::mt19937 random(5);
  std::uniform_real_distribution<float> noise(-1e-3f, 1e-3f);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const float wall = 2.5f + 0.02f * float(x) - 0.01f * float(y);
      const float dx = float(x - width / 3), dy = float(y - height / 2);
      const float bump = 1.2f - 0.004f * (dx * dx + dy * dy);
      v[std::size_t(y) * std::size_t(width) + std::size_t(x)] = (bump > 0.6f ? bump : wall) + noise(random);
    }
  if (specials) {
    const float values[] = {0.f,
                            -0.f,
                            std::numeric_limits<float>::infinity(),
                            std::numeric_limits<float>::quiet_NaN(),
                            -1.5f,
                            std::numeric_limits<float>::denorm_min(),
                            65504.f,
                            1e-7f};
    for (std::size_t k = 0; k < std::size(values); ++k) v[7 * k + 3] = values[k];
  }
  return v;
}

/// What a HALF channel holds for `v`: OpenEXR's float -> half conversion.
std::vector<float> as_half(const std::vector<float>& v) {
  std::vector<float> out;
  for (const float f : v) out.push_back(float(half(f)));
  return out;
}

enum class Layout { Scanline, Tiled, TiledMipmap };

/// Writes `values` (width x height, row by row) through OpenEXR into
/// channels Z and R (the same values; DWA's codecs treat R as colour and
/// compress it with loss, Z without) of `type`, in a data window whose
/// top-left corner is `origin`.
void write_with_openexr(const std::string& path, const std::vector<float>& values, int width, int height,
                        Imf::Compression compression, Imf::PixelType type, Layout layout,
                        Imath::V2i origin = Imath::V2i(-3, 5)) {
  const Imath::Box2i window(origin, origin + Imath::V2i(width - 1, height - 1));
  Imf::Header header(Imath::Box2i(Imath::V2i(0, 0), Imath::V2i(width - 1, height - 1)), window);
  header.compression() = compression;
  for (const char* name : {"Z", "R"}) header.channels().insert(name, Imf::Channel(type));
  std::vector<half> halves(values.begin(), values.end());
  const auto frame_buffer = [&](const void* data, const Imath::Box2i& box) {
    const std::size_t size = type == Imf::HALF ? sizeof(half) : sizeof(float);
    const std::size_t row = size * std::size_t(box.max.x - box.min.x + 1);
    Imf::FrameBuffer frame;
    for (const char* name : {"Z", "R"}) frame.insert(name, Imf::Slice::Make(type, data, box, size, row));
    return frame;
  };
  const void* data = type == Imf::HALF ? static_cast<const void*>(halves.data()) : values.data();
  if (layout == Layout::Scanline) {
    Imf::OutputFile file(path.c_str(), header);
    file.setFrameBuffer(frame_buffer(data, window));
    file.writePixels(height);
    return;
  }
  // Tiles of 16x8 do not divide the image: the last ones are partial.
  header.setTileDescription(
      Imf::TileDescription(16, 8, layout == Layout::Tiled ? Imf::ONE_LEVEL : Imf::MIPMAP_LEVELS, Imf::ROUND_DOWN));
  Imf::TiledOutputFile file(path.c_str(), header);
  for (int level = 0; level < file.numLevels(); ++level) {
    // The smaller levels hold other values: the reader must take level 0.
    const Imath::Box2i box = file.dataWindowForLevel(level);
    const std::size_t pixels = std::size_t(box.max.x - box.min.x + 1) * std::size_t(box.max.y - box.min.y + 1);
    std::vector<float> other(pixels, 100.f + float(level));
    std::vector<half> other_halves(other.begin(), other.end());
    const void* level_data = level == 0          ? data
                             : type == Imf::HALF ? static_cast<const void*>(other_halves.data())
                                                 : other.data();
    file.setFrameBuffer(frame_buffer(level_data, box));
    file.writeTiles(0, file.numXTiles(level) - 1, 0, file.numYTiles(level) - 1, level);
  }
}

/// Largest |got - expected| / |expected| (0 where both are 0).
double relative_error(const std::vector<float>& got, const std::vector<float>& expected) {
  double error = 0;
  for (std::size_t k = 0; k < got.size(); ++k) {
    const double e = std::abs(double(got[k]) - double(expected[k]));
    if (e > 0) error = std::max(error, e / std::abs(double(expected[k])));
  }
  return error;
}

const char* name_of(Imf::Compression c) {
  // In the order of Imf::Compression's values.
  static const char* const names[] = {"NONE", "RLE", "ZIPS", "ZIP", "PIZ", "PXR24", "B44", "B44A", "DWAA", "DWAB"};
  return names[int(c)];
}

}  // namespace

TEST_CASE("read_exr reads files written by the OpenEXR library", "[io][exr]") {
  ScratchDir dir;
  const std::string float_zip = dir.write("float_zip.exr", from_hex(float_zip_hex));
  const std::string half_zips = dir.write("half_zips.exr", from_hex(half_zips_hex));
  const std::string mixed_zip = dir.write("mixed_zip.exr", from_hex(mixed_zip_hex));
  const std::string rgb = dir.write("rgb_half_none.exr", from_hex(rgb_half_none_hex));

  const Image<float, Host> a = read_exr(float_zip);
  CHECK(a.same_size(5, 20));
  CHECK(reference_error(a, 0) == 0);
  const Image<float, Host> b = read_exr(half_zips);
  CHECK(b.same_size(40, 3));
  CHECK(reference_error(b, 0) == 0);
  // Z (FLOAT) is preferred to A; A (HALF) by name.
  CHECK(reference_error(read_exr(mixed_zip), 1) == 0);
  CHECK(reference_error(read_exr(mixed_zip, "A"), 0) == 0);
  CHECK(read_exr(mixed_zip, "A").same_size(6, 18));
  // R of R, G, B; pixel (0, 0) is the data window's corner (2, 3).
  const Image<float, Host> r = read_exr(rgb);
  CHECK(r.same_size(4, 3));
  CHECK(reference_error(r, 0) == 0);
  CHECK(reference_error(read_exr(rgb, "G"), 1) == 0);
  CHECK(reference_error(read_exr(rgb, "B"), 2) == 0);

  const std::string e = error_of([&] { read_exr(rgb, "Q"); });
  CHECK(contains(e, "read_exr: '" + rgb + "'"));
  CHECK(contains(e, "no channel 'Q'"));
  CHECK(contains(e, "'B', 'G', 'R'"));

  // decode_exr reads the same bytes from memory.
  const std::string bytes = read_bytes(float_zip);
  CHECK(decode_exr(bytes.data(), bytes.size(), "mem").to_host() == a.to_host());
  CHECK_THROWS_WITH(decode_exr(bytes.data(), 7, "mem"), EMF_CONTAINS("read_exr: 'mem': not an OpenEXR file"));
}

TEST_CASE("read_exr reads every compression OpenEXR writes, HALF and FLOAT, scanline and tiled", "[io][exr]") {
  ScratchDir dir;
  // 37 rows: two DWAA chunks of 32 (and parts of ZIP's 16), 67 columns: B44's
  // 4x4 blocks and the 16x8 tiles do not divide the image.
  constexpr int width = 67, height = 37;
  for (const Imf::Compression compression :
       {Imf::NO_COMPRESSION, Imf::RLE_COMPRESSION, Imf::ZIPS_COMPRESSION, Imf::ZIP_COMPRESSION, Imf::PIZ_COMPRESSION,
        Imf::PXR24_COMPRESSION, Imf::B44_COMPRESSION, Imf::B44A_COMPRESSION, Imf::DWAA_COMPRESSION,
        Imf::DWAB_COMPRESSION})
    for (const Imf::PixelType type : {Imf::HALF, Imf::FLOAT})
      for (const Layout layout : {Layout::Scanline, Layout::Tiled, Layout::TiledMipmap}) {
        const std::string codec = name_of(compression);
        const bool lossless = codec == "NONE" || codec == "RLE" || codec == "ZIPS" || codec == "ZIP" || codec == "PIZ";
        const bool is_half = type == Imf::HALF;
        INFO(codec << (is_half ? " HALF " : " FLOAT ")
                   << (layout == Layout::Scanline ? "scanline"
                       : layout == Layout::Tiled  ? "tiled"
                                                  : "mipmap"));
        const std::vector<float> values = depth_values(width, height, lossless);
        // HALF samples are values rounded to half, which read_exr must
        // convert back to float exactly.
        const std::vector<float> stored = is_half ? as_half(values) : values;
        const std::string path = dir.file(codec + (is_half ? "_half" : "_float") + ".exr");
        write_with_openexr(path, values, width, height, compression, type, layout);

        const Image<float, Host> z = read_exr(path);
        REQUIRE(z.same_size(width, height));
        const std::vector<float> depth = z.to_host(), colour = read_exr(path, "R").to_host();
        if (lossless) {
          CHECK(same_bits(depth, stored));
          CHECK(same_bits(colour, stored));
        } else if (codec == "PXR24") {
          // HALF is kept; FLOAT loses 8 mantissa bits, rounded (2^-16 relative).
          if (is_half) CHECK(same_bits(depth, stored));
          const double error = relative_error(depth, stored);
          INFO("PXR24 relative error " << error);
          CHECK(error <= std::ldexp(1.0, -15));
          CHECK((is_half || error > 0));
        } else if (codec == "B44" || codec == "B44A") {
          // Only HALF is coded, in 4x4 blocks whose samples are stored as
          // differences at one precision: a block across the step from 1.2
          // to 2.5 m loses most (measured 5.1%). FLOAT is stored as it is.
          const double error = relative_error(depth, stored);
          INFO("B44 relative error " << error);
          if (is_half)
            CHECK(error <= 0.06);
          else
            CHECK(error == 0);
          CHECK(relative_error(colour, stored) == error);
        } else {
          // DWA codes channels named as colours (R), HALF or FLOAT, by DCT
          // at its default level, 45 (measured 1.4% at most, at the step;
          // DWAB's tiles of HALF came back whole), and others (Z) without loss.
          CHECK(same_bits(depth, stored));
          const double error = relative_error(colour, stored);
          INFO("DWA relative error of R " << error);
          CHECK(error <= 0.02);
        }
      }
}

TEST_CASE("write_exr round-trips every compression through read_exr", "[io][exr]") {
  ScratchDir dir;
  constexpr int width = 67, height = 37;
  const std::vector<float> plain = depth_values(width, height, false), special = depth_values(width, height, true);
  const auto image_of = [&](const std::vector<float>& values) {
    Image<float, Host> image(width, height);
    std::copy(values.begin(), values.end(), image.view().data);
    return image;
  };
  const std::pair<ExrCompression, int> all[] = {
      {ExrCompression::None, Imf::NO_COMPRESSION},   {ExrCompression::Rle, Imf::RLE_COMPRESSION},
      {ExrCompression::Zips, Imf::ZIPS_COMPRESSION}, {ExrCompression::Zip, Imf::ZIP_COMPRESSION},
      {ExrCompression::Piz, Imf::PIZ_COMPRESSION},   {ExrCompression::Pxr24, Imf::PXR24_COMPRESSION},
      {ExrCompression::B44, Imf::B44_COMPRESSION},   {ExrCompression::B44a, Imf::B44A_COMPRESSION},
      {ExrCompression::Dwaa, Imf::DWAA_COMPRESSION}, {ExrCompression::Dwab, Imf::DWAB_COMPRESSION}};
  for (const auto& [compression, code] : all) {
    const std::string codec = name_of(Imf::Compression(code));
    INFO(codec);
    const std::string path = dir.file(codec + ".exr");
    if (compression == ExrCompression::Pxr24) {
      write_exr(path, image_of(plain), {compression, "Z"});
      const double error = relative_error(read_exr(path).to_host(), plain);
      CHECK(error <= std::ldexp(1.0, -15));
      CHECK(error > 0);
    } else {
      // The depth channel is FLOAT, which B44 and B44A store whole, and DWA
      // too unless it is named as a colour channel.
      const bool dwa = compression == ExrCompression::Dwaa || compression == ExrCompression::Dwab;
      for (const char* channel : {"Z", "depth", "R"}) {
        INFO(channel);
        if (dwa && std::string(channel) == "R") {
          write_exr(path, image_of(plain), {compression, channel});
          CHECK(relative_error(read_exr(path).to_host(), plain) <= 0.02);
        } else {
          write_exr(path, image_of(special), {compression, channel});
          CHECK(same_bits(read_exr(path).to_host(), special));
        }
      }
    }
    // The file says the compression asked for (the attribute's value byte).
    const std::string key = std::string("compression\0compression\0\x01\0\0\0", 28) + char(code);
    CHECK(contains(read_bytes(path), key));
  }

  // Depth on a coarse grid (few mantissa bits) compresses.
  std::vector<float> coarse(std::size_t(width) * height);
  for (std::size_t i = 0; i < coarse.size(); ++i) coarse[i] = 1.f + float(i % width / 8) / 64.f;
  write_exr(dir.file("none.exr"), image_of(coarse), {ExrCompression::None, "Z"});
  write_exr(dir.file("zip.exr"), image_of(coarse), {ExrCompression::Zip, "Z"});
  CHECK(read_bytes(dir.file("zip.exr")).size() < read_bytes(dir.file("none.exr")).size() / 4);
  CHECK(read_exr(dir.file("zip.exr")).to_host() == coarse);
  // The default: ZIP, channel Z.
  write_exr(dir.file("default.exr"), image_of(coarse));
  CHECK(read_bytes(dir.file("default.exr")) == read_bytes(dir.file("zip.exr")));
  CHECK(read_exr(dir.file("default.exr"), "Z").to_host() == coarse);

  const Image<float, Host> image = image_of(plain);
  CHECK(contains(error_of([&] { write_exr(dir.file("e.exr"), Image<float, Host>()); }), "empty"));
  CHECK(contains(error_of([&] { write_exr(dir.file("e.exr"), image, {ExrCompression::Zip, ""}); }), "channel name"));
  CHECK_THROWS_AS(write_exr(dir.file("e.exr"), image, {ExrCompression::Zip, std::string(32, 'a')}),
                  std::invalid_argument);
  CHECK_THROWS_AS(write_exr(dir.file("e.exr"), image, {ExrCompression(42), "Z"}), std::invalid_argument);
  const std::string nowhere = dir.file("no/such/folder/x.exr");
  CHECK(contains(error_of([&] { write_exr(nowhere, image); }), "write_exr: '" + nowhere + "': cannot open"));
}

TEST_CASE("read_exr names unsupported features", "[io][exr]") {
  ScratchDir dir;
  const std::vector<std::uint32_t> ones(6, 0x3c00);
  const auto error = [&](const std::string& name, const std::string& bytes) {
    const std::string path = dir.write(name, bytes);
    const std::string e = error_of([&] { read_exr(path); });
    CHECK(contains(e, "read_exr: '" + path + "'"));
    return e;
  };
  // The hand-built file itself reads.
  CHECK(read_exr(dir.write("ones.exr", hand_built(ones))).to_host() == std::vector<float>(6, 1.f));
  CHECK(contains(error("multi.exr", hand_built(ones, 1, "depth", 2 | 0x1000)), "multi-part"));
  CHECK(contains(error("deep.exr", hand_built(ones, 1, "depth", 2 | 0x800)), "deep"));
  CHECK(contains(error("v1.exr", hand_built(ones, 1, "depth", 1)), "OpenEXR: "));
  CHECK(contains(error("tiled.exr", hand_built(ones, 1, "depth", 2 | 0x200)), "OpenEXR: "));
  CHECK(contains(error("uint.exr", hand_built({1, 2, 3, 4, 5, 6}, 0)), "UINT"));
  error("type.exr", hand_built(ones, 7));

  // A subsampled depth channel (OpenEXR writes one), beside a full one.
  const std::string sub = dir.file("sub.exr");
  {
    Imf::Header header(4, 4);
    header.channels().insert("Z", Imf::Channel(Imf::FLOAT, 2, 2));
    header.channels().insert("R", Imf::Channel(Imf::FLOAT));
    std::vector<float> z(4, 2.f), r(16, 3.f);
    Imf::FrameBuffer frame;
    frame.insert("Z",
                 Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(z.data()), sizeof(float), 2 * sizeof(float), 2, 2));
    frame.insert("R", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(r.data()), sizeof(float), 4 * sizeof(float)));
    Imf::OutputFile file(sub.c_str(), header);
    file.setFrameBuffer(frame);
    file.writePixels(4);
  }
  CHECK(contains(error_of([&] { read_exr(sub); }), "subsampled channel 'Z' (sampling 2 x 2)"));
  CHECK(read_exr(sub, "R").to_host() == std::vector<float>(16, 3.f));

  // A data window wider than the reader's bound, refused before any pixels.
  std::string wide = hand_built(ones);
  const std::size_t box = wide.find(std::string("dataWindow\0box2i\0\x10\0\0\0", 21));
  REQUIRE(box != std::string::npos);
  wide[box + 21 + 8 + 2] = 0x20;  // x max = 2 + 2^21
  CHECK(contains(error("wide.exr", wide), "too large"));

  // Sizes OpenEXR would allocate before checking them, refused first: an
  // attribute claiming more bytes than the file has (the fuzz target's
  // 1.7 GB), a name longer than the format allows, tiles larger than the
  // image.
  std::string huge = hand_built(ones);
  const std::size_t order = huge.find(std::string("lineOrder\0lineOrder\0\x01\0\0\0", 24));
  REQUIRE(order != std::string::npos);
  huge[order + 20 + 3] = 0x69;
  CHECK(contains(error("huge.exr", huge), "attribute 'lineOrder' at byte " + std::to_string(order) +
                                              " claims 1761607681 bytes, more than the file holds"));
  // Values OpenEXR reads by their own layout must have the size their size
  // field says, or OpenEXR reads on from the wrong place (the fuzz target's
  // channel list that ran into a 2 GB "attribute").
  std::string longer = hand_built(ones);
  const std::string compression_key = std::string("compression\0compression\0\x01\0\0\0", 28);
  const std::size_t compression_at = longer.find(compression_key);
  REQUIRE(compression_at != std::string::npos);
  longer[compression_at + 24] = 2;
  longer.insert(compression_at + 28, 1, '\0');
  CHECK(contains(error("longer.exr", longer), "attribute 'compression' at byte " + std::to_string(compression_at) +
                                                  " (type 'compression', 2 bytes): a value of this type has 1 bytes"));
  std::string list = hand_built(ones);
  const std::size_t list_at = list.find(std::string("channels\0chlist\0", 16));
  REQUIRE(list_at != std::string::npos);
  list[list_at + 16] = char(list[list_at + 16] - 1);  // the final NUL left outside
  CHECK(contains(error("list.exr", list), "not a channel list of that size"));
  std::string named = hand_built(ones);
  named.insert(8, std::string(40, 'n') + '\0' + "int" + '\0' + std::string("\x04\0\0\0\0\0\0\0", 8));
  CHECK(contains(error("named.exr", named), "longer than 31 characters"));
  std::string tiled = hand_built(ones, 1, "depth", 2 | 0x200);
  std::string description;
  le32(description, 4096);
  le32(description, 16);
  description += '\0';
  std::string tiles;
  attribute(tiles, "tiles", "tiledesc", description);
  tiled.insert(8, tiles);
  CHECK(contains(error("tiles.exr", tiled), "tiles of 4096x16 pixels for an image of 3x2: too large"));

  // An unknown compression code.
  std::string bytes = hand_built(ones);
  const std::string key = std::string("compression\0compression\0\x01\0\0\0", 28);
  const std::size_t at = bytes.find(key);
  REQUIRE(at != std::string::npos);
  bytes[at + key.size()] = 42;
  error("c.exr", bytes);
}

TEST_CASE("read_exr reports truncated and corrupt files without reading out of bounds", "[io][exr]") {
  ScratchDir dir;
  const std::string missing = dir.file("missing.exr");
  CHECK(contains(error_of([&] { read_exr(missing); }), "cannot open"));
  const std::string text = dir.write("text.exr", "P6 not an exr file");
  CHECK(contains(error_of([&] { read_exr(text); }), "not an OpenEXR file"));
  CHECK(contains(error_of([&] { read_exr(dir.write("short.exr", "v/1")); }), "not an OpenEXR file"));

  // Files of several codecs and layouts, written by OpenEXR (the mipmapped
  // one last).
  constexpr int width = 21, height = 19;
  std::vector<std::string> files = {from_hex(float_zip_hex), from_hex(half_zips_hex)};
  for (const auto& [compression, layout] :
       std::vector<std::pair<Imf::Compression, Layout> >{{Imf::RLE_COMPRESSION, Layout::Scanline},
                                                         {Imf::PIZ_COMPRESSION, Layout::Scanline},
                                                         {Imf::PXR24_COMPRESSION, Layout::Scanline},
                                                         {Imf::B44A_COMPRESSION, Layout::Scanline},
                                                         {Imf::DWAA_COMPRESSION, Layout::Scanline},
                                                         {Imf::ZIP_COMPRESSION, Layout::Tiled},
                                                         {Imf::PIZ_COMPRESSION, Layout::TiledMipmap}}) {
    const std::string path = dir.file("source.exr");
    write_with_openexr(path, depth_values(width, height, false), width, height, compression, Imf::HALF, layout);
    files.push_back(read_bytes(path));
  }

  std::mt19937 random(11);
  for (std::size_t f = 0; f < files.size(); ++f) {
    const std::string& good = files[f];
    INFO("file " << f << ", " << good.size() << " bytes");
    // Every truncation of a valid file is an error naming the file, except
    // that a mipmapped file cut within its smaller levels, which come last
    // and are not read, still gives the full-resolution image.
    const std::vector<float> whole = decode_exr(good.data(), good.size(), "whole.exr").to_host();
    int errors = 0, whole_images = 0;
    for (std::size_t n = 0; n < good.size(); ++n) {
      try {
        whole_images += same_bits(decode_exr(good.data(), n, "cut.exr").to_host(), whole) ? 1 : 0;
      } catch (const std::runtime_error& e) {
        errors += contains(e.what(), "read_exr: 'cut.exr'") ? 1 : 0;
      }
    }
    CHECK(errors + whole_images == int(good.size()));
    if (f + 1 < files.size()) CHECK(whole_images == 0);
    // Random damage: every result is an image or a runtime_error.
    int failures = 0;
    for (int trial = 0; trial < 150; ++trial) {
      std::string damaged = good;
      for (int k = 0; k < 3; ++k) damaged[random() % damaged.size()] = char(random());
      try {
        decode_exr(damaged.data(), damaged.size(), "damaged.exr");
      } catch (const std::runtime_error& error) {
        failures += contains(error.what(), "read_exr: 'damaged.exr'") ? 0 : 1;
      }
    }
    CHECK(failures == 0);
  }

  // Corrupt compressed data: OpenEXR's error, after the file's name.
  std::string bad = from_hex(float_zip_hex);
  bad[bad.size() - 20] = char(bad[bad.size() - 20] ^ 0x5a);
  bad[bad.size() - 21] = char(bad[bad.size() - 21] ^ 0xa5);
  const std::string corrupt = dir.write("corrupt.exr", bad);
  CHECK(contains(error_of([&] { read_exr(corrupt); }), "read_exr: '" + corrupt + "': OpenEXR: "));
}

#endif  // EMFUSION_HAS_OPENEXR
