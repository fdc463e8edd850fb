// System<S, Host> for float and double, compiled once for the unit tests
// instead of in every test file that runs the system: include this instead
// of emfusion/slam/system.hpp. float comes from the library every program
// of the repository shares in a CPU build (examples/support/system_host.hpp),
// else from support/system_instances.cpp, as double does (not in the
// sanitizer build, whose system tests run float only: support/configs.hpp,
// HeavyConfigs). Under the sanitizers each file's own instantiation took
// about half a minute.
#pragma once

#include "support/system_host.hpp"

#if !EMFUSION_SYSTEM_HOST_LIBRARY
extern template class emfusion::System<float, emfusion::Host>;
#endif
#if !EMFUSION_SANITIZER_BUILD
extern template class emfusion::System<double, emfusion::Host>;
#endif
