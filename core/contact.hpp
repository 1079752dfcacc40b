// Tool contact (docs/contact.md), written once for every backend as
// host/device functions: the cpu backend runs them in TBB loops over the
// candidates its BVH finds, the cuda backend in kernels over the surface.
//
// The rule, per TLED step, after the step's free displacement update:
//  1. every surface triangle near a tool is swept along the tool's motion
//     during the step, in contact_substeps() checks per step (the tool moves
//     at most r / 2 between two checks: no tunnelling); at each check
//     (a) node contact: each corner inside the capsule moves to the nearest
//         point of the capsule's surface (radially from the axis);
//     (b) face contact: if the triangle's deepest point -- its point
//         closest to the axis -- is still inside by more than the face's
//         allowance (face_allowance: the sagitta of a flat face whose
//         corners lie on the tool, at most 5 % of r) -- the tool is smaller
//         than the triangle, or pokes between its corners -- the triangle
//         moves so that this point comes back to the allowance: the correction
//         delta n is spread to the corners with barycentric weights,
//         dx_k = w_k delta n / sum_j w_j^2 (the smallest corner motion that
//         moves the point by delta n); corners that cannot move (fixed,
//         outside the region, grasped) take no share.
//     Sidedness: the tool belongs on the outer side of every face (its
//     outward normal N). Where its tip has passed through a face -- the
//     axis point nearest the face is the tip, and it lies on the face, or
//     more than kThrough radii on the tissue's side of the face's plane
//     having crossed that plane since the previous check (a fast tool) or
//     with its nearest point inside the face (the face cuts the tip sphere
//     beyond its centre) -- (a) moves that face's corners and
//     (b) the face along -N to the far side of the tip (tip_exit),
//     instead of radially out through the tool: a tool cannot slip through
//     the surface. A face lying along the shaft (N crosswise to it) that
//     the shaft lies more than kThrough radii behind, under the face or
//     having crossed its plane since the previous check, goes the same way
//     to the shaft's far side (through_exit), the whole face at least as
//     far as its point over the axis. A face across the shaft instead is
//     the rim of the hole the shaft makes: its corners go out radially from
//     the shaft (moving it along -N would carry it down the whole shaft);
//  2. each surface node combines its triangles' proposals dx_i, in
//     ascending triangle order, into one correction that satisfies each of
//     them along its own direction: dx = dx_1, then for every further
//     proposal the shortfall |dx_i| - dx . dx_i / |dx_i|, if positive, is
//     added along dx_i, in kMergePasses passes over the proposals (one
//     suffices unless two are more than 90 degrees apart) -- a continuous
//     rule: a node between two triangles does not flip from one to the
//     other from step to step. It moves by dx in
//     its free components (a roller's held component stays) and is in
//     contact with the tool of its largest proposal, with the contact normal
//     n = the unit free part of dx (out of the tool).
//     Friction (core/node_rules.hpp coulomb_slip): the node's tangential
//     motion relative to the tool over the step is removed up to mu |dx|
//     (all of it: the node sticks; part: it slides, the tool's tangential
//     impulse mu times its normal one). It leaves the step
//     with the tool's normal velocity and half of its own tangential
//     velocity relative to the tool (core/node_rules.hpp contact_previous).
// The contact never pulls: a node that the tissue carries out of the tool
// by itself is not inside after the free update, so it is not moved and
// leaves the contact set. Grasped nodes follow the tool rigidly instead.
//
// Reaction on a tool: each pushing contact node is held in its normal n by
// the force (f . n) n, f its internal force, clamped at zero (a contact
// cannot pull), and along the tool by f's tangential part f_t up to
// mu (f . n) (f_t: stuck; mu (f . n) f_t / |f_t|: sliding); a grasped node
// by its whole internal force f. The force on the tool is minus their sum
// (contact_reaction).
#pragma once

#include <cstdint>
#include <limits>

#include "core/tool.hpp"
#include "core/vec.hpp"

