// Gauss-Newton and Levenberg-Marquardt on a problem with a known answer
// (point-to-point alignment), their reports and their failure modes.
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "emfusion/core/image.hpp"
#include "emfusion/solve/normal_equations.hpp"
#include "emfusion/solve/pose_prior.hpp"
#include "emfusion/solve/solvers.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"

using namespace emfusion;

namespace {

/// Three scalar terms per point: (T * source - target)[axis].
template <class S>
struct PointToPoint {
  ImageView<const Vec3<S>> source, target;
  EMF_HD int term_count() const { return 3 * source.size(); }
  EMF_HD bool term(int i, const SE3<S>& T, S& r, Vec6<S>& J, S& w) const {
    const int k = i / 3, axis = i % 3;
    const Vec3<S> x = T * source[k];
    r = x[axis] - target[k][axis];
    const auto Jx = SE3<S>::left_jacobian_of_action(x);
    for (int j = 0; j < 6; ++j) J[j] = Jx(axis, j);
    w = S(1);
    return true;
  }
};

template <class S, class B>
struct Fixture {
  Image<Vec3<S>, B> source, target;
  SE3<S> truth;
  Fixture(int n, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1, 1);
    std::vector<Vec3<S>> s, t;
    truth = SE3<S>::exp(Vec6<S>{{S(0.3), S(-0.2), S(0.1), S(0.4), S(-0.3), S(0.2)}});
    for (int i = 0; i < n; ++i) {
      s.push_back(vec3(S(u(rng)), S(u(rng)), S(2 + u(rng))));
      t.push_back(truth * s.back());
    }
    source = Image<Vec3<S>, Host>::from_host(n, 1, s).template to<B>();
    target = Image<Vec3<S>, Host>::from_host(n, 1, t).template to<B>();
  }
  PointToPoint<S> problem() const { return {source.view(), target.view()}; }
};

template <class S>
double pose_error(const SE3<S>& a, const SE3<S>& b) {
  return double(max_abs_diff(a.matrix(), b.matrix()));
}

}  // namespace

TEMPLATE_LIST_TEST_CASE("Solvers recover a known pose", "[solve]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const Fixture<S, B> f(200, 1);
  const auto problem = f.problem();
  const B backend{};
  const auto lin = [&](const SE3<S>& T, const SE3<S>* ref) { return linearize(backend, problem, L2Norm<S>{}, T, ref); };
  // LM stops once its step is below eps2 = 1e-8 (relative): that bounds the accuracy.
  const double tol = sizeof(S) <= 4 ? 2e-5 : 1e-8;

  SolveReport lm_report;
  const SE3<S> lm = levenberg_marquardt(lin, SE3<S>::identity(), {}, &lm_report);
  INFO("LM: " << lm_report.iterations << " iterations, stop " << to_string(lm_report.reason));
  CHECK(pose_error(lm, f.truth) < tol);
  CHECK(lm_report.converged());
  CHECK(lm_report.final_cost < 1e-6 * lm_report.initial_cost);
  CHECK(lm_report.terms == 600);
  CHECK(lm_report.iterations > 0);

  SolveReport gn_report;
  const SE3<S> gn = gauss_newton(lin, SE3<S>::identity(), {}, &gn_report);
  CHECK(pose_error(gn, f.truth) < tol);
  CHECK(gn_report.iterations <= 10);  // quadratic convergence on a zero-residual problem
}

