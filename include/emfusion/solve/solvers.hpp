// Gauss-Newton and Levenberg-Marquardt on SE(3), as functions and as
// PoseSolver types (LevenbergMarquardt, GaussNewton) that the system and
// the alignment functions take as a template argument.
//
// A solver sees the problem only as a callable `linearize(T, reference)`
// returning the NormalEquations6 at pose T (residuals, IRLS weights and cost
// included; with a non-null reference pose also the costs over the terms
// valid at both poses), so the same solvers serve any problem, robust norm and
// backend. Updates are left-multiplied: T <- exp(xi) * T, accumulated in
// double whatever the problem's scalar (a float pose several metres from its
// volume's origin resolves only ~2e-7 m), and the problem is linearised at
// the pose rounded to its scalar. Each solve fills a SolveReport.
//
// Levenberg-Marquardt follows Madsen, Nielsen & Tingleff (2004): initial
// damping tau * max(diag H), gain ratio test, damping scaled by
// max(1/3, 1 - (2 rho - 1)^3) after a success and by nu (doubling) after a
// failure; it stops when |g|_inf <= eps1, when the step is below
// eps2 (|xi(T)| + eps2), when the undamped step is below converged_step
// or a step gains too little (converged_gain; both off in the reference),
// or after max_iterations linearisations. A solve
// that starts near its solution (the finer levels of a coarse-to-fine solve)
// may start less damped: refined(solver).
#pragma once

#include <algorithm>
#include <cmath>
#include <concepts>
#include <limits>
#include <string>
#include <utility>

#include "emfusion/core/error.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/solve/normal_equations.hpp"

namespace emfusion {

enum class StopReason {
  gradient_small,   ///< |g|_inf <= eps1: at a stationary point
  step_small,       ///< the step fell below eps2 or below the scalar's resolution: converged
  max_iterations,   ///< ran out of iterations
  too_few_terms,    ///< fewer than `min_terms` terms at the start: nothing to solve
  not_finite,       ///< the normal equations contained NaN or inf
  singular,         ///< the system could not be solved even with damping
  gain_small,       ///< a step gained, or was expected to gain, too little (converged_gain): converged
};

inline const char* to_string(StopReason r) {
  switch (r) {
    case StopReason::gradient_small: return "gradient_small";
    case StopReason::step_small: return "step_small";
    case StopReason::max_iterations: return "max_iterations";
    case StopReason::too_few_terms: return "too_few_terms";
    case StopReason::not_finite: return "not_finite";
    case StopReason::singular: return "singular";
    case StopReason::gain_small: return "gain_small";
  }
  return "unknown";
}

struct SolveReport {
  int iterations = 0;          ///< linearisations after the first
  int accepted_steps = 0;
  double initial_cost = 0;
  double final_cost = 0;
  double terms = 0;            ///< terms at the final pose
  StopReason reason = StopReason::max_iterations;

  /// True when the solver stopped at a solution (not for lack of data).
  bool converged() const {
    return reason == StopReason::gradient_small || reason == StopReason::step_small ||
           reason == StopReason::max_iterations || reason == StopReason::gain_small;
  }
};

/// Defaults are the reference implementation's (shared/PARAMETERS.md).
struct LevenbergMarquardtParams {
  int max_iterations = 100;
  double tau = 1e3;
  double eps1 = 1e-8;
  double eps2 = 1e-8;
  double nu = 2;
  double min_terms = 6;
  /// Floor of the damping, relative to the largest diagonal entry of H: keeps
  /// steps bounded along directions the data cannot observe (a single plane).
  double min_damping = 1e-6;
  /// Converged when the undamped (Gauss-Newton) step of the current
  /// linearisation is shorter than this (the norm of the se(3) increment,
  /// radians and metres, as eps2's): the pose is that close to the minimum
  /// of the local model. Unlike eps2 it does not wait for the damping to
  /// shrink the step, nor scale with the pose's distance from its frame's
  /// origin. 0 = off (the reference, which runs to eps2 or to the
  /// scalar's resolution).
  double converged_step = 0;
  /// Converged when an accepted step lowered the cost (over the terms valid
  /// before and after it) by at most this fraction of it, or when the next
  /// step's own model expects no more than that: the cost function's
  /// tolerance of other solvers. Unlike converged_step it ends the solve
  /// where the cost is flat along a direction the data hardly observe (a
  /// wall the camera may slide along), where the undamped step stays long
  /// and each step, taken or refused, changes nothing. 0 = off (the
  /// reference).
  double converged_gain = 0;
  /// tau for a start already near the solution: refined(LevenbergMarquardt)
  /// solves with it (coarse-to-fine's finer levels). 0 = tau.
  double refine_tau = 0;

