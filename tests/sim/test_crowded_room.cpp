// The room of make_dynamic_room with more than 8 objects (up to 16, for the
// object-count sweep of bench_system): it builds for the seeds the benches
// use, every object is distinct, starts clear of the others and in view,
// moves within the planner's limits and is seen; rooms of up to 8 objects
// are what they were before the room grew.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <set>
#include <string>
#include <vector>

#include "emfusion/sim/dynamic_scene.hpp"
#include "support/catch.hpp"
#include "support/small_room.hpp"

using namespace emfusion;

namespace {

double yaw_of(const SE3<double>& T) { return std::atan2(T.rotation()(1, 0), T.rotation()(0, 0)); }

}  // namespace

TEST_CASE("A room of 16 objects: distinct, apart, in view, moving within the limits", "[sim]") {
  constexpr int n = 16, frames = 300;
  const auto scene = sim::make_dynamic_room<double>(test::small_room(n, frames));
  REQUIRE(scene.object_count() == n);

  // Names "<class>_<k+1>", all different; the first eight as in smaller rooms.
  std::set<std::string> names;
  for (int k = 0; k < n; ++k) {
    CAPTURE(k);
    CHECK(scene.object_name(k) == scene.object_class(k) + "_" + std::to_string(k + 1));
    names.insert(scene.object_name(k));
    CHECK(scene.object_shapes(k).size() == 2u);
  }
  CHECK(names.size() == std::size_t(n));
  const char* const first[8] = {"car", "cup", "book", "backpack", "teddy_bear", "potted_plant", "laptop", "bottle"};
  for (int k = 0; k < 8; ++k) CHECK(scene.object_class(k) == first[k]);

  const auto& cam = scene.camera();
  const double dt = 1.0 / 30;
  for (int k = 0; k < n; ++k) {
    CAPTURE(k);
    // At frame 0 the centre projects inside the image, in front of the camera.
    const Vec3<double> c = scene.camera_pose(0).inverse() * scene.object_pose(k, 0).translation();
    REQUIRE(c.z() > 0.5);
    const Vec2<double> uv = cam.project(c);
    CHECK(uv.x() > 0);
    CHECK(uv.x() < cam.width - 1);
    CHECK(uv.y() > 0);
    CHECK(uv.y() < cam.height - 1);
    // It moves, upright at rest, and never faster than the planner allows
    // (0.35 m/s and 50 deg/s at the peak; frame differences bounded as in
    // the rooms of up to 8).
    const SE3<double> rest = scene.object_pose(k, 0);
    CHECK(rest.rotation()(2, 2) == test::Approx(1.0));
    double path = 0, max_speed = 0, max_rate = 0;
    for (int f = 1; f < frames; ++f) {
      const SE3<double> a = scene.object_pose(k, f - 1), b = scene.object_pose(k, f);
      const double step = norm(b.translation() - a.translation());
      path += step;
      max_speed = std::max(max_speed, step / dt);
      max_rate = std::max(max_rate, norm(so3_log((a.inverse() * b).rotation())) / dt);
    }
    CHECK(path > 0.05);
    CHECK(max_speed <= 0.4);
    CHECK(max_rate <= 60 * M_PI / 180);
  }
  // Bounding spheres stay apart in every frame.
  for (int f = 0; f < frames; ++f)
    for (int k = 0; k < n; ++k)
      for (int j = 0; j < k; ++j) {
        const double gap = norm(scene.object_pose(k, f).translation() - scene.object_pose(j, f).translation()) -
                           scene.object_radius(k) - scene.object_radius(j);
        if (gap < 0) FAIL("objects " << j << " and " << k << " overlap at frame " << f);
      }

  // Rendered at frame 0, every object shows some pixels of its own.
  Image<double, Host> depth;
  Image<int, Host> labels;
  scene.render(0, depth, &labels, false);
  std::vector<int> area(std::size_t(n) + 1, 0);
  for (int label : labels.to_host()) ++area[std::size_t(label)];
  for (int k = 0; k < n; ++k) {
    CAPTURE(k);
    CHECK(area[std::size_t(k) + 1] > 20);
  }
}

