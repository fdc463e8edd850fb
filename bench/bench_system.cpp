// bench_system: the whole EM-Fusion system, per frame and per stage, on a
// synthetic dynamic scene (default: 640x480, 300 frames, a 512^3 background
// of 1 cm, 3 moving objects, the simulated detector every 30 frames) or on a
// TUM-layout sequence with its masks/ folder. Prints the median and 90th
// percentile of every stage and of the frame, peak host memory (and GPU
// memory on CUDA), and the camera and object ATE when there is ground truth;
// --json writes the same numbers. `--sweep 1,2,4,8,16` runs the synthetic scene
// once per number of moving objects instead and prints the frame's median,
// 90th and 99th percentiles against the objects tracked, the device memory
// of each run, and the cost of an added object: the slope of the
// least-squares line through median frame time against objects tracked
// (their mean over the frames: the scene's objects appear one by one, and
// a static class is never tracked).
//
//   bench_system [--backend cpu|cuda] [--frames N] [--objects K] [--width W]
//                [--voxels N] [--voxel-size M] [--sequence DIR] [--json FILE]
//                [--set key=value ...] [--sweep K1,K2,...]
//
// --set overrides a system parameter by its name in the app's configuration
// (docs/parameters.md; io/config.hpp), after --voxels and --voxel-size.
//
// The first frame (allocation, no tracking) is left out of the statistics.
// The detector's own time is not part of the system's (it is precomputed,
// as a real detector runs beside the system). On small CPUs set
// OMP_WAIT_POLICY=passive (docs/benchmarks.md).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
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
  std::vector<int> sweep;              // --sweep: object counts of the synthetic scene
};

struct Stats {
  double median = 0, p90 = 0, p99 = 0;
};

Stats stats(std::vector<double> v) {
  if (v.empty()) return {};
  std::sort(v.begin(), v.end());
  const auto at = [&](std::size_t per_cent) { return v[std::min(v.size() - 1, (v.size() * per_cent) / 100)]; };
  return {v[v.size() / 2], at(90), at(99)};
}

/// One run of the system over a workload: every frame's stage times but the
/// first's, the live objects, the device memory it took.
struct Run {
  std::vector<StageTimes> times;
  int max_objects = 0;
  double mean_objects = 0;  ///< live objects, mean over the timed frames
  double device_mib = 0;
};

template <class B>
Run process_all(System<S, B>& system, const examples::Workload& w, const B& backend, double device_before) {
  Run run;
  double device_peak = device_before, objects = 0;
  for (std::size_t i = 0; i < w.depth.size(); ++i) {
    const Image<S, B> depth = w.depth[i].template to<B>(backend);
    const FrameResult r = system.process(depth, w.timestamps[i], w.detections[i] ? &*w.detections[i] : nullptr);
    if (i > 0) run.times.push_back(r.times), objects += r.live_objects;
    run.max_objects = std::max(run.max_objects, r.live_objects);
    device_peak = std::max(device_peak, bench::device_used_mib<B>());
  }
  run.mean_objects = run.times.empty() ? 0 : objects / double(run.times.size());
  run.device_mib = device_peak - device_before;
  return run;
}

SystemParams<S> system_params(const Options& o) {
  SystemParams<S> params;
  params.background_voxels = o.voxels;
  params.background_voxel_size = S(o.voxel_size);
  for (const std::string& assignment : o.overrides) apply_override(params, assignment);
  return params;
}

template <class B>
void run(const Options& o) {
  const examples::Workload w = examples::load_workload(o.sequence, o.frames, o.width, o.objects);
  const SystemParams<S> params = system_params(o);
  const B backend{};
  const double device_before = bench::device_used_mib<B>();
  System<S, B> system(w.camera.cast<S>(), params, backend);
  const Run run = process_all(system, w, backend, device_before);
  const std::vector<StageTimes>& times = run.times;
  const int max_objects = run.max_objects;

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
  fmt::print("{:<18} {:>10} {:>10} {:>10}\n", "stage (ms)", "median", "p90", "p99");
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
    fmt::print("{:<18} {:10.2f} {:10.2f} {:10.2f}\n", name, s.median, s.p90, s.p99);
    Json& entry = timings[name] = Json::object();
    entry["median"] = s.median;
    entry["p90"] = s.p90;
    entry["p99"] = s.p99;
  }
  const double host = bench::peak_host_mib(), device = run.device_mib;
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