  /// Throws std::invalid_argument (prefixed with `where`) unless every value
  /// is in its range: max_iterations >= 0, tau > 0, nu > 1, the tolerances,
  /// min_terms, min_damping, converged_step, converged_gain and refine_tau
  /// >= 0 (NaN fails).
  void validate(const char* where = "LevenbergMarquardtParams") const {
    detail::require(max_iterations >= 0, where, "lm max_iterations must not be negative");
    detail::require(tau > 0 && std::isfinite(tau), where, "lm tau must be positive and finite");
    detail::require(nu > 1 && std::isfinite(nu), where, "lm nu must be greater than 1");
    detail::require(eps1 >= 0 && eps2 >= 0 && min_terms >= 0 && min_damping >= 0, where,
                    "lm eps1, eps2, min_terms and min_damping must not be negative");
    detail::require(converged_step >= 0 && std::isfinite(converged_step), where,
                    "lm converged_step must not be negative (0: off)");
    detail::require(converged_gain >= 0 && std::isfinite(converged_gain), where,
                    "lm converged_gain must not be negative (0: off)");
    detail::require(refine_tau >= 0 && std::isfinite(refine_tau), where, "lm refine_tau must not be negative (0: tau)");
  }
};

struct GaussNewtonParams {
  int max_iterations = 20;
  double eps2 = 1e-8;
  double min_terms = 6;
};

template <class F, class S>
concept Linearizer = requires(F f, const SE3<S>& T, const SE3<S>* reference) {
  { f(T, reference) } -> std::convertible_to<NormalEquations6>;
};

namespace detail {
EMF_HD inline bool finite(const NormalEquations6& n) {
  for (double h : n.H)
    if (!std::isfinite(h)) return false;
  for (double v : n.g)
    if (!std::isfinite(v)) return false;
  return std::isfinite(n.cost);
}
EMF_HD inline double max_diagonal(const NormalEquations6& n) {
  const Mat6<double> H = n.hessian();
  double m = 0;
  for (int i = 0; i < 6; ++i) m = H(i, i) > m ? H(i, i) : m;
  return m;
}
EMF_HD inline double max_abs(const double* v, int n) {
  double m = 0;
  for (int i = 0; i < n; ++i) m = std::fabs(v[i]) > m ? std::fabs(v[i]) : m;
  return m;
}
/// The step below which a solve has converged: eps2 (|xi(T)| + eps2).
template <class S>
EMF_HD double step_norm_limit(const SE3<S>& T, double eps2) {
  const double x = norm(T.template cast<double>().log());
  return eps2 * (x + eps2);
}
/// At least step_norm_limit(T, eps2), without the logarithm (1 700 cycles
/// on one GPU thread, in every iteration of a batched solve): xi(T) = (v, w)
/// with |w| <= pi and v = V^-1 t, where |V^-1| = max(1, (theta / 2) /
/// sin(theta / 2)) <= pi / 2; so |xi(T)| <= 3.15 + 1.6 |t|.
EMF_HD inline double step_norm_limit_bound(const SE3<double>& T, double eps2) {
  return eps2 * (3.15 + 1.6 * norm(T.translation()) + eps2);
}
/// True if applying a step left the pose unchanged in S: the step is below
/// what the scalar resolves (in float long before eps2 is reached).
template <class S>
EMF_HD bool unchanged(const SE3<S>& a, const SE3<S>& b) {
  return max_abs_diff(a.matrix(), b.matrix()) == S(0);
}
/// The solvers' pose, in double and in S: steps compose in double, the
/// problem is linearised at the S copy.
template <class S>
struct SolverPose {
  SE3<double> T;
  SE3<S> T_s;

