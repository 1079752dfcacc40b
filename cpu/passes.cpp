#include "cpu/passes.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <type_traits>
#include <utility>

#include "core/node_rules.hpp"
#include "core/tet.hpp"
#include "cpu/element_lanes.hpp"

namespace tissue::cpu {
namespace {

/// A pass's loop over its index list: TBB chunks of at least `grain` entries
/// with the pass's affinity partitioner (Tbb), or the whole list on the
/// calling thread, a team member's slice (Serial). Both call body(begin, end).
struct Tbb {
  tbb::affinity_partitioner& part;
  template <class Body>
  void operator()(std::size_t n, std::size_t grain, const Body& body) const {
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, n, grain),
        [&](const tbb::blocked_range<std::size_t>& r) { body(r.begin(), r.end()); }, part);
  }
};
struct Serial {
  template <class Body>
  void operator()(std::size_t n, std::size_t, const Body& body) const {
    body(std::size_t(0), n);
  }
};

/// Runs body(idx[k]) for every k.
template <class Run, class Body>
void for_each_index(const Run& run, std::span<const index_t> idx, std::size_t grain, const Body& body) {
  run(idx.size(), grain, [&](std::size_t begin, std::size_t end) {
    for (std::size_t k = begin; k != end; ++k) body(idx[k]);
  });
}

/// Runs body(first, count) over consecutive batches of at most kLanes
/// entries of idx (a chunk's last batch may be partial).
template <class Run, class Body>
void for_each_batch(const Run& run, std::span<const index_t> idx, std::size_t grain, const Body& body) {
  run(idx.size(), grain, [&](std::size_t begin, std::size_t end) {
    for (std::size_t k = begin; k < end; k += kLanes)
      body(idx.data() + k, int(std::min<std::size_t>(kLanes, end - k)));
  });
}

/// Pass 3 with the law terms Terms instantiates (core/material.hpp): a
/// Neo-Hookean model runs the plain lane kernel and gathers no law data.
template <class T, bool kIanp, class Terms, class Run>
void element_forces_impl(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> elems,
                         BadElementFlag& bad, const Run& run) {
  constexpr bool kLaw = Terms::any;
  const T* p = kIanp ? s.node_p.data() : nullptr;
  T* fs = s.f_slot.data();
  T* q = s.visco_q.data();
  for_each_batch(run, elems, kForceGrain, [&](const index_t* e, int count) {
    ElementLanes<T> b;
    gather_force_lanes(m, s.elem_F.data(), p, e, count, b);
    if constexpr (kLaw) {
      LawLanes<T> w;
      gather_law_lanes<Terms>(m, q, e, count, w);
      lanes_forces_law<T, kIanp, Terms>(b, w);
      scatter_law_lanes<Terms>(m, q, w);
    } else {
      lanes_forces<T, kIanp>(b);
    }
    for (int l = 0; l < count; ++l) {
      const T J = b.ret[l];
      if (!(J > T(0)) || !std::isfinite(J)) bad.record(e[l], double(J));
      T* f = fs + 12 * size_t(e[l]);  // the element's 12 slots, each thread's own cache lines
      for (int k = 0; k < 12; ++k) f[k] = b.f[k][l];
    }
  });
}

template <class T, bool kIanp, class Run>
void element_forces_terms(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> elems,
                          BadElementFlag& bad, const Run& run) {
  for_law_terms(m, [&](auto terms) { element_forces_impl<T, kIanp, decltype(terms)>(m, s, elems, bad, run); });
}

template <class T, class Run>
void element_pressure_run(const TissueModel<T>& m, const T* u, std::span<const index_t> elems, T* J_out,
                          T* dv_out, T* F_out, const Run& run) {
  for_each_batch(run, elems, kElemGrain, [&](const index_t* e, int count) {
    ElementLanes<T> b;
    gather_pressure_lanes(m, u, e, count, J_out, dv_out, F_out, b);
    lanes_pressure(b);
    finish_pressure_lanes(m, e, J_out, dv_out, F_out, b);
  });
}

template <class T, class Run>
void nodal_pressure_run(const TissueModel<T>& m, const T* dv, const std::vector<T>& node_divisor,
                        std::span<const index_t> nodes, T* p, const Run& run) {
  const index_t* start = m.node_elem_start.data();
  const index_t* list = m.node_elem.data();
  const T* divisor = node_divisor.data();
  for_each_index(run, nodes, kNodeGrain, [&](index_t a) {
    T sum = 0;
    for (index_t k = start[a]; k < start[a + 1]; ++k) sum += dv[incident_element(list[k])];
    p[a] = sum / divisor[a];
  });
}

template <class T, class Run>
void element_forces_run(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> elems,
                        BadElementFlag& bad, const Run& run) {
  if (m.ianp)
    element_forces_terms<T, true>(m, s, elems, bad, run);
  else
    element_forces_terms<T, false>(m, s, elems, bad, run);
}

