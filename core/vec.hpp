// Small fixed-size vector and matrix types for per-element math, usable on
// host and device (no CUDA includes). Row-major 3x3.
#pragma once

#include <cmath>

#include "core/hd.hpp"

namespace tissue {

template <class T>
struct Vec3 {
  T x, y, z;
  TISSUE_HD T& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
  TISSUE_HD T operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
};

template <class T> TISSUE_HD Vec3<T> operator+(Vec3<T> a, Vec3<T> b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
template <class T> TISSUE_HD Vec3<T> operator-(Vec3<T> a, Vec3<T> b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
template <class T> TISSUE_HD Vec3<T> operator*(T s, Vec3<T> a) { return {s * a.x, s * a.y, s * a.z}; }
template <class T> TISSUE_HD T dot(Vec3<T> a, Vec3<T> b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
template <class T> TISSUE_HD Vec3<T> cross(Vec3<T> a, Vec3<T> b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <class T> TISSUE_HD T norm(Vec3<T> a) { return std::sqrt(dot(a, a)); }

template <class T>
struct Mat3 {
  T m[9];  // row-major: m[3*i + j] = M_ij
  TISSUE_HD T& operator()(int i, int j) { return m[3 * i + j]; }
  TISSUE_HD T operator()(int i, int j) const { return m[3 * i + j]; }
  TISSUE_HD static Mat3 identity() { return {{1, 0, 0, 0, 1, 0, 0, 0, 1}}; }
  TISSUE_HD static Mat3 zero() { return {{0, 0, 0, 0, 0, 0, 0, 0, 0}}; }
};

template <class T> TISSUE_HD Mat3<T> operator*(const Mat3<T>& a, const Mat3<T>& b) {
  Mat3<T> c;
TISSUE_UNROLL
  for (int i = 0; i < 3; ++i)
TISSUE_UNROLL
    for (int j = 0; j < 3; ++j) c(i, j) = a(i, 0) * b(0, j) + a(i, 1) * b(1, j) + a(i, 2) * b(2, j);
  return c;
}
template <class T> TISSUE_HD Mat3<T> operator*(T s, const Mat3<T>& a) {
  Mat3<T> c;
TISSUE_UNROLL
  for (int k = 0; k < 9; ++k) c.m[k] = s * a.m[k];
  return c;
}
template <class T> TISSUE_HD Mat3<T> operator+(const Mat3<T>& a, const Mat3<T>& b) {
  Mat3<T> c;
TISSUE_UNROLL
  for (int k = 0; k < 9; ++k) c.m[k] = a.m[k] + b.m[k];
  return c;
}
template <class T> TISSUE_HD Vec3<T> operator*(const Mat3<T>& a, Vec3<T> v) {
  return {a(0, 0) * v.x + a(0, 1) * v.y + a(0, 2) * v.z, a(1, 0) * v.x + a(1, 1) * v.y + a(1, 2) * v.z,
          a(2, 0) * v.x + a(2, 1) * v.y + a(2, 2) * v.z};
}
template <class T> TISSUE_HD Mat3<T> transpose(const Mat3<T>& a) {
  return {{a(0, 0), a(1, 0), a(2, 0), a(0, 1), a(1, 1), a(2, 1), a(0, 2), a(1, 2), a(2, 2)}};
}
template <class T> TISSUE_HD T trace(const Mat3<T>& a) { return a(0, 0) + a(1, 1) + a(2, 2); }
template <class T> TISSUE_HD T det(const Mat3<T>& a) {
  return a(0, 0) * (a(1, 1) * a(2, 2) - a(1, 2) * a(2, 1)) - a(0, 1) * (a(1, 0) * a(2, 2) - a(1, 2) * a(2, 0)) +
         a(0, 2) * (a(1, 0) * a(2, 1) - a(1, 1) * a(2, 0));
}
/// Inverse through the adjugate; the caller guarantees det != 0.
template <class T> TISSUE_HD Mat3<T> inverse(const Mat3<T>& a, T d) {
  const T s = T(1) / d;
  return {{s * (a(1, 1) * a(2, 2) - a(1, 2) * a(2, 1)), s * (a(0, 2) * a(2, 1) - a(0, 1) * a(2, 2)),
           s * (a(0, 1) * a(1, 2) - a(0, 2) * a(1, 1)), s * (a(1, 2) * a(2, 0) - a(1, 0) * a(2, 2)),
           s * (a(0, 0) * a(2, 2) - a(0, 2) * a(2, 0)), s * (a(0, 2) * a(1, 0) - a(0, 0) * a(1, 2)),
           s * (a(1, 0) * a(2, 1) - a(1, 1) * a(2, 0)), s * (a(0, 1) * a(2, 0) - a(0, 0) * a(2, 1)),
           s * (a(0, 0) * a(1, 1) - a(0, 1) * a(1, 0))}};
}

}  // namespace tissue
