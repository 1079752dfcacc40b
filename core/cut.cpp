#include "core/cut.hpp"

#include "core/contact.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <unordered_map>
#include <numeric>
#include <utility>

namespace tissue {
namespace {

using V = Vec3<double>;

/// The cut's plane and the parallelogram on it.
struct Parallelogram {
  V o, a, b, n;
  double inv[2][2];  ///< inverse of the Gram matrix of (a, b)
  explicit Parallelogram(const CutSurface& c) : o(c.origin), a(c.edge), b(c.sweep) {
    const V ab = cross(a, b);
    n = (1 / norm(ab)) * ab;
    const double aa = dot(a, a), bb = dot(b, b), ba = dot(a, b), det = aa * bb - ba * ba;
    inv[0][0] = bb / det, inv[0][1] = -ba / det, inv[1][0] = -ba / det, inv[1][1] = aa / det;
  }
  double distance(V x) const { return dot(x - o, n); }
  /// Whether x's projection on the plane lies on the parallelogram.
  bool over(V x) const {
    const V r = x - o;
    const double ra = dot(r, a), rb = dot(r, b);
    const double s = inv[0][0] * ra + inv[0][1] * rb, t = inv[1][0] * ra + inv[1][1] * rb;
    constexpr double e = 1e-9;
    return s >= -e && s <= 1 + e && t >= -e && t <= 1 + e;
  }
};

double volume(V a, V b, V c, V d) { return dot(cross(b - a, c - a), d - a) / 6; }

/// A surface node slides along the surface only where its faces turn less
/// than 20 degrees from its normal (cos 20 degrees): on a flat face it keeps
/// the volume exactly, on a smooth organ to the second order of the move.
constexpr double kSmooth = 0.9397;

constexpr int kFace[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};  // face opposite each corner
constexpr int kEdge[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};

struct FaceRef {
  std::array<index_t, 3> key;  ///< its nodes, ascending
  index_t elem;
  bool operator<(const FaceRef& o) const { return key != o.key ? key < o.key : elem < o.elem; }
};

std::array<index_t, 3> sorted(index_t a, index_t b, index_t c) {
  std::array<index_t, 3> k{a, b, c};
  std::sort(k.begin(), k.end());
  return k;
}

/// Every face of every element, sorted by its nodes (an interior face twice, a boundary face once).
std::vector<FaceRef> all_faces(const std::vector<index_t>& tets) {
  std::vector<FaceRef> f;
  f.reserve(tets.size());
  for (std::size_t e = 0; e < tets.size() / 4; ++e)
    for (const auto& c : kFace)
      f.push_back({sorted(tets[4 * e + c[0]], tets[4 * e + c[1]], tets[4 * e + c[2]]), index_t(e)});
  std::sort(f.begin(), f.end());
  return f;
}

/// Splits meshes into tetrahedra: the element list it appends to, the
/// node positions for orientation.
struct Tets {
  std::vector<index_t>& out;
  std::vector<index_t>& from;
  const std::vector<V>& x;
  index_t origin;

