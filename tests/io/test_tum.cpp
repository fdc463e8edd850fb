// TUM formats: trajectory and calibration files (round trips, comments,
// errors naming file and line), sequence directories written on the fly
// (associations, nearest-timestamp pairing of rgb.txt and depth.txt, depth in
// metres, camera sources, depth-only copies, bad input), and the real
// redkitchen_300 sequence when shared/data is there.
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "emfusion/io/frame_source.hpp"
#include "emfusion/io/tum.hpp"
#include "support/catch.hpp"
#include "support/files.hpp"

using namespace emfusion;
namespace fs = std::filesystem;
using emfusion::test::ScratchDir;
using emfusion::test::contains;
using emfusion::test::error_of;
using emfusion::test::read_bytes;
using emfusion::test::write_bytes;

using emfusion::test::Approx;

static_assert(FrameSource<TumSequence>);

namespace {



double max_abs_difference(const SE3<double>& a, const SE3<double>& b) {
  double d = 0;
  for (int r = 0; r < 3; ++r) {
    d = std::max(d, std::abs(a.translation()[r] - b.translation()[r]));
    for (int c = 0; c < 3; ++c) d = std::max(d, std::abs(a.rotation()(r, c) - b.rotation()(r, c)));
  }
  return d;
}

double translation_difference(const SE3<double>& a, const SE3<double>& b) {
  double d = 0;
  for (int r = 0; r < 3; ++r) d = std::max(d, std::abs(a.translation()[r] - b.translation()[r]));
  return d;
}

double quaternion_difference(const SE3<double>& a, const SE3<double>& b) {
  const auto qa = a.quaternion(), qb = b.quaternion();
  double d = 0;
  for (int k = 0; k < 4; ++k) d = std::max(d, std::abs(qa[k] - qb[k]));
  return d;
}

/// An 8x6 depth PNG whose pixel k holds values[k % values.size()].
void write_depth(const std::string& path, const std::vector<std::uint16_t>& values, int width = 8, int height = 6) {
  std::vector<std::uint16_t> pixels(std::size_t(width * height));
  for (std::size_t k = 0; k < pixels.size(); ++k) pixels[k] = values[k % values.size()];
  fs::create_directories(fs::path(path).parent_path());
  write_png(path, Image<std::uint16_t, Host>::from_host(width, height, pixels));
}

/// A small sequence without associations.txt: depth at 1.0 .. 1.4 s, rgb
/// near them, except the depth frame at 1.2 s whose nearest rgb frame is
/// 0.03 s away. The depth frame at 1.4 s has an rgb frame exactly 0.02 s
/// after it (kept).
void write_pairing_sequence(const ScratchDir& dir) {
  dir.write("calibration.txt", "# fx fy cx cy width height\n4 4.5 3.5 2.5 8 6\n");
  dir.write("depth.txt",
            "# timestamp filename\n"
            "1.000000 depth/1.000000.png\n"
            "1.100000 depth/1.100000.png\n"
            "\n"
            "1.200000 depth/1.200000.png   # no rgb within 0.02 s\n"
            "1.300000\tdepth/1.300000.png\r\n"
            "1.400000 depth/1.400000.png\n");
  dir.write("rgb.txt",
            "# timestamp filename\n"
            "1.010000 rgb/1.010000.jpg\n"
            "1.095000 rgb/1.095000.jpg\n"
            "1.230000 rgb/1.230000.jpg\n"
            "1.305000 rgb/1.305000.jpg\n"
            "1.420000 rgb/1.420000.jpg\n");
  for (const char* t : {"1.010000", "1.095000", "1.230000", "1.305000", "1.420000"})
    dir.write(std::string("rgb/") + t + ".jpg", "not read by the depth reader");
  write_depth(dir.file("depth/1.000000.png"), {5000, 0, 12345, 65535});
  for (const char* t : {"1.100000", "1.200000", "1.300000", "1.400000"})
    write_depth(dir.file(std::string("depth/") + t + ".png"), {2500});
}

}  // namespace

// ---- trajectories -----------------------------------------------------------------

