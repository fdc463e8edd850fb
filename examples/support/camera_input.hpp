// The inputs of the camera-only tools (track_camera, export_synthetic): a
// TUM-layout sequence directory, or a built-in simulated scene named
// synthetic:<scene> whose depth is rendered on the fly, with its exact
// ground truth. The scenes are static rooms for camera tracking over long
// runs (docs/tracking.md, "Long sequences"):
//
//   synthetic:long        900 frames, 640x480, static room, Kinect v1 depth
//                         noise, hand-held path with fast segments (peaks
//                         0.70-0.85 m/s and 35-42 deg/s)
//   synthetic:long-slow   the same room and noise on the slow hand-held path
//   synthetic:long-small  300 frames at 320x240, the same room and noise, seed 5:
//                         two fast segments in its 10 s (for a ctest)
//
// export_tum_sequence writes a scene as a TUM-layout folder (16-bit PNG
// depth at 5000 per metre, depth.txt, groundtruth.txt, calibration.txt; no
// colour: the TUM reader opens such a folder depth-only), for tools that
// read only files (bench/peers.py runs Open3D on it).
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <fmt/core.h>

#include "emfusion/core/image.hpp"
#include "emfusion/core/timed_pose.hpp"
#include "emfusion/io/jpeg.hpp"
#include "emfusion/io/png.hpp"
#include "emfusion/io/run_outputs.hpp"
#include "emfusion/io/tum.hpp"
#include "emfusion/sim/dynamic_scene.hpp"

namespace emfusion::examples {

/// A built-in scene for camera tracking.
struct CameraScene {
  const char* name;
  const char* description;
  sim::DynamicSceneParams params;
};

inline std::vector<CameraScene> camera_scenes() {
  sim::DynamicSceneParams longp;
  longp.frames = 900;
  longp.moving_objects = 0;
  longp.camera_path = sim::CameraPath::hand_held_fast;
  sim::DynamicSceneParams slow = longp;
  slow.camera_path = sim::CameraPath::hand_held;
  sim::DynamicSceneParams small = longp;
  small.frames = 300, small.width = 320, small.height = 240;
  small.seed = 5;  // two fast segments within its 10 s (seed 1 has one)
  sim::DynamicSceneParams corridor;
  corridor.layout = sim::SceneLayout::corridor;
  corridor.frames = 600;
  corridor.moving_objects = 0;
  return {
      {"long", "900 frames, 640x480, static room, Kinect noise, fast segments", longp},
      {"corridor", "600 frames, 640x480, a static corridor walked 11 m along, Kinect noise", corridor},
      {"long-slow", "900 frames, 640x480, static room, Kinect noise, slow hand-held path", slow},
      {"long-small", "300 frames, 320x240, static room, Kinect noise, two fast segments", small},
  };
}

/// The scene that `input` names when it starts with "synthetic:", nothing
/// for any other input; an unknown name is an error listing the known ones.
inline std::optional<CameraScene> camera_scene(const std::string& input) {
  const std::string prefix = "synthetic:";
  if (input.rfind(prefix, 0) != 0) return std::nullopt;
  const std::string name = input.substr(prefix.size());
  std::string known;
  for (const CameraScene& s : camera_scenes()) {
    if (name == s.name) return s;
    known += (known.empty() ? "" : ", ") + std::string(s.name);
  }
  throw std::invalid_argument("unknown synthetic scene '" + name + "' in '" + input + "' (known: " + known + ")");
}

/// A sequence of depth frames: a TUM-layout directory or a built-in scene.
/// The members a tracker uses are TumSequence's.
class CameraInput {
 public:
  explicit CameraInput(const std::string& input) : name_(input) {
    if (const auto scene = camera_scene(input))
      synthetic_.emplace(scene->params);
    else
      tum_.emplace(TumSequence::open(input));
  }

