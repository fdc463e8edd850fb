// Rigid-body transforms SE(3), generic over the scalar and usable in kernels.
//
// A pose is stored as rotation matrix R and translation t and maps points
// p_b -> R p_b + t; name variables after the frames, `T_world_camera` maps
// camera points into the world. Tangent vectors are ordered (v, w):
// translation part first, rotation part second. `exp` and `log` stay accurate
// in float down to zero angle (series expansions near zero, a symmetric-part
// formula near pi).
#pragma once

#include <cmath>

#include "emfusion/core/host_device.hpp"
#include "emfusion/core/math.hpp"

namespace emfusion {

namespace detail {

/// Below this angle (radians) the SO(3)/SE(3) coefficients use series
/// expansions: the direct formulas lose digits to cancellation there.
template <class S>
EMF_HD constexpr S small_angle() {
  return sizeof(S) <= 4 ? S(0.1) : S(1e-3);
}

/// Coefficients of exp: A = sin(t)/t, B = (1 - cos t)/t^2, C = (t - sin t)/t^3.
template <class S>
struct ExpCoefficients {
  S a, b, c;
};

template <class S>
EMF_HD ExpCoefficients<S> exp_coefficients(S theta) {
  const S t2 = theta * theta;
  ExpCoefficients<S> k{};
  if (theta < small_angle<S>()) {
    k.a = S(1) - t2 / S(6) * (S(1) - t2 / S(20));
    k.b = S(0.5) - t2 / S(24) * (S(1) - t2 / S(30));
    k.c = S(1) / S(6) - t2 / S(120) * (S(1) - t2 / S(42) * (S(1) - t2 / S(72)));
  } else {
    const S s = std::sin(theta);
    const S h = std::sin(theta / S(2)) / (theta / S(2));
    k.a = s / theta;
    k.b = S(0.5) * h * h;  // 1 - cos t = 2 sin^2(t/2): no cancellation
    k.c = (theta - s) / (t2 * theta);
  }
  return k;
}

}  // namespace detail

/// Rotation exp map: angle-axis vector w -> rotation matrix.
template <class S>
EMF_HD Mat3<S> so3_exp(const Vec3<S>& w) {
  const S theta = norm(w);
  const auto k = detail::exp_coefficients(theta);
  const Mat3<S> W = hat(w);
  return Mat3<S>::identity() + k.a * W + k.b * (W * W);
}

/// Rotation log map: rotation matrix -> angle-axis vector (angle in [0, pi]).
template <class S>
EMF_HD Vec3<S> so3_log(const Mat3<S>& R) {
  // 2 sin(theta) * axis = vee(R - R^T); 2 cos(theta) = trace(R) - 1.
  const Vec3<S> v2 = vec3(R(2, 1) - R(1, 2), R(0, 2) - R(2, 0), R(1, 0) - R(0, 1));
  const S sin_t = S(0.5) * norm(v2);
  const S cos_t = S(0.5) * (trace(R) - S(1));
  const S theta = std::atan2(sin_t, cos_t);
  if (cos_t > S(0) || sin_t > S(0.1)) {
    // Away from pi the antisymmetric part carries the axis well.
    const S factor =
        theta < detail::small_angle<S>() ? S(1) + theta * theta / S(6) : theta / sin_t;
    return S(0.5) * factor * v2;
  }
  // Near pi: R + R^T - 2 cos(t) I = 2 (1 - cos t) axis axis^T; take the column
  // with the largest diagonal, then fix the sign with the antisymmetric part.
  const S one_minus_cos = S(1) - cos_t;
  int best = 0;
  for (int i = 1; i < 3; ++i)
    if (R(i, i) > R(best, best)) best = i;
  Vec3<S> axis{};
  for (int i = 0; i < 3; ++i)
    axis[i] = (R(i, best) + R(best, i) - (i == best ? S(2) * cos_t : S(0))) / (S(2) * one_minus_cos);
  axis = normalized(axis);
  if (dot(axis, v2) < S(0)) axis = -axis;
  return theta * axis;
}

template <class S>
class SE3 {
 public:
  using Scalar = S;
  using Tangent = Vec6<S>;

