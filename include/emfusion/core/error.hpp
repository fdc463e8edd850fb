// Errors raised by emfusion: bad arguments throw std::invalid_argument, failed
// device calls throw emfusion::DeviceError. Messages name the function and
// the value that was wrong.
#pragma once

#include <stdexcept>
#include <string>

namespace emfusion {

/// A CUDA runtime call failed.
class DeviceError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

namespace detail {
/// Throws std::invalid_argument("<where>: <what>") unless `ok`.
inline void require(bool ok, const char* where, const std::string& what) {
  if (!ok) throw std::invalid_argument(std::string(where) + ": " + what);
}
}  // namespace detail

}  // namespace emfusion