  const std::string& name() const { return name_; }
  std::size_t size() const { return tum_ ? tum_->size() : synthetic_->size(); }
  double timestamp(std::size_t i) const { return tum_ ? tum_->timestamp(i) : synthetic_->timestamp(i); }
  Image<float, Host> depth(std::size_t i) const { return tum_ ? tum_->depth(i) : synthetic_->depth(i); }
  PinholeCamera<double> camera() const { return tum_ ? tum_->camera() : synthetic_->camera(); }
  /// True when every frame has a colour image (a recorded sequence with
  /// rgb.txt or associations.txt; the simulated scenes have none).
  bool has_colour() const { return tum_ && tum_->has_colour(); }
  /// Frame i's colour image (PNG or JPEG); an error naming the input when it
  /// has no colour.
  ColourImage colour(std::size_t i) const {
    if (!has_colour()) throw std::runtime_error("'" + name_ + "' has no colour images");
    return read_colour(tum_->colour_path(i));
  }
  /// The simulated scene; nullptr for a recorded sequence.
  const sim::DynamicScene<float>* scene() const { return synthetic_ ? &synthetic_->scene() : nullptr; }

  /// The camera's reference trajectory: the scene's exact poses, or the
  /// sequence's groundtruth.txt; an error naming the input when it has none.
  Trajectory ground_truth() const {
    if (synthetic_) return synthetic_->scene().camera_trajectory();
    auto gt = tum_->ground_truth();
    if (!gt) throw std::runtime_error("'" + name_ + "' has no groundtruth.txt (no reference trajectory to write)");
    return std::move(*gt);
  }

 private:
  std::string name_;
  std::optional<TumSequence> tum_;
  std::optional<sim::SyntheticSequence> synthetic_;
};

/// Writes frames [0, frames) of `scene` (noisy depth, as track_camera sees
/// it) as a TUM-layout sequence in `dir` (created if needed; files of an
/// earlier export there are replaced): depth/<frame>.png (16-bit, value =
/// metres * 5000 rounded, 0 = no measurement, depth beyond 13.1 m dropped),
/// depth.txt, groundtruth.txt, calibration.txt and README.txt. Throws naming
/// the file that cannot be written. With `labels_of`, each frame is rendered
/// with its labels (object k as k + 1, 0 elsewhere), which it is given with
/// the frame's index: one render a frame for a caller that writes them too.
inline void export_tum_sequence(const sim::DynamicScene<float>& scene, const std::string& name, int frames,
                                const std::string& dir,
                                const std::function<void(int, const Image<int, Host>&)>& labels_of = {}) {
  namespace fs = std::filesystem;
  if (frames < 1 || frames > scene.frame_count())
    throw std::invalid_argument("export_tum_sequence: frames must be in 1.." + std::to_string(scene.frame_count()) +
                                ", got " + std::to_string(frames));
  create_output_directory((fs::path(dir) / "depth").string());
  check_writable_directory(dir);
  const PinholeCamera<float>& cam = scene.camera();
  std::string list = "# timestamp filename (16-bit PNG, metres = value / 5000, 0 = invalid), " + name + "\n";
  Image<float, Host> depth;
  Image<int, Host> labels;
  for (int f = 0; f < frames; ++f) {
    scene.render(f, depth, labels_of ? &labels : nullptr);
    if (labels_of) labels_of(f, labels);
    const std::vector<float> metres = depth.to_host();
    std::vector<std::uint16_t> units(metres.size());
    for (std::size_t i = 0; i < metres.size(); ++i) {
      const double v = std::isfinite(metres[i]) && metres[i] > 0 ? std::round(double(metres[i]) * 5000) : 0;
      units[i] = v >= 1 && v <= 65535 ? std::uint16_t(v) : std::uint16_t(0);
    }
    const std::string file = fmt::format("depth/{:06}.png", f);
    write_png((fs::path(dir) / file).string(), Image<std::uint16_t, Host>::from_host(cam.width, cam.height, units));
    list += fmt::format("{:.6f} {}\n", scene.timestamp(f), file);
  }
  write_text_file((fs::path(dir) / "depth.txt").string(), list);
  Trajectory truth = scene.camera_trajectory();
  truth.resize(std::size_t(frames));
  write_tum_trajectory((fs::path(dir) / "groundtruth.txt").string(), truth);
  write_text_file((fs::path(dir) / "calibration.txt").string(),
                  fmt::format("{:.9g} {:.9g} {:.9g} {:.9g} {} {}\n", double(cam.fx), double(cam.fy), double(cam.cx),
                              double(cam.cy), cam.width, cam.height));
  write_text_file((fs::path(dir) / "README.txt").string(),
                  "Made by export_synthetic from the built-in scene " + name + " (" + std::to_string(frames) +
                      " frames): rendered noisy depth, no colour; groundtruth.txt is the scene's exact camera "
                      "trajectory. Generated, not data: delete freely.\n");
}

}  // namespace emfusion::examples
