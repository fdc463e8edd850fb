// The one instantiation of System<S, Host> for the unit tests
// (support/system_instances.hpp).
#include "support/system_instances.hpp"

template class emfusion::System<float, emfusion::Host>;
template class emfusion::System<double, emfusion::Host>;
