// opencv_sequence: the full EM-Fusion system fed with cv::Mat frames, as a
// program whose camera driver gives OpenCV images would feed it. The frames
// come from a TUM-layout sequence (shared/FORMATS.md section 1) read with
// cv::imread; only the lists and the calibration go through io/ (TumSequence
// and MaskDirectory), every image through OpenCV and interop/opencv.hpp
// (docs/user-guide.md, "Frames from OpenCV"). Built only where OpenCV is
// found.
//
//   opencv_sequence <sequence-dir> [--output camera.txt] [--max-frames N]
//                   [--depth-scale 5000] [--voxels 512] [--voxel-size 0.01]
//
// Depth: <dir>/depth/*.png, 16-bit, value / depth-scale metres. Detections:
// <dir>/masks (masks.txt and its label PNGs, io/masks.hpp) when it is there,
// each label PNG read with cv::imread and turned into Detections by
// opencv::detections_from_labels. Runs System<float, Host> (the CPU), writes
// the camera trajectory (T_world_camera per frame, TUM format) to --output
// (default opencv-camera.txt) and prints the camera's ATE when the sequence
// has groundtruth.txt. A missing or unreadable folder or image is one error
// naming it.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include <fmt/core.h>

#include "emfusion/eval/ate.hpp"
#include "emfusion/interop/opencv.hpp"
#include "emfusion/io/masks.hpp"
#include "emfusion/io/tum.hpp"
#include "support/args.hpp"
#include "support/system_host.hpp"  // emfusion/slam/system.hpp, System<float, Host> compiled once

using namespace emfusion;

namespace {

struct Options {
  std::string sequence;
  std::string output = "opencv-camera.txt";
  int max_frames = 100000;
  double depth_scale = 5000;
  int voxels = 512;
  double voxel_size = 0.01;
};

/// cv::imread of an image that must be there (IMREAD_UNCHANGED: 16-bit
/// depth stays 16-bit, label PNGs keep their values).
cv::Mat read_image(const std::string& path, const char* what) {
  cv::Mat image = cv::imread(path, cv::IMREAD_UNCHANGED);
  if (image.empty()) throw std::runtime_error("cannot read the " + std::string(what) + " '" + path + "' with cv::imread");
  return image;
}

void run(const Options& o) {
  namespace fs = std::filesystem;
  if (!fs::is_directory(o.sequence))
    throw std::runtime_error("'" + o.sequence + "': " +
                             (fs::exists(o.sequence) ? "not a directory" : "sequence directory not found") +
                             " (expected a TUM-layout sequence: depth.txt or associations.txt, depth/)");
  TumOptions tum;
  tum.depth_scale = o.depth_scale;
  // The frame lists and the intrinsics; no image is read here.
  const TumSequence seq = TumSequence::open(o.sequence, tum);
  const PinholeCamera<float> camera = seq.camera().cast<float>();
  std::optional<MaskDirectory> masks;
  const std::string mask_dir = (fs::path(o.sequence) / "masks").string();
  if (fs::exists(fs::path(mask_dir) / "masks.txt")) masks = MaskDirectory::open(mask_dir, camera.width, camera.height);

  SystemParams<float> params;
  params.background_voxels = o.voxels;
  params.background_voxel_size = float(o.voxel_size);
  System<float, Host> system(camera, params);

  const std::size_t frames = std::min<std::size_t>(seq.size(), std::size_t(o.max_frames));
  int detector_frames = 0, untracked = 0;
  for (std::size_t i = 0; i < frames; ++i) {
    const double t = seq.timestamp(i);
    // What a driver would hand over: a 16-bit depth Mat.
    const cv::Mat raw = read_image(seq.depth_path(i), "depth image");
    if (raw.cols != camera.width || raw.rows != camera.height)
      throw std::runtime_error("depth image '" + seq.depth_path(i) + "' is " + std::to_string(raw.cols) + "x" +
                               std::to_string(raw.rows) + " but the camera (" + seq.camera_source() + ") is " +
                               std::to_string(camera.width) + "x" + std::to_string(camera.height));
    const Image<float, Host> depth = opencv::depth_from_mat(raw, o.depth_scale);  // copies, scaled to metres

    // A detector's label image as a Mat, with the instances its line lists.
    std::optional<Detections> detections;
    if (masks)
      if (const std::optional<std::size_t> k = masks->nearest(t)) {
        const cv::Mat labels = read_image(masks->label_path(*k), "label image");
        detections = opencv::detections_from_labels(labels, masks->instances(*k), t);
        ++detector_frames;
      }

    const FrameResult r = system.process(depth, t, detections ? &*detections : nullptr);
    if (r.camera_tracking != TrackingOutcome::tracked && i > 0) ++untracked;
  }

  write_tum_trajectory(o.output, system.camera_trajectory());
  fmt::print("{} frames of '{}' read with OpenCV ({} with detections), {} untracked, {} objects live, {} created\n",
             frames, o.sequence, detector_frames, untracked, system.objects().size(), system.object_records().size());
  if (const auto truth = seq.ground_truth(); truth && system.camera_trajectory().size() >= 3)
    fmt::print("camera ATE RMSE {:.4f} m\n", eval::absolute_trajectory_error(system.camera_trajectory(), *truth).rmse);
  fmt::print("wrote the camera trajectory to {}\n", o.output);
}

}  // namespace

int main(int argc, char** argv) {
  try {
    Options o;
    const std::vector<std::string> positional =
        examples::parse_command_line(argc, argv, {}, [&](const std::string& flag, const std::string& value) {
          if (flag == "--output")
            o.output = value;
          else if (flag == "--max-frames")
            o.max_frames = examples::parse_positive_int(flag, value);
          else if (flag == "--depth-scale")
            o.depth_scale = examples::parse_positive_double(flag, value);
          else if (flag == "--voxels")
            o.voxels = examples::parse_int(flag, value, 8, 2048);
          else if (flag == "--voxel-size")
            o.voxel_size = examples::parse_positive_double(flag, value);
          else
            throw std::invalid_argument("unknown option '" + flag + "'");
        });
    if (positional.size() != 1)
      throw std::invalid_argument("expected one sequence directory, got " + std::to_string(positional.size()) +
                                  " arguments (usage: opencv_sequence <sequence-dir> [--output camera.txt] "
                                  "[--max-frames N] [--depth-scale 5000] [--voxels 512] [--voxel-size 0.01])");
    o.sequence = positional[0];
    run(o);
    return 0;
  } catch (const std::exception& e) {
    fmt::print(stderr, "opencv_sequence: error: {}\n", e.what());
    return 1;
  }
}
