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
#include <type_traits>
#include <utility>
#include <vector>

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
/// One segment of grouped_accumulate on the CPU, in index order: through
/// f.accumulate_range(begin, end, acc) where f has it (it may look up once
/// what the segment's indices share), else index by index.
template <class T, class F>
struct AccumulateSegment {
  F f;
  T zero;
  const int* offsets;
  T* out;
  void operator()(int s) const {
    T acc = zero;
    if constexpr (requires { f.accumulate_range(offsets[s], offsets[s + 1], acc); }) {
      f.accumulate_range(offsets[s], offsets[s + 1], acc);
    } else {
      for (int i = offsets[s]; i < offsets[s + 1]; ++i) f(i, acc);
    }
    out[s] = acc;
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

/// An accumulator that grouped_accumulate can sum on a device: a fixed
/// number of doubles, read and written one by one (NormalEquations6).
template <class T>
concept ComponentSum = requires(T& t, const T& c, int i) {
  { T::components } -> std::convertible_to<int>;
  { t.component(i) } -> std::same_as<double&>;
  { c.component(i) } -> std::convertible_to<double>;
};

/// Where grouped_accumulate's segments are: segment s holds the indices
/// [offsets[s], offsets[s + 1]), group g the segments [first_segment[g],
/// first_segment[g + 1]), and group_of[s] is the group of segment s. Every
/// array lives on the backend; `counters` (one per group, zero) is the
/// device's count of a group's finished segments, back at zero afterwards.
struct SegmentGroups {
  int segments = 0, groups = 0;
  const int* offsets = nullptr;
  const int* first_segment = nullptr;
  const int* group_of = nullptr;
  unsigned* counters = nullptr;
};

#if EMFUSION_HAS_CUDA
namespace detail {
inline constexpr int grouped_threads = 256;  ///< threads of a block of grouped_accumulate on a device

/// Block s of grouped_accumulate on a device (accumulate_groups, and the
/// passes of grouped_accumulate_while in core/grouped_loop.hpp). Thread
/// block s sums segment s: each thread the indices offsets[s] + t,
/// + Threads, ..., then the block its threads' sums number by number (warp
/// shuffles, then one value a warp in shared memory). The block that
/// completes its group last (an atomic count) sums the group's segments, in
/// an order fixed by the layout alone, and calls finish from one thread.
template <int Threads, class T, class F, class Finish>
__device__ __forceinline__ void accumulate_group_block(int s, const F& f, const T& zero, const SegmentGroups& layout,
                                                       T* partials, const Finish& finish) {
  constexpr int warps = Threads / 32, n = T::components;
  const int t = int(threadIdx.x);
  T acc = zero;
  for (int i = layout.offsets[s] + t; i < layout.offsets[s + 1]; i += Threads) f(i, acc);
  __shared__ double sums[warps][n];
  __shared__ bool last;
#pragma unroll  // constant indices: the accumulator stays in registers
  for (int c = 0; c < n; ++c) {
    double v = acc.component(c);
    for (int d = 16; d > 0; d /= 2) v += __shfl_down_sync(0xffffffffu, v, d);
    if (t % 32 == 0) sums[t / 32][c] = v;
  }
  __syncthreads();
  if (t < n) {
    double v = 0;
    for (int w = 0; w < warps; ++w) v += sums[w][t];
    partials[s].component(t) = v;
    __threadfence();  // the partial is visible to every block before the count says so
  }
  __syncthreads();
  const int g = layout.group_of[s];
  const int first = layout.first_segment[g], count = layout.first_segment[g + 1] - first;
  if (t == 0) last = atomicAdd(&layout.counters[g], 1u) == unsigned(count - 1);
  __syncthreads();
  if (!last) return;
  __threadfence();
  // Lane q of component c sums segments first + q, + warps, ..., four
  // loads in flight at a time; then thread c sums component c's lanes in
  // order, and thread 0 reads the totals. Thread 0 summing all 232 lane
  // sums itself took 4 000 cycles of every solver step (H200, clock64).
  if (t < warps * n) {
    const int c = t % n, q = t / n, end = first + count;
    double v[4] = {0, 0, 0, 0};
    int j = first + q;
    for (; j + 3 * warps < end; j += 4 * warps) {
      double loaded[4];
#pragma unroll
      for (int k = 0; k < 4; ++k) loaded[k] = __ldcg(&partials[j + k * warps].component(c));
#pragma unroll
      for (int k = 0; k < 4; ++k) v[k] += loaded[k];
    }
    for (int k = 0; j < end; j += warps, ++k) v[k & 3] += __ldcg(&partials[j].component(c));
    sums[q][c] = (v[0] + v[1]) + (v[2] + v[3]);
  }
  __syncthreads();
  if (t < n) {
    double v = 0;
    for (int q = 0; q < warps; ++q) v += sums[q][t];
    sums[0][t] = v;  // lane 0 of component t is read only by this thread
  }
  __syncthreads();
  if (t == 0) {
    T total = zero;
#pragma unroll
    for (int c = 0; c < n; ++c) total.component(c) = sums[0][c];
    layout.counters[g] = 0;
    finish(g, total);
  }
}

/// grouped_accumulate on a device: a block a segment.
template <int Threads, class T, class F, class Finish>
__global__ void __launch_bounds__(Threads)
    accumulate_groups(F f, T zero, SegmentGroups layout, T* partials, Finish finish) {
  accumulate_group_block<Threads>(int(blockIdx.x), f, zero, layout, partials, finish);
}
}  // namespace detail
#endif

namespace detail {
/// grouped_accumulate on the CPU: the segments in parallel, then finish
/// group after group. Returns whether any finish returned true (finish may
/// return bool: grouped_accumulate_while goes on while one does).
template <class B, class T, class F, class Finish>
bool grouped_accumulate_on_host(const B& backend, const SegmentGroups& layout, const F& f, const T& zero, T* partials,
                                const Finish& finish) {
  for_each_index(backend, layout.segments, AccumulateSegment<T, F>{f, zero, layout.offsets, partials});
  bool again = false;
  for (int g = 0; g < layout.groups; ++g) {
    T total = zero;
    for (int j = layout.first_segment[g]; j < layout.first_segment[g + 1]; ++j) total += partials[j];
    if constexpr (std::is_same_v<decltype(finish(g, total)), bool>) {
      again = finish(g, total) || again;
    } else {
      finish(g, total);
    }
  }
  return again;
}
}  // namespace detail

/// The layout of grouped_accumulate for `groups` groups of the same `n`
/// indices each (group g's index i is g n + i), each group cut into
/// `segments` segments of about n / segments: one pass that reduces the same
/// range once per group (the deletion rules' pixel counts of every object).
/// The arrays live in `storage` on the backend (resized as needed; the
/// counters start at zero).
template <Backend B>
SegmentGroups equal_groups(const B& backend, int groups, int n, int segments,
                           typename B::template Vector<int>& storage) {
  segments = std::max(1, std::min(segments, std::max(n, 1)));
  const int total = groups * segments;
  std::vector<int> words;  // offsets, first_segment, group_of, counters
  words.reserve(std::size_t(3 * total + 2 * groups + 2));
  for (int g = 0; g < groups; ++g)
    for (int j = 0; j < segments; ++j)
      words.push_back(g * n + int(std::int64_t(j) * n / segments));
  words.push_back(groups * n);
  for (int g = 0; g <= groups; ++g) words.push_back(g * segments);
  for (int g = 0; g < groups; ++g)
    for (int j = 0; j < segments; ++j) words.push_back(g);
  words.insert(words.end(), std::size_t(groups), 0);
  if (storage.size() < words.size()) storage.resize(words.size());
  int* on_backend = raw_data(storage);
  copy_to_backend(backend, words.data(), words.size(), on_backend);
  static_assert(sizeof(unsigned) == sizeof(int), "the counters share the layout's words");
  return SegmentGroups{total, groups, on_backend, on_backend + total + 1, on_backend + total + groups + 2,
                       reinterpret_cast<unsigned*>(on_backend + 2 * total + groups + 2)};
}

/// For every group g of segments (SegmentGroups), calls finish(g, sum) with
/// the sum of the contributions f(i, acc) (as accumulate_index) of every
/// index of its segments: many reductions, and what follows each, in one
/// pass, as the batched solves need (solve/batched_solve.hpp). `zero` must
/// be the empty sum; `partials` holds one T per segment on the backend. On
/// a device it is one queued kernel that does not wait: a thread block a
/// segment, and the group's last block to finish sums the group and calls
/// `finish` (which runs there, on one thread). On the CPU the segments run
/// in parallel, each in index order, then `finish` group after group.
/// Either way a sum does not depend on the number of threads.
template <Backend B, ComponentSum T, class F, class Finish>
void grouped_accumulate(const B& backend, const SegmentGroups& layout, F f, const T& zero, T* partials,
                        Finish finish) {
  if (layout.segments <= 0) return;
  if constexpr (B::is_device) {
#if EMFUSION_HAS_CUDA
    constexpr int threads = detail::grouped_threads;
    static_assert(threads / 32 * T::components <= threads, "a block sums a group with one thread a number");
    detail::accumulate_groups<threads><<<layout.segments, threads, 0, backend.stream>>>(f, zero, layout, partials,
                                                                                        finish);
    detail::check_cuda(cudaGetLastError(), "grouped_accumulate: kernel launch");
#endif
  } else {
    detail::grouped_accumulate_on_host(backend, layout, f, zero, partials, finish);
  }
}

/// What reduce_per_group keeps between calls: the layout, the groups'
/// views and the results, on the backend.
template <class View, class T, Backend B>
struct PerGroupWorkspace {
  typename B::template Vector<int> layout;
  typename B::template Vector<View> views;
  typename B::template Vector<T> partials, results;
};

namespace detail {
/// Index g n + i of reduce_per_group: f(g, views[g], i, acc).
template <class View, class T, class F>
struct PerGroupIndex {
  const View* views;
  int n;
  F f;
  EMF_HD void operator()(int index, T& acc) const {
    const int g = index / n;
    f(g, views[g], index - g * n, acc);
  }
};
/// grouped_accumulate's finish that stores group g's result.
template <class T>
struct StoreGroupResult {
  T* out;
  EMF_HD void operator()(int g, const T& result) const { out[g] = result; }
};
}  // namespace detail

/// For every view g (an image, say), the reduction of f(g, views[g], i,
/// acc) over i in [0, n), as grouped_accumulate reduces: the same range
/// once per view, all in one pass on the backend and one copy to the host.
/// Where one reduction per view each waited for its copy, a GPU idled
/// between them (the deletion rules' pixel counts of every object).
template <ComponentSum T, Backend B, class View, class F>
std::vector<T> reduce_per_group(const B& backend, const std::vector<View>& views, int n, F f, const T& zero,
                                PerGroupWorkspace<View, T, B>& ws) {
  if (views.empty()) return {};
  if (ws.views.size() < views.size()) ws.views.resize(views.size());
  copy_to_backend(backend, views.data(), views.size(), raw_data(ws.views));
  const int segments = std::max(1, std::min(64, n / 4096));  // segments of at least 4096 indices
  const SegmentGroups layout = equal_groups(backend, int(views.size()), n, segments, ws.layout);
  if (ws.partials.size() < std::size_t(layout.segments)) ws.partials.resize(std::size_t(layout.segments));
  if (ws.results.size() < views.size()) ws.results.resize(views.size());
  grouped_accumulate(backend, layout, detail::PerGroupIndex<View, T, F>{raw_data(ws.views), n, f}, zero,
                     raw_data(ws.partials), detail::StoreGroupResult<T>{raw_data(ws.results)});
  std::vector<T> out(views.size());
  copy_to_host(backend, raw_data(std::as_const(ws.results)), out.size(), out.data());
  return out;
}

}  // namespace emfusion
