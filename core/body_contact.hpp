// Contact between bodies (docs/contact.md, "Bodies touching each other"),
// written once for every backend: the host builds the candidate lists
// (build_body_lists), the cpu backend runs the per-step rule in loops over
// them, the cuda backend in two kernels.
//
// The rule, per TLED step, after the step's free displacement update and
// before the tools' contact stage (a tool is rigid and has the last word):
//  1. every surface node p of a body that touches another (a row) finds,
//     among its candidate triangles of the bodies it touches, the one whose
//     closest point q is nearest (ties: the one whose plane p lies furthest
//     from, then the first; each compared past 64 double epsilons of p's
//     coordinates, so that roundings do not decide); p is inside when it
//     lies behind that triangle's plane (dot(p - q, N) < 0, N the
//     triangle's outward normal) and |p - q| is at
//     most the contact's reach (the lists' skin: a node further in has passed
//     through, and is left alone);
//  2. the gap g = q - p is closed between the node and the triangle's
//     corners in proportion to their inverse masses: with the barycentric
//     weights w_k of q and W = 1/m_p + sum_k w_k^2 / m_k,
//       dx_p = (1/m_p) C / W,   dx_k = -(1/m_k) w_k C / W,
//     so that p and q meet and sum m dx = 0 (no momentum made). With
//     friction mu, C = g minus p's tangential offset s from its anchor, up
//     to mu |g| (Coulomb: stick, or slide with the tangential share mu). The
//     anchor is the point of the other surface p sticks to, carried from
//     step to step as a triangle and weights (a material point): where p
//     was sent the step it came into contact or last slid; in its first
//     step in contact s is the step's relative tangential motion of p and
//     q. A node that cannot move (fixed, halo or outside the region,
//     grasped) has 1/m = 0, and a pair where nothing can move is skipped;
//  3. each contact's correction is scaled by one over the most any of its
//     nodes takes part in contacts, a corner by its weight (body_row_count:
//     a node between several contacts is not
//     moved by each in full, which would overshoot and push the bodies apart
//     with energy the contact made; both sides scale alike, so no momentum
//     is made either), and each node sums, in list order, its own scaled
//     correction and its shares as a corner of other rows' triangles; a
//     roller's held component stays.
// The corrections close the gap where the step left one and never pull:
// bodies that separate by themselves are not touched.
//
// The lips of a cut (BodyContactSpec::lips) touch each other by the same
// rule: a lip is a surface triangle with a twin of the same reference
// corners in the same body (the two faces a cut opened from one); a lip's
// corner is a row, and its candidates are the lips facing it (reference
// normal against the node's lip normal, the sum of its lips' reference
// normals; a corner of lips of both sides, on a crack's front, has none).
//
// Candidate lists (Verlet lists): a row's candidates are the triangles of
// the bodies it touches (or the lips facing it) whose box comes within the skin of the node when
// the lists are built; they hold while no listed node has moved more than a
// quarter of the skin since (body_lists_stale), checked after every advance.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "core/contact.hpp"
#include "core/vec.hpp"