  void tet(index_t a, index_t b, index_t c, index_t d) {
    if (volume(x[a], x[b], x[c], x[d]) < 0) std::swap(c, d);
    out.insert(out.end(), {a, b, c, d});
    from.push_back(origin);
  }
  /// A prism: triangles (p0 p1 p2) and (p3 p4 p5), edges p_i p_{i+3}; its
  /// quadrilaterals split by the diagonal from their lowest node id.
  void prism(std::array<index_t, 6> p) {
    const int m = int(std::min_element(p.begin(), p.end()) - p.begin());
    if (m >= 3) p = {p[3], p[4], p[5], p[0], p[1], p[2]};
    const int r = m % 3;
    const std::array<index_t, 6> q = {p[r], p[(r + 1) % 3], p[(r + 2) % 3], p[3 + r], p[3 + (r + 1) % 3],
                                      p[3 + (r + 2) % 3]};
    if (std::min(q[1], q[5]) < std::min(q[2], q[4])) {
      tet(q[0], q[1], q[2], q[5]);
      tet(q[0], q[1], q[5], q[4]);
    } else {
      tet(q[0], q[1], q[2], q[4]);
      tet(q[0], q[4], q[2], q[5]);
    }
    tet(q[0], q[4], q[5], q[3]);
  }
  /// A pyramid: quadrilateral (q0 q1 q2 q3) in order around it, apex a.
  void pyramid(std::array<index_t, 4> q, index_t a) {
    const int m = int(std::min_element(q.begin(), q.end()) - q.begin());
    if (m % 2 == 0) {
      tet(q[0], q[1], q[2], a);
      tet(q[0], q[2], q[3], a);
    } else {
      tet(q[1], q[2], q[3], a);
      tet(q[1], q[3], q[0], a);
    }
  }
};

}  // namespace

CutResult cut_along(std::span<const double> nodes, std::span<const index_t> tets, const CutSurface& cut,
                   const CutOptions& o) {
  if (nodes.size() % 3 != 0 || tets.size() % 4 != 0 || tets.empty())
    throw CutError(fmt::format("cut: {} coordinates and {} corner ids are not a mesh of x y z per node and 4 ids "
                               "per element",
                               nodes.size(), tets.size()));
  if (!(o.snap >= 0 && o.snap <= 0.5))
    throw CutError(fmt::format("cut: snap = {} must lie in [0, 0.5] (a fraction of a node's shortest edge)", o.snap));
  if (!(o.touch >= 0 && o.touch <= o.snap + 0.5))
    throw CutError(fmt::format("cut: touch = {} must lie in [0, 0.5] (a fraction of a node's shortest edge)", o.touch));
  if (!(o.keep > 0 && o.keep < 1))
    throw CutError(fmt::format("cut: keep = {} must lie in (0, 1) (a fraction of an element's volume)", o.keep));
  const double le = norm(cut.edge), ls = norm(cut.sweep);
  for (const V& v : {cut.origin, cut.edge, cut.sweep})
    if (!(std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z)))
      throw CutError("cut: the blade's origin, edge and sweep must be finite");
  if (!(le > 0)) throw CutError("cut: the blade's edge has zero length; a blade cuts along an edge of some length");
  if (!(ls > 0)) throw CutError("cut: the blade's sweep has zero length; a blade cuts only while it moves");
  if (!(norm(cross(cut.edge, cut.sweep)) > 1e-9 * le * ls))
    throw CutError("cut: the blade moves along its own edge; it sweeps no surface (move it across its edge)");
  const Parallelogram P(cut);

  const index_t n0 = index_t(nodes.size() / 3), e0 = index_t(tets.size() / 4);
  std::vector<V> x(n0);
  for (index_t i = 0; i < n0; ++i) x[i] = {nodes[3 * i], nodes[3 * i + 1], nodes[3 * i + 2]};
  std::vector<index_t> t(tets.begin(), tets.end());
  for (index_t v : t)
    if (v < 0 || v >= n0) throw CutError(fmt::format("cut: corner id {} is out of range (0..{})", v, n0 - 1));

  // shortest edge at each node, the nodes' elements, the boundary's nodes
  std::vector<double> h(n0, INFINITY);
  for (index_t e = 0; e < e0; ++e)
    for (const auto& k : kEdge) {
      const index_t a = t[4 * e + k[0]], b = t[4 * e + k[1]];
      const double l = norm(x[a] - x[b]);
      h[a] = std::min(h[a], l);
      h[b] = std::min(h[b], l);
    }
  std::vector<std::vector<index_t>> star(n0);
  for (index_t e = 0; e < e0; ++e)
    for (int c = 0; c < 4; ++c) star[t[4 * e + c]].push_back(e);
  std::vector<std::uint8_t> boundary(n0, 0);
  std::vector<V> outward(n0, V{0, 0, 0});  // a boundary node's area-weighted outward normal
  std::vector<double> flatness(n0, 1);     // the least cosine between it and the normals of the node's faces
  {
    const std::vector<FaceRef> f = all_faces(t);
    std::vector<std::array<index_t, 3>> once;
    for (std::size_t i = 0; i < f.size(); ++i) {
      const bool twin = (i > 0 && f[i - 1].key == f[i].key) || (i + 1 < f.size() && f[i + 1].key == f[i].key);
      if (!twin) once.push_back(f[i].key);
    }
    std::vector<std::array<index_t, 3>> outer;  // the boundary faces, outward
    for (index_t e = 0; e < e0; ++e)
      for (const auto& c : kFace) {
        const index_t a = t[4 * e + c[0]], b = t[4 * e + c[1]], q = t[4 * e + c[2]];
        if (std::binary_search(once.begin(), once.end(), sorted(a, b, q))) outer.push_back({a, b, q});
      }
    for (const auto& [a, b, q] : outer) {
      const V nf = cross(x[b] - x[a], x[q] - x[a]);  // outward: the faces of kFace turn away from their element
      for (index_t v : {a, b, q}) boundary[v] = 1, outward[v] = outward[v] + nf;
    }
    for (const auto& [a, b, q] : outer) {  // how far its faces turn from the node's normal
      const V nf = cross(x[b] - x[a], x[q] - x[a]);
      for (index_t v : {a, b, q}) flatness[v] = std::min(flatness[v], dot(nf, outward[v]) / (norm(nf) * norm(outward[v])));
    }
  }
  std::vector<double> v0(e0);
  for (index_t e = 0; e < e0; ++e) v0[e] = volume(x[t[4 * e]], x[t[4 * e + 1]], x[t[4 * e + 2]], x[t[4 * e + 3]]);