namespace tissue {

/// What a surface node's contact is (one byte per node).
enum ContactKind : std::uint8_t {
  kNoContact = 0,
  kPushed = 1,          ///< moved onto a tool's surface this step (held along it by friction up to mu)
  kGrasped = 2,         ///< stuck to a grasping tool
  kRigidContact = 3,    ///< inside a tool but held by the scene (fixed): a rigid support under the tool
  kOutsideRegion = 4,   ///< inside a tool but not an inner node of the region: it cannot move
};

/// One tool over one advance() of `steps` TLED steps, in the backend's scalar.
template <class T>
struct ToolStep {
  Vec3<T> tip0, axis0;        ///< pose at the start of the advance (m, unit)
  Vec3<T> tip1, axis1;        ///< pose at its end
  T radius, shaft;            ///< m
  int substeps;               ///< contact checks per TLED step (>= 1)
  int grasping;               ///< 1 = its grasped nodes follow it
  Vec3<T> grasp_tip, grasp_axis;  ///< the pose when the grasp started
  T friction;                 ///< Coulomb's mu at its pushed nodes (0: frictionless; coulomb_slip)
};

/// Every tool over one advance(); what the contact stage reads.
template <class T>
struct ContactTools {
  int n_tools = 0;
  int steps = 1;              ///< TLED steps of the advance (the poses are interpolated across them)
  int face = 1;               ///< 1 = face contact on (0: node contact only; a tradeoff setting)
  /// Checks of the region's candidate sweep (contact_candidates: the whole
  /// advance as one step), per tool: for a backend that checks on the
  /// device whether the region must grow before the steps.
  int sweep_substeps[kMaxTools] = {};
  ToolStep<T> tool[kMaxTools];
};

/// The same tools in another scalar (a backend's: Backend hands them over in double).
template <class T>
ContactTools<T> contact_tools_as(const ContactTools<double>& d) {
  const auto v = [](Vec3<double> x) { return Vec3<T>{T(x.x), T(x.y), T(x.z)}; };
  ContactTools<T> c{};
  c.n_tools = d.n_tools;
  c.steps = d.steps;
  c.face = d.face;
  for (int t = 0; t < kMaxTools; ++t) c.sweep_substeps[t] = d.sweep_substeps[t];
  for (int t = 0; t < d.n_tools; ++t) {
    const ToolStep<double>& s = d.tool[t];
    c.tool[t] = {v(s.tip0), v(s.axis0), v(s.tip1), v(s.axis1), T(s.radius), T(s.shaft), s.substeps, s.grasping,
                 v(s.grasp_tip), v(s.grasp_axis), T(s.friction)};
  }
  return c;
}

/// A capsule: segment a -> b (a = tip) and radius r.
template <class T>
struct Capsule {
  Vec3<T> a, b;
  T r;
};

/// The capsule of tool t at the sub-check `j` (1..substeps) of step k
/// (0..steps-1) of the advance: the pose a fraction (k + j / substeps) /
/// steps of the way from the start pose to the end pose.
template <class T>
TISSUE_HD Capsule<T> tool_capsule(const ToolStep<T>& t, int steps, int k, int j) {
  const T s = (T(k) + T(j) / T(t.substeps)) / T(steps);
  Vec3<T> tip, axis;
  interpolate_pose(t.tip0, t.axis0, t.tip1, t.axis1, s, tip, axis);
  return {tip, tip + t.shaft * axis, t.radius};
}

/// The sub-check capsules of TLED step k of an advance, as the sweep reads
/// them: capsule(t, j) for tool t and j = 0..substeps (0: where the previous
/// step's last check left it). This one computes each on demand (a GPU
/// thread sweeps one triangle); a host stage that sweeps many triangles per
/// step may compute them once into a table with the same values.
template <class T>
struct StepCapsules {
  const ContactTools<T>& tools;
  int k;
  TISSUE_HD Capsule<T> operator()(int t, int j) const { return tool_capsule(tools.tool[t], tools.steps, k, j); }
};

/// How far the axis point of tool t level with x moves during TLED step k
/// of the advance (m): its tip's motion plus the turn of its axis at x's
/// axial coordinate (clamped to the shaft).
template <class T>
TISSUE_HD Vec3<T> tool_motion_at(const ToolStep<T>& t, int steps, int k, Vec3<T> x) {
  Vec3<T> tip0, axis0, tip1, axis1;
  interpolate_pose(t.tip0, t.axis0, t.tip1, t.axis1, T(k) / T(steps), tip0, axis0);
  interpolate_pose(t.tip0, t.axis0, t.tip1, t.axis1, T(k + 1) / T(steps), tip1, axis1);
  T s = dot(x - tip1, axis1);
  s = s < T(0) ? T(0) : (s > t.shaft ? t.shaft : s);
  return (tip1 + s * axis1) - (tip0 + s * axis0);
}

/// Parameter in [0, 1] of the point of segment a -> b closest to x (0 for a
/// zero-length segment).
template <class T>
TISSUE_HD T closest_on_segment(Vec3<T> a, Vec3<T> b, Vec3<T> x) {
  const Vec3<T> d = b - a;
  const T dd = dot(d, d);
  if (!(dd > T(0))) return T(0);
  const T s = dot(x - a, d) / dd;
  return s < T(0) ? T(0) : (s > T(1) ? T(1) : s);
}

/// A unit vector perpendicular to d (any; deterministic).
template <class T>
TISSUE_HD Vec3<T> any_perpendicular(Vec3<T> d) {
  const Vec3<T> e = std::fabs(d.x) < T(0.6) ? Vec3<T>{T(1), T(0), T(0)} : Vec3<T>{T(0), T(1), T(0)};
  return unit_or(cross(d, e), Vec3<T>{T(0), T(0), T(1)});
}

/// Direction out of the capsule at axis point c for a point on the axis
/// itself (distance zero): away from the handle at the tip, perpendicular to
/// the axis along the shaft.
template <class T>
TISSUE_HD Vec3<T> axis_escape(const Capsule<T>& cap, T s) {
  const Vec3<T> d = cap.b - cap.a;
  const Vec3<T> ahead = unit_or(T(-1) * d, Vec3<T>{T(0), T(0), T(-1)});
  return s > T(0) ? any_perpendicular(ahead) : ahead;
}

/// Node contact: if x lies inside the capsule, moves it radially to the
/// capsule's surface, writes the outward normal n and returns true.
template <class T>
TISSUE_HD bool push_out_of_capsule(const Capsule<T>& cap, Vec3<T>& x, Vec3<T>& n) {
  const T s = closest_on_segment(cap.a, cap.b, x);
  const Vec3<T> c = cap.a + s * (cap.b - cap.a);
  const Vec3<T> d = x - c;
  const T dist = norm(d);
  if (!(dist < cap.r)) return false;
  n = dist > T(0) ? (T(1) / dist) * d : axis_escape(cap, s);
  x = c + cap.r * n;
  return true;
}

/// The point of triangle (P0, P1, P2) closest to x; w receives its
/// barycentric weights (w0 + w1 + w2 = 1). Works on degenerate triangles.
template <class T>
TISSUE_HD Vec3<T> closest_on_triangle(Vec3<T> x, Vec3<T> P0, Vec3<T> P1, Vec3<T> P2, T w[3]) {
  // Voronoi regions of the vertices, edges and face (Ericson, Real-Time
  // Collision Detection, 5.1.5), in the order vertex, edge, face.
  const Vec3<T> ab = P1 - P0, ac = P2 - P0, ap = x - P0;
  const T d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= T(0) && d2 <= T(0)) { w[0] = T(1); w[1] = w[2] = T(0); return P0; }
  const Vec3<T> bp = x - P1;
  const T d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= T(0) && d4 <= d3) { w[1] = T(1); w[0] = w[2] = T(0); return P1; }
  const T vc = d1 * d4 - d3 * d2;
  if (vc <= T(0) && d1 >= T(0) && d3 <= T(0)) {
    const T v = d1 / (d1 - d3);
    w[0] = T(1) - v; w[1] = v; w[2] = T(0);
    return P0 + v * ab;
  }
  const Vec3<T> cp = x - P2;
  const T d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= T(0) && d5 <= d6) { w[2] = T(1); w[0] = w[1] = T(0); return P2; }
  const T vb = d5 * d2 - d1 * d6;
  if (vb <= T(0) && d2 >= T(0) && d6 <= T(0)) {
    const T v = d2 / (d2 - d6);
    w[0] = T(1) - v; w[1] = T(0); w[2] = v;
    return P0 + v * ac;
  }
  const T va = d3 * d6 - d5 * d4;
  if (va <= T(0) && (d4 - d3) >= T(0) && (d5 - d6) >= T(0)) {
    const T v = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    w[0] = T(0); w[1] = T(1) - v; w[2] = v;
    return P1 + v * (P2 - P1);
  }
  // den = |ab x ac|^2: for a (nearly) flat triangle the region tests above are rounding noise and the face
  // solution divides by noise; its nearest point then lies on one of its edges
  const T den = va + vb + vc;
  if (!(den > T(64) * std::numeric_limits<T>::epsilon() * dot(ab, ab) * dot(ac, ac))) {
    const Vec3<T> bc = P2 - P1;
    const T s0 = closest_on_segment(P0, P1, x), s1 = closest_on_segment(P1, P2, x), s2 = closest_on_segment(P0, P2, x);
    const Vec3<T> q0 = P0 + s0 * ab, q1 = P1 + s1 * bc, q2 = P0 + s2 * ac;
    const T d0 = dot(x - q0, x - q0), d1 = dot(x - q1, x - q1), d2 = dot(x - q2, x - q2);
    if (d0 <= d1 && d0 <= d2) { w[0] = T(1) - s0; w[1] = s0; w[2] = T(0); return q0; }
    if (d1 <= d2) { w[0] = T(0); w[1] = T(1) - s1; w[2] = s1; return q1; }
    w[0] = T(1) - s2; w[1] = T(0); w[2] = s2;
    return q2;
  }
  const T v = vb / den, u = vc / den;
  w[0] = T(1) - v - u; w[1] = v; w[2] = u;
  return P0 + v * ab + u * ac;
}

