// A 16-bit floating-point storage type (IEEE 754 binary16) for volumes:
// TsdfVolume<float, B, Half> keeps SDF and weight in half the memory and
// memory traffic of float, computing in float. Conversions round to nearest
// even and keep infinities and NaN: bit arithmetic on the host, the
// hardware's conversion on a device. It pays on a GPU, where the conversion
// is one instruction; on a CPU without F16C it costs more time than it saves
// (docs/benchmarks.md, "Half storage").
#pragma once

#include <bit>
#include <cstdint>
#include <type_traits>

#include "emfusion/core/host_device.hpp"

#if defined(__CUDACC__)
#include <cuda_fp16.h>
#endif

namespace emfusion {

namespace detail {

/// binary16 bits of f, rounded to nearest even (overflow gives infinity).
/// On a device the hardware conversion, which rounds the same way.
EMF_HD inline std::uint16_t float_to_half_bits(float f) {
#if defined(__CUDA_ARCH__)
  return __half_as_ushort(__float2half_rn(f));
#else
  const std::uint32_t x = std::bit_cast<std::uint32_t>(f);
  const std::uint32_t sign = (x >> 16) & 0x8000u;
  const std::uint32_t a = x & 0x7fffffffu;
  if (a >= 0x7f800000u) return std::uint16_t(sign | 0x7c00u | (a > 0x7f800000u ? 0x200u : 0u));  // inf, NaN
  if (a >= 0x477ff000u) return std::uint16_t(sign | 0x7c00u);  // rounds beyond 65504: infinity
  if (a < 0x38800000u) {                                        // below 2^-14: subnormal or zero
    if (a < 0x33000000u) return std::uint16_t(sign);            // at most 2^-25: rounds to zero
    const std::uint32_t exponent = a >> 23, mantissa = (a & 0x7fffffu) | 0x800000u;
    const std::uint32_t shift = 126u - exponent;  // 14 .. 24: units of 2^-24
    std::uint32_t h = mantissa >> shift;
    const std::uint32_t rest = mantissa & ((1u << shift) - 1u), halfway = 1u << (shift - 1u);
    if (rest > halfway || (rest == halfway && (h & 1u))) ++h;
    return std::uint16_t(sign | h);
  }
  std::uint32_t h = (a - 0x38000000u) >> 13;  // rebias the exponent by 127 - 15
  const std::uint32_t rest = a & 0x1fffu;
  if (rest > 0x1000u || (rest == 0x1000u && (h & 1u))) ++h;  // a carry into the exponent is right
  return std::uint16_t(sign | h);
#endif
}

/// The float value of binary16 bits (exact).
EMF_HD inline float half_bits_to_float(std::uint16_t bits) {
#if defined(__CUDA_ARCH__)
  return __half2float(__ushort_as_half(bits));
#else
  const std::uint32_t sign = std::uint32_t(bits & 0x8000u) << 16;
  const std::uint32_t exponent = (bits >> 10) & 0x1fu, mantissa = bits & 0x3ffu;
  if (exponent == 0) {
    const float magnitude = float(mantissa) * 5.9604644775390625e-8f;  // 2^-24
    return sign ? -magnitude : magnitude;
  }
  if (exponent == 31) return std::bit_cast<float>(sign | 0x7f800000u | (mantissa << 13));
  return std::bit_cast<float>(sign | ((exponent + 112u) << 23) | (mantissa << 13));
#endif
}

}  // namespace detail

/// IEEE binary16 as a storage scalar: construct from any arithmetic value
/// (through float) and convert to float or double explicitly, as
/// TsdfVolume's code does with every storage type.
struct Half {
  std::uint16_t bits = 0;

  Half() = default;
  template <class T>
    requires std::is_arithmetic_v<T>
  EMF_HD explicit Half(T value) : bits(detail::float_to_half_bits(float(value))) {}
  EMF_HD explicit operator float() const { return detail::half_bits_to_float(bits); }
  EMF_HD explicit operator double() const { return double(detail::half_bits_to_float(bits)); }
};

static_assert(sizeof(Half) == 2, "Half must be two bytes");

}  // namespace emfusion
