// The atomic operations the library's parallel hash table needs, on either
// backend: compare-and-swap and fetch-and-add of a 64-bit word.
// std::atomic_ref on the host (OpenMP threads), atomicCAS and atomicAdd in
// CUDA device code.
#pragma once

#include <atomic>

#include "emfusion/core/host_device.hpp"

namespace emfusion {

/// If *address equals `expected`, stores `desired` there. Either way returns
/// the value *address held before, atomically with respect to every other
/// call on the same address. `address` must be 8-byte aligned.
EMF_HD inline unsigned long long atomic_compare_and_swap(unsigned long long* address, unsigned long long expected,
                                                         unsigned long long desired) {
#if defined(__CUDA_ARCH__)
  return atomicCAS(address, expected, desired);
#else
  std::atomic_ref<unsigned long long>(*address).compare_exchange_strong(expected, desired);
  return expected;  // compare_exchange_strong wrote the old value here on failure
#endif
}

/// Adds `value` to *address and returns what it held before, atomically with
/// respect to every other atomic call on the same address. `address` must be
/// 8-byte aligned.
EMF_HD inline unsigned long long atomic_fetch_add(unsigned long long* address, unsigned long long value) {
#if defined(__CUDA_ARCH__)
  return atomicAdd(address, value);
#else
  return std::atomic_ref<unsigned long long>(*address).fetch_add(value);
#endif
}

}  // namespace emfusion
