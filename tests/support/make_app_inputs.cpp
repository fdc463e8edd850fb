// Writes the tiny inputs of the `emfusion run` ctest entries
// (examples/CMakeLists.txt) into one folder, emptied first:
//
//   wall.klg               3 frames, 64x48, zlib depth in millimetres, no colour
//   wall-calibration.txt   its camera: "52.5 52.5 31.5 23.5 64 48"
//   wall-truncated.klg     wall.klg without its last 5 bytes
//   garbage.klg            text, not a log
//   cofusion/              colour/Color000{0,1,2}.png, depth/Depth000{0,1,2}.exr
//                          (text placeholders in a build without OpenEXR),
//                          calibration.txt (the same camera)
//   depth-folder-only/     an empty depth/ folder: neither TUM nor Co-Fusion
//   tum/                   TUM layout: depth.txt, depth/<t>.png (value / 5000 m),
//                          calibration.txt, groundtruth.txt (the camera at rest
//                          at the origin), no colour
//   tum-other-clock.txt    that trajectory 100 s later: no pose matches a frame
//   tum-colour/            tum/ with colour: rgb.txt, rgb/<t>.png (gray, 64x48)
//   tum-odd-colour/        the same with colour images of 32x24
//
// The scene: a wall 1.2 m away with a box face 0.9 m away in the middle of
// the image, the same in every frame (a camera at rest).
//
//   make_app_inputs <folder>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "emfusion/io/exr.hpp"
#include "emfusion/io/klg.hpp"
#include "emfusion/io/png.hpp"

using namespace emfusion;
namespace fs = std::filesystem;

namespace {

constexpr int width = 64, height = 48, frames = 3;
constexpr const char* calibration = "52.5 52.5 31.5 23.5 64 48\n";

/// Depth in metres at pixel (x, y).
double depth_at(int x, int y) { return x >= 24 && x < 40 && y >= 16 && y < 32 ? 0.9 : 1.2; }

void write_text(const fs::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
  if (!out.flush()) throw std::runtime_error("cannot write '" + path.string() + "'");
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s <folder>\n", argv[0]);
    return 2;
  }
  try {
    const fs::path dir = argv[1];
    fs::remove_all(dir);
    fs::create_directories(dir / "cofusion" / "colour");
    fs::create_directories(dir / "cofusion" / "depth");
    fs::create_directories(dir / "depth-folder-only" / "depth");
    fs::create_directories(dir / "tum" / "depth");

    Image<std::uint16_t, Host> millimetres(width, height), fifths(width, height);
    Image<float, Host> metres(width, height);
    Image<std::uint8_t, Host> grey(width, height);
    for (int y = 0; y < height; ++y)
      for (int x = 0; x < width; ++x) {
        millimetres.view()(x, y) = std::uint16_t(depth_at(x, y) * 1000 + 0.5);
        fifths.view()(x, y) = std::uint16_t(depth_at(x, y) * 5000 + 0.5);
        metres.view()(x, y) = float(depth_at(x, y));
        grey.view()(x, y) = std::uint8_t(depth_at(x, y) < 1 ? 200 : 80);
      }

    std::vector<KlgFrame> log;
    for (int i = 0; i < frames; ++i) log.push_back({std::int64_t(i) * 33333, millimetres, {}});
    const std::string klg = (dir / "wall.klg").string();
    write_klg(klg, log, KlgDepthEncoding::Zlib);
    write_text(dir / "wall-calibration.txt", calibration);
    std::ifstream in(klg, std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    write_text(dir / "wall-truncated.klg", bytes.substr(0, bytes.size() - 5));
    write_text(dir / "garbage.klg", "this is not a klg log\n");

    for (int i = 0; i < frames; ++i) {
      const std::string number = "000" + std::to_string(i);
      write_png((dir / "cofusion" / "colour" / ("Color" + number + ".png")).string(), grey);
      const fs::path depth = dir / "cofusion" / "depth" / ("Depth" + number + ".exr");
      // Without OpenEXR the folder is still a Co-Fusion folder to the app's
      // argument checks, which read no depth; the runs that do are not
      // registered (examples/CMakeLists.txt).
      if (detail::exr::available)
        write_exr(depth.string(), metres);
      else
        write_text(depth, "placeholder: this build has no OpenEXR\n");
    }
    write_text(dir / "cofusion" / "calibration.txt", calibration);

    std::string depth_list = "# timestamp filename\n", poses = "# timestamp tx ty tz qx qy qz qw\n", later = poses;
    for (int i = 0; i < frames; ++i) {
      char t[32], t_later[32];
      std::snprintf(t, sizeof t, "%.6f", i / 30.0);
      std::snprintf(t_later, sizeof t_later, "%.6f", 100 + i / 30.0);
      write_png((dir / "tum" / "depth" / (std::string(t) + ".png")).string(), fifths);
      depth_list += std::string(t) + " depth/" + t + ".png\n";
      poses += std::string(t) + " 0 0 0 0 0 0 1\n";
      later += std::string(t_later) + " 0 0 0 0 0 0 1\n";
    }
    write_text(dir / "tum" / "depth.txt", depth_list);
    write_text(dir / "tum" / "calibration.txt", calibration);
    write_text(dir / "tum" / "groundtruth.txt", poses);
    write_text(dir / "tum-other-clock.txt", later);
    // With colour of the camera's size, and of another.
    Image<std::uint8_t, Host> small(width / 2, height / 2, std::uint8_t(128));
    for (const auto& [name, colour] : {std::pair{"tum-colour", &grey}, std::pair{"tum-odd-colour", &small}}) {
      fs::create_directories(dir / name / "depth");
      fs::create_directories(dir / name / "rgb");
      std::string rgb_list = "# timestamp filename\n";
      for (int i = 0; i < frames; ++i) {
        char t[32];
        std::snprintf(t, sizeof t, "%.6f", i / 30.0);
        write_png((dir / name / "depth" / (std::string(t) + ".png")).string(), fifths);
        write_png((dir / name / "rgb" / (std::string(t) + ".png")).string(), *colour);
        rgb_list += std::string(t) + " rgb/" + t + ".png\n";
      }
      write_text(dir / name / "depth.txt", depth_list);
      write_text(dir / name / "rgb.txt", rgb_list);
      write_text(dir / name / "calibration.txt", calibration);
    }
    std::printf("wrote %s\n", dir.string().c_str());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "make_app_inputs: error: %s\n", e.what());
    return 1;
  }
}
