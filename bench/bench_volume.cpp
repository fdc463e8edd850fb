// bench_volume: time of integrating and raycasting one 640x480 frame with a
// large TSDF volume (default 512^3 voxels of 1 cm, the paper's background),
// dense or sparse (blocks of 8^3 voxels of the same size), on every backend
// built or the one asked for.
//
//   bench_volume [--voxels N] [--repeats R] [--backend cpu|cuda|all] [--store float|half]
//                [--volume dense|sparse|both] [--json FILE]
//
// The sparse volume's integration includes its block allocation, which is
// also timed on its own ("allocate"); after the warm-up every block the frame
// touches is stored, as for a camera in a mapped place. Depth beyond 5 m is
// dropped, so that both volumes hold the same surfaces.
// --store half keeps SDF and weight in 16 bits (core/half.hpp); the raycast
// depth's error against the rendered depth (median and 90th percentile over
// the pixels hit) shows what that costs in accuracy.
// The scene is a synthetic room corner seen from the paper's background
// placement (camera at the centre of one face of the volume). Each stage is
// run `repeats` times after one warm-up; medians and 90th percentiles are
// printed. Set OMP_WAIT_POLICY=passive on small machines (docs/benchmarks.md).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <fmt/core.h>

#include "emfusion/core/half.hpp"
#include "emfusion/io/run_outputs.hpp"
#include "emfusion/sim/primitives.hpp"
#include "emfusion/sim/render.hpp"
#include "emfusion/volume/integrate.hpp"
#include "emfusion/volume/raycast.hpp"
#include "emfusion/volume/sparse_tsdf_volume.hpp"
#include "support/args.hpp"

using namespace emfusion;
using S = float;

