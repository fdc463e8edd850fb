// SE3 exp/log, composition, adjoint, action Jacobians and quaternions, for
// float and double, on the host and inside kernels of every backend.
#include <cmath>
#include <random>
#include <vector>

#include "emfusion/core/image.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/core/se3.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"

using namespace emfusion;

namespace {

template <class S>
Vec6<S> random_tangent(std::mt19937& rng, double max_angle, double max_translation) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Vec3d axis{{u(rng), u(rng), u(rng)}};
  axis = normalized(axis);
  const double angle = max_angle * std::fabs(u(rng));
  return Vec6<S>{{S(max_translation * u(rng)), S(max_translation * u(rng)), S(max_translation * u(rng)),
                  S(axis[0] * angle), S(axis[1] * angle), S(axis[2] * angle)}};
}

template <class S>
double tol() {
  return sizeof(S) <= 4 ? 2e-5 : 1e-11;
}

// Kernel that round-trips tangents through exp and log: proves the SE3 code
// runs in device code and gives host results there too.
template <class S>
struct ExpLogRoundTrip {
  const Vec6<S>* in;
  Vec6<S>* out;
  EMF_HD void operator()(int i) const { out[i] = SE3<S>::exp(in[i]).log(); }
};

}  // namespace

TEMPLATE_LIST_TEST_CASE("SE3 exp and log are inverse", "[core]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  std::mt19937 rng(7);
  // Angles from zero up to just below pi, including the series and near-pi branches.
  std::vector<Vec6<S>> xs;
  for (double max_angle : {0.0, 1e-7, 1e-4, 0.05, 1.0, 3.0, 3.1415}) {
    for (int k = 0; k < 50; ++k) xs.push_back(random_tangent<S>(rng, max_angle, 2.0));
  }
  // Exactly representable specials: zero, pure translation, a half turn.
  xs.push_back(Vec6<S>::zero());
  xs.push_back(Vec6<S>{{S(1), S(-2), S(0.5), S(0), S(0), S(0)}});
  xs.push_back(Vec6<S>{{S(0.1), S(0.2), S(0.3), S(0), S(0), S(3.14159)}});

  // Host results.
  for (const auto& xi : xs) {
    const Vec6<S> back = SE3<S>::exp(xi).log();
    INFO("angle " << norm(vec3(xi[3], xi[4], xi[5])));
    CHECK(double(max_abs_diff(back, xi)) < 20 * tol<S>() * (1 + norm(xi)));
  }
  // Same in a kernel on the backend.
  Image<Vec6<S>, B> in = Image<Vec6<S>, Host>::from_host(int(xs.size()), 1, xs).template to<B>();
  Image<Vec6<S>, B> out(int(xs.size()), 1, Vec6<S>::zero());
  for_each_index(out.backend(), out.size(), ExpLogRoundTrip<S>{in.view().data, out.view().data});
  const auto back = out.to_host();
  for (std::size_t i = 0; i < xs.size(); ++i)
    CHECK(double(max_abs_diff(back[i], xs[i])) < 20 * tol<S>() * (1 + norm(xs[i])));
}

TEMPLATE_LIST_TEST_CASE("SE3 composition, inverse and action agree", "[core]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  std::mt19937 rng(11);
  for (int k = 0; k < 100; ++k) {
    const SE3<S> a = SE3<S>::exp(random_tangent<S>(rng, 3.0, 1.0));
    const SE3<S> b = SE3<S>::exp(random_tangent<S>(rng, 3.0, 1.0));
    const Vec3<S> p = vec3(S(0.3), S(-0.2), S(1.5));
    CHECK(double(max_abs_diff((a * b) * p, a * (b * p))) < 10 * tol<S>());
    CHECK(double(max_abs_diff(a.inverse() * (a * p), p)) < 10 * tol<S>());
    CHECK(double(max_abs_diff((a * a.inverse()).matrix(), Matrix<S, 4, 4>::identity())) < 10 * tol<S>());
    // Rotation stays orthonormal after exp.
    CHECK(double(max_abs_diff(a.rotation() * a.rotation().transpose(), Mat3<S>::identity())) < 10 * tol<S>());
  }
}

TEMPLATE_LIST_TEST_CASE("SE3 adjoint moves tangents between frames", "[core]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  std::mt19937 rng(3);
  for (int k = 0; k < 50; ++k) {
    const SE3<S> T = SE3<S>::exp(random_tangent<S>(rng, 2.5, 1.0));
    const Vec6<S> xi = random_tangent<S>(rng, 0.5, 0.3);
    const SE3<S> lhs = SE3<S>::exp(T.adjoint() * xi);
    const SE3<S> rhs = T * SE3<S>::exp(xi) * T.inverse();
    CHECK(double(max_abs_diff(lhs.matrix(), rhs.matrix())) < 20 * tol<S>());
  }
}