TEST_CASE("TUM trajectories round-trip through write and read", "[io][tum]") {
  ScratchDir dir;
  std::mt19937 rng(7);
  std::normal_distribution<double> n(0.0, 1.0);
  std::vector<TimedPose> poses;
  double t = 1305031102.175304;
  for (int i = 0; i < 200; ++i) {
    SE3<double>::Tangent xi{};
    for (int k = 0; k < 6; ++k) xi[k] = (k < 3 ? 3.0 : 1.5) * n(rng);
    poses.push_back({t, SE3<double>::exp(xi)});
    t += 0.01 + 0.05 * std::abs(n(rng));
  }
  // Rotations by about pi and the identity, where the quaternion is fragile.
  poses[0].pose = SE3<double>::identity();
  poses[1].pose = SE3<double>(so3_exp(vec3(0.0, 3.14159265358979, 0.0)), vec3(-1e3, 0.0, 1e-9));

  const std::string path = dir.file("traj.txt");
  write_tum_trajectory(path, poses);
  CHECK_FALSE(fs::exists(path + ".tmp"));
  const std::vector<TimedPose> back = read_tum_trajectory(path);
  REQUIRE(back.size() == poses.size());
  double worst_t = 0, worst_translation = 0, worst_quaternion = 0, worst_rotation = 0;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    worst_t = std::max(worst_t, std::abs(back[i].timestamp - poses[i].timestamp));
    worst_translation = std::max(worst_translation, translation_difference(back[i].pose, poses[i].pose));
    worst_quaternion = std::max(worst_quaternion, quaternion_difference(back[i].pose, poses[i].pose));
    worst_rotation = std::max(worst_rotation, max_abs_difference(back[i].pose, poses[i].pose));
  }
  CAPTURE(worst_t, worst_translation, worst_quaternion, worst_rotation);
  CHECK(worst_t <= 1e-6);  // written with 6 decimals
  // Translation and quaternion are written with 9 decimals (error <= 5e-10
  // each); normalising the read quaternion can add up to |q - q_written|
  // <= 1e-9 to a component, and the rotation matrix sums a few such terms.
  CHECK(worst_translation <= 1e-9);
  CHECK(worst_quaternion <= 1.5e-9);
  CHECK(worst_rotation <= 4e-9);
  // Written as "timestamp tx ty tz qx qy qz qw", w >= 0.
  std::ifstream in(path);
  std::string header, first;
  std::getline(in, header);
  std::getline(in, first);
  CHECK(header == "# timestamp tx ty tz qx qy qz qw");
  CHECK(first ==
        "1305031102.175304 0.000000000 0.000000000 0.000000000 0.000000000 0.000000000 0.000000000 "
        "1.000000000");
}

TEST_CASE("read_tum_trajectory takes comments, blank lines, tabs, commas and CRLF", "[io][tum]") {
  ScratchDir dir;
  const std::string path = dir.write("t.txt",
                                     "# ground truth\r\n"
                                     "\n"
                                     "0.5 1 2 3 0 0 0 1   # identity rotation\r\n"
                                     "   \t\n"
                                     "0.75\t1,2,3\t0 0 0.7071067811865476 0.7071067811865476\n"
                                     "1 0 0 0 0 0 0 -2\n");  // not normalised, w < 0: the same rotation
  const auto poses = read_tum_trajectory(path);
  REQUIRE(poses.size() == 3);
  CHECK(poses[0].timestamp == 0.5);
  CHECK(poses[0].pose.translation()[2] == 3.0);
  CHECK(max_abs_difference(poses[0].pose, SE3<double>::translation(vec3(1.0, 2.0, 3.0))) < 1e-15);
  // 90 degrees about z.
  CHECK(poses[1].pose.rotation()(0, 1) == Approx(-1.0).margin(1e-12));
  CHECK(poses[1].pose.rotation()(1, 0) == Approx(1.0).margin(1e-12));
  CHECK(max_abs_difference(poses[2].pose, SE3<double>::identity()) < 1e-15);

  CHECK(read_tum_trajectory(dir.write("empty.txt", "# nothing yet\n")).empty());
}