TEMPLATE_LIST_TEST_CASE("Solvers report why they could not solve", "[solve]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const B backend{};
  // One point gives 3 terms: fewer than the 6 unknowns.
  const Fixture<S, B> one(1, 2);
  const auto p1 = one.problem();
  SolveReport report;
  const SE3<S> start = SE3<S>::translation(vec3(S(0.1), S(0), S(0)));
  const SE3<S> T = levenberg_marquardt([&](const SE3<S>& X, const SE3<S>* ref) { return linearize(backend, p1, L2Norm<S>{}, X, ref); },
                                       start, {}, &report);
  CHECK(report.reason == StopReason::too_few_terms);
  CHECK(!report.converged());
  CHECK(pose_error(T, start) == 0.0);

  // A NaN in the data is reported, not iterated on.
  std::vector<Vec3<S>> pts(10, vec3(S(1), S(2), S(3)));
  pts[4] = Vec3<S>::constant(std::numeric_limits<S>::quiet_NaN());
  const auto src = Image<Vec3<S>, Host>::from_host(10, 1, pts).template to<B>();
  const PointToPoint<S> p2{src.view(), src.view()};
  levenberg_marquardt([&](const SE3<S>& X, const SE3<S>* ref) { return linearize(backend, p2, L2Norm<S>{}, X, ref); },
                      SE3<S>::identity(), {},
                      &report);
  CHECK(report.reason == StopReason::not_finite);

  // All points equal: rotations about the point are unobservable. GN cannot
  // solve the singular system; LM's damping keeps the step finite.
  std::vector<Vec3<S>> same(10, vec3(S(0.5), S(0.5), S(2)));
  const auto s3 = Image<Vec3<S>, Host>::from_host(10, 1, same).template to<B>();
  std::vector<Vec3<S>> moved(10, vec3(S(0.6), S(0.5), S(2)));
  const auto t3 = Image<Vec3<S>, Host>::from_host(10, 1, moved).template to<B>();
  const PointToPoint<S> p3{s3.view(), t3.view()};
  const auto lin3 = [&](const SE3<S>& X, const SE3<S>* ref) { return linearize(backend, p3, L2Norm<S>{}, X, ref); };
  gauss_newton(lin3, SE3<S>::identity(), {}, &report);
  CHECK(report.reason == StopReason::singular);
  const SE3<S> damped = levenberg_marquardt(lin3, SE3<S>::identity(), {}, &report);
  CHECK(report.converged());
  CHECK(double(norm(damped * vec3(S(0.5), S(0.5), S(2)) - vec3(S(0.6), S(0.5), S(2)))) < 1e-3);
}

TEMPLATE_LIST_TEST_CASE("LM's converged_step and refined(): fewer iterations, the same pose", "[solve]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const Fixture<S, B> f(200, 3);
  const auto problem = f.problem();
  const B backend{};
  const auto lin = [&](const SE3<S>& T, const SE3<S>* ref) { return linearize(backend, problem, L2Norm<S>{}, T, ref); };
  const double tol = sizeof(S) <= 4 ? 2e-5 : 1e-8;

  // The reference runs until its damped steps fall below eps2.
  SolveReport reference_report;
  const SE3<S> reference = levenberg_marquardt(lin, SE3<S>::identity(), {}, &reference_report);
  REQUIRE(pose_error(reference, f.truth) < tol);

  // Stopping once the undamped step is below 1e-4 lands within about that
  // of the solution, and sooner.
  LevenbergMarquardtParams quick;
  quick.converged_step = 1e-4;
  SolveReport quick_report;
  const SE3<S> stopped = levenberg_marquardt(lin, SE3<S>::identity(), quick, &quick_report);
  INFO("reference " << reference_report.iterations << " iterations, converged_step " << quick_report.iterations);
  CHECK(quick_report.reason == StopReason::step_small);
  CHECK(quick_report.iterations < reference_report.iterations);
  CHECK(pose_error(stopped, f.truth) < 1e-4);

  // From a start near the solution, refined() (refine_tau 1e-6 against the
  // reference's tau 1e3) needs fewer iterations for the same pose; a solver
  // without refine_tau, or without refined() at all, is itself.
  LevenbergMarquardt solver;
  solver.params.refine_tau = 1e-6;
  const SE3<S> near = SE3<S>::exp(Vec6<S>{{S(0.002), S(0), S(-0.001), S(0.001), S(0), S(0)}}) * f.truth;
  SolveReport coarse_report, refined_report;
  const SE3<S> from_solver = solver.solve(lin, near, &coarse_report);
  const SE3<S> from_refined = refined(solver).solve(lin, near, &refined_report);
  CHECK(refined(solver).params.tau == 1e-6);
  CHECK(refined(LevenbergMarquardt{}).params.tau == LevenbergMarquardtParams{}.tau);
  CHECK(refined(GaussNewton{}).params.max_iterations == GaussNewtonParams{}.max_iterations);
  CHECK(refined_report.iterations < coarse_report.iterations);
  CHECK(pose_error(from_solver, f.truth) < tol);
  CHECK(pose_error(from_refined, f.truth) < tol);
}

