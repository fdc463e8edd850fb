// Little-endian binary fields for the binary reader and writer of io/ (.klg
// logs): reading fixed-size integers out of a byte buffer, and appending
// them to one, independent of the host's byte order.
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

}  // namespace emfusion::detail::bytes
