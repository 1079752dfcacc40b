#include "cpu/element_lanes.hpp"

#include "core/energy.hpp"
#include "core/tet.hpp"

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(__SANITIZE_THREAD__)
#define TISSUE_SIMD_CLONES __attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#else
#define TISSUE_SIMD_CLONES
#endif

namespace tissue::cpu {
namespace {

/// Lane l's shape gradients and deformation gradient as core's arguments.
template <class T>
inline void lane_dN(const ElementLanes<T>& b, int l, T dN[12]) {
  TISSUE_UNROLL
  for (int k = 0; k < 12; ++k) dN[k] = b.dN(k, l);
}

template <class T>
inline Mat3<T> lane_F(const ElementLanes<T>& b, int l) {
  Mat3<T> F;
  TISSUE_UNROLL
  for (int k = 0; k < 9; ++k) F.m[k] = b.F(k, l);
  return F;
}

/// Lane l's law terms as core's ElementLaw.
template <class Terms, class T>
inline ElementLaw<T> lane_law(const LawLanes<T>& w, int l) {
  ElementLaw<T> law;
  if constexpr (Terms::fibre) {
    law.a = {w.a[0][l], w.a[1][l], w.a[2][l]};
    law.eta = w.eta[l];
  }
  if constexpr (Terms::visco) {
    TISSUE_UNROLL
    for (int i = 0; i < kMaxProny; ++i) {
      law.decay[i] = w.decay[i][l];
      law.gain[i] = w.gain[i][l];
      TISSUE_UNROLL
      for (int c = 0; c < kSymComponents; ++c) law.q[i][c] = w.q[kSymComponents * i + c][l];
    }
  }
  return law;
}

template <class T>
inline void store_forces(ElementLanes<T>& b, int l, const Vec3<T> f[4]) {
  TISSUE_UNROLL
  for (int a = 0; a < 4; ++a) {
    b.f[3 * a][l] = f[a].x;
    b.f[3 * a + 1][l] = f[a].y;
    b.f[3 * a + 2][l] = f[a].z;
  }
}

}  // namespace

template <class T>
TISSUE_SIMD_CLONES void lanes_corner_u(const T* u, index_t n, const index_t* en, index_t ne, T (&out)[12][kLanes]) {
#pragma GCC ivdep
  for (int l = 0; l < kLanes; ++l) load_corner_u(u, std::size_t(n), en, std::size_t(ne), std::size_t(l), out, l);
}

template <class T>
TISSUE_SIMD_CLONES void lanes_pbar(const T* node_p, const index_t* en, index_t ne, T (&pbar)[kLanes]) {
#pragma GCC ivdep
  for (int l = 0; l < kLanes; ++l) pbar[l] = corner_pressure_mean(node_p, en, std::size_t(ne), std::size_t(l));
}

template <class T>
TISSUE_SIMD_CLONES void lanes_pressure(ElementLanes<T>& b) {
#pragma GCC ivdep
  for (int l = 0; l < kLanes; ++l) {
    Vec3<T> ue[4];
    T dN[12];
    TISSUE_UNROLL
    for (int a = 0; a < 4; ++a) ue[a] = {b.u[3 * a][l], b.u[3 * a + 1][l], b.u[3 * a + 2][l]};
    lane_dN(b, l, dN);
    const Mat3<T> F = deformation_gradient(ue, dN);
    const T J = det(F);
    TISSUE_UNROLL
    for (int k = 0; k < 9; ++k) b.F(k, l) = F.m[k];
    b.J(0, l) = J;
    b.dv(0, l) = (J - T(1)) * b.V(0, l);
  }
}

/// Pass 3's lane loop for the terms Terms instantiates (w: their lanes;
/// unused for Neo-Hookean, whose lanes call core's Neo-Hookean routines
/// and touch no law data). Inlined into each SIMD clone below.
template <class T, bool kIanp, class Terms>
__attribute__((always_inline)) inline void forces_loop(ElementLanes<T>& b, LawLanes<T>* w) {
  constexpr bool kLaw = Terms::fibre || Terms::visco;
#pragma GCC ivdep
  for (int l = 0; l < kLanes; ++l) {
    Vec3<T> f[4];
    T dN[12];
    lane_dN(b, l, dN);
    const Mat3<T> F = lane_F(b, l);
    if constexpr (kLaw) {
      ElementLaw<T> law = lane_law<Terms>(*w, l);
      if constexpr (kIanp)
        b.ret[l] = ianp_element_forces<Terms>(F, dN, b.V(0, l), b.mu(0, l), b.K(0, l), b.pbar[l], f, law);
      else
        b.ret[l] = plain_element_forces<Terms>(F, dN, b.V(0, l), b.mu(0, l), b.K(0, l), f, law);
      if constexpr (Terms::visco) {
        TISSUE_UNROLL
        for (int i = 0; i < kMaxProny; ++i)
          TISSUE_UNROLL
          for (int c = 0; c < kSymComponents; ++c) w->q[kSymComponents * i + c][l] = law.q[i][c];
      }
    } else if constexpr (kIanp) {
      b.ret[l] = ianp_element_forces(F, dN, b.V(0, l), b.mu(0, l), b.K(0, l), b.pbar[l], f);
    } else {
      b.ret[l] = plain_element_forces(F, dN, b.V(0, l), b.mu(0, l), b.K(0, l), f);
    }
    store_forces(b, l, f);
  }
}

template <class T, bool kIanp>
TISSUE_SIMD_CLONES void lanes_forces(ElementLanes<T>& b) {
  forces_loop<T, kIanp, NeoHookeanTerms>(b, nullptr);
}

template <class T, bool kIanp, class Terms>
TISSUE_SIMD_CLONES void lanes_forces_law(ElementLanes<T>& b, LawLanes<T>& w) {
  forces_loop<T, kIanp, Terms>(b, &w);
}

/// The energy's lane loop: Neo-Hookean (w unused) or with the fibre term.
template <class T, bool kIanp, bool kFibre>
__attribute__((always_inline)) inline void energy_loop(ElementLanes<T>& b, const LawLanes<T>* w) {
  using Fibre = LawTerms<true, false>;
#pragma GCC ivdep
  for (int l = 0; l < kLanes; ++l) {
    const Mat3<T> F = lane_F(b, l);
    const T J = det(F);
    const T Jbar = kIanp ? T(1) + b.pbar[l] / b.K(0, l) : J;
    if constexpr (kFibre)
      b.ret[l] = element_strain_energy<Fibre>(F, J, Jbar, b.V(0, l), b.mu(0, l), b.K(0, l), lane_law<Fibre>(*w, l));
    else
      b.ret[l] = element_strain_energy(F, J, Jbar, b.V(0, l), b.mu(0, l), b.K(0, l));
  }
}

template <class T, bool kIanp>
TISSUE_SIMD_CLONES void lanes_energy(ElementLanes<T>& b) {
  energy_loop<T, kIanp, false>(b, nullptr);
}

template <class T, bool kIanp>
TISSUE_SIMD_CLONES void lanes_energy_fibre(ElementLanes<T>& b, const LawLanes<T>& w) {
  energy_loop<T, kIanp, true>(b, &w);
}

template <class T, bool kIanp>
TISSUE_SIMD_CLONES void lanes_prony_energy(ElementLanes<T>& b, const LawLanes<T>& w, const T (&g)[kMaxProny][kLanes],
                                           const T (&tau)[kMaxProny][kLanes], T (&power)[kLanes],
                                           T (&stored)[kLanes]) {
  using Visco = LawTerms<false, true>;
#pragma GCC ivdep
  for (int l = 0; l < kLanes; ++l) {
    const Mat3<T> F = lane_F(b, l);
    const T J = det(F);
    const T Jbar = kIanp ? T(1) + b.pbar[l] / b.K(0, l) : J;
    const ElementLaw<T> law = lane_law<Visco>(w, l);
    T gl[kMaxProny], tl[kMaxProny];
    TISSUE_UNROLL
    for (int i = 0; i < kMaxProny; ++i) {
      gl[i] = g[i][l];
      tl[i] = tau[i][l];
    }
    const PronyEnergy e = element_prony_energy(F, J, Jbar, b.V(0, l), b.mu(0, l), law.q, gl, tl);
    power[l] = T(e.power);
    stored[l] = T(e.stored);
  }
}

#define TISSUE_CPU_LANES_LAW(T, I)                                                            \
  template void lanes_forces_law<T, I, LawTerms<true, false>>(ElementLanes<T>&, LawLanes<T>&); \
  template void lanes_forces_law<T, I, LawTerms<false, true>>(ElementLanes<T>&, LawLanes<T>&); \
  template void lanes_forces_law<T, I, LawTerms<true, true>>(ElementLanes<T>&, LawLanes<T>&);  \
  template void lanes_energy_fibre<T, I>(ElementLanes<T>&, const LawLanes<T>&);                \
  template void lanes_prony_energy<T, I>(ElementLanes<T>&, const LawLanes<T>&, const T(&)[kMaxProny][kLanes], \
                                         const T(&)[kMaxProny][kLanes], T(&)[kLanes], T(&)[kLanes]);
TISSUE_CPU_LANES_LAW(float, true)
TISSUE_CPU_LANES_LAW(float, false)
TISSUE_CPU_LANES_LAW(double, true)
TISSUE_CPU_LANES_LAW(double, false)
#undef TISSUE_CPU_LANES_LAW

#define TISSUE_CPU_LANES(T)                         \
  template void lanes_corner_u<T>(const T*, index_t, const index_t*, index_t, T(&)[12][kLanes]); \
  template void lanes_pbar<T>(const T*, const index_t*, index_t, T(&)[kLanes]); \
  template void lanes_pressure<T>(ElementLanes<T>&); \
  template void lanes_forces<T, true>(ElementLanes<T>&); \
  template void lanes_forces<T, false>(ElementLanes<T>&); \
  template void lanes_energy<T, true>(ElementLanes<T>&); \
  template void lanes_energy<T, false>(ElementLanes<T>&);
TISSUE_CPU_LANES(float)
TISSUE_CPU_LANES(double)
#undef TISSUE_CPU_LANES

}  // namespace tissue::cpu
