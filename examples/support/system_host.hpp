// System<float, Host>, the system on the CPU, compiled once for every
// program of this repository that runs it (the app, the examples, the
// benchmarks, the tests): include this instead of emfusion/slam/system.hpp
// and link emfusion_system_host (CMakeLists.txt). In an optimised build each
// program's own instantiation took about a minute of one core, and CI's
// release build had six. A program of your own needs none of this: include
// emfusion/slam/system.hpp.
#pragma once

#include "emfusion/slam/system.hpp"

extern template class emfusion::System<float, emfusion::Host>;
