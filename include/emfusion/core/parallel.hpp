// The loops everything is built from: run a functor for every index, reduce
// functor results over every index, and accumulate per-index contributions in
// place, on any backend.
//
// Functors are written once, marked EMF_HD, and capture views (raw pointers
// and sizes), never containers.
#pragma once

#include <algorithm>
#include <concepts>
#include <cstdint>

#if defined(_OPENMP)
#include <omp.h>
#endif
#include <thrust/for_each.h>
#include <thrust/host_vector.h>
#include <thrust/iterator/counting_iterator.h>
#include <thrust/transform_reduce.h>

#include "emfusion/core/backend.hpp"

namespace emfusion {

/// The policy for a reduction on `backend`: its reduction_policy() where it
/// has one (pooled temporaries on CUDA), else its policy().
template <Backend B>
auto reduction_policy(const B& backend) {
  if constexpr (requires { backend.reduction_policy(); })
    return backend.reduction_policy();
  else
    return backend.policy();
}

/// Calls f(i) for i in [0, n) on the backend (asynchronously on a device).
/// On the CPU with OpenMP, threads take the indices in runs of about
/// n / (16 threads) as they become free (a dynamic schedule): thrust's
/// OpenMP loop splits [0, n) into one contiguous share per thread, and
/// where the cost of an index varies over the range (rays that hit near or
/// far, pixels inside or outside an object) one thread waited for the
/// other a fifth of the time in parallel loops (2 cores, the whole system).
/// Every index runs once either way, so results do not change.
template <Backend B, class Index, class F>
void for_each_index(const B& backend, Index n, F f) {
  if (n <= 0) return;
#if defined(_OPENMP)
  if constexpr (std::same_as<B, Host>) {
    const Index grain = std::max<Index>(Index(1), Index(n / (Index(omp_get_max_threads()) * Index(16))));
#pragma omp parallel for schedule(dynamic, grain)
    for (Index i = 0; i < n; ++i) f(i);
  } else  // discarded for Host: each loop is compiled once
#endif
  {
    thrust::for_each_n(backend.policy(), thrust::counting_iterator<Index>(0), n, f);
  }
}

/// Returns op-reduction of f(i) over i in [0, n), starting from init. `op`
/// must be associative and commutative; T is usually a small POD accumulator.
template <Backend B, class Index, class T, class F, class Op>
T transform_reduce_index(const B& backend, Index n, F f, T init, Op op) {
  if (n <= 0) return init;
  return thrust::transform_reduce(reduction_policy(backend), thrust::counting_iterator<Index>(0),
                                  thrust::counting_iterator<Index>(n), f, init, op);
}

namespace detail {
/// One CPU chunk of accumulate_index: indices [c * n / chunks, (c + 1) * n / chunks).
template <class Index, class T, class F>
struct AccumulateChunk {
  F f;
  T zero;
  T* partial;
  Index n, chunks;
  void operator()(Index c) const {
    T acc = zero;
    const Index begin = Index(std::int64_t(c) * n / chunks), end = Index(std::int64_t(c + 1) * n / chunks);
    for (Index i = begin; i < end; ++i) f(i, acc);
    partial[c] = acc;
  }
};
/// One index of accumulate_index on a device: its contribution alone.
template <class T, class F>
struct AccumulateOne {
  F f;
  T zero;
  template <class Index>
  EMF_HD T operator()(Index i) const {
    T acc = zero;
    f(i, acc);
    return acc;
  }
};
struct AddInPlace {
  template <class T>
  EMF_HD T operator()(T a, const T& b) const {
    return a += b;
  }
};
}  // namespace detail

/// Returns the sum of every index's contribution over [0, n), where f(i, acc)
/// adds index i's contribution into `acc` in place (T has `+=`). `zero` is the
/// empty sum: every partial sum starts from it, so it must be the identity
/// of `+=`, not a starting value. On the CPU a
/// fixed number of chunks each accumulate sequentially: an index that adds
/// nothing costs nothing, large accumulators are not copied per index, and
/// the sum does not depend on the number of threads. On a device it is a
/// transform_reduce of each index's contribution.
template <Backend B, class Index, class T, class F>
T accumulate_index(const B& backend, Index n, F f, const T& zero) {
  if (n <= 0) return zero;
  if constexpr (B::is_device) {
    return thrust::transform_reduce(reduction_policy(backend), thrust::counting_iterator<Index>(0),
                                    thrust::counting_iterator<Index>(n), detail::AccumulateOne<T, F>{f, zero}, zero,
                                    detail::AddInPlace{});
  } else {
    const Index chunks = n < Index(128) ? n : Index(128);
    thrust::host_vector<T> partial(std::size_t(chunks), zero);
    for_each_index(backend, chunks, detail::AccumulateChunk<Index, T, F>{f, zero, partial.data(), n, chunks});
    T sum = zero;
    for (Index c = 0; c < chunks; ++c) sum += partial[std::size_t(c)];
    return sum;
  }
}

}  // namespace emfusion