  CutResult r;
  // signed distances; within rounding of the plane counts as on it
  std::vector<double> d(n0);
  for (index_t i = 0; i < n0; ++i) {
    d[i] = P.distance(x[i]);
    if (std::fabs(d[i]) <= 1e-9 * h[i]) d[i] = 0;
  }

  // 1. snap nodes near the plane onto it, where their elements keep their volume: an interior node along
  //    the plane's normal, a surface node along the surface (its move's normal part taken out)
  if (o.method != CutMethod::Split && o.snap > 0)
    for (index_t i = 0; i < n0; ++i) {
      if (d[i] == 0 || !(std::fabs(d[i]) < o.snap * h[i])) continue;
      V dir = P.n;
      if (boundary[i]) {
        if (!(flatness[i] > kSmooth)) continue;  // an edge or a corner of the surface: it stays
        const V nu = (1 / norm(outward[i])) * outward[i];
        dir = P.n - dot(P.n, nu) * nu;  // |dir|^2 = sin^2 of the angle between the plane and the surface
        if (!(dot(dir, dir) > 0.25)) continue;  // the plane runs within 30 degrees of the surface: leave it
      }
      const V moved = x[i] - (d[i] / dot(P.n, dir)) * dir;
      if (!(norm(moved - x[i]) < o.snap * h[i])) continue;
      bool ok = true;
      for (index_t e : star[i]) {
        V c[4];
        for (int k = 0; k < 4; ++k) c[k] = t[4 * e + k] == i ? moved : x[t[4 * e + k]];
        ok = ok && volume(c[0], c[1], c[2], c[3]) >= o.keep * v0[e];
      }
      if (!ok) continue;
      x[i] = moved;
      d[i] = 0;
      ++r.snapped;
    }

  for (index_t i = 0; i < n0; ++i)  // what stays this close counts as on the plane: the cut passes through it
    if (std::fabs(d[i]) < o.touch * h[i]) d[i] = 0;
  const auto side = [&](index_t v) { return d[v] > 0 ? 1 : d[v] < 0 ? -1 : 0; };
  const auto crossed = [&](index_t e) {
    bool pos = false, neg = false;
    for (int k = 0; k < 4; ++k) pos = pos || side(t[4 * e + k]) > 0, neg = neg || side(t[4 * e + k]) < 0;
    return pos && neg;
  };
  // the centroid of the element's cut polygon (its nodes on the plane and its edges' crossings)
  const auto polygon_over = [&](index_t e) {
    V c{0, 0, 0};
    int n = 0;
    for (int k = 0; k < 4; ++k)
      if (side(t[4 * e + k]) == 0) c = c + x[t[4 * e + k]], ++n;
    for (const auto& k : kEdge) {
      const index_t a = t[4 * e + k[0]], b = t[4 * e + k[1]];
      if (side(a) * side(b) < 0) c = c + (x[a] + (d[a] / (d[a] - d[b])) * (x[b] - x[a])), ++n;
    }
    return n > 0 && P.over((1.0 / n) * c);
  };

