// export_synthetic: writes a built-in camera-tracking scene (synthetic:long,
// synthetic:long-slow, synthetic:long-small; examples/support/camera_input.hpp)
// as a TUM-layout folder of noisy 16-bit PNG depth (5000 per metre) with
// depth.txt, groundtruth.txt and calibration.txt, for tools that read files
// (bench/peers.py runs Open3D on it; track_camera reads it like any TUM
// sequence). No colour: the scenes have none, and the folder opens depth-only.
//
//   export_synthetic synthetic:<scene> <dir> [--max-frames N]
#include <cstdio>
#include <stdexcept>
#include <string>

#include <fmt/core.h>

#include "support/args.hpp"
#include "support/camera_input.hpp"

using namespace emfusion;

int main(int argc, char** argv) {
  try {
    int max_frames = 0;
    const auto positional =
        examples::parse_command_line(argc, argv, {}, [&](const std::string& a, const std::string& v) {
          if (a == "--max-frames") max_frames = examples::parse_positive_int(a, v);
          else throw std::invalid_argument("unknown option '" + a + "'");
        });
    if (positional.size() != 2)
      throw std::invalid_argument("usage: export_synthetic synthetic:<scene> <dir> [--max-frames N]");
    const auto scene = examples::camera_scene(positional[0]);
    if (!scene)
      throw std::invalid_argument("'" + positional[0] +
                                  "' is not a built-in scene: expected synthetic:<scene> (long, corridor, long-slow, long-small)");
    const sim::DynamicScene<float> room = sim::make_dynamic_scene<float>(scene->params);
    const int frames = max_frames > 0 && max_frames < room.frame_count() ? max_frames : room.frame_count();
    examples::export_tum_sequence(room, positional[0], frames, positional[1]);
    fmt::print("wrote {} frames of {} to {}\n", frames, positional[0], positional[1]);
    return 0;
  } catch (const std::exception& e) {
    fmt::print(stderr, "export_synthetic: error: {}\n", e.what());
    return 1;
  }
}
