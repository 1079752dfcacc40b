// Strain energy of one element (docs/design.md section 2's Neo-Hookean W), written
// once for every backend like core/tet.hpp. The energy a TLED step actually
// uses is W(Fbar): for IANP Fbar = (Jbar / J)^(1/3) F with Jbar = 1 + pbar / K,
// and since the isochoric part J^(-2/3) I1 is unchanged by scaling F,
//     V W(Fbar) = V [mu/2 (J^(-2/3) I1 - 3) + K/2 (Jbar - 1)^2],
// with J and I1 of the unmodified F. For plain tets Jbar = J and this is V W(F).
#pragma once

#include <cmath>
#include <limits>

#include "core/cube_root.hpp"
#include "core/material.hpp"
#include "core/vec.hpp"

namespace tissue {

/// Strain energy (J) of an element of reference volume V (m^3), shear and
/// bulk moduli mu, K (Pa), deformation gradient F with J = det F, and the
/// modified Jacobian Jbar of its volumetric term (Jbar = J for plain tets).
/// Returns 0 when J <= 0 or is not finite: an inverted element has no
/// energy of this law; the bad-element flag reports it. Branch-free (a
/// select), like the force routines, so that it vectorises.
template <class Terms, class T>
TISSUE_HD T element_strain_energy(const Mat3<T>& F, T J, T Jbar, T volume, T mu, T K, const ElementLaw<T>& law) {
  const bool ok = (J > T(0)) & (J <= std::numeric_limits<T>::max());  // & not &&: no branch
  const T cbrt_J = cube_root(ok ? J : T(1));
  const Mat3<T> C = transpose(F) * F;
  const T iso = mu / T(2) * (trace(C) / (cbrt_J * cbrt_J) - T(3));
  const T vol = K / T(2) * (Jbar - T(1)) * (Jbar - T(1));
  const T w = iso + vol + extra_energy<Terms>(C, T(1) / (cbrt_J * cbrt_J), law);  // the fibre term
  return ok ? volume * w : T(0);
}

/// Neo-Hookean alone (no law data).
template <class T>
TISSUE_HD T element_strain_energy(const Mat3<T>& F, T J, T Jbar, T volume, T mu, T K) {
  const bool ok = (J > T(0)) & (J <= std::numeric_limits<T>::max());  // & not &&: no branch
  const T cbrt_J = cube_root(ok ? J : T(1));
  const T I1 = trace(transpose(F) * F);
  const T iso = mu / T(2) * (I1 / (cbrt_J * cbrt_J) - T(3));
  const T vol = K / T(2) * (Jbar - T(1)) * (Jbar - T(1));
  return ok ? volume * (iso + vol) : T(0);
}

/// The Prony branches' viscous power (W) and stored energy (J) of an
/// element (core/material.hpp prony_energy) of reference volume V (m^3),
/// instantaneous shear modulus mu (Pa), at F with J = det F and the Jbar
/// of element_strain_energy: pass 3 relaxed S_iso(Fbar) = mu Jbar^(-2/3)
/// (I - I1/3 C^-1) (the scaling to Fbar cancels in I1 C^-1). q: the
/// element's Prony state; g, tau: its set's terms (g = 0: none). Zero when
/// J <= 0 or is not finite.
/// R: the arithmetic of prony_energy. Branch-free, like the energy.
template <class T, class R>
TISSUE_HD PronyEnergy element_prony_energy(const Mat3<T>& F, T J, T Jbar, T volume, T mu,
                                           const T q[kMaxProny][kSymComponents], const R g[kMaxProny],
                                           const R tau[kMaxProny]) {
  const bool ok = (J > T(0)) & (J <= std::numeric_limits<T>::max()) & (Jbar > T(0));  // & not &&: no branch
  const T Js = ok ? J : T(1), Jbars = ok ? Jbar : T(1);
  const Mat3<T> C = transpose(F) * F;
  const T cbrt_Jbar = cube_root(Jbars);
  const PronyEnergy e = prony_energy(isochoric_pk2(C, inverse(C, Js * Js), mu / (cbrt_Jbar * cbrt_Jbar)), q, g, tau, R(mu));
  const double v = ok ? double(volume) : 0.0;
  return {v * e.power, v * e.stored};
}

}  // namespace tissue
