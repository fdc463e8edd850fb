// OpenEXR: files written by the OpenEXR library itself (ZIP, ZIPS, NONE;
// HALF and FLOAT; several channels; an offset data window), a file built
// byte by byte from the format's description, write/read round trips of
// every compression, and unsupported features, truncated and corrupt files
// (each an error naming the file and the problem, never a crash).
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "emfusion/io/exr.hpp"
#include "support/catch.hpp"
#include "support/files.hpp"

using namespace emfusion;
using emfusion::test::contains;
using emfusion::test::error_of;
using emfusion::test::read_bytes;
using emfusion::test::ScratchDir;
using emfusion::test::write_bytes;

namespace {

// Written by OpenEXR 3.1.5 (Debian's libopenexr-dev) with Imf::OutputFile:
// channel number c (in the order of insertion) holds, at pixel (x, y) of the
// data window, 0.25 x + 1.5 y + 10 c + 0.125, which HALF stores exactly.
//   float_zip:     5x20, channel Z FLOAT, ZIP (two chunks, the second of 4 lines)
//   half_zips:     40x3, channel Y HALF, ZIPS
//   mixed_zip:     6x18, channels A (c=0, HALF) and Z (c=1, FLOAT), ZIP
//   rgb_half_none: 4x3, data window (2,3)-(5,5), channels R, G, B (c=0,1,2;
//                  stored B, G, R), HALF, no compression

const char* const float_zip_hex =
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

const char* const half_zips_hex =
    "762f3101020000006368616e6e656c730063686c69737400130000005900010000000000000001000000010000000063"
    "6f6d7072657373696f6e00636f6d7072657373696f6e0001000000026461746157696e646f7700626f78326900100000"
    "0000000000000000002700000002000000646973706c617957696e646f7700626f783269001000000000000000000000"
    "0029000000040000006c696e654f72646572006c696e654f72646572000100000000706978656c417370656374526174"
    "696f00666c6f617400040000000000803f73637265656e57696e646f7743656e74657200763266000800000000000000"
    "0000000073637265656e57696e646f77576964746800666c6f617400040000000000803f002d010000000000005c0100"
    "000000000084010000000000000000000027000000785e63686868600062070608787000156c58000107da9a9b1a41a0"
    "01061b30300800002d1e28c90100000020000000785e6b6870608080070750c18605c880afb1b101061b303008406800"
    "86c129ca020000001e000000785e73606060787000156c588009821a1a81b001038300320d0062cb2ccb";

const char* const mixed_zip_hex =
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

const char* const rgb_half_none_hex =
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

float reference_value(int x, int y, int c) { return 0.25f * float(x) + 1.5f * float(y) + 10.f * float(c) + 0.125f; }

std::string from_hex(const char* hex) {
  std::string out;
  for (std::size_t k = 0; hex[k] && hex[k + 1]; k += 2)
    out.push_back(char(std::stoi(std::string(hex + k, 2), nullptr, 16)));
  return out;
}

/// Largest |image - reference_value(., ., c)|.
double reference_error(const Image<float, Host>& image, int c) {
  double error = 0;
  const auto v = image.view();
  for (int y = 0; y < v.height; ++y)
    for (int x = 0; x < v.width; ++x) error = std::max(error, std::abs(double(v(x, y)) - reference_value(x, y, c)));
  return error;
}

// Little-endian fields for files built by hand (deliberately not the
// library's helpers).
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
/// FLOAT) with the given samples (2 or 4 bytes each, row by row), sampling
/// `sampling`, `version` in the version field.
std::string hand_built(const std::vector<std::uint32_t>& samples, int pixel_type = 1, const std::string& name = "depth",
                       std::uint32_t version = 2, int sampling = 1) {
  const int bytes = pixel_type == 1 ? 2 : 4;
  std::string s;
  le32(s, 20000630);
  le32(s, version);
  std::string channels = name + '\0';
  le32(channels, std::uint32_t(pixel_type));
  channels += std::string(4, '\0');  // pLinear, reserved
  le32(channels, std::uint32_t(sampling));
  le32(channels, std::uint32_t(sampling));
  channels += '\0';
  attribute(s, "channels", "chlist", channels);
  attribute(s, "compression", "compression", std::string(1, '\0'));
  std::string box;
  for (std::uint32_t v : {0u, 0u, 2u, 1u}) le32(box, v);
  attribute(s, "dataWindow", "box2i", box);
  attribute(s, "displayWindow", "box2i", box);
  attribute(s, "lineOrder", "lineOrder", std::string(1, '\0'));
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

Image<float, Host> ramp(int width, int height) {
  Image<float, Host> image(width, height);
  const auto v = image.view();
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) v(x, y) = 0.5f + 0.001f * float(x) + 0.01f * float(y) + (x % 3 == 0 ? 0.f : 1e-4f);
  return image;
}

bool same_bits(float a, float b) { return std::memcmp(&a, &b, sizeof(float)) == 0; }

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
}