  // 2. split the crossed elements over the parallelogram, and (for a conforming mesh) every crossed element
  //    that shares a crossed edge with one split
  std::vector<std::uint8_t> split(e0, 0);
  std::vector<index_t> queue;
  bool meets = false;
  for (index_t e = 0; e < e0; ++e) {
    if (!crossed(e) || !polygon_over(e)) continue;
    meets = true;
    if (o.method == CutMethod::Snap) {
      ++r.unresolved;
      continue;
    }
    split[e] = 1;
    queue.push_back(e);
  }
  std::map<std::pair<index_t, index_t>, index_t> edge_node;  // crossed edge -> its node
  std::vector<std::array<index_t, 2>> from(n0);
  std::vector<double> weight(n0, 0);
  for (index_t i = 0; i < n0; ++i) from[i] = {i, i};
  for (std::size_t q = 0; q < queue.size(); ++q) {
    const index_t e = queue[q];
    for (const auto& k : kEdge) {
      index_t a = t[4 * e + k[0]], b = t[4 * e + k[1]];
      if (side(a) * side(b) >= 0) continue;
      if (a > b) std::swap(a, b);
      if (edge_node.count({a, b})) continue;
      const double w = d[a] / (d[a] - d[b]);
      edge_node[{a, b}] = index_t(x.size());
      x.push_back(x[a] + w * (x[b] - x[a]));
      d.push_back(0);
      from.push_back({a, b});
      weight.push_back(w);
      for (index_t f : star[a])  // the edge's other elements split too
        if (!split[f] && crossed(f) && std::find(t.begin() + 4 * f, t.begin() + 4 * f + 4, b) != t.begin() + 4 * f + 4) {
          split[f] = 1;
          queue.push_back(f);
        }
    }
  }
  r.edge_nodes = index_t(x.size()) - n0;

  std::vector<index_t> out;
  out.reserve(t.size() + 24 * queue.size());
  std::vector<index_t> elem_from;
  std::vector<index_t> more, more_from;  // the split elements' pieces
  std::vector<std::uint8_t> placed;      // per piece: the first of its element's, which takes its place
  Tets M{more, more_from, x, 0};
  for (index_t e = 0; e < e0; ++e) {
    if (!split[e]) {
      out.insert(out.end(), t.begin() + 4 * e, t.begin() + 4 * e + 4);
      elem_from.push_back(e);
      continue;
    }
    ++r.split;
    const index_t* v = &t[4 * e];
    const auto cross_node = [&](index_t a, index_t b) { return edge_node.at({std::min(a, b), std::max(a, b)}); };
    std::vector<index_t> pos, neg, zero;
    for (int k = 0; k < 4; ++k) (side(v[k]) > 0 ? pos : side(v[k]) < 0 ? neg : zero).push_back(v[k]);
    const std::size_t first = more.size() / 4;
    M.origin = e;
    if (zero.empty() && (pos.size() == 1 || neg.size() == 1)) {  // one node alone: a tet and a prism
      const std::vector<index_t>& lone = pos.size() == 1 ? pos : neg;
      const std::vector<index_t>& rest = pos.size() == 1 ? neg : pos;
      const index_t c0 = cross_node(lone[0], rest[0]), c1 = cross_node(lone[0], rest[1]),
                    c2 = cross_node(lone[0], rest[2]);
      M.tet(lone[0], c0, c1, c2);
      M.prism({c0, c1, c2, rest[0], rest[1], rest[2]});
    } else if (zero.empty()) {  // two and two: two prisms
      const index_t A = pos[0], B = pos[1], C = neg[0], D = neg[1];
      const index_t ac = cross_node(A, C), ad = cross_node(A, D), bc = cross_node(B, C), bd = cross_node(B, D);
      M.prism({A, ac, ad, B, bc, bd});
      M.prism({C, ac, bc, D, ad, bd});
    } else if (zero.size() == 1) {  // one on the plane: a tet and a pyramid
      const std::vector<index_t>& lone = pos.size() == 1 ? pos : neg;
      const std::vector<index_t>& rest = pos.size() == 1 ? neg : pos;
      const index_t c0 = cross_node(lone[0], rest[0]), c1 = cross_node(lone[0], rest[1]);
      M.tet(lone[0], zero[0], c0, c1);
      M.pyramid({rest[0], rest[1], c1, c0}, zero[0]);
    } else {  // two on the plane, one on each side: two tets
      const index_t c = cross_node(pos[0], neg[0]);
      M.tet(zero[0], zero[1], pos[0], c);
      M.tet(zero[0], zero[1], neg[0], c);
    }
    placed.resize(more.size() / 4, 0);
    placed[first] = 1;
    out.insert(out.end(), more.begin() + 4 * first, more.begin() + 4 * first + 4);
    elem_from.push_back(e);
  }
  for (std::size_t p = 0; p < placed.size(); ++p)  // the further pieces, after every kept or replaced element
    if (!placed[p]) {
      out.insert(out.end(), more.begin() + 4 * p, more.begin() + 4 * p + 4);
      elem_from.push_back(more_from[p]);
    }

