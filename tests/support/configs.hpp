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

/// Every backend built, for tests whose scalar does not matter:
/// TEMPLATE_LIST_TEST_CASE("...", "[tag]", emfusion::test::AllBackends)
/// gives the backend as TestType.
#if EMFUSION_HAS_CUDA
using AllBackends = std::tuple<Host, Cuda>;
#else
using AllBackends = std::tuple<Host>;
#endif

/// The long whole-system rule tests (tests/slam/test_system_rules.cpp,
/// test_lost_objects.cpp, test_hidden_objects.cpp):
/// float on every backend built. Their rules do not depend on the scalar,
/// and System<double> runs in the stage and hostile-frame tests; in double
/// too they cost over a minute of the sanitizer build's tests.
#if EMFUSION_HAS_CUDA
using SystemRuleConfigs = std::tuple<Config<float, Host>, Config<float, Cuda>>;
#else
using SystemRuleConfigs = std::tuple<Config<float, Host>>;
#endif

/// The long tests: the sparse volume (tests/volume/test_sparse_*.cpp,
/// tests/solve/test_sparse_alignment.cpp) and the whole system (tests/slam,
/// tests/io/test_checkpoint.cpp): every config, but float only in the
/// sanitizer build (EMFUSION_SANITIZER_BUILD), which then compiles no
/// System<double> (support/system_instances.cpp). Memory errors and
/// undefined behaviour show in the float instantiation of the same code, at
/// half the sanitizer build's compile and run time; the double one checks
/// arithmetic, which every unit-test build without the sanitizers runs (the
/// GPU machine's, `EMFUSION_SKIP_SANITIZERS=1 scripts/test.sh`).
#if EMFUSION_SANITIZER_BUILD && !EMFUSION_HAS_CUDA
using HeavyConfigs = std::tuple<Config<float, Host>>;
#else
using HeavyConfigs = AllConfigs;
#endif

/// Tolerance helpers: float tests get looser bounds than double tests.
template <class S>
constexpr double eps_for() {
  return sizeof(S) <= 4 ? 1e-4 : 1e-9;
}

}  // namespace emfusion::test
