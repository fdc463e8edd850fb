// StageClock (core/stage_clock.hpp): a frame's laps add the time of each
// stage to where they are told to, a stage with work takes time, the laps
// fit inside the frame's total, and the clock serves frame after frame with
// more laps than before, on every backend built.

#include "emfusion/core/parallel.hpp"
#include "emfusion/core/stage_clock.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"

using namespace emfusion;

namespace {
/// Work that takes a while on any backend: two passes over 1 M floats.
struct Churn {
  float* data;
  EMF_HD void operator()(int i) const {
    float v = data[i];
    for (int k = 0; k < 16; ++k) v = v * 0.999f + 1.0f;
    data[i] = v;
  }
};
}  // namespace

TEMPLATE_LIST_TEST_CASE("StageClock adds each stage's time where its lap says, within the frame's total", "[core]",
                        emfusion::test::AllBackends) {
  using B = TestType;
  const B backend{};
  typename B::template Vector<float> buffer(std::size_t(1) << 20, 0.0f);
  const auto churn = [&] {
    for (int pass = 0; pass < 2; ++pass)
      for_each_index(backend, int(buffer.size()), Churn{thrust::raw_pointer_cast(buffer.data())});
  };
  StageClock<B> clock;
  for (const int stages : {2, 5}) {  // the second frame has more laps than the first had
    double busy = 0.5, idle = 0, again = 0;
    clock.start(backend);
    churn();
    clock.lap(busy);
    for (int k = 2; k < stages; ++k) clock.lap(idle);  // nothing queued between these
    churn();
    clock.lap(again);
    const double total = clock.finish();
    INFO(stages << " laps: busy " << busy << " ms, idle " << idle << " ms, again " << again << " ms, total " << total
                << " ms");
    CHECK(busy > 0.5);  // added to what was there
    CHECK(again > 0);
    CHECK(idle >= 0);
    CHECK((busy - 0.5) + idle + again <= total + 1e-3);
  }
}
