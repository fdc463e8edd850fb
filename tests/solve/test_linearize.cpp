// The accumulation behind every linearisation: accumulate_index (in-place
// per-index contributions, chunked on the CPU) and LinearizationCache (the
// reference pose's term values reused), which must change nothing but speed.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <random>
#include <type_traits>
#include <vector>

#include "emfusion/core/grouped_loop.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/solve/normal_equations.hpp"
#include "emfusion/solve/solvers.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"

using namespace emfusion;

namespace {

struct SumCount {
  double sum = 0, count = 0;
  EMF_HD SumCount& operator+=(const SumCount& o) {
    sum += o.sum, count += o.count;
    return *this;
  }
  static constexpr int components = 2;  // a ComponentSum, for grouped_accumulate
  EMF_HD double& component(int c) { return c == 0 ? sum : count; }
  EMF_HD double component(int c) const { return c == 0 ? sum : count; }
};

/// grouped_accumulate's last step: group g's sum into out[g], and a mark
/// that g was finished (once).
struct StoreGroup {
  SumCount* out;
  int* calls;
  EMF_HD void operator()(int g, const SumCount& sum) const {
    out[g] = sum;
    calls[g] += 1;
  }
};

/// Adds i for every index divisible by 3.
struct AddMultiplesOfThree {
  EMF_HD void operator()(int i, SumCount& acc) const {
    if (i % 3 != 0) return;
    acc.sum += double(i);
    acc.count += 1;
  }
};

/// Point-to-point terms, three per point, with weights that vary per point;
/// a point whose transformed z falls below `min_z` does not take part, so the
/// valid set changes with the pose.
template <class S>
struct ClippedPointToPoint {
  ImageView<const Vec3<S>> source, target;
  S min_z;
  EMF_HD int term_count() const { return 3 * source.size(); }
  EMF_HD bool term(int i, const SE3<S>& T, S& r, Vec6<S>& J, S& w) const {
    const int k = i / 3, axis = i % 3;
    const Vec3<S> x = T * source[k];
    if (x.z() < min_z) return false;
    r = x[axis] - target[k][axis];
    const auto Jx = SE3<S>::left_jacobian_of_action(x);
    for (int j = 0; j < 6; ++j) J[j] = Jx(axis, j);
    w = S(0.5) + S(k % 5) / S(4);
    return true;
  }
};

template <class S, class B>
struct Points {
  Image<Vec3<S>, B> source, target;
  SE3<S> truth = SE3<S>::exp(Vec6<S>{{S(0.05), S(-0.04), S(0.03), S(0.06), S(-0.05), S(0.04)}});
  explicit Points(int n) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(-1, 1);
    std::vector<Vec3<S>> s, t;
    for (int i = 0; i < n; ++i) {
      s.push_back(vec3(S(u(rng)), S(u(rng)), S(2 + u(rng))));
      t.push_back(truth * s.back() + vec3(S(0.01 * u(rng)), S(0.01 * u(rng)), S(0.01 * u(rng))));
    }
    source = Image<Vec3<S>, Host>::from_host(n, 1, s).template to<B>();
    target = Image<Vec3<S>, Host>::from_host(n, 1, t).template to<B>();
  }
  ClippedPointToPoint<S> problem() const { return {source.view(), target.view(), S(1.2)}; }
};

bool same_bits(const NormalEquations6& a, const NormalEquations6& b) {
  return std::memcmp(&a, &b, sizeof(NormalEquations6)) == 0;
}

}  // namespace

TEMPLATE_LIST_TEST_CASE("accumulate_index adds in-place contributions of every index once", "[solve]",
                        emfusion::test::AllConfigs) {
  using B = typename TestType::Backend;
  const B backend{};
  for (const int n : {0, 1, 2, 5, 127, 128, 129, 100003}) {
    const SumCount s = accumulate_index(backend, n, AddMultiplesOfThree{}, SumCount{});
    double sum = 0, count = 0;
    for (int i = 0; i < n; i += 3) sum += double(i), count += 1;
    INFO("n = " << n);
    CHECK(s.sum == sum);
    CHECK(s.count == count);
  }
}

