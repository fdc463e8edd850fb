// emfusion_demo: the library end to end on a built-in synthetic scene.
//
// Renders a table-top scene (floor, box, sphere, cylinder) from a camera
// circling it, fuses every frame into a TSDF volume, raycasts a view that was
// not fused and compares it with the rendered ground truth, extracts a mesh
// and writes it as PLY. Needs no data.
//
//   emfusion_demo [--output DIR] [--frames N] [--voxels N] [--backend cpu|cuda]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include <fmt/core.h>

#include "emfusion/io/ply.hpp"
#include "emfusion/sim/primitives.hpp"
#include "emfusion/sim/render.hpp"
#include "emfusion/volume/integrate.hpp"
#include "emfusion/volume/marching_cubes.hpp"
#include "emfusion/volume/mesh.hpp"
#include "emfusion/volume/raycast.hpp"
#include "support/args.hpp"

using namespace emfusion;
using S = float;

namespace {

struct Options {
  std::string output = "out/demo";
  int frames = 60;
  int voxels = 160;
  std::string backend = "cpu";
};

Options parse(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help" || a == "-h") {
      fmt::print("usage: emfusion_demo [--output DIR] [--frames N] [--voxels N] [--backend cpu|cuda]\n");
      std::exit(0);
    }
    if (i + 1 >= argc) throw std::invalid_argument("unknown option or missing value: '" + a + "'");
    const char* v = argv[++i];
    if (a == "--output") o.output = v;
    else if (a == "--frames") o.frames = examples::parse_positive_int(a, v);
    else if (a == "--voxels") o.voxels = examples::parse_positive_int(a, v, 1024);
    else if (a == "--backend") o.backend = v;
    else throw std::invalid_argument("unknown option '" + a + "'");
  }
  if (o.backend != "cpu" && o.backend != "cuda")
    throw std::invalid_argument("--backend must be cpu or cuda, got '" + o.backend + "'");
#if !EMFUSION_HAS_CUDA
  if (o.backend == "cuda") throw std::invalid_argument("--backend cuda: this build has no CUDA backend");
#endif
  return o;
}

sim::Scene<S> table_top() {
  sim::Scene<S> scene;
  scene.add(sim::make_plane(SE3<S>::identity()));  // the floor, z = 0
  scene.add(sim::make_box(SE3<S>::exp(Vec6<S>{{0.15f, -0.1f, 0.1f, 0.f, 0.f, 0.4f}}), vec3(0.12f, 0.08f, 0.1f)));
  scene.add(sim::make_sphere(vec3(-0.15f, 0.12f, 0.12f), 0.12f));
  scene.add(sim::make_cylinder(SE3<S>::translation(vec3(-0.05f, -0.25f, 0.15f)), 0.06f, 0.15f));
  return scene;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

template <class B>
int run(const Options& o) {
  // Fail before the work, not after it, if the output cannot be written.
  const std::filesystem::path dir = std::filesystem::path(o.output) / "meshes";
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw std::runtime_error("cannot create output directory '" + dir.string() + "': " + ec.message());
  const B backend{};
  const auto scene = table_top();
  const PinholeCamera<S> camera{};  // 640x480, fx = fy = 525
  const Vec3<S> target = vec3(0.f, 0.f, 0.1f);
  auto orbit = [&](double angle) {
    const Vec3<S> eye = vec3(S(1.0 * std::cos(angle)), S(1.0 * std::sin(angle)), 0.7f);
    return sim::look_at(eye, target, vec3(0.f, 0.f, 1.f));
  };

  // A cube of 1.6 m around the objects, 1 cm voxels at the default size.
  const S extent = 1.6f;
  VolumeGeometry<S> geometry;
  geometry.dims = Vec3i{{o.voxels, o.voxels, o.voxels}};
  geometry.voxel_size = extent / S(o.voxels);
  geometry.T_world_volume = SE3<S>::translation(vec3(-extent / 2, -extent / 2, -0.2f));
  TsdfVolume<S, B> volume(geometry, backend);
  fmt::print("emfusion demo: {} frames of 640x480 into {}^3 voxels of {:.1f} mm on {}\n", o.frames, o.voxels,
             1000.0 * geometry.voxel_size, B::name);

  Image<S, B> depth;
  std::vector<double> frame_ms;
  for (int k = 0; k < o.frames; ++k) {
    const SE3<S> pose = orbit(2.0 * M_PI * k / o.frames);
    sim::render_depth(scene, camera, pose, depth, static_cast<Image<int, B>*>(nullptr), {}, backend);
    const auto t0 = std::chrono::steady_clock::now();
    // Clean synthetic depth: the refined update keeps the geometry within a
    // fraction of a voxel (docs/decisions.md).
    integrate(volume, depth, camera, pose, static_cast<const Image<S, B>*>(nullptr), IntegrationParams<S>::refined());
    backend.synchronize();
    frame_ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  fmt::print("  integration: median {:.1f} ms per frame\n", median(frame_ms));

  // A view half-way between two fused ones, from higher up.
  const SE3<S> check_pose =
      sim::look_at(vec3(0.6f, -0.5f, 0.9f), target, vec3(0.f, 0.f, 1.f));
  Image<S, B> truth;
  sim::render_depth(scene, camera, check_pose, truth, static_cast<Image<int, B>*>(nullptr), {}, backend);
  RaycastResult<S, B> cast;
  raycast(volume, camera, check_pose, cast);
  const auto t = truth.to_host(), d = cast.depth.to_host();
  std::vector<double> err;
  for (std::size_t i = 0; i < t.size(); ++i)
    if (t[i] > 0 && d[i] > 0) err.push_back(std::fabs(double(d[i]) - double(t[i])));
  fmt::print("  raycast of an unfused view: median depth error {:.2f} mm over {} pixels\n", 1000 * median(err),
             err.size());

  const auto mesh = transformed(marching_cubes(volume), volume.pose());
  std::vector<double> vertex_err;
  for (const auto& v : mesh.vertices) vertex_err.push_back(std::fabs(double(scene.distance(v))));
  fmt::print("  mesh: {} vertices, {} triangles; median distance to the true surface {:.2f} mm\n",
             mesh.vertices.size(), mesh.triangles.size(), 1000 * median(vertex_err));

  const std::string path = (dir / "scene.ply").string();
  write_ply(path, mesh);
  fmt::print("  wrote {}\n", path);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const Options o = parse(argc, argv);
#if EMFUSION_HAS_CUDA
    if (o.backend == "cuda") return run<Cuda>(o);
#endif
    return run<Host>(o);
  } catch (const std::exception& e) {
    fmt::print(stderr, "emfusion_demo: error: {}\n", e.what());
    return 1;
  }
}