namespace {

/// The normal equations of a cost whose quadratic model promises a gain at
/// every pose (H = I, g = (0.1, ..., 0.1), cost 1) while a step to another
/// pose lowers it by `gained` only: the camera's cost near its minimum,
/// where an interpolated SDF and a robust norm leave it flat along a
/// direction the frame hardly observes, and the undamped step stays long.
NormalEquations6 flat_cost(const SE3<double>* reference, double gained) {
  NormalEquations6 n = NormalEquations6::zero();
  for (int i = 0; i < 6; ++i) {
    Vec6<double> J = Vec6<double>::zero();
    J[i] = 1;
    n.add(J, 0.1, 1.0, 0.0);
  }
  n.cost = 1;
  if (reference) n.shared_reference_cost = 1, n.shared_cost = 1 - gained;
  return n;
}

}  // namespace

TEST_CASE("LM's converged_gain ends a solve once its steps stop lowering the cost", "[solve]") {
  LevenbergMarquardtParams off;  // the system's: tau 1e-3, eps2 1e-6
  off.tau = 1e-3, off.eps2 = 1e-6;
  LevenbergMarquardtParams on = off;
  on.converged_gain = 1e-4;
  const auto solve = [](double gained, const LevenbergMarquardtParams& p) {
    SolveReport report;
    levenberg_marquardt([&](const SE3<double>&, const SE3<double>* ref) { return flat_cost(ref, gained); },
                        SE3<double>::identity(), p, &report);
    return report;
  };
  SECTION("steps taken that gain a millionth of the cost: the first ends it") {
    const SolveReport without = solve(1e-6, off), with = solve(1e-6, on);
    INFO(without.iterations << " iterations without, " << with.iterations << " with");
    CHECK(without.accepted_steps > 10);
    CHECK(with.reason == StopReason::gain_small);
    CHECK(with.converged());
    CHECK(with.iterations == 1);
    CHECK(with.accepted_steps == 1);
  }
  SECTION("every step refused: ended once the damped model expects too little, not at eps2") {
    const SolveReport without = solve(0, off), with = solve(0, on);
    INFO(without.iterations << " iterations without, " << with.iterations << " with");
    CHECK(without.reason == StopReason::step_small);
    CHECK(with.reason == StopReason::gain_small);
    CHECK(with.accepted_steps == 0);
    CHECK(with.iterations < without.iterations);
  }
  SECTION("steps that gain a tenth of the cost go on; heavy damping at the start is no refusal") {
    LevenbergMarquardtParams reference = LevenbergMarquardtParams{};  // tau 1e3
    reference.converged_gain = 1e-4;
    reference.max_iterations = 20;
    CHECK(solve(0.1, on).reason == StopReason::max_iterations);
    CHECK(solve(0.1, reference).iterations == 20);
  }
  SECTION("off by default; with_converged_gain sets it where a solver has it") {
    CHECK(LevenbergMarquardtParams{}.converged_gain == 0);
    CHECK(with_converged_gain(LevenbergMarquardt{}, 1e-3).params.converged_gain == 1e-3);
    CHECK(with_converged_gain(GaussNewton{}, 1e-3).params.max_iterations == GaussNewtonParams{}.max_iterations);
    LevenbergMarquardtParams bad;
    bad.converged_gain = -1;
    CHECK_THROWS_WITH(bad.validate(), EMF_CONTAINS("converged_gain"));
  }
}