TEST_CASE("read_exr reads a file built byte by byte from the format description", "[io][exr]") {
  ScratchDir dir;
  // HALF: 1, 2, 0.5 / smallest subnormal 2^-24, +infinity, -2.
  const std::string path = dir.write("half.exr", hand_built({0x3c00, 0x4000, 0x3800, 0x0001, 0x7c00, 0xc000}));
  const std::vector<float> v = read_exr(path).to_host();
  REQUIRE(v.size() == 6);
  CHECK(v[0] == 1.f);
  CHECK(v[1] == 2.f);
  CHECK(v[2] == 0.5f);
  CHECK(v[3] == std::ldexp(1.f, -24));
  CHECK(v[4] == std::numeric_limits<float>::infinity());
  CHECK(v[5] == -2.f);
  // A NaN half stays NaN; the largest half is 65504; a subnormal with more bits.
  const std::vector<float> w =
      read_exr(dir.write("half2.exr", hand_built({0x7e00, 0x7bff, 0x03ff, 0x8000, 0x3555, 0x0200}))).to_host();
  CHECK(std::isnan(w[0]));
  CHECK(w[1] == 65504.f);
  CHECK(w[2] == std::ldexp(1023.f, -24));
  CHECK((w[3] == 0.f && std::signbit(w[3])));
  CHECK(w[4] == std::ldexp(float(0x400 + 0x155), -2 - 10));  // 0x3555: exponent 13 - 15, mantissa 0x155
  CHECK(w[5] == std::ldexp(1.f, -15));
  // FLOAT samples are the IEEE bits, little-endian.
  std::uint32_t bits;
  const float value = 1.25f;
  std::memcpy(&bits, &value, 4);
  const std::vector<float> f = read_exr(dir.write("float.exr", hand_built({bits, 0, bits, 0, 0, bits}, 2))).to_host();
  CHECK(f == std::vector<float>{1.25f, 0.f, 1.25f, 0.f, 0.f, 1.25f});
}