/// Closest points of segments p1 -> q1 and p2 -> q2 (Ericson 5.1.9):
/// returns s, t in [0, 1] with the points p1 + s (q1 - p1), p2 + t (q2 - p2).
template <class T>
TISSUE_HD void closest_segment_segment(Vec3<T> p1, Vec3<T> q1, Vec3<T> p2, Vec3<T> q2, T& s, T& t) {
  const Vec3<T> d1 = q1 - p1, d2 = q2 - p2, r = p1 - p2;
  const T a = dot(d1, d1), e = dot(d2, d2), f = dot(d2, r);
  const auto clamp01 = [](T v) { return v < T(0) ? T(0) : (v > T(1) ? T(1) : v); };
  if (!(a > T(0)) && !(e > T(0))) { s = t = T(0); return; }
  if (!(a > T(0))) { s = T(0); t = clamp01(f / e); return; }
  const T c = dot(d1, r);
  if (!(e > T(0))) { t = T(0); s = clamp01(-c / a); return; }
  const T b = dot(d1, d2), den = a * e - b * b;
  s = den > T(0) ? clamp01((b * f - c * e) / den) : T(0);
  t = (b * s + f) / e;
  if (t < T(0)) { t = T(0); s = clamp01(-c / a); }
  else if (t > T(1)) { t = T(1); s = clamp01((b - c) / a); }
}

