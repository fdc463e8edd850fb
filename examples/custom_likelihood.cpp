// custom_likelihood: a measurement likelihood that is not the paper's,
// defined in this file alone, run through the full EM-Fusion system beside
// the paper's model on the same frames. Prints the camera's and every
// object's ATE for both (docs/user-guide.md, "Plug in your own likelihood,
// norm or solver").
//
//   custom_likelihood [<sequence-dir>] [--backend cpu|cuda] [--max-frames N]
//
// <sequence-dir> is a TUM-layout sequence with masks/ and ground truth
// (groundtruth.txt, groundtruth_objects/), as ../shared/data/room_dyn_300;
// without one, the built-in scene synthetic:room-small runs.
//
// The model: the paper's mixture (eq. 7) with a Laplace scale that grows
// with the point's depth as a structured-light sensor's noise does. The
// paper's scale (2 cm) stands for how far a measured point may lie from a
// model's surface that explains it: misalignment, discretisation, sensor
// noise. Here the sensor's axial noise at the point's depth (the Kinect v1
// model of Nguyen et al. 2012, kinect_depth_sigma) is added to it in
// quadrature, `noise_scale` times over: 2.1 cm at 1 m, 4.7 cm at 3 m.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include <fmt/core.h>

#include "emfusion/eval/ate.hpp"
#include "emfusion/eval/object_matching.hpp"
#include "emfusion/slam/system.hpp"
#include "support/args.hpp"
#include "support/backend.hpp"
#include "support/workload.hpp"

using namespace emfusion;

/// The user's model: everything the system needs is the two view members it
/// points at each model's maps and a device-callable likelihood; this one
/// also asks for the point in the camera frame (its depth). It reads its
/// volume through any view type (`with_volume` names the model over
/// another), so that the system can give it the sparse background, the
/// default; a model over TsdfView alone runs with sparse_background = false.
template <class S, class View = TsdfView<S, const S>>
struct DepthScaledLaplace {
  template <class OtherView>
  using with_volume = DepthScaledLaplace<S, OtherView>;
  View volume;                                ///< set by the system per model
  ForegroundView<S, const float> foreground;  ///< empty for the background
  S alpha = S(0.8);                           ///< weight of the inlier component
  S sigma = S(0.02);                          ///< the paper's Laplace scale, metres
  S noise_scale = S(3);                       ///< sensor noise added, in its standard deviations
  S p_uniform = S(1);                         ///< the outlier density

  EMF_HD S likelihood(const Vec3<S>& p_volume, const Vec3<S>& p_camera) const {
    if (!volume.contains_point(p_volume)) return S(0);
    S sdf;
    if (!volume.sample(p_volume, sdf)) sdf = volume.truncation;  // unobserved: as far as the map can say
    const S noise = noise_scale * kinect_depth_sigma(p_camera.z());
    const S b = std::sqrt(sigma * sigma + noise * noise);
    const S fg = foreground.empty() ? S(1) : foreground.probability(p_volume);
    return alpha * std::exp(-std::fabs(sdf) / b) / (S(2) * b) * fg + (S(1) - alpha) * p_uniform;
  }
};

namespace {

using S = float;

struct Options {
  std::string sequence, backend = "cpu";
  int max_frames = 100000;
};

struct Errors {
  double camera = NAN;
  std::map<std::string, eval::ObjectEvaluation> objects;
};

/// Runs the system of type Sys on the workload; returns its errors.
template <class Sys, class B>
Errors run(const examples::Workload& w, Sys& system, const B& backend) {
  for (std::size_t i = 0; i < w.depth.size(); ++i) {
    const Image<S, B> depth = w.depth[i].template to<B>(backend);
    system.process(depth, w.timestamps[i], w.detections[i] ? &*w.detections[i] : nullptr);
  }
  Errors e;
  if (!w.camera_truth || system.camera_trajectory().size() < 3) return e;
  e.camera = eval::absolute_trajectory_error(system.camera_trajectory(), *w.camera_truth).rmse;
  std::map<int, Trajectory> estimates;
  for (const ObjectRecord& r : system.object_records()) estimates[r.id] = r.trajectory;
  for (auto& o : eval::evaluate_objects(system.camera_trajectory(), *w.camera_truth, estimates, w.object_truth))
    e.objects[o.name] = o;
  return e;
}

std::string cell(const eval::ObjectEvaluation* o) {
  if (!o || !o->evaluated) return "-";
  return fmt::format("{:.2f} cm ({:.0f} %)", 100 * o->result.ate.rmse, 100 * o->result.coverage);
}

template <class B>
void compare(const Options& o) {
  // The built-in scene is synthetic:room-small: 150 frames of 320x240.
  const int frames = o.sequence.empty() ? std::min(o.max_frames, 150) : o.max_frames;
  const examples::Workload w = examples::load_workload(o.sequence, frames, 320, 3);
  if (w.depth.empty()) throw std::runtime_error("'" + o.sequence + "' has no frames");
  if (!w.camera_truth) throw std::runtime_error("'" + o.sequence + "' has no groundtruth.txt to compare against");
  SystemParams<S> params;
  if (o.sequence.empty()) params.background_voxels = 256, params.background_voxel_size = S(0.02);
  const B backend{};
  const PinholeCamera<S> camera = w.camera.template cast<S>();

  System<S, B> paper(camera, params, backend);
  const Errors p = run(w, paper, backend);

  // The same system with the user's model: only the likelihood differs.
  using Custom = System<S, B, DepthScaledLaplace<S>>;
  typename Custom::Parts parts = parts_from<typename Custom::Parts>(params);
  parts.likelihood.sigma = params.likelihood.sigma;
  Custom custom(camera, params, backend, parts);
  const Errors c = run(w, custom, backend);

  fmt::print("{} frames of {} on {}\n", w.depth.size(), o.sequence.empty() ? "synthetic:room-small" : o.sequence,
             B::name);
  fmt::print("{:<16} {:<22} {:<22}\n", "", "paper (eq. 7)", "depth-scaled Laplace");
  fmt::print("{:<16} {:<22.2f} {:<22.2f} (ATE cm)\n", "camera", 100 * p.camera, 100 * c.camera);
  for (const auto& [name, truth] : w.object_truth) {
    const auto find = [&](const Errors& e) { return e.objects.count(name) ? &e.objects.at(name) : nullptr; };
    fmt::print("{:<16} {:<22} {:<22}\n", name, cell(find(p)), cell(find(c)));
  }
}

}  // namespace

int main(int argc, char** argv) {
  try {
    Options o;
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      const auto value = [&]() -> std::string {
        if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
        return argv[++i];
      };
      if (a == "--backend")
        o.backend = value();
      else if (a == "--max-frames")
        o.max_frames = examples::parse_positive_int(a, value());
      else if (!a.empty() && a[0] == '-')
        throw std::invalid_argument("unknown option '" + a + "'");
      else if (o.sequence.empty())
        o.sequence = a;
      else
        throw std::invalid_argument("one sequence at a time, got '" + o.sequence + "' and '" + a + "'");
    }
    examples::with_backend(o.backend, [&](auto backend) { compare<decltype(backend)>(o); });
    return 0;
  } catch (const std::exception& e) {
    fmt::print(stderr, "custom_likelihood: error: {}\n", e.what());
    return 1;
  }
}
