#include "cpu/passes.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <utility>

#include "core/tet.hpp"

namespace tissue::cpu {
namespace {

/// Runs body(idx[k]) for every k, in parallel chunks of at least `grain`.
template <class Body>
void for_each_index(std::span<const index_t> idx, std::size_t grain, tbb::affinity_partitioner& part,
                    const Body& body) {
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, idx.size(), grain),
      [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t k = r.begin(); k != r.end(); ++k) body(idx[k]);
      },
      part);
}

/// Corner displacements u (m) and shape gradients dN (4 x 3, 1/m) of element e.
template <class T>
inline void load_element(const TissueModel<T>& m, const T* u, index_t e, Vec3<T> ue[4], T dN[12]) {
  const index_t n = m.n_nodes, ne = m.n_elems;
  for (int a = 0; a < 4; ++a) {
    const index_t i = m.elem_nodes[a * ne + e];
    ue[a] = {u[i], u[n + i], u[2 * n + i]};
  }
  for (int k = 0; k < 12; ++k) dN[k] = m.dndx[k * ne + e];
}

template <class T, bool kIanp>
void element_forces_impl(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> elems,
                         BadElementFlag& bad, tbb::affinity_partitioner& part) {
  const index_t ne = m.n_elems;
  const T* u = s.u.data();
  const T* p = s.node_p.data();
  T* ef = s.elem_f.data();
  for_each_index(elems, kForceGrain, part, [&](index_t e) {
    Vec3<T> ue[4], f[4];
    T dN[12];
    load_element(m, u, e, ue, dN);
    T J;
    if constexpr (kIanp) {
      const index_t* c = m.elem_nodes.data();
      const T pbar = T(0.25) * (((p[c[e]] + p[c[ne + e]]) + p[c[2 * ne + e]]) + p[c[3 * ne + e]]);
      J = ianp_element_forces(ue, dN, m.volume[e], m.mu[e], m.K[e], pbar, f);
    } else {
      J = plain_element_forces(ue, dN, m.volume[e], m.mu[e], m.K[e], f);
    }
    if (!(J > T(0)) || !std::isfinite(J)) bad.record(e, double(J));
    for (int a = 0; a < 4; ++a)
      for (int c = 0; c < 3; ++c) ef[(3 * a + c) * ne + e] = f[a][c];
  });
}

}  // namespace

template <class T>
void element_pressure(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> elems,
                      tbb::affinity_partitioner& part) {
  const T* u = s.u.data();
  T* J_out = s.elem_J.data();
  T* pv_out = s.elem_pv.data();
  for_each_index(elems, kElemGrain, part, [&](index_t e) {
    Vec3<T> ue[4];
    T dN[12];
    load_element(m, u, e, ue, dN);
    const T J = det(deformation_gradient(ue, dN));
    J_out[e] = J;
    pv_out[e] = volumetric_pressure(J, m.K[e]) * m.volume[e];
  });
}

template <class T>
void nodal_pressure(const TissueModel<T>& m, TissueState<T>& s, const std::vector<T>& node_volume,
                    std::span<const index_t> nodes, tbb::affinity_partitioner& part) {
  const index_t* start = m.node_elem_start.data();
  const index_t* list = m.node_elem.data();
  const T* pv = s.elem_pv.data();
  const T* vol = node_volume.data();
  T* p = s.node_p.data();
  for_each_index(nodes, kNodeGrain, part, [&](index_t a) {
    T sum = 0;
    for (index_t k = start[a]; k < start[a + 1]; ++k) sum += pv[list[k] >> 2];
    p[a] = sum / vol[a];
  });
}

template <class T>
void element_forces(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> elems, BadElementFlag& bad,
                    tbb::affinity_partitioner& part) {
  if (m.ianp)
    element_forces_impl<T, true>(m, s, elems, bad, part);
  else
    element_forces_impl<T, false>(m, s, elems, bad, part);
}

template <class T>
void node_update(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> nodes,
                 tbb::affinity_partitioner& part) {
  const index_t n = m.n_nodes, ne = m.n_elems;
  const index_t* start = m.node_elem_start.data();
  const index_t* list = m.node_elem.data();
  const T* ef = s.elem_f.data();
  const T* u = s.u.data();
  const T* u_prev = s.u_prev.data();
  const T* u_held = s.u_held.data();
  const std::uint8_t* held = s.held.data();
  T* f_out = s.f.data();
  T* u_next = s.u_next.data();
  for_each_index(nodes, kNodeGrain, part, [&](index_t a) {
    T f[3] = {0, 0, 0};
    for (index_t k = start[a]; k < start[a + 1]; ++k) {
      const index_t e = list[k] >> 2, corner = list[k] & 3;
      for (int c = 0; c < 3; ++c) f[c] += ef[(3 * corner + c) * ne + e];
    }
    const std::uint8_t h = held[a];
    if (h == kAllAxes) {
      for (int c = 0; c < 3; ++c) {
        f_out[c * n + a] = f[c];
        u_next[c * n + a] = u_held[c * n + a];
      }
      return;
    }
    const CentralDifference<T> cd{m.cd_A[a], m.cd_B[a], m.cd_C[a]};
    for (int c = 0; c < 3; ++c) {
      f_out[c * n + a] = f[c];
      u_next[c * n + a] = (h >> c & 1) ? u_held[c * n + a]
                                       : central_difference_update(cd, -f[c], u[c * n + a], u_prev[c * n + a]);
    }
  });
  std::swap(s.u_prev, s.u);  // u_prev <- u^n
  std::swap(s.u, s.u_next);  // u <- u^{n+1}; u_next now holds u^{n-1} (scratch)
}

#define TISSUE_CPU_PASSES(T)                                                                                      \
  template void element_pressure(const TissueModel<T>&, TissueState<T>&, std::span<const index_t>,                \
                                 tbb::affinity_partitioner&);                                                     \
  template void nodal_pressure(const TissueModel<T>&, TissueState<T>&, const std::vector<T>&,                     \
                               std::span<const index_t>, tbb::affinity_partitioner&);                             \
  template void element_forces(const TissueModel<T>&, TissueState<T>&, std::span<const index_t>, BadElementFlag&, \
                               tbb::affinity_partitioner&);                                                       \
  template void node_update(const TissueModel<T>&, TissueState<T>&, std::span<const index_t>,                     \
                            tbb::affinity_partitioner&);
TISSUE_CPU_PASSES(float)
TISSUE_CPU_PASSES(double)
#undef TISSUE_CPU_PASSES

}  // namespace tissue::cpu
