// Half, the 16-bit storage scalar: every binary16 value survives the round
// trip through float, floats round to the nearest binary16 (ties to even)
// as an exhaustive search over the finite values says, and infinities, NaN
// and overflow come out as IEEE 754 has them.
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "emfusion/core/half.hpp"
#include "support/catch.hpp"

using namespace emfusion;

namespace {
Half from_bits(int bits) {
  Half h;
  h.bits = std::uint16_t(bits);
  return h;
}
}  // namespace

TEST_CASE("Half: every binary16 value converts to float and back unchanged", "[core]") {
  int mismatches = 0, nans = 0;
  for (int b = 0; b < 65536; ++b) {
    const float f = float(from_bits(b));
    if (std::isnan(f)) {
      ++nans;
      mismatches += !std::isnan(float(Half(f)));
      continue;
    }
    mismatches += Half(f).bits != b;
  }
  CHECK(mismatches == 0);
  CHECK(nans == 2 * 1023);  // exponent 31 with a non-zero mantissa, both signs
  CHECK(float(from_bits(0x3c00)) == 1.0f);
  CHECK(float(from_bits(0x0001)) == std::ldexp(1.0f, -24));  // the smallest subnormal
  CHECK(float(from_bits(0x7bff)) == 65504.0f);
}

TEST_CASE("Half: floats round to the nearest binary16, ties to even", "[core]") {
  std::vector<double> finite;  // every non-negative finite binary16, ascending
  for (int b = 0; b < 0x7c00; ++b) finite.push_back(double(float(from_bits(b))));
  const auto reference = [&](double v) {  // v >= 0
    if (v >= 65520.0) return 0x7c00;      // halfway to 2^16 and beyond: infinity
    const auto it = std::lower_bound(finite.begin(), finite.end(), v);
    const int hi = int(it - finite.begin());
    if (hi == int(finite.size())) return 0x7bff;
    if (hi == 0 || finite[std::size_t(hi)] == v) return hi;
    const double below = v - finite[std::size_t(hi - 1)], above = finite[std::size_t(hi)] - v;
    if (below != above) return below < above ? hi - 1 : hi;
    return (hi - 1) % 2 == 0 ? hi - 1 : hi;
  };
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> exponent(-30, 17);
  int mismatches = 0;
  for (int k = 0; k < 200000; ++k) {
    const float f = float(std::pow(2.0, exponent(rng)));
    const int expected = reference(double(f));
    mismatches += Half(f).bits != expected;
    mismatches += Half(-f).bits != (expected | 0x8000);
  }
  // Exact ties: halfway between neighbours, in the normal and subnormal range.
  for (const int b : {0x0001, 0x0002, 0x03ff, 0x0400, 0x3c00, 0x3c01, 0x7bfe}) {
    const double mid = 0.5 * (double(float(from_bits(b))) + double(float(from_bits(b + 1))));
    mismatches += Half(float(mid)).bits != reference(mid);
  }
  CHECK(mismatches == 0);
}

TEST_CASE("Half: infinities, NaN, overflow and signed zero", "[core]") {
  const float inf = std::numeric_limits<float>::infinity();
  CHECK(Half(inf).bits == 0x7c00);
  CHECK(Half(-inf).bits == 0xfc00);
  CHECK(std::isnan(float(Half(std::numeric_limits<float>::quiet_NaN()))));
  CHECK(Half(65519.0f).bits == 0x7bff);  // below the halfway point to 2^16
  CHECK(Half(65520.0f).bits == 0x7c00);
  CHECK(Half(1e9f).bits == 0x7c00);
  CHECK(Half(-0.0f).bits == 0x8000);
  CHECK(Half(1e-9f).bits == 0x0000);
  CHECK(double(Half(0.1)) == emfusion::test::Approx(0.1).epsilon(1e-3));
}
