// Must not compile (ctest compile_fail_likelihood): a likelihood without the
// `foreground` member that the system points at each object's counts. The
// error must name the concept VolumeLikelihood.
#include "emfusion/slam/system.hpp"

struct NoForeground {
  emfusion::TsdfView<float, const float> volume;
  EMF_HD float likelihood(const emfusion::Vec3<float>&) const { return 1.0f; }
};

int main() {
  const emfusion::PinholeCamera<float> camera{100, 100, 31.5f, 23.5f, 64, 48};
  emfusion::System<float, emfusion::Host, NoForeground> system(camera);
  return system.frame_count();
}
