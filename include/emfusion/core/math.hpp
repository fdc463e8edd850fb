// Small fixed-size vectors and matrices usable in device code.
//
// The library's maths, per pixel and per voxel in kernels and on the host
// (the solvers' 6x6 systems, evaluation's alignments), uses these plain
// aggregates: they compile identically under g++ and nvcc and cost nothing
// to copy into a kernel. No header includes Eigen (eval/alignment.hpp says
// why); the build still finds it, as DESIGN.md allows.
#pragma once

#include <cmath>

#include "emfusion/core/host_device.hpp"

namespace emfusion {

/// Row-major R x C matrix of scalars S; vectors are R x 1.
template <class S, int R, int C>
struct Matrix {
  static_assert(R > 0 && C > 0, "Matrix dimensions must be positive");
  using Scalar = S;
  static constexpr int rows = R;
  static constexpr int cols = C;

  S m[R * C];

  EMF_HD static Matrix zero() {
    Matrix r{};
    for (int i = 0; i < R * C; ++i) r.m[i] = S(0);
    return r;
  }
  EMF_HD static Matrix identity() {
    Matrix r = zero();
    for (int i = 0; i < (R < C ? R : C); ++i) r(i, i) = S(1);
    return r;
  }
  EMF_HD static Matrix constant(S value) {
    Matrix r{};
    for (int i = 0; i < R * C; ++i) r.m[i] = value;
    return r;
  }

  EMF_HD S& operator()(int r, int c) { return m[r * C + c]; }
  EMF_HD const S& operator()(int r, int c) const { return m[r * C + c]; }
  EMF_HD S& operator[](int i) { return m[i]; }
  EMF_HD const S& operator[](int i) const { return m[i]; }

  // Named access for 2-, 3- and 4-vectors.
  EMF_HD S& x() { return m[0]; }
  EMF_HD S& y() { return m[1]; }
  EMF_HD S& z() { return m[2]; }
  EMF_HD const S& x() const { return m[0]; }
  EMF_HD const S& y() const { return m[1]; }
  EMF_HD const S& z() const { return m[2]; }

  template <class T>
  EMF_HD Matrix<T, R, C> cast() const {
    Matrix<T, R, C> r{};
    for (int i = 0; i < R * C; ++i) r.m[i] = static_cast<T>(m[i]);
    return r;
  }

  EMF_HD Matrix<S, C, R> transpose() const {
    Matrix<S, C, R> r{};
    for (int i = 0; i < R; ++i)
      for (int j = 0; j < C; ++j) r(j, i) = (*this)(i, j);
    return r;
  }

