// Must not compile (ctest compile_fail_solver): a solver whose solve() takes
// the problem but returns a number instead of the solved pose. The error
// must name the concept PoseSolver.
#include "emfusion/slam/system.hpp"

struct ReturnsCost {
  template <class F, class S>
  double solve(F&&, const emfusion::SE3<S>&, emfusion::SolveReport*) const {
    return 0.0;
  }
};

int main() {
  using namespace emfusion;
  const PinholeCamera<float> camera{100, 100, 31.5f, 23.5f, 64, 48};
  System<float, Host, PaperLikelihood<float>, HuberNorm<float>, HuberNorm<float>, ReturnsCost> system(camera);
  return system.frame_count();
}