TEMPLATE_LIST_TEST_CASE("grouped_accumulate sums every group of segments once and finishes each group once", "[solve]",
                        emfusion::test::AllConfigs) {
  using B = typename TestType::Backend;
  const B backend{};
  // Four groups: 3 segments, 1 empty segment, 200 segments, 1 segment; the
  // indices end to end. Run twice: the device's counters must be back at 0.
  std::vector<int> offsets{0}, first_segment{0}, group_of;
  const std::vector<std::vector<int>> sizes = {{700, 1, 5000}, {0}, std::vector<int>(200, 97), {3}};
  for (std::size_t g = 0; g < sizes.size(); ++g) {
    for (const int n : sizes[g]) offsets.push_back(offsets.back() + n), group_of.push_back(int(g));
    first_segment.push_back(int(offsets.size()) - 1);
  }
  const auto on_backend = [](const auto& v) {
    typename B::template Vector<typename std::decay_t<decltype(v)>::value_type> d(v.begin(), v.end());
    return d;
  };
  auto d_offsets = on_backend(offsets), d_first = on_backend(first_segment), d_group = on_backend(group_of);
  typename B::template Vector<unsigned> counters(sizes.size(), 0u);
  typename B::template Vector<SumCount> partials(group_of.size()), out(sizes.size());
  typename B::template Vector<int> calls(sizes.size(), 0);
  const auto raw = [](auto& v) { return thrust::raw_pointer_cast(v.data()); };
  const SegmentGroups layout{int(group_of.size()), int(sizes.size()), raw(d_offsets),
                             raw(d_first),         raw(d_group),      raw(counters)};
  for (int run = 1; run <= 2; ++run) {
    grouped_accumulate(backend, layout, AddMultiplesOfThree{}, SumCount{}, raw(partials),
                       StoreGroup{raw(out), raw(calls)});
    backend.synchronize();
    const std::vector<SumCount> sums(out.begin(), out.end());
    const std::vector<int> finished(calls.begin(), calls.end());
    for (std::size_t g = 0; g < sizes.size(); ++g) {
      double sum = 0, count = 0;
      for (int i = offsets[std::size_t(first_segment[g])]; i < offsets[std::size_t(first_segment[g + 1])]; ++i)
        if (i % 3 == 0) sum += double(i), count += 1;
      INFO("run " << run << ", group " << g);
      CHECK(sums[g].component(0) == sum);  // through the const accessor a device sum reads
      CHECK(sums[g].component(1) == count);
      CHECK(finished[g] == run);
    }
    CHECK(std::vector<unsigned>(counters.begin(), counters.end()) == std::vector<unsigned>(sizes.size(), 0u));
  }
}

namespace {
/// grouped_accumulate_while's last step: StoreGroup's, and another pass
/// until group g has been finished stop_after + 2 g times.
struct StoreGroupUntil {
  StoreGroup store;
  int stop_after;
  EMF_HD bool operator()(int g, const SumCount& sum) const {
    store(g, sum);
    return store.calls[g] < stop_after + 2 * g;
  }
};
}  // namespace

TEMPLATE_LIST_TEST_CASE("grouped_accumulate_while repeats passes while a group asks, up to its limit", "[solve]",
                        emfusion::test::AllConfigs) {
  using B = typename TestType::Backend;
  const B backend{};
  // Two groups (2 and 40 segments of 300 indices), then one (3 segments):
  // the second layout has fewer segments and runs through the same graph.
  // One pass a round of the device's while node, and three (loops that end
  // inside a round: the passes queued after the end do nothing).
  const auto raw = [](auto& v) { return thrust::raw_pointer_cast(v.data()); };
  for (const int per_body : {1, 3}) {
    GroupedLoop loop(per_body);
    CHECK(loop.passes_per_body() == per_body);
    for (const std::vector<int>& segments_of : {std::vector<int>{2, 40}, std::vector<int>{3}}) {
      std::vector<int> offsets{0}, first_segment{0}, group_of;
      for (std::size_t g = 0; g < segments_of.size(); ++g) {
        for (int k = 0; k < segments_of[g]; ++k) offsets.push_back(offsets.back() + 300), group_of.push_back(int(g));
        first_segment.push_back(int(offsets.size()) - 1);
      }
      const std::size_t groups = segments_of.size();
      typename B::template Vector<int> d_offsets(offsets.begin(), offsets.end()),
          d_first(first_segment.begin(), first_segment.end()), d_group(group_of.begin(), group_of.end());
      typename B::template Vector<unsigned> counters(groups, 0u);
      typename B::template Vector<SumCount> partials(group_of.size()), out(groups);
      const SegmentGroups layout{int(group_of.size()), int(groups),  raw(d_offsets),
                                 raw(d_first),         raw(d_group), raw(counters)};
      // Stopped by the last group's answer, by the limit, and a first answer
      // of stop still runs one pass.
      for (const auto [stop_after, max_passes] : {std::array{5, 100}, std::array{1000, 7}, std::array{0, 10}}) {
        const int last_group = int(groups) - 1;
        const int expected = std::min(max_passes, std::max(1, stop_after + 2 * last_group));
        typename B::template Vector<int> calls(groups, 0);
        grouped_accumulate_while(backend, loop, layout, AddMultiplesOfThree{}, SumCount{}, raw(partials),
                                 StoreGroupUntil{{raw(out), raw(calls)}, stop_after}, max_passes);
        const std::vector<int> finished(calls.begin(), calls.end());  // waits for the backend
        INFO(groups << " groups: stop after " << stop_after << ", at most " << max_passes << ", " << per_body
                    << " passes a round");
        CHECK(finished == std::vector<int>(groups, expected));
        const std::vector<SumCount> sums(out.begin(), out.end());
        double count = 0;
        for (int i = 0; i < offsets[std::size_t(first_segment[1])]; ++i) count += i % 3 == 0 ? 1 : 0;
        CHECK(sums[0].component(1) == count);
        CHECK(std::vector<unsigned>(counters.begin(), counters.end()) == std::vector<unsigned>(groups, 0u));
      }
    }
    CHECK(loop.builds() == (B::is_device ? 1 : 0));
  }
}