  EMF_HD Matrix& operator+=(const Matrix& o) {
    for (int i = 0; i < R * C; ++i) m[i] += o.m[i];
    return *this;
  }
  EMF_HD Matrix& operator-=(const Matrix& o) {
    for (int i = 0; i < R * C; ++i) m[i] -= o.m[i];
    return *this;
  }
  EMF_HD Matrix& operator*=(S s) {
    for (int i = 0; i < R * C; ++i) m[i] *= s;
    return *this;
  }
};

template <class S, int N>
using Vector = Matrix<S, N, 1>;
template <class S>
using Vec2 = Vector<S, 2>;
template <class S>
using Vec3 = Vector<S, 3>;
template <class S>
using Vec6 = Vector<S, 6>;
template <class S>
using Mat3 = Matrix<S, 3, 3>;
template <class S>
using Mat6 = Matrix<S, 6, 6>;

using Vec3f = Vec3<float>;
using Vec3d = Vec3<double>;
using Vec3i = Vector<int, 3>;

template <class S>
EMF_HD Vec2<S> vec2(S x, S y) {
  return Vec2<S>{{x, y}};
}
template <class S>
EMF_HD Vec3<S> vec3(S x, S y, S z) {
  return Vec3<S>{{x, y, z}};
}

template <class S, int R, int C>
EMF_HD Matrix<S, R, C> operator+(Matrix<S, R, C> a, const Matrix<S, R, C>& b) {
  return a += b;
}
template <class S, int R, int C>
EMF_HD Matrix<S, R, C> operator-(Matrix<S, R, C> a, const Matrix<S, R, C>& b) {
  return a -= b;
}
template <class S, int R, int C>
EMF_HD Matrix<S, R, C> operator-(Matrix<S, R, C> a) {
  return a *= S(-1);
}
template <class S, int R, int C>
EMF_HD Matrix<S, R, C> operator*(Matrix<S, R, C> a, S s) {
  return a *= s;
}
template <class S, int R, int C>
EMF_HD Matrix<S, R, C> operator*(S s, Matrix<S, R, C> a) {
  return a *= s;
}
template <class S, int R, int C>
EMF_HD Matrix<S, R, C> operator/(Matrix<S, R, C> a, S s) {
  return a *= (S(1) / s);
}

template <class S, int R, int K, int C>
EMF_HD Matrix<S, R, C> operator*(const Matrix<S, R, K>& a, const Matrix<S, K, C>& b) {
  Matrix<S, R, C> r = Matrix<S, R, C>::zero();
  for (int i = 0; i < R; ++i)
    for (int k = 0; k < K; ++k) {
      const S aik = a(i, k);
      for (int j = 0; j < C; ++j) r(i, j) += aik * b(k, j);
    }
  return r;
}

template <class S, int N>
EMF_HD S dot(const Vector<S, N>& a, const Vector<S, N>& b) {
  S s = S(0);
  for (int i = 0; i < N; ++i) s += a[i] * b[i];
  return s;
}
template <class S, int N>
EMF_HD S squared_norm(const Vector<S, N>& a) {
  return dot(a, a);
}
template <class S, int N>
EMF_HD S norm(const Vector<S, N>& a) {
  return std::sqrt(dot(a, a));
}
/// a / |a|; the zero vector stays zero.
template <class S, int N>
EMF_HD Vector<S, N> normalized(const Vector<S, N>& a) {
  const S n = norm(a);
  return n > S(0) ? a / n : a;
}
template <class S>
EMF_HD Vec3<S> cross(const Vec3<S>& a, const Vec3<S>& b) {
  return vec3(a.y() * b.z() - a.z() * b.y(), a.z() * b.x() - a.x() * b.z(),
              a.x() * b.y() - a.y() * b.x());
}
/// The cross-product matrix: hat(a) * b == cross(a, b).
template <class S>
EMF_HD Mat3<S> hat(const Vec3<S>& a) {
  return Mat3<S>{{S(0), -a.z(), a.y(), a.z(), S(0), -a.x(), -a.y(), a.x(), S(0)}};
}
template <class S>
EMF_HD S trace(const Mat3<S>& a) {
  return a(0, 0) + a(1, 1) + a(2, 2);
}

/// Element-wise maximum absolute difference (for tests and tolerances).
template <class S, int R, int C>
EMF_HD S max_abs_diff(const Matrix<S, R, C>& a, const Matrix<S, R, C>& b) {
  S d = S(0);
  for (int i = 0; i < R * C; ++i) {
    const S e = std::fabs(a.m[i] - b.m[i]);
    d = e > d ? e : d;
  }
  return d;
}

template <class S>
EMF_HD S clamp(S v, S lo, S hi) {
  return v < lo ? lo : (v > hi ? hi : v);
}

/// The bits of a float as an int, and back, through the builtin that
/// std::bit_cast wraps: the builtin takes its argument by value, while
/// std::bit_cast's reference parameter put it in memory in the sanitizer
/// build (-O1), where the bilateral filter then ran at a third of its speed.
EMF_HD inline int float_bits(float x) {
#if defined(__CUDA_ARCH__)
  return __float_as_int(x);
#else
  return __builtin_bit_cast(int, x);
#endif
}
EMF_HD inline float float_from_bits(int bits) {
#if defined(__CUDA_ARCH__)
  return __int_as_float(bits);
#else
  return __builtin_bit_cast(float, bits);
#endif
}

/// e^x in single precision from a polynomial and the exponent's bits, no
/// library call: a loop over it vectorises on the host (glibc's expf is a
/// call per element). Relative error below 3e-7 (a few ulps) for x in
/// [-87, 87]; x is clamped to that range (e^-87 is about 1.6e-38, near the
/// smallest normal float), infinities too, and NaN gives one of its ends:
/// mask such arguments. Double keeps std::exp.
EMF_HD inline float fast_exp(float x) {
  // |x| clamped to 87 as an integer minimum of its bits: a clamp by float
  // comparisons became branches (they may trap) and left loops over
  // fast_exp unvectorised.
  // (Unsigned arithmetic on the bits throughout: nothing to overflow, and
  // nothing for UBSan to check in the sanitizer build's inner loops.)
  const unsigned bits = unsigned(float_bits(x)), magnitude = bits & 0x7fffffffu, limit = 0x42ae0000u;  // 87.0f
  x = float_from_bits(int((bits & 0x80000000u) | (magnitude < limit ? magnitude : limit)));
  // n = round(x / ln 2) by the float adder: 1.5 * 2^23 added leaves n in
  // the low mantissa bits.
  const float shifter = 12582912.0f;
  const float t = x * 1.44269504f + shifter;
  const float n = t - shifter;
  // r = x - n ln 2 with ln 2 split in two (its high part exact in float):
  // |r| <= ln(2) / 2, where Taylor's series to r^6 is within 1.3e-7.
  const float r = (x - n * 0.693145752f) - n * 1.42860677e-6f;
  const float p =
      1.0f + r * (1.0f + r * (0.5f + r * (1.0f / 6 + r * (1.0f / 24 + r * (1.0f / 120 + r * (1.0f / 720))))));
  return p * float_from_bits(int((unsigned(float_bits(t)) - unsigned(float_bits(shifter)) + 127u) << 23));
}
EMF_HD inline double fast_exp(double x) { return std::exp(x); }

}  // namespace emfusion
