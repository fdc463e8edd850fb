// Downstream smoke test of the installed emfusion package: SE3 exp/log round
// trip, a host reduction over an image, and an EXR round trip through
// emfusion::io (whose OpenEXR, when the library was built with it, the
// package config must find again; without it, the error that says so).
// Exits non-zero on a wrong result.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include <emfusion/core/image.hpp>
#include <emfusion/core/parallel.hpp>
#include <emfusion/core/se3.hpp>
#include <emfusion/io/exr.hpp>

#ifndef EMFUSION_HAS_OPENEXR
#define EMFUSION_HAS_OPENEXR 0
#endif

int main() {
  int failures = 0;

  // SE3: log(exp(xi)) == xi for a generic tangent vector.
  const emfusion::SE3d::Tangent xi{{0.1, -0.2, 0.3, 0.4, -0.5, 0.6}};
  const emfusion::SE3d::Tangent back = emfusion::SE3d::exp(xi).log();
  double max_err = 0.0;
  for (int i = 0; i < 6; ++i) max_err = std::max(max_err, std::abs(back[i] - xi[i]));
  if (!(max_err < 1e-9)) {
    std::fprintf(stderr, "consumer: SE3 exp/log round trip error %g (expected < 1e-9)\n", max_err);
    ++failures;
  }

  // Image + transform_reduce_index on the host backend.
  const int width = 64, height = 48;
  std::vector<float> pixels(std::size_t(width) * height);
  double expected = 0.0;
  for (std::size_t i = 0; i < pixels.size(); ++i) {
    pixels[i] = float(i % 7);
    expected += pixels[i];
  }
  const auto image = emfusion::Image<float, emfusion::Host>::from_host(width, height, pixels);
  const emfusion::ImageView<const float> view = image.view();
  const double sum = emfusion::transform_reduce_index(
      image.backend(), view.size(), [view](int i) { return double(view[i]); }, 0.0, std::plus<double>());
  if (sum != expected) {
    std::fprintf(stderr, "consumer: transform_reduce_index sum %g, expected %g\n", sum, expected);
    ++failures;
  }

  // EXR through emfusion::io.
  const std::string exr = (std::filesystem::temp_directory_path() / "emfusion-consumer-depth.exr").string();
  try {
    emfusion::write_exr(exr, image);
    const bool same = emfusion::read_exr(exr).to_host() == pixels;
    std::filesystem::remove(exr);
    if (!same || !EMFUSION_HAS_OPENEXR) {
      std::fprintf(stderr, "consumer: EXR round trip %s\n", same ? "worked without OpenEXR" : "changed the pixels");
      ++failures;
    }
  } catch (const std::runtime_error& e) {
    if (EMFUSION_HAS_OPENEXR || std::string(e.what()).find("no OpenEXR support") == std::string::npos) {
      std::fprintf(stderr, "consumer: EXR round trip failed: %s\n", e.what());
      ++failures;
    }
  }

  if (failures == 0) std::printf("consumer: ok (SE3 round trip error %g, image sum %g)\n", max_err, sum);
  return failures == 0 ? 0 : 1;
}