  /// A start whose rotation is not quite orthonormal (products of float
  /// poses) would pass its error on to the result: start at the nearest
  /// rotation.
  EMF_HD static SolverPose at(const SE3<S>& start) {
    SolverPose p;
    p.T = start.template cast<double>().orthonormalized();
    p.T_s = p.T.template cast<S>();
    return p;
  }
  /// exp(xi) * T into `next`; false if that leaves the pose unchanged in S.
  EMF_HD bool step(const Vec6<double>& xi, SolverPose& next) const {
    next.T = SE3<double>::exp(xi) * T;
    next.T_s = next.T.template cast<S>();
    return !unchanged(next.T_s, T_s);
  }
};
/// Common start: linearise at T0 and check there is something to solve.
EMF_HD inline bool start(const NormalEquations6& n, double min_terms, SolveReport& report) {
  report.initial_cost = report.final_cost = n.cost;
  report.terms = n.terms;
  if (!finite(n)) {
    report.reason = StopReason::not_finite;
    return false;
  }
  if (n.terms < min_terms) {
    report.reason = StopReason::too_few_terms;
    return false;
  }
  return true;
}
}  // namespace detail

/// Levenberg-Marquardt one linearisation at a time: a state that says at
/// which pose (and reference) it needs the problem linearised next and
/// takes that linearisation in advance(), until it is done. The algorithm
/// is written once here: levenberg_marquardt below runs it in a loop, and
/// the batched solves (solve/batched_solve.hpp) keep one per problem on the
/// backend, advanced by a kernel, so that their iterations need no host.
template <class S>
struct LevenbergMarquardtIteration {
  detail::SolverPose<S> pose;  ///< the current pose
  detail::SolverPose<S> next;  ///< the candidate asked for, once started
  NormalEquations6 n;          ///< the linearisation at `pose`
  Vec6<double> xi;             ///< the step from pose to next
  double mu = 0, nu = 0;
  /// detail::step_norm_limit at `pose` once a step was short enough to need
  /// it (below step_norm_limit_bound), -1 before: a log of the pose, taken
  /// only near convergence.
  double step_limit = -1;
  SolveReport report;
  bool started = false;  ///< the linearisation at the start was taken
  bool done = false;

  EMF_HD static LevenbergMarquardtIteration at(const SE3<S>& start) {
    LevenbergMarquardtIteration it;
    it.pose = detail::SolverPose<S>::at(start);
    it.n = NormalEquations6::zero();
    return it;
  }
  /// The pose to linearise at next.
  EMF_HD const SE3<S>& target() const { return started ? next.T_s : pose.T_s; }
  /// Its reference pose (the current one), or null for the start.
  EMF_HD const SE3<S>* reference() const { return started ? &pose.T_s : nullptr; }

  /// Takes the linearisation at target(); false once the solve is done
  /// (`report` and `pose` then hold its outcome).
  EMF_HD bool advance(const LevenbergMarquardtParams& p, const NormalEquations6& at_target) {
    if (done) return false;
    if (!started) {
      started = true;
      n = at_target;
      if (!detail::start(n, p.min_terms, report)) return finish();
      mu = p.tau * detail::max_diagonal(n);
      nu = p.nu;
      report.reason = StopReason::max_iterations;
      return propose(p);
    }
    ++report.iterations;
    // Predicted decrease of the quadratic model: xi^T (mu xi - g) / 2,
    // against the actual decrease over the terms valid at both poses.
    const double predicted = predicted_gain(xi);
    const double gained = at_target.shared_reference_cost - at_target.shared_cost;
    const double rho =
        detail::finite(at_target) && at_target.terms >= p.min_terms && predicted > 0 ? gained / predicted : -1.0;
    if (rho > 0) {
      pose = next;
      n = at_target;
      step_limit = -1;
      ++report.accepted_steps;
      const double a = 2 * rho - 1;
      const double shrink = 1.0 - a * a * a;
      mu *= shrink > 1.0 / 3.0 ? shrink : 1.0 / 3.0;
      const double floor = p.min_damping * detail::max_diagonal(n);
      mu = mu > floor ? mu : floor;
      nu = p.nu;
      if (p.converged_gain > 0 && gained <= p.converged_gain * at_target.shared_reference_cost)
        return finish(StopReason::gain_small);
    } else {
      mu *= nu;
      nu *= 2;
    }
    return propose(p);
  }

