// What a pass of the batched solves' device loop costs apart from its terms
// (issue 22): grouped_accumulate_while (core/grouped_loop.hpp) running
// passes whose terms do next to nothing, against the same pass launched from
// the host once a pass (grouped_accumulate), for a few layouts of segments.
// Each pass reduces a NormalEquations6 per group (28 numbers) as the
// solver's do; what is left is the launch or the graph's relaunch, the block
// reductions, the count of finished segments and the group's tail. CUDA
// builds only. Usage: bench_device_loop [--passes N] (default 200).
#include <array>
#include <cstdio>
#include <stdexcept>
#include <string>

#include <fmt/core.h>

#include "emfusion/core/grouped_loop.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/core/stage_clock.hpp"
#include "emfusion/solve/normal_equations.hpp"
#include "support/args.hpp"

using namespace emfusion;

namespace {

/// An index's contribution: one number, so that the pass has data to sum.
struct OneTerm {
  EMF_HD void operator()(int i, NormalEquations6& acc) const { acc.cost += double(i & 7); }
};
/// Every group asks for another pass (the loop stops at its maximum).
struct Again {
  EMF_HD bool operator()(int, const NormalEquations6&) const { return true; }
};
/// A pass launched from the host: nothing to decide.
struct Nothing {
  EMF_HD void operator()(int, const NormalEquations6&) const {}
};

/// Milliseconds of `run` on the backend's stream (the device's time between
/// two events: StageClock), the best of `repeats`.
template <class Run>
float best_ms(const Cuda& backend, int repeats, Run&& run) {
  StageClock<Cuda> clock;
  double best = 1e30;
  for (int r = 0; r < repeats; ++r) {
    double ms = 0;
    clock.start(backend);
    run();
    clock.lap(ms);
    clock.finish();
    best = ms < best ? ms : best;
  }
  return float(best);
}

}  // namespace

int main(int argc, char** argv) {
  try {
    int passes = 200;
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      if (a != "--passes")
        throw std::invalid_argument("usage: bench_device_loop [--passes N]; unknown argument '" + a + "'");
      if (i + 1 >= argc) throw std::invalid_argument("--passes needs a value");
      passes = examples::parse_positive_int(a, argv[++i]);
    }
    const Cuda backend{};
    const std::array<int, 4> per_body{1, 2, 4, 8};
    fmt::print("{} passes of 256-thread blocks, each segment 512 indices; microseconds a pass (best of 10)\n", passes);
    fmt::print("{:>6} {:>8} {:>9}  {:>9} {:>9} {:>9} {:>9}  {:>13}  {:>11}\n", "groups", "segments", "of each",
               "graph x1", "graph x2", "graph x4", "graph x8", "host launches", "queued, idle");
    for (const int groups : {1, 3}) {
      for (const int per_group : {1, 16, 64, 128}) {
        Cuda::Vector<int> storage;
        const SegmentGroups layout = equal_groups(backend, groups, per_group * 512, per_group, storage);
        Cuda::Vector<NormalEquations6> partials(std::size_t(layout.segments));
        NormalEquations6* p = thrust::raw_pointer_cast(partials.data());
        std::array<float, 4> in_graph{};
        for (std::size_t k = 0; k < per_body.size(); ++k) {
          GroupedLoop loop(per_body[k]);
          in_graph[k] = best_ms(backend, 10, [&] {
            grouped_accumulate_while(backend, loop, layout, OneTerm{}, NormalEquations6::zero(), p, Again{}, passes);
          });
        }
        // A loop of one pass with 8 a round against 1 a round: 7 passes
        // queued after the end.
        float one_pass[2]{};
        for (const int k : {0, 1}) {
          GroupedLoop loop(k == 0 ? 1 : 8);
          one_pass[k] = best_ms(backend, 10, [&] {
            grouped_accumulate_while(backend, loop, layout, OneTerm{}, NormalEquations6::zero(), p, Again{}, 1);
          });
        }
        const float launched = best_ms(backend, 10, [&] {
          for (int k = 0; k < passes; ++k)
            grouped_accumulate(backend, layout, OneTerm{}, NormalEquations6::zero(), p, Nothing{});
        });
        fmt::print("{:>6} {:>8} {:>9}  {:>9.2f} {:>9.2f} {:>9.2f} {:>9.2f}  {:>13.2f}  {:>11.2f}\n", groups,
                   layout.segments, per_group, 1000.0 * in_graph[0] / passes, 1000.0 * in_graph[1] / passes,
                   1000.0 * in_graph[2] / passes, 1000.0 * in_graph[3] / passes, 1000.0 * launched / passes,
                   1000.0 * (one_pass[1] - one_pass[0]) / 7);
      }
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_device_loop: %s\n", e.what());
    return 1;
  }
}
