// .klg logs: write/read round trips (raw and zlib depth, raw, JPEG and no
// colour), a log built byte by byte, every kind of bad file (errors name the
// file, the frame and its byte offset), and the command-line intrinsics
// (presets and "fx,fy,cx,cy[,w,h]").
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include <zlib.h>

#include "emfusion/io/frame_source.hpp"
#include "emfusion/io/intrinsics.hpp"
#include "emfusion/io/klg.hpp"
#include "support/catch.hpp"
#include "support/files.hpp"

using namespace emfusion;
using emfusion::test::Approx;
using emfusion::test::contains;
using emfusion::test::error_of;
using emfusion::test::read_bytes;
using emfusion::test::ScratchDir;
using emfusion::test::write_bytes;

static_assert(FrameSource<KlgSequence>);

namespace {

constexpr int W = 6, H = 4;

PinholeCamera<double> small_camera() { return PinholeCamera<double>{5.0, 5.5, 2.5, 1.5, W, H}; }

/// A WxH depth image with pixel k = base + 37 k, some zeros, one 65535.
Image<std::uint16_t, Host> depth_image(std::uint16_t base) {
  std::vector<std::uint16_t> pixels(W * H);
  for (std::size_t k = 0; k < pixels.size(); ++k) pixels[k] = std::uint16_t(base + 37 * k);
  pixels[3] = 0;
  pixels[10] = 0;
  pixels[W * H - 1] = 65535;
  return Image<std::uint16_t, Host>::from_host(W, H, pixels);
}

std::vector<KlgFrame> three_frames() {
  std::vector<KlgFrame> frames(3);
  frames[0].timestamp = 1305031102175304;
  frames[0].depth = depth_image(800);
  frames[0].colour.assign(W * H * 3, 7);  // raw RGB
  frames[1].timestamp = 1305031102211000;
  frames[1].depth = depth_image(1200);
  frames[1].colour = {0xff, 0xd8, 0xff, 0xe0, 1, 2, 3, 0xff, 0xd9};  // "JPEG" bytes, stored as given
  frames[2].timestamp = 1305031102243999;
  frames[2].depth = depth_image(4000);  // no colour
  return frames;
}

// Little-endian fields for logs built by hand.
void le32(std::string& s, std::int32_t v) {
  for (int k = 0; k < 4; ++k) s.push_back(char((std::uint32_t(v) >> (8 * k)) & 0xff));
}
void le64(std::string& s, std::int64_t v) {
  for (int k = 0; k < 8; ++k) s.push_back(char((std::uint64_t(v) >> (8 * k)) & 0xff));
}

std::string raw_depth_bytes(const Image<std::uint16_t, Host>& image) {
  std::string s;
  for (const std::uint16_t v : image.to_host()) {
    s.push_back(char(v & 0xff));
    s.push_back(char(v >> 8));
  }
  return s;
}

std::string zlib_bytes(const std::string& data) {
  uLongf size = compressBound(uLong(data.size()));
  std::string out(size, '\0');
  compress(reinterpret_cast<Bytef*>(out.data()), &size, reinterpret_cast<const Bytef*>(data.data()),
           uLong(data.size()));
  out.resize(size);
  return out;
}

/// One frame: header, depth bytes, colour bytes.
std::string frame_bytes(std::int64_t t, const std::string& depth, const std::string& colour = {}) {
  std::string s;
  le64(s, t);
  le32(s, std::int32_t(depth.size()));
  le32(s, std::int32_t(colour.size()));
  return s + depth + colour;
}

std::string count_bytes(std::int32_t count) {
  std::string s;
  le32(s, count);
  return s;
}

}  // namespace