TEMPLATE_LIST_TEST_CASE("Linearising with a cache gives bit-identical normal equations", "[solve]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const B backend{};
  const Points<S, B> points(3000);
  const auto problem = points.problem();
  const HuberNorm<S> norm{S(0.005)};
  const SE3<S> A = SE3<S>::exp(Vec6<S>{{S(0.01), S(0.02), S(-0.3), S(0.02), S(0.01), S(0.0)}});
  const SE3<S> Bp = SE3<S>::exp(Vec6<S>{{S(0.03), S(0.0), S(-0.25), S(0.03), S(0.02), S(0.01)}});
  const SE3<S> C = SE3<S>::exp(Vec6<S>{{S(0.04), S(-0.01), S(-0.2), S(0.04), S(0.0), S(0.02)}});

  LinearizationCache<S, B> cache;
  CHECK(cache.find(A) == -1);
  // No reference: plain linearisation, values of A remembered.
  CHECK(same_bits(linearize(backend, problem, norm, A, nullptr, cache), linearize(backend, problem, norm, A)));
  CHECK(cache.find(A) >= 0);
  // Reference A from the cache, and B remembered beside it.
  const NormalEquations6 b_cached = linearize(backend, problem, norm, Bp, &A, cache);
  const NormalEquations6 b_plain = linearize(backend, problem, norm, Bp, &A);
  CHECK(b_plain.shared_cost > 0);
  CHECK(b_plain.shared_reference_cost != b_plain.shared_cost);
  CHECK(same_bits(b_cached, b_plain));
  CHECK(cache.find(A) >= 0);
  CHECK(cache.find(Bp) >= 0);
  // Reference B (cached) and then a reference the cache does not hold.
  CHECK(same_bits(linearize(backend, problem, norm, C, &Bp, cache), linearize(backend, problem, norm, C, &Bp)));
  const SE3<S> unseen = SE3<S>::exp(Vec6<S>{{S(0.02), S(0.0), S(-0.1), S(0.0), S(0.0), S(0.0)}});
  CHECK(cache.find(unseen) == -1);
  CHECK(same_bits(linearize(backend, problem, norm, A, &unseen, cache), linearize(backend, problem, norm, A, &unseen)));
  cache.reset();
  CHECK(cache.find(A) == -1);

  // A whole Levenberg-Marquardt solve takes the same steps either way.
  const auto plain = [&](const SE3<S>& T, const SE3<S>* ref) { return linearize(backend, problem, norm, T, ref); };
  const auto cached = [&](const SE3<S>& T, const SE3<S>* ref) {
    return linearize(backend, problem, norm, T, ref, cache);
  };
  SolveReport r_plain, r_cached;
  const SE3<S> p = levenberg_marquardt(plain, SE3<S>::identity(), {}, &r_plain);
  const SE3<S> q = levenberg_marquardt(cached, SE3<S>::identity(), {}, &r_cached);
  CHECK(r_plain.iterations > 2);
  CHECK(r_plain.iterations == r_cached.iterations);
  CHECK(r_plain.accepted_steps == r_cached.accepted_steps);
  CHECK(max_abs_diff(p.matrix(), q.matrix()) == S(0));
  CHECK(max_abs_diff(p.matrix(), points.truth.matrix()) < S(0.01));
}
