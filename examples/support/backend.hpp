// Choosing the backend from a --backend value, for the app and the
// benchmarks: one place that knows which backends this build has.
#pragma once

#include <stdexcept>
#include <string>

#include "emfusion/core/backend.hpp"

namespace emfusion::examples {

/// Calls f(Host{}) for "cpu" and f(Cuda{}) for "cuda"; throws
/// std::invalid_argument for any other name, or for "cuda" in a build
/// without CUDA.
template <class F>
void with_backend(const std::string& name, F&& f) {
  if (name == "cpu") return f(Host{});
  if (name == "cuda") {
#if EMFUSION_HAS_CUDA
    return f(Cuda{});
#else
    throw std::invalid_argument("--backend 'cuda' is not available: this build has no CUDA");
#endif
  }
  throw std::invalid_argument("--backend must be cpu or cuda, got '" + name + "'");
}

}  // namespace emfusion::examples