TEST_CASE("KlgSequence reads what write_klg writes, raw and zlib depth", "[io][klg]") {
  ScratchDir dir;
  const std::vector<KlgFrame> frames = three_frames();
  for (const KlgDepthEncoding encoding : {KlgDepthEncoding::Raw, KlgDepthEncoding::Zlib}) {
    const bool zlib = encoding == KlgDepthEncoding::Zlib;
    const std::string path = dir.file(zlib ? "zlib.klg" : "raw.klg");
    write_klg(path, frames, encoding);
    const KlgSequence log = KlgSequence::open(path, small_camera());
    REQUIRE(log.size() == 3);
    CHECK(log.path() == path);
    CHECK(log.camera().fy == 5.5);
    for (std::size_t i = 0; i < 3; ++i) {
      CHECK(log.timestamp_us(i) == frames[i].timestamp);
      CHECK(log.timestamp(i) == double(frames[i].timestamp) / 1e6);
      CHECK(log.depth_is_compressed(i) == zlib);
      CHECK(log.raw_depth(i).to_host() == frames[i].depth.to_host());
      const std::vector<float> metres = log.depth(i).to_host();
      const std::vector<std::uint16_t> stored = frames[i].depth.to_host();
      bool exact = true;
      for (std::size_t k = 0; k < metres.size(); ++k)
        exact = exact && metres[k] == (stored[k] == 0 ? 0.f : float(double(stored[k]) / 1000.0));
      CHECK(exact);
      CHECK(log.colour_bytes(i) == frames[i].colour);
      CHECK(log.colour_size(i) == frames[i].colour.size());
    }
    CHECK(!log.colour_is_jpeg(0));
    CHECK(log.colour_is_jpeg(1));
    CHECK(!log.colour_is_jpeg(2));
    CHECK(log.timestamp(1) == Approx(1305031102.211));
    CHECK_THROWS_AS(log.depth(3), std::out_of_range);
  }
  // The raw log is 4 + 3 * 16 bytes of headers plus the data.
  CHECK(read_bytes(dir.file("raw.klg")).size() == 4 + 3 * 16 + 3 * W * H * 2 + W * H * 3 + 9);

  // Another depth scale.
  const KlgSequence tum = KlgSequence::open(dir.file("raw.klg"), small_camera(), 5000.0);
  CHECK(tum.depth(0).to_host()[0] == float(800.0 / 5000.0));
}

TEST_CASE("KlgSequence reads a log built byte by byte", "[io][klg]") {
  ScratchDir dir;
  const Image<std::uint16_t, Host> a = depth_image(100), b = depth_image(2000);
  const std::string colour(W * H * 3, 'c');
  const std::string log = count_bytes(2) + frame_bytes(-5, raw_depth_bytes(a), colour) +
                          frame_bytes(33333, zlib_bytes(raw_depth_bytes(b)), "\xff\xd8\xff");
  const std::string path = dir.write("hand.klg", log);
  const KlgSequence seq = KlgSequence::open(path, small_camera());
  REQUIRE(seq.size() == 2);
  CHECK(seq.timestamp_us(0) == -5);
  CHECK(seq.timestamp(1) == 0.033333);
  CHECK(seq.raw_depth(0).to_host() == a.to_host());
  CHECK(seq.raw_depth(1).to_host() == b.to_host());
  CHECK(seq.depth(1).to_host()[1] == float(2037.0 / 1000.0));
  CHECK(!seq.depth_is_compressed(0));
  CHECK(seq.depth_is_compressed(1));
  CHECK(!seq.colour_is_jpeg(0));
  CHECK(seq.colour_is_jpeg(1));
  CHECK(seq.colour_bytes(1) == std::vector<std::uint8_t>{0xff, 0xd8, 0xff});
}