TEMPLATE_LIST_TEST_CASE("SE3 action Jacobians match finite differences", "[core]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  // Finite differences in double; the Jacobian evaluated in S.
  std::mt19937 rng(5);
  const double h = 1e-6;
  for (int k = 0; k < 20; ++k) {
    const SE3d T = SE3d::exp(random_tangent<double>(rng, 2.0, 1.0));
    const Vec3d p{{0.4, -0.7, 1.2}};
    const auto J_left = SE3<S>::left_jacobian_of_action((T * p).template cast<S>());
    const auto J_right = T.template cast<S>().right_jacobian_of_action(p.template cast<S>());
    for (int j = 0; j < 6; ++j) {
      Vec6<double> d = Vec6<double>::zero();
      d[j] = h;
      const Vec3d left = (SE3d::exp(d) * T * p - SE3d::exp(-d) * T * p) / (2 * h);
      const Vec3d right = (T * SE3d::exp(d) * p - T * SE3d::exp(-d) * p) / (2 * h);
      for (int i = 0; i < 3; ++i) {
        CHECK(std::fabs(double(J_left(i, j)) - left[i]) < 1e-5);
        CHECK(std::fabs(double(J_right(i, j)) - right[i]) < 1e-5);
      }
    }
  }
}

TEMPLATE_LIST_TEST_CASE("SE3 quaternion round trip", "[core]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  std::mt19937 rng(9);
  for (int k = 0; k < 100; ++k) {
    const SE3<S> T = SE3<S>::exp(random_tangent<S>(rng, 3.14, 2.0));
    const auto q = T.quaternion();
    CHECK(std::fabs(double(norm(q)) - 1.0) < 10 * tol<S>());
    CHECK(double(q[3]) >= 0.0);
    const SE3<S> back = SE3<S>::from_quaternion(q[0], q[1], q[2], q[3], T.translation());
    CHECK(double(max_abs_diff(back.matrix(), T.matrix())) < 20 * tol<S>());
  }
  // A known quaternion: 90 degrees about z.
  const S s = S(std::sqrt(0.5));
  const SE3<S> Rz = SE3<S>::from_quaternion(S(0), S(0), s, s, Vec3<S>::zero());
  const Vec3<S> x = Rz * vec3(S(1), S(0), S(0));
  CHECK(double(max_abs_diff(x, vec3(S(0), S(1), S(0)))) < 10 * tol<S>());
}

namespace {
template <class S>
double orthonormality_error(const SE3<S>& T) {
  const Mat3<S> M = T.rotation().transpose() * T.rotation();
  return double(max_abs_diff(M, Mat3<S>::identity()));
}
}  // namespace

TEMPLATE_LIST_TEST_CASE("SE3 orthonormalized gives the nearest rotation", "[core]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int k = 0; k < 50; ++k) {
    const SE3<S> T = SE3<S>::exp(random_tangent<S>(rng, 3.0, 2.0));
    SE3<S> bent = T;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) bent.rotation()(i, j) += S(5e-3 * u(rng));
    REQUIRE(orthonormality_error(bent) > 1e-3);
    const SE3<S> fixed = bent.orthonormalized();
    CHECK(orthonormality_error(fixed) < 10 * tol<S>());
    // Close to the pose it was bent from, translation untouched.
    CHECK(double(norm(so3_log(fixed.rotation().transpose() * T.rotation()))) < 2e-2);
    CHECK(double(max_abs_diff(fixed.translation(), T.translation())) == 0.0);
  }
}

// The old update of an object's pose from its tracked camera pose went
// through the world and back: moved = T_world_volume * T_volume_camera, then
// T_volume_camera = T_world_volume^-1 * moved and T_world_volume <-
// T_world_camera * T_volume_camera^-1. inverse() is the transpose, so an
// error e in R^T R came back as about 3 e each frame and grew exponentially
// (a float object pose went from 5e-8 to 5e-3 in ten frames and the object
// flew off). Orthonormalising the new pose keeps it at rounding level.
TEMPLATE_LIST_TEST_CASE("Repeated pose round trips stay orthonormal when orthonormalised", "[core]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  std::mt19937 rng(12);
  const SE3<S> T_world_camera = SE3<S>::exp(random_tangent<S>(rng, 1.0, 2.0));
  SE3<S> raw = SE3<S>::exp(random_tangent<S>(rng, 1.0, 2.0));
  raw.rotation()(0, 1) += S(1e-6);  // the error a few float products leave
  SE3<S> kept = raw.orthonormalized();
  const auto update = [&](const SE3<S>& T_world_volume) {
    const SE3<S> moved = T_world_volume * (T_world_volume.inverse() * T_world_camera);
    const SE3<S> T_volume_camera = T_world_volume.inverse() * moved;
    return T_world_camera * T_volume_camera.inverse();
  };
  for (int frame = 0; frame < 12; ++frame) {
    raw = update(raw);
    kept = update(kept).orthonormalized();
  }
  CHECK(orthonormality_error(raw) > 1e-3);  // what the system did before
  CHECK(orthonormality_error(kept) < 10 * tol<S>());
}