/// One candidate for a triangle's point closest to a capsule's axis
/// (triangle_deepest_point), k = 0..kDeepestCandidates - 1: 0 and 1 the axis
/// ends a and b against the face, 2-4 the axis against edge k - 2 (its
/// corners k - 2 and the next), 5 the axis piercing the face's plane
/// (`found` false where it does not: parallel to it, or meeting it beyond
/// an end). q is the triangle point, w its barycentric weights, c the axis
/// point and d2 = |q - c|^2. The candidates are independent: a backend may
/// compute them side by side (the cuda sweep gives each its own lane).
template <class T>
struct DeepestCandidate {
  Vec3<T> q, c;
  T w[3];
  T d2;
  bool found;
};

inline constexpr int kDeepestCandidates = 6;

/// a[i] of three, by selects: an index that differs between a warp's lanes
/// would put a register array in memory.
template <class V>
TISSUE_HD V one_of_three(const V a[3], int i) {
  return i == 0 ? a[0] : (i == 1 ? a[1] : a[2]);
}

template <class T>
TISSUE_HD DeepestCandidate<T> deepest_candidate(const Capsule<T>& cap, const Vec3<T> P[3], int k) {
  DeepestCandidate<T> r{{T(0), T(0), T(0)}, {T(0), T(0), T(0)}, {T(0), T(0), T(0)}, T(0), true};
  if (k >= 2 && k <= 4) {  // an edge against the axis
    const int i = k - 2, j = i == 2 ? 0 : i + 1;
    const Vec3<T> Pi = one_of_three(P, i), Pj = one_of_three(P, j);
    T s, t;
    closest_segment_segment(cap.a, cap.b, Pi, Pj, s, t);
    r.c = cap.a + s * (cap.b - cap.a);
    r.q = Pi + t * (Pj - Pi);
    for (int m = 0; m < 3; ++m) r.w[m] = m == i ? T(1) - t : (m == j ? t : T(0));
  } else {  // an axis point against the face: an end, or where the axis pierces the face's plane
    if (k == 0) {
      r.c = cap.a;
    } else if (k == 1) {
      r.c = cap.b;
    } else {
      const Vec3<T> d = cap.b - cap.a, e1 = P[1] - P[0], e2 = P[2] - P[0], nrm = cross(e1, e2);
      const T den = dot(nrm, d);
      const T s = den != T(0) ? dot(nrm, P[0] - cap.a) / den : T(-1);
      r.found = s >= T(0) && s <= T(1);
      if (r.found) r.c = cap.a + s * d;
    }
    if (r.found) r.q = closest_on_triangle(r.c, P[0], P[1], P[2], r.w);  // one call: lanes 0, 1 and 5 share it
  }
  if (r.found) r.d2 = dot(r.q - r.c, r.q - r.c);
  return r;
}

/// Whether candidate e replaces the deepest so far (squared distance best):
/// the first of equal ones stays.
template <class T>
TISSUE_HD bool deeper(bool found, T d2, T best) {
  return found && d2 < best;
}

/// The triangle's point closest to the capsule's axis: writes its
/// barycentric weights w, the axis point c closest to it, and returns the
/// triangle point q. When the axis pierces the triangle the distance is zero
/// and q = c is the piercing point. The candidates in order k = 0..5, the
/// first closest kept.
template <class T>
TISSUE_HD Vec3<T> triangle_deepest_point(const Capsule<T>& cap, const Vec3<T> P[3], T w[3], Vec3<T>& c) {
  DeepestCandidate<T> best = deepest_candidate(cap, P, 0);
  TISSUE_UNROLL
  for (int k = 1; k < kDeepestCandidates; ++k) {
    const DeepestCandidate<T> e = deepest_candidate(cap, P, k);
    if (deeper(e.found, e.d2, best.d2)) best = e;
  }
  w[0] = best.w[0]; w[1] = best.w[1]; w[2] = best.w[2];
  c = best.c;
  return best.q;
}

/// How far a point x inside the tool's tip sphere must move along the unit
/// direction d to leave the sphere (0 when x is outside it). Where the tip
/// has passed a face, the face goes to the tip's far side; never along the
/// shaft (a face whose normal lines up with the shaft, on the rim of the
/// hole the tool makes, would be carried the shaft's whole length).
template <class T>
TISSUE_HD T tip_exit(const Capsule<T>& cap, Vec3<T> x, Vec3<T> d) {
  const Vec3<T> m = x - cap.a;
  const T b = dot(m, d), c = dot(m, m) - cap.r * cap.r, disc = b * b - c;
  return c < T(0) && disc > T(0) ? -b + std::sqrt(disc) : T(0);
}

/// A direction d is crosswise to the shaft when |d . axis| is below this
/// (d within 60 degrees of perpendicular to the shaft): moving along it
/// crosses the shaft's width, at most 2 r / sin(60 degrees), never its length.
template <class T>
inline constexpr T kCrosswise = T(0.5);

