// The material seam (docs/materials.md): every constitutive law the engine
// offers, written once for every backend (__host__ __device__, branch-free,
// no libm call but exp in the host-side constants), as additive terms of one
// PK2 stress:
//
//   S = S_iso(C) - sum_i q_i + S_vol(C) + S_fibre(C)   (core/tet.hpp law_pk2)
//
//   Neo-Hookean (always)    S_iso = mu J^(-2/3) (I - I1/3 C^-1),
//                           S_vol = K J (J - 1) C^-1 (IANP evaluates it at Fbar);
//   fibre (transversely     S_fibre = 2 eta (I4b - 1) J^(-2/3) (a (x) a - I4/3 C^-1)
//   isotropic, tension        when I4b = J^(-2/3) a.C.a > 1, else 0
//   only)                     (W_fibre = eta/2 (I4b - 1)^2, Taylor et al. 2009, NiftySim's TI law);
//   viscoelastic (Prony     q_i: the relaxed part of S_iso, per element, integrated exactly for a
//   series on S_iso)          stress constant over each step:
//                             q_i^n = d_i q_i^(n-1) + g_i (1 - d_i) S_iso^n,  d_i = exp(-dt / tau_i),
//                           so a held strain relaxes as G(t) = 1 - sum_i g_i (1 - exp(-t / tau_i)).
//
// mu is the instantaneous shear modulus; a viscoelastic set relaxes to
// mu (1 - sum g_i). A kernel is instantiated for the terms a scene has
// (LawTerms): a Neo-Hookean scene runs the Neo-Hookean kernel and carries
// no fibre or Prony data. Elements of a set without a term run it with
// neutral parameters (eta = 0, g_i = 0), so a warp never branches on the law.
#pragma once

#include <cmath>

#include "core/cube_root.hpp"
#include "core/vec.hpp"

namespace tissue {

/// Most Prony terms a viscoelastic set may give.
inline constexpr int kMaxProny = 4;

// ---- the law terms' store, written once ----------------------------------
// Every array the optional terms keep, one line each: X(kind, name, len).
// kind: Scalar (the backend's T), Index (index_t) or Real (double, kept in
// double); len: its length, from a model m. An array is empty when no set
// uses its term. From these lists come TissueModel's and TissueState's
// members (core/model.hpp, core/state.hpp), convert(), and the CUDA store's
// device arrays, uploads and LawView pointers (cuda/device_store.*,
// cuda/views.hpp): a new term's data is a line here.
//
// Model (read-only after build_model; set_time_step rewrites the decays and gains):
//   fibre        4 x n_elems: a_x, a_y, a_z, eta (Pa); eta = 0 in the sets without fibres
//   visco_slot   the Prony state slot of each element, -1 elastic (n_elems)
//   prony_g      g_i per slot, component-major (n_prony x n_visco); g = 0: no such term
//   prony_tau    tau_i per slot (n_prony x n_visco) s
//   prony_decay  exp(-dt / tau_i) per slot (n_prony x n_visco)
//   prony_gain   g_i (1 - exp(-dt / tau_i)) per slot (n_prony x n_visco)
#define TISSUE_LAW_MODEL_FIELDS(X)                              \
  X(Scalar, fibre, m.has_fibre() ? 4 * std::size_t(m.n_elems) : 0) \
  X(Index, visco_slot, m.has_visco() ? std::size_t(m.n_elems) : 0) \
  X(Real, prony_g, std::size_t(m.n_prony) * m.n_visco)           \
  X(Real, prony_tau, std::size_t(m.n_prony) * m.n_visco)         \
  X(Scalar, prony_decay, std::size_t(m.n_prony) * m.n_visco)     \
  X(Scalar, prony_gain, std::size_t(m.n_prony) * m.n_visco)
// State (per step; zero after upload and set_displacements):
//   visco_q      the Prony state q_i by slot: q[(6 i + c) * n_visco + slot] (6 n_prony x n_visco) Pa
#define TISSUE_LAW_STATE_FIELDS(X) X(Scalar, visco_q, std::size_t(kSymComponents) * m.n_prony * m.n_visco)

/// The element type of a law array of kind K for a backend of scalar T.
template <class T>
struct LawFieldTypes {
  using Scalar = T;
  using Index = index_t;
  using Real = double;
};

/// The terms a kernel instantiation computes (compile time).
template <bool Fibre, bool Visco>
struct LawTerms {
  static constexpr bool fibre = Fibre, visco = Visco;
};
using NeoHookeanTerms = LawTerms<false, false>;

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

/// The strain energy density (J/m^3) of the optional elastic terms, from
/// C = F^T F and J^(-2/3) (the Neo-Hookean part is core/energy.hpp's). The
/// Prony branches' energy is prony_energy's (docs/materials.md: a
/// viscoelastic set reports its instantaneous elastic energy here).
template <class Terms, class T>
TISSUE_HD T extra_energy(const Mat3<T>& C, T j23, const ElementLaw<T>& law) {
  if constexpr (Terms::fibre) return fibre_energy(C, j23, law.a, law.eta);
  return T(0);
}

/// Stable-step stiffness added by the fibre term to the P-wave modulus
/// lambda + 2 mu (Pa): 16 eta / 9 at rest along the fibre, taken as 4 eta
/// to cover the stiffening of stretched fibres (docs/materials.md).
inline double fibre_wave_modulus(double eta) { return 4 * eta; }

/// The Prony constants of one term for step dt (s): decay d = exp(-dt /
/// tau) and gain g (1 - d).
inline void prony_constants(double g, double tau, double dt, double* decay, double* gain) {
  *decay = std::exp(-dt / tau);
  *gain = g * -std::expm1(-dt / tau);
}

}  // namespace tissue
