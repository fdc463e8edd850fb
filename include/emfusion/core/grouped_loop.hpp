// Passes of grouped_accumulate (core/parallel.hpp) repeated while any
// group's finish asks for another, without the host looking in between: the
// loop of the batched solves (solve/batched_solve.hpp). On a device the
// whole loop is one launch of a CUDA graph whose conditional while node
// (CUDA 12.4 and later) runs a few passes one after the other, and the last
// group to finish a pass decides whether there is another (the passes left
// in the node's body return at once when there is not, and the node stops);
// the graph is built once and kept in a GroupedLoop. On the CPU it is a
// plain loop.
#pragma once

#include <cstddef>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/parallel.hpp"

namespace emfusion {

/// Everything a pass of grouped_accumulate_while reads, as the device reads
/// it: the arguments of grouped_accumulate and the loop's counts.
template <class T, class F, class Finish>
struct GroupedPasses {
  F f;
  T zero;
  SegmentGroups layout;
  T* partials;
  Finish finish;
  int max_passes = 0;
  int passes = 0;             ///< passes run so far
  unsigned groups_done = 0;   ///< groups finished in this pass
  unsigned groups_again = 0;  ///< of them, those that asked for another pass
  int stopped = 0;            ///< the loop is over: passes still queued return at once
};

#if EMFUSION_HAS_CUDA
namespace detail {
/// One pass on a device. The grid is rounded up, so blocks past the
/// layout's segments have nothing to do, and a pass queued after the loop
/// ended does nothing at all. The arguments are copied out of global memory
/// once, as a kernel's own arguments would be. After each group's finish,
/// its answer is counted (atomics, which every block sees alike); the
/// pass's last group sets the loop's condition, and on the last pass marks
/// the loop stopped for the passes still queued in the node's body (they
/// read it after this kernel has ended: no block of this pass reads it
/// after the last group has counted).
template <int Threads, class T, class F, class Finish>
__global__ void __launch_bounds__(Threads)
    grouped_pass(GroupedPasses<T, F, Finish>* passes, cudaGraphConditionalHandle again) {
  const SegmentGroups layout = passes->layout;
  if (int(blockIdx.x) >= layout.segments || passes->stopped) return;
  const F f = passes->f;
  const T zero = passes->zero;
  const Finish finish = passes->finish;
  const auto finish_and_count = [&](int g, const T& total) {
    if (finish(g, total)) atomicAdd(&passes->groups_again, 1u);
    __threadfence();  // the answer is counted before the group is
    if (atomicAdd(&passes->groups_done, 1u) != unsigned(layout.groups - 1)) return;
    const unsigned asking = atomicExch(&passes->groups_again, 0u);
    passes->groups_done = 0;  // read by the next pass, after this kernel
    const int done = ++passes->passes;
    if (done < passes->max_passes && asking > 0) return;  // the condition stays 1, as each launch sets it
    passes->stopped = 1;
    cudaGraphSetConditional(again, 0u);
  };
  accumulate_group_block<Threads>(int(blockIdx.x), f, zero, layout, passes->partials, finish_and_count);
}
}  // namespace detail
#endif

/// The device's side of grouped_accumulate_while, kept between calls: the
/// arguments' buffer on the device and the graph of the loop, built for one
/// kind of pass (its functors' types) and a grid size; a call with another
/// kind or more segments builds it again. Holds nothing on the CPU. A copy
/// starts empty (a graph is not shared) with the same passes a body.
///
/// `passes_per_body` passes run back to back in each round of the while
/// node: the node's relaunch costs more than a launch queued behind another
/// (about 4 us a pass on an H200, bench/bench_device_loop.cpp), and a pass
/// queued after the loop has ended costs a launch that returns at once
/// (about 1.2 us). The default, 4, recovers most of the relaunch; 8 measured
/// no better on the whole system (docs/decisions.md, "Several passes a
/// round of the while node").
class GroupedLoop {
 public:
  GroupedLoop() = default;
  explicit GroupedLoop(int passes_per_body) : per_body_(passes_per_body < 1 ? 1 : passes_per_body) {}
  GroupedLoop(const GroupedLoop& other) : per_body_(other.per_body_) {}
  GroupedLoop& operator=(const GroupedLoop& other) {
    if (per_body_ != other.per_body_) release(), per_body_ = other.per_body_;  // its graph is kept otherwise
    return *this;
  }
  ~GroupedLoop() { release(); }

