// Normal equations of a 6-DoF least-squares problem as a POD accumulator,
// their backend-generic reduction over per-term residuals (with IRLS weights
// from a robust norm), and a small dense solver for the 6x6 system.
//
// Accumulation is in double whatever the problem's scalar: a frame has ~3e5
// terms, and float sums of that many squares lose the digits the solver needs.
#pragma once

#include <algorithm>
#include <cmath>
#include <concepts>
#include <cstdint>
#include <type_traits>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/host_device.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/robust/norms.hpp"

namespace emfusion {

/// H = sum w J^T J (upper triangle, row by row), g = sum w J^T r, the robust
/// cost sum c rho(r) and the number of terms that contributed. When the
/// linearisation was given a reference pose, `shared_cost` and
/// `shared_reference_cost` hold the cost at the pose and at the reference over
/// the terms valid at both, each term weighted with its fixed weight at the
/// reference: solvers compare those, since terms entering or leaving the valid
/// set (points crossing the map's border) and weights that change with the
/// pose would otherwise make costs at two poses incomparable.
struct NormalEquations6 {
  double H[21];
  double g[6];
  double cost;
  double terms;
  double shared_cost;
  double shared_reference_cost;

  EMF_HD static NormalEquations6 zero() {
    NormalEquations6 n{};
    for (double& h : n.H) h = 0;
    for (double& v : n.g) v = 0;
    n.cost = 0, n.terms = 0, n.shared_cost = 0, n.shared_reference_cost = 0;
    return n;
  }
  /// Adds one term: residual r with Jacobian J (d r / d xi), IRLS weight w
  /// and cost contribution.
  template <class S>
  EMF_HD void add(const Vec6<S>& J, S r, S w, S cost_term) {
    int k = 0;
    for (int i = 0; i < 6; ++i) {
      const double wj = double(w) * double(J[i]);
      for (int j = i; j < 6; ++j) H[k++] += wj * double(J[j]);
      g[i] += wj * double(r);
    }
    cost += double(cost_term);
    terms += 1;
  }
  EMF_HD NormalEquations6& operator+=(const NormalEquations6& o) {
    for (int i = 0; i < 21; ++i) H[i] += o.H[i];
    for (int i = 0; i < 6; ++i) g[i] += o.g[i];
    cost += o.cost, terms += o.terms;
    shared_cost += o.shared_cost, shared_reference_cost += o.shared_reference_cost;
    return *this;
  }
  /// The full symmetric 6x6 H.
  EMF_HD Mat6<double> hessian() const {
    Mat6<double> M{};
    int k = 0;
    for (int i = 0; i < 6; ++i)
      for (int j = i; j < 6; ++j) M(i, j) = M(j, i) = H[k++];
    return M;
  }
  EMF_HD Vec6<double> gradient() const { return Vec6<double>{{g[0], g[1], g[2], g[3], g[4], g[5]}}; }

