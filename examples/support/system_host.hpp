// System<float, Host>, the system on the CPU, compiled once for every
// program of this repository that runs it (the app, the benchmarks, the
// tests): include this instead of emfusion/slam/system.hpp and link
// emfusion_system_host (CMakeLists.txt). In CI's sanitizer build each
// program's own instantiation took about a minute of one core. In a CUDA
// build each program instantiates it itself (EMFUSION_SYSTEM_HOST_LIBRARY
// unset): make builds a library before the programs that link it, and the
// library's unit then ran alone ahead of the app's, the longest one. A
// program of your own needs none of this: include emfusion/slam/system.hpp.
#pragma once

#include "emfusion/slam/system.hpp"

#if EMFUSION_SYSTEM_HOST_LIBRARY
extern template class emfusion::System<float, emfusion::Host>;
#endif
