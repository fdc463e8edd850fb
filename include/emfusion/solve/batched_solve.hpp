// Many pose problems solved at once: Levenberg-Marquardt for every problem
// of a batch in lock step (the system's objects, issue 22). An iteration is
// one pass over the terms of all problems still running that reduces their
// normal equations per problem and takes each problem's solver step
// (LevenbergMarquardtIteration, solve/solvers.hpp: the algorithm of
// levenberg_marquardt, written once) on the backend (grouped_accumulate,
// core/parallel.hpp). On a GPU that pass is one kernel, and the passes
// until every problem has stopped are one launch of a graph that decides
// on the device whether to go on (grouped_accumulate_while,
// core/grouped_loop.hpp); solved one by one, each iteration of each problem
// waited for a reduction's copy to the host and a 6x6 solve there. On the
// CPU the same code runs one problem after another (each a batch of one),
// which keeps a problem's data in the cache.
//
// Each problem keeps the per-term values of its current pose (as a
// LinearizationCache does), so a candidate is compared with the current
// pose without evaluating the terms there again. Summed in another order
// than a single solve's reduction, a problem's normal equations differ in
// their last digits, and so may the pose it stops at.
//
// The problems of one batch share their terms' and norm's types and the
// solver's parameters: the system's objects (dense volumes) are one batch,
// the camera (the background) another.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstring>
#include <type_traits>
#include <vector>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/grouped_loop.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/solve/normal_equations.hpp"
#include "emfusion/solve/solvers.hpp"

namespace emfusion {

/// One problem of a batch: its terms (a PoseTerms) and its robust norm.
template <class P, class N>
struct BatchedProblem {
  P terms;
  N norm;
};

/// What a batch's term pass computes for one problem: the linearisation at
/// T, with the shared costs at `reference` when has_reference is set; its
/// terms' values at T are stored in slot `write_slot` of the problem's two
/// (-1: not stored) and those at the reference read from `read_slot` (-1:
/// evaluated).
template <class S>
struct LinearizationRequest {
  SE3<S> T, reference;
  int active = 0;
  int has_reference = 0;
  int write_slot = -1, read_slot = -1;
};

namespace detail {

/// The request of a running solve: its next target, storing its values in
/// the slot that does not hold the current pose's. The current pose's
/// values are in slot (accepted steps mod 2): the start's were written to
/// slot 0, and every accepted candidate's were written to the other slot.
template <class S>
EMF_HD LinearizationRequest<S> request_of(const LevenbergMarquardtIteration<S>& it) {
  LinearizationRequest<S> q;
  q.active = it.done ? 0 : 1;
  q.T = it.target();
  const int current = it.report.accepted_steps & 1;
  if (it.started) {
    q.reference = it.pose.T_s;
    q.has_reference = 1;
    q.read_slot = current;
    q.write_slot = current ^ 1;
  } else {
    q.reference = q.T;
    q.write_slot = current;
  }
  return q;
}

/// Term i of the whole batch (problems laid end to end by first_term) into
/// acc, as its problem's request says.
template <class S, class P, class N>
struct BatchedTerm {
  const BatchedProblem<P, N>* problems;
  const LinearizationRequest<S>* requests;
  const int* first_term;  ///< problem p's terms are [first_term[p], first_term[p + 1])
  int problem_count;
  TermValue<S>* values;   ///< slot k of every problem at values + k * total_terms; null: none
  int total_terms;

  EMF_HD int problem_of(int g) const {  // the last p with first_term[p] <= g
    int lo = 0, hi = problem_count - 1;
    while (lo < hi) {
      const int mid = (lo + hi + 1) / 2;
      if (first_term[mid] <= g) lo = mid;
      else hi = mid - 1;
    }
    return lo;
  }
  /// Slot k of the problem whose terms start at `base`; null without one.
  EMF_HD TermValue<S>* slot(int k, int base) const {
    return values && k >= 0 ? values + k * total_terms + base : nullptr;
  }
  EMF_HD void operator()(int g, NormalEquations6& acc) const {
    const int p = problem_of(g);
    const LinearizationRequest<S>& q = requests[p];
    if (!q.active) return;
    const int base = first_term[p];
    add_term(problems[p].terms, problems[p].norm, q.T, q.has_reference ? &q.reference : nullptr,
             slot(q.write_slot, base), slot(q.read_slot, base), g - base, acc);
  }
  /// Terms [begin, end) of one problem (a segment on the CPU): the problem
  /// and its request looked up once, the loop that of a single
  /// linearisation.
  void accumulate_range(int begin, int end, NormalEquations6& acc) const {
    if (begin >= end) return;
    const int p = problem_of(begin);
    const LinearizationRequest<S>& q = requests[p];
    if (!q.active) return;
    const int base = first_term[p];
    LinearizeTerm<S, P, N> f{problems[p].terms, problems[p].norm, q.T, q.reference, q.has_reference != 0};
    f.store = slot(q.write_slot, base), f.stored_reference = slot(q.read_slot, base);
    for (int g = begin; g < end; ++g) f(g - base, acc);
  }
};

/// After a term pass of a solve: the solver step of problem p, if it had
/// asked for the pass, and its next request; whether it asks for another.
template <class S>
struct AdvanceSolve {
  LevenbergMarquardtIteration<S>* solves;
  LinearizationRequest<S>* requests;
  LevenbergMarquardtParams params;

