// bench_longrun: a long run of the whole system on a synthetic dynamic scene
// (default 3000 frames), rendering each frame when it is needed so that the
// process holds one frame at a time. Every --sample-every frames it records
// the resident host memory and the device memory in use; at the end it
// prints the samples, the growth after warm-up (the last sample minus the
// first one at or after --warmup frames) and the camera and object ATE.
// With --max-growth-mib X it exits with status 2 when either growth exceeds
// X, so that a test can hold the system to flat memory.
//
//   bench_longrun [--backend cpu|cuda] [--frames N] [--objects K] [--width W]
//                 [--voxels N] [--voxel-size M] [--sample-every N]
//                 [--warmup N] [--max-growth-mib X] [--json FILE]
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include <fmt/core.h>

#include "emfusion/eval/ate.hpp"
#include "emfusion/io/run_outputs.hpp"
#include "emfusion/sim/detector.hpp"
#include "emfusion/sim/dynamic_scene.hpp"
#include "support/system_host.hpp"  // emfusion/slam/system.hpp, System<float, Host> compiled once
#include "memory.hpp"
#include "report.hpp"
#include "support/workload.hpp"
#include "support/args.hpp"
#include "support/backend.hpp"

using namespace emfusion;
using S = float;

namespace {

struct Options {
  std::string backend = "cpu", json;
  int frames = 3000, objects = 3, width = 320, voxels = 256, sample_every = 100, warmup = 500;
  double voxel_size = 0.02, max_growth_mib = -1;
};

struct Sample {
  int frame = 0;
  double host_mib = 0, device_mib = 0, model_mib = 0;
  int live_objects = 0, created = 0, deleted = 0;
};

template <class B>
int run(const Options& o) {
  examples::SyntheticRoom room = examples::synthetic_room(o.frames, o.width, o.objects);
  const sim::DynamicSceneParams& p = room.params;
  const sim::SyntheticSequence& seq = room.sequence;
  sim::SimulatedDetector<float>& detector = room.detector;

  SystemParams<S> params;
  params.background_voxels = o.voxels;
  params.background_voxel_size = S(o.voxel_size);
  const B backend{};
  System<S, B> system(seq.camera().cast<S>(), params, backend);

  fmt::print("{}, {} frames of {}x{}, background {}^3 x {:.3g} m, {} moving objects\n", B::name, seq.size(), p.width,
             p.height, o.voxels, o.voxel_size, o.objects);
  fmt::print("{:>8} {:>10} {:>12} {:>11} {:>6} {:>8} {:>8} {:>10}\n", "frame", "host MiB", "device MiB", "models MiB",
             "live", "created", "deleted", "ms/frame");
  std::vector<Sample> samples;
  std::vector<double> frame_ms;
  int created = 0, deleted = 0;
  for (std::size_t i = 0; i < seq.size(); ++i) {
    const Image<S, B> depth = seq.depth(i).template to<B>(backend);
    const std::optional<Detections> det = detector.detect(int(i), seq.timestamp(i));
    const FrameResult r = system.process(depth, seq.timestamp(i), det ? &*det : nullptr);
    created += int(r.created.size());
    deleted += int(r.deleted.size());
    if (i > 0) frame_ms.push_back(r.times.total);
    const int frame = int(i) + 1;
    if (frame % o.sample_every == 0 || i + 1 == seq.size()) {
      const Sample s{frame,           bench::current_host_mib(), bench::device_used_mib<B>(),
                     double(system.memory_bytes()) / 1048576.0, r.live_objects, created, deleted};
      samples.push_back(s);
      std::vector<double> recent(frame_ms.end() - std::min<std::ptrdiff_t>(std::ptrdiff_t(frame_ms.size()), o.sample_every),
                                 frame_ms.end());
      std::sort(recent.begin(), recent.end());
      fmt::print("{:8} {:10.1f} {:12.1f} {:11.1f} {:6} {:8} {:8} {:10.2f}\n", s.frame, s.host_mib, s.device_mib,
                 s.model_mib, s.live_objects, s.created, s.deleted, recent.empty() ? 0.0 : recent[recent.size() / 2]);
      std::fflush(stdout);
    }
  }

  // Growth after warm-up: last sample minus the first at or after --warmup.
  const auto first = std::find_if(samples.begin(), samples.end(), [&](const Sample& s) { return s.frame >= o.warmup; });
  double host_growth = 0, device_growth = 0;
  if (first != samples.end()) {
    host_growth = samples.back().host_mib - first->host_mib;
    device_growth = samples.back().device_mib - first->device_mib;
    fmt::print("growth from frame {} to {}: host {:+.1f} MiB, device {:+.1f} MiB, models {:+.1f} MiB\n", first->frame,
               samples.back().frame, host_growth, device_growth, samples.back().model_mib - first->model_mib);
    // On the CPU the models are host memory: what the process holds beyond
    // them should stay flat.
    if (!B::is_device) {
      double low = 1e300, high = -1e300;
      for (auto s = first; s != samples.end(); ++s)
        low = std::min(low, s->host_mib - s->model_mib), high = std::max(high, s->host_mib - s->model_mib);
      fmt::print("host memory beyond the models from frame {} on: {:.1f} to {:.1f} MiB\n", first->frame, low, high);
    }
  } else {
    fmt::print("no sample at or after the warm-up (frame {}): growth not measured\n", o.warmup);
  }

  Json json;
  json["backend"] = B::name;
  json["frames"] = seq.size();
  json["width"] = p.width;
  json["height"] = p.height;
  json["objects"] = o.objects;
  json["background_voxels"] = o.voxels;
  json["background_voxel_size_m"] = o.voxel_size;
  json["warmup"] = o.warmup;
  json["host_growth_mib"] = host_growth;
  json["device_growth_mib"] = device_growth;
  json["peak_host_mib"] = bench::peak_host_mib();
  Json& sampled = json["samples"] = Json::object();  // keyed by frame
  for (const Sample& s : samples) {
    Json& entry = sampled[std::to_string(s.frame)] = Json::object();
    entry["host_mib"] = s.host_mib;
    entry["device_mib"] = s.device_mib;
    entry["model_mib"] = s.model_mib;
    entry["live_objects"] = s.live_objects;
    entry["created"] = s.created;
    entry["deleted"] = s.deleted;
  }
  if (system.camera_trajectory().size() >= 3) {  // the ATE needs three poses
    const auto ate = eval::absolute_trajectory_error(system.camera_trajectory(), seq.scene().camera_trajectory());
    fmt::print("camera ATE {:.2f} cm over {} frames\n", 100 * ate.rmse, seq.size());
    json["camera_ate_m"] = ate.rmse;
    std::map<std::string, Trajectory> truth;
    for (int k = 0; k < seq.scene().object_count(); ++k)
      truth[seq.scene().object_name(k)] = seq.scene().object_trajectory(k);
    bench::report_objects(system, seq.scene().camera_trajectory(), truth, json);
  }
  if (!o.json.empty()) write_json_file(o.json, json);

  if (o.max_growth_mib >= 0 && (host_growth > o.max_growth_mib || device_growth > o.max_growth_mib)) {
    fmt::print(stderr, "bench_longrun: memory grew by more than {:.1f} MiB after frame {} (host {:+.1f}, device {:+.1f})\n",
               o.max_growth_mib, o.warmup, host_growth, device_growth);
    return 2;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    Options o;
    examples::for_each_option(argc, argv, [&](const std::string& a, const std::string& v) {
      if (a == "--backend") o.backend = v;
      else if (a == "--frames") o.frames = examples::parse_positive_int(a, v, 1000000);
      else if (a == "--objects") o.objects = examples::parse_int(a, v, 1, sim::max_room_objects);
      else if (a == "--width") o.width = examples::parse_int(a, v, 64, 4096);
      else if (a == "--voxels") o.voxels = examples::parse_int(a, v, 8, 2048);
      else if (a == "--voxel-size") o.voxel_size = examples::parse_positive_double(a, v);
      else if (a == "--sample-every") o.sample_every = examples::parse_positive_int(a, v, 1000000);
      else if (a == "--warmup") o.warmup = examples::parse_int(a, v, 0, 1000000);
      else if (a == "--max-growth-mib") o.max_growth_mib = examples::parse_positive_double(a, v);
      else if (a == "--json") o.json = v;
      else throw std::invalid_argument("unknown option '" + a + "'");
    });
    int status = 0;
    examples::with_backend(o.backend, [&](auto backend) { status = run<decltype(backend)>(o); });
    return status;
  } catch (const std::exception& e) {
    fmt::print(stderr, "bench_longrun: error: {}\n", e.what());
    return 1;
  }
}
