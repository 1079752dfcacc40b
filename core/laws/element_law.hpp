// What every law term reads at an element (core/material.hpp): its
// per-element inputs and state (ElementLaw) and the strain measures the
// Neo-Hookean stress has already formed (LawPoint).
#pragma once

#include "core/vec.hpp"

namespace tissue {

/// Most Prony terms a viscoelastic set may give.
inline constexpr int kMaxProny = 4;

/// Symmetric 3x3 as six components (xx, yy, zz, xy, yz, xz): the Prony state.
inline constexpr int kSymComponents = 6;

template <class T>
TISSUE_HD T sym_component(const Mat3<T>& S, int c) {
  const int i[6] = {0, 1, 2, 0, 1, 0}, j[6] = {0, 1, 2, 1, 2, 2};
  return S(i[c], j[c]);
}

/// The per-element inputs and state of the optional terms. Only the fields
/// of the instantiated terms are read.
template <class T>
struct ElementLaw {
  Vec3<T> a = {T(0), T(0), T(0)};  ///< unit fibre direction in the reference configuration
  T eta = T(0);                    ///< fibre stiffness (Pa); 0 = no fibres
  T decay[kMaxProny] = {};         ///< d_i = exp(-dt / tau_i); unused terms: 0 (with gain 0)
  T gain[kMaxProny] = {};          ///< g_i (1 - d_i); 0 = no such term
  T q[kMaxProny][kSymComponents] = {};  ///< in: q_i^(n-1); out: q_i^n (Pa)
};

/// The strain measures of one stress evaluation, shared by every term:
/// C = F^T F, C^-1, J^(-2/3) and mu J^(-2/3) (Pa), each formed the way
/// the Neo-Hookean stress forms it.
template <class T>
struct LawPoint {
  Mat3<T> C, Ci;
  T j23;     ///< J^(-2/3)
  T mu_j23;  ///< mu J^(-2/3): the isochoric stress's scale
};

}  // namespace tissue