  EMF_HD SE3() : R_(Mat3<S>::identity()), t_(Vec3<S>::zero()) {}
  EMF_HD SE3(const Mat3<S>& R, const Vec3<S>& t) : R_(R), t_(t) {}

  EMF_HD static SE3 identity() { return SE3(); }
  EMF_HD static SE3 translation(const Vec3<S>& t) { return SE3(Mat3<S>::identity(), t); }

  /// Pose from a unit quaternion (Hamilton, x y z w) and a translation; the
  /// quaternion is normalised first.
  EMF_HD static SE3 from_quaternion(S qx, S qy, S qz, S qw, const Vec3<S>& t) {
    const S n = std::sqrt(qx * qx + qy * qy + qz * qz + qw * qw);
    qx /= n, qy /= n, qz /= n, qw /= n;
    Mat3<S> R{{S(1) - S(2) * (qy * qy + qz * qz), S(2) * (qx * qy - qz * qw), S(2) * (qx * qz + qy * qw),
               S(2) * (qx * qy + qz * qw), S(1) - S(2) * (qx * qx + qz * qz), S(2) * (qy * qz - qx * qw),
               S(2) * (qx * qz - qy * qw), S(2) * (qy * qz + qx * qw), S(1) - S(2) * (qx * qx + qy * qy)}};
    return SE3(R, t);
  }

  /// Exponential map: tangent (v, w) -> pose.
  EMF_HD static SE3 exp(const Tangent& xi) {
    const Vec3<S> v = vec3(xi[0], xi[1], xi[2]);
    const Vec3<S> w = vec3(xi[3], xi[4], xi[5]);
    const S theta = norm(w);
    const auto k = detail::exp_coefficients(theta);
    const Mat3<S> W = hat(w);
    const Mat3<S> W2 = W * W;
    const Mat3<S> R = Mat3<S>::identity() + k.a * W + k.b * W2;
    const Mat3<S> V = Mat3<S>::identity() + k.b * W + k.c * W2;
    return SE3(R, V * v);
  }

  /// Logarithm: pose -> tangent (v, w), rotation angle in [0, pi].
  EMF_HD Tangent log() const {
    const Vec3<S> w = so3_log(R_);
    const S theta = norm(w);
    const Mat3<S> W = hat(w);
    // V^-1 = I - W/2 + D W^2 with D = (1 - (t/2) cot(t/2)) / t^2.
    S d;
    if (theta < detail::small_angle<S>()) {
      const S t2 = theta * theta;
      d = S(1) / S(12) + t2 / S(720) + t2 * t2 / S(30240);
    } else {
      const S half = theta / S(2);
      d = (S(1) - half * std::cos(half) / std::sin(half)) / (theta * theta);
    }
    const Mat3<S> V_inv = Mat3<S>::identity() - S(0.5) * W + d * (W * W);
    const Vec3<S> v = V_inv * t_;
    return Tangent{{v[0], v[1], v[2], w[0], w[1], w[2]}};
  }

  EMF_HD SE3 inverse() const {
    const Mat3<S> Rt = R_.transpose();
    return SE3(Rt, -(Rt * t_));
  }

  EMF_HD SE3 operator*(const SE3& o) const { return SE3(R_ * o.R_, R_ * o.t_ + t_); }
  EMF_HD Vec3<S> operator*(const Vec3<S>& p) const { return R_ * p + t_; }
  /// Rotates a direction (no translation).
  EMF_HD Vec3<S> rotate(const Vec3<S>& d) const { return R_ * d; }

  /// Adjoint: exp(adjoint() * xi) == T * exp(xi) * T^-1.
  EMF_HD Mat6<S> adjoint() const {
    Mat6<S> A = Mat6<S>::zero();
    const Mat3<S> tR = hat(t_) * R_;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        A(i, j) = R_(i, j);
        A(i + 3, j + 3) = R_(i, j);
        A(i, j + 3) = tR(i, j);
      }
    return A;
  }

  /// d/d(xi) of exp(xi) * T * p at xi = 0 (left perturbation), given q = T * p:
  /// [ I | -hat(q) ].
  EMF_HD static Matrix<S, 3, 6> left_jacobian_of_action(const Vec3<S>& q) {
    Matrix<S, 3, 6> J = Matrix<S, 3, 6>::zero();
    const Mat3<S> Q = hat(q);
    for (int i = 0; i < 3; ++i) {
      J(i, i) = S(1);
      for (int j = 0; j < 3; ++j) J(i, j + 3) = -Q(i, j);
    }
    return J;
  }