 private:
  /// The decrease of the cost that the damped quadratic model at `pose`
  /// predicts for step `step` (solved with the damping mu):
  /// step^T (mu step - g) / 2.
  EMF_HD double predicted_gain(const Vec6<double>& step) const {
    double predicted = 0;
    for (int i = 0; i < 6; ++i) predicted += step[i] * (mu * step[i] - n.g[i]);
    return 0.5 * predicted;
  }
  /// The next candidate from the current pose, or the reason to stop.
  EMF_HD bool propose(const LevenbergMarquardtParams& p) {
    if (report.iterations >= p.max_iterations) return finish();
    if (detail::max_abs(n.g, 6) <= p.eps1) return finish(StopReason::gradient_small);
    if (p.converged_step > 0 && solve_damped(n, p.min_damping * detail::max_diagonal(n), xi) &&
        norm(xi) <= p.converged_step)
      return finish(StopReason::step_small);
    if (!solve_damped(n, mu, xi)) return finish(StopReason::singular);
    // After a refused step only (nu grows past p.nu with each refusal and
    // is p.nu again after a step taken): a start's heavy damping (the
    // reference's tau 1e3) predicts little of its first steps without any
    // step having failed.
    const bool refused = nu > p.nu;
    if (p.converged_gain > 0 && refused && predicted_gain(xi) <= p.converged_gain * n.cost)
      return finish(StopReason::gain_small);
    const double step = norm(xi);
    if (step <= detail::step_norm_limit_bound(pose.T, p.eps2)) {
      if (step_limit < 0) step_limit = detail::step_norm_limit(pose.T, p.eps2);
      if (step <= step_limit) return finish(StopReason::step_small);
    }
    if (!pose.step(xi, next)) return finish(StopReason::step_small);
    return true;
  }
  EMF_HD bool finish() {
    done = true;
    report.final_cost = n.cost;
    report.terms = n.terms;
    return false;
  }
  EMF_HD bool finish(StopReason reason) {
    report.reason = reason;
    return finish();
  }
};

/// Minimises the problem behind `linearize` starting at T; returns the pose.
template <class S, class F>
  requires Linearizer<F, S>
SE3<S> levenberg_marquardt(F&& linearize, const SE3<S>& start, const LevenbergMarquardtParams& p = {},
                           SolveReport* report_out = nullptr) {
  auto it = LevenbergMarquardtIteration<S>::at(start);
  while (it.advance(p, linearize(it.target(), it.reference()))) {
  }
  if (report_out) *report_out = it.report;
  return it.pose.T_s;
}

/// Plain Gauss-Newton: every step accepted; stops on a small step.
template <class S, class F>
  requires Linearizer<F, S>
SE3<S> gauss_newton(F&& linearize, const SE3<S>& start, const GaussNewtonParams& p = {},
                    SolveReport* report_out = nullptr) {
  SolveReport report;
  const SE3<S>* no_reference = nullptr;
  auto pose = detail::SolverPose<S>::at(start);
  NormalEquations6 n = linearize(pose.T_s, no_reference);
  if (detail::start(n, p.min_terms, report)) {
    report.reason = StopReason::max_iterations;
    while (report.iterations < p.max_iterations) {
      Vec6<double> xi;
      if (!solve_damped(n, 0.0, xi)) {
        report.reason = StopReason::singular;
        break;
      }
      detail::SolverPose<S> next;
      if (!pose.step(xi, next)) {
        report.reason = StopReason::step_small;
        break;
      }
      pose = next;
      n = linearize(pose.T_s, no_reference);
      ++report.iterations, ++report.accepted_steps;
      if (!detail::finite(n)) {
        report.reason = StopReason::not_finite;
        break;
      }
      // Undamped steps settle at the noise of the scalar's arithmetic rather
      // than at eps2 in float: stop there too.
      const double resolution = 10.0 * double(std::numeric_limits<S>::epsilon()) *
                                (norm(pose.T.log()) + 1.0);
      if (norm(xi) <= std::max(detail::step_norm_limit(pose.T, p.eps2), resolution)) {
        report.reason = StopReason::step_small;
        break;
      }
    }
  }
  report.final_cost = n.cost;
  report.terms = n.terms;
  if (report_out) *report_out = report;
  return pose.T_s;
}

namespace detail {
/// A problem with no terms: a PoseSolver is checked against it.
struct NoTerms {
  template <class S>
  NormalEquations6 operator()(const SE3<S>&, const SE3<S>*) const {
    return {};
  }
};
}  // namespace detail

/// What the system needs from a solver of a pose problem: `solve(linearize,
/// start, report)` minimises the problem behind `linearize` (a Linearizer:
/// normal equations at a pose, with the costs at a reference pose) from
/// `start`, returns the pose and fills the report (`converged()` says
/// whether the pose may be used). The two solvers below are models of it.
template <class Solver, class S>
concept PoseSolver = std::copyable<Solver> && requires(const Solver& solver, const SE3<S>& start, SolveReport* r) {
  { solver.solve(detail::NoTerms{}, start, r) } -> std::same_as<SE3<S>>;
};

/// levenberg_marquardt as a PoseSolver (the system's default).
struct LevenbergMarquardt {
  LevenbergMarquardtParams params{};
  template <class F, class S>
    requires Linearizer<F, S>
  SE3<S> solve(F&& linearize, const SE3<S>& start, SolveReport* report = nullptr) const {
    return levenberg_marquardt(std::forward<F>(linearize), start, params, report);
  }
  /// This solver for a start already near the solution: tau = refine_tau
  /// (when set).
  LevenbergMarquardt refined() const {
    LevenbergMarquardt r = *this;
    if (params.refine_tau > 0) r.params.tau = params.refine_tau;
    return r;
  }
};

/// gauss_newton as a PoseSolver.
struct GaussNewton {
  GaussNewtonParams params{};
  template <class F, class S>
    requires Linearizer<F, S>
  SE3<S> solve(F&& linearize, const SE3<S>& start, SolveReport* report = nullptr) const {
    return gauss_newton(std::forward<F>(linearize), start, params, report);
  }
};

static_assert(PoseSolver<LevenbergMarquardt, float> && PoseSolver<GaussNewton, double>);

/// The solver for a start already near the solution (the finer levels of a
/// coarse-to-fine solve): solver.refined() where the solver has it
/// (LevenbergMarquardt: refine_tau), the solver itself otherwise (a user's
/// solver needs nothing more).
template <class Solver>
Solver refined(const Solver& solver) {
  if constexpr (requires {
                  { solver.refined() } -> std::convertible_to<Solver>;
                })
    return solver.refined();
  else
    return solver;
}

/// `solver`, stopping once its undamped step is shorter than `step` where it
/// has that stop (LevenbergMarquardtParams::converged_step; 0 turns it
/// off), unchanged otherwise (a user's solver decides for itself).
template <class Solver>
Solver with_converged_step(Solver solver, double step) {
  if constexpr (requires { solver.params.converged_step = step; }) solver.params.converged_step = step;
  return solver;
}

/// `solver` with converged_gain = `gain` when it has that stop
/// (LevenbergMarquardtParams::converged_gain; 0 turns it off), unchanged
/// otherwise.
template <class Solver>
Solver with_converged_gain(Solver solver, double gain) {
  if constexpr (requires { solver.params.converged_gain = gain; }) solver.params.converged_gain = gain;
  return solver;
}

}  // namespace emfusion
