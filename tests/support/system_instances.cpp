// The unit tests' instantiations of System<S, Host>
// (support/system_instances.hpp): float where emfusion_system_host does not
// compile it (a CUDA build), double but in the sanitizer build.
#include "support/system_instances.hpp"

#if !EMFUSION_SYSTEM_HOST_LIBRARY
template class emfusion::System<float, emfusion::Host>;
#endif
#if !EMFUSION_SANITIZER_BUILD  // float only there (support/configs.hpp, HeavyConfigs)
template class emfusion::System<double, emfusion::Host>;
#endif
