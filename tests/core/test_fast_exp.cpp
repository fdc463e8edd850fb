// fast_exp, the library's single-precision e^x without a library call (the
// bilateral filter's weights): within a few ulps of the exact value over
// the whole clamped range, clamped outside it, and e^0 = 1 exactly.
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "emfusion/core/math.hpp"
#include "support/catch.hpp"

using namespace emfusion;

TEST_CASE("fast_exp is within 3e-7 of e^x on [-87, 87]", "[core]") {
  double worst = 0;
  float worst_at = 0;
  int count = 0;
  // Every 977th float of the range, by its bits: about two million
  // arguments, every binade and both signs (the denormals around 0, where
  // e^x is 1 to within a float, skipped).
  const auto check = [&](float x) {
    const double exact = std::exp(double(x));
    const double error = std::fabs(double(fast_exp(x)) - exact) / exact;
    if (error > worst) worst = error, worst_at = x;
    ++count;
  };
  for (std::uint32_t bits = 0x00800000u; bits <= 0x42ae0000u; bits += 977u) {  // 2^-126 .. 87
    float x;
    std::memcpy(&x, &bits, sizeof x);
    check(x);
    check(-x);
  }
  INFO(count << " arguments, worst relative error " << worst << " at " << worst_at);
  CHECK(count > 1000000);
  CHECK(worst < 3e-7);
  CHECK(fast_exp(0.0f) == 1.0f);
  CHECK(fast_exp(-0.0f) == 1.0f);
}

TEST_CASE("fast_exp clamps its argument to [-87, 87] and stays finite", "[core]") {
  const float inf = std::numeric_limits<float>::infinity();
  const float at_low = fast_exp(-87.0f), at_high = fast_exp(87.0f);
  CHECK(at_low > 0.0f);
  CHECK(std::isnormal(at_low));
  CHECK(std::isfinite(at_high));
  CHECK(fast_exp(-1000.0f) == at_low);
  CHECK(fast_exp(-inf) == at_low);
  CHECK(fast_exp(1000.0f) == at_high);
  CHECK(fast_exp(inf) == at_high);
  const float nan = fast_exp(std::numeric_limits<float>::quiet_NaN());
  CHECK((nan == at_low || nan == at_high));
  // Double is the library's std::exp.
  CHECK(fast_exp(-1000.0) == 0.0);
  CHECK(fast_exp(1.5) == std::exp(1.5));
}