TEST_CASE("write_exr round-trips floats exactly with every compression", "[io][exr]") {
  ScratchDir dir;
  Image<float, Host> image = ramp(67, 37);  // 37 = two full ZIP chunks and a partial one
  image.view()(1, 2) = 0.f;
  image.view()(2, 2) = std::numeric_limits<float>::infinity();
  image.view()(3, 2) = std::numeric_limits<float>::quiet_NaN();
  image.view()(4, 2) = -1.5f;
  const std::vector<float> expected = image.to_host();
  std::size_t sizes[3] = {};
  int k = 0;
  for (const ExrCompression c : {ExrCompression::None, ExrCompression::Zips, ExrCompression::Zip}) {
    const std::string path = dir.file("depth" + std::to_string(k) + ".exr");
    write_exr(path, image, {c, "Z"});
    const Image<float, Host> back = read_exr(path);
    REQUIRE(back.same_size(67, 37));
    const std::vector<float> got = back.to_host();
    bool same = true;
    for (std::size_t i = 0; i < got.size(); ++i) same = same && same_bits(got[i], expected[i]);
    CHECK(same);
    // Depth on a coarse grid (few mantissa bits) compresses, line by line too.
    Image<float, Host> coarse(67, 37);
    for (int i = 0; i < coarse.size(); ++i) coarse.view()[i] = 1.f + float(i % 67 / 8) / 64.f;
    const std::string coarse_path = dir.file("coarse" + std::to_string(k) + ".exr");
    write_exr(coarse_path, coarse, {c, "Z"});
    CHECK(read_exr(coarse_path).to_host() == coarse.to_host());
    sizes[k++] = read_bytes(coarse_path).size();
  }
  CHECK(sizes[1] < sizes[0]);
  CHECK(sizes[2] < sizes[1]);
  // decode_exr reads the same bytes from memory.
  const std::string coarse_bytes = read_bytes(dir.file("coarse2.exr"));
  CHECK(decode_exr(coarse_bytes.data(), coarse_bytes.size(), "mem").to_host() ==
        read_exr(dir.file("coarse2.exr")).to_host());
  CHECK_THROWS_WITH(decode_exr(coarse_bytes.data(), 7, "mem"), EMF_CONTAINS("read_exr: 'mem': not an OpenEXR file"));

  // Data zlib cannot shrink is stored raw inside a ZIP file, and still reads.
  Image<float, Host> noise(9, 5);
  std::mt19937 random(7);
  for (int i = 0; i < noise.size(); ++i) {
    const std::uint32_t bits = std::uint32_t(random()) & 0x3fffffffu;  // finite
    std::memcpy(&noise.view()[i], &bits, 4);
  }
  const std::string path = dir.file("noise.exr");
  write_exr(path, noise, {ExrCompression::Zip, "depth"});
  CHECK(read_exr(path).to_host() == noise.to_host());

  // The layout of the start, independently of the reader.
  const std::string bytes = read_bytes(dir.file("depth0.exr"));
  CHECK(bytes.substr(0, 8) == std::string("\x76\x2f\x31\x01\x02\x00\x00\x00", 8));
  CHECK(contains(bytes, std::string("channels\0chlist\0", 16)));
  CHECK(contains(bytes, std::string("compression\0compression\0\x01\0\0\0\0", 29)));

  CHECK(contains(error_of([&] { write_exr(dir.file("e.exr"), Image<float, Host>()); }), "empty"));
  CHECK(contains(error_of([&] { write_exr(dir.file("e.exr"), image, {ExrCompression::Zip, ""}); }), "channel name"));
  CHECK_THROWS_AS(write_exr(dir.file("e.exr"), image, {ExrCompression::Zip, std::string(32, 'a')}),
                  std::invalid_argument);
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
  CHECK(contains(error("tiled.exr", hand_built(ones, 1, "depth", 2 | 0x200)), "tiled"));
  CHECK(contains(error("multi.exr", hand_built(ones, 1, "depth", 2 | 0x1000)), "multi-part"));
  CHECK(contains(error("deep.exr", hand_built(ones, 1, "depth", 2 | 0x800)), "deep"));
  CHECK(contains(error("v1.exr", hand_built(ones, 1, "depth", 1)), "version 1"));
  CHECK(contains(error("uint.exr", hand_built({1, 2, 3, 4, 5, 6}, 0)), "UINT"));
  CHECK(contains(error("sub.exr", hand_built(ones, 1, "depth", 2, 2)), "subsampled"));
  CHECK(contains(error("type.exr", hand_built(ones, 7)), "unknown pixel type 7"));

  // Other compressions: patch the compression byte of a written file.
  Image<float, Host> image = ramp(4, 4);
  const std::string path = dir.file("piz.exr");
  write_exr(path, image, {ExrCompression::None, "Z"});
  std::string bytes = read_bytes(path);
  const std::string key = std::string("compression\0compression\0\x01\0\0\0", 28);
  const std::size_t at = bytes.find(key);
  REQUIRE(at != std::string::npos);
  for (const auto& [code, name] : std::vector<std::pair<char, std::string>>{
           {1, "RLE"}, {4, "PIZ"}, {5, "PXR24"}, {6, "B44"}, {8, "DWAA"}, {42, "unknown (code 42)"}}) {
    bytes[at + key.size()] = code;
    CHECK(contains(error("c.exr", bytes), name + " compression"));
  }
}

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

