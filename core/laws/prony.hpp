// The viscoelastic term: a Prony series on the isochoric stress. Its state
// q_i per element, integrated exactly for a stress constant over each step:
//   q_i^n = d_i q_i^(n-1) + g_i (1 - d_i) S_iso^n,  d_i = exp(-dt / tau_i),
// so a held strain relaxes as G(t) = 1 - sum_i g_i (1 - exp(-t / tau_i));
// the stress is S_iso - sum_i q_i. Its data: core/material.hpp's
// visco_slot, prony_* and visco_q; g_i = 0 in sets without it.
#pragma once

#include <cmath>

#include "core/laws/element_law.hpp"

namespace tissue {

/// Advances the Prony state with this step's isochoric stress and returns
/// sum_i q_i^n.
template <class T>
TISSUE_HD Mat3<T> prony_update(const Mat3<T>& S_iso, ElementLaw<T>& law) {
  T sum[kSymComponents] = {};
  TISSUE_UNROLL
  for (int i = 0; i < kMaxProny; ++i)
    TISSUE_UNROLL
    for (int c = 0; c < kSymComponents; ++c) {
      law.q[i][c] = law.decay[i] * law.q[i][c] + law.gain[i] * sym_component(S_iso, c);
      sum[c] += law.q[i][c];
    }
  return {{sum[0], sum[3], sum[5], sum[3], sum[1], sum[4], sum[5], sum[4], sum[2]}};
}

/// The Neo-Hookean isochoric PK2 stress S_iso = a (I - I1/3 C^-1) from C,
/// C^-1 and a = mu J^(-2/3): what the Prony terms relax.
template <class T>
TISSUE_HD Mat3<T> isochoric_pk2(const Mat3<T>& C, const Mat3<T>& Ci, T a) {
  Mat3<T> S = (-a * trace(C) / T(3)) * Ci;
  S(0, 0) += a;
  S(1, 1) += a;
  S(2, 2) += a;
  return S;
}

/// The Prony terms' viscous power and stored energy, per unit reference
/// volume, at an element's current state (docs/materials.md, energy):
/// term i's Maxwell branch still carries h_i = g_i S_iso - q_i (what has
/// not relaxed yet); with the branch's shear modulus g_i mu and viscosity
/// g_i mu tau_i, it dissipates h_i:h_i / (2 g_i mu tau_i) (W/m^3) and
/// stores h_i:h_i / (4 g_i mu) (J/m^3). The linear standard solid's exact
/// energies, taken as the finite-strain definition (S in PK2, the
/// reference volume). g[i] = 0: no term i.
struct PronyEnergy {
  double power = 0;   ///< W/m^3
  double stored = 0;  ///< J/m^3
};

/// Computed in R (double on the GPU; the cpu's lanes use their own T, so
/// that they vectorise); branch-free.
template <class T, class R>
TISSUE_HD PronyEnergy prony_energy(const Mat3<T>& S_iso, const T q[kMaxProny][kSymComponents], const R g[kMaxProny],
                                   const R tau[kMaxProny], R mu) {
  R power = R(0), stored = R(0);
  TISSUE_UNROLL
  for (int i = 0; i < kMaxProny; ++i) {
    R hh = R(0);
    TISSUE_UNROLL
    for (int c = 0; c < kSymComponents; ++c) {
      const R h = g[i] * R(sym_component(S_iso, c)) - R(q[i][c]);
      hh += (c < 3 ? R(1) : R(2)) * h * h;  // the off-diagonal components count twice
    }
    const bool on = g[i] > R(0);
    const R gm = on ? g[i] * mu : R(1);  // (no division by zero for an unused term)
    power += on ? hh / (R(2) * gm * tau[i]) : R(0);
    stored += on ? hh / (R(4) * gm) : R(0);
  }
  return {double(power), double(stored)};
}

/// The Prony constants of one term for step dt (s): decay d = exp(-dt /
/// tau) and gain g (1 - d).
inline void prony_constants(double g, double tau, double dt, double* decay, double* gain) {
  *decay = std::exp(-dt / tau);
  *gain = g * -std::expm1(-dt / tau);
}

/// The term as an entry of LawTerms (core/material.hpp).
struct PronyTerm {
  static constexpr bool kState = true;  ///< advances law.q: a bad element must keep its old state
  template <class Model>
  static bool in(const Model& m) {
    return m.has_visco();
  }
  template <class T>
  TISSUE_HD static Mat3<T> pk2(const LawPoint<T>& p, ElementLaw<T>& law) {
    return T(-1) * prony_update(isochoric_pk2(p.C, p.Ci, p.mu_j23), law);
  }
  template <class T>
  TISSUE_HD static T energy(const Mat3<T>&, T, const ElementLaw<T>&) {
    return T(0);  // the branches' energy is prony_energy's, reported apart
  }
};

}  // namespace tissue