TEST_CASE("read_tum_trajectory normalises quaternions of any scale", "[io][tum]") {
  // Components near 1e200 overflowed the norm to infinity, and the pose
  // read as the identity (found by tests/fuzz/fuzz_tum_trajectory.cpp).
  const auto poses = parse_tum_trajectory("1 0 0 0 0 0 2e200 2e200\n2 0 0 0 -1e300 0 0 0\n", "big.txt");
  REQUIRE(poses.size() == 2);
  CHECK(poses[0].pose.rotation()(0, 1) == Approx(-1.0).margin(1e-12));  // 90 degrees about z
  CHECK(poses[0].pose.rotation()(1, 0) == Approx(1.0).margin(1e-12));
  CHECK(poses[1].pose.rotation()(1, 1) == Approx(-1.0).margin(1e-12));  // 180 degrees about x
  CHECK(poses[1].pose.rotation()(2, 2) == Approx(-1.0).margin(1e-12));
  CHECK_THROWS_WITH(parse_tum_trajectory("1 0 0 0 0 0 1e-7 1e-7\n", "small.txt"), EMF_CONTAINS("zero norm"));
}

TEST_CASE("The TUM readers take text in memory, naming it in messages", "[io][tum]") {
  ScratchDir dir;
  const std::vector<TimedPose> poses = parse_tum_trajectory("0.5 1 2 3 0 0 0 1\n0.75 0 0 0 1 0 0 0\n", "gt");
  REQUIRE(poses.size() == 2);
  write_tum_trajectory(dir.file("gt.txt"), poses);
  CHECK(format_tum_trajectory(poses, "gt") == read_bytes(dir.file("gt.txt")));
  CHECK_THROWS_WITH(parse_tum_trajectory("0.5 1 2 3 0 0 0 1\n0.5 1 2 3 0 0 0 1\n", "gt"),
                    EMF_CONTAINS("read_tum_trajectory: 'gt' line 2: timestamp 0.5 is not after"));
  CHECK_THROWS_AS(format_tum_trajectory({poses[0], poses[0]}, "gt"), std::invalid_argument);

  const PinholeCamera<double> camera = parse_calibration("# c\n500 501 320 240 640 480\n", "calib");
  CHECK(camera.fy == 501.0);
  CHECK(camera.height == 480);
  CHECK_THROWS_WITH(parse_calibration("", "calib"), EMF_CONTAINS("read_calibration: 'calib': no calibration line"));

  const std::vector<TumListEntry> list = parse_tum_list("# d\n1.5 depth/a.png\n\n2.5 depth/b.png\n", "depth.txt");
  REQUIRE(list.size() == 2);
  CHECK(list[1].timestamp == 2.5);
  CHECK(list[1].path == "depth/b.png");
  CHECK(list[1].line == 4);
  CHECK_THROWS_WITH(parse_tum_list("1 a.png\n0.5 b.png\n", "depth.txt"),
                    EMF_CONTAINS("TumSequence::open: 'depth.txt' line 2: timestamp 0.5 is not after"));
}

TEST_CASE("read_tum_trajectory names file and line of a bad line", "[io][tum]") {
  ScratchDir dir;
  const std::string good = "# t tx ty tz qx qy qz qw\n0.1 0 0 0 0 0 0 1\n";
  struct Bad {
    const char* line;
    const char* problem;
  };
  const Bad cases[] = {
      {"0.2 0 0 0 0 0 1", "8 fields expected (timestamp tx ty tz qx qy qz qw), got 7"},
      {"0.2 0 0 0 0 0 0 1 9", "got 9"},
      {"0.2 0 0 zero 0 0 0 1", "tz 'zero' is not a number"},
      {"0.2 0 0 0.5x 0 0 0 1", "tz '0.5x' is not a number"},
      {"0.2 0 nan 0 0 0 0 1", "ty 'nan' is not a finite number"},
      {"0.2 0 0 0 0 0 0 inf", "qw 'inf' is not a finite number"},
      {"0.2 0 0 0 1e999 0 0 1", "qx '1e999' is not a finite number"},
      {"0.2 0 0 0 0 0 0 0", "zero norm"},
      {"0.1 0 0 0 0 0 0 1", "timestamp 0.1 is not after the previous one (0.1 on line 2)"},
      {"0.05 0 0 0 0 0 0 1", "not after the previous one"},
  };
  for (const Bad& bad : cases) {
    CAPTURE(bad.line);
    const std::string path = dir.write("bad.txt", good + "\n" + bad.line + "\n");
    const std::string e = error_of([&] { read_tum_trajectory(path); });
    CHECK(contains(e, "read_tum_trajectory: '" + path + "' line 4: "));
    CHECK(contains(e, bad.problem));
  }
  const std::string missing = dir.file("missing.txt");
  CHECK_THROWS_WITH(read_tum_trajectory(missing), EMF_CONTAINS("'" + missing + "': cannot open"));
}

