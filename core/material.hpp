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
// mu (1 - sum g_i). Each optional term is its own header under core/laws/
// and an entry of the type list AllLawTerms below. A kernel is
// instantiated for the terms a scene has (LawTerms<...>, picked by
// for_law_terms): a Neo-Hookean scene runs the Neo-Hookean kernel and
// carries no fibre or Prony data. Elements of a set without a term run it
// with neutral parameters (eta = 0, g_i = 0), so a warp never branches on
// the law.
#pragma once

#include <cstddef>
#include <type_traits>

#include "core/cube_root.hpp"
#include "core/laws/element_law.hpp"
#include "core/laws/fibre.hpp"
#include "core/laws/prony.hpp"
#include "core/vec.hpp"

namespace tissue {

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

/// The terms a kernel instantiation computes (compile time): a list of
/// term types (core/laws/), each with in(model) (does a model use it),
/// pk2(point, law) (its share of the PK2 stress), energy(C, J^(-2/3), law)
/// (its strain energy density) and kState (it advances per-step state).
template <class... Term>
struct LawTerms {
  template <class X>
  static constexpr bool has = (std::is_same_v<X, Term> || ...);
  static constexpr bool any = sizeof...(Term) > 0;
  static constexpr bool stateful = (Term::kState || ...);

  /// S += each term's stress, in list order.
  template <class T>
  TISSUE_HD static void add_pk2(Mat3<T>& S, const LawPoint<T>& p, ElementLaw<T>& law) {
    ((S = S + Term::pk2(p, law)), ...);
  }
  /// The terms' strain energy density (J/m^3).
  template <class T>
  TISSUE_HD static T energy(const Mat3<T>& C, T j23, const ElementLaw<T>& law) {
    return (T(0) + ... + Term::energy(C, j23, law));
  }
};
using NeoHookeanTerms = LawTerms<>;

/// Every optional term, in the order their stresses add: a new law is its
/// header in core/laws/ and an entry here.
using AllLawTerms = LawTerms<PronyTerm, FibreTerm>;

namespace detail {
template <class Model, class F, class... Chosen>
void for_law_terms(const Model&, F&& f, LawTerms<Chosen...>, LawTerms<>) {
  f(LawTerms<Chosen...>{});
}
template <class Model, class F, class... Chosen, class Next, class... Rest>
void for_law_terms(const Model& m, F&& f, LawTerms<Chosen...>, LawTerms<Next, Rest...>) {
  if (Next::in(m))
    for_law_terms(m, f, LawTerms<Chosen..., Next>{}, LawTerms<Rest...>{});
  else
    for_law_terms(m, f, LawTerms<Chosen...>{}, LawTerms<Rest...>{});
}
}  // namespace detail

/// Calls f(LawTerms<the terms of Terms that model m uses>{}): the one
/// instantiation a pass runs (every subset of Terms is compiled).
template <class Terms = AllLawTerms, class Model, class F>
void for_law_terms(const Model& m, F&& f) {
  detail::for_law_terms(m, f, LawTerms<>{}, Terms{});
}

/// The strain energy density (J/m^3) of the optional elastic terms, from
/// C = F^T F and J^(-2/3) (the Neo-Hookean part is core/energy.hpp's). The
/// Prony branches' energy is prony_energy's (docs/materials.md: a
/// viscoelastic set reports its instantaneous elastic energy here).
template <class Terms, class T>
TISSUE_HD T extra_energy(const Mat3<T>& C, T j23, const ElementLaw<T>& law) {
  return Terms::energy(C, j23, law);
}

}  // namespace tissue