template <class T, class Run>
void node_update_run(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> nodes, const Run& run) {
  const index_t n = m.n_nodes;
  const index_t* start = m.node_elem_start.data();
  const index_t* list = m.node_elem.data();
  const T* fs = s.f_slot.data();
  const T* u = s.u.data();
  const T* u_prev = s.u_prev.data();
  const T* u_held = s.u_held.data();
  const std::uint8_t* held = s.held.data();
  const T* applied = s.load.empty() ? nullptr : s.load.data();
  T* f_out = s.f.data();
  T* u_next = s.u_next.data();
  T* carry = s.u_carry.data();
  for_each_index(run, nodes, kNodeGrain, [&](index_t a) {
    Vec3<T> f = {0, 0, 0};
    for (index_t k = start[a]; k < start[a + 1]; ++k) {  // in the node's list order: slot 4 e + corner
      const T* fk = fs + 3 * size_t(list[k]);
      f = f + Vec3<T>{fk[0], fk[1], fk[2]};
    }
    const auto load = [&](const T* v) { return Vec3<T>{v[a], v[n + a], v[2 * size_t(n) + a]}; };
    if (applied) f = f - load(applied);  // the out-of-balance force f - R
    constexpr bool kCarry = std::is_same_v<T, float>;  // double carries nothing: no load, no store
    Vec3<T> lost = kCarry ? load(carry) : Vec3<T>{0, 0, 0};
    const Vec3<T> next = node_next(held[a], load(u_held), CentralDifference<T>{m.cd_A[a], m.cd_B[a], m.cd_C[a]}, f,
                                   load(u), load(u_prev), lost);
    for (int c = 0; c < 3; ++c) {
      f_out[c * n + a] = f[c];
      u_next[c * n + a] = next[c];
      if constexpr (kCarry) carry[c * n + a] = lost[c];
    }
  });
}

}  // namespace

template <class T>
void element_pressure(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> elems,
                      tbb::affinity_partitioner& part) {
  element_pressure_run(m, s.u.data(), elems, s.elem_J.data(), s.elem_dv.data(), s.elem_F.data(), Tbb{part});
}

template <class T>
void element_pressure(const TissueModel<T>& m, const T* u, std::span<const index_t> elems, T* J_out, T* dv_out,
                      T* F_out) {
  element_pressure_run(m, u, elems, J_out, dv_out, F_out, Serial{});
}

template <class T>
void element_pressure(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> elems) {
  element_pressure_run(m, s.u.data(), elems, s.elem_J.data(), s.elem_dv.data(), s.elem_F.data(), Serial{});
}

template <class T>
void nodal_pressure(const TissueModel<T>& m, TissueState<T>& s, const std::vector<T>& node_divisor,
                    std::span<const index_t> nodes, tbb::affinity_partitioner& part) {
  nodal_pressure_run(m, s.elem_dv.data(), node_divisor, nodes, s.node_p.data(), Tbb{part});
}

template <class T>
void nodal_pressure(const TissueModel<T>& m, const T* dv, const std::vector<T>& node_divisor,
                    std::span<const index_t> nodes, T* p) {
  nodal_pressure_run(m, dv, node_divisor, nodes, p, Serial{});
}

template <class T>
void nodal_pressure(const TissueModel<T>& m, TissueState<T>& s, const std::vector<T>& node_divisor,
                    std::span<const index_t> nodes) {
  nodal_pressure_run(m, s.elem_dv.data(), node_divisor, nodes, s.node_p.data(), Serial{});
}

template <class T>
void element_forces(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> elems, BadElementFlag& bad,
                    tbb::affinity_partitioner& part) {
  element_forces_run(m, s, elems, bad, Tbb{part});
}

template <class T>
void element_forces(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> elems, BadElementFlag& bad) {
  element_forces_run(m, s, elems, bad, Serial{});
}

template <class T>
void node_update(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> nodes,
                 tbb::affinity_partitioner& part) {
  node_update_run(m, s, nodes, Tbb{part});
}

template <class T>
void node_update(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> nodes) {
  node_update_run(m, s, nodes, Serial{});
}

template <class T>
void rotate(TissueState<T>& s) {
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
                            tbb::affinity_partitioner&);                                                          \
  template void element_pressure(const TissueModel<T>&, TissueState<T>&, std::span<const index_t>);               \
  template void element_pressure(const TissueModel<T>&, const T*, std::span<const index_t>, T*, T*, T*);          \
  template void nodal_pressure(const TissueModel<T>&, const T*, const std::vector<T>&, std::span<const index_t>,  \
                               T*);                                                                               \
  template void nodal_pressure(const TissueModel<T>&, TissueState<T>&, const std::vector<T>&,                     \
                               std::span<const index_t>);                                                         \
  template void element_forces(const TissueModel<T>&, TissueState<T>&, std::span<const index_t>, BadElementFlag&); \
  template void node_update(const TissueModel<T>&, TissueState<T>&, std::span<const index_t>);                     \
  template void rotate(TissueState<T>&);
TISSUE_CPU_PASSES(float)
TISSUE_CPU_PASSES(double)
#undef TISSUE_CPU_PASSES

}  // namespace tissue::cpu