/// How far a point x must move along the unit direction d to leave the tool
/// where a face has passed it (0 when x is outside): the tip sphere's far
/// side (tip_exit), and, where d is crosswise to the shaft, the shaft's far
/// side too -- a face that the shaft lies behind (a tool lying along the
/// surface pressed through it) goes back under the shaft, not out over it.
/// Along the shaft only the tip sphere counts (tip_exit says why).
template <class T>
TISSUE_HD T through_exit(const Capsule<T>& cap, Vec3<T> x, Vec3<T> d) {
  T exit = tip_exit(cap, x, d);
  const Vec3<T> ab = cap.b - cap.a;
  const T len = norm(ab);
  if (!(len > T(0))) return exit;
  const Vec3<T> e = (T(1) / len) * ab;
  const T de = dot(d, e);
  if (!(std::fabs(de) < kCrosswise<T>)) return exit;
  const Vec3<T> m = x - cap.a;
  const T me = dot(m, e);
  const T sx = me < T(0) ? T(0) : (me > len ? len : me);
  if (!(norm(m - sx * e) < cap.r)) return exit;  // outside the capsule: nothing to leave
  // the capsule is convex and holds x: the ray leaves it at the largest exit of its three pieces
  // (tip sphere, cylinder level with the shaft, far end's sphere)
  const Vec3<T> mp = m - me * e, dp = d - de * e;
  const T a = dot(dp, dp), b = dot(mp, dp), c = dot(mp, mp) - cap.r * cap.r, disc = b * b - a * c;
  if (a > T(0) && disc > T(0)) {
    const T root = std::sqrt(disc);
    T lo = (-b - root) / a, hi = (-b + root) / a;  // inside the infinite cylinder
    if (de != T(0)) {                               // and level with the shaft
      const T t0 = -me / de, t1 = (len - me) / de;
      lo = t0 < t1 ? (lo > t0 ? lo : t0) : (lo > t1 ? lo : t1);
      hi = t0 < t1 ? (hi < t1 ? hi : t1) : (hi < t0 ? hi : t0);
    } else if (me < T(0) || me > len) {
      hi = lo - T(1);
    }
    if (hi >= lo && hi > exit) exit = hi;
  }
  const Vec3<T> mb = x - cap.b;
  const T bb = dot(mb, d), cb = dot(mb, mb) - cap.r * cap.r, discb = bb * bb - cb;
  if (discb > T(0) && -bb + std::sqrt(discb) > exit) exit = -bb + std::sqrt(discb);
  return exit;
}

/// Per-corner result of the contact sweep of one triangle.
template <class T>
struct CornerContact {
  Vec3<T> dx;           ///< correction of the corner's position (m)
  signed char tool;     ///< the tool that moved it last, -1 none
  std::uint8_t blocked; ///< ContactKind: kRigidContact / kOutsideRegion when the tool penetrated it but it
                        ///< could not move (0 otherwise)
};

/// Whether a corner's proposal can change its node's merge (merge_corner):
/// a blocked penetration or any non-zero component (a superset of
/// merge_corner's |dx|^2 > 0). Any other is a no-op whatever its tool: the
/// backends keep only these (the cpu's step entries, the cuda slots).
template <class T>
TISSUE_HD bool proposes(const CornerContact<T>& c) {
  return c.blocked || c.dx.x != T(0) || c.dx.y != T(0) || c.dx.z != T(0);
}

/// Whether a corner may be moved by contact, and why not (ContactKind).
/// movable = inner region node, not held in every component, not grasped.
TISSUE_HD std::uint8_t corner_block(bool inner, bool held_all, bool grasped) {
  return !inner ? std::uint8_t(kOutsideRegion) : ((held_all || grasped) ? std::uint8_t(kRigidContact) : std::uint8_t(0));
}

/// A tool has passed through a face when its axis point nearest the face is
/// this many radii behind the face's plane (on the tissue's side), or the
/// axis pierces the face. Within this band the tool is at the surface's level
/// -- beside a shaft through a hole the rim's corners must go sideways --
/// and pushes stay radial.
template <class T>
inline constexpr T kThrough = T(0.1);

/// The axis pierces a face when its distance to it is below this many radii
/// (the radial direction out of the tool is then rounding, not geometry).
template <class T>
inline constexpr T kPierced = T(1e-4);

/// The most a face may sink into a tool before face contact moves it, in
/// radii (see face_allowance).
template <class T>
inline constexpr T kFaceAllowance = T(0.05);