  // 3. open the interior faces on the plane over the parallelogram
  const std::vector<FaceRef> faces = all_faces(out);
  const auto on_cut = [&](const std::array<index_t, 3>& k) {
    if (d[k[0]] != 0 || d[k[1]] != 0 || d[k[2]] != 0) return false;
    return P.over((1.0 / 3) * (x[k[0]] + x[k[1]] + x[k[2]]));
  };
  std::map<std::array<index_t, 3>, std::pair<index_t, index_t>> shared;  // interior face -> its two elements
  std::vector<std::uint8_t> cut_node(x.size(), 0);
  for (std::size_t i = 0; i + 1 < faces.size(); ++i)
    if (faces[i].key == faces[i + 1].key) {
      shared[faces[i].key] = {faces[i].elem, faces[i + 1].elem};
      if (on_cut(faces[i].key)) {
        ++r.cut_faces;
        for (index_t v : faces[i].key) cut_node[v] = 1;
      }
    }
  if (!meets && r.cut_faces == 0)
    throw CutError(fmt::format("cut: the cut surface (origin ({:.4g}, {:.4g}, {:.4g}) m, edge ({:.4g}, {:.4g}, "
                               "{:.4g}) m, sweep ({:.4g}, {:.4g}, {:.4g}) m) crosses no element of the mesh",
                               cut.origin.x, cut.origin.y, cut.origin.z, cut.edge.x, cut.edge.y, cut.edge.z,
                               cut.sweep.x, cut.sweep.y, cut.sweep.z));
  const index_t n_before = index_t(x.size()), ne = index_t(out.size() / 4);
  std::vector<std::vector<index_t>> star2(x.size());
  for (index_t e = 0; e < ne; ++e)
    for (int c = 0; c < 4; ++c)
      if (cut_node[out[4 * e + c]]) star2[out[4 * e + c]].push_back(e);
  std::vector<std::pair<std::size_t, index_t>> renumber;  // (corner slot, its node's copy)
  for (index_t v = 0; v < n_before; ++v) {
    if (!cut_node[v]) continue;
    const std::vector<index_t>& s = star2[v];  // ascending
    std::vector<index_t> parent(s.size());
    std::iota(parent.begin(), parent.end(), index_t(0));
    const auto root = [&](index_t i) {
      while (parent[i] != i) i = parent[i] = parent[parent[i]];
      return i;
    };
    const auto local = [&](index_t e) { return index_t(std::lower_bound(s.begin(), s.end(), e) - s.begin()); };
    for (index_t e : s)
      for (const auto& c : kFace) {
        const std::array<index_t, 3> k = sorted(out[4 * e + c[0]], out[4 * e + c[1]], out[4 * e + c[2]]);
        if (k[0] != v && k[1] != v && k[2] != v) continue;
        const auto it = shared.find(k);
        if (it == shared.end() || on_cut(k)) continue;
        const index_t a = root(local(it->second.first)), b = root(local(it->second.second));
        if (a != b) parent[std::max(a, b)] = std::min(a, b);
      }
    // the group of the lowest element keeps v; each further group gets a copy (renumbered below, so that
    // every node's groups are found on the connectivity before any copy)
    std::map<index_t, index_t> copy;  // group root -> node
    for (std::size_t i = 0; i < s.size(); ++i) {
      const index_t g = root(index_t(i));
      if (g == root(0)) continue;
      auto [it, fresh] = copy.emplace(g, index_t(x.size()));
      if (fresh) {
        x.push_back(x[v]);
        d.push_back(0);
        from.push_back(from[v]);
        weight.push_back(weight[v]);
        ++r.copies;
      }
      for (int c = 0; c < 4; ++c)
        if (out[4 * s[i] + c] == v) renumber.push_back({4 * std::size_t(s[i]) + std::size_t(c), it->second});
    }
  }
  for (const auto& [slot, node] : renumber) out[slot] = node;

