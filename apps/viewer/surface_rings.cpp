#include "apps/viewer/surface_rings.hpp"

#include "core/cut.hpp"

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
  const std::size_t n = std::size_t(m.n_nodes);
  const std::vector<index_t> twin = twin_triangles(std::span<const index_t>(m.tris), [&](index_t a) {
    return Vec3<double>{m.X[std::size_t(a)], m.X[n + std::size_t(a)], m.X[2 * n + std::size_t(a)]};
  });
  std::vector<std::uint8_t> cut(twin.size());
  for (std::size_t t = 0; t < twin.size(); ++t) cut[t] = twin[t] >= 0 ? 1 : 0;
  return cut;
}

}  // namespace tissue::viewer