  /// d/d(xi) of T * exp(xi) * p at xi = 0 (right perturbation): R [ I | -hat(p) ].
  EMF_HD Matrix<S, 3, 6> right_jacobian_of_action(const Vec3<S>& p) const {
    return R_ * left_jacobian_of_action(p);
  }

  /// Unit quaternion (x, y, z, w) of the rotation, w >= 0.
  EMF_HD Vector<S, 4> quaternion() const {
    const Mat3<S>& R = R_;
    Vector<S, 4> q{};
    const S tr = trace(R);
    if (tr > S(0)) {
      const S s = std::sqrt(tr + S(1)) * S(2);
      q = Vector<S, 4>{{(R(2, 1) - R(1, 2)) / s, (R(0, 2) - R(2, 0)) / s, (R(1, 0) - R(0, 1)) / s, S(0.25) * s}};
    } else if (R(0, 0) > R(1, 1) && R(0, 0) > R(2, 2)) {
      const S s = std::sqrt(S(1) + R(0, 0) - R(1, 1) - R(2, 2)) * S(2);
      q = Vector<S, 4>{{S(0.25) * s, (R(0, 1) + R(1, 0)) / s, (R(0, 2) + R(2, 0)) / s, (R(2, 1) - R(1, 2)) / s}};
    } else if (R(1, 1) > R(2, 2)) {
      const S s = std::sqrt(S(1) + R(1, 1) - R(0, 0) - R(2, 2)) * S(2);
      q = Vector<S, 4>{{(R(0, 1) + R(1, 0)) / s, S(0.25) * s, (R(1, 2) + R(2, 1)) / s, (R(0, 2) - R(2, 0)) / s}};
    } else {
      const S s = std::sqrt(S(1) + R(2, 2) - R(0, 0) - R(1, 1)) * S(2);
      q = Vector<S, 4>{{(R(0, 2) + R(2, 0)) / s, (R(1, 2) + R(2, 1)) / s, S(0.25) * s, (R(1, 0) - R(0, 1)) / s}};
    }
    if (q[3] < S(0)) q = -q;
    return normalized(q);
  }

  /// The same pose with R replaced by the nearest rotation (three Newton steps
  /// of the polar decomposition, R <- R (3 I - R^T R) / 2, enough for the
  /// drift that products of poses accumulate). Poses that are composed and
  /// inverted over and over, such as an object's pose updated every frame,
  /// need it: inverse() is the transpose, so an error e in R^T R grows to
  /// about 3 e in each round trip through T^-1 (T ...) and blows up.
  EMF_HD SE3 orthonormalized() const {
    Mat3<S> R = R_;
    for (int k = 0; k < 3; ++k) R = S(0.5) * (R * (S(3) * Mat3<S>::identity() - R.transpose() * R));
    return SE3(R, t_);
  }

  EMF_HD const Mat3<S>& rotation() const { return R_; }
  EMF_HD const Vec3<S>& translation() const { return t_; }
  EMF_HD Mat3<S>& rotation() { return R_; }
  EMF_HD Vec3<S>& translation() { return t_; }

  /// 4x4 homogeneous matrix.
  EMF_HD Matrix<S, 4, 4> matrix() const {
    Matrix<S, 4, 4> M = Matrix<S, 4, 4>::identity();
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) M(i, j) = R_(i, j);
      M(i, 3) = t_[i];
    }
    return M;
  }

  template <class T>
  EMF_HD SE3<T> cast() const {
    return SE3<T>(R_.template cast<T>(), t_.template cast<T>());
  }

 private:
  Mat3<S> R_;
  Vec3<S> t_;
};

using SE3f = SE3<float>;
using SE3d = SE3<double>;

/// True if every entry of T's 3x4 matrix is finite.
template <class S>
bool is_finite(const SE3<S>& T) {
  const auto m = T.matrix();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c)
      if (!std::isfinite(double(m(r, c)))) return false;
  return true;
}

}  // namespace emfusion
