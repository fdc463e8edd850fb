// Backends: where data lives and where per-element work runs.
//
// A backend is a small tag type. `Host` runs on the CPU through thrust's
// OpenMP system (or its serial C++ system without OpenMP) and stores data in
// host vectors; `Cuda` (only in units compiled by nvcc) runs on a CUDA stream
// and stores data in device vectors. Algorithms take the backend from the
// container they write, call `policy()` for thrust and use
// `Vector<T>` for storage; nothing else about a backend is assumed.
#pragma once

#include <algorithm>
#include <concepts>
#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include <thrust/copy.h>
#include <thrust/host_vector.h>
#include <thrust/memory.h>
#include <thrust/system/cpp/execution_policy.h>
#if defined(EMFUSION_HAS_OPENMP)
#include <thrust/system/omp/execution_policy.h>
#endif

#include "emfusion/core/error.hpp"
#include "emfusion/core/host_device.hpp"

#if EMFUSION_HAS_CUDA
#include <cuda_runtime.h>
#include <thrust/device_vector.h>
#include <thrust/system/cuda/execution_policy.h>

#include <map>
#include <mutex>
#endif

namespace emfusion {

/// The CPU backend.
struct Host {
  template <class T>
  using Vector = thrust::host_vector<T>;
  static constexpr bool is_device = false;
  static constexpr const char* name = "cpu";

  static auto policy() {
#if defined(EMFUSION_HAS_OPENMP)
    return thrust::omp::par;
#else
    return thrust::cpp::par;
#endif
  }
  static void synchronize() {}
};

#if EMFUSION_HAS_CUDA

namespace detail {
inline void check_cuda(cudaError_t status, const char* what) {
  if (status != cudaSuccess)
    throw DeviceError(std::string(what) + ": " + cudaGetErrorName(status) + " (" +
                      cudaGetErrorString(status) + ")");
}

/// Device memory for the temporaries of reductions (their scratch space and
/// result), kept for reuse: thrust otherwise pays a cudaMalloc and a
/// device-wide synchronising cudaFree on every call, dozens of times a frame.
/// One pool per process, shared by every stream and thread. Only algorithms
/// whose result the host reads before they return may use it (a block goes
/// back to the pool when the algorithm ends, and the next user may run on
/// another stream). The pool holds the largest set of temporaries in use at
/// once (a few hundred KiB) and frees it at exit.
class ReductionMemoryPool {
 public:
  static ReductionMemoryPool& instance() {
    // Constructed after the CUDA runtime started (on the first reduction), so
    // destroyed before the runtime's own teardown.
    static ReductionMemoryPool pool;
    return pool;
  }
  ReductionMemoryPool() = default;
  ReductionMemoryPool(const ReductionMemoryPool&) = delete;
  ReductionMemoryPool& operator=(const ReductionMemoryPool&) = delete;
  ~ReductionMemoryPool() {
    for (auto& entry : free_) cudaFree(entry.second);  // errors at exit have nowhere to go
  }
  char* allocate(std::size_t bytes) {
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      const auto it = free_.lower_bound(bytes);
      if (it != free_.end() && it->first <= 2 * bytes + 4096) {
        char* p = it->second;
        used_[p] = it->first;
        free_.erase(it);
        return p;
      }
    }
    void* p = nullptr;
    check_cuda(cudaMalloc(&p, bytes), "ReductionMemoryPool: cudaMalloc");
    const std::lock_guard<std::mutex> lock(mutex_);
    used_[static_cast<char*>(p)] = bytes;
    return static_cast<char*>(p);
  }
  void deallocate(char* p) {
    const std::lock_guard<std::mutex> lock(mutex_);
    const auto it = used_.find(p);
    if (it == used_.end()) return;
    free_.emplace(it->second, p);
    used_.erase(it);
  }

 private:
  std::mutex mutex_;
  std::multimap<std::size_t, char*> free_;
  std::map<char*, std::size_t> used_;
};

/// The allocator thrust takes for temporaries, drawing on the pool above.
struct ReductionAllocator {
  using value_type = char;
  char* allocate(std::ptrdiff_t bytes) { return ReductionMemoryPool::instance().allocate(std::size_t(bytes)); }
  void deallocate(char* p, std::size_t) { ReductionMemoryPool::instance().deallocate(p); }
};

/// The current device's memory pool for stream-ordered temporaries
/// (StreamScratch), created on first use and kept for the process: it holds
/// on to freed memory (release threshold: never), so that allocations after
/// the first cost no call into the driver's page mapping.
inline cudaMemPool_t scratch_memory_pool() {
  int device = 0;
  check_cuda(cudaGetDevice(&device), "scratch_memory_pool: cudaGetDevice");
  static std::mutex mutex;
  static std::map<int, cudaMemPool_t> pools;
  const std::lock_guard<std::mutex> lock(mutex);
  const auto found = pools.find(device);
  if (found != pools.end()) return found->second;
  cudaMemPoolProps props{};
  props.allocType = cudaMemAllocationTypePinned;
  props.handleTypes = cudaMemHandleTypeNone;
  props.location.type = cudaMemLocationTypeDevice;
  props.location.id = device;
  cudaMemPool_t pool = nullptr;
  check_cuda(cudaMemPoolCreate(&pool, &props), "scratch_memory_pool: cudaMemPoolCreate");
  unsigned long long keep = ~0ull;
  check_cuda(cudaMemPoolSetAttribute(pool, cudaMemPoolAttrReleaseThreshold, &keep),
             "scratch_memory_pool: cudaMemPoolSetAttribute");
  pools.emplace(device, pool);
  return pool;
}
}  // namespace detail

