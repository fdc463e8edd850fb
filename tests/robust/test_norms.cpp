// Every robust norm's IRLS weight equals its cost's derivative over the
// residual, and the norms have the shapes their names promise.
#include <cmath>

#include "emfusion/robust/norms.hpp"
#include "support/catch.hpp"

using namespace emfusion;

namespace {
template <class S, class N>
void check_weight_is_derivative(const N& norm) {
  const double h = sizeof(S) <= 4 ? 1e-3 : 1e-6;
  const double tol = sizeof(S) <= 4 ? 5e-3 : 1e-6;
  for (double r = -3.0; r <= 3.0; r += 0.0137) {
    if (std::fabs(r) < 0.05) continue;  // w = rho'(r) / r is 0/0 at r = 0
    const double derivative = (double(norm.cost(S(r + h))) - double(norm.cost(S(r - h)))) / (2 * h);
    INFO("r = " << r);
    CHECK(std::fabs(double(norm.weight(S(r))) - derivative / r) < tol);
  }
  CHECK(double(norm.cost(S(0))) == 0.0);
  CHECK(double(norm.weight(S(0))) == test::Approx(1.0));
}

// A user-defined norm: only cost() and weight() are needed.
template <class S>
struct GemanMcClure {
  S c = S(1);
  EMF_HD S cost(S r) const { return S(0.5) * r * r / (S(1) + r * r / (c * c)); }
  EMF_HD S weight(S r) const {
    const S d = S(1) + r * r / (c * c);
    return S(1) / (d * d);
  }
};
}  // namespace

TEMPLATE_TEST_CASE("Robust norm weights are the cost derivative over the residual", "[robust]", float, double) {
  using S = TestType;
  check_weight_is_derivative<S>(L2Norm<S>{});
  check_weight_is_derivative<S>(HuberNorm<S>{S(0.7)});
  check_weight_is_derivative<S>(TukeyNorm<S>{S(1.9)});
  check_weight_is_derivative<S>(CauchyNorm<S>{S(0.5)});
  static_assert(RobustNorm<GemanMcClure<S>, S>);
  check_weight_is_derivative<S>(GemanMcClure<S>{S(1.3)});
}

TEMPLATE_TEST_CASE("Robust norms have their characteristic shapes", "[robust]", float, double) {
  using S = TestType;
  const HuberNorm<S> huber{S(2)};
  CHECK(double(huber.cost(S(1))) == test::Approx(0.5));  // quadratic inside
  CHECK(double(huber.cost(S(5))) == test::Approx(2 * (5 - 1)));  // linear outside
  CHECK(double(huber.weight(S(-4))) == test::Approx(0.5));
  const TukeyNorm<S> tukey{S(1)};
  CHECK(double(tukey.weight(S(1.5))) == 0.0);  // outliers are ignored
  CHECK(double(tukey.cost(S(1.5))) == test::Approx(1.0 / 6));
  const CauchyNorm<S> cauchy{S(1)};
  CHECK(double(cauchy.weight(S(1))) == test::Approx(0.5));
  CHECK(double(L2Norm<S>{}.weight(S(100))) == 1.0);
}
