// Backends: where data lives and where per-element work runs.
//
// A backend is a small tag type. `Host` runs on the CPU through thrust's
// OpenMP system (or its serial C++ system without OpenMP) and stores data in
// host vectors; `Cuda` (only in units compiled by nvcc) runs on a CUDA stream
// and stores data in device vectors. Algorithms take the backend from the
// container they write, call `policy()` for thrust and use
// `Vector<T>` for storage; nothing else about a backend is assumed.
#pragma once

#include <concepts>
#include <string>

#include <thrust/host_vector.h>
#include <thrust/system/cpp/execution_policy.h>
#if defined(EMFUSION_HAS_OPENMP)
#include <thrust/system/omp/execution_policy.h>
#endif

#include "emfusion/core/error.hpp"
#include "emfusion/core/host_device.hpp"

#if EMFUSION_HAS_CUDA
#include <cuda_runtime.h>
#include <thrust/device_vector.h>
#include <thrust/system/cuda/execution_policy.h>
#endif

namespace emfusion {

/// The CPU backend.
struct Host {
  template <class T>
  using Vector = thrust::host_vector<T>;
  static constexpr bool is_device = false;
  static constexpr const char* name = "cpu";

  static auto policy() {
#if defined(EMFUSION_HAS_OPENMP)
    return thrust::omp::par;
#else
    return thrust::cpp::par;
#endif
  }
  static void synchronize() {}
};

#if EMFUSION_HAS_CUDA

namespace detail {
inline void check_cuda(cudaError_t status, const char* what) {
  if (status != cudaSuccess)
    throw DeviceError(std::string(what) + ": " + cudaGetErrorName(status) + " (" +
                      cudaGetErrorString(status) + ")");
}
}  // namespace detail

/// The CUDA backend: work is queued on `stream` (the legacy default stream
/// unless set) without synchronising; call synchronize() before reading
/// results on the host by other means than the library's copies.
struct Cuda {
  template <class T>
  using Vector = thrust::device_vector<T>;
  static constexpr bool is_device = true;
  static constexpr const char* name = "cuda";

  cudaStream_t stream = nullptr;

  auto policy() const { return thrust::cuda::par_nosync.on(stream); }
  void synchronize() const { detail::check_cuda(cudaStreamSynchronize(stream), "Cuda::synchronize"); }
};

#endif

/// What the library needs from a backend.
template <class B>
concept Backend = requires(const B& b) {
  typename B::template Vector<float>;
  { B::is_device } -> std::convertible_to<bool>;
  b.policy();
  b.synchronize();
};

static_assert(Backend<Host>);

}  // namespace emfusion
