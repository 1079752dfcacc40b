#include "cpu/constraints.hpp"

#include "core/node_rules.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace tissue::cpu {
namespace {

template <class T>
void set_all(std::vector<T>& v, index_t n, index_t a, T x, T y, T z) {
  v[a] = x;
  v[n + a] = y;
  v[2 * n + a] = z;
}

/// u_prev = u_next = u at node a (stops it; frozen or held-in-place nodes).
template <class T>
void stop_node(TissueState<T>& s, index_t n, index_t a) {
  for (int c = 0; c < 3; ++c) s.u_prev[c * n + a] = s.u_next[c * n + a] = s.u[c * n + a];
}

/// Components of node a the model holds at zero (kAllAxes for kFixed).
template <class T>
std::uint8_t model_axes(const TissueModel<T>& m, index_t a) {
  return fixed_axes(m.node_flags[a]);
}

/// Holds every component of halo node a (core halo_target).
template <class T>
void hold_halo(const TissueModel<T>& m, TissueState<T>& s, index_t a) {
  const index_t n = m.n_nodes;
  const Vec3<T> u = {s.u[a], s.u[n + a], s.u[2 * n + a]};
  const Vec3<T> held = halo_target(model_axes(m, a), s.driven[a], u, Vec3<T>{s.u_held[a], s.u_held[n + a], s.u_held[2 * n + a]});
  set_all(s.u_held, n, a, held.x, held.y, held.z);
  s.held[a] = kAllAxes;
}

}  // namespace

template <class T>
void install_region(const TissueModel<T>& m, TissueState<T>& s, Region region) {
  const index_t n = m.n_nodes, ne = m.n_elems;
  for (index_t a = 0; a < n; ++a) {
    const std::uint8_t role = region.role[a];
    if (role == kOutside) {
      stop_node(s, n, a);
      for (int c = 0; c < 3; ++c) s.f[c * n + a] = T(0);
    }
    if (role == kHalo) {
      stop_node(s, n, a);
      hold_halo(m, s, a);
      continue;
    }
    // driven components keep their targets in u_held; fixed ones are at 0
    const std::uint8_t fixed = model_axes(m, a);
    for (int c = 0; c < 3; ++c)
      if (fixed >> c & 1) s.u_held[c * n + a] = T(0);
    s.held[a] = std::uint8_t(s.driven[a] | fixed);
  }
  std::vector<std::uint8_t> in_region(ne, 0);
  for (index_t e : region.elems) in_region[e] = 1;
  for (index_t e = 0; e < ne; ++e)
    if (!in_region[e])
      for (int k = 0; k < 12; ++k) s.f_slot[12 * size_t(e) + k] = T(0);
  s.region = std::move(region);
}

template <class T>
void release_driven(const TissueModel<T>& m, TissueState<T>& s, std::vector<index_t>& driven_list) {
  for (index_t a : driven_list) {
    s.driven[a] = 0;
    if (s.region.role[a] == kHalo)
      hold_halo(m, s, a);  // at its current u
    else
      s.held[a] = model_axes(m, a);  // their targets are already 0
  }
  driven_list.clear();
}

template <class T>
void drive_nodes(const TissueModel<T>& m, TissueState<T>& s, std::vector<index_t>& driven_list,
                 std::span<const index_t> nodes, std::span<const double> u, std::span<const std::uint8_t> axes) {
  const index_t n = m.n_nodes;
  release_driven(m, s, driven_list);
  for (std::size_t k = 0; k < nodes.size(); ++k) {
    const index_t a = nodes[k];
    const std::uint8_t mask = axes[k];
    if (!s.driven[a]) driven_list.push_back(a);
    s.driven[a] |= mask;
    s.held[a] |= mask;
    const std::uint8_t fixed = model_axes(m, a);  // a fixed component stays at 0 even under the drive
    for (int c = 0; c < 3; ++c)
      if ((mask >> c & 1) && !(fixed >> c & 1)) s.u_held[c * n + a] = T(u[3 * k + c]);
  }
}

#define TISSUE_CPU_CONSTRAINTS(T)                                                                                    \
  template void install_region(const TissueModel<T>&, TissueState<T>&, Region);                                      \
  template void release_driven(const TissueModel<T>&, TissueState<T>&, std::vector<index_t>&);                       \
  template void drive_nodes(const TissueModel<T>&, TissueState<T>&, std::vector<index_t>&, std::span<const index_t>, \
                            std::span<const double>, std::span<const std::uint8_t>);
TISSUE_CPU_CONSTRAINTS(float)
TISSUE_CPU_CONSTRAINTS(double)
#undef TISSUE_CPU_CONSTRAINTS

}  // namespace tissue::cpu
