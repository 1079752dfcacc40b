#include "cpu/constraints.hpp"

#include <fmt/format.h>

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

template <class T>
bool is_fixed(const TissueModel<T>& m, index_t a) {
  return (m.node_flags[a] & kFixed) != 0;
}

}  // namespace

template <class T>
void init_constraints(const TissueModel<T>& m, TissueState<T>& s) {
  const index_t n = m.n_nodes;
  for (index_t a = 0; a < n; ++a) {
    s.held[a] = is_fixed(m, a) ? 1 : 0;
    s.driven[a] = 0;
    set_all(s.u_held, n, a, T(0), T(0), T(0));
  }
}

template <class T>
void install_region(const TissueModel<T>& m, TissueState<T>& s, Region region) {
  const index_t n = m.n_nodes, ne = m.n_elems;
  for (index_t a = 0; a < n; ++a) {
    const std::uint8_t role = region.role[a];
    if (role == kOutside) {
      stop_node(s, n, a);
      for (int c = 0; c < 3; ++c) s.f[c * n + a] = T(0);
    }
    s.held[a] = 0;
    if (role == kHalo) {
      stop_node(s, n, a);
      s.held[a] = 1;
      if (!s.driven[a]) set_all(s.u_held, n, a, s.u[a], s.u[n + a], s.u[2 * n + a]);
    }
    if (s.driven[a]) s.held[a] = 1;  // its target in u_held is kept
    if (is_fixed(m, a)) {
      set_all(s.u_held, n, a, T(0), T(0), T(0));
      s.held[a] = 1;
    }
  }
  std::vector<std::uint8_t> in_region(ne, 0);
  for (index_t e : region.elems) in_region[e] = 1;
  for (index_t e = 0; e < ne; ++e)
    if (!in_region[e])
      for (int k = 0; k < 12; ++k) s.elem_f[k * ne + e] = T(0);
  s.region = std::move(region);
}

template <class T>
void release_driven(const TissueModel<T>& m, TissueState<T>& s, std::vector<index_t>& driven_list) {
  const index_t n = m.n_nodes;
  for (index_t a : driven_list) {
    s.driven[a] = 0;
    s.held[a] = 0;
    if (s.region.role[a] == kHalo) {
      set_all(s.u_held, n, a, s.u[a], s.u[n + a], s.u[2 * n + a]);
      s.held[a] = 1;
    }
    if (is_fixed(m, a)) {
      set_all(s.u_held, n, a, T(0), T(0), T(0));
      s.held[a] = 1;
    }
  }
  driven_list.clear();
}

template <class T>
void drive_nodes(const TissueModel<T>& m, TissueState<T>& s, std::vector<index_t>& driven_list,
                 std::span<const index_t> nodes, std::span<const double> u) {
  const index_t n = m.n_nodes;
  if (u.size() != 3 * nodes.size())
    throw std::invalid_argument(
        fmt::format("set_driven: {} displacement values for {} nodes (need 3 per node)", u.size(), nodes.size()));
  for (std::size_t k = 0; k < nodes.size(); ++k) {
    const index_t a = nodes[k];
    if (a < 0 || a >= n) throw std::invalid_argument(fmt::format("set_driven: node {} out of range (0..{})", a, n - 1));
    if (s.region.role[a] == kOutside)
      throw std::invalid_argument(
          fmt::format("set_driven: node {} is outside the deformation region (build_region from it first)", a));
    for (int c = 0; c < 3; ++c)
      if (!std::isfinite(u[3 * k + c]))
        throw std::invalid_argument(
            fmt::format("set_driven: node {}: displacement {} = {} is not finite", a, "xyz"[c], u[3 * k + c]));
  }
  release_driven(m, s, driven_list);
  for (std::size_t k = 0; k < nodes.size(); ++k) {
    const index_t a = nodes[k];
    if (std::find(driven_list.begin(), driven_list.end(), a) == driven_list.end()) driven_list.push_back(a);
    s.driven[a] = 1;
    s.held[a] = 1;
    if (is_fixed(m, a)) continue;  // a fixed node stays at 0 even under the tool
    set_all(s.u_held, n, a, T(u[3 * k]), T(u[3 * k + 1]), T(u[3 * k + 2]));
  }
}

#define TISSUE_CPU_CONSTRAINTS(T)                                                                                    \
  template void init_constraints(const TissueModel<T>&, TissueState<T>&);                                            \
  template void install_region(const TissueModel<T>&, TissueState<T>&, Region);                                      \
  template void release_driven(const TissueModel<T>&, TissueState<T>&, std::vector<index_t>&);                       \
  template void drive_nodes(const TissueModel<T>&, TissueState<T>&, std::vector<index_t>&, std::span<const index_t>, \
                            std::span<const double>);
TISSUE_CPU_CONSTRAINTS(float)
TISSUE_CPU_CONSTRAINTS(double)
#undef TISSUE_CPU_CONSTRAINTS

}  // namespace tissue::cpu