  r.nodes.resize(3 * x.size());
  for (std::size_t i = 0; i < x.size(); ++i) r.nodes[3 * i] = x[i].x, r.nodes[3 * i + 1] = x[i].y, r.nodes[3 * i + 2] = x[i].z;
  r.tets = std::move(out);
  r.from = std::move(from);
  r.weight = std::move(weight);
  r.element_from = std::move(elem_from);
  return r;
}

std::vector<double> MovingCut::Transfer::operator()(std::span<const double> field) const {
  const std::size_t n = std::size_t(n_old), m = between.size();
  if (field.size() != 3 * n)
    throw std::invalid_argument(
        fmt::format("cut transfer: a field of {} values for the old mesh's {} nodes (3 per node)", field.size(), n));
  const std::size_t places = start.size() - 1;
  std::vector<double> at(3 * places), out(3 * m);
  for (std::size_t p = 0; p < places; ++p)
    for (std::size_t c = 0; c < 3; ++c) {
      double sum = 0;
      for (index_t k = start[p]; k < start[p + 1]; ++k) sum += weight[std::size_t(k)] * field[c * n + std::size_t(node[std::size_t(k)])];
      at[3 * p + c] = sum;
    }
  for (std::size_t i = 0; i < m; ++i) {
    const auto [a, b] = between[i];
    for (std::size_t c = 0; c < 3; ++c) {
      const double fa = at[3 * std::size_t(a) + c], fb = at[3 * std::size_t(b) + c];
      out[c * m + i] = a == b ? fa : (1 - w[i]) * fa + w[i] * fb;
    }
  }
  return out;
}

