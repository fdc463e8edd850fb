// Rigid (rotation + translation, no scale) alignment of two matched point
// sets, the least-squares fit that the absolute trajectory error (ATE) is
// measured after.
//
// Horn's closed form with unit quaternions (Horn 1987, "Closed-form solution
// of absolute orientation using unit quaternions"): the best rotation is the
// eigenvector of the largest eigenvalue of a symmetric 4x4 matrix built from
// the cross-covariance of the centred points. It gives the same transform as
// Umeyama's SVD method without scale, including its sign correction: the
// quaternion always encodes a proper rotation, so a point set that would be
// fitted best by a reflection gets the best proper rotation instead.
//
// The eigenvector comes from a cyclic Jacobi iteration written here rather
// than from Eigen: Eigen 3.4's headers raise warnings under nvcc (CUDA 13,
// #20012 on its defaulted __host__ __device__ members) and under g++ when not
// included as a system header, and every test unit is compiled by nvcc in
// CUDA builds. A 4x4 Jacobi iteration is short, converges in a few sweeps and
// is accurate to rounding.
#pragma once

#include <cmath>
#include <cstddef>
#include <stdexcept>
#include <string>
#include <vector>

#include "emfusion/core/error.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/core/se3.hpp"

namespace emfusion::eval {

namespace detail {

/// Eigen-decomposition of a symmetric 4x4 matrix by cyclic Jacobi rotations.
/// On return `a` is diagonal (the eigenvalues) and the columns of `v` are the
/// matching orthonormal eigenvectors.
inline void jacobi_eigen_4x4(double (&a)[4][4], double (&v)[4][4]) {
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) v[i][j] = i == j ? 1.0 : 0.0;
  for (int sweep = 0; sweep < 64; ++sweep) {
    double off = 0.0, total = 0.0;
    for (int p = 0; p < 4; ++p)
      for (int q = 0; q < 4; ++q) {
        total += a[p][q] * a[p][q];
        if (p != q) off += a[p][q] * a[p][q];
      }
    // Rounding leaves off-diagonal entries near eps * |a|; stop there.
    if (off <= 1e-32 * total) return;
    for (int p = 0; p < 3; ++p)
      for (int q = p + 1; q < 4; ++q) {
        if (a[p][q] == 0.0) continue;
        // Rotation by angle phi in the (p, q) plane that zeroes a[p][q]:
        // t = tan(phi), the smaller root of t^2 + 2 theta t - 1 = 0.
        const double theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
        const double t = (theta >= 0.0 ? 1.0 : -1.0) / (std::fabs(theta) + std::hypot(theta, 1.0));
        const double c = 1.0 / std::sqrt(t * t + 1.0);
        const double s = t * c;
        for (int k = 0; k < 4; ++k) {  // a <- a J
          const double akp = a[k][p], akq = a[k][q];
          a[k][p] = c * akp - s * akq;
          a[k][q] = s * akp + c * akq;
        }
        for (int k = 0; k < 4; ++k) {  // a <- J^T a
          const double apk = a[p][k], aqk = a[q][k];
          a[p][k] = c * apk - s * aqk;
          a[q][k] = s * apk + c * aqk;
        }
        a[p][q] = a[q][p] = 0.0;
        for (int k = 0; k < 4; ++k) {  // v <- v J
          const double vkp = v[k][p], vkq = v[k][q];
          v[k][p] = c * vkp - s * vkq;
          v[k][q] = s * vkp + c * vkq;
        }
      }
  }
}

inline Vec3d centroid(const std::vector<Vec3d>& points) {
  Vec3d sum = Vec3d::zero();
  for (const Vec3d& p : points) sum += p;
  return sum / double(points.size());
}

}  // namespace detail

/// The rigid transform T (rotation and translation, no scale) that minimises
/// sum_i |T * source[i] - target[i]|^2. With ATE's naming, source = estimated
/// positions and target = ground-truth positions give T_gt_est.
///
/// Needs at least 3 matched points of equal count, all finite; otherwise
/// throws std::invalid_argument. Degenerate sets still give a proper rotation
/// that attains the minimum: for collinear points the rotation about their
/// line is not determined and one of the optimal ones is returned; for
/// coincident points the rotation is the identity.
inline SE3<double> align_rigid(const std::vector<Vec3d>& source, const std::vector<Vec3d>& target) {
  constexpr const char* where = "align_rigid";
  emfusion::detail::require(source.size() == target.size(), where,
                            "source has " + std::to_string(source.size()) + " points but target has " +
                                std::to_string(target.size()) + " (they must be matched pairs)");
  emfusion::detail::require(source.size() >= 3, where,
                            "need at least 3 point pairs, got " + std::to_string(source.size()));
  for (std::size_t i = 0; i < source.size(); ++i)
    for (int k = 0; k < 3; ++k)
      emfusion::detail::require(std::isfinite(source[i][k]) && std::isfinite(target[i][k]), where,
                                "point pair " + std::to_string(i) + " is not finite");

  const Vec3d cs = detail::centroid(source);
  const Vec3d ct = detail::centroid(target);
  // Cross-covariance S(j, k) = sum (source_j - cs_j)(target_k - ct_k).
  double S[3][3] = {};
  for (std::size_t i = 0; i < source.size(); ++i) {
    const Vec3d a = source[i] - cs;
    const Vec3d b = target[i] - ct;
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) S[j][k] += a[j] * b[k];
  }
  // Horn's N: q^T N q = sum b_i . (R(q) a_i) for unit quaternions q = (w, x, y, z).
  const double sxx = S[0][0], sxy = S[0][1], sxz = S[0][2];
  const double syx = S[1][0], syy = S[1][1], syz = S[1][2];
  const double szx = S[2][0], szy = S[2][1], szz = S[2][2];
  double N[4][4] = {{sxx + syy + szz, syz - szy, szx - sxz, sxy - syx},
                    {syz - szy, sxx - syy - szz, sxy + syx, szx + sxz},
                    {szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy},
                    {sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz}};
  double V[4][4];
  detail::jacobi_eigen_4x4(N, V);
  int best = 0;
  for (int i = 1; i < 4; ++i)
    if (N[i][i] > N[best][best]) best = i;

  const SE3<double> rotation =
      SE3<double>::from_quaternion(V[1][best], V[2][best], V[3][best], V[0][best], Vec3d::zero());
  return SE3<double>(rotation.rotation(), ct - rotation.rotate(cs));
}

}  // namespace emfusion::eval