TEMPLATE_LIST_TEST_CASE("LM's converged_gain leaves a smooth solve's pose as it was", "[solve]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const B backend{};
  // Targets off the truth by up to 2 mm: the cost's minimum is not zero.
  Fixture<S, B> f(200, 5);
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(-0.002, 0.002);
  std::vector<Vec3<S>> t = f.target.to_host();
  for (Vec3<S>& x : t) x = x + vec3(S(u(rng)), S(u(rng)), S(u(rng)));
  f.target = Image<Vec3<S>, Host>::from_host(int(t.size()), 1, t).template to<B>();
  const auto problem = f.problem();
  const auto lin = [&](const SE3<S>& T, const SE3<S>* ref) { return linearize(backend, problem, L2Norm<S>{}, T, ref); };
  for (const double tau : {1e-3, 1e3}) {
    LevenbergMarquardtParams off;
    off.tau = tau;
    LevenbergMarquardtParams on = off;
    on.converged_gain = 1e-4;
    SolveReport without, with;
    const SE3<S> reference = levenberg_marquardt(lin, SE3<S>::identity(), off, &without);
    const SE3<S> stopped = levenberg_marquardt(lin, SE3<S>::identity(), on, &with);
    INFO("tau " << tau << ": " << without.iterations << " iterations without, " << with.iterations << " with");
    CHECK(with.converged());
    CHECK(with.iterations <= without.iterations);
    CHECK(pose_error(stopped, reference) < 1e-4);
    CHECK(pose_error(stopped, f.truth) < 2e-3);
  }
}

TEST_CASE("LM's cheap bound on the converged step is never below the step itself", "[solve]") {
  // The solver takes the log of its pose only for steps under the bound, so
  // a bound below step_norm_limit would stop solves later than before.
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1, 1), angle(0, 3.14159265358979);
  const double pi = 3.14159265358979323846;
  for (int i = 0; i < 20000; ++i) {
    // Rotations up to and just below pi (where |V^-1| is largest), and
    // translations from millimetres to 100 m.
    Vec3<double> axis = normalized(vec3(u(rng), u(rng), u(rng)));
    const double theta = i % 4 == 0 ? pi - 1e-7 * (1 + i % 7) : angle(rng);
    const double scale = std::pow(10.0, 2 * u(rng) + (i % 3) - 1);
    const Vec6<double> xi{{scale * u(rng), scale * u(rng), scale * u(rng), theta * axis[0], theta * axis[1],
                           theta * axis[2]}};
    const SE3<double> T = SE3<double>::exp(xi);
    for (const double eps2 : {1e-8, 1e-6}) {
      INFO("pose " << i << ", angle " << theta << ", |t| " << norm(T.translation()));
      CHECK(detail::step_norm_limit(T, eps2) <= detail::step_norm_limit_bound(T, eps2));
    }
  }
  // And the bound is not far above it where poses are: a metre, a quarter turn.
  const SE3<double> T = SE3<double>::exp(Vec6<double>{{1, 0, 0, 0, 0, pi / 2}});
  CHECK(detail::step_norm_limit_bound(T, 1e-6) < 4 * detail::step_norm_limit(T, 1e-6));
}

namespace {

/// Terms that see only a plane z = 1 (volume frame) through points of it
/// at the pose T (the plane's z offset and its tilts are observed, motion
/// along it and the turn about its normal are not), and one weak term that
/// pulls T's x translation to `pull_to` (what a neighbour's pixels do to a
/// flat patch of a model).
template <class S>
struct PlaneAndPull {
  S pull_to = S(0.1), pull_weight = S(0.5);
  EMF_HD int term_count() const { return 401; }
  EMF_HD bool term(int i, const SE3<S>& T, S& r, Vec6<S>& J, S& w) const {
    if (i == 400) {
      r = T.translation().x() - pull_to;
      const auto Jt = SE3<S>::left_jacobian_of_action(T.translation());
      for (int j = 0; j < 6; ++j) J[j] = Jt(0, j);
      w = pull_weight;
      return true;
    }
    const Vec3<S> p = vec3(S(0.02) * S(i % 20) - S(0.19), S(0.02) * S(i / 20) - S(0.19), S(1));
    const Vec3<S> x = T * p;
    r = x.z() - S(1);
    const auto Jx = SE3<S>::left_jacobian_of_action(x);
    for (int j = 0; j < 6; ++j) J[j] = Jx(2, j);
    w = S(1);
    return true;
  }
};

}  // namespace

