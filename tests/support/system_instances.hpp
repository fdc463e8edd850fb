// System<S, Host> for float and double, compiled once for the unit tests
// (support/system_instances.cpp) instead of in every test file that runs the
// system: include this instead of emfusion/slam/system.hpp. Under the
// sanitizers each file's own instantiation took about half a minute.
#pragma once

#include "emfusion/slam/system.hpp"

extern template class emfusion::System<float, emfusion::Host>;
extern template class emfusion::System<double, emfusion::Host>;
