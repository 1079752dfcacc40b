// Vectorised element loops of the cpu backend. An element pass gathers the
// inputs of kLanes elements into lane arrays (ElementLanes), runs core's
// per-element math over the lanes in one SIMD loop, and scatters the outputs
// back. The math is core/tet.hpp's and core/energy.hpp's, unchanged: those
// functions are branch-free and call no libm function (core/cube_root.hpp),
// so GCC vectorises the lane loop across elements.
//
// Each lane kernel (element_lanes_kernels.inc) is compiled three times (GCC target_clones: x86-64-v4 =
// AVX-512, x86-64-v3 = AVX2 + FMA, and the baseline x86-64 = SSE2) and the
// loader picks the best the CPU runs, so one binary is portable and fast.
// The clones may round differently (FMA contraction), so results can differ
// in the last bits between CPUs of different levels; on one machine they
// are deterministic. Where target_clones is unavailable (not GCC/x86-64,
// or under ThreadSanitizer, whose runtime starts after the ifunc resolvers
// run), the kernels are compiled once for the build's target.
//
// A full run's gathers (the corners' displacements of pass 1, the nodal
// pressures of pass 3) are cloned too, so that the AVX-512 and AVX2 clones
// load a lane per element with vector gathers. The file is tuned for a
// recent Xeon (cpu/CMakeLists.txt): with GCC 12's generic tuning the
// vectoriser emulates gathers with scalar loads and inserts. Tuning picks
// instructions and their order, not the arithmetic: the same bits.
#pragma once

#include <cstddef>

#include "core/model.hpp"