/// How deep a flat triangle may lie inside a tool of radius r before face
/// contact moves it (m): the sagitta of its circumcircle on the tip sphere,
/// r - sqrt(r^2 - rho^2) for circumradius rho -- how deep a face whose
/// corners all lie on the sphere reaches into it -- capped at
/// kFaceAllowance r. A faceted surface cannot follow a round tool closer
/// than its chords do: asking every face to stay wholly outside would push
/// the nodes of a fine mesh past the tool's surface by that sagitta and
/// widen the contact by up to an edge (measured on Hertz: +14 % force on a
/// 12-cell mesh). A tool smaller than the faces may sink kFaceAllowance r
/// into one and no further: it cannot slip between the corners.
template <class T>
TISSUE_HD T face_allowance(const Vec3<T> x[3], T r) {
  const Vec3<T> a = x[1] - x[0], b = x[2] - x[0], ab = x[2] - x[1];
  const T cross2 = dot(cross(a, b), cross(a, b));
  const T cap = kFaceAllowance<T> * r;
  const T rho2_num = dot(a, a) * dot(b, b) * dot(ab, ab);  // rho^2 = num / (4 |a x b|^2)
  if (!(T(4) * cross2 * r * r > rho2_num)) return cap;     // rho >= r (or a degenerate face)
  const T rho2 = rho2_num / (T(4) * cross2);
  const T sag = rho2 / (r + std::sqrt(r * r - rho2));      // r - sqrt(r^2 - rho^2) without cancellation
  return sag < cap ? sag : cap;
}

/// Whether triangle x[3] may come within reach of any sub-check capsule of
/// a TLED step (capsule(t, j): StepCapsules or a table of the same values)
/// (false: no corner and no point of it is inside any of them, so
/// sweep_triangle leaves it untouched). A conservative bound that costs
/// one point-segment distance per capsule: the triangle lies within rho of
/// its centroid g, so it is clear of a capsule when |g - axis| - rho exceeds
/// the radius, with a margin of 1e-3 r plus rounding. Most of the triangles
/// a box query returns around a tool smaller than the box fail it.
template <class T, class Capsules>
TISSUE_HD bool triangle_may_touch(const ContactTools<T>& tools, const Capsules& capsule, const Vec3<T> x[3]) {
  const Vec3<T> g = (T(1) / T(3)) * (x[0] + x[1] + x[2]);
  T rho2 = T(0);
  for (int i = 0; i < 3; ++i) rho2 = dot(x[i] - g, x[i] - g) > rho2 ? dot(x[i] - g, x[i] - g) : rho2;
  const T rho = std::sqrt(rho2);
  const T size = std::fabs(g.x) + std::fabs(g.y) + std::fabs(g.z) + rho;
  for (int t = 0; t < tools.n_tools; ++t)
    for (int j = 1; j <= tools.tool[t].substeps; ++j) {
      const Capsule<T> cap = capsule(t, j);
      const Vec3<T> c = cap.a + closest_on_segment(cap.a, cap.b, g) * (cap.b - cap.a);
      const T slack = T(1e-3) * cap.r + T(64) * std::numeric_limits<T>::epsilon() * (size + std::fabs(cap.r));
      if (!(norm(g - c) - rho > cap.r + slack)) return true;
    }
  return false;
}

/// Node contact (a) for one corner at x: whether it lies inside the capsule,
/// and where it goes -- radially to the capsule's surface, or, where the
/// tip has passed through the face (`through`, outward normal N), to the
/// face's far side of the tip.
template <class T>
struct CornerPush {
  Vec3<T> x;
  bool inside;
};

template <class T>
TISSUE_HD CornerPush<T> corner_push(const Capsule<T>& cap, Vec3<T> x, bool through, Vec3<T> N) {
  CornerPush<T> p{x, false};
  Vec3<T> n;
  if (!push_out_of_capsule(cap, p.x, n)) return p;
  p.inside = true;
  const T exit = through ? through_exit(cap, x, T(-1) * N) : T(0);
  if (exit > T(0)) p.x = x + exit * (T(-1) * N);  // to the face's far side, not out through the tool
  return p;
}

/// How sweep_touching_triangle computes its independent parts: the deepest
/// point's candidates and the three corners' pushes, one after another on
/// the calling thread. (The cuda sweep passes its own, computing them on
/// several lanes with the same arithmetic and the same choice.)
struct SweepInOrder {
  template <class T>
  TISSUE_HD Vec3<T> deepest(const Capsule<T>& cap, const Vec3<T> P[3], T w[3], Vec3<T>& c) const {
    return triangle_deepest_point(cap, P, w, c);
  }
  template <class T>
  TISSUE_HD void push_corners(const Capsule<T>& cap, const Vec3<T> x[3], bool through, Vec3<T> N,
                              CornerPush<T> push[3]) const {
    for (int i = 0; i < 3; ++i) push[i] = corner_push(cap, x[i], through, N);
  }
};

