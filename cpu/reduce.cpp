#include "cpu/reduce.hpp"

#include <algorithm>
#include <cmath>
#include <functional>

#include "core/energy.hpp"
#include "core/node_rules.hpp"
#include "cpu/element_lanes.hpp"
#include "cpu/passes.hpp"

namespace tissue::cpu {
namespace {

NodeSums combine(NodeSums a, const NodeSums& b) {
  for (int c = 0; c < 3; ++c) {
    a.reaction[c] += b.reaction[c];
    a.internal[c] += b.internal[c];
  }
  a.free2 += b.free2;
  a.held2 += b.held2;
  a.kinetic += b.kinetic;
  a.max_disp = std::max(a.max_disp, b.max_disp);
  a.finite = a.finite && b.finite;
  return a;
}

ElementEnergies combine(ElementEnergies a, const ElementEnergies& b) {
  a.strain += b.strain;
  a.prony.power += b.prony.power;
  a.prony.stored += b.prony.stored;
  return a;
}

/// Sums of node_terms over nodes[begin, end).
template <class T>
NodeSums node_sums(const TissueModel<T>& m, const TissueState<T>& s, std::span<const index_t> nodes,
                   std::size_t begin, std::size_t end) {
  const index_t n = m.n_nodes;
  const auto load = [&](const std::vector<T>& v, index_t a) { return Vec3<T>{v[a], v[n + a], v[2 * size_t(n) + a]}; };
  NodeSums p;
  for (std::size_t k = begin; k != end; ++k) {
    const index_t a = nodes[k];
    const NodeTerms t = node_terms(load(s.f, a), load(s.u, a), load(s.u_prev, a), double(m.mass[a]), m.dt,
                                   s.region.role[a] == kInner, s.held[a], s.driven[a], s.contact[a],
                                   load(s.contact_normal, a));
    p = combine(p, NodeSums{{t.reaction[0], t.reaction[1], t.reaction[2]},
                            {t.internal[0], t.internal[1], t.internal[2]},
                            t.free2, t.held2, t.kinetic, t.disp, t.finite});
  }
  return p;
}

/// The strain and Prony energies of elems[begin, end) (begin a multiple of
/// kLanes) from passes 1-2 in `energy`.
template <class T>
ElementEnergies energy_sums(const TissueModel<T>& m, const TissueState<T>& s, EnergyScratch<T>& energy,
                            std::span<const index_t> elems, std::size_t begin, std::size_t end) {
  const T* node_p = m.ianp ? energy.node_p.data() : nullptr;
  const std::size_t nv = std::size_t(m.n_visco);
  ElementEnergies sum;
  for (std::size_t k = begin; k < end; k += kLanes) {
    ElementLanes<T> b;
    const int count = int(std::min<std::size_t>(kLanes, end - k));
    gather_force_lanes(m, energy.elem_F.data(), node_p, elems.data() + k, count, b);
    if (m.has_fibre()) {  // the fibre term's energy (core/material.hpp)
      LawLanes<T> w;
      gather_law_lanes<LawTerms<FibreTerm>>(m, static_cast<const T*>(nullptr), elems.data() + k, count, w);
      if (m.ianp)
        lanes_energy_fibre<T, true>(b, w);
      else
        lanes_energy_fibre<T, false>(b, w);
    } else if (m.ianp) {
      lanes_energy<T, true>(b);
    } else {
      lanes_energy<T, false>(b);
    }
    for (int l = 0; l < count; ++l) sum.strain += double(b.ret[l]);
    if (!m.has_visco()) continue;
    // the Prony terms' power and stored energy from the same F and pbar
    LawLanes<T> w;
    gather_law_lanes<LawTerms<PronyTerm>>(m, s.visco_q.data(), elems.data() + k, count, w);
    alignas(64) T g[kMaxProny][kLanes], tau[kMaxProny][kLanes], power[kLanes], stored[kLanes];
    for (int i = 0; i < kMaxProny; ++i)
      for (int l = 0; l < kLanes; ++l) {
        const index_t v = w.slot[l];
        const bool in = v >= 0 && i < m.n_prony;
        g[i][l] = in ? T(m.prony_g[i * nv + v]) : T(0);
        tau[i][l] = in ? T(m.prony_tau[i * nv + v]) : T(1);
      }
    if (m.ianp)
      lanes_prony_energy<T, true>(b, w, g, tau, power, stored);
    else
      lanes_prony_energy<T, false>(b, w, g, tau, power, stored);
    for (int l = 0; l < count; ++l) {
      sum.prony.power += double(power[l]);
      sum.prony.stored += double(stored[l]);
    }
  }
  return sum;
}

/// Member r's share of the fixed chunks [0, chunks) among `parts` members,
/// as {first, last} chunk.
std::pair<std::size_t, std::size_t> chunk_share(std::size_t chunks, int r, int parts) {
  return {chunks * std::size_t(r) / std::size_t(parts), chunks * std::size_t(r + 1) / std::size_t(parts)};
}

}  // namespace

template <class T>
Reductions reduce_region(const TissueModel<T>& m, const TissueState<T>& s, const std::vector<T>& node_divisor,
                         EnergyScratch<T>& energy, ReduceScratch& sums, ThreadTeam& team, const Slices& slices) {
  const std::span<const index_t> elems = s.region.elems, nodes = s.region.nodes;
  // passes 1-2 below rewrite the region's entries; the rest must equal the state's, so that
  // take_passes can swap the arrays: copied whole only when they may not (O(mesh) per reduce before)
  if (!energy.synced || energy.elem_dv.size() != s.elem_dv.size() || energy.node_p.size() != s.node_p.size()) {
    energy.elem_dv.assign(s.elem_dv.begin(), s.elem_dv.end());
    energy.elem_J.assign(s.elem_J.begin(), s.elem_J.end());
    energy.node_p.assign(s.node_p.begin(), s.node_p.end());
    energy.synced = true;
  }
  energy.elem_F.resize(s.elem_F.size());
  const std::size_t elem_chunks = (elems.size() + kReduceGrain - 1) / kReduceGrain;
  const std::size_t node_chunks = (nodes.size() + kReduceGrain - 1) / kReduceGrain;
  sums.elems.resize(elem_chunks);
  sums.nodes.resize(node_chunks);
  team.run(slices.parts, [&](int r) {
    element_pressure(m, s.u.data(), slices.elems(elems, r), energy.elem_J.data(), energy.elem_dv.data(),
                     energy.elem_F.data());
    team.barrier();
    nodal_pressure(m, energy.elem_dv.data(), node_divisor, slices.nodes(nodes, r), energy.node_p.data());
    team.barrier();
    // fixed chunks, whatever the team's size: the same batches and the same sums at any size; the
    // element chunks, then the node chunks, shared as one list (a region of one chunk of each sums
    // its energies and its nodes on two members at once)
    const auto [c0, c1] = chunk_share(elem_chunks + node_chunks, r, slices.parts);
    for (std::size_t c = c0; c < c1; ++c) {
      if (c < elem_chunks) {
        sums.elems[c] = energy_sums(m, s, energy, elems, c * kReduceGrain, std::min(elems.size(), (c + 1) * kReduceGrain));
      } else {
        const std::size_t d = c - elem_chunks;
        sums.nodes[d] = node_sums(m, s, nodes, d * kReduceGrain, std::min(nodes.size(), (d + 1) * kReduceGrain));
      }
    }
  });
  energy.fresh = true;
  NodeSums total;
  for (const NodeSums& p : sums.nodes) total = combine(total, p);
  ElementEnergies e;
  for (const ElementEnergies& p : sums.elems) e = combine(e, p);
  Reductions out;
  out.reaction = {total.reaction[0], total.reaction[1], total.reaction[2]};
  out.internal = {total.internal[0], total.internal[1], total.internal[2]};
  out.free_force2 = total.free2;
  out.held_force2 = total.held2;
  out.kinetic = total.kinetic;
  out.max_disp = total.max_disp;
  out.strain_energy = e.strain;
  out.visco_power = e.prony.power;
  out.visco_stored = e.prony.stored;
  out.finite = total.finite && std::isfinite(total.free2 + total.held2 + total.kinetic) &&
               std::isfinite(total.reaction[0] + total.reaction[1] + total.reaction[2]) &&
               std::isfinite(e.prony.power) && std::isfinite(e.prony.stored);
  return out;
}

template <class T>
double front_displacement(const TissueModel<T>& m, const TissueState<T>& s) {
  const index_t n = m.n_nodes;
  double max2 = 0;
  for (index_t a : s.region.front) {
    double u2 = 0;
    for (int c = 0; c < 3; ++c) u2 += double(s.u[c * n + a]) * double(s.u[c * n + a]);
    max2 = std::max(max2, u2);
  }
  return std::sqrt(max2);
}

template <class T>
bool take_passes(EnergyScratch<T>& scratch, TissueState<T>& s) {
  if (!scratch.fresh) return false;
  scratch.fresh = false;
  std::swap(scratch.elem_dv, s.elem_dv);
  std::swap(scratch.elem_J, s.elem_J);
  std::swap(scratch.elem_F, s.elem_F);
  std::swap(scratch.node_p, s.node_p);
  return true;
}

#define TISSUE_CPU_REDUCE(T)                                                                                 \
  template Reductions reduce_region(const TissueModel<T>&, const TissueState<T>&, const std::vector<T>&,      \
                                    EnergyScratch<T>&, ReduceScratch&, ThreadTeam&, const Slices&);          \
  template double front_displacement(const TissueModel<T>&, const TissueState<T>&);                          \
  template bool take_passes(EnergyScratch<T>&, TissueState<T>&);
TISSUE_CPU_REDUCE(float)
TISSUE_CPU_REDUCE(double)
#undef TISSUE_CPU_REDUCE

}  // namespace tissue::cpu