TEST_CASE("write_tum_trajectory refuses poses it could not read back", "[io][tum]") {
  ScratchDir dir;
  const std::string path = dir.file("out.txt");
  std::vector<TimedPose> poses = {{1.0, SE3<double>()}, {1.0000001, SE3<double>()}};
  const std::string e = error_of([&] { write_tum_trajectory(path, poses); });
  CHECK(contains(e, "write_tum_trajectory: '" + path + "': pose 1: timestamp 1.000000 is not after"));
  poses[1].timestamp = 2.0;
  poses[1].pose.translation()[1] = std::nan("");
  CHECK_THROWS_AS(write_tum_trajectory(path, poses), std::invalid_argument);
  poses[1].pose.translation()[1] = 0;
  poses[0].timestamp = INFINITY;
  CHECK_THROWS_WITH(write_tum_trajectory(path, poses), EMF_CONTAINS("pose 0: the timestamp is not finite"));
  CHECK_FALSE(fs::exists(path));
  CHECK_FALSE(fs::exists(path + ".tmp"));

  write_tum_trajectory(path, {});
  CHECK(read_tum_trajectory(path).empty());
  CHECK_THROWS_WITH(write_tum_trajectory(dir.file("no/dir/t.txt"), {}), EMF_CONTAINS("cannot open"));
}

// ---- calibration -------------------------------------------------------------------

TEST_CASE("read_calibration reads fx fy cx cy width height", "[io][tum]") {
  ScratchDir dir;
  const auto camera = read_calibration(dir.write("c.txt", "# Kinect\n\n585 585.5 320 239.5 640 480  # depth camera\n"));
  CHECK(camera.fx == 585.0);
  CHECK(camera.fy == 585.5);
  CHECK(camera.cx == 320.0);
  CHECK(camera.cy == 239.5);
  CHECK(camera.width == 640);
  CHECK(camera.height == 480);
  CHECK(read_calibration(dir.write("d.txt", "525 525 -3 2 640.0 480")).width == 640);

  struct Bad {
    const char* text;
    const char* problem;
  };
  const Bad cases[] = {
      {"#c\n585 585 320 240 640", "line 2: 6 fields expected (fx fy cx cy width height), got 5"},
      {"#c\n0 585 320 240 640 480", "line 2: fx 0 is not positive"},
      {"#c\n585 -1 320 240 640 480", "line 2: fy -1 is not positive"},
      {"#c\n585 585 320 240 640.5 480", "line 2: width '640.5' is not a positive integer"},
      {"#c\n585 585 320 240 640 0", "line 2: height '0' is not a positive integer"},
      {"#c\n585 585 cx 240 640 480", "line 2: cx 'cx' is not a number"},
      {"#c\n585 585 320 240 640 480\n525 525 320 240 640 480", "line 3: a second calibration line"},
      {"# nothing\n", "no calibration line"},
  };
  for (const Bad& bad : cases) {
    CAPTURE(bad.text);
    const std::string path = dir.write("bad.txt", bad.text);
    const std::string e = error_of([&] { read_calibration(path); });
    CHECK(contains(e, "read_calibration: '" + path + "'"));
    CHECK(contains(e, bad.problem));
  }
}

// ---- sequences ---------------------------------------------------------------------

