// Vectorised element loops of the cpu backend. An element pass gathers the
// inputs of kLanes elements into lane arrays (ElementLanes), runs core's
// per-element math over the lanes in one SIMD loop, and scatters the outputs
// back. The math is core/tet.hpp's and core/energy.hpp's, unchanged: those
// functions are branch-free and call no libm function (core/cube_root.hpp),
// so GCC vectorises the lane loop across elements.
//
// Each lane kernel (element_lanes.cpp) is compiled three times (GCC target_clones: x86-64-v4 =
// AVX-512, x86-64-v3 = AVX2 + FMA, and the baseline x86-64 = SSE2) and the
// loader picks the best the CPU runs, so one binary is portable and fast.
// The clones may round differently (FMA contraction), so results can differ
// in the last bits between CPUs of different levels; on one machine they
// are deterministic. Where target_clones is unavailable (not GCC/x86-64,
// or under ThreadSanitizer, whose runtime starts after the ifunc resolvers
// run), the kernels are compiled once for the build's target.
#pragma once

#include <cstddef>

#include "core/model.hpp"

namespace tissue::cpu {

/// Elements per batch: a multiple of every SIMD width in use (16 floats or
/// 8 doubles per AVX-512 register).
inline constexpr int kLanes = 16;

/// Inputs and outputs of up to kLanes elements, lane-major ([field][lane]).
/// Lanes past `count` hold an undeformed element of zero volume (u = 0,
/// F = I, K = mu = 1), so that the math stays finite on them.
template <class T>
struct alignas(64) ElementLanes {
  T u[12][kLanes];   ///< corner displacements, k = 3 * corner + axis (m); pass 1 and the energy
  T F[9][kLanes];    ///< deformation gradient, k = 3 i + j: pass 1's output, pass 3's input
  T dN[12][kLanes];  ///< shape gradients, k = 3 * corner + axis (1/m)
  T V[kLanes], mu[kLanes], K[kLanes];  ///< m^3, Pa, Pa
  T pbar[kLanes];    ///< averaged nodal pressure (Pa); pass 3 and the energy
  T f[12][kLanes];   ///< out: element nodal forces, k = 3 * corner + axis (N)
  T J[kLanes];       ///< out: det F (pass 3: ianp_element_forces' return value)
  T out[kLanes];     ///< out: pass 1 p_e V_e (N m); energy: V W (J)
  int count = 0;     ///< elements in the batch (<= kLanes)
  bool run = false;  ///< the batch is consecutive elements elems[0] .. elems[0] + count - 1
};

/// Copies `rows` rows of a per-element array src (rows x n_elems,
/// component-major) at the batch's elements into dst (rows x kLanes):
/// straight row copies for a run of consecutive elements (always on the
/// whole mesh; ascending region lists have long runs), else one element at
/// a time.
template <class T>
inline void gather_rows(const T* src, std::size_t ne, int rows, const index_t* elems, const ElementLanes<T>& b,
                        T* dst) {
  if (b.run && b.count == kLanes) {  // a fixed trip count: whole-vector copies
    src += elems[0];
    for (int k = 0; k < rows; ++k)
      for (int l = 0; l < kLanes; ++l) dst[k * kLanes + l] = src[k * ne + l];
  } else if (b.run) {
    for (int k = 0; k < rows; ++k)
      for (int l = 0; l < b.count; ++l) dst[k * kLanes + l] = src[k * ne + std::size_t(elems[0]) + l];
  } else {
    for (int l = 0; l < b.count; ++l)
      for (int k = 0; k < rows; ++k) dst[k * kLanes + l] = src[k * ne + std::size_t(elems[l])];
  }
}

/// The inverse of gather_rows: src (rows x kLanes) into dst (rows x n_elems).
template <class T>
inline void scatter_rows(const T* src, std::size_t ne, int rows, const index_t* elems, const ElementLanes<T>& b,
                         T* dst) {
  if (b.run && b.count == kLanes) {
    dst += elems[0];
    for (int k = 0; k < rows; ++k)
      for (int l = 0; l < kLanes; ++l) dst[k * ne + l] = src[k * kLanes + l];
  } else if (b.run) {
    for (int k = 0; k < rows; ++k)
      for (int l = 0; l < b.count; ++l) dst[k * ne + std::size_t(elems[0]) + l] = src[k * kLanes + l];
  } else {
    for (int l = 0; l < b.count; ++l)
      for (int k = 0; k < rows; ++k) dst[k * ne + std::size_t(elems[l])] = src[k * kLanes + l];
  }
}

/// Starts a batch of elems[0..count): count, run, the model's dN, V, mu and
/// K, and the padding lanes.
template <class T>
void begin_lanes(const TissueModel<T>& m, const index_t* elems, int count, ElementLanes<T>& b) {
  const std::size_t ne = m.n_elems;
  b.count = count;
  b.run = elems[count - 1] - elems[0] == count - 1;
  gather_rows(m.dndx.data(), ne, 12, elems, b, &b.dN[0][0]);
  gather_rows(m.volume.data(), ne, 1, elems, b, b.V);
  gather_rows(m.mu.data(), ne, 1, elems, b, b.mu);
  gather_rows(m.K.data(), ne, 1, elems, b, b.K);
  for (int l = count; l < kLanes; ++l) {
    for (int k = 0; k < 12; ++k) b.u[k][l] = b.dN[k][l] = T(0);
    for (int k = 0; k < 9; ++k) b.F[k][l] = k % 4 == 0 ? T(1) : T(0);
    b.V[l] = b.pbar[l] = T(0);
    b.mu[l] = b.K[l] = T(1);
  }
}

/// A batch for pass 1 or the energy: begin_lanes, the corner displacements
/// from u (3 x n_nodes, component-major) and, with node_p (Pa, n_nodes),
/// pbar, the mean of the element's four nodal pressures.
template <class T>
void gather_lanes(const TissueModel<T>& m, const T* u, const T* node_p, const index_t* elems, int count,
                  ElementLanes<T>& b) {
  begin_lanes(m, elems, count, b);
  const index_t n = m.n_nodes, ne = m.n_elems;
  const index_t* en = m.elem_nodes.data();
  for (int l = 0; l < count; ++l) {
    T p = 0;
    for (int a = 0; a < 4; ++a) {
      const index_t i = en[a * ne + elems[l]];
      for (int c = 0; c < 3; ++c) b.u[3 * a + c][l] = u[c * n + i];
      if (node_p) p += node_p[i];
    }
    b.pbar[l] = T(0.25) * p;
  }
}

/// A batch for pass 3: begin_lanes, pass 1's deformation gradients from
/// elem_F (9 x n_elems) and, with node_p (IANP), pbar.
template <class T>
void gather_force_lanes(const TissueModel<T>& m, const T* elem_F, const T* node_p, const index_t* elems, int count,
                        ElementLanes<T>& b) {
  begin_lanes(m, elems, count, b);
  const index_t ne = m.n_elems;
  gather_rows(elem_F, ne, 9, elems, b, &b.F[0][0]);
  if (!node_p) return;
  const index_t* en = m.elem_nodes.data();
  for (int l = 0; l < count; ++l) {
    const index_t e = elems[l];
    b.pbar[l] = T(0.25) * (((node_p[en[e]] + node_p[en[ne + e]]) + node_p[en[2 * ne + e]]) + node_p[en[3 * ne + e]]);
  }
}

/// Pass 1 on every lane: F = deformation_gradient, J = det F,
/// out = volumetric_pressure(J, K) V.
template <class T>
void lanes_pressure(ElementLanes<T>& b);

/// Pass 3 on every lane: ianp_element_forces (or plain_element_forces) of F
/// into f, its returned J into J.
template <class T, bool kIanp>
void lanes_forces(ElementLanes<T>& b);

/// Strain energy on every lane: out = element_strain_energy with Jbar from
/// pbar (IANP) or Jbar = J (plain).
template <class T, bool kIanp>
void lanes_energy(ElementLanes<T>& b);

}  // namespace tissue::cpu
