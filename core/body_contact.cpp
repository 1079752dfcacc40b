#include "core/body_contact.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <unordered_map>

#include "core/cut.hpp"
#include "core/model.hpp"

namespace tissue {

void check_body_contact(const BodyContactSpec& spec, index_t n_nodes) {
  if (spec.empty()) return;
  const int nb = spec.n_bodies();
  if (nb < 2 && !spec.pairs.empty())
    throw std::invalid_argument("body contact: needs two bodies or more (first_node gives " + std::to_string(nb) +
                                ")");
  if (!(spec.lip_friction >= 0) || !std::isfinite(spec.lip_friction))
    throw std::invalid_argument("body contact: lip friction must be finite and >= 0, got " +
                                std::to_string(spec.lip_friction));
  if (nb > 0 && (spec.first_node.front() != 0 || spec.first_node.back() != n_nodes))
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
  if (spec.first_node.empty()) return 0;  // one body
  return int(std::upper_bound(spec.first_node.begin(), spec.first_node.end(), node) - spec.first_node.begin()) - 1;
}

/// The lips of cuts: the surface triangles that have a twin of the same reference corners in the same body
/// (the two faces a cut opened from one interior face; their nodes differ, but for a crack front's); per node
/// its side, the unit sum of its lips' reference normals (area-weighted, outward; zero for a node of no lip,
/// or of lips of both sides, on a crack's front); and the ring, the other surface triangles with a corner on
/// a lip: where a lip meets the organ's surface, a node slid past the other lip's edge finds the surface
/// beyond it (not the edge, which would push it along the surface).
template <class T> struct Lips {
  std::vector<std::uint8_t> tri;     ///< per surface triangle: 1 = a lip, 2 = of the ring
  std::vector<Vec3<double>> normal;  ///< per triangle: its reference normal (lips only)
  std::vector<Vec3<double>> side;    ///< per node
};

template <class T> Lips<T> find_lips(const TissueModel<T>& m, const BodyContactSpec& spec) {
  const index_t nt = m.n_tris, n = m.n_nodes;
  Lips<T> L;
  L.tri.assign(std::size_t(nt), 0);
  L.normal.assign(std::size_t(nt), Vec3<double>{0, 0, 0});
  L.side.assign(std::size_t(n), Vec3<double>{0, 0, 0});
  std::vector<double> area(std::size_t(n), 0.0);
  const auto X = [&](index_t a) {
    return Vec3<double>{double(m.X[a]), double(m.X[std::size_t(n) + a]), double(m.X[2 * std::size_t(n) + a])};
  };
  const std::vector<index_t> twin = twin_triangles(std::span<const index_t>(m.tris), X);
  for (index_t t = 0; t < nt; ++t) {
    const index_t u = twin[std::size_t(t)];
    // not two bodies' faces that coincide
    if (u >= 0 && body_of(spec, m.tris[u]) == body_of(spec, m.tris[t])) L.tri[std::size_t(t)] = 1;
  }
  for (index_t t = 0; t < nt; ++t) {
    if (!L.tri[std::size_t(t)]) continue;
    const Vec3<double> x0 = X(m.tris[t]);
    const Vec3<double> N = cross(X(m.tris[nt + t]) - x0, X(m.tris[2 * nt + t]) - x0);
    L.normal[std::size_t(t)] = N;
    for (int k = 0; k < 3; ++k) {
      const std::size_t a = std::size_t(m.tris[k * nt + t]);
      L.side[a] = L.side[a] + N;
      area[a] += norm(N);
    }
  }
  for (std::size_t a = 0; a < std::size_t(n); ++a)
    L.side[a] = area[a] > 0 && norm(L.side[a]) >= 0.5 * area[a] ? (1 / norm(L.side[a])) * L.side[a] : Vec3<double>{0, 0, 0};
  for (index_t t = 0; t < nt; ++t)
    if (!L.tri[std::size_t(t)])
      for (int k = 0; k < 3; ++k)
        if (norm(L.side[std::size_t(m.tris[k * nt + t])]) > 0) L.tri[std::size_t(t)] = 2;
  return L;
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
  const int nb = std::max(1, spec.n_bodies());
  // which bodies each body touches, and with what mu (-1: not)
  std::vector<double> mu(std::size_t(nb) * nb, -1.0);
  for (const BodyContactSpec::Pair& p : spec.pairs) mu[std::size_t(p.a) * nb + p.b] = mu[std::size_t(p.b) * nb + p.a] = p.friction;
  std::vector<int> tri_body(nt);
  std::vector<std::uint8_t> touches(nb, 0);
  const Lips<T> lips = spec.lips ? find_lips(m, spec) : Lips<T>{};
  const auto is_lip = [&](index_t t) { return spec.lips && lips.tri[std::size_t(t)] != 0; };  // or of the ring
  // a row for each corner of a lip or a ring triangle (those off the lips, and a front's, with no candidates:
  // they are candidates' corners)
  std::vector<std::uint8_t> lip_corner(spec.lips ? std::size_t(m.n_nodes) : 0, 0);
  for (index_t t = 0; t < nt && spec.lips; ++t)
    if (lips.tri[std::size_t(t)] != 0)
      for (int k = 0; k < 3; ++k) lip_corner[std::size_t(m.tris[k * nt + t])] = 1;
  const auto lip_node = [&](index_t a) { return spec.lips && lip_corner[std::size_t(a)] != 0; };
  // whether triangle t lies across the lips from a node of side s: a lip facing it, or a ring triangle with a
  // corner on the other lip and none on its own
  const auto across = [&](index_t t, const Vec3<double>& s) {
    if (lips.tri[std::size_t(t)] == 1) {
      const Vec3<double>& N = lips.normal[std::size_t(t)];
      return dot(N, s) < -0.5 * norm(N);
    }
    bool other = false;
    for (int k = 0; k < 3; ++k) {
      const double d = dot(lips.side[std::size_t(m.tris[k * nt + t])], s);
      if (d > 0.5) return false;
      other = other || d < -0.5;
    }
    return other;
  };
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
    if (!touches[tri_body[t]] && !is_lip(t)) continue;
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
  // rows: the touching bodies' surface nodes and the lips' corners, each with the triangles of the bodies it
  // touches near it and the lips facing it
  std::vector<index_t> row_of(std::size_t(m.n_nodes), -1);
  std::vector<std::pair<index_t, double>> found;  // a row's (triangle, mu)
  L.cand_start.push_back(0);
  for (index_t i = 0; i < m.n_surf; ++i) {
    const index_t a = m.surf_nodes[i];
    const int ba = body_of(spec, a);
    if (!touches[ba] && !lip_node(a)) continue;
    row_of[a] = L.rows();
    L.node.push_back(a);
    const Vec3<double> xa = P(a);
    for (int c = 0; c < 3; ++c) L.x_built.push_back(xa[c]);
    const Vec3<double> side = lip_node(a) ? lips.side[std::size_t(a)] : Vec3<double>{0, 0, 0};
    const auto it = grid.find(cell_key(std::int64_t(std::floor(xa.x / h)), std::int64_t(std::floor(xa.y / h)),
                                       std::int64_t(std::floor(xa.z / h))));
    found.clear();
    if (it != grid.end()) {
      for (index_t t : it->second) {
        bool in = true;
        for (int c = 0; c < 3 && in; ++c) in = xa[c] >= lo[3 * size_t(t) + c] && xa[c] <= hi[3 * size_t(t) + c];
        if (!in) continue;
        if (touches[ba] && touches[tri_body[t]]) {
          const double f = mu[std::size_t(ba) * nb + tri_body[t]];
          if (f >= 0) {  // not its own body, nor one it does not touch
            found.emplace_back(t, f);
            continue;
          }
        }
        if (!is_lip(t) || norm(side) == 0 || !across(t, side)) continue;  // its own side, or another cut's
        if (m.tris[t] == a || m.tris[nt + t] == a || m.tris[2 * nt + t] == a) continue;
        found.emplace_back(t, spec.lip_friction);
      }
    }
    std::sort(found.begin(), found.end());
    for (const auto& [t, f] : found) {
      L.cand_tri.push_back(t);
      L.cand_mu.push_back(f);
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