TEST_CASE("TumSequence pairs depth.txt with the nearest rgb.txt frame", "[io][tum]") {
  ScratchDir dir;
  write_pairing_sequence(dir);
  const TumSequence seq = TumSequence::open(dir.path());
  REQUIRE(seq.size() == 4);  // the depth frame at 1.2 s is dropped
  CHECK(seq.has_colour());
  const double depth_t[] = {1.0, 1.1, 1.3, 1.4};
  const double rgb_t[] = {1.01, 1.095, 1.305, 1.42};
  for (std::size_t i = 0; i < 4; ++i) {
    CHECK(seq.timestamp(i) == depth_t[i]);
    CHECK(seq.colour_timestamp(i) == rgb_t[i]);
  }
  CHECK(seq.depth_path(2) == dir.file("depth/1.300000.png"));
  CHECK(seq.colour_path(2) == dir.file("rgb/1.305000.jpg"));
  CHECK(seq.dir() == dir.path());
  CHECK(seq.camera().fx == 4.0);
  CHECK(seq.camera().fy == 4.5);
  CHECK(seq.camera().width == 8);
  CHECK(seq.camera_source() == dir.file("calibration.txt"));

  // Metres = value / 5000; 0 stays 0.
  const Image<float, Host> depth = seq.depth(0);
  REQUIRE(depth.width() == 8);
  REQUIRE(depth.height() == 6);
  const auto d = depth.to_host();
  CHECK(d[0] == 1.0f);
  CHECK(d[1] == 0.0f);
  CHECK(d[2] == Approx(12345.0 / 5000.0).epsilon(1e-7));
  CHECK(d[3] == Approx(65535.0 / 5000.0).epsilon(1e-7));
  CHECK(seq.depth(3).to_host()[7] == 0.5f);

  SECTION("a tighter max_time_difference drops more") {
    TumOptions options;
    options.max_time_difference = 0.006;
    const TumSequence tight = TumSequence::open(dir.path(), options);
    REQUIRE(tight.size() == 2);
    CHECK(tight.timestamp(0) == 1.1);
    CHECK(tight.timestamp(1) == 1.3);
  }
  SECTION("depth_scale") {
    TumOptions options;
    options.depth_scale = 1000;
    CHECK(TumSequence::open(dir.path(), options).depth(0).to_host()[0] == 5.0f);
  }
  SECTION("no ground truth, then some") {
    CHECK_FALSE(seq.ground_truth().has_value());
    CHECK(seq.ground_truth_objects().empty());
    dir.write("groundtruth.txt", "1.0 1 2 3 0 0 0 1\n1.1 1 2 3 0 0 0 1\n");
    dir.write("groundtruth_objects/cup_2.txt", "1.0 0 0 1 0 0 0 1\n");
    dir.write("groundtruth_objects/notes.md", "not a trajectory");
    REQUIRE(seq.ground_truth().has_value());
    CHECK(seq.ground_truth()->size() == 2);
    const auto objects = seq.ground_truth_objects();
    REQUIRE(objects.size() == 1);
    CHECK(objects.at("cup_2").size() == 1);
  }
  SECTION("without rgb.txt every depth frame is kept, without colour") {
    fs::remove(dir.file("rgb.txt"));
    const TumSequence depth_only = TumSequence::open(dir.path());
    REQUIRE(depth_only.size() == 5);
    CHECK_FALSE(depth_only.has_colour());
    CHECK(depth_only.colour_path(2).empty());
    CHECK(std::isnan(depth_only.colour_timestamp(2)));
  }
  SECTION("frame indices are checked") {
    CHECK_THROWS_AS(seq.depth(4), std::out_of_range);
    CHECK_THROWS_AS(seq.timestamp(99), std::out_of_range);
  }
}

TEST_CASE("TumSequence prefers associations.txt and takes it as written", "[io][tum]") {
  ScratchDir dir;
  write_pairing_sequence(dir);
  dir.write("associations.txt",
            "# t_rgb rgb t_depth depth\n"
            "1.230000 rgb/1.230000.jpg 1.200000 depth/1.200000.png\n"
            "1.420000 rgb/1.420000.jpg 1.400000 depth/1.400000.png\n");
  const TumSequence seq = TumSequence::open(dir.path());
  REQUIRE(seq.size() == 2);
  CHECK(seq.timestamp(0) == 1.2);
  CHECK(seq.colour_timestamp(0) == 1.23);
  CHECK(seq.depth_path(1) == dir.file("depth/1.400000.png"));
  CHECK(seq.colour_path(1) == dir.file("rgb/1.420000.jpg"));
  CHECK(seq.has_colour());
}