  EMF_HD bool operator()(int p, const NormalEquations6& sum) const {
    if (!requests[p].active) return false;
    solves[p].advance(params, sum);
    requests[p] = request_of(solves[p]);
    return requests[p].active != 0;
  }
};

}  // namespace detail

/// The buffers of a batch's solves, kept between calls (any terms and norm
/// of scalar S on backend B; one per batch that may run at a time).
template <class S, Backend B>
struct BatchedSolveWorkspace {
  int segment_count = 0, total_terms = 0;  ///< of the batch laid out last
  /// The batch's problems (of its own type), term and segment offsets,
  /// requests and solver states, packed as words so that they go to the
  /// backend in one copy; where each part starts (in words).
  typename B::template Vector<double> packed;
  std::size_t at_problems = 0, at_first_term = 0, at_requests = 0, at_solves = 0;
  SegmentGroups groups;  ///< the segments of each problem (pointers into packed)
  // These only grow (resizing a device vector waits for the device).
  typename B::template Vector<NormalEquations6> partials, sums;
  typename B::template Vector<TermValue<S>> values;
  GroupedLoop loop;  ///< on a device, the graph of solve_batch's iterations

  /// Part `at` of `packed`, as values of type T.
  template <class T>
  T* part(std::size_t at) {
    return reinterpret_cast<T*>(raw_data(packed) + at);
  }
};

namespace detail {

/// Host values packed as words, each part starting at a word.
struct PackedWords {
  std::vector<double> words;
  template <class T>
  std::size_t add(const T* values, std::size_t n) {
    static_assert(std::is_trivially_copyable_v<T> && alignof(T) <= alignof(double),
                  "a batch's parts are copied as bytes into words");
    const std::size_t at = words.size();
    words.resize(at + (n * sizeof(T) + sizeof(double) - 1) / sizeof(double));
    if (n) std::memcpy(static_cast<void*>(words.data() + at), static_cast<const void*>(values), n * sizeof(T));
    return at;
  }
  template <class T>
  std::size_t add(const std::vector<T>& values) {
    return add(values.data(), values.size());
  }
};

/// How many terms a segment of a problem with n terms takes: on a device at
/// least 512 (two for each thread of a block), on the CPU at least 32; at
/// most 128 segments a problem (on the CPU as accumulate_index's chunks:
/// fewer, larger ones left a thread waiting on the camera's coarse levels).
template <Backend B>
int segment_terms(int n) {
  const int least = B::is_device ? 512 : 32, most_segments = 128;
  return std::max(least, (n + most_segments - 1) / most_segments);
}

/// Lays out `problems` with their `requests` (and, for a solve, `solves`)
/// and copies them to the backend in one go: the problems' terms end to
/// end, cut into segments (ws.total_terms, ws.segment_count).
template <class S, Backend B, class P, class N>
void lay_out(const B& backend, const std::vector<BatchedProblem<P, N>>& problems,
             const std::vector<LinearizationRequest<S>>& requests,
             const std::vector<LevenbergMarquardtIteration<S>>& solves, BatchedSolveWorkspace<S, B>& ws) {
  std::vector<int> first_term{0}, first_segment{0}, offsets{0}, group_of;
  for (const auto& problem : problems) {
    const int n = problem.terms.term_count();
    const int step = segment_terms<B>(n);
    int begin = 0;
    do {  // at least one segment, so that a problem without terms is finished too
      offsets.push_back(first_term.back() + std::min(n, begin + step));
      group_of.push_back(int(first_term.size()) - 1);
      begin += step;
    } while (begin < n);
    first_term.push_back(first_term.back() + n);
    first_segment.push_back(int(offsets.size()) - 1);
  }
  PackedWords packed;
  ws.at_problems = packed.add(problems);
  ws.at_first_term = packed.add(first_term);
  const std::size_t at_first_segment = packed.add(first_segment), at_offsets = packed.add(offsets),
                    at_group_of = packed.add(group_of);
  const std::size_t at_counters = packed.add(std::vector<unsigned>(problems.size(), 0u));
  ws.at_requests = packed.add(requests);
  ws.at_solves = packed.add(solves);
  if (ws.packed.size() < packed.words.size()) ws.packed.resize(packed.words.size());
  copy_to_backend(backend, packed.words.data(), packed.words.size(), raw_data(ws.packed));
  ws.segment_count = int(offsets.size()) - 1;
  ws.total_terms = first_term.back();
  ws.groups = SegmentGroups{ws.segment_count,
                            int(problems.size()),
                            ws.template part<int>(at_offsets),
                            ws.template part<int>(at_first_segment),
                            ws.template part<int>(at_group_of),
                            ws.template part<unsigned>(at_counters)};
  if (ws.partials.size() < std::size_t(ws.segment_count)) ws.partials.resize(std::size_t(ws.segment_count));
  if (ws.sums.size() < problems.size()) ws.sums.resize(problems.size());
}

/// The term functor of the batch laid out in `ws`, for its current
/// requests; keep_values: each problem's term values are stored and read
/// (ws.values holds two slots).
template <class S, Backend B, class P, class N>
BatchedTerm<S, P, N> batch_terms(bool keep_values, BatchedSolveWorkspace<S, B>& ws) {
  return {ws.template part<BatchedProblem<P, N>>(ws.at_problems),
          ws.template part<LinearizationRequest<S>>(ws.at_requests),
          ws.template part<int>(ws.at_first_term),
          ws.groups.groups,
          keep_values ? raw_data(ws.values) : nullptr,
          ws.total_terms};
}

/// The first n values at `from` on the backend, on the host.
template <class T, Backend B>
std::vector<T> download(const B& backend, const T* from, std::size_t n) {
  std::vector<T> host(n);
  copy_to_host(backend, from, n, host.data());
  return host;
}

}  // namespace detail

/// The normal equations of every problem at its request's pose (with the
/// shared costs at its reference where it has one), in one pass over all
/// their terms. Requests need only T, reference, active and has_reference.
template <class S, Backend B, class P, class N>
  requires PoseTerms<P, S> && RobustNorm<N, S>
std::vector<NormalEquations6> linearize_batch(const B& backend, const std::vector<BatchedProblem<P, N>>& problems,
                                              std::vector<LinearizationRequest<S>> requests,
                                              BatchedSolveWorkspace<S, B>& ws) {
  detail::require(requests.size() == problems.size(), "linearize_batch", "need one request per problem");
  if (problems.empty()) return {};
  for (auto& q : requests) q.write_slot = q.read_slot = -1;
  detail::lay_out(backend, problems, requests, {}, ws);
  grouped_accumulate(backend, ws.groups, detail::batch_terms<S, B, P, N>(false, ws), NormalEquations6::zero(),
                     raw_data(ws.partials), detail::StoreGroupResult<NormalEquations6>{raw_data(ws.sums)});
  return detail::download(backend, raw_data(ws.sums), problems.size());
}

/// Levenberg-Marquardt with parameters `params` for every problem from its
/// start, all at once; returns the poses and fills `reports` (one each, as
/// levenberg_marquardt would). At most params.max_iterations + 1 term passes.
template <class S, Backend B, class P, class N>
  requires PoseTerms<P, S> && RobustNorm<N, S>
std::vector<SE3<S>> solve_batch(const B& backend, const std::vector<BatchedProblem<P, N>>& problems,
                                const std::vector<SE3<S>>& starts, const LevenbergMarquardtParams& params,
                                std::vector<SolveReport>& reports, BatchedSolveWorkspace<S, B>& ws) {
  detail::require(starts.size() == problems.size(), "solve_batch", "need one start per problem");
  const std::size_t n = problems.size();
  reports.assign(n, SolveReport{});
  if (n == 0) return {};
  if constexpr (!B::is_device) {
    // On the CPU one problem after another, each a batch of one: a problem's
    // volume stays in the cache over its iterations. In lock step the
    // objects' terms took a fifth longer (2 cores, redkitchen_dyn_300:
    // track_objects 44 -> 52 ms a frame), and waiting for the host costs
    // nothing here.
    if (n > 1) {
      std::vector<SE3<S>> solved;
      for (std::size_t p = 0; p < n; ++p) {
        std::vector<SolveReport> one;
        solved.push_back(solve_batch(backend, std::vector{problems[p]}, std::vector{starts[p]}, params, one, ws)[0]);
        reports[p] = one[0];
      }
      return solved;
    }
  }
  std::vector<LevenbergMarquardtIteration<S>> solves(n);
  std::vector<LinearizationRequest<S>> requests(n);
  for (std::size_t p = 0; p < n; ++p) {
    solves[p] = LevenbergMarquardtIteration<S>::at(starts[p]);
    requests[p] = detail::request_of(solves[p]);
  }
  detail::lay_out(backend, problems, requests, solves, ws);
  if (ws.values.size() < 2 * std::size_t(ws.total_terms)) ws.values.resize(2 * std::size_t(ws.total_terms));
  LevenbergMarquardtIteration<S>* on_backend = ws.template part<LevenbergMarquardtIteration<S>>(ws.at_solves);
  LinearizationRequest<S>* requested = ws.template part<LinearizationRequest<S>>(ws.at_requests);
  // Every pass advances every running solve once; the loop ends when none
  // runs (on a device the device decides, without the host looking).
  grouped_accumulate_while(backend, ws.loop, ws.groups, detail::batch_terms<S, B, P, N>(true, ws),
                           NormalEquations6::zero(), raw_data(ws.partials),
                           detail::AdvanceSolve<S>{on_backend, requested, params}, params.max_iterations + 1);
  solves = detail::download(backend, on_backend, n);
  std::vector<SE3<S>> solved(n);
  for (std::size_t p = 0; p < n; ++p) solved[p] = solves[p].pose.T_s, reports[p] = solves[p].report;
  return solved;
}

}  // namespace emfusion