/// Slope of the least-squares line through (x, y); NaN when every x is the
/// same.
double slope(const std::vector<double>& x, const std::vector<double>& y) {
  const double n = double(x.size());
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (std::size_t i = 0; i < x.size(); ++i) sx += x[i], sy += y[i], sxx += x[i] * x[i], sxy += x[i] * y[i];
  const double d = n * sxx - sx * sx;
  return d > 0 ? (n * sxy - sx * sy) / d : std::numeric_limits<double>::quiet_NaN();
}

template <class B>
void sweep(const Options& o) {
  if (!o.sequence.empty()) throw std::invalid_argument("--sweep runs the synthetic scene: leave out --sequence");
  const SystemParams<S> params = system_params(o);
  const B backend{};
  fmt::print("{}, synthetic scene, {} frames of width {}: the frame (ms) against the objects tracked\n", B::name,
             o.frames, o.width);
  fmt::print("{:>9} {:>8} {:>10} {:>10} {:>10} {:>12}\n", "requested", "tracked", "median", "p90", "p99",
             "device MiB");
  Json json;
  json["backend"] = B::name;
  json["frames"] = o.frames;
  json["width"] = o.width;
  Json& rows = json["sweep"] = Json::array();
  std::vector<double> tracked, medians;
  for (const int objects : o.sweep) {
    const examples::Workload w = examples::load_workload("", o.frames, o.width, objects);
    const double device_before = bench::device_used_mib<B>();
    System<S, B> system(w.camera.cast<S>(), params, backend);
    const Run run = process_all(system, w, backend, device_before);
    std::vector<double> totals;
    for (const StageTimes& t : run.times) totals.push_back(t.total);
    const Stats s = stats(totals);
    fmt::print("{:>9} {:>8.2f} {:>10.2f} {:>10.2f} {:>10.2f} {:>12.0f}\n", objects, run.mean_objects, s.median, s.p90,
               s.p99, run.device_mib);
    tracked.push_back(run.mean_objects);
    medians.push_back(s.median);
    Json row = Json::object();
    row["requested_objects"] = objects;
    row["tracked_objects_mean"] = run.mean_objects;
    row["max_live_objects"] = run.max_objects;
    row["median_ms"] = s.median;
    row["p90_ms"] = s.p90;
    row["p99_ms"] = s.p99;
    row["device_mib"] = run.device_mib;
    rows.push_back(row);
  }
  const double per_object = slope(tracked, medians);
  if (std::isfinite(per_object)) {
    fmt::print("each added object: {:.3f} ms per frame (least squares over {} runs)\n", per_object, o.sweep.size());
    json["ms_per_added_object"] = per_object;
  } else {
    fmt::print("each added object: undefined (every run tracked as many objects; more frames let them appear)\n");
    json["ms_per_added_object"] = nullptr;
  }
  if (!o.json.empty()) write_json_file(o.json, json);
}

/// "1,2,4,8,16": object counts from 1 to 16 (the room holds 16), at least two.
std::vector<int> parse_sweep(const std::string& flag, const std::string& value) {
  std::vector<int> counts;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = value.find(',', start);
    counts.push_back(examples::parse_int(flag, value.substr(start, comma - start), 1, sim::max_room_objects));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  if (counts.size() < 2)
    throw std::invalid_argument(flag + " needs at least two object counts (a line through one point has no slope), got '" +
                                value + "'");
  return counts;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    Options o;
    examples::for_each_option(argc, argv, [&](const std::string& a, const std::string& v) {
      if (a == "--backend") o.backend = v;
      else if (a == "--frames") o.frames = examples::parse_positive_int(a, v);
      else if (a == "--objects") o.objects = examples::parse_int(a, v, 1, sim::max_room_objects);
      else if (a == "--width") o.width = examples::parse_int(a, v, 64, 4096);
      else if (a == "--voxels") o.voxels = examples::parse_int(a, v, 8, 2048);
      else if (a == "--voxel-size") o.voxel_size = examples::parse_positive_double(a, v);
      else if (a == "--sequence") o.sequence = v;
      else if (a == "--json") o.json = v;
      else if (a == "--set") o.overrides.push_back(v);
      else if (a == "--sweep") o.sweep = parse_sweep(a, v);
      else throw std::invalid_argument("unknown option '" + a + "'");
    });
    examples::with_backend(o.backend, [&](auto backend) {
      if (o.sweep.empty())
        run<decltype(backend)>(o);
      else
        sweep<decltype(backend)>(o);
    });
    return 0;
  } catch (const std::exception& e) {
    fmt::print(stderr, "bench_system: error: {}\n", e.what());
    return 1;
  }
}
