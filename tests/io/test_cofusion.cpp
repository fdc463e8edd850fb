// Co-Fusion image folders written on the fly: numbering from 0 or 1,
// timestamps from the frame rate, depth in metres from EXR, the camera from
// the options, calibration.txt or colour/calibration.txt, and bad folders
// (missing folders or files, gaps, wrong image sizes), each error naming the
// folder or file. Depth frames are EXR: built without OpenEXR, only the
// error that says so is tested.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "emfusion/io/cofusion.hpp"
#include "emfusion/io/exr.hpp"
#include "emfusion/io/frame_source.hpp"
#include "emfusion/io/png.hpp"
#include "support/catch.hpp"
#include "support/files.hpp"

using namespace emfusion;
namespace fs = std::filesystem;
using emfusion::test::contains;
using emfusion::test::error_of;
using emfusion::test::ScratchDir;

static_assert(FrameSource<CoFusionSequence>);

namespace {

constexpr int W = 5, H = 3;

#if EMFUSION_HAS_OPENEXR

/// Depth of frame n: 1 + n/10 + pixel/100 metres.
Image<float, Host> frame_depth(long n, int width = W, int height = H) {
  Image<float, Host> image(width, height);
  for (int k = 0; k < image.size(); ++k) image.view()[k] = 1.f + float(n) / 10.f + float(k) / 100.f;
  return image;
}

void write_colour(const std::string& path) {
  fs::create_directories(fs::path(path).parent_path());
  write_png(path, Image<std::uint8_t, Host>(W, H, 128));
}

void write_depth(const std::string& path, const Image<float, Host>& image) {
  fs::create_directories(fs::path(path).parent_path());
  write_exr(path, image);
}

/// Frames numbered first .. first + count - 1, and calibration.txt.
void write_folder(const ScratchDir& dir, long first, long count) {
  dir.write("calibration.txt", "4 4.5 2 1 5 3\n");
  for (long n = first; n < first + count; ++n) {
    char name[64];
    std::snprintf(name, sizeof(name), "colour/Color%04ld.png", n);
    write_colour(dir.file(name));
    std::snprintf(name, sizeof(name), "depth/Depth%04ld.exr", n);
    write_depth(dir.file(name), frame_depth(n));
  }
}

}  // namespace

TEST_CASE("CoFusionSequence reads numbered colour and depth folders", "[io][cofusion]") {
  for (const long first : {0L, 1L}) {
    ScratchDir dir;
    write_folder(dir, first, 4);
    dir.write("colour/notes.txt", "ignored");
    dir.write("depth/Depth12.exr", "ignored: not %04d");
    const CoFusionSequence seq = CoFusionSequence::open(dir.path());
    REQUIRE(seq.size() == 4);
    CHECK(seq.first_number() == first);
    CHECK(seq.camera().fy == 4.5);
    CHECK(seq.camera().width == W);
    CHECK(seq.camera_source() == dir.file("calibration.txt"));
    for (std::size_t i = 0; i < 4; ++i) {
      CHECK(seq.timestamp(i) == double(i) / 30.0);
      CHECK(seq.depth(i).to_host() == frame_depth(first + long(i)).to_host());
    }
    CHECK(fs::path(seq.depth_path(2)).filename() == (first == 0 ? "Depth0002.exr" : "Depth0003.exr"));
    CHECK(fs::path(seq.colour_path(0)).filename() == (first == 0 ? "Color0000.png" : "Color0001.png"));
    CHECK_THROWS_AS(seq.depth(4), std::out_of_range);
  }
}

TEST_CASE("CoFusionSequence options, calibration sources and invalid depths", "[io][cofusion]") {
  ScratchDir dir;
  write_folder(dir, 1, 2);
  Image<float, Host> odd = frame_depth(3);
  odd.view()[0] = std::numeric_limits<float>::quiet_NaN();
  odd.view()[1] = -2.f;
  odd.view()[2] = std::numeric_limits<float>::infinity();
  write_depth(dir.file("depth/Depth0002.exr"), odd);

  CoFusionOptions options;
  options.frame_rate = 10;
  options.camera = PinholeCamera<double>{100, 100, 2, 1, W, H};
  const CoFusionSequence seq = CoFusionSequence::open(dir.path(), options);
  CHECK(seq.camera().fx == 100);
  CHECK(seq.camera_source() == "CoFusionOptions::camera");
  CHECK(seq.timestamp(1) == 0.1);
  const std::vector<float> depth = seq.depth(1).to_host();
  CHECK((depth[0] == 0.f && depth[1] == 0.f && depth[2] == 0.f && depth[3] == odd.to_host()[3]));

  // Co-Fusion keeps calibration.txt in the colour folder.
  fs::rename(dir.file("calibration.txt"), dir.file("colour/calibration.txt"));
  const CoFusionSequence colour_calibration = CoFusionSequence::open(dir.path());
  CHECK(colour_calibration.camera_source() == dir.file("colour/calibration.txt"));
  CHECK(colour_calibration.camera().fx == 4);

  fs::remove(dir.file("colour/calibration.txt"));
  const std::string e = error_of([&] { CoFusionSequence::open(dir.path()); });
  CHECK(contains(e, "CoFusionSequence::open: '" + dir.path() + "'"));
  CHECK(contains(e, "no calibration.txt"));

  options.frame_rate = 0;
  CHECK_THROWS_AS(CoFusionSequence::open(dir.path(), options), std::invalid_argument);
}