  /// The 31 numbers one after the other (H, g, cost, terms, shared_cost,
  /// shared_reference_cost): a reduction may sum them one by one.
  static constexpr int components = 31;
  EMF_HD double& component(int c) {
    if (c < 21) return H[c];
    if (c < 27) return g[c - 21];
    if (c == 27) return cost;
    if (c == 28) return terms;
    return c == 29 ? shared_cost : shared_reference_cost;
  }
  EMF_HD double component(int c) const { return const_cast<NormalEquations6&>(*this).component(c); }
};

/// `n` with H, g and every cost multiplied by `weight` (the term counts
/// stay): the normal equations of `weight` times a problem's cost, to add to
/// another problem's when a pose is solved for the sum of two costs.
inline NormalEquations6 scaled(NormalEquations6 n, double weight) {
  for (double& h : n.H) h *= weight;
  for (double& v : n.g) v *= weight;
  n.cost *= weight, n.shared_cost *= weight, n.shared_reference_cost *= weight;
  return n;
}

/// A least-squares problem over a pose, one term per index: `term` gives the
/// residual, its Jacobian with respect to a left perturbation exp(xi) * T and
/// a fixed weight (>= 0), or false if the term does not take part at T.
/// It is copied into kernels, so it holds views, not containers.
template <class P, class S>
concept PoseTerms = std::copy_constructible<P> && requires(const P& p, int i, const SE3<S>& T, S& r, Vec6<S>& J,
                                                            S& w) {
  { p.term_count() } -> std::convertible_to<int>;
  { p.term(i, T, r, J, w) } -> std::convertible_to<bool>;
};

/// A term's residual and fixed weight at one pose; w < 0: it did not take part.
template <class S>
struct TermValue {
  S r, w;
};

/// Each term's residual and weight from the last two linearisations, with
/// their poses. A linearisation whose reference pose is one of them reads the
/// reference's values instead of evaluating every term a second time:
/// Levenberg-Marquardt compares each candidate with the current pose, which
/// was linearised before, so this halves a solve's work. Keep one per solve
/// in flight and call reset() when the terms' data change (a new frame);
/// reusing it across solves avoids allocations.
template <class S, Backend B>
class LinearizationCache {
 public:
  void reset() { filled_[0] = filled_[1] = false; }

  /// The slot holding values at exactly pose T, or -1.
  int find(const SE3<S>& T) const {
    for (int k = 0; k < 2; ++k)
      if (filled_[k] && same(poses_[k], T)) return k;
    return -1;
  }
  /// Slot k sized for n terms, marked empty until filled(k, T).
  TermValue<S>* begin_write(int k, int n) {
    filled_[k] = false;
    if (int(values_[k].size()) != n) values_[k].resize(std::size_t(n));
    return raw_data(values_[k]);
  }
  void filled(int k, const SE3<S>& T) { poses_[k] = T, filled_[k] = true; }
  const TermValue<S>* values(int k) const { return raw_data(values_[k]); }

 private:
  static bool same(const SE3<S>& a, const SE3<S>& b) {
    for (int r = 0; r < 3; ++r) {
      if (a.translation()[r] != b.translation()[r]) return false;
      for (int c = 0; c < 3; ++c)
        if (a.rotation()(r, c) != b.rotation()(r, c)) return false;
    }
    return true;
  }
  typename B::template Vector<TermValue<S>> values_[2];
  SE3<S> poses_[2];
  bool filled_[2] = {false, false};
};

namespace detail {
/// Adds term i of `problem` at T into n (nothing when it does not take
/// part), with the shared costs at `reference` when one is given (its values
/// read from `stored_reference` when known); stores the term's value at T
/// in `store` when set. The body of every linearisation, batched or not.
template <class S, class P, class N>
EMF_HD void add_term(const P& problem, const N& norm, const SE3<S>& T, const SE3<S>* reference,
                     TermValue<S>* store, const TermValue<S>* stored_reference, int i, NormalEquations6& n) {
  S r, w;
  Vec6<S> J;
  const bool valid = problem.term(i, T, r, J, w) && w > S(0);
  if (store) store[i] = valid ? TermValue<S>{r, w} : TermValue<S>{S(0), S(-1)};
  if (!valid) return;
  const S c = w * norm.cost(r);
  n.add(J, r, w * norm.weight(r), c);
  if (!reference) return;
  S r0, w0;
  if (stored_reference) {
    r0 = stored_reference[i].r, w0 = stored_reference[i].w;
  } else if (!problem.term(i, *reference, r0, J, w0)) {
    return;
  }
  if (w0 > S(0)) {
    // Both with the weight at the reference: IRLS holds weights fixed
    // within a step, and weights that vary with the pose (the map
    // confidence) would otherwise make the cost change disagree with g.
    n.shared_cost += double(w0 * norm.cost(r));
    n.shared_reference_cost += double(w0 * norm.cost(r0));
  }
}

template <class S, class P, class N>
struct LinearizeTerm {
  P problem;
  N norm;
  SE3<S> T;
  SE3<S> reference;
  bool has_reference;
  TermValue<S>* store = nullptr;                   ///< each term's value at T, when set
  const TermValue<S>* stored_reference = nullptr;  ///< the values at the reference, when known