/// sweep_triangle for a triangle that triangle_may_touch(tools, capsule, x)
/// accepted, over the step's capsules (StepCapsules or a table of
/// the same values); `parts` computes its independent parts (SweepInOrder).
template <class T, class Capsules, class Parts = SweepInOrder>
TISSUE_HD void sweep_touching_triangle(const ContactTools<T>& tools, const Capsules& capsule, const Vec3<T> x_in[3],
                                       const std::uint8_t block[3], CornerContact<T> out[3],
                                       const Parts& parts = {}) {
  Vec3<T> x[3] = {x_in[0], x_in[1], x_in[2]};
  for (int i = 0; i < 3; ++i) out[i] = {{T(0), T(0), T(0)}, -1, 0};
  for (int t = 0; t < tools.n_tools; ++t) {
    const ToolStep<T>& tool = tools.tool[t];
    for (int j = 1; j <= tool.substeps; ++j) {
      const Capsule<T> cap = capsule(t, j);
      // has the tool passed through this face? (sidedness, at the top of this file)
      T w[3];
      Vec3<T> c;
      const Vec3<T> N = unit_or(cross(x[1] - x[0], x[2] - x[0]), axis_escape(cap, T(0)));  // outward
      Vec3<T> q = parts.deepest(cap, x, w, c);
      // the tip passes through a face: the axis meets the face at the tip, or the tip is behind
      // the face's plane having crossed it since the last check, or behind it and over the face
      // (its nearest point inside the face: the face cuts the tip sphere beyond its centre).
      // The shaft passes a face that lies along it (its normal crosswise to the shaft) the same
      // two ways: crossed since the last check, or lying under the face -- a tool lying on
      // the surface, which the tissue pushed more than its radius into it in one step, would
      // otherwise have that face pushed radially out over it and sink through the surface.
      // A face across the shaft is a hole's rim, and a face whose edge the tissue tilted past the
      // tip is rounded off: both are pushed radially.
      const bool at_tip = !(norm(c - cap.a) > kPierced<T> * cap.r);
      const Capsule<T> before = capsule(t, j - 1);
      const T along = at_tip ? T(0) : closest_on_segment(cap.a, cap.b, c);
      const Vec3<T> c_before = before.a + along * (before.b - before.a);  // c's axis point at the last check
      const bool behind = dot(c - q, N) < -kThrough<T> * cap.r;
      const bool crossed = behind && dot(c_before - q, N) >= T(0);
      const bool under = behind && w[0] > T(0) && w[1] > T(0) && w[2] > T(0);
      // over the face, for the shaft: the face's plane lies over c to within kThrough radii sideways
      // (its nearest point is where the axis passes under it, inside the face or on its edge: a shaft
      // lying across a face is nearest it all along its chord, and the first found is on an edge)
      const Vec3<T> up = q - c;
      const Vec3<T> side = up - dot(up, N) * N;
      const bool over = behind && !(norm(side) > kThrough<T> * cap.r);
      const Vec3<T> shaft = cap.b - cap.a;
      const bool lies_along = !at_tip && std::fabs(dot(N, shaft)) < kCrosswise<T> * norm(shaft);
      const bool tip_through = at_tip && (!(norm(q - c) > kPierced<T> * cap.r) || crossed || under);
      const bool shaft_through = !tip_through && lies_along && norm(up) < cap.r && (crossed || over);
      const bool through = tip_through || shaft_through;
      // a face the shaft lies under goes whole to the shaft's far side: the shaft is under it all
      // along a chord, and moving the corners by barycentric shares of one point's exit would tilt
      // the face about its far corner until the shaft pierced it
      const T shaft_exit = shaft_through ? through_exit(cap, q, T(-1) * N) : T(0);
      const Vec3<T> x_check[3] = {x[0], x[1], x[2]};
      bool moved = false;  // by (a): else (b) starts from the deepest point found above
      CornerPush<T> push[3];
      parts.push_corners(cap, x, through, N, push);
      for (int i = 0; i < 3; ++i) {  // (a) node contact
        if (!push[i].inside) continue;
        if (block[i]) {
          out[i].blocked = block[i];
          out[i].tool = out[i].tool < 0 ? static_cast<signed char>(t) : out[i].tool;
          continue;
        }
        x[i] = push[i].x;
        moved = true;
        out[i].tool = static_cast<signed char>(t);
      }
      if (!tools.face) continue;
      if (shaft_through) {  // (b) for a face the shaft lies under: every corner at least shaft_exit along -N
        const bool all_blocked = block[0] && block[1] && block[2];
        for (int i = 0; i < 3; ++i) {
          if (block[i]) {  // it cannot move; reported where none of the face can (as face contact does)
            if (all_blocked) out[i].blocked = block[i];
            if (all_blocked && out[i].tool < 0) out[i].tool = static_cast<signed char>(t);
            continue;
          }
          const T gone = -dot(x[i] - x_check[i], N);
          if (!(gone < shaft_exit)) continue;
          x[i] = x[i] + (shaft_exit - gone) * (T(-1) * N);
          out[i].tool = static_cast<signed char>(t);
        }
        continue;
      }
      if (moved) q = parts.deepest(cap, x, w, c);  // (b) face contact, after (a)
      const Vec3<T> d = q - c;
      const T dist = norm(d);
      const T reach = cap.r - face_allowance(x, cap.r);  // how close the face may come to the axis
      if (!(dist < reach) && !through) continue;
      if (!(dist < cap.r)) continue;
      const bool pierced = !(dist > kPierced<T> * cap.r);  // the direction out is the face's, not rounding's
      if (pierced && !through) continue;  // the shaft through a rim face: its corners go out radially, by (a)
      const Vec3<T> n = through || pierced ? T(-1) * N : (T(1) / dist) * d;
      const T delta = through || pierced ? through_exit(cap, q, n) : reach - dist;
      if (!(delta > T(0))) continue;
      T wsum = T(0);
      for (int i = 0; i < 3; ++i) wsum += block[i] ? T(0) : w[i] * w[i];
      if (!(wsum > T(0))) {
        for (int i = 0; i < 3; ++i)
          if (w[i] > T(0) && block[i]) {
            out[i].blocked = block[i];
            if (out[i].tool < 0) out[i].tool = static_cast<signed char>(t);
          }
        continue;
      }
      for (int i = 0; i < 3; ++i) {
        if (block[i] || !(w[i] > T(0))) continue;
        x[i] = x[i] + (w[i] * delta / wsum) * n;
        out[i].tool = static_cast<signed char>(t);
      }
    }
  }
  for (int i = 0; i < 3; ++i) out[i].dx = x[i] - x_in[i];
}

