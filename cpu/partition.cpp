#include "cpu/partition.hpp"

#include <algorithm>

namespace tissue::cpu {

int busy_members(std::size_t n_elems, int team_size) {
  return int(std::clamp<std::size_t>(n_elems / kMinMemberElems, 1, std::size_t(std::max(team_size, 1))));
}

void slice_region(const Region& region, const index_t* node_elem_start, int parts, std::size_t align, Slices& s) {
  s.parts = parts;
  const std::size_t ne = region.elems.size(), nn = region.nodes.size();
  s.elem_cut.resize(std::size_t(parts) + 1);
  s.node_cut.resize(std::size_t(parts) + 1);
  const std::size_t batches = (ne + align - 1) / align;
  for (int r = 0; r <= parts; ++r) s.elem_cut[r] = std::min(ne, batches * std::size_t(r) / std::size_t(parts) * align);
  // nodes: cut where the running cost passes r / parts of the total
  const auto cost = [&](index_t a) { return std::size_t(1 + node_elem_start[a + 1] - node_elem_start[a]); };
  std::size_t total = 0;
  for (index_t a : region.nodes) total += cost(a);
  std::size_t run = 0, k = 0;
  s.node_cut[0] = 0;
  for (int r = 1; r < parts; ++r) {
    const std::size_t target = total * std::size_t(r) / std::size_t(parts);
    while (k < nn && run + cost(region.nodes[k]) <= target) run += cost(region.nodes[k++]);
    s.node_cut[r] = k;
  }
  s.node_cut[parts] = nn;
}

}  // namespace tissue::cpu
