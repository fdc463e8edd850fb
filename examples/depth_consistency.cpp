// depth_consistency: how well a trajectory agrees with a sequence's depth,
// without ground truth. Fuses the frames of one range at the trajectory's
// poses (the paper's integration), then measures the frames of another range
// against that map at their poses (eval/depth_consistency.hpp). Comparing
// two trajectories of one sequence (an estimate and a ground truth, say)
// over disjoint ranges tells which one the recorded depth supports better.
//
//   depth_consistency <sequence-dir> <trajectory.txt> [--fuse FIRST:END] [--check FIRST:END]
//                     [--voxels N] [--voxel-size M] [--max-abs M] [--backend cpu|cuda]
//
// Ranges are frame indices, END excluded; both default to every frame. Each
// frame takes the trajectory's pose nearest in time (within 0.02 s); frames
// without one are skipped. The map is N^3 voxels of M metres (default 256 of
// 0.02 m) with the first fused pose at the centre of one face.
#include <algorithm>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <vector>

#include <fmt/core.h>

#include "emfusion/eval/depth_consistency.hpp"
#include "emfusion/eval/trajectory.hpp"
#include "emfusion/io/tum.hpp"
#include "emfusion/preprocess/bilateral_filter.hpp"
#include "emfusion/preprocess/vertex_map.hpp"
#include "emfusion/volume/integrate.hpp"
#include "support/args.hpp"
#include "support/backend.hpp"

using namespace emfusion;
using S = float;

namespace {

struct Range {
  int first = 0, end = -1;  // end -1: to the last frame
};

struct Options {
  std::string sequence, trajectory, backend = "cpu";
  Range fuse, check;
  int voxels = 256;
  double voxel_size = 0.02, max_abs = 0.05;
};

Range parse_range(const std::string& flag, const std::string& v) {
  const auto colon = v.find(':');
  if (colon == std::string::npos) throw std::invalid_argument(flag + " expects FIRST:END, got '" + v + "'");
  Range r;
  r.first = examples::parse_int(flag + " FIRST", v.substr(0, colon), 0, 10000000);
  r.end = examples::parse_int(flag + " END", v.substr(colon + 1), 1, 10000000);
  if (r.end <= r.first) throw std::invalid_argument(flag + " '" + v + "' is empty: END must exceed FIRST");
  return r;
}

// The index of frame i's pose in `trajectory`, or -1: the nearest in time within 0.02 s.
std::vector<int> poses_of_frames(const TumSequence& seq, const Trajectory& trajectory) {
  Trajectory frames(seq.size());
  for (std::size_t i = 0; i < seq.size(); ++i) frames[i] = {seq.timestamp(i), SE3<double>::identity()};
  std::vector<int> pose_of(seq.size(), -1);
  for (const eval::Match& m : eval::associate(frames, trajectory)) pose_of[m.est] = int(m.gt);
  return pose_of;
}

template <class B>
void run(const Options& o, const B& backend) {
  const TumSequence seq = TumSequence::open(o.sequence);
  const Trajectory trajectory = read_tum_trajectory(o.trajectory);
  const int n = int(seq.size());
  const auto clamp = [&](Range r, const char* flag) {
    if (r.end < 0) r.end = n;
    if (r.end > n)
      throw std::invalid_argument(std::string(flag) + " ends at frame " + std::to_string(r.end) + " but '" +
                                  o.sequence + "' has " + std::to_string(n) + " frames");
    return r;
  };
  const Range fuse = clamp(o.fuse, "--fuse"), check = clamp(o.check, "--check");
  const std::vector<int> pose_of = poses_of_frames(seq, trajectory);
  const auto posed = [&](const Range& r) {
    std::vector<int> frames;
    for (int i = r.first; i < r.end; ++i)
      if (pose_of[std::size_t(i)] >= 0) frames.push_back(i);
    return frames;
  };
  const std::vector<int> fused = posed(fuse), checked = posed(check);
  for (const auto& [frames, what] : {std::pair{&fused, "--fuse"}, std::pair{&checked, "--check"}})
    if (frames->empty())
      throw std::invalid_argument(std::string(what) + ": no frame of the range has a pose in '" + o.trajectory +
                                  "' within 0.02 s (do the timestamps use the same clock?)");
  const auto pose = [&](int i) { return trajectory[std::size_t(pose_of[std::size_t(i)])].pose.template cast<S>(); };

  const PinholeCamera<S> camera = seq.camera().cast<S>();
  VolumeGeometry<S> geometry;
  geometry.dims = Vec3i{{o.voxels, o.voxels, o.voxels}};
  geometry.voxel_size = S(o.voxel_size);
  geometry.T_world_volume = volume_pose_in_front_of(pose(fused.front()), S(o.voxels * o.voxel_size));
  TsdfVolume<S, B> volume(geometry, backend);
  for (int i : fused)
    integrate(volume, seq.depth(i).template to<B>(), camera, pose(i), static_cast<const Image<S, B>*>(nullptr),
              IntegrationParams<S>{});

  Image<S, B> filtered;
  Image<Vec3<S>, B> points;
  eval::DepthResiduals sum;
  for (int i : checked) {
    bilateral_filter(seq.depth(i).template to<B>(), filtered, BilateralParams<S>{});
    back_project(filtered, camera, points);
    sum += eval::depth_residuals(volume, points, pose(i), S(o.max_abs), S(0.005));
  }
  fmt::print("fused frames {}-{} ({} with a pose), checked frames {}-{} ({} with a pose) on {}\n", fuse.first,
             fuse.end - 1, fused.size(), check.first, check.end - 1, checked.size(), B::name);
  fmt::print("{:.0f} points within {:.3f} m of the map: mean |SDF| {:.2f} mm, RMS {:.2f} mm, {:.1f} % within 5 mm\n",
             sum.points, o.max_abs, 1e3 * sum.mean_abs(), 1e3 * sum.rms(), 100.0 * sum.share_within());
}

Options parse(int argc, char** argv) {
  Options o;
  const auto positional = examples::parse_command_line(argc, argv, {}, [&](const std::string& a, const std::string& v) {
    if (a == "--fuse") o.fuse = parse_range(a, v);
    else if (a == "--check") o.check = parse_range(a, v);
    else if (a == "--voxels") o.voxels = examples::parse_positive_int(a, v, 2048);
    else if (a == "--voxel-size") o.voxel_size = examples::parse_positive_double(a, v);
    else if (a == "--max-abs") o.max_abs = examples::parse_positive_double(a, v);
    else if (a == "--backend") o.backend = v;
    else throw std::invalid_argument("unknown option '" + a + "'");
  });
  if (positional.size() != 2)
    throw std::invalid_argument("usage: depth_consistency <sequence-dir> <trajectory.txt> [--fuse FIRST:END] "
                                "[--check FIRST:END] [--voxels N] [--voxel-size M] [--max-abs M] [--backend cpu|cuda]");
  o.sequence = positional[0], o.trajectory = positional[1];
  return o;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const Options o = parse(argc, argv);
    examples::with_backend(o.backend, [&](const auto& backend) { run(o, backend); });
    return 0;
  } catch (const std::exception& e) {
    fmt::print(stderr, "depth_consistency: error: {}\n", e.what());
    return 1;
  }
}
