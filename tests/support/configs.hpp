// Type lists for tests that run over every scalar and every backend built:
// TEMPLATE_LIST_TEST_CASE("...", "[tag]", emfusion::test::AllConfigs) gives
// TestType::Scalar and TestType::Backend.
#pragma once

#include <tuple>

#include "emfusion/core/backend.hpp"

namespace emfusion::test {

template <class S, class B>
struct Config {
  using Scalar = S;
  using Backend = B;
};

#if EMFUSION_HAS_CUDA
using AllConfigs = std::tuple<Config<float, Host>, Config<double, Host>, Config<float, Cuda>, Config<double, Cuda>>;
#else
using AllConfigs = std::tuple<Config<float, Host>, Config<double, Host>>;
#endif

/// Tolerance helpers: float tests get looser bounds than double tests.
template <class S>
constexpr double eps_for() {
  return sizeof(S) <= 4 ? 1e-4 : 1e-9;
}

}  // namespace emfusion::test