/// The contact sweep of one surface triangle during TLED step k of the
/// advance (see the rule at the top): x[3] are its corners' positions after
/// the free update (m), block[3] their corner_block() values. Fills out[3]
/// (a triangle that triangle_may_touch rejects: no tool, dx = 0).
template <class T>
TISSUE_HD void sweep_triangle(const ContactTools<T>& tools, int k, const Vec3<T> x[3], const std::uint8_t block[3],
                              CornerContact<T> out[3]) {
  const StepCapsules<T> capsule{tools, k};
  if (triangle_may_touch(tools, capsule, x)) return sweep_touching_triangle(tools, capsule, x, block, out);
  for (int i = 0; i < 3; ++i) out[i] = {{T(0), T(0), T(0)}, -1, 0};  // no contact: dx = 0, no tool
}

/// How near a triangle must come to a tool's axis, in radii, for its corners
/// to be contact candidates (they seed the region before the advance).
template <class T>
inline constexpr T kCandidateReach = T(1.5);

/// Whether the triangle x[3] comes within kCandidateReach radii of the axis
/// of any sub-check capsule of the motion `sweep` (a one-step ContactTools:
/// the Backend's contact_candidates, on both backends).
template <class T>
TISSUE_HD bool triangle_near_tools(const ContactTools<T>& sweep, const Vec3<T> x[3]) {
  for (int k = 0; k < sweep.n_tools; ++k)
    for (int j = 1; j <= sweep.tool[k].substeps; ++j) {
      const Capsule<T> cap = tool_capsule(sweep.tool[k], 1, 0, j);
      T w[3];
      Vec3<T> axis_point;
      if (norm(triangle_deepest_point(cap, x, w, axis_point) - axis_point) < kCandidateReach<T> * cap.r) return true;
    }
  return false;
}

/// Rotation taking unit vector a to unit vector b applied to v (Rodrigues,
/// the smallest rotation; identity when a == b; a half turn about an axis
/// perpendicular to a when they are opposite to rounding). 1 + a.b is taken
/// as |a + b|^2 / 2, accurate also near opposite vectors.
template <class T>
TISSUE_HD Vec3<T> rotate_between(Vec3<T> a, Vec3<T> b, Vec3<T> v) {
  const Vec3<T> sum = a + b;
  const T one_plus_c = T(0.5) * dot(sum, sum);  // 1 + a.b, without the cancellation near -1
  if (!(one_plus_c > T(16) * std::numeric_limits<T>::epsilon())) {
    // opposite: half turn about any perpendicular axis p, R v = 2 (p.v) p - v
    const Vec3<T> p = any_perpendicular(a);
    return T(2) * dot(p, v) * p - v;
  }
  const Vec3<T> k = cross(a, b);
  return (one_plus_c - T(1)) * v + cross(k, v) + (dot(k, v) / one_plus_c) * k;
}

/// Where a grasped node goes when its tool is at pose (tip, axis): the
/// node's offset from the tip when the grasp started (offset, with the axis
/// then `axis0`) carried along by the tool's translation and the smallest
/// rotation of its axis.
template <class T>
TISSUE_HD Vec3<T> grasped_position(Vec3<T> tip, Vec3<T> axis, Vec3<T> axis0, Vec3<T> offset) {
  return tip + rotate_between(axis0, axis, offset);
}

/// Force the tool exerts on one contact node with internal force f (N):
/// pushed: (f . n)+ n plus, for a tool of friction coefficient mu > 0,
/// f's tangential part f_t clamped to the Coulomb cone, |f_t| <= mu (f . n)+
/// (continuous from stick to slide); grasped: f; otherwise zero. `fixed`
/// masks components that a scene constraint holds (their force is the
/// support's, not the tool's).
template <class T>
TISSUE_HD Vec3<T> contact_reaction(std::uint8_t kind, Vec3<T> f, Vec3<T> n, std::uint8_t fixed, T mu = T(0)) {
  const Vec3<T> fm = {(fixed & 1) ? T(0) : f.x, (fixed & 2) ? T(0) : f.y, (fixed & 4) ? T(0) : f.z};
  if (kind == kGrasped) return fm;
  if (kind != kPushed) return {T(0), T(0), T(0)};
  const T fn = dot(fm, n);
  if (!(fn > T(0))) return {T(0), T(0), T(0)};
  if (!(mu > T(0))) return fn * n;
  const Vec3<T> ft = fm - fn * n;
  const T t = norm(ft), cap = mu * fn;
  return fn * n + (t > cap ? cap / t : T(1)) * ft;
}

}  // namespace tissue
