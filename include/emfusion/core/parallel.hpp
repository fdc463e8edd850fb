// The two loops everything is built from: run a functor for every index, and
// reduce functor results over every index, on any backend.
//
// Functors are written once, marked EMF_HD, and capture views (raw pointers
// and sizes), never containers.
#pragma once

#include <cstdint>

#include <thrust/for_each.h>
#include <thrust/iterator/counting_iterator.h>
#include <thrust/transform_reduce.h>

#include "emfusion/core/backend.hpp"

namespace emfusion {

/// Calls f(i) for i in [0, n) on the backend (asynchronously on a device).
template <Backend B, class Index, class F>
void for_each_index(const B& backend, Index n, F f) {
  if (n <= 0) return;
  thrust::for_each_n(backend.policy(), thrust::counting_iterator<Index>(0), n, f);
}

/// Returns op-reduction of f(i) over i in [0, n), starting from init. `op`
/// must be associative and commutative; T is usually a small POD accumulator.
template <Backend B, class Index, class T, class F, class Op>
T transform_reduce_index(const B& backend, Index n, F f, T init, Op op) {
  if (n <= 0) return init;
  return thrust::transform_reduce(backend.policy(), thrust::counting_iterator<Index>(0),
                                  thrust::counting_iterator<Index>(n), f, init, op);
}

}  // namespace emfusion
