// The one instantiation of System<float, Host> of a CPU build
// (support/system_host.hpp).
#include "support/system_host.hpp"

template class emfusion::System<float, emfusion::Host>;