TEST_CASE("TumSequence opens a copy without colour images as depth only, not a partial copy", "[io][tum]") {
  ScratchDir dir;
  write_pairing_sequence(dir);
  const std::string assoc = dir.write("associations.txt",
                                      "# t_rgb rgb t_depth depth\n"
                                      "1.010000 rgb/1.010000.jpg 1.000000 depth/1.000000.png\n"
                                      "1.095000 rgb/1.095000.jpg 1.100000 depth/1.100000.png\n"
                                      "1.305000 rgb/1.305000.jpg 1.300000 depth/1.300000.png\n");
  SECTION("associations.txt, every colour image absent: depth only") {
    fs::remove_all(dir.file("rgb"));
    const TumSequence seq = TumSequence::open(dir.path());
    REQUIRE(seq.size() == 3);
    CHECK_FALSE(seq.has_colour());
    for (std::size_t i = 0; i < seq.size(); ++i) {
      CHECK(seq.colour_path(i).empty());
      CHECK(std::isnan(seq.colour_timestamp(i)));
    }
    CHECK(seq.timestamp(2) == 1.3);
    CHECK(seq.depth_path(2) == dir.file("depth/1.300000.png"));
    CHECK(seq.depth(0).to_host()[0] == 1.0f);
  }
  SECTION("associations.txt, some colour images absent: an error naming the first and the count") {
    fs::remove(dir.file("rgb/1.095000.jpg"));
    fs::remove(dir.file("rgb/1.305000.jpg"));
    const std::string e = error_of([&] { TumSequence::open(dir.path()); });
    CHECK(contains(e, "TumSequence::open: '" + assoc + "' line 3: colour image '" + dir.file("rgb/1.095000.jpg") +
                          "' not found (2 of 3 frames lack their colour image"));
  }
  SECTION("associations.txt, depth images must all exist even without colour") {
    fs::remove_all(dir.file("rgb"));
    fs::remove(dir.file("depth/1.100000.png"));
    CHECK_THROWS_WITH(TumSequence::open(dir.path()), EMF_CONTAINS("'" + assoc + "' line 3: depth image '" +
                                                                  dir.file("depth/1.100000.png") + "' not found"));
  }
  SECTION("rgb.txt pairing, every colour image absent: the same frames, depth only") {
    fs::remove(assoc);
    fs::remove_all(dir.file("rgb"));
    const TumSequence seq = TumSequence::open(dir.path());
    REQUIRE(seq.size() == 4);  // paired as with the images: the depth frame at 1.2 s is still dropped
    CHECK_FALSE(seq.has_colour());
    CHECK(seq.timestamp(2) == 1.3);
    CHECK(seq.colour_path(2).empty());
    CHECK(std::isnan(seq.colour_timestamp(2)));
  }
  SECTION("rgb.txt pairing, some colour images absent: an error") {
    fs::remove(assoc);
    for (const char* t : {"1.010000", "1.095000", "1.305000"}) fs::remove(dir.file(std::string("rgb/") + t + ".jpg"));
    CHECK_THROWS_WITH(TumSequence::open(dir.path()),
                      EMF_CONTAINS("rgb.txt' line 2: colour image '" + dir.file("rgb/1.010000.jpg") +
                                   "' not found (3 of 4 frames lack their colour image"));
  }
}

TEST_CASE("TumSequence takes its camera from the options, calibration.txt or the default", "[io][tum]") {
  ScratchDir dir;
  write_pairing_sequence(dir);
  TumOptions options;
  options.camera = PinholeCamera<double>{10, 11, 3, 2, 8, 6};
  const TumSequence given = TumSequence::open(dir.path(), options);
  CHECK(given.camera().fx == 10.0);
  CHECK(given.camera_source() == "TumOptions::camera");

  fs::remove(dir.file("calibration.txt"));
  const TumSequence fallback = TumSequence::open(dir.path());
  CHECK(fallback.camera().fx == 525.0);
  CHECK(fallback.camera().cx == 319.5);
  CHECK(fallback.camera().width == 640);
  CHECK(fallback.camera_source().rfind("default", 0) == 0);
  // Our 8x6 depth images do not fit the default 640x480 camera.
  const std::string e = error_of([&] { fallback.depth(0); });
  CHECK(contains(e, "TumSequence::depth: '" + dir.file("depth/1.000000.png") + "': "));
  CHECK(contains(e, "the image is 8x6 but the camera"));
  CHECK(contains(e, "640x480"));

  options.camera->fx = 0;
  CHECK_THROWS_AS(TumSequence::open(dir.path(), options), std::invalid_argument);
  options.camera.reset();
  options.depth_scale = 0;
  CHECK_THROWS_WITH(TumSequence::open(dir.path(), options), EMF_CONTAINS("depth_scale"));
}