TEST_CASE("Rooms of 9..16 objects build for the benches' seeds", "[sim]") {
  // bench_system's sweep (seed 1, 300 frames), a few other seeds and lengths;
  // planning only, no rendering.
  for (const std::uint64_t seed : {1u, 2u, 3u, 7u, 42u})
    for (const int frames : {120, 300}) {
      CAPTURE(seed, frames);
      const auto scene = sim::make_dynamic_room<float>(test::small_room(16, frames, seed));
      CHECK(scene.object_count() == 16);
    }
  for (int n = 9; n <= 15; ++n) {
    CAPTURE(n);
    const auto scene = sim::make_dynamic_room<float>(test::small_room(n, 300));
    CHECK(scene.object_count() == n);
    CHECK(scene.object_name(n - 1) == scene.object_class(n - 1) + "_" + std::to_string(n));
  }
}

TEST_CASE("Rooms of up to 8 objects are unchanged by the larger room", "[sim]") {
  // Poses of the 8-object room (seed 1, 300 frames) from the code before the
  // room held more than 8: object, frame, x, y, z, yaw. Frame 100 is within
  // motions (lifted and tilted).
  struct Row {
    int k, f;
    double x, y, z, yaw;
  };
  const Row rows[] = {
      {0, 0, 0.272658140874, 0.937115868772, 0.590000000000, 0.671739164477},
      {0, 100, -0.108981667542, 0.959615971709, 0.591404032270, 1.347532856666},
      {0, 299, 0.215186348291, 0.991352057873, 0.590000000000, 0.112977023225},
      {1, 0, -0.380004170464, 0.451129176952, 0.610000000000, 1.367210596914},
      {1, 100, -0.405847089473, 0.554582706446, 0.701977882107, 1.534664228596},
      {1, 299, -0.213629049202, 0.958447756591, 0.611324592089, 2.328218287714},
      {2, 0, 0.711311125605, 0.511282070149, 0.550000000000, 0.392140122025},
      {2, 100, 0.413945919000, 0.658190526916, 0.581160752582, 0.826180892098},
      {2, 299, 0.022083272450, 0.471499938120, 0.550000000000, 0.383796918485},
      {3, 0, 0.782087880909, -0.055439385777, 0.160000000000, -0.649345084953},
      {3, 100, 0.681969297850, -0.057391791137, 0.226832879207, -0.213688073771},
      {3, 299, 0.657737332528, -0.073737470263, 0.250037191278, 1.571411445461},
      {4, 0, -0.494754159134, 1.157050454275, 0.660000000000, 1.653806149325},
      {4, 100, -0.734921243734, 1.113981258698, 0.686897822949, 2.317238256905},
      {4, 299, -0.769302221375, 1.068410280141, 0.734417496469, 1.253716766469},
      {5, 0, -0.019171809934, -0.086715459742, 0.170000000000, -1.851634291438},
      {5, 100, -0.203293825438, -0.166641864836, 0.170000000000, -2.229150577507},
      {5, 299, 0.192736822956, 0.029346911427, 0.170842048936, -1.980180213762},
      {6, 0, -0.788346785473, 0.781836291698, 0.612000000000, -1.740298543078},
      {6, 100, -0.843611189492, 0.554231590043, 0.626543860617, -1.085815103152},
      {6, 299, -0.730570801059, 0.512113625383, 0.665168586450, -1.478992628453},
      {7, 0, -0.739895618556, -0.068947824660, 0.090000000000, 1.046808275919},
      {7, 100, -0.698307489890, -0.194015290995, 0.157887812704, 1.583803414548},
      {7, 299, -0.603852439487, -0.166427164385, 0.161511133224, 0.634204825760},
  };
  const auto eight = sim::make_dynamic_room<double>(test::small_room(8, 300));
  for (const Row& r : rows) {
    CAPTURE(r.k, r.f);
    const SE3<double> T = eight.object_pose(r.k, r.f);
    CHECK(T.translation().x() == test::Approx(r.x).margin(1e-9));
    CHECK(T.translation().y() == test::Approx(r.y).margin(1e-9));
    CHECK(T.translation().z() == test::Approx(r.z).margin(1e-9));
    CHECK(yaw_of(T) == test::Approx(r.yaw).margin(1e-9));
  }
  // A smaller room is the same room with fewer objects, as before: the
  // objects' starting poses do not depend on the objects after them.
  for (int n = 1; n < 8; ++n) {
    CAPTURE(n);
    const auto room = sim::make_dynamic_room<double>(test::small_room(n, 300));
    for (int k = 0; k < n; ++k)
      CHECK(max_abs_diff(room.object_pose(k, 0).matrix(), eight.object_pose(k, 0).matrix()) == 0.0);
  }
}
