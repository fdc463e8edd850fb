// Memory figures for the benchmarks: peak and current resident host memory
// of this process, and device memory in use (CUDA builds), in MiB. The
// current figures are the ones frames.csv records (io/frame_log.hpp).
#pragma once

#include <sys/resource.h>

#include "emfusion/core/backend.hpp"
#include "emfusion/io/frame_log.hpp"

namespace emfusion::bench {

/// Peak resident set size of this process so far.
inline double peak_host_mib() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_maxrss) / 1024.0;  // KiB on Linux
}

/// Resident set size now (/proc/self/statm); 0 where that file is missing.
inline double current_host_mib() { return resident_memory_mib(); }

/// Device memory in use on the current GPU (all processes); 0 on the host
/// backend or when the GPU cannot say.
template <class B>
double device_used_mib() {
  return device_memory_mib<B>().value_or(0.0);
}

}  // namespace emfusion::bench
