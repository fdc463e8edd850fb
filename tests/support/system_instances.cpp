// The unit tests' instantiation of System<double, Host>
// (support/system_instances.hpp); System<float, Host> is
// emfusion_system_host's.
#include "support/system_instances.hpp"

#if !EMFUSION_SANITIZER_BUILD  // float only there (support/configs.hpp, HeavyConfigs)
template class emfusion::System<double, emfusion::Host>;
#endif