MovingCut cut_moving(std::span<const double> X, std::span<const index_t> tets, std::span<const double> u,
                     std::span<const double> u_prev, const CutSurface& cut, const CutOptions& o, CutSpace space) {
  const std::size_t n = X.size() / 3;
  if (X.size() % 3 != 0 || u.size() != 3 * n || u_prev.size() != 3 * n)
    throw CutError(fmt::format("cut: {} reference coordinates, {} displacements and {} previous ones are not 3 per "
                               "node each",
                               X.size(), u.size(), u_prev.size()));
  const auto field = [n](std::span<const double> f, std::size_t a) { return V{f[a], f[n + a], f[2 * n + a]}; };
  const auto ref = [&](std::size_t a) { return V{X[3 * a], X[3 * a + 1], X[3 * a + 2]}; };
  std::vector<double> x(X.size());
  for (std::size_t a = 0; a < n; ++a) {
    const V p = space == CutSpace::Deformed ? ref(a) + field(u, a) : ref(a);
    x[3 * a] = p.x, x[3 * a + 1] = p.y, x[3 * a + 2] = p.z;
  }
  MovingCut out;
  out.cut = cut_along(x, tets, cut, o);
  CutResult& r = out.cut;
  const std::size_t m = std::size_t(r.n_nodes());
  const auto now = [&](std::size_t a) { return V{x[3 * a], x[3 * a + 1], x[3 * a + 2]}; };
  const auto placed = [&](std::size_t i) { return V{r.nodes[3 * i], r.nodes[3 * i + 1], r.nodes[3 * i + 2]}; };

  // each input node's elements, for the snapped ones' new place
  std::vector<index_t> start(n + 1, 0), star(tets.size());
  for (index_t v : tets) ++start[std::size_t(v) + 1];
  std::partial_sum(start.begin(), start.end(), start.begin());
  {
    std::vector<index_t> fill(start.begin(), start.end() - 1);
    for (std::size_t k = 0; k < tets.size(); ++k) star[std::size_t(fill[std::size_t(tets[k])]++)] = index_t(k / 4);
  }
  // an input node's reference place and motion after the cut: its own, or (snapped) the field at its new place,
  // from the element of its star that holds it (the one whose smallest barycentric weight is largest); each a
  // place of the transfer, its weights on old nodes
  MovingCut::Transfer& tr = out.transfer;
  tr.n_old = index_t(n);
  tr.start = {0};
  const auto add_place = [&](std::span<const index_t> corners, std::span<const double> w) {
    for (std::size_t j = 0; j < corners.size(); ++j) {
      tr.node.push_back(corners[j]);
      tr.weight.push_back(w[j]);
    }
    tr.start.push_back(index_t(tr.node.size()));
    return index_t(tr.start.size() - 2);
  };
  std::vector<index_t> kept(n, -1);
  // the boundary faces (in one element only), by node: a surface node's new place is taken back onto the
  // reference surface, so that the reference mesh keeps the old one's boundary and volume
  std::vector<std::vector<std::array<index_t, 3>>> boundary(n);
  {
    const std::vector<index_t> all(tets.begin(), tets.end());
    const std::vector<FaceRef> faces = all_faces(all);
    for (std::size_t f = 0; f < faces.size(); ++f) {
      const bool twice = (f > 0 && faces[f - 1].key == faces[f].key) ||
                         (f + 1 < faces.size() && faces[f + 1].key == faces[f].key);
      if (twice) continue;
      for (index_t v : faces[f].key) boundary[std::size_t(v)].push_back(faces[f].key);
    }
  }
  const auto kept_place = [&](std::size_t k, V p) -> index_t {
    if (kept[k] >= 0) return kept[k];
    const index_t self[1] = {index_t(k)};
    const double one[1] = {1.0};
    if (norm(p - now(k)) == 0) return kept[k] = add_place(self, one);
    if (!boundary[k].empty()) {  // the nearest point of its boundary faces, as they are now
      double nearest = INFINITY;
      std::array<index_t, 3> corners{};
      double at[3] = {1, 0, 0};
      bool found = false;
      for (const std::array<index_t, 3>& f : boundary[k]) {
        double w[3];
        const V q = closest_on_triangle(p, now(std::size_t(f[0])), now(std::size_t(f[1])), now(std::size_t(f[2])), w);
        if (!(norm(q - p) < nearest)) continue;
        nearest = norm(q - p);
        corners = f;
        std::copy(w, w + 3, at);
        found = true;
      }
      return kept[k] = found ? add_place(corners, at) : add_place(self, one);
    }
    double best = -INFINITY;
    std::array<index_t, 4> corners{};
    double at[4] = {};
    bool found = false;
    for (index_t s = start[k]; s < start[k + 1]; ++s) {
      const std::size_t e = std::size_t(star[std::size_t(s)]);
      const index_t* c = &tets[4 * e];
      const double v = volume(now(c[0]), now(c[1]), now(c[2]), now(c[3]));
      double w[4];
      for (int j = 0; j < 4; ++j) {
        V corner[4] = {now(c[0]), now(c[1]), now(c[2]), now(c[3])};
        corner[j] = p;
        w[j] = volume(corner[0], corner[1], corner[2], corner[3]) / v;
      }
      const double least = std::min({w[0], w[1], w[2], w[3]});
      if (!(least > best)) continue;
      best = least;
      // a place a rounding (or a surface node's slide over a curved face) outside the star: its nearest
      // point in the element, so that the reference mesh stays inside the old one and keeps its volume
      double sum = 0;
      for (double& wj : w) sum += (wj = std::max(wj, 0.0));
      for (double& wj : w) wj /= sum;
      std::copy(c, c + 4, corners.begin());
      std::copy(w, w + 4, at);
      found = true;
    }
    return kept[k] = found ? add_place(corners, at) : add_place(self, one);
  };
  tr.between.resize(m);
  tr.w.assign(m, 0.0);
  for (std::size_t i = 0; i < m; ++i) {
    const auto [a, b] = r.from[i];
    if (a == b) {
      const index_t p = kept_place(std::size_t(a), placed(i));
      tr.between[i] = {p, p};
      continue;
    }
    // an edge node: between its ends as they are after the snap (each end's own kept place)
    tr.between[i] = {kept_place(std::size_t(a), placed(std::size_t(a))), kept_place(std::size_t(b), placed(std::size_t(b)))};
    tr.w[i] = r.weight[i];
  }
  out.u = tr(u);
  out.u_prev = tr(u_prev);
  std::vector<double> X_major(3 * n);
  for (std::size_t a = 0; a < n; ++a)
    for (int c = 0; c < 3; ++c) X_major[std::size_t(c) * n + a] = X[3 * a + std::size_t(c)];
  const std::vector<double> X_new = tr(X_major);
  for (std::size_t i = 0; i < m; ++i)
    for (int c = 0; c < 3; ++c) r.nodes[3 * i + std::size_t(c)] = X_new[std::size_t(c) * m + i];
  return out;
}