namespace {

struct Options {
  int voxels = 512;
  int repeats = 10;
  std::string backend = "all";
  std::string store = "float";
  std::string volume = "both";
  std::string json;
};

struct Stats {
  double median = 0, p90 = 0;
};

Stats stats(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return {v[v.size() / 2], v[std::min(v.size() - 1, (v.size() * 9) / 10)]};
}

sim::Scene<S> room(const SE3<S>& T_world_camera) {
  // Floor 1 m below the camera, a back wall 3.5 m ahead, a side wall, clutter.
  sim::Scene<S> scene;
  const auto at = [&](S x, S y, S z) { return T_world_camera * vec3(x, y, z); };
  // A plane pose has the normal as its z axis: look from the floor point up.
  scene.add(sim::make_plane(sim::look_at(at(0, 1, 0), at(0, 0, 0), at(0, 0, 1) - at(0, 0, 0))));
  scene.add(sim::make_box(SE3<S>::translation(at(0, 0, 3.8f)), vec3(3.f, 3.f, 0.3f)));
  scene.add(sim::make_box(SE3<S>::translation(at(2.2f, 0, 2)), vec3(0.3f, 3.f, 3.f)));
  scene.add(sim::make_sphere(at(-0.5f, 0.3f, 1.8f), 0.3f));
  scene.add(sim::make_box(SE3<S>::translation(at(0.6f, 0.6f, 2.2f)), vec3(0.3f, 0.4f, 0.3f)));
  scene.add(sim::make_cylinder(SE3<S>::translation(at(-1.0f, 0.4f, 2.8f)), 0.2f, 0.6f));
  return scene;
}

template <class B, class Store>
TsdfVolume<S, B, Store> dense_volume(const Options& o, const SE3<S>& T_world_camera, const B& backend) {
  VolumeGeometry<S> g;
  g.dims = Vec3i{{o.voxels, o.voxels, o.voxels}};
  g.voxel_size = 5.12f / S(o.voxels);
  g.T_world_volume = volume_pose_in_front_of(T_world_camera, 5.12f);
  return TsdfVolume<S, B, Store>(g, backend);
}

/// The sparse volume with the dense one's voxel size and origin, room for
/// every block of the dense cube's size (the room fills a small part).
template <class B, class Store>
SparseTsdfVolume<S, B, Store> sparse_volume(const Options& o, const SE3<S>& T_world_camera, const B& backend) {
  SparseVolumeParams<S> p;
  p.voxel_size = 5.12f / S(o.voxels);
  p.T_world_volume = volume_pose_in_front_of(T_world_camera, 5.12f);
  const int side = (o.voxels + 7) / 8;
  p.block_capacity = int(std::min<std::int64_t>(std::int64_t(side) * side * side, std::int64_t(1) << 20));
  return SparseTsdfVolume<S, B, Store>(p, backend);
}

template <class B, class Store>
void run(const Options& o, const std::string& kind, Json* json) {
  const B backend{};
  const PinholeCamera<S> camera{};
  const SE3<S> T_world_camera = SE3<S>::identity();
  Image<S, B> depth;
  {
    // Depth beyond the dense cube's far face (5.12 m from the camera less a
    // truncation) is dropped: the floor runs on to the horizon, and a sparse
    // volume would map and march all of it where the cube holds 5 m.
    Image<S, Host> rendered;
    sim::render_depth(room(T_world_camera), camera, T_world_camera, rendered, static_cast<Image<int, Host>*>(nullptr),
                      {}, Host{});
    std::vector<S> d = rendered.to_host();
    for (S& z : d)
      if (z > S(5)) z = S(0);
    depth = Image<S, B>::from_host(camera.width, camera.height, d, backend);
  }
  RaycastResult<S, B> cast;
  using clock = std::chrono::steady_clock;
  auto time = [&](auto&& f) {
    backend.synchronize();
    const auto t0 = clock::now();
    f();
    backend.synchronize();
    return std::chrono::duration<double, std::milli>(clock::now() - t0).count();
  };
  std::vector<double> integrate_ms, raycast_ms, allocate_ms;
  std::size_t memory = 0;
  const Image<S, B>* const no_weights = nullptr;
  const auto measure = [&](auto& volume, auto&& fuse, auto&& allocate) {
    for (int k = 0; k <= o.repeats; ++k) {
      const double ti = time(fuse);
      const double tr = time([&] { raycast(volume, camera, T_world_camera, cast); });
      const double ta = time(allocate);
      if (k > 0) integrate_ms.push_back(ti), raycast_ms.push_back(tr), allocate_ms.push_back(ta);  // k = 0 warms up
    }
    memory = volume.memory_bytes();
  };
  if (kind == "dense") {
    auto volume = dense_volume<B, Store>(o, T_world_camera, backend);
    IntegrationWorkspace<S, B> ws;
    measure(
        volume, [&] { integrate(volume, depth, camera, T_world_camera, no_weights, {}, &ws); }, [] {});
  } else {
    auto volume = sparse_volume<B, Store>(o, T_world_camera, backend);
    SparseIntegrationWorkspace<S, B> ws;
    measure(
        volume, [&] { integrate(volume, depth, camera, T_world_camera, no_weights, {}, &ws); },
        [&] { allocate_blocks(volume, depth, camera, T_world_camera, no_weights, &ws); });
  }
  const Stats si = stats(integrate_ms), sr = stats(raycast_ms), sa = stats(allocate_ms);
  // The raycast's depth against the rendered one, where both exist.
  const std::vector<S> truth = depth.to_host(), cast_depth = cast.depth.to_host();
  std::vector<double> error_mm;
  for (std::size_t i = 0; i < truth.size(); ++i)
    if (truth[i] > S(0) && cast_depth[i] > S(0)) error_mm.push_back(1000.0 * std::fabs(double(cast_depth[i] - truth[i])));
  const Stats se = error_mm.empty() ? Stats{} : stats(error_mm);
  fmt::print("{:<5} {:<5} {:<6} {:4}^3 ({:6.0f} MiB)  integrate median {:8.2f} ms  p90 {:8.2f} ms", B::name, o.store,
             kind, o.voxels, double(memory) / 1048576.0, si.median, si.p90);
  if (kind == "sparse") fmt::print(" (allocate {:.2f} ms)", sa.median);
  fmt::print(" | raycast median {:8.2f} ms  p90 {:8.2f} ms | depth error median {:.3f} mm  p90 {:.3f} mm\n", sr.median,
             sr.p90, se.median, se.p90);
  if (json) {
    const auto statistics = [](const Stats& s) {
      Json entry;
      entry["median"] = s.median;
      entry["p90"] = s.p90;
      return entry;
    };
    Json entry;
    entry["backend"] = B::name;
    entry["store"] = o.store;
    entry["volume"] = kind;
    entry["voxels"] = o.voxels;
    entry["repeats"] = o.repeats;
    entry["memory_bytes"] = memory;
    entry["integrate_ms"] = statistics(si);
    if (kind == "sparse") entry["allocate_ms"] = statistics(sa);
    entry["raycast_ms"] = statistics(sr);
    entry["depth_error_mm"] = statistics(se);
    json->push_back(std::move(entry));
  }
}

template <class B, class Store>
void run_volumes(const Options& o, Json* json) {
  if (o.volume != "sparse") run<B, Store>(o, "dense", json);
  if (o.volume != "dense") run<B, Store>(o, "sparse", json);
}

Options parse(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) throw std::invalid_argument("unknown option or missing value: '" + a + "'");
    const std::string v = argv[++i];
    if (a == "--voxels") o.voxels = examples::parse_positive_int(a, v, 2048);
    else if (a == "--repeats") o.repeats = examples::parse_positive_int(a, v);
    else if (a == "--backend") o.backend = v;
    else if (a == "--store") o.store = v;
    else if (a == "--volume") o.volume = v;
    else if (a == "--json") o.json = v;
    else throw std::invalid_argument("unknown option '" + a + "'");
  }
  if (o.backend != "cpu" && o.backend != "cuda" && o.backend != "all")
    throw std::invalid_argument("--backend must be cpu, cuda or all");
  if (o.store != "float" && o.store != "half") throw std::invalid_argument("--store must be float or half");
  if (o.volume != "dense" && o.volume != "sparse" && o.volume != "both")
    throw std::invalid_argument("--volume must be dense, sparse or both");
  return o;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const Options o = parse(argc, argv);
    // One entry per backend run, as an array; an empty one is written
    // first so that an unwritable --json fails before the timing starts.
    Json results = Json::array();
    Json* json = o.json.empty() ? nullptr : &results;
    if (json) write_json_file(o.json, results);
    const bool half = o.store == "half";
    if (o.backend != "cuda") half ? run_volumes<Host, Half>(o, json) : run_volumes<Host, S>(o, json);
#if EMFUSION_HAS_CUDA
    if (o.backend != "cpu") half ? run_volumes<Cuda, Half>(o, json) : run_volumes<Cuda, S>(o, json);
#else
    if (o.backend == "cuda") throw std::invalid_argument("this build has no CUDA backend");
#endif
    if (json) write_json_file(o.json, results);
    return 0;
  } catch (const std::exception& e) {
    fmt::print(stderr, "bench_volume: error: {}\n", e.what());
    return 1;
  }
}