namespace tissue::cpu {

/// Elements per batch: a multiple of every SIMD width in use (16 floats or
/// 8 doubles per AVX-512 register).
inline constexpr int kLanes = 16;

/// A per-element field seen by a batch: row k (component), lane l at
/// p[k * stride + l]. Either the model's or the state's own array at the
/// batch's first element (stride n_elems), or a batch buffer (stride kLanes).
template <class T>
struct Rows {
  T* p = nullptr;
  std::size_t stride = 0;
  T& operator()(int k, int l) const { return p[k * stride + l]; }
};

/// One batch of up to kLanes elements. When the batch is a full run of
/// consecutive elements (always on the whole mesh; ascending region lists
/// have long runs) the views point straight into the model's and state's
/// arrays, which are component-major and so already lane-major: nothing is
/// copied. Otherwise the batch gathers into its buffers and the views point
/// there; lanes past `count` then hold an undeformed element of zero volume
/// (u = 0, F = I, K = mu = 1), so that the math stays finite on them.
template <class T>
struct alignas(64) ElementLanes {
  Rows<const T> dN, V, mu, K;  ///< shape gradients (12 rows, 1/m), volume (m^3), moduli (Pa)
  Rows<T> F;                   ///< deformation gradient (9 rows, k = 3 i + j): pass 1 writes, pass 3 and energy read
  Rows<T> J, dv;               ///< pass 1's det F and volume change (J_e - 1) V_e (m^3)
  T u[12][kLanes];             ///< corner displacements, k = 3 * corner + axis (m): pass 1
  T pbar[kLanes];              ///< averaged nodal pressure (Pa): pass 3 and the energy
  T f[12][kLanes];             ///< out: element nodal forces, k = 3 * corner + axis (N): pass 3
  T ret[kLanes];               ///< out: pass 3's returned J; the energy's V W (J)
  int count = 0;               ///< elements in the batch (<= kLanes)
  bool direct = false;         ///< a full run: the views are the arrays themselves
  // buffers behind the views of a gathered batch
  T dN_buf[12][kLanes], V_buf[kLanes], mu_buf[kLanes], K_buf[kLanes], F_buf[9][kLanes], J_buf[kLanes], dv_buf[kLanes];
};

/// Copies `rows` rows of a per-element array src (rows x n_elems,
/// component-major) at elems[0..count) into dst (rows x kLanes).
template <class T>
inline void gather_rows(const T* src, std::size_t ne, int rows, const index_t* elems, int count, T* dst) {
  for (int l = 0; l < count; ++l)
    for (int k = 0; k < rows; ++k) dst[k * kLanes + l] = src[k * ne + std::size_t(elems[l])];
}

/// The inverse: lanes 0..count of src (rows x kLanes) into dst (rows x n_elems).
template <class T>
inline void scatter_rows(const T* src, std::size_t ne, int rows, const index_t* elems, int count, T* dst) {
  for (int l = 0; l < count; ++l)
    for (int k = 0; k < rows; ++k) dst[k * ne + std::size_t(elems[l])] = src[k * kLanes + l];
}

/// Starts a batch of elems[0..count): the model's dN, V, mu and K, viewed
/// in place for a full run, else gathered (with the padding lanes).
template <class T>
void begin_lanes(const TissueModel<T>& m, const index_t* elems, int count, ElementLanes<T>& b) {
  const std::size_t ne = m.n_elems;
  b.count = count;
  b.direct = count == kLanes && elems[count - 1] - elems[0] == count - 1;
  if (b.direct) {
    const std::size_t e0 = elems[0];
    b.dN = {m.dndx.data() + e0, ne};
    b.V = {m.volume.data() + e0, ne};
    b.mu = {m.mu.data() + e0, ne};
    b.K = {m.K.data() + e0, ne};
    return;
  }
  gather_rows(m.dndx.data(), ne, 12, elems, count, &b.dN_buf[0][0]);
  gather_rows(m.volume.data(), ne, 1, elems, count, b.V_buf);
  gather_rows(m.mu.data(), ne, 1, elems, count, b.mu_buf);
  gather_rows(m.K.data(), ne, 1, elems, count, b.K_buf);
  for (int l = count; l < kLanes; ++l) {
    for (int k = 0; k < 12; ++k) b.u[k][l] = b.dN_buf[k][l] = T(0);
    for (int k = 0; k < 9; ++k) b.F_buf[k][l] = k % 4 == 0 ? T(1) : T(0);
    b.V_buf[l] = b.pbar[l] = T(0);
    b.mu_buf[l] = b.K_buf[l] = T(1);
  }
  b.dN = {&b.dN_buf[0][0], kLanes};
  b.V = {b.V_buf, kLanes};
  b.mu = {b.mu_buf, kLanes};
  b.K = {b.K_buf, kLanes};
}

/// Element e's corner displacements from u (3 x n_nodes, component-major)
/// into lane l of out (row 3 corner + axis); en: the corner rows
/// (TissueModel::elem_nodes, row a at en[a ne]).
template <class T>
inline void load_corner_u(const T* u, std::size_t n, const index_t* en, std::size_t ne, std::size_t e,
                          T (&out)[12][kLanes], int l) {
  TISSUE_UNROLL
  for (int a = 0; a < 4; ++a) {
    const std::size_t i = std::size_t(en[a * ne + e]);
    TISSUE_UNROLL
    for (int c = 0; c < 3; ++c) out[3 * a + c][l] = u[c * n + i];
  }
}

/// Element e's pbar: the mean of its four corners' nodal pressures, summed
/// in corner order (en as above).
template <class T>
inline T corner_pressure_mean(const T* node_p, const index_t* en, std::size_t ne, std::size_t e) {
  return T(0.25) * (((node_p[en[e]] + node_p[en[ne + e]]) + node_p[en[2 * ne + e]]) + node_p[en[3 * ne + e]]);
}

template <class T>
struct LawLanes;  // below

#include "cpu/element_lanes_api.inc"  // the lane kernels (lanes_corner_u, lanes_pbar, lanes_pressure, ...)

/// A batch for pass 1: begin_lanes, the corner displacements from u (3 x
/// n_nodes, component-major), and the output views: elem_J, elem_dv
/// (n_elems) and elem_F (9 x n_elems) themselves for a full run, else the
/// buffers, which finish_pressure_lanes scatters.
template <class T>
void gather_pressure_lanes(const TissueModel<T>& m, const T* u, const index_t* elems, int count, T* elem_J,
                           T* elem_dv, T* elem_F, ElementLanes<T>& b) {
  begin_lanes(m, elems, count, b);
  const index_t n = m.n_nodes, ne = m.n_elems;
  const index_t* en = m.elem_nodes.data();
  if (b.direct) {
    lanes_corner_u(u, n, en + elems[0], ne, b.u);
    b.F = {elem_F + elems[0], std::size_t(ne)};
    b.J = {elem_J + elems[0], std::size_t(ne)};
    b.dv = {elem_dv + elems[0], std::size_t(ne)};
  } else {
    for (int l = 0; l < count; ++l) load_corner_u(u, n, en, ne, elems[l], b.u, l);
    b.F = {&b.F_buf[0][0], kLanes};
    b.J = {b.J_buf, kLanes};
    b.dv = {b.dv_buf, kLanes};
  }
}

/// After pass 1's kernel: scatters a gathered batch's outputs (a full run
/// wrote in place).
template <class T>
void finish_pressure_lanes(const TissueModel<T>& m, const index_t* elems, T* elem_J, T* elem_dv, T* elem_F,
                           const ElementLanes<T>& b) {
  if (b.direct) return;
  const std::size_t ne = m.n_elems;
  scatter_rows(&b.F_buf[0][0], ne, 9, elems, b.count, elem_F);
  scatter_rows(b.J_buf, ne, 1, elems, b.count, elem_J);
  scatter_rows(b.dv_buf, ne, 1, elems, b.count, elem_dv);
}

/// A batch for pass 3 or the energy: begin_lanes, pass 1's deformation
/// gradients elem_F (9 x n_elems) and, with node_p (IANP), pbar, the mean
/// of the element's four nodal pressures.
template <class T>
void gather_force_lanes(const TissueModel<T>& m, T* elem_F, const T* node_p, const index_t* elems, int count,
                        ElementLanes<T>& b) {
  begin_lanes(m, elems, count, b);
  const index_t ne = m.n_elems;
  if (b.direct) {
    b.F = {elem_F + elems[0], std::size_t(ne)};
  } else {
    gather_rows(elem_F, ne, 9, elems, count, &b.F_buf[0][0]);
    b.F = {&b.F_buf[0][0], kLanes};
  }
  if (!node_p) return;
  const index_t* en = m.elem_nodes.data();
  if (b.direct) {
    lanes_pbar(node_p, en + elems[0], ne, b.pbar);
    return;
  }
  for (int l = 0; l < count; ++l) b.pbar[l] = corner_pressure_mean(node_p, en, ne, elems[l]);
}

/// The optional law terms of a batch (core/material.hpp), gathered only by
/// the kernels that instantiate them: fibre direction and stiffness, the
/// Prony constants and state. Lanes without a term (another set, padding)
/// hold neutral values: eta = 0, gain = decay = 0, q = 0.
template <class T>
struct alignas(64) LawLanes {
  T a[3][kLanes], eta[kLanes];
  T decay[kMaxProny][kLanes], gain[kMaxProny][kLanes];
  T q[kMaxProny * kSymComponents][kLanes];  ///< row 6 i + c
  index_t slot[kLanes];                     ///< Prony state slot, -1 none
  bool run = false;                         ///< every lane viscoelastic, slots slot[0] + l: rows copy whole
};

/// Gathers the batch's law terms that Terms instantiates: fibres from the
/// model, the Prony constants and the state q (6 n_prony x n_visco) by slot;
/// terms beyond the model's n_prony are neutral (0).
template <class Terms, class T>
void gather_law_lanes(const TissueModel<T>& m, const T* q, const index_t* elems, int count, LawLanes<T>& w) {
  const std::size_t ne = m.n_elems, nv = m.n_visco;
  const int np = m.n_prony;
  if constexpr (Terms::template has<FibreTerm>) {
    for (int l = 0; l < kLanes; ++l) {
      const bool in = l < count;
      for (int c = 0; c < 3; ++c) w.a[c][l] = in ? m.fibre[c * ne + elems[l]] : T(0);
      w.eta[l] = in ? m.fibre[3 * ne + elems[l]] : T(0);
    }
  }
  if constexpr (Terms::template has<PronyTerm>) {
    // a full batch whose slots are consecutive (build_model numbers them in element order, so a run of
    // viscoelastic elements has them): its rows are contiguous and copy as vectors
    const index_t v0 = m.visco_slot[elems[0]];
    w.run = count == kLanes && v0 >= 0;
    for (int l = 1; l < kLanes && w.run; ++l) w.run = m.visco_slot[elems[l]] == v0 + l;
    if (w.run) {
      for (int l = 0; l < kLanes; ++l) w.slot[l] = v0 + l;
      for (int i = 0; i < kMaxProny; ++i) {
        if (i < np) {
          const T* d = m.prony_decay.data() + i * nv + v0;
          const T* g = m.prony_gain.data() + i * nv + v0;
          for (int l = 0; l < kLanes; ++l) {
            w.decay[i][l] = d[l];
            w.gain[i][l] = g[l];
          }
        } else {
          for (int l = 0; l < kLanes; ++l) w.decay[i][l] = w.gain[i][l] = T(0);
        }
      }
      for (int k = 0; k < kMaxProny * kSymComponents; ++k) {
        if (k < np * kSymComponents) {
          const T* row = q + k * nv + v0;
          for (int l = 0; l < kLanes; ++l) w.q[k][l] = row[l];
        } else {
          for (int l = 0; l < kLanes; ++l) w.q[k][l] = T(0);
        }
      }
      return;
    }
    for (int l = 0; l < kLanes; ++l) {
      const index_t v = l < count ? m.visco_slot[elems[l]] : -1;
      w.slot[l] = v;
      for (int i = 0; i < kMaxProny; ++i) {
        w.decay[i][l] = v < 0 || i >= np ? T(0) : m.prony_decay[i * nv + v];
        w.gain[i][l] = v < 0 || i >= np ? T(0) : m.prony_gain[i * nv + v];
      }
      for (int k = 0; k < kMaxProny * kSymComponents; ++k)
        w.q[k][l] = v < 0 || k >= np * kSymComponents ? T(0) : q[k * nv + v];
    }
  }
}

/// Writes the advanced Prony state of the batch's viscoelastic lanes back.
template <class Terms, class T>
void scatter_law_lanes(const TissueModel<T>& m, T* q, const LawLanes<T>& w) {
  if constexpr (Terms::template has<PronyTerm>) {
    const std::size_t nv = m.n_visco;
    if (w.run) {
      for (int k = 0; k < m.n_prony * kSymComponents; ++k) {
        T* row = q + k * nv + w.slot[0];
        for (int l = 0; l < kLanes; ++l) row[l] = w.q[k][l];
      }
      return;
    }
    for (int l = 0; l < kLanes; ++l) {
      const index_t v = w.slot[l];
      if (v < 0) continue;
      for (int k = 0; k < m.n_prony * kSymComponents; ++k) q[k * nv + v] = w.q[k][l];
    }
  }
}

/// Which compilation of the lane kernels (element_lanes_api.inc) runs. They are compiled
/// twice from one source: tuned for a recent Xeon (its vector gathers:
/// docs/benchmarks/README.md, "Vector gathers on the cpu"), and under the
/// compiler's generic tuning, with which an AMD EPYC (family 26, Zen 5
/// class) ran 15-29 % more steps a second on one thread ("The cpu's tuning
/// by vendor"). The tuning chooses instructions, not arithmetic: both give
/// the same bits (CpuLanes.BothTuningsGiveTheSameBits).
enum class LanesTuning { Xeon, Generic };
/// The one in use: set_lanes_tuning's, else the environment's
/// TISSUE_CPU_TUNING (xeon | generic; anything else throws
/// std::invalid_argument at the first call), else Xeon on an Intel CPU and
/// Generic on any other.
LanesTuning lanes_tuning();
/// Tests and benchmarks: runs the other compilation (process-wide; call it
/// between advances, not while a pass runs).
void set_lanes_tuning(LanesTuning t);
const char* to_string(LanesTuning t);  ///< "xeon", "generic"

}  // namespace tissue::cpu
