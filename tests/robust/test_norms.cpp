// Every robust norm's IRLS weight equals its cost's derivative over the
// residual, and the norms have the shapes their names promise.
#include <cmath>
#include <type_traits>

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

TEMPLATE_TEST_CASE("A norm in voxels scales to metres", "[robust]", float, double) {
  using S = TestType;
  const S voxel = S(0.004);
  // The library's norms scale their own parameter: Huber of 2 voxels is a delta of 8 mm.
  const auto huber = scaled_norm(HuberNorm<S>{S(2)}, voxel);
  static_assert(std::is_same_v<std::remove_const_t<decltype(huber)>, HuberNorm<S>>);
  CHECK(double(huber.delta) == test::Approx(0.008));
  // A user's norm without `scaled` gets ScaledNorm: the same weights as the
  // norm of the scaled parameter, and its cost in metres squared.
  const auto geman = scaled_norm(GemanMcClure<S>{S(3)}, voxel);
  static_assert(std::is_same_v<std::remove_const_t<decltype(geman)>, ScaledNorm<GemanMcClure<S>, S>>);
  const GemanMcClure<S> metres{S(3) * voxel};
  for (double r = -0.03; r <= 0.03; r += 0.0013) {
    CHECK(double(geman.weight(S(r))) == test::Approx(double(metres.weight(S(r)))).epsilon(1e-4));
    CHECK(double(geman.cost(S(r))) == test::Approx(double(metres.cost(S(r)))).epsilon(1e-4).margin(1e-12));
  }
  check_weight_is_derivative<S>(ScaledNorm<TukeyNorm<S>, S>{TukeyNorm<S>{S(4)}, S(0.5)});
}
