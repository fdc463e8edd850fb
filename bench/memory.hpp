// Memory figures for the benchmarks: peak and current resident host memory
// of this process, and device memory in use (CUDA builds), in MiB.
#pragma once

#include <sys/resource.h>

#include <cstdio>
#include <type_traits>
#include <unistd.h>

#include "emfusion/core/backend.hpp"

namespace emfusion::bench {

/// Peak resident set size of this process so far.
inline double peak_host_mib() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_maxrss) / 1024.0;  // KiB on Linux
}

/// Resident set size now (/proc/self/statm); 0 where that file is missing.
inline double current_host_mib() {
  std::FILE* f = std::fopen("/proc/self/statm", "r");
  if (!f) return 0;
  long pages = 0, resident = 0;
  const int n = std::fscanf(f, "%ld %ld", &pages, &resident);
  std::fclose(f);
  return n == 2 ? double(resident) * double(sysconf(_SC_PAGESIZE)) / (1024.0 * 1024.0) : 0.0;
}

/// Device memory in use on the current GPU (all processes); 0 on the host backend.
template <class B>
double device_used_mib() {
#if EMFUSION_HAS_CUDA
  if constexpr (std::is_same_v<B, Cuda>) {
    std::size_t free = 0, total = 0;
    cudaMemGetInfo(&free, &total);
    return double(total - free) / (1024.0 * 1024.0);
  }
#endif
  return 0;
}

}  // namespace emfusion::bench
