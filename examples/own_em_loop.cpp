// own_em_loop: an EM-Fusion loop of a user's own, written from the stage
// headers of slam/ alone (no System): the background and detector-driven
// objects, tracked and mapped as in the paper, but with detection handling
// of its own that never resizes an object and never brings a lost one back
// (deleted is deleted, the paper's rule). It runs on the built-in dynamic
// scene and prints the camera's and the objects' ATE (docs/user-guide.md,
// "Write your own loop").
//
//   own_em_loop [--frames N] [--backend cpu|cuda] [--max-ate-cm X]
//
// --max-ate-cm: exit 1 unless the camera and every object tracked are
// within X cm (ctest runs it so).
#include <cmath>
#include <cstdio>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <fmt/core.h>

#include "emfusion/detect/matching.hpp"
#include "emfusion/eval/ate.hpp"
#include "emfusion/eval/object_matching.hpp"
#include "emfusion/slam/association.hpp"
#include "emfusion/slam/detection_handling.hpp"
#include "emfusion/slam/lifecycle.hpp"
#include "emfusion/slam/mapping.hpp"
#include "emfusion/slam/preprocessing.hpp"
#include "emfusion/slam/rendering.hpp"
#include "emfusion/slam/tracking.hpp"
#include "support/args.hpp"
#include "support/backend.hpp"
#include "support/workload.hpp"

using namespace emfusion;
using S = float;

namespace {

/// Detection handling without resizing or re-identification: match by mask
/// IoU, count existence, make an object of every unmatched detection the
/// creation rules allow. Returns the new objects' first-view weights.
template <class B>
std::vector<NewObjectWeights<S, B>> handle(Map<S, B>& map, const Frame<S, B>& frame, const Detections& det,
                                           const std::vector<int>& seg, const PinholeCamera<S>& camera,
                                           const SystemParams<S>& params, S outside, std::vector<int>& object_of) {
  FrameResult notes;  // create_object reports what it did here; this loop does not need it
  const DetectionMatch match = match_detections(mask_iou(det, seg, int(map.objects.size())), params.match_iou);
  object_of = match.object_of;
  std::vector<bool> seen(map.objects.size(), false);
  for (int o : object_of)
    if (o >= 0) seen[std::size_t(o)] = true;
  for (std::size_t k = 0; k < map.objects.size(); ++k) seen[k] ? map.objects[k]->count_detected() : map.objects[k]->count_missed();
  std::vector<NewObjectWeights<S, B>> fresh;
  const std::vector<Vec3<S>> points = frame.points.to_host();
  for (std::size_t d = 0; d < det.instances.size(); ++d)
    if (object_of[d] < 0)
      if (auto w = create_object(map, det, int(d), seg, points, camera, params, outside, notes))
        fresh.push_back(std::move(*w));
  return fresh;
}

template <class B>
int run(int frames, double max_ate_cm) {
  const examples::Workload w = examples::load_workload("", frames, 320, 3);  // synthetic:room-small
  const PinholeCamera<S> camera = w.camera.template cast<S>();
  SystemParams<S> params;
  params.background_voxels = 256;
  params.background_voxel_size = S(0.02);
  params.lost_object_frames = 0;  // no lost objects: this loop cannot bring them back

  // The parts: the paper's likelihood, Huber norms of 2 voxels, LM.
  PaperLikelihood<S> likelihood;
  likelihood.params = params.likelihood;
  const HuberNorm<S> huber{params.huber_voxels};
  const LevenbergMarquardt solver{params.lm};
  const S outside = unexplained_association<S>(likelihood);

  Map<S, B> map(params);
  Frame<S, B> frame;
  RenderWorkspace<S, B> render;
  for (std::size_t i = 0; i < w.depth.size(); ++i) {
    const double t = w.timestamps[i];
    preprocess(w.depth[i].template to<B>(), camera, params, frame);
    frame.object_tracks.assign(map.objects.size(), PoseTrack{});
    if (map.started) {
      associate(map, frame, likelihood, params);  // E-step at the previous poses
      if (track_camera(map, frame, params, huber, solver).outcome != TrackingOutcome::tracked) {
        map.record_poses(t);  // keep every pose, map nothing
        ++map.frames;
        continue;
      }
      associate(map, frame, likelihood, params);  // at the new camera pose
      frame.object_tracks = track_objects(map, frame, params, huber, solver);
      associate(map, frame, likelihood, params);  // at the final poses: the mapping weights
    }
    render_models(map, frame, camera, params, render);

    const std::optional<Detections>& det = w.detections[i];
    std::vector<NewObjectWeights<S, B>> fresh;
    std::vector<int> object_of;
    const std::vector<int> seg = det ? frame.segmentation.to_host() : std::vector<int>{};
    if (det && map.started) fresh = handle(map, frame, *det, seg, camera, params, outside, object_of);

    const bool first = !map.started;
    integrate_models(map, frame, camera, params, fresh, first);
    if (det && !first) update_foreground_counts(map, frame, *det, seg, object_of, fresh, camera);
    map.started = true;
    map.record_poses(t);
    FrameResult result;
    delete_objects(map, frame, params, result, det && !first, int(fresh.size()), !first);
    for (int id : result.deleted) fmt::print("frame {}: deleted object {}\n", i, id);
    ++map.frames;
  }

  const double camera_ate = eval::absolute_trajectory_error(map.camera_trajectory, *w.camera_truth).rmse;
  fmt::print("{} frames on {}: camera ATE {:.2f} cm\n", w.depth.size(), B::name, 100 * camera_ate);
  bool within = 100 * camera_ate < max_ate_cm;
  std::map<int, Trajectory> estimates;
  for (const ObjectRecord& r : map.records) estimates[r.id] = r.trajectory;
  int tracked = 0;
  for (const auto& o : eval::evaluate_objects(map.camera_trajectory, *w.camera_truth, estimates, w.object_truth)) {
    if (!o.evaluated) {
      fmt::print("object {:<12} not tracked ({})\n", o.name, o.problem);
      continue;
    }
    ++tracked;
    fmt::print("object {:<12} ATE {:.2f} cm, coverage {:.0f} %\n", o.name, 100 * o.result.ate.rmse,
               100 * o.result.coverage);
    within = within && 100 * o.result.ate.rmse < max_ate_cm;
  }
  if (max_ate_cm < INFINITY && (!within || tracked == 0)) {
    fmt::print(stderr, "own_em_loop: the camera or an object is not within {:.2f} cm (or no object was tracked)\n",
               max_ate_cm);
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    int frames = 150;
    double max_ate_cm = INFINITY;
    std::string backend = "cpu";
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      if (i + 1 >= argc) throw std::invalid_argument("unknown option or missing value: '" + a + "'");
      const std::string v = argv[++i];
      if (a == "--frames")
        frames = examples::parse_positive_int(a, v, 100000);
      else if (a == "--backend")
        backend = v;
      else if (a == "--max-ate-cm")
        max_ate_cm = examples::parse_positive_double(a, v);
      else
        throw std::invalid_argument("unknown option '" + a + "'");
    }
    int rc = 0;
    examples::with_backend(backend, [&](auto b) { rc = run<decltype(b)>(frames, max_ate_cm); });
    return rc;
  } catch (const std::exception& e) {
    fmt::print(stderr, "own_em_loop: error: {}\n", e.what());
    return 1;
  }
}
