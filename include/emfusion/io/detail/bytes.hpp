// Little-endian binary fields for the binary readers and writers of io/ (.klg
// logs, OpenEXR): reading fixed-size integers and floats out of a byte
// buffer, and appending them to one, independent of the host's byte order.
// Bounds are the caller's business: every read here takes a pointer to at
// least as many bytes as the field has.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>

namespace emfusion::detail::bytes {

inline std::uint16_t u16(const unsigned char* p) { return std::uint16_t(p[0] | (unsigned(p[1]) << 8)); }

inline std::uint32_t u32(const unsigned char* p) {
  return std::uint32_t(p[0]) | (std::uint32_t(p[1]) << 8) | (std::uint32_t(p[2]) << 16) | (std::uint32_t(p[3]) << 24);
}

inline std::uint64_t u64(const unsigned char* p) { return std::uint64_t(u32(p)) | (std::uint64_t(u32(p + 4)) << 32); }

inline std::int32_t i32(const unsigned char* p) {
  const std::uint32_t v = u32(p);
  std::int32_t out;
  std::memcpy(&out, &v, 4);  // two's complement reinterpretation, no overflow
  return out;
}

inline std::int64_t i64(const unsigned char* p) {
  const std::uint64_t v = u64(p);
  std::int64_t out;
  std::memcpy(&out, &v, 8);
  return out;
}

inline float f32(const unsigned char* p) {
  const std::uint32_t v = u32(p);
  float out;
  std::memcpy(&out, &v, 4);
  return out;
}

inline void put_u8(std::string& out, unsigned value) { out.push_back(char(value & 0xffu)); }

inline void put_u16(std::string& out, std::uint16_t value) {
  put_u8(out, value);
  put_u8(out, unsigned(value) >> 8);
}

inline void put_u32(std::string& out, std::uint32_t value) {
  for (int k = 0; k < 4; ++k) put_u8(out, unsigned(value >> (8 * k)));
}

inline void put_u64(std::string& out, std::uint64_t value) {
  for (int k = 0; k < 8; ++k) put_u8(out, unsigned(value >> (8 * k)));
}

inline void put_i32(std::string& out, std::int32_t value) {
  std::uint32_t v;
  std::memcpy(&v, &value, 4);
  put_u32(out, v);
}

inline void put_i64(std::string& out, std::int64_t value) {
  std::uint64_t v;
  std::memcpy(&v, &value, 8);
  put_u64(out, v);
}

inline void put_f32(std::string& out, float value) {
  std::uint32_t v;
  std::memcpy(&v, &value, 4);
  put_u32(out, v);
}

/// Overwrites 8 bytes at `offset` of `out` (a field reserved earlier).
inline void set_u64(std::string& out, std::size_t offset, std::uint64_t value) {
  for (int k = 0; k < 8; ++k) out[offset + std::size_t(k)] = char((value >> (8 * k)) & 0xffu);
}

/// IEEE 754 half-precision bits to float: every half value, subnormals,
/// infinities and NaNs included, converts exactly.
inline float half_to_float(std::uint16_t h) {
  const std::uint32_t sign = std::uint32_t(h & 0x8000u) << 16;
  const std::uint32_t exponent = (h >> 10) & 0x1fu;
  std::uint32_t mantissa = h & 0x3ffu;
  std::uint32_t bits;
  if (exponent == 0) {
    if (mantissa == 0) {
      bits = sign;  // +-0
    } else {
      // Subnormal half: mantissa * 2^-24. Normalise it for the float format.
      int e = -1;
      do {
        ++e;
        mantissa <<= 1;
      } while ((mantissa & 0x400u) == 0);
      bits = sign | (std::uint32_t(127 - 15 - e) << 23) | ((mantissa & 0x3ffu) << 13);
    }
  } else if (exponent == 31) {
    bits = sign | 0x7f800000u | (mantissa << 13);  // infinity or NaN (payload kept)
  } else {
    bits = sign | ((exponent + 127 - 15) << 23) | (mantissa << 13);
  }
  float out;
  std::memcpy(&out, &bits, 4);
  return out;
}

}  // namespace emfusion::detail::bytes