namespace tissue {

template <class T> struct TissueModel;

/// Which bodies touch: the bodies as node ranges of the one mesh, and the
/// pairs that may touch, each with its Coulomb coefficient; and whether the
/// lips of cuts touch each other.
struct BodyContactSpec {
  std::vector<index_t> first_node;  ///< per body, then n_nodes: ascending, first 0 (empty: one body, for lips alone)
  struct Pair {
    int a = 0, b = 0;               ///< body indices, a != b
    double friction = 0;            ///< mu (>= 0)
  };
  std::vector<Pair> pairs;
  bool lips = false;                ///< a cut's two lips keep out of each other (a mesh without lips has no rows)
  double lip_friction = 0;          ///< mu between lips (>= 0)
  double skin = 0;                  ///< m (> 0): list reach; 0 = the median surface edge
  bool empty() const { return pairs.empty() && !lips; }
  int n_bodies() const { return first_node.empty() ? 0 : int(first_node.size()) - 1; }
};

/// Host-built candidate lists of one mesh (the arrays both backends read).
struct BodyLists {
  double skin = 0;                      ///< m: the lists' reach (and the deepest correction)
  std::vector<index_t> node;            ///< rows: the touching bodies' surface nodes, ascending
  std::vector<index_t> cand_start;      ///< (rows + 1)
  std::vector<index_t> cand_tri;        ///< candidate triangles of each row, ascending
  std::vector<double> cand_mu;          ///< each candidate's Coulomb coefficient
  std::vector<index_t> cand_rows;       ///< 3 per candidate: the rows of its triangle's corners
  std::vector<index_t> corner_start;    ///< (rows + 1): the candidates whose triangle has the row's node as a corner
  std::vector<index_t> corner_cand;     ///< index into cand_tri, ascending per row
  std::vector<index_t> corner_row;      ///< the row that candidate belongs to
  std::vector<std::uint8_t> corner_slot;  ///< the node's corner (0..2) of that triangle
  std::vector<double> x_built;          ///< 3 per row: the node's position when built (m)
  index_t rows() const { return index_t(node.size()); }
};

/// The surface nodes of the spec's touching bodies and their candidate
/// triangles at positions x (3 per node, xyz; X + u). The surface's triangles
/// are those of m; a triangle belongs to the body of its first corner.
/// std::invalid_argument for a bad spec (names the body or pair and the rule).
template <class T>
BodyLists build_body_lists(const TissueModel<T>& m, const BodyContactSpec& spec, const std::vector<double>& x);

/// Whether any row's node, at pos(a) (m, Vec3<double>), has moved more than
/// a quarter of the skin since the lists were built.
template <class Pos>
bool body_lists_stale(const BodyLists& lists, Pos pos) {
  const double limit = 0.25 * lists.skin;
  for (index_t r = 0; r < lists.rows(); ++r) {
    const Vec3<double> x = pos(lists.node[r]);
    const Vec3<double> d = {x.x - lists.x_built[3 * std::size_t(r)], x.y - lists.x_built[3 * std::size_t(r) + 1],
                            x.z - lists.x_built[3 * std::size_t(r) + 2]};
    if (dot(d, d) > limit * limit) return true;
  }
  return false;
}

/// The spec checked against a mesh of n_nodes nodes (std::invalid_argument naming what is wrong).
void check_body_contact(const BodyContactSpec& spec, index_t n_nodes);

/// A row's stick anchor (rule 2): the point of another body's surface its
/// node sticks to, as triangle `tri` and the weights w[0], w[1], 1 - w[0] -
/// w[1] of its corners (a material point: it moves with that surface).
/// tri -1: none (no contact at the last step, or no friction). Carried
/// across steps and list rebuilds (the rows do not change); a new initial
/// state (set_displacements) clears it.
template <class T>
struct BodyAnchor {
  index_t tri = -1;
  T w[2] = {T(0), T(0)};
};

/// The weights of y's projection onto the plane of P0 P1 P2 (outside the
/// triangle too: negative weights); false for a degenerate triangle.
template <class T>
TISSUE_HD bool plane_weights(Vec3<T> y, Vec3<T> P0, Vec3<T> P1, Vec3<T> P2, T w[3]) {
  const Vec3<T> e1 = P1 - P0, e2 = P2 - P0, d = y - P0;
  const T a = dot(e1, e1), b = dot(e1, e2), c = dot(e2, e2), den = a * c - b * b;
  if (!(den > T(0))) return false;
  const T p = dot(d, e1), q = dot(d, e2);
  w[1] = (c * p - b * q) / den;
  w[2] = (a * q - b * p) / den;
  w[0] = T(1) - w[1] - w[2];
  return true;
}

/// One row's contact over one step: the candidate it touches (-1: none),
/// the correction per unit inverse mass c (= C / W) and q's weights.
template <class T>
struct BodyHit {
  index_t cand = -1;
  T gap = T(0);                     ///< |q - p| before the correction (m)
  Vec3<T> c = {T(0), T(0), T(0)};
  T w[3] = {T(0), T(0), T(0)};
};

/// A candidate triangle after the step's free update: its corners, and
/// the ball about their centroid m (radius^2 r2) that holds it.
template <class T>
struct BodyTri {
  Vec3<T> p[3];
  Vec3<T> m;
  T r2;
};

/// Triangle t's BodyTri from pos(a) (the position after the free update)
/// and tri(t, k) (corner k of triangle t).
template <class T, class Pos, class Tri>
TISSUE_HD BodyTri<T> body_tri(index_t t, Pos pos, Tri tri) {
  BodyTri<T> g;
  for (int k = 0; k < 3; ++k) g.p[k] = pos(tri(t, k));
  g.m = T(1) / T(3) * (g.p[0] + g.p[1] + g.p[2]);
  g.r2 = std::fmax(dot(g.p[0] - g.m, g.p[0] - g.m), std::fmax(dot(g.p[1] - g.m, g.p[1] - g.m), dot(g.p[2] - g.m, g.p[2] - g.m)));
  return g;
}

/// Rule 1 and 2 for one row. pos(a), prev(a): node a's position after the
/// free update and at the step's start; inv_mass(a): 1/m or 0 (immovable);
/// tri(t, k): corner k of triangle t; geom(t): body_tri(t, pos, tri), or
/// the same read from where it was computed once for the step. was: the
/// row's anchor from the step before; now receives this step's.
template <class T, class Pos, class Prev, class InvMass, class Tri, class Geom>
TISSUE_HD BodyHit<T> body_row_hit(index_t p, index_t first, index_t last, const index_t* cand_tri, const T* cand_mu,
                                  T reach, Pos pos, Prev prev, InvMass inv_mass, Tri tri, Geom geom,
                                  const BodyAnchor<T>& was, BodyAnchor<T>& now) {
  now = BodyAnchor<T>{};
  BodyHit<T> hit;
  const Vec3<T> xp = pos(p);
  // what double's rounding can move p's distances and sides by: 64 epsilons of its coordinates.
  // (Float's contact gaps are a few roundings of its positions: a window of its own would
  // swallow them, so float keeps this double-sized one, and its roundings can still flip ties.)
  const T tiny = T(64 * std::numeric_limits<double>::epsilon()) * (std::fabs(xp.x) + std::fabs(xp.y) + std::fabs(xp.z));
  T best = reach, best_side = T(0);
  index_t best_cand = -1;
  Vec3<T> best_q{};
  T best_w[3] = {T(0), T(0), T(0)};
  for (index_t j = first; j < last; ++j) {
    const index_t t = cand_tri[j];
    // Skipped when it cannot be as near as the best so far: every point of
    // it lies within r of its centroid m, so it is further than `best`
    // (with a margin past the tie window) when |p - m| > r + 1.01 best,
    // which |p - m|^2 > 2 (r^2 + (1.01 best)^2) implies.
    const BodyTri<T> g = geom(t);
    const T near = T(1.01) * best;
    if (dot(xp - g.m, xp - g.m) > T(2) * (g.r2 + near * near)) continue;
    const Vec3<T> P0 = g.p[0], P1 = g.p[1], P2 = g.p[2];
    T w[3];
    const Vec3<T> q = closest_on_triangle(xp, P0, P1, P2, w);
    const Vec3<T> N = unit_or(cross(P1 - P0, P2 - P0), Vec3<T>{T(0), T(0), T(0)});
    const T d = norm(q - xp), side = dot(xp - q, N);
    // nearest; of equally near (a shared edge or corner), the one p lies furthest from the plane of;
    // of those, the first (coplanar faces): each compared past what rounding can change, so that
    // the backends' roundings pick the same
    const bool nearer = d < best * (T(1) - T(64) * std::numeric_limits<T>::epsilon()) - tiny;
    const bool tie = !nearer && d <= best * (T(1) + T(64) * std::numeric_limits<T>::epsilon()) + tiny;
    if (nearer || (tie && std::fabs(side) > std::fabs(best_side) + tiny)) {
      best = d;
      best_side = side;
      best_cand = j;
      best_q = q;
      for (int k = 0; k < 3; ++k) best_w[k] = w[k];
    }
  }
  if (best_cand < 0 || !(best_side < T(0)) || !(best > T(0))) return hit;  // outside, or exactly on
  const index_t t = cand_tri[best_cand];
  const index_t c[3] = {tri(t, 0), tri(t, 1), tri(t, 2)};
  const T ip = inv_mass(p);
  T W = ip;
  for (int k = 0; k < 3; ++k) W += best_w[k] * best_w[k] * inv_mass(c[k]);
  if (!(W > T(0))) return hit;  // nothing here can move
  const Vec3<T> g = best_q - xp, n = T(1) / best * g;
  Vec3<T> C = g;
  const T mu = cand_mu[best_cand];
  if (mu > T(0)) {
    Vec3<T> rel;
    if (was.tri >= 0) {  // p's offset from the point it sticks to
      const T wa[3] = {was.w[0], was.w[1], T(1) - was.w[0] - was.w[1]};
      Vec3<T> a{T(0), T(0), T(0)};
      for (int k = 0; k < 3; ++k) a = a + wa[k] * pos(tri(was.tri, k));
      rel = xp - a;
    } else {  // its first step in contact: the step's relative motion
      Vec3<T> dq{T(0), T(0), T(0)};
      for (int k = 0; k < 3; ++k) dq = dq + best_w[k] * (pos(c[k]) - prev(c[k]));
      rel = (xp - prev(p)) - dq;
    }
    const Vec3<T> rel_t = rel - dot(rel, n) * n;
    const T slip = norm(rel_t), cap = mu * best;
    const bool stick = slip <= cap;
    const Vec3<T> back = stick ? rel_t : (cap / slip) * rel_t;
    C = C - back;
    if (stick && was.tri >= 0) {
      now = was;
    } else {  // anchored where p is sent: q less what friction takes back
      T wn[3];
      if (!plane_weights(best_q - back, pos(c[0]), pos(c[1]), pos(c[2]), wn))
        for (int k = 0; k < 3; ++k) wn[k] = best_w[k];
      now.tri = t;
      now.w[0] = wn[0];
      now.w[1] = wn[1];
    }
  }
  hit.cand = best_cand;
  hit.gap = best;
  hit.c = T(1) / W * C;
  for (int k = 0; k < 3; ++k) hit.w[k] = best_w[k];
  return hit;
}

/// Rule 3, first: how much row `row`'s node takes part in contacts: 1 for
/// its own hit, and w for each hit of another row whose triangle has it as
/// a corner of weight w > 0 (the corner entries first..last, in order).
/// Weighted, so that a corner of vanishing weight counts for nothing: a node
/// whose nearest point moves between two triangles of a shared corner or
/// edge changes no count by a jump.
template <class T, class Hits>
TISSUE_HD T body_row_count(index_t row, index_t first, index_t last, const index_t* corner_cand,
                           const index_t* corner_row, const std::uint8_t* corner_slot, Hits hits) {
  T count = hits(row).cand >= 0 ? T(1) : T(0);
  for (index_t e = first; e < last; ++e) {
    const BodyHit<T>& h = hits(corner_row[e]);
    const T w = h.w[corner_slot[e]];
    if (h.cand == corner_cand[e] && w > T(0)) count += w;
  }
  return count;
}

/// Rule 3, second: a row's hit scaled by one over the most any of its nodes
/// takes part in contacts (counts by row; cand_rows: the rows of each
/// candidate triangle's corners, 3 a candidate): its own node's count, and
/// each corner's, whole from weight 1/4 up and below it blended towards 1 as
/// the weight falls to 0 (1 + 4 w (count - 1)), so that a corner leaving the
/// hit changes no scale by a jump. Both sides of a contact scale alike, so
/// it still makes no momentum, and no node moves by more than about the
/// weighted mean of its contacts' full corrections (a blend over all weights,
/// 1 + w (count - 1), let corners of middling weight overshoot: a sheared
/// pair's friction then pushed the upper block back against its pull).
template <class T>
TISSUE_HD void body_scale_hit(BodyHit<T>& h, index_t row, const index_t* cand_rows, const T* counts) {
  if (h.cand < 0) return;
  constexpr T full = T(0.25);  // a corner of at least this weight weighs in with its whole count
  T most = counts[row];
  for (int k = 0; k < 3; ++k) {
    if (!(h.w[k] > T(0))) continue;
    const T lean = h.w[k] < full ? h.w[k] / full : T(1);
    const T c = T(1) + lean * (counts[cand_rows[3 * h.cand + k]] - T(1));
    most = c > most ? c : most;
  }
  if (most > T(1)) h.c = (T(1) / most) * h.c;
}

/// Rule 3, last: row `row`'s node's move, from its own (scaled) hit and its
/// shares of the hits whose triangle has it as a corner, summed in list order.
template <class T, class Hits>
TISSUE_HD Vec3<T> body_row_move(index_t row, T inv_mass, index_t first, index_t last, const index_t* corner_cand,
                                const index_t* corner_row, const std::uint8_t* corner_slot, Hits hits) {
  Vec3<T> sum{T(0), T(0), T(0)};
  if (!(inv_mass > T(0))) return sum;
  const BodyHit<T>& own = hits(row);
  if (own.cand >= 0) sum = own.c;
  for (index_t e = first; e < last; ++e) {
    const BodyHit<T>& h = hits(corner_row[e]);
    if (h.cand != corner_cand[e]) continue;
    const T w = h.w[corner_slot[e]];
    if (w > T(0)) sum = sum - w * h.c;
  }
  return inv_mass * sum;
}

}  // namespace tissue