TEMPLATE_LIST_TEST_CASE("A pose prior holds the directions the data does not observe", "[solve]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const B backend{};
  const SE3<S> start(so3_exp(vec3(S(0.02), S(-0.01), S(0.05))), vec3(S(0.03), S(-0.02), S(0.04)));
  PosePrior<S> prior;
  prior.pose = start;
  prior.centre = vec3(S(0), S(0), S(1));
  prior.radius = S(0.2);

  // The prior's Jacobian is that of its residuals under exp(xi) * T.
  prior.weight = S(1);
  const WithPosePrior<PlaneAndPull<S>, S> pulled{PlaneAndPull<S>{}, prior};
  REQUIRE(pulled.term_count() == 407);
  const SE3<S> T = SE3<S>(so3_exp(vec3(S(0.1), S(0.2), S(-0.1))), vec3(S(0.05), S(0.01), S(-0.03))) * start;
  const double h = sizeof(S) <= 4 ? 1e-3 : 1e-6;
  for (int i = 401; i < 407; ++i) {
    S r, w;
    Vec6<S> J;
    REQUIRE(pulled.term(i, T, r, J, w));
    CHECK(w == S(1));
    for (int j = 0; j < 6; ++j) {
      Vec6<S> xi = Vec6<S>::zero();
      xi[j] = S(h);
      S r_plus, r_minus, w2;
      Vec6<S> J2;
      pulled.term(i, SE3<S>::exp(xi) * T, r_plus, J2, w2);
      xi[j] = S(-h);
      pulled.term(i, SE3<S>::exp(xi) * T, r_minus, J2, w2);
      // First order: the rotation rows drop the Jacobian of log (its error
      // grows with the rotation between T and the prior, 0.24 rad here).
      CHECK(double(J[j]) == emfusion::test::Approx((double(r_plus) - double(r_minus)) / (2 * h)).margin(0.04));
    }
  }
  // At the prior's own pose its residuals are zero.
  for (int i = 401; i < 407; ++i) {
    S r, w;
    Vec6<S> J;
    pulled.term(i, start, r, J, w);
    CHECK(std::abs(double(r)) < 1e-6);
  }

  const auto solve = [&](S weight) {
    PosePrior<S> p = prior;
    p.weight = weight;
    const WithPosePrior<PlaneAndPull<S>, S> problem{PlaneAndPull<S>{}, p};
    const auto lin = [&](const SE3<S>& pose, const SE3<S>* ref) {
      return linearize(backend, problem, L2Norm<S>{}, pose, ref);
    };
    return levenberg_marquardt(lin, start, {});
  };
  // Without the prior the weak pull alone places x; with it x stays near
  // its start, while the plane, which 400 points observe, is met either way.
  const SE3<S> free = solve(S(0)), held = solve(S(20));
  CHECK(double(free.translation().x()) == emfusion::test::Approx(0.1).margin(1e-3));
  INFO("x: " << free.translation().x() << " free, " << held.translation().x() << " held");
  CHECK(std::abs(double(held.translation().x()) - 0.03) < 0.01);
  for (const SE3<S>& solved : {free, held}) {
    const Vec3<S> on_plane = solved * vec3(S(0), S(0), S(1));
    CHECK(double(on_plane.z()) == emfusion::test::Approx(1.0).margin(2e-3));
  }
}
