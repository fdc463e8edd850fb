// Milliseconds per stage of a frame, measured without draining the backend
// between stages (the stage times of slam/system.hpp). On the CPU a stage's
// work is done when its call returns, and a lap reads the wall clock. On
// CUDA the work is only queued: a lap queues an event on the backend's
// stream, and finish() waits once and reads the time between consecutive
// events, so the host queues the next stage while the device still runs
// this one. A stage's time is then the device's progress from one lap to
// the next, time it spent waiting for the host included; the frame's total
// is the wall clock from start() to the end of finish().
#pragma once

#include <chrono>
#include <cstddef>
#include <utility>
#include <vector>

#include "emfusion/core/backend.hpp"

namespace emfusion {

namespace detail {
using StageWall = std::chrono::steady_clock;
inline double milliseconds_between(StageWall::time_point a, StageWall::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}
}  // namespace detail

/// A frame's stage clock on backend B: start(), lap(into) at the end of
/// each stage (its milliseconds are added to `into`, which must outlive
/// finish()), finish() for the total. Any backend without events of its own
/// is synchronised at each lap.
template <Backend B>
class StageClock {
 public:
  void start(const B& backend) {
    backend_ = backend;
    begin_ = last_ = detail::StageWall::now();
  }
  void lap(double& into) {
    backend_.synchronize();
    const auto now = detail::StageWall::now();
    into += detail::milliseconds_between(last_, now);
    last_ = now;
  }
  double finish() {
    backend_.synchronize();
    return detail::milliseconds_between(begin_, detail::StageWall::now());
  }

 private:
  B backend_{};
  detail::StageWall::time_point begin_{}, last_{};
};

#if EMFUSION_HAS_CUDA
/// On CUDA: an event a lap, read at finish() (the events are created on
/// first use and kept). A copy starts without events (they are not shared).
template <>
class StageClock<Cuda> {
 public:
  StageClock() = default;
  StageClock(const StageClock&) {}
  StageClock& operator=(const StageClock&) { return *this; }
  StageClock(StageClock&& o) noexcept { swap(o); }
  StageClock& operator=(StageClock&& o) noexcept {
    swap(o);
    return *this;
  }
  ~StageClock() {
    for (cudaEvent_t e : events_) cudaEventDestroy(e);  // at teardown an error has nowhere to go
  }

  void start(const Cuda& backend) {
    backend_ = backend;
    laps_.clear();
    begin_ = detail::StageWall::now();
    record();
  }
  void lap(double& into) {
    laps_.push_back(&into);
    record();
  }
  double finish() {
    backend_.synchronize();
    const double total = detail::milliseconds_between(begin_, detail::StageWall::now());
    for (std::size_t i = 0; i < laps_.size(); ++i) {
      float ms = 0;
      detail::check_cuda(cudaEventElapsedTime(&ms, events_[i], events_[i + 1]), "StageClock: cudaEventElapsedTime");
      *laps_[i] += double(ms);
    }
    laps_.clear();
    return total;
  }

 private:
  /// The event of lap laps_.size() (0: the start), queued now.
  void record() {
    const std::size_t k = laps_.size();
    while (events_.size() <= k) {
      cudaEvent_t e = nullptr;
      detail::check_cuda(cudaEventCreate(&e), "StageClock: cudaEventCreate");
      events_.push_back(e);
    }
    detail::check_cuda(cudaEventRecord(events_[k], backend_.stream), "StageClock: cudaEventRecord");
  }
  void swap(StageClock& o) noexcept {
    std::swap(backend_, o.backend_);
    std::swap(events_, o.events_);
    std::swap(laps_, o.laps_);
    std::swap(begin_, o.begin_);
  }
  Cuda backend_{};
  std::vector<cudaEvent_t> events_;
  std::vector<double*> laps_;
  detail::StageWall::time_point begin_{};
};
#endif

}  // namespace emfusion
