// Trajectories written pose by pose (io/trajectory_stream.hpp): the same
// bytes as write_tum_trajectory, readable after every flush, continued after
// a close; bad poses and write failures (/dev/full, a missing folder) are
// errors naming the file; check_writable_directory (io/run_outputs.hpp).
#include <cmath>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include "emfusion/io/run_outputs.hpp"
#include "emfusion/io/trajectory_stream.hpp"
#include "emfusion/io/tum.hpp"
#include "support/catch.hpp"
#include "support/files.hpp"

using namespace emfusion;
namespace fs = std::filesystem;
using emfusion::test::contains;
using emfusion::test::error_of;
using emfusion::test::read_bytes;
using emfusion::test::ScratchDir;

namespace {

Trajectory some_poses(int n) {
  Trajectory poses;
  for (int i = 0; i < n; ++i)
    poses.push_back({1305031102.175304 + i / 30.0,
                     SE3<double>::from_quaternion(0.1 * i, -0.2, 0.3, 1.0, vec3(0.01 * i, -1.5, 2.0 / (i + 1)))});
  return poses;
}

}  // namespace

TEST_CASE("A streamed trajectory is write_tum_trajectory's file, readable after every flush", "[io][tum]") {
  ScratchDir dir;
  const Trajectory poses = some_poses(7);
  write_tum_trajectory(dir.file("whole.txt"), poses);

  TumTrajectoryStream stream(dir.file("streamed.txt"));
  CHECK(read_bytes(dir.file("streamed.txt")) == "# timestamp tx ty tz qx qy qz qw\n");
  for (std::size_t i = 0; i < poses.size(); ++i) {
    stream.append(poses[i]);
    // Appended poses wait in memory until the flush.
    CHECK(read_tum_trajectory(dir.file("streamed.txt")).size() == i);
    stream.flush();
    CHECK(read_tum_trajectory(dir.file("streamed.txt")).size() == i + 1);
    CHECK(stream.size() == i + 1);
    // A deleted object's file is closed, and continued when it returns.
    if (i == 3) {
      stream.close();
      CHECK_FALSE(stream.is_open());
    }
  }
  stream.sync();
  stream.close();
  CHECK(read_bytes(dir.file("streamed.txt")) == read_bytes(dir.file("whole.txt")));

  // A new stream on the same path starts the file again.
  TumTrajectoryStream again(dir.file("streamed.txt"));
  CHECK(read_tum_trajectory(dir.file("streamed.txt")).empty());
}

TEST_CASE("A streamed trajectory refuses what write_tum_trajectory refuses, adding nothing", "[io][tum]") {
  ScratchDir dir;
  const Trajectory poses = some_poses(2);
  TumTrajectoryStream stream(dir.file("t.txt"));
  stream.append(poses[1]);
  std::string e = error_of([&] { stream.append(poses[0]); });
  CHECK(contains(e, "TumTrajectoryStream: '" + dir.file("t.txt") + "': pose 1: timestamp"));
  CHECK(contains(e, "is not after the previous one"));
  TimedPose bad = poses[1];
  bad.timestamp += 1;
  bad.pose = SE3<double>::from_quaternion(0, 0, 0, 1, vec3(std::nan(""), 0.0, 0.0));
  CHECK_THROWS_AS(stream.append(bad), std::invalid_argument);
  stream.close();
  CHECK(stream.size() == 1);
  CHECK(read_tum_trajectory(dir.file("t.txt")).size() == 1);
}

TEST_CASE("Streamed trajectories that cannot be written name the file and the reason", "[io][tum]") {
  ScratchDir dir;
  std::string e = error_of([&] { TumTrajectoryStream s(dir.file("missing/t.txt")); });
  CHECK(contains(e, "TumTrajectoryStream: '" + dir.file("missing/t.txt") + "': cannot open for writing: No such file"));
  if (fs::exists("/dev/full")) {
    // A full disk: the header's write fails at once, not at the end of a run.
    fs::create_symlink("/dev/full", dir.file("full.txt"));
    e = error_of([&] { TumTrajectoryStream s(dir.file("full.txt")); });
    CHECK(contains(e, "TumTrajectoryStream: '" + dir.file("full.txt") + "': cannot write: No space left on device"));
  }
}

TEST_CASE("check_writable_directory leaves nothing behind and names what fails", "[io]") {
  ScratchDir dir;
  check_writable_directory(dir.path());
  CHECK(fs::is_empty(dir.path()));
  const std::string e = error_of([&] { check_writable_directory(dir.file("missing")); });
  CHECK(contains(e, "check_writable_directory: '" + dir.file("missing/.emfusion-write-test") + "': cannot open"));
  CHECK(contains(e, "No such file or directory"));
}
