#include "cpu/reduce.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <functional>

#include "core/energy.hpp"
#include "core/node_rules.hpp"
#include "cpu/element_lanes.hpp"
#include "cpu/passes.hpp"

namespace tissue::cpu {
namespace {

/// Partial sums of one chunk (all double).
struct Partial {
  double reaction[3] = {0, 0, 0};
  double internal[3] = {0, 0, 0};
  double free2 = 0, held2 = 0, kinetic = 0, max_disp = 0;
  bool finite = true;
};

Partial combine(Partial a, const Partial& b) {
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

}  // namespace

template <class T>
Reductions reduce_region(const TissueModel<T>& m, const TissueState<T>& s, std::span<const index_t> nodes) {
  const index_t n = m.n_nodes;
  const Partial total = tbb::parallel_deterministic_reduce(
      tbb::blocked_range<std::size_t>(0, nodes.size(), kReduceGrain), Partial{},
      [&](const tbb::blocked_range<std::size_t>& r, Partial p) {
        const auto load = [&](const std::vector<T>& v, index_t a) {
          return Vec3<T>{v[a], v[n + a], v[2 * size_t(n) + a]};
        };
        for (std::size_t k = r.begin(); k != r.end(); ++k) {
          const index_t a = nodes[k];
          const NodeTerms t = node_terms(load(s.f, a), load(s.u, a), load(s.u_prev, a), double(m.mass[a]), m.dt,
                                         s.region.role[a] == kInner, s.held[a], s.driven[a], s.contact[a],
                                         load(s.contact_normal, a));
          for (int c = 0; c < 3; ++c) {
            p.reaction[c] += t.reaction[c];
            p.internal[c] += t.internal[c];
          }
          p.free2 += t.free2;
          p.held2 += t.held2;
          p.kinetic += t.kinetic;
          p.max_disp = std::max(p.max_disp, t.disp);
          p.finite = p.finite && t.finite;
        }
        return p;
      },
      combine);
  Reductions out;
  out.reaction = {total.reaction[0], total.reaction[1], total.reaction[2]};
  out.internal = {total.internal[0], total.internal[1], total.internal[2]};
  out.free_force2 = total.free2;
  out.held_force2 = total.held2;
  out.kinetic = total.kinetic;
  out.max_disp = total.max_disp;
  out.finite = total.finite && std::isfinite(total.free2 + total.held2 + total.kinetic) &&
               std::isfinite(total.reaction[0] + total.reaction[1] + total.reaction[2]);
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
ElementEnergies element_energies(const TissueModel<T>& m, const TissueState<T>& s, const std::vector<T>& node_divisor,
                                 EnergyScratch<T>& scratch) {
  const std::span<const index_t> elems = s.region.elems, nodes = s.region.nodes;
  // passes 1-2 below rewrite the region's entries; the rest must equal the state's, so that
  // take_passes can swap the arrays: copied whole only when they may not (O(mesh) per reduce before)
  if (!scratch.synced || scratch.elem_dv.size() != s.elem_dv.size() || scratch.node_p.size() != s.node_p.size()) {
    scratch.elem_dv.assign(s.elem_dv.begin(), s.elem_dv.end());
    scratch.elem_J.assign(s.elem_J.begin(), s.elem_J.end());
    scratch.node_p.assign(s.node_p.begin(), s.node_p.end());
    scratch.synced = true;
  }
  scratch.elem_F.resize(s.elem_F.size());
  element_pressure(m, s.u.data(), elems, scratch.elem_J.data(), scratch.elem_dv.data(), scratch.elem_F.data(),
                   scratch.pressure_part);
  nodal_pressure(m, scratch.elem_dv.data(), node_divisor, nodes, scratch.node_p.data(), scratch.nodal_part);
  scratch.fresh = true;
  const T* node_p = m.ianp ? scratch.node_p.data() : nullptr;
  const std::size_t nv = std::size_t(m.n_visco);
  // batches aligned to kLanes inside every fixed-grain chunk: the same
  // batches and the same summation order at any thread count
  return tbb::parallel_deterministic_reduce(
      tbb::blocked_range<std::size_t>(0, elems.size(), kReduceGrain), ElementEnergies{},
      [&](const tbb::blocked_range<std::size_t>& r, ElementEnergies sum) {
        for (std::size_t k = r.begin(); k < r.end(); k += kLanes) {
          ElementLanes<T> b;
          const int count = int(std::min<std::size_t>(kLanes, r.end() - k));
          gather_force_lanes(m, scratch.elem_F.data(), node_p, elems.data() + k, count, b);
          if (m.has_fibre()) {  // the fibre term's energy (core/material.hpp)
            LawLanes<T> w;
            gather_law_lanes<LawTerms<true, false>>(m, static_cast<const T*>(nullptr), elems.data() + k, count, w);
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
          gather_law_lanes<LawTerms<false, true>>(m, s.visco_q.data(), elems.data() + k, count, w);
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
      },
      [](ElementEnergies a, const ElementEnergies& b) {
        a.strain += b.strain;
        a.prony.power += b.prony.power;
        a.prony.stored += b.prony.stored;
        return a;
      });
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
  template Reductions reduce_region(const TissueModel<T>&, const TissueState<T>&, std::span<const index_t>); \
  template double front_displacement(const TissueModel<T>&, const TissueState<T>&);                          \
  template ElementEnergies element_energies(const TissueModel<T>&, const TissueState<T>&, const std::vector<T>&, \
                                            EnergyScratch<T>&);                                                \
  template bool take_passes(EnergyScratch<T>&, TissueState<T>&);
TISSUE_CPU_REDUCE(float)
TISSUE_CPU_REDUCE(double)
#undef TISSUE_CPU_REDUCE

}  // namespace tissue::cpu