TEST_CASE("read_exr reports truncated and corrupt files without reading out of bounds", "[io][exr]") {
  ScratchDir dir;
  const std::string missing = dir.file("missing.exr");
  CHECK(contains(error_of([&] { read_exr(missing); }), "cannot open"));
  const std::string text = dir.write("text.exr", "P6 not an exr file");
  CHECK(contains(error_of([&] { read_exr(text); }), "not an OpenEXR file"));
  CHECK(contains(error_of([&] { read_exr(dir.write("short.exr", "v/1")); }), "not an OpenEXR file"));

  const std::string good = from_hex(float_zip_hex);
  // Every truncation of a valid file is an error naming the file.
  int errors = 0;
  for (std::size_t n = 0; n < good.size(); ++n) {
    const std::string path = dir.write("cut.exr", good.substr(0, n));
    const std::string e = error_of([&] { read_exr(path); });
    errors += contains(e, "read_exr: '" + path + "'") ? 1 : 0;
  }
  CHECK(errors == int(good.size()));
  const std::string last = dir.write("cut.exr", good.substr(0, good.size() - 1));
  CHECK(contains(error_of([&] { read_exr(last); }), "chunk 1 (byte offset"));

  // Corrupt compressed data names the chunk and the zlib problem.
  std::string bad = good;
  bad[bad.size() - 20] = char(bad[bad.size() - 20] ^ 0x5a);
  bad[bad.size() - 21] = char(bad[bad.size() - 21] ^ 0xa5);
  const std::string corrupt = dir.write("corrupt.exr", bad);
  const std::string e = error_of([&] { read_exr(corrupt); });
  CHECK(contains(e, "chunk 1"));
  CHECK(contains(e, "zlib"));

  // An offset table entry pointing outside the file.
  std::string far = hand_built(std::vector<std::uint32_t>(6, 0x3c00));
  const std::size_t table = far.size() - 2 * (8 + 6) - 16;
  far[table + 8 + 5] = 1;  // chunk 1 offset += 2^40
  CHECK(contains(error_of([&] { read_exr(dir.write("far.exr", far)); }), "chunk 1 (byte offset"));
  // A chunk starting at the wrong scanline.
  std::string wrong = hand_built(std::vector<std::uint32_t>(6, 0x3c00));
  wrong[table + 16] = 5;
  CHECK(contains(error_of([&] { read_exr(dir.write("wrong.exr", wrong)); }), "scanline y = 5, expected 0"));
  // A chunk whose size is not that of its pixels.
  std::string size = hand_built(std::vector<std::uint32_t>(6, 0x3c00));
  size[table + 16 + 4] = 4;
  CHECK(contains(error_of([&] { read_exr(dir.write("size.exr", size)); }), "4 bytes of uncompressed data, expected 6"));

  // Random damage: every result is an image or a runtime_error.
  std::mt19937 random(11);
  int failures = 0;
  for (int trial = 0; trial < 300; ++trial) {
    std::string damaged = good;
    for (int k = 0; k < 3; ++k) damaged[random() % damaged.size()] = char(random());
    const std::string path = dir.write("damaged.exr", damaged);
    try {
      read_exr(path);
    } catch (const std::runtime_error& error) {
      failures += contains(error.what(), path) ? 0 : 1;
    }
  }
  CHECK(failures == 0);
}