TEST_CASE("KlgSequence reports bad logs with file, frame and byte offset", "[io][klg]") {
  ScratchDir dir;
  const std::string depth = raw_depth_bytes(depth_image(500));
  const std::string packed = zlib_bytes(depth);
  const std::string frame0 = frame_bytes(1000, depth);
  const std::string frame1 = frame_bytes(2000, packed);
  const auto open_error = [&](const std::string& name, const std::string& bytes) {
    const std::string path = dir.write(name, bytes);
    const std::string e = error_of([&] { KlgSequence::open(path, small_camera()); });
    CHECK(contains(e, "KlgSequence::open: '" + path + "'"));
    return e;
  };
  const std::string f1 = "frame 1 (byte offset " + std::to_string(4 + frame0.size()) + ")";

  SECTION("missing or unreadable") {
    const std::string path = dir.file("missing.klg");
    const std::string e = error_of([&] { KlgSequence::open(path, small_camera()); });
    CHECK(contains(e, "'" + path + "'"));
    CHECK(contains(e, "cannot open"));
  }
  SECTION("truncated header") { CHECK(contains(open_error("short.klg", "\x02\x00"), "truncated header")); }
  SECTION("negative, zero or absurd frame count") {
    CHECK(contains(open_error("neg.klg", count_bytes(-3) + frame0), "negative frame count -3"));
    CHECK(contains(open_error("zero.klg", count_bytes(0)), "no frames"));
    CHECK(contains(open_error("absurd.klg", count_bytes(1000000) + frame0), "absurd frame count 1000000"));
  }
  SECTION("more frames announced than present") {
    const std::string e = open_error("count.klg", count_bytes(3) + frame0 + frame1);
    CHECK(contains(e, "the header says 3 frames but the file ends after 2"));
  }
  SECTION("fewer frames announced than present") {
    CHECK(
        contains(open_error("trailing.klg", count_bytes(1) + frame0 + frame1), "bytes after the last of the 1 frames"));
  }
  SECTION("truncated frame") {
    const std::string whole = count_bytes(2) + frame0 + frame1;
    const std::string e = open_error("cut.klg", whole.substr(0, whole.size() - 5));
    CHECK(contains(e, f1));
    CHECK(contains(e, "run past the end of the file"));
    CHECK(contains(e, "truncated"));
    const std::string h = open_error("cuthead.klg", whole.substr(0, 4 + frame0.size() + 10));
    CHECK(contains(h, f1 + ": truncated frame header"));
  }
  SECTION("negative sizes") {
    std::string bad = frame1;
    bad[8 + 3] = char(0x80);  // depth size < 0
    CHECK(contains(open_error("negdepth.klg", count_bytes(2) + frame0 + bad), f1 + ": negative depth size"));
    bad = frame1;
    bad[12 + 3] = char(0xff);  // colour size < 0
    CHECK(contains(open_error("negcolour.klg", count_bytes(2) + frame0 + bad), f1 + ": negative colour size"));
  }
  SECTION("depth neither raw nor zlib") {
    // 100 bytes of something that is not a zlib stream.
    const std::string e = open_error("junk.klg", count_bytes(2) + frame0 + frame_bytes(2000, std::string(100, 'x')));
    CHECK(contains(e, f1));
    CHECK(contains(e, "not a zlib stream"));
    // A raw log opened with the wrong camera size.
    const std::string path = dir.write("size.klg", count_bytes(1) + frame0);
    PinholeCamera<double> wide = small_camera();
    wide.width = W + 1;
    CHECK(contains(error_of([&] { KlgSequence::open(path, wide); }), "is not 56 (raw 16-bit depth of 7x4)"));
  }
  SECTION("a zlib stream that is corrupt or of the wrong size fails when read") {
    std::string damaged = packed;
    damaged[damaged.size() / 2] = char(damaged[damaged.size() / 2] ^ 0x55);
    damaged[damaged.size() / 2 + 1] = char(damaged[damaged.size() / 2 + 1] ^ 0xaa);
    const std::string path = dir.write("damaged.klg", count_bytes(2) + frame0 + frame_bytes(2000, damaged));
    const KlgSequence seq = KlgSequence::open(path, small_camera());
    CHECK(seq.depth(0).width() == W);
    const std::string e = error_of([&] { seq.depth(1); });
    CHECK(contains(e, "KlgSequence::depth: '" + path + "': " + f1));
    CHECK(contains(e, "zlib"));

    const std::string longer = zlib_bytes(depth + "xx");
    const std::string path2 = dir.write("long.klg", count_bytes(2) + frame0 + frame_bytes(2000, longer));
    CHECK(contains(error_of([&] { KlgSequence::open(path2, small_camera()).depth(1); }),
                   "decodes to more than the expected 48 bytes"));
    const std::string shorter = zlib_bytes(depth.substr(0, 40));
    const std::string path3 = dir.write("shorter.klg", count_bytes(2) + frame0 + frame_bytes(2000, shorter));
    CHECK(contains(error_of([&] { KlgSequence::open(path3, small_camera()).depth(1); }),
                   "decodes to 40 bytes, expected 48"));
    const std::string path4 =
        dir.write("cutzlib.klg", count_bytes(2) + frame0 + frame_bytes(2000, packed.substr(0, packed.size() - 6)));
    CHECK(contains(error_of([&] { KlgSequence::open(path4, small_camera()).depth(1); }), "truncated"));
  }
  SECTION("timestamps that do not increase") {
    const std::string e = open_error("time.klg", count_bytes(2) + frame0 + frame_bytes(1000, packed));
    CHECK(contains(e, f1 + ": timestamp 1000 us is not after the previous frame's (1000 us)"));
  }
  SECTION("bad arguments") {
    const std::string path = dir.write("ok.klg", count_bytes(1) + frame0);
    CHECK_THROWS_AS(KlgSequence::open(path, small_camera(), 0.0), std::invalid_argument);
    PinholeCamera<double> camera = small_camera();
    camera.fx = -1;
    CHECK_THROWS_AS(KlgSequence::open(path, camera), std::invalid_argument);
    CHECK(KlgSequence::open(path, small_camera()).size() == 1);
  }
  SECTION("every truncation of a good log is an error") {
    const std::string whole = count_bytes(2) + frame0 + frame1;
    int named = 0;
    for (std::size_t n = 0; n < whole.size(); n += 3) {
      const std::string path = dir.write("prefix.klg", whole.substr(0, n));
      named += contains(error_of([&] { KlgSequence::open(path, small_camera()); }), path) ? 1 : 0;
    }
    CHECK(named == int((whole.size() + 2) / 3));
  }
}