  EMF_HD void operator()(int i, NormalEquations6& n) const {
    add_term(problem, norm, T, has_reference ? &reference : nullptr, store, stored_reference, i, n);
  }
};
}  // namespace detail

/// One IRLS linearisation at T: the robust norm's weights come from the
/// residuals at T and multiply each term's fixed weight. With a reference
/// pose, the shared costs (see NormalEquations6) are filled too.
template <class S, Backend B, class P, class N>
  requires PoseTerms<P, S> && RobustNorm<N, S>
NormalEquations6 linearize(const B& backend, const P& problem, const N& norm, const SE3<S>& T,
                           const std::type_identity_t<SE3<S>>* reference = nullptr) {
  const detail::LinearizeTerm<S, P, N> f{problem, norm, T, reference ? *reference : T, reference != nullptr};
  return accumulate_index(backend, problem.term_count(), f, NormalEquations6::zero());
}

/// The same, remembering the terms' values at T in `cache` and reading the
/// reference's values from it when it holds them (bit-identical results).
template <class S, Backend B, class P, class N>
  requires PoseTerms<P, S> && RobustNorm<N, S>
NormalEquations6 linearize(const B& backend, const P& problem, const N& norm, const SE3<S>& T,
                           const std::type_identity_t<SE3<S>>* reference, LinearizationCache<S, B>& cache) {
  const int n = problem.term_count();
  const int read = reference ? cache.find(*reference) : -1;
  const int write = read == 0 ? 1 : 0;
  detail::LinearizeTerm<S, P, N> f{problem, norm, T, reference ? *reference : T, reference != nullptr};
  f.store = cache.begin_write(write, n);
  if (read >= 0) f.stored_reference = cache.values(read);
  const NormalEquations6 result = accumulate_index(backend, n, f, NormalEquations6::zero());
  cache.filled(write, T);
  return result;
}

/// Solves (H + lambda I) x = -g by Cholesky; false if the matrix is not
/// positive definite, judged relative to its largest diagonal entry. Each
/// diagonal is inverted once and multiplied with after: on a GPU, where
/// the batched solves take this step on one thread (batched_solve.hpp), a
/// double division costs about 120 cycles, and the 27 of the textbook
/// version doubled the solve's time.
EMF_HD inline bool solve_damped(const NormalEquations6& n, double lambda, Vec6<double>& x) {
  Mat6<double> A = n.hessian();
  double scale = 0;
  for (int i = 0; i < 6; ++i) A(i, i) += lambda, scale = std::fabs(A(i, i)) > scale ? std::fabs(A(i, i)) : scale;
  const double tiny = 1e-12 * scale;
  Mat6<double> L = Mat6<double>::zero();
  double inverse_diagonal[6];
  for (int j = 0; j < 6; ++j) {
    double d = A(j, j);
    for (int k = 0; k < j; ++k) d -= L(j, k) * L(j, k);
    if (!(d > tiny) || !(d > 0)) return false;
    L(j, j) = std::sqrt(d);
    inverse_diagonal[j] = 1.0 / L(j, j);
    for (int i = j + 1; i < 6; ++i) {
      double s = A(i, j);
      for (int k = 0; k < j; ++k) s -= L(i, k) * L(j, k);
      L(i, j) = s * inverse_diagonal[j];
    }
  }
  Vec6<double> y;
  for (int i = 0; i < 6; ++i) {
    double s = -n.g[i];
    for (int k = 0; k < i; ++k) s -= L(i, k) * y[k];
    y[i] = s * inverse_diagonal[i];
  }
  for (int i = 5; i >= 0; --i) {
    double s = y[i];
    for (int k = i + 1; k < 6; ++k) s -= L(k, i) * x[k];
    x[i] = s * inverse_diagonal[i];
  }
  return true;
}

}  // namespace emfusion