TEST_CASE("CoFusionSequence reports bad folders and files", "[io][cofusion]") {
  ScratchDir dir;
  const std::string missing = dir.file("nothing");
  CHECK(contains(error_of([&] { CoFusionSequence::open(missing); }), "'" + missing + "': directory not found"));

  SECTION("missing folders or frames") {
    dir.write("calibration.txt", "4 4.5 2 1 5 3\n");
    CHECK(contains(error_of([&] { CoFusionSequence::open(dir.path()); }), "no folder 'colour'"));
    fs::create_directories(dir.file("colour"));
    CHECK(contains(error_of([&] { CoFusionSequence::open(dir.path()); }), "no folder 'depth'"));
    fs::create_directories(dir.file("depth"));
    CHECK(contains(error_of([&] { CoFusionSequence::open(dir.path()); }), "no frames"));
  }
  SECTION("a colour frame without depth, and a depth frame without colour") {
    write_folder(dir, 1, 4);
    fs::remove(dir.file("depth/Depth0003.exr"));
    const std::string e = error_of([&] { CoFusionSequence::open(dir.path()); });
    CHECK(contains(e, "'" + dir.file("depth/Depth0003.exr") + "': not found"));
    CHECK(contains(e, "Color0003.png"));
    write_depth(dir.file("depth/Depth0003.exr"), frame_depth(3));
    fs::remove(dir.file("colour/Color0004.png"));
    const std::string f = error_of([&] { CoFusionSequence::open(dir.path()); });
    CHECK(contains(f, "'" + dir.file("colour/Color0004.png") + "': not found"));
    CHECK(contains(f, "Depth0004.exr"));
  }
  SECTION("a gap in the numbering") {
    write_folder(dir, 0, 2);
    write_colour(dir.file("colour/Color0005.png"));
    write_depth(dir.file("depth/Depth0005.exr"), frame_depth(5));
    const std::string e = error_of([&] { CoFusionSequence::open(dir.path()); });
    CHECK(contains(e, "gap in the frame numbering"));
    CHECK(contains(e, "Color0002.png"));
    CHECK(contains(e, "from 0 to 5"));
  }
  SECTION("a depth image of another size than the calibration") {
    write_folder(dir, 0, 2);
    write_depth(dir.file("depth/Depth0001.exr"), frame_depth(1, W + 1, H));
    const CoFusionSequence seq = CoFusionSequence::open(dir.path());
    CHECK(seq.depth(0).width() == W);
    const std::string e = error_of([&] { seq.depth(1); });
    CHECK(contains(e, "CoFusionSequence::depth: '" + dir.file("depth/Depth0001.exr") + "'"));
    CHECK(contains(e, "the image is 6x3 but the camera"));
    CHECK(contains(e, "is 5x3"));
  }
  SECTION("a damaged EXR") {
    write_folder(dir, 0, 1);
    dir.write("depth/Depth0000.exr", "garbage");
    const CoFusionSequence seq = CoFusionSequence::open(dir.path());
    CHECK(contains(error_of([&] { seq.depth(0); }), "read_exr: '" + dir.file("depth/Depth0000.exr") + "'"));
  }
}

#else  // EMFUSION_HAS_OPENEXR

}  // namespace

TEST_CASE("CoFusionSequence without OpenEXR fails reading depth, naming the file and the missing library",
          "[io][cofusion]") {
  ScratchDir dir;
  dir.write("calibration.txt", "4 4.5 2 1 5 3\n");
  fs::create_directories(dir.file("colour"));
  write_png(dir.file("colour/Color0000.png"), Image<std::uint8_t, Host>(W, H, 128));
  dir.write("depth/Depth0000.exr", "not read: this build cannot read EXR");
  const CoFusionSequence seq = CoFusionSequence::open(dir.path());
  const std::string e = error_of([&] { seq.depth(0); });
  CHECK(contains(e, "read_exr: '" + dir.file("depth/Depth0000.exr") + "'"));
  CHECK(contains(e, "no OpenEXR support"));
}

#endif  // EMFUSION_HAS_OPENEXR