TEST_CASE("write_klg refuses frames it could not write", "[io][klg]") {
  ScratchDir dir;
  const std::string path = dir.file("out.klg");
  CHECK(contains(error_of([&] { write_klg(path, {}); }), "no frames"));
  std::vector<KlgFrame> frames = three_frames();
  frames[2].timestamp = frames[1].timestamp;
  CHECK(contains(error_of([&] { write_klg(path, frames); }), "frame 2: timestamp"));
  frames = three_frames();
  frames[1].depth = Image<std::uint16_t, Host>(W + 1, H);
  CHECK(contains(error_of([&] { write_klg(path, frames); }), "frame 1: the depth image is 7x4, frame 0's is 6x4"));
  frames = three_frames();
  frames[0].depth = Image<std::uint16_t, Host>();
  CHECK_THROWS_AS(write_klg(path, frames), std::invalid_argument);
  CHECK(!std::filesystem::exists(path));
}

TEST_CASE("Intrinsics presets and command-line text", "[io][intrinsics]") {
  const PinholeCamera<double> d = intrinsics_preset("default");
  CHECK((d.fx == 525 && d.fy == 525 && d.cx == 319.5 && d.cy == 239.5 && d.width == 640 && d.height == 480));
  const PinholeCamera<double> fr1 = intrinsics_preset("fr1");
  CHECK((fr1.fx == 517.3 && fr1.fy == 516.5 && fr1.cx == 318.6 && fr1.cy == 255.3));
  const PinholeCamera<double> fr2 = intrinsics_preset("FR2");
  CHECK((fr2.fx == 520.9 && fr2.fy == 521.0 && fr2.cx == 325.1 && fr2.cy == 249.7 && fr2.width == 640));
  const PinholeCamera<double> fr3 = intrinsics_preset("fr3");
  CHECK((fr3.fx == 535.4 && fr3.fy == 539.2 && fr3.cx == 320.1 && fr3.cy == 247.6 && fr3.height == 480));
  const std::string e = error_of([] { intrinsics_preset("fr4"); });
  CHECK(contains(e, "unknown preset 'fr4'"));
  CHECK(contains(e, "default, fr1, fr2, fr3"));

  const PinholeCamera<double> c = parse_intrinsics("500, 501.5,320,240.25");
  CHECK((c.fx == 500 && c.fy == 501.5 && c.cx == 320 && c.cy == 240.25 && c.width == 640 && c.height == 480));
  const PinholeCamera<double> s = parse_intrinsics("360,360,319.5,239.5,320,240");
  CHECK((s.width == 320 && s.height == 240));
  CHECK(intrinsics_from_argument("fr1").fx == 517.3);
  CHECK(intrinsics_from_argument("1,2,3,4").fy == 2);

  for (const auto& [text, problem] : std::vector<std::pair<std::string, std::string>>{
           {"", "1 fields"},
           {"1,2,3", "3 fields"},
           {"1,2,3,4,5", "5 fields"},
           {"1,2,,4", "cx is empty"},
           {"1,2,x,4", "cx 'x' is not a finite number"},
           {"1,2,3,4abc", "cy '4abc' is not a finite number"},
           {"1,2,3,inf", "cy 'inf' is not a finite number"},
           {"0,2,3,4", "fx 0 is not positive"},
           {"1,-2,3,4", "fy -2 is not positive"},
           {"1,2,3,4,640.5,480", "width 640.5 is not a positive integer"},
           {"1,2,3,4,640,0", "height 0 is not a positive integer"},
       }) {
    const std::string error = error_of([&] { parse_intrinsics(text); });
    CHECK(contains(error, "parse_intrinsics: '" + text + "': " + problem));
  }
  CHECK_THROWS_AS(parse_intrinsics("1,2"), std::invalid_argument);
  CHECK(contains(error_of([] { intrinsics_from_argument("525"); }), "neither a preset nor fx,fy,cx,cy"));
}
