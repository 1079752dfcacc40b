// The fibre term: transversely isotropic, tension only (Taylor et al. 2009,
// NiftySim's TI law):
//   S_fibre = 2 eta (I4b - 1) J^(-2/3) (a (x) a - I4/3 C^-1) when
//   I4b = J^(-2/3) a.C.a > 1, else 0;  W_fibre = eta/2 (I4b - 1)^2.
// Its per-element data: the direction a and eta (core/material.hpp's
// TISSUE_LAW_MODEL_FIELDS, fibre); eta = 0 in sets without fibres.
#pragma once

#include "core/laws/element_law.hpp"

namespace tissue {

/// The fibre term's PK2 stress (tension only), from C, C^-1, J^(-2/3).
template <class T>
TISSUE_HD Mat3<T> fibre_pk2(const Mat3<T>& C, const Mat3<T>& Ci, T j23, Vec3<T> a, T eta) {
  const T I4 = dot(a, C * a);
  const T I4b = j23 * I4;
  const T s = I4b > T(1) ? T(2) * eta * (I4b - T(1)) * j23 : T(0);  // a select: tension only
  const T t = -s * I4 / T(3);
  Mat3<T> S;
  TISSUE_UNROLL
  for (int i = 0; i < 3; ++i)
    TISSUE_UNROLL
    for (int j = 0; j < 3; ++j) S(i, j) = s * a[i] * a[j] + t * Ci(i, j);
  return S;
}

/// The fibre term's strain energy density eta/2 (I4b - 1)^2 in tension, else 0.
template <class T>
TISSUE_HD T fibre_energy(const Mat3<T>& C, T j23, Vec3<T> a, T eta) {
  const T e = j23 * dot(a, C * a) - T(1);
  return e > T(0) ? eta / T(2) * e * e : T(0);
}

/// Stable-step stiffness added by the fibre term to the P-wave modulus
/// lambda + 2 mu (Pa): 16 eta / 9 at rest along the fibre, taken as 4 eta
/// to cover the stiffening of stretched fibres (docs/materials.md).
inline double fibre_wave_modulus(double eta) { return 4 * eta; }

/// The term as an entry of LawTerms (core/material.hpp).
struct FibreTerm {
  static constexpr bool kState = false;  ///< no per-step state
  template <class Model>
  static bool in(const Model& m) {
    return m.has_fibre();
  }
  template <class T>
  TISSUE_HD static Mat3<T> pk2(const LawPoint<T>& p, ElementLaw<T>& law) {
    return fibre_pk2(p.C, p.Ci, p.j23, law.a, law.eta);
  }
  template <class T>
  TISSUE_HD static T energy(const Mat3<T>& C, T j23, const ElementLaw<T>& law) {
    return fibre_energy(C, j23, law.a, law.eta);
  }
};

}  // namespace tissue
