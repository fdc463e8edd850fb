// Fuzz target: calibration files ("fx fy cx cy width height") through
// parse_calibration. A parsed camera must be valid (PinholeCamera::validate),
// with finite intrinsics and a size in [1, 1000000], and the camera written
// back as text must read back unchanged.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>

#include "emfusion/io/tum.hpp"
#include "fuzz_check.hpp"

namespace fuzz_calibration {

inline void check(const std::string& text) {
  const std::string name = "fuzz/calibration.txt";
  emfusion::PinholeCamera<double> camera;
  if (!emfusion::fuzz::returns([&] { camera = emfusion::parse_calibration(text, name); }, name)) return;
  EMF_FUZZ_CHECK(std::isfinite(camera.fx) && camera.fx > 0);
  EMF_FUZZ_CHECK(std::isfinite(camera.fy) && camera.fy > 0);
  EMF_FUZZ_CHECK(std::isfinite(camera.cx) && std::isfinite(camera.cy));
  EMF_FUZZ_CHECK(camera.width >= 1 && camera.width <= 1000000 && camera.height >= 1 && camera.height <= 1000000);
  EMF_FUZZ_CHECK(emfusion::fuzz::returns([&] { camera.validate("fuzz"); }, ""));

  namespace tum = emfusion::detail::tum;
  const std::string written = tum::format(camera.fx) + " " + tum::format(camera.fy) + " " + tum::format(camera.cx) +
                              " " + tum::format(camera.cy) + " " + std::to_string(camera.width) + " " +
                              std::to_string(camera.height) + "\n";
  emfusion::PinholeCamera<double> again;
  EMF_FUZZ_CHECK(emfusion::fuzz::returns([&] { again = emfusion::parse_calibration(written, name); }, name));
  EMF_FUZZ_CHECK(again.fx == camera.fx && again.fy == camera.fy && again.cx == camera.cx && again.cy == camera.cy);
  EMF_FUZZ_CHECK(again.width == camera.width && again.height == camera.height);
}

}  // namespace fuzz_calibration

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  fuzz_calibration::check(emfusion::fuzz::text_of(data, size));
  return 0;
}
