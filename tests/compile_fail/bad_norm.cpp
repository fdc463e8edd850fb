// Must not compile (ctest compile_fail_norm): an object norm with a cost but
// no IRLS weight. The error must name the concept RobustNorm.
#include "emfusion/slam/system.hpp"

struct CostOnly {
  EMF_HD float cost(float r) const { return r * r; }
};

int main() {
  using namespace emfusion;
  const PinholeCamera<float> camera{100, 100, 31.5f, 23.5f, 64, 48};
  System<float, Host, PaperLikelihood<float>, HuberNorm<float>, CostOnly> system(camera);
  return system.frame_count();
}