/// Temporaries of the thrust algorithms one object queues on one stream
/// (sorts, scans, compactions), allocated and freed in that stream's order
/// (cudaMallocFromPoolAsync, cudaFreeAsync): no device-wide synchronisation
/// as with thrust's own cudaMalloc and cudaFree, and safe however the
/// algorithm and later work overlap. An object keeps one beside its backend
/// and passes it to scratch_policy(); thrust holds it by reference, so it
/// must outlive the policy.
struct StreamScratch {
  using value_type = char;
  cudaStream_t stream = nullptr;
  char* allocate(std::ptrdiff_t bytes) {
    void* p = nullptr;
    detail::check_cuda(cudaMallocFromPoolAsync(&p, std::size_t(bytes), detail::scratch_memory_pool(), stream),
                       "StreamScratch: cudaMallocFromPoolAsync");
    return static_cast<char*>(p);
  }
  void deallocate(char* p, std::size_t) {
    cudaFreeAsync(p, stream);  // called from destructors: an error has nowhere to go
  }
};

/// The CUDA backend: work is queued on `stream` (the legacy default stream
/// unless set) without synchronising; call synchronize() before reading
/// results on the host by other means than the library's copies.
struct Cuda {
  template <class T>
  using Vector = thrust::device_vector<T>;
  static constexpr bool is_device = true;
  static constexpr const char* name = "cuda";

  cudaStream_t stream = nullptr;

  auto policy() const { return thrust::cuda::par_nosync.on(stream); }
  /// For reductions, whose result the host reads before they return: their
  /// temporaries come from detail::ReductionMemoryPool.
  auto reduction_policy() const {
    static detail::ReductionAllocator allocator;
    return thrust::cuda::par_nosync(allocator).on(stream);
  }
  void synchronize() const { detail::check_cuda(cudaStreamSynchronize(stream), "Cuda::synchronize"); }
};

/// The policy for `backend` with temporaries from `scratch` (which must be
/// for the backend's stream): see StreamScratch.
inline auto scratch_policy(const Cuda& backend, StreamScratch& scratch) {
  return thrust::cuda::par_nosync(scratch).on(backend.stream);
}

#endif

/// On every other backend temporaries cost no device synchronisation:
/// scratch_policy is the backend's policy, and its scratch holds nothing.
struct NoScratch {};
template <class B>
auto scratch_policy(const B& backend, NoScratch&) {
  return backend.policy();
}

namespace detail {
template <class B>
struct ScratchOf {
  using type = NoScratch;
};
#if EMFUSION_HAS_CUDA
template <>
struct ScratchOf<Cuda> {
  using type = StreamScratch;
};
#endif
}  // namespace detail

/// What an object keeps to give its thrust algorithms on backend B
/// stream-ordered temporaries (StreamScratch on CUDA, nothing elsewhere);
/// make one with make_scratch(backend).
template <class B>
using ScratchFor = typename detail::ScratchOf<B>::type;

template <class B>
ScratchFor<B> make_scratch(const B& backend) {
  if constexpr (std::same_as<ScratchFor<B>, NoScratch>)
    return NoScratch{};
  else
    return ScratchFor<B>{backend.stream};
}

/// Independent queues of work on a backend, for work that may run at the
/// same time: solves from several host threads, or the objects' ray casts
/// queued one after another from one thread (fork, queue on the lanes,
/// join). On the CPU there are none (`concurrent` is false: work runs one
/// piece after another, each parallel inside, and fork and join do
/// nothing); on CUDA, lane k is a stream of its own, created on first use
/// and destroyed with the set.
template <class B>
class ConcurrentLanes {
 public:
  static constexpr bool concurrent = false;
  B lane(std::size_t, const B& base) { return base; }
  /// Lanes 0..count-1 start after the work queued on `base` so far.
  void fork(const B&, std::size_t) {}
  /// Work queued on `base` from now on starts after lanes 0..count-1's.
  void join(const B&, std::size_t) {}
};