Vec3<double> pull_back(std::span<const double> X, std::span<const index_t> tets, std::span<const double> u,
                       Vec3<double> p) {
  const std::size_t n = X.size() / 3;
  const auto disp = [&](std::size_t a) { return V{u[a], u[n + a], u[2 * n + a]}; };
  const auto at = [&](std::size_t a) { return V{X[3 * a], X[3 * a + 1], X[3 * a + 2]} + disp(a); };
  double best = -INFINITY;
  V shift = {0, 0, 0};  // u at p: x = X + u is affine in each element, so X = p - u(p)
  for (std::size_t e = 0; e < tets.size() / 4; ++e) {
    const index_t* c = &tets[4 * e];
    const V corner[4] = {at(std::size_t(c[0])), at(std::size_t(c[1])), at(std::size_t(c[2])), at(std::size_t(c[3]))};
    const double v = volume(corner[0], corner[1], corner[2], corner[3]);
    if (!(v > 0)) continue;
    double w[4];
    for (int j = 0; j < 4; ++j) {
      V moved[4] = {corner[0], corner[1], corner[2], corner[3]};
      moved[j] = p;
      w[j] = volume(moved[0], moved[1], moved[2], moved[3]) / v;
    }
    const double least = std::min({w[0], w[1], w[2], w[3]});
    if (!(least > best)) continue;
    best = least;
    // outside the mesh: the displacement of the nearest element's nearest point (a translation, not the
    // element's map extrapolated)
    double sum = 0;
    for (double& wj : w) sum += (wj = std::max(wj, 0.0));
    shift = {0, 0, 0};
    for (int j = 0; j < 4; ++j) shift = shift + (w[j] / sum) * disp(std::size_t(c[j]));
    if (least >= 0) break;  // inside this element
  }
  return p - shift;
}

std::vector<index_t> twin_triangles(std::span<const index_t> tris,
                                    const std::function<Vec3<double>(index_t)>& position) {
  const std::size_t nt = tris.size() / 3;
  using Key = std::array<double, 9>;  // the sorted corners' coordinates
  struct KeyHash {
    std::size_t operator()(const Key& k) const {
      std::size_t h = 0;
      for (double v : k) h = h * 1000003u ^ std::hash<double>{}(v);
      return h;
    }
  };
  std::unordered_map<Key, index_t, KeyHash> first;
  first.reserve(nt);
  std::vector<index_t> twin(nt, -1);
  for (std::size_t t = 0; t < nt; ++t) {
    std::array<Vec3<double>, 3> c = {position(tris[t]), position(tris[nt + t]), position(tris[2 * nt + t])};
    std::sort(c.begin(), c.end(), [](const Vec3<double>& a, const Vec3<double>& b) {
      return a.x != b.x ? a.x < b.x : a.y != b.y ? a.y < b.y : a.z < b.z;
    });
    const Key key = {c[0].x, c[0].y, c[0].z, c[1].x, c[1].y, c[1].z, c[2].x, c[2].y, c[2].z};
    const auto [it, fresh] = first.emplace(key, index_t(t));
    if (fresh) continue;
    twin[t] = it->second;
    twin[std::size_t(it->second)] = index_t(t);
  }
  return twin;
}

}  // namespace tissue
