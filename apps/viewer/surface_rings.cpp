#include "apps/viewer/surface_rings.hpp"

#include <algorithm>
#include <array>

namespace tissue::viewer {

SurfaceRings surface_rings(const TissueModel<double>& m) {
  SurfaceRings r;
  const index_t nt = m.n_tris;
  std::vector<std::int32_t> count(m.n_nodes, 0);
  for (index_t t = 0; t < nt; ++t)
    for (int v = 0; v < 3; ++v) ++count[m.tris[v * size_t(nt) + t]];
  r.range.resize(2 * size_t(m.n_nodes));
  std::int32_t first = 0;
  for (index_t a = 0; a < m.n_nodes; ++a) {
    r.range[2 * a] = first;
    r.range[2 * a + 1] = 0;
    first += count[a];
  }
  r.corners.resize(2 * size_t(first));
  for (index_t t = 0; t < nt; ++t)
    for (int v = 0; v < 3; ++v) {
      const index_t a = m.tris[v * size_t(nt) + t];
      const std::size_t k = 2 * std::size_t(r.range[2 * a] + r.range[2 * a + 1]++);
      r.corners[k] = m.tris[((v + 1) % 3) * size_t(nt) + t];
      r.corners[k + 1] = m.tris[((v + 2) % 3) * size_t(nt) + t];
    }
  return r;
}

std::vector<std::uint8_t> cut_faces(const TissueModel<double>& m) {
  const std::size_t nt = std::size_t(m.n_tris), n = std::size_t(m.n_nodes);
  // each triangle's corners' reference positions, sorted: twins have equal keys
  using Key = std::array<std::array<double, 3>, 3>;
  std::vector<Key> key(nt);
  for (std::size_t t = 0; t < nt; ++t) {
    for (int v = 0; v < 3; ++v) {
      const std::size_t a = std::size_t(m.tris[std::size_t(v) * nt + t]);
      key[t][std::size_t(v)] = {m.X[a], m.X[n + a], m.X[2 * n + a]};
    }
    std::sort(key[t].begin(), key[t].end());
  }
  std::vector<std::size_t> order(nt);
  for (std::size_t t = 0; t < nt; ++t) order[t] = t;
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return key[a] < key[b]; });
  std::vector<std::uint8_t> cut(nt, 0);
  for (std::size_t k = 1; k < nt; ++k)
    if (key[order[k]] == key[order[k - 1]]) cut[order[k]] = cut[order[k - 1]] = 1;
  return cut;
}

}  // namespace tissue::viewer