#if EMFUSION_HAS_CUDA
template <>
class ConcurrentLanes<Cuda> {
 public:
  static constexpr bool concurrent = true;
  ConcurrentLanes() = default;
  ConcurrentLanes(const ConcurrentLanes&) = delete;
  ConcurrentLanes& operator=(const ConcurrentLanes&) = delete;
  ConcurrentLanes(ConcurrentLanes&& o) noexcept : streams_(std::move(o.streams_)), events_(std::move(o.events_)) {
    o.streams_.clear(), o.events_.clear();
  }
  ConcurrentLanes& operator=(ConcurrentLanes&& o) noexcept {
    std::swap(streams_, o.streams_);
    std::swap(events_, o.events_);
    return *this;
  }
  ~ConcurrentLanes() {
    // Errors at teardown have nowhere to go.
    for (cudaStream_t s : streams_) cudaStreamDestroy(s);
    for (cudaEvent_t e : events_) cudaEventDestroy(e);
  }
  /// Lane k: a blocking stream, so it also orders itself after the legacy
  /// default stream's work.
  Cuda lane(std::size_t k, const Cuda&) {
    while (streams_.size() <= k) {
      cudaStream_t s = nullptr;
      detail::check_cuda(cudaStreamCreate(&s), "ConcurrentLanes: cudaStreamCreate");
      streams_.push_back(s);
    }
    return Cuda{streams_[k]};
  }
  /// Lanes 0..count-1 start after the work queued on `base` so far.
  void fork(const Cuda& base, std::size_t count) {
    if (count == 0) return;
    lane(count - 1, base);
    cudaEvent_t e = event(0);
    detail::check_cuda(cudaEventRecord(e, base.stream), "ConcurrentLanes::fork: cudaEventRecord");
    for (std::size_t k = 0; k < count; ++k)
      detail::check_cuda(cudaStreamWaitEvent(streams_[k], e, 0), "ConcurrentLanes::fork: cudaStreamWaitEvent");
  }
  /// Work queued on `base` from now on starts after lanes 0..count-1's.
  void join(const Cuda& base, std::size_t count) {
    for (std::size_t k = 0; k < count && k < streams_.size(); ++k) {
      cudaEvent_t e = event(k + 1);
      detail::check_cuda(cudaEventRecord(e, streams_[k]), "ConcurrentLanes::join: cudaEventRecord");
      detail::check_cuda(cudaStreamWaitEvent(base.stream, e, 0), "ConcurrentLanes::join: cudaStreamWaitEvent");
    }
  }

 private:
  /// Event i (0: the fork's; k + 1: lane k's join), created on first use.
  cudaEvent_t event(std::size_t i) {
    while (events_.size() <= i) {
      cudaEvent_t e = nullptr;
      detail::check_cuda(cudaEventCreateWithFlags(&e, cudaEventDisableTiming), "ConcurrentLanes: cudaEventCreate");
      events_.push_back(e);
    }
    return events_[i];
  }

  std::vector<cudaStream_t> streams_;
  std::vector<cudaEvent_t> events_;
};
#endif

/// Copies n values between host memory and memory of `backend`, in the
/// order of the backend's work: to_backend queues the copy (the host values
/// may change once it returns), to_host waits for the backend's queued work
/// and the copy. T must be trivially copyable.
template <class T>
void copy_to_backend(const Host&, const T* from, std::size_t n, T* to) {
  std::copy(from, from + n, to);
}
template <class T>
void copy_to_host(const Host&, const T* from, std::size_t n, T* to) {
  std::copy(from, from + n, to);
}
#if EMFUSION_HAS_CUDA
template <class T>
void copy_to_backend(const Cuda& backend, const T* from, std::size_t n, T* to) {
  if (n == 0) return;
  detail::check_cuda(cudaMemcpyAsync(to, from, n * sizeof(T), cudaMemcpyHostToDevice, backend.stream),
                     "copy_to_backend: cudaMemcpyAsync");
}
template <class T>
void copy_to_host(const Cuda& backend, const T* from, std::size_t n, T* to) {
  if (n == 0) return;
  detail::check_cuda(cudaMemcpyAsync(to, from, n * sizeof(T), cudaMemcpyDeviceToHost, backend.stream),
                     "copy_to_host: cudaMemcpyAsync");
  backend.synchronize();
}
#endif

/// A raw pointer to a backend vector's elements (what kernels and views
/// take); nullptr for an empty vector, whose data() thrust would form by
/// dereferencing its first element.
template <class Vec>
auto* raw_data(Vec& v) {
  return v.empty() ? nullptr : thrust::raw_pointer_cast(v.data());
}

/// The first `count` elements of a backend vector (all of them by default)
/// in a host vector, once `backend`'s queued work is done.
template <class B, class Vec>
std::vector<typename Vec::value_type> vector_to_host(const B& backend, const Vec& v,
                                                     std::size_t count = std::size_t(-1)) {
  backend.synchronize();
  std::vector<typename Vec::value_type> out(std::min(count, std::size_t(v.size())));
  if (!out.empty()) thrust::copy(v.begin(), v.begin() + std::ptrdiff_t(out.size()), out.begin());
  return out;
}

/// What the library needs from a backend.
template <class B>
concept Backend = requires(const B& b) {
  typename B::template Vector<float>;
  { B::is_device } -> std::convertible_to<bool>;
  b.policy();
  b.synchronize();
};

static_assert(Backend<Host>);

}  // namespace emfusion
