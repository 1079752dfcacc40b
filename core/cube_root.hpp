// Cube root of a positive number without a libm call, so that the host's
// element loops vectorise (a call to std::cbrt or std::pow stops GCC's
// vectoriser, and the two calls per element were a quarter of a cpu step).
// On the device it is CUDA's cbrt (a few instructions there).
//
// Method (host): x = m 2^E with m in [1, 2); E = 3q + r, r in {0, 1, 2};
// z = m 2^r in [1, 8) has cube root z^(1/3) in [1, 2), and x^(1/3) =
// z^(1/3) 2^q exactly. The start is the chord of m^(1/3) on [1, 2), raised
// by half its largest gap (relative error <= 0.66 %), times 2^(r/3); two
// Halley steps y <- y (y^3 + 2z) / (2y^3 + z) (cubic convergence:
// 0.66 % -> ~1e-7 -> below double rounding) finish it. Every operation is
// integer or floating-point arithmetic on one value, with no branch, so a
// SIMD loop runs it on every lane. Tested against std::cbrt over the whole
// normal range (tests/test_tet.cpp).
#pragma once

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>

#include "core/hd.hpp"

namespace tissue {

namespace detail {

/// Bit layout of an IEEE binary format.
template <class T>
struct FloatBits;
template <>
struct FloatBits<double> {
  using U = std::uint64_t;
  using I = std::int64_t;
  static constexpr int mantissa = 52;
  static constexpr I bias = 1023;
};
template <>
struct FloatBits<float> {
  using U = std::uint32_t;
  using I = std::int32_t;
  static constexpr int mantissa = 23;
  static constexpr I bias = 127;
};

/// z^(1/3) for z in [1, 8) (z = m 2^r, m in [1, 2), r in {0, 1, 2}).
template <class T>
inline T cube_root_reduced(T z, T m, T r) {
  // chord of m^(1/3) on [1, 2) raised by half its gap, times 2^(r/3) (the
  // quadratic in r through 1, 2^(1/3), 2^(2/3)): no select on r
  T y = (T(0.7475095) + T(0.2599210498948731648) * m) * (T(1) + r * (T(0.2261415) + r * T(0.0337795)));
  for (int k = 0; k < 2; ++k) {
    const T y3 = y * y * y;
    y = y * (y3 + T(2) * z) / (T(2) * y3 + z);
  }
  return y;
}

}  // namespace detail

/// x^(1/3) for x > 0 (m^3 -> m, ...). Inputs below the smallest normal
/// number are treated as that number; the caller keeps x finite and > 0
/// (the element routines pass a stand-in of 1 for a bad element).
template <class T>
TISSUE_HD T cube_root(T x) {
#if defined(__CUDA_ARCH__)
  return cbrt(x);
#else
  using B = detail::FloatBits<T>;
  using U = typename B::U;
  using I = typename B::I;
  x = x < std::numeric_limits<T>::min() ? std::numeric_limits<T>::min() : x;
  const U bits = std::bit_cast<U>(x);
  // biased exponent e, shifted so that the bias offset is a multiple of 3:
  // E = e - bias = e' - 3 c with e' = e + s, s = (3 - bias % 3) % 3
  constexpr I shift = (3 - B::bias % 3) % 3, c = (B::bias + shift) / 3;
  const I e = I(bits >> B::mantissa) + shift;
  const I k = (e * 21846) >> 16;  // floor(e / 3) for 0 <= e < 3 * 2^15 / 2
  const I r = e - 3 * k;
  const U frac = bits & ((U(1) << B::mantissa) - 1);
  const T m = std::bit_cast<T>(U(frac | (U(B::bias) << B::mantissa)));       // [1, 2)
  const T z = std::bit_cast<T>(U(frac | (U(B::bias + r) << B::mantissa)));   // m 2^r
  const T scale = std::bit_cast<T>(U(U(k - c + B::bias) << B::mantissa));  // 2^q, q = k - c
  // T(r) without an integer conversion (AVX2 has none for 64-bit lanes):
  // 2^mantissa + r as bits, minus 2^mantissa
  const T big = T(U(1) << B::mantissa);
  const T rf = std::bit_cast<T>(U(std::bit_cast<U>(big) | U(r))) - big;
  return detail::cube_root_reduced(z, m, rf) * scale;
#endif
}

}  // namespace tissue
