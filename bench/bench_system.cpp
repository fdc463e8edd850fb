// bench_system: the whole EM-Fusion system, per frame and per stage, on a
// synthetic dynamic scene (default: 640x480, 300 frames, a 512^3 background
// of 1 cm, 3 moving objects, the simulated detector every 30 frames) or on a
// TUM-layout sequence with its masks/ folder. Prints the median and 90th
// percentile of every stage and of the frame, peak host memory (and GPU
// memory on CUDA), and the camera and object ATE when there is ground truth;
// --json writes the same numbers.
//
//   bench_system [--backend cpu|cuda] [--frames N] [--objects K] [--width W]
//                [--voxels N] [--voxel-size M] [--sequence DIR] [--json FILE]
//                [--set key=value ...]
//
// --set overrides a system parameter by its name in the app's configuration
// (docs/parameters.md; io/config.hpp), after --voxels and --voxel-size.
//
// The first frame (allocation, no tracking) is left out of the statistics.
// The detector's own time is not part of the system's (it is precomputed,
// as a real detector runs beside the system). On small CPUs set
// OMP_WAIT_POLICY=passive (docs/benchmarks.md).
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <fmt/core.h>

#include "emfusion/eval/ate.hpp"
#include "emfusion/io/config.hpp"
#include "emfusion/io/masks.hpp"
#include "emfusion/io/run_outputs.hpp"
#include "emfusion/io/tum.hpp"
#include "emfusion/sim/detector.hpp"
#include "emfusion/sim/dynamic_scene.hpp"
#include "support/system_host.hpp"  // emfusion/slam/system.hpp, System<float, Host> compiled once
#include "support/args.hpp"
#include "memory.hpp"
#include "report.hpp"
#include "support/workload.hpp"
#include "support/backend.hpp"

using namespace emfusion;
using S = float;

namespace {

struct Options {
  std::string backend = "cpu", sequence, json;
  int frames = 300, objects = 3, width = 640, voxels = 512;
  double voxel_size = 0.01;
  std::vector<std::string> overrides;  // --set key=value
};

struct Stats {
  double median = 0, p90 = 0;
};

Stats stats(std::vector<double> v) {
  if (v.empty()) return {};
  std::sort(v.begin(), v.end());
  return {v[v.size() / 2], v[std::min(v.size() - 1, (v.size() * 9) / 10)]};
}

template <class B>
void run(const Options& o) {
  const examples::Workload w = examples::load_workload(o.sequence, o.frames, o.width, o.objects);
  SystemParams<S> params;
  params.background_voxels = o.voxels;
  params.background_voxel_size = S(o.voxel_size);
  for (const std::string& assignment : o.overrides) apply_override(params, assignment);
  const B backend{};
  const double device_before = bench::device_used_mib<B>();
  double device_peak = device_before;
  System<S, B> system(w.camera.cast<S>(), params, backend);
  std::vector<StageTimes> times;
  int max_objects = 0;
  for (std::size_t i = 0; i < w.depth.size(); ++i) {
    const Image<S, B> depth = w.depth[i].template to<B>(backend);
    const FrameResult r = system.process(depth, w.timestamps[i], w.detections[i] ? &*w.detections[i] : nullptr);
    if (i > 0) times.push_back(r.times);
    max_objects = std::max(max_objects, r.live_objects);
    device_peak = std::max(device_peak, bench::device_used_mib<B>());
  }

  Json json;
  json["backend"] = B::name;
  json["input"] = o.sequence.empty() ? "synthetic" : o.sequence;
  json["frames"] = w.depth.size();
  json["width"] = w.camera.width;
  json["height"] = w.camera.height;
  json["background_voxels"] = o.voxels;
  json["background_voxel_size_m"] = o.voxel_size;
  json["max_live_objects"] = max_objects;
  const std::string background = system.background().describe();
  const double background_mib = double(system.background().memory_bytes()) / (1 << 20);
  json["background"] = background;
  json["background_mib"] = background_mib;
  fmt::print("{}, {} frames of {}x{}, background {} of {:.3g} m ({:.1f} MiB), up to {} live objects\n", B::name,
             w.depth.size(), w.camera.width, w.camera.height, background, o.voxel_size, background_mib, max_objects);
  fmt::print("{:<18} {:>10} {:>10}\n", "stage (ms)", "median", "p90");
  Json& timings = json["timings_ms"] = Json::object();
  const std::pair<const char*, double StageTimes::*> stages[] = {
      {"preprocess", &StageTimes::preprocess},   {"e_step", &StageTimes::e_step},
      {"track_background", &StageTimes::track_background}, {"track_objects", &StageTimes::track_objects},
      {"raycast", &StageTimes::raycast},         {"detections", &StageTimes::detections},
      {"integrate", &StageTimes::integrate},     {"foreground", &StageTimes::foreground},
      {"total", &StageTimes::total}};
  for (const auto& [name, field] : stages) {
    std::vector<double> v;
    for (const StageTimes& t : times) v.push_back(t.*field);
    const Stats s = stats(v);
    fmt::print("{:<18} {:10.2f} {:10.2f}\n", name, s.median, s.p90);
    Json& entry = timings[name] = Json::object();
    entry["median"] = s.median;
    entry["p90"] = s.p90;
  }
  const double host = bench::peak_host_mib(), device = device_peak - device_before;
  fmt::print("peak host memory {:.0f} MiB; device memory used by the system {:.0f} MiB\n", host, device);
  json["peak_host_mib"] = host;
  json["device_mib"] = device;
  if (w.camera_truth && system.camera_trajectory().size() >= 3) {
    const auto ate = eval::absolute_trajectory_error(system.camera_trajectory(), *w.camera_truth);
    fmt::print("camera ATE {:.2f} cm\n", 100 * ate.rmse);
    json["camera_ate_m"] = ate.rmse;
    bench::report_objects(system, *w.camera_truth, w.object_truth, json);
  }
  if (!o.json.empty()) write_json_file(o.json, json);
}

}  // namespace

int main(int argc, char** argv) {
  try {
    Options o;
    examples::for_each_option(argc, argv, [&](const std::string& a, const std::string& v) {
      if (a == "--backend") o.backend = v;
      else if (a == "--frames") o.frames = examples::parse_positive_int(a, v);
      else if (a == "--objects") o.objects = examples::parse_int(a, v, 1, 8);
      else if (a == "--width") o.width = examples::parse_int(a, v, 64, 4096);
      else if (a == "--voxels") o.voxels = examples::parse_int(a, v, 8, 2048);
      else if (a == "--voxel-size") o.voxel_size = examples::parse_positive_double(a, v);
      else if (a == "--sequence") o.sequence = v;
      else if (a == "--json") o.json = v;
      else if (a == "--set") o.overrides.push_back(v);
      else throw std::invalid_argument("unknown option '" + a + "'");
    });
    examples::with_backend(o.backend, [&](auto backend) { run<decltype(backend)>(o); });
    return 0;
  } catch (const std::exception& e) {
    fmt::print(stderr, "bench_system: error: {}\n", e.what());
    return 1;
  }
}
