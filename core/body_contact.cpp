#include "core/body_contact.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <unordered_map>

#include "core/model.hpp"

namespace tissue {

void check_body_contact(const BodyContactSpec& spec, index_t n_nodes) {
  if (spec.empty()) return;
  const int nb = spec.n_bodies();
  if (nb < 2) throw std::invalid_argument("body contact: needs two bodies or more (first_node gives " +
                                          std::to_string(nb) + ")");
  if (spec.first_node.front() != 0 || spec.first_node.back() != n_nodes)
    throw std::invalid_argument("body contact: the bodies' node ranges must cover nodes 0.." +
                                std::to_string(n_nodes - 1) + " of the mesh");
  for (int b = 0; b < nb; ++b)
    if (spec.first_node[b + 1] <= spec.first_node[b])
      throw std::invalid_argument("body contact: body " + std::to_string(b) + " has no nodes (ranges must ascend)");
  if (!(spec.skin >= 0) || !std::isfinite(spec.skin))
    throw std::invalid_argument("body contact: skin must be finite and >= 0 (m), got " + std::to_string(spec.skin));
  for (std::size_t i = 0; i < spec.pairs.size(); ++i) {
    const BodyContactSpec::Pair& p = spec.pairs[i];
    const std::string which = "body contact pair " + std::to_string(i) + " (" + std::to_string(p.a) + ", " +
                              std::to_string(p.b) + ")";
    if (p.a < 0 || p.b < 0 || p.a >= nb || p.b >= nb) throw std::invalid_argument(which + ": no such body");
    if (p.a == p.b) throw std::invalid_argument(which + ": a body against itself (self-contact is not modelled)");
    if (!(p.friction >= 0) || !std::isfinite(p.friction))
      throw std::invalid_argument(which + ": friction must be finite and >= 0, got " + std::to_string(p.friction));
    for (std::size_t j = 0; j < i; ++j) {
      const BodyContactSpec::Pair& q = spec.pairs[j];
      if ((q.a == p.a && q.b == p.b) || (q.a == p.b && q.b == p.a))
        throw std::invalid_argument(which + ": the same bodies as pair " + std::to_string(j));
    }
  }
}

namespace {

int body_of(const BodyContactSpec& spec, index_t node) {
  return int(std::upper_bound(spec.first_node.begin(), spec.first_node.end(), node) - spec.first_node.begin()) - 1;
}

/// A grid cell key (21 bits a coordinate).
std::uint64_t cell_key(std::int64_t i, std::int64_t j, std::int64_t k) {
  const auto b = [](std::int64_t v) { return std::uint64_t(v + (std::int64_t(1) << 20)) & ((1u << 21) - 1); };
  return (b(i) << 42) | (b(j) << 21) | b(k);
}

/// A face on a symmetry plane: its normal lies along an axis that each of its corners holds, a roller at one
/// corner at least (a fully fixed face is a support, and stays touchable). It is a cut of the model, not a
/// surface another body can touch.
template <class T> bool on_symmetry_plane(const TissueModel<T>& m, index_t t, const Vec3<double>& normal) {
  std::uint8_t held = kAllAxes;
  bool roller = false;
  for (int k = 0; k < 3; ++k) {
    const std::uint8_t f = m.node_flags[m.tris[k * m.n_tris + t]];
    held &= fixed_axes(f);
    roller = roller || !(f & kFixed);
  }
  for (int c = 0; c < 3; ++c)
    if ((held >> c & 1) && roller && std::fabs(normal[c]) > 0.999 * norm(normal)) return true;
  return false;
}

}  // namespace

template <class T>
BodyLists build_body_lists(const TissueModel<T>& m, const BodyContactSpec& spec, const std::vector<double>& x) {
  check_body_contact(spec, m.n_nodes);
  BodyLists L;
  if (spec.empty()) return L;
  if (m.node_flags.size() != std::size_t(m.n_nodes))
    throw std::invalid_argument(fmt::format("body contact: the model has {} node flags for its {} nodes (the lists "
                                            "leave out faces on symmetry planes by their corners' supports)",
                                            m.node_flags.size(), m.n_nodes));
  const index_t nt = m.n_tris;
  const int nb = spec.n_bodies();
  // which bodies each body touches, and with what mu (-1: not)
  std::vector<double> mu(std::size_t(nb) * nb, -1.0);
  for (const BodyContactSpec::Pair& p : spec.pairs) mu[std::size_t(p.a) * nb + p.b] = mu[std::size_t(p.b) * nb + p.a] = p.friction;
  std::vector<int> tri_body(nt);
  std::vector<std::uint8_t> touches(nb, 0);
  for (int a = 0; a < nb; ++a)
    for (int b = 0; b < nb; ++b) touches[a] |= mu[std::size_t(a) * nb + b] >= 0 ? 1 : 0;
  const auto P = [&](index_t a) { return Vec3<double>{x[3 * size_t(a)], x[3 * size_t(a) + 1], x[3 * size_t(a) + 2]}; };
  // the skin: the median surface edge unless given
  double skin = spec.skin;
  if (!(skin > 0)) {
    std::vector<double> edges;
    edges.reserve(3 * std::size_t(nt));
    for (index_t t = 0; t < nt; ++t)
      for (int k = 0; k < 3; ++k)
        edges.push_back(norm(P(m.tris[k * nt + t]) - P(m.tris[((k + 1) % 3) * nt + t])));
    if (!edges.empty()) {
      std::nth_element(edges.begin(), edges.begin() + edges.size() / 2, edges.end());
      skin = edges[edges.size() / 2];
    }
    if (!(skin > 0)) skin = 1e-3;
  }
  L.skin = skin;
  // the touching bodies' triangles in a grid of cells of the largest triangle box plus the skin
  double extent = 0;
  for (index_t t = 0; t < nt; ++t) {
    tri_body[t] = body_of(spec, m.tris[t]);
    for (int k = 0; k < 3; ++k) extent = std::max(extent, norm(P(m.tris[k * nt + t]) - P(m.tris[((k + 1) % 3) * nt + t])));
  }
  const double h = extent + 2 * skin;
  std::unordered_map<std::uint64_t, std::vector<index_t>> grid;
  std::vector<double> lo(3 * std::size_t(nt)), hi(3 * std::size_t(nt));
  for (index_t t = 0; t < nt; ++t) {
    if (!touches[tri_body[t]]) continue;
    const Vec3<double> x0 = P(m.tris[t]);
    if (on_symmetry_plane(m, t, cross(P(m.tris[nt + t]) - x0, P(m.tris[2 * nt + t]) - x0))) continue;
    for (int c = 0; c < 3; ++c) {
      double a = P(m.tris[t])[c], b = a;
      for (int k = 1; k < 3; ++k) {
        a = std::min(a, P(m.tris[k * nt + t])[c]);
        b = std::max(b, P(m.tris[k * nt + t])[c]);
      }
      lo[3 * size_t(t) + c] = a - skin;
      hi[3 * size_t(t) + c] = b + skin;
    }
    const auto cell = [&](double v) { return std::int64_t(std::floor(v / h)); };
    const std::int64_t i0 = cell(lo[3 * size_t(t)]), j0 = cell(lo[3 * size_t(t) + 1]),
                       k0 = cell(lo[3 * size_t(t) + 2]);
    const std::int64_t i1 = cell(hi[3 * size_t(t)]), j1 = cell(hi[3 * size_t(t) + 1]),
                       k1 = cell(hi[3 * size_t(t) + 2]);
    for (std::int64_t i = i0; i <= i1; ++i)
      for (std::int64_t j = j0; j <= j1; ++j)
        for (std::int64_t k = k0; k <= k1; ++k) grid[cell_key(i, j, k)].push_back(t);
  }
  // rows: the touching bodies' surface nodes, each with the triangles of the bodies it touches near it
  std::vector<index_t> row_of(std::size_t(m.n_nodes), -1);
  L.cand_start.push_back(0);
  for (index_t i = 0; i < m.n_surf; ++i) {
    const index_t a = m.surf_nodes[i];
    const int ba = body_of(spec, a);
    if (!touches[ba]) continue;
    row_of[a] = L.rows();
    L.node.push_back(a);
    const Vec3<double> xa = P(a);
    for (int c = 0; c < 3; ++c) L.x_built.push_back(xa[c]);
    const auto it = grid.find(cell_key(std::int64_t(std::floor(xa.x / h)), std::int64_t(std::floor(xa.y / h)),
                                       std::int64_t(std::floor(xa.z / h))));
    if (it != grid.end()) {
      const std::size_t first = L.cand_tri.size();
      for (index_t t : it->second) {
        const double f = mu[std::size_t(ba) * nb + tri_body[t]];
        if (f < 0) continue;  // its own body, or one it does not touch
        bool in = true;
        for (int c = 0; c < 3 && in; ++c) in = xa[c] >= lo[3 * size_t(t) + c] && xa[c] <= hi[3 * size_t(t) + c];
        if (!in) continue;
        L.cand_tri.push_back(t);
      }
      std::sort(L.cand_tri.begin() + std::ptrdiff_t(first), L.cand_tri.end());
      for (std::size_t j = first; j < L.cand_tri.size(); ++j)
        L.cand_mu.push_back(mu[std::size_t(ba) * nb + tri_body[L.cand_tri[j]]]);
    }
    L.cand_start.push_back(index_t(L.cand_tri.size()));
  }
  for (index_t t : L.cand_tri)
    for (int k = 0; k < 3; ++k) L.cand_rows.push_back(row_of[m.tris[k * nt + t]]);
  // each row's corner entries: the candidates (of any row) whose triangle has its node as a corner
  const index_t rows = L.rows();
  std::vector<index_t> count(std::size_t(rows) + 1, 0);
  for (index_t r = 0; r < rows; ++r)
    for (index_t j = L.cand_start[r]; j < L.cand_start[r + 1]; ++j)
      for (int k = 0; k < 3; ++k) ++count[std::size_t(row_of[m.tris[k * nt + L.cand_tri[j]]]) + 1];
  L.corner_start.assign(std::size_t(rows) + 1, 0);
  for (index_t r = 0; r < rows; ++r) L.corner_start[r + 1] = L.corner_start[r] + count[std::size_t(r) + 1];
  const std::size_t n_corner = std::size_t(L.corner_start[rows]);
  L.corner_cand.resize(n_corner);
  L.corner_row.resize(n_corner);
  L.corner_slot.resize(n_corner);
  std::vector<index_t> fill(L.corner_start.begin(), L.corner_start.end() - 1);
  for (index_t r = 0; r < rows; ++r)  // ascending (row, candidate): each row's entries ascend
    for (index_t j = L.cand_start[r]; j < L.cand_start[r + 1]; ++j)
      for (int k = 0; k < 3; ++k) {
        const index_t c = row_of[m.tris[k * nt + L.cand_tri[j]]];
        const index_t e = fill[c]++;
        L.corner_cand[e] = j;
        L.corner_row[e] = r;
        L.corner_slot[e] = std::uint8_t(k);
      }
  return L;
}

template BodyLists build_body_lists(const TissueModel<float>&, const BodyContactSpec&, const std::vector<double>&);
template BodyLists build_body_lists(const TissueModel<double>&, const BodyContactSpec&, const std::vector<double>&);

}  // namespace tissue
