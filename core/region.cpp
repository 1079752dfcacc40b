#include "core/region.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <numeric>
#include <stdexcept>

#include "core/model.hpp"

namespace tissue {

template <class T>
Region flood_fill(const TissueModel<T>& m, std::span<const index_t> seeds, int depth) {
  Region r;
  r.depth = depth;
  r.seeds.assign(seeds.begin(), seeds.end());
  const index_t n = m.n_nodes, ne = m.n_elems;
  if (depth == kDepthAll) {
    r.role.assign(n, kInner);
    r.nodes.resize(n);
    std::iota(r.nodes.begin(), r.nodes.end(), 0);
    r.elems.resize(ne);
    std::iota(r.elems.begin(), r.elems.end(), 0);
    r.n_inner = n;
    return r;
  }
  if (depth < 0) throw std::invalid_argument(fmt::format("region depth {} must be >= 0 or 'all'", depth));
  r.role.assign(n, kOutside);
  std::vector<index_t> frontier, next;
  for (index_t s : seeds) {
    if (s < 0 || s >= n) throw std::out_of_range(fmt::format("region seed node {} out of range (0..{})", s, n - 1));
    if (r.role[s] == kOutside) frontier.push_back(s);
    r.role[s] = kInner;
  }
  int ring = 0;
  for (; ring < depth && !frontier.empty(); ++ring) {
    next.clear();
    for (index_t a : frontier)
      for (index_t k = m.node_elem_start[a]; k < m.node_elem_start[a + 1]; ++k) {
        const index_t e = incident_element(m.node_elem[k]);
        for (int c = 0; c < 4; ++c) {
          const index_t b = m.elem_nodes[c * ne + e];
          if (r.role[b] == kOutside) {
            r.role[b] = kInner;
            next.push_back(b);
          }
        }
      }
    frontier.swap(next);
  }
  if (ring == depth) {  // the last ring reached nodes (or depth 0): it is the front
    r.front = frontier;
    std::sort(r.front.begin(), r.front.end());
  }
  std::vector<std::uint8_t> elem_on(ne, 0);
  for (index_t a = 0; a < n; ++a)
    if (r.role[a] == kInner)
      for (index_t k = m.node_elem_start[a]; k < m.node_elem_start[a + 1]; ++k) elem_on[incident_element(m.node_elem[k])] = 1;
  for (index_t e = 0; e < ne; ++e) {
    if (!elem_on[e]) continue;
    r.elems.push_back(e);
    for (int c = 0; c < 4; ++c) {
      const index_t b = m.elem_nodes[c * ne + e];
      if (r.role[b] == kOutside) r.role[b] = kHalo;
    }
  }
  for (index_t a = 0; a < n; ++a)
    if (r.role[a] != kOutside) {
      r.nodes.push_back(a);
      (r.role[a] == kInner ? r.n_inner : r.n_halo)++;
    }
  return r;
}

template Region flood_fill(const TissueModel<float>&, std::span<const index_t>, int);
template Region flood_fill(const TissueModel<double>&, std::span<const index_t>, int);

}  // namespace tissue