  /// How many times a graph was built (a test's measure of reuse).
  int builds() const { return builds_; }
  /// Passes a round of the device's while node.
  int passes_per_body() const { return per_body_; }

#if EMFUSION_HAS_CUDA
  /// The loop of `passes` on backend's stream, queued (it does not wait).
  template <class T, class F, class Finish>
  void run(const Cuda& backend, const GroupedPasses<T, F, Finish>& passes) {
    using Passes = GroupedPasses<T, F, Finish>;
    const void* pass_kernel =
        reinterpret_cast<const void*>(&detail::grouped_pass<detail::grouped_threads, T, F, Finish>);
    if (sizeof(Passes) > bytes_) {
      release();
      detail::check_cuda(cudaMalloc(&arguments_, sizeof(Passes)), "grouped_accumulate_while: cudaMalloc");
      bytes_ = sizeof(Passes);
    }
    if (exec_ == nullptr || kernel_ != pass_kernel || passes.layout.segments > grid_) {
      int grid = 32;  // rounded up to a power of two: segment counts change from call to call
      while (grid < passes.layout.segments) grid *= 2;
      build<Passes>(pass_kernel, grid);
    }
    detail::check_cuda(cudaMemcpyAsync(arguments_, &passes, sizeof(Passes), cudaMemcpyHostToDevice, backend.stream),
                       "grouped_accumulate_while: cudaMemcpyAsync");
    detail::check_cuda(cudaGraphLaunch(exec_, backend.stream), "grouped_accumulate_while: cudaGraphLaunch");
  }
#endif

 private:
#if EMFUSION_HAS_CUDA
  /// The graph: a while node (its condition 1 at every launch) whose body
  /// is per_body_ passes in a row, each reading `arguments_`.
  template <class Passes>
  void build(const void* pass_kernel, int grid) {
    if (exec_) cudaGraphExecDestroy(exec_), exec_ = nullptr;
    const char* what = "grouped_accumulate_while: building the graph";
    cudaGraph_t graph = nullptr;
    detail::check_cuda(cudaGraphCreate(&graph, 0), what);
    struct Destroy {
      cudaGraph_t g;
      ~Destroy() { cudaGraphDestroy(g); }
    } destroy{graph};
    cudaGraphConditionalHandle again{};
    detail::check_cuda(cudaGraphConditionalHandleCreate(&again, graph, 1, cudaGraphCondAssignDefault), what);
    cudaGraphNodeParams loop{};
    loop.type = cudaGraphNodeTypeConditional;
    loop.conditional.handle = again;
    loop.conditional.type = cudaGraphCondTypeWhile;
    loop.conditional.size = 1;
    cudaGraphNode_t loop_node = nullptr;
    detail::check_cuda(cudaGraphAddNode(&loop_node, graph, nullptr, nullptr, 0, &loop), what);
    Passes* arguments = static_cast<Passes*>(arguments_);
    void* pass_arguments[] = {&arguments, &again};
    cudaKernelNodeParams pass{};
    pass.func = const_cast<void*>(pass_kernel);
    pass.gridDim = dim3(unsigned(grid));
    pass.blockDim = dim3(unsigned(detail::grouped_threads));
    pass.kernelParams = pass_arguments;
    cudaGraphNode_t previous = nullptr;
    for (int k = 0; k < per_body_; ++k) {
      cudaGraphNode_t pass_node = nullptr;
      detail::check_cuda(cudaGraphAddKernelNode(&pass_node, loop.conditional.phGraph_out[0],
                                                previous ? &previous : nullptr, previous ? 1 : 0, &pass),
                         what);
      previous = pass_node;
    }
    detail::check_cuda(cudaGraphInstantiate(&exec_, graph, 0), what);
    kernel_ = pass_kernel;
    grid_ = grid;
    ++builds_;
  }
#endif
  void release() {
#if EMFUSION_HAS_CUDA
    // No error checks: this may run after the device has gone (at exit).
    if (exec_) cudaGraphExecDestroy(exec_);
    if (arguments_) cudaFree(arguments_);
    exec_ = nullptr, arguments_ = nullptr, kernel_ = nullptr;
#endif
    bytes_ = 0, grid_ = 0;
  }

#if EMFUSION_HAS_CUDA
  cudaGraphExec_t exec_ = nullptr;
  void* arguments_ = nullptr;
  const void* kernel_ = nullptr;
#endif
  std::size_t bytes_ = 0;
  int per_body_ = 4;
  int grid_ = 0;
  int builds_ = 0;
};

/// grouped_accumulate(backend, layout, f, zero, partials, finish) run pass
/// after pass, at least once and at most max_passes times, while any
/// group's finish(g, sum) returns true (it asks for another pass); what a
/// pass's finish writes is what the next pass's f reads. On a device all
/// passes are one queued graph launch (`loop` keeps the graph between
/// calls), and the host waits for nothing; it reads the outcome with a copy
/// afterwards. On the CPU, a loop.
template <Backend B, ComponentSum T, class F, class Finish>
void grouped_accumulate_while(const B& backend, GroupedLoop& loop, const SegmentGroups& layout, F f, const T& zero,
                              T* partials, Finish finish, int max_passes) {
  if (layout.segments <= 0 || max_passes <= 0) return;
  if constexpr (B::is_device) {
#if EMFUSION_HAS_CUDA
    loop.run(backend, GroupedPasses<T, F, Finish>{f, zero, layout, partials, finish, max_passes});
#endif
  } else {
    (void)loop;
    for (int pass = 0; pass < max_passes; ++pass)
      if (!detail::grouped_accumulate_on_host(backend, layout, f, zero, partials, finish)) break;
  }
}

}  // namespace emfusion
