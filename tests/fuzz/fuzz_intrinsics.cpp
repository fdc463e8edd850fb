// Fuzz target: the --intrinsics argument ("fx,fy,cx,cy[,width,height]" or a
// preset name) through parse_intrinsics and intrinsics_from_argument. The
// input is cut at its first NUL byte, as a command-line argument would be.
// A parsed camera must be valid with finite intrinsics, 640x480 when no size
// was given, and read back unchanged from "fx,fy,cx,cy,width,height".
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>

#include "emfusion/io/intrinsics.hpp"
#include "emfusion/io/tum.hpp"
#include "fuzz_check.hpp"

namespace fuzz_intrinsics {

inline void check_camera(const emfusion::PinholeCamera<double>& camera) {
  EMF_FUZZ_CHECK(std::isfinite(camera.fx) && camera.fx > 0);
  EMF_FUZZ_CHECK(std::isfinite(camera.fy) && camera.fy > 0);
  EMF_FUZZ_CHECK(std::isfinite(camera.cx) && std::isfinite(camera.cy));
  EMF_FUZZ_CHECK(camera.width >= 1 && camera.width <= 1000000 && camera.height >= 1 && camera.height <= 1000000);
  EMF_FUZZ_CHECK(emfusion::fuzz::returns([&] { camera.validate("fuzz"); }, ""));
}

inline void check(const std::string& text) {
  emfusion::PinholeCamera<double> camera;
  if (emfusion::fuzz::returns([&] { camera = emfusion::parse_intrinsics(text); }, text)) {
    check_camera(camera);
    std::size_t commas = 0;
    for (const char c : text) commas += c == ',' ? 1 : 0;
    EMF_FUZZ_CHECK(commas == 3 || commas == 5);
    if (commas == 3) EMF_FUZZ_CHECK(camera.width == 640 && camera.height == 480);
    namespace tum = emfusion::detail::tum;
    const std::string written = tum::format(camera.fx) + "," + tum::format(camera.fy) + "," + tum::format(camera.cx) +
                                "," + tum::format(camera.cy) + "," + std::to_string(camera.width) + "," +
                                std::to_string(camera.height);
    emfusion::PinholeCamera<double> again;
    EMF_FUZZ_CHECK(emfusion::fuzz::returns([&] { again = emfusion::parse_intrinsics(written); }, written));
    EMF_FUZZ_CHECK(again.fx == camera.fx && again.fy == camera.fy && again.cx == camera.cx &&
                   again.cy == camera.cy && again.width == camera.width && again.height == camera.height);
  }
  if (emfusion::fuzz::returns([&] { camera = emfusion::intrinsics_from_argument(text); }, text)) {
    check_camera(camera);
    if (text.find(',') == std::string::npos) {
      bool preset = false;
      for (const emfusion::IntrinsicsPreset& p : emfusion::intrinsics_presets())
        preset = preset || (camera.fx == p.fx && camera.fy == p.fy && camera.cx == p.cx && camera.cy == p.cy);
      EMF_FUZZ_CHECK(preset && camera.width == 640 && camera.height == 480);
    }
  }
}

}  // namespace fuzz_intrinsics

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::string text = emfusion::fuzz::text_of(data, size);
  text.resize(std::min(text.size(), text.find('\0')));
  fuzz_intrinsics::check(text);
  return 0;
}