TEST_CASE("TumSequence reports bad directories, lists and images", "[io][tum]") {
  ScratchDir dir;
  SECTION("missing directory") {
    const std::string missing = dir.file("nowhere");
    const std::string e = error_of([&] { TumSequence::open(missing); });
    CHECK(contains(e, "TumSequence::open: '" + missing + "': directory not found"));
    CHECK_THROWS_WITH(TumSequence::open(dir.write("file", "x")), EMF_CONTAINS("not a directory"));
  }
  SECTION("no lists") {
    CHECK_THROWS_WITH(TumSequence::open(dir.path()), EMF_CONTAINS("neither associations.txt nor depth.txt"));
  }
  SECTION("malformed list line") {
    write_pairing_sequence(dir);
    const std::string list =
        dir.write("depth.txt", "# t path\n1.000000 depth/1.000000.png\n1.100000 depth/1.100000.png extra\n");
    const std::string e = error_of([&] { TumSequence::open(dir.path()); });
    CHECK(contains(e, "TumSequence::open: '" + list + "' line 3: 2 fields expected (timestamp path), got 3"));

    dir.write("rgb.txt", "1.0 rgb/1.010000.jpg\n1.0 rgb/1.095000.jpg\n");
    dir.write("depth.txt", "1.0 depth/1.000000.png\n");
    CHECK_THROWS_WITH(TumSequence::open(dir.path()),
                      EMF_CONTAINS("rgb.txt' line 2: timestamp 1.0 is not after the previous one"));

    const std::string assoc = dir.write("associations.txt", "\n\n1.0 rgb/1.010000.jpg one depth/1.000000.png\n");
    CHECK_THROWS_WITH(TumSequence::open(dir.path()),
                      EMF_CONTAINS("'" + assoc + "' line 3: t_depth 'one' is not a number"));
    dir.write("associations.txt", "1.0 rgb/1.010000.jpg 1.0\n");
    CHECK_THROWS_WITH(TumSequence::open(dir.path()),
                      EMF_CONTAINS("line 1: 4 fields expected (t_rgb rgb_path t_depth depth_path), got 3"));
  }
  SECTION("missing images") {
    write_pairing_sequence(dir);
    fs::remove(dir.file("depth/1.300000.png"));
    const std::string e = error_of([&] { TumSequence::open(dir.path()); });
    CHECK(contains(
        e, "'" + dir.file("depth.txt") + "' line 6: depth image '" + dir.file("depth/1.300000.png") + "' not found"));
    write_depth(dir.file("depth/1.300000.png"), {1});
    fs::remove(dir.file("rgb/1.095000.jpg"));
    CHECK_THROWS_WITH(TumSequence::open(dir.path()), EMF_CONTAINS("rgb.txt' line 3: colour image"));
    // An rgb frame that no depth frame uses may be missing.
    write_pairing_sequence(dir);
    fs::remove(dir.file("rgb/1.230000.jpg"));
    CHECK(TumSequence::open(dir.path()).size() == 4);
  }
  SECTION("no frames") {
    dir.write("depth.txt", "# empty\n");
    CHECK_THROWS_WITH(TumSequence::open(dir.path()), EMF_CONTAINS("depth.txt': no frames"));
    write_depth(dir.file("depth/a.png"), {1});
    dir.write("depth.txt", "5.0 depth/a.png\n");
    dir.write("rgb.txt", "1.0 rgb/a.jpg\n");
    CHECK_THROWS_WITH(TumSequence::open(dir.path()), EMF_CONTAINS("no frames: no depth frame"));
  }
  SECTION("bad calibration.txt") {
    write_pairing_sequence(dir);
    dir.write("calibration.txt", "585 585 320 240\n");
    CHECK_THROWS_WITH(TumSequence::open(dir.path()),
                      EMF_CONTAINS("read_calibration: '" + dir.file("calibration.txt") + "' line 1: 6 fields"));
  }
  SECTION("bad depth images, found when read") {
    write_pairing_sequence(dir);
    const TumSequence seq = TumSequence::open(dir.path());
    // Wrong size for the calibration (8x6).
    write_depth(seq.depth_path(0), {1}, 6, 8);
    CHECK_THROWS_WITH(seq.depth(0), EMF_CONTAINS("'" + seq.depth_path(0) + "': the image is 6x8 but the camera (" +
                                                 dir.file("calibration.txt") + ") is 8x6"));
    // 8 bits: depth must be 16-bit.
    write_png(seq.depth_path(1), Image<std::uint8_t, Host>(8, 6, 3));
    CHECK_THROWS_WITH(seq.depth(1), EMF_CONTAINS("read_png: '" + seq.depth_path(1) + "': 8-bit"));
    // Truncated.
    std::ifstream in(seq.depth_path(2), std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    in.close();
    dir.write("depth/1.300000.png", bytes.substr(0, bytes.size() / 2));
    CHECK_THROWS_WITH(seq.depth(2), EMF_CONTAINS("read_png: '" + seq.depth_path(2) + "': corrupt or truncated"));
    // Not a PNG at all.
    dir.write("depth/1.400000.png", "GIF89a");
    CHECK_THROWS_WITH(seq.depth(3), EMF_CONTAINS("'" + seq.depth_path(3) + "': not a PNG file"));
  }
}

// ---- real data -----------------------------------------------------------------------

TEST_CASE("TumSequence reads shared/data/redkitchen_300", "[io][tum][data]") {
  const std::string path = std::string(EMFUSION_SHARED_DATA_DIR) + "/redkitchen_300";
  if (!fs::is_directory(path)) {
    WARN("redkitchen_300 test skipped: " << path << " not found");
    return;
  }
  const TumSequence seq = TumSequence::open(path);
  REQUIRE(seq.size() == 300);
  CHECK(seq.has_colour());
  CHECK(seq.camera().fx == 585.0);
  CHECK(seq.camera().fy == 585.0);
  CHECK(seq.camera().cx == 320.0);
  CHECK(seq.camera().cy == 240.0);
  CHECK(seq.camera().width == 640);
  CHECK(seq.camera().height == 480);
  CHECK(seq.timestamp(0) == 0.0);
  CHECK(seq.timestamp(299) == Approx(299.0 / 30.0).margin(1e-6));

  const auto depth = seq.depth(0).to_host();
  REQUIRE(depth.size() == 640u * 480u);
  std::size_t valid = 0;
  float lowest = 1e9f, highest = 0;
  for (const float d : depth)
    if (d > 0) {
      ++valid;
      lowest = std::min(lowest, d);
      highest = std::max(highest, d);
    }
  const double fraction = double(valid) / double(depth.size());
  CAPTURE(fraction, lowest, highest);
  CHECK(fraction > 0.85);
  CHECK(fraction < 0.93);
  CHECK(lowest >= 0.5f);
  CHECK(highest <= 5.0f);

  const auto gt = seq.ground_truth();
  REQUIRE(gt.has_value());
  REQUIRE(gt->size() == 300);
  CHECK(gt->front().pose.translation()[0] == Approx(-0.340456340).margin(1e-9));
  CHECK(seq.ground_truth_objects().empty());
}

TEST_CASE("TumSequence reads shared/data/room_dyn_300 object ground truth", "[io][tum][data]") {
  const std::string path = std::string(EMFUSION_SHARED_DATA_DIR) + "/room_dyn_300";
  if (!fs::is_directory(path)) {
    WARN("room_dyn_300 test skipped: " << path << " not found");
    return;
  }
  const TumSequence seq = TumSequence::open(path);
  CHECK(seq.size() == 300);
  CHECK(seq.camera().fx == 525.0);
  const auto objects = seq.ground_truth_objects();
  CHECK(objects.size() == 3);
  CHECK(objects.count("cup_2") == 1);
  for (const auto& [name, trajectory] : objects) {
    CAPTURE(name);
    CHECK_FALSE(trajectory.empty());
  }
}
